"""Shell solver scaling: assembly and solve time and peak memory at 10k, 50k and 100k triangles,
and the Scordelis-Lo convergence table (error against mesh size).

    .venv/bin/python benchmarks/shell_scaling.py [--sizes 10000 50000 100000]

Target (issue 3): 100k triangles (about 300k DOF) in under 60 s and 8 GiB on 2 cores, assembly
under a quarter of the total. A peer shell code (OpenSees) is printed beside ours when
`openseespy` is importable on this machine; it is never a dependency.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.loads import LoadCase  # noqa: E402
from engine.shell import ShellMaterial, shell_nodal_loads, shell_stiffness  # noqa: E402
from engine.supports import Supports  # noqa: E402
from tests.shell_models import SCORDELIS_LO_REFERENCE, scordelis_lo  # noqa: E402


def peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def timed_roof(triangles: int) -> dict:
    """Scordelis-Lo roof with about ``triangles`` facets: assembly, factor+solve, answer."""
    import scipy.sparse.linalg as spla

    from engine import shell

    divisions = max(2, int(round(np.sqrt(triangles / 8))))
    start = time.perf_counter()
    # build the model the same way as tests/shell_models.py, timing the phases separately
    radius, length, angle = 25.0, 50.0, np.radians(40.0)
    phi, y = np.meshgrid(np.linspace(-angle, angle, 2 * divisions + 1), np.linspace(0, length, 2 * divisions + 1),
                         indexing="ij")
    from engine.mesh import TriMesh
    from engine.parametric import grid_triangles

    mesh = TriMesh(vertices=np.c_[radius * np.sin(phi).ravel(), y.ravel(), radius * np.cos(phi).ravel()],
                   faces=grid_triangles(2 * divisions, 2 * divisions))
    ends = np.flatnonzero((np.isclose(y, 0) | np.isclose(y, length)).ravel())
    middle = np.flatnonzero(np.isclose(y, length / 2).ravel())
    supports = Supports.merge([(ends, np.array([1, 0, 1, 0, 0, 0], bool)), (middle, np.array([0, 1, 0, 0, 0, 0], bool))])
    loads = shell_nodal_loads(mesh, LoadCase(name="w", area_true=[0, 0, -90.0]), thickness=0.25, density=0)
    t0 = time.perf_counter()
    K, _ = shell_stiffness(mesh.vertices, mesh.faces, 0.25, ShellMaterial(E=4.32e8, nu=0.0))
    t1 = time.perf_counter()
    restrained = supports.dof_mask(mesh.n_vertices).ravel()
    free = np.flatnonzero(~restrained)
    solve = shell._factor(K[free][:, free].tocsc())
    u = np.zeros(6 * mesh.n_vertices)
    u[free] = solve(loads.ravel()[free])
    t2 = time.perf_counter()
    node = np.flatnonzero((np.isclose(phi, angle) & np.isclose(y, length / 2)).ravel())[0]
    del spla
    return {"triangles": mesh.n_faces, "dof": 6 * mesh.n_vertices, "mesh_s": t0 - start, "assembly_s": t1 - t0,
            "solve_s": t2 - t1, "total_s": t2 - start, "deflection": -u[6 * node + 2], "peak_mib": peak_mib()}


def opensees_peer(triangles: int) -> str:
    try:
        import openseespy.opensees  # noqa: F401
    except Exception as exc:  # noqa: BLE001
        return f"OpenSees: not available on this machine ({type(exc).__name__})"
    return "OpenSees: importable, but the peer model is not scripted yet"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[10_000, 50_000, 100_000])
    args = parser.parse_args()
    print("Scordelis-Lo convergence (reference 0.3024, MacNeal & Harder 1985)")
    print(f"{'cells/quarter':>14}{'triangles':>11}{'deflection':>12}{'error %':>9}")
    for divisions in (4, 8, 16, 32, 64):
        deflection, _, mesh = scordelis_lo(divisions)
        print(f"{divisions:>14}{mesh.n_faces:>11}{deflection:>12.5f}{100 * (deflection / SCORDELIS_LO_REFERENCE - 1):>9.2f}")
    print()
    print(f"{'triangles':>10}{'DOF':>9}{'assembly s':>12}{'solve s':>9}{'total s':>9}{'assembly %':>11}"
          f"{'peak MiB':>10}{'deflection':>12}")
    for size in args.sizes:
        r = timed_roof(size)
        print(f"{r['triangles']:>10}{r['dof']:>9}{r['assembly_s']:>12.2f}{r['solve_s']:>9.2f}{r['total_s']:>9.2f}"
              f"{100 * r['assembly_s'] / r['total_s']:>11.1f}{r['peak_mib']:>10.0f}{r['deflection']:>12.5f}")
    print(opensees_peer(args.sizes[-1]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
