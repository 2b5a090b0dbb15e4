"""Polygon OBJ for grid-shells (one face per cell as its node loop), read back by Rhino and trimesh.

Node flags (boundary, support, corner) travel in a JSON side-car so the OBJ stays plain.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from engine.mesh import PolyMesh
from fabrication.files import atomic_path

__all__ = ["write_polymesh_obj", "read_polymesh_obj"]


def write_polymesh_obj(polymesh: PolyMesh, path: Path, *, header: str = "gridshell grid-shell") -> Path:
    """Write ``path`` (.obj, metres) and ``path`` with suffix .nodes.json (node flags)."""
    lines = [f"# {header}", "# units: m; one face per cell (node loop); beams are the face edges",
             f"# nodes {polymesh.n_nodes} cells {polymesh.n_faces} beams {len(polymesh.edges)}"]
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in polymesh.nodes.tolist()]  # exact: a reload gives the same grid
    lines += ["f " + " ".join(str(i + 1) for i in face.tolist()) for face in polymesh.faces]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n", encoding="ascii")
    flags = {name: np.flatnonzero(getattr(polymesh, name)).tolist() for name in ("boundary", "supports", "corners")}
    with atomic_path(Path(path).with_suffix(".nodes.json")) as tmp:
        tmp.write_text(json.dumps(flags), encoding="ascii")
    return Path(path)


def read_polymesh_obj(path: Path) -> PolyMesh:
    """Read a polygon OBJ written by ``write_polymesh_obj`` (flags from its side-car if present)."""
    nodes, faces = [], []
    for line in Path(path).read_text(encoding="ascii").splitlines():
        if line.startswith("v "):
            nodes.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            faces.append(np.array([int(tok.split("/")[0]) - 1 for tok in line.split()[1:]], dtype=np.int64))
    n = len(nodes)
    masks = {}
    side = Path(path).with_suffix(".nodes.json")
    if side.is_file():
        data = json.loads(side.read_text())
        for name in ("boundary", "supports", "corners"):
            mask = np.zeros(n, dtype=bool)
            mask[np.asarray(data.get(name, []), dtype=np.int64)] = True
            masks[name] = mask
    return PolyMesh(nodes=np.array(nodes), faces=tuple(faces), **masks)
