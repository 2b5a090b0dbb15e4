"""Element matrices turned from the beams' local axes to the global ones, compiled.

A two-node element's transformation T is block-diagonal, its frame R (3 x 3) four times, so
T^T K T is R^T K_ab R on each of its sixteen 3 x 3 blocks: 864 products an element where the
batched product of the full 12 x 12 matrices takes 3456, and numpy's batched matmul of small
matrices is slow besides (the 5000-node frame's 29 536 elements: 0.014 s against 0.14-0.23 s,
``benchmarks/frame_speed.py``; the same matrices to 2e-15).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["to_global"]


@njit(cache=True, nogil=True)
def _to_global(R, K, out):  # pragma: no cover - compiled
    m = K.shape[0]
    KR = np.empty((12, 12))
    for e in range(m):
        for i in range(12):                      # K T: each column block times R
            for b in range(4):
                for j in range(3):
                    s = 0.0
                    for t in range(3):
                        s += K[e, i, 3 * b + t] * R[e, t, j]
                    KR[i, 3 * b + j] = s
        for a in range(4):                       # T^T (K T): each row block times R^T
            for i in range(3):
                for j in range(12):
                    s = 0.0
                    for t in range(3):
                        s += R[e, t, i] * KR[3 * a + t, j]
                    out[e, 3 * a + i, j] = s


def to_global(R: np.ndarray, K_local: np.ndarray) -> np.ndarray:
    """T^T K T (m, 12, 12) of element matrices ``K_local`` (m, 12, 12) in local axes, T the
    block-diagonal transformation of the frames R (m, 3, 3) (rows: the local axes in global
    coordinates, as ``engine.structure.beam_elements.local_axes``)."""
    out = np.empty((len(K_local), 12, 12))
    _to_global(np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(K_local, dtype=float), out)
    return out
