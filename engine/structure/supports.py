"""Support selections and restraints.

A selection picks node ids of a surface or grid-shell by a rule (whole boundary, one
boundary loop, a plane, a box, the flagged vertices of the input, explicit ids, the
nearest node to a point). A restraint says which of the six DOFs (ux, uy, uz, rx, ry,
rz) are held. ``Supports`` is the resolved result: node ids and a (k, 6) flag array.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from ..errors import InputError, SelectionError

__all__ = [
    "DOF_NAMES",
    "Restraint",
    "Supports",
    "restraint_flags",
    "select_boundary",
    "select_loop",
    "select_plane",
    "select_box",
    "select_flagged",
    "select_ids",
    "select_nearest",
]

DOF_NAMES = ("ux", "uy", "uz", "rx", "ry", "rz")


class Restraint(StrEnum):
    """Named restraint codes; an explicit 6-flag list is also accepted."""

    pinned = "pinned"
    fixed = "fixed"
    roller_x = "roller_x"
    roller_y = "roller_y"
    roller_z = "roller_z"


def restraint_flags(code: str | list[int] | list[bool] | tuple) -> np.ndarray:
    """(6,) bool flags for a restraint code or an explicit list of 6 flags (1 = held).

    pinned holds the translations, fixed all six DOFs; ``roller_<axis>`` leaves the
    translation along that axis free and holds the other two (rotations free).
    """
    if isinstance(code, (list, tuple, np.ndarray)):
        flags = np.asarray(code)
        if flags.shape != (6,) or not np.isin(flags.astype(float), (0.0, 1.0)).all():
            raise InputError(f"restraint flags {list(code)!r} must be six 0/1 values (ux uy uz rx ry rz)")
        return flags.astype(bool)
    try:
        kind = Restraint(str(code))
    except ValueError:
        allowed = ", ".join(r.value for r in Restraint)
        raise InputError(f"unknown restraint {code!r}; allowed: {allowed} or six 0/1 flags") from None
    flags = np.zeros(6, dtype=bool)
    if kind is Restraint.fixed:
        flags[:] = True
    elif kind is Restraint.pinned:
        flags[:3] = True
    else:
        flags[:3] = True
        flags["xyz".index(kind.value[-1])] = False
    return flags


@dataclass(frozen=True, kw_only=True)
class Supports:
    """Resolved supports: nodes (k,) int64 sorted unique, restraints (k, 6) bool."""

    nodes: np.ndarray
    restraints: np.ndarray

    def __post_init__(self) -> None:
        nodes = np.asarray(self.nodes, dtype=np.int64)
        restraints = np.asarray(self.restraints, dtype=bool).reshape(len(nodes), 6)
        for name, value in (("nodes", nodes), ("restraints", restraints)):
            value.flags.writeable = False
            object.__setattr__(self, name, value)

    @classmethod
    def merge(cls, parts: list[tuple[np.ndarray, np.ndarray]]) -> "Supports":
        """Union of (node ids, (6,) flags) parts; a node in several parts gets the OR of flags."""
        held: dict[int, np.ndarray] = {}
        for nodes, flags in parts:
            for node in np.asarray(nodes, dtype=np.int64).ravel():
                held[int(node)] = held.get(int(node), np.zeros(6, dtype=bool)) | flags
        order = sorted(held)
        restraints = np.array([held[n] for n in order], dtype=bool).reshape(len(order), 6)
        return cls(nodes=np.array(order, dtype=np.int64), restraints=restraints)

    def dof_mask(self, n_nodes: int) -> np.ndarray:
        """(n_nodes, 6) bool: True where a DOF is restrained."""
        mask = np.zeros((n_nodes, 6), dtype=bool)
        mask[self.nodes] = self.restraints
        return mask

    def to_json(self) -> dict:
        """{"node": [6 flags]} with 0-based string keys, as in the solver-level JSON files."""
        return {str(int(n)): [int(b) for b in r] for n, r in zip(self.nodes, self.restraints)}


def _fmt(vector) -> str:
    return "[" + ", ".join(f"{float(x):g}" for x in np.ravel(vector)) + "]"


def _nonempty(ids: np.ndarray, what: str) -> np.ndarray:
    ids = np.unique(np.asarray(ids, dtype=np.int64))
    if len(ids) == 0:
        raise SelectionError(f"support selection {what} matched no node",
                             hint="check the selection's coordinates and tolerance against the surface's extent")
    return ids


def select_boundary(boundary_loops: list[np.ndarray]) -> np.ndarray:
    """Every node on any boundary loop."""
    ids = np.concatenate(boundary_loops) if boundary_loops else np.zeros(0, dtype=np.int64)
    return _nonempty(ids, "'boundary'")


def select_loop(boundary_loops: list[np.ndarray], index: int) -> np.ndarray:
    """Nodes of one boundary loop; loops are numbered from 0, longest (outer) first."""
    if not 0 <= index < len(boundary_loops):
        raise SelectionError(f"support selection 'loop = {index}' matched no loop: the surface has "
                             f"{len(boundary_loops)} boundary loop(s), numbered 0..{len(boundary_loops) - 1}")
    return _nonempty(boundary_loops[index], f"'loop = {index}'")


def select_plane(points: np.ndarray, point: np.ndarray, normal: np.ndarray, tolerance: float) -> np.ndarray:
    """Nodes within ``tolerance`` (m) of the plane through ``point`` with ``normal``."""
    normal = np.asarray(normal, dtype=float)
    if np.linalg.norm(normal) == 0:
        raise InputError("plane normal must not be zero")
    normal = normal / np.linalg.norm(normal)
    distance = np.abs((points - np.asarray(point, dtype=float)) @ normal)
    return _nonempty(np.flatnonzero(distance <= tolerance),
                     f"'plane through {_fmt(point)} normal {_fmt(normal.round(3))} (tolerance {tolerance:g} m)'")


def select_box(points: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Nodes inside the axis-aligned box [lower, upper] (m), faces included."""
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    inside = np.all((points >= lower) & (points <= upper), axis=1)
    return _nonempty(np.flatnonzero(inside), f"'box {_fmt(lower)} .. {_fmt(upper)}'")


def select_flagged(flagged: np.ndarray) -> np.ndarray:
    """The vertices flagged as supports in the input file (red in a PLY)."""
    ids = np.flatnonzero(flagged)
    if len(ids) == 0:
        raise SelectionError("support selection 'flagged' matched no node: the surface file has no "
                             "red (255,0,0) vertices", hint="use supports = 'boundary' or select nodes by plane or box")
    return ids


def select_ids(n_nodes: int, ids: list[int]) -> np.ndarray:
    """Explicit 0-based node ids; an id out of range is an error."""
    ids_arr = np.asarray(ids, dtype=np.int64).ravel()
    bad = ids_arr[(ids_arr < 0) | (ids_arr >= n_nodes)]
    if len(bad):
        raise SelectionError(f"support selection 'ids' has ids {bad.tolist()} outside 0..{n_nodes - 1}")
    return _nonempty(ids_arr, "'ids'")


#: A 'nearest' point may lie this many times the surface's size across (its box's diagonal) from
#: the node it selects: a column's foot under its roof, or a point far out towards a corner, but not
#: a point in millimetres read as metres (a thousand times too far) or in the wrong coordinates.
NEAREST_REACH = 5.0


def select_nearest(points: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """The node nearest to each target point (m). A target farther from every node than
    NEAREST_REACH times the nodes' size across is refused (SelectionError), naming it."""
    points = np.asarray(points, dtype=float)
    targets = np.atleast_2d(np.asarray(targets, dtype=float))
    d = np.linalg.norm(points[None, :, :] - targets[:, None, :], axis=2)
    nearest = d.argmin(axis=1)
    across = float(np.linalg.norm(np.ptp(points, axis=0))) if len(points) else 0.0
    far = np.flatnonzero(d[np.arange(len(targets)), nearest] > NEAREST_REACH * across)
    if len(far):
        i = int(far[0])
        raise SelectionError(f"'nearest' point {i} {[float(f'{c:.6g}') for c in targets[i]]} lies "
                             f"{d[i, nearest[i]]:.4g} m from the nearest vertex of the surface, itself "
                             f"{across:.3g} m across",
                             hint="give points on or near the roof, in metres (or with units: \"6000 mm\")")
    return _nonempty(nearest, "'nearest'")
