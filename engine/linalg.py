"""Small batched linear-algebra kernels shared by the element codes."""

from __future__ import annotations

import numpy as np

__all__ = ["congruent"]


def congruent(T: np.ndarray, K: np.ndarray) -> np.ndarray:
    """T^T K T for stacks (m, k, k) of matrices (batched matmul, far faster than a three-operand einsum)."""
    return np.matmul(np.matmul(np.transpose(T, (0, 2, 1)), K), T)
