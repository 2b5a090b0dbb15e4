"""Stage ``fabrication``: everything a workshop needs to build the checked grid-shell.

Artifacts (07-fabrication/): joints/ (J0001.step, J0001.stl for printed sockets ..., joints.step on
request under 30 MB), beams/ (cutlist.csv, cutlist.xlsx, bars.csv, beams.step), panels/ (P0001.dxf
..., sheets/SHEET01.dxf ..., panels.csv), assembly/ (sequence.csv, steps/*.png), drawings/ (plan.dxf, plan.pdf),
gridshell.step, gridshell.3dm and fabrication.json (counts and checks; the seconds each step took
go into the manifest, ``step_seconds``). Lengths in mm.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from engine.design.sections import material
from engine.findings import Finding
from engine.mesh import PolyMesh
from engine.structure.grid_model import beam_up_vectors
from fabrication.assembly import plan_assembly, write_assembly
from fabrication.beams import RectangularSection, slot_volumes_mm3, tube_axes_mm, tube_solids
from fabrication.clearance import joint_clashes_parallel
from fabrication.drawings import write_plan_drawings
from fabrication.files import atomic_path, write_text_atomic
from fabrication.ids import joint_id
from fabrication.ifc import IfcBeam, IfcJoint, IfcPanel, write_gridshell_ifc
from fabrication.joints import (
    JOINTS_STEP_LIMIT_BYTES,
    EndSlots,
    JointGeometry,
    JointSettings,
    JointsInBackground,
    copy_placements,
    fin_plate_slots,
    geometry_hub_height_mm,
    geometry_setback_mm,
    joint_geometry,
    joint_hub_radius_mm,
    joint_parts,
    joint_plate_height_mm,
    joint_sleeve_mm,
    knife_plate_height_mm,
    same_joints,
)
from fabrication.limits import BuildLimits, default_min_cut_length_mm
from fabrication.model3d import JointSolids, write_gridshell_3dm, write_gridshell_step
from fabrication.nesting_bars import nest_bars
from fabrication.site import site_origin_m
from fabrication.tube_clearance import TUBE_CLASH_MM
from fabrication.workers import run_steps

from ..config import MM, Project
from ..runner import StageContext
from .analysis import AnalysisSummary, beam_properties, grid_normals
from .build_limits import build_limits_of
from .optimize import OptimizedGrid
from .sizing import BeamSections, profile_name, project_sections
from .surface import SurfaceResult

if TYPE_CHECKING:  # pragma: no cover
    from fabrication.nesting_sheets import StockNesting
    from fabrication.panels import Panel
    from fabrication.settings import PanelSettings, SheetSettings

# fabrication.beams and fabrication.nc1 (pandas), fabrication.panels and fabrication.nesting_sheets
# (shapely) are imported where they are used: a run whose stages are all cached does not load them

__all__ = ["FabricationResult", "run", "load"]


@dataclass(frozen=True, kw_only=True)
class FabricationResult:
    """The fabrication stage's result: how many joints and panels (None where [fabrication.panels]
    is off) it made, and ``summary``, its fabrication.json (counts, limits, joint problems and
    clashes, findings)."""

    joints: int
    panels: int | None
    summary: dict

    @classmethod
    def of_summary(cls, summary: dict) -> "FabricationResult":
        return cls(joints=summary["joints"], panels=summary.get("panels"), summary=summary)


class _StepClock:
    """Seconds per named step of the stage: each ``start`` ends the step before (and names it to the
    stage's progress, where there is a ``ctx``)."""

    def __init__(self, ctx: StageContext | None = None) -> None:
        self._ctx = ctx
        self.seconds: dict[str, float] = {}
        self._name: str | None = None
        self._started = 0.0

    def start(self, name: str) -> None:
        self.stop()
        if self._ctx is not None:
            self._ctx.step(name)
        self._name, self._started = name, time.perf_counter()

    def stop(self) -> None:
        if self._name is not None:
            self.seconds[self._name] = round(self.seconds.get(self._name, 0.0) + time.perf_counter() - self._started, 3)
            self._name = None


def run(surface: SurfaceResult, optimize: OptimizedGrid, analysis: AnalysisSummary, project: Project,
        ctx: StageContext) -> FabricationResult:
    clock = _StepClock(ctx)
    config = project.fabrication
    polymesh = optimize.polymesh
    sections = analysis.sections
    folder: Path = ctx.folder
    normals = grid_normals(polymesh, surface, project)  # mirror images across the symmetry planes
    # a roof in site coordinates is built in a local frame (fabrication.site)
    origin_m = site_origin_m(polymesh.nodes)
    if origin_m.any():
        polymesh = polymesh.replace_nodes(polymesh.nodes - origin_m)
        optimize = replace(optimize, polymesh=polymesh)
        ctx.step(f"the grid stands far from the coordinate origin: the files' coordinates start at "
                 f"{', '.join(f'{c:.0f}' for c in origin_m)} m (site_origin_m)")
    # one outer size, or one per beam where the analysis sized the tubes
    size_mm = project.section.outer_size_mm() if sections is None else MM * sections.diameter
    limits = build_limits_of(project)
    summary: dict = {"nodes": polymesh.n_nodes, "beams": int(len(polymesh.edges)), "cells": polymesh.n_faces,
                     "limits": limits.to_dict(), "site_origin_m": origin_m.tolist()}
    findings: list[Finding] = []
    joint_settings = _joint_settings(project)
    summary.update({"joints": 0, "joint_problems": []})
    # the joints take both cores in worker processes; the other steps run here meanwhile
    clock.start("joints: start")
    # the joints' solids in OCCT's own format for gridshell.step, outside the stage's folder (removed
    # below, or by the object's finaliser if the stage fails before)
    scratch = tempfile.TemporaryDirectory(prefix="gridshell-joints-")
    breps = Path(scratch.name)
    # with very many distinct joints their solids would pass GRIDSHELL_STEP_JOINT_BYTES: the model
    # then draws spheres and is written alongside the joints rather than after them
    most_solids = GRIDSHELL_STEP_JOINT_BYTES // JOINT_STEP_BYTES_AT_LEAST
    with JointsInBackground(polymesh, normals, size_mm, joint_settings, folder / "joints",
                            workers=config.workers, combined_step=config.joints.combined_step,
                            breps=breps, breps_limit=most_solids) as joints:
        spheres = joints.distinct > most_solids
        write_model = _beams_panels_drawings_assembly(project, ctx, clock, optimize, normals, joint_settings,
                                                      limits, summary, findings, sections, share=joints.run_steps,
                                                      spheres=spheres)
        clock.start("joints: waiting")
        joints.wait(ctx.step)
    if write_model is not None:
        clock.start("model: gridshell.step")
        summary["gridshell_step"] = write_model(_joint_solids(joints, folder / "joints", breps))
    elif "gridshell_step" in summary:
        summary["gridshell_step"]["reason"] = (f"{joints.distinct} distinct joints: over "
                                               f"{GRIDSHELL_STEP_JOINT_BYTES // JOINT_STEP_BYTES_AT_LEAST}")
    scratch.cleanup()
    clock.stop()
    clock.seconds["joints (alongside the other steps)"] = round(joints.seconds, 3)
    joint_reports = joints.reports
    summary["joints"] = len(joint_reports)
    summary["joint_problems"] = [{k: v for k, v in r.items() if k != "seconds"} for r in joint_reports
                                 if not r.get("ok", True)]
    # the same part but for the engraved id: one print file would do for each group but the label
    clock.start("joints: same parts")
    groups = same_joints(joints.geometries)
    clock.stop()
    summary["same_joints"] = groups
    summary["distinct_joints"] = len(joint_reports) - sum(len(g) - 1 for g in groups)
    # how the workers made them: built by booleans, or an equal joint's blank turned or mirrored
    turned, mirrored = (sum(1 for r in joint_reports if r.get(key)) for key in ("copy_of", "mirror_of"))
    summary["joints_made"] = {"built": len(joint_reports) - turned - mirrored, "turned": turned, "mirrored": mirrored}
    findings += _joint_findings(joint_reports, limits)
    clock.start("joints: clearance between neighbours")
    summary["joint_clashes"] = _joint_clashes(folder / "joints", [r["id"] for r in joint_reports
                                                                  if r.get("built", True)], config.workers,
                                              {r["id"]: r["box_mm"] for r in joint_reports if "box_mm" in r})
    findings += [Finding(kind="joint_clash", parts=list(c["parts"]), measure=c.get("volume_mm3"), limit=CLASH_MM3,
                         unit="mm3", stage="fabrication",
                         message=(f"joints {c['parts'][0]} and {c['parts'][1]} overlap by "
                                  f"{c['volume_mm3']:.1f} mm3" if c.get("volume_mm3") is not None else
                                  f"joints {c['parts'][0]} and {c['parts'][1]}: clearance not checked "
                                  f"({c.get('error', 'boolean failed')})"),
                         fix="make the beams between them longer: raise [fabrication.beams] min_cut_length or "
                             "lower [remesh] n_cells; or smaller joints ([fabrication.joints] sleeve_length)")
                 for c in summary["joint_clashes"]]
    clock.stop()
    summary["findings"] = [f.to_dict() for f in findings]
    summary["sizes_mb"] = output_sizes_mb(folder)
    summary["files"] = output_files(folder)
    summary["files"]["joints_step"] = {"asked": config.joints.combined_step,
                                       "written": (folder / "joints" / "joints.step").is_file(),
                                       "bytes": joints.combined_bytes, "limit_bytes": JOINTS_STEP_LIMIT_BYTES}
    ctx.report_findings(summary["findings"])
    ctx.timings.update(clock.seconds)
    write_text_atomic(folder / "fabrication.json", json.dumps(summary, indent=1, default=_jsonable))
    return FabricationResult.of_summary(summary)


#: gridshell.step takes the joints' own solids while the distinct ones' STEP files come under this
#: (the mock-up's 55 distinct printed sockets: 6 MB); over it, each joint is a sphere.
GRIDSHELL_STEP_JOINT_BYTES = 30_000_000
#: Fewer bytes than any joint's STEP file takes (the cap's steel nodes: 32 kB each, printed sockets
#: some 110 kB): more distinct joints than the limit over this are spheres, known before they are built.
JOINT_STEP_BYTES_AT_LEAST = 20_000
#: IFC4's IfcMaterial.Category for a material kind that it names otherwise.
IFC_MATERIAL_CATEGORY = {"timber": "wood"}


def _joint_solids(joints: JointsInBackground, folder: Path, breps: Path) -> JointSolids:
    """The joints' solids for gridshell.step: the built joints' own STEP files (and their .brep
    copies in ``breps``), and the turned copies placed from the joint they copy
    (fabrication.joints.copy_placements)."""
    copies = copy_placements(joints.geometries, joints.reports, joints.groups)
    files = {r["id"]: folder / f"{r['id']}.step" for r in joints.reports
             if r.get("built", True) and r["id"] not in copies and (folder / f"{r['id']}.step").is_file()}
    return JointSolids(files=files, copies={k: v for k, v in copies.items() if v[0] in files},
                       breps={k: breps / f"{k}.brep" for k in files})


def _joint_settings(project: Project) -> JointSettings:
    """The joints' settings: [fabrication.joints], with knife plates within a solid rectangular
    (timber) beam's depth at steel nodes (fabrication.joints.knife_plate_height_mm), where fin
    plates through a tube stand out of it."""
    settings = project.fabrication.joints.to_settings()
    if settings.kind == "steel" and project.section.kind == "solid_rectangle":
        settings = replace(settings, plate_height_mm=knife_plate_height_mm(MM * project.section.height))
    return settings


def _tube_clashes(polymesh: PolyMesh, table, geometries: list[JointGeometry], joint_settings: JointSettings,
                  sizes_mm: np.ndarray, rectangle: RectangularSection | None) -> list[dict]:
    """fabrication.tube_clearance on the beams as cut (their axes from the cut list, round or
    rectangular sections) and the joints as built: the tubes that overlap a joint they do not end
    in, or a tube they share no node with."""
    from fabrication.tube_clearance import tube_clashes

    e = polymesh.edges
    starts, direction = tube_axes_mm(polymesh, table["setback_start_mm"].to_numpy())
    ends = starts + np.maximum(table["cut_length_mm"].to_numpy(), 0.0)[:, None] * direction
    radii = (0.5 * np.asarray(sizes_mm, dtype=float) if rectangle is None else
             np.full(len(e), 0.5 * np.hypot(rectangle.height_mm, rectangle.width_mm)))
    parts = {g.node: joint_parts(g, joint_settings) for g in geometries}
    clashes = tube_clashes(MM * polymesh.nodes, e, starts, ends, radii, parts, table["id"].tolist(),
                           {g.node: joint_id(g.node) for g in geometries})
    return [c.to_dict() for c in clashes]


def _tube_clash_finding(clash: dict, size_key: str = "[section] diameter") -> Finding:
    """The finding of a tube that runs into a joint or tube (``size_key``: the section's size keys)."""
    beam, other = clash["parts"]
    what = f"joint {other}, which it does not end in" if other.startswith("J") else f"beam {other}"
    return Finding(kind="tube_clash", parts=[beam, other], measure=clash["depth_mm"], limit=TUBE_CLASH_MM,
                   unit="mm", stage="fabrication",
                   message=f"beam {beam} runs {clash['depth_mm']:.1f} mm into {what}, near {clash['at_mm']} mm",
                   fix=f"a smaller beam ({size_key}), or fewer cells ([remesh] n_cells) so that the cells are wider "
                       "than the beams; where the surface folds, smooth it or move its supports")


def _beam_shapes(project: Project, polymesh: PolyMesh, normals: np.ndarray,
                 tube_walls_mm: np.ndarray | None) -> tuple[RectangularSection | None, np.ndarray | None]:
    """(rectangle, walls in mm) of the beams as solids: a rectangular [section] turned to each beam's
    up (the analysis's local z), hollow by its thickness where it is a rectangular_hollow; None and
    the tubes' walls (None: solid rods) for round sections."""
    s = project.section
    if s.kind not in ("rectangular_hollow", "solid_rectangle"):
        return None, tube_walls_mm
    rectangle = RectangularSection(height_mm=MM * s.height, width_mm=MM * s.width,
                                   up=beam_up_vectors(polymesh, normals))
    walls = np.full(len(polymesh.edges), MM * s.thickness) if s.kind == "rectangular_hollow" else None
    return rectangle, walls


def _seats(polymesh: PolyMesh, geometries: list[JointGeometry], sizes_mm: np.ndarray, panels: list, pieces: list,
           joint_settings: JointSettings, rectangle: RectangularSection | None) -> tuple[np.ndarray, np.ndarray]:
    """Where each panel rests on the joints and beams (fabrication.panels.panel_seats), from the
    joints' geometry as their solids are built from it and the beams' sections as cut."""
    from fabrication.panels import panel_seats

    if rectangle is None:
        radii: dict = {(min(a, b), max(a, b)): 0.5 * float(s) for (a, b), s in zip(polymesh.edges, sizes_mm)}
    else:
        radii = {(min(a, b), max(a, b)): (0.5 * rectangle.height_mm, 0.5 * rectangle.width_mm, up)
                 for (a, b), up in zip(polymesh.edges, rectangle.up)}
    return panel_seats(panels, [p.loop for p in pieces], {g.node: g for g in geometries}, joint_settings, radii,
                       [pieces[panel.face].cell for panel in panels])


def _write_model_step(polymesh: PolyMesh, panels: list, seats: tuple[np.ndarray, np.ndarray], table,
                      sizes_mm: np.ndarray, walls_mm: np.ndarray | None, rectangle: RectangularSection | None,
                      panel_settings: PanelSettings, joint_radius_mm: float, path: Path, slots: EndSlots | None,
                      joints: JointSolids) -> dict:
    """gridshell.step with the beams as cut, the joints' own solids (spheres where there are none,
    or where the distinct joints' STEP files exceed GRIDSHELL_STEP_JOINT_BYTES) and the panels
    resting on them (fabrication.panels.panel_seats); returns fabrication.json's record of what it
    holds."""

    distinct = joints.distinct_bytes
    real = bool(joints.files) and distinct <= GRIDSHELL_STEP_JOINT_BYTES
    tubes = tube_solids(polymesh, table, outer_size_mm=sizes_mm, wall_mm=walls_mm, slots=slots, rectangle=rectangle)
    write_gridshell_step(polymesh, panels, path, tubes=tubes, joints=joints if real else None,
                         joint_radius_mm=joint_radius_mm, seats=seats, panel_thickness_mm=panel_settings.thickness_mm)
    n_nodes = polymesh.n_nodes
    n_solids = len(joints.files) + len(joints.copies) if real else 0
    reason = None if real else (f"the distinct joints' STEP files take {distinct} bytes" if joints.files
                                else "no joint solids")
    return {"joints": "solids" if real else "spheres", "reason": reason,
            "joint_solids": n_solids, "joint_parts": len(joints.files) if real else 0,
            "joint_spheres": n_nodes - n_solids,
            "distinct_joint_bytes": distinct, "limit_bytes": GRIDSHELL_STEP_JOINT_BYTES,
            "beams": len(tubes), "panels": len(panels)}


def output_sizes_mb(folder: Path) -> dict[str, float]:
    """MB (10^6 bytes, to 10 kB) of the stage's files: each sub-folder, each file at the top, and the total
    (fabrication.json itself, written after, not counted)."""
    sizes: dict[str, float] = {}
    for entry in sorted(Path(folder).iterdir()):
        if entry.name.startswith("."):
            continue
        files = ([entry] if entry.is_file()
                 else [p for p in entry.rglob("*") if p.is_file() and not p.name.startswith(".")])
        sizes[entry.name] = round(sum(p.stat().st_size for p in files) / 1e6, 2)
    sizes["total"] = round(sum(sizes.values()), 2)
    return sizes


def _file_kind(relative: Path) -> str:
    """The kind of a file of the stage, by its path in the stage folder: joints_step (the combined
    file), joint_steps and joint_stls (one per joint), the sub-folder's name for other files in
    one (beams, panels, ...), else the file's name with "_" for "." (gridshell_step, ...)."""
    parts = relative.parts
    if parts[0] == "joints" and len(parts) == 2:
        if parts[1] == "joints.step":
            return "joints_step"
        if relative.suffix in (".step", ".stl"):
            return f"joint_{relative.suffix[1:]}s"
    return parts[0] if len(parts) > 1 else parts[0].replace(".", "_")


def output_files(folder: Path) -> dict:
    """Bytes of the stage's files: ``total_bytes`` and ``by_kind`` (see _file_kind), with
    ``count_by_kind``; fabrication.json itself (written after) and hidden files not counted."""
    by_kind: dict[str, int] = {}
    count: dict[str, int] = {}
    for path in sorted(Path(folder).rglob("*")):
        relative = path.relative_to(folder)
        if not path.is_file() or any(p.startswith(".") for p in relative.parts) or relative.as_posix() == \
                "fabrication.json":
            continue
        kind = _file_kind(relative)
        by_kind[kind] = by_kind.get(kind, 0) + path.stat().st_size
        count[kind] = count.get(kind, 0) + 1
    return {"total_bytes": sum(by_kind.values()), "by_kind": dict(sorted(by_kind.items())),
            "count_by_kind": dict(sorted(count.items()))}


#: Joint solids sharing more than this volume (mm3) clash.
CLASH_MM3 = 1.0


def _joint_clashes(folder: Path, names: list[str], workers: int | None = None,
                   boxes: dict[str, np.ndarray] | None = None) -> list[dict]:
    """Pairs of joint solids (as written) that intersect by more than CLASH_MM3, the booleans on
    every core (the joints' workers have ended by then). ``boxes``: the boxes of the joints that
    have no STL (steel nodes), from their reports."""
    # boxes from the STL each worker wrote beside the STEP (same solid), or from the solid where it
    # wrote none: only touching joints are read
    return joint_clashes_parallel(folder, names, workers=workers or os.cpu_count() or 1, min_volume_mm3=CLASH_MM3,
                                  stl_boxes=True, boxes=boxes)


def _joint_findings(reports: list[dict], limits: BuildLimits) -> list[Finding]:
    """Joints whose solid failed a check, or whose beams meet at less than the joint takes."""
    out = []
    for r in reports:
        angle = r.get("smallest_angle_deg")
        if angle is not None and angle < limits.min_angle_deg and r.get("beams", 0) > 1:
            out.append(Finding(kind="joint_angle", parts=[r["id"]], measure=angle, limit=limits.min_angle_deg,
                               unit="deg", stage="fabrication",
                               message=f"joint {r['id']}: two beams meet at {angle:.1f} deg",
                               fix="lower [fabrication.joints] min_angle if the joint takes it, or move the node "
                                   "(other [remesh] seed or n_cells)"))
        if r.get("ok", True):
            continue
        failed = [r["error"]] if r.get("error") else []
        failed += [words for name, words in (
            ("valid", "not a valid solid"), ("single_solid", "not one solid (a part of it does not join the rest)"),
            ("watertight", "its STL is not watertight"),
            ("stl_volume_ok", f"its STL's volume is off the solid's by {100 * r.get('stl_volume_error', 0):.2f} %"),
            ("wall_ok", f"its thinnest wall is {r.get('min_wall_mm', float('nan')):.1f} mm, under min_wall"))
            if not r.get(name, True)]
        if r.get("clashes"):
            failed.append(f"{len(r['clashes'])} sleeve pairs overlap")
        error = r.get("max_axis_error_deg")
        if error is not None and np.isfinite(error) and error > 0.1:
            failed.append(f"bore axis off by {error:.2f} deg")
        out.append(Finding(kind="joint_solid", parts=[r["id"]], measure=r.get("min_wall_mm"), unit="mm",
                           stage="fabrication", message=f"joint {r['id']}: {', '.join(failed) or 'check failed'}",
                           fix="[fabrication.joints] wall, min_wall or sleeve_length; or "
                               "[fabrication.joints] min_angle with a new run"))
    return out


def _beams_panels_drawings_assembly(project: Project, ctx: StageContext, clock: _StepClock, grid: OptimizedGrid,
                                    normals: np.ndarray, joint_settings: JointSettings, limits: BuildLimits,
                                    summary: dict, findings: list[Finding],
                                    sections: BeamSections | None = None,
                                    share: Callable[..., dict] = run_steps,
                                    spheres: bool = False) -> Callable[[JointSolids], dict] | None:
    """Every step but the joints (they run meanwhile); fills ``summary`` and ``findings``.
    ``sections``: the analysis's per-beam tubes where it sized them (workflow.stages.sizing);
    ``share`` runs independent steps (fabrication.workers.run_steps, on the joints' workers as they
    fall idle). Returns the writer of gridshell.step, a function of the joints' solids to call
    once they are built; None where ``spheres`` had it written here, alongside the joints, with a
    sphere per joint."""
    polymesh = grid.polymesh
    config = project.fabrication
    folder: Path = ctx.folder
    size_mm = project.section.outer_size_mm()
    # each beam's tube: the sized ones, else the project's one tube (None for other sections)
    tubes = sections if sections is not None else project_sections(project, len(polymesh.edges))
    sizes_mm = np.full(len(polymesh.edges), size_mm) if tubes is None else MM * tubes.diameter
    walls_mm = None if tubes is None else MM * tubes.thickness
    # the beams as solids: round (tubes, or rods), or rectangles turned to each beam's up
    rectangle, solid_walls_mm = _beam_shapes(project, polymesh, normals, walls_mm)
    clock.start("beams: cut list")
    from fabrication.beams import cut_list, write_beams_step, write_cut_list

    b = config.beams
    props, section, _ = beam_properties(project)
    beam_settings = b.to_settings(profile_name=profile_name(project), material_name=project.material.name,
                                  density=_density(project), area_m2=section.A, outer_size_mm=size_mm)
    areas_m2 = np.full(len(sizes_mm), section.A) if tubes is None else tubes.properties["A"]
    table = cut_list(polymesh, normals, beam_settings, joint_settings, profiles=None if tubes is None else tubes.names,
                     areas_m2=areas_m2, outer_sizes_mm=sizes_mm)
    # the joints as their solids are built: the panels rest on them, steel fin plates enter slots
    geometries = joint_geometry(polymesh, normals, sizes_mm)
    slots = fin_plate_slots(polymesh, geometries, joint_settings) if joint_settings.kind == "steel" else None
    if slots is not None:  # the beams' mass as cut, less their slots
        removed = slot_volumes_mm3(slots, table["cut_length_mm"].to_numpy(), sizes_mm, solid_walls_mm, rectangle)
        table["mass_kg"] = np.round(table["mass_kg"] - 1e-9 * removed * _density(project), 4)
    write_cut_list(table, folder / "beams")
    clock.start("beams: clearance")
    summary["tube_clashes"] = _tube_clashes(polymesh, table, geometries, joint_settings, sizes_mm, rectangle)
    findings += [_tube_clash_finding(c, project.section.size_key()) for c in summary["tube_clashes"]]
    # the saw's files: round tubes, and rectangular hollow sections (not solid bars, nor timber)
    if tubes is not None or (rectangle is not None and solid_walls_mm is not None):
        clock.start("beams: NC1 files")
        from fabrication.nc1 import nc1_pieces, write_nc1_files

        masses_per_m = areas_m2 * _density(project)
        if rectangle is not None and solid_walls_mm is not None:
            pieces = nc1_pieces(table, np.full(len(sizes_mm), rectangle.height_mm), solid_walls_mm, masses_per_m,
                                joint_settings, project.material.name,
                                widths_mm=np.full(len(sizes_mm), rectangle.width_mm))
        else:
            pieces = nc1_pieces(table, sizes_mm, walls_mm, masses_per_m, joint_settings, project.material.name)
        summary["nc1_files"] = len(write_nc1_files(pieces, folder / "beams" / "nc1", order=project.project.name,
                                                   drawing=f"{project.project.name} plan"))
    cut = table["cut_length_mm"].to_numpy()
    # the shortest cut each beam's own tube needs (the setting where given)
    min_cut = np.full(len(cut), limits.min_cut_length_mm)
    if sections is not None and b.min_cut_length is None:
        min_cut = np.array([default_min_cut_length_mm(joint_settings, s) for s in sizes_mm])
    ids = table["id"].tolist()
    fix_short = ("no valid collapse could remove this beam (its cells or joints would break): fewer cells "
                 "([remesh] n_cells) or another [remesh] seed; or, if the fabricator accepts it, a smaller "
                 "[fabrication.beams] min_cut_length or [fabrication.joints] sleeve_length")
    for i in np.flatnonzero(cut < min_cut - 0.05):
        a, z = table["start_node"].iloc[i], table["end_node"].iloc[i]
        findings.append(Finding(kind="cut_length", parts=[ids[i], a, z], measure=float(cut[i]),
                                limit=float(min_cut[i]), unit="mm", stage="fabrication",
                                message=(f"beam {ids[i]} ({a}-{z}) is shorter than its two joints take"
                                         if cut[i] <= 0 else f"beam {ids[i]} ({a}-{z}) cuts to {cut[i]:.1f} mm"),
                                fix=fix_short))
    stock, kerf = beam_settings.stock_length_mm, beam_settings.kerf_mm
    for i in np.flatnonzero(cut + kerf > stock):
        findings.append(Finding(kind="stock_length", parts=[ids[i]], measure=float(cut[i]), limit=stock, unit="mm",
                                stage="fabrication",
                                message=f"beam {ids[i]} ({cut[i]:.0f} mm) is longer than a stock bar",
                                fix="raise [fabrication.beams] stock_length, or more cells ([remesh] n_cells)"))
    nestable = (cut > 0) & (cut + kerf <= stock)
    clock.start("beams: bar nesting")
    # bars of each profile are nested apart: a bar is cut into pieces of its own tube only
    profiles = table["profile"].to_numpy()
    nestings = []
    for profile in sorted(set(profiles.tolist())):
        members = np.flatnonzero(nestable & (profiles == profile))
        nestings.append((profile, nest_bars(cut[members], [ids[i] for i in members], stock, kerf)))
    _write_bars_by_profile(nestings, folder / "beams" / "bars.csv")
    summary.update({"bars_used": sum(int(n.bars_used) for _, n in nestings),
                    "bars_lower_bound": sum(int(n.lower_bound) for _, n in nestings),
                    "bar_nesting_method": ", ".join(sorted({getattr(n, "method", "") for _, n in nestings})),
                    "bar_waste_mm": float(sum(n.waste_mm for _, n in nestings)),
                    "bars_by_profile": {p: int(n.bars_used) for p, n in nestings},
                    "total_cut_length_m": float(table["cut_length_mm"].sum() / MM),
                    "shortest_cut_length_mm": float(cut.min()) if len(cut) else 0.0,
                    "shortest_beam_m": float(polymesh.beam_lengths.min()) if len(cut) else 0.0,
                    "beam_mass_kg": float(table["mass_kg"].sum())})

    panels, pieces = [], grid.pieces
    panel_settings, stocks = config.panels.to_settings(), config.sheets.to_settings()
    steps: dict[str, Callable[[], object]] = {}
    if config.panels.enabled:
        clock.start("panels: flatten")
        from fabrication.panels import FOLD_FIX, flatten_panels, trim_at_folds

        problems: list[tuple[str, str]] = []
        glazing = PolyMesh(nodes=polymesh.nodes, faces=tuple(p.loop for p in pieces))
        panels = flatten_panels(glazing, panel_settings, problems=problems)
        findings += [Finding(kind="panel_outline", parts=[pid], stage="fabrication", message=message,
                             fix="[fabrication.panels] clearance, or a new grid ([remesh] seed)")
                     for pid, message in problems]
    seats = _seats(polymesh, geometries, sizes_mm, panels, pieces, joint_settings, rectangle)
    if panels:
        # resting on the joints, neighbours at a valley fold would close their joint: cut back
        folds: list[tuple[tuple[str, ...], str]] = []
        panels, cut_back = trim_at_folds(panels, [p.loop for p in pieces], polymesh.nodes, seats, panel_settings,
                                         problems=folds)
        findings += [Finding(kind="panel_outline", parts=list(ids), stage="fabrication", message=message, fix=FOLD_FIX)
                     for ids, message in folds]
        summary.update({"panels_cut_back_at_folds": int((cut_back > 0).sum()),
                        "panel_cut_back_max_mm": round(float(cut_back.max()), 1)})
        cells = {panel.id: (pieces[panel.face].cell + 1, pieces[panel.face].piece) for panel in panels}
        steps["panels"] = partial(_panel_files, panels, panel_settings, stocks, folder / "panels", cells)
    if sections is not None:  # the sized tubes carry the erection stages too
        props = sections.frame_properties(beam_properties(project)[2])
    beam = {"E": props.E, "G": props.G, "A": props.A, "Iy": props.Iy, "Iz": props.Iz, "J": props.J,
            "mass_per_length": props.mass_per_length}
    steps["assembly sequence"] = partial(_assembly_files, polymesh, beam, config.assembly.deflection_limit,
                                         folder / "assembly")
    steps["drawings"] = partial(write_plan_drawings, polymesh, folder / "drawings",
                                project_name=project.project.name, support_nodes=np.flatnonzero(polymesh.supports))
    joint_radius_mm = getattr(joint_settings, "hub_radius_mm", None) or 1.5 * float(sizes_mm.max())
    # gridshell.step takes the joints' own solids: written once they are built (see run)
    write_model = partial(_write_model_step, polymesh, panels, seats, table, sizes_mm, solid_walls_mm, rectangle,
                          panel_settings, joint_radius_mm, folder / "gridshell.step", slots)
    if spheres:
        steps["model: gridshell.step"] = partial(write_model, JointSolids())
    steps["beams: beams.step"] = partial(write_beams_step, polymesh, table, folder / "beams" / "beams.step",
                                         outer_size_mm=sizes_mm, wall_mm=solid_walls_mm, slots=slots,
                                         rectangle=rectangle)
    # independent steps, longest first: here one after another, and on the joints' workers as they run
    # out of joints (the default job's joints outlast them; a large roof's steps outlast its joints)
    clock.start("panels, assembly, drawings, models (wall clock)")
    done = share(steps, ctx.step)
    clock.stop()
    for name, (result, seconds, where) in done.items():
        on = " (on a worker)" if where == "worker" else ""
        parts = result.seconds if isinstance(result, _PanelFiles) else {name: seconds}
        clock.seconds.update({part: round(s, 3) for part, s in ((k + on, v) for k, v in parts.items())})
    if "model: gridshell.step" in done:
        summary["gridshell_step"] = done["model: gridshell.step"][0]
    if "panels" in done:
        files: _PanelFiles = done["panels"][0]
        stock_nesting = files.nesting
        largest = max(stocks, key=lambda s: s.width_mm * s.height_mm)
        for i, (w, h, over) in files.overshoots.items():
            findings.append(Finding(
                kind="sheet_size", parts=[panels[i].id], measure=over, limit=1.0, unit="x sheet",
                stage="fabrication",
                message=(f"panel {panels[i].id} ({w:.0f} x {h:.0f} mm) fits no stock sheet "
                         f"(largest {largest.width_mm:g} x {largest.height_mm:g} mm"
                         + (", its grain along the sheet's length" if panels[i].grain_deg is not None else "")
                         + "); its DXF is written"),
                fix="add a larger size to [fabrication.sheets] sizes, or more cells ([remesh] n_cells)"
                    + (f"; or [fabrication.panels] grain = \"none\" (now \"{panel_settings.grain}\")"
                       if panels[i].grain_deg is not None else "")))
        summary.update({"panels": len(panels), "sheets": int(stock_nesting.n_sheets),
                        "sheet_sizes_mm": [[s.width_mm, s.height_mm, n.n_sheets] for s, _, n in stock_nesting.groups],
                        "sheet_utilisation": float(stock_nesting.utilisation),
                        "panels_over_planarity_tolerance": [getattr(x, "id", "") for x in panels
                                                            if getattr(x, "nonplanar", False)]})
    written = done["assembly sequence"][0]
    # the stage folder is a temporary one until the stage succeeds: name the file from the stage's folder
    written["csv"] = Path(written["csv"]).relative_to(folder).as_posix()
    summary["assembly"] = written
    clock.start("model: gridshell.ifc")  # while the joints build: it needs their geometry only
    from fabrication.nc1 import grade_name

    beams, plates, joints = _swept_parts(project, folder, polymesh, geometries, table, panels, sizes_mm,
                                         solid_walls_mm, rectangle, joint_settings, seats, slots)
    kind = material(project.material.name).kind
    write_gridshell_ifc(folder / "gridshell.ifc", project_name=project.project.name, beams=beams, panels=plates,
                        joints=joints, beam_material=grade_name(project.material.name),
                        beam_category=IFC_MATERIAL_CATEGORY.get(kind, kind),
                        site_origin_m=np.asarray(summary["site_origin_m"], dtype=float))
    summary["ifc"] = "gridshell.ifc"
    clock.start("model: gridshell.3dm")
    write_gridshell_3dm(folder / "gridshell.3dm", beams, plates, joints)
    return None if spheres else write_model


@dataclass(frozen=True)
class _PanelFiles:
    """What the panels' step returns: the nesting on the stock sizes, the panels too large for every
    size (index -> width, height mm and overshoot), and its sub-steps' seconds."""

    nesting: StockNesting
    overshoots: dict[int, tuple[float, float, float]]
    seconds: dict[str, float]


def _panel_files(panels: list[Panel], settings: PanelSettings, stocks: list[SheetSettings], folder: Path,
                 cells: dict[str, tuple[int, int]]) -> _PanelFiles:
    """Every panel file: one DXF per panel, the nesting on the stock sheets, the sheets' DXFs and
    contact sheet, panels.csv (a step that may run in a worker process)."""
    from fabrication.nesting_sheets import nest_on_stock, sheet_overshoot, write_contact_sheet, write_sheet_dxfs
    from fabrication.panels import write_panel_dxfs, write_panels_csv

    clock = _StepClock()  # no progress from a worker process
    clock.start("panels: DXFs")
    write_panel_dxfs(panels, folder, settings)
    clock.start("panels: sheet nesting")
    nesting = nest_on_stock(panels, stocks)
    clock.start("panels: sheet DXFs, picture, CSV")
    numbered = [(nesting_k, [panels[i] for i in members], first)
                for first, (_, members, nesting_k) in zip(nesting.first_numbers(), nesting.groups)]
    for nesting_k, group, first in numbered:
        write_sheet_dxfs(nesting_k, group, folder / "sheets", settings, first_number=first)
    if numbered:  # every sheet of every stock size, on one contact sheet
        write_contact_sheet(numbered, folder / "sheets.png")
    write_panels_csv(panels, None, settings, folder / "panels.csv", sheet_names=nesting.sheet_of(panels), cells=cells)
    clock.stop()
    return _PanelFiles(nesting=nesting, overshoots={i: sheet_overshoot(panels[i], stocks) for i in nesting.unfit},
                       seconds=clock.seconds)


def _assembly_files(polymesh: PolyMesh, beam: dict, deflection_limit_m: float | None, folder: Path) -> dict:
    """The assembly sequence planned and written (fabrication.assembly); returns write_assembly's summary."""
    sequence = plan_assembly(polymesh, np.flatnonzero(polymesh.supports), beam, deflection_limit_m=deflection_limit_m)
    return dict(write_assembly(sequence, polymesh, folder))


def _swept_parts(project: Project, folder: Path, polymesh: PolyMesh, geometries: list[JointGeometry], table,
                 panels: list, sizes: np.ndarray, walls: np.ndarray | None, rectangle: RectangularSection | None,
                 joint_settings: JointSettings, seats: tuple[np.ndarray, np.ndarray], slots: EndSlots | None
                 ) -> tuple[list[IfcBeam], list[IfcPanel], list[IfcJoint]]:
    """The parts as swept solids for gridshell.ifc and gridshell.3dm (fabrication.ifc's records), from
    the stage's cut list, panels (resting where ``seats`` puts them, as in gridshell.step),
    panels.csv, sequence.csv and the joints' ``geometries`` as the joint solids are built from them."""
    import pandas as pd

    step_of: dict[str, int] = {}
    sequence = folder / "assembly" / "sequence.csv"
    if sequence.is_file():
        for row in pd.read_csv(sequence).itertuples():
            for part in str(row.parts).split():
                step_of.setdefault(part, int(row.step))
    beams = []
    starts, directions = tube_axes_mm(polymesh, table["setback_start_mm"].to_numpy())
    for k, (row, start, direction) in enumerate(zip(table.itertuples(index=False), starts, directions)):
        if row.cut_length_mm <= 0:
            continue
        # the end slots of steel fin plates, as tube_solids cuts them
        ends = (tuple(zip(slots.sides[k], slots.lengths[k]))
                if slots is not None and slots.fit(k, row.cut_length_mm) else ())
        beams.append(IfcBeam(id=row.id, start_mm=start, direction=direction,
                             cut_length_mm=float(row.cut_length_mm),
                             size_mm=float(sizes[k]) if rectangle is None else rectangle.height_mm,
                             width_mm=None if rectangle is None else rectangle.width_mm,
                             up=None if rectangle is None else rectangle.up[k],
                             wall_mm=0.0 if walls is None else float(walls[k]), profile=str(row.profile),
                             mass_kg=float(row.mass_kg),
                             step=step_of.get(row.id), slots=ends,
                             slot_width_mm=slots.width if slots is not None else 0.0))
    sheets, masses = {}, {}
    panels_csv = folder / "panels" / "panels.csv"
    if panels_csv.is_file():
        frame = pd.read_csv(panels_csv)
        sheets = dict(zip(frame["id"], frame["sheet"].astype("string").fillna("")))
        masses = dict(zip(frame["id"], frame["mass_kg"]))
    glazing = project.fabrication.panels.to_settings()
    plates = []
    for panel, up, shift in zip(panels, *seats):
        axes = np.asarray(panel.axes)
        if float(np.cross(axes[0], axes[1]) @ up) < 0:  # the plate's thickness towards up, off its seat
            axes = axes[::-1]
        plates.append(IfcPanel(id=panel.id, outline_mm=MM * np.asarray(panel.outline_3d_m) + shift, axes=axes,
                               thickness_mm=glazing.thickness_mm, material=glazing.material_name,
                               mass_kg=float(masses.get(panel.id, 0.0)),
                               sheet=str(sheets.get(panel.id, "")), step=step_of.get(panel.id)))
    joints = []
    settings = joint_settings
    for g in geometries:
        own = g.sizes_mm
        size = g.beam_size_mm
        setback = geometry_setback_mm(settings, g)
        reach = setback + np.array([joint_sleeve_mm(settings, s) for s in own])
        bore = 0.5 * own + settings.clearance_mm
        steel = settings.kind == "steel"
        joints.append(IfcJoint(id=joint_id(g.node), position_mm=g.position_mm, axis=g.axis, directions=g.directions,
                               hub_radius_mm=joint_hub_radius_mm(settings, size),
                               hub_height_mm=geometry_hub_height_mm(settings, g),
                               setback_mm=setback, reach_mm=reach, outer_mm=bore + settings.wall_mm, bore_mm=bore,
                               plate_mm=(settings.plate_thickness_mm, joint_plate_height_mm(settings, size))
                               if steel else None,
                               part_file=f"joints/{joint_id(g.node)}.step"))
    return beams, plates, joints


def _jsonable(value):
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def _density(project: Project) -> float:
    if project.material.density is not None:
        return project.material.density
    return material(project.material.name).density


def _write_bars_by_profile(nestings: list, path: Path) -> None:
    """bars.csv of every profile's nesting, bars numbered on from one profile to the next, with a
    profile column."""
    import pandas as pd

    rows: list[dict] = []
    for profile, nesting in nestings:
        rows += nesting.rows(first_number=len(rows) + 1, profile=profile)
    columns = ["bar", "profile", "pieces", "lengths_mm", "count", "used_mm", "offcut_mm"]
    with atomic_path(path) as tmp:
        pd.DataFrame(rows, columns=columns).to_csv(tmp, index=False)


def load(folder: Path, project: Project) -> FabricationResult:
    return FabricationResult.of_summary(json.loads((folder / "fabrication.json").read_text()))
