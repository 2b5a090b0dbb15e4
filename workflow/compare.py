"""``gridshell compare PROJECT``: Voronoi, quad and triangular grids of the same total length.

The thesis's comparison (METHOD.md section 5): the project's Voro(D, A) grid-shell (from the
optimize stage, run or reused from the project's output folder) sets L_tot; a triangular and
a quadrilateral grid of the same L_tot (within 1 %) are built on the same surface with the
same supports, section and loads; each goes through the structural protocol (LS, LB, GNL with
every imperfection). Writes OUT/compare/: compare.csv, compare.md, response.png and each
grid as a polygon OBJ.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.loads import combine
from engine.mesh import PolyMesh
from fabrication.files import atomic_path, write_text_atomic

from .config import Project, check_inputs, load_project
from .progress import Progress

__all__ = ["GridRow", "compare_grids", "run_compare", "markdown_table"]

COLUMNS = ["grid", "nodes", "beams", "L_tot_m", "weight_kg", "delta_L_mm", "lambda_LB", "lambda_NL_perfect",
           "lambda_NL_worst", "worst_shape", "limit_point", "knock_down"]


@dataclass(frozen=True, kw_only=True)
class GridRow:
    """One grid's line in the comparison table and its response curves."""

    values: dict
    curves: dict[str, np.ndarray]
    worst: str | None


def _protocol(polymesh: PolyMesh, surface, project: Project, progress, executor=None) -> GridRow:
    from engine.protocol import ProtocolSettings, run_protocol
    from engine.structure import gridshell_loads

    from .stages.analysis import beam_properties, build_frame, pick_combination

    config = project.analysis
    props, _, _ = beam_properties(project)
    model, supports, _ = build_frame(polymesh, surface, props, config.elements_per_beam)
    loads = {}
    for state in ("SLS", "ULS"):
        case = combine(surface.load_cases, pick_combination(project, surface, state))
        loads[state] = gridshell_loads(polymesh, case, mass_per_length=props.mass_per_length,
                                       surface_vertices=surface.mesh.vertices)
    span = float(np.ptp(polymesh.nodes[:, :2], axis=0).min())
    settings = ProtocolSettings(n_modes=config.n_modes, amplitude=config.imperfection_amplitude or span / 300.0,
                                shapes=tuple(config.imperfection_shapes), nonlinear=config.nonlinear,
                                max_load_factor=config.max_load_factor)
    result = run_protocol(model, supports, loads["SLS"], loads["ULS"], settings, progress=progress, executor=executor)
    worst = result.worst
    values = {"nodes": polymesh.n_nodes, "beams": int(len(polymesh.edges)), "L_tot_m": polymesh.total_length,
              "weight_kg": polymesh.total_length * props.mass_per_length, "delta_L_mm": 1000 * result.delta_L,
              "lambda_LB": result.lambda_LB,
              "lambda_NL_perfect": None if result.perfect is None else result.perfect.capacity,
              "lambda_NL_worst": None if worst is None else worst.capacity,
              "limit_point": None if worst is None else worst.limit_load_factor is not None,
              "worst_shape": None if worst is None else worst.name, "knock_down": result.knock_down}
    curves = {}
    if result.perfect is not None:
        curves["perfect"] = np.asarray(result.perfect.path)
    if worst is not None:
        curves[f"worst ({worst.name})"] = np.asarray(worst.path)
    return GridRow(values=values, curves=curves, worst=None if worst is None else worst.name)


def compare_grids(project: Project, surface, voronoi: PolyMesh, *, progress=None) -> dict[str, tuple[PolyMesh, GridRow]]:
    """The three grids of equal total length and their protocol results, keyed by grid name."""
    from engine.grids import quad_grid, triangular_grid

    def say(text: str) -> None:
        if progress is not None:
            progress(text, None)

    support_vertices = np.zeros(surface.mesh.n_vertices, dtype=bool)
    support_vertices[surface.supports.nodes] = True
    length = voronoi.total_length
    name = f"Voro({project.field.max_size_ratio:g},{project.field.max_aspect:g})"
    say("building the triangular grid")
    tri = triangular_grid(surface.mesh, total_length=length, support_vertices=support_vertices)
    say("building the quad grid")
    quad = quad_grid(surface.mesh, total_length=length, support_vertices=support_vertices)
    from .stages.analysis import path_pool

    out = {}
    config = project.analysis
    with path_pool(config.workers if config.nonlinear else 1) as pool:  # each grid's paths side by side
        for label, grid in (("triangular", tri), ("quad", quad), (name, voronoi)):
            say(f"analysing the {label} grid")
            out[label] = (grid, _protocol(grid, surface, project, lambda text, fraction=None: say(f"{label}: {text}"),
                                          executor=pool))
    return out


def markdown_table(rows: list[dict]) -> str:
    """A GitHub-style Markdown table of the comparison rows."""
    def cell(value) -> str:
        if value is None:
            return "-"
        if isinstance(value, float):
            return f"{value:.4g}"
        return str(value)

    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(cell(row.get(c)) for c in COLUMNS) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def run_compare(args: argparse.Namespace) -> int:
    """The CLI verb: run (or reuse) the project up to optimize, then compare the three grids."""
    import pandas as pd

    from .runner import run_project
    from .stages import STAGES
    from .stages.polymesh_io import write_polymesh_obj

    project_path = Path(args.project)
    project = load_project(project_path)
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
    voronoi = _load_stage(project, out_dir, "optimize")
    progress.stage_start("compare")
    results = compare_grids(project, surface, voronoi, progress=progress.step)
    folder = out_dir / "compare"
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    curves = {}
    for label, (grid, row) in results.items():
        rows.append({"grid": label, **row.values})
        for name, path in row.curves.items():
            curves[f"{label}: {name}"] = path
        write_polymesh_obj(grid, folder / f"{_file_name(label)}.obj", header=f"{project.project.name}: {label} grid")
    frame = pd.DataFrame(rows, columns=COLUMNS)
    with atomic_path(folder / "compare.csv") as tmp:
        frame.to_csv(tmp, index=False, float_format="%.6g")
    text = (f"# Same-length comparison: {project.project.name}\n\nTotal beam length of the Voronoi grid: "
            f"{rows[-1]['L_tot_m']:.3f} m; the other grids match it within 1 %.\n\n" + markdown_table(rows))
    write_text_atomic(folder / "compare.md", text)
    if curves:
        from .plots.analysis import plot_response

        worst_curves = [k for k in curves if "worst" in k]
        plot_response(curves, folder / "response.png", worst=worst_curves[0] if worst_curves else None,
                      required=project.analysis.required_load_factor,
                      title=f"{project.project.name}: grids of equal length")
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

    class _Context:
        def __init__(self) -> None:
            self.project, self.out_dir = project, out_dir
            self.folder = out_dir / stage.folder

        def result(self, other: str):
            return _load_stage(project, out_dir, other)

        def step(self, *_args) -> None:
            pass

    return stage.load(out_dir / stage.folder, _Context())
