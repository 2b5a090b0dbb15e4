"""Stage ``optimize``: regular, planar cells that stay on the surface.

Artifacts (05-optimize/): gridshell.obj (+ gridshell.nodes.json), optimize.json (planarity,
regularity, closeness before and after, the boundary cells split for planar panels and the new
beams, the end game's record, with the weights used) and pictures.
"""

from __future__ import annotations

import json
from pathlib import Path

import dataclasses

from fabrication.files import write_text_atomic

from ..config import Project
from ._require import require
from .polymesh_io import read_polymesh_obj, write_polymesh_obj
from .fabrication import build_limits_of
from .remesh import buildable_grid

#: The end game keeps beams this much above the shortest buildable beam between 120-degree joints.
MIN_LENGTH_MARGIN = 1.05
#: Rounds of (collapse the beams the optimiser left too short, optimise again).
BUILDABLE_ROUNDS = 2

__all__ = ["run", "load", "optimize_settings"]


def optimize_settings(project: Project):
    OptimizeSettings = require("optimize", "engine.optimize", "OptimizeSettings")
    c = project.optimize
    limits = build_limits_of(project)
    return OptimizeSettings(regularity_weight=c.regularity_weight, planarity_weight=c.planarity_weight,
                            closeness_weight=c.closeness_weight, fairness_weight=c.fairness_weight,
                            iterations=c.iterations, planar=c.planar, planarity_tolerance=c.planarity_tolerance,
                            planarity_iterations=c.planarity_iterations, split_cells=c.split_cells,
                            min_beam_length=MIN_LENGTH_MARGIN * limits.shortest_beam_mm() / 1000,
                            min_corner_angle_deg=max(20.0, MIN_LENGTH_MARGIN * limits.min_angle_deg))


def run(ctx):
    optimize, optimize_quality = require("optimize", "engine.optimize", "optimize", "optimize_quality")
    project: Project = ctx.project
    surface = ctx.result("surface")
    field = ctx.result("field")
    polymesh = ctx.result("remesh")
    ctx.step("local/global iterations and the planarity end game")
    settings = optimize_settings(project)
    result = optimize(polymesh, surface.mesh, field, settings, progress=ctx.step)
    # fabrication limits: collapse what the optimiser made too short, then optimise again
    grid, buildable = buildable_grid(result.polymesh, project)
    rounds, collapsed = 0, buildable["collapsed_beams"]
    while buildable["collapsed_beams"] and rounds < BUILDABLE_ROUNDS:
        rounds += 1
        ctx.step(f"{buildable['collapsed_beams']} short beams collapsed: optimising again ({rounds})")
        again = optimize(grid, surface.mesh, field, dataclasses.replace(settings, split_cells=False),
                         progress=ctx.step)
        result = dataclasses.replace(result, polymesh=again.polymesh,
                                     quality={**again.quality, "before": result.quality["before"]})
        grid, buildable = buildable_grid(again.polymesh, project)
        collapsed += buildable["collapsed_beams"]
    if buildable["collapsed_beams"]:  # the last collapse stands without a further optimisation
        result = dataclasses.replace(result, polymesh=grid)
        result.quality["after"].update(optimize_quality(grid, surface.mesh))
    buildable.update({"collapsed_beams": collapsed, "reoptimised": rounds})
    write_polymesh_obj(result.polymesh, ctx.folder / "gridshell.obj",
                       header=f"{project.project.name}: optimised grid-shell")
    quality = dict(result.quality)
    quality["buildable"] = buildable
    quality["shortest_beam_m"] = buildable["shortest_beam_m"]
    quality["smallest_beam_angle_deg"] = buildable["smallest_beam_angle_deg"]
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
