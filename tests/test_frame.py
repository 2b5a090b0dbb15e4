"""Frame elements against closed-form and published answers."""

from __future__ import annotations

import json

import numpy as np
import pytest

from engine.errors import InputError, MechanismError
from engine.structure.frame import FrameModel, linear_buckling, linear_static, nonlinear_static
from engine.structure.solvers import pardiso_available
from engine.structure.supports import Supports
from workflow.solver_json import solve_frame_json

E, G = 2.0e11, 8.0e10
A, IY, IZ, J = 1e-3, 2e-6, 1e-6, 3e-6
FIXED = np.ones(6, bool)
FRAME_LIBRARIES = ["superlu"] + (["pardiso"] if pardiso_available() else [])


def _factor_frames_with(library: str, monkeypatch) -> None:
    """Every frame factor of the test by ``library`` (S of any size)."""
    import engine.structure.solvers as solvers

    monkeypatch.setattr(solvers, "PARDISO_FROM_DOFS", 0 if library == "pardiso" else 10**12)


@pytest.fixture(params=["differences", "closed form"])
def tangent(request, monkeypatch) -> str:
    """The path in numpy, its element tangents by differences; or with the compiled kernels, which
    the frames of these tests are too small to get by default: the tangents in closed form, the
    internal forces, the update of the triads and the internal blocks' elimination."""
    from engine.structure import corotational

    monkeypatch.setattr(corotational, "COMPILED_FROM", 0 if request.param == "closed form" else 2**62)
    return request.param


def _line(direction, length: float, n: int, up, **properties) -> FrameModel:
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    nodes = np.outer(np.linspace(0.0, length, n + 1), d)
    beams = np.c_[np.arange(n), np.arange(1, n + 1)]
    values = dict(E=E, G=G, A=A, Iy=IY, Iz=IZ, J=J)
    values.update(properties)
    return FrameModel(nodes=nodes, beams=beams, up=np.asarray(up, float), **values)


@pytest.mark.parametrize("direction, up", [((1, 0, 0), (0, 0, 1)), ((0, 1, 0), (1, 0, 0)), ((1, 1, 1), (0, 0, 1))])
def test_cantilever_tip_under_force_moment_and_torque(direction, up):
    length, n = 2.0, 6
    model = _line(direction, length, n, up)
    supports = Supports(nodes=np.array([0]), restraints=FIXED[None])
    x = model.nodes[1] - model.nodes[0]
    x /= np.linalg.norm(x)
    z = np.asarray(up, float) - np.dot(up, x) * x
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    P, M, T = 1000.0, 300.0, 200.0
    loads = np.zeros((n + 1, 6))
    loads[-1, :3] = P * z                      # bending about local y (Iy)
    result = linear_static(model, supports, loads)
    tip = result.displacements[-1]
    assert tip[:3] @ z == pytest.approx(P * length**3 / (3 * E * IY), rel=1e-9)
    assert tip[3:] @ y == pytest.approx(-P * length**2 / (2 * E * IY), rel=1e-9)
    loads[:] = 0
    loads[-1, 3:] = M * z                      # moment about local z (Iz)
    tip = linear_static(model, supports, loads).displacements[-1]
    assert tip[:3] @ y == pytest.approx(M * length**2 / (2 * E * IZ), rel=1e-9)
    assert tip[3:] @ z == pytest.approx(M * length / (E * IZ), rel=1e-9)
    loads[:] = 0
    loads[-1, 3:] = T * x
    result = linear_static(model, supports, loads)
    assert result.displacements[-1, 3:] @ x == pytest.approx(T * length / (G * J), rel=1e-9)
    assert result.beam_end_forces[:, :, 3] == pytest.approx(T)
    assert result.equilibrium_error < 1e-9


def test_section_forces_of_a_cantilever():
    length, n, P = 2.0, 4, 500.0
    model = _line((1, 0, 0), length, n, (0, 0, 1))
    loads = np.zeros((n + 1, 6))
    loads[-1, 0] = P          # tension
    loads[-1, 2] = -P         # downward tip load
    result = linear_static(model, Supports(nodes=np.array([0]), restraints=FIXED[None]), loads)
    assert np.allclose(result.beam_end_forces[:, :, 0], P)
    # the hogging moment at the root is P L
    assert abs(result.beam_end_forces[0, 0, 4]) == pytest.approx(P * length)
    assert abs(result.beam_end_forces[-1, 1, 4]) < 1e-9 * P * length
    assert result.reactions[0, 2] == pytest.approx(P)


@pytest.mark.parametrize("ends, factor", [
    (("pinned", "pinned"), 1.0),
    (("fixed", "free"), 0.25),
    (("fixed", "pinned"), 2.0457),   # (4.4934 / pi)^2
    (("fixed", "fixed"), 4.0),
])
def test_euler_buckling_of_columns(ends, factor):
    length, n = 3.0, 16
    model = _line((0, 0, 1), length, n, (1, 0, 0), Iy=1e-6, Iz=1e-6)
    flags = {"pinned": np.array([1, 1, 1, 0, 0, 1], bool), "fixed": FIXED,
             "free": np.zeros(6, bool)}
    bottom, top = flags[ends[0]], flags[ends[1]].copy()
    top[2] = False  # the top carries the load
    supports = Supports.merge([(np.array([0]), bottom), (np.array([n]), top)])
    loads = np.zeros((n + 1, 6))
    loads[n, 2] = -1.0
    result = linear_buckling(model, supports, loads, n_modes=2)
    assert result.factors[0] == pytest.approx(factor * np.pi**2 * E * 1e-6 / length**2, rel=0.01)


@pytest.mark.parametrize("library", FRAME_LIBRARIES)
def test_cantilever_rolls_into_a_circle(library, monkeypatch, tangent):
    """End moment 2 pi EI / L bends a cantilever into a full circle: the tip returns to the root.
    Its tangents are up to 6e-2 from symmetric: where PARDISO factors their symmetric part, the
    steps that do not converge on it are redone on the whole tangent."""
    _factor_frames_with(library, monkeypatch)
    n, length = 32, 1.0
    model = _line((1, 0, 0), length, n, (0, 0, 1), E=1.0, G=1.0, A=1e4, Iy=1.0, Iz=1.0, J=1.0)
    loads = np.zeros((n + 1, 6))
    loads[n, 5] = 2 * np.pi / length
    run = nonlinear_static(model, Supports(nodes=np.array([0]), restraints=FIXED[None]), loads, control=(n, 5),
                           max_load_factor=1.0, max_steps=200)
    assert run.path[-1, 0] == pytest.approx(1.0)
    tip = model.nodes[n] + run.displacements[n, :3]
    assert np.linalg.norm(tip) < 0.01 * length


def test_the_path_stops_at_the_tolerable_deformation_of_a_cantilever_elastica():
    """A cantilever under a tip force stiffens as it bends and has no limit point: the path stops
    where the tip has moved the tolerable deformation. At P L^2 / EI = 1 the large-deflection tip
    moves u/L = 0.05643 along and v/L = 0.30172 across (Mattiasson 1981, Table 1), so a tolerable
    deformation of that translation is reached at the load factor 1."""
    n, length = 16, 2.0
    model = _line((1, 0, 0), length, n, (0, 0, 1), A=1.0)
    loads = np.zeros((n + 1, 6))
    loads[n, 2] = E * IY / length**2
    tolerable = float(np.hypot(0.05643, 0.30172)) * length
    run = nonlinear_static(model, Supports(nodes=np.array([0]), restraints=FIXED[None]), loads, control=(n, 2),
                           max_load_factor=10.0, max_steps=200, max_displacement=tolerable)
    assert run.limit_load_factor is None and run.converged
    assert run.tolerable_load_factor == pytest.approx(1.0, rel=5e-3)
    assert run.path[-1, 0] < 2.0                        # stopped there, not carried on to 10
    free_run = nonlinear_static(model, Supports(nodes=np.array([0]), restraints=FIXED[None]), loads,
                                control=(n, 2), max_load_factor=10.0, max_steps=200)
    assert free_run.tolerable_load_factor is None and free_run.path[-1, 0] == pytest.approx(10.0)


def test_a_dead_load_past_the_tolerable_deformation_leaves_no_load_factor_to_carry():
    """The bound is passed under the held dead load alone: the path stops at once, at load factor 0."""
    n, length = 8, 2.0
    model = _line((1, 0, 0), length, n, (0, 0, 1))
    dead, loads = np.zeros((n + 1, 6)), np.zeros((n + 1, 6))
    dead[n, 2] = loads[n, 2] = -1000.0
    tip = 1000.0 * length**3 / (3 * E * IY)                  # the dead load's tip deflection
    run = nonlinear_static(model, Supports(nodes=np.array([0]), restraints=FIXED[None]), loads, control=(n, 2),
                           initial_loads=dead, max_load_factor=10.0, max_displacement=0.5 * tip)
    assert run.tolerable_load_factor == 0.0 and run.limit_load_factor is None


def _lee_frame(n: int = 10):
    column = np.c_[np.zeros(n + 1), np.zeros(n + 1), np.linspace(0, 120.0, n + 1)]
    beam = np.c_[np.linspace(0, 120.0, n + 1)[1:], np.zeros(n), np.full(n, 120.0)]
    nodes = np.vstack([column, beam])
    beams = np.r_[np.c_[np.arange(n), np.arange(1, n + 1)],
                  np.c_[np.r_[n, np.arange(n + 1, 2 * n)], np.arange(n + 1, 2 * n + 1)]]
    model = FrameModel(nodes=nodes, beams=beams, E=720.0, G=720.0 / 2.6, A=6.0, Iy=2.0, Iz=2.0, J=4.0,
                       up=np.array([0.0, 1.0, 0.0]))
    pin = np.array([1, 1, 1, 1, 0, 1], bool)
    supports = Supports.merge([(np.array([0]), pin), (np.array([2 * n]), pin)])
    loaded = int(np.argmin(np.abs(nodes[:, 0] - 24.0) + np.abs(nodes[:, 2] - 120.0)))
    return model, supports, loaded


def test_lee_frame_limit_load(tangent):
    """Lee's frame (L 120, EI 1440, load 24 from the knee): P_max L^2 / EI = 18.5 (Schweizerhof &
    Wriggers 1986; Battini 2002 finds 18.55)."""
    model, supports, loaded = _lee_frame()
    loads = np.zeros((len(model.nodes), 6))
    loads[loaded, 2] = -1.0
    run = nonlinear_static(model, supports, loads, control=(loaded, 2), max_load_factor=40, max_steps=150)
    assert run.limit_load_factor is not None
    normalised = run.limit_load_factor * 120.0**2 / (720.0 * 2.0)
    assert normalised == pytest.approx(18.5, rel=0.02)
    assert run.path[:, 0].max() == pytest.approx(run.limit_load_factor)
    assert run.path[-1, 0] < run.limit_load_factor, "the path goes past the limit point"


def test_imperfect_column_approaches_the_euler_load():
    length, n = 3.0, 12
    z = np.linspace(0, length, n + 1)
    model = FrameModel(nodes=np.c_[0.001 * length * np.sin(np.pi * z / length), np.zeros(n + 1), z],
                       beams=np.c_[np.arange(n), np.arange(1, n + 1)], E=E, G=G, A=A, Iy=1e-6, Iz=1e-6, J=J,
                       up=np.array([1.0, 0, 0]))
    supports = Supports.merge([(np.array([0]), np.array([1, 1, 1, 0, 0, 1], bool)),
                               (np.array([n]), np.array([1, 1, 0, 0, 0, 0], bool))])
    loads = np.zeros((n + 1, 6))
    loads[n, 2] = -1.0
    euler = np.pi**2 * E * 1e-6 / length**2
    linear = linear_buckling(model, supports, loads, n_modes=1).factors[0]
    run = nonlinear_static(model, supports, loads, control=(n // 2, 0), max_load_factor=1.05 * euler, max_steps=80)
    lateral = np.abs(run.path[:, 1])
    # the lateral deflection grows without bound as the load approaches the buckling load
    near = run.path[:, 0] > 0.97 * linear
    assert near.any() and lateral[near].max() > 0.05 * length
    assert linear == pytest.approx(euler, rel=0.01)


def test_mechanisms_are_reported():
    model = _line((1, 0, 0), 2.0, 4, (0, 0, 1))
    loads = np.zeros((5, 6))
    loads[-1, 2] = -1.0
    with pytest.raises(MechanismError) as info:
        linear_static(model, Supports(nodes=np.array([0]), restraints=np.array([[1, 1, 1, 0, 0, 0]], bool)), loads)
    assert info.value.n_modes == 3
    with pytest.raises(MechanismError) as info:
        linear_static(model, Supports(nodes=np.zeros(0, int), restraints=np.zeros((0, 6), bool)), loads)
    assert info.value.n_modes == 6


def _json_model() -> dict:
    n = 8
    nodes = np.c_[np.linspace(0, 4.0, n + 1), np.zeros(n + 1), 0.5 * np.sin(np.linspace(0, np.pi, n + 1))]
    beams = [{"nodes": [i, i + 1], "E": E, "G": G, "A": A, "Iy": IY, "Iz": IZ, "J": J, "up": [0, 1, 0]}
             for i in range(n)]
    return {"nodes": nodes.tolist(), "beams": beams, "elements_per_beam": 2,
            "supports": {"0": [1, 1, 1, 1, 0, 1], str(n): [1, 1, 1, 1, 0, 1]},
            "loads": {str(n // 2): [0, 0, -1000.0, 0, 0, 0]}}


@pytest.mark.parametrize("analysis", ["linear", "buckling", "nonlinear"])
def test_json_interface(tmp_path, analysis):
    from workflow.cli import main

    path = tmp_path / "model.json"
    path.write_text(json.dumps(_json_model()))
    out = tmp_path / "result.json"
    args = ["frame", str(path), "--analysis", analysis, "--out", str(out), "--modes", "3"]
    if analysis == "nonlinear":
        args += ["--control", "4", "uz", "--max-load-factor", "2000"]
    assert main(args) == 0
    result = json.loads(out.read_text())
    assert len(result["displacements"]) == 9
    assert sum(r[2] for r in result["reactions"].values()) == pytest.approx(1000.0, rel=1e-9)
    if analysis == "buckling":
        assert len(result["buckling_factors"]) == 3 and result["buckling_factors"][0] > 0
    if analysis == "nonlinear":
        assert result["path"][0] == [0.0, 0.0] and len(result["path"]) > 3
        factors = [p[0] for p in result["path"]]
        if result["limit_load_factor"] is not None:
            assert result["limit_load_factor"] == pytest.approx(max(factors))
        else:
            assert max(factors) == pytest.approx(2000.0)


def test_json_errors_name_the_problem():
    model = _json_model()
    del model["beams"][0]["Iy"]
    with pytest.raises(InputError, match="Iy"):
        solve_frame_json(model)
    with pytest.raises(InputError, match="analysis"):
        solve_frame_json(_json_model(), analysis="dynamic")


def test_end_release_makes_a_pin():
    """Both ends fixed, moments released at one: a propped cantilever under a mid-span load,
    deflection 7 P L^3 / (768 EI) under the load."""
    length, n, P = 4.0, 8, 1000.0
    model = _line((1, 0, 0), length, n, (0, 0, 1))
    releases = np.zeros((n, 2, 6), bool)
    releases[-1, 1, 3:] = True          # the last beam's end: no moments, no torsion
    pinned = FrameModel(nodes=model.nodes, beams=model.beams, E=E, G=G, A=A, Iy=IY, Iz=IZ, J=J,
                        up=np.array([0.0, 0, 1]), releases=releases)
    supports = Supports(nodes=np.array([0, n]), restraints=np.ones((2, 6), bool))
    loads = np.zeros((n + 1, 6))
    loads[n // 2, 2] = -P
    result = linear_static(pinned, supports, loads)
    assert -result.displacements[n // 2, 2] == pytest.approx(7 * P * length**3 / (768 * E * IY), rel=1e-9)
    assert abs(result.beam_end_forces[-1, 1, 4]) < 1e-9 * P * length
    assert abs(result.reactions[n, 4]) < 1e-9 * P * length, "the released end carries no moment"
    with pytest.raises(InputError, match="released"):
        FrameModel(nodes=model.nodes, beams=model.beams, E=E, G=G, A=A, Iy=IY, Iz=IZ, J=J,
                   up=np.array([0.0, 0, 1]), releases=np.ones((n, 2, 6), bool))


def test_deep_circular_arch_limit_load(tangent):
    """Clamped-hinged deep circular arch (R 100, opening 215 degrees, EI 1e6, EA 1e8) under an apex
    load: limit load 897 = 8.97 EI / R^2 (DaDeppo & Schmidt 1975, inextensible closed-form
    solution; co-rotational beam results in the literature lie within about 1 % of it)."""
    n, radius = 40, 100.0
    angle = np.linspace(-np.radians(107.5), np.radians(107.5), n + 1)
    nodes = np.c_[radius * np.sin(angle), np.zeros(n + 1), radius * np.cos(angle)]
    model = FrameModel(nodes=nodes, beams=np.c_[np.arange(n), np.arange(1, n + 1)], E=1.0, G=1.0, A=1e8,
                       Iy=1e6, Iz=1e6, J=1e6, up=np.array([0.0, 1.0, 0.0]))
    in_plane = np.array([0, 1, 0, 1, 0, 1], bool)          # a plane problem: uy, rx, rz held
    supports = Supports.merge([(np.array([0]), np.array([1, 1, 1, 1, 0, 1], bool)),
                               (np.array([n]), FIXED), (np.arange(1, n), in_plane)])
    loads = np.zeros((n + 1, 6))
    loads[n // 2, 2] = -1.0
    run = nonlinear_static(model, supports, loads, control=(n // 2, 2), max_load_factor=2000.0, max_steps=150)
    assert run.converged and run.limit_load_factor is not None
    assert run.limit_load_factor == pytest.approx(897.0, rel=0.015)
    assert run.negative_pivots[-1] >= 1, "one negative pivot past a limit point"


def test_elastica_of_a_buckled_cantilever_column(tangent):
    """Post-buckling of a fixed-free column (Euler's elastica): at a tip rotation alpha the load is
    P / P_cr = (2 K(k) / pi)^2 and the tip deflection delta / L = 2 k / K(k), k = sin(alpha / 2),
    P_cr = pi^2 EI / (4 L^2) (Timoshenko & Gere, Theory of Elastic Stability, 2.7: 1.152 at 60 deg)."""
    from scipy.special import ellipk

    length, n = 1.0, 24
    model = _line((0, 0, 1), length, n, (1, 0, 0), E=1.0, G=1.0, A=1e5, Iy=1.0, Iz=1.0, J=1.0)
    critical = np.pi**2 / (4 * length**2)
    loads = np.zeros((n + 1, 6))
    loads[n, 2] = -1.0
    loads[n, 0] = 1e-4                                      # a small lateral imperfection load
    run = nonlinear_static(model, Supports(nodes=np.array([0]), restraints=FIXED[None]), loads,
                           control=(n, 4), max_load_factor=1.3 * critical, max_steps=120, monitor=[(n, 0)])
    alpha = np.radians(60.0)
    rotation = np.abs(run.path[:, 1])
    assert rotation.max() > alpha
    k = np.sin(alpha / 2)
    load = np.interp(alpha, rotation, run.path[:, 0]) / critical
    deflection = np.interp(alpha, rotation, np.abs(run.monitored[:, 0])) / length
    assert load == pytest.approx((2 * ellipk(k**2) / np.pi) ** 2, rel=0.01)
    assert deflection == pytest.approx(2 * k / ellipk(k**2), rel=0.01)


def space_frame_geometry() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(nodes, beams, up vectors) of a one-bay, two-storey 3D frame with a diagonal (no symmetry);
    nodes 0-3 are its feet."""
    plan = np.array([[0.0, 0, 0], [4, 0, 0], [4, 3, 0], [0, 3, 0]])
    nodes = np.vstack([plan, plan + [0, 0, 3.5], plan + [0.2, 0.1, 6.5]])
    beams = [(i, i + 4) for i in range(4)] + [(i + 4, i + 8) for i in range(4)]
    beams += [(4 + i, 4 + (i + 1) % 4) for i in range(4)] + [(8 + i, 8 + (i + 1) % 4) for i in range(4)] + [(0, 5)]
    beams = np.array(beams)
    up = np.where(np.abs(nodes[beams[:, 1], 2] - nodes[beams[:, 0], 2])[:, None] > 1.0, [1.0, 0, 0], [0, 0, 1.0])
    return nodes, beams, up


def _space_frame() -> tuple[FrameModel, Supports, np.ndarray]:
    """The space frame with fixed feet, loads and moments in all directions."""
    nodes, beams, up = space_frame_geometry()
    model = FrameModel(nodes=nodes, beams=beams, E=E, G=G, A=A, Iy=IY, Iz=IZ, J=J, up=up, elements_per_beam=2)
    loads = np.random.default_rng(7).normal(size=(len(nodes), 6)) * [2e3, 2e3, 5e3, 1e3, 1e3, 1e3]
    loads[:4] = 0.0
    return model, Supports(nodes=np.arange(4), restraints=np.ones((4, 6), bool)), loads


def test_reactions_balance_the_loads():
    """Statics: the reactions balance the applied forces and their moments about any point."""
    model, supports, loads = _space_frame()
    result = linear_static(model, supports, loads)
    point = np.array([0.3, -1.0, 2.0])
    arm = model.nodes - point
    total = loads + result.reactions
    assert np.abs(total[:, :3].sum(axis=0)).max() < 1e-9 * np.abs(loads[:, :3]).sum()
    moments = (np.cross(arm, total[:, :3]) + total[:, 3:]).sum(axis=0)
    assert np.abs(moments).max() < 1e-9 * np.abs(loads).sum() * 10
    assert result.equilibrium_error < 1e-10
    assert np.all(result.reactions[4:] == 0.0)


def test_small_loads_follow_the_linear_solution():
    """At a load factor far below buckling the non-linear solution is the linear one."""
    model, supports, loads = _space_frame()
    factor = 1e-3 * linear_buckling(model, supports, loads, n_modes=1).factors[0]
    linear = linear_static(model, supports, loads).displacements * factor
    run = nonlinear_static(model, supports, loads, control=(10, 0), max_load_factor=factor, max_steps=20)
    assert run.path[-1, 0] == pytest.approx(factor)
    assert np.abs(run.displacements - linear).max() < 2e-3 * np.abs(linear).max()


@pytest.mark.parametrize("scale", [1e-6, 1e-8])
def test_a_very_stiff_frame_follows_its_linear_solution_to_the_largest_load_factor(scale):
    """Loads a millionth of the space frame's and less (a 1.5 m model with 114 mm steel tubes moves
    micrometres): the corrector's residual stalls at the coordinates' round-off, which must end its
    iterations, not the path. At 1e-6 of buckling the path is the linear solution."""
    model, supports, loads = _space_frame()
    run = nonlinear_static(model, supports, loads * scale, control=(10, 0), max_load_factor=10.0, max_steps=40)
    linear = linear_static(model, supports, loads * scale * 10.0).displacements
    assert run.converged and run.path[-1, 0] == pytest.approx(10.0)
    assert np.abs(run.displacements - linear).max() < 1e-5 * np.abs(linear).max()


@pytest.mark.parametrize("library", FRAME_LIBRARIES)
def test_a_torsion_release_without_other_restraint_is_a_mechanism(library, monkeypatch):
    """Torsion released at the start of the last beam of a cantilever: its tip can spin freely.
    SuperLU meets a zero pivot; PARDISO perturbs it and counts it."""
    _factor_frames_with(library, monkeypatch)
    model = _line((1, 0, 0), 2.0, 4, (0, 0, 1))
    releases = np.zeros((4, 2, 6), bool)
    releases[-1, 0, 3] = True
    released = FrameModel(nodes=model.nodes, beams=model.beams, E=E, G=G, A=A, Iy=IY, Iz=IZ, J=J,
                          up=np.array([0.0, 0, 1]), releases=releases)
    loads = np.zeros((5, 6))
    loads[-1, 2] = -1.0
    with pytest.raises(MechanismError) as info:
        linear_static(released, Supports(nodes=np.array([0]), restraints=FIXED[None]), loads)
    assert info.value.n_modes == 1


def test_dead_load_held_while_the_reference_load_grows():
    """A column carrying half its Euler load as a dead load buckles when the added load reaches the
    other half (the mock-up's load test: permanent load held, test load increased)."""
    length, n = 3.0, 12
    z = np.linspace(0, length, n + 1)
    model = FrameModel(nodes=np.c_[0.001 * length * np.sin(np.pi * z / length), np.zeros(n + 1), z],
                       beams=np.c_[np.arange(n), np.arange(1, n + 1)], E=E, G=G, A=A, Iy=1e-6, Iz=1e-6, J=J,
                       up=np.array([1.0, 0, 0]))
    supports = Supports.merge([(np.array([0]), np.array([1, 1, 1, 0, 0, 1], bool)),
                               (np.array([n]), np.array([1, 1, 0, 0, 0, 0], bool))])
    euler = np.pi**2 * E * 1e-6 / length**2
    dead, reference = np.zeros((n + 1, 6)), np.zeros((n + 1, 6))
    dead[n, 2] = -0.5 * euler
    reference[n, 2] = -1.0
    run = nonlinear_static(model, supports, reference, initial_loads=dead, control=(n // 2, 0),
                           max_load_factor=0.55 * euler, max_steps=80)
    assert run.path[0, 0] == 0.0 and abs(run.path[0, 1]) > 0, "the dead load deflects before the test load"
    lateral = np.abs(run.path[:, 1])
    assert lateral[run.path[:, 0] < 0.1 * euler].max() < 0.01 * length
    assert lateral[run.path[:, 0] > 0.97 * 0.5 * euler].max() > 0.05 * length


def test_displacements_match_pyfe3d():
    """An independent element code: pyfe3d's BeamC (Timoshenko, made shear-rigid) assembled on the
    same frame gives the same displacements (local axes: y = up x axis in pyfe3d's terms)."""
    pyfe3d = pytest.importorskip("pyfe3d")
    from dataclasses import replace

    import scipy.sparse as sp
    from pyfe3d.beamprop import BeamProp
    from scipy.sparse.linalg import spsolve

    model, supports, loads = _space_frame()
    model = replace(model, elements_per_beam=1)
    ours = linear_static(model, supports, loads).displacements
    prop = BeamProp()
    prop.A, prop.E, prop.G, prop.Iyy, prop.Izz = A, E, G, IY, IZ
    prop.G12 = prop.G13 = 1e6 * G
    prop.GJ = G * J
    n, m = len(model.nodes), len(model.beams)
    rows, cols, values = np.zeros(144 * m, np.int64), np.zeros(144 * m, np.int64), np.zeros(144 * m)
    x = np.ascontiguousarray(model.nodes.ravel())
    probe = pyfe3d.BeamCProbe()
    for k, (a, b) in enumerate(model.beams):
        beam = pyfe3d.BeamC(probe)
        beam.n1, beam.n2, beam.c1, beam.c2, beam.init_k_KC0 = int(a), int(b), 6 * int(a), 6 * int(b), 144 * k
        beam.update_rotation_matrix(*np.cross(model.up[k], model.nodes[b] - model.nodes[a]).tolist(), x)
        beam.update_probe_xe(x)
        beam.update_KC0(rows, cols, values, prop)
    K = sp.coo_matrix((values, (rows, cols)), shape=(6 * n, 6 * n)).tocsc()
    free = ~supports.dof_mask(n).ravel()
    theirs = np.zeros(6 * n)
    theirs[free] = spsolve(K[free][:, free], loads.ravel()[free])
    assert np.allclose(ours, theirs.reshape(n, 6), rtol=0, atol=1e-6 * np.abs(ours).max())


@pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
@pytest.mark.parametrize("library", FRAME_LIBRARIES)
def test_condensed_factor_solves_as_a_plain_lu_and_keeps_the_inertia(library, compiled):
    """The beams' internal nodes condensed out of the factor (engine.structure.condensed), S factored by
    either library, the internal blocks eliminated by numpy or by the compiled kernel: the same
    solution as SuperLU on the assembled matrix, and the same number of negative pivots on an
    indefinite K + sigma K_G (Sylvester's inertia, which the buckling shift and the path's pivot
    count use)."""
    from dataclasses import replace

    import scipy.sparse.linalg as spla

    from engine.linalg import congruent
    from engine.structure import beam_elements, frame
    from engine.structure.condensed import CondensedFactor


    model, supports, loads = _space_frame()
    for k in (1, 2, 4):
        fine = replace(model, elements_per_beam=k)
        state = frame._solve_linear(fine, supports, loads)
        el, free = state.el, state.free
        dofs = beam_elements.element_dofs(el.connectivity)
        K_G = congruent(state.T, beam_elements.geometric_stiffness(state.L, state.local_forces[:, 6], el))
        first = linear_buckling(fine, supports, loads, n_modes=3).factors
        rhs = np.random.default_rng(k).normal(size=(len(free), 2))
        for sigma in (0.0, 0.5 * (first[1] + first[2])):       # positive definite; two factors below sigma
            elements = state.K_elements + sigma * K_G
            factor = CondensedFactor(elements, el.connectivity, len(el.nodes), el.n_original, free, k,
                                     library=library, compiled=compiled)
            assert factor.library == library
            K = beam_elements.assemble(elements, dofs, 6 * len(el.nodes))[free][:, free].tocsc()
            expected = spla.spsolve(K, rhs)
            assert np.abs(factor.solve(rhs) - expected).max() < 1e-9 * np.abs(expected).max()
            assert np.abs(factor.solve(rhs[:, 0]) - expected[:, 0]).max() < 1e-9 * np.abs(expected).max()
            assert factor.negative_pivots == (0 if sigma == 0 else 2)


@pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
def test_condensed_solve_of_a_non_symmetric_tangent_is_the_plain_lu_solve(compiled):
    """A co-rotational tangent is not quite symmetric, so K_ei K_ii^-1 is not (K_ii^-1 K_ie)^T:
    element matrices with a skew part, condensed and solved (one and three right-hand sides; the
    compiled solve carries the internal loads to the ends and back in its own loops) against
    SuperLU on the assembled matrix."""
    from dataclasses import replace

    import scipy.sparse.linalg as spla

    from engine.structure import beam_elements, frame
    from engine.structure.condensed import CondensedFactor

    model, supports, loads = _space_frame()
    fine = replace(model, elements_per_beam=4)
    state = frame._solve_linear(fine, supports, loads)
    el, free = state.el, state.free
    rng = np.random.default_rng(7)
    skew = rng.normal(size=state.K_elements.shape)
    skew = 1e-3 * np.abs(state.K_elements).max() * (skew - skew.transpose(0, 2, 1))
    elements = state.K_elements + skew
    factor = CondensedFactor(elements, el.connectivity, len(el.nodes), el.n_original, free, 4, library="superlu",
                             compiled=compiled)
    K = beam_elements.assemble(elements, beam_elements.element_dofs(el.connectivity), 6 * len(el.nodes))
    K = K[free][:, free].tocsc()
    assert abs(K - K.T).max() > 1e-6 * abs(K).max()                 # the case: not symmetric
    rhs = rng.normal(size=(len(free), 3))
    expected = spla.spsolve(K, rhs)
    assert np.abs(factor.solve(rhs) - expected).max() < 1e-9 * np.abs(expected).max()
    assert np.abs(factor.solve(rhs[:, 1]) - expected[:, 1]).max() < 1e-9 * np.abs(expected).max()


def test_the_compiled_condensation_gives_numpys_block_products():
    """W = K_ii^-1 K_ie, V = K_ei K_ii^-1 and K_ee - K_ei W of random non-symmetric beams of four
    elements, against numpy's products of the blocks written out."""
    from engine.structure.block_inverse import condensation

    rng = np.random.default_rng(5)
    m, g = 7, 18
    inverse, first, last = rng.normal(size=(m, g, g)), rng.normal(size=(m, 12, 12)), rng.normal(size=(m, 12, 12))
    K_ie = np.zeros((m, g, 12))
    K_ie[:, :6, :6], K_ie[:, g - 6:, 6:] = first[:, 6:, :6], last[:, :6, 6:]
    K_ei = np.zeros((m, 12, g))
    K_ei[:, :6, :6], K_ei[:, 6:, g - 6:] = first[:, :6, 6:], last[:, 6:, :6]
    K_ee = np.zeros((m, 12, 12))
    K_ee[:, :6, :6], K_ee[:, 6:, 6:] = first[:, :6, :6], last[:, 6:, 6:]
    W, V, condensed = condensation(inverse, first, last)
    assert np.allclose(W, inverse @ K_ie, rtol=1e-12, atol=1e-12)
    assert np.allclose(V, K_ei @ inverse, rtol=1e-12, atol=1e-12)
    assert np.allclose(condensed, K_ee - K_ei @ inverse @ K_ie, rtol=1e-12, atol=1e-11)


def test_the_compiled_block_elimination_gives_numpys_inverses_and_pivots():
    """Block-tridiagonal blocks of 6 x 6 (three internal nodes, as a beam of four elements):
    positive definite, indefinite and non-symmetric ones against numpy's inverse and the
    vectorised elimination's pivots; a block whose first pivot is zero but which is regular is
    inverted with row exchanges; a singular one is not finite."""
    from engine.structure.block_inverse import inverse_and_pivots
    from engine.structure.condensed import _block_pivots

    rng = np.random.default_rng(2)
    m, g = 40, 18
    blocks = np.zeros((m, g, g))
    for t in range(2):
        coupling = rng.normal(size=(m, 6, 6))
        blocks[:, 6 * t:6 * t + 6, 6 * t + 6:6 * t + 12] = coupling
        blocks[:, 6 * t + 6:6 * t + 12, 6 * t:6 * t + 6] = np.transpose(coupling, (0, 2, 1))
    for t in range(3):
        a = rng.normal(size=(m, 6, 6))
        blocks[:, 6 * t:6 * t + 6, 6 * t:6 * t + 6] = a @ np.transpose(a, (0, 2, 1)) + 8 * np.eye(6)
    blocks[10:20] -= 9 * np.eye(g)                          # indefinite
    blocks[20:30, 0, 1] += 0.7                              # not symmetric
    blocks[30] = np.eye(g)[[1, 0, *range(2, g)]]            # a permutation: first pivot zero
    blocks[31, 5] = blocks[31, :, 5] = 0.0                  # singular: a node's DOF held by nothing
    inverse, pivots = inverse_and_pivots(blocks)
    regular = np.r_[0:30, 32:m]
    expected = np.linalg.inv(blocks[regular])
    assert np.abs(inverse[regular] - expected).max() < 1e-12 * np.abs(expected).max()
    assert np.array_equal(np.sign(pivots[regular]), np.sign(_block_pivots(blocks[regular])))
    reference = _block_pivots(blocks[regular])                 # (rounded in another order: 2e-12)
    assert np.abs(pivots[regular] - reference).max() < 1e-10 * np.abs(reference).max()
    assert (pivots[10:20] < 0).any() and not (pivots[:10] < 0).any()
    assert np.array_equal(inverse[30], blocks[30].T) and pivots[30, 0] == 0
    assert not np.all(np.isfinite(inverse[31]))


def test_a_kept_fill_ordering_gives_the_factor_of_a_fresh_one():
    """The ordering found at a path's first factorisation and given to the next ones (of other
    values on the same pattern): the same solutions and the same negative pivots as a factor
    that orders its matrix afresh, on a positive definite and an indefinite K + sigma K_G."""
    from dataclasses import replace

    from engine.linalg import congruent
    from engine.structure import beam_elements, frame
    from engine.structure.condensed import CondensedFactor, FillOrdering

    model, supports, loads = _space_frame()
    fine = replace(model, elements_per_beam=3)
    state = frame._solve_linear(fine, supports, loads)
    el, free = state.el, state.free
    K_G = congruent(state.T, beam_elements.geometric_stiffness(state.L, state.local_forces[:, 6], el))
    first = linear_buckling(fine, supports, loads, n_modes=3).factors
    rhs = np.random.default_rng(3).normal(size=(len(free), 3))
    kept = FillOrdering()
    for sigma in (0.0, 0.5 * (first[1] + first[2]), 0.5 * first[0]):
        elements = state.K_elements + sigma * K_G
        args = (elements, el.connectivity, len(el.nodes), el.n_original, free, 3)
        fresh, reordered = CondensedFactor(*args), CondensedFactor(*args, ordering=kept)
        expected = fresh.solve(rhs)
        assert np.abs(reordered.solve(rhs) - expected).max() < 1e-10 * np.abs(expected).max()
        assert np.abs(reordered.solve(rhs[:, 1]) - expected[:, 1]).max() < 1e-10 * np.abs(expected).max()
        assert reordered.negative_pivots == fresh.negative_pivots == {0.0: 0, 0.5 * first[0]: 0}.get(sigma, 2)


def test_rotation_matrices_and_vectors_match_scipy():
    """Rodrigues and its log map against scipy's Rotation, from 1e-13 rad (the first-order branch)
    to 3 rad."""
    from scipy.spatial.transform import Rotation

    from engine.structure.corotational import _rotation_matrices, _rotation_vectors

    rng = np.random.default_rng(3)
    axes = rng.normal(size=(600, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    vectors = axes * np.geomspace(1e-13, 3.0, 600)[:, None]
    R = _rotation_matrices(vectors)
    assert np.abs(R - Rotation.from_rotvec(vectors).as_matrix()).max() < 1e-14
    assert np.abs(_rotation_vectors(R) - vectors).max() < 1e-12


@pytest.mark.parametrize("scheme", ["difference_tangent", "closed_form_tangent"])
def test_the_corotational_tangent_is_the_derivative_of_the_end_forces(scheme):
    """The element tangent (forward differences, end a's translation columns taken as minus end
    b's; or in closed form) against central differences of the end forces in every direction, at
    a deformed state of a frame with a released beam end."""
    from dataclasses import replace

    from engine.structure.corotational import _Corotational, _rotation_matrices

    model, supports, _ = _space_frame()
    releases = np.zeros((len(model.beams), 2, 6), bool)
    releases[3, 1, 4:] = True
    model = replace(model, releases=releases)
    cr = _Corotational(model, supports)
    rng = np.random.default_rng(5)
    x = cr.X + 0.02 * rng.normal(size=cr.X.shape)
    triads = _rotation_matrices(0.2 * rng.normal(size=(cr.n_all, 3)))
    _, state = cr.internal_forces(x, triads)
    K = getattr(cr, scheme)(state)
    xa, xb, Ra, Rb = state
    h = 1e-6
    for column in range(12):
        end, component = divmod(column, 6)
        pair = {+1: None, -1: None}
        for sign in pair:
            x_pair, r_pair = [xa.copy(), xb.copy()], [Ra, Rb]
            if component < 3:
                x_pair[end][component] += sign * h * cr.L0
            else:
                spin = _rotation_matrices(sign * h * np.eye(3)[component - 3:component - 2])[0]
                r_pair[end] = np.einsum("ij,jkm->ikm", spin, r_pair[end])
            pair[sign] = cr._end_forces(x_pair[0], x_pair[1], r_pair[0], r_pair[1])
        step = h * cr.L0 if component < 3 else h
        central = (pair[1] - pair[-1]) / (2 * step)
        scale = np.abs(K).max(axis=(1, 2))
        assert np.all(np.abs(K[:, :, column].T - central).max(axis=0) < 1e-5 * scale), column


def test_the_closed_form_tangent_falls_back_where_the_mean_z_runs_along_the_chord():
    """An element whose nodal z axes both lie along its chord has its frame from local_axes, not
    from the mean z: its tangent is the differences', the others' the closed form's."""
    from engine.structure.corotational import _Corotational

    model, supports, _ = _space_frame()
    cr = _Corotational(model, supports)
    _, state = cr.internal_forces(cr.X, np.tile(np.eye(3), (cr.n_all, 1, 1)))
    xa, xb, Ra, Rb = (a.copy() for a in state)
    e1 = (xb[:, 0] - xa[:, 0]) / np.linalg.norm(xb[:, 0] - xa[:, 0])
    u = np.cross(e1, [0.0, 0.0, 1.0] if abs(e1[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    along = np.c_[u, np.cross(e1, u), e1]                  # a rotation whose z is the chord
    Ra[:, :, 0] = Rb[:, :, 0] = along
    state = (xa, xb, Ra, Rb)
    closed, differences = cr.closed_form_tangent(state), cr.difference_tangent(state)
    assert np.array_equal(closed[0], differences[0])
    scale = np.abs(differences).max(axis=(1, 2))
    assert np.all(np.abs(closed - differences).max(axis=(1, 2)) < 1e-5 * scale)


@pytest.mark.parametrize("spin_rad", [1e-7, 0.2, 2.5])
def test_the_compiled_internal_forces_are_numpys(monkeypatch, spin_rad):
    """The compiled element states and end forces against the numpy kernels they stand in for, at
    deformed states of a frame with a released beam end (nodal spins from 1e-7 rad, where arccos
    of the trace loses digits, to 2.5 rad); an element whose mean z runs along its chord is
    flagged and left to numpy's frame."""
    from dataclasses import replace

    from engine.structure import corotational
    from engine.structure.corotational import _Corotational, _rotation_matrices
    from engine.structure.corotational_kernels import element_forces

    model, supports, _ = _space_frame()
    releases = np.zeros((len(model.beams), 2, 6), bool)
    releases[3, 1, 4:] = True
    cr = _Corotational(replace(model, releases=releases), supports)
    rng = np.random.default_rng(7)
    x = cr.X + 0.02 * rng.normal(size=cr.X.shape)
    triads = _rotation_matrices(spin_rad * rng.normal(size=(cr.n_all, 3)))
    monkeypatch.setattr(corotational, "COMPILED_FROM", 2**62)
    expected, numpy_state = cr.internal_forces(x, triads)
    monkeypatch.setattr(corotational, "COMPILED_FROM", 0)
    forces, state = cr.internal_forces(x, triads)
    for ours, theirs in zip(state, numpy_state):
        assert np.array_equal(ours, theirs)
    assert np.abs(forces - expected).max() < 1e-12 * np.abs(expected).max()

    xa, xb, Ra, Rb = (a.copy() for a in state)
    e1 = (xb[:, 0] - xa[:, 0]) / np.linalg.norm(xb[:, 0] - xa[:, 0])
    u = np.cross(e1, [0.0, 0.0, 1.0] if abs(e1[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    Ra[:, :, 0] = Rb[:, :, 0] = np.c_[u, np.cross(e1, u), e1]  # both nodal z along the chord
    f, bad = element_forces(xa, xb, Ra, Rb, cr.L0, cr.K7)
    assert bad.tolist() == [True] + [False] * (len(bad) - 1) and not f[:, 0].any()
    reference = cr._end_forces(xa, xb, Ra, Rb)
    assert np.abs(f[:, 1:] - reference[:, 1:]).max() < 1e-12 * np.abs(reference).max()


def test_the_compiled_update_turns_the_triads_as_rodrigues(monkeypatch):
    """A path's update of the nodes, compiled, against Rodrigues' matrices times the triads, from
    no spin (the first-order branch) to 3 rad."""
    from engine.structure import corotational

    rng = np.random.default_rng(11)
    x = rng.normal(size=(200, 3))
    triads = corotational._rotation_matrices(rng.normal(size=(200, 3)))
    du = rng.normal(size=(200, 6)) * np.geomspace(1e-14, 3.0, 200)[:, None]
    du[:5] = 0.0
    monkeypatch.setattr(corotational, "COMPILED_FROM", 0)
    moved, turned = corotational._update(x, triads, du.ravel())
    assert np.array_equal(moved, x + du[:, :3])
    expected = np.einsum("kij,kjl->kil", corotational._rotation_matrices(du[:, 3:]), triads)
    assert np.abs(turned - expected).max() < 1e-15 * 8


def test_buckling_factors_match_a_dense_eigensolver():
    """All requested factors of the shifted sparse Lanczos against scipy's dense symmetric solver
    on the same K and K_G (mixed tension and compression, 3 elements per beam)."""
    _against_the_dense_eigensolver()


def _against_the_dense_eigensolver() -> None:
    model, supports, loads = _space_frame_of_three_elements()
    ours = linear_buckling(model, supports, loads, n_modes=6).factors
    _, minus_KG, K = _free_stiffnesses(model, supports, loads)
    mu = _dense_mu(minus_KG, K)
    dense = np.sort(1.0 / mu[mu > 1e-12 * np.abs(mu).max()])[:6]
    assert len(ours) == 6
    assert ours == pytest.approx(dense, rel=1e-8)


def _space_frame_of_three_elements():
    from dataclasses import replace

    model, supports, loads = _space_frame()
    return replace(model, elements_per_beam=3), supports, loads


def _free_stiffnesses(model, supports, loads):
    """(the linear state, -K_G, K) on the free DOFs (CSR), K_G from the linear axial forces."""
    from engine.linalg import congruent
    from engine.structure import beam_elements, frame

    state = frame._solve_linear(model, supports, loads)
    el, free = state.el, state.free
    K_G_elements = congruent(state.T, beam_elements.geometric_stiffness(state.L, state.local_forces[:, 6], el))
    K_G = beam_elements.assemble(K_G_elements, beam_elements.element_dofs(el.connectivity), len(state.u))
    return state, (-K_G[free][:, free]).tocsr(), state.K[free][:, free].tocsr()


def _dense_mu(minus_KG, K) -> np.ndarray:
    """Every mu of -K_G phi = mu K phi, by scipy's dense symmetric solver."""
    import scipy.linalg as sla

    return sla.eigh(minus_KG.toarray(), K.toarray(), eigvals_only=True)


def test_buckling_with_a_rough_estimate_above_the_first_factor_still_finds_every_factor(monkeypatch):
    """A rough first factor that is far too high (twice lambda_1) puts the shift above lambda_1:
    the shifted factor's negative pivots say so, the shift is halved until there are none, and
    the factors are those of the dense solver all the same."""
    from engine.structure import frame

    rough, halvings = frame._rough_first_factor, []
    monkeypatch.setattr(frame, "_rough_first_factor", lambda *a: 0.5 * rough(*a))
    factor = frame.factor_or_none

    def counted(*args, **kwargs):
        shifted = factor(*args, **kwargs)
        halvings.append(shifted.negative_pivots)
        return shifted

    monkeypatch.setattr(frame, "factor_or_none", counted)
    _against_the_dense_eigensolver()
    assert halvings[0] > 0 and halvings[-1] == 0, "the first shift lay above lambda_1 and was halved"


def test_rough_first_factor_lies_just_above_the_first_factor():
    """The few Lanczos steps' estimate is a Ritz value, so 1 / mu is never below the dense
    lambda_1, and it stops within the 1/0.95 that the shift needs (the loads and their opposites,
    mixed tension and compression, 3 elements per beam)."""
    from engine.structure import frame

    model, supports, loads = _space_frame_of_three_elements()
    for sign in (1.0, -1.0):
        state, minus_KG, K = _free_stiffnesses(model, supports, sign * loads)
        mu = _dense_mu(minus_KG, K).max()
        start = np.random.default_rng(0).standard_normal(K.shape[0])
        estimate = frame._rough_first_factor(minus_KG, K, state.lu.solve, start)
        assert estimate <= mu * (1 + 1e-9)
        assert estimate >= 0.95 * mu


def test_two_bar_toggle_snaps_through_at_its_closed_form_limit(tangent):
    """The pin-jointed two-bar toggle (von Mises truss), bars pinned at both ends, apex load: with
    the bar force N = EA (l - L0) / L0 of the co-rotational element, equilibrium of the apex is
    P(w) = -2 N(w) (h - w) / l(w), l = sqrt(b^2 + (h - w)^2); its maximum is the limit load."""
    from scipy.optimize import minimize_scalar

    b, h, EA = 1.0, 0.1, 1e4
    nodes = np.array([[-b, 0.0, 0.0], [0.0, 0.0, h], [b, 0.0, 0.0]])
    releases = np.zeros((2, 2, 6), bool)
    releases[:, :, 4:] = True                                   # no bending moment at either end
    model = FrameModel(nodes=nodes, beams=np.array([[0, 1], [1, 2]]), E=EA, G=EA, A=1.0, Iy=1e-2, Iz=1e-2,
                       J=1e-2, up=np.array([0.0, 1.0, 0.0]), releases=releases)
    apex = np.array([0, 1, 0, 1, 1, 1], bool)                   # in the plane; the apex's spin held
    supports = Supports.merge([(np.array([0, 2]), FIXED), (np.array([1]), apex)])
    loads = np.zeros((3, 6))
    loads[1, 2] = -1.0
    run = nonlinear_static(model, supports, loads, control=(1, 2), max_load_factor=1e4, max_steps=100)
    L0 = np.hypot(b, h)

    def load(w):
        length = np.hypot(b, h - w)
        return -2 * EA * (length - L0) / L0 * (h - w) / length

    peak = -minimize_scalar(lambda w: -load(w), bounds=(0.0, h), method="bounded", options={"xatol": 1e-12}).fun
    assert run.converged and run.limit_load_factor is not None
    assert run.limit_load_factor == pytest.approx(peak, rel=1e-3)
    # every converged point of the path lies on the closed-form curve
    assert run.path[:, 0] == pytest.approx(load(-run.path[:, 1]), rel=1e-5, abs=1e-9 * peak)   # residual < 1e-5
    assert run.negative_pivots[-1] == 1, "one negative pivot past the limit point"


def test_nonlinear_solution_is_in_equilibrium(tangent):
    """The converged large-displacement state balances the applied loads: the co-rotational
    internal forces of the returned displacements and rotations equal lambda F on the free DOFs
    to 1e-6 of |lambda F| (path tolerance 1e-8)."""
    from dataclasses import replace

    from engine.structure import corotational

    model, supports, loads = _space_frame()
    model = replace(model, elements_per_beam=1)              # every node's state is returned
    factor = 0.3 * linear_buckling(model, supports, loads, n_modes=1).factors[0]
    run = nonlinear_static(model, supports, loads, control=(10, 0), max_load_factor=factor, max_steps=40,
                           tolerance=1e-8)
    assert run.path[-1, 0] == pytest.approx(factor)
    cr = corotational._Corotational(model, supports)
    x = cr.X + run.displacements[:, :3]
    triads = corotational._rotation_matrices(run.displacements[:, 3:])
    internal, _ = cr.internal_forces(x, triads)
    applied = factor * loads.ravel()
    residual = (applied - internal)[cr.free]
    assert np.linalg.norm(residual) < 1e-6 * np.linalg.norm(applied[cr.free])


def test_a_frame_in_tension_has_no_buckling_factor():
    """A column pulled at its top: K_G stiffens every mode (all mu = 1/lambda negative), so no
    positive factor is returned; pushed, the same column buckles at pi^2 EI / (4 L^2)."""
    length, n = 3.0, 8
    model = _line((0, 0, 1), length, n, (1, 0, 0), Iy=1e-6, Iz=1e-6)
    supports = Supports(nodes=np.array([0]), restraints=FIXED[None])
    loads = np.zeros((n + 1, 6))
    loads[n, 2] = 1.0
    assert len(linear_buckling(model, supports, loads, n_modes=3).factors) == 0
    result = linear_buckling(model, supports, -loads, n_modes=1)
    assert result.factors[0] == pytest.approx(np.pi**2 * E * 1e-6 / (4 * length**2), rel=1e-3)


def test_the_kept_factor_follows_the_model_and_its_supports():
    """The last factored stiffness is reused only for the same model and supports: a stiffer
    copy deflects half as much, a propped copy as a propped cantilever (P L^3 / (3 EI) and
    7 P L^3 / (768 EI) under the mid-span load of test_end_release_makes_a_pin)."""
    from dataclasses import replace

    length, n, P = 2.0, 4, 500.0
    model = _line((1, 0, 0), length, n, (0, 0, 1))
    fixed = Supports(nodes=np.array([0]), restraints=FIXED[None])
    loads = np.zeros((n + 1, 6))
    loads[-1, 2] = -P
    tip = -linear_static(model, fixed, loads).displacements[-1, 2]
    assert tip == pytest.approx(P * length**3 / (3 * E * IY), rel=1e-9)
    stiffer = replace(model, E=np.full(n, 2 * E))
    assert -linear_static(stiffer, fixed, loads).displacements[-1, 2] == pytest.approx(tip / 2, rel=1e-9)
    assert -linear_static(model, fixed, loads).displacements[-1, 2] == pytest.approx(tip, rel=1e-12)
    propped = Supports(nodes=np.array([0, n]), restraints=np.array([FIXED, [1, 1, 1, 0, 0, 0]], bool))
    mid = np.zeros((n + 1, 6))
    mid[n // 2, 2] = -P
    deflection = -linear_static(model, propped, mid).displacements[n // 2, 2]
    assert deflection == pytest.approx(7 * P * length**3 / (768 * E * IY), rel=1e-9)


def _extensible_elastica_toggle(half_span: float, rise: float, EA: float, EI: float):
    """Apex load P(w) of a symmetric clamped toggle from the extensible elastica of one member.

    The member runs from the clamped support (0, 0) to the apex (b, h); by symmetry the apex moves
    straight down by w and does not rotate. Along the undeformed arc length s, with the constant
    end force F = (Fx, Fz) on the member at the apex and the moment m_A at the support:
    EI theta' = m_A - (x Fz - z Fx), (x', z') = (1 + N / EA)(cos theta, sin theta),
    N = Fx cos theta + Fz sin theta. Shooting on (Fx, Fz, m_A) meets x = b, z = h - w and
    theta = theta_0 at the apex; P = -2 Fz. An exact solution of the Euler-Bernoulli rod problem
    by a method that shares nothing with the co-rotational elements."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import fsolve

    angle, length = np.arctan2(rise, half_span), np.hypot(half_span, rise)

    def apex(unknowns):
        fx, fz, moment = unknowns

        def rod(s, y):
            x, z, theta = y
            stretch = 1.0 + (fx * np.cos(theta) + fz * np.sin(theta)) / EA
            return [stretch * np.cos(theta), stretch * np.sin(theta), (moment - (x * fz - z * fx)) / EI]

        return solve_ivp(rod, (0.0, length), [0.0, 0.0, angle], method="DOP853", rtol=1e-11, atol=1e-13).y[:, -1]

    state = {"guess": np.zeros(3)}

    def load(w: float) -> float:
        def mismatch(unknowns):
            x, z, theta = apex(unknowns)
            return [x - half_span, z - (rise - w), (theta - angle) * length]

        state["guess"] = fsolve(mismatch, state["guess"], xtol=1e-13)
        return -2.0 * state["guess"][1]

    return load


def test_williams_toggle_limit_load():
    """Williams' toggle (Williams 1964): two members of half span 12.943 in and rise 0.386 in,
    clamped at both supports and rigidly joined at the apex, E 10.3e6 psi, A 0.18 in^2,
    I 0.0009 in^4, apex load. Reference: the limit load of the extensible elastica of the same
    frame (shooting, _extensible_elastica_toggle), about 33.6 lbf at an apex deflection near
    0.23 in; the co-rotational beams converge to it under mesh refinement."""
    from scipy.optimize import minimize_scalar

    half_span, rise, E_psi, A_in2, I_in4 = 12.943, 0.386, 10.3e6, 0.18, 0.0009
    load = _extensible_elastica_toggle(half_span, rise, E_psi * A_in2, E_psi * I_in4)
    coarse = [(w, load(w)) for w in np.linspace(0.02, 0.36, 18)]
    k = int(np.argmax([p for _, p in coarse]))
    assert 0 < k < len(coarse) - 1, "the elastica has a limit point inside the traced range"
    load(coarse[k - 1][0])
    peak = minimize_scalar(lambda w: -load(w), bounds=(coarse[k - 1][0], coarse[k + 1][0]), method="bounded",
                           options={"xatol": 1e-7})
    reference = -peak.fun

    def frame_limit(n: int) -> tuple[float, np.ndarray]:
        t = np.linspace(0.0, 1.0, n + 1)
        nodes = np.vstack([np.c_[half_span * t, np.zeros(n + 1), rise * t],
                           np.c_[half_span * (1 + t[1:]), np.zeros(n), rise * (1 - t[1:])]])
        model = FrameModel(nodes=nodes, beams=np.c_[np.arange(2 * n), np.arange(1, 2 * n + 1)], E=E_psi,
                           G=E_psi / 2.6, A=A_in2, Iy=I_in4, Iz=I_in4, J=2 * I_in4, up=np.array([0.0, 1.0, 0.0]))
        in_plane = np.array([0, 1, 0, 1, 0, 1], bool)
        supports = Supports.merge([(np.array([0, 2 * n]), FIXED), (np.arange(1, 2 * n), in_plane)])
        loads = np.zeros((2 * n + 1, 6))
        loads[n, 2] = -1.0
        run = nonlinear_static(model, supports, loads, control=(n, 2), max_load_factor=200.0, max_steps=150)
        assert run.converged and run.limit_load_factor is not None
        return run.limit_load_factor, run.negative_pivots

    coarse_limit, _ = frame_limit(8)
    fine_limit, pivots = frame_limit(16)
    assert fine_limit == pytest.approx(reference, rel=0.01)
    assert abs(fine_limit - reference) < 0.5 * abs(coarse_limit - reference), "converges under refinement"
    assert pivots[-1] == 1, "one negative pivot past the limit point"


#: Levy & Spillers, Analysis of Geometrically Nonlinear Structures (2nd ed., 2003), section 2.4.2:
#: the 24-member star dome (space truss), coordinates in inches, supports pinned at the outer ring.
STAR_DOME_NODES = np.array([
    [0.0, 0.0, 3.2346],
    [4.92125, 8.5239, 2.4472], [-4.92125, 8.5239, 2.4472], [-9.8425, 0.0, 2.4472],
    [-4.92125, -8.5239, 2.4472], [4.92125, -8.5239, 2.4472], [9.8425, 0.0, 2.4472],
    [0.0, 19.685, 0.0], [-17.0472, 9.8425, 0.0], [-17.0472, -9.8425, 0.0],
    [0.0, -19.685, 0.0], [17.0472, -9.8425, 0.0], [17.0472, 9.8425, 0.0]])
STAR_DOME_MEMBERS = np.array([
    [0, 1], [0, 2], [0, 3], [0, 4], [0, 5], [0, 6], [5, 11], [6, 11], [6, 12], [1, 12], [1, 7], [2, 7],
    [2, 8], [3, 8], [3, 9], [4, 9], [4, 10], [5, 10], [1, 2], [2, 3], [3, 4], [4, 5], [5, 6], [6, 1]])


def _star_dome_symmetric_limit(E_psi: float, A_in2: float) -> float:
    """Limit load of the star dome's symmetric path from a reduced model: crown down by w, the six
    ring nodes out by u and down by v, bar forces N = EA (l - L) / L as in the co-rotational
    element; for each w the ring is in equilibrium (two equations) and P(w) is the crown's
    generalised force; the maximum of P over w is found by bounded scalar search."""
    from scipy.optimize import fsolve, minimize_scalar

    ring = np.arange(1, 7)
    radial = STAR_DOME_NODES[ring, :2] / np.linalg.norm(STAR_DOME_NODES[ring, :2], axis=1)[:, None]
    rest = np.linalg.norm(STAR_DOME_NODES[STAR_DOME_MEMBERS[:, 1]] - STAR_DOME_NODES[STAR_DOME_MEMBERS[:, 0]], axis=1)

    def forces(w, u, v):
        x = STAR_DOME_NODES.copy()
        x[0, 2] -= w
        x[ring, :2] += u * radial
        x[ring, 2] -= v
        d = x[STAR_DOME_MEMBERS[:, 1]] - x[STAR_DOME_MEMBERS[:, 0]]
        length = np.linalg.norm(d, axis=1)
        pull = (E_psi * A_in2 * (length - rest) / rest / length)[:, None] * d
        nodal = np.zeros_like(x)
        np.add.at(nodal, STAR_DOME_MEMBERS[:, 0], pull)
        np.add.at(nodal, STAR_DOME_MEMBERS[:, 1], -pull)
        # the bars' forces on the nodes, as generalised forces of (w, u, v): the crown's balances P,
        # the ring's (no load there) vanish
        return np.array([nodal[0, 2], np.einsum("ij,ij->", nodal[ring, :2], radial), nodal[ring, 2].sum()])

    state = {"ring": np.zeros(2)}

    def crown_load(w: float) -> float:
        state["ring"] = fsolve(lambda uv: forces(w, *uv)[1:], state["ring"], xtol=1e-9)
        return forces(w, *state["ring"])[0]

    ws = np.linspace(0.01, 0.6, 60)
    loads = [crown_load(w) for w in ws]
    k = int(np.argmax(loads))
    state["ring"] = np.zeros(2)
    for w in ws[:k]:
        crown_load(w)
    peak = minimize_scalar(lambda w: -crown_load(w), bounds=(ws[k - 1], ws[k + 1]), method="bounded",
                           options={"xatol": 1e-8})
    return -peak.fun


def test_star_dome_linear_deflection_and_limit_load():
    """The 24-member star dome (a shallow space truss; Levy & Spillers 2003, section 2.4.2), E 30e6 psi,
    A 0.0155 in^2, crown load 220.46 lbf: published linear crown deflection 0.20641184 in; the
    non-linear path meets its limit point at the maximum of the symmetric path of a reduced
    three-unknown model of the same bars (about 0.666 of that load, well below 1, as the book says).
    The bars are beams with both bending moments and one end's torsion released, every node's
    rotations held."""
    E_psi, A_in2, P = 30e6, 0.0155, 220.46
    n_members = len(STAR_DOME_MEMBERS)
    releases = np.zeros((n_members, 2, 6), bool)
    releases[:, :, 4:] = True
    releases[:, 1, 3] = True
    model = FrameModel(nodes=STAR_DOME_NODES, beams=STAR_DOME_MEMBERS, E=E_psi, G=E_psi / 2.6, A=A_in2,
                       Iy=1e-4, Iz=1e-4, J=1e-4, up=np.array([0.0, 0.0, 1.0]), releases=releases)
    rotations = np.array([0, 0, 0, 1, 1, 1], bool)
    supports = Supports.merge([(np.arange(7, 13), FIXED), (np.arange(0, 7), rotations)])
    loads = np.zeros((13, 6))
    loads[0, 2] = -P
    linear = linear_static(model, supports, loads)
    assert linear.displacements[0, 2] == pytest.approx(-0.20641184, rel=1e-5)
    run = nonlinear_static(model, supports, loads, control=(0, 2), max_load_factor=5.0, max_steps=200)
    assert run.converged and run.limit_load_factor is not None
    assert run.limit_load_factor * P == pytest.approx(_star_dome_symmetric_limit(E_psi, A_in2), rel=1e-3)
    assert run.limit_load_factor < 0.7
    assert run.negative_pivots[-1] == 1, "a limit point: one negative pivot past it"


def test_protocol_paths_side_by_side_give_the_paths_one_after_another():
    """The protocol on Lee's frame with its non-linear paths in a two-process pool: the perfect
    limit load is the published one (18.5 EI / L^2), and every imperfect path has the same name,
    order, limit and path as when the paths run one after another in this process."""
    from concurrent.futures import ProcessPoolExecutor

    from engine.structure.protocol import ProtocolSettings, run_protocol

    model, supports, loaded = _lee_frame()
    loads = np.zeros((len(model.nodes), 6))
    loads[loaded, 2] = -1.0
    settings = ProtocolSettings(n_modes=3, amplitude=0.5, max_load_factor=5.0, max_steps=150)
    alone = run_protocol(model, supports, loads, loads, settings)
    with ProcessPoolExecutor(max_workers=2) as pool:
        pooled = run_protocol(model, supports, loads, loads, settings, executor=pool)
    assert alone.perfect.limit_load_factor * 120.0**2 / (720.0 * 2.0) == pytest.approx(18.5, rel=0.02)
    assert [c.name for c in pooled.imperfect] == [c.name for c in alone.imperfect]
    assert len(alone.imperfect) == 10
    for a, b in zip(alone.imperfect, pooled.imperfect):
        assert a.limit_load_factor == b.limit_load_factor
        np.testing.assert_array_equal(a.path, b.path)
    assert pooled.perfect.limit_load_factor == alone.perfect.limit_load_factor


def _deep_arch():
    n, radius = 40, 100.0
    angle = np.linspace(-np.radians(107.5), np.radians(107.5), n + 1)
    nodes = np.c_[radius * np.sin(angle), np.zeros(n + 1), radius * np.cos(angle)]
    model = FrameModel(nodes=nodes, beams=np.c_[np.arange(n), np.arange(1, n + 1)], E=1.0, G=1.0, A=1e8,
                       Iy=1e6, Iz=1e6, J=1e6, up=np.array([0.0, 1.0, 0.0]))
    supports = Supports.merge([(np.array([0]), np.array([1, 1, 1, 1, 0, 1], bool)), (np.array([n]), FIXED),
                               (np.arange(1, n), np.array([0, 1, 0, 1, 0, 1], bool))])
    loads = np.zeros((n + 1, 6))
    loads[n // 2, 2] = -1.0
    return model, supports, loads, (n // 2, 2), 2000.0, 897.0, 0.015


def _star_dome():
    E_psi, A_in2, P = 30e6, 0.0155, 220.46
    releases = np.zeros((len(STAR_DOME_MEMBERS), 2, 6), bool)
    releases[:, :, 4:] = True
    releases[:, 1, 3] = True
    model = FrameModel(nodes=STAR_DOME_NODES, beams=STAR_DOME_MEMBERS, E=E_psi, G=E_psi / 2.6, A=A_in2,
                       Iy=1e-4, Iz=1e-4, J=1e-4, up=np.array([0.0, 0.0, 1.0]), releases=releases)
    supports = Supports.merge([(np.arange(7, 13), FIXED), (np.arange(0, 7), np.array([0, 0, 0, 1, 1, 1], bool))])
    loads = np.zeros((13, 6))
    loads[0, 2] = -P
    return model, supports, loads, (0, 2), 5.0, _star_dome_symmetric_limit(E_psi, A_in2) / P, 1e-3


def _lee():
    model, supports, loaded = _lee_frame()
    loads = np.zeros((len(model.nodes), 6))
    loads[loaded, 2] = -1.0
    return model, supports, loads, (loaded, 2), 40.0, 18.5 * 720.0 * 2.0 / 120.0**2, 0.02


@pytest.mark.parametrize("problem", [_star_dome, _lee, _deep_arch], ids=["star dome", "Lee frame", "deep arch"])
def test_a_reused_factor_finds_the_published_limit_with_no_more_factorisations(problem):
    """The corrector on a reused factor (modified Newton, the default) and on a factor at every
    iteration (full Newton) meet the same published limit load (star dome: the reduced model's;
    Lee's frame 18.5 EI / L^2; the deep arch 8.97 EI / R^2) and agree with each other within the
    path's limit tolerance (each lands within it below the peak); the reuse factors less often,
    on the shallow star dome about half as often. Where the reused factor does not contract (Lee's
    frame, the deep arch) the corrector is full Newton again, and the factor of its last iteration
    starts the next step."""
    from engine.structure.corotational import PathSettings

    model, supports, loads, control, largest, published, rel = problem()
    runs = {reuse: nonlinear_static(model, supports, loads, control=control, settings=PathSettings(
        max_load_factor=largest, max_steps=200, reuse_factor=reuse)) for reuse in (True, False)}
    for run in runs.values():
        assert run.converged and run.limit_load_factor == pytest.approx(published, rel=rel)
    assert runs[True].limit_load_factor == pytest.approx(runs[False].limit_load_factor,
                                                         rel=PathSettings().limit_tolerance)
    assert runs[True].factorisations < runs[False].factorisations
    if problem is _star_dome:
        assert runs[True].factorisations < 0.6 * runs[False].factorisations


def test_the_compiled_turn_to_global_axes_is_the_full_congruence():
    """T^T K T by the sixteen 3 x 3 blocks of the compiled kernel against the batched product of
    the full block-diagonal T, on random frames and random non-symmetric matrices."""
    from engine.linalg import congruent
    from engine.structure.beam_elements import transformation
    from engine.structure.element_kernels import to_global

    rng = np.random.default_rng(3)
    R = np.linalg.qr(rng.normal(size=(50, 3, 3)))[0]
    K = rng.normal(size=(50, 12, 12))
    expected = congruent(transformation(R), K)
    assert np.abs(to_global(R, K) - expected).max() < 1e-13 * np.abs(expected).max()
