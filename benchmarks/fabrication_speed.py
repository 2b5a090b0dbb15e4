"""Fabrication speed: joints of a 500-node grid-shell (time per joint, both cores), and 1000
panel DXFs with sheet nesting (benchmarks/_bench_panels.py).

    .venv/bin/python benchmarks/fabrication_speed.py [--nodes 500] [--workers 2]

Targets (issue 6): under 1 s per joint on average on 2 cores; 1000 panels with nesting under 30 s.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from engine.field import GuidingField  # noqa: E402
from engine.parametric import mockup  # noqa: E402
from engine.structure import node_normals  # noqa: E402
from engine.voronoi import RemeshSettings, remesh  # noqa: E402
from fabrication.joints import JointSettings, build_joints  # noqa: E402


def bench_joints(nodes: int, workers: int) -> None:
    surface = mockup().mesh
    n = surface.n_vertices
    field = GuidingField(size=np.ones(n), anisotropy=np.ones(n), direction=np.tile([1.0, 0, 0], (n, 1)),
                         normals=surface.vertex_normals)
    grid = remesh(surface, field, RemeshSettings(n_cells=max(8, nodes // 2), lloyd_iterations=20)).polymesh
    normals = node_normals(grid, surface)
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        reports = build_joints(grid, normals, 12.0, JointSettings(), Path(folder) / "joints", workers=workers)
        seconds = time.perf_counter() - start
    ok = sum(r["ok"] for r in reports)
    print(f"joints: {len(reports)} on {workers} worker(s) in {seconds:.1f} s = {seconds / len(reports):.2f} s per joint "
          f"(target < 1 s); {ok} pass every check; peak {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB "
          f"(parent)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, default=500)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--skip-panels", action="store_true")
    args = parser.parse_args()
    bench_joints(args.nodes, args.workers)
    if not args.skip_panels:
        from _bench_panels import bench_panels

        bench_panels()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
