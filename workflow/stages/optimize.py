"""Stage ``optimize``: regular, planar cells that stay on the surface.

Artifacts (05-optimize/): gridshell.obj (+ gridshell.nodes.json), optimize.json (planarity,
regularity, closeness before and after, the boundary cells split for planar panels and the new
beams, the end game's record, with the weights used) and pictures.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from engine.findings import Finding
from engine.geometry.projections import CellFans, folded_cells, unfolded
from engine.geometry.symmetry import symmetrised_grid, symmetry_record
from engine.mesh import PolyMesh, neighbour_lists, node_adjacency
from engine.remeshing.collapse import (
    collapse_beams,
    dissolve_kinks,
    flip_defects,
    open_narrow_joints,
    remove_short_beams,
)
from engine.remeshing.field import GuidingField
from engine.remeshing.grids import LATTICES, GridKind, isotropic_field
from engine.remeshing.local_global import ClosestSurfacePoints
from engine.remeshing.openings import OPENING_KEPT, Opening, openings
from engine.remeshing.optimize import OptimizeResult, OptimizeSettings, grid_quality, optimize
from fabrication.files import write_text_atomic
from fabrication.ids import joint_id, panel_id
from fabrication.limits import required_beam_lengths_m

from ..config import Project
from ..plots.remesh import plot_gridshell
from ..runner import StageContext
from . import lattice
from .build_limits import build_limits_of
from .polymesh_io import read_polymesh_obj, write_polymesh_obj
from .remesh import (
    MAX_COLLAPSE_SHARE,
    RemeshedGrid,
    buildable_grid,
    grid_figures,
    short_count,
    short_share,
    too_fine_finding,
)
from .surface import SurfaceResult

if TYPE_CHECKING:  # engine.remeshing.panel_pieces imports shapely: loaded where panels are made or read
    from engine.remeshing.panel_pieces import PanelPiece

#: The end game keeps beams this much above the shortest buildable beam between 120-degree joints.
MIN_LENGTH_MARGIN = 1.05
#: A cell's regularity target is stretched at most this much beyond the field's aspect bound A.
STRETCH_MARGIN = 1.5
#: Above this share of beams left too short for their joints with the field's grading kept, the
#: optimiser tries again with the sizes evened out (engine.remeshing.optimize.OptimizeSettings.keep_grading).
GRADED_SHORT_SHARE = 0.02
#: A grading slope lowered by more than this for the joints is a finding (grading_compressed).
COMPRESSED_SLOPE = 0.05
#: A size rank correlation with the field lower than the remeshed grid's by more than this, where
#: the field is graded (GRADED_SPAN at the cells) and no other grading finding says why, is a
#: finding (grading_lost): issue 13's bound on what the optimiser may cost the grading.
GRADING_LOST = 0.1
GRADED_SPAN = 1.3
#: Rounds of (collapse the beams the optimiser left too short, optimise again).
BUILDABLE_ROUNDS = 2
#: Rounds of (remove the beams still short, collapse those the removals freed) at the end.
LAST_RESORT_ROUNDS = 5
#: After collapses and flips the grid is optimised again within this many beams of the nodes they
#: changed; the rest, optimised already, is held where it is.
REOPTIMISED_RINGS = 3

__all__ = ["OptimizedGrid", "run", "load", "optimize_settings", "panel_pieces_of", "write_panels_obj",
           "read_panels_obj", "onto_surface"]


@dataclass(frozen=True, kw_only=True)
class OptimizedGrid:
    """The optimize stage's result: the grid-shell (05-optimize/gridshell.obj) and its panels'
    pieces (05-optimize/panels.obj), in panel order: each cell, or the planar convex pieces of a
    cell that is not planar."""

    polymesh: PolyMesh
    pieces: list[PanelPiece]


def optimize_settings(project: Project) -> OptimizeSettings:
    """The engine's optimiser settings of [optimize], holding the grid to its joints (with the end
    game's margin), its cells to the field's aspect bound (with STRETCH_MARGIN) and its nodes
    symmetric about [field] symmetry_planes."""
    limits = build_limits_of(project)
    settings = project.optimize.to_settings(min_beam_length_mm=MIN_LENGTH_MARGIN * limits.shortest_beam_mm(),
                                            min_corner_angle_deg=max(20.0, MIN_LENGTH_MARGIN * limits.min_angle_deg),
                                            max_cell_stretch=STRETCH_MARGIN * project.field.max_aspect)
    return dataclasses.replace(settings, symmetry_planes=project.field.to_settings().symmetry_planes)


def beam_length_limits(project: Project):
    """grid -> (n_beams,) shortest buildable length of each beam (m) at its joints' angles, with the
    end game's margin: what the optimiser holds the beams to."""
    limits = build_limits_of(project)
    return lambda grid: MIN_LENGTH_MARGIN * required_beam_lengths_m(grid, limits)


def _unsettled(result: OptimizeResult) -> bool:
    """Whether an optimisation stopped at a step that left the reals (the engine then keeps the last
    finite grid) or ended with a grid that is not finite."""
    return bool(result.quality.get("stopped_non_finite")) or not np.all(np.isfinite(result.polymesh.nodes))


def _optimised(grid: PolyMesh, surface: SurfaceResult, field: GuidingField, settings: OptimizeSettings,
               limits, ctx: StageContext, held: np.ndarray | None = None) -> tuple[OptimizeResult, OptimizeSettings]:
    """(result, settings used): ``grid`` optimised (``held`` nodes held where they are), and again
    without the symmetry planes where the symmetric optimisation did not settle (optimize.json's
    symmetry record measures what is left)."""
    result = optimize(grid, surface.mesh, field, settings, progress=ctx.step, beam_length_limits=limits, held=held)
    if settings.symmetry_planes and _unsettled(result):
        ctx.step("the symmetric optimisation did not settle: optimising without the symmetry planes")
        settings = dataclasses.replace(settings, symmetry_planes=())
        result = optimize(grid, surface.mesh, field, settings, progress=ctx.step, beam_length_limits=limits,
                          held=held)
    return result, settings


def changed_region(before: PolyMesh, after: PolyMesh, rings: int = REOPTIMISED_RINGS) -> np.ndarray:
    """(after.n_nodes,) bool: the nodes of ``after`` within ``rings`` beams of a node that the
    collapses and flips from ``before`` moved, made or reconnected (a node is the same node where it
    lies at the same point with the same neighbours)."""
    distance, match = cKDTree(before.nodes).query(after.nodes)
    same = distance <= 1e-9 * max(float(before.beam_lengths.mean()), 1e-300)
    old_id = np.where(same, match, -1)

    old, new = neighbour_lists(before.edges, before.n_nodes), neighbour_lists(after.edges, after.n_nodes)
    changed = ~same
    for i in np.flatnonzero(same):
        changed[i] = sorted(old_id[new[i]].tolist()) != sorted(old[old_id[i]])
    adjacency = node_adjacency(after.edges, after.n_nodes)
    region = changed
    for _ in range(rings):
        region = region | (adjacency @ region.astype(float) > 0)
    return region


def run(surface: SurfaceResult, field: GuidingField, remesh: RemeshedGrid, project: Project,
        ctx: StageContext) -> OptimizedGrid:
    grid = GridKind(project.remesh.grid)
    if grid in LATTICES:  # a lattice is not a grid of Voronoi cells: it goes through as built
        return lattice.run_optimize(surface, field, remesh.polymesh, project, ctx)
    if grid == GridKind.ISOTROPIC:  # the control is held to uniform cells, not to the field's grading
        field = isotropic_field(field)
    polymesh = remesh.polymesh
    field = remesh.field(field)  # statics rounds: the field the grid was made under
    settings = optimize_settings(project)
    defects = 0
    if not settings.symmetry_planes:  # (a flip on one side of a plane would break the mirror)
        polymesh, defects = flip_defects(polymesh)
    ctx.step("local/global iterations and the planarity end game")
    limits = beam_length_limits(project)
    result, settings = _optimised(polymesh, surface, field, settings, limits, ctx)
    grading_kept, share_kept = True, short_share(result.polymesh, project)
    share = share_kept
    if share_kept > GRADED_SHORT_SHARE:
        # the field's smallest cells are too small for the joints: let the sizes even out, and keep
        # whichever grid leaves fewer beams short (a finding says what it cost)
        ctx.step(f"{100 * share_kept:.0f} % of the beams too short for the joints at the field's grading: "
                 "optimising with the sizes evened out")
        even = optimize(polymesh, surface.mesh, field, dataclasses.replace(settings, keep_grading=False),
                        progress=ctx.step, beam_length_limits=limits)
        share_even = short_share(even.polymesh, project)
        if share_even < share_kept:
            result, grading_kept, settings = even, False, dataclasses.replace(settings, keep_grading=False)
            share = share_even
    if share > MAX_COLLAPSE_SHARE:
        # too fine for its joints even when held to their lengths, which then unmake the cells:
        # optimised free of them instead (the grid_too_fine finding below says so)
        ctx.step("the grid is too fine for its joints: optimising without their lengths")
        limits = None
        settings = dataclasses.replace(settings, min_beam_length=0.0)
        result = optimize(polymesh, surface.mesh, field, settings, progress=ctx.step)
    # fabrication limits: collapse what the optimiser made too short, then optimise again
    closest = ClosestSurfacePoints(surface.mesh)

    def normals(points: np.ndarray) -> np.ndarray:
        return closest.closest_normals(points)[1]

    grid, buildable = buildable_grid(result.polymesh, project, normals=normals)
    rounds, collapsed, flipped = 0, buildable["collapsed_beams"], buildable["flipped_beams"]

    def changed(record: dict) -> int:
        return record["collapsed_beams"] + record["flipped_beams"]

    def reoptimised(result, grid, record: dict, when: str):
        """``result`` with ``grid`` (after ``record``'s collapses and flips) optimised again."""
        ctx.step(f"{record['collapsed_beams']} short beams collapsed, {record['flipped_beams']} flipped: "
                 f"optimising {when}")
        # round the changes only (with symmetry planes all of it: the mirror pairs move together)
        held = None if settings.symmetry_planes else ~changed_region(result.polymesh, grid)
        grid = onto_surface(grid, changed_region(result.polymesh, grid, rings=0), closest)
        again, _ = _optimised(grid, surface, field, dataclasses.replace(settings, split_cells=False), limits, ctx,
                              held=held)
        return dataclasses.replace(result, polymesh=again.polymesh, quality={
            **again.quality, "before": result.quality["before"], "grading": result.quality.get("grading")})

    while changed(buildable) and rounds < BUILDABLE_ROUNDS:
        rounds += 1
        result = reoptimised(result, grid, buildable, f"again ({rounds})")
        grid, buildable = buildable_grid(result.polymesh, project, normals=normals)
        collapsed += buildable["collapsed_beams"]
        flipped += buildable["flipped_beams"]
    if changed(buildable):
        # the last collapses or flips: optimised once more (their nodes and corners held to the
        # limits), and what is short after that is reported, not collapsed again
        rounds += 1
        result = reoptimised(result, grid, buildable, "a last time")
        buildable.update({**grid_figures(result.polymesh), "short_beams_left": short_count(result.polymesh, project)})
    removed = 0
    if not buildable["too_fine"]:
        # the last resort for beams that no flip, collapse or optimisation could lengthen, and for
        # joints too narrow: the beam goes, its two cells become one
        result, removed = without_unbuildable_beams(result, project, surface, field)
        if removed:
            ctx.step(f"{removed} beams too short or too close to another at a joint removed or collapsed")
            ctx.report_findings([removed_finding(removed, result.polymesh)])
        if result.quality.get("corner_merges"):
            ctx.report_findings([corners_finding(result.quality["corner_merges"], build_limits_of(project))])
    buildable.update({"collapsed_beams": collapsed, "flipped_beams": flipped, "removed_beams": removed,
                      "reoptimised": rounds, "grading_kept": grading_kept, "short_share_at_grading": share_kept})
    if buildable["too_fine"]:
        ctx.report_findings([too_fine_finding(buildable, "optimize", project.section.size_key(),
                                              cells=result.polymesh.n_faces)])
    elif not grading_kept:
        ctx.report_findings([grading_finding(share_kept, result.quality, project.section.size_key())])
    elif compressed_grading(result.quality):
        ctx.report_findings([compressed_finding(result.quality, project.section.size_key())])
    elif lost_grading(result.quality):
        ctx.report_findings([lost_finding(result.quality, collapsed, removed, project.section.size_key())])
    planes = settings.symmetry_planes
    folded = folded_cells_on(result.polymesh, surface)
    if len(folded):
        ctx.report_findings([folded_finding([int(c) for c in folded])])
    if planes:  # the collapses and removals keep mirror orbits only nearly: nodes symmetrised again
        symmetric = symmetrised_grid(result.polymesh, planes)
        if np.all(np.isfinite(symmetric.nodes)):  # else kept as optimised; the record measures it
            result = dataclasses.replace(result, polymesh=symmetric)
    if removed or planes:  # the shortest beam and the smallest angle of the grid as written
        buildable.update({**grid_figures(result.polymesh), "short_beams_left": short_count(result.polymesh, project)})
    kept_open = openings(surface.mesh, result.polymesh)
    if any(o.kept < OPENING_KEPT for o in kept_open):
        ctx.report_findings([openings_finding(kept_open, project.section.size_key())])
    write_polymesh_obj(result.polymesh, ctx.folder / "gridshell.obj",
                       header=f"{project.project.name}: optimised grid-shell")
    ctx.step("panels: planar convex pieces of the cells that are not")
    pieces = panel_pieces_of(result.polymesh, project)
    write_panels_obj(result.polymesh, pieces, ctx.folder / "panels.obj",
                     header=f"{project.project.name}: panels (cells, and planar pieces of the cells that are not)")
    split = sorted({p.cell for p in pieces if p.piece})
    quality = dict(result.quality)
    quality["buildable"] = buildable
    quality["panels"] = {"panels": len(pieces), "cells_split": len(split), "split_cells": [c + 1 for c in split],
                         "planar_panels": bool(project.optimize.planar),
                         "planarity_tolerance_m": _piece_tolerance(result.polymesh, project)}
    quality["shortest_beam_m"] = buildable["shortest_beam_m"]
    quality["smallest_beam_angle_deg"] = buildable["smallest_beam_angle_deg"]
    quality["defects_flipped"] = defects
    quality["openings"] = [o.to_dict() for o in kept_open]
    quality["weights"] = project.optimize.model_dump(mode="json")
    if planes:  # of the grid as written
        quality["symmetry"] = symmetry_record(result.polymesh.nodes, planes,
                                              float(result.polymesh.beam_lengths.mean()))
    write_text_atomic(ctx.folder / "optimize.json", json.dumps(quality, indent=1, default=float))
    ctx.step("drawing")
    plot_gridshell(result.polymesh, ctx.folder / "planarity.png", color_by="planarity",
                   title=f"{project.project.name}: optimised grid-shell, planarity of the cells")
    plot_gridshell(result.polymesh, ctx.folder / "degree.png", color_by="degree",
                   title=f"{project.project.name}: optimised grid-shell, cells by number of sides")
    return OptimizedGrid(polymesh=result.polymesh, pieces=pieces)


def onto_surface(grid: PolyMesh, nodes: np.ndarray, closest: ClosestSurfacePoints) -> PolyMesh:
    """``grid`` with its interior ``nodes`` ((n_nodes,) bool) at their ``closest`` points on the surface,
    but for the nodes of cells that the move would fold: a flip turns its beam across in the plane
    of its cells and a collapse merges at the midpoint, both off a curved surface, and the optimiser
    pulls nodes back only as strongly as its closeness weight."""
    free = np.asarray(nodes, dtype=bool) & ~(grid.boundary | grid.supports | grid.corners)
    if not free.any():
        return grid
    x = np.array(grid.nodes, dtype=float)
    x[free] = closest.closest(x[free])[0]
    fans = CellFans(grid.faces)
    return grid.replace_nodes(unfolded(grid.nodes, x, fans, closest.closest_normals(fans.centroids(grid.nodes))[1]))


def without_unbuildable_beams(result: OptimizeResult, project: Project, surface: SurfaceResult,
                              field: GuidingField) -> tuple[OptimizeResult, int]:
    """(result, removed): ``result`` with the beams still shorter than their joints and the shortest
    cut take removed where their two cells can become one, collapsed where the removals freed their
    end nodes, and one beam of each pair closer than the joint's smallest angle removed
    (engine.remeshing.collapse: remove_short_beams, collapse_beams, open_narrow_joints), a corner of the outline
    with no inner beam merged into the next corner where the two lie closer than that, in rounds while that
    changes the grid (LAST_RESORT_ROUNDS at most, then the short beams removed once more); its "after"
    figures are measured again. ``removed`` counts the beams removed
    and collapsed. No node moves but those of the collapses, so nothing is optimised again."""
    limits = build_limits_of(project)
    grid, removed, corners = result.polymesh, 0, 0
    merges: list[tuple[np.ndarray, np.ndarray]] = []  # (corner kept, corner merged into it), m
    for _ in range(LAST_RESORT_ROUNDS):
        grid, gone, left = remove_short_beams(grid, lambda g: required_beam_lengths_m(g, limits))
        grid, merged = collapse_beams(grid, left) if len(left) else (grid, 0)
        if len(left) and not merged:
            # two corners of the outline closer than a beam can be built: the bare one goes
            before = grid.nodes[grid.corners]
            grid, merged = collapse_beams(grid, left, merge_corners=True)
            corners += merged
            merges += _corner_merges(before, grid.nodes[grid.corners])
        grid, straightened = dissolve_kinks(grid)
        grid, opened, _ = open_narrow_joints(grid, np.radians(limits.min_angle_deg))
        grid, more = dissolve_kinks(grid)
        removed += gone + merged + straightened + more + opened
        if not (merged or opened or straightened or more):
            break
    else:
        # a straightened kink can leave a beam short at its ends' narrower angles: removals (which
        # only widen angles) have the last word
        grid, gone, _ = remove_short_beams(grid, lambda g: required_beam_lengths_m(g, limits))
        removed += gone
    if not removed:
        return result, 0
    after = grid_quality(grid, surface.mesh, field)
    quality = {**result.quality, "after": after, "corners_merged": corners}
    if merges:  # the kept corners by their joints in the grid as it leaves the stage (corners do not move)
        at = cKDTree(grid.nodes)
        quality["corner_merges"] = [{"joint": joint_id(int(at.query(kept)[1])), "kept_m": kept.tolist(),
                                     "merged_m": gone.tolist(), "distance_m": float(np.linalg.norm(kept - gone))}
                                    for kept, gone in merges]
    return dataclasses.replace(result, polymesh=grid, quality=quality), removed


def _corner_merges(before: np.ndarray, after: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """(kept, merged) corner positions of a corner merge: each corner of ``before`` that is not in
    ``after`` went into the nearest corner that is (collapse_beams leaves the kept corner in place)."""
    if not len(after):
        return []
    tree = cKDTree(after)
    distance, nearest = tree.query(before)
    return [(after[j], before[i]) for i, j in enumerate(nearest) if distance[i] > 1e-9]


def corners_finding(merges: list[dict], limits) -> dict:
    """The finding that corners of the outline closer than a buildable beam were merged, naming the
    joints they were merged into (``merges``: optimize.json's ``corner_merges``; JSON-ready)."""
    where = ", ".join(f"{m['distance_m'] * 1000:.0f} mm from {m['joint']}" for m in merges)
    return Finding(kind="corners_merged", parts=[m["joint"] for m in merges] or ["outline"], measure=len(merges),
                   limit=0, unit="corners", stage="optimize",
                   message=(f"{len(merges)} corner(s) of the outline lay closer to the next corner than the "
                            f"shortest buildable beam ({limits.min_cut_length_mm:.0f} mm of cut plus both joints; "
                            f"{where}): each was merged into that corner's joint, so the outline is cut there "
                            "by less than one beam"),
                   fix="keep the corners apart in the surface's outline, or smaller joints ([fabrication.joints] "
                       "sleeve_length) or a shorter [fabrication.beams] min_cut_length if the fabricator accepts "
                       "it").to_dict()


def removed_finding(removed: int, grid: PolyMesh) -> dict:
    """The finding that beams were removed or collapsed after the last optimisation (JSON-ready)."""
    return Finding(kind="beams_removed", parts=["grid"], measure=removed, limit=0, unit="beams", stage="optimize",
                   message=(f"{removed} beams that no optimisation could make as long as their joints take, or as "
                            "wide apart at a joint as it takes, were removed (their two cells are one panel) or "
                            f"collapsed: the grid has {grid.n_faces} cells"),
                   fix="smaller joints ([fabrication.joints] kind, hub_radius, sleeve_length, min_angle) or fewer "
                       "cells ([remesh] n_cells) keep every beam").to_dict()


def folded_cells_on(grid: PolyMesh, surface: SurfaceResult) -> np.ndarray:
    """Ids of the cells of ``grid`` that cross themselves or are turned over on the surface."""
    fans = CellFans(grid.faces)
    normals = ClosestSurfacePoints(surface.mesh).closest_normals(fans.centroids(grid.nodes))[1]
    return folded_cells(grid.nodes, fans, normals)


def openings_finding(kept_open: list[Opening], size_key: str = "[section] diameter") -> dict:
    """The finding that the grid spans openings of the surface: where joints coarsened the grid or
    collapsed the beams along an opening, its outline shrank (JSON-ready)."""
    spanned = [(k, o) for k, o in enumerate(kept_open, start=1) if o.kept < OPENING_KEPT]
    where = "; ".join(f"opening {k} at ({o.centre[0]:.1f}, {o.centre[1]:.1f}) m: {o.grid_area_m2:.2f} of "
                      f"{o.surface_area_m2:.2f} m^2 left open, {o.joints} joints on its outline" for k, o in spanned)
    return Finding(kind="opening_spanned", parts=[f"opening {k}" for k, _ in spanned],
                   measure=100 * min(o.kept for _, o in spanned), limit=100 * OPENING_KEPT, unit="% open",
                   stage="optimize",
                   message=(f"the grid's cells span {len(spanned)} of the surface's openings, leaving less than "
                            f"{OPENING_KEPT:.0%} of each open ({where}): their panels and beams cross what was "
                            "meant to be open"),
                   fix=("more cells ([remesh] n_cells) or smaller joints and shorter cuts, so that beams can run "
                        f"along the openings ([fabrication.joints], [fabrication.beams] min_cut_length, {size_key}); "
                        "or [remesh] coarsen_for_joints = false")).to_dict()


def folded_finding(cells: list[int]) -> dict:
    """The finding that cells of the optimised grid overlap their neighbours (JSON-ready)."""
    return Finding(kind="grid_folded", parts=[f"cell {c + 1}" for c in cells], measure=len(cells), limit=0,
                   unit="cells", stage="optimize",
                   message=(f"folded cells in the optimised grid: {len(cells)} (crossing themselves or turned over on "
                            "the surface); they overlap their neighbours, and so do their panels and joints"),
                   fix="fewer cells ([remesh] n_cells), less grading ([field] max_size_ratio), or smaller joints "
                       "([fabrication.joints]); or send the surface with the report").to_dict()


def grading_finding(share: float, quality: dict, size_key: str = "[section] diameter") -> dict:
    """The finding that the joints evened out the field's grading (JSON-ready)."""
    before = quality["before"].get("size_correlation")
    after = quality["after"].get("size_correlation")
    figures = (f" (size correlation with the field {before:.2f} remeshed, {after:.2f} optimised)"
               if before is not None and after is not None else "")
    return Finding(kind="grading_evened", parts=["grid"], measure=100 * share, limit=100 * GRADED_SHORT_SHARE,
                   unit="% of beams", stage="optimize",
                   message=(f"at the field's grading {100 * share:.0f} % of the beams are too short for their "
                            f"joints, so the optimiser evened out the cell sizes{figures}"),
                   fix="fewer cells ([remesh] n_cells), less grading ([field] max_size_ratio), or smaller "
                       f"joints or beams ([fabrication.joints], {size_key})").to_dict()


def compressed_grading(quality: dict) -> bool:
    """Whether the optimiser compressed the field's grading for the joints (engine.remeshing.optimize.graded_areas)."""
    grading = quality.get("grading") or {}
    given, target = grading.get("given_slope"), grading.get("target_slope")
    return given is not None and target is not None and target < given - COMPRESSED_SLOPE


def compressed_finding(quality: dict, size_key: str = "[section] diameter") -> dict:
    """The finding that the joints compressed the field's grading (JSON-ready)."""
    from engine.findings import Finding

    given, target = quality["grading"]["given_slope"], quality["grading"]["target_slope"]
    before, after = quality["before"].get("size_rank_correlation"), quality["after"].get("size_rank_correlation")
    figures = (f"; size rank correlation with the field {before:.2f} remeshed, {after:.2f} optimised"
               if before is not None and after is not None else "")
    return Finding(kind="grading_compressed", parts=["grid"], measure=target, limit=given, unit="slope",
                   stage="optimize",
                   message=(f"the smallest cells are too small for their joints, so the optimiser compressed the "
                            f"field's grading in order: cell size as the field's to the power {target:.2f} instead "
                            f"of {given:.2f}{figures}"),
                   fix="fewer cells ([remesh] n_cells), less grading ([field] max_size_ratio), or smaller "
                       f"joints or beams ([fabrication.joints], {size_key})").to_dict()


def lost_grading(quality: dict) -> bool:
    """Whether the optimised grid follows a graded field less than the remeshed one, by more than
    GRADING_LOST of the size rank correlation."""
    before, after = quality.get("before") or {}, quality.get("after") or {}
    r0, r1 = before.get("size_rank_correlation"), after.get("size_rank_correlation")
    span = before.get("field_size_span_cells") or 0.0
    return r0 is not None and r1 is not None and span >= GRADED_SPAN and r0 - r1 > GRADING_LOST


def lost_finding(quality: dict, collapsed: int, removed: int, size_key: str = "[section] diameter") -> dict:
    """The finding that the beams collapsed and removed for the joints cost the grid its grading,
    the field's sizes kept as the optimiser's targets (JSON-ready)."""
    from engine.findings import Finding

    r0, r1 = quality["before"]["size_rank_correlation"], quality["after"]["size_rank_correlation"]
    return Finding(kind="grading_lost", parts=["grid"], measure=r1, limit=r0 - GRADING_LOST,
                   unit="rank correlation", stage="optimize",
                   message=(f"the {collapsed} beams collapsed and {removed} removed, shorter than their joints take, "
                            f"cost the grid its grading: size rank correlation with the field {r0:.2f} remeshed, "
                            f"{r1:.2f} optimised"),
                   fix="fewer cells ([remesh] n_cells), or smaller joints or beams ([fabrication.joints], "
                       f"{size_key})").to_dict()


def _piece_tolerance(polymesh: PolyMesh, project: Project) -> float:
    """Largest node distance from a panel's plane (m): the planarity tolerance times the mean beam."""
    return float(project.optimize.planarity_tolerance * polymesh.beam_lengths.mean())


def panel_pieces_of(polymesh: PolyMesh, project: Project) -> list[PanelPiece]:
    """The panels of the grid: with ``[optimize] planar``, every cell planar and convex within the
    tolerance, else its planar convex pieces; without, the cells as they are."""
    from engine.remeshing.panel_pieces import PanelPiece, panel_pieces

    if not project.optimize.planar:
        return [PanelPiece(cell=c, piece=0, loop=np.asarray(f)) for c, f in enumerate(polymesh.faces)]
    return panel_pieces(polymesh, _piece_tolerance(polymesh, project))


def write_panels_obj(polymesh: PolyMesh, pieces: list[PanelPiece], path: Path, *, header: str) -> Path:
    """05-optimize/panels.obj: the grid's nodes and one face per panel (node loop); a comment line
    before each face names its cell and piece (``# panel P0001 cell 1 piece 0``, piece 0: the whole cell)."""
    lines = [f"# {header}", "# units: m; one face per panel (node loop over the grid's nodes)",
             f"# nodes {polymesh.n_nodes} panels {len(pieces)}"]
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in polymesh.nodes.tolist()]  # exact: a reload gives the same grid
    for k, p in enumerate(pieces):
        lines.append(f"# panel {panel_id(k)} cell {p.cell + 1} piece {p.piece}")
        lines.append("f " + " ".join(str(i + 1) for i in p.loop.tolist()))
    return write_text_atomic(path, "\n".join(lines) + "\n")


def read_panels_obj(path: Path) -> list[PanelPiece]:
    """The pieces (engine.remeshing.panel_pieces.PanelPiece) of a panels.obj written by :func:`write_panels_obj`."""
    from engine.remeshing.panel_pieces import PanelPiece

    pieces, cell, piece = [], 0, 0
    for line in Path(path).read_text(encoding="ascii").splitlines():
        if line.startswith("# panel "):
            words = line.split()
            cell, piece = int(words[4]) - 1, int(words[6])
        elif line.startswith("f "):
            pieces.append(PanelPiece(cell=cell, piece=piece,
                                     loop=np.array([int(t) - 1 for t in line.split()[1:]], dtype=np.int64)))
    return pieces


def load(folder: Path, project: Project) -> OptimizedGrid:
    polymesh = read_polymesh_obj(folder / "gridshell.obj")
    return OptimizedGrid(polymesh=polymesh, pieces=panels_of(folder, polymesh, project))


def panels_of(folder: Path, polymesh: PolyMesh, project: Project) -> list[PanelPiece]:
    """The panels in ``folder``/panels.obj where it has them for ``polymesh``, else made again
    (the optimize stage's panels of a grid written before panels.obj was)."""
    path = Path(folder) / "panels.obj"
    if path.is_file():
        pieces = read_panels_obj(path)
        if all(len(p.loop) and p.loop.max() < polymesh.n_nodes for p in pieces):
            return pieces
    return panel_pieces_of(polymesh, project)
