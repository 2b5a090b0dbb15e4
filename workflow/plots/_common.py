"""Shared set-up of the matplotlib pictures: Agg backend, atomic PNG saving, 3-D framing."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fabrication.files import save_figure_png
from fabrication.plan_view import WIDE_PLAN, is_wide_plan, plan_depth_ratio, plan_height_in, plan_limits

__all__ = ["pyplot", "save_png", "frame_3d", "view_and_plan", "plan_figure", "colour_bar", "spread_sample",
           "WIDE_PLAN", "plan_depth_ratio", "is_wide_plan", "plan_height_in", "plan_limits"]

#: Height (inches) of the 3-D view's row above a wide plan (a 3-D axes keeps itself square).
VIEW_ROW_IN = 4.2


def spread_sample(points: np.ndarray, count: int, plan_area: float) -> tuple[np.ndarray, float]:
    """(ids, spacing m): at most about ``count`` of the plan ``points`` (k, 2), spread evenly: the
    plan is cut into squares of side ``spacing`` (``count`` of them over ``plan_area``) and the point
    nearest each square's centre is kept. All points when there are no more than ``count``.
    A random choice clumped and left gaps where the mesh is fine (a scan of a million triangles)."""
    points = np.asarray(points, dtype=float)[:, :2]
    if len(points) <= count:
        return np.arange(len(points)), float(np.sqrt(max(plan_area, 1e-300) / max(len(points), 1)))
    spacing = float(np.sqrt(max(plan_area, 1e-300) / count))
    cell = np.floor((points - points.min(axis=0)) / spacing).astype(np.int64)
    key = cell[:, 0] * (int(cell[:, 1].max()) + 1) + cell[:, 1]
    off_centre = np.linalg.norm(points - points.min(axis=0) - (cell + 0.5) * spacing, axis=1)
    order = np.lexsort((off_centre, key))
    first = np.r_[True, key[order][1:] != key[order][:-1]]
    return np.sort(order[first]), spacing


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_png(fig, path: Path, dpi: int = 130) -> Path:
    """Save ``fig`` as a palette PNG (fabrication.files.figure_png) atomically and close it."""
    plt = pyplot()
    save_figure_png(fig, path, dpi=dpi)
    plt.close(fig)
    return Path(path)


def frame_3d(ax, points: np.ndarray) -> None:
    """Limits and box of a 3-D axes around ``points`` (k, 3) at true scale, the height at least
    5 % of the plan's extent so that flat or nearly flat surfaces still read (and the projection
    stays finite)."""
    lo, span = points.min(axis=0), np.ptp(points, axis=0)
    height = max(span[2], 0.05 * span.max(), 1e-9)
    middle = lo[2] + 0.5 * span[2]
    ax.set_xlim(lo[0], lo[0] + max(span[0], 1e-9))
    ax.set_ylim(lo[1], lo[1] + max(span[1], 1e-9))
    ax.set_zlim(middle - 0.5 * height, middle + 0.5 * height)
    ax.set_box_aspect((max(span[0], 1e-9), max(span[1], 1e-9), height))
    # as many height ticks as the box is tall can hold without their labels running together
    from matplotlib.ticker import MaxNLocator

    ax.zaxis.set_major_locator(MaxNLocator(nbins=int(np.clip(round(8 * height / max(span.max(), 1e-9)), 1, 6))))



def view_and_plan(plt, points: np.ndarray, *, size_in: tuple[float, float], plan_width_in: float,
                  dpi: float | None = None):
    """(figure, 3-D axes, plan axes, wide): a 3-D view beside the plan of ``points`` in a
    ``size_in`` picture, or, for a wide plan (WIDE_PLAN), above it, the plan then across
    ``plan_width_in`` of the picture's width at its true scale."""
    extra = {} if dpi is None else {"dpi": dpi}
    if is_wide_plan(points):
        plan_in = plan_height_in(points, plan_width_in, labels_in=1.25)
        fig = plt.figure(figsize=(size_in[0], VIEW_ROW_IN + plan_in), **extra)
        rows = fig.add_gridspec(2, 1, height_ratios=[VIEW_ROW_IN, plan_in])
        return fig, fig.add_subplot(rows[0], projection="3d"), fig.add_subplot(rows[1]), True
    fig = plt.figure(figsize=size_in, **extra)
    return fig, fig.add_subplot(1, 2, 1, projection="3d"), fig.add_subplot(1, 2, 2), False


def plan_figure(plt, points: np.ndarray, size_in: tuple[float, float], *, labels_in: float):
    """(figure, axes, wide) of one plan of ``points``: a ``size_in`` picture, or for a wide plan
    (WIDE_PLAN) one 12 inches wide and as deep as the plan needs across 10.5 of them, with
    ``labels_in`` more for its title, labels and what goes under it."""
    wide = is_wide_plan(points)
    fig, ax = plt.subplots(figsize=(12, plan_height_in(points, 10.5, labels_in=labels_in)) if wide else size_in)
    return fig, ax, wide


def colour_bar(fig, mappable, ax, wide: bool, **kwargs):
    """A colour bar beside a plan, or under a wide one (beside it, a bar stood far off at the
    picture's edge, and a long label did not fit its height); ``kwargs`` go to ``fig.colorbar``."""
    if wide:
        return fig.colorbar(mappable, ax=ax, **{"orientation": "horizontal", "shrink": 0.5, "pad": 0.3, "aspect": 40,
                                                **kwargs})
    return fig.colorbar(mappable, ax=ax, **{"shrink": 0.8, **kwargs})
