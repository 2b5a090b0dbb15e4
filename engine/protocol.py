"""The structural protocol of the thesis (METHOD.md section 5) on one grid-shell.

Linear static (LS) under the serviceability load: the largest displacement delta_L;
linear static under the ultimate load: member forces for the checks; linear buckling
(LB) under the ultimate load: lambda_LB and the first modes; geometrically non-linear
static (GNL) with arc-length up to the limit point, on the perfect geometry and on
imperfect ones: the LS shape, the GNL shape and LB modes 1-3, each scaled to a largest
amplitude eps, both signs. The lowest lambda_NL is the worst imperfection.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .supports import Supports

__all__ = ["ImperfectionCase", "ProtocolSettings", "ProtocolResult", "imperfection_shapes", "run_protocol"]


@dataclass(frozen=True, kw_only=True)
class ProtocolSettings:
    """n_modes: buckling modes computed; amplitude: eps (m); shapes: which imperfections;
    nonlinear: run the GNL analyses; max_load_factor: where a GNL path stops without a limit point."""

    n_modes: int = 6
    amplitude: float = 0.01
    shapes: tuple[str, ...] = ("linear", "nonlinear", "mode1", "mode2", "mode3")
    nonlinear: bool = True
    max_load_factor: float = 10.0
    max_steps: int = 80


@dataclass(frozen=True, kw_only=True)
class ImperfectionCase:
    """One GNL run: its shape name and sign, limit load factor (None if not reached), path (s, 2),
    and whether the path ended normally (False: the solver stopped early)."""

    name: str
    limit_load_factor: float | None
    path: np.ndarray
    negative_pivots: np.ndarray | None = None
    converged: bool = True

    @property
    def peak_load_factor(self) -> float:
        """The highest load factor carried along the path."""
        return float(np.max(self.path[:, 0])) if len(self.path) else 0.0

    @property
    def capacity(self) -> float:
        """The limit load factor, or where no limit point was found the highest factor carried
        (a lower bound, conservative when the path stopped early)."""
        return self.limit_load_factor if self.limit_load_factor is not None else self.peak_load_factor


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
    sources: dict[str, np.ndarray | None] = {}
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


def run_protocol(model, supports: Supports, sls_loads: np.ndarray, uls_loads: np.ndarray,
                 settings: ProtocolSettings, *, progress=None) -> ProtocolResult:
    """Run LS (SLS and ULS), LB and GNL with imperfections on a frame model (engine.frame)."""
    from dataclasses import replace

    from .errors import ConvergenceError
    from .frame import BucklingResult, linear_buckling, linear_static, nonlinear_static

    def say(text: str, fraction: float | None = None) -> None:
        if progress is not None:
            progress(text, fraction)

    say("linear static, SLS")
    sls = linear_static(model, supports, sls_loads)
    say("linear static, ULS")
    uls = linear_static(model, supports, uls_loads)
    say("linear buckling")
    buckling_error = None
    try:
        buckling = linear_buckling(model, supports, uls_loads, n_modes=settings.n_modes)
    except ConvergenceError as error:  # reported by the caller; the non-linear paths go on without modes
        buckling_error = str(error).splitlines()[0]
        buckling = BucklingResult(factors=np.zeros(0), modes=np.zeros((0, len(model.nodes), 6)))
    vertical = np.abs(uls.displacements[:, 2])
    control_node = int(np.argmax(vertical))
    perfect = None
    imperfect: list[ImperfectionCase] = []
    if settings.nonlinear:
        def gnl(nodes: np.ndarray, name: str) -> tuple[ImperfectionCase, np.ndarray]:
            run = nonlinear_static(replace(model, nodes=nodes), supports, uls_loads, control=(control_node, 2),
                                   max_load_factor=settings.max_load_factor, max_steps=settings.max_steps)
            return (ImperfectionCase(name=name, limit_load_factor=run.limit_load_factor, path=np.asarray(run.path),
                                     negative_pivots=getattr(run, "negative_pivots", None),
                                     converged=bool(getattr(run, "converged", True))), run.displacements)

        say("non-linear, perfect")
        perfect, gnl_shape = gnl(np.asarray(model.nodes), "perfect")
        shapes = imperfection_shapes(settings, sls.displacements, gnl_shape, buckling.modes)
        for i, (name, offset) in enumerate(shapes.items()):
            say(f"non-linear, imperfection {name}", (i + 1) / max(len(shapes), 1))
            case, _ = gnl(np.asarray(model.nodes) + offset, name)
            imperfect.append(case)
    return ProtocolResult(sls_displacements=sls.displacements, uls_displacements=uls.displacements,
                          uls_beam_end_forces=uls.beam_end_forces, uls_reactions=uls.reactions,
                          equilibrium_error=float(uls.equilibrium_error),
                          buckling_factors=np.asarray(buckling.factors), buckling_modes=np.asarray(buckling.modes),
                          control_node=control_node, perfect=perfect, imperfect=imperfect,
                          buckling_error=buckling_error)
