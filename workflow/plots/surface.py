"""Picture of the input surface with its supports: a 3D view and a plan."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from engine.mesh import TriMesh

from ._common import frame_3d, save_png, view_and_plan

__all__ = ["plot_surface"]


def plot_surface(mesh: TriMesh, support_nodes: np.ndarray, path: Path, *, title: str = "") -> Path:
    """Write a PNG: shaded 3D view (left) and plan with boundary loops and supports (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.tri import Triangulation

    v, f = mesh.vertices, mesh.faces
    fig, ax3, ax, wide = view_and_plan(plt, v, size_in=(12, 5.5), plan_width_in=10.0, dpi=110)
    ax3.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=f, cmap="Greys", linewidth=0.1,
                     edgecolor=(0.3, 0.3, 0.3, 0.3), alpha=0.9, shade=True)
    s = v[support_nodes]
    ax3.scatter(s[:, 0], s[:, 1], s[:, 2], c="crimson", s=8, depthshade=False, label="supports")
    frame_3d(ax3, v)
    if wide:  # the plan below gives the scale; the short axes' ticks ran together
        ax3.set_axis_off()
    else:
        ax3.set_xlabel("x (m)"), ax3.set_ylabel("y (m)"), ax3.set_zlabel("z (m)")
        ax3.legend(loc="upper left")

    tri = Triangulation(v[:, 0], v[:, 1], f)
    contour = ax.tricontourf(tri, v[:, 2], levels=14, cmap="viridis")
    ax.triplot(tri, color=(1, 1, 1, 0.25), linewidth=0.3)
    for loop in mesh.boundary_loops:
        closed = np.r_[loop, loop[:1]]
        ax.plot(v[closed, 0], v[closed, 1], color="k", linewidth=1.2)
    ax.scatter(s[:, 0], s[:, 1], c="crimson", s=14, zorder=3, label=f"{len(support_nodes)} supported nodes")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)"), ax.set_ylabel("y (m)")
    fig.colorbar(contour, ax=ax, label="height z (m)", shrink=0.8, fraction=0.03 if wide else 0.15)
    if wide:  # below the plan, not over its narrow depth
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.45), fontsize=8, frameon=False)
    else:
        ax.legend(loc="upper right", fontsize=8)
    ax.set_title("plan: height and supports")
    fig.suptitle(title or f"{mesh.name}: {mesh.n_vertices} vertices, {mesh.n_faces} triangles, "
                 f"{len(mesh.boundary_loops)} boundary loop(s)")
    # room between the two: tight_layout leaves out the 3D view's z label, which then ran into the
    # plan's y label on plans wider than deep (the courtyard template)
    fig.tight_layout(w_pad=5.0, h_pad=1.0)
    return save_png(fig, path, dpi=110)
