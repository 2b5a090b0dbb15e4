"""The whole structure as one model: gridshell.step (a named, coloured cadquery Assembly of the
joints, the beams as cut and the panels) and gridshell.3dm (rhino3dm, one layer per part kind).
Millimetres."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from engine.mesh import PolyMesh

from .files import stamp_3dm, write_assembly_step, write_bytes_atomic
from .ids import beam_id, joint_id
from .ifc import square_to

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


def write_gridshell_3dm(path: Path, beams: list, panels: list, joints: list) -> Path:
    """gridshell.3dm: the parts as gridshell.ifc holds them (fabrication.ifc's IfcBeam, IfcPanel and
    IfcJoint, mm), as Rhino extrusions on the layers joints, beams and panels: each beam its section
    as cut between its set-backs (the fin plates' slots aside), each panel a slab of its thickness
    resting on its joints, each joint its hub and fin plates or sleeves (solid from the node to the
    set-back, then a tube of the beam's bore: as printed, and as the IFC has them), as a group
    named by the joint. Objects are named by their ids and carry what the IFC's property sets say as user
    text (profile, cut length, mass, sheet, assembly step).

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

    def add(solid, layer: str, name: str, key: str, text: dict | None = None, group: int | None = None) -> None:
        a = rhino3dm.ObjectAttributes()
        a.LayerIndex = layers[layer]
        a.Name = name
        a.Id = _stable_id(key)  # rhino3dm draws a random GUID per object otherwise
        for k, v in (text or {}).items():
            if v is not None and v != "":
                a.SetUserString(k, str(v))
        if group is not None:
            a.AddToGroup(group)
        model.Objects.AddExtrusion(solid, a)

    for beam in beams:
        up = beam.up if beam.up is not None else square_to(beam.direction)
        if beam.width_mm is None:
            outer, inner = _circle(0.5 * beam.size_mm), None
            if 0 < beam.wall_mm < 0.5 * beam.size_mm:
                inner = _circle(0.5 * beam.size_mm - beam.wall_mm)
        else:
            outer, inner = _rectangle(beam.width_mm, beam.size_mm), None
            if beam.wall_mm > 0:
                inner = _rectangle(beam.width_mm - 2 * beam.wall_mm, beam.size_mm - 2 * beam.wall_mm)
        solid = _extrusion(beam.start_mm, beam.direction, beam.cut_length_mm, up, outer, inner)
        add(solid, "beams", beam.id, beam.id, {"profile": beam.profile, "cut_length_mm": f"{beam.cut_length_mm:.1f}",
                                               "mass_kg": f"{beam.mass_kg:.3f}", "assembly_step": beam.step})
    for panel in panels:
        axes = np.asarray(panel.axes, float)
        normal = np.cross(axes[0], axes[1])
        origin = np.asarray(panel.outline_mm, float)[0]
        flat = (np.asarray(panel.outline_mm, float) - origin) @ axes.T
        solid = _extrusion(origin, normal, panel.thickness_mm, axes[1], _polygon(flat))
        add(solid, "panels", panel.id, panel.id, {"material": panel.material, "thickness_mm": f"{panel.thickness_mm:g}",
                                                  "mass_kg": f"{panel.mass_kg:.3f}", "sheet": panel.sheet,
                                                  "assembly_step": panel.step})
    for joint in joints:
        group = rhino3dm.Group()
        group.Name = joint.id
        group.Id = _stable_id(f"group {joint.id}")
        model.Groups.Add(group)  # returns nothing: the new group is the table's last
        index = len(model.Groups) - 1
        axis = np.asarray(joint.axis, float) / np.linalg.norm(joint.axis)
        at = np.asarray(joint.position_mm, float)
        pieces = [("hub", _extrusion(at - 0.5 * joint.hub_height_mm * axis, axis, joint.hub_height_mm,
                                     square_to(axis), _circle(joint.hub_radius_mm)))]
        for k, (d, reach, outer, bore) in enumerate(zip(joint.directions, joint.reach_mm, joint.outer_mm,
                                                        joint.bore_mm)):
            d = np.asarray(d, float)
            if joint.plate_mm is not None:
                thickness, height = joint.plate_mm
                side = np.cross(d, axis)
                up = np.cross(d, side) if np.linalg.norm(side) > 1e-9 else square_to(d)
                pieces.append((f"plate {k + 1}", _extrusion(at, d, float(reach), up, _rectangle(thickness, height))))
            else:  # the sleeve as printed: solid up to the set-back, then a tube of the beam's bore
                setback = min(float(joint.setback_mm), float(reach))
                pieces.append((f"sleeve {k + 1}", _extrusion(at, d, setback, square_to(d), _circle(outer))))
                if reach > setback:
                    pieces.append((f"socket {k + 1}", _extrusion(at + setback * d, d, float(reach) - setback,
                                                                 square_to(d), _circle(outer), _circle(bore))))
        for piece, solid in pieces:  # user text on the hub only: 0.4 kB an object
            add(solid, "joints", joint.id, f"{joint.id} {piece}",
                {"part_file": joint.part_file} if piece == "hub" else None, group=index)
    options = rhino3dm.File3dmWriteOptions()
    options.Version = 7
    encoded = model.Encode(options)
    if not encoded:
        raise OSError(f"rhino3dm could not write {path}")
    return write_bytes_atomic(path, stamp_3dm(base64.b64decode(encoded)))


def _circle(radius: float):
    import rhino3dm

    return rhino3dm.Circle(float(radius)).ToNurbsCurve()


def _polygon(points_2d: np.ndarray):
    import rhino3dm

    closed = [*map(tuple, np.asarray(points_2d, float)), tuple(np.asarray(points_2d, float)[0])]
    return rhino3dm.Polyline([rhino3dm.Point3d(float(x), float(y), 0.0) for x, y in closed]).ToPolylineCurve()


def _rectangle(width: float, height: float):
    """A rectangle ``width`` along the profile's x (across the path) and ``height`` along its y (up)."""
    w, h = 0.5 * width, 0.5 * height
    return _polygon(np.array([[-w, -h], [w, -h], [w, h], [-w, h]]))


def _extrusion(start_mm: np.ndarray, direction: np.ndarray, length_mm: float, up: np.ndarray, outer, inner=None):
    """A capped Rhino extrusion of the profile ``outer`` (less ``inner``), curves on the profile's xy,
    from ``start_mm`` along the unit ``direction`` by ``length_mm``: the profile's y along ``up``
    (square to the direction) and its x along up x direction."""
    import rhino3dm

    start = np.asarray(start_mm, float)
    end = start + float(length_mm) * np.asarray(direction, float)
    solid = rhino3dm.Extrusion()
    if not (solid.SetPathAndUp(rhino3dm.Point3d(*map(float, start)), rhino3dm.Point3d(*map(float, end)),
                               rhino3dm.Vector3d(*map(float, up)))
            and solid.SetOuterProfile(outer, True) and (inner is None or solid.AddInnerProfile(inner))):
        raise ValueError("rhino3dm refused an extrusion")  # pragma: no cover (a degenerate path or profile)
    return solid
