"""One-dimensional cutting stock: beams cut from stock bars with a saw kerf.

Exact for small jobs (an assignment model solved with scipy.optimize.milp: piece i in bar j,
bar j used; bars used in order to break symmetry), best-fit decreasing for large ones. Each
piece takes its length plus one kerf. Lengths in mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from engine.errors import InputError

from .files import atomic_path
from .ids import bar_id

__all__ = ["BarNesting", "nest_bars", "best_fit_decreasing", "lower_bound"]


@dataclass(frozen=True, kw_only=True)
class BarNesting:
    """bars: piece indices per bar; offcuts_mm per bar; waste_mm = total offcut; method and
    optimal (proven by the MILP, or equal to the lower bound)."""

    bars: list[list[int]]
    lengths_mm: np.ndarray
    labels: list[str]
    stock_length_mm: float
    kerf_mm: float
    lower_bound: int
    method: str
    optimal: bool
    offcuts_mm: list[float] = field(default_factory=list)

    @property
    def bars_used(self) -> int:
        return len(self.bars)

    @property
    def waste_mm(self) -> float:
        return float(sum(self.offcuts_mm))

    def rows(self, *, first_number: int = 1, profile: str | None = None) -> list[dict]:
        """One row per bar: bar id (numbered from ``first_number``), profile where given, pieces
        (labels), piece lengths (mm), count, used and offcut (mm)."""
        rows = []
        for number, (pieces, offcut) in enumerate(zip(self.bars, self.offcuts_mm), start=first_number):
            rows.append({"bar": bar_id(number - 1), **({} if profile is None else {"profile": profile}),
                         "pieces": " ".join(self.labels[i] for i in pieces),
                         "lengths_mm": " ".join(f"{self.lengths_mm[i]:.1f}" for i in pieces),
                         "count": len(pieces), "used_mm": round(self.stock_length_mm - offcut, 1),
                         "offcut_mm": round(offcut, 1)})
        return rows

    def to_csv(self, path: Path) -> Path:
        """bars.csv: bar, pieces (labels), piece lengths (mm), used and offcut (mm)."""
        import pandas as pd

        with atomic_path(path) as tmp:
            pd.DataFrame(self.rows()).to_csv(tmp, index=False)
        return Path(path)


def lower_bound(lengths_mm: np.ndarray, stock_length_mm: float, kerf_mm: float) -> int:
    """ceil(sum(length + kerf) / stock): no nesting can use fewer bars."""
    return int(math.ceil((np.sum(lengths_mm) + kerf_mm * len(lengths_mm)) / stock_length_mm - 1e-9))


def best_fit_decreasing(lengths_mm: np.ndarray, stock_length_mm: float, kerf_mm: float) -> list[list[int]]:
    """Longest pieces first, each into the bar it leaves the least room in."""
    room: list[float] = []
    bars: list[list[int]] = []
    for i in np.argsort(-np.asarray(lengths_mm), kind="stable"):
        need = lengths_mm[i] + kerf_mm
        fits = [(r - need, b) for b, r in enumerate(room) if r - need >= -1e-9]
        if fits:
            _, b = min(fits)
            room[b] -= need
            bars[b].append(int(i))
        else:
            room.append(stock_length_mm - need)
            bars.append([int(i)])
    return bars


def _milp(lengths_mm: np.ndarray, stock_length_mm: float, kerf_mm: float, n_bars: int,
          time_limit_s: float) -> tuple[list[list[int]], bool] | None:
    from scipy.optimize import Bounds, LinearConstraint, milp

    n = len(lengths_mm)
    size = lengths_mm + kerf_mm
    # variables: x (n * n_bars) then y (n_bars); minimise bars used
    c = np.r_[np.zeros(n * n_bars), np.ones(n_bars)]
    rows, lo, hi = [], [], []
    assign = np.zeros((n, n * n_bars + n_bars))
    for i in range(n):
        assign[i, i * n_bars:(i + 1) * n_bars] = 1
    rows.append(assign), lo.append(np.ones(n)), hi.append(np.ones(n))
    capacity = np.zeros((n_bars, n * n_bars + n_bars))
    for j in range(n_bars):
        capacity[j, j:n * n_bars:n_bars] = size
        capacity[j, n * n_bars + j] = -stock_length_mm
    rows.append(capacity), lo.append(np.full(n_bars, -np.inf)), hi.append(np.zeros(n_bars))
    order = np.zeros((n_bars - 1, n * n_bars + n_bars))
    for j in range(n_bars - 1):
        order[j, n * n_bars + j] = -1
        order[j, n * n_bars + j + 1] = 1
    rows.append(order), lo.append(np.full(n_bars - 1, -np.inf)), hi.append(np.zeros(n_bars - 1))
    constraint = LinearConstraint(np.vstack(rows), np.concatenate(lo), np.concatenate(hi))
    result = milp(c, constraints=constraint, integrality=np.ones_like(c), bounds=Bounds(0, 1),
                  options={"time_limit": time_limit_s})
    if result.x is None:
        return None
    x = np.round(result.x[:n * n_bars]).reshape(n, n_bars)
    bars = [list(np.flatnonzero(x[:, j])) for j in range(n_bars)]
    return [b for b in bars if b], bool(result.status == 0)


def nest_bars(lengths_mm, labels: list[str], stock_length_mm: float, kerf_mm: float, *, exact_limit: int = 40,
              time_limit_s: float = 20.0) -> BarNesting:
    """Cut every piece from stock bars; exact (MILP) up to ``exact_limit`` pieces, else best-fit decreasing."""
    lengths = np.asarray(lengths_mm, dtype=float)
    if stock_length_mm <= 0 or kerf_mm < 0:
        raise InputError("bar nesting: stock length must be positive and kerf not negative")
    too_long = np.flatnonzero(lengths + kerf_mm > stock_length_mm)
    if len(too_long):
        i = int(too_long[0])
        raise InputError(f"beam {labels[i]} ({lengths[i]:.0f} mm) is longer than the stock bar "
                         f"({stock_length_mm:.0f} mm)",
                         hint="use longer stock bars or split the beam")
    bound = lower_bound(lengths, stock_length_mm, kerf_mm)
    bars = best_fit_decreasing(lengths, stock_length_mm, kerf_mm)
    method, optimal = "best-fit-decreasing", len(bars) == bound
    if not optimal and len(lengths) <= exact_limit:
        solved = _milp(lengths, stock_length_mm, kerf_mm, len(bars), time_limit_s)
        if solved is not None and len(solved[0]) <= len(bars):
            bars, optimal = solved
            method = "milp"
    offcuts = [float(stock_length_mm - np.sum(lengths[b] + kerf_mm)) for b in bars]
    return BarNesting(bars=[[int(i) for i in b] for b in bars], lengths_mm=lengths, labels=list(labels),
                      stock_length_mm=stock_length_mm, kerf_mm=kerf_mm, lower_bound=bound, method=method,
                      optimal=optimal, offcuts_mm=offcuts)
