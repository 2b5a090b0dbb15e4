"""A sweep of the cap, point after point and on a local Dask cluster of two workers, cold, in the same run.

    .venv/bin/python benchmarks/sweep_speed.py [--points 8] [--until analysis] [--cells 150] [--out DIR]

The points vary the remesher's seed ("remesh.seed" = 1..N), so the surface, shell and field are
shared and every point remeshes, optimises and analyses its own grid. Three ways, each a separate
``gridshell`` process in a fresh folder:

- plain runs: ``gridshell run`` of each point's project one after another, as a user would without
  sweeps (each run's analysis puts its non-linear paths on both cores);
- ``gridshell sweep --workers 1``: the points one after another, one process;
- ``gridshell sweep --workers 2``: two points at a time.

Prints the seconds of each and the ratios; issue 14's target is at least 1.8 for one worker against
two. Then a rerun of the finished sweep (cached).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GRIDSHELL = [sys.executable, "-m", "workflow.cli"]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


def _timed(arguments: list[str]) -> float:
    started = time.perf_counter()
    run = subprocess.run([*GRIDSHELL, *arguments], env=ENV, capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"gridshell {' '.join(arguments)} failed:\n{run.stderr[-2000:]}")
    return time.perf_counter() - started


def _with(project: str, section: str, key: str, value) -> str:
    """The project text with ``[section] key = value`` (the line replaced, or added)."""
    head, rest = project.split(f"[{section}]\n", 1)
    body, tail = (rest.split("\n[", 1) + [""])[:2]
    lines = [line for line in body.splitlines() if not line.strip().startswith(f"{key} ")
             and not line.strip().startswith(f"{key}=")]
    return head + f"[{section}]\n{key} = {value}\n" + "\n".join(lines) + ("\n[" + tail if tail else "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=8)
    parser.add_argument("--until", default="analysis")
    parser.add_argument("--cells", type=int, default=150, help="the cap's cells (its template has 150)")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="sweep_speed_"))
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    _timed(["init", str(out / "cap"), "--template", "cap"])
    project = (out / "cap" / "project.toml").read_text()
    project = _with(project, "remesh", "n_cells", args.cells)
    (out / "cap" / "project.toml").write_text(project)
    seeds = list(range(1, args.points + 1))
    (out / "sweep.toml").write_text(f'project = "cap/project.toml"\nuntil = "{args.until}"\n'
                                    f'[parameters]\n"remesh.seed" = {seeds}\n')
    print(f"sweep_speed: the cap, {args.cells} cells, {args.points} points (remesh.seed 1..{args.points}), "
          f"stages up to {args.until}, {os.cpu_count()} cores; folder {out}", flush=True)
    plain = 0.0
    for seed in seeds:
        folder = out / "plain" / f"seed{seed}"
        folder.mkdir(parents=True)
        (folder / "project.toml").write_text(_with(project, "remesh", "seed", seed))
        plain += _timed(["run", str(folder / "project.toml"), "--out", str(folder / "out"), "--until", args.until,
                         "--quiet"])
    print(f"  plain runs, one after another:  {plain:7.1f} s", flush=True)
    one = _timed(["sweep", str(out / "sweep.toml"), "--out", str(out / "one"), "--workers", "1", "--quiet"])
    print(f"  sweep, 1 worker:                {one:7.1f} s", flush=True)
    two = _timed(["sweep", str(out / "sweep.toml"), "--out", str(out / "two"), "--workers", "2", "--quiet"])
    print(f"  sweep, 2 workers:               {two:7.1f} s", flush=True)
    cached = _timed(["sweep", str(out / "sweep.toml"), "--out", str(out / "two"), "--workers", "2", "--quiet"])
    print(f"  sweep, 2 workers, rerun cached: {cached:7.1f} s")
    print(f"  ratios: 1 worker / 2 workers {one / two:.2f} (target >= 1.8); plain runs / 2 workers {plain / two:.2f}")


if __name__ == "__main__":
    main()
