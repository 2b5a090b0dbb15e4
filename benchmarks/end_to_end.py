"""The default job (the 2.4 m mock-up) cold, in a fresh output folder, and again cached; with
--large, a real roof at 1500 cells through every stage with the default protocol.

Targets: the default job cold under 1 minute, cached under 2 s (issue 16; issue 7 had 2 min and
5 s); the large job's analysis under 60 s, the whole job under 5 minutes and peak memory under
4 GiB (issue 16); the default job's whole output under 60 MB (issue 17: the bytes of its files;
`du -sb` adds a few kB for the folders). Each run is a separate `gridshell run` process, so the figures include start-up
and imports, as a user sees them; peak memory is the largest resident set of the run and of the
worker processes it waited for. The load average is printed before and after the cold run, and
the CPU seconds of each run (its own and its workers', user and system) with the cores they kept
busy on average: the wall clock of this shared machine varies by 10-20 % from run to run.

    .venv/bin/python benchmarks/end_to_end.py [--out DIR] [--project FILE]
    .venv/bin/python benchmarks/end_to_end.py --large [--roof ../shared/data/surfaces/Hall.ply] [--cells 1500]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _run(arguments: list[str]) -> tuple[float, float, int, float]:
    """(wall seconds, peak MiB, exit code, CPU seconds) of one ``gridshell`` process: the CPU time
    (user and system) is its own and that of every worker it waited for, so that a change of the
    work shows beside this machine's changes of speed, which move the wall clock by 10-20 %."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    completed = subprocess.run([sys.executable, "-m", "workflow.cli", *arguments], capture_output=True, text=True)
    seconds = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    peak_mib = max(after.ru_maxrss, before.ru_maxrss) / 1024
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    if completed.returncode != 0:
        print(completed.stderr[-3000:], file=sys.stderr)
    return seconds, peak_mib, completed.returncode, cpu


ROOT = Path(__file__).resolve().parents[1]
TARGETS_S = {"default": (60.0, 2.0), "large": (300.0, 5.0)}


def _large_project(roof: Path, cells: int, folder: Path) -> Path:
    """The quick start's project of a real roof (flagged supports) at ``cells`` cells."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "project.toml"
    path.write_text("\n".join([
        "[project]", f'name = "{roof.stem}-{cells}"', "[surface]", f"file = {json.dumps(str(roof.resolve()))}",
        "[[supports]]", 'select = "flagged"', 'restraint = "pinned"', "[remesh]", f"n_cells = {cells}", ""]))
    return path


def main() -> int:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--out", help="output folder (default: a fresh temporary folder)")
    parser.add_argument("--project", help="project file (default: the mock-up template)")
    parser.add_argument("--large", action="store_true", help="the large job: --roof at --cells cells")
    parser.add_argument("--roof", type=Path, default=ROOT.parent / "shared" / "data" / "surfaces" / "Hall.ply",
                        help="the large job's roof (a mesh with red support vertices; default Hall)")
    parser.add_argument("--cells", type=int, default=1500, help="the large job's cell count (default 1500)")
    args = parser.parse_args()
    kind = "large" if args.large else "default"
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="gridshell-e2e-")) / kind
    shutil.rmtree(out, ignore_errors=True)
    if args.large:
        if not args.roof.is_file():
            print(f"end_to_end --large: no roof at {args.roof} (give --roof MESH)")
            return 1
        args.project = str(_large_project(args.roof, args.cells, out.parent / f"{kind}-project"))
    base = ([args.project] if args.project else []) + ["--out", str(out), "--quiet"]
    load_before = os.getloadavg()
    cold, cold_peak, code, cold_cpu = _run(["run", *base])
    if code != 0:
        print(f"cold run failed with exit code {code}")
        return 1
    cold_stages = json.loads((out / "manifest.json").read_text())["stages"]
    steps = next((s.get("step_seconds", {}) for s in cold_stages if s["name"] == "fabrication"), {})
    load_after_cold = os.getloadavg()
    cached, cached_peak, code, cached_cpu = _run(["run", *base])
    manifest = json.loads((out / "manifest.json").read_text())
    stages = {s["name"]: (s["status"], s.get("duration_s", 0.0)) for s in manifest["stages"]}
    print(f"cores: {os.cpu_count()}  output: {out}")
    print(f"load average before / after the cold run: {load_before[0]:.2f} / {load_after_cold[0]:.2f}")
    print("stage durations of the cold run (s): "
          + ", ".join(f"{s['name']} {s.get('duration_s', 0.0):.1f}" for s in cold_stages))
    if steps:
        print("fabrication steps of the cold run (s): " + ", ".join(f"{k} {v:.1f}" for k, v in steps.items()))
    print(f"{'run':<8}{'time s':>10}{'target s':>10}{'peak MiB':>10}{'CPU s':>10}{'cores':>7}")
    print(f"{'cold':<8}{cold:>10.1f}{TARGETS_S[kind][0]:>10.0f}{cold_peak:>10.0f}{cold_cpu:>10.1f}"
          f"{cold_cpu / cold:>7.2f}")
    print(f"{'cached':<8}{cached:>10.2f}{TARGETS_S[kind][1]:>10.0f}{cached_peak:>10.0f}{cached_cpu:>10.2f}"
          f"{cached_cpu / cached:>7.2f}")
    if args.large:
        analysis = next((s.get("duration_s", 0.0) for s in cold_stages if s["name"] == "analysis"), float("nan"))
        optimize = json.loads((out / "05-optimize" / "optimize.json").read_text()).get("after", {})
        print(f"large job: {optimize.get('n_nodes')} nodes, {optimize.get('n_beams')} beams; analysis {analysis:.1f} s "
              f"(target 60 s), whole job {cold:.1f} s (target 300 s), peak {cold_peak / 1024:.2f} GiB (target 4 GiB)")
    if not args.large:
        size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
        print(f"whole output: {size / 1e6:.2f} MB (target under 60 MB)")
    print("cached run statuses: " + ", ".join(f"{k}={v[0]}" for k, v in stages.items()))
    report = out / "report.html"
    print(f"report: {report if report.is_file() else 'missing'}")
    return 0 if code == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
