"""Lattice grids in the remesh and optimize stages (``[remesh] grid`` = quad, quad45, triangular or
statics_quad): the reference grids of engine.remeshing.grids built for the project, made buildable
for their joints in the remesh stage as a Voronoi grid is (coarsened, short beams collapsed), and
passed through the optimiser unchanged (the optimiser's regularity and grading targets are a
Voronoi grid's; a lattice is already regular and planar where flat). ``gridshell compare``
analyses its lattices as laid out, at the Voronoi grid's length.

Artifacts as the Voronoi grid's: 04-remesh/gridshell.obj, remesh.json (with ``grid``, the length
asked for and how near it is), degree.png; 05-optimize/gridshell.obj (the same grid), panels.obj,
optimize.json (``grid``, ``optimised`` false, the same figures before and after), degree.png.
"""

from __future__ import annotations

import json

import numpy as np

from engine.mesh import PolyMesh
from engine.remeshing.field import GuidingField
from engine.remeshing.grids import (
    GridKind,
    lattice_total_length,
    quad45_grid,
    quad_grid,
    statics_quad_grid,
    triangular_grid,
)
from fabrication.files import write_text_atomic

from ..config import DEFAULT_CELLS, Project
from ..plots.remesh import plot_gridshell
from ..runner import StageContext
from .surface import SurfaceResult

__all__ = ["target_length", "build_lattice", "run_remesh", "run_optimize"]

#: how near a lattice comes to the length of n_cells or mean_beam_length (total_length: 1 %)
GUIDE_TOLERANCE = 0.1
#: what each lattice is called in titles and messages
NAMES = {GridKind.QUAD: "square", GridKind.QUAD45: "square, at 45 degrees", GridKind.TRIANGULAR: "triangular",
         GridKind.STATICS_QUAD: "statics-aware quad"}


def target_length(surface: SurfaceResult, project: Project) -> float:
    """The total beam length (m) the lattice is matched to: [remesh] total_length, else that of a
    regular lattice of n_cells cells or of beams mean_beam_length long (default DEFAULT_CELLS cells)."""
    config = project.remesh
    if config.total_length is not None:
        return float(config.total_length)
    if config.mean_beam_length is not None:
        return lattice_total_length(surface.mesh, config.grid, mean_beam_length=config.mean_beam_length)
    return lattice_total_length(surface.mesh, config.grid, n_cells=config.n_cells or DEFAULT_CELLS)


def build_lattice(surface: SurfaceResult, field: GuidingField, project: Project,
                  total_length: float | None = None) -> PolyMesh:
    """The project's lattice ([remesh] grid) with its target length (m, default target_length) matched
    within 1 % ([remesh] total_length) or GUIDE_TOLERANCE (a length from n_cells or mean_beam_length),
    supported at the boundary nodes near the surface's supports."""
    kind = GridKind(project.remesh.grid)
    length = target_length(surface, project) if total_length is None else total_length
    support_vertices = np.zeros(surface.mesh.n_vertices, dtype=bool)
    support_vertices[surface.supports.nodes] = True
    # a length from a cell count or a beam length is a guide: on a coarse grid whole rows are
    # several per cent of it
    options = {"total_length": length, "support_vertices": support_vertices,
               "tolerance": 0.01 if project.remesh.total_length is not None else GUIDE_TOLERANCE}
    if kind == GridKind.STATICS_QUAD:
        return statics_quad_grid(surface.mesh, field, **options)
    make = {GridKind.QUAD: quad_grid, GridKind.QUAD45: quad45_grid, GridKind.TRIANGULAR: triangular_grid}[kind]
    return make(surface.mesh, **options)


def run_remesh(surface: SurfaceResult, field: GuidingField, project: Project, ctx: StageContext) -> PolyMesh:
    """The remesh stage for a lattice: built, made buildable as a Voronoi grid is (coarsened where
    most beams are shorter than their joints take, unless [remesh] coarsen_for_joints is false,
    then its short beams flipped or collapsed, the lines cut short by the outline most of all;
    findings say so), written and measured (against the field too)."""
    from types import SimpleNamespace

    from engine.remeshing.grid_quality import polymesh_quality
    from engine.remeshing.local_global import ClosestSurfacePoints

    from .polymesh_io import write_polymesh_obj
    from .remesh import COARSEN_SHARE, buildable_grid, coarsened_finding, fitted_to_joints, too_fine_finding

    kind = GridKind(project.remesh.grid)
    length = target_length(surface, project)
    ctx.step(f"{NAMES[kind]} lattice of {length:.1f} m of beams")
    built = SimpleNamespace(polymesh=build_lattice(surface, field, project, length))
    asked, remeshes = project.remesh.n_cells or built.polymesh.n_faces, 0
    if project.remesh.coarsen_for_joints:
        def coarser(n_cells: int) -> SimpleNamespace:
            nonlocal length
            length = lattice_total_length(surface.mesh, kind, n_cells=n_cells)
            return SimpleNamespace(polymesh=build_lattice(surface, field, project, length))

        built, remeshes = fitted_to_joints(built, project, coarser, progress=ctx.step)
    if remeshes:
        ctx.report_findings([coarsened_finding(asked, built, project.section.size_key())])
    # no optimiser follows to lengthen them: every beam shorter than its joints take is collapsed or
    # flipped, up to the share that coarsening leaves (the lines the outline cuts short are many: a
    # quarter of the beams of a 5 m dome's square lattice of 80 cells, the lattice's own beams twice
    # as long as their joints take)
    ctx.step("collapsing beams shorter than the joints and the shortest cut take")
    closest = ClosestSurfacePoints(surface.mesh)
    polymesh, buildable = buildable_grid(built.polymesh, project, max_share=COARSEN_SHARE,
                                         normals=lambda points: closest.closest_normals(points)[1])
    if buildable["too_fine"]:
        ctx.report_findings([too_fine_finding(buildable, "remesh", project.section.size_key(), cells=polymesh.n_faces)])
    write_polymesh_obj(polymesh, ctx.folder / "gridshell.obj",
                       header=f"{project.project.name}: {NAMES[kind]} lattice grid-shell (remesh)")
    quality = polymesh_quality(polymesh, mesh=surface.mesh, field=field)
    quality.update({"grid": kind.value, "total_length_target_m": length,
                    "total_length_error": polymesh.total_length / length - 1.0, "buildable": buildable,
                    "coarsened": {"cells_asked": int(asked), "cells_built": int(polymesh.n_faces),
                                  "remeshes": remeshes}})
    write_text_atomic(ctx.folder / "remesh.json", json.dumps(quality, indent=1, default=float))
    ctx.step("drawing")
    plot_gridshell(polymesh, ctx.folder / "degree.png", color_by="degree",
                   title=f"{project.project.name}: {NAMES[kind]} lattice, cells by number of sides")
    return polymesh


def run_optimize(surface: SurfaceResult, field: GuidingField, remesh: PolyMesh, project: Project,
                 ctx: StageContext):
    """The optimize stage for a lattice: the grid goes through unchanged (optimize.json says so), with
    its panels (planar convex pieces of the cells that are not, as for any grid)."""
    from engine.remeshing.optimize import grid_quality

    from .optimize import OptimizedGrid, _piece_tolerance, panel_pieces_of, write_panels_obj
    from .polymesh_io import write_polymesh_obj
    from .remesh import grid_figures, short_count

    kind = GridKind(project.remesh.grid)
    ctx.step(f"the {NAMES[kind]} lattice is not optimised: written as built")
    polymesh = remesh
    write_polymesh_obj(polymesh, ctx.folder / "gridshell.obj",
                       header=f"{project.project.name}: {NAMES[kind]} lattice grid-shell (not optimised)")
    pieces = panel_pieces_of(polymesh, project)
    write_panels_obj(polymesh, pieces, ctx.folder / "panels.obj",
                     header=f"{project.project.name}: panels (cells, and planar pieces of the cells that are not)")
    figures = grid_quality(polymesh, surface.mesh, field)
    split = sorted({p.cell for p in pieces if p.piece})
    built = grid_figures(polymesh)
    quality = {"grid": kind.value, "optimised": False,
               "note": "a lattice grid goes through unchanged (made buildable in the remesh stage)",
               "before": figures, "after": figures,
               "buildable": {"collapsed_beams": 0, "flipped_beams": 0, "removed_beams": 0,
                             "short_beams_left": short_count(polymesh, project), **built},
               "panels": {"panels": len(pieces), "cells_split": len(split), "split_cells": [c + 1 for c in split],
                          "planar_panels": bool(project.optimize.planar),
                          "planarity_tolerance_m": _piece_tolerance(polymesh, project)},
               "shortest_beam_m": built["shortest_beam_m"], "smallest_beam_angle_deg": built["smallest_beam_angle_deg"]}
    write_text_atomic(ctx.folder / "optimize.json", json.dumps(quality, indent=1, default=float))
    ctx.step("drawing")
    plot_gridshell(polymesh, ctx.folder / "degree.png", color_by="degree",
                   title=f"{project.project.name}: {NAMES[kind]} lattice, cells by number of sides")
    return OptimizedGrid(polymesh=polymesh, pieces=pieces)
