"""Assembly sequence: every part once, every step connected, panels after their ring,
props where the partial structure is a mechanism; the partial-frame analysis against a
closed-form cantilever; files re-read."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pandas as pd
import pytest

from engine.errors import InputError
from engine.mesh import PolyMesh
from fabrication.assembly import (
    _build_model,
    deflections_without_props,
    partial_frame_deflection,
    plan_assembly,
    step_groups,
    step_image_name,
    write_assembly,
)
from fabrication.drawings import beam_id, node_id, panel_id
from tests.test_panels import hex_polymesh

# timber 40 x 20 mm (C24-like: E = 11 GPa, G = 0.69 GPa, 420 kg/m^3)
B, H = 0.02, 0.04
TIMBER = dict(E=11e9, G=0.69e9, A=B * H, Iy=B * H**3 / 12, Iz=H * B**3 / 12, J=0.229 * H * B**3,
              mass_per_length=420 * B * H)


def _ring_beams(mesh: PolyMesh) -> list[set[int]]:
    lookup = {tuple(e): k for k, e in enumerate(mesh.edges.tolist())}
    return [{lookup[tuple(sorted((int(a), int(b))))] for a, b in zip(f, np.roll(f, -1))} for f in mesh.faces]


def check_sequence(sequence, mesh: PolyMesh) -> None:
    beams = [b for s in sequence.steps for b in s.beams]
    panels = [f for s in sequence.steps for f in s.panels]
    assert sorted(beams) == list(range(len(mesh.edges)))  # every beam exactly once
    assert sorted(panels) == list(range(mesh.n_faces))  # every panel exactly once
    rings = _ring_beams(mesh)
    built: set[int] = set()
    supports = set(sequence.support_nodes.tolist())
    joined: set[int] = set()
    for s in sequence.steps:
        built |= set(s.beams)
        graph = nx.Graph([tuple(mesh.edges[k]) for k in built])
        assert nx.is_connected(graph), f"step {s.step}: the built structure falls apart"
        assert graph.nodes & (supports | set(s.props)), f"step {s.step}: nothing holds the structure"
        for f in s.panels:
            assert rings[f] <= built, f"step {s.step}: panel {f} before its ring of beams"
        new = set(graph.nodes) - joined
        assert set(s.nodes_built) == new
        joined |= new
        assert all(p in graph.nodes for p in s.props)
        # NaN: a step inside a run of steps, not analysed on its own (plan_assembly's analysed_runs)
        assert np.isnan(s.largest_deflection_m) or np.isfinite(s.largest_deflection_m) and s.largest_deflection_m >= 0
        # no props: the pinned supports reached must hold all rigid-body motions of a frame
        # with rigid joints, i.e. at least three of them not on one line
        if not s.props:
            held = mesh.nodes[sorted(supports & set(graph.nodes))]
            assert len(held) >= 3
            assert np.linalg.matrix_rank(held[1:] - held[0], tol=1e-9) >= 2


def test_cantilever_closed_form():
    # one beam of the cell, fully fixed at node 0 by a prop: the lumped half-weight at the
    # free end P = m g L / 2 gives the tip deflection P L^3 / (3 E Iy) (Euler-Bernoulli)
    nodes = np.array([[0.0, 0.0, 0.0], [0.8, 0.0, 0.0], [0.0, 0.6, 0.0]])
    mesh = PolyMesh(nodes=nodes, faces=(np.array([0, 1, 2]),))
    model = _build_model(mesh, np.array([2]), TIMBER, 0.0, "pinned")
    k = int(np.flatnonzero((mesh.edges == [0, 1]).all(axis=1))[0])
    deflection, field = partial_frame_deflection(model, np.array([k]), np.zeros(0, np.int64), [0])
    L = 0.8
    P = 0.5 * TIMBER["mass_per_length"] * 9.81 * L
    assert deflection == pytest.approx(P * L**3 / (3 * TIMBER["E"] * TIMBER["Iy"]), rel=1e-6)
    assert field[0] == 0.0 and field[2] == 0.0 and field[1] == pytest.approx(deflection)
    # a panel load on the triangle adds (q A / 3) at each node: the whole cell on three pinned nodes
    # moves nothing, so the closed cell held at all three nodes does not deflect
    model = _build_model(mesh, np.array([0, 1, 2]), TIMBER, 100.0, "pinned")
    deflection, _ = partial_frame_deflection(model, np.arange(3), np.array([0]), [])
    assert deflection == pytest.approx(0.0, abs=1e-15)


def test_releasing_props_through_one_factor_equals_analysing_each_trial():
    """The partial frames held by subsets of the props, solved on one factor with every prop held
    (Schur complements of the released DOFs), against a direct analysis of each: the same largest
    translation to 1e-9, and the same mechanisms (a part held by props alone, then released)."""
    from engine.errors import MechanismError

    mesh = hex_polymesh(3, 4)
    supports = np.flatnonzero(mesh.supports)
    model = _build_model(mesh, supports, TIMBER, 35.0, "pinned")
    rng = np.random.default_rng(3)
    interior = np.flatnonzero(~mesh.supports)
    mechanisms, samples = 0, 0
    for _ in range(40):
        beams = np.sort(rng.choice(len(mesh.edges), size=len(mesh.edges) * 4 // 5, replace=False))
        used = np.unique(mesh.edges[beams])
        props = [int(p) for p in rng.choice(np.intersect1d(interior, used), size=4, replace=False)]
        trials = [[]] + [[p for p in props if p != q] for q in props[:3]] + [props[:1]]
        try:
            fast = deflections_without_props(model, beams, np.zeros(0, np.int64), props, trials)
        except MechanismError:  # some part is loose even with every prop: nothing to release
            continue
        samples += 1
        for trial, value in zip(trials, fast):
            try:
                direct, _ = partial_frame_deflection(model, beams, np.zeros(0, np.int64), trial)
            except MechanismError:
                direct = None
            if direct is None:
                mechanisms += 1
                assert value is None
            else:
                assert value == pytest.approx(direct, rel=1e-9)
    assert samples >= 4 and mechanisms > 0, "several frames stand on their props, and some trial is a mechanism"


def test_hex_sequence_valid():
    mesh = hex_polymesh(3, 4)
    supports = np.flatnonzero(mesh.supports)
    sequence = plan_assembly(mesh, supports, TIMBER, panel_area_load=35.0)
    check_sequence(sequence, mesh)
    assert sequence.deflection_limit_m == pytest.approx(np.ptp(mesh.nodes[:, :2], axis=0).max() / 500)
    # props stay only while needed: if the finished shell stands within the limit on its
    # supports alone, no prop is left after the last step
    model = _build_model(mesh, supports, TIMBER, 35.0, "pinned")
    final, _ = partial_frame_deflection(model, np.arange(len(mesh.edges)), np.arange(mesh.n_faces), [])
    if final <= sequence.deflection_limit_m:
        assert sequence.steps[-1].props == []
    else:
        assert sequence.steps[-1].props


def test_single_support_needs_prop_at_dangling_end():
    # one hexagon held at one pinned node: a mechanism; the prop goes to the opposite node
    mesh = hex_polymesh(1, 1, lift=False)
    loop = mesh.faces[0]
    sequence = plan_assembly(mesh, np.array([loop[0]]), TIMBER)
    (step,) = sequence.steps
    assert step.props_added == [int(loop[3])] and step.props == [int(loop[3])]
    check_sequence(sequence, mesh)


def test_tight_limit_adds_props_loose_limit_not():
    mesh = hex_polymesh(2, 3)
    supports = np.flatnonzero(mesh.supports)
    loose = plan_assembly(mesh, supports, TIMBER, deflection_limit_m=1.0)
    tight = plan_assembly(mesh, supports, TIMBER, deflection_limit_m=1e-6)
    check_sequence(loose, mesh)
    check_sequence(tight, mesh)
    assert len(tight.props_used) > len(loose.props_used)


def test_bad_input():
    mesh = hex_polymesh(1, 2)
    with pytest.raises(InputError, match="mass_per_length"):
        plan_assembly(mesh, np.array([0]), {k: v for k, v in TIMBER.items() if k != "mass_per_length"})
    with pytest.raises(InputError):
        plan_assembly(mesh, np.array([], dtype=int), TIMBER)


def test_write_assembly_files(tmp_path):
    mesh = hex_polymesh(2, 2)
    sequence = plan_assembly(mesh, np.flatnonzero(mesh.supports), TIMBER, panel_area_load=35.0)
    summary = write_assembly(sequence, mesh, tmp_path / "assembly")
    csv_path = summary["csv"]
    assert summary["steps"] == len(sequence.steps)
    table = pd.read_csv(csv_path, keep_default_na=False)
    assert list(table.columns) == ["step", "parts", "props", "largest_deflection_mm"]
    assert list(table["step"]) == list(range(1, len(sequence.steps) + 1))
    parts = " ".join(table["parts"]).split()
    expected = [beam_id(k) for k in range(len(mesh.edges))] + [panel_id(f) for f in range(mesh.n_faces)]
    assert sorted(parts) == sorted(expected)
    for row, step in zip(table.itertuples(), sequence.steps):
        assert row.props.split() == [node_id(p) for p in step.props]
        assert row.largest_deflection_mm == pytest.approx(step.largest_deflection_m * 1e3, abs=1e-3)
    images = sorted((tmp_path / "assembly" / "steps").iterdir())
    assert [p.name for p in images] == [f"step_{k:03d}.png" for k in range(1, len(sequence.steps) + 1)]
    for p in images + [tmp_path / "assembly" / "steps_strip.png"]:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("n_steps, max_images", [(1, 100), (7, 100), (100, 100), (101, 100), (1497, 100), (10, 3)])
def test_step_images_cover_every_step_once_in_order(n_steps, max_images):
    """One image per step up to the cap; beyond it runs of consecutive steps, at most the cap,
    every step in exactly one, names that sort in the order of the steps."""
    groups = step_groups(n_steps, max_images)
    assert len(groups) <= max_images
    assert [k for g in groups for k in g] == list(range(n_steps))
    runs = len(groups) < n_steps
    names = [step_image_name(g, n_steps, runs) for g in groups]
    assert max(map(len, groups), default=0) - min(map(len, groups), default=0) <= 1
    assert names == sorted(names) and len(set(names)) == len(names)
    if n_steps <= max_images:
        assert names[0] == "step_001.png" and all(len(g) == 1 for g in groups)
    else:
        assert names[0].startswith("steps_") and names[-1].endswith(f"-{n_steps:03d}.png")


def test_runs_of_steps_are_drawn_when_the_steps_are_more_than_the_cap(tmp_path):
    mesh = hex_polymesh(3, 3)
    sequence = plan_assembly(mesh, np.flatnonzero(mesh.supports), TIMBER, panel_area_load=35.0)
    summary = write_assembly(sequence, mesh, tmp_path / "assembly", max_step_images=2)
    images = sorted(p.name for p in (tmp_path / "assembly" / "steps").iterdir())
    n = len(sequence.steps)
    assert summary["step_images"] == len(images) == 2
    half = int(images[0][10:13])
    assert half in (n // 2, n - n // 2)
    assert images == [f"steps_001-{half:03d}.png", f"steps_{half + 1:03d}-{n:03d}.png"]


@pytest.mark.parametrize("limit", [None, 0.002])
def test_large_grids_are_planned_in_runs_whose_ends_stand(limit):
    """64 cells with at most 10 analysed runs: runs of 7 steps. The sequence is valid (every
    beam once, every panel after its ring); every analysed step, re-analysed here with the props
    standing after it, deflects as recorded and within the limit; the others are NaN; far fewer
    frames are solved than with every step analysed."""
    mesh = hex_polymesh(8, 8)
    supports = np.flatnonzero(mesh.supports)
    sequence = plan_assembly(mesh, supports, TIMBER, panel_area_load=35.0, deflection_limit_m=limit, analysed_runs=10)
    every = plan_assembly(mesh, supports, TIMBER, panel_area_load=35.0, deflection_limit_m=limit, analysed_runs=None)
    check_sequence(sequence, mesh)
    assert sequence.n_analyses < every.n_analyses / 2
    model = _build_model(mesh, supports, TIMBER, 35.0, "pinned")
    analysed = [k for k, s in enumerate(sequence.steps) if np.isfinite(s.largest_deflection_m)]
    assert len(analysed) >= len(sequence.steps) / 7 - 1
    assert analysed[-1] == len(sequence.steps) - 1
    for k in analysed:
        step = sequence.steps[k]
        beams = [b for s in sequence.steps[:k + 1] for b in s.beams]
        panels = [f for s in sequence.steps[:k + 1] for f in s.panels]
        value, _ = partial_frame_deflection(model, np.array(beams), np.array(panels, dtype=np.int64), step.props)
        assert value == pytest.approx(step.largest_deflection_m, rel=1e-9)
        assert value <= sequence.deflection_limit_m * (1 + 1e-9)


@pytest.mark.parametrize("max_images, rows, cols", [(None, 3, 3), (3, 3, 3), (None, 2, 12)])
def test_each_step_image_shows_the_panels_built_before_in_grey_and_its_own_in_pink(tmp_path, max_images, rows,
                                                                                   cols):
    """The step pictures read back as pixels: at each panel's centre, grey where the panel went
    up in an earlier picture, pink where it goes up in this one, white where it is still to come
    (one picture per step, and pictures of runs of steps); a grid much wider than deep is drawn
    across a picture as wide (it was a strip across a square one)."""
    from PIL import Image

    from fabrication.assembly import _StepCanvas

    mesh = hex_polymesh(rows, cols)
    sequence = plan_assembly(mesh, np.flatnonzero(mesh.supports), TIMBER, panel_area_load=35.0)
    canvas = _StepCanvas(sequence, mesh)
    centres = np.array([mesh.nodes[f, :2].mean(axis=0) for f in mesh.faces])
    step_of = {f: k for k, s in enumerate(sequence.steps) for f in s.panels}
    colours = {"built": (204, 204, 204), "new": (244, 166, 166), "to come": (255, 255, 255)}
    for group in step_groups(len(sequence.steps), max_images):
        target = tmp_path / f"{group.start}.png"
        canvas.save(group, target)
        with Image.open(target) as image:
            pixels = np.asarray(image.convert("RGB"), dtype=int)
        height, width = pixels.shape[:2]
        assert (width >= 2.5 * height) if cols > 2 * rows else (width == height)
        x, y = canvas.ax.transData.transform(centres).T
        seen = pixels[(pixels.shape[0] - y).astype(int), x.astype(int)]
        for f, colour in enumerate(seen):
            state = ("built" if step_of[f] < group.start else "new" if step_of[f] < group.stop else "to come")
            assert np.abs(colour - colours[state]).max() <= 3, (group, f, state, colour)


def test_cells_deflecting_the_same_to_round_off_go_up_in_their_rank_order():
    """Mirror-image cells deflect the same but for round-off: the one ranked first is built, so
    that a change in the last digits of the analyses does not reorder the sequence; fewer props
    and a deflection clearly smaller still win."""
    from fabrication.assembly import SAME_DEFLECTION, _ranks_before

    best = (0, 0.3)
    assert not _ranks_before((0, 0.3 * (1 - 0.1 * SAME_DEFLECTION)), best)
    assert _ranks_before((0, 0.3 * (1 - 10 * SAME_DEFLECTION)), best)
    assert _ranks_before((0, 5.0), (1, 0.1)) and not _ranks_before((1, 0.1), (0, 5.0))
    assert _ranks_before((0, 1.0), (0, np.inf)) and not _ranks_before((0, np.inf), (0, 1.0))


def test_a_change_in_the_last_digits_does_not_reorder_the_sequence():
    """A symmetric grid with its nodes moved by 1e-12 of its span, differently each time (what
    another BLAS or an algebraically equal kernel does to the analyses' last digits): mirror-image
    cells then deflect differently by round-off only, and the same cells go up in the same order."""
    from dataclasses import replace

    mesh = hex_polymesh(3, 4, lift=False)         # flat, held all round: mirror-image about y = 0
    supports = np.flatnonzero(mesh.supports)
    span = float(np.ptp(mesh.nodes, axis=0).max())
    orders = []
    for seed in range(4):
        moved = mesh.nodes + 1e-12 * span * np.random.default_rng(seed).normal(size=mesh.nodes.shape)
        sequence = plan_assembly(replace(mesh, nodes=moved), supports, TIMBER, panel_area_load=35.0)
        orders.append([s.beams for s in sequence.steps])
    assert all(order == orders[0] for order in orders[1:])
