"""The registered stages, in order. Each stage module has ``run(ctx)`` and ``load(folder, ctx)``."""

from __future__ import annotations

import importlib

from ..runner import Stage, StageNotAvailable

__all__ = ["STAGES", "stage_names"]

_ORDER = [
    # name, folder, depends
    ("surface", "01-surface", ()),
    ("shell", "02-shell", ("surface",)),
    ("field", "03-field", ("surface", "shell")),
    ("remesh", "04-remesh", ("surface", "field")),
    ("optimize", "05-optimize", ("surface", "field", "remesh")),
    ("analysis", "06-analysis", ("surface", "optimize")),
    ("fabrication", "07-fabrication", ("surface", "optimize", "analysis")),
    ("report", "report", ("surface", "shell", "field", "remesh", "optimize", "analysis", "fabrication")),
]


def _not_available(name: str):
    def run(ctx):
        raise StageNotAvailable(f"stage '{name}' is not available in this version of gridshell; "
                                f"the run stopped before it (results up to the previous stage are in {ctx.out_dir})")

    def load(folder, ctx):
        raise StageNotAvailable(f"stage '{name}' is not available in this version of gridshell")

    return run, load


def _build() -> list[Stage]:
    stages = []
    for name, folder, depends in _ORDER:
        try:
            module = importlib.import_module(f"{__name__}.{name}")
            run, load = module.run, module.load
            external = getattr(module, "external", None)
            published = tuple(getattr(module, "published", ()))
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
            (run, load), external, published = _not_available(name), None, ()
        stages.append(Stage(name=name, folder=folder, run=run, load=load, depends=depends, external=external,
                            published=published))
    return stages


STAGES: list[Stage] = _build()


def stage_names() -> list[str]:
    return [s.name for s in STAGES]
