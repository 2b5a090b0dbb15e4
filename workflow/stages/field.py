"""Stage ``field``: the statics-aware guiding field (size, anisotropy, direction per vertex).

Sizes are relative here (smallest = 1); the remesh stage scales them to its size target.
Artifacts (03-field/): field.npz (size, anisotropy, direction, normals), field.json
(achieved ratio and aspect against D and A) and field.png.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from engine.errors import InputError
from engine.mesh import TriMesh
from engine.remeshing.field import GuidingField, guiding_field
from engine.structure.shell import ShellResult
from fabrication.files import atomic_path, write_text_atomic

from ..config import Project
from ..plots.field import plot_field
from ..runner import StageContext
from .surface import SurfaceResult

__all__ = ["run", "load", "save_field", "load_field", "check_symmetry_planes"]


#: A surface is taken for symmetric about a [field] symmetry plane while its vertices' mirror images
#: lie within this share of its size across (the diagonal of its box), plus two of its median
#: edges (a symmetric surface meshed otherwise), of a vertex.
SYMMETRY_GAP_SHARE = 0.02


def check_symmetry_planes(mesh: TriMesh, project: Project) -> None:
    """Raise InputError, naming [field] symmetry_planes and a plane that would do, where the surface
    is not symmetric about one of them (a plane through the origin of a roof modelled elsewhere,
    or on a roof that has none): the field would be averaged with unrelated points, and the grid
    made without symmetry, without a word."""
    from engine.geometry.symmetry import mirror_gap

    planes = project.field.to_settings().symmetry_planes
    if not planes:
        return
    edge = float(np.median(mesh.edge_lengths))
    low, high = mesh.bounds
    allowed = SYMMETRY_GAP_SHARE * float(np.linalg.norm(high - low)) + 2.0 * edge
    centre = 0.5 * (low + high)
    for index, (point, normal) in enumerate(planes):
        gap = mirror_gap(mesh.vertices, (point, normal))
        if gap <= allowed:
            continue
        there = mirror_gap(mesh.vertices, (centre, normal))
        where = ", ".join(f"{c:.6g}" for c in point)
        hint = (f"point = [{', '.join(f'{c:.3f}' for c in centre)}], the centre of the surface's box, where it is "
                f"symmetric within {there:.3g} m" if there <= allowed else
                "the surface is not symmetric about a plane of that normal through its centre either: remove the plane")
        raise InputError(f"[field] symmetry_planes[{index}]: the surface is not symmetric about the plane through "
                         f"[{where}] m with normal {list(map(float, normal))}: a vertex's mirror image lies "
                         f"{gap:.3g} m from the surface's nearest vertex (at most {allowed:.3g} m taken for symmetric)",
                         hint=hint)


def run(surface: SurfaceResult, shell: ShellResult, project: Project, ctx: StageContext) -> GuidingField:
    mesh = surface.mesh
    check_symmetry_planes(mesh, project)
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
