"""Principal membrane force crosses over the surface (compression red, tension blue)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from engine.mesh import TriMesh

from ._common import plan_figure, pyplot, save_png, spread_sample

__all__ = ["plot_principal_forces"]

MAX_CROSSES = 1500
#: The bars' colours: a red and a blue that stay apart in print, on screen at report size and for
#: red-green colour blindness (the former navy tension, #1f4e9e, read as black beside the grey mesh).
COMPRESSION, TENSION = "#c0392b", "#1f78d1"


def plot_principal_forces(mesh: TriMesh, principal_forces: np.ndarray, principal_directions: np.ndarray,
                          path: Path, *, support_nodes: np.ndarray | None = None, title: str = "") -> Path:
    """Plan view with one cross per facet (thinned to about 1500, spread evenly over the plan): N1
    along its direction, N2 across it (in the facet plane), bar lengths proportional to |N| up to the
    98th percentile of |N| (longer bars are capped, so that a singular peak at a support does not
    shrink the rest); compression red, tension blue. principal_forces (m,2) N/m, principal_directions (m,3) of N1."""
    plt = pyplot()
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D

    v, f = mesh.vertices, mesh.faces
    centroids = mesh.face_centroids
    normals = mesh.face_normals
    picked, spacing = spread_sample(centroids, MAX_CROSSES, float(mesh.face_plan_areas.sum()))
    first = principal_directions[picked]
    second = np.cross(normals[picked], first)
    values = principal_forces[picked]
    peak = max(float(np.abs(principal_forces).max()), 1e-300)
    reference = max(float(np.percentile(np.abs(principal_forces[:, 0]), 98.0)), 1e-9 * peak)
    half = 0.45 * spacing * np.minimum(np.abs(values) / reference, 1.0)
    segments, colours = [], []
    for k, axis in enumerate((first, second)):
        offset = axis[:, :2] * half[:, k:k + 1]
        c = centroids[picked, :2]
        segments.append(np.stack([c - offset, c + offset], axis=1))
        colours.append(np.where(values[:, k] < 0, COMPRESSION, TENSION))
    fig, ax, wide = plan_figure(plt, v, (9, 8), labels_in=1.8)  # wide: the legend above, the note below
    ax.triplot(v[:, 0], v[:, 1], f, color=(0.6, 0.6, 0.6, 0.25), linewidth=0.3)
    ax.add_collection(LineCollection(np.concatenate(segments), colors=np.concatenate(colours), linewidths=1.1))
    for loop in mesh.boundary_loops:
        closed = np.r_[loop, loop[:1]]
        ax.plot(v[closed, 0], v[closed, 1], color="k", linewidth=1.0)
    if support_nodes is not None and len(support_nodes):
        s = v[np.asarray(support_nodes)]
        ax.scatter(s[:, 0], s[:, 1], marker="^", c="k", s=16, zorder=3)
    handles = [Line2D([], [], color=COMPRESSION, label="compression"), Line2D([], [], color=TENSION, label="tension"),
               Line2D([], [], color="k", marker="^", linestyle="", label="supports")]
    note = (f"largest |N| = {peak / 1e3:.3g} kN/m; full bar = {reference / 1e3:.3g} kN/m "
            f"(98th percentile), longer bars capped")
    ax.set_aspect("equal")
    ax.set_ylabel("y (m)")
    if wide:
        ax.legend(handles=handles, loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=3, fontsize=8, frameon=False)
        ax.set_xlabel(f"x (m)\n{note}", fontsize=9)
    else:
        ax.legend(handles=handles, loc="upper right", fontsize=8)
        ax.set_xlabel("x (m)")
        ax.text(0.01, 0.01, note, transform=ax.transAxes, fontsize=8)
    ax.set_title(title or "principal membrane forces", loc="left" if wide else "center")
    fig.tight_layout()
    return save_png(fig, path, dpi=150)
