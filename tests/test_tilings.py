"""Equivalent plate stiffness of regular tilings: closed forms (METHOD.md section 6, thesis
chapter 7) against the periodic homogenisation with the frame elements, and the homogenised
membrane stiffness against a finite patch solved with engine.structure.frame.linear_static."""

from __future__ import annotations

import numpy as np
import pytest

from engine.errors import InputError
from engine.remeshing.tilings import (
    TILINGS,
    PeriodicCell,
    closed_form_stiffness,
    equal_length_edges,
    homogenise,
    length_per_area,
    periodic_cell,
    periodic_voronoi_cell,
)
from engine.structure.frame import FrameModel, linear_static
from engine.structure.supports import Supports

# the thesis's bar: solid steel 50 mm, E = 210 GPa, nu = 0.3 (METHOD.md section 6)
EA, EI, GJ = 412_334e3, 64.427e3, 49.559e3


def test_thesis_bar_values_follow_from_the_section():
    d, E, G = 0.05, 210e9, 210e9 / 2.6
    assert E * np.pi * d**2 / 4 == pytest.approx(EA, rel=1e-5)
    assert E * np.pi * d**4 / 64 == pytest.approx(EI, rel=1e-4)
    assert G * np.pi * d**4 / 32 == pytest.approx(GJ, rel=1e-4)


@pytest.mark.parametrize("tiling", TILINGS)
@pytest.mark.parametrize("l", [1.0, 0.25])
def test_homogenisation_reproduces_the_closed_forms(tiling, l):
    closed = closed_form_stiffness(tiling, l, EA, EI, GJ)
    numeric = homogenise(periodic_cell(tiling, l), EA=EA, EI=EI, GJ=GJ)
    np.testing.assert_allclose(numeric.C, closed.C, rtol=0.02, atol=1e-9 * closed.C.max())
    np.testing.assert_allclose(numeric.D, closed.D, rtol=0.02, atol=1e-9 * closed.D.max())
    assert numeric.length_per_area == pytest.approx(length_per_area(tiling, l))


def test_finer_beam_elements_change_nothing():
    """The macro fields are at most quadratic along a beam: one cubic element is exact."""
    cell = periodic_cell("hexagon", 0.5)
    one = homogenise(cell, EA=EA, EI=EI, GJ=GJ)
    three = homogenise(cell, EA=EA, EI=EI, GJ=GJ, elements_per_beam=3)
    np.testing.assert_allclose(three.C, one.C, rtol=1e-8, atol=1e-9 * one.C.max())
    np.testing.assert_allclose(three.D, one.D, rtol=1e-8, atol=1e-9 * one.D.max())


@pytest.mark.parametrize("tiling", ["triangle", "hexagon"])
def test_hexagonal_symmetry_gives_isotropy_in_any_orientation(tiling):
    cell = periodic_cell(tiling, 1.0)
    c, s = np.cos(0.37), np.sin(0.37)
    R = np.array([[c, -s], [s, c]])
    rotated = PeriodicCell(cell.nodes @ R.T, cell.beams, cell.shifts, cell.lattice @ R.T)
    a = homogenise(cell, EA=EA, EI=EI, GJ=GJ)
    b = homogenise(rotated, EA=EA, EI=EI, GJ=GJ)
    np.testing.assert_allclose(b.C, a.C, rtol=1e-8, atol=1e-8 * a.C.max())
    np.testing.assert_allclose(b.D, a.D, rtol=1e-8, atol=1e-8 * a.D.max())
    assert a.C[2, 2] == pytest.approx((a.C[0, 0] - a.C[0, 1]) / 2, rel=1e-8)
    assert a.D[2, 2] == pytest.approx((a.D[0, 0] - a.D[0, 1]) / 2, rel=1e-8)


def test_equal_length_ratio_is_three_to_root_three_to_one():
    edges = equal_length_edges(4.0)
    assert edges["triangle"] / edges["hexagon"] == pytest.approx(3.0)
    assert edges["square"] / edges["hexagon"] == pytest.approx(np.sqrt(3.0))
    for tiling, l in edges.items():
        assert periodic_cell(tiling, l).length_per_area == pytest.approx(4.0)


def test_equivalent_thickness_of_the_square_grid():
    """Square grid: E t = EA / l, B = EI / l, so t = sqrt(12 EI / EA) = sqrt(12) d / 4 for a solid bar."""
    square = closed_form_stiffness("square", 0.7, EA, EI, GJ)
    assert square.equivalent_thickness == pytest.approx(np.sqrt(12) * 0.05 / 4, rel=1e-4)
    triangle = closed_form_stiffness("triangle", 0.7, EA, EI, GJ)
    K, mu = triangle.C[0, 0] - triangle.C[2, 2], triangle.C[2, 2]
    assert triangle.membrane_modulus == pytest.approx(4 * K * mu / (K + mu))


def test_finite_triangular_patch_under_tension_agrees_with_the_homogenised_plate():
    """24 x 21 nodes, uniform N_yy on the straight top and bottom rows, one node held: the strains
    fitted over the central quarter match C^-1 N within 2 % (boundary effects of the finite patch)."""
    l, nx, ny, N = 1.0, 24, 21, 1e5
    rows = np.arange(ny)[:, None]
    points = np.stack(np.broadcast_arrays(np.arange(nx)[None, :] * l + 0.5 * l * (rows % 2),
                                          rows * l * np.sqrt(3) / 2), axis=-1).reshape(-1, 2)
    ids = np.arange(nx * ny).reshape(ny, nx)
    beams = [np.column_stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()]),
             np.column_stack([ids[:-1].ravel(), ids[1:].ravel()])]
    even, odd = ids[0:-1:2], ids[1:-1:2]
    beams.append(np.column_stack([even[:, 1:].ravel(), ids[1::2][: len(even)][:, :-1].ravel()]))
    beams.append(np.column_stack([odd[:, :-1].ravel(), ids[2::2][: len(odd)][:, 1:].ravel()]))
    beams = np.vstack(beams)
    lengths = np.linalg.norm(points[beams[:, 1]] - points[beams[:, 0]], axis=1)
    assert np.allclose(lengths, l)
    model = FrameModel(nodes=np.column_stack([points, np.zeros(len(points))]), beams=beams, E=EA, G=GJ, A=1.0,
                       Iy=EI / EA, Iz=EI / EA, J=1.0, up=np.array([0.0, 0.0, 1.0]))
    loads = np.zeros((len(points), 6))
    share = np.full(nx, N * l)
    share[[0, -1]] = N * l / 2
    loads[ids[0], 1], loads[ids[-1], 1] = -share, share
    centre = ids[ny // 2, nx // 2]
    result = linear_static(model, Supports(nodes=np.array([centre]), restraints=np.ones((1, 6), bool)), loads)
    assert np.abs(result.reactions).max() < 1e-6 * N * l
    inner = np.all(np.abs(points - points[centre]) < [nx * l / 4, ny * l * np.sqrt(3) / 8], axis=1)
    basis = np.column_stack([np.ones(inner.sum()), points[inner]])
    eps_xx = np.linalg.lstsq(basis, result.displacements[inner, 0], rcond=None)[0][1]
    eps_yy = np.linalg.lstsq(basis, result.displacements[inner, 1], rcond=None)[0][2]
    expected = np.linalg.solve(homogenise(periodic_cell("triangle", l), EA=EA, EI=EI, GJ=GJ).C, [0.0, N, 0.0])
    assert eps_yy == pytest.approx(expected[1], rel=0.02)
    assert eps_xx == pytest.approx(expected[0], rel=0.02)


def test_voronoi_of_a_triangular_seed_lattice_is_the_hexagon_tiling():
    """Seeds on a triangular lattice of spacing a: regular hexagons of side a / sqrt3."""
    a = 0.8
    lattice = a * np.array([[1.0, 0.0], [0.5, np.sqrt(3) / 2]])
    cell = periodic_voronoi_cell(np.array([[0.13, 0.21]]), lattice)
    assert len(cell.nodes) == 2 and len(cell.beams) == 3
    numeric = homogenise(cell, EA=EA, EI=EI, GJ=GJ)
    closed = closed_form_stiffness("hexagon", a / np.sqrt(3), EA, EI, GJ)
    np.testing.assert_allclose(numeric.C, closed.C, rtol=1e-6, atol=1e-9 * closed.C.max())
    np.testing.assert_allclose(numeric.D, closed.D, rtol=1e-6, atol=1e-9 * closed.D.max())


def test_random_periodic_voronoi_patch_is_independent_of_the_cell_description():
    """One periodic pattern, described by translated seeds and by another pair of period vectors
    ((4,0),(4,4) instead of (4,0),(0,4)), has one C and one D; Euler on the torus: V = 2k, E = 3k."""
    rng = np.random.default_rng(3)
    seeds = rng.uniform(0.0, 4.0, (16, 2))
    square = periodic_voronoi_cell(seeds, 4.0 * np.eye(2))
    assert len(square.nodes) == 32 and len(square.beams) == 48
    assert np.all(np.bincount(square.beams.ravel()) == 3)
    sheared = periodic_voronoi_cell(seeds + [0.37, -1.1], np.array([[4.0, 0.0], [4.0, 4.0]]))
    assert sheared.length_per_area == pytest.approx(square.length_per_area, rel=1e-9)
    a = homogenise(square, EA=EA, EI=EI, GJ=GJ)
    b = homogenise(sheared, EA=EA, EI=EI, GJ=GJ)
    np.testing.assert_allclose(b.C, a.C, rtol=1e-6, atol=1e-7 * a.C.max())
    np.testing.assert_allclose(b.D, a.D, rtol=1e-6, atol=1e-7 * a.D.max())
    assert np.all(np.linalg.eigvalsh(a.C) > 0) and np.all(np.linalg.eigvalsh(a.D) > 0)


def test_bad_input_is_an_input_error():
    with pytest.raises(InputError, match="triangle"):
        closed_form_stiffness("pentagon", 1.0, EA, EI, GJ)
    with pytest.raises(InputError):
        closed_form_stiffness("square", -1.0, EA, EI, GJ)
    with pytest.raises(InputError):
        homogenise(periodic_cell("square", 1.0), EA=EA, EI=0.0, GJ=GJ)
    with pytest.raises(InputError, match="coincide"):
        periodic_voronoi_cell(np.array([[0.1, 0.1], [1.1, 0.1]]), np.eye(2))
