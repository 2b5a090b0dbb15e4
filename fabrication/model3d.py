"""The whole structure as one model: gridshell.step (a named, coloured cadquery Assembly of joints,
beams and panels) and gridshell.3dm (rhino3dm, one layer per part kind). Millimetres."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from engine.mesh import PolyMesh
from engine.parts import beam_id, joint_id

from .files import atomic_path, stamp_3dm, stamp_step, write_bytes_atomic

__all__ = ["write_gridshell_step", "write_gridshell_3dm"]


def write_gridshell_step(polymesh: PolyMesh, panels, beam_radius_mm: float | np.ndarray, joint_radius_mm: float,
                         path: Path) -> Path:
    """Joints as spheres J0001... (one sphere shape, instanced at every node), beams as cylinders
    B0001... (one radius, or one per beam), panels as 3 mm plates P0001... ."""
    import cadquery as cq

    nodes = 1000 * polymesh.nodes
    assembly = cq.Assembly(name="gridshell")
    grey, blue, glass = cq.Color(0.6, 0.6, 0.6), cq.Color(0.27, 0.51, 0.71), cq.Color(0.7, 0.85, 0.95, 0.5)
    sphere = cq.Workplane().sphere(joint_radius_mm)  # one shape, placed at every node (instances)
    for i, p in enumerate(nodes):
        assembly.add(sphere, name=joint_id(i), loc=cq.Location(cq.Vector(*p)), color=grey)
    radii = np.broadcast_to(np.asarray(beam_radius_mm, dtype=float), (len(polymesh.edges),))
    for k, (a, b) in enumerate(polymesh.edges):
        direction = nodes[b] - nodes[a]
        length = float(np.linalg.norm(direction))
        solid = cq.Solid.makeCylinder(float(radii[k]), length, cq.Vector(*nodes[a]), cq.Vector(*(direction / length)))
        assembly.add(solid, name=beam_id(k), color=blue)
    for panel in panels:
        outline = 1000 * np.asarray(panel.outline_3d_m)
        normal = np.cross(panel.axes[0], panel.axes[1])
        wire = cq.Wire.makePolygon([cq.Vector(*p) for p in outline], close=True)
        face = cq.Face.makeFromWires(wire)
        solid = cq.Solid.extrudeLinear(face, cq.Vector(*(3.0 * normal)))
        assembly.add(solid, name=panel.id, color=glass)
    with atomic_path(path) as tmp:
        # no p-curves (2D copies of the edges on their faces, which readers rebuild): a third of the bytes
        assembly.export(str(tmp), "STEP", write_pcurves=False)
        stamp_step(tmp)
    return Path(path)


def _stable_id(name: str):
    """A GUID that follows from the part's name, so that the same model gives the same file."""
    import uuid

    return uuid.uuid5(uuid.NAMESPACE_URL, f"gridshell:{name}")


def write_gridshell_3dm(polymesh: PolyMesh, panels, beam_radius_mm: float | np.ndarray, joint_radius_mm: float,
                        path: Path) -> Path:
    """Layers joints (spheres), beams (centre lines), panels (meshes); object names are the ids.

    The same model gives the same bytes: object and layer ids follow from the names, the file is
    encoded in memory (``File3dm.Write`` records the path it wrote to, here a temporary name) and
    its created and last edited times are fabrication.files.file_date's day."""
    import base64

    import rhino3dm

    model = rhino3dm.File3dm()
    model.Settings.ModelUnitSystem = rhino3dm.UnitSystem.Millimeters
    layers = {}
    for name, colour in (("joints", (150, 150, 150, 255)), ("beams", (70, 130, 180, 255)),
                         ("panels", (180, 215, 240, 255))):
        layer = rhino3dm.Layer()
        layer.Name = name
        layer.Color = colour
        layer.Id = _stable_id(f"layer {name}")
        layers[name] = model.Layers.Add(layer)
    nodes = 1000 * polymesh.nodes

    def attributes(layer: str, name: str):
        a = rhino3dm.ObjectAttributes()
        a.LayerIndex = layers[layer]
        a.Name = name
        a.Id = _stable_id(name)  # rhino3dm draws a random GUID per object otherwise
        return a

    for i, p in enumerate(nodes):
        sphere = rhino3dm.Sphere(rhino3dm.Point3d(*p), joint_radius_mm)
        model.Objects.AddSphere(sphere, attributes("joints", joint_id(i)))
    for k, (a, b) in enumerate(polymesh.edges):
        start, end = rhino3dm.Point3d(*nodes[a]), rhino3dm.Point3d(*nodes[b])
        model.Objects.AddLine(start, end, attributes("beams", beam_id(k)))
    for panel in panels:
        outline = 1000 * np.asarray(panel.outline_3d_m)
        mesh = rhino3dm.Mesh()
        for p in outline:
            mesh.Vertices.Add(*map(float, p))
        centre = outline.mean(axis=0)
        mesh.Vertices.Add(*map(float, centre))
        c = len(outline)
        for j in range(c):
            mesh.Faces.AddFace(j, (j + 1) % c, c)
        mesh.Normals.ComputeNormals()
        model.Objects.AddMesh(mesh, attributes("panels", panel.id))
    options = rhino3dm.File3dmWriteOptions()
    options.Version = 7
    encoded = model.Encode(options)
    if not encoded:
        raise OSError(f"rhino3dm could not write {path}")
    return write_bytes_atomic(path, stamp_3dm(base64.b64decode(encoded)))
