"""The greedy label placement of ``fabrication.label_placement`` as one compiled loop (numba,
``cache=True``): the placed boxes are kept in a grid of buckets as linked lists, each box in the
at most 2 x 2 buckets it meets (a bucket is as large as the largest box)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def greedy_places(boxes: np.ndarray, allowed: np.ndarray, x_low: float, y_low: float, cell: float,
                  nx: int, ny: int) -> np.ndarray:  # pragma: no cover - compiled; held against the Python loop
    """(n,) the first allowed candidate (boxes (n, k, 4): x0, y0, x1, y1) of each label, in order,
    that meets no box placed before it (open intervals: touching boxes are free); -1 for none."""
    n, k = allowed.shape
    head = np.full(nx * ny, -1, np.int64)
    entry_box = np.empty(4 * n, np.int64)
    entry_next = np.empty(4 * n, np.int64)
    kept = np.empty((n, 4))
    chosen = np.full(n, -1, np.int64)
    count = 0
    entries = 0
    for i in range(n):
        for j in range(k):
            if not allowed[i, j]:
                continue
            x0, y0, x1, y1 = boxes[i, j, 0], boxes[i, j, 1], boxes[i, j, 2], boxes[i, j, 3]
            cx0 = min(max(int(np.floor((x0 - x_low) / cell)), 0), nx - 1)
            cx1 = min(max(int(np.floor((x1 - x_low) / cell)), 0), nx - 1)
            cy0 = min(max(int(np.floor((y0 - y_low) / cell)), 0), ny - 1)
            cy1 = min(max(int(np.floor((y1 - y_low) / cell)), 0), ny - 1)
            free = True
            for cx in range(cx0, cx1 + 1):
                for cy in range(cy0, cy1 + 1):
                    e = head[cx * ny + cy]
                    while e >= 0:
                        b = entry_box[e]
                        if x0 < kept[b, 2] and kept[b, 0] < x1 and y0 < kept[b, 3] and kept[b, 1] < y1:
                            free = False
                            break
                        e = entry_next[e]
                    if not free:
                        break
                if not free:
                    break
            if not free:
                continue
            kept[count, 0], kept[count, 1], kept[count, 2], kept[count, 3] = x0, y0, x1, y1
            for cx in range(cx0, cx1 + 1):
                for cy in range(cy0, cy1 + 1):
                    entry_box[entries] = count
                    entry_next[entries] = head[cx * ny + cy]
                    head[cx * ny + cy] = entries
                    entries += 1
            chosen[i] = j
            count += 1
            break
    return chosen
