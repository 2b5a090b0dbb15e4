"""The quick start on roofs as modellers and surveyors export them: one file per awkward case,
each run cold through every stage.

    .venv/bin/python benchmarks/awkward_exports.py [--cells 120] [--out out/awkward_exports]
        [--match NAME,...] [--timeout SECONDS]

Each case is a mesh file written into OUT/meshes by this script (seeded, so the same files every
time) and a ``gridshell run --surface FILE --cells N --out OUT/runs/NAME --quiet`` with the flags a
user of that file would give. A case either reaches report.html or is refused, as two are meant to
be, with an error message (exit 2, no traceback); the script prints one row per case (exit code,
seconds, report.html, and the first line of the error or of the cleaning notes) and exits 1 when a
case ends otherwise than expected.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _cli import run_gridshell, table_header, table_row  # noqa: E402


@dataclass
class Case:
    """A mesh file to write (``make(path)``), the flags a user would give with it, and whether the
    run is meant to be refused with a message (the text it must hold) rather than reach the report."""

    name: str
    suffix: str
    make: Callable[[Path], None]
    flags: list[str] = field(default_factory=list)
    refused: str | None = None


def _grid(nx: int, ny: int, lx: float, ly: float, height) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, triangles, quadrilaterals) of an nx x ny grid over lx x ly m centred on the origin."""
    x, y = np.meshgrid(np.linspace(-lx / 2, lx / 2, nx + 1), np.linspace(-ly / 2, ly / 2, ny + 1), indexing="ij")
    vertices = np.c_[x.ravel(), y.ravel(), height(x, y).ravel()]
    ids = np.arange(len(vertices)).reshape(nx + 1, ny + 1)
    a, b, c, d = ids[:-1, :-1].ravel(), ids[1:, :-1].ravel(), ids[1:, 1:].ravel(), ids[:-1, 1:].ravel()
    return vertices, np.r_[np.c_[a, b, c], np.c_[a, c, d]], np.c_[a, b, c, d]


def _dome(x, y):
    return 4.0 * (1 - 0.5 * ((x / 8) ** 2 + (y / 6) ** 2))


def _vault(x, y):
    return 3.0 * (1 - (2 * x / 16) ** 2)


def _save(vertices: np.ndarray, faces: np.ndarray, path: Path, **export) -> None:
    import trimesh

    trimesh.Trimesh(vertices, faces, process=False).export(path, **export)


def _site_coordinates(path: Path) -> None:  # a georeferenced model: survey metres
    v, t, _ = _grid(40, 30, 16, 12, _dome)
    _save(v + [512345.0, 5412345.0, 231.0], t, path)


def _unwelded_flipped(path: Path) -> None:  # an STL: no shared vertices, half the triangles wound back
    v, t, _ = _grid(40, 30, 16, 12, _dome)
    flip = np.random.default_rng(7).random(len(t)) < 0.5
    t = t.copy()
    t[flip] = t[flip][:, ::-1]
    _save(v[t].reshape(-1, 3), np.arange(3 * len(t)).reshape(-1, 3), path)


def _quads_y_up(path: Path) -> None:  # Blender's OBJ: faces of four, y up
    v, _, q = _grid(30, 20, 20, 12, _vault)
    lines = [f"v {p[0]:.6f} {p[2]:.6f} {-p[1]:.6f}" for p in v] + ["f " + " ".join(str(i + 1) for i in a) for a in q]
    path.write_text("\n".join(lines) + "\n")


def _two_triangles(path: Path) -> None:  # a hypar of two triangles
    _save(np.array([[0, 0, 0], [10, 0, 3], [10, 10, 0], [0, 10, 3.0]]), np.array([[0, 1, 2], [0, 2, 3]]), path)


def _fine(path: Path, divisions: int = 400) -> None:  # 2 x divisions^2 triangles, 320 000 by default
    v, t, _ = _grid(divisions, divisions, 20, 20, lambda x, y: 0.02 * (x * x - y * y) + 4)
    _save(v, t, path)


def _seams(path: Path) -> None:  # a roof meshed face by face: its seam divided 30 / 43 on its two sides
    left, t, _ = _grid(20, 30, 8, 12, _dome)
    right, u, _ = _grid(30, 43, 8, 12, _dome)
    vertices = np.r_[left + [-4, 0, 0], right + [4, 0, 0]]
    vertices[:, 2] = _dome(vertices[:, 0], vertices[:, 1])
    _save(vertices, np.r_[t, u + len(left)], path, file_type="obj")


def _open_seam(path: Path) -> None:  # two halves left unjoined at a modeller's tolerance: 0.5 mm apart
    half, t, _ = _grid(20, 30, 8, 12, _dome)
    vertices = np.r_[half + [-4, 0, 0], half + [4.0005, 0, 0]]
    vertices[:, 2] = _dome(vertices[:, 0], vertices[:, 1])
    _save(vertices, np.r_[t, t + len(half)], path)


def _stray(path: Path) -> None:  # a leftover triangle floating over the roof
    v, t, _ = _grid(40, 30, 16, 12, _dome)
    stray = np.array([[0, 0, 10.0], [0.1, 0, 10.0], [0, 0.1, 10.0]])
    _save(np.r_[v, stray], np.r_[t, len(v) + np.array([[0, 1, 2]])], path)


def _fin(path: Path) -> None:  # a pin hole and a triangle standing on an edge: not a sheet
    v, t, _ = _grid(40, 30, 16, 12, _dome)
    t = np.delete(t, [600, 601, 602], axis=0)
    edge = t[100, :2]
    _save(np.r_[v, (v[edge].mean(axis=0) + [0, 0, 0.5])[None]], np.r_[t, [[edge[0], edge[1], len(v)]]], path)


def _hemisphere(path: Path) -> None:  # its rim vertical
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=4, radius=8.0)
    half = trimesh.Trimesh(sphere.vertices, sphere.faces[sphere.triangles_center[:, 2] > 0])
    half.remove_unreferenced_vertices()
    half.export(path)


def _big_flat(path: Path) -> None:  # 120 x 80 m, rise 6 m
    v, t, _ = _grid(60, 40, 120, 80, lambda x, y: 6 * (1 - (x / 60) ** 2) * (1 - (y / 40) ** 2))
    _save(v, t, path)


def _l_shape_mm(path: Path) -> None:  # an L-shaped plan modelled in millimetres
    import trimesh

    v, t, _ = _grid(40, 40, 20, 20, lambda x, y: 2 + 0.01 * (100 - x * x) + 0.01 * (100 - y * y))
    centre = v[t].mean(axis=1)
    mesh = trimesh.Trimesh(v * 1000, t[~((centre[:, 0] > 0) & (centre[:, 1] > 0))])
    mesh.remove_unreferenced_vertices()
    mesh.export(path)


def _strips(path: Path) -> None:  # one row of slivers across the width, as a modeller meshes a NURBS
    v, t, _ = _grid(200, 1, 16, 12, _vault)
    _save(v, t, path)


def _obj_with_everything(path: Path) -> None:  # texture coordinates, normals, groups, materials
    v, t, _ = _grid(30, 20, 16, 12, _dome)
    lines = ["mtllib roof.mtl", "o Roof", "g part1"] + [f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}" for p in v]
    lines += [f"vt {p[0] / 16 + 0.5:.4f} {p[1] / 12 + 0.5:.4f}" for p in v] + ["vn 0 0 1", "usemtl glass", "s off"]
    for k, a in enumerate(t):
        lines += ["g part2"] if k == len(t) // 2 else []
        lines.append("f " + " ".join(f"{i + 1}/{i + 1}/1" for i in a))
    path.write_text("\n".join(lines) + "\n")


def _binary_ply(path: Path) -> None:
    v, t, _ = _grid(30, 20, 16, 12, _dome)
    _save(v, t, path, encoding="binary")


def _ascii_stl(path: Path) -> None:
    import trimesh

    v, t, _ = _grid(30, 20, 16, 12, _dome)
    path.write_text(trimesh.exchange.stl.export_stl_ascii(trimesh.Trimesh(v, t, process=False)))


def _bowl(path: Path) -> None:  # hanging from its rim
    v, t, _ = _grid(30, 20, 16, 12, lambda x, y: 4.0 - _dome(x, y))
    _save(v, t, path)


def _model(path: Path) -> None:  # a 0.5 m model
    v, t, _ = _grid(30, 20, 0.5, 0.4, lambda x, y: 0.08 * (1 - (x / 0.25) ** 2))
    _save(v, t, path)


def _feet(path: Path) -> None:  # 60 x 40 ft
    v, t, _ = _grid(30, 20, 60, 40, lambda x, y: 12 * (1 - (x / 30) ** 2 * 0.5 - (y / 20) ** 2 * 0.5))
    _save(v, t, path)


def _rhino(path: Path, unit: str = "Feet", per_metre: float = 1 / 0.3048) -> None:
    import rhino3dm

    v, t, _ = _grid(30, 20, 16, 12, _dome)
    model = rhino3dm.File3dm()
    model.Settings.ModelUnitSystem = getattr(rhino3dm.UnitSystem, unit)
    mesh = rhino3dm.Mesh()
    for x, y, z in v * per_metre:
        mesh.Vertices.Add(float(x), float(y), float(z))
    for a, b, c in t:
        mesh.Faces.AddFace(int(a), int(b), int(c))
    model.Objects.AddMesh(mesh)
    model.Write(str(path), 7)


def _canopy(path: Path) -> None:  # 50 x 5 m
    v, t, _ = _grid(100, 10, 50, 5, lambda x, y: 4 + 1.2 * (1 - (2 * y / 5) ** 2))
    _save(v, t, path)


def _neck(path: Path) -> None:  # two domes joined by a 1 m strip
    import trimesh

    v, t, _ = _grid(120, 50, 24, 10, lambda x, y: 3 * np.exp(-((np.abs(x) - 6) ** 2 + y ** 2) / 30))
    c = v[t].mean(axis=1)
    inside = (np.hypot(np.abs(c[:, 0]) - 6, c[:, 1]) < 4.8) | ((np.abs(c[:, 0]) < 6) & (np.abs(c[:, 1]) < 0.5))
    mesh = trimesh.Trimesh(v, t[inside])
    mesh.remove_unreferenced_vertices()
    mesh.export(path)


def _negative_indices(path: Path) -> None:  # quadrilaterals with relative (negative) indices
    v, _, q = _grid(20, 14, 16, 12, _dome)
    lines = []
    for a in q:
        lines += [f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}" for p in v[a]] + ["f -4 -3 -2 -1"]
    path.write_text("\n".join(lines) + "\n")


def _flat(path: Path) -> None:  # 30 x 20 m, rise 0.3 m
    v, t, _ = _grid(60, 40, 30, 20, lambda x, y: 0.3 * (1 - (x / 15) ** 2) * (1 - (y / 10) ** 2))
    _save(v, t, path)


def _folded(path: Path) -> None:  # a V ridge with a sharp crease
    v, t, _ = _grid(40, 40, 16, 16, lambda x, y: 4 - 0.4 * np.abs(y))
    _save(v, t, path)


CASES = [
    Case("site_coordinates", ".ply", _site_coordinates),
    Case("unwelded_flipped", ".stl", _unwelded_flipped),
    Case("quads_y_up", ".obj", _quads_y_up, ["--surface-up", "y"]),
    Case("two_triangles", ".ply", _two_triangles),
    Case("fine_320k", ".ply", _fine),
    Case("scan_1280k", ".ply", lambda p: _fine(p, 800)),
    Case("stray_triangle", ".ply", _stray),
    Case("seams_t_junctions", ".obj", _seams),
    Case("seam_open_0_5mm", ".ply", _open_seam),
    Case("non_manifold_fin", ".ply", _fin, refused="non-manifold edge"),
    Case("hemisphere", ".ply", _hemisphere),
    Case("big_flat", ".ply", _big_flat),
    Case("l_shape_mm", ".obj", _l_shape_mm, ["--surface-units", "mm"]),
    Case("sliver_strips", ".ply", _strips),
    Case("obj_vt_vn_groups", ".obj", _obj_with_everything),
    Case("binary", ".ply", _binary_ply),
    Case("ascii", ".stl", _ascii_stl),
    Case("bowl", ".ply", _bowl),
    Case("model_0_5m", ".ply", _model),
    Case("feet", ".obj", _feet, ["--surface-units", "ft"]),
    Case("rhino_feet", ".3dm", _rhino),
    Case("rhino_units_wrong", ".3dm", lambda p: _rhino(p, "Millimeters", 1.0), refused="the .3dm file's own units"),
    Case("canopy_50x5", ".ply", _canopy),
    Case("two_domes_neck", ".ply", _neck),
    Case("negative_indices", ".obj", _negative_indices),
    Case("nearly_flat", ".ply", _flat),
    Case("folded_plate", ".ply", _folded),
]


def run_case(case: Case, out: Path, cells: int, timeout: float) -> dict:
    """Write the case's file, run the quick start on it, and say how it ended."""
    path = out / "meshes" / f"{case.name}{case.suffix}"
    path.parent.mkdir(parents=True, exist_ok=True)
    case.make(path)
    run_dir = out / "runs" / case.name
    ended = run_gridshell(["run", "--surface", str(path), *case.flags, "--cells", str(cells), "--out", str(run_dir),
                           "--quiet", "--force"], run_dir, timeout)
    notes = ""
    if (run_dir / "01-surface" / "surface.json").is_file():
        notes = "; ".join(json.loads((run_dir / "01-surface" / "surface.json").read_text()).get(
            "cleaning", {}).get("notes", []))
    expected = ended.report if case.refused is None else ended.refused_with(case.refused)
    return {"name": case.name, "exit": ended.code, "seconds": round(ended.seconds, 1), "report": ended.report,
            "expected": expected, "said": ended.error(120) if ended.code else notes}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=120)
    parser.add_argument("--out", type=Path, default=Path("out/awkward_exports"))
    parser.add_argument("--match", default="", help="only the cases whose name holds one of these (comma-separated)")
    parser.add_argument("--timeout", type=float, default=1200.0, help="seconds per run")
    args = parser.parse_args()
    wanted = [m for m in args.match.split(",") if m]
    cases = [c for c in CASES if not wanted or any(m in c.name for m in wanted)]
    print(f"awkward_exports: {len(cases)} files, the quick start at {args.cells} cells, into {args.out}")
    print(table_header(20))
    rows = []
    for case in cases:
        row = run_case(case, args.out, args.cells, args.timeout)
        rows.append(row)
        print(table_row(row, 20, 110), flush=True)
    met = sum(r["expected"] for r in rows)
    print(f"{met} of {len(rows)} ended as meant (the report, or a refusal with its message)")
    return 0 if met == len(rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
