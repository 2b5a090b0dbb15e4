"""The whole pipeline (``gridshell run``, surface .. report) on any roof: every template, every real surface
and N generated ones, each at several cell counts; one row per roof and size.

    .venv/bin/python benchmarks/any_roof.py [--cells 60,300,1500] [--surfaces N] [--only-templates]
        [--first-seed S] [--only-generated] [--out out/any_roof] [--jobs 1] [--timeout SECONDS] [--match NAME,...]
        [--min-cut-mm MM] [--check]

Roofs: the templates (``gridshell init DIR --template NAME``: mockup, cap, vault, hypar, courtyard) with
their own settings; every PLY in ../shared/data/surfaces (or GRIDSHELL_SURFACES; skipped when absent),
supported at its red vertices (the whole boundary where it has none); and the generated roofs of
tests/generated_surfaces.py (seeds 0..N-1, written as PLY into OUT/surfaces), supported at their flagged
vertices. Both kinds of file get a quick-start project (defaults but for the supports and the cell count).
Each run is a separate, cold ``gridshell run PROJECT --out OUT/runs/NAME-cCELLS --quiet`` with a time
limit; a crash, a time-out or a non-zero exit is a row with its status and the last line of stderr.

Per row: seconds per stage (manifest.json), the run's wall-clock seconds, the shortest beam node to node
(optimize.json ``shortest_beam_m``, else measured on 05-optimize/gridshell.obj), the shortest cut length
(07-fabrication/beams/cutlist.csv; "<=0" when fabrication stopped on a beam shorter than its joints), joint
and tube clashes (fabrication.json ``joint_clashes`` and ``tube_clashes``), findings by kind (fabrication.json
``findings``), the structural verdict (analysis.json ``verdicts``) and whether report.html was written. Keys
that are not written yet print "-". The cut-length minimum is --min-cut-mm, else the product's own
(fabrication.json ``limits.min_cut_length_mm``), else the section's outer size (a piece shorter than the tube
is wide). The table is printed and written to OUT/any_roof.csv (rewritten after every run). Exit code 0; with
--check, 1 when a run did not reach report.html or has joint or tube clashes.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
import tomllib
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _cli import ROOT, gridshell_command  # noqa: E402

TEMPLATES = ("mockup", "cap", "vault", "hypar", "courtyard")
STAGES = ("surface", "shell", "field", "remesh", "optimize", "analysis", "fabrication", "report")
REAL_SURFACES = Path(os.environ.get("GRIDSHELL_SURFACES", ROOT.parent / "shared" / "data" / "surfaces"))
SHORT_CHECK = {"nonlinear": "NL", "non-linear": "NL", "utilisation": "util", "deflection": "defl", "buckling": "LB"}
COLUMNS = ("name", "source", "cells", "built", *STAGES, "total_s", "shortest_beam_mm", "shortest_cut_mm", "cut_min_mm",
           "joint_clashes", "findings", "findings_by_kind", "verdict", "failed_checks", "report_html", "status",
           "error", "out")


@dataclass
class Case:
    """One roof: a name, where it comes from, and how to write its project file for a cell count."""

    name: str
    source: str                       # template | real | generated
    template: str | None = None       # template name
    surface: Path | None = None       # PLY file
    supports: str = "flagged"
    settings: str = ""                # extra TOML drawn by --vary-settings (generated roofs)


@dataclass
class Row:
    case: Case
    cells: int
    values: dict = field(default_factory=dict)


# ------------------------------------------------------------------------------------------ cases and projects


def _real_cases() -> list[Case]:
    if not REAL_SURFACES.is_dir():
        print(f"any_roof: no real surfaces at {REAL_SURFACES}; skipped", file=sys.stderr)
        return []
    cases = []
    for path in sorted(REAL_SURFACES.glob("*.ply")):
        supports = "boundary"
        try:
            from workflow.surface_io import read_surface

            supports = "flagged" if read_surface(path)[2].any() else "boundary"
        except Exception as exc:  # the run will report the problem as its row
            print(f"any_roof: {path.name}: {exc}", file=sys.stderr)
        cases.append(Case(name=path.stem, source="real", surface=path, supports=supports))
    return cases


def _generated_cases(n: int, out: Path, first_seed: int = 0, vary: bool = False) -> list[Case]:
    if n <= 0:
        return []
    from tests.generated_surfaces import drawn_settings, generate_surface, write_ply

    cases = []
    for seed in range(first_seed, first_seed + n):
        surface = generate_surface(seed)
        path = write_ply(surface, out / "surfaces" / f"{surface.name}.ply")
        supports, settings = drawn_settings(seed, surface.span_m) if vary else ("flagged", "")
        cases.append(Case(name=surface.name + ("-v" if vary else ""), source="generated", surface=path,
                          supports=supports, settings=settings))
    return cases




def _with_cells(text: str, cells: int) -> str:
    """A template's TOML text with ``[remesh] n_cells = cells`` (other size targets removed)."""
    lines = text.splitlines()
    header = next((i for i, line in enumerate(lines) if line.strip() == "[remesh]"), None)
    if header is None:
        return text.rstrip("\n") + f"\n\n[remesh]\nn_cells = {cells}\n"
    end = next((i for i in range(header + 1, len(lines)) if lines[i].lstrip().startswith("[")), len(lines))
    body = [line for line in lines[header + 1:end]
            if not re.match(r"\s*(n_cells|mean_beam_length|total_length)\s*=", line)]
    return "\n".join([*lines[:header + 1], f"n_cells = {cells}", *body, *lines[end:]]) + "\n"


def _surface_project(case: Case, cells: int) -> str:
    return "\n".join([
        "# any_roof benchmark: the quick-start project of a mesh file, with a cell count",
        "[project]", f"name = {json.dumps(case.name)}", "",
        "[surface]", f"file = {json.dumps(str(case.surface.resolve()))}", "",
        "[[supports]]", f"select = {json.dumps(case.supports)}", 'restraint = "pinned"', "",
        "[remesh]", f"n_cells = {cells}", "", case.settings])


_INIT_LOCK = threading.Lock()


def _project_file(case: Case, cells: int, out: Path) -> Path:
    folder = out / "projects" / case.name
    folder.mkdir(parents=True, exist_ok=True)
    if case.source == "template":
        base = folder / "project.toml"
        with _INIT_LOCK:
            if not base.is_file():
                command = [*gridshell_command(), "init", str(folder), "--template", case.template, "--force"]
                done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
                if done.returncode != 0:
                    raise RuntimeError(f"gridshell init --template {case.template}: " + _last_line(done.stderr))
        text = _with_cells(base.read_text(encoding="utf-8"), cells)
    else:
        text = _surface_project(case, cells)
    if tomllib.loads(text).get("remesh", {}).get("n_cells") != cells:
        raise RuntimeError(f"could not set [remesh] n_cells = {cells} in the project of {case.name}")
    path = folder / f"project-c{cells}.toml"
    path.write_text(text, encoding="utf-8")
    return path


# ------------------------------------------------------------------------------------------ one run


def _last_line(text: str) -> str:
    """The last line of stderr; after the product's 'error: ...' line when that last line is its hint."""
    lines = [line.strip() for line in (text or "").splitlines() if line.strip()]
    if not lines:
        return ""
    errors = [line for line in lines if line.startswith("error:")]
    if lines[-1].startswith("hint:") and errors:
        return f"{errors[-1]} ({lines[-1]})"
    return lines[-1]


def _read_json(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _shortest_obj_edge_m(path: Path) -> float | None:
    """Shortest node-to-node edge of a polygon OBJ (m), or None when it cannot be read."""
    try:
        nodes, best = [], None
        for line in path.read_text(encoding="utf-8").splitlines():
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                nodes.append(tuple(float(c) for c in parts[1:4]))
            elif parts[0] == "f":
                ids = [int(p.split("/")[0]) for p in parts[1:]]
                ids = [i - 1 if i > 0 else len(nodes) + i for i in ids]
                for a, b in zip(ids, ids[1:] + ids[:1]):
                    length = sum((p - q) ** 2 for p, q in zip(nodes[a], nodes[b])) ** 0.5
                    best = length if best is None else min(best, length)
        return best
    except (OSError, ValueError, IndexError):
        return None


def _shortest_cut_mm(path: Path) -> float | None:
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            values = [float(r["cut_length_mm"]) for r in csv.DictReader(handle)
                      if r.get("cut_length_mm") not in (None, "")]
    except (OSError, ValueError, KeyError):
        return None
    return min(values) if values else None


def _section_size_mm(manifest: dict | None) -> float | None:
    section = ((manifest or {}).get("config") or {}).get("section") or {}
    sizes = [section.get(k) for k in ("diameter", "height", "width")]
    sizes = [float(s) for s in sizes if isinstance(s, (int, float))]
    return 1000.0 * max(sizes) if sizes else None


def _verdict(analysis: dict | None) -> tuple[str, str]:
    """('pass 4/4' | 'FAIL util,NL' | '-', the failing checks in full)."""
    if analysis is None:
        return "-", ""
    verdicts = analysis.get("verdicts")
    if isinstance(analysis.get("verdict"), str) and not verdicts:
        return analysis["verdict"], ""
    if not isinstance(verdicts, list) or not verdicts:
        return "-", ""
    failed = [v for v in verdicts if isinstance(v, dict) and not v.get("pass", False)]
    if not failed:
        return f"pass {len(verdicts)}/{len(verdicts)}", ""
    short = []
    for v in failed:
        check = str(v.get("kind") or v.get("check", "?"))
        short.append(next((s for key, s in SHORT_CHECK.items() if key in check), check.split()[0]))
    return ("FAIL " + ",".join(short),
            "; ".join(f"{v.get('check')}: {v.get('value')} vs {v.get('limit')}" for v in failed))


def _findings(stages: dict) -> tuple[object, str]:
    """The count and kinds of the geometry and fabrication findings (the manifest's, of every stage
    but the analysis, whose failing checks are the verdict column)."""
    if "fabrication" not in stages:
        return "-", "-"
    findings = [f for name, stage in stages.items() if name != "analysis"
                for f in (stage.get("findings") or []) if isinstance(f, dict)]
    counts: dict[str, int] = {}
    for finding in findings:
        kind = str(finding.get("kind", "?"))
        counts[kind] = counts.get(kind, 0) + 1
    return len(findings), ",".join(f"{k}:{n}" for k, n in sorted(counts.items())) or "0"


def _clashes(fabrication: dict | None) -> object:
    """Joint-to-joint and tube clashes together ("-" before fabrication.json has them)."""
    if fabrication is None or "joint_clashes" not in fabrication:
        return "-"
    total = 0
    for key in ("joint_clashes", "tube_clashes"):
        value = fabrication.get(key, [])
        total += len(value) if isinstance(value, (list, tuple, dict)) else int(value)
    return total


_CHILDREN: set[subprocess.Popen] = set()
_CHILDREN_LOCK = threading.Lock()


def _kill(process: subprocess.Popen) -> None:
    """End the run and the worker processes it started (its own process group)."""
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def run_one(case: Case, cells: int, out: Path, timeout: float, min_cut_mm: float | None) -> Row:
    row = Row(case=case, cells=cells)
    v = row.values
    v.update({"name": case.name, "source": case.source, "cells": cells})
    run_dir = out / "runs" / f"{case.name}-c{cells}"
    v["out"] = str(run_dir)
    try:
        project = _project_file(case, cells, out)
    except Exception as exc:
        v.update({"status": "no project", "error": str(exc)})
        return row
    shutil.rmtree(run_dir, ignore_errors=True)
    command = [*gridshell_command(), "run", str(project), "--out", str(run_dir), "--quiet"]
    started = time.perf_counter()
    process = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    with _CHILDREN_LOCK:
        _CHILDREN.add(process)
    timed_out = False
    try:
        _, stderr = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        timed_out = True
        _kill(process)
        _, stderr = process.communicate()
    finally:
        _kill(process)              # workers it may have left behind
        with _CHILDREN_LOCK:
            _CHILDREN.discard(process)
    v["total_s"] = round(time.perf_counter() - started, 1)
    code = process.returncode

    manifest = _read_json(run_dir / "manifest.json")
    stages = {s.get("name"): s for s in (manifest or {}).get("stages", []) if isinstance(s, dict)}
    for name in STAGES:
        entry = stages.get(name, {})
        seconds = entry.get("duration_s")
        timed = entry.get("status") in ("ran", "cached", "failed") and seconds is not None
        v[name] = round(float(seconds), 1) if timed else "-"
    problem = next((n for n in STAGES if stages.get(n, {}).get("status") in ("failed", "not available")), None)
    unfinished = next((n for n in STAGES if stages.get(n, {}).get("status") not in ("ran", "cached")), None)

    optimize = _read_json(run_dir / "05-optimize" / "optimize.json")
    shortest = (optimize or {}).get("shortest_beam_m")
    if not isinstance(shortest, (int, float)):
        shortest = _shortest_obj_edge_m(run_dir / "05-optimize" / "gridshell.obj")
    v["shortest_beam_mm"] = "-" if shortest is None else round(1000.0 * shortest, 1)
    v["built"] = ((optimize or {}).get("after") or {}).get("n_faces", "-")

    stage_message = str(stages.get(problem, {}).get("message", "")) if problem else ""
    error = _last_line(stderr) or stage_message
    cut = _shortest_cut_mm(run_dir / "07-fabrication" / "beams" / "cutlist.csv")
    joints_eat_beam = "shorter than its two joints take" in (stderr or "") + stage_message
    v["shortest_cut_mm"] = cut if cut is not None else ("<=0" if joints_eat_beam else "-")
    fabrication = _read_json(run_dir / "07-fabrication" / "fabrication.json")
    product_minimum = ((fabrication or {}).get("limits") or {}).get("min_cut_length_mm")
    minimum = next((m for m in (min_cut_mm, product_minimum, _section_size_mm(manifest))
                    if isinstance(m, (int, float))), None)
    v["cut_min_mm"] = "-" if minimum is None else round(float(minimum), 1)
    v["_cut_under"] = joints_eat_beam or (cut is not None and minimum is not None and cut < minimum)
    v["joint_clashes"] = _clashes(fabrication)
    v["findings"], v["findings_by_kind"] = _findings(stages)
    v["verdict"], v["failed_checks"] = _verdict(_read_json(run_dir / "06-analysis" / "analysis.json"))
    v["report_html"] = "yes" if (run_dir / "report.html").is_file() else "no"

    if timed_out:
        v["status"] = f"timeout@{unfinished or '?'}"
        error = f"no result after {timeout:g} s; " + error if error else f"no result after {timeout:g} s"
    elif code != 0:
        where = problem or unfinished
        v["status"] = (f"failed@{where} (exit {code})" if where else f"exit {code}") if code > 0 else f"killed ({code})"
    elif problem or unfinished:
        v["status"] = f"stopped@{problem or unfinished}"
        error = error or str((manifest or {}).get("message") or "")
    elif v["report_html"] != "yes":
        v["status"] = "no report.html"
    else:
        v["status"] = "ok"
    v["error"] = "" if v["status"] == "ok" and code == 0 else error
    return row


# ------------------------------------------------------------------------------------------ table


def _cell(value) -> str:
    if isinstance(value, float):
        return f"{value:.1f}"
    return "-" if value is None else str(value)


TABLE = (("name", "name"), ("cells", "cells"), ("built", "built"),
         *((s, s[:5] if s != "fabrication" else "fabr") for s in STAGES),
         ("total_s", "total"), ("shortest_beam_mm", "beam_mm"), ("shortest_cut_mm", "cut_mm"),
         ("joint_clashes", "clash"), ("findings_by_kind", "findings"), ("verdict", "verdict"),
         ("report_html", "html"), ("status", "status"), ("error", "error"))


def format_table(rows: list[Row], error_width: int = 70) -> str:
    header = [title for _, title in TABLE]
    body = []
    for row in rows:
        cells = [_cell(row.values.get(key)) for key, _ in TABLE]
        if len(cells[-1]) > error_width:
            cells[-1] = cells[-1][:error_width - 3] + "..."
        body.append(cells)
    widths = [max(len(r[i]) for r in [header, *body]) for i in range(len(header))]
    numeric = {i for i, (key, _) in enumerate(TABLE) if key in (*STAGES, "cells", "total_s", "shortest_beam_mm",
                                                                "shortest_cut_mm", "joint_clashes")}

    def line(cells: list[str]) -> str:
        return "  ".join(c.rjust(w) if i in numeric else c.ljust(w)
                         for i, (c, w) in enumerate(zip(cells, widths))).rstrip()

    return "\n".join([line(header), line(["-" * w for w in widths]), *(line(c) for c in body)])


def write_csv(rows: list[Row], path: Path) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _cell(row.values.get(k)) for k in COLUMNS})
    tmp.replace(path)


def summary_line(rows: list[Row]) -> str:
    reached = sum(r.values.get("report_html") == "yes" for r in rows)
    clashes = sum(isinstance(r.values.get("joint_clashes"), int) and r.values["joint_clashes"] > 0 for r in rows)
    short = sum(bool(r.values.get("_cut_under")) for r in rows)
    failed = sum(r.values.get("status") != "ok" for r in rows)
    return (f"runs {len(rows)}, reached report.html {reached}, with clashes {clashes}, "
            f"with cut length under the minimum {short}, failed {failed}")


# ------------------------------------------------------------------------------------------ main


def _cells(text: str) -> list[int]:
    try:
        cells = [int(c) for c in text.split(",") if c.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--cells {text!r}: give cell counts like 60,300,1500") from None
    if not cells or min(cells) < 4:
        raise argparse.ArgumentTypeError(f"--cells {text!r}: at least one count, each >= 4")
    return cells


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--cells", type=_cells, default=[60, 300, 1500], help="cell counts (default 60,300,1500)")
    parser.add_argument("--surfaces", type=int, default=20, metavar="N",
                        help="generated roofs, seeds 0..N-1 (default 20)")
    parser.add_argument("--first-seed", type=int, default=0, metavar="S",
                        help="generated roofs from seed S (S..S+N-1; default 0): roofs the product was never tuned on")
    parser.add_argument("--only-generated", action="store_true", help="the generated roofs only")
    parser.add_argument("--vary-settings", action="store_true",
                        help="generated roofs with settings drawn from their seed (material, section, joints, D, A, "
                             "loads, panels, sheets, supports) instead of the quick-start ones")
    parser.add_argument("--only-templates", action="store_true", help="the templates only")
    parser.add_argument("--match", help="only roofs whose name contains one of these comma-separated strings "
                                           "(=NAME: that name exactly)")
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "any_roof",
                        help="output folder (default out/any_roof)")
    parser.add_argument("--jobs", type=int, default=1, help="runs at a time (default 1)")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds per run (default 1800)")
    parser.add_argument("--min-cut-mm", type=float,
                        help="shortest acceptable cut length (default: the product's limit, else the section's "
                             "outer size)")
    parser.add_argument("--check", action="store_true",
                        help="exit 1 when a run misses report.html or has joint clashes")
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    out: Path = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    sys.path.insert(0, str(ROOT))

    cases = [] if args.only_generated else [Case(name=name, source="template", template=name) for name in TEMPLATES]
    if not args.only_templates:
        cases += [] if args.only_generated else _real_cases()
        cases += _generated_cases(args.surfaces, out, args.first_seed, args.vary_settings)
    if args.match:
        wanted = [w for w in args.match.split(",") if w]
        cases = [c for c in cases if any(c.name == w[1:] if w.startswith("=") else w in c.name for w in wanted)]
    order = {c.name: i for i, c in enumerate(cases)}
    # the cheap sweep first: every roof at the smallest size, then the next size
    plan = [(case, cells) for cells in sorted(args.cells) for case in cases]
    print(f"any_roof: {len(plan)} runs ({len(cases)} roofs x {len(args.cells)} sizes) into {out}", file=sys.stderr)

    rows: list[Row] = []

    def ordered() -> list[Row]:
        return sorted(rows, key=lambda r: (order[r.case.name], r.cells))

    pool = ThreadPoolExecutor(max_workers=args.jobs)
    try:
        futures = {pool.submit(run_one, case, cells, out, args.timeout, args.min_cut_mm): (case, cells)
                   for case, cells in plan}
        for done, future in enumerate(as_completed(futures), start=1):
            case, cells = futures[future]
            try:
                row = future.result()
            except Exception as exc:  # a bug of the benchmark itself: still a row
                row = Row(case=case, cells=cells, values={"name": case.name, "source": case.source, "cells": cells,
                                                         "status": "benchmark error", "error": repr(exc)})
            rows.append(row)
            write_csv(ordered(), out / "any_roof.csv")
            v = row.values
            print(f"[{done}/{len(plan)}] {case.name} c{cells}: {v.get('status')} {_cell(v.get('total_s'))} s"
                  + (f"  {v['error']}" if v.get("error") else ""), file=sys.stderr, flush=True)
    except KeyboardInterrupt:
        pool.shutdown(wait=False, cancel_futures=True)
        with _CHILDREN_LOCK:
            for process in list(_CHILDREN):
                _kill(process)
        print("any_roof: interrupted; the table holds the finished runs", file=sys.stderr)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)

    table = ordered()
    print(format_table(table))
    print(f"csv: {out / 'any_roof.csv'}")
    print(summary_line(table))
    if args.check and any(r.values.get("report_html") != "yes" or
                          (isinstance(r.values.get("joint_clashes"), int) and r.values["joint_clashes"] > 0)
                          for r in table):
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
