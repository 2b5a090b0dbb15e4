"""Fabrication speed: joints of a 500-node grid-shell (time per joint, both cores), and 1000
panel DXFs with sheet nesting (benchmarks/_bench_panels.py).

    .venv/bin/python benchmarks/fabrication_speed.py [--nodes 500] [--workers 2] [--peers 12] [--skip-panels]
    .venv/bin/python benchmarks/fabrication_speed.py --beams 4500   # beams.step only
    .venv/bin/python benchmarks/fabrication_speed.py --same-joints 3000   # grouping the joints only
    .venv/bin/python benchmarks/fabrication_speed.py --tube-clearance 3000   # the tubes' clearance only

Targets (issue 6): under 1 s per joint on average on 2 cores; 1000 panels with nesting under 30 s.
Peers, measured in the same run on the first ``--peers`` joints, one process, CPU seconds: the id
engraved by a boolean cut (as before the face-built pockets), and joints.step written by OCCT
from all the solids held in one process (as before the part files streamed by the parent).

``--beams N``: beams.step of a grid of about N beams (CHS 60.3 x 3.2), and in the same run the
same file with every tube extruded from one shared profile face, as it was before 2026-12-03
(its build and export grew as the square of the tubes).

``--same-joints N``: the grouping of equal joints (fabrication.joints.same_joints) on the joints of
a grid of about N nodes, and in the same run every joint compared with every group's first, as it
was before 2026-12-04, with both groupings compared.

``--tube-clearance N``: the tubes' clearance from other tubes and joints
(fabrication.tube_clearance) on a grid of about N nodes with 12 mm tubes in printed sockets, and
the peer in the same run: OCCT's boolean common of a tube and one joint part, timed on 20 of the
pairs whose bounding boxes overlap and multiplied out to all of them (the route of the joints'
own clash check, fabrication.clearance).
"""

from __future__ import annotations

import argparse
import collections
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from engine.geometry.parametric import mockup  # noqa: E402
from engine.remeshing.field import GuidingField  # noqa: E402
from engine.remeshing.voronoi import RemeshSettings, remesh  # noqa: E402
from engine.structure.grid_model import node_normals  # noqa: E402
from fabrication import joints  # noqa: E402
from fabrication.joints import JointSettings, build_joints  # noqa: E402


def _grid(nodes: int):
    surface = mockup().mesh
    n = surface.n_vertices
    field = GuidingField(size=np.ones(n), anisotropy=np.ones(n), direction=np.tile([1.0, 0, 0], (n, 1)),
                         normals=surface.vertex_normals)
    grid = remesh(surface, field, RemeshSettings(n_cells=max(8, nodes // 2), lloyd_iterations=20)).polymesh
    return grid, node_normals(grid, surface)


def bench_joints(nodes: int, workers: int) -> None:
    grid, normals = _grid(nodes)
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        reports = build_joints(grid, normals, 12.0, JointSettings(), Path(folder) / "joints", workers=workers,
                               combined_step=True)
        seconds = time.perf_counter() - start
        combined = Path(folder) / "joints" / "joints.step"  # not written over 30 MB
        size_mb = combined.stat().st_size / 1e6 if combined.is_file() else float("nan")
    ok = sum(r["ok"] for r in reports)
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"joints: {len(reports)} on {workers} worker(s) in {seconds:.1f} s = {seconds / len(reports):.2f} s "
          f"per joint (target < 1 s); {ok} pass every check; peak {peak_mib:.0f} MiB (parent); "
          f"joints.step {size_mb:.0f} MB; load average {load:.2f} before, {os.getloadavg()[0]:.2f} after")
    phases = {k: np.mean([r["seconds"][k] for r in reports]) for k in reports[0]["seconds"]}
    print("  per joint in a worker (s, wall): " + ", ".join(f"{k} {v:.3f}" for k, v in phases.items())
          + f"; engraving: {dict(collections.Counter(r.get('engraving') for r in reports))}")


def bench_peers(nodes: int, count: int) -> None:
    """CPU seconds per joint of the id engraved by faces against a boolean cut, and of joints.step
    streamed from part files against OCCT writing it from the solids, on the same joints."""
    from build123d import Compound, Location, export_step

    from fabrication.files import atomic_path
    from fabrication.step_assembly import StepAssemblyWriter

    grid, normals = _grid(nodes)
    geometries = joints.joint_geometry(grid, normals, 12.0)[:count]
    settings = JointSettings()

    def build_all() -> tuple[float, list]:
        started = time.process_time()
        solids = [joints.build_joint(g, settings)[0] for g in geometries]
        return (time.process_time() - started) / len(geometries), solids

    faces, solids = build_all()
    clear = joints._label_is_clear
    joints._label_is_clear = lambda *args, **kwargs: False
    try:
        boolean, _ = build_all()
    finally:
        joints._label_is_clear = clear
    print(f"peer, engraving ({count} joints, CPU s per joint, whole build): faces {faces:.3f}, "
          f"boolean cut {boolean:.3f} "
          f"({boolean / faces:.1f}x)")
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        ranges = joints._id_ranges(len(geometries))
        reports = [joints._build_and_write((g, settings, str(folder), str(folder), *ranges[k]))
                   for k, g in enumerate(geometries)]
        started = time.process_time()
        with atomic_path(folder / "joints.step") as tmp, open(tmp, "w", encoding="utf-8") as combined:
            writer = StepAssemblyWriter(combined, "joints")
            for report in reports:
                writer.add_file(Path(report["_part"]))
            writer.finish([r["id"] for r in reports])
        streamed = time.process_time() - started
        started = time.process_time()
        placed = []
        for g, solid, report in zip(geometries, solids, reports):
            part = solid.moved(Location(tuple(map(float, g.position_mm))))
            part.label = report["id"]
            placed.append(part)
        assembly = Compound(children=placed)
        assembly.label = "joints"
        export_step(assembly, str(folder / "occt.step"))
        occt = time.process_time() - started
        # the part files themselves are written in the workers (STEP of each joint, then renumbered)
        prepared = np.mean([r["seconds"]["check_and_step"] for r in reports])
    print(f"peer, joints.step ({count} joints, parent CPU s per joint): "
          f"streamed from part files {streamed / count:.4f}, "
          f"OCCT from the solids {occt / count:.3f} ({occt / max(streamed, 1e-9):.0f}x); the workers spend "
          f"{prepared:.3f} s per joint on checks, STEP and its part file")


def bench_beams_step(beams: int) -> None:
    """Seconds of beams.step for a grid of about ``beams`` beams, the tubes' profile copied per tube
    (the product) and shared by all (the scheme before), with the files' sizes."""
    import pandas as pd

    from fabrication import beams as beams_module

    grid, _ = _grid(max(8, (2 * beams) // 3))
    lengths = 1000 * grid.beam_lengths
    table = pd.DataFrame({"id": [f"B{k + 1:04d}" for k in range(len(lengths))], "cut_length_mm": 0.7 * lengths,
                          "setback_start_mm": 0.15 * lengths})
    print(f"beams.step, {len(lengths)} tubes CHS 60.3 x 3.2:")
    with tempfile.TemporaryDirectory() as folder:
        for name, per_tube in (("profile copied per tube", True), ("one shared profile", False)):
            start = time.perf_counter()
            path = beams_module.write_beams_step(grid, table, Path(folder) / "beams.step", outer_size_mm=60.3,
                                                 wall_mm=3.2, profile_per_tube=per_tube)
            print(f"  {name:24s} {time.perf_counter() - start:7.1f} s  {path.stat().st_size / 1e6:6.1f} MB",
                  flush=True)


def bench_same_joints(nodes: int) -> None:
    """Seconds of same_joints on a grid of about ``nodes`` nodes, and of comparing every joint with
    every group's first member (the peer, as before); both must give the same groups."""
    grid, normals = _grid(nodes)
    geometries = joints.joint_geometry(grid, normals, 12.0)
    start = time.perf_counter()
    groups = joints.same_joints(geometries)
    ours = time.perf_counter() - start
    described = [joints._beams_about_axis(g) for g in geometries]
    scale = np.array([1e-3, 1e-3, 1e-3])
    start = time.perf_counter()
    every: list[list[int]] = []
    for k, d in enumerate(described):
        for group in every:
            a = described[group[0]]
            if len(a) == len(d) and any(np.all(np.abs(a - np.roll(d, s, axis=0)) <= scale) for s in range(len(d))):
                group.append(k)
                break
        else:
            every.append([k])
    peer = time.perf_counter() - start
    same = groups == [[joints.joint_name(geometries[k].node) for k in g] for g in every if len(g) > 1]
    print(f"same joints, {len(geometries)} joints ({len(groups)} groups): k-d tree neighbours {ours:.3f} s, "
          f"every group's first (peer) {peer:.1f} s ({peer / max(ours, 1e-9):.0f}x); same groups: {same}")


def bench_tube_clearance(nodes: int) -> None:
    """Seconds of tube_clashes on a grid of about ``nodes`` nodes, tubes a twentieth of the mean
    beam wide (as a 60 mm tube on 1.2 m beams), and the OCCT estimate."""
    from OCP.Bnd import Bnd_Box
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Common
    from OCP.BRepBndLib import BRepBndLib
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt
    from scipy.spatial import cKDTree

    from fabrication.beams import BeamSettings, cut_list, tube_axes_mm
    from fabrication.tube_clearance import tube_clashes

    grid, normals = _grid(nodes)
    size = float(1000 * grid.beam_lengths.mean() / 20)
    settings = JointSettings()
    geometries = joints.joint_geometry(grid, normals, size)
    nodes_mm = 1000 * grid.nodes
    e = grid.edges
    # the tubes as the fabrication stage cuts them
    table = cut_list(grid, normals, BeamSettings(profile_name="tube", material_name="steel", density=7850.0,
                                                 outer_size_mm=size), settings)
    cut = table["cut_length_mm"].to_numpy()
    starts, direction = tube_axes_mm(grid, table["setback_start_mm"].to_numpy())
    ends = starts + cut[:, None] * direction
    radii = np.full(len(e), 0.5 * size)
    started = time.perf_counter()
    parts = {g.node: joints.joint_parts(g, settings) for g in geometries}
    clashes = tube_clashes(nodes_mm, e, starts, ends, radii, parts, [f"B{k + 1:04d}" for k in range(len(e))],
                           {g.node: joints.joint_name(g.node) for g in geometries})
    ours = time.perf_counter() - started

    def cylinder(base, axis, radius, height):
        return BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(*map(float, base)), gp_Dir(*map(float, axis))),
                                        float(radius), float(height)).Shape()

    def box(shape):
        b = Bnd_Box()
        BRepBndLib.Add_s(shape, b)
        return b

    present = np.flatnonzero(cut > 0)
    tubes = {i: cylinder(starts[i], direction[i], 0.5 * size, cut[i]) for i in present}
    rows = [(g.node, row) for g in geometries for row in parts[g.node].cylinders]
    joint_shapes = [cylinder(nodes_mm[n] + row[:3], row[3:6], row[7], row[6]) for n, row in rows]
    centres = np.array([nodes_mm[n] + row[:3] + 0.5 * row[6] * row[3:6] for n, row in rows])
    reach = max(float(np.hypot(0.5 * row[6], row[7])) for _, row in rows)
    tree = cKDTree(centres)
    part_boxes = [box(p) for p in joint_shapes]
    pairs = []
    for i in present:
        tube_box = box(tubes[i])
        middle = 0.5 * (starts[i] + ends[i])
        for j in tree.query_ball_point(middle, 0.5 * cut[i] + 0.5 * size + reach):
            if not tube_box.IsOut(part_boxes[j]):
                pairs.append((i, j))
    sample = pairs[:: max(1, len(pairs) // 20)][:20]
    started = time.perf_counter()
    for i, j in sample:
        BRepAlgoAPI_Common(tubes[i], joint_shapes[j]).Shape()
    per_pair = (time.perf_counter() - started) / max(len(sample), 1)
    print(f"tube clearance, {len(e)} tubes of {size:.0f} mm and {len(geometries)} joints: {ours:.2f} s, "
          f"{len(clashes)} clashes; OCCT booleans (peer) on the {len(pairs)} tube and joint part pairs whose "
          f"boxes overlap (tubes against tubes not counted): {per_pair * 1e3:.1f} ms a pair, "
          f"{per_pair * len(pairs):.0f} s estimated ({len(sample)} timed)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, default=500)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--peers", type=int, default=12, help="joints for the peer figures (0: none)")
    parser.add_argument("--skip-panels", action="store_true")
    parser.add_argument("--beams", type=int, default=0, help="only beams.step of a grid of about this many beams")
    parser.add_argument("--same-joints", type=int, default=0, help="only the grouping of equal joints, about N nodes")
    parser.add_argument("--tube-clearance", type=int, default=0, help="only the tubes' clearance, about N nodes")
    args = parser.parse_args()
    if args.tube_clearance:
        bench_tube_clearance(args.tube_clearance)
        return 0
    if args.same_joints:
        bench_same_joints(args.same_joints)
        return 0
    if args.beams:
        bench_beams_step(args.beams)
        return 0
    bench_joints(args.nodes, args.workers)
    if args.peers:
        bench_peers(args.nodes, args.peers)
    if not args.skip_panels:
        from _bench_panels import bench_panels

        bench_panels()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
