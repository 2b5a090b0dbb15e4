"""Load cases and combinations, and their lumping to nodal forces.

A ``LoadCase`` holds, in SI: a self-weight factor (multiplier of the structure's own
weight, acting along -z with g = 9.81 m/s^2), an area load per unit true area
(cladding, N/m^2 as a 3-vector), an area load per unit plan area (snow, N/m^2 as a
3-vector) and point loads (node ids with [Fx, Fy, Fz, Mx, My, Mz] in N and N m).
A ``LoadCombination`` is a factored sum of cases, tagged ULS or SLS.
Cases combine linearly, so a combination is resolved into one equivalent case.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from ..errors import InputError

__all__ = [
    "GRAVITY",
    "LimitState",
    "LoadCase",
    "LoadCombination",
    "combine",
    "lump_area_load",
    "pick_combination",
]

GRAVITY = 9.81
"""Standard acceleration of gravity used for self-weight, m/s^2."""


class LimitState(StrEnum):
    ULS = "ULS"
    SLS = "SLS"


def _vec3(value) -> np.ndarray:
    out = np.zeros(3) if value is None else np.asarray(value, dtype=float).reshape(3)
    out.flags.writeable = False
    return out


@dataclass(frozen=True, kw_only=True)
class LoadCase:
    """One load case; see the module docstring for units."""

    name: str
    self_weight: float = 0.0
    # the constructor also takes None (no load) or sequences, which __post_init__ turns into read-only
    # arrays: the attributes are always arrays, and mypy has no field converters to say so
    area_true: np.ndarray = field(default=None)  # type: ignore[arg-type]
    area_plan: np.ndarray = field(default=None)  # type: ignore[arg-type]
    point_nodes: np.ndarray = field(default=None)  # type: ignore[arg-type]
    point_forces: np.ndarray = field(default=None)  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        object.__setattr__(self, "area_true", _vec3(self.area_true))
        object.__setattr__(self, "area_plan", _vec3(self.area_plan))
        nodes = (np.zeros(0, dtype=np.int64) if self.point_nodes is None
                 else np.asarray(self.point_nodes, dtype=np.int64).ravel())
        forces = (np.zeros((0, 6)) if self.point_forces is None
                  else np.asarray(self.point_forces, dtype=float).reshape(len(nodes), 6))
        nodes.flags.writeable = False
        forces.flags.writeable = False
        object.__setattr__(self, "point_nodes", nodes)
        object.__setattr__(self, "point_forces", forces)

    def scaled(self, factor: float, name: str | None = None) -> "LoadCase":
        return LoadCase(name=name or self.name, self_weight=factor * self.self_weight,
                        area_true=factor * self.area_true, area_plan=factor * self.area_plan,
                        point_nodes=self.point_nodes, point_forces=factor * self.point_forces)

    def point_load_array(self, n_nodes: int) -> np.ndarray:
        """(n_nodes, 6) point loads summed per node."""
        out = np.zeros((n_nodes, 6))
        if len(self.point_nodes):
            if self.point_nodes.max() >= n_nodes or self.point_nodes.min() < 0:
                raise InputError(f"load case {self.name!r}: point load node out of range 0..{n_nodes - 1}")
            np.add.at(out, self.point_nodes, self.point_forces)
        return out


@dataclass(frozen=True, kw_only=True)
class LoadCombination:
    """A factored sum of load cases: ``factors`` maps case name to factor."""

    name: str
    limit_state: LimitState
    factors: dict[str, float] = field(default_factory=dict)


def combine(cases: Mapping[str, LoadCase], combination: LoadCombination) -> LoadCase:
    """The single load case equivalent to a combination (loads add linearly)."""
    missing = [c for c in combination.factors if c not in cases]
    if missing:
        raise InputError(f"combination {combination.name!r} names unknown load case(s) {missing}; "
                         f"defined: {sorted(cases)}")
    self_weight = 0.0
    area_true = np.zeros(3)
    area_plan = np.zeros(3)
    nodes: list[np.ndarray] = []
    forces: list[np.ndarray] = []
    for case_name, factor in combination.factors.items():
        case = cases[case_name]
        self_weight += factor * case.self_weight
        area_true += factor * case.area_true
        area_plan += factor * case.area_plan
        nodes.append(case.point_nodes)
        forces.append(factor * case.point_forces)
    return LoadCase(name=combination.name, self_weight=self_weight, area_true=area_true,
                    area_plan=area_plan,
                    point_nodes=np.concatenate(nodes) if nodes else np.zeros(0, dtype=np.int64),
                    point_forces=np.concatenate(forces) if forces else np.zeros((0, 6)))


def pick_combination(combinations: Mapping[str, LoadCombination], load_cases: Mapping[str, LoadCase],
                     limit_state: LimitState | str, name: str | None = None) -> LoadCombination:
    """The combination that the checks of ``limit_state`` run under: the combination called ``name``,
    or the load case of that name alone (factor 1); without a name, the first combination of that
    limit state. Where none of these is found, every load case at factor 1, named after the limit
    state."""
    state = LimitState(limit_state)
    if name is None:
        named = [n for n, c in combinations.items() if c.limit_state == state]
        name = named[0] if named else None
    if name is not None and name in combinations:
        return combinations[name]
    if name is not None and name in load_cases:
        return LoadCombination(name=name, limit_state=state, factors={name: 1.0})
    return LoadCombination(name=state.value, limit_state=state, factors={n: 1.0 for n in load_cases})


def lump_area_load(vertices: np.ndarray, triangles: np.ndarray, case: LoadCase) -> np.ndarray:
    """(n_vertices, 3) nodal forces (N) of the case's area loads on a triangulated surface.

    Each triangle's resultant (true area times ``area_true`` plus plan area times
    ``area_plan``) goes one third to each corner: the consistent load of linear
    triangles. Self-weight and point loads are left to the caller, which knows the mass.
    """
    corners = vertices[triangles]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    true_area = 0.5 * np.linalg.norm(cross, axis=1)
    plan_area = 0.5 * np.abs(cross[:, 2])
    resultant = true_area[:, None] * case.area_true + plan_area[:, None] * case.area_plan
    out = np.zeros((len(vertices), 3))
    for k in range(3):
        np.add.at(out, triangles[:, k], resultant / 3.0)
    return out


def resultant(points: np.ndarray, forces: np.ndarray) -> np.ndarray:
    """(6,) resultant force and moment about the origin of nodal forces and moments (n,6) at points (n,3)."""
    return np.concatenate([forces[:, :3].sum(axis=0), (np.cross(points, forces[:, :3]) + forces[:, 3:]).sum(axis=0)])


def equilibrium_error(points: np.ndarray, loads: np.ndarray, reactions: np.ndarray, size: float | None = None) -> float:
    """|loads + reactions| / |loads|, forces plus moments about the origin divided by ``size`` (a
    length of the model; default: the points' largest extent), both (n,6) at points (n,3)."""
    size = max(float(np.ptp(points, axis=0).max()) if size is None else float(size), 1e-300)
    total = resultant(points, loads)
    balance = total + resultant(points, reactions)
    scale = float(np.linalg.norm(total[:3]) + np.linalg.norm(total[3:]) / size)
    return float((np.linalg.norm(balance[:3]) + np.linalg.norm(balance[3:]) / size) / max(scale, 1e-300))
