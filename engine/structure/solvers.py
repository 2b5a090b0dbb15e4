"""Sparse symmetric factorisations of a stiffness: factor once, solve many, with the inertia.

Two libraries, chosen by the matrix's size from the figures of ``benchmarks/factorisations.py``
on our own matrices (docs/benchmarks.md, "Factorisations"):

- PARDISO (Intel MKL, through pypardiso), symmetric indefinite LDL^T with Bunch-Kaufman pivots,
  its inertia and its perturbed (near-zero) pivots from ``iparm``. On one thread 1.6 times faster
  than SuperLU on a frame's 2 200-DOF matrix and 2.4 times at 29 000 DOF; on two, 3-6 times on
  a 150 000-DOF shell; more accurate on indefinite matrices, where SuperLU's diagonal pivots are
  not (relative residual 9e-6 against 8e-4 there). Used from PARDISO_FROM_DOFS up when pypardiso
  imports (it needs MKL, which has wheels for x86-64 Linux and Windows only).
- SuperLU (scipy ``splu``): minimum degree on A^T + A and diagonal pivots, so the signs of U's
  diagonal give the inertia. As fast below some thousand DOF (no library to load), and the
  fallback everywhere else.

``factor_symmetric`` returns a :class:`SymmetricFactor` either way. PARDISO runs on one thread
(PARDISO_THREADS), so that a factorisation gives the same bits every time. The tangents along a
non-linear path share their pattern: :class:`PardisoAnalysis` keeps PARDISO's ordering and
symbolic factorisation for them, so that each is only factored numerically (``factor_upper``).
"""

from __future__ import annotations

import ctypes
import logging
import os
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["PardisoAnalysis", "SymmetricFactor", "count_tiny", "factor_symmetric", "factor_upper", "library_for",
           "pardiso_available", "pardiso_solver", "describe", "PARDISO_FROM_DOFS", "PARDISO_THREADS", "SingularMatrix"]

log = logging.getLogger(__name__)

#: Matrices of at least this many rows are factored by PARDISO when it is installed (a frame's
#: 765-DOF matrix: 2.0 ms against SuperLU's 1.8; 2 205 DOF: 5.0 against 8.7 ms).
PARDISO_FROM_DOFS = 2_000
#: A pivot this small against the largest is taken for zero (a mechanism).
TINY_PIVOT = 1e-11


class SingularMatrix(RuntimeError):
    """The matrix is exactly singular (a zero pivot)."""


def count_tiny(pivots: np.ndarray, relative: float) -> int:
    """How many pivots are at most ``relative`` times the largest in magnitude (zero ones)."""
    scale = np.abs(pivots).max() if pivots.size else 1.0
    return int(np.sum(np.abs(pivots) <= relative * scale))


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
        self.negative_pivots = int(np.sum(pivots < 0))
        self.tiny_pivots = count_tiny(pivots, TINY_PIVOT)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._lu.solve(np.asarray(rhs, dtype=float))


#: PARDISO's threads. On two, the same matrix factored twice gave solutions that differ in the last
#: bits (two distinct of six, measured), and the remesh turns such a difference into another grid
#: (a principal direction's sign); on one, every factorisation is the same bits, in the stage's
#: process and in a pool's workers alike. One thread costs 1.4 times two on a 29 000-DOF matrix.
PARDISO_THREADS = 1


def _point_pypardiso_at_mkl() -> None:
    """Set pypardiso's own PYPARDISO_MKL_RT to MKL's runtime library where pip's wheel puts it
    (``lib/`` of the environment), unless it is set already. Where the loader does not know the
    library, pypardiso looks for it by a recursive search of sys.prefix at every solver it makes,
    its import's default solver included: 1.9 s each in a 44 000-file environment (measured on the
    5000-node frame of ``benchmarks/frame_speed.py``: 3.8 s of its first factorisation), paid again
    by every worker process. Not found here: pypardiso searches as before."""
    if "PYPARDISO_MKL_RT" in os.environ:
        return
    import glob
    import site
    import sys

    for prefix in dict.fromkeys(p for p in (sys.prefix, sys.base_prefix, site.USER_BASE) if p):
        for path in sorted(glob.glob(os.path.join(prefix, "lib", "*mkl_rt*")), key=len):
            try:
                ctypes.CDLL(path)       # the loader keeps it: pypardiso's own load is then free
            except OSError:
                continue
            os.environ["PYPARDISO_MKL_RT"] = path
            return


def pardiso_solver(mtype: int):
    """A new ``pypardiso.PyPardisoSolver``, MKL's library found once per process
    (``_point_pypardiso_at_mkl``; a path pypardiso found itself is handed on through its own
    PYPARDISO_MKL_RT)."""
    _point_pypardiso_at_mkl()
    import pypardiso

    solver = pypardiso.PyPardisoSolver(mtype=mtype)
    name = getattr(solver.libmkl, "_name", None)
    if name and "PYPARDISO_MKL_RT" not in os.environ:
        os.environ["PYPARDISO_MKL_RT"] = name
    # the process's count and this thread's: threadpoolctl (the eigensolver's BLAS limit) sets the
    # latter, which overrides the former and which a forked worker inherits
    solver.libmkl.MKL_Set_Num_Threads(PARDISO_THREADS)
    solver.libmkl.MKL_Set_Num_Threads_Local(PARDISO_THREADS)
    return solver


#: PARDISO's settings (1-based iparm index: value), all others MKL's documented default of 0:
#: given settings (1); nested dissection, METIS (2); iterative refinement only where a pivot was
#: perturbed (8: 0); perturb pivots under 1e-13 of the norm and count them (10); no scaling or
#: matching, as MKL's default for symmetric matrices (11, 13: 0); Bunch-Kaufman 1x1 and 2x2
#: pivots (21). Without iparm(1) = 1, MKL ignores the others: its default then perturbs under
#: 1e-8 and refines twice at every solve (three times its cost, measured).
PARDISO_SETTINGS = {1: 1, 2: 2, 8: 0, 10: 13, 21: 1}


class _Pardiso(SymmetricFactor):
    """PARDISO's LDL^T of the upper triangle, called through MKL directly with the matrix's index
    arrays made once: pypardiso's ``solve`` compares the matrix with the factored one at every
    call, and ``factorize`` copies it."""

    library = "pardiso"

    def __init__(self, matrix: sp.spmatrix | None, *, upper: sp.csr_matrix | None = None,
                 analysis: "PardisoAnalysis | None" = None) -> None:
        """``upper``: the matrix's upper triangle already made as ``_upper_with_diagonal`` makes it
        (sorted CSR, every diagonal entry stored), in place of ``matrix``. ``analysis``: the kept
        ordering of that pattern with a free slot (PardisoAnalysis.factor), else a handle of its own."""
        upper = _upper_with_diagonal(matrix) if upper is None else upper
        self._data = np.ascontiguousarray(upper.data, dtype=float)
        self._shared = analysis is not None
        if analysis is None:  # a handle of its own, freed with this factor (PardisoAnalysis.__del__)
            analysis = PardisoAnalysis(upper, slots=1)
            self._analysis, self._call = analysis, analysis.caller(self._data, slot=1)
            self._call(12, analysis.no_rhs)
        else:                 # a slot of the kept analysis, given back by __del__
            self._analysis, self._call = analysis, analysis.caller(self._data, slot=analysis.take())
            self._call(22, analysis.no_rhs)
        self._n = analysis.n
        iparm = analysis.iparm
        self.negative_pivots = int(iparm[22])
        self.tiny_pivots = int(iparm[13])

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        rhs = np.asarray(rhs, dtype=float)
        columns = np.asfortranarray(rhs.reshape(self._n, -1))
        return np.ascontiguousarray(self._call(33, columns)).reshape(rhs.shape)

    def __del__(self) -> None:
        if getattr(self, "_shared", False) and getattr(self, "_call", None) is not None:
            try:
                self._analysis.give_back(self._call)
            except Exception:  # noqa: BLE001 - MKL may be gone at interpreter exit
                pass


class PardisoAnalysis:
    """PARDISO's ordering and symbolic factorisation of one sparsity pattern (phase 11), kept for
    the numerical factorisations of matrices that share it (phase 22): the tangents along a
    non-linear path. The analysis was a third of each factorisation of the 5000-node frame's
    29 000-DOF tangent (0.057 of 0.165 s, docs/benchmarks.md). Up to ``slots`` factors live at once
    in one handle (PARDISO's maxfct; each its own mnum); ``factor(data)`` returns None when all are
    taken. The factors are the bits of a fresh handle's (the same METIS ordering, measured)."""

    def __init__(self, upper: sp.csr_matrix, slots: int = 4) -> None:
        """``upper``: the pattern, as ``_upper_with_diagonal`` makes it; its values are not used."""
        self._solver = solver = pardiso_solver(mtype=-2)  # real symmetric indefinite: the upper triangle
        for index, value in PARDISO_SETTINGS.items():
            solver.iparm[index - 1] = value
        self.iparm = solver.iparm
        self.n = upper.shape[0]
        self.nnz = upper.nnz
        self._ia = (upper.indptr + 1).astype(np.int32)  # one-based, as iparm(35) = 0 says
        self._ja = (upper.indices + 1).astype(np.int32)
        self._slots = int(slots)
        self._free = list(range(self._slots, 0, -1))
        self.no_rhs = np.zeros((self.n, 1), order="F")
        self._analysed = False

    def caller(self, data: np.ndarray, slot: int):
        """``call(phase, rhs)`` on ``data`` (this pattern's values) in factor slot ``slot``."""
        solver, n = self._solver, self.n
        int_p, float_p = ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_double)

        def call(phase: int, rhs: np.ndarray) -> np.ndarray:
            out, error = np.zeros_like(rhs), ctypes.c_int32(0)
            solver._mkl_pardiso(solver.pt.ctypes.data_as(ctypes.POINTER(solver._pt_type[0])),
                                ctypes.byref(ctypes.c_int32(self._slots)), ctypes.byref(ctypes.c_int32(slot)),
                                ctypes.byref(ctypes.c_int32(solver.mtype)), ctypes.byref(ctypes.c_int32(phase)),
                                ctypes.byref(ctypes.c_int32(n)), data.ctypes.data_as(float_p),
                                self._ia.ctypes.data_as(int_p), self._ja.ctypes.data_as(int_p),
                                solver.perm.ctypes.data_as(int_p), ctypes.byref(ctypes.c_int32(rhs.shape[1])),
                                solver.iparm.ctypes.data_as(int_p), ctypes.byref(ctypes.c_int32(0)),  # msglvl
                                rhs.ctypes.data_as(float_p), out.ctypes.data_as(float_p), ctypes.byref(error))
            if error.value != 0:
                raise SingularMatrix(f"PARDISO failed with error {error.value} (phase {phase})")
            return out
        call.slot = slot  # type: ignore[attr-defined]
        return call

    @property
    def available(self) -> bool:
        """Whether a factor slot is free."""
        return bool(self._free)

    def take(self) -> int:
        """A free slot, the pattern analysed first if it is not yet."""
        slot = self._free.pop()
        if not self._analysed:
            self.caller(np.zeros(self.nnz), slot)(11, self.no_rhs)
            self._analysed = True
        return slot

    def give_back(self, call) -> None:
        """Free the factor made by ``call`` (phase 0 of its slot) and its slot."""
        try:
            call(0, self.no_rhs)
        finally:
            self._free.append(call.slot)

    def factor(self, upper: sp.csr_matrix) -> "SymmetricFactor | None":
        """PARDISO's factor of ``upper`` (this pattern, sorted CSR as ``_upper_with_diagonal``
        makes it) in a free slot; None when every slot holds a live factor."""
        if not self._free or upper.nnz != self.nnz or upper.shape[0] != self.n:
            return None
        return _Pardiso(None, upper=upper, analysis=self)

    def free(self) -> None:
        """Release everything (phase -1, with this handle's slot count)."""
        self.caller(np.zeros(self.nnz), 1)(-1, self.no_rhs)

    def __del__(self) -> None:
        if getattr(self, "_solver", None) is not None:
            try:
                self.free()
            except Exception:  # noqa: BLE001 - MKL may be gone at interpreter exit
                pass


def _upper_with_diagonal(matrix: sp.spmatrix) -> sp.csr_matrix:
    """The upper triangle (CSR, sorted) with every diagonal entry stored, zeros too: PARDISO
    needs them, and a zero one (a DOF without stiffness) is then a perturbed pivot, counted."""
    upper = sp.triu(matrix, k=1, format="coo")
    n = matrix.shape[0]
    diagonal = np.arange(n)
    out = sp.csr_matrix((np.concatenate([upper.data, matrix.diagonal()]),
                         (np.concatenate([upper.row, diagonal]), np.concatenate([upper.col, diagonal]))),
                        shape=matrix.shape)
    out.sort_indices()
    return out


def describe() -> dict:
    """What factors the stiffness here, for the manifest: the libraries installed and from which
    size PARDISO takes over."""
    pardiso = pardiso_available()
    return {"libraries": ["superlu", "pardiso"] if pardiso else ["superlu"],
            "pardiso_from_dofs": PARDISO_FROM_DOFS if pardiso else None,
            "shell": f"PARDISO from {PARDISO_FROM_DOFS} DOF, SuperLU below" if pardiso
            else "SuperLU (pypardiso is not installed)",
            "frame": (f"the beams' internal nodes condensed out, then PARDISO from {PARDISO_FROM_DOFS} DOF (the "
                      "symmetric part of a co-rotational tangent), SuperLU below" if pardiso
                      else "the beams' internal nodes condensed out, then SuperLU (pypardiso is not installed)")}


def factor_upper(upper: sp.csr_matrix, analysis: PardisoAnalysis | None = None) -> SymmetricFactor:
    """PARDISO's factor of a symmetric matrix given by its upper triangle (sorted CSR, every
    diagonal entry stored, zeros too), on ``analysis`` (that pattern's, kept) where it has a free
    slot. Raises ImportError or OSError where PARDISO does not load."""
    factor = analysis.factor(upper) if analysis is not None else None
    return factor if factor is not None else _Pardiso(None, upper=upper)


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
