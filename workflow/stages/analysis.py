"""Stage ``analysis``: the beam grid-shell checked as an engineer signs it off.

Linear static under SLS (deflection) and ULS (member forces and checks), linear buckling,
geometrically non-linear analysis of the perfect and imperfect shapes (METHOD.md 5), and
for projects with named control points the incremental load test (dead load held, then a
proportional load). Artifacts (06-analysis/): analysis.json (figures and the verdict
table), members.csv, response.csv and pictures (response, modes, utilisation, axial).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from engine.design.checks import member_checks
from engine.design.en1993 import CHECKED, NOT_CHECKED
from engine.design.load_test import load_test
from engine.design.sections import Material, Section, section_from_spec
from engine.design.sections import material as material_by_name
from engine.design.sizing import size_sections
from engine.design.verdicts import VerdictFixes, design_verdicts, findings_of
from engine.errors import ConvergenceError, MechanismError
from engine.findings import Finding
from engine.linalg import free_rigid_motions
from engine.mesh import PolyMesh
from engine.structure.frame import FrameModel, factor_stiffness, linear_buckling, linear_static
from engine.structure.grid_model import (
    BeamProperties,
    beam_up_vectors,
    gridshell_loads,
    node_normals,
    support_restraints,
)
from engine.structure.loads import LoadCombination, combine
from engine.structure.loads import pick_combination as choose_combination
from engine.structure.protocol import run_protocol
from engine.structure.supports import Supports
from fabrication.files import atomic_path, write_text_atomic
from fabrication.ids import beam_id, node_id

from ..config import Project
from ..plots.analysis import plot_axial_forces, plot_buckling_modes, plot_response, plot_sections, plot_utilisation
from ..pools import process_pool
from ..runner import StageContext
from .optimize import OptimizedGrid
from .sizing import (
    BeamSections,
    checks_method,
    make_analyse,
    profile_name,
    project_catalogue,
    project_sections,
    sized_checks,
    start_tubes,
)
from .surface import SurfaceResult

__all__ = ["run", "load", "beam_properties", "build_frame", "grid_normals", "pick_combination", "linear_axial_forces",
           "AnalysisSummary"]


@dataclass(frozen=True, kw_only=True)
class AnalysisSummary:
    """What later stages need: the figures (analysis.json), per-beam axial forces (N) and, where
    the tubes were sized ([design] size_sections), each beam's tube."""

    figures: dict
    axial_forces: np.ndarray
    sections: BeamSections | None = None


def beam_properties(project: Project) -> tuple[BeamProperties, Section, Material]:
    """(BeamProperties, section object, material object) from the project's material and section."""
    material = material_by_name(project.material.name)
    overrides = {k: v for k, v in (("E", project.material.E), ("G", project.material.G),
                                   ("density", project.material.density),
                                   ("fy", project.material.yield_strength)) if v is not None}
    if overrides:
        material = replace(material, **overrides)
    section = section_from_spec(project.section.kind, **project.section.dimensions())
    props = BeamProperties(E=material.E, G=material.G, A=section.A, Iy=section.Iy, Iz=section.Iz, J=section.J,
                           mass_per_length=section.A * material.density)
    return props, section, material


def pick_combination(project: Project, surface: SurfaceResult, limit_state: str) -> LoadCombination:
    """The combination of ``limit_state`` (engine.structure.loads.pick_combination) with the name that
    ``[analysis] uls_combination`` or ``sls_combination`` asks for."""
    name = project.analysis.uls_combination if limit_state == "ULS" else project.analysis.sls_combination
    return choose_combination(surface.combinations, surface.load_cases, limit_state, name)


def grid_normals(polymesh: PolyMesh, surface: SurfaceResult, project: Project | None = None) -> np.ndarray:
    """(n_nodes, 3) the grid's node normals (engine.structure.grid_model.node_normals), mirror
    images of each other across [field] symmetry_planes where the grid is symmetric: the joints'
    axes and the beams' up vectors of the analysis and the fabrication."""
    planes = project.field.to_settings().symmetry_planes if project is not None else ()
    return node_normals(polymesh, surface.mesh, symmetry_planes=planes)


#: What a mechanism's message says to do.
SUPPORTS_HINT = ('hold more nodes or more directions in [[supports]] (select, restraint): roller_x, roller_y and '
                 'roller_z leave that axis free; a support that holds the roof up and lets it slide is '
                 'restraint = [0, 0, 1, 0, 0, 0]; with --surface: --supports boundary')


def build_frame(polymesh: PolyMesh, surface: SurfaceResult, props: BeamProperties,
                elements_per_beam: int, project: Project | None = None) -> tuple[FrameModel, Supports, np.ndarray]:
    """(FrameModel, Supports, node normals) of the grid-shell (``project``: its symmetry planes for
    the normals, grid_normals)."""
    normals = grid_normals(polymesh, surface, project)
    up = beam_up_vectors(polymesh, normals)
    n_beams = len(polymesh.edges)
    model = FrameModel(nodes=polymesh.nodes, beams=polymesh.edges, E=np.full(n_beams, props.E),
                       G=np.full(n_beams, props.G), A=np.full(n_beams, props.A), Iy=np.full(n_beams, props.Iy),
                       Iz=np.full(n_beams, props.Iz), J=np.full(n_beams, props.J), up=up,
                       elements_per_beam=elements_per_beam)
    nodes, flags = support_restraints(polymesh, surface.supports.nodes, surface.supports.restraints,
                                      surface.mesh.vertices)
    if len(nodes) == 0:
        raise MechanismError("the grid-shell has no supported node, so it is a free body",
                             n_modes=6, hint="check the supports of the surface: they must lie on the "
                                             "grid-shell's boundary")
    supports = Supports(nodes=nodes, restraints=flags)
    free = free_rigid_motions(polymesh.nodes, supports.dof_mask(polymesh.n_nodes).ravel())
    if free:  # the surface's supports can hold the shell and not the grid's fewer nodes
        raise MechanismError(f"the grid-shell is a mechanism: its {len(nodes)} supported nodes leave it free "
                             f"({', '.join(free)})", n_modes=len(free), hint=SUPPORTS_HINT)
    return model, supports, normals


def _plan_span(polymesh) -> float:
    extent = np.ptp(polymesh.nodes[:, :2], axis=0)
    return float(extent.min())


def run(surface: SurfaceResult, optimize: OptimizedGrid, project: Project, ctx: StageContext) -> AnalysisSummary:
    config = project.analysis
    polymesh = optimize.polymesh
    props, section, material = beam_properties(project)
    lengths = polymesh.beam_lengths
    sections = project_sections(project, len(lengths))
    method = checks_method(project, material) if sections is not None else "simplified"
    uls_combo, sls_combo = pick_combination(project, surface, "ULS"), pick_combination(project, surface, "SLS")
    span = _plan_span(polymesh)
    deflection_limit = span / config.deflection_limit_ratio
    settings = config.to_settings(span)
    mass_before = float(lengths.sum() * props.mass_per_length)
    design_run = protocol_with_design(ctx, project, polymesh, surface, material, method, sections,
                                      (uls_combo, sls_combo), deflection_limit, settings)
    result, sections, design, sizer, rounds = (design_run.result, design_run.sections, design_run.design,
                                               design_run.sizer, design_run.rounds)
    props, model, supports = design_run.props, design_run.model, design_run.supports
    worst = result.worst
    ctx.step("member checks")
    if sections is not None:
        checks = sized_checks(project, method, sections, material, result, lengths)
    else:
        checks = member_checks(result.uls_beam_end_forces, lengths, section, material,
                               buckling_length_factor=config.buckling_length_factor)
    utilisation = np.asarray(checks.utilisation)
    vertical_sls = float(np.abs(result.sls_displacements[:, 2]).max())
    verdicts = design_verdicts(utilisation=utilisation, sls_displacements=result.sls_displacements,
                               deflection_limit=deflection_limit, deflection_ratio=config.deflection_limit_ratio,
                               required_load_factor=config.required_load_factor, lambda_LB=result.lambda_LB,
                               buckling_error=result.buckling_error, worst=worst,
                               fixes=_fixes(project, sections))
    axial = np.asarray(checks.axial_force)
    figures = {
        "nodes": polymesh.n_nodes, "beams": int(len(polymesh.edges)), "cells": polymesh.n_faces,
        "supported_nodes": int(len(supports.nodes)), "total_beam_length_m": float(lengths.sum()),
        "beam_mass_kg": float((lengths * props.mass_per_length).sum()),
        "uls_combination": uls_combo.name, "sls_combination": sls_combo.name,
        "material": project.material.name, "section": project.section.model_dump(mode="json"),
        "delta_L_m": result.delta_L, "max_vertical_sls_m": vertical_sls, "deflection_limit_m": deflection_limit,
        "max_utilisation": float(utilisation.max()), "governing_member": beam_id(utilisation.argmax()),
        "lambda_LB": result.lambda_LB, "buckling_factors": [float(x) for x in result.buckling_factors],
        "lambda_NL_perfect": None if result.perfect is None else result.perfect.capacity,
        "lambda_NL_worst": None if worst is None else worst.capacity,
        "limit_point_reached": None if worst is None else worst.limit_load_factor is not None,
        "tolerable_deflection_m": settings.max_displacement,
        "worst_imperfection": None if worst is None else worst.name, "knock_down": result.knock_down,
        "imperfection_amplitude_m": settings.amplitude, "control_node": node_id(result.control_node),
        "equilibrium_error": result.equilibrium_error,
        "imperfections": [{"shape": c.name, "lambda_NL": c.capacity, "limit_point": c.limit_load_factor is not None,
                           "tolerable_deflection_reached": c.tolerable_load_factor is not None,
                           "path_complete": c.converged} for c in result.imperfect],
        "verdicts": [v.to_dict() for v in verdicts],
        "checks": _checks_note(method, checks),
        "findings": [f.to_dict() for f in findings_of(verdicts, stage="analysis")],
    }
    if design is not None:
        figures["design"] = sizer.summary(design, sections, checks, lengths, mass_before, rounds)
        if not design.converged:
            figures["findings"].append(sizer.finding(design, utilisation))
        outgrown = sizer.outgrown(sections, project)
        if outgrown is not None:
            figures["findings"].append(outgrown)
    ctx.report_findings(figures["findings"])
    ctx.step("writing")
    write_text_atomic(ctx.folder / "analysis.json", json.dumps(figures, indent=1, default=float))
    import pandas as pd

    members = pd.DataFrame({"beam": [beam_id(i) for i in range(len(lengths))],
                            "start_node": [node_id(a) for a in polymesh.edges[:, 0]],
                            "end_node": [node_id(b) for b in polymesh.edges[:, 1]],
                            "length_m": lengths, "axial_force_kN": axial / 1e3, "utilisation": utilisation,
                            "governing_check": list(getattr(checks, "governing", [""] * len(lengths)))})
    if sections is not None:
        members["profile"] = sections.names
        members["diameter_mm"] = np.round(sections.diameter * 1000, 3)
        members["thickness_mm"] = np.round(sections.thickness * 1000, 3)
        members["section_class"] = np.asarray(getattr(checks, "section_class", np.zeros(len(lengths), int)))
        members["buckling_length_m"] = np.asarray(getattr(checks, "buckling_length", lengths))
    with atomic_path(ctx.folder / "members.csv") as tmp:
        members.to_csv(tmp, index=False, float_format="%.6g")
    rows = []
    for case in ([result.perfect] if result.perfect else []) + list(result.imperfect):
        rows += [{"shape": case.name, "load_factor": lf, "control_displacement_m": u} for lf, u in case.path]
    with atomic_path(ctx.folder / "response.csv") as tmp:
        pd.DataFrame(rows, columns=["shape", "load_factor", "control_displacement_m"]).to_csv(tmp, index=False)
    ctx.step("drawing")
    _draw(ctx, polymesh, result, utilisation, axial, project)
    if design is not None:
        plot_sections(polymesh.nodes, polymesh.edges, sections.names, sections.diameter, ctx.folder / "sections.png",
                      title=f"{project.project.name}: sized sections ({figures['design']['catalogue']})")
    if config.control_points and config.nonlinear:
        ctx.step("incremental load test")
        figures["load_test"] = _load_test(ctx, project, surface, polymesh, model, supports, props, sls_combo)
        write_text_atomic(ctx.folder / "analysis.json", json.dumps(figures, indent=1, default=float))
    # what the artifacts say, as a cached run reads it: the later stages see the same either way
    return load(ctx.folder, project)


def _fixes(project: Project, sections: BeamSections | None) -> VerdictFixes:
    """What to change when a verdict fails, naming the project file's keys."""
    dimensions = {"circular_hollow": "diameter or thickness", "solid_round": "diameter",
                  "rectangular_hollow": "height, width or thickness"}.get(project.section.kind, "height or width")
    stiffer = (f"a larger [section] {dimensions}, a stronger [material], or more supports ([[supports]])"
               + ("" if project.design.size_sections or sections is None else
                  "; or let the tubes be sized: [design] size_sections = true"))
    return VerdictFixes(stiffer=stiffer,
                        deflection=f"{stiffer}; or [analysis] deflection_limit_ratio if the limit is not the project's",
                        buckling_not_solved="check the supports ([[supports]]) for a near-mechanism, or fewer "
                                            "[analysis] n_modes; the non-linear paths ran without mode-shaped "
                                            "imperfections",
                        path_stopped="the solver stopped, not the structure: its load factor is only a lower "
                                     "bound. Check the supports ([[supports]]) for a near-mechanism; or leave "
                                     "that shape out of [analysis] imperfection_shapes, or set [analysis] "
                                     "elements_per_beam, and run again")


def _load_test(ctx, project: Project, surface, polymesh, model, supports, props, combination) -> dict:
    """The mock-up's incremental load test (METHOD.md 7, engine.design.load_test) under the SLS
    combination: loadtest.csv (the vertical deflection of each named control point's nearest node
    against the load factor), its picture and the record for analysis.json."""
    import pandas as pd

    test = load_test(model, supports, surface.load_cases, combination, project.analysis.control_points,
                     lambda case: gridshell_loads(polymesh, case, mass_per_length=props.mass_per_length,
                                                  surface_vertices=surface.mesh.vertices),
                     max_load_factor=project.analysis.max_load_factor)
    if test is None:
        return {"skipped": "the SLS combination has no variable load case to increase"}
    table = pd.DataFrame({"load_factor": test.load_factors})
    for name, column in zip(test.control_nodes, test.monitored.T):
        table[f"{name}_uz_mm"] = 1000 * column
    with atomic_path(ctx.folder / "loadtest.csv") as tmp:
        table.to_csv(tmp, index=False, float_format="%.6g")
    curves = {f"{name} ({node_id(n)})": np.c_[test.load_factors, column]
              for (name, n), column in zip(test.control_nodes.items(), test.monitored.T)}
    plot_response(curves, ctx.folder / "loadtest.png", required=project.analysis.required_load_factor,
                  title=f"{project.project.name}: load test, {', '.join(test.permanent) or 'no'} load held, "
                        f"{', '.join(test.variable)} increased")
    return test.to_dict()


def _draw(ctx, polymesh, result, utilisation, axial, project: Project) -> None:
    name = project.project.name
    plot_utilisation(polymesh.nodes, polymesh.edges, utilisation, ctx.folder / "utilisation.png",
                     title=f"{name}: member utilisation (ULS)")
    plot_axial_forces(polymesh.nodes, polymesh.edges, axial, ctx.folder / "axial.png",
                      title=f"{name}: axial forces (ULS), compression red, tension blue")
    if len(result.buckling_factors):
        plot_buckling_modes(polymesh.nodes, polymesh.edges, result.buckling_modes[:4], result.buckling_factors[:4],
                            ctx.folder / "modes.png", title=f"{name}: linear buckling modes")
    cases = ([result.perfect] if result.perfect else []) + list(result.imperfect)
    curves = {c.name: np.asarray(c.path) for c in cases}
    if curves:
        worst = result.worst.name if result.worst else None
        ends = {c.name: (c.read_at, c.capacity) for c in cases if c.read_at != "carried"}
        plot_response(curves, ctx.folder / "response.png", worst=worst, required=project.analysis.required_load_factor,
                      title=f"{name}: load factor against control-node deflection", ends=ends)


def load(folder: Path, project: Project) -> AnalysisSummary:
    figures = json.loads((folder / "analysis.json").read_text())
    import pandas as pd

    members = pd.read_csv(folder / "members.csv")
    sections = None
    if "design" in figures and {"profile", "diameter_mm", "thickness_mm"} <= set(members.columns):
        sections = BeamSections(names=members["profile"].astype(str).tolist(),
                                diameter=members["diameter_mm"].to_numpy(float) / 1000,
                                thickness=members["thickness_mm"].to_numpy(float) / 1000,
                                process=figures["design"].get("process"))
    return AnalysisSummary(figures=figures, axial_forces=members["axial_force_kN"].to_numpy() * 1e3, sections=sections)


def frame_and_loads(polymesh, surface, props: BeamProperties, cases, elements_per_beam: int,
                    project: Project | None = None):
    """(FrameModel, Supports, [nodal loads (n,6) per load case]) of the grid-shell with ``props``
    (whose mass per length the self-weight takes); ``project`` as for build_frame."""
    model, supports, _ = build_frame(polymesh, surface, props, elements_per_beam, project)
    loads = [gridshell_loads(polymesh, case, mass_per_length=props.mass_per_length,
                             surface_vertices=surface.mesh.vertices) for case in cases]
    return model, supports, loads


def linear_axial_forces(polymesh: PolyMesh, surface: SurfaceResult, project: Project) -> np.ndarray:
    """(n_beams,) axial forces, N (tension > 0), of a linear static analysis of ``polymesh`` with the
    project's section under its ULS combination: the frame model and loads of this stage, each
    beam's force the mean of its two ends."""
    props = beam_properties(project)[0]
    case = combine(surface.load_cases, pick_combination(project, surface, "ULS"))
    model, supports, (loads,) = frame_and_loads(polymesh, surface, props, [case], project.analysis.elements_per_beam,
                                                project)
    return linear_static(model, supports, loads).beam_end_forces[:, :, 0].mean(axis=1)


@dataclass(frozen=True, kw_only=True)
class DesignRun:
    """The protocol's result on the final sections, with the sizing that chose them (None without
    ``[design] size_sections``): sections, design (engine.design.sizing.Design), sizer, rounds (of the
    non-linear limit), and the frame model, supports and beam properties it ran on."""

    result: object
    sections: BeamSections | None
    design: object
    sizer: object
    rounds: int
    model: object
    supports: Supports
    props: BeamProperties


def protocol_with_design(ctx, project: Project, polymesh, surface, material, method: str,
                         sections: BeamSections | None, combos, deflection_limit: float, settings, *,
                         executor=None) -> DesignRun:
    """The structural protocol on ``polymesh``; with ``[design] size_sections`` on tubes sized first,
    and sized again for a higher lambda_LB (up to ``nonlinear_rounds`` times) where
    lambda_NL_worst misses its limit. ``ctx`` needs ``step(text, fraction=None)``; ``executor``
    runs the paths (default: a pool of ``[analysis] workers``)."""
    config = project.analysis
    cases = [combine(surface.load_cases, c) for c in combos]
    props = beam_properties(project)[0]
    design = sizer = None
    if project.design.size_sections:
        sizer = _Sizer(ctx, project, polymesh, surface, material, method, cases, deflection_limit)
        design = sizer.size(None)
        sections = sizer.sections(design)
    rounds = 0
    while True:
        if sections is not None:
            props = sections.frame_properties(material)
        ctx.step("frame model")
        model, supports, (uls_loads, sls_loads) = frame_and_loads(polymesh, surface, props, cases,
                                                                 config.elements_per_beam, project)
        if executor is not None:
            result = run_protocol(model, supports, sls_loads, uls_loads, settings, progress=ctx.step,
                                  executor=executor)
        else:
            with process_pool(config.workers if config.nonlinear else 1) as pool:
                result = run_protocol(model, supports, sls_loads, uls_loads, settings, progress=ctx.step,
                                      executor=pool)
        worst = result.worst
        short = worst is not None and worst.capacity < config.required_load_factor
        if design is None or not short or not design.converged or rounds >= project.design.nonlinear_rounds:
            return DesignRun(result=result, sections=sections, design=design, sizer=sizer, rounds=rounds,
                             model=model, supports=supports, props=props)
        rounds += 1
        stiffer = 1.05 * config.required_load_factor / max(worst.capacity, 1e-3)
        ctx.step(f"lambda_NL_worst {worst.capacity:.2f} under {config.required_load_factor:g}: "
                 f"sections {rounds} of {project.design.nonlinear_rounds} sized for {stiffer:.2f} times lambda_LB")
        # the knock-down lambda_NL / lambda_LB taken as it is: lambda_LB must grow by the ratio missed,
        # and the sizing puts the stiffness where the first mode's energy is (uniformly without modes)
        if result.lambda_LB is not None:
            design = sizer.size(design, buckling_target=stiffer * result.lambda_LB)
        else:
            design = sizer.size(design, stiffness_factor=stiffer)
        sections = sizer.sections(design)


def _checks_note(method: str, checks) -> dict:
    """What the member checks cover, for analysis.json and the report."""
    if method == "en1993":
        return {"method": "EN 1993-1-1 (circular hollow sections)", "checked": list(CHECKED),
                "not_checked": list(NOT_CHECKED)}
    return {"method": "simplified (linear N+M interaction, elastic moduli, flexural buckling with k = 1)",
            "checked": ["axial force with bending", "flexural buckling"],
            "not_checked": ["section class", "shear", "torsion", "joints", "fatigue", "fire"]}


class _Sizer:
    """The stage's use of engine.design.sizing: a design's linear response (ULS forces, SLS deflection,
    lambda_LB) and what analysis.json says of the sizing."""

    def __init__(self, ctx, project: Project, polymesh, surface, material, method: str, cases, deflection_limit):
        """``cases``: the ULS and SLS load cases (engine.structure.loads.combine of the combinations)."""
        self.ctx, self.project, self.polymesh, self.surface = ctx, project, polymesh, surface
        self.material, self.method, self.deflection_limit = material, method, deflection_limit
        self.catalogue = project_catalogue(project)
        self.lengths = polymesh.beam_lengths
        self.cases = cases
        self.history: list[dict] = []
        self.required = project.analysis.required_load_factor  # lambda_LB asked of the design

    def _solve(self, sections: BeamSections):
        model, supports, (uls, sls) = frame_and_loads(self.polymesh, self.surface,
                                                      sections.frame_properties(self.material), self.cases,
                                                      self.project.analysis.elements_per_beam, self.project)
        stiffness = factor_stiffness(model, supports)
        uls_result = linear_static(model, supports, uls, stiffness=stiffness)
        sls_result = linear_static(model, supports, sls, stiffness=stiffness, with_energy=True)
        deflection = float(np.abs(sls_result.displacements[:, 2]).max())
        try:
            buckling = linear_buckling(model, supports, uls, n_modes=1, stiffness=stiffness)
            factors, buckling_energy = buckling.factors, buckling.beam_energy
        except ConvergenceError:
            factors, buckling_energy = np.zeros(0), None
        return (uls_result.beam_end_forces, deflection, (float(factors[0]) if len(factors) else None),
                (sls_result.beam_energy, buckling_energy))

    def size(self, previous, *, stiffness_factor: float = 1.0, buckling_target: float | None = None):
        """A design from the start tubes, or from ``previous`` with every I raised by
        ``stiffness_factor`` or with lambda_LB at least ``buckling_target``."""
        cat, design = self.catalogue, self.project.design
        start = start_tubes(self.project, cat, len(self.lengths)) if previous is None else previous.tube
        floor = None if previous is None or buckling_target is not None else stiffness_factor * cat.I[previous.tube]
        self.required = max(self.required, buckling_target or 0.0)
        analyse = make_analyse(self.method, cat, self.material, self.lengths, self._solve, self.project)
        result = size_sections(analyse, cat, self.lengths, self.material.density, start=start, groups=design.groups,
                               deflection_limit=self.deflection_limit,
                               required_load_factor=self.required, stiffness_floor=floor,
                               max_iterations=design.max_iterations, progress=lambda text: self.ctx.step(text))
        round_ = 0 if previous is None else self.history[-1]["round"] + 1
        self.history += [{"round": round_, **record} for record in result.iterations]
        return result

    def sections(self, design) -> BeamSections:
        return BeamSections.of_catalogue(self.catalogue, design.tube)

    def summary(self, design, sections: BeamSections, checks, lengths, mass_before: float, rounds: int) -> dict:
        mass = self.catalogue.mass_per_length(self.material.density)[design.tube] * lengths
        groups = []
        governing = np.asarray(checks.governing if checks.governing is not None else [""] * len(lengths))
        utilisation = np.asarray(checks.utilisation)
        for tube in sorted(set(design.tube.tolist()), key=lambda k: -self.catalogue.A[k]):
            beams = design.tube == tube
            names, counts = np.unique(governing[beams], return_counts=True)
            groups.append({"profile": self.catalogue.names[tube],
                           "diameter_mm": round(1000 * self.catalogue.diameter[tube], 3),
                           "thickness_mm": round(1000 * self.catalogue.thickness[tube], 3),
                           "beams": int(beams.sum()), "length_m": float(lengths[beams].sum()),
                           "mass_kg": float(mass[beams].sum()), "max_utilisation": float(utilisation[beams].max()),
                           "governing": str(names[np.argmax(counts)]) if len(names) else ""})
        names, counts = np.unique(governing, return_counts=True)
        return {"catalogue": self.catalogue.name, "process": self.catalogue.process,
                "catalogue_source": self.catalogue.source.splitlines()[:2],
                "checks": self.method, "groups_asked": self.project.design.groups, "converged": design.converged,
                "reason": design.reason,
                "failing_member": None if design.failing_beam is None else beam_id(design.failing_beam),
                "iterations": len(self.history), "history": self.history, "nonlinear_rounds": rounds,
                "mass_before_kg": mass_before, "mass_after_kg": float(mass.sum()), "groups": groups,
                "governing_checks": {str(n): int(c) for n, c in zip(names, counts)}}

    def outgrown(self, sections: BeamSections, project: Project) -> dict | None:
        """A finding where sized tubes are larger than the [section] the grid was made for (their
        joints need longer beams), unless the run makes the grid again for them."""
        larger = sections.diameter > project.section.diameter + 1e-6
        if not larger.any() or project.design.fit_grid_to_tubes:
            return None
        k = int(np.argmax(sections.diameter))
        section = profile_name(project)
        return Finding(kind="tubes_outgrow_grid", parts=[beam_id(i) for i in np.flatnonzero(larger)[:20]],
                       measure=float(1000 * sections.diameter[k]), limit=float(1000 * project.section.diameter),
                       unit="mm", stage="analysis",
                       message=f"{int(larger.sum())} beams were sized larger than the [section] {section} the grid "
                               f"was made for (largest {sections.names[k]}): their joints may clash or leave short "
                               "cuts (the fabrication's findings name them)",
                       fix=f"[design] max_diameter = \"{1000 * project.section.diameter:g} mm\" (thicker walls "
                           "instead), or [design] fit_grid_to_tubes = true (the grid made again for them, with "
                           "fewer cells), or [section] the larger tube").to_dict()

    def finding(self, design, utilisation: np.ndarray) -> dict:
        """The sizing's finding: the beam no tube passes with its utilisation, or why it stopped."""
        beam = design.failing_beam
        part = beam_id(beam) if beam is not None else "design"
        reason = design.reason.replace("this beam", part) if beam is not None else design.reason
        measure = None if beam is None else float(utilisation[beam])
        return Finding(kind="sizing", parts=[part], measure=measure, limit=None if beam is None else 1.0,
                       unit="", stage="analysis",
                       fix="a catalogue with larger tubes ([design] catalogue), more supports ([[supports]]) or a "
                           "stronger [material]; the analysis used the least utilised tube where none passed",
                       message=f"section sizing: {reason}"
                               + ("" if measure is None else f" (utilisation {measure:.2f} with its tube)")).to_dict()
