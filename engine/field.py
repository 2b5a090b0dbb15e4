"""Statics-aware guiding field: target cell size, anisotropy and direction per vertex.

(METHOD.md section 2.) This module is being written; ``GuidingField`` is the contract
the remeshing consumes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GuidingField"]


@dataclass(frozen=True, kw_only=True)
class GuidingField:
    """Per-vertex guiding field on a TriMesh.

    size: (n_vertices,) target cell size h, m; anisotropy: (n_vertices,) a >= 1;
    direction: (n_vertices, 3) unit tangent u, the direction of the larger principal
    force, along which cells are elongated; normals: (n_vertices, 3) unit normals.
    The metric is M = R diag(1/(h^2 a), a/h^2) R^T in the (u, v = n x u) frame: its
    unit ellipse has semi-axes h sqrt(a) along u and h / sqrt(a) along v.
    """

    size: np.ndarray
    anisotropy: np.ndarray
    direction: np.ndarray
    normals: np.ndarray

    def metric(self) -> np.ndarray:
        """(n_vertices, 3, 3) metric tensors in global coordinates (rank 2, tangent)."""
        u = self.direction
        v = np.cross(self.normals, u)
        h2 = self.size**2
        a = self.anisotropy
        return (np.einsum("ni,nj->nij", u, u) / (h2 * a)[:, None, None]
                + np.einsum("ni,nj->nij", v, v) * (a / h2)[:, None, None])
