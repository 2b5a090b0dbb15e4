"""The tubes' clearance from other tubes and from the joints they pass: against closed forms and
against OCCT's booleans of the joints as built."""

from __future__ import annotations

import numpy as np
import pytest

from fabrication.joints import JointGeometry, JointSettings, build_joint_and_blank, joint_parts
from fabrication.tube_clearance import TUBE_CLASH_MM, tube_clashes


def _two_tubes(gap_mm: float, radius_mm: float, angle_deg: float = 90.0):
    """Two tubes 1 m long crossing at ``angle_deg`` with axes ``gap_mm`` apart."""
    turn = np.radians(angle_deg)
    across = 500 * np.array([np.cos(turn), np.sin(turn), 0.0])
    nodes = np.array([[-500, 0, 0], [500, 0, 0], [0, 0, gap_mm] - across, [0, 0, gap_mm] + across])
    beams = np.array([[0, 1], [2, 3]])
    starts, ends = 0.9 * nodes[beams[:, 0]], 0.9 * nodes[beams[:, 1]]
    starts[1, 2] = ends[1, 2] = gap_mm
    return tube_clashes(nodes, beams, starts, ends, np.full(2, radius_mm), {}, ["B0001", "B0002"], {})


@pytest.mark.parametrize("angle_deg", [90.0, 30.0, 5.0])
@pytest.mark.parametrize("gap_mm", [20.0, 45.0, 59.0, 59.6, 70.0])
def test_two_crossing_tubes_overlap_by_their_radii_less_the_axes_distance(gap_mm, angle_deg):
    clashes = _two_tubes(gap_mm, 30.0, angle_deg)
    expected = 60.0 - gap_mm
    if expected <= TUBE_CLASH_MM:
        assert clashes == []
    else:
        assert [c.to_dict()["parts"] for c in clashes] == [["B0001", "B0002"]]
        assert clashes[0].depth_mm == pytest.approx(expected, abs=0.05)


def test_tubes_that_meet_at_a_node_are_left_to_the_joint():
    nodes = np.array([[0.0, 0, 0], [1000, 0, 0], [1000, 10, 0]])
    beams = np.array([[0, 1], [0, 2]])
    starts, ends = nodes[beams[:, 0]] + 0.0, nodes[beams[:, 1]] + 0.0
    assert tube_clashes(nodes, beams, starts, ends, np.full(2, 20.0), {}, ["B0001", "B0002"], {}) == []


def _rod(start: np.ndarray, end: np.ndarray, radius: float):
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    axis = (end - start) / np.linalg.norm(end - start)
    return BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(*map(float, start)), gp_Dir(*map(float, axis))),
                                    float(radius), float(np.linalg.norm(end - start))).Shape()


def _common_volume(a, b) -> float:
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Common
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(BRepAlgoAPI_Common(a, b).Shape(), props)
    return props.Mass()


@pytest.mark.parametrize("kind", ["socket", "steel"])
def test_a_tube_passing_a_joint_clashes_where_occt_finds_their_common_solid(kind):
    """Rods of a tube's radius on seeded random lines near a joint built as the fabrication builds
    it (hub, sleeves with bores and pin holes, or fin plates with bolt holes): the closed form's
    verdict is OCCT's (common volume over 1 mm3) wherever the depth is not within a millimetre of
    the threshold, and both verdicts occur."""
    size = 30.0
    directions = np.array([[1.0, 0, 0], [-0.5, np.sqrt(3) / 2, 0.1], [-0.5, -np.sqrt(3) / 2, -0.1]])
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    geometry = JointGeometry(node=0, position_mm=np.zeros(3), directions=directions, axis=np.array([0.0, 0, 1]),
                             beam_size_mm=size)
    settings = JointSettings(kind=kind, engrave=False)
    _, solid, _ = build_joint_and_blank(geometry, settings)
    parts = joint_parts(geometry, settings)
    reach = float(np.abs(parts.cylinders[:, 6]).max() + 60.0)
    rng = np.random.default_rng(7)
    radius = 0.5 * size
    verdicts = []
    for _ in range(40):
        centre = rng.uniform(-0.6, 0.6, 3) * reach * np.array([1, 1, 0.3])
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        start, end = centre - 2 * reach * direction, centre + 2 * reach * direction
        nodes = np.array([[0.0, 0, 0], start - direction, end + direction])
        clashes = tube_clashes(nodes, np.array([[1, 2]]), start[None], end[None], np.array([radius]),
                               {0: parts}, ["B0001"], {0: "J0001"})
        depth = clashes[0].depth_mm if clashes else None
        near = [c for c in tube_clashes(nodes, np.array([[1, 2]]), start[None], end[None],
                                        np.array([radius + 1.0]), {0: parts}, ["B0001"], {0: "J0001"})]
        far = tube_clashes(nodes, np.array([[1, 2]]), start[None], end[None], np.array([radius - 1.0]),
                           {0: parts}, ["B0001"], {0: "J0001"})
        if bool(near) != bool(far):
            continue                                   # within a millimetre of the threshold
        occt = _common_volume(solid.wrapped, _rod(start, end, radius)) > 1.0
        verdicts.append(occt)
        assert (depth is not None) == occt, (centre, direction, depth)
    assert 5 <= sum(verdicts) <= len(verdicts) - 5


def test_a_tube_through_a_third_joint_is_named_with_it():
    settings = JointSettings()
    geometry = JointGeometry(node=2, position_mm=np.zeros(3), directions=np.array([[1.0, 0, 0], [0, 1.0, 0]]),
                             axis=np.array([0.0, 0, 1]), beam_size_mm=12.0)
    nodes = np.array([[-400.0, 5, 0], [400, 5, 0], [0, 0, 0], [0, 400, 0]])
    beams = np.array([[0, 1], [2, 3]])
    starts = np.array([[-380.0, 5, 0], [0, 30, 0]])
    ends = np.array([[380.0, 5, 0], [0, 380, 0]])
    clashes = tube_clashes(nodes, beams, starts, ends, np.full(2, 6.0), {2: joint_parts(geometry, settings)},
                           ["B0001", "B0002"], {2: "J0003"})
    assert {tuple(c.to_dict()["parts"]) for c in clashes} >= {("B0001", "J0003")}
    worst = next(c for c in clashes if c.other == "J0003")
    hub = joint_parts(geometry, settings).cylinders[0]
    # the rod's axis 5 mm off the hub's centre: it reaches the hub's radius plus its own less 5
    assert worst.depth_mm == pytest.approx(6.0 + hub[7] - 5.0, abs=0.1)  # sampled a quarter radius apart


@pytest.mark.parametrize("height_m", [0.01, 0.04])
def test_the_stage_finds_a_tube_through_a_joint_of_its_grid_and_names_the_setting(height_m):
    """A grid whose node D sits over the middle of beam A-B (a fold of the surface), 12 mm tubes in
    printed sockets: the fabrication stage's check, on the cut list's tubes and the joints as built,
    reports A-B running into D's joint at 10 mm (D's hub reaches 8.8 mm down, the tube 6 mm up) and
    nothing at 40 mm; its finding names the parts, the depth and a TOML key."""
    from engine.mesh import PolyMesh
    from fabrication.beams import cut_list
    from fabrication.joints import joint_geometry
    from fabrication.settings import BeamSettings
    from workflow.stages.fabrication import _tube_clash_finding, _tube_clashes

    grid = PolyMesh(nodes=np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0, height_m]]),
                    faces=[[0, 1, 2, 3], [0, 4, 1]])
    normals = np.tile([0.0, 0, 1], (grid.n_nodes, 1))
    settings = JointSettings()
    table = cut_list(grid, normals, BeamSettings(profile_name="CHS 12", material_name="steel", density=7850.0,
                                                 outer_size_mm=12.0), settings)
    sizes = np.full(len(grid.edges), 12.0)
    geometries = joint_geometry(grid, normals, sizes)
    clashes = _tube_clashes(grid, table, geometries, settings, sizes, None)
    if height_m > 0.03:
        assert clashes == []
        return
    e = [tuple(sorted(edge)) for edge in grid.edges.tolist()]
    ab = table["id"].iloc[e.index((0, 1))]
    assert [c["parts"] for c in clashes] == [[ab, "J0005"]]
    hub = joint_parts(next(g for g in geometries if g.node == 4), settings).cylinders[0]
    assert clashes[0]["depth_mm"] == pytest.approx(6.0 + 0.5 * hub[6] - 1000 * height_m, abs=0.1)
    finding = _tube_clash_finding(clashes[0]).to_dict()
    assert finding["kind"] == "tube_clash" and finding["parts"] == [ab, "J0005"]
    assert "[section] diameter" in finding["fix"]
