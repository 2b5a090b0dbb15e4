"""The analysis stage's sections: one tube per beam, its member checks, and the sizing of
``[design] size_sections`` (engine.design.sizing) on the project's catalogue."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from engine.design.catalogue import CATALOGUES, Catalogue, catalogue, chs_properties
from engine.design.en1993 import ChecksMethod, EndForces, TubeChecks, buckling_alpha, chs_checks, simplified_checks
from engine.design.sections import Material
from engine.structure.grid_model import BeamProperties

from ..config import Project

__all__ = ["BeamSections", "project_sections", "checks_method", "tube_checks", "sized_checks", "buckling_lengths",
           "project_catalogue", "profile_name", "MM"]

MM = 1000.0


@dataclass(frozen=True, kw_only=True)
class BeamSections:
    """Per beam (b,): profile names, outer diameter and wall (m), and the arrays of the analysis."""

    names: list[str]
    diameter: np.ndarray
    thickness: np.ndarray
    process: str | None = None

    @property
    def properties(self) -> dict[str, np.ndarray]:
        return chs_properties(self.diameter, self.thickness)

    def frame_properties(self, material: Material) -> BeamProperties:
        p = self.properties
        return BeamProperties(E=material.E, G=material.G, A=p["A"], Iy=p["I"], Iz=p["I"], J=p["J"],
                              mass_per_length=p["A"] * material.density)

    @classmethod
    def of_catalogue(cls, cat: Catalogue, tube: np.ndarray) -> "BeamSections":
        return cls(names=[cat.names[k] for k in tube], diameter=cat.diameter[tube], thickness=cat.thickness[tube],
                   process=cat.process)


def profile_name(project: Project) -> str:
    """The project's [section] as a fabricator names it (CHS 48.3x3.2, RHS 100x50x4, ...)."""
    s = project.section
    order = {"circular_hollow": ("diameter", "thickness"), "rectangular_hollow": ("height", "width", "thickness"),
             "solid_round": ("diameter",), "solid_rectangle": ("height", "width")}[s.kind]
    mm = [f"{round(MM * getattr(s, k), 2):g}" for k in order]
    prefix = {"circular_hollow": "CHS ", "rectangular_hollow": "RHS ", "solid_round": "RD ", "solid_rectangle": ""}
    return prefix[s.kind] + "x".join(mm)


def project_sections(project: Project, n_beams: int) -> BeamSections | None:
    """The project's one [section] on every beam, where it is a tube (None otherwise)."""
    s = project.section
    if s.kind != "circular_hollow":
        return None
    # the shipped catalogue's manufacturing process (a project's own list has none): its buckling curve
    process = CATALOGUES.get(project.design.catalogue, (None, None))[1]
    return BeamSections(names=[profile_name(project)] * n_beams, diameter=np.full(n_beams, s.diameter),
                        thickness=np.full(n_beams, s.thickness), process=process)


def project_catalogue(project: Project) -> Catalogue:
    """The [design] catalogue, up to its max_diameter."""
    return catalogue(project.design.catalogue).up_to(project.design.max_diameter)


def checks_method(project: Project, material: Material) -> ChecksMethod:
    """en1993 (steel tubes, [analysis] checks = "en1993") or simplified (every other case)."""
    if (project.analysis.checks == "en1993" and project.section.kind == "circular_hollow"
            and material.kind == "steel"):
        return "en1993"
    return "simplified"


def buckling_lengths(project: Project, lengths: np.ndarray, end_forces: np.ndarray, I: np.ndarray, E: float,
                     lambda_LB: float | None) -> np.ndarray:
    """Buckling length per beam (m): k x node-to-node length, or (``[analysis] buckling_length =
    "buckling_modes"``) the length at which the beam's Euler load is lambda_LB times its ULS
    compression, N_cr = lambda_LB N_Ed (the node-to-node one where it is not compressed)."""
    node_to_node = project.analysis.buckling_length_factor * np.asarray(lengths, float)
    if project.analysis.buckling_length != "buckling_modes" or lambda_LB is None:
        return node_to_node
    compression = np.maximum(-np.asarray(end_forces)[:, :, 0], 0.0).max(axis=1)
    from_modes = np.pi * np.sqrt(E * I / np.maximum(lambda_LB * compression, 1e-300))
    return np.where(compression > 0, from_modes, node_to_node)


def tube_checks(method: ChecksMethod, forces: EndForces, diameter: np.ndarray, thickness: np.ndarray,
                material: Material, *, process: str | None, buckling_length: np.ndarray) -> TubeChecks:
    """The member checks of ``method`` on tubes (arrays broadcast: one per beam, or candidates)."""
    alpha = buckling_alpha(process, material)
    if method == "en1993":
        return chs_checks(forces, diameter, thickness, material, alpha=alpha, buckling_length=buckling_length)
    p = chs_properties(diameter, thickness)
    return simplified_checks(forces, p["A"], p["I"], p["W_el"], material, alpha=alpha,
                             buckling_length=buckling_length)


def sized_checks(project: Project, method: ChecksMethod, sections: BeamSections, material: Material, result,
                 lengths: np.ndarray) -> TubeChecks:
    """The member checks of every beam's own tube under a protocol result's ULS forces
    (engine.structure.protocol.ProtocolResult), with the project's buckling lengths."""
    forces = result.uls_beam_end_forces
    return tube_checks(method, EndForces.of(forces), sections.diameter, sections.thickness, material,
                       process=sections.process,
                       buckling_length=buckling_lengths(project, lengths, forces, sections.properties["I"],
                                                        material.E, result.lambda_LB))


def candidate_utilisation(method: ChecksMethod, end_forces: np.ndarray, cat: Catalogue, material: Material,
                          buckling_length: np.ndarray) -> np.ndarray:
    """(b, s) utilisation of every beam with every catalogue tube under these forces."""
    forces = EndForces.of(end_forces).column()
    return tube_checks(method, forces, cat.diameter[None, :], cat.thickness[None, :], material,
                       process=cat.process, buckling_length=np.asarray(buckling_length)[:, None]).utilisation


def start_tubes(project: Project, cat: Catalogue, n_beams: int) -> np.ndarray:
    """The first design: the lightest catalogue tube at least as stiff as the project's section."""
    I = chs_properties(project.section.diameter, project.section.thickness)["I"]
    stiff = np.flatnonzero(cat.I >= I * (1 - 1e-9))
    return np.full(n_beams, int(stiff[0]) if len(stiff) else len(cat) - 1)


def make_analyse(method: ChecksMethod, cat: Catalogue, material: Material, lengths: np.ndarray,
                 solve: Callable[[BeamSections], tuple[np.ndarray, float, float | None, tuple]],
                 project: Project):
    """analyse(tube indices) for engine.design.sizing: ``solve`` gives (ULS end forces, SLS deflection,
    lambda_LB, (SLS and buckling strain energy shares per beam)) of a design."""
    from engine.design.sizing import DesignState

    def analyse(tube: np.ndarray) -> DesignState:
        sections = BeamSections.of_catalogue(cat, tube)
        end_forces, deflection, lambda_LB, energies = solve(sections)
        L_cr = buckling_lengths(project, lengths, end_forces, cat.I[tube], material.E, lambda_LB)
        return DesignState(utilisation=candidate_utilisation(method, end_forces, cat, material, L_cr),
                           deflection=deflection, lambda_LB=lambda_LB, deflection_energy=energies[0],
                           buckling_energy=energies[1])

    return analyse
