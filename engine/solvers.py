"""Sparse symmetric factorisations of a stiffness: factor once, solve many, with the inertia.

Two libraries, chosen by the matrix's size from the figures of ``benchmarks/factorisations.py``
on our own matrices (docs/benchmarks.md, "Factorisations"):

- SuperLU (scipy ``splu``): minimum degree on A^T + A and diagonal pivots, so the signs of U's
  diagonal give the inertia. Fastest up to some tens of thousands of DOF (the shell at 10k
  triangles, 30k DOF: 2.5 times faster than PARDISO; every frame of the benchmarks).
- PARDISO (Intel MKL, through pypardiso), symmetric indefinite LDL^T with Bunch-Kaufman pivots,
  its inertia and its perturbed (near-zero) pivots from ``iparm``: 1.9 times faster than SuperLU at
  150k DOF, and accurate on indefinite matrices where SuperLU's diagonal pivots are not (relative
  residual 1e-9 against 7e-4). Used from PARDISO_FROM_DOFS up when pypardiso imports (it needs
  MKL, which has wheels for x86-64 Linux and Windows only).

``factor_symmetric`` returns a :class:`SymmetricFactor` either way.
"""

from __future__ import annotations

import logging
import os
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["SymmetricFactor", "factor_symmetric", "library_for", "pardiso_available", "pardiso_solver", "describe",
           "PARDISO_FROM_DOFS", "SingularMatrix"]

log = logging.getLogger(__name__)

#: Matrices of at least this many rows are factored by PARDISO when it is installed.
PARDISO_FROM_DOFS = 60_000
#: A pivot this small against the largest is taken for zero (a mechanism).
TINY_PIVOT = 1e-11


class SingularMatrix(RuntimeError):
    """The matrix is exactly singular (a zero pivot)."""


def pardiso_available() -> bool:
    """Whether pypardiso is installed here (found, not imported: loading MKL takes a second, which
    a cached run should not spend; factor_symmetric falls back on SuperLU if it does not load)."""
    from importlib.util import find_spec

    return find_spec("pypardiso") is not None


def library_for(n_rows: int, library: str = "auto") -> str:
    """"superlu" or "pardiso": the one asked for, or with "auto" the faster for this size that is
    installed."""
    if library not in ("auto", "superlu", "pardiso"):
        raise ValueError(f"unknown factorisation library {library!r}: auto, superlu or pardiso")
    if library == "auto":
        return "pardiso" if n_rows >= PARDISO_FROM_DOFS and pardiso_available() else "superlu"
    return library


class SymmetricFactor:
    """A factored symmetric matrix: ``solve(rhs)`` for (n,) or (n, r) right-hand sides,
    ``negative_pivots`` (the count of negative eigenvalues, Sylvester), ``tiny_pivots`` (pivots
    under TINY_PIVOT of the largest, or perturbed by PARDISO: zero eigenvalues, a mechanism) and
    ``library``."""

    library: str
    negative_pivots: int
    tiny_pivots: int

    def solve(self, rhs: np.ndarray) -> np.ndarray:  # pragma: no cover - the subclasses'
        raise NotImplementedError


class _SuperLU(SymmetricFactor):
    library = "superlu"

    def __init__(self, matrix: sp.spmatrix) -> None:
        try:
            self._lu = spla.splu(sp.csc_matrix(matrix), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                 options={"SymmetricMode": True})
        except RuntimeError as error:  # "Factor is exactly singular"
            raise SingularMatrix(str(error)) from error
        pivots = self._lu.U.diagonal()
        scale = np.abs(pivots).max() if pivots.size else 1.0
        self.negative_pivots = int(np.sum(pivots < 0))
        self.tiny_pivots = int(np.sum(np.abs(pivots) <= TINY_PIVOT * scale))

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._lu.solve(np.asarray(rhs, dtype=float))


def pardiso_solver(mtype: int):
    """A new ``pypardiso.PyPardisoSolver``, MKL's library found once per process. Where the loader
    does not know it (pip's wheels), pypardiso looks for it at every solver it makes, by a recursive
    search of sys.prefix: 0.6-1.4 s measured, twenty times an 8 600-DOF factorisation. The
    path found first is handed to the next ones through pypardiso's own PYPARDISO_MKL_RT."""
    import pypardiso

    solver = pypardiso.PyPardisoSolver(mtype=mtype)
    name = getattr(solver.libmkl, "_name", None)
    if name and "PYPARDISO_MKL_RT" not in os.environ:
        os.environ["PYPARDISO_MKL_RT"] = name
    return solver


class _Pardiso(SymmetricFactor):
    library = "pardiso"

    def __init__(self, matrix: sp.spmatrix) -> None:
        self._solver = pardiso_solver(mtype=-2)  # real symmetric indefinite
        self._solver.set_iparm(10, 13)  # perturb pivots under 1e-13 of the norm (and count them)
        upper = sp.triu(sp.csr_matrix(matrix), format="csr")
        upper.sort_indices()
        self._upper = upper
        self._solver.factorize(upper)
        iparm = self._solver.iparm
        self.negative_pivots = int(iparm[22])
        self.tiny_pivots = int(iparm[13])

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        rhs = np.asarray(rhs, dtype=float)
        return np.asarray(self._solver.solve(self._upper, np.ascontiguousarray(rhs))).reshape(rhs.shape)

    def __del__(self) -> None:
        solver = getattr(self, "_solver", None)
        if solver is not None:
            try:
                solver.free_memory(everything=True)
            except Exception:  # noqa: BLE001 - MKL may be gone at interpreter exit
                pass


def describe() -> dict:
    """What factors the stiffness here, for the manifest: the libraries installed and from which
    size PARDISO takes over."""
    pardiso = pardiso_available()
    return {"libraries": ["superlu", "pardiso"] if pardiso else ["superlu"],
            "pardiso_from_dofs": PARDISO_FROM_DOFS if pardiso else None,
            "shell": f"PARDISO from {PARDISO_FROM_DOFS} DOF, SuperLU below" if pardiso
            else "SuperLU (pypardiso is not installed)",
            "frame": "SuperLU (PARDISO is faster on its matrices too, but not yet used in the forked path "
                     "workers; docs/decisions.md, Factorisations)"}


def factor_symmetric(matrix: sp.spmatrix, *, library: str = "auto") -> SymmetricFactor:
    """Factor a sparse symmetric matrix with ``library`` ("auto": see library_for). Raises
    SingularMatrix when SuperLU meets an exactly zero pivot."""
    chosen = library_for(matrix.shape[0], library)
    started = time.perf_counter()
    factor: SymmetricFactor | None = None
    if chosen == "pardiso":
        try:
            factor = _Pardiso(matrix)
        except (ImportError, OSError):  # installed, but MKL does not load here
            if library == "pardiso":
                raise
            log.info("PARDISO did not load here: SuperLU factors the %d rows instead", matrix.shape[0])
    factor = factor if factor is not None else _SuperLU(matrix)
    log.debug("factored %d rows, %d non-zeros with %s in %.2f s", matrix.shape[0], matrix.nnz, factor.library,
              time.perf_counter() - started)
    return factor
