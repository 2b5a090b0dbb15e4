"""The whole structure as one model: gridshell.step (a named, coloured cadquery Assembly of the
joints, the beams as cut and the panels) and gridshell.3dm (rhino3dm, one layer per part kind).
Millimetres."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from engine.mesh import PolyMesh
from engine.parts import beam_id, joint_id

from .files import stamp_3dm, write_assembly_step, write_bytes_atomic

__all__ = ["JointSolids", "write_gridshell_step", "write_gridshell_3dm"]


@dataclass(frozen=True)
class JointSolids:
    """Where gridshell.step takes each joint's solid from: ``files`` joint id -> its own STEP file
    (the solid placed at its node), ``copies`` joint id -> (the id of the joint whose solid it is,
    the 4 x 4 transform in mm onto this one; fabrication.joints.copy_placements). A joint in
    neither is drawn as a sphere (one not built). ``breps``: the same solids in OCCT's own
    format, read instead of the STEP files where given (the same shape, 30 times faster)."""

    files: dict[str, Path] = field(default_factory=dict)
    copies: dict[str, tuple[str, np.ndarray]] = field(default_factory=dict)
    breps: dict[str, Path] = field(default_factory=dict)

    @property
    def distinct_bytes(self) -> int:
        """The bytes of the STEP files the model reads: what the joints add to gridshell.step."""
        return sum(Path(f).stat().st_size for f in self.files.values())


def _read_brep_shape(path: Path):
    from OCP.BRep import BRep_Builder
    from OCP.BRepTools import BRepTools
    from OCP.TopoDS import TopoDS_Shape

    shape = TopoDS_Shape()
    if not BRepTools.Read_s(shape, str(path), BRep_Builder()):
        raise OSError(f"could not read the joint's solid {path}")
    return shape


def _read_step_shape(path: Path):
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader()
    if reader.ReadFile(str(path)) != IFSelect_RetDone or reader.TransferRoots() == 0:
        raise OSError(f"could not read the joint's STEP file {path}")
    return reader.OneShape()


def write_gridshell_step(polymesh: PolyMesh, panels, path: Path, *, tubes: list | None = None,
                         beam_radius_mm: float | np.ndarray = 10.0, joints: JointSolids | None = None,
                         joint_radius_mm: float = 20.0, seats: tuple[np.ndarray, np.ndarray] | None = None,
                         panel_thickness_mm: float = 3.0) -> Path:
    """gridshell.step: the assembly "gridshell" of the joints J0001..., beams B0001... and panels
    P0001..., each a named component, joints grey, beams blue, panels glass.

    ``seats``: (up, shift_mm) of each panel (fabrication.panels.panel_seats): the plate is moved by
    ``shift_mm`` from its nodes' plane and is ``panel_thickness_mm`` thick towards ``up``; without
    them it lies in that plane.

    ``joints``: the joints' own solids; a joint's solid that repeats (a copy, turned) is one part
    placed at each of its joints, not copied. Joints not given are spheres of ``joint_radius_mm``
    (one shape, placed at every such node). ``tubes``: the beams as cut
    (fabrication.beams.tube_solids); without them, each beam is a cylinder of ``beam_radius_mm``
    from node to node."""
    import cadquery as cq

    nodes = 1000 * polymesh.nodes
    assembly = cq.Assembly(name="gridshell")
    grey, blue, glass = cq.Color(0.6, 0.6, 0.6), cq.Color(0.27, 0.51, 0.71), cq.Color(0.7, 0.85, 0.95, 0.5)
    joints = joints or JointSolids()
    sphere = None
    read: dict[str, cq.Shape] = {}
    for i, p in enumerate(nodes):
        name = joint_id(i)
        source, transform = name, None
        if name in joints.copies and joints.copies[name][0] in joints.files:
            source, transform = joints.copies[name]
        if source in joints.files:
            if source not in read:  # one shape per distinct joint: cadquery writes it once, placed at each
                brep = joints.breps.get(source)
                read[source] = cq.Shape.cast(_read_brep_shape(brep) if brep is not None and Path(brep).is_file()
                                             else _read_step_shape(joints.files[source]))
            loc = cq.Location() if transform is None else _location(transform)
            assembly.add(read[source], name=name, loc=loc, color=grey)
        else:
            sphere = sphere if sphere is not None else cq.Workplane().sphere(joint_radius_mm)
            assembly.add(sphere, name=name, loc=cq.Location(cq.Vector(*p)), color=grey)
    if tubes is not None:
        for tube in tubes:
            tube.add_to(assembly, color=blue)
    else:
        radii = np.broadcast_to(np.asarray(beam_radius_mm, dtype=float), (len(polymesh.edges),))
        for k, (a, b) in enumerate(polymesh.edges):
            direction = nodes[b] - nodes[a]
            length = float(np.linalg.norm(direction))
            solid = cq.Solid.makeCylinder(float(radii[k]), length, cq.Vector(*nodes[a]),
                                          cq.Vector(*(direction / length)))
            assembly.add(solid, name=beam_id(k), color=blue)
    for k, panel in enumerate(panels):
        outline = 1000 * np.asarray(panel.outline_3d_m)
        normal = np.cross(panel.axes[0], panel.axes[1])
        if seats is not None:
            normal = seats[0][k]
            outline = outline + seats[1][k]
        wire = cq.Wire.makePolygon([cq.Vector(*p) for p in outline], close=True)
        face = cq.Face.makeFromWires(wire)
        solid = cq.Solid.extrudeLinear(face, cq.Vector(*(panel_thickness_mm * normal)))
        assembly.add(solid, name=panel.id, color=glass)
    return write_assembly_step(assembly, path, point_decimals=8)  # points to 1e-8 mm, as the joints' files


def _location(transform: np.ndarray):
    """A cadquery Location of a rigid 4 x 4 transform (mm)."""
    import cadquery as cq
    from OCP.gp import gp_Trsf

    trsf = gp_Trsf()
    t = np.asarray(transform, dtype=float)
    trsf.SetValues(*map(float, t[0]), *map(float, t[1]), *map(float, t[2]))
    return cq.Location(trsf)


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
