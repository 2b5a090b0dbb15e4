"""Greedy label placement (fabrication.label_placement): no overlap, the first free place of each
label in order, and the compiled loop equal to the Python one."""

from __future__ import annotations

import numpy as np
import pytest

from fabrication import label_placement
from fabrication.label_placement import place_labels, ring_offsets


def _case(seed: int, n: int = 400):
    """Labels of two sizes crowded on a 60 x 40 field, on whole-number places so that many boxes
    touch exactly; eight near places and four far ones."""
    rng = np.random.default_rng(seed)
    anchor = rng.integers(0, 60, size=(n, 2)).astype(float) * [1.0, 40 / 60]
    size = np.where(rng.random((n, 1)) < 0.5, [[4.0, 2.0]], [[6.0, 2.0]])
    near = np.round(ring_offsets(2.0, 8), 6)
    far = ring_offsets(7.0, 4, phase=0.3)
    return anchor, size, near, far


def _placed_boxes(anchor, size, placement, gap):
    half = 0.5 * size[placement.placed] + gap
    centre = placement.centre[placement.placed]
    return np.concatenate([centre - half, centre + half], axis=1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_placed_labels_do_not_overlap_and_take_their_first_free_place(seed):
    """Every pair of placed boxes (with the gap) is apart or touching, each box is inside the bounds
    and off the obstacle, and each label took its first candidate that met no box placed before it
    (so a label left out had none)."""
    anchor, size, near, far = _case(seed)
    bounds, obstacle, gap = (-5.0, -5.0, 65.0, 45.0), np.array([[20.0, 10.0, 30.0, 20.0]]), 0.2
    placement = place_labels(anchor, size, near, far, bounds=bounds, obstacles=obstacle, gap=gap)
    boxes = _placed_boxes(anchor, size, placement, gap)
    a, b = boxes[:, None], boxes[None, :]
    overlap = (a[..., 0] < b[..., 2]) & (b[..., 0] < a[..., 2]) & (a[..., 1] < b[..., 3]) & (b[..., 1] < a[..., 3])
    np.fill_diagonal(overlap, False)
    assert not overlap.any()
    assert (boxes[:, :2] >= bounds[:2]).all() and (boxes[:, 2:] <= bounds[2:]).all()
    x0, y0, x1, y1 = obstacle[0]
    assert not ((boxes[:, 0] < x1) & (x0 < boxes[:, 2]) & (boxes[:, 1] < y1) & (y0 < boxes[:, 3])).any()
    # the greedy rule, checked label by label against the boxes of the labels before it
    offsets = np.concatenate([near, far])
    order = np.cumsum(placement.placed) - placement.placed
    for i in range(len(anchor)):
        earlier = boxes[:order[i]]
        for k, offset in enumerate(offsets):
            box = np.r_[anchor[i] + offset - 0.5 * size[i] - gap, anchor[i] + offset + 0.5 * size[i] + gap]
            inside = (box[:2] >= bounds[:2]).all() and (box[2:] <= bounds[2:]).all()
            off_obstacle = not (box[0] < x1 and x0 < box[2] and box[1] < y1 and y0 < box[3])
            free = not ((box[0] < earlier[:, 2]) & (earlier[:, 0] < box[2])
                        & (box[1] < earlier[:, 3]) & (earlier[:, 1] < box[3])).any()
            if inside and off_obstacle and free:
                assert placement.placed[i] and np.allclose(placement.centre[i], anchor[i] + offset)
                assert placement.leader[i] == (k >= len(near))
                break
        else:
            assert not placement.placed[i]


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_compiled_placement_is_the_python_loop(monkeypatch, seed):
    """The compiled greedy loop (used from COMPILED_FROM labels) places every label where the
    Python loop does, with and without bounds, far places and obstacles."""
    anchor, size, near, far = _case(seed, n=600)
    for options in ({}, {"bounds": (-5.0, -5.0, 65.0, 45.0), "obstacles": np.array([[20.0, 10.0, 30.0, 20.0]])}):
        for far_places in (far, None):
            monkeypatch.setattr(label_placement, "COMPILED_FROM", 10**9)
            python = place_labels(anchor, size, near, far_places, **options)
            monkeypatch.setattr(label_placement, "COMPILED_FROM", 0)
            compiled = place_labels(anchor, size, near, far_places, **options)
            assert python.left_out > 0 and python.placed.sum() > 100
            assert np.array_equal(python.placed, compiled.placed)
            assert np.array_equal(python.leader, compiled.leader)
            assert np.array_equal(python.centre, compiled.centre, equal_nan=True)
