"""The structural protocol of the thesis (METHOD.md section 5) on one grid-shell.

Linear static (LS) under the serviceability load: the largest displacement delta_L;
linear static under the ultimate load: member forces for the checks; linear buckling
(LB) under the ultimate load: lambda_LB and the first modes; geometrically non-linear
static (GNL) with arc-length up to the limit point, on the perfect geometry and on
imperfect ones: the LS shape, the GNL shape and LB modes 1-3, each scaled to a largest
amplitude eps, both signs. The lowest lambda_NL is the worst imperfection.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from .supports import Supports

__all__ = ["TOLERABLE_DEFLECTION_RATIO", "ImperfectionCase", "ImperfectionShape", "ProtocolSettings",
           "ProtocolResult", "imperfection_shapes", "nonlinear_path", "run_protocol"]

#: The tolerable deflection of a non-linear path is the grid's shorter plan side over this ratio
#: (``ProtocolSettings.max_displacement``, set by the caller that knows the span).
TOLERABLE_DEFLECTION_RATIO = 50.0

#: The imperfect geometries: the linear (LS) and non-linear (GNL) shapes and the first three buckling modes.
ImperfectionShape = Literal["linear", "nonlinear", "mode1", "mode2", "mode3"]


@dataclass(frozen=True, kw_only=True)
class ProtocolSettings:
    """n_modes: buckling modes computed; amplitude: eps (m); shapes: which imperfections;
    nonlinear: run the GNL analyses; max_load_factor: where a GNL path stops without a limit point;
    max_displacement: the tolerable deformation (m), where a GNL path without a limit point before
    it stops and reads its capacity (None: none)."""

    n_modes: int = 6
    amplitude: float = 0.01
    shapes: tuple[ImperfectionShape, ...] = ("linear", "nonlinear", "mode1", "mode2", "mode3")
    nonlinear: bool = True
    max_load_factor: float = 10.0
    max_steps: int = 80
    max_displacement: float | None = None


@dataclass(frozen=True, kw_only=True)
class ImperfectionCase:
    """One GNL run: its shape name and sign, limit load factor (None if not reached), path (s, 2),
    whether the path ended normally (False: the solver stopped early), and the load factor at the
    tolerable deformation where the path reached it before any limit point (else None)."""

    name: str
    limit_load_factor: float | None
    path: np.ndarray
    negative_pivots: np.ndarray | None = None
    converged: bool = True
    tolerable_load_factor: float | None = None

    @property
    def peak_load_factor(self) -> float:
        """The highest load factor carried along the path."""
        return float(np.max(self.path[:, 0])) if len(self.path) else 0.0

    @property
    def read_at(self) -> Literal["limit", "tolerable", "carried"]:
        """Where the capacity is read: the limit point, the tolerable deformation reached before
        any, or (neither reached) the highest factor carried."""
        if self.limit_load_factor is not None:
            return "limit"
        return "carried" if self.tolerable_load_factor is None else "tolerable"

    @property
    def capacity(self) -> float:
        """The load factor where the path's capacity is read (``read_at``): its limit load factor,
        the load factor at the tolerable deformation, or the highest factor carried (a lower bound,
        conservative when the path stopped early)."""
        if self.limit_load_factor is not None:
            return self.limit_load_factor
        return self.peak_load_factor if self.tolerable_load_factor is None else self.tolerable_load_factor


@dataclass(frozen=True, kw_only=True)
class ProtocolResult:
    sls_displacements: np.ndarray
    uls_displacements: np.ndarray
    uls_beam_end_forces: np.ndarray
    uls_reactions: np.ndarray
    equilibrium_error: float
    buckling_factors: np.ndarray
    buckling_modes: np.ndarray
    control_node: int
    perfect: ImperfectionCase | None
    imperfect: list[ImperfectionCase] = field(default_factory=list)
    buckling_error: str | None = None

    @property
    def delta_L(self) -> float:
        """Largest displacement under the serviceability load, m."""
        return float(np.linalg.norm(self.sls_displacements[:, :3], axis=1).max())

    @property
    def lambda_LB(self) -> float | None:
        return float(self.buckling_factors[0]) if len(self.buckling_factors) else None

    @property
    def worst(self) -> ImperfectionCase | None:
        """The imperfect case with the lowest capacity (limit load factor, or load factor carried)."""
        return min(self.imperfect, key=lambda c: c.capacity) if self.imperfect else None

    @property
    def knock_down(self) -> float | None:
        """Worst imperfect over perfect limit load factor."""
        worst = self.worst
        if not worst or not self.perfect or not self.perfect.capacity:
            return None
        return worst.capacity / self.perfect.capacity


def _scaled(shape: np.ndarray, amplitude: float) -> np.ndarray | None:
    translations = np.asarray(shape)[:, :3]
    peak = np.linalg.norm(translations, axis=1).max()
    return None if peak < 1e-300 else translations * (amplitude / peak)


def imperfection_shapes(settings: ProtocolSettings, sls_displacements: np.ndarray,
                        nonlinear_displacements: np.ndarray | None,
                        modes: np.ndarray) -> dict[str, np.ndarray]:
    """Named nodal offsets (n, 3), each with largest translation ``settings.amplitude``, both signs."""
    sources: dict[ImperfectionShape, np.ndarray | None] = {}
    for name in settings.shapes:
        if name == "linear":
            sources[name] = sls_displacements
        elif name == "nonlinear":
            sources[name] = nonlinear_displacements
        elif name.startswith("mode"):
            k = int(name[4:]) - 1
            sources[name] = modes[k] if k < len(modes) else None
    out: dict[str, np.ndarray] = {}
    for name, shape in sources.items():
        scaled = None if shape is None else _scaled(shape, settings.amplitude)
        if scaled is not None:
            out[f"{name}+"] = scaled
            out[f"{name}-"] = -scaled
    return out


class _Deferred:
    """A call run when its result is first asked for: the in-process stand-in for a pool's future,
    so that without a pool the paths run one after another, each when it is awaited."""

    def __init__(self, function: Callable, args: tuple) -> None:
        self._call, self._value = (function, args), None

    def result(self):
        if self._call is not None:
            function, args = self._call
            self._value, self._call = function(*args), None
        return self._value


def _submit(executor: Executor | None, function: Callable, *args):
    return _Deferred(function, args) if executor is None else executor.submit(function, *args)


def nonlinear_path(model, supports: Supports, loads: np.ndarray, control_node: int, settings: ProtocolSettings,
                   name: str) -> tuple[ImperfectionCase, np.ndarray]:
    """One GNL path of ``model`` (its nodes as given: perfect or imperfect) under ``loads`` with
    arc-length control of ``control_node``'s vertical displacement: the case and the displacements
    at its end (n, 6). A module-level function, so that a process pool can run it."""
    from .frame import nonlinear_static

    run = nonlinear_static(model, supports, loads, control=(control_node, 2),
                           max_load_factor=settings.max_load_factor, max_steps=settings.max_steps,
                           max_displacement=settings.max_displacement)
    return (ImperfectionCase(name=name, limit_load_factor=run.limit_load_factor, path=np.asarray(run.path),
                             negative_pivots=run.negative_pivots, converged=run.converged,
                             tolerable_load_factor=run.tolerable_load_factor), run.displacements)


def run_protocol(model, supports: Supports, sls_loads: np.ndarray, uls_loads: np.ndarray,
                 settings: ProtocolSettings, *, progress=None, executor: Executor | None = None) -> ProtocolResult:
    """Run LS (SLS and ULS), LB and GNL with imperfections on a frame model (engine.structure.frame).

    ``executor`` (e.g. a process pool) runs the GNL paths side by side: the perfect path and the
    imperfections that do not need its shape at once, the GNL-shape imperfections after it; the
    results are the same, in the same order, as without one."""
    from ..errors import ConvergenceError
    from .frame import BucklingResult, factor_stiffness, linear_buckling, linear_static

    def say(text: str, fraction: float | None = None) -> None:
        if progress is not None:
            progress(text, fraction)

    say("linear static, SLS")
    stiffness = factor_stiffness(model, supports)  # factored once for the three linear analyses
    sls = linear_static(model, supports, sls_loads, stiffness=stiffness)
    say("linear static, ULS")
    uls = linear_static(model, supports, uls_loads, stiffness=stiffness)
    say("linear buckling")
    buckling_error = None
    try:
        buckling = linear_buckling(model, supports, uls_loads, n_modes=settings.n_modes, stiffness=stiffness)
    except ConvergenceError as error:  # reported by the caller; the non-linear paths go on without modes
        buckling_error = str(error).splitlines()[0]
        buckling = BucklingResult(factors=np.zeros(0), modes=np.zeros((0, len(model.nodes), 6)))
    del stiffness  # its factor is not needed by the paths, which factor their tangents
    vertical = np.abs(uls.displacements[:, 2])
    control_node = int(np.argmax(vertical))
    perfect = None
    imperfect: list[ImperfectionCase] = []
    if settings.nonlinear:
        nodes = np.asarray(model.nodes)

        def path(offset: np.ndarray | None, name: str):
            shaped = model if offset is None else replace(model, nodes=nodes + offset)
            return _submit(executor, nonlinear_path, shaped, supports, uls_loads, control_node, settings, name)

        first = replace(settings, shapes=tuple(s for s in settings.shapes if s != "nonlinear"))
        paths = {"perfect": path(None, "perfect")}
        paths.update({name: path(offset, name)
                      for name, offset in imperfection_shapes(first, sls.displacements, None, buckling.modes).items()})
        say("non-linear, perfect")
        perfect, gnl_shape = paths["perfect"].result()
        shapes = imperfection_shapes(settings, sls.displacements, gnl_shape, buckling.modes)
        paths.update({name: path(offset, name) for name, offset in shapes.items() if name not in paths})
        for i, name in enumerate(shapes):
            say(f"non-linear, imperfection {name}", (i + 1) / max(len(shapes), 1))
            imperfect.append(paths[name].result()[0])
    return ProtocolResult(sls_displacements=sls.displacements, uls_displacements=uls.displacements,
                          uls_beam_end_forces=uls.beam_end_forces, uls_reactions=uls.reactions,
                          equilibrium_error=float(uls.equilibrium_error),
                          buckling_factors=np.asarray(buckling.factors), buckling_modes=np.asarray(buckling.modes),
                          control_node=control_node, perfect=perfect, imperfect=imperfect,
                          buckling_error=buckling_error)
