"""The shape of a plan picture: a roof much wider than deep is drawn across the picture's width.

Used by the pictures of the workflow (workflow.plots) and of the fabrication (the assembly steps),
so that a 50 m x 5 m canopy is not a thin strip across a picture sized for a square roof.
"""

from __future__ import annotations

import numpy as np

__all__ = ["WIDE_PLAN", "plan_depth_ratio", "is_wide_plan", "plan_height_in", "plan_limits"]

#: A plan at least this many times as wide (x) as it is deep (y) is drawn across the picture's
#: width, its panels one above the other: side by side, or in a picture sized for a square roof, a
#: 50 m x 5 m canopy was a thin strip across a picture mostly white.
WIDE_PLAN = 2.0


def plan_depth_ratio(points: np.ndarray) -> float:
    """Depth (y extent) over width (x extent) of the plan of ``points`` (k, 2 or 3)."""
    span = np.ptp(np.asarray(points, dtype=float)[:, :2], axis=0)
    return float(max(span[1], 1e-9) / max(span[0], 1e-9))


def is_wide_plan(points: np.ndarray) -> bool:
    """Whether the plan of ``points`` is at least WIDE_PLAN times as wide as it is deep."""
    return plan_depth_ratio(points) <= 1.0 / WIDE_PLAN


def plan_height_in(points: np.ndarray, width_in: float, *, labels_in: float, least_in: float = 1.5) -> float:
    """Height (inches) of a picture row holding the plan of ``points`` at true scale across
    ``width_in``, with ``labels_in`` more for its title, axis labels and legend."""
    return max(width_in * plan_depth_ratio(points), least_in) + labels_in


def plan_limits(points: np.ndarray, pad: float = 0.04) -> tuple[tuple[float, float], tuple[float, float]]:
    """(x limits, y limits) of a plan axes around ``points``: each side padded by ``pad`` of its own
    extent, and at least a quarter of that of the longest (a wide plan's depth is not padded by its
    length, which left a 50 m x 5 m canopy a strip between two bands of white)."""
    xy = np.asarray(points, dtype=float)[:, :2]
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    margin = np.maximum(pad * (hi - lo), 0.25 * pad * (hi - lo).max())
    return (float(lo[0] - margin[0]), float(hi[0] + margin[0])), (float(lo[1] - margin[1]), float(hi[1] + margin[1]))
