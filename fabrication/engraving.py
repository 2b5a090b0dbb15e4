"""Engraving text into a planar face of a solid by building the pockets' faces, without a boolean.

A boolean cut of a text tool is slow: every glyph face is intersected with the solid and the
whole solid is rebuilt (0.3 s for a five-letter label on a socket joint, more than the rest of
the joint's booleans). When the pockets lie inside one planar face, away from every other face,
the engraved solid is known face by face: the face gets one hole per glyph outline, each glyph's
counters (the inside of an O) stay as islands of that face, and each glyph prism (the glyph swept
by the depth into the solid) gives its side and bottom faces, reversed, as the pocket's walls and
floor. These share their edges with the new holes, so the shell closes without sewing. The caller
decides that the pockets are clear of the other faces (it knows its solid) and checks the result
(BRepCheck); ``pocket_volume`` is what the engraving removes, for a volume check.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["text_faces", "glyph_bounds", "planar_faces", "text_placement", "engrave_planar_face", "pocket_volume"]


def text_faces(text: str, font_size_mm: float) -> list:
    """The glyph faces (OCP TopoDS_Face) of ``text`` in the XY plane, centred on the origin,
    normals +Z (build123d's default font)."""
    from build123d import Align, Compound

    label = Compound.make_text(text, font_size=font_size_mm, align=(Align.CENTER, Align.CENTER))
    return [face.wrapped for face in label.faces()]


def glyph_bounds(faces: Sequence) -> tuple[float, float, float, float]:
    """(x_min, y_min, x_max, y_max) of faces in the XY plane, mm."""
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    for face in faces:
        BRepBndLib.Add_s(face, box, False)
    box.SetGap(0.0)
    x0, y0, _, x1, y1, _ = box.Get()
    return x0, y0, x1, y1


def subshapes(shape, kind: str = "face") -> list:
    """The faces (``kind`` "face") or solids ("solid") of an OCP shape, as typed OCP objects."""
    from OCP.TopAbs import TopAbs_FACE, TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    shape_type, cast = {"face": (TopAbs_FACE, TopoDS.Face_s), "solid": (TopAbs_SOLID, TopoDS.Solid_s)}[kind]
    out = []
    explorer = TopExp_Explorer(shape, shape_type)
    while explorer.More():
        out.append(cast(explorer.Current()))
        explorer.Next()
    return out


def _faces(shape) -> list:
    return subshapes(shape, "face")


def planar_faces(solid, origin: np.ndarray, normal: np.ndarray, tolerance: float = 1e-6) -> list:
    """The faces of ``solid`` in the plane through ``origin`` whose outward normal is ``normal`` (unit)."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.GeomAbs import GeomAbs_Plane
    from OCP.TopAbs import TopAbs_REVERSED

    found = []
    for face in _faces(solid):
        surface = BRepAdaptor_Surface(face)
        if surface.GetType() != GeomAbs_Plane:
            continue
        plane = surface.Plane()
        d, p = plane.Axis().Direction(), plane.Location()
        # the surface's normal is the axis of a right-handed plane, its opposite for a left-handed
        # one (a mirrored solid's); the face's own normal is the surface's, reversed if the face is
        sign = (1.0 if plane.Direct() else -1.0) * (-1.0 if face.Orientation() == TopAbs_REVERSED else 1.0)
        outward = np.array([d.X(), d.Y(), d.Z()]) * sign
        if outward @ normal > 1 - 1e-9 and abs((np.array([p.X(), p.Y(), p.Z()]) - origin) @ normal) < tolerance:
            found.append(face)
    return found


def text_placement(origin: np.ndarray, normal: np.ndarray, x_dir: np.ndarray):
    """The gp_Trsf taking the text's XY plane to the plane through ``origin`` with ``normal``, x along ``x_dir``."""
    from OCP.gp import gp_Ax3, gp_Dir, gp_Pnt, gp_Trsf

    trsf = gp_Trsf()
    trsf.SetTransformation(gp_Ax3(gp_Pnt(*map(float, origin)), gp_Dir(*map(float, normal)), gp_Dir(*map(float, x_dir))),
                           gp_Ax3())
    return trsf


def engrave_planar_face(solid, face, glyphs: Sequence, origin: np.ndarray, normal: np.ndarray, x_dir: np.ndarray,
                        depth_mm: float):
    """``solid`` (TopoDS_Solid) with ``glyphs`` (faces in the XY plane, normals +Z) placed on its
    planar ``face`` (origin on it, ``normal`` its outward normal, text along ``x_dir``) and sunk
    ``depth_mm`` into it. The glyphs must lie inside the face and the pockets away from every
    other face (not checked here). Returns a TopoDS_Solid (check it with BRepCheck)."""
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace, BRepBuilderAPI_Transform
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.BRepTools import BRepTools
    from OCP.gp import gp_Dir, gp_Pln, gp_Pnt, gp_Vec
    from OCP.TopAbs import TopAbs_WIRE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS, TopoDS_Shell, TopoDS_Solid

    normal = np.asarray(normal, float)
    trsf = text_placement(origin, normal, x_dir)
    plane = gp_Pln(gp_Pnt(*map(float, origin)), gp_Dir(*map(float, normal)))
    sink = gp_Vec(*map(float, -depth_mm * normal))
    new_face = BRepBuilderAPI_MakeFace(face)
    pocket_faces = []
    for glyph in glyphs:
        placed = TopoDS.Face_s(BRepBuilderAPI_Transform(glyph, trsf, True).Shape())
        prism = BRepPrimAPI_MakePrism(placed, sink)
        first = prism.FirstShape()
        top = None
        for f in _faces(prism.Shape()):
            if f.IsSame(first):
                top = f  # as oriented in the prism: outward normal = +normal
            else:
                pocket_faces.append(TopoDS.Face_s(f.Reversed()))
        outer = BRepTools.OuterWire_s(top)
        wires = TopExp_Explorer(top, TopAbs_WIRE)
        while wires.More():
            wire = TopoDS.Wire_s(wires.Current())
            if wire.IsSame(outer):
                new_face.Add(TopoDS.Wire_s(wire.Reversed()))  # a hole in the face
            else:  # a counter of the glyph: an island of the face, at its level
                pocket_faces.append(BRepBuilderAPI_MakeFace(plane, TopoDS.Wire_s(wire.Reversed())).Face())
            wires.Next()
    builder = BRep_Builder()
    shell = TopoDS_Shell()
    builder.MakeShell(shell)
    for f in _faces(solid):
        if not f.IsSame(face):
            builder.Add(shell, f)
    builder.Add(shell, new_face.Face())
    for f in pocket_faces:
        builder.Add(shell, f)
    shell.Closed(True)
    engraved = TopoDS_Solid()
    builder.MakeSolid(engraved)
    builder.Add(engraved, shell)
    return engraved


def pocket_volume(glyphs: Sequence, depth_mm: float) -> float:
    """Volume (mm^3) that engraving the glyphs ``depth_mm`` deep removes: their area times the depth."""
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    area = 0.0
    for glyph in glyphs:
        props = GProp_GProps()
        BRepGProp.SurfaceProperties_s(glyph, props)
        area += props.Mass()
    return area * depth_mm
