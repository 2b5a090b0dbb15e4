"""The limits the project's joints and tube set on the grid: the shortest buildable beam and the
smallest angle between two beams at a joint.

The stages that make the grid (remesh, optimize) hold it to these limits, and the fabrication
stage builds the joints from the same settings, so they live here, upstream of all three. The
settings themselves (in mm) are built by the project's sections (workflow.config).
"""

from __future__ import annotations

from fabrication.limits import BuildLimits

from ..config import Project

__all__ = ["build_limits_of"]


def build_limits_of(project: Project) -> BuildLimits:
    """The shortest buildable beam and smallest angle at a joint that the project's joints, tube
    and fabrication settings give."""
    return project.fabrication.build_limits(project.section.outer_size_mm())
