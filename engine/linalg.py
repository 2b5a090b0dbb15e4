"""Small batched linear-algebra kernels shared by the element codes."""

from __future__ import annotations

import numpy as np

__all__ = ["congruent"]


def congruent(T: np.ndarray, K: np.ndarray) -> np.ndarray:
    """T^T K T for stacks (m, k, k) of matrices (batched matmul, far faster than a three-operand einsum)."""
    return np.matmul(np.matmul(np.transpose(T, (0, 2, 1)), K), T)


def assemble_blocks(element_matrices: np.ndarray, connectivity: np.ndarray, n_nodes: int,
                    dofs_per_node: int = 6):
    """Global sparse matrix (CSC) from element matrices (m, k*d, k*d) on nodes (m, k), d DOFs per node.

    Works on d x d node blocks: the k^2 blocks of every element are summed by a sort on their
    (row node, column node) key and become a block-sparse matrix, so the scalar duplicates of a
    plain COO assembly (m k^2 d^2 of them) are never sorted.
    """
    import scipy.sparse as sp

    m, k = connectivity.shape
    d = dofs_per_node
    blocks = element_matrices.reshape(m, k, d, k, d).transpose(0, 1, 3, 2, 4).reshape(m * k * k, d, d)
    rows = np.repeat(connectivity, k, axis=1).ravel()
    cols = np.tile(connectivity, (1, k)).ravel()
    key = rows.astype(np.int64) * n_nodes + cols
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    starts = np.flatnonzero(np.r_[True, sorted_key[1:] != sorted_key[:-1]])
    summed = np.add.reduceat(blocks[order], starts, axis=0)
    unique = sorted_key[starts]
    block_rows, block_cols = unique // n_nodes, unique % n_nodes
    indptr = np.zeros(n_nodes + 1, dtype=np.int64)
    np.add.at(indptr, block_rows + 1, 1)
    indptr = np.cumsum(indptr)
    matrix = sp.bsr_matrix((summed, block_cols, indptr), shape=(n_nodes * d, n_nodes * d))
    return matrix.tocsc()
