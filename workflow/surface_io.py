"""Reading and writing surface meshes: OBJ, PLY, STL, OFF (trimesh) and Rhino .3dm (rhino3dm).

Readers return raw arrays; ``engine.geometry.surfaces.clean_mesh`` does the cleaning and checking.
The red vertices (255, 0, 0) of a PLY are returned as support flags.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from engine.errors import InputError
from engine.mesh import TriMesh
from fabrication.files import atomic_path

__all__ = ["SURFACE_SUFFIXES", "FILE_UNITS_M", "read_surface", "read_surface_with_unit", "file_scale_m",
           "write_surface_ply"]

SURFACE_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".3dm")
#: Metres per unit of a mesh file's numbers, by [surface] file_units (--surface-units).
FILE_UNITS_M = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048}
#: Rhino's model unit systems (rhino3dm.UnitSystem's values): name and metres per unit. A .3dm in
#: none of them (no unit system, custom units) is read as its numbers, in [surface] file_units.
RHINO_UNITS = {1: ("microns", 1e-6), 2: ("mm", 1e-3), 3: ("cm", 1e-2), 4: ("m", 1.0), 5: ("km", 1e3),
               6: ("microinches", 2.54e-8), 7: ("mils", 2.54e-5), 8: ("in", 0.0254), 9: ("ft", 0.3048),
               10: ("miles", 1609.344), 12: ("angstroms", 1e-10), 13: ("nm", 1e-9), 14: ("dm", 0.1),
               15: ("dam", 10.0), 16: ("hm", 100.0), 19: ("yd", 0.9144)}


def _red_flags(mesh, n_vertices: int) -> np.ndarray:
    """Support flags from vertex colours: pure red (255, 0, 0) vertices."""
    raw = (getattr(mesh, "metadata", None) or {}).get("_ply_raw")
    if raw and "vertex" in raw:
        data = raw["vertex"]["data"]
        names = data.keys() if isinstance(data, dict) else (data.dtype.names or ())
        if {"red", "green", "blue"} <= set(names):
            rgb = np.stack([np.asarray(data[c]).ravel() for c in ("red", "green", "blue")], axis=1)
            if len(rgb) == n_vertices:
                return (rgb[:, 0] == 255) & (rgb[:, 1] == 0) & (rgb[:, 2] == 0)
    colours = getattr(getattr(mesh, "visual", None), "vertex_colors", None)
    if getattr(mesh.visual, "kind", None) == "vertex" and colours is not None and len(colours) == n_vertices:
        return (colours[:, 0] == 255) & (colours[:, 1] == 0) & (colours[:, 2] == 0)
    return np.zeros(n_vertices, dtype=bool)


def _read_3dm(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, str | None]:
    """(vertices, faces, flags, the file's unit): vertices in metres where the file states a unit
    (RHINO_UNITS), else as written and the unit None."""
    import rhino3dm

    model = rhino3dm.File3dm.Read(str(path))
    if model is None:
        raise InputError(f"{path}: not a readable Rhino .3dm file", hint="save it again from Rhino 6 or later")
    vertices: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    offset = 0
    skipped: list[str] = []
    for obj in model.Objects:
        geometry = obj.Geometry
        if not isinstance(geometry, rhino3dm.Mesh):
            skipped.append(type(geometry).__name__)
            continue
        v = np.array([[p.X, p.Y, p.Z] for p in geometry.Vertices], dtype=float)
        tris = []
        for i in range(len(geometry.Faces)):
            a, b, c, d = geometry.Faces[i]
            tris.append((a, b, c))
            if d != c:
                tris.append((a, c, d))
        vertices.append(v)
        faces.append(np.array(tris, dtype=np.int64) + offset)
        offset += len(v)
    if not vertices:
        what = f" (it holds {', '.join(sorted(set(skipped)))})" if skipped else ""
        raise InputError(f"{path}: no mesh object in the .3dm file{what}",
                         hint="in Rhino, mesh the surface (_Mesh) and save the mesh")
    unit, scale = RHINO_UNITS.get(int(model.Settings.ModelUnitSystem), (None, 1.0))
    v_all = np.concatenate(vertices) * scale
    return v_all, np.concatenate(faces), np.zeros(len(v_all), dtype=bool), unit


def file_scale_m(stated: str | None, file_units: str) -> float:
    """Metres per unit of the vertices read_surface_with_unit gives: 1 where the file stated its
    unit (they are in metres already), else those of ``file_units``."""
    return 1.0 if stated else FILE_UNITS_M[file_units]


def read_surface(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (n,3), faces (m,3), flagged (n,) bool) of a mesh file: see read_surface_with_unit."""
    return read_surface_with_unit(path)[:3]


def read_surface_with_unit(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, str | None]:
    """(vertices (n,3), faces (m,3), flagged (n,) bool, unit) of a mesh file. ``unit`` is the unit
    the file states (a Rhino .3dm's model units), its vertices then in metres; None for formats
    that state none (OBJ, PLY, STL, OFF), whose vertices are as written ([surface] file_units says
    in what).

    Raises ``InputError`` for a missing file, an unknown suffix or an unreadable file.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"surface file {path} does not exist", hint="check the path (relative paths are "
                         "relative to the project file)")
    suffix = path.suffix.lower()
    if suffix not in SURFACE_SUFFIXES:
        raise InputError(f"surface file {path}: unknown format {suffix!r}; allowed: {', '.join(SURFACE_SUFFIXES)}")
    if suffix == ".3dm":
        return _read_3dm(path)
    import trimesh

    try:
        loaded = trimesh.load(str(path), process=False, force="mesh")
    except Exception as exc:  # trimesh raises many kinds for corrupt files
        raise InputError(f"surface file {path} could not be read: {exc}",
                         hint="re-export it as a triangle mesh (OBJ, PLY, STL or OFF)") from exc
    vertices = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=float)
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), dtype=np.int64)
    if len(vertices) == 0 or len(faces) == 0:
        raise InputError(f"surface file {path} holds no triangles",
                         hint="export the surface as a mesh, not as points or curves")
    return vertices, faces, _red_flags(loaded, len(vertices)), None


def write_surface_ply(mesh: TriMesh, path: str | Path) -> Path:
    """Write an ASCII PLY with the support flags as red vertices (others white), atomically."""
    colours = np.full((mesh.n_vertices, 4), 255, dtype=np.uint8)
    colours[mesh.flagged, 1:3] = 0
    header = "\n".join([
        "ply", "format ascii 1.0", "comment gridshell surface, metres; red vertices are flagged supports",
        f"element vertex {mesh.n_vertices}", "property double x", "property double y", "property double z",
        "property uchar red", "property uchar green", "property uchar blue", "property uchar alpha",
        f"element face {mesh.n_faces}", "property list uchar int vertex_indices", "end_header"])
    vertex_lines = [f"{x!r} {y!r} {z!r} {r} {g} {b} {a}"  # exact: a reload gives the same mesh
                    for (x, y, z), (r, g, b, a) in zip(mesh.vertices.tolist(), colours.tolist())]
    face_lines = [f"3 {a} {b} {c}" for a, b, c in mesh.faces.tolist()]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join([header, *vertex_lines, *face_lines]) + "\n", encoding="ascii")
    return Path(path)
