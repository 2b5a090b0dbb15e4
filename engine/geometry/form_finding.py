"""Force density method (Schek 1974) for funicular nets.

A net of nodes and edges with a force density q (force / length) per edge, some nodes
fixed, and nodal loads p. Equilibrium at a free node i: sum_j q_ij (x_j - x_i) + p_i = 0,
i.e. with the branch-node matrix C = [C_free | C_fixed] and Q = diag(q):
C_free^T Q C_free x_free = p_free - C_free^T Q C_fixed x_fixed, one linear solve per
coordinate. For vertical loads the plan coordinates follow from the x and y equations
with zero load and the heights from the z equation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import splu

from ..errors import InputError

__all__ = ["FormFindingResult", "force_density", "equilibrium_residual"]


@dataclass(frozen=True, kw_only=True)
class FormFindingResult:
    """Form-found node coordinates (n, 3) m, edge forces (e,) N, and the relative residual."""

    nodes: np.ndarray
    edge_forces: np.ndarray
    residual: float


def _branch_node_matrix(edges: np.ndarray, n_nodes: int) -> sparse.csr_matrix:
    e = len(edges)
    rows = np.repeat(np.arange(e), 2)
    cols = edges.ravel()
    vals = np.tile([1.0, -1.0], e)
    return sparse.csr_matrix((vals, (rows, cols)), shape=(e, n_nodes))


def equilibrium_residual(nodes: np.ndarray, edges: np.ndarray, force_densities: np.ndarray,
                         loads: np.ndarray, fixed: np.ndarray) -> float:
    """Largest out-of-balance force at a free node divided by the largest applied nodal load."""
    C = _branch_node_matrix(edges, len(nodes))
    internal = C.T @ (force_densities[:, None] * (C @ nodes))
    out_of_balance = (loads - internal)[~fixed]
    scale = max(np.abs(loads[~fixed]).max(), 1e-300)
    return float(np.abs(out_of_balance).max() / scale)


def force_density(nodes: np.ndarray, edges: np.ndarray, force_densities: np.ndarray | float,
                  loads: np.ndarray, fixed: np.ndarray) -> FormFindingResult:
    """Solve the force density equations; fixed nodes keep their coordinates.

    nodes: (n, 3) start coordinates (fixed ones are kept); edges: (e, 2); force_densities:
    (e,) or a scalar, N/m, positive in tension (a hanging net; flip the load's sign for a
    compression shell); loads: (n, 3) N; fixed: (n,) bool.
    """
    nodes = np.asarray(nodes, dtype=float)
    fixed = np.asarray(fixed, dtype=bool)
    q = np.broadcast_to(np.asarray(force_densities, dtype=float), (len(edges),)).copy()
    if (q <= 0).any():
        raise InputError("force densities must be positive")
    if not fixed.any():
        raise InputError("force density form-finding needs at least one fixed node")
    C = _branch_node_matrix(edges, len(nodes))
    Cf, Cx = C[:, ~fixed], C[:, fixed]
    Q = sparse.diags(q)
    D = (Cf.T @ Q @ Cf).tocsc()
    rhs = loads[~fixed] - Cf.T @ (Q @ (Cx @ nodes[fixed]))
    solved = nodes.copy()
    solved[~fixed] = splu(D).solve(np.ascontiguousarray(rhs))
    lengths = np.linalg.norm(C @ solved, axis=1)
    residual = equilibrium_residual(solved, edges, q, loads, fixed)
    return FormFindingResult(nodes=solved, edge_forces=q * lengths, residual=residual)
