"""Findings: what a stage could not build or what does not pass, reported instead of raised.

A finding names its kind, the parts it concerns (B0001, J0001, P0001, N0001), the measure and the
limit it was held against (with their unit), and what to change, naming the TOML key. A stage
carries its findings in its result and its JSON; the run prints them at the end, the report opens
with them, and ``gridshell run --strict`` exits 3 when there is any.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

__all__ = ["Finding", "findings_table", "COUNT_UNITS"]

#: Units that count parts: a measure or limit in them is a whole number ("63 beams", not "63.0").
COUNT_UNITS = frozenset({"beams", "cells", "joints", "nodes", "panels", "sheets", "bars", "steps", "props"})


@dataclass(frozen=True, kw_only=True)
class Finding:
    """One check that failed: ``kind`` (e.g. "cut_length", "joint_clash", "sheet_size",
    "utilisation"), ``parts`` (ids), ``measure`` and ``limit`` in ``unit``, ``message`` (one line
    for a person) and ``fix`` (what to change, naming the TOML key)."""

    kind: str
    parts: list[str] = field(default_factory=list)
    measure: float | None = None
    limit: float | None = None
    unit: str = ""
    message: str = ""
    fix: str = ""
    stage: str = ""

    def to_dict(self) -> dict:
        """JSON-ready record: measure and limit as floats, or as whole numbers in ``COUNT_UNITS``."""
        out = asdict(self)
        for key in ("measure", "limit"):
            if out[key] is not None:
                value = float(out[key])
                out[key] = int(value) if self.unit in COUNT_UNITS and value.is_integer() else value
        return out


def findings_table(findings: list[dict], max_parts: int = 6) -> list[dict]:
    """Findings grouped by kind for a person: one row per kind with the count, the worst measure
    and its parts (at most ``max_parts`` named), the limit and the fix."""
    rows: dict[str, dict] = {}
    for f in findings:
        row = rows.setdefault(f["kind"], {"kind": f["kind"], "count": 0, "parts": [], "worst": None,
                                          "worst_parts": [], "limit": f.get("limit"), "unit": f.get("unit", ""),
                                          "fix": f.get("fix", ""), "message": f.get("message", "")})
        row["count"] += 1
        row["parts"].extend(f.get("parts", []))
        measure = f.get("measure")
        if measure is not None and (row["worst"] is None or _worse(f, measure, row["worst"])):
            row["worst"], row["worst_parts"], row["message"] = measure, f.get("parts", []), f.get("message", "")
    for row in rows.values():
        named = row["parts"][:max_parts]
        row["parts"] = named + ([f"... {len(row['parts']) - max_parts} more"] if len(row["parts"]) > max_parts else [])
    return list(rows.values())


def _worse(finding: dict, measure: float, worst: float) -> bool:
    """Whether ``measure`` is further past the finding's limit than ``worst`` (limits are minima
    when the measure is under them, maxima otherwise)."""
    limit = finding.get("limit")
    if limit is None:
        return measure > worst
    return abs(measure - limit) > abs(worst - limit)
