"""The same-length study of issue 14: when does a statics-aware Voronoi grid beat a quad grid?

    .venv/bin/python benchmarks/study.py [--surfaces cap,Neumunster,...] [--cells 40,80,160]
        [--seeds 0,1,2] [--questions spacing,statics,optimiser,rounds] [--workers N] [--out out/study]

Every surface gets one project: the cap template's loads, material, section (CHS 114.3 x 6.3 S355)
and analysis protocol, on the surface with its flagged supports (pinned), and ``[remesh]
total_length`` as the size target, so that every grid of a row has the same total beam length
L_tot. The surfaces are the cap and every roof in ../shared/data/surfaces that is a height field
over its plan (the reference lattices need one). The L_tot levels are those of a hexagonal grid of
about ``--cells`` cells over the surface's area (3 n edges of a regular hexagon of area A / n).
Each question is one or two ``gridshell sweep`` runs (their files and results stay under
OUT/SURFACE/QUESTION/), up to the analysis:

| question | sweep | at |
|---|---|---|
| spacing | remesh.grid (voronoi, isotropic) x remesh.seed; remesh.grid (quad, quad45, triangular, statics_quad) | every L_tot |
| statics | (field.max_size_ratio, field.max_aspect) in (1,1) (2,1) (1,2) (3,3), and (2,2) with field.orientation = across, x remesh.seed | the middle L_tot |
| optimiser | optimize.iterations = 0 (none), optimize.planarise_cells = true (planar cells, added beams) x remesh.seed | the middle L_tot |
| rounds | remesh.statics_rounds = 2, 3 (field from the grid's own beam forces) x remesh.seed | the middle L_tot |

The default Voronoi grid, Voro(2,2) with split panels and one round, is the spacing sweep's voronoi
row at the same L_tot; the isotropic uniform CVT of the same length is the control. Printed and
written to OUT/study.md: one table per question with the median over the seeds of the worst
non-linear load factor of the imperfection protocol (lambda_NL_worst), the linear buckling factor
and the size rank correlation of the optimised grid with the field, and the largest deviation of
L_tot from its row's target, after a table of verdicts (design against reference, at how many
surface and length pairs it is higher). OUT/study.csv has every point, OUT/study_summary.csv the
table rows; OUT/spacing.png and OUT/designs.png plot them. Last, a table per roof (OUT/study_roofs.csv,
plotted in OUT/roofs.png): what the roof is (span, rise, curvature, supports, the shell's membrane
forces and eccentricity, the field's aspect) beside the default design's load factor over the quad
grid's and over the control's, to say where the claim holds and why. Sweeps already run are read
from their cache, so a rerun only adds what is missing (a new surface, seed or question).

With ``--stiff-sections REFERENCE_OUT`` each roof takes its own tube (every design of the roof the
same one): the lightest EN 10210 tube that would bring the default design within its deflection
limit, estimated from the study's run at the cap's section in REFERENCE_OUT (``stiff_section``). At
the cap's section most roofs deflect metres under the serviceability load and every path stops at
the tolerable deflection (span / 50) before any limit point: their load factors compare stiffness,
not buckling, which is what the thesis's claim is about.
"""  # noqa: E501 (Markdown table rows, which cannot be wrapped)

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _cli import ROOT, gridshell_command  # noqa: E402

sys.path.insert(0, str(ROOT))
from engine.structure.protocol import ProtocolSettings  # noqa: E402

REAL_SURFACES = Path(os.environ.get("GRIDSHELL_SURFACES", ROOT.parent / "shared" / "data" / "surfaces"))
QUESTIONS = ("spacing", "statics", "optimiser", "rounds")
LATTICES = ("quad", "quad45", "triangular", "statics_quad")
VORONOI = ("voronoi", "isotropic")
#: (D, A) pairs of the statics question besides the default (2, 2)
PAIRS = ((1.0, 1.0), (2.0, 1.0), (1.0, 2.0), (3.0, 3.0))


def height_field_roofs() -> list[Path]:
    """The shared roofs that are height fields over their plan (the lattices need one)."""
    from engine.mesh import TriMesh
    from engine.remeshing.grids import is_height_field
    from workflow.surface_io import read_surface

    if not REAL_SURFACES.is_dir():
        print(f"study: no real surfaces at {REAL_SURFACES}; the cap only", file=sys.stderr)
        return []
    roofs = []
    for path in sorted(REAL_SURFACES.glob("*.ply")):
        vertices, faces, flagged = read_surface(path)
        if is_height_field(TriMesh(vertices=vertices, faces=faces, flagged=flagged)):
            roofs.append(path)
    return roofs


#: The study's tube (diameter, wall; mm): the cap template's when the study was run (2026-12-06).
#: The template has CHS 168.3 x 6.3 since, so that it passes its own checks; the study keeps its own.
STUDY_TUBE_MM = (114.3, 6.3)


def _cap_text() -> str:
    return (ROOT / "templates" / "cap.toml").read_text(encoding="utf-8")


def project_text(surface: Path | None, name: str, total_length_m: float,
                 section_mm: tuple[float, float] | None = None) -> str:
    """The study's project: the cap template with the surface (None: the cap itself) and its
    flagged supports, no symmetry planes but the cap's, a total-length target (set per point) and no
    coarsening for the joints (which would change L_tot); ``section_mm``: the tube's diameter and
    wall (``stiff_section``), else STUDY_TUBE_MM."""
    lines = _cap_text().splitlines()
    section_mm = STUDY_TUBE_MM if section_mm is None else section_mm
    lines = [f'diameter = "{section_mm[0]:g} mm"' if line.startswith("diameter = ")
             else f'thickness = "{section_mm[1]:g} mm"' if line.startswith("thickness = ") else line
             for line in lines]
    out = []
    skip = None
    for line in lines:
        stripped = line.strip()
        if stripped.startswith("["):
            skip = None
            if surface is not None and stripped in ("[surface]", "[surface.parameters]", "[[supports]]"):
                skip = stripped
                if stripped == "[surface]":
                    out += ["[surface]", f"file = {json.dumps(str(surface.resolve()))}", "",
                            "[[supports]]", 'select = "flagged"', 'restraint = "pinned"', ""]
                continue
            if stripped == "[remesh]":
                out += ["[remesh]", f"total_length = {total_length_m}", "coarsen_for_joints = false", ""]
                skip = stripped
                continue
        if skip is not None:
            continue
        if surface is not None and (stripped.startswith("symmetry_planes") or stripped.startswith("{ point")
                                    or stripped == "]"):
            continue
        out.append(line)
    text = "\n".join(out) + "\n"
    text = re.sub(r'name = "cap"', f'name = {json.dumps(name)}', text, count=1)
    text = re.sub(r'description = ".*"', 'description = "same-length study: the cap\'s loads, section and protocol"',
                  text, count=1)
    return text


def stiff_section(reference: Path) -> tuple[str, float, float, float] | None:
    """The lightest EN 10210 tube that would bring the default design's deflection under the
    serviceability load within its limit (span / 250), estimated from a run of the study at the
    cap's section (``reference``: that run's OUT/SURFACE): the median deflection delta_0 of Voro(2,2)
    at the middle length, and the second moment I >= I_0 delta_0 / limit (a bending-dominated grid:
    the deflection goes as 1 / I; the heavier tube's own weight is left out). (name, diameter mm,
    wall mm, delta_0 / limit); the cap's section where delta_0 already meets the limit, and None
    without the reference's spacing sweep."""
    import pandas as pd

    table = reference / "spacing" / "voronoi" / "out" / "sweep.csv"
    if not table.is_file():
        return None
    rows = pd.read_csv(table)
    rows = rows[(rows["remesh.grid"] == "voronoi") & (rows["status"] == "ok")]
    if rows.empty:
        return None
    lengths = sorted(rows["remesh.total_length"].unique())
    middle = rows[rows["remesh.total_length"] == lengths[len(lengths) // 2]]
    limit = json.loads((table.parent / str(middle["folder"].iloc[0]) / "06-analysis" / "analysis.json").read_text(
        encoding="utf-8"))["deflection_limit_m"]
    over = float(middle["delta_L_m"].median()) / limit
    catalogue = pd.read_csv(ROOT / "engine" / "data" / "en10210_chs.csv", comment="#")
    cap = catalogue[np.isclose(catalogue["diameter_mm"], STUDY_TUBE_MM[0])
                    & np.isclose(catalogue["thickness_mm"], STUDY_TUBE_MM[1])].iloc[0]
    enough = catalogue[catalogue["I_cm4"] >= cap["I_cm4"] * over].sort_values("mass_kg_per_m")
    pick = cap if over <= 1.0 else enough.iloc[0] if not enough.empty else catalogue.sort_values("I_cm4").iloc[-1]
    return str(pick["name"]), float(pick["diameter_mm"]), float(pick["thickness_mm"]), over


def length_levels(project: Path, cells: list[int]) -> list[float]:
    """L_tot (m) of a regular hexagonal grid of about n cells over the surface's area, per n."""
    from workflow.config import load_project
    from workflow.stages.surface import build_surface

    mesh, _ = build_surface(load_project(project))
    area = float(mesh.face_areas.sum())
    return [round(float(3 * n * np.sqrt(2 * area / (3 * np.sqrt(3) * n))), 1) for n in cells]


def _toml_value(value) -> str:
    return json.dumps(value)


def write_sweep(folder: Path, project: Path, parameters: dict[str, list]) -> Path:
    """OUT/SURFACE/QUESTION/NAME.toml: a sweep file of the contract."""
    folder.mkdir(parents=True, exist_ok=True)
    lines = [f"project = {json.dumps(os.path.relpath(project, folder))}", 'until = "analysis"', "", "[parameters]"]
    for key, values in parameters.items():
        lines.append(f"{json.dumps(key)} = [{', '.join(_toml_value(v) for v in values)}]")
    path = folder / "sweep.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def run_sweep(path: Path, workers: int | None) -> list[dict]:
    """Run one sweep (a cached one only reads its manifests) and return its rows with the optimised
    grid's size rank correlation and L_tot added."""
    import pandas as pd

    command = [*gridshell_command(), "sweep", str(path), "--out", str(path.parent / "out"), "--quiet"]
    if workers:
        command += ["--workers", str(workers)]
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
    if done.returncode != 0:
        raise RuntimeError(f"{path}: gridshell sweep exited {done.returncode}: {done.stderr.strip()[-400:]}")
    print(f"  {path.parent.relative_to(path.parents[2])}: {time.perf_counter() - started:.0f} s", flush=True)
    rows = pd.read_csv(path.parent / "out" / "sweep.csv").to_dict("records")
    for row in rows:
        folder = path.parent / "out" / str(row["folder"])
        for stage, key, column in (("05-optimize/optimize.json", "after", "size_rank_correlation"),
                                   ("04-remesh/remesh.json", None, "remesh_rank_correlation")):
            row[column] = None
            try:
                data = json.loads((folder / stage).read_text(encoding="utf-8"))
            except (OSError, ValueError):
                continue
            figures = data.get(key, data) if key else data
            value = figures.get("size_rank_correlation") if isinstance(figures, dict) else None
            row[column] = float(value) if isinstance(value, (int, float)) else None
        try:                  # whether lambda_NL_worst is a limit point or the load at the tolerable deflection
            row["limit_point"] = json.loads((folder / "06-analysis" / "analysis.json").read_text(
                encoding="utf-8")).get("limit_point_reached")
        except (OSError, ValueError):
            row["limit_point"] = None
    return rows


def questions_of(surface_dir: Path, project: Path, lengths: list[float], seeds: list[int],
                 asked: list[str]) -> dict[str, dict[str, dict[str, list]]]:
    """The sweeps of each question: {question: {sweep name: parameters}}."""
    middle = lengths[len(lengths) // 2]
    plans: dict[str, dict[str, dict[str, list]]] = {}
    if "spacing" in asked:
        plans["spacing"] = {
            "voronoi": {"remesh.total_length": lengths, "remesh.grid": list(VORONOI), "remesh.seed": seeds},
            "lattices": {"remesh.total_length": lengths, "remesh.grid": list(LATTICES)}}
    if "statics" in asked:
        plans["statics"] = {f"D{d:g}A{a:g}": {"remesh.total_length": [middle], "field.max_size_ratio": [d],
                                              "field.max_aspect": [a], "remesh.seed": seeds} for d, a in PAIRS}
        plans["statics"]["across"] = {"remesh.total_length": [middle], "field.orientation": ["across"],
                                      "remesh.seed": seeds}
    if "optimiser" in asked:
        plans["optimiser"] = {
            "none": {"remesh.total_length": [middle], "optimize.iterations": [0], "remesh.seed": seeds},
            "added_beams": {"remesh.total_length": [middle], "optimize.planarise_cells": [True], "remesh.seed": seeds}}
    if "rounds" in asked:
        plans["rounds"] = {"rounds": {"remesh.total_length": [middle], "remesh.statics_rounds": [2, 3],
                                      "remesh.seed": seeds}}
    return plans


def variant_of(question: str, sweep: str, row: dict) -> str:
    """The name of a row's design in the tables."""
    if sweep in ("voronoi", "lattices"):
        return {"voronoi": "Voro(2,2)", "isotropic": "isotropic CVT", "quad": "quad 0", "quad45": "quad 45",
                "triangular": "triangular", "statics_quad": "statics-aware quad"}[row["remesh.grid"]]
    if sweep == "across":
        return "Voro(2,2) across"
    if sweep.startswith("D"):
        return f"Voro({row['field.max_size_ratio']:g},{row['field.max_aspect']:g})"
    if sweep == "none":
        return "Voro(2,2) not optimised"
    if sweep == "added_beams":
        return "Voro(2,2) planar cells, added beams"
    return f"Voro(2,2) {int(row['remesh.statics_rounds'])} rounds"


def _median(values) -> float | None:
    finite = [v for v in values if v is not None and np.isfinite(v)]
    return float(np.median(finite)) if finite else None


def summary(rows: list[dict]) -> list[dict]:
    """One line per (surface, L_tot, design): medians over the seeds, the worst L_tot deviation."""
    groups: dict[tuple, list[dict]] = {}
    for row in rows:
        groups.setdefault((row["surface"], row["remesh.total_length"], row["design"]), []).append(row)
    lines = []
    for (surface, length, design), members in groups.items():
        ok = [m for m in members if m["status"] == "ok"]
        deviation = [abs(m["total_beam_length_m"] / length - 1) for m in ok if m.get("total_beam_length_m")]
        lines.append({"surface": surface, "L_tot_m": length, "design": design, "runs": len(members), "ok": len(ok),
                      "lambda_NL_worst": _median(m["lambda_NL_worst"] for m in ok),
                      "lambda_LB": _median(m["lambda_LB"] for m in ok),
                      "delta_L_mm": _median(1e3 * m["delta_L_m"] for m in ok if m["delta_L_m"] is not None),
                      "size_rank_correlation": _median(m["size_rank_correlation"] for m in ok),
                      "L_tot_deviation": max(deviation) if deviation else None,
                      "L_tot_median_m": _median(m.get("total_beam_length_m") for m in ok),
                      "at_limit": sum(m.get("limit_point") is True for m in ok),
                      "message": next((m["message"] for m in members if m["status"] != "ok"), "")})
    return lines


def _fmt(value, digits=2) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def markdown(lines: list[dict], question: str) -> str:
    rows = [line for line in lines if line["question"] == question]
    head = ("| surface | L_tot m | design | runs ok | at a limit point | lambda_NL worst | lambda_LB | delta_L mm "
            "| size rank corr. | L_tot dev. % |")
    out = [head, "|" + "---|" * 10]
    for r in rows:
        out.append(f"| {r['surface']} | {r['L_tot_m']:.0f} | {r['design']} | {r['ok']}/{r['runs']} | "
                   f"{r.get('at_limit', 0)}/{r['ok']} | "
                   f"{_fmt(r['lambda_NL_worst'])} | {_fmt(r['lambda_LB'])} | {_fmt(r['delta_L_mm'], 1)} | "
                   f"{_fmt(r['size_rank_correlation'])} | "
                   f"{_fmt(None if r['L_tot_deviation'] is None else 100 * r['L_tot_deviation'], 1)} |")
    return "\n".join(out)


#: The protocol's largest load factor: a path that carries it stops there, so a pair of designs
#: that both reach it has no verdict.
CEILING = ProtocolSettings().max_load_factor

#: The verdicts: each design's lambda_NL_worst over a reference design's at the same surface and L_tot.
VERDICTS = (("Voro(2,2)", "quad 0"), ("Voro(2,2)", "quad 45"), ("Voro(2,2)", "isotropic CVT"),
            ("statics-aware quad", "quad 0"), ("Voro(2,2)", "triangular"), ("Voro(1,2)", "isotropic CVT"),
            ("Voro(2,1)", "isotropic CVT"), ("Voro(3,3)", "isotropic CVT"), ("Voro(2,2) across", "Voro(2,2)"),
            ("Voro(2,2) not optimised", "Voro(2,2)"), ("Voro(2,2) planar cells, added beams", "Voro(2,2)"),
            ("Voro(2,2) 2 rounds", "Voro(2,2)"), ("Voro(2,2) 3 rounds", "Voro(2,2)"))


def verdicts(lines: list[dict]) -> str:
    """Per pair of designs: at how many (surface, L_tot) the first's median lambda_NL_worst is
    higher, the median and range of the ratio, the median ratio of the linear buckling factors,
    the median ratio of the deflections under the
    serviceability load (below 1: stiffer), and how far apart the two designs' median lengths
    are at most (the study asks for 1 %: a pair beyond it is marked, and its ratio carries the
    difference: lambda_NL grows about 1.5 to 2 times as fast as L_tot in the spacing study). The
    pairs where both designs carried the protocol's largest load factor (``CEILING``) are left out. The
    last column counts the pairs whose every run reached a limit point (a buckling load, not the
    load at the tolerable deflection span/50), with the first design higher at how many."""
    best = {(line["surface"], line["L_tot_m"], line["design"]): line for line in lines}
    out = ["| design | against | higher at | ratio median | ratio range | lambda_LB ratio median "
           "| deflection ratio median | L_tot apart, at most | both at a limit point: higher at |",
           "|---|---|---|---|---|---|---|---|---|"]
    for design, reference in VERDICTS:
        ratios, apart, deflections, buckled, linear = [], [], [], [], []
        for (surface, length, name), line in best.items():
            other = best.get((surface, length, reference))
            if name != design or other is None or not line["lambda_NL_worst"] or not other["lambda_NL_worst"]:
                continue
            if min(line["lambda_NL_worst"], other["lambda_NL_worst"]) >= CEILING * (1 - 1e-6):
                continue                                   # both carried the largest load asked: no verdict
            ratios.append(line["lambda_NL_worst"] / other["lambda_NL_worst"])
            if all(r.get("at_limit", 0) == r["ok"] > 0 for r in (line, other)):
                buckled.append(ratios[-1])
            if line.get("lambda_LB") and other.get("lambda_LB"):
                linear.append(line["lambda_LB"] / other["lambda_LB"])
            if line["delta_L_mm"] and other["delta_L_mm"]:
                deflections.append(line["delta_L_mm"] / other["delta_L_mm"])
            if line["L_tot_median_m"] and other["L_tot_median_m"]:
                apart.append(abs(line["L_tot_median_m"] / other["L_tot_median_m"] - 1))
        if not ratios:
            continue
        higher = sum(r > 1 for r in ratios)
        gap = f"{100 * max(apart):.1f} %" + (" (over 1 %)" if max(apart) > 0.01 else "") if apart else "-"
        at_limit = (f"{sum(r > 1 for r in buckled)} of {len(buckled)} (median {np.median(buckled):.2f})"
                    if buckled else "none")
        out.append(f"| {design} | {reference} | {higher} of {len(ratios)} | {np.median(ratios):.2f} | "
                   f"{min(ratios):.2f}-{max(ratios):.2f} | {_fmt(float(np.median(linear)) if linear else None)} | "
                   f"{_fmt(float(np.median(deflections)) if deflections else None)} | {gap} | {at_limit} |")
    return "\n".join(out)


def roof_descriptors(surface_dir: Path) -> dict | None:
    """What a roof is, from the shared stages of its spacing sweep (the first point's surface, shell
    and field; None before they exist): plan span (m, the larger side of the plan's box), rise over
    span, the share of its area that is anticlastic (negative angle defect at the vertex), the share
    of its boundary nodes supported, the shares of its area where the shell's principal membrane
    forces are both compressive and of opposite signs (a force within 2 % of the roof's median
    largest magnitude counts as zero), the median eccentricity |M| / |N| of the shell's moments (mm)
    and the field's mean aspect."""
    import trimesh

    points = sorted((surface_dir / "spacing" / "voronoi" / "out" / "points").glob("*/02-shell/shell.npz"))
    if not points:
        return None
    point = points[0].parents[1]
    mesh = trimesh.load(point / "01-surface" / "surface.ply", process=False)
    shell = np.load(point / "02-shell" / "shell.npz")
    field = json.loads((point / "03-field" / "field.json").read_text(encoding="utf-8"))
    supported = {int(k) for k in json.loads((point / "01-surface" / "supports.json").read_text(
        encoding="utf-8"))["supports"]}
    lower, upper = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    span = float(max(upper[:2] - lower[:2]))
    areas = mesh.area_faces
    vertex_area = np.bincount(mesh.faces.ravel(), weights=np.repeat(areas / 3, 3), minlength=len(mesh.vertices))
    boundary = np.zeros(len(mesh.vertices), bool)
    edges = mesh.edges_sorted
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    boundary[unique[counts == 1].ravel()] = True
    interior = ~boundary
    anticlastic = interior & (mesh.vertex_defects < -1e-9)
    forces = shell["face_principal_forces"]                       # (m, 2) N/m, N1 >= N2
    magnitude = np.abs(forces).max(axis=1)
    zero = 0.02 * float(np.median(magnitude))
    biaxial = (forces < -zero).all(axis=1)
    mixed = (forces.max(axis=1) > zero) & (forces.min(axis=1) < -zero)
    moments = np.linalg.norm(shell["face_moments"], axis=1)
    membrane = np.linalg.norm(shell["face_membrane_forces"], axis=1)
    eccentricity = np.median(moments / np.maximum(membrane, 1e-9 * membrane.max()))
    return {"span_m": span, "rise_to_span": float(upper[2] - lower[2]) / span, "area_m2": float(areas.sum()),
            "anticlastic_share": float(vertex_area[anticlastic].sum() / vertex_area[interior].sum()),
            "supported_share": len(supported & set(np.flatnonzero(boundary))) / max(int(boundary.sum()), 1),
            "biaxial_compression_share": float(areas[biaxial].sum() / areas.sum()),
            "mixed_share": float(areas[mixed].sum() / areas.sum()),
            "eccentricity_mm": 1e3 * float(eccentricity), "field_mean_aspect": field.get("mean_aspect")}


def roof_table(lines: list[dict], out: Path) -> tuple[str, list[dict]]:
    """One row per roof: its descriptors (``roof_descriptors``) and, per L_tot, the default design's
    lambda_NL_worst over the quad grid's at 0 degrees and over the isotropic control's (medians over
    the seeds), and how many of the default design's and the quad grid's runs reached a limit point
    (the others' lambda_NL is the load at the tolerable deflection). Markdown and the rows."""
    spacing = [r for r in lines if r["question"] == "spacing"]
    best = {(r["surface"], r["L_tot_m"], r["design"]): r["lambda_NL_worst"] for r in spacing if r["lambda_NL_worst"]}
    rows = []
    for surface in sorted({r["surface"] for r in spacing}, key=str.lower):
        roof = roof_descriptors(out / surface) or {}
        lengths = sorted({length for (s, length, _) in best if s == surface})
        ratios = {ref: [best[(surface, n, "Voro(2,2)")] / best[(surface, n, ref)] if best.get((surface, n, ref))
                        and best.get((surface, n, "Voro(2,2)")) else None for n in lengths]
                  for ref in ("quad 0", "isotropic CVT")}
        limits = {design: (sum(r.get("at_limit", 0) for r in spacing if r["surface"] == surface
                               and r["design"] == design),
                           sum(r["ok"] for r in spacing if r["surface"] == surface and r["design"] == design))
                  for design in ("Voro(2,2)", "quad 0")}
        rows.append({"surface": surface, **roof, "voronoi_over_quad": ratios["quad 0"],
                     "voronoi_over_control": ratios["isotropic CVT"],
                     "voronoi_at_limit": limits["Voro(2,2)"], "quad_at_limit": limits["quad 0"]})
    head = ("| roof | span m | rise / span | anticlastic | supported edge | biaxial compression | mixed signs "
            "| eccentricity mm | field aspect | Voro(2,2) / quad 0 | Voro(2,2) / control "
            "| at a limit point: Voro, quad |")
    text = [head, "|" + "---|" * 12]

    def share(row: dict, key: str) -> str:
        return "-" if row.get(key) is None else f"{100 * row[key]:.0f} %"

    for r in rows:
        text.append(f"| {r['surface']} | {_fmt(r.get('span_m'), 1)} | {_fmt(r.get('rise_to_span'))} | "
                    f"{share(r, 'anticlastic_share')} | {share(r, 'supported_share')} | "
                    f"{share(r, 'biaxial_compression_share')} | {share(r, 'mixed_share')} | "
                    f"{_fmt(r.get('eccentricity_mm'), 0)} | {_fmt(r.get('field_mean_aspect'))} | "
                    f"{', '.join(_fmt(v) for v in r['voronoi_over_quad'])} | "
                    f"{', '.join(_fmt(v) for v in r['voronoi_over_control'])} | "
                    f"{'/'.join(map(str, r['voronoi_at_limit']))}, {'/'.join(map(str, r['quad_at_limit']))} |")
    return "\n".join(text), rows


def plot_study(lines: list[dict], out: Path) -> list[Path]:
    """OUT/spacing.png: lambda_NL_worst against L_tot per design, one panel per surface (medians over
    the seeds, the seeds' range as a band); OUT/designs.png: each design's lambda_NL_worst over the
    isotropic control's at the middle L_tot, per surface."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    spacing = [r for r in lines if r["question"] == "spacing"]
    surfaces = sorted({r["surface"] for r in spacing})
    if surfaces:
        columns = min(3, len(surfaces))
        rows = -(-len(surfaces) // columns)
        figure, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 3.4 * rows), squeeze=False)
        for ax, surface in zip(axes.ravel(), surfaces):
            for design in sorted({r["design"] for r in spacing if r["surface"] == surface}):
                points = sorted((r["L_tot_m"], r["lambda_NL_worst"]) for r in spacing
                                if r["surface"] == surface and r["design"] == design and r["lambda_NL_worst"])
                if points:
                    x, y = zip(*points)
                    ax.plot(x, y, marker="o", lw=2.2 if design == "Voro(2,2)" else 1.2, label=design)
            ax.set_title(surface)
            ax.set_xlabel("total beam length L_tot (m)")
            ax.set_ylabel("worst non-linear load factor")
            ax.grid(alpha=0.3)
        for ax in axes.ravel()[len(surfaces):]:
            ax.axis("off")
        axes.ravel()[0].legend(fontsize=7)
        figure.suptitle("Worst non-linear load factor at equal beam length\n(median of the seeds)", fontsize=10)
        figure.tight_layout()
        written.append(out / "spacing.png")
        figure.savefig(written[-1], dpi=110)
        plt.close(figure)
    others = [r for r in lines if r["question"] in ("statics", "optimiser", "rounds")]
    if others:
        control = {(r["surface"], r["L_tot_m"]): r["lambda_NL_worst"] for r in lines
                   if r["design"] == "isotropic CVT" and r["lambda_NL_worst"]}
        order = [v[0] for v in VERDICTS] + [r["design"] for r in others]
        designs = [d for d in dict.fromkeys(order) if d != "isotropic CVT" and any(r["design"] == d for r in others)]
        surfaces = sorted({r["surface"] for r in others}, key=str.lower)
        figure, ax = plt.subplots(figsize=(max(6.0, 0.9 * len(designs) + 2), 4.6))
        colours = plt.get_cmap("tab20")
        offsets = np.linspace(-0.3, 0.3, len(surfaces)) if len(surfaces) > 1 else np.zeros(1)
        for k, surface in enumerate(surfaces):
            label: str | None = surface                  # on the roof's first dot only
            for j, design in enumerate(designs):
                match = [r["lambda_NL_worst"] / control[(surface, r["L_tot_m"])] for r in others
                         if r["surface"] == surface and r["design"] == design and r["lambda_NL_worst"]
                         and control.get((surface, r["L_tot_m"]))]
                if match:
                    ax.plot(j + offsets[k], match[0], "o", ms=5, color=colours(k % 20), label=label)
                    label = None
        for j, design in enumerate(designs):
            ratios = [r["lambda_NL_worst"] / control[(r["surface"], r["L_tot_m"])] for r in others
                      if r["design"] == design and r["lambda_NL_worst"] and control.get((r["surface"], r["L_tot_m"]))]
            if ratios:
                ax.hlines(np.median(ratios), j - 0.38, j + 0.38, color="k", lw=2)
        ax.axhline(1.0, color="grey", lw=0.8, ls="--")
        ax.set_xticks(np.arange(len(designs)), designs, rotation=35, ha="right", fontsize=8)
        ax.set_ylabel("lambda_NL worst / isotropic CVT's")
        ax.set_title("Voronoi designs against the isotropic CVT of the same length (middle L_tot);\n"
                     "a dot per roof, the bar their median", fontsize=10)
        ax.legend(fontsize=7, ncol=2 if len(surfaces) > 6 else 1, loc="best")
        figure.tight_layout()
        written.append(out / "designs.png")
        figure.savefig(written[-1], dpi=110)
        plt.close(figure)
    return written


def plot_roofs(rows: list[dict], out: Path) -> Path | None:
    """OUT/roofs.png: the default design's lambda_NL_worst over the quad grid's (median over the
    lengths) against what each roof is: rise over span, the share of its area under membrane forces
    of mixed signs, and the shell's eccentricity."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    points = [(r, _median(r["voronoi_over_quad"])) for r in rows if r.get("span_m") is not None]
    points = [(r, y) for r, y in points if y is not None]
    if not points:
        return None
    panels = (("rise_to_span", "rise / span", 1.0), ("mixed_share", "area under forces of mixed signs (%)", 100.0),
              ("eccentricity_mm", "shell eccentricity |M| / |N| (mm, median)", 1.0))
    figure, axes = plt.subplots(1, 3, figsize=(13, 4.0))
    for ax, (key, label, scale) in zip(axes, panels):
        for row, ratio in points:
            ax.plot(scale * row[key], ratio, "o", color="C0" if ratio > 1 else "C3")
            ax.annotate(row["surface"], (scale * row[key], ratio), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
        ax.axhline(1.0, color="grey", lw=0.8, ls="--")
        ax.set_xlabel(label)
        ax.set_ylabel("Voro(2,2) / quad 0, lambda_NL worst")
        ax.grid(alpha=0.3)
    figure.suptitle("Where the statics-aware Voronoi grid beats the quad grid of the same length "
                    "(median over the three lengths)", fontsize=10)
    figure.tight_layout()
    path = out / "roofs.png"
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--surfaces", help="comma list of names (cap and shared roof stems); default: all")
    parser.add_argument("--cells", default="40,80,160", help="hexagonal cell counts that set the L_tot levels")
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--questions", default=",".join(QUESTIONS))
    parser.add_argument("--workers", type=int, default=None, help="sweep workers (default: the cores)")
    parser.add_argument("--out", default=str(ROOT / "out" / "study"))
    parser.add_argument("--stiff-sections", metavar="REFERENCE_OUT",
                        help="each roof takes the tube that brings its default design within the deflection "
                             "limit, estimated from a run of the study at the cap's section (stiff_section)")
    args = parser.parse_args(argv)
    import pandas as pd

    out = Path(args.out).resolve()
    cells = [int(c) for c in args.cells.split(",")]
    seeds = [int(s) for s in args.seeds.split(",")]
    asked = [q for q in args.questions.split(",") if q]
    unknown = sorted(set(asked) - set(QUESTIONS))
    if unknown:
        parser.error(f"--questions: unknown {unknown}; choose from {QUESTIONS}")
    surfaces: list[tuple[str, Path | None]] = [("cap", None)] + [(p.stem, p) for p in height_field_roofs()]
    if args.surfaces:
        wanted = args.surfaces.split(",")
        surfaces = [s for s in surfaces if s[0] in wanted]
    rows: list[dict] = []
    sections: list[str] = []
    started = time.perf_counter()
    for name, path in surfaces:
        folder = out / name
        folder.mkdir(parents=True, exist_ok=True)
        project = folder / "project.toml"
        section = None
        if args.stiff_sections:
            picked = stiff_section(Path(args.stiff_sections).resolve() / name)
            if picked is None:
                print(f"{name}: no reference run in {args.stiff_sections}; skipped", flush=True)
                continue
            sections.append(f"| {name} | {picked[3]:.1f} | {picked[0]} |")
            if picked[3] <= 1.0:           # the cap's section: the reference's sweeps are this roof's
                if not folder.is_symlink() and not any(folder.iterdir()):
                    folder.rmdir()
                    folder.symlink_to(Path(args.stiff_sections).resolve() / name, target_is_directory=True)
            else:
                section = picked[1:3]
        project.write_text(project_text(path, name, 1.0, section), encoding="utf-8")
        lengths = length_levels(project, cells)
        project.write_text(project_text(path, name, lengths[len(lengths) // 2], section), encoding="utf-8")
        print(f"{name}: L_tot {lengths} m" + (f", {sections[-1]}" if section else ""), flush=True)
        for question, sweeps in questions_of(folder, project, lengths, seeds, asked).items():
            for sweep, parameters in sweeps.items():
                sweep_file = write_sweep(folder / question / sweep, project, parameters)
                try:
                    found = run_sweep(sweep_file, args.workers)
                except RuntimeError as error:
                    print(f"  {error}", flush=True)
                    found = [{"status": "failed", "message": str(error), **{k: v[0] for k, v in parameters.items()}}]
                for row in found:
                    row.update(surface=name, question=question, sweep=sweep, design=variant_of(question, sweep, row))
                    rows.append(row)
    frame = pd.DataFrame(rows)
    frame.to_csv(out / "study.csv", index=False)
    lines = []
    for question in asked:
        members = [r for r in rows if r["question"] == question]
        if question != "spacing":  # the default design and the control at the same L_tot come from spacing
            lengths = {(r["surface"], r["remesh.total_length"]) for r in members}
            members += [dict(r, question=question) for r in rows
                        if r["question"] == "spacing" and r["sweep"] == "voronoi"
                        and (r["surface"], r["remesh.total_length"]) in lengths]
        for line in summary(members):
            lines.append(dict(line, question=question))
    lines.sort(key=lambda r: (r["question"], r["surface"], r["L_tot_m"], r["design"]))
    unique = {(r["surface"], r["L_tot_m"], r["design"]): r for r in lines}  # the shared rows once
    text = "### verdicts (median over the seeds of lambda_NL_worst)\n\n" + verdicts(list(unique.values()))
    if sections:
        text = ("### sections (the default design's deflection over its limit at the cap's section, and the tube "
                "taken)\n\n| roof | delta / limit | section |\n|---|---|---|\n" + "\n".join(sections) + "\n\n" + text)
    text += "\n\n" + "\n\n".join(f"### {q}\n\n{markdown(lines, q)}" for q in asked)
    roofs_text, roofs = roof_table(lines, out)
    if roofs:
        text += "\n\n### roofs\n\n" + roofs_text
        pd.DataFrame(roofs).to_csv(out / "study_roofs.csv", index=False)
    (out / "study.md").write_text(text + "\n", encoding="utf-8")
    pd.DataFrame(lines).to_csv(out / "study_summary.csv", index=False)
    for path in [*plot_study(lines, out), plot_roofs(roofs, out)]:
        if path is not None:
            print(f"plot: {path}")
    print(text)
    print(f"\n{len(rows)} points, {sum(r.get('status') == 'ok' for r in rows)} ok, "
          f"{time.perf_counter() - started:.0f} s; {out / 'study.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
