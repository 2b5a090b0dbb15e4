"""The grid-shell as an IFC4 model for the BIM tools (``07-fabrication/gridshell.ifc``, mm).

Through ifcopenshell: a project, site and building ("grid-shell roof") holding an IfcMember per
beam (a circular hollow profile swept along the beam's cut length, between its joints), an IfcPlate
per panel (its outline extruded by the panel's thickness) and an IfcMechanicalFastener per joint (its
hub and its sleeves or fin plates as swept solids: what a clash check needs; the exact solid with its
holes and engraving is the part's STEP file, named in its properties). Each is Named by its id and
carries a property set ``Pset_Gridshell``: profile, material, cut length, mass and assembly step for
beams; material, thickness, mass, sheet and assembly step for panels; node, beams and part file for
joints.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .files import atomic_path

__all__ = ["IfcBeam", "IfcPanel", "IfcJoint", "write_gridshell_ifc"]


@dataclass(frozen=True, kw_only=True)
class IfcBeam:
    """A beam between its joints: start point and unit direction (mm), cut length and section (mm):
    round of outer diameter ``size_mm``, or where ``width_mm`` is given a rectangle ``size_mm`` high
    along the unit ``up``; hollow by ``wall_mm`` (0: solid).
    ``slots``: (unit direction across the slot, its length in mm) at the start and at the end, where
    steel fin plates enter (fabrication.joints.fin_plate_slots), ``slot_width_mm`` wide."""

    id: str
    start_mm: np.ndarray
    direction: np.ndarray
    cut_length_mm: float
    size_mm: float
    wall_mm: float
    profile: str
    mass_kg: float
    width_mm: float | None = None
    up: np.ndarray | None = None
    step: int | None = None
    slots: tuple = ()
    slot_width_mm: float = 0.0


@dataclass(frozen=True, kw_only=True)
class IfcPanel:
    """A panel: its outline (k,3) mm on its plane, in-plane axes (2,3), thickness (mm), sheet."""

    id: str
    outline_mm: np.ndarray
    axes: np.ndarray
    thickness_mm: float
    material: str
    mass_kg: float
    sheet: str = ""
    step: int | None = None


@dataclass(frozen=True, kw_only=True)
class IfcJoint:
    """A joint as swept solids in its own axes (mm): the hub (a cylinder of ``hub_radius_mm`` and
    ``hub_height_mm`` about ``axis``, centred on the node), and per beam either a socket's sleeve
    (solid up to the set-back, then a tube of the beam's bore to the sleeve's end) or a steel fin
    plate (``plate_mm``: thickness, height) reaching ``reach_mm`` along the beam."""

    id: str
    position_mm: np.ndarray
    axis: np.ndarray
    directions: np.ndarray
    hub_radius_mm: float
    hub_height_mm: float
    setback_mm: float
    reach_mm: np.ndarray
    outer_mm: np.ndarray
    bore_mm: np.ndarray
    plate_mm: tuple[float, float] | None = None
    part_file: str = ""

def square_to(direction: np.ndarray) -> np.ndarray:
    """A unit vector square to ``direction``: the world's z made square to it, else x (where
    ``direction`` is near z)."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    trial = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    square = trial - (trial @ d) * d
    return square / np.linalg.norm(square)


def _frame(origin_mm: np.ndarray, z: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
    """A 4 x 4 placement in metres with its local z along ``z`` (and x along ``x`` where given)."""
    z = np.asarray(z, float) / np.linalg.norm(z)
    if x is None:
        x = square_to(z)
    x = np.asarray(x, float) - (np.asarray(x, float) @ z) * z
    x /= np.linalg.norm(x)
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2] = x, np.cross(z, x), z
    matrix[:3, 3] = np.asarray(origin_mm, float) / 1000.0
    return matrix


def write_gridshell_ifc(path: Path, *, project_name: str, beams: list[IfcBeam], panels: list[IfcPanel],
                        joints: list[IfcJoint], beam_material: str, beam_category: str = "steel",
                        site_origin_m: np.ndarray | None = None) -> Path:
    """Write the IFC4 model (atomically); see the module docstring. ``site_origin_m``: where the
    parts' frame starts (fabrication.site; they are given from it): the site is placed there and
    every part relative to it, so the model stands where the roof does; None or zero: no site
    placement.

    ifcopenshell appends its ``express`` folder to ``sys.path`` as it works, and that folder's
    ``templates.py`` then shadows the project's own ``templates`` package for every later import
    (the report stage failed with "'templates' is not a package" after a run's fabrication):
    ``sys.path`` is put back as it was when the model is written."""
    saved = list(sys.path)
    try:
        return _write_ifc(path, project_name=project_name, beams=beams, panels=panels, joints=joints,
                          beam_material=beam_material, beam_category=beam_category,
                          site_origin_m=np.zeros(3) if site_origin_m is None else np.asarray(site_origin_m, float))
    finally:
        sys.path[:] = saved


def _profile(model, beam: IfcBeam):
    """The beam's section as an IFC profile (mm): circle or rectangle, hollow where it has a wall."""
    hollow = beam.wall_mm > 0
    if beam.width_mm is None:
        if hollow:
            return model.create_entity("IfcCircleHollowProfileDef", ProfileType="AREA", ProfileName=beam.profile,
                                       Radius=0.5 * beam.size_mm, WallThickness=beam.wall_mm)
        return model.create_entity("IfcCircleProfileDef", ProfileType="AREA", ProfileName=beam.profile,
                                   Radius=0.5 * beam.size_mm)
    if hollow:  # XDim across, YDim along the member's local y (its up)
        return model.create_entity("IfcRectangleHollowProfileDef", ProfileType="AREA", ProfileName=beam.profile,
                                   XDim=float(beam.width_mm), YDim=float(beam.size_mm), WallThickness=beam.wall_mm)
    return model.create_entity("IfcRectangleProfileDef", ProfileType="AREA", ProfileName=beam.profile,
                               XDim=float(beam.width_mm), YDim=float(beam.size_mm))


def _write_ifc(path: Path, *, project_name: str, beams: list[IfcBeam], panels: list[IfcPanel],
               joints: list[IfcJoint], beam_material: str, beam_category: str, site_origin_m: np.ndarray) -> Path:
    import ifcopenshell
    import ifcopenshell.api.aggregate as aggregate
    import ifcopenshell.api.context as context
    import ifcopenshell.api.material as material
    import ifcopenshell.api.root as root
    import ifcopenshell.api.unit as unit
    import ifcopenshell.guid

    model = ifcopenshell.file(schema="IFC4")
    project = root.create_entity(model, ifc_class="IfcProject", name=project_name)
    unit.assign_unit(model, units=[unit.add_si_unit(model, unit_type="LENGTHUNIT", prefix="MILLI"),
                                   unit.add_si_unit(model, unit_type="AREAUNIT"),
                                   unit.add_si_unit(model, unit_type="VOLUMEUNIT"),
                                   unit.add_si_unit(model, unit_type="MASSUNIT", prefix="KILO")])
    model_context = context.add_context(model, context_type="Model")
    body = context.add_context(model, context_type="Model", context_identifier="Body", target_view="MODEL_VIEW",
                               parent=model_context)
    site = root.create_entity(model, ifc_class="IfcSite", name="site")
    building = root.create_entity(model, ifc_class="IfcBuilding", name="grid-shell roof")
    aggregate.assign_object(model, products=[site], relating_object=project)
    aggregate.assign_object(model, products=[building], relating_object=site)

    def axes(frame: np.ndarray):
        """IfcAxis2Placement3D of a 4 x 4 frame in metres, written in mm."""
        return model.create_entity(
            "IfcAxis2Placement3D", Location=model.create_entity("IfcCartesianPoint", Coordinates=tuple(
                float(c) for c in 1000.0 * frame[:3, 3])),
            Axis=model.create_entity("IfcDirection", DirectionRatios=tuple(float(c) for c in frame[:3, 2])),
            RefDirection=model.create_entity("IfcDirection", DirectionRatios=tuple(float(c) for c in frame[:3, 0])))

    site_placement = None
    if site_origin_m.any():  # the parts are given from the site's origin (fabrication.site)
        site_frame = np.eye(4)
        site_frame[:3, 3] = site_origin_m
        site_placement = site.ObjectPlacement = model.create_entity("IfcLocalPlacement",
                                                                    RelativePlacement=axes(site_frame))

    def place(product, frame: np.ndarray) -> None:
        # made here rather than by the placement API, whose entity order varied from run to run
        product.ObjectPlacement = model.create_entity("IfcLocalPlacement", PlacementRelTo=site_placement,
                                                      RelativePlacement=axes(frame))

    # the products, their shapes and property sets made as entities: ifcopenshell's API took some
    # 3 ms a product in its bookkeeping (37 s for the large job's 10 800 products)
    def product(ifc_class: str, name: str, **attributes):
        return model.create_entity(ifc_class, GlobalId=ifcopenshell.guid.new(), Name=name, **attributes)

    def swept_shape(item) -> object:
        """An IfcProductDefinitionShape of one swept solid on the body context."""
        representation = model.create_entity("IfcShapeRepresentation", ContextOfItems=body,
                                             RepresentationIdentifier="Body", RepresentationType="SweptSolid",
                                             Items=[item])
        return model.create_entity("IfcProductDefinitionShape", Representations=[representation])

    def extruded(profile, depth_mm: float):
        """``profile`` extruded along its local z by ``depth_mm`` from the product's placement."""
        position = model.create_entity(
            "IfcAxis2Placement3D", Location=model.create_entity("IfcCartesianPoint", Coordinates=(0.0, 0.0, 0.0)),
            Axis=model.create_entity("IfcDirection", DirectionRatios=(0.0, 0.0, 1.0)),
            RefDirection=model.create_entity("IfcDirection", DirectionRatios=(1.0, 0.0, 0.0)))
        along = model.create_entity("IfcDirection", DirectionRatios=(0.0, 0.0, 1.0))
        return model.create_entity("IfcExtrudedAreaSolid", SweptArea=profile, Position=position,
                                   ExtrudedDirection=along, Depth=float(depth_mm))

    def properties(item, values: dict) -> None:
        """Pset_Gridshell: each value a single value, IfcLabel (text), IfcInteger or IfcReal."""
        single = []
        for key, value in values.items():
            if value is None:
                continue
            kind = ("IfcLabel" if isinstance(value, str) else
                    "IfcInteger" if isinstance(value, (int, np.integer)) and not isinstance(value, bool) else "IfcReal")
            nominal = model.create_entity(kind, str(value) if kind == "IfcLabel" else
                                          int(value) if kind == "IfcInteger" else float(value))
            single.append(model.create_entity("IfcPropertySingleValue", Name=key, NominalValue=nominal))
        props = model.create_entity("IfcPropertySet", GlobalId=ifcopenshell.guid.new(), Name="Pset_Gridshell",
                                    HasProperties=single)
        model.create_entity("IfcRelDefinesByProperties", GlobalId=ifcopenshell.guid.new(), RelatedObjects=[item],
                            RelatingPropertyDefinition=props)

    products = []
    profiles: dict[str, object] = {}
    steel = material.add_material(model, name=beam_material, category=beam_category)
    members = []
    for beam in beams:
        member = product("IfcMember", beam.id, PredefinedType="MEMBER")
        if beam.profile not in profiles:
            profiles[beam.profile] = _profile(model, beam)
        member.Representation = swept_shape(extruded(profiles[beam.profile], beam.cut_length_mm))
        # a rectangle's height (the profile's y) along the beam's up: local x = up x direction
        frame = _frame(beam.start_mm, beam.direction, None if beam.up is None else np.cross(beam.up, beam.direction))
        place(member, frame)
        for end, (side, length) in enumerate(beam.slots):
            # the end slot as an opening that voids the member, in the member's own axes (mm)
            across = frame[:3, :3].T @ np.asarray(side, float)
            at, inward = (np.zeros(3), np.array([0.0, 0.0, 1.0])) if end == 0 else (
                np.array([0.0, 0.0, beam.cut_length_mm]), np.array([0.0, 0.0, -1.0]))
            opening = product("IfcOpeningElement", f"{beam.id} slot {end + 1}")
            strip = model.create_entity("IfcRectangleProfileDef", ProfileType="AREA", XDim=float(beam.slot_width_mm),
                                        YDim=float(2 * max(beam.size_mm, beam.width_mm or 0.0)))
            up = model.create_entity("IfcDirection", DirectionRatios=(0.0, 0.0, 1.0))
            solid = model.create_entity("IfcExtrudedAreaSolid", SweptArea=strip, ExtrudedDirection=up,
                                        Position=axes(_frame(at, inward, across)), Depth=float(length))
            opening.Representation = swept_shape(solid)
            opening.ObjectPlacement = model.create_entity(
                "IfcLocalPlacement", PlacementRelTo=member.ObjectPlacement, RelativePlacement=axes(np.eye(4)))
            model.create_entity("IfcRelVoidsElement", GlobalId=ifcopenshell.guid.new(), RelatingBuildingElement=member,
                                RelatedOpeningElement=opening)
        properties(member, {"Profile": beam.profile, "Material": beam_material, "CutLength_mm": beam.cut_length_mm,
                            "Mass_kg": beam.mass_kg, "AssemblyStep": beam.step})
        members.append(member)
    if members:
        material.assign_material(model, products=members, material=steel)
    products += members
    materials: dict[str, object] = {}
    plates_of: dict[str, list] = {}
    for panel in panels:
        plate = product("IfcPlate", panel.id, PredefinedType="CURTAIN_PANEL")
        outline = np.asarray(panel.outline_mm, float)
        x, y = np.asarray(panel.axes[0], float), np.asarray(panel.axes[1], float)
        local = np.c_[(outline - outline[0]) @ x, (outline - outline[0]) @ y]
        points = [model.create_entity("IfcCartesianPoint", Coordinates=(float(u), float(v))) for u, v in local]
        curve = model.create_entity("IfcPolyline", Points=points + points[:1])
        profile = model.create_entity("IfcArbitraryClosedProfileDef", ProfileType="AREA", OuterCurve=curve)
        plate.Representation = swept_shape(extruded(profile, panel.thickness_mm))
        place(plate, _frame(outline[0], np.cross(x, y), x))
        if panel.material not in materials:
            materials[panel.material] = material.add_material(model, name=panel.material, category="glass")
        plates_of.setdefault(panel.material, []).append(plate)
        properties(plate, {"Material": panel.material, "Thickness_mm": panel.thickness_mm, "Mass_kg": panel.mass_kg,
                           "Sheet": panel.sheet or None, "AssemblyStep": panel.step})
        products.append(plate)
    for name, plates in plates_of.items():  # one assignment per material, as for the members
        material.assign_material(model, products=plates, material=materials[name])
    def swept(profile, origin, z, depth: float, x=None):
        """An extruded solid of ``profile`` from ``origin`` along ``z`` (joint axes, mm)."""
        # entities in the order the file numbers them: the placement, then the direction
        position = axes(_frame(origin, z, x))
        up = model.create_entity("IfcDirection", DirectionRatios=(0.0, 0.0, 1.0))
        return model.create_entity("IfcExtrudedAreaSolid", SweptArea=profile, Position=position,
                                   ExtrudedDirection=up, Depth=float(depth))

    for joint in joints:
        fastener = product("IfcMechanicalFastener", joint.id)
        axis = np.asarray(joint.axis, float) / np.linalg.norm(joint.axis)
        circle = lambda r: model.create_entity("IfcCircleProfileDef", ProfileType="AREA", Radius=float(r))  # noqa: E731
        items = [swept(circle(joint.hub_radius_mm), -0.5 * joint.hub_height_mm * axis, axis, joint.hub_height_mm)]
        for d, reach, outer, bore in zip(joint.directions, joint.reach_mm, joint.outer_mm, joint.bore_mm):
            if joint.plate_mm is not None:
                thickness, height = joint.plate_mm
                plate = model.create_entity("IfcRectangleProfileDef", ProfileType="AREA", XDim=float(thickness),
                                            YDim=float(height))
                side = np.cross(d, axis)
                items.append(swept(plate, np.zeros(3), d, reach, x=side if np.linalg.norm(side) > 1e-9 else None))
            else:
                items.append(swept(circle(outer), np.zeros(3), d, joint.setback_mm))
                tube = model.create_entity("IfcCircleHollowProfileDef", ProfileType="AREA", Radius=float(outer),
                                           WallThickness=float(outer - bore))
                items.append(swept(tube, d * joint.setback_mm, d, reach - joint.setback_mm))
        representation = model.create_entity("IfcShapeRepresentation", ContextOfItems=body,
                                             RepresentationIdentifier="Body", RepresentationType="SweptSolid",
                                             Items=items)
        fastener.Representation = model.create_entity("IfcProductDefinitionShape", Representations=[representation])
        place(fastener, _frame(joint.position_mm, np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])))
        properties(fastener, {"Beams": int(len(joint.directions)), "PartFile": joint.part_file or None,
                              "Geometry": "hub and sleeves or fin plates as swept solids; the joint's solid, with "
                                          "its holes and engraving, is the part file"})
        products.append(fastener)
    if products:
        # made here rather than by the spatial API, which re-made every placement in an order of its own
        model.create_entity("IfcRelContainedInSpatialStructure", GlobalId=ifcopenshell.guid.new(),
                            Name="grid-shell parts", RelatingStructure=building, RelatedElements=products)
    _make_reproducible(model)
    with atomic_path(path) as tmp:
        model.write(str(tmp))
    return Path(path)


def _make_reproducible(model) -> None:
    """The same model, the same bytes: every GlobalId from its class, name and order (uuid5, instead
    of the random ones), and file_date() as the header's time stamp."""
    import uuid

    import ifcopenshell.guid

    from .files import file_date

    seen: dict[tuple[str, str], int] = {}
    for entity in model.by_type("IfcRoot"):
        key = (entity.is_a(), str(entity.Name or ""))
        seen[key] = seen.get(key, 0) + 1
        entity.GlobalId = ifcopenshell.guid.compress(
            uuid.uuid5(uuid.NAMESPACE_URL, f"gridshell:{key[0]}:{key[1]}:{seen[key]}").hex)
    model.header.file_name.time_stamp = file_date().strftime("%Y-%m-%dT%H:%M:%S")
