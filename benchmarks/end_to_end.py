"""The default job (the 2.4 m mock-up) cold, in a fresh output folder, and again cached.

Targets (issue 7): cold under 2 minutes, cached under 5 s on the 2-core machine. Each run is a
separate `gridshell run` process, so the figures include start-up and imports, as a user sees
them; peak memory is the child's largest resident set.

    .venv/bin/python benchmarks/end_to_end.py [--out DIR] [--project FILE]
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


def _run(arguments: list[str]) -> tuple[float, float, int]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    completed = subprocess.run([sys.executable, "-m", "workflow.cli", *arguments], capture_output=True, text=True)
    seconds = time.perf_counter() - start
    peak_mib = max(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, before) / 1024
    if completed.returncode != 0:
        print(completed.stderr[-3000:], file=sys.stderr)
    return seconds, peak_mib, completed.returncode


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="output folder (default: a fresh temporary folder)")
    parser.add_argument("--project", help="project file (default: the mock-up template)")
    args = parser.parse_args()
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="gridshell-e2e-")) / "mockup"
    shutil.rmtree(out, ignore_errors=True)
    base = ([args.project] if args.project else []) + ["--out", str(out), "--quiet"]
    load_before = os.getloadavg()
    cold, cold_peak, code = _run(["run", *base])
    if code != 0:
        print(f"cold run failed with exit code {code}")
        return 1
    cold_stages = json.loads((out / "manifest.json").read_text())["stages"]
    steps = next((s.get("step_seconds", {}) for s in cold_stages if s["name"] == "fabrication"), {})
    load_after_cold = os.getloadavg()
    cached, cached_peak, code = _run(["run", *base])
    manifest = json.loads((out / "manifest.json").read_text())
    stages = {s["name"]: (s["status"], s.get("duration_s", 0.0)) for s in manifest["stages"]}
    print(f"cores: {os.cpu_count()}  output: {out}")
    print(f"load average before / after the cold run: {load_before[0]:.2f} / {load_after_cold[0]:.2f}")
    print("stage durations of the cold run (s): "
          + ", ".join(f"{s['name']} {s.get('duration_s', 0.0):.1f}" for s in cold_stages))
    if steps:
        print("fabrication steps of the cold run (s): " + ", ".join(f"{k} {v:.1f}" for k, v in steps.items()))
    print(f"{'run':<8}{'time s':>10}{'target s':>10}{'peak MiB':>10}")
    print(f"{'cold':<8}{cold:>10.1f}{120:>10}{cold_peak:>10.0f}")
    print(f"{'cached':<8}{cached:>10.2f}{5:>10}{cached_peak:>10.0f}")
    print("cached run statuses: " + ", ".join(f"{k}={v[0]}" for k, v in stages.items()))
    report = out / "report.html"
    print(f"report: {report if report.is_file() else 'missing'}")
    return 0 if code == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
