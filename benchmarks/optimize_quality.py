"""Benchmark of the face optimisation against the planarity target, through the real pipeline.

For the mock-up (templates/mockup.toml) and every PLY in the real surfaces folder (with its
flagged supports, the whole boundary where a file flags none), the stages surface -> shell ->
field -> remesh run as ``gridshell run`` runs them (workflow.runner, into a scratch folder or
``--cache DIR`` to reuse), then ``engine.remeshing.optimize.optimize`` runs with the project's optimize
settings (workflow.stages.optimize.optimize_settings) and, as the peer in the same process, the
local/global iterations alone (planarity_iterations = 0, split_cells = false: the optimiser as
it was before the end game). Printed per surface and method: planarity max and p95 (relative to
the mean beam length, and in mm), closeness max (relative to the bounding-box diagonal),
regularity before -> after, smallest corner angle, non-convex cells, boundary splits (corner +
edge + repair) and the change of total beam length, the time, and whether the target is met:

    largest planarity error <= 0.5 % of the mean beam length, largest node distance to the
    surface < 0.5 % of the bounding-box diagonal.

Issue 13's other figures are printed beside them for the optimiser as the stage calls it: hexagons
among interior cells and interior nodes with three beams after it, the size rank correlation
(Spearman) with the field remeshed -> optimised, and the optimisation's seconds over the remesh
stage's (target: at most 3). The whole table on the stage's files, collapses included, is
benchmarks/statics_aware.py's.

Usage: python benchmarks/optimize_quality.py [--cache DIR] [--only NAME ...] [--cells N[,N...]] [--generated N]
The surfaces folder is ../shared/data/surfaces next to the checkout, or $GRIDSHELL_SURFACES;
it is skipped (with a line saying so) when absent.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
import time
from importlib import resources
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engine.remeshing.optimize import optimize  # noqa: E402
from workflow.config import load_project, project_from_surface  # noqa: E402
from workflow.progress import Progress  # noqa: E402
from workflow.runner import run_project  # noqa: E402
from workflow.stages import STAGES  # noqa: E402
from workflow.stages.optimize import optimize_settings  # noqa: E402
from workflow.surface_io import read_surface  # noqa: E402

SURFACES = Path(os.environ.get("GRIDSHELL_SURFACES", ROOT.parent / "shared" / "data" / "surfaces"))
PLANARITY_TARGET, CLOSENESS_TARGET = 0.005, 0.005


def _load(project, out_dir: Path, name: str):
    """A stage's result, loaded from its files in ``out_dir``."""
    stage = next(s for s in STAGES if s.name == name)
    return stage.load(out_dir / stage.folder, project)


def _jobs(only: list[str], generated: int = 0) -> list[tuple[str, object]]:
    jobs = [("mockup", load_project(resources.files("templates") / "mockup.toml"))]
    if generated:
        from tests.generated_surfaces import generate_surface, write_ply

        folder = Path(tempfile.mkdtemp(prefix="optimize_quality_"))
        for seed in range(generated):
            surface = generate_surface(seed)
            path = write_ply(surface, folder / f"gen{seed:02d}-{surface.kind}.ply")
            jobs.append((path.stem, project_from_surface(str(path), "flagged")))
    if SURFACES.is_dir():
        for path in sorted(SURFACES.glob("*.ply")):
            _, _, flagged = read_surface(path)
            supports = "flagged" if flagged is not None and np.any(flagged) else "boundary"
            jobs.append((path.stem, project_from_surface(str(path), supports)))
    else:
        print(f"(no real surfaces: {SURFACES} is absent; the mock-up only)")
    return [(name, project) for name, project in jobs if not only or name in only]


def _row(name: str, label: str, quality: dict, seconds: float, remesh_s: float) -> str:
    a, b = quality["after"], quality["before"]
    rank_before, rank_after = b.get("size_rank_correlation"), a.get("size_rank_correlation")
    ranks = (f"{rank_before:.2f}->{rank_after:.2f}" if rank_before is not None and rank_after is not None
             else "-")
    met = a["planarity_max_rel"] <= PLANARITY_TARGET and a["closeness_max_rel"] < CLOSENESS_TARGET
    added = a.get("total_length_m", np.nan) / b.get("total_length_m", np.nan) - 1
    return (f"{name:13s} {label:10s} {b['n_faces'] if 'n_faces' in b else '':>4}->{a.get('n_faces', ''):<4} "
            f"{100 * a['planarity_max_rel']:6.2f} {100 * a['planarity_p95_rel']:6.2f} "
            f"{1000 * a['planarity_max_m']:7.1f} {1000 * a['planarity_p95_m']:7.1f} "
            f"{100 * a['closeness_max_rel']:6.3f}  {b['regularity']:.3f}->{a['regularity']:.3f} "
            f"{a['smallest_angle_deg']:6.1f} {a['nonconvex_faces']:5d} "
            f"{quality['corner_splits']:2d}+{quality['edge_splits']:<2d}+{quality.get('repair_splits', 0):<2d} "
            f"{100 * added:+6.1f} "
            f"{100 * a.get('hexagon_share_interior', np.nan):5.1f} "
            f"{100 * a.get('valence3_share_interior', np.nan):5.1f} "
            f"{ranks:>10s} "
            f"{seconds:6.2f} {seconds / max(remesh_s, 1e-9):5.2f}  {'met' if met else 'NOT met'}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cache", type=Path, help="reuse/keep the pipeline outputs here (one folder per surface)")
    parser.add_argument("--only", nargs="*", default=[], help="surface names (mockup, Botanic, ...)")
    parser.add_argument("--cells", help="remesh every surface into these many cells, comma-separated (default: the "
                                        "project's)")
    parser.add_argument("--generated", type=int, default=0, metavar="N",
                        help="also the generated free-form roofs of seeds 0 .. N-1 (flagged supports)")
    args = parser.parse_args(argv)
    scratch = None if args.cache else tempfile.TemporaryDirectory(prefix="optimize_quality_")
    base = args.cache or Path(scratch.name)
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}, {os.cpu_count()} cores; "
          f"target: planarity <= {100 * PLANARITY_TARGET:g} % of the mean beam, closeness < "
          f"{100 * CLOSENESS_TARGET:g} % of the diagonal")
    print(f"{'surface':13s} {'method':10s} {'cells':>9s} {'p.max%':>6s} {'p.p95%':>6s} {'max mm':>7s} "
          f"{'p95 mm':>7s} {'close%':>6s}  {'regularity':11s} {'angle':>6s} {'ncvx':>5s} {'splits c+e+r':12s} "
          f"{'dL %':>6s} {'hex %':>5s} {'v3 %':>5s} {'rank r->o':>10s} {'time s':>6s} {'x rem':>5s}  target")
    met = total = 0
    sizes = [int(c) for c in args.cells.split(",")] if args.cells else [None]
    for (name, project), cells in ((job, cells) for job in _jobs(args.only, args.generated) for cells in sizes):
        if cells:
            project = project.model_copy(update={"remesh": project.remesh.model_copy(update={"n_cells": cells})})
            name = f"{name}-{cells}" if len(sizes) > 1 else name
        out = base / (name if not cells else f"{name}-{cells}")
        start = time.perf_counter()
        summary = run_project(project, out, STAGES, until="remesh", progress=Progress(enabled=False))
        if summary.message:
            print(f"{name:13s} pipeline stopped: {summary.message}")
            continue
        pipeline = time.perf_counter() - start
        import json

        stages = json.loads((out / "manifest.json").read_text())["stages"]
        remesh_s = next((s.get("duration_s") or 0.0 for s in stages if s["name"] == "remesh"), 0.0)
        surface, field = _load(project, out, "surface"), _load(project, out, "field")
        grid = _load(project, out, "remesh")
        settings = optimize_settings(project)
        peer = dataclasses.replace(settings, planarity_iterations=0, split_cells=False)
        for label, chosen in (("end game", settings), ("LG only", peer)):
            start = time.perf_counter()
            result = optimize(grid, surface.mesh, field, chosen)
            seconds = time.perf_counter() - start
            print(_row(name, label, result.quality, seconds, remesh_s), flush=True)
            if chosen is settings:
                total += 1
                a = result.quality["after"]
                met += a["planarity_max_rel"] <= PLANARITY_TARGET and a["closeness_max_rel"] < CLOSENESS_TARGET
        print(f"{'':13s} (pipeline to remesh {pipeline:.1f} s, {grid.n_nodes} nodes, "
              f"{project.optimize.iterations} local/global iterations)")
    print(f"target met on {met} of {total} surfaces with the end game")
    if scratch is not None:
        scratch.cleanup()


if __name__ == "__main__":
    main()
