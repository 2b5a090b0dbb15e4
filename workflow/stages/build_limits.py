"""The project's joints and tube in fabrication's terms (mm), and the limits they set on the grid:
the shortest buildable beam and the smallest angle between two beams at a joint.

The stages that make the grid (remesh, optimize) hold it to these limits, and the fabrication
stage builds the joints from the same settings, so they live here, upstream of all three.
"""

from __future__ import annotations

from fabrication.joints import JointSettings
from fabrication.limits import BuildLimits

from ..config import Project

__all__ = ["MM", "beam_outer_size_mm", "joint_settings_of", "build_limits_of"]

MM = 1000.0


def beam_outer_size_mm(project: Project) -> float:
    """The beam's largest outer dimension in mm (tube or rod diameter, or the section height)."""
    s = project.section
    return MM * (s.diameter if s.diameter is not None else max(s.height or 0.0, s.width or 0.0))


def joint_settings_of(project: Project) -> JointSettings:
    """The project's joint settings in fabrication's terms (mm)."""
    j = project.fabrication.joints
    return JointSettings(**{k: v for k, v in {
        "kind": j.kind, "clearance_mm": MM * j.clearance, "wall_mm": MM * j.wall, "min_wall_mm": MM * j.min_wall,
        "pin_hole_mm": MM * j.pin_hole, "engrave": j.engrave,
        "hub_radius_mm": None if j.hub_radius is None else MM * j.hub_radius,
        "sleeve_length_mm": None if j.sleeve_length is None else MM * j.sleeve_length,
        "plate_thickness_mm": MM * j.plate_thickness, "bolt_hole_mm": MM * j.bolt_hole}.items() if v is not None})


def build_limits_of(project: Project) -> BuildLimits:
    """The shortest buildable beam and smallest angle at a joint that the project's joints, tube
    and fabrication settings give."""
    b = project.fabrication.beams
    return BuildLimits.of(joint_settings_of(project), beam_outer_size_mm(project),
                          min_cut_length_mm=None if b.min_cut_length is None else MM * b.min_cut_length,
                          min_angle_deg=project.fabrication.joints.min_angle)
