"""gridshell.ifc re-read with ifcopenshell (its geometry engine and placement utilities, not the
writer's code): one named element per beam, panel and joint, the cut list's quantities, the tubes
where the beams are."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

ifcopenshell = pytest.importorskip("ifcopenshell")


def test_the_ifc_model_has_every_part_with_the_cut_lists_quantities(small_run):
    import ifcopenshell.geom
    import ifcopenshell.util.element as element
    import ifcopenshell.util.placement as placement
    import ifcopenshell.util.shape as shape

    from workflow.stages.polymesh_io import read_polymesh_obj

    project, out = small_run
    folder = out / "07-fabrication"
    model = ifcopenshell.open(str(folder / "gridshell.ifc"))
    assert model.schema == "IFC4"
    cut = pd.read_csv(folder / "beams" / "cutlist.csv")
    cut = cut[cut["cut_length_mm"] > 0].set_index("id")
    panels = pd.read_csv(folder / "panels" / "panels.csv").set_index("id")
    polymesh = read_polymesh_obj(out / "05-optimize" / "gridshell.obj")
    members = {m.Name: m for m in model.by_type("IfcMember")}
    assert sorted(members) == sorted(cut.index)
    assert sorted(p.Name for p in model.by_type("IfcPlate")) == sorted(panels.index)
    assert len(model.by_type("IfcMechanicalFastener")) == polymesh.n_nodes
    assert not model.by_type("IfcBuildingElementProxy")
    settings = ifcopenshell.geom.settings()
    D, t = 1000 * project.section.diameter, 1000 * project.section.thickness
    area_mm2 = np.pi * t * (D - t)
    nodes_mm = 1000 * polymesh.nodes
    for name in list(members)[:25]:
        member, row = members[name], cut.loc[name]
        props = element.get_psets(member)["Pset_Gridshell"]
        assert props["CutLength_mm"] == pytest.approx(row.cut_length_mm) and props["Profile"] == row.profile
        assert props["Mass_kg"] == pytest.approx(row.mass_kg)
        volume_mm3 = shape.get_volume(ifcopenshell.geom.create_shape(settings, member).geometry) * 1e9
        assert volume_mm3 == pytest.approx(area_mm2 * row.cut_length_mm, rel=0.02)  # a polygon of the circle
        matrix = placement.get_local_placement(member.ObjectPlacement)  # mm
        a, b = int(row.start_node[1:]) - 1, int(row.end_node[1:]) - 1
        direction = (nodes_mm[b] - nodes_mm[a]) / np.linalg.norm(nodes_mm[b] - nodes_mm[a])
        assert matrix[:3, 2] == pytest.approx(direction, abs=1e-6)
        assert matrix[:3, 3] == pytest.approx(nodes_mm[a] + row.setback_start_mm * direction, abs=0.06)
    plate = model.by_type("IfcPlate")[0]
    assert element.get_psets(plate)["Pset_Gridshell"]["Sheet"] == panels.loc[plate.Name, "sheet"]
    joint = model.by_type("IfcMechanicalFastener")[0]
    assert element.get_psets(joint)["Pset_Gridshell"]["PartFile"] == f"joints/{joint.Name}.step"
    assert shape.get_volume(ifcopenshell.geom.create_shape(settings, joint).geometry) > 0


def test_writing_the_ifc_leaves_the_project_templates_importable(tmp_path):
    """ifcopenshell puts its own templates.py on sys.path while it works: after the model is written,
    a fresh process still finds the project's templates package (the report reads it)."""
    import subprocess
    import sys

    code = ("import numpy as np, importlib.resources as r\n"
            "from pathlib import Path\n"
            "from fabrication.ifc import IfcBeam, write_gridshell_ifc\n"
            "beam = IfcBeam(id='B0001', start_mm=np.zeros(3), direction=np.array([1.0, 0, 0]), cut_length_mm=100.0,\n"
            "               size_mm=10.0, wall_mm=1.0, profile='CHS 10x1', mass_kg=1.0)\n"
            f"write_gridshell_ifc(Path({str(tmp_path / 'a.ifc')!r}), project_name='t', beams=[beam], panels=[],\n"
            "                    joints=[], beam_material='S355')\n"
            "print(r.files('templates').joinpath('report.html').is_file())\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path,
                          env={**__import__("os").environ,
                               "PYTHONPATH": str(__import__("pathlib").Path(__file__).parents[1])})
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True"


def test_a_steel_nodes_tube_is_voided_by_its_end_slots(tmp_path):
    """A beam with end slots (steel fin plates) carries one IfcOpeningElement per slot, voiding it:
    ifcopenshell's geometry engine takes from the member the annulus's area within the slot's strip
    (closed form) times each slot's length."""
    import ifcopenshell.geom
    import ifcopenshell.util.shape as shape

    from fabrication.ifc import IfcBeam, write_gridshell_ifc

    D, t, cut, width, lengths = 48.3, 3.2, 1000.0, 20.0, (150.0, 100.0)
    common = dict(id="B0001", start_mm=np.zeros(3), direction=np.array([1.0, 0.0, 0.0]), cut_length_mm=cut,
                  size_mm=D, wall_mm=t, profile="CHS 48.3x3.2", mass_kg=4.0)
    sides = (np.array([0.0, 0.0, 1.0]), np.array([0.0, np.sqrt(0.5), np.sqrt(0.5)]))
    volumes = {}
    for name, beam in (("plain", IfcBeam(**common)),
                       ("slotted", IfcBeam(**common, slots=tuple(zip(sides, lengths)), slot_width_mm=width))):
        path = write_gridshell_ifc(tmp_path / f"{name}.ifc", project_name="slots", beams=[beam], panels=[], joints=[],
                                   beam_material="S355")
        model = ifcopenshell.open(str(path))
        member = model.by_type("IfcMember")[0]
        settings = ifcopenshell.geom.settings()
        settings.set("mesher-angular-deflection", 0.02)  # the circles as fine polygons (the default's
        settings.set("mesher-linear-deflection", 1e-4)   # 1 % of area moves a slot's removal by 12 %)
        volumes[name] = shape.get_volume(ifcopenshell.geom.create_shape(settings, member).geometry) * 1e9
        voids = model.by_type("IfcRelVoidsElement")
        assert len(voids) == (2 if name == "slotted" else 0)
        assert all(v.RelatingBuildingElement == member for v in voids)

    def strip(radius: float) -> float:  # a disc's area within |x| <= width / 2
        h = 0.5 * width
        return 2 * (h * np.sqrt(radius**2 - h**2) + radius**2 * np.arcsin(h / radius))

    removed = (strip(0.5 * D) - strip(0.5 * D - t)) * sum(lengths)
    assert volumes["plain"] - volumes["slotted"] == pytest.approx(removed, rel=0.005)


@pytest.mark.parametrize("wall", [0.0, 8.0])
def test_a_rectangular_member_is_its_section_turned_to_the_beams_up(tmp_path, wall):
    """A rectangular beam (glulam, or a hollow section) is swept as its rectangle: ifcopenshell's
    geometry engine gives the area times the cut length, and in world coordinates the member spans its
    height along the beam's up and its width across."""
    import ifcopenshell.geom
    import ifcopenshell.util.shape as shape

    from fabrication.ifc import IfcBeam, write_gridshell_ifc

    h, w, cut = 200.0, 100.0, 1500.0
    direction = np.array([1.0, 1.0, 0.5]) / 1.5
    up = np.array([-0.3, 0.1, 1.0])
    up -= (up @ direction) * direction
    up /= np.linalg.norm(up)
    beam = IfcBeam(id="B0001", start_mm=np.array([100.0, 200.0, 300.0]), direction=direction, cut_length_mm=cut,
                   size_mm=h, width_mm=w, up=up, wall_mm=wall, profile="GL24h 200x100", mass_kg=12.6)
    path = write_gridshell_ifc(tmp_path / "a.ifc", project_name="rect", beams=[beam], panels=[], joints=[],
                               beam_material="GL24h", beam_category="wood")
    model = ifcopenshell.open(str(path))
    member = model.by_type("IfcMember")[0]
    assert model.by_type("IfcMaterial")[0].Category == "wood"
    settings = ifcopenshell.geom.settings()
    settings.set("use-world-coords", True)
    geometry = ifcopenshell.geom.create_shape(settings, member).geometry
    area = h * w - (h - 2 * wall) * (w - 2 * wall) if wall else h * w
    assert shape.get_volume(geometry) * 1e9 == pytest.approx(area * cut, rel=1e-6)
    points = 1000 * np.asarray(geometry.verts).reshape(-1, 3)
    assert np.ptp(points @ up) == pytest.approx(h, abs=1e-3)
    assert np.ptp(points @ np.cross(up, direction)) == pytest.approx(w, abs=1e-3)
    assert np.ptp(points @ direction) == pytest.approx(cut, abs=1e-3)
