"""Whether a grid keeps its surface's openings.

A surface with holes (a courtyard, a roof light, the pitch of a ring roof) has inner boundary
loops. The grid's beams run along them as long as there are enough nodes on each; where joints
coarsen the grid or collapse short beams along an opening, its outline can shrink to a triangle
and the cells beside it then span the opening. Each opening is measured by the area of its loop
(the norm of its vector area, 1/2 sum p_i x p_i+1, so a curved loop counts as spanned), against
the area of the grid's holes whose centroids lie nearest it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..mesh import PolyMesh, TriMesh

__all__ = ["OPENING_KEPT", "Opening", "loop_area", "openings"]

#: An opening that the grid leaves less than this share of open is a finding.
OPENING_KEPT = 0.5


@dataclass(frozen=True, kw_only=True)
class Opening:
    """One inner boundary loop of the surface: ``centre`` (3,) its vertices' centroid (m), its
    ``surface_area_m2``, the ``grid_area_m2`` that the grid's holes there leave open, and the
    grid's ``joints`` on their outlines (0: the grid covers the opening)."""

    centre: np.ndarray
    surface_area_m2: float
    grid_area_m2: float
    joints: int

    @property
    def kept(self) -> float:
        """The share of the opening that the grid leaves open."""
        return self.grid_area_m2 / self.surface_area_m2 if self.surface_area_m2 > 0 else 1.0

    def to_dict(self) -> dict:
        return {"centre_m": [float(c) for c in self.centre], "surface_area_m2": self.surface_area_m2,
                "grid_area_m2": self.grid_area_m2, "kept": self.kept, "joints": self.joints}


def loop_area(points: np.ndarray) -> float:
    """Area (m^2) spanned by the closed loop ``points`` (k, 3): the norm of its vector area."""
    p = np.asarray(points, dtype=float)
    if len(p) < 3:
        return 0.0
    return float(np.linalg.norm(0.5 * np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)))


def _inner(loops: list[np.ndarray], points: np.ndarray) -> tuple[list[np.ndarray], list[float]]:
    """The loops but the one spanning the largest area (the outline), and their areas."""
    if not loops:
        return [], []
    areas = [loop_area(points[loop]) for loop in loops]
    outer = int(np.argmax(areas))
    return ([loop for i, loop in enumerate(loops) if i != outer], [a for i, a in enumerate(areas) if i != outer])


def openings(surface: TriMesh, grid: PolyMesh) -> list[Opening]:
    """Each opening of ``surface`` (an inner boundary loop) with the area the grid's holes leave
    open there: every hole of the grid counts at the opening whose loop passes nearest its centroid."""
    holes, hole_areas = _inner(surface.boundary_loops, surface.vertices)
    if not holes:
        return []
    gaps, gap_areas = _inner(grid.boundary_loops, grid.nodes)
    trees = [cKDTree(surface.vertices[hole]) for hole in holes]
    open_area = np.zeros(len(holes))
    joints = np.zeros(len(holes), dtype=int)
    for gap, area in zip(gaps, gap_areas):
        centroid = grid.nodes[gap].mean(axis=0)
        nearest = int(np.argmin([tree.query(centroid)[0] for tree in trees]))
        open_area[nearest] += area
        joints[nearest] += len(gap)
    return [Opening(centre=surface.vertices[hole].mean(axis=0), surface_area_m2=area,
                    grid_area_m2=float(open_area[i]), joints=int(joints[i]))
            for i, (hole, area) in enumerate(zip(holes, hole_areas))]
