"""Frame solver speed on a 5000-node grid-shell: linear static, 10 buckling modes and a 50-step
non-linear path, with peak memory.

    .venv/bin/python benchmarks/frame_speed.py [--nodes 5000] [--elements-per-beam 4]

Target (issue 5): linear static plus 10 modes under 10 s on 2 cores. PyNite is run on the same
model when it is importable (it is not a dependency); otherwise the line says so.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.frame import FrameModel, linear_buckling, linear_static, nonlinear_static  # noqa: E402
from engine.grids import quad_grid  # noqa: E402
from engine.parametric import cap  # noqa: E402
from engine.structure import beam_up_vectors, node_normals  # noqa: E402
from engine.supports import Supports  # noqa: E402


def model(nodes: int, elements_per_beam: int):
    surface = cap(span=40.0, span_to_rise=7.0, rings=30)
    # a square grid of n nodes over a disc of area A has about 2 n beams of length sqrt(A / n)
    length = 2 * nodes * np.sqrt(surface.area / nodes)
    support = np.zeros(surface.n_vertices, dtype=bool)
    support[surface.boundary_loops[0]] = True
    grid = quad_grid(surface, total_length=length, support_vertices=support)
    normals = node_normals(grid, surface)
    n_beams = len(grid.edges)
    diameter, wall = 0.1683, 0.008
    area = np.pi / 4 * (diameter**2 - (diameter - 2 * wall) ** 2)
    inertia = np.pi / 64 * (diameter**4 - (diameter - 2 * wall) ** 4)
    frame = FrameModel(nodes=grid.nodes, beams=grid.edges, E=np.full(n_beams, 210e9), G=np.full(n_beams, 81e9),
                       A=np.full(n_beams, area), Iy=np.full(n_beams, inertia), Iz=np.full(n_beams, inertia),
                       J=np.full(n_beams, 2 * inertia), up=beam_up_vectors(grid, normals),
                       elements_per_beam=elements_per_beam)
    supported = np.flatnonzero(grid.supports)
    supports = Supports(nodes=supported, restraints=np.tile([1, 1, 1, 0, 0, 0], (len(supported), 1)).astype(bool))
    loads = np.zeros((grid.n_nodes, 6))
    loads[:, 2] = -20e3
    return frame, supports, loads


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, default=5000)
    parser.add_argument("--elements-per-beam", type=int, default=4)
    parser.add_argument("--steps", type=int, default=50)
    args = parser.parse_args()
    frame, supports, loads = model(args.nodes, args.elements_per_beam)
    print(f"grid-shell: {len(frame.nodes)} nodes, {len(frame.beams)} beams, {args.elements_per_beam} elements per beam, "
          f"{6 * (len(frame.nodes) + len(frame.beams) * (args.elements_per_beam - 1))} DOF")
    start = time.perf_counter()
    linear = linear_static(frame, supports, loads)
    t_linear = time.perf_counter() - start
    start = time.perf_counter()
    buckling = linear_buckling(frame, supports, loads, n_modes=10)
    t_buckling = time.perf_counter() - start
    print(f"linear static      {t_linear:7.2f} s   equilibrium error {linear.equilibrium_error:.1e}")
    print(f"10 buckling modes  {t_buckling:7.2f} s   lambda_1 = {buckling.factors[0]:.3f}")
    print(f"linear + 10 modes  {t_linear + t_buckling:7.2f} s   (target < 10 s)")
    control = int(np.argmax(np.abs(linear.displacements[:, 2])))
    start = time.perf_counter()
    run = nonlinear_static(frame, supports, loads, control=(control, 2), max_load_factor=1e9, max_steps=args.steps)
    t_nonlinear = time.perf_counter() - start
    print(f"non-linear path    {t_nonlinear:7.2f} s   {len(run.path) - 1} steps, limit "
          f"{run.limit_load_factor if run.limit_load_factor is None else round(run.limit_load_factor, 3)}")
    print(f"peak memory        {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:7.0f} MiB")
    try:
        import Pynite  # noqa: F401
        print("PyNite: importable, but the peer model is not scripted yet")
    except ImportError:
        print("PyNite: not installed here (pip install PyNiteFEA to compare; not a dependency)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
