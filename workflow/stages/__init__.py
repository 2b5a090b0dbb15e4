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

import importlib
from collections.abc import Callable
from typing import Any

from ..runner import Stage

__all__ = ["STAGES", "stage_names"]


def _later(module: str, function: str) -> Callable[..., Any]:
    """``workflow.stages.<module>.<function>``, its module imported at the first call: a run whose
    stages are all cached imports none of their libraries (pandas, OCP, scipy ...; 0.9 s of the
    default job's cached run, which has a 2 s target)."""

    def target() -> Callable[..., Any]:
        return getattr(importlib.import_module(f"{__name__}.{module}"), function)

    def call(*args: Any, **kwargs: Any) -> Any:
        return target()(*args, **kwargs)

    call.__name__ = call.__qualname__ = f"{module}.{function}"
    call.target = target  # type: ignore[attr-defined]  # the function itself, for its signature
    return call


def _stage(name: str, folder: str, **options: Any) -> Stage:
    return Stage(name=name, folder=folder, run=_later(name, "run"), load=_later(name, "load"), **options)


STAGES: list[Stage] = [
    _stage("surface", "01-surface", external=_later("surface", "external")),
    _stage("shell", "02-shell", depends=("surface",)),
    _stage("field", "03-field", depends=("surface", "shell")),
    _stage("remesh", "04-remesh", depends=("surface", "field")),
    _stage("optimize", "05-optimize", depends=("surface", "field", "remesh")),
    _stage("analysis", "06-analysis", depends=("surface", "optimize")),
    _stage("fabrication", "07-fabrication", depends=("surface", "optimize", "analysis")),
    # the report reads every earlier stage's files (figures, JSON, CSV): all of them are in its key
    _stage("report", "report", depends=("surface", "shell", "field", "remesh", "optimize", "analysis", "fabrication"),
           takes=("surface", "optimize", "analysis", "fabrication"), published=("report.html",)),
]


def stage_names() -> list[str]:
    return [s.name for s in STAGES]
