"""Shell solver scaling: assembly and solve time and peak memory at 10k, 50k and 100k triangles,
and the Scordelis-Lo convergence table (error against mesh size).

    .venv/bin/python benchmarks/shell_scaling.py [--sizes 10000 50000 100000] [--no-peer]

Target (issue 3): 100k triangles (about 300k DOF) in under 60 s and 8 GiB on 2 cores, assembly
under a quarter of the total. A peer shell code, OpenSees (ShellDKGT triangles, the same mesh,
supports and nodal loads), is run beside ours in the same process when `openseespy` is importable
on this machine; it is never a dependency of gridshell (its licence forbids redistribution).
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.geometry.parametric import grid_triangles  # noqa: E402
from engine.mesh import TriMesh  # noqa: E402
from engine.structure import shell  # noqa: E402
from engine.structure.loads import LoadCase  # noqa: E402
from engine.structure.shell import ShellMaterial, shell_nodal_loads, shell_stiffness  # noqa: E402
from engine.structure.supports import Supports  # noqa: E402
from tests.shell_models import SCORDELIS_LO_REFERENCE, scordelis_lo  # noqa: E402

THICKNESS = 0.25
MATERIAL = ShellMaterial(E=4.32e8, nu=0.0)


def peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


@dataclass
class Roof:
    """The Scordelis-Lo roof as arrays both codes can take."""

    mesh: TriMesh
    restrained: np.ndarray  # (n, 6) bool
    loads: np.ndarray       # (n, 6) N
    control: int            # midside node of the free edge


def roof(triangles: int) -> Roof:
    """Scordelis-Lo roof (as in tests/shell_models.py) with about ``triangles`` facets."""
    divisions = max(2, int(round(np.sqrt(triangles / 8))))
    radius, length, angle = 25.0, 50.0, np.radians(40.0)
    phi, y = np.meshgrid(np.linspace(-angle, angle, 2 * divisions + 1), np.linspace(0, length, 2 * divisions + 1),
                         indexing="ij")
    mesh = TriMesh(vertices=np.c_[radius * np.sin(phi).ravel(), y.ravel(), radius * np.cos(phi).ravel()],
                   faces=grid_triangles(2 * divisions, 2 * divisions))
    ends = np.flatnonzero((np.isclose(y, 0) | np.isclose(y, length)).ravel())
    middle = np.flatnonzero(np.isclose(y, length / 2).ravel())
    supports = Supports.merge([(ends, np.array([1, 0, 1, 0, 0, 0], bool)),
                               (middle, np.array([0, 1, 0, 0, 0, 0], bool))])
    loads = shell_nodal_loads(mesh, LoadCase(name="w", area_true=[0, 0, -90.0]), thickness=THICKNESS, density=0)
    control = int(np.flatnonzero((np.isclose(phi, angle) & np.isclose(y, length / 2)).ravel())[0])
    return Roof(mesh=mesh, restrained=supports.dof_mask(mesh.n_vertices), loads=loads, control=control)


def ours(model: Roof) -> dict:
    """Assembly, then factor + solve, timed separately."""
    t0 = time.perf_counter()
    K, _ = shell_stiffness(model.mesh.vertices, model.mesh.faces, THICKNESS, MATERIAL)
    t1 = time.perf_counter()
    free = np.flatnonzero(~model.restrained.ravel())
    solve = shell._factor(K[free][:, free].tocsc()).solve
    u = np.zeros(6 * model.mesh.n_vertices)
    u[free] = solve(model.loads.ravel()[free])
    t2 = time.perf_counter()
    return {"assembly_s": t1 - t0, "solve_s": t2 - t1, "total_s": t2 - t0, "deflection": -u[6 * model.control + 2],
            "peak_mib": peak_mib()}


def opensees(model: Roof) -> dict | str:
    """The same roof in OpenSees (ShellDKGT, ElasticMembranePlateSection, UmfPack), or why not."""
    try:
        import openseespy.opensees as ops
    except Exception as exc:  # noqa: BLE001
        return f"not available on this machine ({type(exc).__name__}: {exc})"
    t0 = time.perf_counter()
    ops.wipe()
    ops.model("basic", "-ndm", 3, "-ndf", 6)
    for i, (x, y, z) in enumerate(model.mesh.vertices):
        ops.node(i + 1, float(x), float(y), float(z))
    for i in np.flatnonzero(model.restrained.any(axis=1)):
        ops.fix(int(i) + 1, *[int(f) for f in model.restrained[i]])
    ops.section("ElasticMembranePlateSection", 1, MATERIAL.E, MATERIAL.nu, THICKNESS, 0.0)
    for k, (a, b, c) in enumerate(model.mesh.faces):
        ops.element("ShellDKGT", k + 1, int(a) + 1, int(b) + 1, int(c) + 1, 1)
    ops.timeSeries("Constant", 1)
    ops.pattern("Plain", 1, 1)
    for i in np.flatnonzero(np.any(model.loads != 0, axis=1)):
        ops.load(int(i) + 1, *[float(v) for v in model.loads[i]])
    ops.constraints("Plain")
    ops.numberer("RCM")
    ops.system("UmfPack")
    ops.test("NormUnbalance", 1e-8, 2)
    ops.algorithm("Linear")
    ops.integrator("LoadControl", 1.0)
    ops.analysis("Static")
    t1 = time.perf_counter()
    ops.analyze(1)
    t2 = time.perf_counter()
    deflection = -ops.nodeDisp(model.control + 1, 3)
    ops.wipe()
    return {"build_s": t1 - t0, "solve_s": t2 - t1, "total_s": t2 - t0, "deflection": deflection}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[10_000, 50_000, 100_000])
    parser.add_argument("--no-peer", action="store_true", help="skip OpenSees even where it is installed")
    args = parser.parse_args()
    print("Scordelis-Lo convergence (reference 0.3024, MacNeal & Harder 1985)")
    print(f"{'cells/quarter':>14}{'triangles':>11}{'deflection':>12}{'error %':>9}")
    for divisions in (4, 8, 16, 32, 64):
        deflection, _, mesh = scordelis_lo(divisions)
        print(f"{divisions:>14}{mesh.n_faces:>11}{deflection:>12.5f}"
              f"{100 * (deflection / SCORDELIS_LO_REFERENCE - 1):>9.2f}")
    print()
    print("Scaling, Scordelis-Lo roof refined (deflection: midside of the free edge)")
    print(f"{'triangles':>10}{'DOF':>9}{'assembly s':>12}{'solve s':>9}{'total s':>9}{'assembly %':>11}"
          f"{'peak MiB':>10}{'deflection':>12}")
    models = {}
    for size in args.sizes:
        model = models[size] = roof(size)
        r = ours(model)
        print(f"{model.mesh.n_faces:>10}{6 * model.mesh.n_vertices:>9}{r['assembly_s']:>12.2f}{r['solve_s']:>9.2f}"
              f"{r['total_s']:>9.2f}{100 * r['assembly_s'] / r['total_s']:>11.1f}{r['peak_mib']:>10.0f}"
              f"{r['deflection']:>12.5f}", flush=True)
    print()
    if args.no_peer:
        print("OpenSees: skipped (--no-peer)")
        return 0
    print("Peer: OpenSees ShellDKGT on the same meshes, supports and nodal loads")
    for size, model in models.items():
        r = opensees(model)
        if isinstance(r, str):
            print(f"OpenSees: {r}")
            break
        print(f"{model.mesh.n_faces:>10}{6 * model.mesh.n_vertices:>9}  build {r['build_s']:7.2f} s  solve "
              f"{r['solve_s']:7.2f} s  total {r['total_s']:7.2f} s  deflection {r['deflection']:.5f}  "
              f"peak {peak_mib():.0f} MiB (process)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
