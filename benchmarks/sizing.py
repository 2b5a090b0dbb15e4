"""Section sizing ([design] size_sections) on every real roof and a large generated one.

    .venv/bin/python benchmarks/sizing.py [--cells 300] [--large-cells 1500] [--match NAME,...]
        [--out out/sizing] [--no-large] [--no-check-run]

Each roof (every PLY in ../shared/data/surfaces, supported at its red vertices or else its boundary;
and the generated dome of tests/generated_surfaces.py, seed 0, scaled by --large-scale to 85 x 52 m,
at --large-cells: about 3000 nodes)
gets the cap template's loads, material and section (CHS 114.3 x 6.3, S355) and runs
``gridshell run --until analysis`` twice in one output folder: first as a check run (the peer:
the project's one section, EN 1993-1-1 checks), then with ``[design] size_sections = true`` (3
groups from EN 10210-2), reusing the check run's surface..optimize stages; where the sized tubes
outgrow CHS 114.3, ``--fit-grid`` has the run make the grid again for the largest (``[design]
fit_grid_to_tubes = true``: ``refits`` and ``grid_section``; ``sized_run_s`` is the whole run
then). Per roof it prints the check run's verdict (largest utilisation, deflection over its limit,
lambda_NL_worst), the mass before and after, the sized groups, the analyses the sizing took, the
governing checks, whether every check passes, and the seconds of the analysis stage of both runs
(manifest.json). The table is written to OUT/sizing.csv.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SURFACES = Path(os.environ.get("GRIDSHELL_SURFACES", ROOT.parent / "shared" / "data" / "surfaces"))

LOADS = """
[loads.cases.dead]
self_weight = 1.0
area_true = "0.5 kN/m^2"

[loads.cases.snow]
area_plan = "1.0 kN/m^2"

[loads.combinations.SLS]
limit_state = "SLS"
factors = { dead = 1.0, snow = 1.0 }

[loads.combinations.ULS]
limit_state = "ULS"
factors = { dead = 1.35, snow = 1.5 }

[material]
name = "steel_s355"

[section]
kind = "circular_hollow"
diameter = "114.3 mm"
thickness = "6.3 mm"
"""


def _gridshell() -> list[str]:
    candidate = Path(sys.executable).parent / "gridshell"
    if candidate.is_file() and not os.environ.get("PYTHONPATH"):
        return [str(candidate)]
    return [sys.executable, "-m", "workflow.cli"]


def _supports(path: Path) -> str:
    sys.path.insert(0, str(ROOT))
    from workflow.surface_io import read_surface

    return "flagged" if read_surface(path)[2].any() else "boundary"


def _project(name: str, surface: Path, supports: str, cells: int, sized: bool, fit_grid: bool = False) -> str:
    design = ("\n[design]\nsize_sections = true\ncatalogue = \"EN 10210-2 CHS\"\ngroups = 3\n"
              f"fit_grid_to_tubes = {'true' if fit_grid else 'false'}\n") if sized else ""
    return (f'[project]\nname = "{name}"\n\n[surface]\nfile = "{surface.resolve()}"\n\n'
            f'[[supports]]\nselect = "{supports}"\nrestraint = "pinned"\n{LOADS}\n'
            f'[remesh]\nn_cells = {cells}\n{design}')


def _run(project: Path, out: Path) -> tuple[int, float, str]:
    started = time.perf_counter()
    done = subprocess.run([*_gridshell(), "run", str(project), "--out", str(out), "--until", "analysis", "--quiet"],
                          capture_output=True, text=True, cwd=ROOT)
    last = (done.stderr.strip().splitlines() or [""])[-1]
    return done.returncode, time.perf_counter() - started, last


def _stage_seconds(out: Path, stage: str) -> float | None:
    try:
        manifest = json.loads((out / "manifest.json").read_text())
    except (OSError, ValueError):
        return None
    entry = next((s for s in manifest["stages"] if s["name"] == stage), None)
    return None if entry is None else entry.get("computed_s", entry.get("seconds"))


def _analysis(out: Path) -> dict:
    try:
        return json.loads((out / "06-analysis" / "analysis.json").read_text())
    except (OSError, ValueError):
        return {}


def _fitted(out: Path) -> dict:
    """The grid's refits for the sized tubes (fitted_grid.json): rounds and the section it was made for."""
    try:
        fitted = json.loads((out / "fitted_grid.json").read_text())
    except (OSError, ValueError):
        return {"refits": 0, "grid_section": "as given"}
    return {"refits": len(fitted["rounds"]), "grid_section": fitted["section"], "fits": fitted["fits"]}


def _verdict(a: dict) -> str:
    if not a:
        return "-"
    defl = a.get("max_vertical_sls_m", 0) / max(a.get("deflection_limit_m", 1), 1e-12)
    nl = a.get("lambda_NL_worst")
    return f"u {a.get('max_utilisation', 0):.2f}, defl {defl:.2f} x limit, NL {nl if nl is None else round(nl, 2)}"


def bench(name: str, surface: Path, supports: str, cells: int, out: Path, *, check_run: bool,
          fit_grid: bool = False) -> dict:
    folder = out / name
    folder.mkdir(parents=True, exist_ok=True)
    row: dict = {"roof": name, "cells": cells}
    if check_run:
        (folder / "check.toml").write_text(_project(name, surface, supports, cells, sized=False))
        code, seconds, last = _run(folder / "check.toml", folder / "run")
        check = _analysis(folder / "run")
        row.update({"check_verdict": _verdict(check), "check_analysis_s": _stage_seconds(folder / "run", "analysis"),
                    "check_status": "ok" if code == 0 else last})
    (folder / "sized.toml").write_text(_project(name, surface, supports, cells, sized=True, fit_grid=fit_grid))
    code, seconds, last = _run(folder / "sized.toml", folder / "run")
    a = _analysis(folder / "run")
    d = a.get("design", {})
    row.update({
        "nodes": a.get("nodes"), "beams": a.get("beams"),
        "mass_before_kg": round(d.get("mass_before_kg", float("nan")), 0),
        "mass_after_kg": round(d.get("mass_after_kg", float("nan")), 0),
        "groups": " / ".join(f"{g['profile']} x{g['beams']}" for g in d.get("groups", [])),
        "analyses": d.get("iterations"), "nonlinear_rounds": d.get("nonlinear_rounds"),
        "converged": d.get("converged"),
        "governing": ", ".join(f"{k} {v}" for k, v in d.get("governing_checks", {}).items()),
        "all_pass": all(v["pass"] for v in a.get("verdicts", [])) if a else None,
        "sized_verdict": _verdict(a), "sized_analysis_s": _stage_seconds(folder / "run", "analysis"),
        **_fitted(folder / "run"),
        "sized_run_s": round(seconds, 1), "status": "ok" if code == 0 else last})
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=300)
    parser.add_argument("--large-cells", type=int, default=1500)
    parser.add_argument("--match", default="", help="comma-separated roof names (default: all)")
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "sizing")
    parser.add_argument("--no-large", action="store_true")
    parser.add_argument("--large-scale", type=float, default=3.5, help="scale of the generated dome (24 x 15 m)")
    parser.add_argument("--no-check-run", action="store_true")
    parser.add_argument("--fit-grid", action="store_true", help="[design] fit_grid_to_tubes = true")
    args = parser.parse_args()
    wanted = {m for m in args.match.split(",") if m}
    cases = []
    if SURFACES.is_dir():
        cases += [(p.stem, p, _supports(p), args.cells) for p in sorted(SURFACES.glob("*.ply"))]
    else:
        print(f"sizing: no real surfaces at {SURFACES}; skipped", file=sys.stderr)
    if not args.no_large:
        sys.path.insert(0, str(ROOT))
        from dataclasses import replace

        from tests.generated_surfaces import generate_surface, write_ply

        # the generated dome (24 x 15 m) scaled to a station roof's 85 x 52 m, so that 1500 cells
        # of CHS 114.3 need no coarsening for their joints (about 3000 nodes)
        surface = generate_surface(0)
        surface = replace(surface, vertices=surface.vertices * args.large_scale)
        path = write_ply(surface, args.out / "surfaces" / f"{surface.name}-x{args.large_scale:g}.ply")
        cases.append((f"{surface.name}-large", path, "flagged", args.large_cells))
    cases = [c for c in cases if not wanted or c[0] in wanted]
    rows = []
    for name, path, supports, cells in cases:
        row = bench(name, path, supports, cells, args.out, check_run=not args.no_check_run, fit_grid=args.fit_grid)
        rows.append(row)
        print(" | ".join(f"{k}={v}" for k, v in row.items()), flush=True)
        args.out.mkdir(parents=True, exist_ok=True)
        keys = list(dict.fromkeys(k for r in rows for k in r))
        with open(args.out / "sizing.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=keys)
            writer.writeheader()
            writer.writerows(rows)


if __name__ == "__main__":
    main()
