"""Sparse factorisations of our own stiffness matrices, one library beside the other in one run.

    .venv/bin/python benchmarks/factorisations.py [--triangles 10000 50000 100000] [--nodes 1500 5000]

Matrices: the Scordelis-Lo shell roof (free DOFs of ``engine.structure.shell.shell_stiffness``, symmetric
positive definite) and the frame grid-shell of benchmarks/frame_speed.py (its Schur complement on
the beam-end nodes, as ``engine.structure.condensed`` factors it; its tangent past a limit point is
indefinite, and the inertia is checked on K - sigma I with sigma above the lowest eigenvalues).
Per matrix and library: factor seconds, solve seconds, the residual of one solve and the count of
negative pivots against scipy's dense count (small matrices) or SuperLU's. Libraries: SuperLU
(scipy ``splu``), PARDISO (MKL through pypardiso, symmetric indefinite, as ``engine.structure.solvers``
factors: the product's from 2 000 DOF) and CHOLMOD
(scikit-sparse, LDL^T) where they import. Each factorisation is timed three times, the median printed.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.structure.condensed import sparse_lu  # noqa: E402


def shell_matrix(triangles: int) -> sp.csc_matrix:
    from benchmarks.shell_scaling import MATERIAL, THICKNESS, roof
    from engine.structure.shell import shell_stiffness

    model = roof(triangles)
    K, _ = shell_stiffness(model.mesh.vertices, model.mesh.faces, THICKNESS, MATERIAL)
    free = np.flatnonzero(~model.restrained.ravel())
    return sp.csc_matrix(K[free][:, free])


def frame_matrix(nodes: int) -> sp.csc_matrix:
    """The Schur complement on the beam ends (one element per beam: the matrix SuperLU factors)."""
    from benchmarks.frame_speed import model
    from engine.structure import frame as fr

    frame, supports, _ = model(nodes, 1)
    stiffness = fr.factor_stiffness(frame, supports)
    return sp.csc_matrix(stiffness.K[stiffness.free][:, stiffness.free])


class _SuperLU:
    name = "SuperLU (scipy splu)"

    def factor(self, A):
        return sparse_lu(A)

    def solve(self, f, b):
        return f.solve(b)

    def negative(self, f, A):
        return int(np.sum(f.U.diagonal() < 0))


class _Pardiso:
    name = "PARDISO (MKL, engine.structure.solvers' settings)"

    def __init__(self):
        import pypardiso  # noqa: F401

    def factor(self, A):
        from engine.structure.solvers import factor_symmetric  # MKL found once, iparm as the product sets it

        return factor_symmetric(A, library="pardiso")

    def solve(self, f, b):
        return f.solve(b)

    def negative(self, f, A):
        return int(f.negative_pivots)


class _Cholmod:
    name = "CHOLMOD (scikit-sparse, LDL^T)"

    def __init__(self):
        import sksparse.cholmod  # noqa: F401

    def factor(self, A):
        from sksparse.cholmod import cholesky

        return cholesky(sp.csc_matrix(A), mode="simplicial")

    def solve(self, f, b):
        return f(b)

    def negative(self, f, A):
        return int(np.sum(f.D() < 0))


def libraries() -> tuple[list, list[str]]:
    found, missing = [_SuperLU()], []
    for kind in (_Pardiso, _Cholmod):
        try:
            found.append(kind())
        except ImportError as error:
            missing.append(f"{kind.name}: not installed ({error})")
    return found, missing


def measure(library, A: sp.csc_matrix, repeats: int = 3) -> dict:
    times, factor = [], None
    for _ in range(repeats):
        started = time.perf_counter()
        factor = library.factor(A)
        times.append(time.perf_counter() - started)
    b = np.random.default_rng(0).normal(size=A.shape[0])
    started = time.perf_counter()
    x = library.solve(factor, b)
    solve_s = time.perf_counter() - started
    residual = float(np.linalg.norm(A @ x - b) / np.linalg.norm(b))
    return {"factor_s": float(np.median(times)), "solve_s": solve_s, "residual": residual,
            "negative": library.negative(factor, A)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--triangles", type=int, nargs="*", default=[10_000, 50_000, 100_000])
    parser.add_argument("--nodes", type=int, nargs="*", default=[1500, 5000])
    args = parser.parse_args()
    found, missing = libraries()
    load = os.getloadavg()[0]
    print(f"factorisations: {len(found)} libraries, load average {load:.1f} at the start; "
          f"MKL/OpenBLAS threads: {os.environ.get('MKL_NUM_THREADS', 'default')}")
    for line in missing:
        print("  " + line)
    cases = [(f"shell {t} triangles", lambda t=t: shell_matrix(t)) for t in args.triangles]
    cases += [(f"frame {n} nodes", lambda n=n: frame_matrix(n)) for n in args.nodes]
    print("| matrix | n | non-zeros | library | factor s | solve s | residual | negative pivots | factor / fastest |")
    print("|---|---|---|---|---|---|---|---|---|")
    for title, build in cases:
        A = build()
        # an indefinite copy: shifted above the smallest diagonal entries' scale, so that some
        # pivots are negative and the libraries' inertia can be compared
        rows = []
        for matrix, label in ((A, title), (_shifted(A), title + ", shifted (indefinite)")):
            results = [(lib, measure(lib, matrix)) for lib in found]
            fastest = min(r["factor_s"] for _, r in results)
            for lib, r in results:
                rows.append(f"| {label} | {matrix.shape[0]} | {matrix.nnz} | {lib.name} | {r['factor_s']:.3f} | "
                            f"{r['solve_s']:.3f} | {r['residual']:.1e} | {r['negative']} | "
                            f"{r['factor_s'] / fastest:.2f} |")
        print("\n".join(rows), flush=True)
    return 0


def _shifted(A: sp.csc_matrix) -> sp.csc_matrix:
    """A - sigma I with sigma the 1st percentile of the diagonal: indefinite, still sparse."""
    sigma = float(np.percentile(A.diagonal(), 1))
    return sp.csc_matrix(A - sigma * sp.identity(A.shape[0], format="csc"))


if __name__ == "__main__":
    raise SystemExit(main())
