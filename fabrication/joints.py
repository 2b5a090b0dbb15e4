"""Joint solids, one per node, built with build123d (mm).

Socket joint (3D printing): a cylindrical hub along the node axis (surface normal) with the
node id engraved on its top face, one sleeve per beam (bore = beam size + 2 clearance, a wall
around it, a pin hole across it); the bore starts at the set-back where neighbouring bores keep
the least wall. Steel joint (full size): a hub tube along the node axis with one fin plate per
beam, in the plane of the beam and the axis, with a bolt hole. Files: joints/J0001.step (the
solid named J0001), joints/J0001.stl (watertight), joints/joints.step (all, named).
"""

from __future__ import annotations

import os
import tempfile
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from engine.mesh import PolyMesh

from .files import atomic_path

__all__ = ["JointSettings", "JointGeometry", "joint_geometry", "joint_setback_mm", "build_joint", "build_joints",
           "joint_name"]


@dataclass(frozen=True, kw_only=True)
class JointSettings:
    """Dimensions in mm. hub_radius_mm / sleeve_length_mm None: derived from the beam size."""

    kind: str = "socket"
    clearance_mm: float = 0.3
    wall_mm: float = 2.0
    min_wall_mm: float = 1.5
    pin_hole_mm: float = 3.0
    engrave: bool = True
    hub_radius_mm: float | None = None
    sleeve_length_mm: float | None = None
    plate_thickness_mm: float = 10.0
    bolt_hole_mm: float = 18.0


@dataclass(frozen=True, kw_only=True)
class JointGeometry:
    """What a joint needs, in mm and unit vectors: position, beam directions (k,3), axis (3,)."""

    node: int
    position_mm: np.ndarray
    directions: np.ndarray
    axis: np.ndarray
    beam_size_mm: float


def joint_name(node: int) -> str:
    return f"J{node + 1:04d}"


def _smallest_angle(directions: np.ndarray) -> float:
    if len(directions) < 2:
        return np.pi
    cosine = np.clip(directions @ directions.T, -1.0, 1.0)
    np.fill_diagonal(cosine, -1.0)
    return float(np.arccos(cosine.max()))


def joint_setback_mm(settings: JointSettings, beam_size_mm: float, smallest_angle_rad: float = 2 * np.pi / 3) -> float:
    """Distance from the node to where a beam ends in its sleeve (the bore's start), mm: far enough
    that two bores at the smallest angle keep the least wall between them, and outside the hub."""
    bore = 0.5 * beam_size_mm + settings.clearance_mm
    if settings.kind == "steel":
        return (settings.hub_radius_mm or 1.2 * beam_size_mm) + 5.0
    half = max(np.sin(0.5 * smallest_angle_rad), 0.05)
    setback = (2 * bore + settings.min_wall_mm) / (2 * half)
    hub = settings.hub_radius_mm or (bore + settings.wall_mm) * 1.5
    return float(max(setback, 0.8 * hub))


def joint_geometry(polymesh: PolyMesh, normals: np.ndarray, beam_size_mm: float) -> list[JointGeometry]:
    """Per node: its beam directions and axis (mm positions)."""
    edges = polymesh.edges
    out = []
    incident: list[list[int]] = [[] for _ in range(polymesh.n_nodes)]
    for b, (i, j) in enumerate(edges):
        incident[i].append(j)
        incident[j].append(i)
    for node in range(polymesh.n_nodes):
        if not incident[node]:
            continue
        others = np.array(incident[node], dtype=int)
        d = polymesh.nodes[others] - polymesh.nodes[node]
        d /= np.linalg.norm(d, axis=1)[:, None]
        out.append(JointGeometry(node=node, position_mm=1000 * polymesh.nodes[node], directions=d,
                                 axis=np.asarray(normals[node], float) / np.linalg.norm(normals[node]),
                                 beam_size_mm=beam_size_mm))
    return out


def _plane(origin, z_dir, x_dir=None):
    from build123d import Plane

    if x_dir is None:
        return Plane(origin=tuple(map(float, origin)), z_dir=tuple(map(float, z_dir)))
    return Plane(origin=tuple(map(float, origin)), x_dir=tuple(map(float, x_dir)), z_dir=tuple(map(float, z_dir)))


def _perpendicular(direction: np.ndarray, axis: np.ndarray) -> np.ndarray:
    side = np.cross(axis, direction)
    if np.linalg.norm(side) < 1e-6:
        side = np.cross([1.0, 0.0, 0.0] if abs(direction[0]) < 0.9 else [0.0, 1.0, 0.0], direction)
    return side / np.linalg.norm(side)


def build_joint(geometry: JointGeometry, settings: JointSettings):
    """(solid, report) of one joint, built at the origin (mm); the caller places it."""
    from build123d import Align, Cylinder, Location, Text, extrude

    name = joint_name(geometry.node)
    directions, axis = geometry.directions, geometry.axis
    size = geometry.beam_size_mm
    bore = 0.5 * size + settings.clearance_mm
    outer = bore + settings.wall_mm
    angle = _smallest_angle(directions)
    setback = joint_setback_mm(settings, size, angle)
    sleeve = settings.sleeve_length_mm or 2.0 * size
    report = {"id": name, "node": geometry.node, "beams": int(len(directions)), "setback_mm": setback,
              "smallest_angle_deg": float(np.degrees(angle))}
    base = Align.CENTER, Align.CENTER, Align.MIN
    if settings.kind == "steel":
        hub_radius = settings.hub_radius_mm or 1.2 * size
        height = 2.5 * size
        solid = Cylinder(hub_radius, height).moved(Location(_plane((0, 0, 0), axis)))
        for d in directions:
            side = _perpendicular(d, axis)
            normal_of_plate = side
            length = setback + sleeve
            from build123d import Box

            plate = Box(length, settings.plate_thickness_mm, 0.8 * height, align=(Align.MIN, Align.CENTER, Align.CENTER))
            x_dir = d
            plate = plate.moved(Location(_plane((0, 0, 0), np.cross(x_dir, normal_of_plate), x_dir)))
            hole = Cylinder(0.5 * settings.bolt_hole_mm, 3 * settings.plate_thickness_mm)
            hole = hole.moved(Location(_plane(d * (setback + 0.5 * sleeve), normal_of_plate)))
            solid = solid + plate - hole
        report["min_wall_mm"] = float(settings.plate_thickness_mm)
    else:
        hub_radius = settings.hub_radius_mm or 1.5 * outer
        hub_height = 2.0 * outer + 1.0  # taller than a sleeve: no tangent faces between hub top and sleeves
        hub = Cylinder(hub_radius, hub_height).moved(Location(_plane((0, 0, 0), axis)))
        sleeves = [Cylinder(outer, setback + sleeve, align=base).moved(Location(_plane((0, 0, 0), d)))
                   for d in directions]
        tools = []
        for d in directions:
            side = _perpendicular(d, axis)
            tools.append(Cylinder(bore, sleeve + 1.0, align=base).moved(Location(_plane(d * setback, d))))
            pin_centre = d * (setback + 0.6 * sleeve)
            tools.append(Cylinder(0.5 * settings.pin_hole_mm, 4 * outer).moved(Location(_plane(pin_centre, side))))
        if settings.engrave:
            try:
                label = Text(name, font_size=0.45 * hub_radius, align=(Align.CENTER, Align.CENTER))
                tools.append(extrude(label, amount=0.6).moved(Location(_plane(axis * (0.5 * hub_height - 0.6), axis))))
                report["engraved"] = True
            except Exception:  # noqa: BLE001 - a font problem must not stop the joints
                report["engraved"] = False
        # one fuse and one cut with all tools: faster than a boolean per feature
        solid = hub.fuse(*sleeves).cut(*tools)
        # wall left between neighbouring bores at their start
        wall_between = 2 * setback * np.sin(0.5 * angle) - 2 * bore if len(directions) > 1 else settings.wall_mm
        report["min_wall_mm"] = float(min(settings.wall_mm, wall_between))
    report["clashes"] = _clashes(directions, outer, setback, sleeve)
    return solid, report


def _clashes(directions: np.ndarray, outer: float, setback: float, sleeve: float) -> list[list]:
    """Pairs of sleeves that overlap beyond their bores' start (the angle is too small for the sleeve)."""
    out = []
    for i in range(len(directions)):
        for j in range(i + 1, len(directions)):
            angle = float(np.arccos(np.clip(directions[i] @ directions[j], -1, 1)))
            # two sleeves of radius R overlap up to a distance R / tan(angle / 2) from the node
            reach = outer / max(np.tan(0.5 * angle), 1e-9)
            if reach > setback + 0.5 * sleeve:
                out.append([i, j, float(np.degrees(angle))])
    return out


def _axis_errors_deg(solid, directions: np.ndarray, bore_radius: float) -> float:
    """Largest angle (degrees) between each bore's cylinder axis in the solid and its beam."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.GeomAbs import GeomAbs_Cylinder

    axes = []
    for face in solid.faces():
        surface = BRepAdaptor_Surface(face.wrapped)
        if surface.GetType() == GeomAbs_Cylinder:
            cylinder = surface.Cylinder()
            if abs(cylinder.Radius() - bore_radius) < 1e-6:
                d = cylinder.Axis().Direction()
                axes.append([d.X(), d.Y(), d.Z()])
    if not axes:
        return float("nan")
    axes = np.array(axes)
    worst = 0.0
    for d in directions:
        cosine = np.abs(axes @ d).max()
        worst = max(worst, float(np.degrees(np.arccos(np.clip(cosine, -1, 1)))))
    return worst


def _watertight_stl(solid, path: Path) -> bool:
    """Tessellate, weld and write an STL; True when trimesh finds it watertight."""
    import trimesh

    vertices, triangles = solid.tessellate(0.05, 0.3)
    mesh = trimesh.Trimesh(np.array([tuple(v) for v in vertices]), np.array(triangles), process=True)
    mesh.merge_vertices(digits_vertex=5)
    mesh.update_faces(mesh.nondegenerate_faces())
    if not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
    trimesh.repair.fix_normals(mesh)
    with atomic_path(path) as tmp:
        mesh.export(tmp, file_type="stl")
    return bool(mesh.is_watertight)


def _build_and_write(job: tuple[JointGeometry, JointSettings, str, str]) -> dict:
    geometry, settings, folder, brep_folder = job
    from build123d import Location, export_brep, export_step

    solid, report = build_joint(geometry, settings)
    bore = 0.5 * geometry.beam_size_mm + settings.clearance_mm
    report["max_axis_error_deg"] = _axis_errors_deg(solid, geometry.directions, bore) if settings.kind == "socket" else 0.0
    report["single_solid"] = len(solid.solids()) == 1
    report["valid"] = bool(solid.is_valid)
    placed = solid.moved(Location(tuple(map(float, geometry.position_mm))))
    placed.label = report["id"]
    folder = Path(folder)
    with atomic_path(folder / f"{report['id']}.step") as tmp:
        export_step(placed, str(tmp))
    report["watertight"] = _watertight_stl(placed, folder / f"{report['id']}.stl")
    export_brep(placed, str(Path(brep_folder) / f"{report['id']}.brep"))
    error = report["max_axis_error_deg"]
    report["wall_ok"] = report["min_wall_mm"] >= settings.min_wall_mm - 1e-9
    report["ok"] = bool(report["valid"] and report["single_solid"] and report["watertight"] and report["wall_ok"]
                        and not report["clashes"] and (np.isnan(error) or error <= 0.1))
    return report


def build_joints(polymesh: PolyMesh, normals: np.ndarray, beam_size_mm: float, settings: JointSettings, folder: Path,
                 *, workers: int | None = None, progress=None) -> list[dict]:
    """Build, check and write every joint (see the module docstring); returns one report per joint."""
    from build123d import Compound, export_step, import_brep

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    geometries = joint_geometry(polymesh, normals, beam_size_mm)
    workers = workers or os.cpu_count() or 1
    reports: list[dict] = []
    with tempfile.TemporaryDirectory(dir=folder.parent) as brep_folder:
        jobs = [(g, settings, str(folder), brep_folder) for g in geometries]
        if workers > 1 and len(jobs) > 4:
            with ProcessPoolExecutor(max_workers=workers) as pool:
                for i, report in enumerate(pool.map(_build_and_write, jobs, chunksize=4)):
                    reports.append(report)
                    if progress is not None and i % 10 == 0:
                        progress(f"joints {i + 1}/{len(jobs)}", (i + 1) / len(jobs))
        else:
            for i, job in enumerate(jobs):
                reports.append(_build_and_write(job))
                if progress is not None:
                    progress(f"joints {i + 1}/{len(jobs)}", (i + 1) / len(jobs))
        solids = []
        for report in reports:
            solid = import_brep(str(Path(brep_folder) / f"{report['id']}.brep"))
            solid.label = report["id"]
            solids.append(solid)
        assembly = Compound(children=solids)
        assembly.label = "joints"
        with atomic_path(folder / "joints.step") as tmp:
            export_step(assembly, str(tmp))
    return [{k: v for k, v in r.items()} for r in reports]


def settings_dict(settings: JointSettings) -> dict:
    return asdict(settings)
