"""The registered stages, in order.

Each stage module has ``run(<upstream results>, project, ctx) -> <its result>`` and
``load(folder, project) -> <its result>``; the upstream results are keyword arguments named after
the stages that made them (workflow.runner.Stage):

- surface: () -> surface.SurfaceResult
- shell: (surface) -> engine.structure.shell.ShellResult
- field: (surface, shell) -> engine.remeshing.field.GuidingField
- remesh: (surface, field) -> remesh.RemeshedGrid (the grid, and the field of its statics rounds)
- optimize: (surface, field, remesh) -> optimize.OptimizedGrid
- analysis: (surface, optimize) -> analysis.AnalysisSummary
- fabrication: (surface, optimize, analysis) -> fabrication.FabricationResult
- report: (surface, optimize, analysis, fabrication, and the files of every stage) -> report.ReportResult
"""

from __future__ import annotations

from ..runner import Stage
from . import analysis, fabrication, field, optimize, remesh, report, shell, surface

__all__ = ["STAGES", "stage_names"]

STAGES: list[Stage] = [
    Stage(name="surface", folder="01-surface", run=surface.run, load=surface.load, external=surface.external),
    Stage(name="shell", folder="02-shell", run=shell.run, load=shell.load, depends=("surface",)),
    Stage(name="field", folder="03-field", run=field.run, load=field.load, depends=("surface", "shell")),
    Stage(name="remesh", folder="04-remesh", run=remesh.run, load=remesh.load, depends=("surface", "field")),
    Stage(name="optimize", folder="05-optimize", run=optimize.run, load=optimize.load,
          depends=("surface", "field", "remesh")),
    Stage(name="analysis", folder="06-analysis", run=analysis.run, load=analysis.load,
          depends=("surface", "optimize")),
    Stage(name="fabrication", folder="07-fabrication", run=fabrication.run, load=fabrication.load,
          depends=("surface", "optimize", "analysis")),
    # the report reads every earlier stage's files (figures, JSON, CSV): all of them are in its key
    Stage(name="report", folder="report", run=report.run, load=report.load,
          depends=("surface", "shell", "field", "remesh", "optimize", "analysis", "fabrication"),
          takes=("surface", "optimize", "analysis", "fabrication"), published=report.published),
]


def stage_names() -> list[str]:
    return [s.name for s in STAGES]
