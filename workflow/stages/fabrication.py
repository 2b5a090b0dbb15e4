"""Stage ``fabrication``: everything a workshop needs to build the checked grid-shell.

Artifacts (07-fabrication/): joints/ (J0001.step, J0001.stl ..., joints.step), beams/
(cutlist.csv, cutlist.xlsx, bars.csv, beams.step), panels/ (P0001.dxf ..., sheets/S01.dxf
..., panels.csv), assembly/ (sequence.csv, steps/*.png), drawings/ (plan.dxf, plan.pdf),
gridshell.step, gridshell.3dm and fabrication.json (counts and checks, and the seconds each step
took, ``step_seconds``). Lengths in mm.
"""

from __future__ import annotations

import importlib
import json
import time
from pathlib import Path

import numpy as np

from engine.structure import node_normals
from fabrication.files import write_text_atomic

from ..config import Project
from ._require import require

__all__ = ["run", "load", "beam_outer_size_mm"]

MM = 1000.0


def beam_outer_size_mm(project: Project) -> float:
    """The beam's largest outer dimension in mm (tube or rod diameter, or the section height)."""
    s = project.section
    return MM * (s.diameter if s.diameter is not None else max(s.height or 0.0, s.width or 0.0))


class _StepClock:
    """Seconds per named step of the stage: each ``start`` ends the step before."""

    def __init__(self, ctx) -> None:
        self._ctx = ctx
        self.seconds: dict[str, float] = {}
        self._name: str | None = None
        self._started = 0.0

    def start(self, name: str) -> None:
        self.stop()
        self._ctx.step(name)
        self._name, self._started = name, time.perf_counter()

    def stop(self) -> None:
        if self._name is not None:
            self.seconds[self._name] = round(self.seconds.get(self._name, 0.0) + time.perf_counter() - self._started, 3)
            self._name = None


def run(ctx):
    project: Project = ctx.project
    clock = _StepClock(ctx)
    config = project.fabrication
    surface = ctx.result("surface")
    polymesh = ctx.result("optimize")
    ctx.result("analysis")
    folder: Path = ctx.folder
    normals = node_normals(polymesh, surface.mesh)
    size_mm = beam_outer_size_mm(project)
    summary: dict = {"nodes": polymesh.n_nodes, "beams": int(len(polymesh.edges)), "cells": polymesh.n_faces}

    JointSettings, JointsInBackground = require("fabrication", "fabrication.joints", "JointSettings",
                                                "JointsInBackground")
    j = config.joints
    joint_settings = JointSettings(**{k: v for k, v in {
        "kind": j.kind, "clearance_mm": MM * j.clearance, "wall_mm": MM * j.wall, "min_wall_mm": MM * j.min_wall,
        "pin_hole_mm": MM * j.pin_hole, "engrave": j.engrave,
        "hub_radius_mm": None if j.hub_radius is None else MM * j.hub_radius,
        "sleeve_length_mm": None if j.sleeve_length is None else MM * j.sleeve_length,
        "plate_thickness_mm": MM * j.plate_thickness, "bolt_hole_mm": MM * j.bolt_hole}.items() if v is not None})
    summary.update({"joints": 0, "joint_problems": []})
    # the joints take both cores in worker processes; the other steps run here meanwhile
    clock.start("joints: start")
    with JointsInBackground(polymesh, normals, size_mm, joint_settings, folder / "joints",
                            workers=config.workers) as joints:
        _beams_panels_drawings_assembly(ctx, clock, polymesh, normals, joint_settings, summary)
        clock.start("joints: waiting")
        joints.wait(ctx.step)
    clock.stop()
    clock.seconds["joints (alongside the other steps)"] = round(joints.seconds, 3)
    joint_reports = joints.reports
    summary["joints"] = len(joint_reports)
    summary["joint_problems"] = [{k: v for k, v in r.items() if k != "seconds"} for r in joint_reports
                                 if not r.get("ok", True)]
    summary["step_seconds"] = clock.seconds
    write_text_atomic(folder / "fabrication.json", json.dumps(summary, indent=1, default=_jsonable))
    return summary


def _beams_panels_drawings_assembly(ctx, clock: _StepClock, polymesh, normals: np.ndarray, joint_settings,
                                    summary: dict) -> None:
    """Every step but the joints (they run meanwhile); fills ``summary``."""
    project: Project = ctx.project
    config = project.fabrication
    folder: Path = ctx.folder
    size_mm = beam_outer_size_mm(project)
    clock.start("beams: cut list")
    beams = require("fabrication", "fabrication.beams", "BeamSettings", "cut_list", "write_cut_list", "write_beams_step")
    BeamSettings, cut_list, write_cut_list, write_beams_step = beams
    nest_bars = require("fabrication", "fabrication.nesting_bars", "nest_bars")
    b = config.beams
    from .analysis import beam_properties

    props, section, _ = beam_properties(project)
    beam_settings = BeamSettings(profile_name=_profile_name(project), material_name=project.material.name,
                                 density=_density(project), stock_length_mm=MM * b.stock_length, kerf_mm=MM * b.kerf,
                                 area_m2=section.A, outer_size_mm=size_mm)
    table = cut_list(polymesh, normals, beam_settings, joint_settings)
    write_cut_list(table, folder / "beams")
    clock.start("beams: bar nesting")
    nesting = nest_bars(table["cut_length_mm"].to_numpy(), table["id"].tolist(), MM * b.stock_length, MM * b.kerf)
    _write_bars(nesting, folder / "beams" / "bars.csv")
    clock.start("beams: beams.step")
    write_beams_step(polymesh, table, folder / "beams" / "beams.step", outer_size_mm=size_mm)
    summary.update({"bars_used": int(nesting.bars_used), "bars_lower_bound": int(nesting.lower_bound),
                    "bar_nesting_method": getattr(nesting, "method", ""), "bar_waste_mm": float(nesting.waste_mm),
                    "total_cut_length_m": float(table["cut_length_mm"].sum() / MM),
                    "beam_mass_kg": float(table["mass_kg"].sum())})

    panels = []
    if config.panels.enabled:
        clock.start("panels: flatten and DXFs")
        (PanelSettings, flatten_panels, write_panel_dxfs, write_panels_csv) = require(
            "fabrication", "fabrication.panels", "PanelSettings", "flatten_panels", "write_panel_dxfs", "write_panels_csv")
        SheetSettings, nest_sheets, write_sheet_dxfs = require("fabrication", "fabrication.nesting_sheets", "SheetSettings",
                                                               "nest_sheets", "write_sheet_dxfs")
        p, s = config.panels, config.sheets
        panel_settings = PanelSettings(thickness_mm=MM * p.thickness, material_name=p.material, density=p.density,
                                       clearance_mm=MM * p.clearance, hole_diameter_mm=MM * p.hole_diameter,
                                       hole_inset_mm=MM * p.hole_inset, planarity_tolerance_mm=MM * p.planarity_tolerance,
                                       split_nonplanar=p.split_nonplanar)
        panels = flatten_panels(polymesh, panel_settings)
        write_panel_dxfs(panels, folder / "panels", panel_settings)
        clock.start("panels: sheet nesting")
        sheet_nesting = nest_sheets(panels, SheetSettings(width_mm=MM * s.width, height_mm=MM * s.height,
                                                          spacing_mm=MM * s.spacing, margin_mm=MM * s.margin,
                                                          rotations=s.rotations))
        clock.start("panels: sheet DXFs, picture, CSV")
        write_sheet_dxfs(sheet_nesting, panels, folder / "panels" / "sheets")
        picture = getattr(importlib.import_module("fabrication.nesting_sheets"), "write_sheets_picture", None)
        if picture is not None:
            picture(sheet_nesting, panels, folder / "panels" / "sheets.png")
        write_panels_csv(panels, sheet_nesting, panel_settings, folder / "panels" / "panels.csv")
        sheets = getattr(sheet_nesting, "n_sheets", None)
        if sheets is None:
            sheets = len(getattr(sheet_nesting, "sheets", []))
        summary.update({"panels": len(panels), "sheets": int(sheets),
                        "sheet_utilisation": float(getattr(sheet_nesting, "utilisation", 0.0)),
                        "panels_over_planarity_tolerance": [getattr(x, "id", "") for x in panels if getattr(x, "nonplanar", False)]})

    clock.start("drawings")
    write_plan_drawings = require("fabrication", "fabrication.drawings", "write_plan_drawings")
    write_plan_drawings(polymesh, folder / "drawings", project_name=project.project.name,
                        support_nodes=np.flatnonzero(polymesh.supports))
    clock.start("model: gridshell.step")
    write_gridshell_step, write_gridshell_3dm = require("fabrication", "fabrication.model3d", "write_gridshell_step",
                                                        "write_gridshell_3dm")
    joint_radius_mm = getattr(joint_settings, "hub_radius_mm", None) or 1.5 * size_mm
    write_gridshell_step(polymesh, panels, size_mm / 2, joint_radius_mm, folder / "gridshell.step")
    clock.start("model: gridshell.3dm")
    write_gridshell_3dm(polymesh, panels, size_mm / 2, joint_radius_mm, folder / "gridshell.3dm")

    clock.start("assembly sequence: plan")
    plan_assembly, write_assembly = require("fabrication", "fabrication.assembly", "plan_assembly", "write_assembly")
    beam = {"E": props.E, "G": props.G, "A": props.A, "Iy": props.Iy, "Iz": props.Iz, "J": props.J,
            "mass_per_length": props.mass_per_length}
    sequence = plan_assembly(polymesh, np.flatnonzero(polymesh.supports), beam,
                             deflection_limit_m=config.assembly.deflection_limit)
    clock.start("assembly sequence: files")
    written = dict(write_assembly(sequence, polymesh, folder / "assembly"))
    # the stage folder is a temporary one until the stage succeeds: name the file from the stage's folder
    written["csv"] = Path(written["csv"]).relative_to(folder).as_posix()
    summary["assembly"] = written


def _jsonable(value):
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def _profile_name(project: Project) -> str:
    s = project.section
    mm = {k: round(MM * v, 2) for k, v in s.dimensions().items()}
    return {"circular_hollow": f"CHS {mm.get('diameter')}x{mm.get('thickness')}",
            "rectangular_hollow": f"RHS {mm.get('height')}x{mm.get('width')}x{mm.get('thickness')}",
            "solid_round": f"RD {mm.get('diameter')}",
            "solid_rectangle": f"{mm.get('height')}x{mm.get('width')}"}[s.kind]


def _density(project: Project) -> float:
    if project.material.density is not None:
        return project.material.density
    material = require("fabrication", "engine.sections", "material")
    return material(project.material.name).density


def _write_bars(nesting, path: Path) -> None:
    writer = getattr(nesting, "to_csv", None)
    if writer is not None:
        writer(path)
        return
    write_bars_csv = require("fabrication", "fabrication.nesting_bars", "write_bars_csv")
    write_bars_csv(nesting, path)


def load(folder: Path, ctx):
    return json.loads((folder / "fabrication.json").read_text())
