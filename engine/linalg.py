"""Small batched linear-algebra kernels shared by the element codes."""

from __future__ import annotations

import contextlib

import numpy as np

__all__ = ["congruent", "assemble_blocks", "block_diagonal", "node_dofs", "single_threaded_blas",
           "rigid_body_modes", "count_free_rigid_modes"]


def congruent(T: np.ndarray, K: np.ndarray) -> np.ndarray:
    """T^T K T for stacks (m, k, k) of matrices (batched matmul, far faster than a three-operand einsum)."""
    return np.matmul(np.matmul(np.transpose(T, (0, 2, 1)), K), T)


def block_diagonal(frames: np.ndarray, blocks: int) -> np.ndarray:
    """(m, 3b, 3b) block-diagonal transformations with each element's (m,3,3) frame ``blocks`` times."""
    T = np.zeros((len(frames), 3 * blocks, 3 * blocks))
    for block in range(blocks):
        T[:, 3 * block:3 * block + 3, 3 * block:3 * block + 3] = frames
    return T


def node_dofs(connectivity: np.ndarray) -> np.ndarray:
    """(m, 6k) node-major DOF indices (6 per node) of elements with k nodes each, (m,k)."""
    return (6 * connectivity[:, :, None] + np.arange(6)).reshape(len(connectivity), 6 * connectivity.shape[1])


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


def single_threaded_blas():
    """Limit BLAS to one thread where threadpoolctl is available: the eigensolver and the path
    following do many small vector operations, for which BLAS threads on a busy machine cost
    more than they bring (10 buckling modes of a 64k-DOF model: 2.2 s instead of 5.6 s)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def tangent_projectors(normals: np.ndarray) -> np.ndarray:
    """(n, 3, 3) P = I - n n^T of the unit ``normals`` (n, 3): each projects onto its tangent plane."""
    normals = np.asarray(normals, dtype=float)
    return np.eye(3)[None] - np.einsum("ni,nj->nij", normals, normals)


def in_tangent_planes(tensors: np.ndarray, projectors: np.ndarray) -> np.ndarray:
    """(n, 3, 3) P T P: the ``tensors`` (n, 3, 3) projected into the tangent planes of their
    ``projectors`` (tangent_projectors)."""
    return np.einsum("nij,njk,nkl->nil", projectors, tensors, projectors)


def rigid_body_modes(vertices: np.ndarray) -> np.ndarray:
    """(6n, 6) the three translations and three rotations (about the centroid) of the nodes."""
    n = len(vertices)
    r = vertices - vertices.mean(axis=0)
    scale = max(float(np.abs(r).max()), 1e-300)
    modes = np.zeros((n, 6, 6))
    for axis in range(3):
        modes[:, axis, axis] = 1.0
        rotation = np.zeros(3)
        rotation[axis] = 1.0
        modes[:, :3, 3 + axis] = np.cross(rotation, r) / scale
        modes[:, 3 + axis, 3 + axis] = 1.0 / scale
    return modes.reshape(6 * n, 6)


def count_free_rigid_modes(vertices: np.ndarray, restrained: np.ndarray) -> int:
    """How many rigid-body motions the restrained DOFs (6n,) bool leave free."""
    return len(_free_rigid_motions(vertices, restrained))


#: The rigid-body motions of rigid_body_modes, as free_rigid_motions names them.
RIGID_MOTIONS = ("sliding along x", "sliding along y", "sliding along z",
                 "turning about x", "turning about y", "turning about z")


def _free_rigid_motions(vertices: np.ndarray, restrained: np.ndarray) -> np.ndarray:
    """(k, 6) an orthonormal basis of the rigid-body motions (coefficients of rigid_body_modes)
    that the restrained DOFs (6n,) bool leave free."""
    constrained = rigid_body_modes(vertices)[restrained]
    if constrained.size == 0:
        return np.eye(6)
    _, singular, vt = np.linalg.svd(constrained)
    rank = int(np.sum(singular > 1e-9 * max(singular.max(), 1e-300)))
    return vt[rank:]


def free_rigid_motions(vertices: np.ndarray, restrained: np.ndarray) -> list[str]:
    """The rigid-body motions the restrained DOFs (6n,) bool leave free, named (RIGID_MOTIONS;
    rotations about axes through the vertices' centroid): each translation or rotation that lies
    mostly (over half its length) among the free ones; empty when none is free."""
    free = _free_rigid_motions(vertices, restrained)
    if not len(free):
        return []
    share = np.linalg.norm(free, axis=0)  # how much of each unit motion the free ones hold
    names = [RIGID_MOTIONS[i] for i in np.flatnonzero(share > 0.5)]
    return names or ["sliding and turning at once"]
