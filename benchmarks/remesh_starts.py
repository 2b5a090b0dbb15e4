"""The remesh's starts one after another against side by side on the cores, on the default job's
surface and field (the mock-up template at 60 cells, two symmetry planes): small grids are
clustered from several starts (lattice offsets), each tessellation of the size search once per
start, and ``[remesh] workers`` puts them on a process pool.

    .venv/bin/python benchmarks/remesh_starts.py [--cells 60,120] [--workers 2] [--repeat 2]

Prints, per cell count, the seconds of ``engine.remeshing.voronoi.remesh`` with the starts in turn (the
peer: the code path before, ``starts_map=None``) and with a pool of ``--workers`` processes
(started before the clock, as the stage keeps its pool over all its remeshes), the ratio, and
whether the two grids are the same node for node.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def inputs(cells: int, folder: Path):
    """(mesh, field, settings, support mask, buildable) of the mock-up template at ``cells`` cells,
    from its own project run up to the field stage."""
    from workflow.cli import main as gridshell
    from workflow.config import load_project
    from workflow.stages import field as field_stage
    from workflow.stages import surface as surface_stage
    from workflow.stages.remesh import buildable_as_remeshed, remesh_settings

    with contextlib.redirect_stdout(io.StringIO()):
        made = gridshell(["init", str(folder), "--template", "mockup", "--force"])
    if made != 0:
        raise SystemExit("gridshell init failed")
    path = folder / "project.toml"
    text = path.read_text(encoding="utf-8")
    path.write_text(text.replace("n_cells = 60", f"n_cells = {cells}"), encoding="utf-8")
    out = folder / "out"
    if gridshell(["run", str(path), "--out", str(out), "--until", "field", "--quiet"]) != 0:
        raise SystemExit("gridshell run --until field failed")
    project = load_project(path)
    surface = surface_stage.load(out / "01-surface", project)
    field = field_stage.load(out / "03-field", project)
    support = np.zeros(surface.mesh.n_vertices, dtype=bool)
    support[surface.supports.nodes] = True
    return surface.mesh, field, remesh_settings(project), support, buildable_as_remeshed(project)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", default="60,120", help="comma-separated cell counts (default 60,120)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--repeat", type=int, default=2, help="runs of each (the fastest is printed)")
    args = parser.parse_args()
    from engine.remeshing.voronoi import remesh

    print(f"cores {os.cpu_count()}, workers {args.workers}, load average {os.getloadavg()[0]:.2f}")
    print(f"{'cells':>6} {'in turn s':>10} {'side by side s':>15} {'ratio':>6}  same grid")
    with tempfile.TemporaryDirectory() as tmp, ProcessPoolExecutor(max_workers=args.workers) as pool:
        for cells in (int(c) for c in args.cells.split(",")):
            mesh, field, settings, support, buildable = inputs(cells, Path(tmp) / f"c{cells}")
            remesh(mesh, field, settings, support_vertices=support, buildable=buildable)  # numba's cache loaded

            def timed(starts_map):
                best, grid = np.inf, None
                for _ in range(args.repeat):
                    start = time.perf_counter()
                    grid = remesh(mesh, field, settings, support_vertices=support, buildable=buildable,
                                  starts_map=starts_map).polymesh
                    best = min(best, time.perf_counter() - start)
                return best, grid

            serial_s, serial = timed(None)
            pooled_s, pooled = timed(pool.map)
            same = (np.array_equal(serial.nodes, pooled.nodes)
                    and [f.tolist() for f in serial.faces] == [f.tolist() for f in pooled.faces])
            print(f"{cells:>6} {serial_s:>10.2f} {pooled_s:>15.2f} {serial_s / pooled_s:>6.2f}  {same}")
    print(f"load average after {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
