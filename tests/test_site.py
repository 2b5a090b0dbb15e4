"""A roof in site coordinates: its fabrication files in a local frame from a stated origin
(fabrication.site), re-read with readers other than the writers (ifcopenshell's placements, trimesh)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fabrication.site import FAR_FROM_ORIGIN_M, site_origin_m

SITE = np.array([512345.3, 5412345.8, 231.4])  # metres: as a survey or UTM frame gives them


def test_a_grid_near_the_origin_keeps_its_coordinates():
    nodes = np.array([[-40.0, -30.0, 0.0], [40.0, 30.0, 12.0], [0.0, 0.0, 6.0]])
    assert site_origin_m(nodes).tolist() == [0.0, 0.0, 0.0]
    at_the_limit = np.array([[FAR_FROM_ORIGIN_M - 1.0, 0.0, 0.0], [FAR_FROM_ORIGIN_M - 21.0, 20.0, 5.0]])
    assert not site_origin_m(at_the_limit).any()


def test_a_far_grid_starts_at_its_plan_centre_and_lowest_point_in_whole_metres():
    nodes = SITE + np.array([[-8.2, -6.1, 0.3], [8.2, 6.1, 4.0], [1.0, 0.5, 2.0]])
    origin = site_origin_m(nodes)
    assert origin.tolist() == [512345.0, 5412346.0, 232.0]
    local = nodes - origin
    assert np.abs(local).max() < 10.0


def test_the_ifc_site_stands_at_the_origin_and_its_parts_from_it(tmp_path):
    """ifcopenshell's placement utilities (not the writer) put a member given from the site origin
    back where the beam is in the surface's coordinates."""
    ifcopenshell = pytest.importorskip("ifcopenshell")
    import ifcopenshell.util.placement as placement

    from fabrication.ifc import IfcBeam, write_gridshell_ifc

    origin_m = np.array([512345.0, 5412346.0, 232.0])
    start_mm = np.array([1234.5, -2500.25, 1800.0])
    beam = IfcBeam(id="B0001", start_mm=start_mm, direction=np.array([0.0, 1.0, 0.0]), cut_length_mm=900.0,
                   size_mm=48.3, wall_mm=3.2, profile="CHS 48.3x3.2", mass_kg=3.0)
    for origin in (origin_m, None):
        path = write_gridshell_ifc(tmp_path / "site.ifc", project_name="site", beams=[beam], panels=[], joints=[],
                                   beam_material="S355", site_origin_m=origin)
        model = ifcopenshell.open(str(path))
        member = model.by_type("IfcMember")[0]
        at = placement.get_local_placement(member.ObjectPlacement)[:3, 3]
        expected = start_mm + (0.0 if origin is None else 1000.0 * origin)
        assert at == pytest.approx(expected, abs=1e-6)
        site = model.by_type("IfcSite")[0]
        assert (site.ObjectPlacement is None) == (origin is None)


@pytest.mark.slow
def test_a_roof_in_site_coordinates_is_built_to_the_end(tmp_path):
    """The small mock-up moved 5 400 km from the origin: every stage completes (the panels' faces
    in gridshell.step were not planar to OCCT at those millimetres), the printed sockets' STL files
    are local and watertight, and the IFC places the members where the grid is."""
    import trimesh

    from workflow.progress import Progress
    from workflow.runner import run_project
    from workflow.stages import STAGES
    from workflow.stages.polymesh_io import read_polymesh_obj
    from workflow.stages.surface import build_surface

    from .conftest import small_project

    project = small_project()
    surface = build_surface(project)[0]
    path = tmp_path / "roof.ply"
    trimesh.Trimesh(surface.vertices + SITE, surface.faces, process=False).export(path)
    # the mock-up's symmetry planes move with it (through the origin they are refused: the roof is
    # not symmetric about them)
    planes = [plane.model_copy(update={"point": [float(c) for c in np.add(plane.point, SITE)]})
              for plane in project.field.symmetry_planes]
    project = project.model_copy(update={
        "surface": project.surface.model_copy(update={"template": None, "file": str(path), "parameters": {}}),
        "supports": [project.supports[0].model_copy(update={"select": "boundary"})],
        "field": project.field.model_copy(update={"symmetry_planes": planes})})
    out = tmp_path / "out"
    summary = run_project(project, out, STAGES, progress=Progress(enabled=False))
    assert summary.message is None, summary.message
    assert (out / "report.html").is_file()
    fabrication = json.loads((out / "07-fabrication" / "fabrication.json").read_text())
    nodes = read_polymesh_obj(out / "05-optimize" / "gridshell.obj").nodes  # in the surface's frame
    low, high = nodes.min(axis=0), nodes.max(axis=0)
    origin = np.round([0.5 * (low[0] + high[0]), 0.5 * (low[1] + high[1]), low[2]])
    assert fabrication["site_origin_m"] == origin.tolist()
    assert not fabrication["joint_problems"]
    stl = trimesh.load(out / "07-fabrication" / "joints" / "J0001.stl")
    assert stl.is_watertight and np.abs(stl.vertices).max() < 5000.0  # mm, from the site origin
    ifcopenshell = pytest.importorskip("ifcopenshell")
    import ifcopenshell.util.placement as placement

    model = ifcopenshell.open(str(out / "07-fabrication" / "gridshell.ifc"))
    joints = {j.Name: placement.get_local_placement(j.ObjectPlacement)[:3, 3] for j in
              model.by_type("IfcMechanicalFastener")}
    assert joints["J0001"] == pytest.approx(1000.0 * nodes[0], abs=0.01)
