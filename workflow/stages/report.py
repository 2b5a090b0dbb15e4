"""Stage ``report``: one page that shows the whole job, ``OUT/report.html``.

The page is self-contained (opens offline) and there is one of it; its figures are also copied as
PNG to ``report/figures/`` and its tables written as CSV to ``report/tables/``. Figures and figures'
numbers are read from the earlier stages' artifacts, so the report never recomputes anything.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.findings import findings_table
from fabrication.files import atomic_path, write_bytes_atomic, write_text_atomic

from ..config import Project, SectionConfig
from ..labels import column_label, figure_rows, in_unit, label_of
from ..report import Figure, Section, Table, Viewer, figure_from_file, render_report
from ..runner import StageContext
from .analysis import AnalysisSummary
from .fabrication import FabricationResult
from .optimize import OptimizedGrid
from .sizing import profile_name
from .surface import SurfaceResult

__all__ = ["ReportResult", "run", "load"]


@dataclass(frozen=True, kw_only=True)
class ReportResult:
    """The report stage's result: where its page is (``OUT/report.html``)."""

    path: Path

FIGURES = {
    "surface": [("01-surface/surface.png", "The surface and its supports (red)")],
    "shell": [("02-shell/stress.png", "Principal membrane forces of the continuous shell: compression red, "
                                      "tension blue")],
    "field": [("03-field/field.png", "Guiding field: cell size and anisotropy with its direction")],
    "remesh": [("04-remesh/degree.png", "Remeshed grid-shell, cells by number of sides")],
    "optimize": [("05-optimize/degree.png", "Optimised grid-shell, cells by number of sides"),
                 ("05-optimize/planarity.png", "Optimised grid-shell, planarity of the cells")],
    "analysis": [("06-analysis/axial.png", "Axial forces (ULS): compression red, tension blue"),
                 ("06-analysis/utilisation.png", "Member utilisation (ULS)"),
                 ("06-analysis/sections.png", "Sized sections: each beam's tube from the catalogue"),
                 ("06-analysis/modes.png", "Linear buckling modes, coloured by displacement (each drawn at 8 % of "
                                           "the span), with their load factors"),
                 ("06-analysis/response.png", "Load factor against control-node deflection, worst imperfection bold; "
                  "dots: limit points, squares: the tolerable deflection reached first"),
                 ("06-analysis/loadtest.png", "Incremental load test: deflection of the control points")],
    "compare": [("compare/response.png", "Same-length comparison: response diagrams of the three grids")],
    "fabrication": [("07-fabrication/assembly/steps_strip.png", "Assembly sequence, from the supports inward"),
                    ("07-fabrication/panels/sheets.png", "Every stock sheet with its nested panels")],
}

#: Pictures of several panels, shown across the page's width.
WIDE = {"06-analysis/modes.png", "07-fabrication/assembly/steps_strip.png", "07-fabrication/panels/sheets.png"}


def _json(path: Path) -> dict:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def _figures(out_dir: Path, key: str) -> list[Figure]:
    figures = []
    for relative, caption in FIGURES.get(key, []):
        name = relative.replace("/", "-").removesuffix(".png")
        figure = figure_from_file(out_dir / relative, caption, name=name, wide=relative in WIDE)
        if figure is not None:
            figures.append(figure)
    return figures


def _csv_table(path: Path, name: str, caption: str, max_rows: int = 12, sort_by: str | None = None,
               drop_when_zero: tuple[str, ...] = ()) -> Table | None:
    """The first ``max_rows`` rows of a CSV (largest ``sort_by`` first), with human headings; the
    columns ``drop_when_zero`` are left out where every value is 0 (no figure, not a measured 0)."""
    import pandas as pd

    if not path.is_file():
        return None
    frame = pd.read_csv(path)
    frame = frame.drop(columns=[c for c in drop_when_zero if c in frame.columns and not frame[c].fillna(0).any()])
    if sort_by in frame.columns:
        frame = frame.sort_values(sort_by, ascending=False)
    shown = frame.head(max_rows)
    more = f" (first {max_rows} of {len(frame)})" if len(frame) > max_rows else ""
    return Table(name=name, caption=caption + more, columns=[column_label(str(c)) for c in shown.columns],
                 rows=shown.astype(object).where(shown.notna(), None).values.tolist())


def _pairs(name: str, caption: str, values: dict) -> Table:
    """A table of already-labelled items: [item, value]."""
    return Table(name=name, caption=caption, columns=["item", "value"], rows=[[k, v] for k, v in values.items()])


def _read_at(case: dict) -> str:
    """Where an imperfect path's load factor was read (analysis.json's imperfections)."""
    if case.get("limit_point"):
        return "limit point"
    if case.get("tolerable_deflection_reached"):
        return "tolerable deflection"
    return "highest carried" + ("" if case.get("path_complete", True) else " (path stopped early)")


def _figures_table(name: str, caption: str, values: dict, keys: tuple[str, ...] | None = None) -> Table:
    """A table of a stage's JSON figures: [figure, value, unit], labelled and in their units."""
    return Table(name=name, caption=caption, columns=["figure", "value", "unit"], rows=figure_rows(values, keys))


def _in_mm(value, limit, unit: str) -> tuple:
    """(value, limit, unit) with lengths in metres shown in millimetres."""
    if unit == "m":
        scale = lambda v: None if v is None else 1000 * float(v)  # noqa: E731
        return scale(value), scale(limit), "mm"
    return value, limit, unit


def findings_rows(findings: list[dict]) -> list[list]:
    """The report's findings table, a row per kind (engine.findings.findings_table): kind, count,
    worst, limit, unit, worst at, what, fix; lengths in millimetres, as in the verdicts."""
    return [[r["kind"].replace("_", " "), r["count"], *_in_mm(r["worst"], r["limit"], r["unit"]),
             ", ".join(r["worst_parts"]), r["message"], r["fix"]] for r in findings_table(findings)]


def section_text(section: SectionConfig) -> str:
    """The section as the job table gives it: its kind and dimensions in mm, in the order a
    designation reads them (a tube's D x t, a rectangle's h x b x t)."""
    return f"{section.kind} " + " x ".join(f"{1000 * v:g} mm" for v in section.dimensions().values())


def load_case_text(name: str, case, panel_weight_N_per_m2: float) -> str:
    """A project load case in a few words: "dead (beams' weight, panels 245 N/m^2, 250 N/m^2 per
    true area)"; an area load that is not downward as [qx, qy, qz]."""
    parts = []
    if case.self_weight:
        parts.append("beams' weight" + (f" x {case.self_weight:g}" if case.self_weight != 1 else ""))
    if case.panels and panel_weight_N_per_m2:
        parts.append(f"panels {case.panels * panel_weight_N_per_m2:.0f} N/m^2")
    for which, where in (("area_true", "per true area"), ("area_plan", "on plan")):
        qx, qy, qz = case.area_vector(which)
        if qx or qy:
            parts.append(f"[{qx:.0f}, {qy:.0f}, {qz:.0f}] N/m^2 {where}")
        elif qz:
            parts.append(f"{-qz:.0f} N/m^2 {where}")
    if case.points:
        parts.append(f"{len(case.points)} point load{'s' if len(case.points) > 1 else ''}")
    return f"{name} ({', '.join(parts) or 'no load'})"


def fitted_grid_text(fitted: dict) -> str:
    """The job table's line for OUT/fitted_grid.json (workflow.design_loop): the tube the grid was
    made for, and the tubes it was made for before."""
    rounds = fitted["rounds"]
    text = (f"{fitted['section']}: made again {'once' if len(rounds) == 1 else f'{len(rounds)} times'} for the "
            f"sized tubes ({' -> '.join([r['section_before'] for r in rounds] + [fitted['section']])})")
    return text if fitted.get("fits", True) else f"{text}; {fitted.get('largest_sized')} sized larger still"


def _summary(project: Project, surface: SurfaceResult, polymesh, analysis: dict, fabrication: FabricationResult,
             shell: dict, findings: list[dict], fitted: dict | None = None) -> Section:
    """The summary: verdicts, findings and the job's table; ``fitted``: OUT/fitted_grid.json where
    the grid was made again for the sized tubes (workflow.design_loop)."""
    supports = surface.supports
    weight = project.carried_panel_weight_N_per_m2
    loads = "; ".join(load_case_text(n, c, weight) for n, c in project.loads.cases.items()) or "-"
    combos = ", ".join(f"{n} ({c.limit_state.value})" for n, c in surface.combinations.items())
    values = {
        "project": project.project.name,
        "surface": surface.info.get("source", surface.mesh.name),
        "surface area (m^2)": float(surface.mesh.area),
        "supported vertices": int(len(supports.nodes)),
        "load cases": loads, "combinations": combos,
        "D (largest size ratio)": project.field.max_size_ratio,
        "A (largest aspect)": project.field.max_aspect,
        "material / section": f"{project.material.name} / {section_text(project.section)}"
                              + ("" if not analysis.get("design") else
                                 f"; sized from {analysis['design']['catalogue']}: "
                                 + ", ".join(g["profile"] for g in analysis["design"]["groups"])),
        **({"grid made for": fitted_grid_text(fitted)} if fitted and fitted.get("rounds") else {}),
        "nodes": polymesh.n_nodes, "beams": int(len(polymesh.edges)), "cells": polymesh.n_faces,
        "panels": "-" if fabrication.panels is None else fabrication.panels, "joints": fabrication.joints,
        "total beam length (m)": float(polymesh.total_length),
        "beam mass (kg)": analysis.get("beam_mass_kg"),
    }
    tables = [_pairs("summary", "The job", values)]
    verdicts = analysis.get("verdicts", [])
    if verdicts:
        rows = [[v.get("check"), *_in_mm(v.get("value"), v.get("limit"), v.get("unit", "")), bool(v.get("pass"))]
                for v in verdicts]
        tables.insert(0, Table(name="verdicts", caption="Verdicts",
                               columns=["check", "value", "limit", "unit", "result"],
                               rows=rows, verdict_column="result"))
    passed = all(bool(v.get("pass")) for v in verdicts) if verdicts else None
    text = {True: "Every structural check passes.",
            False: "At least one structural check fails: see the verdicts below.",
            None: "No structural verdicts (the analysis did not run)."}[passed]
    if passed is not None and project.loads.self_weight_only:
        if weight > 0:
            text += (f" The only loads are the grid-shell's own weight, its beams' and its panels' "
                     f"({weight:.0f} N/m^2; [loads] gives no other): finishes, snow and wind "
                     "are not in these verdicts.")
        else:
            text += (" The only load is the beams' own weight ([loads] gives no other): the panels, finishes, snow "
                     "and wind are not in these verdicts.")
    if findings:
        rows = findings_rows(findings)
        tables.insert(0, Table(name="findings", caption="Findings: failing checks and parts that cannot be built as "
                                                        "drawn (every file is still written)",
                               columns=["kind", "count", "worst", "limit", "unit", "worst at", "what", "fix"],
                               rows=rows))
        text = (f"{len(findings)} finding{'s' if len(findings) != 1 else ''}, listed first below. ") + text
    else:
        text = "No findings: every part can be built as drawn. " + text
    return Section(title="Summary", text=text, tables=tables)


#: The figures of a grid shown for the remesh and, before and after, for the optimisation.
GRID_KEYS = ("hexagon_share_interior", "valence3_share_interior", "size_correlation", "size_rank_correlation",
             "achieved_size_ratio",
             "achieved_max_aspect", "n_nodes", "n_beams", "n_faces", "total_length_m", "mean_beam_length_m",
             "shortest_beam_m", "smallest_angle_deg")
OPTIMIZE_KEYS = ("nonconvex_faces", "folded_cells", "regularity", "planarity_max_m", "planarity_p95_m",
                 "planarity_max_rel", "closeness_max_rel", "closeness_mean_rel", "closeness_max_beam_rel")


def _stage_sections(out_dir: Path, project: Project) -> list[Section]:
    shell = _json(out_dir / "02-shell/shell.json")
    field = _json(out_dir / "03-field/field.json")
    remesh = _json(out_dir / "04-remesh/remesh.json")
    optimize = _json(out_dir / "05-optimize/optimize.json")
    analysis = _json(out_dir / "06-analysis/analysis.json")
    cleaning = _json(out_dir / "01-surface/surface.json").get("cleaning") or {}
    sections = [Section(title="1. Surface and supports", figures=_figures(out_dir, "surface"),
                        text=" ".join(f"Cleaning: {note}." for note in cleaning.get("notes", [])))]
    shell_keys = ("load_case", "thickness_m", "max_displacement_m", "N1_max_N_per_m", "N2_min_N_per_m",
                  "total_load_N", "total_reaction_N", "equilibrium_error", "surface_triangles", "analysed_triangles")
    sections.append(Section(title="2. Shell statics", figures=_figures(out_dir, "shell"),
                            text=f"Analysed on {shell['analysed_on']}." if shell.get("analysed_on") else "",
                            tables=[_figures_table("shell", "Continuous shell under the serviceability load", shell,
                                                   shell_keys)]))
    sections.append(Section(title="3. Guiding field", figures=_figures(out_dir, "field"),
                            tables=([_figures_table("field", "Field against the bounds D and A", field)]
                                    if field else [])))
    remesh_rows = {k: remesh[k] for k in GRID_KEYS if k in remesh}
    title = "4. Statics-aware Voronoi remeshing" if "grid" not in remesh else f"4. Remeshing: {remesh['grid']} grid"
    sections.append(Section(title=title, figures=_figures(out_dir, "remesh"),
                            tables=[_figures_table("remesh", "Remeshing quality", remesh_rows)]))
    after = optimize.get("after", {})
    before = optimize.get("before", {})
    rows = []
    for key in (*GRID_KEYS, *OPTIMIZE_KEYS):
        if key in after and not isinstance(after[key], (dict, list)):
            label, unit, _ = label_of(key)
            rows.append([label, unit, in_unit(key, before.get(key)), in_unit(key, after[key])])
    sections.append(Section(title="5. Regular cells, planar panels", figures=_figures(out_dir, "optimize"),
                            tables=[Table(name="optimize", caption="Before and after the optimisation",
                                          columns=["figure", "unit", "remeshed", "optimised"], rows=rows)]
                            if rows else []))
    figure_keys = ("uls_combination", "sls_combination", "delta_L_m", "max_vertical_sls_m", "deflection_limit_m",
                   "max_utilisation", "governing_member", "lambda_LB", "lambda_NL_perfect", "lambda_NL_worst",
                   "worst_imperfection", "knock_down", "imperfection_amplitude_m", "tolerable_deflection_m",
                   "control_node", "beam_mass_kg", "equilibrium_error")
    tables = [_figures_table("analysis", "Beam grid-shell analysis", analysis, figure_keys)]
    imperfections = analysis.get("imperfections", [])
    if imperfections:
        tables.append(Table(name="imperfections", caption="Non-linear load factor per imperfection",
                            columns=["imperfection", "non-linear load factor", "read at"],
                            rows=[[i["shape"], i["lambda_NL"], _read_at(i)] for i in imperfections]))
    design = analysis.get("design")
    if design:
        tables.append(Table(name="design", caption=(
            f"Section sizing from {design['catalogue']}: {design['mass_before_kg']:,.0f} kg "
            f"with the project's section, {design['mass_after_kg']:,.0f} kg sized, {design['iterations']} analyses"
            + ("" if design["converged"] else f"; not settled: {design['reason']} ({design['failing_member']})")),
            columns=["profile", "beams", "length (m)", "mass (kg)", "largest utilisation", "governing check"],
            rows=[[g["profile"], g["beams"], round(g["length_m"], 1), round(g["mass_kg"], 1),
                   round(g["max_utilisation"], 3), g["governing"]] for g in design["groups"]]))
    members = _csv_table(out_dir / "06-analysis/members.csv", "members", "Most utilised members", sort_by="utilisation",
                         drop_when_zero=("section_class",))
    if members:
        tables.append(members)
    checks = analysis.get("checks") or {}
    checks_text = (f"Member checks: {checks['method']}. Checked: {'; '.join(checks['checked'])}. "
                   f"Not checked: {'; '.join(checks['not_checked'])}." if checks else "")
    sections.append(Section(title="6. Structural analysis", text=checks_text, figures=_figures(out_dir, "analysis"),
                            tables=tables,
                            links=[("members.csv", "06-analysis/members.csv"),
                                   ("response.csv", "06-analysis/response.csv"),
                                   ("analysis.json", "06-analysis/analysis.json")]))
    compare = _csv_table(out_dir / "compare/compare.csv", "compare", "Grids of the same total length", max_rows=20)
    if compare:
        sections.append(Section(title="7. Same-length comparison", figures=_figures(out_dir, "compare"),
                                tables=[compare], links=[("compare.md", "compare/compare.md")]))
    sections.append(_fabrication_section(out_dir))
    return [Section(title=f"{k}. {section.title.split('. ', 1)[-1]}", text=section.text, figures=section.figures,
                    tables=section.tables, links=section.links) for k, section in enumerate(sections, start=1)]


def _fabrication_section(out_dir: Path) -> Section:
    import pandas as pd

    folder = out_dir / "07-fabrication"
    tables: list[Table] = []
    cut = folder / "beams/cutlist.csv"
    if cut.is_file():
        frame = pd.read_csv(cut)
        group = frame.groupby("profile").agg(beams=("id", "count"),
                                             cut_length_m=("cut_length_mm", lambda s: s.sum() / 1000),
                                             mass_kg=("mass_kg", "sum")).reset_index()
        tables.append(Table(name="cutlist", caption="Cut list by profile",
                            columns=[column_label(c) for c in group.columns], rows=group.values.tolist()))
    fabrication = _json(folder / "fabrication.json")
    bars = {k: fabrication.get(k) for k in ("bars_used", "bars_lower_bound") if k in fabrication}
    if bars:
        tables.append(_figures_table("bars", "Bar nesting (stock bars used against the lower bound)", bars))
    panels = _csv_table(folder / "panels/panels.csv", "panels", "Panel schedule", max_rows=10)
    if panels:
        tables.append(panels)
    summary = {k: fabrication[k] for k in ("joints", "panels", "sheets", "sheet_utilisation") if k in fabrication}
    summary["joints_with_a_problem"] = len(fabrication.get("joint_problems", []))
    summary["joint_clashes"] = len(fabrication.get("joint_clashes", []))
    if "tube_clashes" in fabrication:
        summary["tube_clashes"] = len(fabrication["tube_clashes"])
    summary.update({k: v for k, v in fabrication.get("limits", {}).items()
                    if k in ("min_cut_length_mm", "min_angle_deg", "shortest_beam_mm_at_120deg")})
    if "shortest_cut_length_mm" in fabrication:
        summary["shortest_cut_length_mm"] = fabrication["shortest_cut_length_mm"]
    if any(fabrication.get("site_origin_m") or []):  # the files' frame (fabrication.site)
        summary["site_origin_m"] = ", ".join(f"{c:.0f}" for c in fabrication["site_origin_m"])
    tables.insert(0, _figures_table("fabrication", "Fabrication", summary))
    sequence = _csv_table(folder / "assembly/sequence.csv", "assembly", "Assembly sequence", max_rows=10)
    if sequence:
        tables.append(sequence)
    links = [(p.relative_to(out_dir).as_posix(), p.relative_to(out_dir).as_posix())
             for p in [folder / "beams/cutlist.csv", folder / "beams/cutlist.xlsx", folder / "beams/bars.csv",
                       folder / "beams/beams.step", folder / "panels/panels.csv", folder / "joints/joints.step",
                       folder / "assembly/sequence.csv", folder / "drawings/plan.pdf", folder / "drawings/plan.dxf",
                       folder / "gridshell.step", folder / "gridshell.3dm"] if p.is_file()]
    return Section(title="8. Fabrication", figures=_figures(out_dir, "fabrication"), tables=tables, links=links)


def _safe_name(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", text).strip("-") or "table"


def run(surface: SurfaceResult, optimize: OptimizedGrid, analysis: AnalysisSummary, fabrication: FabricationResult,
        project: Project, ctx: StageContext) -> ReportResult:
    """The page, from these results and the files of every earlier stage in ``ctx.out_dir``."""
    out_dir: Path = ctx.out_dir
    polymesh = optimize.polymesh
    shell = _json(out_dir / "02-shell/shell.json")
    ctx.step("collecting")
    # the record of the refits, where it is this run's: a later run without them leaves it behind
    fitted = _json(out_dir / "fitted_grid.json")
    summary = _summary(project, surface, polymesh, analysis.figures, fabrication, shell, ctx.earlier_findings,
                       fitted if fitted and fitted.get("section") == profile_name(project) else None)
    sections = _stage_sections(out_dir, project)
    axial = np.asarray(analysis.axial_forces, dtype=float)
    viewer = Viewer(nodes=polymesh.nodes, beams=polymesh.edges, panels=[p.loop for p in optimize.pieces],
                    supports=polymesh.supports,
                    beam_values=axial if len(axial) == len(polymesh.edges) else None,
                    beam_value_label="axial force (N), tension +")
    title = project.report.title or f"{project.project.name}: grid-shell design report"
    subtitle = project.project.description or "statics-aware Voronoi grid-shell, from the surface to shop drawings"
    ctx.step("writing")
    figures_dir, tables_dir = ctx.folder / "figures", ctx.folder / "tables"
    figures_dir.mkdir(parents=True, exist_ok=True)
    tables_dir.mkdir(parents=True, exist_ok=True)
    import pandas as pd

    for section in [summary, *sections]:
        for figure in section.figures:
            write_bytes_atomic(figures_dir / f"{figure.name}.png", figure.png)
        for table in section.tables:
            with atomic_path(tables_dir / f"{_safe_name(table.name)}.csv") as tmp:
                pd.DataFrame(table.rows, columns=table.columns).to_csv(tmp, index=False)
    page = render_report(title=title, subtitle=subtitle, summary=summary, sections=sections, viewer=viewer)
    # one page, at OUT/report.html, whose links are relative to OUT (a copy in the stage's own
    # folder had every link broken)
    write_text_atomic(out_dir / "report.html", page)
    return ReportResult(path=out_dir / "report.html")


def load(folder: Path, project: Project) -> ReportResult:
    return ReportResult(path=folder.parent / "report.html")  # folder is OUT/report
