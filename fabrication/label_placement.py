"""Labels on a drawing without overlap: each label takes the first of its candidate places whose box
meets no box placed before it (greedy, in the order given), the far ones with a leader line back to
the part; a label with no free place is left out and counted.

Boxes are axis-aligned rectangles in the drawing's length unit (the plan PDF places them in model
mm, its type sizes times the scale), found through a uniform grid of buckets, so placing n labels
with k candidates each costs about n k box tests. From COMPILED_FROM labels the same greedy loop
runs compiled (numba): a large roof's plan tried 1.1 million candidate boxes, 21 s in Python.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Placement", "place_labels", "ring_offsets"]


@dataclass(frozen=True)
class Placement:
    """Where the labels went: centre (n, 2) (NaN where left out), placed (n,) bool, leader (n,) bool
    (a line from the anchor to the label is drawn)."""

    centre: np.ndarray
    placed: np.ndarray
    leader: np.ndarray

    @property
    def left_out(self) -> int:
        return int((~self.placed).sum())


def ring_offsets(radius: float, count: int, *, phase: float = 0.0) -> np.ndarray:
    """``count`` offsets (count, 2) on a circle of ``radius``, starting at ``phase`` radians."""
    angle = phase + 2.0 * np.pi * np.arange(count) / count
    return radius * np.column_stack([np.cos(angle), np.sin(angle)])


class _Buckets:
    def __init__(self, cell: float):
        self.cell = float(cell)
        self.boxes: list[tuple[float, float, float, float]] = []
        self.grid: dict[tuple[int, int], list[int]] = {}

    def _cells(self, box):
        x0, y0, x1, y1 = (int(np.floor(v / self.cell)) for v in box)
        return ((i, j) for i in range(x0, x1 + 1) for j in range(y0, y1 + 1))

    def free(self, box) -> bool:
        for key in self._cells(box):
            for k in self.grid.get(key, ()):
                other = self.boxes[k]
                if box[0] < other[2] and other[0] < box[2] and box[1] < other[3] and other[1] < box[3]:
                    return False
        return True

    def add(self, box) -> None:
        self.boxes.append(box)
        for key in self._cells(box):
            self.grid.setdefault(key, []).append(len(self.boxes) - 1)


def place_labels(anchor: np.ndarray, size: np.ndarray, near: np.ndarray, far: np.ndarray | None = None, *,
                 bounds: tuple[float, float, float, float] | None = None, obstacles: np.ndarray | None = None,
                 gap: float = 0.2) -> Placement:
    """Place labels of ``size`` (n, 2) width and height around ``anchor`` (n, 2), all in one length unit.

    near (n, k, 2) or (k, 2): offsets of the label's centre from its anchor, tried in turn; far (m, 2):
    offsets tried after them, each drawn with a leader line. bounds (x0, y0, x1, y1): the frame every
    label stays inside; obstacles (j, 4): a few boxes no label may meet (titles, dimensions). ``gap``:
    clear space kept round every label. Labels are placed in their given order, so the first
    have the first choice.
    """
    anchor = np.asarray(anchor, dtype=float).reshape(-1, 2)
    size = np.broadcast_to(np.asarray(size, dtype=float), anchor.shape)
    n = len(anchor)
    near = np.asarray(near, dtype=float)
    near = np.broadcast_to(near, (n, *near.shape[-2:])) if near.ndim == 2 else near
    far = np.zeros((0, 2)) if far is None else np.asarray(far, dtype=float).reshape(-1, 2)
    half = 0.5 * size + gap
    buckets = _Buckets(cell=max(float(np.max(2 * half, initial=1.0)), 1e-3))
    # every candidate's box at once (n, k + m, 4), and which of them the frame and the obstacles allow
    offsets = np.concatenate([near, np.broadcast_to(far, (n, *far.shape))], axis=1)
    centres = anchor[:, None, :] + offsets
    boxes = np.concatenate([centres - half[:, None, :], centres + half[:, None, :]], axis=2)
    allowed = np.isfinite(boxes).all(axis=2)
    if bounds is not None:
        allowed &= ((boxes[..., 0] >= bounds[0]) & (boxes[..., 1] >= bounds[1])
                    & (boxes[..., 2] <= bounds[2]) & (boxes[..., 3] <= bounds[3]))
    for x0, y0, x1, y1 in (np.zeros((0, 4)) if obstacles is None else np.asarray(obstacles, float).reshape(-1, 4)):
        allowed &= ~((boxes[..., 0] < x1) & (x0 < boxes[..., 2]) & (boxes[..., 1] < y1) & (y0 < boxes[..., 3]))
    chosen = _chosen_compiled(boxes, allowed, buckets.cell) if n >= COMPILED_FROM else None
    if chosen is None:
        chosen = np.full(n, -1, dtype=np.int64)
        for i in range(n):
            for k in np.flatnonzero(allowed[i]):
                box = tuple(boxes[i, k].tolist())
                if buckets.free(box):
                    buckets.add(box)
                    chosen[i] = k
                    break
    placed = chosen >= 0
    centre = np.full((n, 2), np.nan)
    centre[placed] = centres[np.flatnonzero(placed), chosen[placed]]
    return Placement(centre=centre, placed=placed, leader=chosen >= near.shape[1])


#: From this many labels the placement runs compiled: below it, loading the compiled code (about
#: 1 s once per process: numba's import and LLVM's start) costs more than the loop it saves.
COMPILED_FROM = 2000
#: The most buckets of the compiled placement's grid (a larger one: the Python loop's dictionary).
MAX_BUCKETS = 20_000_000


def _chosen_compiled(boxes: np.ndarray, allowed: np.ndarray, cell: float) -> np.ndarray | None:
    """The greedy placement of ``place_labels`` compiled: (n,) the candidate each label takes (-1:
    left out), the same as the Python loop's; None where the allowed boxes span too many buckets."""
    if not allowed.any():
        return np.full(len(boxes), -1, dtype=np.int64)
    spread = boxes[allowed]
    lo = spread[:, :2].min(axis=0)
    counts = np.floor((spread[:, 2:].max(axis=0) - lo) / cell).astype(np.int64) + 1
    if counts.prod() > MAX_BUCKETS:
        return None
    from ._label_kernel import greedy_places

    return greedy_places(np.ascontiguousarray(boxes), np.ascontiguousarray(allowed), float(lo[0]), float(lo[1]),
                         float(cell), int(counts[0]), int(counts[1]))
