"""Benchmark of engine.optimize (intended for benchmarks/optimize_quality.py): the mock-up remeshed
into 60 Voronoi cells, then optimised with the default settings; prints planarity, closeness,
regularity, time and peak memory. Also runs the spherical-cap honeycomb of tests/test_optimize.py."""

import resource
import sys
import time

import numpy as np

from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.field import GuidingField
from engine.optimize import OptimizeSettings, optimize
from engine.parametric import mockup
from engine.voronoi import RemeshSettings, remesh


def main(cells: int = 60, iterations: int = 50) -> None:
    surface = mockup(divisions=16).mesh
    n = surface.n_vertices
    field = GuidingField(size=np.ones(n), anisotropy=np.ones(n), direction=np.tile([1.0, 0, 0], (n, 1)),
                         normals=surface.vertex_normals)
    support = np.zeros(n, dtype=bool)
    support[surface.boundary_loops[0]] = True
    grid = remesh(surface, field, RemeshSettings(n_cells=cells, lloyd_iterations=40), support_vertices=support).polymesh
    print(f"mock-up, {grid.n_faces} cells, {grid.n_nodes} nodes, {iterations} iterations")
    for label, settings in (("planar", OptimizeSettings(iterations=iterations)),
                            ("regular only", OptimizeSettings(iterations=iterations, planar=False))):
        start = time.perf_counter()
        result = optimize(grid, surface, field, settings)
        elapsed = time.perf_counter() - start
        q = result.quality
        interior = ~grid.face_boundary
        p = result.polymesh.face_planarity() / result.polymesh.beam_lengths.mean()
        print(f"  {label:13s} {elapsed:6.2f} s  planarity max {q['before']['planarity_max_rel']:.4f} -> "
              f"{q['after']['planarity_max_rel']:.4f} (interior cells {p[interior].max():.4f}), "
              f"p95 {q['after']['planarity_p95_rel']:.4f}, closeness max {q['after']['closeness_max_rel']:.4f}, "
              f"regularity {q['before']['regularity']:.3f} -> {q['after']['regularity']:.3f}, "
              f"smallest angle {q['after']['smallest_angle_deg']:.1f} deg")
    print(f"peak memory {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:]))
