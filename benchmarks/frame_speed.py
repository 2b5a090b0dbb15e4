"""Frame solver speed on a 5000-node grid-shell: assembly, linear static, 10 buckling modes, a
50-step non-linear path, peak memory.

    .venv/bin/python benchmarks/frame_speed.py [--nodes 5000] [--elements-per-beam 4] [--steps 50]

The grid-shell is a honeycomb (valence-3, Voronoi-like) grid of equal beams lifted onto a
spherical cap (span 40 m, span/rise 7), pinned along its boundary, steel tubes 168.3 x 8 mm,
under its self-weight plus 1 kN/m2 lumped on the nodes. Target (task brief): linear static plus
10 modes under 10 s on 2 cores; issue 16: linear static plus 10 modes under 1.5 s, the non-linear
path under 10 s. Peers, where installed (neither is a dependency of the project):
OpenSees (openseespy) on the same element mesh and PyNite with one member per beam (optionally on
a smaller model of the same kind, --pynite-nodes) print their linear-static time and largest
deflection beside ours; OpenSees's co-rotational arc-length path on a smaller model
(--path-nodes) prints its time and largest load factor beside our path's. OpenSees has no
linear buckling analysis, so no peer prints buckling factors.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engine.structure import beam_elements  # noqa: E402
from engine.structure import frame as frame_module  # noqa: E402
from engine.structure.corotational import PathSettings  # noqa: E402
from engine.structure.frame import FrameModel  # noqa: E402
from engine.structure.supports import Supports  # noqa: E402

STEEL_E, STEEL_G, STEEL_DENSITY, GRAVITY = 210e9, 81e9, 7850.0, 9.81


def honeycomb_cap(nodes: int, span: float = 40.0, span_to_rise: float = 7.0):
    """(points (n,3), beams (b,2), boundary (n,) bool): a honeycomb of about ``nodes`` nodes and
    beams of equal plan length on a disc of diameter ``span``, lifted onto a spherical cap."""
    radius = span / 2
    side = np.sqrt(np.pi * radius**2 / (nodes * 3 * np.sqrt(3) / 4))
    count = int(np.ceil(radius / side)) + 2
    i, j = np.meshgrid(np.arange(-2 * count, 2 * count + 1), np.arange(-count, count + 1), indexing="ij")
    i, j = i.ravel(), j.ravel()
    even = (i + j) % 2 == 0
    plan = np.c_[i * np.sqrt(3) / 2 * side, j * 1.5 * side + np.where(even, 0.25, -0.25) * side]
    index = {(a, b): k for k, (a, b) in enumerate(zip(i.tolist(), j.tolist()))}
    edges = [(index[a, b], index[a + 1, b]) for a, b in zip(i.tolist(), j.tolist()) if (a + 1, b) in index]
    edges += [(index[a, b], index[a, b + 1]) for a, b, e in zip(i.tolist(), j.tolist(), even)
              if e and (a, b + 1) in index]
    edges = np.array(edges)
    keep = np.linalg.norm(plan, axis=1) <= radius
    edges = edges[keep[edges].all(axis=1)]
    while True:  # drop dangling nodes
        degree = np.bincount(edges.ravel(), minlength=len(plan))
        dangling = degree == 1
        if not dangling.any():
            break
        edges = edges[~dangling[edges].any(axis=1)]
    used = np.unique(edges)
    renumber = np.full(len(plan), -1)
    renumber[used] = np.arange(len(used))
    plan, edges = plan[used], renumber[edges]
    degree = np.bincount(edges.ravel(), minlength=len(plan))
    rise = span / span_to_rise
    sphere = (radius**2 + rise**2) / (2 * rise)
    z = np.sqrt(sphere**2 - (plan**2).sum(axis=1)) - (sphere - rise)
    boundary = (degree < 3) & (np.linalg.norm(plan, axis=1) > radius - 2 * side)
    return np.c_[plan, z], edges, boundary, sphere


def model(nodes: int, elements_per_beam: int):
    points, beams, boundary, sphere = honeycomb_cap(nodes)
    diameter, wall = 0.1683, 0.008
    area = np.pi / 4 * (diameter**2 - (diameter - 2 * wall) ** 2)
    inertia = np.pi / 64 * (diameter**4 - (diameter - 2 * wall) ** 4)
    centre = np.array([0.0, 0.0, points[:, 2].max() - sphere])
    middle = points[beams].mean(axis=1)
    normals = (middle - centre) / np.linalg.norm(middle - centre, axis=1)[:, None]
    frame = FrameModel(nodes=points, beams=beams, E=STEEL_E, G=STEEL_G, A=area, Iy=inertia, Iz=inertia,
                       J=2 * inertia, up=normals, elements_per_beam=elements_per_beam)
    supported = np.flatnonzero(boundary)
    supports = Supports(nodes=supported, restraints=np.tile([1, 1, 1, 0, 0, 0], (len(supported), 1)).astype(bool))
    lengths = np.linalg.norm(points[beams[:, 1]] - points[beams[:, 0]], axis=1)
    loads = np.zeros((len(points), 6))
    weight = STEEL_DENSITY * area * lengths * GRAVITY / 2
    np.add.at(loads[:, 2], beams[:, 0], -weight)
    np.add.at(loads[:, 2], beams[:, 1], -weight)
    plan_area_per_node = np.pi * 20.0**2 / len(points)
    loads[:, 2] -= 1e3 * plan_area_per_node
    return frame, supports, loads


def _assembly_seconds(frame: FrameModel) -> float:
    """Element kernels (local stiffness, transformation) and the sparse global stiffness, ours."""
    from engine.linalg import congruent

    b = beam_elements
    start = time.perf_counter()
    el = b.element_mesh(frame)
    lengths, rotations = b.element_geometry(el, el.nodes)
    T = b.transformation(rotations)
    b.assemble(congruent(T, b.local_stiffness(lengths, el)), b.element_dofs(el.connectivity), 6 * len(el.nodes))
    return time.perf_counter() - start


def _pyfe3d_seconds(frame: FrameModel) -> str:
    """The same global stiffness from pyfe3d's BeamC (one Python object per element, Cython
    kernels writing COO triplets), the peer kernel we did not adopt (no co-rotational beam)."""
    try:
        from pyfe3d import BeamC, BeamCData, BeamCProbe
        from pyfe3d.beamprop import BeamProp
    except ImportError:
        return "pyfe3d: not importable"
    import scipy.sparse as sp

    el = beam_elements.element_mesh(frame)
    start = time.perf_counter()
    prop = BeamProp()
    prop.A, prop.E, prop.G = float(el.A[0]), float(el.E[0]), float(el.G[0])
    prop.Iyy, prop.Izz, prop.J = float(el.Iy[0]), float(el.Iz[0]), float(el.J[0])
    prop.G12 = prop.G13 = 1e6 * prop.G        # shear-rigid Timoshenko: Euler-Bernoulli as ours
    prop.GJ = prop.G * prop.J
    m, size = len(el.connectivity), BeamCData().KC0_SPARSE_SIZE
    rows, cols, values = np.zeros(size * m, dtype=np.int64), np.zeros(size * m, dtype=np.int64), np.zeros(size * m)
    x = np.ascontiguousarray(el.nodes.ravel())
    probe = BeamCProbe()
    for k, (a, b) in enumerate(el.connectivity):
        beam = BeamC(probe)
        beam.n1, beam.n2, beam.c1, beam.c2 = int(a), int(b), 6 * int(a), 6 * int(b)
        beam.init_k_KC0 = size * k
        y_axis = np.cross(el.up[k], el.nodes[b] - el.nodes[a])   # pyfe3d takes a vector in the local xy plane
        beam.update_rotation_matrix(*map(float, y_axis), x)
        beam.update_probe_xe(x)
        beam.update_KC0(rows, cols, values, prop)
    sp.coo_matrix((values, (rows, cols)), shape=(6 * len(el.nodes),) * 2).tocsc()
    return f"pyfe3d BeamC loop, same stiffness: {time.perf_counter() - start:.2f} s"


def _ours(frame: FrameModel, supports: Supports, loads: np.ndarray, modes: int = 0):
    """(linear seconds, largest |u_z|, buckling seconds, first factors) of our solver, the
    stiffness factored once for both (as the protocol does)."""
    start = time.perf_counter()
    stiffness = frame_module.factor_stiffness(frame, supports)
    linear = frame_module.linear_static(frame, supports, loads, stiffness=stiffness)
    t_linear = time.perf_counter() - start
    factors, t_buckling = None, None
    if modes:
        start = time.perf_counter()
        factors = frame_module.linear_buckling(frame, supports, loads, n_modes=modes, stiffness=stiffness).factors
        t_buckling = time.perf_counter() - start
    return t_linear, float(np.abs(linear.displacements[:, 2]).max()), t_buckling, factors


def _pynite(frame: FrameModel, supports: Supports, loads: np.ndarray):
    """PyNite (MIT, ``pip install PyNiteFEA``; a benchmark peer only, never imported by the
    product): the same beams as one member each (exact for nodal loads), linear static with its
    sparse solver. Returns (seconds, largest |u_z|) or a sentence why not."""
    try:
        from Pynite import FEModel3D  # type: ignore
    except ImportError:
        return "not installed (pip install PyNiteFEA to compare)"
    start = time.perf_counter()
    fe = FEModel3D()
    fe.add_material("steel", float(frame.E[0]), float(frame.G[0]), 0.3, STEEL_DENSITY)
    fe.add_section("tube", float(frame.A[0]), float(frame.Iy[0]), float(frame.Iz[0]), float(frame.J[0]))
    for k, p in enumerate(frame.nodes):
        fe.add_node(f"N{k}", *map(float, p))
    for k, (a, b) in enumerate(frame.beams):
        fe.add_member(f"M{k}", f"N{a}", f"N{b}", "steel", "tube")
    for node, flags in zip(supports.nodes, supports.restraints):
        fe.def_support(f"N{node}", *map(bool, flags))
    for k in np.flatnonzero(loads[:, 2]):
        fe.add_node_load(f"N{k}", "FZ", float(loads[k, 2]))
    fe.analyze_linear(log=False, check_stability=False, check_statics=False, sparse=True)
    seconds = time.perf_counter() - start
    largest = max(abs(node.DZ["Combo 1"]) for node in fe.nodes.values())
    return seconds, largest


def _opensees_model(ops, frame: FrameModel, supports: Supports, loads: np.ndarray, transformation: str) -> None:
    """Our element mesh in OpenSees (the beams' internal nodes included): elasticBeamColumn
    elements with the given geometric transformation, local x-z plane through our ``up`` vector,
    the vertical nodal loads in a linear pattern, UmfPack."""
    el = beam_elements.element_mesh(frame)
    ops.wipe()
    ops.model("basic", "-ndm", 3, "-ndf", 6)
    for k, p in enumerate(el.nodes):
        ops.node(k, *map(float, p))
    for node, flags in zip(supports.nodes, supports.restraints):
        ops.fix(int(node), *map(int, flags))
    for k, ((a, b), up) in enumerate(zip(el.connectivity, el.up)):
        ops.geomTransf(transformation, k + 1, *map(float, up))
        ops.element("elasticBeamColumn", k + 1, int(a), int(b), float(el.A[k]), float(el.E[k]), float(el.G[k]),
                    float(el.J[k]), float(el.Iy[k]), float(el.Iz[k]), k + 1)
    ops.timeSeries("Linear", 1)
    ops.pattern("Plain", 1, 1)
    for k in np.flatnonzero(loads[:, 2]):
        ops.load(int(k), 0.0, 0.0, float(loads[k, 2]), 0.0, 0.0, 0.0)
    ops.constraints("Plain")
    ops.numberer("RCM")
    ops.system("UmfPack")


def _opensees(frame: FrameModel, supports: Supports, loads: np.ndarray):
    """OpenSees (openseespy; its licence forbids redistribution, so it is never a dependency:
    imported here only when this machine has it): elasticBeamColumn elements on the same
    element mesh as ours (the beams' internal nodes included), local x-z plane through our
    ``up`` vector, UmfPack sparse solver. Returns (seconds, largest |u_z|) or a sentence why not."""
    try:
        import openseespy.opensees as ops  # type: ignore
    except Exception:  # ImportError, or its shared libraries missing
        return "not installed (openseespy, with libblas3 and liblapack3, to compare on this machine)"
    start = time.perf_counter()
    _opensees_model(ops, frame, supports, loads, "Linear")
    ops.algorithm("Linear")
    ops.integrator("LoadControl", 1.0)
    ops.analysis("Static")
    if ops.analyze(1) != 0:
        return "the analysis failed"
    seconds = time.perf_counter() - start
    largest = max(abs(ops.nodeDisp(k, 3)) for k in range(frame.nodes.shape[0]))
    ops.wipe()
    return seconds, largest


def _opensees_path(frame: FrameModel, supports: Supports, loads: np.ndarray, control: int, arc: float):
    """OpenSees's co-rotational path on the same element mesh: Corotational transformation,
    Newton with its ArcLength integrator (arc ``arc``, displacements only), until the load factor
    falls. Returns (seconds, largest load factor, steps) or a sentence why not."""
    try:
        import openseespy.opensees as ops  # type: ignore
    except Exception:
        return "not installed"
    start = time.perf_counter()
    _opensees_model(ops, frame, supports, loads, "Corotational")
    ops.test("NormUnbalance", 1e-6 * float(np.abs(loads).sum()), 30, 0)
    ops.algorithm("Newton")
    ops.integrator("ArcLength", float(arc), 0.0)
    ops.analysis("Static")
    factors = [0.0]
    for _ in range(200):
        if ops.analyze(1) != 0:
            break
        factors.append(ops.getLoadFactor(1))
        if len(factors) > 3 and factors[-1] < factors[-2]:
            break
    seconds = time.perf_counter() - start
    ops.wipe()
    return seconds, max(factors), len(factors) - 1


def _peer_lines(frame: FrameModel, supports: Supports, loads: np.ndarray, nodes: int, elements_per_beam: int,
                pynite_nodes: int, path_nodes: int) -> list[str]:
    """Each peer's linear static beside ours on the same model (PyNite on a smaller model of the
    same kind when the full one is too large for it)."""
    lines = []
    t_ours, u_ours, _, _ = _ours(frame, supports, loads)
    result = _opensees(frame, supports, loads)
    if isinstance(result, str):
        lines.append(f"OpenSees           {result}")
    else:
        lines.append(f"OpenSees linear     {result[0]:7.2f} s   largest deflection {result[1] * 1e3:.4f} mm "
                     f"(ours {t_ours:.2f} s, {u_ours * 1e3:.4f} mm; difference {abs(result[1] / u_ours - 1):.1e})")
    small = (frame, supports, loads) if pynite_nodes >= nodes else model(pynite_nodes, elements_per_beam)
    label = "same model" if pynite_nodes >= nodes else f"{len(small[0].nodes)}-node model of the same kind"
    t_small, u_small, _, _ = _ours(*small)
    result = _pynite(*small)
    if isinstance(result, str):
        lines.append(f"PyNite             {result}")
    else:
        lines.append(f"PyNite linear       {result[0]:7.2f} s   largest deflection {result[1] * 1e3:.4f} mm on the "
                     f"{label} (ours {t_small:.2f} s, {u_small * 1e3:.4f} mm; "
                     f"difference {abs(result[1] / u_small - 1):.1e})")
    if path_nodes:
        # a model small enough for OpenSees's path, whose first critical point is a limit point
        # (ours: one pivot turns negative at the maximum; on larger domes of this kind pivots turn
        # negative while the load still rises: bifurcations, where the two paths part ways)
        small = model(path_nodes, elements_per_beam)
        linear = frame_module.linear_static(*small)
        control = int(np.argmax(np.abs(linear.displacements[:, 2])))
        start = time.perf_counter()
        run = frame_module.nonlinear_static(*small, control=(control, 2), max_load_factor=1e9, max_steps=50)
        t_path = time.perf_counter() - start
        result = _opensees_path(*small, control, 20 * float(np.abs(linear.displacements).max()))
        if isinstance(result, str):
            lines.append(f"OpenSees path      {result}")
        else:
            lines.append(f"OpenSees path      {result[0]:7.2f} s   largest load factor {result[1]:.4f} "
                         f"in {result[2]} steps on the {len(small[0].nodes)}-node model "
                         f"(Corotational, ArcLength; ours {t_path:.2f} s, limit "
                         f"{run.limit_load_factor:.4f} in {len(run.path) - 1} steps; difference "
                         f"{abs(result[1] / run.limit_load_factor - 1):.1e})")
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, default=5000)
    parser.add_argument("--elements-per-beam", type=int, default=4)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--pynite-nodes", type=int, default=None,
                        help="PyNite's model size, when the full model is too slow for it (default: the same model)")
    parser.add_argument("--path-nodes", type=int, default=300,
                        help="model size for the non-linear path beside OpenSees's (0: none)")
    parser.add_argument("--no-peers", action="store_true")
    parser.add_argument("--full-newton", action="store_true",
                        help="also follow the path with a factor at every corrector iteration, for comparison")
    parser.add_argument("--limit-tolerances", metavar="T,...",
                        help="also follow the path with these limit tolerances (0: the first maximum always "
                             "refined), for comparison with the default")
    parser.add_argument("--superlu", action="store_true",
                        help="also run linear static, buckling and the path with SuperLU for every factor "
                             "(the library below engine.structure.solvers.PARDISO_FROM_DOFS), for comparison")
    parser.add_argument("--difference-tangent", action="store_true",
                        help="also follow the path with the element tangents by differences (the scheme before "
                             "2026-12-05), for comparison")
    parser.add_argument("--tangents", metavar="NODES,...",
                        help="only time the element tangents, in closed form and by differences, on these model "
                             "sizes, and the closed form's one-off cost in a fresh process")
    args = parser.parse_args()
    if args.tangents:
        for line in _tangent_lines([int(n) for n in args.tangents.split(",")], args.elements_per_beam):
            print(line)
        return 0
    frame, supports, loads = model(args.nodes, args.elements_per_beam)
    n_all = len(frame.nodes) + len(frame.beams) * (args.elements_per_beam - 1)
    print(f"honeycomb grid-shell: {len(frame.nodes)} nodes, {len(frame.beams)} beams, {args.elements_per_beam} "
          f"elements per beam, {6 * n_all} DOF, {len(supports.nodes)} pinned supports")
    print(f"assembly           {_assembly_seconds(frame):7.2f} s   (element kernels + sparse stiffness); "
          f"{_pyfe3d_seconds(frame)}")
    from engine.structure.solvers import factor_symmetric, pardiso_available

    if pardiso_available():  # MKL loads once per process (about a second): not in the first analysis's time
        import scipy.sparse as sp

        start = time.perf_counter()
        factor_symmetric(sp.identity(3, format="csr"), library="pardiso")
        print(f"MKL loaded         {time.perf_counter() - start:7.2f} s")
    # the compiled kernels (numba) load once per process too, and a gridshell run has loaded them
    # before its analysis (the remesher): a small frame's analyses load them, not in the times below
    start = time.perf_counter()
    small, small_supports, small_loads = model(60, args.elements_per_beam)
    sag = frame_module.linear_static(small, small_supports, small_loads).displacements[:, 2]
    frame_module.linear_buckling(small, small_supports, small_loads, n_modes=2)
    frame_module.nonlinear_static(small, small_supports, small_loads, control=(int(np.argmax(np.abs(sag))), 2),
                                  settings=PathSettings(max_load_factor=1e9, max_steps=2))
    print(f"compiled kernels loaded {time.perf_counter() - start:5.2f} s   (a 60-node frame's analyses)")
    for label, limit in [("", None)] + ([("SuperLU: ", 10**12)] if args.superlu else []):
        if limit is not None:
            import engine.structure.solvers

            engine.structure.solvers.PARDISO_FROM_DOFS = limit
        _analyses(frame, supports, loads, args, label)
    print(f"peak memory        {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:7.0f} MiB")
    if not args.no_peers:
        pynite_nodes = args.nodes if args.pynite_nodes is None else args.pynite_nodes
        for line in _peer_lines(frame, supports, loads, args.nodes, args.elements_per_beam, pynite_nodes,
                                args.path_nodes):
            print(line)
    return 0


def _analyses(frame, supports, loads, args, label: str) -> None:
    """Linear static, 10 buckling modes and the path(s), timed; ``label`` starts the first line."""
    from engine.structure.solvers import library_for

    print(f"{label}the beam ends' matrix factored by {library_for(6 * len(frame.nodes))} (engine.structure.solvers)")
    start = time.perf_counter()
    stiffness = frame_module.factor_stiffness(frame, supports)
    linear = frame_module.linear_static(frame, supports, loads, stiffness=stiffness)
    t_linear = time.perf_counter() - start
    start = time.perf_counter()
    buckling = frame_module.linear_buckling(frame, supports, loads, n_modes=10, stiffness=stiffness)
    t_buckling = time.perf_counter() - start
    print(f"linear static      {t_linear:7.2f} s   equilibrium error {linear.equilibrium_error:.1e}, "
          f"largest deflection {np.abs(linear.displacements[:, 2]).max() * 1e3:.1f} mm")
    print(f"10 buckling modes  {t_buckling:7.2f} s   lambda_1..3 = {np.round(buckling.factors[:3], 3).tolist()}")
    print(f"linear + 10 modes  {t_linear + t_buckling:7.2f} s   (target < 1.5 s, issue 16; was 10 s)")
    control = int(np.argmax(np.abs(linear.displacements[:, 2])))
    # the path with the corrector reusing its factor (the default), then with a factor at every
    # iteration (full Newton, the scheme before 2026-12-03) as the reference in the same run
    default = PathSettings(max_load_factor=1e9, max_steps=args.steps)
    schemes = [("non-linear path", default)]
    if args.full_newton:
        schemes.append(("  full Newton", dataclasses.replace(default, reuse_factor=False)))
    if args.difference_tangent:
        schemes.append(("  by differences", default))
    for tolerance in (float(t) for t in (args.limit_tolerances or "").split(",") if t):
        schemes.append((f"  limit tol. {tolerance:g}", dataclasses.replace(default, limit_tolerance=tolerance)))
    from engine.structure import corotational

    closed_form_from = corotational.COMPILED_FROM
    for label, settings in schemes if args.steps > 0 else []:
        corotational.COMPILED_FROM = 2**62 if label == "  by differences" else closed_form_from
        start = time.perf_counter()
        run = frame_module.nonlinear_static(frame, supports, loads, control=(control, 2), settings=settings)
        t_nonlinear = time.perf_counter() - start
        limit = None if run.limit_load_factor is None else round(run.limit_load_factor, 6)
        negative = np.flatnonzero(run.negative_pivots > 0)
        pivots = (f"first negative pivot at load factor {run.path[negative[0], 0]:.3f}" if len(negative)
                  else "no negative pivot")
        print(f"{label:<18} {t_nonlinear:7.2f} s   {len(run.path) - 1} steps ({int(run.iterations.sum())} "
              f"iterations, {run.factorisations} factorisations), largest load factor {run.path[:, 0].max():.3f}, "
              f"limit {limit}, {pivots}, converged {run.converged}")


def _tangent_lines(sizes: list[int], elements_per_beam: int) -> list[str]:
    """The element tangents at a deformed state (random translations of 10 mm and spins of 0.3
    rad), by differences and in closed form, best of 3 each, with their largest difference
    against the largest entry of each element's matrix; and the closed form's cost on its first
    call in a fresh process (importing numba and loading the compiled kernel)."""
    import subprocess

    from engine.structure.corotational import COMPILED_FROM, _Corotational, _rotation_matrices

    code = ("import time, numpy as np; from engine.structure import corotational as c; "
            "t = time.perf_counter(); from engine.structure.corotational_kernels import element_tangents; "
            "e = np.eye(3)[:, :, None]; element_tangents(np.zeros((3, 1)), np.ones((3, 1)), e, e, np.ones(1), "
            "np.zeros((1, 12, 7))); print(time.perf_counter() - t)")
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                           env={**os.environ, "PYTHONPATH": str(ROOT)}) for _ in range(2)]
    lines = [f"closed form, first call in a fresh process (numba's import, the kernel loaded): "
             f"{float(runs[1].stdout):.2f} s (the first run: {float(runs[0].stdout):.2f} s, compiled if not cached); "
             f"used from {COMPILED_FROM} elements on"]
    for nodes in sizes:
        frame, supports, _ = model(nodes, elements_per_beam)
        cr = _Corotational(frame, supports)
        rng = np.random.default_rng(0)
        x = cr.X + 0.01 * rng.standard_normal(cr.X.shape)
        _, state = cr.internal_forces(x, _rotation_matrices(0.3 * rng.standard_normal((cr.n_all, 3))))
        seconds = {}
        for name in ("difference_tangent", "closed_form_tangent"):
            times = []
            for _ in range(3):
                start = time.perf_counter()
                getattr(cr, name)(state)
                times.append(time.perf_counter() - start)
            seconds[name] = min(times)
        differences, closed = cr.difference_tangent(state), cr.closed_form_tangent(state)
        error = float((np.abs(closed - differences).max(axis=(1, 2)) / np.abs(differences).max(axis=(1, 2))).max())
        lines.append(f"{nodes:6d} nodes, {len(cr.L0):6d} elements: by differences "
                     f"{seconds['difference_tangent']:.4f} s, closed form {seconds['closed_form_tangent']:.4f} s, "
                     f"largest difference {error:.1e} of the element's largest entry")
    return lines


if __name__ == "__main__":
    raise SystemExit(main())
