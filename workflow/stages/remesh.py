"""Stage ``remesh``: the statics-aware Voronoi grid-shell (anisotropic CVT under the field's metric).

Artifacts (04-remesh/): gridshell.obj (+ gridshell.nodes.json), remesh.json (quality
figures) and pictures coloured by face degree. With ``[remesh] statics_rounds`` N > 1 the field
is rebuilt N - 1 times from the grid's own beam forces and the surface remeshed under it
(remeshed_from_beam_forces): remesh.json gains the rounds, field_round_N.npz holds the last field
(the one the grid was made under, which the optimiser follows: ``RemeshedGrid.field``) and
field_round_N.png shows it.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.findings import Finding
from engine.geometry.symmetry import symmetrised_grid, symmetry_record
from engine.mesh import PolyMesh, TriMesh
from engine.parts import node_id
from engine.remeshing.collapse import CollapseReport, Normals, collapse_short_beams
from engine.remeshing.field import GuidingField, guiding_field
from engine.remeshing.grid_quality import polymesh_quality
from engine.remeshing.grids import LATTICES, GridKind, isotropic_field
from engine.remeshing.voronoi import DegenerateTessellation, RemeshResult, RemeshSettings, StartsMap, remesh
from engine.structure.grid_model import node_normals
from engine.structure.grid_stress import surface_membrane_forces
from fabrication.files import write_text_atomic
from fabrication.limits import node_smallest_angles, required_beam_lengths_m

from ..config import Project
from ..plots.field import plot_field
from ..plots.remesh import plot_gridshell
from ..pools import process_pool
from ..runner import StageContext
from . import lattice
from .build_limits import build_limits_of
from .field import load_field, save_field
from .polymesh_io import read_polymesh_obj, write_polymesh_obj
from .surface import SurfaceResult

__all__ = ["RemeshedGrid", "run", "load", "remesh_settings", "buildable_grid", "remeshed_from_beam_forces"]


@dataclass(frozen=True)
class RemeshedGrid:
    """The remesh stage's result: the grid, and the field it was made under where statics rounds
    rebuilt that field from the grid's beam forces (``rounds_field``; None: the field stage's)."""

    polymesh: PolyMesh
    rounds_field: GuidingField | None = None

    def field(self, field_stage: GuidingField) -> GuidingField:
        """The field the grid was made under, given the field stage's."""
        return field_stage if self.rounds_field is None else self.rounds_field


def run(surface: SurfaceResult, field: GuidingField, project: Project, ctx: StageContext) -> RemeshedGrid:
    grid = GridKind(project.remesh.grid)
    if grid in LATTICES:  # squares, triangles, the statics-aware quads: .lattice
        return RemeshedGrid(lattice.run_remesh(surface, field, project, ctx))
    with process_pool(project.remesh.workers) as pool:  # a small grid's starts side by side
        return _voronoi(surface, field, project, ctx, grid, None if pool is None else pool.map)


def _voronoi(surface: SurfaceResult, field: GuidingField, project: Project, ctx: StageContext, grid: GridKind,
             starts_map: StartsMap | None) -> RemeshedGrid:
    """The run of a Voronoi grid (the statics-aware one or its isotropic control)."""
    if grid == GridKind.ISOTROPIC:  # the control: the same remesher under a uniform field
        field = isotropic_field(field)
    support_vertices = np.zeros(surface.mesh.n_vertices, dtype=bool)
    support_vertices[surface.supports.nodes] = True
    settings = remesh_settings(project)
    made_buildable = buildable_as_remeshed(project)
    result = remesh(surface.mesh, field, settings, support_vertices=support_vertices, progress=ctx.step,
                    buildable=made_buildable, starts_map=starts_map)
    rounds: list[dict] = []
    if grid == GridKind.VORONOI:  # the control stays uniform: its field is not the forces'
        result, field, rounds = remeshed_from_beam_forces(result, field, surface, project, ctx, starts_map)
    asked, remeshes = settings.n_cells or result.polymesh.n_faces, 0
    if project.remesh.coarsen_for_joints:
        result, remeshes = fitted_to_joints(
            result, project,
            lambda n: remesh(surface.mesh, field, dataclasses.replace(settings, n_cells=n, mean_beam_length=None,
                                                                      total_length=None),
                             support_vertices=support_vertices, progress=ctx.step, buildable=made_buildable,
                             starts_map=starts_map),
            progress=ctx.step)
    if remeshes:
        ctx.report_findings([coarsened_finding(asked, result, project.section.size_key())])
    ctx.step("collapsing beams far shorter than the joints and the shortest cut take")
    polymesh, buildable = buildable_grid(result.polymesh, project, share=REMESH_SHARE)
    planes = settings.symmetry_planes
    if planes:  # the collapses keep mirror orbits only nearly
        symmetric = symmetrised_grid(polymesh, planes)
        polymesh = symmetric if np.all(np.isfinite(symmetric.nodes)) else polymesh
    write_polymesh_obj(polymesh, ctx.folder / "gridshell.obj",
                       header=f"{project.project.name}: statics-aware Voronoi grid-shell (remesh)")
    quality = dict(result.quality)
    for key in ("clustering_s", "extraction_s"):  # seconds go into the manifest, not the artifact
        ctx.timings[key.removesuffix("_s")] = round(float(quality.pop(key, 0.0)), 3)
    if buildable["collapsed_beams"] or buildable["flipped_beams"]:  # the figures of the grid as written
        quality.update(polymesh_quality(polymesh, mesh=surface.mesh, field=field))
    quality["buildable"] = buildable
    columns = column_nodes(surface, polymesh)
    if columns:
        quality["columns"] = columns
    quality["coarsened"] = {"cells_asked": int(asked), "cells_built": int(polymesh.n_faces), "remeshes": remeshes}
    quality.update({"max_size_ratio_D": project.field.max_size_ratio, "max_aspect_A": project.field.max_aspect})
    if rounds:
        quality["statics_rounds"] = rounds
    if planes:  # of the grid as written
        quality["symmetry"] = symmetry_record(polymesh.nodes, planes, float(polymesh.beam_lengths.mean()))
        if not quality["symmetry"]["symmetric"]:
            ctx.report_findings([asymmetric_finding(quality["symmetry"], surface.mesh)])
    if grid != GridKind.VORONOI:  # recorded where set: the default grid's remesh.json is as before
        quality["grid"] = grid.value
    write_text_atomic(ctx.folder / "remesh.json", json.dumps(quality, indent=1, default=float))
    ctx.step("drawing")
    plot_gridshell(polymesh, ctx.folder / "degree.png", color_by="degree",
                   title=f"{project.project.name}: remeshed grid-shell, cells by number of sides")
    return RemeshedGrid(polymesh, field if rounds else None)


def remesh_settings(project: Project) -> RemeshSettings:
    """The engine's remesh settings of [remesh], the grid made symmetric about [field] symmetry_planes."""
    return project.remesh.to_settings(project.field.to_settings().symmetry_planes)


def remeshed_from_beam_forces(result: RemeshResult, field: GuidingField, surface: SurfaceResult, project: Project,
                              ctx: StageContext, starts_map: StartsMap | None = None
                              ) -> tuple[RemeshResult, GuidingField, list[dict]]:
    """(result, field, rounds): with ``[remesh] statics_rounds`` N > 1, N - 1 times the field rebuilt
    from the last grid's beam forces (linear analysis under the ULS combination, as the analysis
    stage builds it; engine.structure.grid_stress) with the project's field settings, and the surface
    remeshed under it with the same size target. rounds (JSON-ready, empty for N = 1): per round
    the grid's total length (m), cells and size rank correlation with the field it was made under
    (round 1: the shell's). The last round's field is written as field_round_N.npz and drawn as
    field_round_N.png."""
    count = project.remesh.statics_rounds
    if count <= 1:
        return result, field, []
    # the analysis stage imports the optimiser's, which imports this module: imported here
    from .analysis import linear_axial_forces

    mesh = surface.mesh
    support_vertices = np.zeros(mesh.n_vertices, dtype=bool)
    support_vertices[surface.supports.nodes] = True
    settings, field_settings = remesh_settings(project), project.field.to_settings()
    rounds = [_round_figures(1, result)]
    for number in range(2, count + 1):
        grid = result.polymesh
        ctx.step(f"statics round {number} of {count}: beam forces of the {grid.n_faces}-cell grid")
        axial = linear_axial_forces(grid, surface, project)
        forces = surface_membrane_forces(mesh, grid, axial, node_normals(grid, mesh))
        field = guiding_field(mesh, forces, field_settings)
        ctx.step(f"statics round {number} of {count}: remeshing under the field of the beam forces")
        result = remesh(mesh, field, settings, support_vertices=support_vertices, progress=ctx.step,
                        buildable=buildable_as_remeshed(project), starts_map=starts_map)
        rounds.append(_round_figures(number, result))
        ctx.step(f"statics round {number} of {count}: {rounds[-1]['cells']} cells, "
                 f"{rounds[-1]['total_length_m']:.1f} m of beams")
    save_field(field, ctx.folder / f"field_round_{count}.npz")
    plot_field(mesh, field, ctx.folder / f"field_round_{count}.png",
               title=f"{project.project.name}: guiding field of round {count} (beam forces of round {count - 1})")
    return result, field, rounds


def _round_figures(number: int, result: RemeshResult) -> dict:
    """One statics round's figures (JSON-ready)."""
    return {"round": number, "field": "shell" if number == 1 else "beam forces",
            "total_length_m": float(result.polymesh.total_length), "cells": int(result.polymesh.n_faces),
            "size_rank_correlation": result.quality.get("size_rank_correlation")}


#: The remesh removes only beams under this share of their buildable length: the optimiser, which
#: holds beams to that length, lengthens the others with less change to the cells.
REMESH_SHARE = 0.5
#: Collapse short beams only while they are at most this share of the grid: beyond it the joints
#: are too big for the grid, and collapsing would unmake it (a finding says so instead).
MAX_COLLAPSE_SHARE = 0.2


#: Remesh with fewer cells while more than this share of the beams is shorter than its joints take:
#: the optimiser makes buildable grids of up to about a third short beams (the hypar at 60 cells,
#: 33 %), not of two thirds (a wave at 300 cells, 64 %); none was seen in between.
COARSEN_SHARE = 0.4
#: ... aiming at this share (the cell count from the beams' length to required-length ratios).
COARSEN_TARGET = 0.25
#: The most remeshes with fewer cells.
COARSEN_ATTEMPTS = 4
#: ... and the fewest cells they ask for: the remesher makes 7 of 7 on a 5 m dome, 3 of 5 and
#: none of 4 (glulam 200 x 160 on steel nodes asked for 4). Fewer would not make the joints fit
#: either; the grid_too_fine finding says so.
MIN_COARSENED_CELLS = 7


def fitted_to_joints(result: RemeshResult, project: Project, remesh_with: Callable[[int], RemeshResult],
                     progress: Callable[[str], None] | None = None) -> tuple[RemeshResult, int]:
    """(result, remeshes): ``result``, or the remesh with fewer cells (``remesh_with(n_cells)``) when more than
    COARSEN_SHARE of its beams are shorter than their joints and the shortest cut take. The count
    scales the beams by the ratio that leaves COARSEN_TARGET of them short (beam lengths go as
    1/sqrt(cells)); at most COARSEN_ATTEMPTS remeshes, each with at most 90 % of the cells before."""
    limits = build_limits_of(project)
    remeshes = 0
    for _ in range(COARSEN_ATTEMPTS):
        grid = result.polymesh
        ratio = required_beam_lengths_m(grid, limits) / np.maximum(grid.beam_lengths, 1e-12)
        if not len(ratio) or np.mean(ratio > 1.0) <= COARSEN_SHARE or grid.n_faces <= MIN_COARSENED_CELLS:
            break
        scale = float(np.quantile(ratio, 1.0 - COARSEN_TARGET))
        n_cells = max(MIN_COARSENED_CELLS, min(int(grid.n_faces / scale ** 2), int(0.9 * grid.n_faces)))
        if progress is not None:
            progress(f"{100 * np.mean(ratio > 1.0):.0f} % of the beams shorter than their joints take: "
                     f"remeshing with {n_cells} cells")
        try:
            result, remeshes = remesh_with(n_cells), remeshes + 1
        except DegenerateTessellation:  # the coarsest grid made stands, its beams too short (a finding)
            break
    return result, remeshes


def coarsened_finding(asked: int, result: RemeshResult, size_key: str = "[section] diameter") -> dict:
    """The finding that the grid has fewer cells than asked, so that its joints fit (JSON-ready)."""
    built = result.polymesh.n_faces
    return Finding(kind="grid_coarsened", parts=["grid"], measure=built, limit=asked, unit="cells",
                   stage="remesh",
                   message=(f"remeshed with {built} cells instead of {asked}: at {asked} cells most beams were "
                            "shorter than their joints and the shortest cut take"),
                   fix="smaller joints ([fabrication.joints] kind, hub_radius, sleeve_length) or a smaller beam "
                       f"({size_key}) for more cells; [remesh] coarsen_for_joints = false keeps the "
                       "cells asked for, with joints that clash").to_dict()


def buildable_as_remeshed(project: Project) -> Callable[[PolyMesh], PolyMesh]:
    """The grid as this stage makes it buildable (buildable_grid at REMESH_SHARE): the remesher
    compares its candidate grids as such, so that one whose short beams would be collapsed (each
    collapse costs two hexagons and a three-beam node) loses to one that needs none."""
    return lambda grid: buildable_grid(grid, project, share=REMESH_SHARE)[0]


def buildable_grid(polymesh: PolyMesh, project: Project, share: float = 1.0, *,
                   normals: Normals | None = None, max_share: float = MAX_COLLAPSE_SHARE) -> tuple[PolyMesh, dict]:
    """(grid, record): ``polymesh`` with every beam shorter than ``share`` times what its joints and
    the shortest cut take flipped or collapsed where a valid flip or collapse exists
    (engine.remeshing.collapse); the record (JSON-ready) has the limits, the collapses and flips, the
    shortest beam and the smallest angle between two beams at a node. When more than ``max_share``
    of the beams are short, nothing is changed and ``too_fine`` is set. ``normals``: the surface's
    unit normals at points, along which no flip or collapse may fold a cell."""
    limits = build_limits_of(project)
    short = short_beams(polymesh, project)
    too_fine = bool(short.mean() > max_share) if len(short) else False
    if too_fine:
        grid, report = polymesh, CollapseReport(collapsed=0, passes=0, left=np.flatnonzero(short))
    else:
        grid, report = collapse_short_beams(polymesh, lambda g: share * required_beam_lengths_m(g, limits),
                                            normals=normals)
    record = {**limits.to_dict(), **report.to_dict(), "too_fine": too_fine, "removed_under_share": share,
              "short_share_before": float(short.mean()) if len(short) else 0.0,
              **grid_figures(grid)}
    return grid, record


def grid_figures(grid: PolyMesh) -> dict:
    """The shortest and mean beam (m) and the smallest angle between two beams at a node (deg)."""
    return {"shortest_beam_m": float(grid.beam_lengths.min()) if len(grid.edges) else 0.0,
            "mean_beam_m": float(grid.beam_lengths.mean()) if len(grid.edges) else 0.0,
            "smallest_beam_angle_deg": float(np.degrees(node_smallest_angles(grid).min()))}


def short_beams(polymesh: PolyMesh, project: Project) -> np.ndarray:
    """(n_beams,) whether each beam of ``polymesh`` is shorter than its joints and the shortest cut take."""
    return polymesh.beam_lengths < required_beam_lengths_m(polymesh, build_limits_of(project))


def short_count(polymesh: PolyMesh, project: Project) -> int:
    """Beams of ``polymesh`` shorter than their joints and the shortest cut take."""
    return int(short_beams(polymesh, project).sum())


def short_share(polymesh: PolyMesh, project: Project) -> float:
    """Share of the beams of ``polymesh`` shorter than their joints and the shortest cut take."""
    return short_count(polymesh, project) / max(len(polymesh.edges), 1)


def too_fine_finding(record: dict, stage: str, size_key: str = "[section] diameter", cells: int | None = None) -> dict:
    """The finding that the joints are too big for the grid (JSON-ready). ``cells``: the grid's,
    where at MIN_COARSENED_CELLS or fewer the fix no longer offers fewer cells (the roof is too small
    for its joints at any count)."""
    fewest = cells is not None and cells <= MIN_COARSENED_CELLS
    return Finding(kind="grid_too_fine", parts=["grid"], measure=record["shortest_beam_mm_at_120deg"],
                   limit=1000 * record["mean_beam_m"], unit="mm", stage=stage,
                   message=(f"{100 * record['short_share_before']:.0f} % of the beams are shorter than the joints "
                            f"and the shortest cut take ({record['shortest_beam_mm_at_120deg']:.0f} mm between "
                            f"120-degree joints, the mean beam is {1000 * record['mean_beam_m']:.0f} mm): "
                            "they are not collapsed" + (f"; the grid has {cells} cells, the fewest the remesher "
                                                         "makes for its joints" if fewest else "")),
                   fix=("" if fewest else "fewer cells ([remesh] n_cells), ") + f"a smaller beam ({size_key}) or "
                       "smaller joints ([fabrication.joints] kind, hub_radius, sleeve_length)").to_dict()


def column_nodes(surface: SurfaceResult, polymesh: PolyMesh) -> list[dict]:
    """Each support inside the surface (a column under the roof) with the grid node that stands on
    it (numbered as in the remeshed grid's OBJ) and how far that node is from it (JSON-ready; empty
    without columns): the remesher moves the node onto the column where that is under COLUMN_SNAP
    of its shortest beam and folds no cell, else the node stays where the cells put it."""
    from engine.remeshing.cell_extraction import column_points, inside_supports

    held = np.zeros(surface.mesh.n_vertices, dtype=bool)
    held[surface.supports.nodes] = True
    points = column_points(surface.mesh, inside_supports(surface.mesh, held,
                                                         np.flatnonzero(surface.mesh.boundary_vertices)))
    inside = np.flatnonzero(polymesh.supports & ~polymesh.boundary)
    if not len(points) or not len(inside):
        return []
    distance = np.linalg.norm(points[:, None, :] - polymesh.nodes[inside][None, :, :], axis=2)
    nearest = distance.argmin(axis=1)
    return [{"column_m": [float(c) for c in p], "node": node_id(int(inside[k])), "offset_m": float(distance[i, k])}
            for i, (p, k) in enumerate(zip(points, nearest))]


def asymmetric_finding(record: dict, mesh: TriMesh) -> dict:
    """The finding that the grid came out without the symmetry [field] symmetry_planes ask for
    (``record``: symmetry_record of the grid): the remesher mirrors the surface's mesh vertex by
    vertex, so a symmetric surface meshed otherwise (or symmetric only roughly) gets a grid of its
    own (JSON-ready)."""
    from engine.geometry.symmetry import mirror_gap

    planes = [(p["point"], p["normal"]) for p in record["planes"]]
    worst = int(np.argmax(record["deviation"]))
    gap = mirror_gap(mesh.vertices, planes[worst])
    return Finding(kind="grid_not_symmetric", parts=["grid"], measure=float(record["deviation"][worst]),
                   limit=float(record["tolerance"]), unit="mean beams", stage="remesh",
                   message=(f"the grid is not symmetric about [field] symmetry_planes[{worst}]: a node's mirror image "
                            f"lies {record['deviation'][worst]:.2f} mean beams from a node. The surface's mesh is "
                            f"not its own mirror image vertex by vertex (a vertex's lies {gap:.3g} m from a "
                            "vertex), which the remesher needs"),
                   fix="mesh the surface symmetrically (mirror one half of it in the modeller), or remove "
                       "[field] symmetry_planes").to_dict()


def load(folder: Path, project: Project) -> RemeshedGrid:
    count = project.remesh.statics_rounds
    rounds_field = folder / f"field_round_{count}.npz"
    return RemeshedGrid(read_polymesh_obj(folder / "gridshell.obj"),
                        load_field(rounds_field) if count > 1 and rounds_field.is_file() else None)
