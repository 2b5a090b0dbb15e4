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

__all__ = ["condensation", "inverse_and_pivots", "SMALL_PIVOT"]

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


@njit(cache=True, nogil=True)
def _condense(inverse, first, last, W, V, condensed):  # pragma: no cover - compiled
    m, g, _ = inverse.shape
    e = g - 6
    for b in range(m):
        for i in range(g):
            for j in range(6):
                w0 = 0.0
                w1 = 0.0
                for t in range(6):
                    w0 += inverse[b, i, t] * first[b, 6 + t, j]
                    w1 += inverse[b, i, e + t] * last[b, t, 6 + j]
                W[b, i, j] = w0
                W[b, i, 6 + j] = w1
        for i in range(6):
            for j in range(g):
                v0 = 0.0
                v1 = 0.0
                for t in range(6):
                    v0 += first[b, i, 6 + t] * inverse[b, t, j]
                    v1 += last[b, 6 + i, t] * inverse[b, e + t, j]
                V[b, i, j] = v0
                V[b, 6 + i, j] = v1
        for i in range(6):
            for j in range(12):
                c0 = first[b, i, j] if j < 6 else 0.0
                c1 = last[b, 6 + i, j] if j >= 6 else 0.0
                for t in range(6):
                    c0 -= first[b, i, 6 + t] * W[b, t, j]
                    c1 -= last[b, 6 + i, t] * W[b, e + t, j]
                condensed[b, i, j] = c0
                condensed[b, 6 + i, j] = c1


def condensation(inverse: np.ndarray, first: np.ndarray, last: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(W (m, g, 12), V (m, 12, g), condensed (m, 12, 12)) of beams whose internal nodes' block has
    the ``inverse`` (m, g, g), first and last elements (m, 12, 12): W = K_ii^-1 K_ie, V = K_ei
    K_ii^-1 and the beam-end stiffness K_ee - K_ei W, K_ie being the first element's block on
    internal node 1 x end node 0 and the last's on internal node k-1 x end node k
    (``engine.structure.condensed``), in one compiled pass where numpy's batched products of 6 x 6
    blocks take several."""
    inverse = np.ascontiguousarray(inverse, dtype=float)
    first = np.ascontiguousarray(first, dtype=float)
    last = np.ascontiguousarray(last, dtype=float)
    m, g, _ = inverse.shape
    W, V, condensed = np.empty((m, g, 12)), np.empty((m, 12, g)), np.empty((m, 12, 12))
    _condense(inverse, first, last, W, V, condensed)
    return W, V, condensed


@njit(cache=True, nogil=True)
def _subtract_end_loads(V, f_i, end_dofs, f_b):  # pragma: no cover - compiled
    m, ends, g = V.shape
    r = f_i.shape[2]
    for b in range(m):
        for c in range(ends):
            row = end_dofs[b, c]
            for col in range(r):
                s = 0.0
                for t in range(g):
                    s += V[b, c, t] * f_i[b, t, col]
                f_b[row, col] -= s


@njit(cache=True, nogil=True)
def _internal_displacements(inverse, W, f_i, x_b, end_dofs, x_i):  # pragma: no cover - compiled
    m, g, ends = W.shape
    r = f_i.shape[2]
    for b in range(m):
        for i in range(g):
            for col in range(r):
                s = 0.0
                for t in range(g):
                    s += inverse[b, i, t] * f_i[b, t, col]
                for c in range(ends):
                    s -= W[b, i, c] * x_b[end_dofs[b, c], col]
                x_i[b, i, col] = s


def subtract_end_loads(V: np.ndarray, f_i: np.ndarray, end_dofs: np.ndarray, f_b: np.ndarray) -> None:
    """f_b (n_end_dofs, r) -= the internal loads f_i (m, g, r) carried to the beam ends, V f_i per
    beam (V (m, 12, g) = K_ei K_ii^-1), scattered onto the end DOFs ``end_dofs`` (m, 12); in place.
    One compiled pass in place of a batched product and a sparse scatter."""
    _subtract_end_loads(V, f_i, end_dofs, f_b)


def internal_displacements(inverse: np.ndarray, W: np.ndarray, f_i: np.ndarray, x_b: np.ndarray,
                           end_dofs: np.ndarray) -> np.ndarray:
    """x_i (m, g, r) = K_ii^-1 f_i - W x_e per beam: the internal nodes' displacements from their
    loads f_i (m, g, r) and the end displacements x_b (n_end_dofs, r) at ``end_dofs`` (m, 12)."""
    x_i = np.empty(f_i.shape)
    _internal_displacements(inverse, W, f_i, x_b, end_dofs, x_i)
    return x_i
