"""The grid-shell in an axonometric view, cells coloured by number of sides or by planarity."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from engine.mesh import PolyMesh

from ._common import colour_bar, frame_3d, pyplot, save_png, view_and_plan

__all__ = ["plot_gridshell", "DEGREE_COLOURS"]

DEGREE_COLOURS = {3: "#f4d35e", 4: "#ee964b", 5: "#f95738", 6: "#8fc93a", 7: "#3f88c5", 8: "#6a4c93"}


def plot_gridshell(polymesh: PolyMesh, path: Path, *, color_by: str = "degree", title: str = "") -> Path:
    """Axonometric view (left) and plan (right) of the cells; ``color_by`` "degree" (discrete
    legend, 8 = 8 or more sides) or "planarity" (largest node distance from the best-fit plane, mm)."""
    plt = pyplot()
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Patch
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    nodes = polymesh.nodes
    polygons = [nodes[f] for f in polymesh.faces]
    if color_by == "degree":
        colours = [DEGREE_COLOURS[min(max(len(f), 3), 8)] for f in polymesh.faces]
        legend = [Patch(color=c,
                        label=f"{d}{'+' if d == 8 else ''} sides: "
                              f"{int(np.sum(np.clip(polymesh.face_degrees, 3, 8) == d))}")
                  for d, c in DEGREE_COLOURS.items() if np.any(np.clip(polymesh.face_degrees, 3, 8) == d)]
        mappable = None
    elif color_by == "planarity":
        planarity_mm = 1000 * polymesh.face_planarity()
        norm = plt.Normalize(0.0, max(float(planarity_mm.max()), 1e-6))
        cmap = plt.get_cmap("plasma")
        colours = cmap(norm(planarity_mm))  # (cells, 4) RGBA, one call for every cell
        legend = None
        mappable = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
    else:
        raise ValueError(f"color_by must be 'degree' or 'planarity', got {color_by!r}")
    fig, ax3, ax, wide = view_and_plan(plt, nodes, size_in=(13, 6), plan_width_in=11.0)
    # autolim=False: matplotlib 3.11 pads cells of fewer sides with uninitialised memory and takes the
    # axis limits from the padding too (limits of +-1e308 at random, then "Axis limits cannot be NaN or
    # Inf"); frame_3d sets the limits from the nodes
    ax3.add_collection3d(Poly3DCollection(polygons, facecolors=colours, edgecolors="#222222", linewidths=0.4),
                         autolim=False)
    frame_3d(ax3, nodes)
    ax3.view_init(elev=32, azim=-60)
    ax3.set_axis_off()
    lo, span = nodes.min(axis=0), np.ptp(nodes, axis=0)
    ax.add_collection(PolyCollection([p[:, :2] for p in polygons], facecolors=colours, edgecolors="#222222",
                                     linewidths=0.4))
    supports = nodes[polymesh.supports]
    if len(supports):
        ax.scatter(supports[:, 0], supports[:, 1], marker="^", c="k", s=14, zorder=3, label="supports")
    ax.set_xlim(lo[0] - 0.03 * span[0], lo[0] + 1.03 * span[0])
    ax.set_ylim(lo[1] - 0.03 * span[1], lo[1] + 1.03 * span[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)"), ax.set_ylabel("y (m)")
    if legend:
        ax.legend(handles=legend, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    if mappable is not None:
        colour_bar(fig, mappable, ax, wide, label="planarity: largest distance to best-fit plane (mm)")
    fig.suptitle(title or f"grid-shell: {polymesh.n_nodes} nodes, {len(polymesh.edges)} beams, "
                          f"{polymesh.n_faces} cells")
    fig.tight_layout()
    return save_png(fig, path)
