"""What the joints and the tubes allow of the grid: the shortest buildable beam and the smallest
angle between two beams at a node.

A beam of node-to-node length L is buildable when its cut length L - s_a - s_b (s the set-back of
the joint at each end, which grows as the node's smallest angle shrinks) is at least the minimum
cut length. The default minimum keeps the two joints' sleeves (or fin plates) apart inside the tube
and leaves half a tube diameter between them: 2 x sleeve + 0.5 x outer size. Lengths in mm here,
as in every fabrication module; :func:`required_beam_lengths_m` gives metres for the geometry stages.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.mesh import PolyMesh
from engine.structure.grid_model import node_normals

from .joints import JointSettings, joint_hub_radius_mm, joint_setback_mm, joint_sleeve_mm

__all__ = ["BuildLimits", "node_smallest_angles", "required_beam_lengths_m", "default_min_cut_length_mm",
           "default_min_angle_deg"]


def default_min_cut_length_mm(settings: JointSettings, beam_size_mm: float) -> float:
    """Shortest cut length a fabricator would accept: the joints' reach into the tube from both
    ends plus half a tube diameter between them, and never under one tube diameter (mm)."""
    return float(max(2 * joint_sleeve_mm(settings, beam_size_mm) + 0.5 * beam_size_mm, beam_size_mm))


def default_min_angle_deg(settings: JointSettings, beam_size_mm: float = 12.0) -> float:
    """Smallest angle between two beams the joint takes, 5 degrees above where its own features
    collide: two sockets' sleeves overlapping past their bores' start (the set-back grows as the
    angle closes, the sleeves' reach faster), or two fin plates meeting at the steel hub's face."""
    if settings.kind == "steel":
        hub = joint_hub_radius_mm(settings, beam_size_mm)
        collide = 2 * np.degrees(np.arcsin(min(1.0, settings.plate_thickness_mm / (2 * hub))))
        return float(round(collide + 5.0))
    outer = 0.5 * beam_size_mm + settings.clearance_mm + settings.wall_mm
    sleeve = joint_sleeve_mm(settings, beam_size_mm)
    for angle in np.arange(5.0, 90.0, 0.5):
        half = np.radians(0.5 * angle)
        if outer / np.tan(half) <= joint_setback_mm(settings, beam_size_mm, 2 * half) + 0.5 * sleeve:
            return float(round(angle + 5.0))
    return 90.0


@dataclass(frozen=True, kw_only=True)
class BuildLimits:
    """The joints, the beam's outer size (mm), the minimum cut length (mm) and the smallest angle
    between two beams at a node (degrees)."""

    joints: JointSettings
    beam_size_mm: float
    min_cut_length_mm: float
    min_angle_deg: float

    @classmethod
    def of(cls, joints: JointSettings, beam_size_mm: float, *, min_cut_length_mm: float | None = None,
           min_angle_deg: float | None = None) -> BuildLimits:
        """Limits with the defaults of :func:`default_min_cut_length_mm` and :func:`default_min_angle_deg`."""
        return cls(joints=joints, beam_size_mm=float(beam_size_mm),
                   min_cut_length_mm=float(default_min_cut_length_mm(joints, beam_size_mm)
                                           if min_cut_length_mm is None else min_cut_length_mm),
                   min_angle_deg=float(default_min_angle_deg(joints, beam_size_mm) if min_angle_deg is None
                                       else min_angle_deg))

    def setback_mm(self, angle_rad: float | np.ndarray, rise: float | np.ndarray = 0.0) -> float | np.ndarray:
        """Set-back of a joint whose smallest angle between beams is ``angle_rad`` and whose steepest
        beam rises ``rise`` (the sine of its angle to the plane square to the joint's axis), mm
        (vectorised)."""
        return joint_setback_mm(self.joints, self.beam_size_mm, angle_rad, rise)

    def shortest_beam_mm(self, angle_rad: float = 2 * np.pi / 3) -> float:
        """Shortest buildable node-to-node length between two joints of that smallest angle, mm."""
        return 2 * self.setback_mm(angle_rad) + self.min_cut_length_mm

    def to_dict(self) -> dict:
        """JSON-ready record (mm and degrees)."""
        return {"joint_kind": self.joints.kind, "beam_size_mm": self.beam_size_mm,
                "min_cut_length_mm": round(self.min_cut_length_mm, 2), "min_angle_deg": self.min_angle_deg,
                "shortest_beam_mm_at_120deg": round(self.shortest_beam_mm(), 2)}


def node_smallest_angles(polymesh: PolyMesh) -> np.ndarray:
    """(n_nodes,) smallest angle (radians) between two beams at each node; pi with fewer than two.
    Vectorised over the nodes of each valence."""
    e = polymesh.edges
    x = polymesh.nodes
    out = np.full(polymesh.n_nodes, np.pi)
    if not len(e):
        return out
    ends = np.r_[e[:, 0], e[:, 1]]
    others = np.r_[e[:, 1], e[:, 0]]
    d = x[others] - x[ends]
    d /= np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
    order = np.argsort(ends, kind="stable")
    ends, d = ends[order], d[order]
    valence = np.bincount(ends, minlength=polymesh.n_nodes)
    first = np.r_[0, np.cumsum(valence)[:-1]]
    for k in np.unique(valence[valence >= 2]):
        nodes = np.flatnonzero(valence == k)
        directions = d[first[nodes, None] + np.arange(k)]  # (m, k, 3)
        cosine = np.clip(np.einsum("mik,mjk->mij", directions, directions), -1.0, 1.0)
        cosine[:, np.arange(k), np.arange(k)] = -1.0
        out[nodes] = np.arccos(cosine.reshape(len(nodes), -1).max(axis=1))
    return out


def node_rises(polymesh: PolyMesh) -> np.ndarray:
    """(n_nodes,) the largest |sine| of a beam's angle to the plane square to its node's axis (the
    grid's own node normals: engine.structure.grid_model.node_normals); 0 at a node of no beam."""
    e = polymesh.edges
    out = np.zeros(polymesh.n_nodes)
    if not len(e):
        return out
    normals = node_normals(polymesh)
    d = polymesh.nodes[e[:, 1]] - polymesh.nodes[e[:, 0]]
    d /= np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
    np.maximum.at(out, e[:, 0], np.abs(np.einsum("ij,ij->i", d, normals[e[:, 0]])))
    np.maximum.at(out, e[:, 1], np.abs(np.einsum("ij,ij->i", d, normals[e[:, 1]])))
    return out


def required_beam_lengths_m(polymesh: PolyMesh, limits: BuildLimits) -> np.ndarray:
    """(n_beams,) shortest buildable node-to-node length of each beam of the grid as it is, m:
    the two set-backs at its end nodes' smallest angles (and, at steel nodes, their steepest
    beams' rise) plus the minimum cut length."""
    angles = node_smallest_angles(polymesh)
    rises = node_rises(polymesh) if limits.joints.kind == "steel" else 0.0
    setback = limits.setback_mm(angles, rises)
    e = polymesh.edges
    return (setback[e[:, 0]] + setback[e[:, 1]] + limits.min_cut_length_mm) / 1000.0
