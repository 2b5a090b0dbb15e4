"""Sparse factorisation of a frame stiffness with the beams' internal nodes condensed out.

A beam split into k elements has k - 1 internal nodes that touch only that beam. Per beam, with
its two end nodes e and its internal DOFs i (g = 6 (k - 1) of them),

    K_beam = [[K_ee, K_ei],
              [K_ie, K_ii]],

so K^-1 needs only the dense inverses of the K_ii (batched over the beams) and one sparse LU of
the Schur complement S, assembled from the condensed beams C = K_ee - K_ei K_ii^-1 K_ie on the
end nodes only (for straight Euler-Bernoulli beams C is the one-element beam stiffness). On the
5000-node benchmark grid-shell with 4 elements per beam S has 29 k DOF instead of 162 k: faster
to factor, and a solve (all DOFs, internal ones included: this is exact, not a reduced model)
takes half the time of the full LU's (docs/decisions.md, "Frame finite elements").

The inertia is kept: the pivots are those of an elimination of the K_ii without row exchanges
followed by S's factor, which are the pivots of the whole matrix eliminated in that order
(Haynsworth), so the negative-pivot count of the co-rotational path is unchanged.

S is factored by ``engine.structure.solvers``' choice for its size: PARDISO's LDL^T (its inertia from the
factor's counts) or SuperLU with diagonal pivots (the signs of U's diagonal). The element
matrices need not be symmetric (the co-rotational tangent is not quite): PARDISO then factors
S's symmetric part, its inertia is that part's, and each solve is refined towards S's own (a
path then takes the steps and iterations it takes on SuperLU; docs/decisions.md).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..linalg import assemble_blocks
from .solvers import PardisoAnalysis, count_tiny, factor_symmetric, factor_upper, library_for

__all__ = ["CondensedFactor", "FillOrdering", "SchurScatter", "sparse_lu"]

#: A pivot this small against the largest of its kind is taken for zero (a mechanism).
TINY_PIVOT = 1e-12


def sparse_lu(matrix: sp.spmatrix):
    """SuperLU of a structurally symmetric matrix: minimum-degree ordering on A^T + A, diagonal
    pivots (the inertia of a symmetric matrix is read from the signs of U's diagonal)."""
    return spla.splu(sp.csc_matrix(matrix), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                     options={"SymmetricMode": True})


class _PermutedLU:
    """A SuperLU of P A P^T solving A x = b (the U of the permuted matrix, whose diagonal holds
    the same pivots in the permuted order)."""

    def __init__(self, lu, order: np.ndarray) -> None:
        self._lu, self._order = lu, order

    @property
    def U(self):
        return self._lu.U

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        out = np.empty_like(rhs, dtype=float)
        out[self._order] = self._lu.solve(rhs[self._order])
        return out


class FillOrdering:
    """A fill-reducing symmetric ordering found at the first factorisation (SuperLU's minimum
    degree on A^T + A) and given to the next ones of the same size: the tangents along one
    non-linear path share their pattern, and finding the ordering again was some 15 % of each
    factorisation (Hall at 1500 cells, docs/benchmarks.md). The factors are those of the same
    elimination order, so the solutions and the pivots' signs are those of ``sparse_lu``."""

    def __init__(self) -> None:
        self._order: np.ndarray | None = None
        self._scatter: SchurScatter | None = None

    def scatter(self, pairs: np.ndarray, n_nodes: int, rows: np.ndarray) -> "SchurScatter":
        """The SchurScatter of S's pattern, made at the first factorisation and kept while the
        pattern (the node pairs, the nodes and the rows) stays the same."""
        kept = self._scatter
        if (kept is None or kept.n_nodes != n_nodes or not np.array_equal(kept.pairs, pairs)
                or not np.array_equal(kept.rows, rows)):
            self._scatter = kept = SchurScatter(pairs, n_nodes, rows)
        return kept

    def factor(self, matrix: sp.spmatrix):
        """SuperLU of ``matrix`` (as ``sparse_lu``) in the kept order, found now if there is none."""
        matrix = sp.csc_matrix(matrix)
        if self._order is None or len(self._order) != matrix.shape[0]:
            lu = sparse_lu(matrix)
            self._order = np.argsort(lu.perm_c)
            return lu
        order = self._order
        lu = spla.splu(matrix[order][:, order].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
        return _PermutedLU(lu, order)


class SchurScatter:
    """Where each entry of blocks (m, 12, 12) on node ``pairs`` (m, 2) lands in the matrix they
    assemble to on ``rows`` (the free DOFs of the ``n_nodes`` nodes, 6 a node): in its upper
    triangle as PARDISO reads it (sorted CSR, every diagonal entry stored) and in the whole of it
    (CSR). Made once for the tangents of a path, which share their pattern: each is then assembled
    by one weighted count per entry (numpy's bincount) instead of a block assembly, a selection of
    the free rows and columns, and a triangle's conversion (0.06-0.1 s of each 0.5-0.6 s
    factorisation of the 5000-node frame's tangent, docs/benchmarks.md). Each entry is summed over the blocks in their
    order: the block assembly's sums to rounding (numpy's reduceat adds in another order)."""

    def __init__(self, pairs: np.ndarray, n_nodes: int, rows: np.ndarray) -> None:
        self.pairs, self.rows, self.n_nodes = np.array(pairs), np.array(rows), int(n_nodes)
        m, n = len(pairs), len(rows)
        local = np.full(6 * n_nodes, -1, dtype=np.int64)
        local[rows] = np.arange(n)
        dofs = local[(6 * np.asarray(pairs)[:, :, None] + np.arange(6)).reshape(m, 12)]
        r = np.broadcast_to(dofs[:, :, None], (m, 12, 12)).ravel()
        c = np.broadcast_to(dofs[:, None, :], (m, 12, 12)).ravel()
        kept = (r >= 0) & (c >= 0)
        self._whole = self._targets(np.flatnonzero(kept), r[kept], c[kept], n, diagonal=False)
        upper = kept & (r <= c)
        self._upper = self._targets(np.flatnonzero(upper), r[upper], c[upper], n, diagonal=True)
        self._analysis: PardisoAnalysis | None = None

    @staticmethod
    def _targets(entries: np.ndarray, r: np.ndarray, c: np.ndarray, n: int, *, diagonal: bool) -> tuple:
        """(entries, their slot in the data, indptr, indices, n) of a CSR holding ``entries`` (flat
        indices into the blocks) at (r, c); ``diagonal``: every diagonal slot, stored or not."""
        key = r * n + c
        if diagonal:
            key = np.concatenate([key, np.arange(n, dtype=np.int64) * (n + 1)])
        unique, slot = np.unique(key, return_inverse=True)
        indptr = np.searchsorted(unique // n, np.arange(n + 1)).astype(np.int64)
        return entries, slot[:len(entries)], indptr, (unique % n).astype(np.int32), len(unique)

    def _matrix(self, blocks: np.ndarray, targets: tuple) -> sp.csr_matrix:
        entries, slot, indptr, indices, size = targets
        data = np.bincount(slot, weights=blocks.reshape(-1)[entries], minlength=size)
        n = len(self.rows)
        return sp.csr_matrix((data, indices.copy(), indptr.copy()), shape=(n, n))

    def upper(self, blocks: np.ndarray) -> sp.csr_matrix:
        """The upper triangle, diagonal stored, of the matrix ``blocks`` assemble to."""
        return self._matrix(blocks, self._upper)

    def whole(self, blocks: np.ndarray) -> sp.csr_matrix:
        """The matrix ``blocks`` assemble to (CSR)."""
        return self._matrix(blocks, self._whole)

    def analysis(self, upper: sp.csr_matrix) -> PardisoAnalysis:
        """PARDISO's analysis of this pattern (``upper``, as ``upper`` makes it), made at the first
        factorisation and kept for the next ones (engine.structure.solvers.PardisoAnalysis)."""
        if self._analysis is None:
            self._analysis = PardisoAnalysis(upper)
        return self._analysis


class _SchurLU:
    """S's SuperLU (kept ordering or not) with the inertia read from U's diagonal when asked for
    (SuperLU builds all of U for it)."""

    library = "superlu"
    singular = False  # an exactly zero pivot raised already

    def __init__(self, matrix: sp.spmatrix, ordering: FillOrdering | None) -> None:
        self._lu = sparse_lu(matrix) if ordering is None else ordering.factor(matrix)
        self._pivots: np.ndarray | None = None

    def _diagonal(self) -> np.ndarray:
        if self._pivots is None:
            self._pivots = self._lu.U.diagonal()
        return self._pivots

    @property
    def negative_pivots(self) -> int:
        return int(np.sum(self._diagonal() < 0))

    @property
    def tiny_pivots(self) -> int:
        return count_tiny(self._diagonal(), TINY_PIVOT)

    def solve(self, rhs: np.ndarray, refine: bool = True) -> np.ndarray:
        return self._lu.solve(rhs)


class _SchurLDLT:
    """S's PARDISO factor (engine.structure.solvers): LDL^T of S's symmetric part, perturbed pivots standing
    for the zero ones (which SuperLU refuses). ``skew``: S's skew-symmetric part, where S is not
    symmetric (a co-rotational tangent): a solve is then refined towards S's own by
    x <- x0 - (S_sym)^-1 (skew x), while that contracts, up to REFINEMENTS times."""

    library = "pardiso"

    def __init__(self, symmetric: sp.spmatrix | None, skew: sp.csr_matrix | None, *,
                 upper: sp.csr_matrix | None = None, analysis: PardisoAnalysis | None = None) -> None:
        self._factor = (factor_symmetric(symmetric, library="pardiso") if upper is None
                        else factor_upper(upper, analysis))
        self._skew = skew
        self.negative_pivots = self._factor.negative_pivots
        self.tiny_pivots = self._factor.tiny_pivots
        self.singular = self.tiny_pivots > 0

    def solve(self, rhs: np.ndarray, refine: bool = True) -> np.ndarray:
        """x with S x = rhs; ``refine`` False: with S's symmetric part (where the factor is an old
        tangent's, as in a modified-Newton corrector, refining towards it gains nothing)."""
        first = self._factor.solve(rhs)
        if self._skew is None or not refine:
            return first
        x, change = first, np.inf
        for _ in range(REFINEMENTS):
            refined = first - self._factor.solve(self._skew @ x)
            new_change = float(np.abs(refined - x).max())
            if not new_change < 0.5 * change:       # not contracting: keep the last that did
                break
            x, change = refined, new_change
            if change <= 1e-9 * float(np.abs(x).max()):
                break
        return x


#: At most this many refinements of a solve on S's symmetric part towards S's own.
REFINEMENTS = 3
#: Blocks this close to symmetric (against their largest entry) are symmetric: a linear stiffness.
SYMMETRIC = 1e-13


def _factor_of_s(blocks: np.ndarray, pairs: np.ndarray, n_nodes: int, rows: np.ndarray,
                 ordering: FillOrdering | None, library: str) -> _SchurLU | _SchurLDLT:
    """The factor of S, the blocks (m, 12, 12) assembled on the node pairs (m, 2), on ``rows``."""
    if library_for(len(rows), library) == "pardiso":
        skew_blocks = 0.5 * (blocks - blocks.transpose(0, 2, 1))
        asymmetric = len(blocks) and np.abs(skew_blocks).max() > SYMMETRIC * np.abs(blocks).max()
        try:
            if ordering is not None:  # a path's tangents: their pattern's scatter, kept
                scatter = ordering.scatter(pairs, n_nodes, rows)
                upper = scatter.upper(blocks - skew_blocks)
                return _SchurLDLT(None, scatter.whole(skew_blocks) if asymmetric else None,
                                  upper=upper, analysis=scatter.analysis(upper))
            symmetric = assemble_blocks(blocks - skew_blocks, pairs, n_nodes)[rows][:, rows]
            skew = sp.csr_matrix(assemble_blocks(skew_blocks, pairs, n_nodes)[rows][:, rows]) if asymmetric else None
            return _SchurLDLT(symmetric, skew)
        except (ImportError, OSError):  # installed, but MKL does not load here
            if library == "pardiso":
                raise
    return _SchurLU(assemble_blocks(blocks, pairs, n_nodes)[rows][:, rows], ordering)


def _block_pivots(blocks: np.ndarray) -> np.ndarray:
    """(m, g) pivots of the Gaussian elimination of each block without row exchanges (as SuperLU
    with diagonal pivots), vectorised over the blocks (block index last, for contiguous rows)."""
    work = np.ascontiguousarray(np.transpose(blocks, (1, 2, 0)))
    g = work.shape[0]
    pivots = np.empty((g, work.shape[2]))
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(g):
            pivots[k] = work[k, k]
            if k + 1 < g:
                factor = work[k + 1:, k] / work[k, k]
                work[k + 1:, k + 1:] -= factor[:, None, :] * work[k, None, k + 1:]
    return pivots.T


class CondensedFactor:
    """Solver for K x = f on the free DOFs of a frame, K given by its element matrices.

    element_matrices (b k, 12, 12) in global axes on ``connectivity`` (b k, 2) of ``n_nodes``
    nodes, beam by beam, k elements per beam, the internal nodes of beam j numbered
    n_original + j (k - 1) + t (as ``engine.structure.frame`` builds them); ``free``: the sorted free DOFs
    (6 per node, node-major), every internal DOF among them. ``solve(f)`` takes (n_free,) or
    (n_free, r). ``negative_pivots`` and ``tiny_pivots``: counts over the pivots of the
    elimination (internal blocks, then S's factor), the inertia of a symmetric K and its zero
    eigenvalues. Raises RuntimeError when K is exactly
    singular (an internal block, or S for SuperLU); PARDISO's factor of a singular S is
    ``singular`` instead, its zero pivots counted in ``tiny_pivots``. With k = 1, S is the
    assembled matrix. ``ordering``: S's elimination order for SuperLU, kept from one factorisation
    of a pattern to the next. ``library``: S's, as ``engine.structure.solvers.library_for``.
    ``compiled``: the internal blocks' inverses and pivots from one compiled elimination, and the
    condensation from one compiled pass (``engine.structure.block_inverse``: 0.03 s against 0.13 s
    at 7384 beams, and about 0.06 s less), and each solve's products with the beams' blocks in two
    compiled loops (in place of three batched products and a sparse scatter), for the many factors
    and solves of a large path; loading it costs some 0.5 s a process, more than one factor saves.
    """

    def __init__(self, element_matrices: np.ndarray, connectivity: np.ndarray, n_nodes: int, n_original: int,
                 free: np.ndarray, elements_per_beam: int, *, ordering: FillOrdering | None = None,
                 library: str = "auto", compiled: bool = False) -> None:
        k = int(elements_per_beam)
        self.free = free
        self._compiled = compiled
        self.n_dofs = 6 * n_nodes
        if k == 1:
            self._lu = _factor_of_s(element_matrices, connectivity, n_nodes, free, ordering, library)
            self._beams = None
            self._block_pivots: np.ndarray | None = np.zeros(0)
            self._K_ii: np.ndarray | None = None
            return
        m = len(connectivity) // k                      # beams
        g = 6 * (k - 1)
        # per beam: internal nodes 1..k-1 (K_ii), end nodes 0 and k (K_ee); element t joins nodes
        # t and t + 1, so only the first and the last element touch the ends
        elements = element_matrices.reshape(m, k, 12, 12)
        first, last = elements[:, 0], elements[:, k - 1]
        K_ii = np.zeros((m, g, g))
        K_ii[:, :6, :6] += first[:, 6:, 6:]
        for t in range(1, k - 1):
            K_ii[:, 6 * (t - 1):6 * (t + 1), 6 * (t - 1):6 * (t + 1)] += elements[:, t]
        K_ii[:, g - 6:, g - 6:] += last[:, :6, :6]
        self._block_pivots = None
        if compiled:
            from .block_inverse import inverse_and_pivots  # numba: imported where it pays

            inverse, pivots = inverse_and_pivots(K_ii)
            self._block_pivots = pivots.ravel()
        else:
            try:
                inverse = np.linalg.inv(K_ii)
            except np.linalg.LinAlgError as exc:
                raise RuntimeError("Factor is exactly singular (the internal nodes of a beam)") from exc
        if not np.all(np.isfinite(inverse)):
            raise RuntimeError("Factor is exactly singular (the internal nodes of a beam)")
        self._K_ii = K_ii
        self._inverse = inverse
        # W = K_ii^-1 K_ie and V = K_ei K_ii^-1 (K_ie: the first element's block on node 1 x
        # node 0 and the last's on node k-1 x node k)
        if compiled:
            from .block_inverse import condensation

            self._W, self._V, condensed = condensation(inverse, first, last)
        else:
            self._W = np.concatenate([np.matmul(inverse[:, :, :6], first[:, 6:, :6]),
                                      np.matmul(inverse[:, :, g - 6:], last[:, :6, 6:])], axis=2)   # (m, g, 12)
            self._V = np.concatenate([np.matmul(first[:, :6, 6:], inverse[:, :6, :]),
                                      np.matmul(last[:, 6:, :6], inverse[:, g - 6:, :])], axis=1)   # (m, 12, g)
            condensed = np.zeros((m, 12, 12))
            condensed[:, :6, :6] = first[:, :6, :6]
            condensed[:, 6:, 6:] = last[:, 6:, 6:]
            condensed[:, :6] -= np.matmul(first[:, :6, 6:], self._W[:, :6, :])
            condensed[:, 6:] -= np.matmul(last[:, 6:, :6], self._W[:, g - 6:, :])
        beam_ends = np.stack([connectivity[::k, 0], connectivity[k - 1::k, 1]], axis=1)
        self._n_boundary_dofs = 6 * n_original
        self._boundary = free[free < 6 * n_original]
        if len(free) - len(self._boundary) != m * g:
            raise ValueError("every internal DOF of the beams must be free")
        self._lu = _factor_of_s(condensed, beam_ends, n_original, self._boundary, ordering, library)
        self._end_dofs = (6 * beam_ends[:, :, None] + np.arange(6)).reshape(m, 12)
        # scatter of the (m, 12) end contributions onto the end-node DOFs
        self._scatter = None if compiled else sp.csr_matrix(
            (np.ones(12 * m), (self._end_dofs.ravel(), np.arange(12 * m))), shape=(6 * n_original, 12 * m))
        self._beams = (m, g)

    @property
    def library(self) -> str:
        """The library that factored S: "superlu" or "pardiso"."""
        return self._lu.library

    @property
    def singular(self) -> bool:
        """Whether PARDISO perturbed a zero pivot of S (SuperLU raised instead)."""
        return self._lu.singular

    def _internal_pivots(self) -> np.ndarray:
        """The pivots of the internal blocks' elimination without row exchanges."""
        if self._block_pivots is None:
            assert self._K_ii is not None  # beams of several elements: their internal blocks are kept
            self._block_pivots = _block_pivots(self._K_ii).ravel()
        return self._block_pivots

    @property
    def negative_pivots(self) -> int:
        """Number of negative pivots (for a symmetric K: of negative eigenvalues)."""
        return int(np.sum(self._internal_pivots() < 0)) + self._lu.negative_pivots

    @property
    def tiny_pivots(self) -> int:
        """Number of pivots under TINY_PIVOT of the largest of the internal blocks', and of S's
        (SuperLU's, or those PARDISO perturbed): zero eigenvalues, a mechanism."""
        return count_tiny(self._internal_pivots(), TINY_PIVOT) + self._lu.tiny_pivots

    def solve(self, rhs: np.ndarray, refine: bool = True) -> np.ndarray:
        """x with K x = rhs on the free DOFs, for rhs (n_free,) or (n_free, r). ``refine`` False:
        a non-symmetric K factored by PARDISO is solved with its symmetric part's factor alone."""
        rhs = np.asarray(rhs, dtype=float)
        if self._beams is None:
            return self._lu.solve(rhs, refine)
        m, g = self._beams
        columns = rhs.shape[1:]
        r = int(np.prod(columns)) if columns else 1
        full = np.zeros((self.n_dofs, r))
        full[self.free] = rhs.reshape(len(self.free), r)
        nb = self._n_boundary_dofs
        f_i = full[nb:].reshape(m, g, r)
        f_b = self._end_loads_taken_off(full[:nb], f_i)
        x_b = np.zeros((nb, r))
        x_b[self._boundary] = self._lu.solve(f_b[self._boundary], refine).reshape(-1, r)
        full[nb:] = self._internal_displacements(f_i, x_b).reshape(m * g, r)
        full[:nb] = x_b
        return full[self.free].reshape(rhs.shape)

    def _end_loads_taken_off(self, f_b: np.ndarray, f_i: np.ndarray) -> np.ndarray:
        """The end nodes' loads f_b (n_end_dofs, r) less the internal loads f_i (m, g, r) carried to
        the beam ends (V f_i per beam): compiled in place, else by batched products and a scatter."""
        if self._compiled:
            from .block_inverse import subtract_end_loads

            subtract_end_loads(self._V, f_i, self._end_dofs, f_b)
            return f_b
        m, _, r = f_i.shape
        end_forces = np.einsum("mij,mj->mi", self._V, f_i[:, :, 0])[:, :, None] if r == 1 else np.matmul(self._V, f_i)
        return f_b - self._scatter @ end_forces.reshape(12 * m, r)

    def _internal_displacements(self, f_i: np.ndarray, x_b: np.ndarray) -> np.ndarray:
        """x_i (m, g, r) = K_ii^-1 f_i - W x_e per beam, from the internal loads and the end nodes'
        displacements x_b (n_end_dofs, r)."""
        if self._compiled:
            from .block_inverse import internal_displacements

            return internal_displacements(self._inverse, self._W, f_i, x_b, self._end_dofs)
        if f_i.shape[2] == 1:                           # einsum is faster than matmul on vectors
            return (np.einsum("mij,mj->mi", self._inverse, f_i[:, :, 0])
                    - np.einsum("mij,mj->mi", self._W, x_b[self._end_dofs][:, :, 0]))[:, :, None]
        return np.matmul(self._inverse, f_i) - np.matmul(self._W, x_b[self._end_dofs])
