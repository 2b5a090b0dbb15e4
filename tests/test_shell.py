"""Shell elements against published benchmarks, a patch test, rigid-body modes and mechanisms."""

from __future__ import annotations

import json

import numpy as np
import pytest

from engine.errors import InputError, MechanismError
from engine.geometry.parametric import cap, grid_triangles
from engine.linalg import rigid_body_modes
from engine.mesh import TriMesh
from engine.structure.loads import LoadCase
from engine.structure.shell import (
    ShellMaterial,
    analyse_shell,
    shell_nodal_loads,
    shell_stiffness,
)
from engine.structure.supports import Supports
from workflow.solver_json import solve_shell_json

from .shell_models import (
    HEMISPHERE_REFERENCE,
    PLATE_CLAMPED,
    PLATE_SIMPLY_SUPPORTED,
    SCORDELIS_LO_REFERENCE,
    pinched_hemisphere,
    scordelis_lo,
    square_plate,
)


@pytest.mark.parametrize("clamped, reference, tolerance", [(False, PLATE_SIMPLY_SUPPORTED, 0.01),
                                                           (True, PLATE_CLAMPED, 0.02)])
def test_square_plates_under_uniform_load(clamped, reference, tolerance):
    deflection, error = square_plate(16, clamped)
    assert deflection == pytest.approx(reference, rel=tolerance)
    assert error < 1e-6


def test_scordelis_lo_roof():
    """32 x 32 cells per quarter (8192 facets in the full roof): within 3 % of 0.3024."""
    deflection, error, _ = scordelis_lo(32)
    assert deflection == pytest.approx(SCORDELIS_LO_REFERENCE, rel=0.03)
    assert error < 1e-6


def test_scordelis_lo_converges_from_below():
    coarse, _, _ = scordelis_lo(4)
    medium, _, _ = scordelis_lo(8)
    assert coarse < medium < SCORDELIS_LO_REFERENCE * 1.01


def test_pinched_hemisphere():
    deflection, error = pinched_hemisphere(16)
    assert deflection == pytest.approx(HEMISPHERE_REFERENCE, rel=0.03)
    assert error < 1e-6


def test_membrane_patch_test_on_an_irregular_mesh():
    """Uniform tension on a distorted mesh: constant N = sigma t and the exact linear displacement."""
    rng = np.random.default_rng(3)
    n = 6
    xs = np.linspace(0, 2.0, n + 1)
    ys = np.linspace(0, 1.0, n + 1)
    x, y = np.meshgrid(xs, ys, indexing="ij")
    interior = ~(np.isclose(x, 0) | np.isclose(x, 2) | np.isclose(y, 0) | np.isclose(y, 1))
    x = x + interior * rng.uniform(-0.08, 0.08, x.shape)
    y = y + interior * rng.uniform(-0.04, 0.04, y.shape)
    mesh = TriMesh(vertices=np.c_[x.ravel(), y.ravel(), np.zeros(x.size)], faces=grid_triangles(n, n))
    E, nu, t, sigma = 2e5, 0.25, 0.1, 3.0
    left = np.flatnonzero(np.isclose(x, 0).ravel())
    corner = np.flatnonzero((np.isclose(x, 0) & np.isclose(y, 0)).ravel())
    out_of_plane = np.flatnonzero((np.isclose(x, 2) & (np.isclose(y, 0) | np.isclose(y, 1))).ravel())
    supports = Supports.merge([(left, np.array([1, 0, 1, 0, 0, 0], bool)), (corner, np.array([0, 1, 0, 0, 0, 0], bool)),
                               (out_of_plane, np.array([0, 0, 1, 0, 0, 0], bool))])
    loads = np.zeros((mesh.n_vertices, 6))
    right = np.flatnonzero(np.isclose(x, 2).ravel())
    right = right[np.argsort(y.ravel()[right])]
    segment = np.diff(y.ravel()[right])
    np.add.at(loads[:, 0], right[:-1], 0.5 * sigma * t * segment)
    np.add.at(loads[:, 0], right[1:], 0.5 * sigma * t * segment)
    result = analyse_shell(mesh, supports, loads, thickness=t, material=ShellMaterial(E=E, nu=nu))
    frames = result.face_frames
    # N in global xy from the facet frames
    e1, e2 = frames[:, 0, :2], frames[:, 1, :2]
    N = result.face_membrane_forces
    nxx = N[:, 0] * e1[:, 0] ** 2 + N[:, 1] * e2[:, 0] ** 2 + 2 * N[:, 2] * e1[:, 0] * e2[:, 0]
    assert np.allclose(nxx, sigma * t, rtol=1e-9)
    assert np.allclose(result.face_principal_forces[:, 1], 0.0, atol=1e-9 * sigma * t)
    assert np.allclose(result.displacements[:, 0], sigma / E * mesh.vertices[:, 0], atol=1e-12)
    assert np.allclose(result.displacements[:, 1], -nu * sigma / E * mesh.vertices[:, 1], atol=1e-12)
    assert result.equilibrium_error < 1e-9


def test_unsupported_mesh_has_exactly_six_rigid_body_modes():
    mesh = cap(span=4.0, span_to_rise=4.0, rings=3)
    K, _ = shell_stiffness(mesh.vertices, mesh.faces, 0.02, ShellMaterial(E=1e9, nu=0.3))
    values = np.linalg.eigvalsh(K.toarray())
    scale = values.max()
    assert np.sum(np.abs(values) < 1e-9 * scale) == 6
    assert values[6] > 1e-7 * scale
    assert np.abs(K @ rigid_body_modes(mesh.vertices)).max() < 1e-8 * scale


@pytest.mark.parametrize("flags, nodes, expected", [
    (None, None, 6),                       # free body
    ([1, 1, 1, 0, 0, 0], [0], 3),          # one pin: three rotations about it
    ([1, 1, 1, 0, 0, 0], [0, 1], 1),       # two pins: rotation about the line through them
    ([0, 0, 1, 0, 0, 0], "all", 3),        # vertical rollers only: sliding and spinning in plan
])
def test_mechanisms_are_reported_with_their_mode_count(flags, nodes, expected):
    mesh = cap(span=4.0, span_to_rise=4.0, rings=3)
    if flags is None:
        supports = Supports(nodes=np.zeros(0, dtype=int), restraints=np.zeros((0, 6), bool))
    else:
        loop = mesh.boundary_loops[0]
        chosen = loop if nodes == "all" else loop[np.array(nodes) * (len(loop) // 2)]
        supports = Supports.merge([(chosen, np.array(flags, bool))])
    loads = np.zeros((mesh.n_vertices, 6))
    loads[:, 2] = -1.0
    with pytest.raises(MechanismError) as info:
        analyse_shell(mesh, supports, loads, thickness=0.02, material=ShellMaterial(E=1e9, nu=0.3))
    assert info.value.n_modes == expected
    assert "mechanism" in str(info.value)


def test_self_weight_is_carried_to_the_supports():
    mesh = cap(span=6.0, span_to_rise=6.0, rings=5)
    supports = Supports.merge([(mesh.boundary_loops[0], np.array([1, 1, 1, 0, 0, 0], bool))])
    t, density = 0.05, 2400.0
    loads = shell_nodal_loads(mesh, LoadCase(name="g", self_weight=1.0), thickness=t, density=density)
    assert loads[:, 2].sum() == pytest.approx(-mesh.area * t * density * 9.81, rel=1e-12)
    result = analyse_shell(mesh, supports, loads, thickness=t, material=ShellMaterial(E=30e9, nu=0.2))
    assert result.reactions[:, 2].sum() == pytest.approx(mesh.area * t * density * 9.81, rel=1e-9)
    assert result.equilibrium_error < 1e-6
    # a dome under its own weight is in compression
    assert np.median(result.face_principal_forces[:, 1]) < 0
    tangential = np.einsum("ni,ni->n", result.vertex_principal_directions, mesh.vertex_normals)
    assert np.abs(tangential).max() < 1e-9


def _plate_model(n: int = 6) -> dict:
    xs = np.linspace(0.0, 1.0, n + 1)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    edge = np.flatnonzero((np.isclose(x, 0) | np.isclose(x, 1) | np.isclose(y, 0) | np.isclose(y, 1)).ravel())
    return {"nodes": np.c_[x.ravel(), y.ravel(), np.zeros(x.size)].tolist(),
            "triangles": grid_triangles(n, n).tolist(), "thickness": 0.01,
            "material": {"E": 1e7, "nu": 0.3, "density": 0.0},
            "supports": {str(int(i)): [1, 1, 1, 0, 0, 0] for i in edge},
            "loads": {str((n + 1) * (n // 2) + n // 2): [0, 0, -1.0, 0, 0, 0]}}


def test_json_interface_round_trip(tmp_path):
    from workflow.cli import main

    model = _plate_model()
    path = tmp_path / "model.json"
    path.write_text(json.dumps(model))
    assert main(["shell", str(path), "--out", str(tmp_path / "result.json")]) == 0
    result = json.loads((tmp_path / "result.json").read_text())
    assert len(result["displacements"]) == len(model["nodes"])
    assert len(result["membrane_forces"]) == len(model["triangles"])
    assert set(result["reactions"]) == set(model["supports"])
    vertical = sum(r[2] for r in result["reactions"].values())
    assert vertical == pytest.approx(1.0, rel=1e-9)
    direct = solve_shell_json(model)
    assert np.allclose(direct["displacements"], result["displacements"])


@pytest.mark.parametrize("broken, message", [
    (lambda m: m.pop("thickness"), "thickness"),
    (lambda m: m["supports"].update({"999": [1, 1, 1, 1, 1, 1]}), "out of range"),
    (lambda m: m["loads"].update({"0": [1, 2]}), "6 values"),
])
def test_json_errors_name_the_problem(broken, message):
    model = _plate_model()
    broken(model)
    with pytest.raises(InputError, match=message):
        solve_shell_json(model)
