"""The incremental load test of a mock-up (METHOD.md 7), as the analysis predicts it.

The load cases of a combination are split into permanent ones (those with self-weight), held
at their factors, and variable ones, scaled together by a load factor that grows along the
geometrically non-linear path (engine.structure.corotational, arc-length). Each named control point is
measured at its nearest node: the vertical displacement of every control node is recorded at
every step, the first one controlling the path.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InputError
from ..parts import node_id
from ..structure.beam_elements import FrameModel
from ..structure.corotational import nonlinear_static
from ..structure.loads import LoadCase, LoadCombination, combine
from ..structure.supports import Supports

__all__ = ["LoadTest", "permanent_and_variable", "load_test"]


@dataclass(frozen=True, kw_only=True)
class LoadTest:
    """A load test's predicted response: ``permanent`` and ``variable`` (case name to its factor in
    the combination), ``control_nodes`` (control point name to its node), ``path`` (s, 2): load
    factor and vertical displacement of the first control node, ``monitored`` (s, k): the vertical
    displacement of each control node (in the order of ``control_nodes``), ``limit_load_factor``
    (None if no limit point was reached) and ``converged`` (False: the path stopped early)."""

    permanent: dict[str, float]
    variable: dict[str, float]
    control_nodes: dict[str, int]
    path: np.ndarray
    monitored: np.ndarray
    limit_load_factor: float | None
    converged: bool

    @property
    def load_factors(self) -> np.ndarray:
        """(s,) the load factor at each step of the path."""
        return self.path[:, 0]

    @property
    def largest_load_factor(self) -> float:
        """The highest load factor the path reached."""
        return float(self.path[:, 0].max())

    def to_dict(self) -> dict[str, object]:
        """JSON-ready record (the load_test of analysis.json), nodes named N0001."""
        return {"permanent_cases": list(self.permanent), "variable_cases": list(self.variable),
                "control_nodes": {name: node_id(n) for name, n in self.control_nodes.items()},
                "limit_load_factor": self.limit_load_factor, "largest_load_factor": self.largest_load_factor,
                "path_complete": bool(self.converged)}


def permanent_and_variable(combination: LoadCombination,
                           load_cases: Mapping[str, LoadCase]) -> tuple[dict[str, float], dict[str, float]]:
    """The combination's factors split into the permanent cases (those with self-weight) and the
    variable ones, each in the combination's order."""
    permanent = {n: f for n, f in combination.factors.items() if load_cases[n].self_weight}
    variable = {n: f for n, f in combination.factors.items() if n not in permanent}
    return permanent, variable


def load_test(model: FrameModel, supports: Supports, load_cases: Mapping[str, LoadCase],
              combination: LoadCombination, control_points: Mapping[str, Sequence[float]],
              nodal_loads: Callable[[LoadCase], np.ndarray], *, max_load_factor: float,
              max_steps: int = 60) -> LoadTest | None:
    """The load test of ``model`` under ``combination``: its permanent cases held, its variable ones
    increased up to ``max_load_factor`` (or a limit point, or ``max_steps`` steps); each of the
    ``control_points`` (name to x, y, z) measured at the model's nearest node. ``nodal_loads`` gives
    the (n, 6) nodal loads of a load case (a combination of ``load_cases``). None when the
    combination has no variable case to increase."""
    if not control_points:
        raise InputError("load test: no control point to measure")
    permanent, variable = permanent_and_variable(combination, load_cases)
    if not variable:
        return None
    nodes = np.asarray(model.nodes)

    def loads_of(factors: dict[str, float]) -> np.ndarray:
        if not factors:
            return np.zeros((len(nodes), 6))
        case = combine(load_cases, LoadCombination(name="part", limit_state=combination.limit_state,
                                                   factors=factors))
        return nodal_loads(case)

    names = list(control_points)
    points = np.array([control_points[n] for n in names], dtype=float)
    _, nearest = cKDTree(nodes).query(points)
    control = [int(n) for n in nearest]
    run = nonlinear_static(model, supports, loads_of(variable), control=(control[0], 2),
                           initial_loads=loads_of(permanent), max_load_factor=max_load_factor,
                           max_steps=max_steps, monitor=[(n, 2) for n in control])
    return LoadTest(permanent=permanent, variable=variable, control_nodes=dict(zip(names, control)),
                    path=np.asarray(run.path), monitored=np.asarray(run.monitored),
                    limit_load_factor=run.limit_load_factor, converged=bool(run.converged))
