"""Flat panels: flattening, inset, splitting, DXF and CSV files re-read with other readers."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
import shapely
from shapely.geometry import Point, Polygon

from engine.errors import InputError
from engine.mesh import PolyMesh, best_fit_plane
from fabrication.panels import PanelSettings, flatten_panels, write_panel_dxfs, write_panels_csv

ezdxf = pytest.importorskip("ezdxf")


@lru_cache(maxsize=None)
def _mockup_heights():
    from scipy.interpolate import LinearNDInterpolator

    from engine.geometry.parametric import mockup

    mesh = mockup(divisions=12).mesh
    return LinearNDInterpolator(mesh.vertices[:, :2], mesh.vertices[:, 2], fill_value=0.0)


def hex_polymesh(rows: int = 4, cols: int = 4, radius: float = 0.18, lift: bool = True,
                 span: float = 2.4) -> PolyMesh:
    """A pointy-top hexagonal grid (rows x cols cells, circumradius ``radius`` m) centred on the
    origin, lifted onto the mock-up funicular (2.4 m square) heights; supports on boundary nodes
    in the lowest quarter of the height range or, when flat, all boundary nodes."""
    w = np.sqrt(3.0) * radius
    corners = np.array([[np.cos(a), np.sin(a)] for a in np.pi / 6 + np.arange(6) * np.pi / 3]) * radius
    centres = np.array([[c * w + (r % 2) * w / 2, r * 1.5 * radius] for r in range(rows) for c in range(cols)])
    centres -= centres.mean(axis=0)
    points = (centres[:, None, :] + corners[None, :, :]).reshape(-1, 2)
    key = np.round(points / (radius * 1e-3)).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    plan = points[first]
    faces = tuple(inverse.reshape(-1, 6)[k] for k in range(len(centres)))
    scale = 0.95 * span / 2 / np.abs(plan).max()
    z = _mockup_heights()(plan * scale) if lift else np.zeros(len(plan))
    nodes = np.column_stack([plan, z])
    counts = np.bincount(np.concatenate(faces), minlength=len(plan))
    boundary = counts < 3
    supports = boundary & (z <= z.min() + 0.25 * max(np.ptp(z), 1e-9)) if lift else boundary
    return PolyMesh(nodes=nodes, faces=faces, boundary=boundary, supports=supports)


def _twisted_quad(twist_mm: float) -> PolyMesh:
    nodes = np.array([[0, 0, 0], [0.4, 0, 0], [0.4, 0.3, twist_mm * 1e-3], [0, 0.3, 0]], float)
    return PolyMesh(nodes=nodes, faces=(np.arange(4),))


def test_flat_square_panel_inset_is_exact():
    # a 300 mm x 200 mm rectangle inset by c has area (300-2c)(200-2c) and mitred corners
    nodes = np.array([[0, 0, 1.0], [0.3, 0, 1.0], [0.3, 0.2, 1.0], [0, 0.2, 1.0]])
    mesh = PolyMesh(nodes=nodes, faces=(np.arange(4),))
    (panel,) = flatten_panels(mesh, PanelSettings(clearance_mm=5))
    assert panel.id == "P0001" and panel.face == 0
    assert panel.area_mm2 == pytest.approx(290 * 190, rel=1e-9)
    assert panel.perimeter_mm == pytest.approx(2 * (290 + 190), rel=1e-9)
    assert len(panel.outline_mm) == 4 and not panel.nonplanar
    assert panel.planarity_mm == pytest.approx(0.0, abs=1e-9)
    # the 3D outline lies in z = 1 and is the inset rectangle
    assert np.allclose(panel.outline_3d_m[:, 2], 1.0)
    lo, hi = panel.outline_3d_m[:, :2].min(0), panel.outline_3d_m[:, :2].max(0)
    assert np.allclose(lo, [0.005, 0.005]) and np.allclose(hi, [0.295, 0.195])


def test_hex_grid_panels_planarity_and_3d_mapping():
    mesh = hex_polymesh(3, 3)
    panels = flatten_panels(mesh, PanelSettings(clearance_mm=2))
    assert [p.id for p in panels] == [f"P{f + 1:04d}" for f in range(mesh.n_faces)]
    planarity = mesh.face_planarity() * 1e3
    for p, expected in zip(panels, planarity):
        # independent planarity: PolyMesh.face_planarity (SVD best-fit plane)
        assert p.planarity_mm == pytest.approx(expected, rel=1e-6, abs=1e-9)
        assert p.nonplanar == (expected > 2.0)
        # the unprojected face outline maps back onto the projection of the nodes
        loop = mesh.nodes[mesh.faces[p.face]]
        centroid, normal = best_fit_plane(loop)
        projected = loop - np.outer((loop - centroid) @ normal, normal)
        back = p.origin_m + 1e-3 * p.face_outline_mm @ p.axes
        assert np.allclose(back, projected, atol=1e-9)
        # the inset outline is counter-clockwise, inside the face outline and 2 mm from it
        cut, face = Polygon(p.outline_mm), Polygon(p.face_outline_mm)
        assert cut.exterior.is_ccw and face.contains(cut)
        assert face.exterior.distance(cut) == pytest.approx(2.0, abs=1e-6)


def test_holes_at_inset_from_both_edges():
    nodes = np.array([[0, 0, 0], [0.3, 0, 0], [0.3, 0.2, 0], [0, 0.2, 0]], float)
    mesh = PolyMesh(nodes=nodes, faces=(np.arange(4),))
    (panel,) = flatten_panels(mesh, PanelSettings(clearance_mm=0, hole_diameter_mm=5, hole_inset_mm=12))
    assert len(panel.holes_mm) == 4
    cut = Polygon(panel.outline_mm)
    for c in panel.holes_mm:
        # distance to the nearest edge is exactly the inset (corner bisector of a right angle)
        assert cut.exterior.distance(Point(c)) == pytest.approx(12.0, abs=1e-9)
    # hexagon (120 degree corners): the centre sits 12 / sin(60 deg) from the corner
    (hex_panel, *_) = flatten_panels(hex_polymesh(1, 1, lift=False),
                                     PanelSettings(clearance_mm=0, hole_diameter_mm=5, hole_inset_mm=12))
    dist = np.linalg.norm(hex_panel.holes_mm[:, None] - hex_panel.outline_mm[None], axis=2).min(1)
    assert np.allclose(dist, 12 / np.sin(np.pi / 3))


def test_split_nonplanar_gives_planar_triangles():
    mesh = _twisted_quad(30.0)
    (whole,) = flatten_panels(mesh, PanelSettings(planarity_tolerance_mm=2))
    assert whole.nonplanar and whole.planarity_mm == pytest.approx(7.5, rel=0.05)  # twist / 4 for a square-ish quad
    parts = flatten_panels(mesh, PanelSettings(planarity_tolerance_mm=2, split_nonplanar=True))
    assert [p.id for p in parts] == ["P0001a", "P0001b"]
    for p in parts:
        assert not p.nonplanar and p.planarity_mm < 1e-9 and p.face == 0
    # the two un-inset triangles tile the face: their flat areas equal the 3D areas of one of
    # the quad's two diagonal triangulations (cross-product areas)
    total = sum(Polygon(p.face_outline_mm).area for p in parts)
    n = mesh.nodes * 1e3

    def area3d(t):
        return 0.5 * np.linalg.norm(np.cross(n[t[1]] - n[t[0]], n[t[2]] - n[t[0]]))

    options = [area3d([0, 1, 2]) + area3d([0, 2, 3]), area3d([0, 1, 3]) + area3d([1, 2, 3])]
    assert min(abs(total - a) for a in options) < 1e-6


def test_split_hex_grid_all_planar():
    mesh = hex_polymesh(3, 3, radius=0.3)
    parts = flatten_panels(mesh, PanelSettings(planarity_tolerance_mm=0.5, split_nonplanar=True))
    assert any(p.id.endswith("d") for p in parts)  # a hexagon makes 4 triangles
    assert all(p.planarity_mm <= 0.5 for p in parts)
    assert {p.face for p in parts} == set(range(mesh.n_faces))


def test_clearance_too_large_is_a_user_error():
    mesh = hex_polymesh(1, 1, radius=0.01, lift=False)
    with pytest.raises(InputError, match="P0001"):
        flatten_panels(mesh, PanelSettings(clearance_mm=20))


def test_panel_dxfs_reread(tmp_path):
    mesh = hex_polymesh(2, 3)
    settings = PanelSettings(clearance_mm=3, hole_diameter_mm=4, hole_inset_mm=10)
    panels = flatten_panels(mesh, settings)
    paths = write_panel_dxfs(panels, tmp_path / "panels", settings)
    assert sorted(p.name for p in paths) == sorted(f"{p.id}.dxf" for p in panels)
    assert not [p for p in (tmp_path / "panels").iterdir() if p.name.startswith(".")]  # no temp files left
    for panel, path in zip(panels, paths):
        doc = ezdxf.readfile(path)
        auditor = doc.audit()
        assert not auditor.has_errors
        assert doc.header["$INSUNITS"] == 4
        assert {"CUT", "ENGRAVE", "DRILL", "NOTES"} <= {layer.dxf.name for layer in doc.layers}
        msp = doc.modelspace()
        cuts = msp.query('LWPOLYLINE[layer=="CUT"]')
        assert len(cuts) == 1 and cuts[0].closed
        xy = np.array([p[:2] for p in cuts[0].get_points()])
        # CUT area equals the inset face area computed independently with shapely
        inset = Polygon(panel.face_outline_mm).buffer(-3, join_style="mitre")
        assert shapely.area(Polygon(xy)) == pytest.approx(inset.area, rel=5e-3)
        labels = [t.dxf.text for t in msp.query('TEXT[layer=="ENGRAVE"]')]
        assert labels == [panel.id]
        circles = msp.query('CIRCLE[layer=="DRILL"]')
        assert len(circles) == len(panel.holes_mm) > 0
        assert all(Polygon(xy).contains(Point(c.dxf.center.x, c.dxf.center.y).buffer(2.0)) for c in circles)
        notes = " ".join(t.dxf.text for t in msp.query('TEXT[layer=="NOTES"]'))
        assert "acrylic" in notes and "3 mm" in notes and "planarity" in notes


def test_panel_files_from_a_shared_document_are_those_of_fresh_documents(tmp_path, monkeypatch):
    """Each panel file written from the shared document has the bytes of a fresh document with
    the same panel saved on its own, in any order of writing, and ezdxf's audit finds nothing; a
    drawing that adds a layer is written from a fresh document, and the files after it are
    still those of fresh documents."""
    from fabrication import dxf
    from fabrication.dxf import SharedDocument, cutting_layers, new_document, save_dxf
    from fabrication.panels import add_panel

    settings = PanelSettings(clearance_mm=3, hole_diameter_mm=4, hole_inset_mm=10)
    panels = flatten_panels(hex_polymesh(2, 3), settings)
    layers = cutting_layers(drill=True)

    def fresh(panel, path, extra: bool = False):
        doc = new_document(layers)
        add_panel(doc.modelspace(), panel, settings=settings, note=True)
        if extra:
            doc.layers.add("EXTRA")
            doc.modelspace().add_point((0, 0), dxfattribs={"layer": "EXTRA"})
        return save_dxf(doc, path).read_bytes()

    def with_extra(msp, panel):
        add_panel(msp, panel, settings=settings, note=True)
        msp.doc.layers.add("EXTRA")
        msp.add_point((0, 0), dxfattribs={"layer": "EXTRA"})

    shared = SharedDocument(layers)
    made = []
    monkeypatch.setattr(dxf, "new_document", lambda *a, **k: made.append(1) or new_document(*a, **k))
    for k, panel in enumerate(panels[::-1]):
        written = shared.save(tmp_path / "shared" / f"{panel.id}.dxf",
                              lambda msp, panel=panel: add_panel(msp, panel, settings=settings, note=True))
        assert written.read_bytes() == fresh(panel, tmp_path / "fresh" / f"{panel.id}.dxf")
        assert not ezdxf.readfile(written).audit().has_errors
        if k == 1:
            odd = shared.save(tmp_path / "shared" / "odd.dxf", lambda msp, panel=panel: with_extra(msp, panel))
            assert odd.read_bytes() == fresh(panel, tmp_path / "fresh" / "odd.dxf", extra=True)
            assert "EXTRA" in {layer.dxf.name for layer in ezdxf.readfile(odd).layers}
            assert len(made) == 2, "the odd drawing, and the shared document made again"
    assert len(made) == 2, "every other file came from the shared document"


def test_panels_without_fixings_have_no_drill_layer(tmp_path):
    """No holes asked for: no DRILL layer, not an empty one (issue 17)."""
    mesh = hex_polymesh(1, 2)
    settings = PanelSettings(clearance_mm=3, hole_diameter_mm=0)
    for path in write_panel_dxfs(flatten_panels(mesh, settings), tmp_path / "panels", settings):
        layers = {layer.dxf.name for layer in ezdxf.readfile(path).layers}
        assert {"CUT", "ENGRAVE", "NOTES"} <= layers and "DRILL" not in layers


def test_every_dxf_writer_uses_the_layer_table(tmp_path):
    """A panel's, a nesting sheet's and the plan's DXF read back in mm with the layers of
    fabrication.dxf (each in its colour and linetype) and no others but ezdxf's 0 and Defpoints."""
    from fabrication.drawings import write_plan_drawings
    from fabrication.dxf import CUTTING_LAYERS, ENGRAVE_STYLE, LAYERS, PLAN_LAYERS
    from fabrication.nesting_sheets import SheetSettings, nest_sheets, write_sheet_dxfs

    mesh = hex_polymesh(2, 3)
    settings = PanelSettings(clearance_mm=3, hole_diameter_mm=4, hole_inset_mm=10)
    panels = flatten_panels(mesh, settings)
    nesting = nest_sheets(panels, SheetSettings(width_mm=1200, height_mm=600))
    written = [(write_panel_dxfs(panels, tmp_path / "panels", settings)[0], CUTTING_LAYERS),
               (write_sheet_dxfs(nesting, panels, tmp_path / "sheets", settings)[0], CUTTING_LAYERS),
               (write_plan_drawings(mesh, tmp_path / "plan", project_name="x")[0], PLAN_LAYERS)]
    for path, expected in written:
        doc = ezdxf.readfile(path)
        assert doc.header["$INSUNITS"] == 4 and doc.header["$MEASUREMENT"] == 1
        layers = {layer.dxf.name: layer for layer in doc.layers if layer.dxf.name not in ("0", "Defpoints")}
        # LABELS_LEADERS is dropped when no id needed a leader line
        assert set(expected) - {"LABELS_LEADERS"} <= set(layers) <= set(expected), path.name
        for name, layer in layers.items():
            assert (layer.color, layer.dxf.linetype) == (LAYERS[name].colour, LAYERS[name].linetype), name
        assert (ENGRAVE_STYLE in doc.styles) == ("ENGRAVE" in layers)


def test_panels_csv(tmp_path):
    mesh = hex_polymesh(2, 2)
    settings = PanelSettings(thickness_mm=4, density=1000, hole_diameter_mm=0)
    panels = flatten_panels(mesh, settings)
    path = write_panels_csv(panels, None, settings, tmp_path / "panels.csv")
    import pandas as pd

    table = pd.read_csv(path)
    assert list(table.columns) == ["id", "area_mm2", "perimeter_mm", "vertex_count", "planarity_mm",
                                   "thickness_mm", "mass_kg", "sheet"]
    assert list(table["id"]) == [p.id for p in panels]
    # mass = area x thickness x density, area re-computed from the outline by the shoelace formula
    for row, p in zip(table.itertuples(), panels):
        x, y = p.outline_mm.T
        area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
        assert row.mass_kg == pytest.approx(area * 1e-6 * 4e-3 * 1000, rel=1e-3)
        assert row.vertex_count == len(p.outline_mm)
    assert table["sheet"].isna().all()


def _slab(panel, up: np.ndarray, shift_mm: np.ndarray, thickness_mm: float):
    """A panel as gridshell.step places it (fabrication.model3d): its outline moved to its seat and
    extruded by its thickness towards ``up`` (an OCP solid)."""
    import cadquery as cq

    outline = 1000 * np.asarray(panel.outline_3d_m) + shift_mm
    face = cq.Face.makeFromWires(cq.Wire.makePolygon([cq.Vector(*p) for p in outline], close=True))
    return cq.Solid.extrudeLinear(face, cq.Vector(*(thickness_mm * up))).wrapped


def _distance_and_overlap(a, b) -> tuple[float, float]:
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Common
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(BRepAlgoAPI_Common(a, b).Shape(), props)
    return BRepExtrema_DistShapeShape(a, b).Value(), props.Mass()


@pytest.mark.parametrize("rise", [0.3, -0.3])
def test_panels_lifted_onto_their_joints_keep_their_joint_open_at_a_valley_fold(rise):
    """Two 1 m panels meet on a beam at a fold of 33 degrees, lifted 150 mm onto their joints. At
    a valley (both rising from the beam) they would run into each other: cut back, they keep the
    two clearances between them (OCCT's distance between the slabs), and are otherwise as flattened.
    At a ridge nothing is cut."""
    from fabrication.joints import JointSettings, joint_geometry
    from fabrication.panels import panel_seats, trim_at_folds

    nodes = np.array([[0, 0, 0], [1, 0, 0], [1, 1, rise], [0, 1, rise], [0, -1, rise], [1, -1, rise]], float)
    grid = PolyMesh(nodes=nodes, faces=((0, 1, 2, 3), (1, 0, 4, 5)))
    settings = PanelSettings(clearance_mm=10.0, thickness_mm=10.0)
    panels = flatten_panels(grid, settings)
    joints = JointSettings(kind="steel", hub_radius_mm=100.0)
    geometries = {g.node: g for g in joint_geometry(grid, np.tile([0.0, 0.0, 1.0], (len(nodes), 1)), 60.0)}
    seats = panel_seats(panels, list(grid.faces), geometries, joints, {})
    assert (np.linalg.norm(seats[1], axis=1) > 100).all()
    trimmed, cut_back = trim_at_folds(panels, list(grid.faces), nodes, seats, settings)
    before = _distance_and_overlap(*(_slab(p, u, s, 10.0) for p, u, s in zip(panels, *seats)))
    after = _distance_and_overlap(*(_slab(p, u, s, 10.0) for p, u, s in zip(trimmed, *seats)))
    if rise > 0:
        assert before[1] > 1000.0  # mm3: the untrimmed panels overlap
        assert after[1] == 0.0 and after[0] == pytest.approx(20.0, abs=0.05)
        assert (cut_back > 10).all()
        for old, new in zip(panels, trimmed):
            assert Polygon(new.outline_mm).within(Polygon(old.outline_mm).buffer(1e-6))
            assert new.area_mm2 == pytest.approx(Polygon(new.outline_mm).area)
    else:
        assert before[0] > 20.0
        assert (cut_back == 0).all()
        assert all(new is old for old, new in zip(panels, trimmed))


def test_panels_round_a_valley_node_keep_clear_of_each_other_also_where_they_meet_at_the_node_only():
    """Six triangles round a node 300 mm below their rim (an upturned hexagonal pyramid), lifted
    onto a large hub: neighbours across an edge keep their two clearances (20 mm), and panels that
    meet at the node only do not touch (OCCT's distance and common volume of every pair)."""
    import itertools

    from fabrication.joints import JointSettings, joint_geometry
    from fabrication.panels import panel_seats, trim_at_folds

    rim = [[np.cos(a), np.sin(a), 0.3] for a in np.arange(6) * np.pi / 3]
    nodes = np.array([[0.0, 0.0, 0.0], *rim])
    grid = PolyMesh(nodes=nodes, faces=tuple((0, 1 + i, 1 + (i + 1) % 6) for i in range(6)))
    settings = PanelSettings(clearance_mm=10.0, thickness_mm=10.0)
    panels = flatten_panels(grid, settings)
    geometries = {g.node: g for g in joint_geometry(grid, np.tile([0.0, 0.0, 1.0], (len(nodes), 1)), 60.0)}
    seats = panel_seats(panels, list(grid.faces), geometries, JointSettings(kind="steel", hub_radius_mm=100.0), {})
    trimmed, cut_back = trim_at_folds(panels, list(grid.faces), nodes, seats, settings)
    assert (cut_back > 0).all()
    slabs = [_slab(p, u, s, 10.0) for p, u, s in zip(trimmed, *seats)]
    for i, j in itertools.combinations(range(6), 2):
        distance, overlap = _distance_and_overlap(slabs[i], slabs[j])
        assert overlap == 0.0
        if j - i in (1, 5):
            assert distance == pytest.approx(20.0, abs=0.05)
        else:
            assert distance > 10.0, (i, j, distance)


def _trimmed_on_their_nodes(nodes: np.ndarray, faces: tuple) -> tuple:
    """(panels, trimmed, cut back, problems) of the cells' panels (clearance and thickness 10 mm)
    resting on their nodes, unlifted, trimmed at their folds with the problems collected."""
    from fabrication.panels import trim_at_folds

    grid = PolyMesh(nodes=nodes, faces=faces)
    settings = PanelSettings(clearance_mm=10.0, thickness_mm=10.0)
    panels = flatten_panels(grid, settings)
    up = np.array([np.cross(*p.axes) for p in panels])
    problems: list = []
    trimmed, cut_back = trim_at_folds(panels, list(grid.faces), nodes, (up, np.zeros((len(panels), 3))), settings,
                                      problems=problems)
    return panels, trimmed, cut_back, problems


def test_panels_that_no_corner_cut_parts_are_reported_with_their_node():
    """Two slivers 2 m long share a node only and cross each other 1-2 m from it: no cut of their
    corners at the node parts them, so they stay as they are and the pair is a problem naming both
    panels and the node; a pair side by side in one plane is not."""
    def run(far_z: float, far_y: tuple[float, float] = (0.05, 0.15)):
        nodes = np.array([[0, 0, 0], [2, 0, 0], [2, 0.2, 0], [2, far_y[0], far_z], [2, far_y[1], -far_z]], float)
        return _trimmed_on_their_nodes(nodes, ((0, 1, 2), (0, 3, 4)))

    panels, trimmed, cut_back, problems = run(0.3)
    assert problems == [(("P0001", "P0002"), problems[0][1])]
    assert "N0001" in problems[0][1] and (cut_back == 0).all()
    assert all(new is old for old, new in zip(panels, trimmed))
    # side by side in one plane, their edges apart by 50 mm at the far ends: nothing to say
    _, _, cut_back, problems = run(0.0, (-0.05, -0.2))
    assert problems == [] and (cut_back == 0).all()


def test_a_corner_cut_that_would_use_up_a_panel_is_not_made():
    """A short panel crossed along its middle by a long one (both meet a third at that node only): the
    cut of their corners that would part them takes the whole short panel first, so none is made
    and the pair is a problem; the third pair, met after it, still finds the short panel whole
    (a 1500-cell roof stopped here, measuring a panel already cut away)."""
    nodes = np.array([[0, 0, 0], [0.3, -0.05, 0], [0.3, 0.05, 0],             # short, flat
                      [2, 0, 0.3], [2, 0, -0.3],                               # long, square through it
                      [-2, -0.1, 0], [-2, 0.1, 0]], float)                     # away on the other side
    panels, trimmed, cut_back, problems = _trimmed_on_their_nodes(nodes, ((0, 1, 2), (0, 3, 4), (0, 5, 6)))
    assert [parts for parts, _ in problems] == [("P0001", "P0002")]
    assert "no cut of their corners" in problems[0][1]
    assert trimmed[0] is panels[0] and cut_back[0] == 0.0
