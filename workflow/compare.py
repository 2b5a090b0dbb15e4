"""``gridshell compare PROJECT``: Voronoi, quad and triangular grids of the same total length.

The thesis's comparison (METHOD.md section 5): the project's Voro(D, A) grid-shell (from the
optimize stage, run or reused from the project's output folder) sets L_tot; the other grids of
the same L_tot (within 1 %) are built on the same surface with the same supports, section and
loads: triangular, quad (squares along the plan's principal axes), quad45 (at 45 degrees to
them), "statics quad" (squares along the guiding field's dominant direction, lines graded by
its size: engine.remeshing.grids.statics_quad_grid) and "isotropic" (the same Voronoi remesher under a
uniform field, Voro(1,1): the control that differs only in statics-awareness). Each goes
through the structural protocol (LS, LB, GNL with every imperfection). ``--grids`` picks the
rows (default: all). The lattices and the isotropic grid are analysed as built, not optimised;
the Voronoi row is the optimised grid (for a control that goes through the optimiser too, sweep
``"remesh.grid" = ["voronoi", "isotropic"]`` with a ``[remesh] total_length``). Writes
OUT/compare/: compare.csv, compare.md, response.png and each grid as a polygon OBJ.

With ``[design] size_sections = true`` (or ``--size-sections``) each grid's tubes are sized as
``gridshell run`` sizes them, and the rows also say what each topology weighs when it passes:
the engineer's same-weight question beside the thesis's same-length one.

A grid that cannot be built on the surface, or whose protocol ends in a user error (a
``GridshellError``: a mechanism, a path that does not converge, a surface that is not a height
field), is a ``failed`` row whose message says why and what to do; the other grids are compared
all the same and the command exits 0 with the table.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.errors import ConvergenceError, GridshellError, InputError
from engine.mesh import PolyMesh
from engine.remeshing.field import GuidingField
from fabrication.files import atomic_path, write_text_atomic

from .config import Project, check_inputs, load_project
from .progress import Progress

__all__ = ["GridRow", "GRIDS", "compare_grids", "failure_message", "run_compare", "markdown_table"]

#: the grids compare can build (``--grids``), in the table's order; "voronoi" is the project's grid
GRIDS = ("triangular", "quad", "quad45", "statics_quad", "isotropic", "voronoi")
#: row labels where they differ from the names
_LABELS = {"statics_quad": "statics quad"}

COLUMNS = ["grid", "nodes", "beams", "L_tot_m", "weight_kg", "delta_L_mm", "lambda_LB", "lambda_NL_perfect",
           "lambda_NL_worst", "worst_shape", "limit_point", "knock_down", "status", "message", "sized_mass_kg",
           "sized_tubes", "max_utilisation", "all_checks_pass"]

#: what to do when an error comes without a hint of its own, by what failed
_FIXES = {"built": "check the surface in gridshell validate PROJECT, or change remesh.n_cells",
          "analysed": "check the supports and the section; gridshell run PROJECT analyses the Voronoi grid alike"}


@dataclass(frozen=True, kw_only=True)
class GridRow:
    """One grid's line in the comparison table and its response curves; ``status`` "ok" or
    "failed", with ``message`` (one line: what failed, why and what to do) when failed."""

    values: dict
    curves: dict[str, np.ndarray]
    worst: str | None
    status: str = "ok"
    message: str = ""
    ends: dict[str, tuple[str, float]] = dataclasses.field(default_factory=dict)  # per curve, as plot_response's


def failure_message(label: str, what: str, error: GridshellError) -> str:
    """One line for a failed grid: "``label`` grid not ``what``: reason; fix" (the error's hint,
    else a fix for what failed: ``what`` is "built" or "analysed")."""
    reason = " ".join(str(error.args[0] if error.args else type(error).__name__).split())
    fix = error.hint
    if what == "built" and isinstance(error, ConvergenceError):
        # the target is the Voronoi grid's length, not the user's to choose
        fix = "the Voronoi grid sets the target length: more cells (remesh.n_cells) make it longer"
    fix = " ".join((fix or _FIXES[what]).split())
    return f"{label} grid not {what}: {reason}; {fix}"


def _grid_values(polymesh: PolyMesh, mass_per_length: float) -> dict:
    return {"nodes": polymesh.n_nodes, "beams": int(len(polymesh.edges)), "L_tot_m": polymesh.total_length,
            "weight_kg": polymesh.total_length * mass_per_length}


class _Steps:
    """The ``ctx.step`` the analysis's helpers call, passing on to compare's progress."""

    def __init__(self, progress) -> None:
        self._progress = progress

    def step(self, text: str, fraction: float | None = None) -> None:
        if self._progress is not None:
            self._progress(text, fraction)


def _protocol(polymesh: PolyMesh, surface, project: Project, progress, executor=None) -> GridRow:
    """The protocol on one grid; with ``[design] size_sections`` its tubes are sized first, as in
    ``gridshell run``, and the row gains the sized mass, its tubes and the member checks."""
    from .stages.analysis import beam_properties, pick_combination, protocol_with_design
    from .stages.sizing import checks_method, project_sections, sized_checks

    config = project.analysis
    props, _, material = beam_properties(project)
    sections = project_sections(project, len(polymesh.edges))
    method = checks_method(project, material) if sections is not None else "simplified"
    span = float(np.ptp(polymesh.nodes[:, :2], axis=0).min())
    settings = config.to_settings(span)
    combos = (pick_combination(project, surface, "ULS"), pick_combination(project, surface, "SLS"))
    run = protocol_with_design(_Steps(progress), project, polymesh, surface, material, method, sections, combos,
                               span / config.deflection_limit_ratio, settings, executor=executor)
    result = run.result
    worst = result.worst
    values = {**_grid_values(polymesh, props.mass_per_length), "delta_L_mm": 1000 * result.delta_L,
              "lambda_LB": result.lambda_LB,
              "lambda_NL_perfect": None if result.perfect is None else result.perfect.capacity,
              "lambda_NL_worst": None if worst is None else worst.capacity,
              "limit_point": None if worst is None else worst.limit_load_factor is not None,
              "worst_shape": None if worst is None else worst.name, "knock_down": result.knock_down}
    if run.design is not None:
        lengths = polymesh.beam_lengths
        checks = sized_checks(project, method, run.sections, material, result, lengths)
        names, counts = np.unique(run.sections.names, return_counts=True)
        deflection = float(np.abs(result.sls_displacements[:, 2]).max())
        passes = (checks.utilisation.max() <= 1.0 and deflection <= span / config.deflection_limit_ratio
                  and all(v is None or v >= config.required_load_factor
                          for v in (result.lambda_LB, values["lambda_NL_worst"])))
        values.update({"sized_mass_kg": float((lengths * run.props.mass_per_length).sum()),
                       "sized_tubes": " / ".join(f"{n} x{c}" for n, c in zip(names, counts)),
                       "max_utilisation": float(checks.utilisation.max()), "all_checks_pass": bool(passes)})
    curves, ends = {}, {}
    for name, case in (("perfect", result.perfect), (f"worst ({worst.name})" if worst else "", worst)):
        if case is None:
            continue
        curves[name] = np.asarray(case.path)
        if case.read_at != "carried":
            ends[name] = (case.read_at, case.capacity)
    return GridRow(values=values, curves=curves, worst=None if worst is None else worst.name, ends=ends)


def compare_grids(project: Project, surface, voronoi: PolyMesh, *, field: GuidingField | None = None,
                  grids: tuple[str, ...] | None = None,
                  progress=None) -> dict[str, tuple[PolyMesh | None, GridRow]]:
    """The grids of equal total length and their protocol results, keyed by row label
    (triangular, quad, quad45, statics quad, isotropic, Voro(...)); ``grids`` names the rows
    (GRIDS, default all); statics quad and isotropic need the guiding ``field``. A grid that
    cannot be built is (None, failed row); one whose protocol raises a GridshellError is (grid,
    failed row with its size); any other exception is a bug and propagates."""
    from engine.remeshing import grids as lattices

    from .pools import process_pool
    from .stages.analysis import beam_properties

    def say(text: str) -> None:
        if progress is not None:
            progress(text, None)

    asked = GRIDS if grids is None else tuple(grids)
    unknown = sorted(set(asked) - set(GRIDS))
    if unknown:
        raise InputError(f"compare: no grid called {unknown[0]!r}", hint=f"the grids are {', '.join(GRIDS)}")
    support_vertices = np.zeros(surface.mesh.n_vertices, dtype=bool)
    support_vertices[surface.supports.nodes] = True
    length = voronoi.total_length
    name = _project_label(project)

    def isotropic(mesh, *, total_length, support_vertices):
        from engine.remeshing.voronoi import RemeshSettings, remesh

        settings = RemeshSettings(total_length=total_length, lloyd_iterations=project.remesh.lloyd_iterations,
                                  seed=project.remesh.seed)
        grid = remesh(mesh, lattices.isotropic_field(_needed(field)), settings,
                      support_vertices=support_vertices).polymesh
        if abs(grid.total_length / total_length - 1) >= 0.01:
            raise ConvergenceError(f"the isotropic remesh reached {grid.total_length:.2f} m of beams, not "
                                   f"{total_length:.2f} m within 1 %")
        return grid

    makers = {"triangular": lambda *a, **k: lattices.triangular_grid(*a, **k),
              "quad": lambda *a, **k: lattices.quad_grid(*a, **k),
              "quad45": lambda *a, **k: lattices.quad45_grid(*a, **k),
              "statics_quad": lambda mesh, **k: lattices.statics_quad_grid(mesh, _needed(field), **k),
              "isotropic": isotropic}
    built: dict[str, PolyMesh | None] = {}
    out: dict[str, tuple[PolyMesh | None, GridRow]] = {}
    for key in (g for g in GRIDS if g in asked and g != "voronoi"):
        label = _LABELS.get(key, key)
        say(f"building the {label} grid")
        try:
            built[label] = makers[key](surface.mesh, total_length=length, support_vertices=support_vertices)
        except GridshellError as error:
            built[label] = None
            out[label] = (None, GridRow(values={}, curves={}, worst=None, status="failed",
                                        message=failure_message(label, "built", error)))
    grids = built
    if "voronoi" in asked:
        grids[name] = voronoi
    mass_per_length = beam_properties(project)[0].mass_per_length
    config = project.analysis
    with process_pool(config.workers if config.nonlinear else 1) as pool:  # each grid's paths side by side
        for label, grid in grids.items():
            if grid is None:
                continue
            say(f"analysing the {label} grid")
            try:
                row = _protocol(grid, surface, project, lambda text, fraction=None: say(f"{label}: {text}"),
                                executor=pool)
            except GridshellError as error:
                row = GridRow(values=_grid_values(grid, mass_per_length), curves={}, worst=None, status="failed",
                              message=failure_message(label, "analysed", error))
            out[label] = (grid, row)
    return {label: out[label] for label in grids}


def _needed(field: GuidingField | None) -> GuidingField:
    if field is None:
        raise InputError("this grid is made from the guiding field, and none was given",
                         hint="run the project's field stage (gridshell run PROJECT --to field)")
    return field


def _project_label(project: Project) -> str:
    """The project's own row: Voro(D,A), or its [remesh] grid where that is not the Voronoi grid."""
    grid = str(getattr(project.remesh.grid, "value", project.remesh.grid))
    if grid == "voronoi":
        return f"Voro({project.field.max_size_ratio:g},{project.field.max_aspect:g})"
    return f"project ({_LABELS.get(grid, grid)})"


def parse_grids(text: str | None) -> tuple[str, ...]:
    """The ``--grids`` option: a comma list of GRIDS (None or empty: all of them)."""
    if not text:
        return GRIDS
    names = tuple(dict.fromkeys(n.strip() for n in text.split(",") if n.strip()))
    unknown = [n for n in names if n not in GRIDS]
    if unknown or not names:
        raise InputError(f"--grids: no grid called {(unknown or [text])[0]!r}",
                         hint=f"a comma list of {','.join(GRIDS)}")
    return names


def markdown_table(rows: list[dict]) -> str:
    """A GitHub-style Markdown table of the comparison rows."""
    def cell(value) -> str:
        if value is None or value == "":
            return "-"
        if isinstance(value, float):
            return f"{value:.4g}"
        return str(value).replace("|", "\\|")

    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(cell(row.get(c)) for c in COLUMNS) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def run_compare(args: argparse.Namespace) -> int:
    """The CLI verb: run (or reuse) the project up to optimize, then compare the grids of ``--grids``."""
    import pandas as pd

    from .runner import run_project
    from .stages import STAGES
    from .stages.polymesh_io import write_polymesh_obj

    project_path = Path(args.project)
    project = load_project(project_path)
    asked = parse_grids(getattr(args, "grids", None))
    if getattr(args, "size_sections", False):
        if project.section.kind != "circular_hollow":
            from .config import ConfigError

            raise ConfigError(f"--size-sections sizes tubes, but [section] kind = \"{project.section.kind}\"",
                              hint='set [section] kind = "circular_hollow", or leave out --size-sections')
        project = project.model_copy(update={"design": project.design.model_copy(update={"size_sections": True})})
    check_inputs(project)  # what validate checks, before any stage runs
    out_dir = Path(args.out) if args.out else Path("out") / project_path.stem
    progress = Progress(enabled=not args.quiet)
    progress.message(f"gridshell compare: {project.project.name} -> {out_dir / 'compare'}")
    summary = run_project(project, out_dir, STAGES, until="optimize", progress=progress,
                          project_file=str(project_path.resolve()))
    if summary.message:
        print(f"stopped: {summary.message}", file=sys.stderr)
        return 1
    surface = _load_stage(project, out_dir, "surface")
    voronoi = _load_stage(project, out_dir, "optimize").polymesh
    field = _load_stage(project, out_dir, "field") if {"isotropic", "statics_quad"} & set(asked) else None
    progress.stage_start("compare")
    results = compare_grids(project, surface, voronoi, field=field, grids=asked, progress=progress.step)
    folder = out_dir / "compare"
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    curves: dict[str, np.ndarray] = {}
    ends: dict[str, tuple[str, float]] = {}
    for label, (grid, row) in results.items():
        rows.append({"grid": label, **row.values, "status": row.status, "message": row.message})
        for name, path in row.curves.items():
            curves[f"{label}: {name}"] = path
            if name in row.ends:
                ends[f"{label}: {name}"] = row.ends[name]
        obj = folder / f"{_file_name(label)}.obj"
        if grid is not None:
            write_polymesh_obj(grid, obj, header=f"{project.project.name}: {label} grid")
        else:
            obj.unlink(missing_ok=True)  # not an older run's grid beside this run's table
    frame = pd.DataFrame(rows, columns=COLUMNS)
    with atomic_path(folder / "compare.csv") as tmp:
        frame.to_csv(tmp, index=False, float_format="%.6g")
    failed = [row for row in rows if row["status"] != "ok"]
    text = (f"# Same-length comparison: {project.project.name}\n\nTotal beam length of the project's grid: "
            f"{voronoi.total_length:.3f} m; the other grids {'built ' if failed else ''}match it within 1 %.\n\n"
            + markdown_table(rows))
    if failed:
        text += "\nNot compared:\n\n" + "".join(f"- {row['message']}\n" for row in failed)
    write_text_atomic(folder / "compare.md", text)
    from .plots.analysis import plot_response

    worst_curves = [k for k in curves if "worst" in k]
    not_analysed = ", ".join(row["grid"] for row in failed)
    plot_response(curves, folder / "response.png", worst=worst_curves[0] if worst_curves else None, ends=ends,
                  required=project.analysis.required_load_factor,
                  title=f"{project.project.name}: grids of equal length"
                        + (f" ({not_analysed}: failed, see compare.md)" if failed else ""))
    for row in failed:
        print(f"compare: {row['message']}", file=sys.stderr)
    progress.stage_done("compare", "ran", 0.0)
    if (out_dir / "report").is_dir():
        # the project's report was made before: make it again so that it shows the comparison
        run_project(project, out_dir, STAGES, only="report", force=True, progress=progress,
                    project_file=str(project_path.resolve()))
    print(markdown_table(rows))
    print(f"comparison: {(folder / 'compare.md').resolve()}")
    return 0


def _file_name(label: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in label).strip("_").lower()


def _load_stage(project: Project, out_dir: Path, name: str):
    from .stages import STAGES

    stage = next(s for s in STAGES if s.name == name)
    return stage.load(out_dir / stage.folder, project)
