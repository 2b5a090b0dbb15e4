"""Remeshing speed: a 100k-triangle surface into 2000 cells, ours (Voro(2,2)-like field) against
pyacvd's isotropic clustering of the same surface into the same number of cells, in one run.

    .venv/bin/python benchmarks/remesh_speed.py [--triangles 100000] [--cells 2000]

Target (issue 4): ours within 3 times pyacvd's time; peak memory printed.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.field import GuidingField  # noqa: E402
from engine.mesh import TriMesh  # noqa: E402
from engine.parametric import mockup  # noqa: E402
from engine.voronoi import RemeshSettings, remesh  # noqa: E402


def surface(triangles: int) -> TriMesh:
    divisions = 2 * max(2, int(round(np.sqrt(triangles / 2) / 2)))  # mockup needs an even count
    return mockup(divisions=divisions).mesh


def field_on(mesh: TriMesh) -> GuidingField:
    x, y = mesh.vertices[:, 0], mesh.vertices[:, 1]
    r = np.hypot(x, y) / np.hypot(x, y).max()
    direction = np.c_[-y, x, np.zeros_like(x)] + 1e-9
    direction -= np.einsum("ni,ni->n", direction, mesh.vertex_normals)[:, None] * mesh.vertex_normals
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    return GuidingField(size=1.0 + r, anisotropy=1.0 + r, direction=direction, normals=mesh.vertex_normals)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--triangles", type=int, default=100_000)
    parser.add_argument("--cells", type=int, default=2000)
    parser.add_argument("--lloyd", type=int, default=80)
    args = parser.parse_args()
    mesh = surface(args.triangles)
    print(f"surface: {mesh.n_faces} triangles, {mesh.n_vertices} vertices; {args.cells} cells")
    start = time.perf_counter()
    result = remesh(mesh, field_on(mesh), RemeshSettings(n_cells=args.cells, lloyd_iterations=args.lloyd))
    ours = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    q = result.quality
    print(f"ours:   {ours:8.2f} s  ({args.lloyd} Lloyd iterations max)  peak {peak:.0f} MiB")
    print(f"        hexagons {100 * q['hexagon_share_interior']:.1f} % of interior cells, valence 3 "
          f"{100 * q['valence3_share_interior']:.1f} %, size ratio {q['achieved_size_ratio']:.2f}, "
          f"aspect {q['achieved_max_aspect']:.2f}, cells {q['n_faces']}")
    try:
        import pyacvd
        import pyvista as pv
    except ImportError as exc:
        print(f"pyacvd: not available ({exc})")
        return 0
    faces = np.c_[np.full(mesh.n_faces, 3), mesh.faces].ravel()
    poly = pv.PolyData(mesh.vertices, faces)
    start = time.perf_counter()
    clustering = pyacvd.Clustering(poly)
    if poly.n_points < 3 * args.cells:
        clustering.subdivide(2)
    clustering.cluster(args.cells)
    peer = time.perf_counter() - start
    print(f"pyacvd: {peer:8.2f} s  (isotropic clustering, same surface and cell count)")
    print(f"ratio ours / pyacvd: {ours / peer:.2f} (target <= 3)")

    return 0


if __name__ == "__main__":
    raise SystemExit(main())
