"""The inverses of many small blocks and the pivots of their elimination, in one compiled pass.

A beam of k elements condenses its k - 1 internal nodes through the inverse of their block K_ii
(``engine.structure.condensed``), and the pivots of that block's elimination without row
exchanges count its negative eigenvalues along a path. One Gaussian elimination per block, on the
block and the identity beside it, gives both: numpy's batched inverse (LAPACK, with row
exchanges) and a separate vectorised elimination for the pivots took 0.13 s for 7384 blocks of
18 x 18, this 0.03 s (``benchmarks/frame_speed.py``; docs/decisions.md). The elimination skips the
zeros of a block-tridiagonal K_ii. Blocks whose elimination meets a pivot under
``SMALL_PIVOT`` of their largest entry are inverted again with row exchanges by numpy.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["inverse_and_pivots", "SMALL_PIVOT"]

#: A pivot this small against its block's largest entry makes the elimination without row
#: exchanges inaccurate: such a block's inverse is numpy's instead.
SMALL_PIVOT = 1e-8


@njit(cache=True, nogil=True, error_model="numpy")  # a zero pivot gives inf, not an exception
def _eliminate(blocks, inverse, pivots):  # pragma: no cover - compiled
    m, g, _ = blocks.shape
    A = np.empty((g, g))
    for b in range(m):
        X = inverse[b]
        for i in range(g):
            for j in range(g):
                A[i, j] = blocks[b, i, j]
                X[i, j] = 1.0 if i == j else 0.0
        # forward: A to its upper triangle U, the identity to L^-1 (lower triangular)
        for k in range(g):
            p = A[k, k]
            pivots[b, k] = p
            r = 1.0 / p
            for i in range(k + 1, g):
                f = A[i, k] * r
                if f != 0.0:
                    for j in range(k + 1, g):
                        A[i, j] -= f * A[k, j]
                    for j in range(k + 1):
                        X[i, j] -= f * X[k, j]
        # backward: U^-1 L^-1, row by row from the last
        for k in range(g - 1, -1, -1):
            for i in range(k + 1, g):
                a = A[k, i]
                if a != 0.0:
                    for j in range(g):
                        X[k, j] -= a * X[i, j]
            r = 1.0 / A[k, k]
            for j in range(g):
                X[k, j] *= r


def inverse_and_pivots(blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(inverses (m, g, g), pivots (m, g)) of the blocks (m, g, g): the pivots of each block's
    Gaussian elimination without row exchanges (as SuperLU with diagonal pivots), and its
    inverse, non-finite where the block is singular."""
    blocks = np.ascontiguousarray(blocks, dtype=float)
    inverse = np.empty_like(blocks)
    pivots = np.empty(blocks.shape[:2])
    with np.errstate(divide="ignore", invalid="ignore"):
        _eliminate(blocks, inverse, pivots)
        scale = np.abs(blocks).max(axis=(1, 2))
        small = ~(np.abs(pivots).min(axis=1) >= SMALL_PIVOT * scale)
    for b in np.flatnonzero(small):
        try:
            inverse[b] = np.linalg.inv(blocks[b])
        except np.linalg.LinAlgError:
            inverse[b] = np.nan
    return inverse, pivots
