"""A roof meshed in parts whose seams are divided differently on each side (T-junctions) is
stitched into one surface; parts apart, and meshes without such seams, are left as they are."""

from __future__ import annotations

import numpy as np
import pytest

from engine.geometry.seams import SEAM_SAG, stitch_seams, weld_seams
from engine.geometry.surfaces import clean_mesh


def _dome_part(nx: int, ny: int, x0: float, x1: float) -> tuple[np.ndarray, np.ndarray]:
    """A grid of the dome z = 4 (1 - ((x/8)^2 + (y/6)^2) / 2) over [x0, x1] x [-6, 6]."""
    x, y = np.meshgrid(np.linspace(x0, x1, nx + 1), np.linspace(-6, 6, ny + 1), indexing="ij")
    vertices = np.c_[x.ravel(), y.ravel(), (4 * (1 - 0.5 * ((x / 8) ** 2 + (y / 6) ** 2))).ravel()]
    ids = np.arange(len(vertices)).reshape(nx + 1, ny + 1)
    a, b, c, d = ids[:-1, :-1].ravel(), ids[1:, :-1].ravel(), ids[1:, 1:].ravel(), ids[:-1, 1:].ravel()
    return vertices, np.r_[np.c_[a, b, c], np.c_[a, c, d]]


def _two_parts(left_rows: int, right_rows: int, gap: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    va, fa = _dome_part(20, left_rows, -8, 0)
    vb, fb = _dome_part(30, right_rows, gap, 8)
    return np.r_[va, vb], np.r_[fa, fb + len(va)]


def _area(vertices: np.ndarray, faces: np.ndarray) -> float:
    corners = vertices[faces]
    return 0.5 * float(np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]),
                                      axis=1).sum())


@pytest.mark.parametrize("left, right", [(30, 45), (30, 43), (17, 40)])
def test_a_curved_seam_divided_differently_on_each_side_is_stitched(left, right):
    """One patch with one boundary loop, every boundary vertex on the outer rectangle (the seam is no
    longer an edge), and the two parts' area within the seam's sag (a split triangle's corners leave
    its plane by under 1e-5 of the area; a lost or doubled triangle is 4e-4 of it). Some rows
    coincide (30/45: every 0.8 m), some only at the ends (30/43)."""
    vertices, faces = _two_parts(left, right)
    mesh, report = clean_mesh(vertices, faces)
    assert report.patches == 1 and report.boundary_loops == 1
    assert report.stitched_vertices > 0 and any("stitched" in note for note in report.notes)
    edge = mesh.vertices[mesh.boundary_vertices]
    on_outline = np.isclose(np.abs(edge[:, 0]), 8.0) | np.isclose(np.abs(edge[:, 1]), 6.0)
    assert on_outline.all()
    assert mesh.area == pytest.approx(_area(vertices, faces), rel=5e-5)


@pytest.mark.parametrize("left, right", [(30, 30), (30, 43)])
def test_a_seam_left_open_at_a_modellers_tolerance_is_closed(left, right):
    """The right half 0.5 mm off the left (Rhino's 1 mm tolerance on a roof in metres): its seam
    vertices are welded to the other side's (and those on its edges stitched): one patch, one
    boundary loop, all on the outline. Before, the two halves made two grids whose joints clashed."""
    vertices, faces = _two_parts(left, right, gap=0.0005)
    mesh, report = clean_mesh(vertices, faces)
    assert report.welded_vertices > 0 and any("welded" in note for note in report.notes)
    assert report.patches == 1 and report.boundary_loops == 1
    edge = mesh.vertices[mesh.boundary_vertices]
    assert np.all(np.isclose(np.abs(edge[:, 0]), 8.0) | np.isclose(np.abs(edge[:, 1]), 6.0))


def test_parts_apart_are_not_stitched():
    """A gap of twice the sag bound between the parts is a gap: nothing is welded or split."""
    vertices, faces = _two_parts(30, 43, gap=2 * SEAM_SAG * 12 / 30)
    representative, welded = weld_seams(vertices, faces)
    assert welded == 0 and np.array_equal(representative, np.arange(len(vertices)))
    stitched_vertices, stitched_faces, count = stitch_seams(vertices, faces)
    assert count == 0 and np.array_equal(stitched_faces, faces)


def test_a_mesh_without_seams_is_left_as_it_is():
    vertices, faces = _dome_part(20, 30, -8, 8)
    out_vertices, out_faces, count = stitch_seams(vertices, faces)
    assert count == 0 and out_vertices is vertices and out_faces is faces
