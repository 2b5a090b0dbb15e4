"""Pictures of the beam analysis: utilisation, axial forces, buckling modes, response diagrams."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fabrication.ids import beam_id

from ._common import colour_bar, frame_3d, plan_figure, plan_limits, pyplot, save_png

__all__ = ["plot_utilisation", "plot_axial_forces", "plot_buckling_modes", "plot_response", "plot_sections"]


def _segments(nodes: np.ndarray, beams: np.ndarray) -> np.ndarray:
    return np.stack([nodes[beams[:, 0], :2], nodes[beams[:, 1], :2]], axis=1)


def _frame(ax, nodes: np.ndarray) -> None:
    x_limits, y_limits = plan_limits(nodes)
    ax.set_xlim(*x_limits)
    ax.set_ylim(*y_limits)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)"), ax.set_ylabel("y (m)")


def plot_utilisation(nodes: np.ndarray, beams: np.ndarray, utilisation: np.ndarray, path: Path, *,
                     title: str = "") -> Path:
    """Plan with beams coloured by utilisation (0 to 1, above 1 in dark red), the largest labelled."""
    plt = pyplot()
    from matplotlib.collections import LineCollection

    fig, ax, wide = plan_figure(plt, nodes, (9, 8), labels_in=2.0)
    utilisation = np.asarray(utilisation, dtype=float)
    cmap = plt.get_cmap("RdYlGn_r").with_extremes(over="#5b0000")
    lines = LineCollection(_segments(nodes, beams), cmap=cmap, norm=plt.Normalize(0.0, 1.0),
                           linewidths=1.5 + 2.5 * np.clip(utilisation, 0, 1.2))
    lines.set_array(utilisation)
    ax.add_collection(lines)
    colour_bar(fig, lines, ax, wide, extend="max", label="utilisation")
    worst = int(np.argmax(utilisation))
    middle = nodes[beams[worst]].mean(axis=0)
    inward = middle[0] > 0.5 * (nodes[:, 0].min() + nodes[:, 0].max())  # the label toward the middle, in the plot
    ax.annotate(f"{beam_id(worst)}: {utilisation[worst]:.2f}", middle[:2], xytext=(-10 if inward else 10, 10),
                textcoords="offset points", ha="right" if inward else "left", fontsize=9,
                bbox={"boxstyle": "round,pad=0.2", "facecolor": "white", "edgecolor": "0.6", "alpha": 0.9},
                arrowprops={"arrowstyle": "->"})
    _frame(ax, nodes)
    ax.set_title(title or "member utilisation")
    fig.tight_layout()
    return save_png(fig, path)


def plot_sections(nodes: np.ndarray, beams: np.ndarray, profiles: list[str], diameters_m: np.ndarray, path: Path, *,
                  title: str = "") -> Path:
    """Plan with beams coloured by their sized tube (legend: profile and count), drawn wider for
    larger tubes."""
    plt = pyplot()
    from matplotlib.collections import LineCollection

    fig, ax, wide = plan_figure(plt, nodes, (11, 8), labels_in=2.0)
    diameters = np.asarray(diameters_m, dtype=float)
    names = np.asarray(profiles)
    order = sorted(set(names.tolist()), key=lambda n: -diameters[names == n].max())
    colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.85, max(len(order), 1)))
    scale = diameters.max() if diameters.max() > 0 else 1.0
    segments = _segments(nodes, beams)
    for colour, name in zip(colours, order):
        mine = names == name
        ax.add_collection(LineCollection(segments[mine], colors=[colour],
                                         linewidths=1.0 + 4.0 * diameters[mine] / scale,
                                         label=f"{name} ({int(mine.sum())} beams)"))
    if wide:  # under a wide grid, not over it
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.35), ncol=3, fontsize=9, frameon=False)
    else:  # beside, not over the grid
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)
    _frame(ax, nodes)
    ax.set_title(title or "sized sections")
    fig.tight_layout()
    return save_png(fig, path)


def plot_axial_forces(nodes: np.ndarray, beams: np.ndarray, axial_forces: np.ndarray, path: Path, *,
                      title: str = "") -> Path:
    """Plan with beams coloured by axial force (compression red, tension blue), width ~ |N|."""
    plt = pyplot()
    from matplotlib.collections import LineCollection

    axial_kN = np.asarray(axial_forces, dtype=float) / 1e3
    peak = max(float(np.abs(axial_kN).max()), 1e-9)
    fig, ax, wide = plan_figure(plt, nodes, (9, 8), labels_in=2.0)
    lines = LineCollection(_segments(nodes, beams), cmap="coolwarm_r", norm=plt.Normalize(-peak, peak),
                           linewidths=0.8 + 4.0 * np.abs(axial_kN) / peak)
    lines.set_array(axial_kN)
    ax.add_collection(lines)
    colour_bar(fig, lines, ax, wide, label="axial force N (kN): compression < 0 < tension")
    _frame(ax, nodes)
    ax.set_title(title or "axial forces")
    fig.tight_layout()
    return save_png(fig, path)


def plot_buckling_modes(nodes: np.ndarray, beams: np.ndarray, modes: np.ndarray, factors: np.ndarray, path: Path, *,
                        title: str = "") -> Path:
    """Up to three modes a row, each an axonometric view of the mode drawn at 8 % of the span over
    the undeformed grid (grey), its beams coloured by the mode's displacement relative to its
    largest (one colour scale for all), with the load factor and the drawn amplitude."""
    plt = pyplot()
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    count = max(len(modes), 1)
    cols = min(count, 3)
    rows = -(-count // cols)
    fig = plt.figure(figsize=(13.0, 13.0 / cols * 0.75 * rows + 0.8))
    span = float(np.ptp(nodes, axis=0).max())
    amplitude = 0.08 * span
    norm = plt.Normalize(0.0, 1.0)
    cmap = plt.get_cmap("viridis")
    for k in range(len(modes)):
        ax = fig.add_subplot(rows, cols, k + 1, projection="3d")
        shape = modes[k][:, :3]
        size = np.linalg.norm(shape, axis=1)
        peak = max(float(size.max()), 1e-300)
        moved = nodes + shape * (amplitude / peak)
        ax.add_collection3d(Line3DCollection(np.stack([nodes[beams[:, 0]], nodes[beams[:, 1]]], axis=1),
                                             colors=(0.6, 0.6, 0.6, 0.45), linewidths=0.5))
        relative = 0.5 * (size[beams[:, 0]] + size[beams[:, 1]]) / peak
        lines = Line3DCollection(np.stack([moved[beams[:, 0]], moved[beams[:, 1]]], axis=1), cmap=cmap, norm=norm,
                                 linewidths=1.4)
        lines.set_array(relative)
        ax.add_collection3d(lines)
        frame_3d(ax, np.vstack([nodes, moved]))
        ax.set_axis_off()
        ax.set_title(f"mode {k + 1}: load factor {factors[k]:.3g}", fontsize=11)
    fig.subplots_adjust(left=0.0, right=0.88, bottom=0.02, top=0.9, wspace=0.0, hspace=0.08)
    mappable = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(mappable, ax=fig.axes, shrink=0.6, pad=0.02,
                 label="displacement / the mode's largest")
    fig.suptitle(f"{title or 'linear buckling modes'}: largest displacement drawn {1000 * amplitude:.0f} mm "
                 "(a mode has no size of its own)", fontsize=11)
    return save_png(fig, path)


#: response points farther out than this (mm, or load factor) are not drawn: matplotlib's transforms
#: fail on limits near the float range, and no real path gets there
_LARGEST_DRAWN = 1e12


def _drawable(curve) -> tuple[np.ndarray | None, int]:
    """The drawable points (k, 2) [displacement mm, load factor] of a path (s, 2) [load factor,
    displacement m]: without its non-finite or absurdly large points, and how many those were;
    None when nothing of the curve can be drawn."""
    try:
        curve = np.asarray(curve, dtype=float)
    except (TypeError, ValueError):
        return None, 0
    if curve.ndim != 2 or curve.shape[1] < 2 or len(curve) == 0:
        return None, 0
    with np.errstate(over="ignore", invalid="ignore"):
        xy = np.column_stack([np.abs(1000 * curve[:, 1]), curve[:, 0]])
        bad = ~(np.isfinite(xy).all(axis=1) & (np.abs(xy) < _LARGEST_DRAWN).all(axis=1))
    return (None if bad.all() else xy[~bad]), int(bad.sum())


#: The marker and legend of each way a path's capacity was read.
_END_MARKERS = {"limit": ("o", "limit point"), "tolerable": ("s", "tolerable deflection reached")}


def plot_response(curves: dict[str, np.ndarray], path: Path, *, worst: str | None = None,
                  required: float | None = None, title: str = "",
                  ends: dict[str, tuple[str, float]] | None = None) -> Path:
    """Load factor against control-node displacement (mm) per curve; the worst bold; the required
    load factor as a dashed line. ``ends``: per curve, why its capacity was read and the load
    factor there: ("limit", lambda) a limit point (a dot), ("tolerable", lambda) the tolerable
    deflection reached before any (a square), labelled once each in the legend.

    Curves are (s, 2) arrays [load factor, displacement m]. Points that are NaN, infinite or beyond
    1e12 are left out (the legend counts them); a curve with nothing left, or empty, is not drawn
    and the title names it; with no curve at all the PNG says so. The picture is always written."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 6))
    skipped = []
    labelled: set[str] = set()
    for name, curve in curves.items():
        xy, dropped = _drawable(curve)
        if xy is None:
            skipped.append(name)
            continue
        bold = name == worst
        label = name if not dropped else f"{name} ({dropped} non-finite point{'s' * (dropped > 1)} left out)"
        line, = ax.plot(xy[:, 0], xy[:, 1], label=label, linewidth=2.6 if bold else 1.1,
                        color="#c0392b" if bold else None, zorder=3 if bold else 2)
        end = (ends or {}).get(name)
        if end is not None and np.isfinite(end[1]):
            kind, factor = end
            rising = xy[: int(np.argmax(xy[:, 1])) + 1]     # up to the highest load factor
            at = float(np.interp(factor, np.maximum.accumulate(rising[:, 1]), rising[:, 0]))
            ax.plot([at], [factor], marker=_END_MARKERS[kind][0], markersize=6, linestyle="none",
                    color=line.get_color(), markeredgecolor="k", zorder=4)
            labelled.add(kind)
    for kind in sorted(labelled):  # one neutral legend entry per kind of end
        ax.plot([], [], marker=_END_MARKERS[kind][0], linestyle="none", color="white", markeredgecolor="k",
                label=_END_MARKERS[kind][1])
    if required is not None and np.isfinite(required):
        ax.axhline(required, color="k", linestyle="--", linewidth=1.0, label=f"required factor {required:g}")
    if len(skipped) == len(curves):
        ax.text(0.5, 0.65, "no response curve to draw", transform=ax.transAxes, ha="center", va="center",
                color="0.3", bbox={"facecolor": "white", "edgecolor": "0.7"})
    ax.set_xlabel("control-node displacement (mm)")
    ax.set_ylabel("load factor")
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, ncol=2)
    heading = title or "load-deflection response"
    if skipped and curves:
        heading += f"\nnot drawn (empty or not finite): {', '.join(skipped)}"
    ax.set_title(heading, fontsize=11 if skipped else None)
    fig.tight_layout()
    return save_png(fig, path)
