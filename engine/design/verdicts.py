"""The verdicts of a design: each structural check of the protocol (METHOD.md 5) as the engineer
signs it off, with its value, its limit, whether it passes, the part it concerns and what to change.

The checks are the largest member utilisation (ULS, at most 1), the largest vertical deflection
(SLS, at most span / ratio), the linear buckling load factor lambda_LB and the worst non-linear
load factor lambda_NL (each at least the required load factor); a linear buckling analysis that
did not solve is a failing verdict of its own. The failing verdicts are the design's findings
(engine.findings). What to change is the caller's to say: its fix texts name the settings in
its own vocabulary (a project file's keys), which the engine does not know.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..findings import Finding
from ..parts import beam_id, node_id
from ..structure.protocol import ImperfectionCase

__all__ = ["Verdict", "VerdictFixes", "design_verdicts", "findings_of"]

#: Verdicts on one member or node, whose record names the result before the part.
_PART_AFTER_RESULT = ("utilisation", "deflection")


@dataclass(frozen=True, kw_only=True)
class Verdict:
    """One check: ``check`` (its line for a person), ``kind`` (utilisation, deflection, buckling,
    buckling_not_solved, nonlinear_buckling, nonlinear_path_stopped), ``value`` against ``limit``
    in ``unit`` (None where the check could not be computed), ``passed``, the ``part`` it concerns
    (B0001, N0001, mode 1, an imperfection's name), ``fix`` (what to change) and ``error`` (why it
    was not computed)."""

    check: str
    kind: str
    value: float | None
    limit: float
    passed: bool
    part: str
    fix: str = ""
    unit: str = ""
    error: str | None = None

    def to_dict(self) -> dict[str, object]:
        """JSON-ready record, as analysis.json holds it: "pass" for ``passed``, "unit" and "error"
        only where set, and a member's or node's check naming its part after the result, the
        others before it."""
        out: dict[str, object] = {"check": self.check, "kind": self.kind, "value": self.value, "limit": self.limit}
        if self.kind in _PART_AFTER_RESULT:
            out["pass"] = self.passed
            if self.unit:
                out["unit"] = self.unit
            out["part"] = self.part
        else:
            out["part"] = self.part
            out["pass"] = self.passed
            if self.unit:
                out["unit"] = self.unit
        if self.error is not None:
            out["error"] = self.error
        out["fix"] = self.fix
        return out

    def finding(self, stage: str = "") -> Finding:
        """The finding of this verdict (whether or not it passed): its error, or the check with its
        value against its limit, as the message."""
        unit = f" {self.unit}" if self.unit else ""
        message = (self.error if self.error is not None
                   else f"{self.check}: {self.value:.3g}{unit} against {self.limit:.3g}{unit}")
        return Finding(kind=self.kind, parts=[self.part], measure=self.value, limit=self.limit, unit=self.unit,
                       stage=stage, fix=self.fix, message=message)


@dataclass(frozen=True, kw_only=True)
class VerdictFixes:
    """What to change when a check fails: ``stiffer`` (a stiffer or stronger structure: utilisation,
    lambda_LB, lambda_NL), ``deflection``, ``buckling_not_solved`` and ``path_stopped`` (a
    non-linear path whose corrector did not converge under the required load factor)."""

    stiffer: str
    deflection: str
    buckling_not_solved: str
    path_stopped: str = "check the supports and end releases for a near-mechanism"


def design_verdicts(*, utilisation: np.ndarray, sls_displacements: np.ndarray, deflection_limit: float,
                    deflection_ratio: float, required_load_factor: float, lambda_LB: float | None,
                    buckling_error: str | None, worst: ImperfectionCase | None,
                    fixes: VerdictFixes) -> list[Verdict]:
    """The verdicts of a design, in order: member utilisation (``utilisation`` (b,), at most 1),
    vertical deflection (``sls_displacements`` (n, 6), at most ``deflection_limit``, the span over
    ``deflection_ratio``), then where there is one each: the linear buckling analysis that did not
    solve (``buckling_error``), lambda_LB and the ``worst`` imperfect non-linear path's capacity (its
    limit load factor, the load factor at the tolerable deformation, or the load factor it carried),
    each at least ``required_load_factor``. A worst path that stopped unconverged under it is a
    ``nonlinear_path_stopped`` verdict: its load factor is a lower bound, not a buckling load."""
    utilisation = np.asarray(utilisation)
    vertical = np.abs(np.asarray(sls_displacements)[:, 2])
    largest_utilisation, deflection = float(utilisation.max()), float(vertical.max())
    verdicts = [
        Verdict(check="member utilisation (ULS)", kind="utilisation", value=largest_utilisation, limit=1.0,
                passed=bool(largest_utilisation <= 1.0), part=beam_id(int(utilisation.argmax())),
                fix=fixes.stiffer),
        Verdict(check=f"deflection (SLS) vs span/{deflection_ratio:g}", kind="deflection", value=deflection,
                limit=deflection_limit, passed=bool(deflection <= deflection_limit), unit="m",
                part=node_id(int(vertical.argmax())), fix=fixes.deflection),
    ]
    if buckling_error is not None:
        verdicts.append(Verdict(check="linear buckling load factor (not solved)", kind="buckling_not_solved",
                                value=None, limit=required_load_factor, part="mode 1", passed=False,
                                error=buckling_error, fix=fixes.buckling_not_solved))
    if lambda_LB is not None:
        verdicts.append(Verdict(check="linear buckling load factor", kind="buckling", value=lambda_LB,
                                limit=required_load_factor, part="mode 1",
                                passed=bool(lambda_LB >= required_load_factor), fix=fixes.stiffer))
    if worst is not None:
        capacity = float(worst.capacity)
        passed = bool(capacity >= required_load_factor)
        kind, fix = "nonlinear_buckling", fixes.stiffer
        if worst.read_at == "carried" and not worst.converged:
            # the solver stopped, not the structure: a lower bound, and no buckling shown
            label = "load factor carried before its path stopped unconverged"
            kind, fix = ("nonlinear_buckling" if passed else "nonlinear_path_stopped"), fixes.path_stopped
        else:
            label = {"limit": "limit load factor",
                     "tolerable": "load factor at the tolerable deflection (no limit point before it)",
                     "carried": "load factor carried (no limit point found)"}[worst.read_at]
        verdicts.append(Verdict(check=f"worst non-linear {label} ({worst.name})", kind=kind, value=capacity,
                                limit=required_load_factor, part=worst.name, passed=passed, fix=fix))
    return verdicts


def findings_of(verdicts: list[Verdict], stage: str = "") -> list[Finding]:
    """The findings of the verdicts that fail, in their order, tagged with ``stage``."""
    return [verdict.finding(stage) for verdict in verdicts if not verdict.passed]
