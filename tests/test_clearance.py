"""fabrication.clearance against closed forms: boxes, sphere lenses, touching and far-apart solids,
the volume threshold, STEP files, and two real socket joints on a short and a long beam."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fabrication import clearance


def _box(size, at=(0.0, 0.0, 0.0)):
    from build123d import Box, Pos

    return Pos(*at) * Box(*size)


def _sphere(radius, at=(0.0, 0.0, 0.0)):
    from build123d import Pos, Sphere

    return Pos(*at) * Sphere(radius)


@pytest.fixture
def common_calls(monkeypatch):
    """The pairs that reach the narrow phase (the boolean)."""
    calls = []
    original = clearance._common

    def counted(a, b):
        calls.append((a, b))
        return original(a, b)

    monkeypatch.setattr(clearance, "_common", counted)
    return calls


def test_overlapping_boxes_share_the_product_of_their_overlaps():
    # centred boxes 10 x 20 x 30 offset by (7, 5, -4): overlaps 3, 15, 26
    clashes = clearance.joint_clashes({"J0001": _box((10, 20, 30)), "J0002": _box((10, 20, 30), (7, 5, -4))})
    assert [c["parts"] for c in clashes] == [["J0001", "J0002"]]
    assert clashes[0]["volume_mm3"] == pytest.approx(3 * 15 * 26, rel=1e-9)
    assert clashes[0]["depth_mm"] == pytest.approx(3.0, abs=1e-6)


@pytest.mark.parametrize("direction", [(1, 0, 0), (1, 2, 2), (3, -1, 0.5)])
def test_two_spheres_share_a_lens(direction):
    r, d = 10.0, 12.0
    at = d * np.asarray(direction, float) / np.linalg.norm(direction)
    clashes = clearance.joint_clashes({"J0001": _sphere(r), "J0002": _sphere(r, at).wrapped})  # raw OCP too
    assert len(clashes) == 1
    assert clashes[0]["volume_mm3"] == pytest.approx(math.pi * (4 * r + d) * (2 * r - d) ** 2 / 12, rel=1e-5)
    assert clashes[0]["depth_mm"] == pytest.approx(2 * r - d, abs=0.05)


def test_touching_solids_do_not_clash(common_calls):
    solids = {"J0001": _box((10, 10, 10)), "J0002": _box((10, 10, 10), (10, 0, 0)),  # a shared face
              "J0003": _sphere(5, (-2, 0, 10))}  # touches J0001's top face at a point
    assert clearance.joint_clashes(solids) == []
    assert len(common_calls) == 2  # their boxes touch, so both pairs were tested


def test_far_apart_solids_never_reach_the_boolean(common_calls):
    solids = {f"J{k + 1:04d}": _box((10, 10, 10), (30.0 * k, 0, 0)) for k in range(6)}
    solids["J0007"] = _box((10, 10, 10), (0, 0, 5))  # overlaps J0001 by 10 x 10 x 5
    clashes = clearance.joint_clashes(solids)
    assert len(common_calls) == 1
    assert clashes == [{"parts": ["J0001", "J0007"], "volume_mm3": pytest.approx(500.0),
                        "depth_mm": pytest.approx(5.0)}]


def test_only_the_given_pairs_are_tested(common_calls):
    solids = {"J0001": _box((10, 10, 10)), "J0002": _box((10, 10, 10), (5, 0, 0)),
              "J0003": _box((10, 10, 10), (0, 5, 0))}
    clashes = clearance.joint_clashes(solids, pairs=[("J0002", "J0003")])
    assert len(common_calls) == 1
    assert [c["parts"] for c in clashes] == [["J0002", "J0003"]]
    assert clashes[0]["volume_mm3"] == pytest.approx(250.0)


def test_a_small_overlap_is_below_the_default_threshold():
    solids = {"J0001": _box((10, 10, 10)), "J0002": _box((10, 10, 10), (9.995, 0, 0))}  # 0.005 x 10 x 10 = 0.5 mm3
    assert clearance.joint_clashes(solids) == []
    clashes = clearance.joint_clashes(solids, min_volume_mm3=0.1)
    assert clashes[0]["volume_mm3"] == pytest.approx(0.5, rel=1e-6)


def test_clashes_are_sorted_by_volume_and_a_failed_boolean_is_reported(monkeypatch):
    solids = {"J0001": _box((10, 10, 10)), "J0002": _box((10, 10, 10), (8, 0, 0)),
              "J0003": _box((10, 10, 10), (-5, 0, 0)), "J0004": _box((10, 10, 10), (0, 30, 0)),
              "J0005": _box((10, 10, 10), (0, 35, 0))}
    original = clearance._common

    def failing(a, b):
        if a.IsSame(solids["J0004"].wrapped):
            raise RuntimeError("BRepAlgoAPI_Common is not done")
        return original(a, b)

    monkeypatch.setattr(clearance, "_common", failing)
    clashes = clearance.joint_clashes(solids)
    assert [c["parts"] for c in clashes] == [["J0001", "J0003"], ["J0001", "J0002"], ["J0004", "J0005"]]
    assert [c["volume_mm3"] for c in clashes[:2]] == [pytest.approx(500.0), pytest.approx(200.0)]
    assert clashes[2]["volume_mm3"] is None and "not done" in clashes[2]["error"]


def test_broad_phase_matches_all_pairs():
    rng = np.random.default_rng(3)
    low = rng.uniform(0, 1000, (400, 3))
    boxes = np.hstack([low, low + rng.uniform(5, 60, (400, 3))])
    boxes[7] = [-500, -500, -500, 2000, 2000, 2000]  # one huge box overlaps all
    lo, hi = boxes[:, :3], boxes[:, 3:]
    expected = np.argwhere(np.triu(np.all((lo[:, None] <= hi[None]) & (lo[None] <= hi[:, None]), axis=2), 1))
    assert np.array_equal(clearance.overlapping_pairs(boxes), expected)


def test_clashes_from_step_files(tmp_path):
    from build123d import export_step

    solids = {"J0001": _box((10, 20, 30)), "J0002": _box((10, 20, 30), (7, 5, -4)), "J0003": _sphere(5, (200, 0, 0))}
    for name, solid in solids.items():
        solid.label = name
        export_step(solid, str(tmp_path / f"{name}.step"))
    export_step(solids["J0001"], str(tmp_path / "joints.step"))  # the combined file is not a joint
    assert clearance.step_joint_names(tmp_path) == ["J0001", "J0002", "J0003"]
    clashes = clearance.joint_clashes_from_step(tmp_path)
    assert [c["parts"] for c in clashes] == [["J0001", "J0002"]]
    assert clashes[0]["volume_mm3"] == pytest.approx(1170.0, rel=1e-6)
    assert clearance.joint_clashes_from_step(tmp_path, ["J0002", "J0003"]) == []


@pytest.fixture(scope="module")
def socket_joints():
    """Two socket joints at the ends of a beam along x (each with two more beams at +-120 deg), built at
    the origin: (solid of the joint whose beam goes +x, solid of the one whose beam goes -x)."""
    from fabrication.joints import JointGeometry, JointSettings, build_joint

    angles = np.radians([0.0, 120.0, -120.0])
    ahead = np.stack([np.cos(angles), np.sin(angles), np.zeros(3)], axis=1)
    built = []
    for node, directions in ((0, ahead), (1, -ahead)):
        geometry = JointGeometry(node=node, position_mm=np.zeros(3), directions=directions,
                                 axis=np.array([0.0, 0.0, 1.0]), beam_size_mm=12.0)
        built.append(build_joint(geometry, JointSettings())[0])
    return built


@pytest.mark.parametrize("beam_mm", [40.0, 300.0])
def test_socket_joints_on_a_short_beam_clash(socket_joints, beam_mm, common_calls):
    from build123d import Pos

    first, second = socket_joints
    clashes = clearance.joint_clashes({"J0001": first, "J0002": Pos(beam_mm, 0, 0) * second})
    if beam_mm < 100:
        # each sleeve reaches 34 mm: both tubes' walls (radii 6.3 to 8.3) share x 10-30 at least
        assert [c["parts"] for c in clashes] == [["J0001", "J0002"]]
        assert clashes[0]["volume_mm3"] > 0.9 * math.pi * (8.3**2 - 6.3**2) * 20
        assert clashes[0]["depth_mm"] > 1.0
    else:
        assert clashes == [] and common_calls == []


def test_a_solid_inside_another_clashes_by_its_own_volume():
    clashes = clearance.joint_clashes({"J0001": _box((10, 10, 10)), "J0002": _sphere(2, (1, 1, 1))})
    assert clashes[0]["volume_mm3"] == pytest.approx(4 / 3 * math.pi * 2**3, rel=1e-6)
    assert clashes[0]["depth_mm"] == pytest.approx(4.0, abs=0.05)


def _write_joints(folder, solids, stl=False):
    from build123d import export_step, export_stl

    for name, solid in solids.items():
        solid.label = name
        export_step(solid, str(folder / f"{name}.step"))
        if stl:
            export_stl(solid, str(folder / f"{name}.stl"), tolerance=0.05, angular_tolerance=0.3)


def test_boxes_from_stl_read_only_the_overlapping_joints(tmp_path, monkeypatch):
    solids = {f"J{k + 1:04d}": _sphere(5, (30.0 * k, 0, 0)) for k in range(5)}
    solids["J0006"] = _sphere(5, (8, 0, 0))  # overlaps J0001 by a lens: r 5, d 8
    _write_joints(tmp_path, solids, stl=True)
    (tmp_path / "J0005.stl").unlink()  # no STL: its STEP file gives the box
    read = []
    original = clearance.read_joint_step
    monkeypatch.setattr(clearance, "read_joint_step", lambda path: read.append(path.stem) or original(path))
    clashes = clearance.joint_clashes_from_step(tmp_path, stl_boxes=True)
    assert [c["parts"] for c in clashes] == [["J0001", "J0006"]]
    assert clashes[0]["volume_mm3"] == pytest.approx(math.pi * (4 * 5 + 8) * (2 * 5 - 8) ** 2 / 12, rel=1e-5)
    assert sorted(read) == ["J0001", "J0005", "J0006"]


def test_parallel_gives_the_same_clashes(tmp_path):
    solids = {f"J{k + 1:04d}": _box((10, 10, 10), (9.0 * k, 0, 0)) for k in range(10)}  # neighbours share 1 x 10 x 10
    _write_joints(tmp_path, solids)
    serial = clearance.joint_clashes_from_step(tmp_path)
    assert len(serial) == 9 and all(c["volume_mm3"] == pytest.approx(100.0) for c in serial)
    assert clearance.joint_clashes_parallel(tmp_path, workers=2) == serial
