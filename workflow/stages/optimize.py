"""Stage ``optimize``: regular, planar cells that stay on the surface.

Artifacts (05-optimize/): gridshell.obj (+ gridshell.nodes.json), optimize.json (planarity,
regularity, closeness before and after, the boundary cells split for planar panels and the new
beams, the end game's record, with the weights used) and pictures.
"""

from __future__ import annotations

import json
from pathlib import Path

from fabrication.files import write_text_atomic

from ..config import Project
from ._require import require
from .polymesh_io import read_polymesh_obj, write_polymesh_obj

__all__ = ["run", "load", "optimize_settings"]


def optimize_settings(project: Project):
    OptimizeSettings = require("optimize", "engine.optimize", "OptimizeSettings")
    c = project.optimize
    return OptimizeSettings(regularity_weight=c.regularity_weight, planarity_weight=c.planarity_weight,
                            closeness_weight=c.closeness_weight, fairness_weight=c.fairness_weight,
                            iterations=c.iterations, planar=c.planar, planarity_tolerance=c.planarity_tolerance,
                            planarity_iterations=c.planarity_iterations, split_cells=c.split_cells)


def run(ctx):
    optimize = require("optimize", "engine.optimize", "optimize")
    project: Project = ctx.project
    surface = ctx.result("surface")
    field = ctx.result("field")
    polymesh = ctx.result("remesh")
    ctx.step("local/global iterations and the planarity end game")
    result = optimize(polymesh, surface.mesh, field, optimize_settings(project), progress=ctx.step)
    write_polymesh_obj(result.polymesh, ctx.folder / "gridshell.obj",
                       header=f"{project.project.name}: optimised grid-shell")
    quality = dict(result.quality)
    quality["weights"] = project.optimize.model_dump(mode="json")
    write_text_atomic(ctx.folder / "optimize.json", json.dumps(quality, indent=1, default=float))
    ctx.step("drawing")
    from ..plots.remesh import plot_gridshell

    plot_gridshell(result.polymesh, ctx.folder / "planarity.png", color_by="planarity",
                   title=f"{project.project.name}: optimised grid-shell, planarity of the cells")
    plot_gridshell(result.polymesh, ctx.folder / "degree.png", color_by="degree",
                   title=f"{project.project.name}: optimised grid-shell, cells by number of sides")
    return result.polymesh


def load(folder: Path, ctx):
    return read_polymesh_obj(folder / "gridshell.obj")
