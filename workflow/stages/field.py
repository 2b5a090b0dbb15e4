"""Stage ``field``: the statics-aware guiding field (size, anisotropy, direction per vertex).

Sizes are relative here (smallest = 1); the remesh stage scales them to its size target.
Artifacts (03-field/): field.npz (size, anisotropy, direction, normals), field.json
(achieved ratio and aspect against D and A) and field.png.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from engine.remeshing.field import GuidingField, guiding_field
from engine.structure.shell import ShellResult
from fabrication.files import atomic_path, write_text_atomic

from ..config import Project
from ..plots.field import plot_field
from ..runner import StageContext
from .surface import SurfaceResult

__all__ = ["run", "load", "save_field", "load_field"]


def run(surface: SurfaceResult, shell: ShellResult, project: Project, ctx: StageContext) -> GuidingField:
    mesh = surface.mesh
    ctx.step("stress to metric")
    field = guiding_field(mesh, shell.vertex_membrane_forces, project.field.to_settings())
    save_field(field, ctx.folder / "field.npz")
    summary = {"max_size_ratio_D": project.field.max_size_ratio, "max_aspect_A": project.field.max_aspect,
               "achieved_size_ratio": float(field.size.max() / field.size.min()),
               "achieved_max_aspect": float(field.anisotropy.max()),
               "mean_aspect": float(field.anisotropy.mean()),
               "size_map": project.field.size_map, "anisotropy_map": project.field.anisotropy_map,
               "symmetry_planes": len(project.field.symmetry_planes)}
    write_text_atomic(ctx.folder / "field.json", json.dumps(summary, indent=1))
    ctx.step("drawing")
    plot_field(mesh, field, ctx.folder / "field.png",
               title=f"{project.project.name}: guiding field Voro({project.field.max_size_ratio:g}, "
                     f"{project.field.max_aspect:g})")
    return field


def save_field(field: GuidingField, path: Path) -> None:
    """Write ``field`` as an npz file (size, anisotropy, direction, normals)."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, size=field.size, anisotropy=field.anisotropy,
                                direction=field.direction, normals=field.normals)


def load_field(path: Path) -> GuidingField:
    """A field written by save_field."""
    with np.load(path) as data:
        return GuidingField(size=data["size"], anisotropy=data["anisotropy"], direction=data["direction"],
                            normals=data["normals"])


def load(folder: Path, project: Project) -> GuidingField:
    return load_field(folder / "field.npz")
