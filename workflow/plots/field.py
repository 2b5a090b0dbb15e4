"""The guiding field: size map, anisotropy map with the direction of elongation."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from engine.mesh import TriMesh
from engine.remeshing.field import GuidingField

from ._common import colour_bar, is_wide_plan, plan_height_in, pyplot, save_png, spread_sample

__all__ = ["plot_field"]

MAX_TICKS = 900


def plot_field(mesh: TriMesh, field: GuidingField, path: Path, *, title: str = "") -> Path:
    """Two plan panels: relative cell size h, and anisotropy a with ticks along the direction u."""
    plt = pyplot()
    from matplotlib.collections import LineCollection
    from matplotlib.tri import Triangulation

    v = mesh.vertices
    tri = Triangulation(v[:, 0], v[:, 1], mesh.faces)
    wide = is_wide_plan(v)  # then one plan above the other, across the picture
    if wide:
        fig, axes = plt.subplots(2, 1, figsize=(13, 2 * plan_height_in(v, 11.0, labels_in=1.6)))
    else:
        fig, axes = plt.subplots(1, 2, figsize=(13, 5.8))
    bar = {"shrink": 0.4, "pad": 0.25} if wide else {}  # two plans stacked: shorter bars, closer
    size_plot = axes[0].tripcolor(tri, field.size / field.size.min(), shading="gouraud", cmap="viridis_r")
    colour_bar(fig, size_plot, axes[0], wide, label="cell size h / h_min", **bar)
    axes[0].set_title(f"size: h_max / h_min = {field.size.max() / field.size.min():.2f}")
    # magma_r without its darkest third: the dark ticks stayed visible over the most anisotropic parts
    import matplotlib
    from matplotlib.colors import ListedColormap

    lighter = ListedColormap(matplotlib.colormaps["magma_r"](np.linspace(0.0, 0.65, 256)), name="magma_r_light")
    aspect_plot = axes[1].tripcolor(tri, field.anisotropy, shading="gouraud", cmap=lighter,
                                    vmin=1.0, vmax=max(1.0 + 1e-6, float(field.anisotropy.max())))
    colour_bar(fig, aspect_plot, axes[1], wide, label="anisotropy a", **bar)
    for shading in (size_plot, aspect_plot):  # the layout would make a path of every triangle (9 s at 1.3 M)
        shading.set_in_layout(False)
    picked, spacing = spread_sample(v, MAX_TICKS, float(mesh.face_plan_areas.sum()))
    length = 0.4 * spacing
    offset = field.direction[picked, :2] * length
    centre = v[picked, :2]
    axes[1].add_collection(LineCollection(np.stack([centre - offset, centre + offset], axis=1),
                                          colors="#1d2330", linewidths=0.8))
    axes[1].set_title(f"anisotropy and direction: largest a = {field.anisotropy.max():.2f}")
    for ax in axes:
        for loop in mesh.boundary_loops:
            closed = np.r_[loop, loop[:1]]
            ax.plot(v[closed, 0], v[closed, 1], color="k", linewidth=0.8)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)"), ax.set_ylabel("y (m)")
    fig.suptitle(title or "guiding field")
    fig.tight_layout()
    return save_png(fig, path, dpi=150)
