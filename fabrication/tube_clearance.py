"""Clearance of the tubes as cut: from the tubes they do not meet at a joint, and from the joints
they do not end in (mm).

The joint-to-joint check (``fabrication.clearance``) takes the built solids; a tube that passes
through a third joint, or two tubes that cross between their joints (a folded or tightly curved
grid, tubes too thick for its cells), are not joints and it cannot see them. This check takes the
parts as the fabrication builds them, in closed form:

- a tube is its axis from the end of its start joint's setback to its cut length, with the radius
  of its section (a rectangle's half diagonal, which errs on the side of a clash);
- a joint is its hub and its sleeves as cylinders, or its fin plates as boxes
  (``fabrication.joints.joint_parts``).

Each tube's axis is sampled every quarter of its radius (at most ``MAX_SAMPLES``); a sample's
signed distance to a cylinder or a box, or to another tube's axis segment, is exact. A tube
overlaps a part by its radius less that distance at the nearest sample: a sphere of the tube's
radius about each sample lies within the tube except within a radius of its square-cut ends,
which sit in their own joints, so near those the figure errs on the side of a clash. Broad phase:
a k-d tree of the samples (scipy). Pairs that meet at a joint are left to that joint's own checks
(its sleeves' angles, the wall between its bores).

Measured on a grid of 3000 joints and 4500 tubes (``benchmarks/fabrication_speed.py --tube-clearance
3000``): 1.8 s, where OCCT's booleans of the 22 000 tube and joint part pairs whose boxes overlap
would take some 200 s (9 ms a pair), the tubes against one another not counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .joints import JointParts

__all__ = ["TubeClash", "tube_clashes", "TUBE_CLASH_MM", "MAX_SAMPLES"]

#: Two parts overlapping by more than this (mm) clash.
TUBE_CLASH_MM = 0.5
#: Samples along one tube's axis at most.
MAX_SAMPLES = 2000


@dataclass(frozen=True)
class TubeClash:
    """``beam`` overlaps ``other`` (a joint's or a beam's id) by ``depth_mm`` near ``at_mm``."""

    beam: str
    other: str
    depth_mm: float
    at_mm: tuple[float, float, float]

    def to_dict(self) -> dict:
        return {"parts": [self.beam, self.other], "depth_mm": round(self.depth_mm, 2),
                "at_mm": [round(v, 1) for v in self.at_mm]}


def _samples(starts: np.ndarray, ends: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(points (s, 3), owning tube (s,)): each axis sampled every quarter radius, ends included."""
    lengths = np.linalg.norm(ends - starts, axis=1)
    counts = np.clip(np.ceil(lengths / np.maximum(0.25 * radii, 1e-3)).astype(int) + 1, 2, MAX_SAMPLES)
    owner = np.repeat(np.arange(len(starts)), counts)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    t = (np.arange(len(owner)) - first[owner]) / (counts[owner] - 1)
    return starts[owner] + t[:, None] * (ends - starts)[owner], owner


def _to_cylinders(p: np.ndarray, cylinders: np.ndarray) -> np.ndarray:
    """Signed distance (negative inside) from points (k, 3) to finite solid cylinders (k, 8)."""
    base, axis, length, radius = cylinders[:, :3], cylinders[:, 3:6], cylinders[:, 6], cylinders[:, 7]
    rel = p - base
    along = np.einsum("ij,ij->i", rel, axis)
    across = np.linalg.norm(rel - along[:, None] * axis, axis=1)
    axial = np.maximum(-along, along - length)            # > 0 beyond an end face
    radial = across - radius                              # > 0 outside the mantle
    outside = np.hypot(np.maximum(axial, 0.0), np.maximum(radial, 0.0))
    return np.where((axial <= 0) & (radial <= 0), np.maximum(axial, radial), outside)


def _to_boxes(p: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Signed distance from points (k, 3) to boxes (k, 12) as JointParts gives them."""
    origin, along, up = boxes[:, :3], boxes[:, 3:6], boxes[:, 6:9]
    through = np.cross(along, up)
    half = 0.5 * boxes[:, 9:12]
    rel = p - (origin + half[:, :1] * along)
    local = np.stack([np.einsum("ij,ij->i", rel, e) for e in (along, up, through)], axis=1)
    excess = np.abs(local) - half
    outside = np.linalg.norm(np.maximum(excess, 0.0), axis=1)
    return np.where((excess <= 0).all(axis=1), excess.max(axis=1), outside)


def _to_segments(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points (k, 3) to segments a-b (k, 3 each)."""
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def _worst(beam: np.ndarray, other: np.ndarray, depth: np.ndarray, at: np.ndarray) -> list[tuple]:
    """The deepest overlap of each (beam, other) pair over ``TUBE_CLASH_MM``."""
    keep = depth > TUBE_CLASH_MM
    beam, other, depth, at = beam[keep], other[keep], depth[keep], at[keep]
    order = np.lexsort((-depth, other, beam))
    first = np.ones(len(order), dtype=bool)
    first[1:] = (beam[order][1:] != beam[order][:-1]) | (other[order][1:] != other[order][:-1])
    chosen = order[first]
    return list(zip(beam[chosen].tolist(), other[chosen].tolist(), depth[chosen].tolist(), at[chosen].tolist()))


def tube_clashes(nodes_mm: np.ndarray, beams: np.ndarray, starts_mm: np.ndarray, ends_mm: np.ndarray,
                 radii_mm: np.ndarray, joints: dict[int, JointParts], beam_ids: list[str],
                 joint_ids: dict[int, str]) -> list[TubeClash]:
    """Tubes that overlap a joint they do not end in, or a tube they share no node with.

    ``nodes_mm`` (n, 3); ``beams`` (b, 2) their end nodes; ``starts_mm``, ``ends_mm`` (b, 3) each
    tube's axis as cut (a tube of zero cut length: equal points, left out); ``radii_mm`` (b,);
    ``joints``: node -> its parts relative to the node (nodes without a joint left out). Sorted by
    depth, deepest first."""
    beams = np.asarray(beams, dtype=int)
    radii = np.asarray(radii_mm, dtype=float)
    present = np.flatnonzero(np.linalg.norm(ends_mm - starts_mm, axis=1) > 0)
    if not len(present):
        return []
    points, owner = _samples(starts_mm[present], ends_mm[present], radii[present])
    owner = present[owner]
    tree = cKDTree(points)
    found: list[tuple] = []
    # the joints' parts, each against the samples within its bounding sphere and a tube's radius
    for kind, parts, distance in (("cylinders", 8, _to_cylinders), ("boxes", 12, _to_boxes)):
        rows, nodes = [], []
        for node, own in joints.items():
            table = getattr(own, kind)
            if len(table):
                placed = table.copy()
                placed[:, :3] += nodes_mm[node]
                rows.append(placed)
                nodes.append(np.full(len(table), node))
        if not rows:
            continue
        table, node_of = np.concatenate(rows).reshape(-1, parts), np.concatenate(nodes)
        if kind == "cylinders":
            centres = table[:, :3] + 0.5 * table[:, 6:7] * table[:, 3:6]
            reach = np.hypot(0.5 * table[:, 6], table[:, 7])
        else:
            centres = table[:, :3] + 0.5 * table[:, 9:10] * table[:, 3:6]
            reach = 0.5 * np.linalg.norm(table[:, 9:12], axis=1)
        near = tree.query_ball_point(centres, reach + radii.max())
        part = np.repeat(np.arange(len(table)), [len(n) for n in near])
        sample = np.fromiter((s for n in near for s in n), dtype=int, count=len(part))
        beam = owner[sample]
        own_end = (beams[beam, 0] == node_of[part]) | (beams[beam, 1] == node_of[part])
        part, sample, beam = part[~own_end], sample[~own_end], beam[~own_end]
        depth = radii[beam] - distance(points[sample], table[part])
        found += [(b, joint_ids[int(n)], d, at) for b, n, d, at in
                  _worst(beam, node_of[part], depth, points[sample])]
    # tube against tube, where they share no node
    pairs = tree.query_pairs(2.25 * radii.max(), output_type="ndarray")  # samples a quarter radius apart
    a, b = owner[pairs[:, 0]], owner[pairs[:, 1]]
    apart = ((beams[a, 0] != beams[b, 0]) & (beams[a, 0] != beams[b, 1])
             & (beams[a, 1] != beams[b, 0]) & (beams[a, 1] != beams[b, 1]))
    pairs, a, b = pairs[apart], a[apart], b[apart]
    if len(pairs):
        sample = pairs[:, 0]
        depth = radii[a] + radii[b] - _to_segments(points[sample], starts_mm[b], ends_mm[b])
        low, high = np.minimum(a, b), np.maximum(a, b)
        found += [(lo, beam_ids[hi], d, at) for lo, hi, d, at in _worst(low, high, depth, points[sample])]
    clashes = [TubeClash(beam=beam_ids[int(b)], other=o, depth_mm=float(d), at_mm=tuple(map(float, at)))
               for b, o, d, at in found]
    return sorted(clashes, key=lambda c: (-c.depth_mm, c.beam, c.other))
