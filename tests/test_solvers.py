"""The factorisation layer against dense linear algebra: solutions, Sylvester's inertia and the
detection of singular matrices, for each library installed here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from engine.structure.solvers import PARDISO_FROM_DOFS, factor_symmetric, library_for, pardiso_available

LIBRARIES = ["superlu"] + (["pardiso"] if pardiso_available() else [])


def _laplacian(n: int, shift: float) -> sp.csr_matrix:
    """The 2D five-point Laplacian on an n x n grid less shift x I: eigenvalues known in closed form."""
    one = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    return sp.csr_matrix(sp.kron(one, sp.identity(n)) + sp.kron(sp.identity(n), one) - shift * sp.identity(n * n))


@pytest.mark.parametrize("library", LIBRARIES)
@pytest.mark.parametrize("shift", [0.0, 0.5, 2.3])
def test_solve_and_inertia_match_the_closed_form_spectrum(library, shift):
    n = 30
    A = _laplacian(n, shift)
    k = np.arange(1, n + 1)
    one = 2 - 2 * np.cos(np.pi * k / (n + 1))                     # eigenvalues of the 1D operator
    eigenvalues = (one[:, None] + one[None, :]).ravel() - shift
    factor = factor_symmetric(A, library=library)
    assert factor.library == library
    assert factor.negative_pivots == int(np.sum(eigenvalues < 0))
    assert factor.tiny_pivots == 0
    b = np.random.default_rng(1).normal(size=(n * n, 3))
    x = factor.solve(b)
    assert x.shape == b.shape
    assert np.linalg.norm(A @ x - b) / np.linalg.norm(b) < 1e-10
    assert np.allclose(factor.solve(b[:, 0]), x[:, 0])


@pytest.mark.parametrize("library", LIBRARIES)
def test_a_singular_matrix_is_seen(library):
    """A free 1D chain (zero row sums: one zero eigenvalue) is singular: an exactly zero pivot
    (SuperLU raises) or a near-zero one counted."""
    from engine.structure.solvers import SingularMatrix

    A = sp.csr_matrix(sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(50, 50)).tolil())
    A = A.tolil()
    A[0, 0] = A[-1, -1] = 1.0
    try:
        factor = factor_symmetric(A.tocsr(), library=library)
    except SingularMatrix:
        return
    assert factor.tiny_pivots + factor.negative_pivots >= 1


def test_the_library_follows_the_size_and_what_is_installed():
    assert library_for(1000) == "superlu"
    assert library_for(PARDISO_FROM_DOFS) == ("pardiso" if pardiso_available() else "superlu")
    assert library_for(10, "pardiso") == "pardiso"
    with pytest.raises(ValueError, match="unknown"):
        library_for(10, "umfpack")


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso is not installed")
def test_the_shell_solved_by_pardiso_is_the_shell_solved_by_superlu(monkeypatch):
    """The Scordelis-Lo roof with PARDISO forced (its size threshold set to 0): the same midside
    deflection as SuperLU's to 1e-9, within 15 % of the published 0.3024 at this coarse mesh
    (12.6 % off, docs/benchmarks.md), and the stage records which library solved it."""
    import engine.structure.solvers as solvers
    from tests.shell_models import scordelis_lo

    superlu, _, _ = scordelis_lo(8)
    monkeypatch.setattr(solvers, "PARDISO_FROM_DOFS", 0)
    pardiso, error, _ = scordelis_lo(8)
    assert pardiso == pytest.approx(superlu, rel=1e-9)
    assert pardiso == pytest.approx(0.3024, rel=0.15) and error < 1e-8


@pytest.mark.parametrize("library", LIBRARIES)
def test_a_loose_part_of_a_shell_is_a_mechanism_for_either_library(library, monkeypatch):
    """Two caps side by side, only the first supported: the supports hold every rigid motion of
    the whole, yet the second cap moves freely: the factor finds the singular stiffness."""
    import engine.structure.solvers as solvers
    from engine.errors import MechanismError
    from engine.geometry.parametric import cap
    from engine.mesh import TriMesh
    from engine.structure.shell import ShellMaterial, analyse_shell
    from engine.structure.supports import Supports

    monkeypatch.setattr(solvers, "PARDISO_FROM_DOFS", 0 if library == "pardiso" else 10**9)
    one = cap(span=4.0, span_to_rise=4.0, rings=3)
    two = TriMesh(vertices=np.vstack([one.vertices, one.vertices + [10.0, 0.0, 0.0]]),
                  faces=np.vstack([one.faces, one.faces + one.n_vertices]))
    supports = Supports.merge([(one.boundary_loops[0], np.array([1, 1, 1, 0, 0, 0], bool))])
    loads = np.zeros((two.n_vertices, 6))
    loads[:, 2] = -1.0
    with pytest.raises(MechanismError, match="beyond rigid-body|singular") as info:
        analyse_shell(two, supports, loads, thickness=0.02, material=ShellMaterial(E=1e9, nu=0.3))
    assert info.value.n_modes >= 1


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso is not installed")
def test_pardiso_looks_for_mkl_once_per_process_and_each_factor_stays_its_own(monkeypatch):
    """pypardiso searches sys.prefix for MKL at every solver it makes where the loader does not
    know the library (0.6-1.4 s, twenty times a small factorisation): after the first factor no
    search runs. Two factors alive at once each solve their own matrix."""
    import glob

    first_matrix, second_matrix = _laplacian(20, 0.0), _laplacian(20, 0.7)
    first = factor_symmetric(first_matrix, library="pardiso")

    def no_search(*args, **kwargs):
        raise AssertionError("pypardiso searched for MKL again")

    monkeypatch.setattr(glob, "glob", no_search)
    second = factor_symmetric(second_matrix, library="pardiso")
    b = np.random.default_rng(2).normal(size=400)
    for factor, matrix in ((first, first_matrix), (second, second_matrix)):
        assert np.linalg.norm(matrix @ factor.solve(b) - b) / np.linalg.norm(b) < 1e-10


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso is not installed")
def test_a_fresh_process_never_searches_the_environment_for_mkl():
    """Nor at pypardiso's import, whose default solver searched sys.prefix recursively before the
    first factor could say where MKL is (1.9 s in this project's environment, in every worker)."""
    import os
    import subprocess
    import sys

    code = """
import glob, os
os.environ.pop("PYPARDISO_MKL_RT", None)
searches = []
plain = glob.glob
glob.glob = lambda pattern, **kw: (searches.append(kw.get("recursive", False)), plain(pattern, **kw))[1]
import numpy as np, scipy.sparse as sp
from engine.structure.solvers import factor_symmetric
f = factor_symmetric(sp.diags([2.0] * 3000).tocsr(), library="pardiso")
assert f.library == "pardiso" and np.allclose(f.solve(np.ones(3000)), 0.5)
print(sum(searches))
"""
    env = {k: v for k, v in os.environ.items() if k != "PYPARDISO_MKL_RT"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         cwd=str(Path(__file__).resolve().parents[1]), timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "0", "a recursive search for MKL ran"


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso is not installed")
def test_pardiso_takes_its_settings_a_small_pivot_is_not_a_zero_one_and_a_solve_is_not_refined():
    """MKL ignores every iparm unless iparm(1) = 1: its defaults then take pivots under 1e-8 of
    the norm for zero (a stiff member beside a soft one would read as a mechanism) and refine
    every solve twice. diag(1, 1e-10) is regular; a zero diagonal is one zero pivot."""
    regular = factor_symmetric(sp.diags([1.0, 1e-10, 2.0]).tocsr(), library="pardiso")
    assert regular.tiny_pivots == 0 and regular.negative_pivots == 0
    assert np.allclose(regular.solve(np.array([1.0, 1e-10, 2.0])), 1.0, rtol=1e-12)
    assert regular._analysis.iparm[6] == 0, "no iterative refinement without perturbed pivots"
    singular = factor_symmetric(sp.csr_matrix(np.diag([1.0, 0.0, 2.0])), library="pardiso")
    assert singular.tiny_pivots == 1


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso is not installed")
def test_pardiso_gives_the_same_bits_every_time_here_and_in_a_pool_worker():
    """On two threads PARDISO's solutions of one matrix differed in the last bits from one
    factorisation to the next, and the remesh turns that into another grid. On one thread, after
    the eigensolver's threadpoolctl limit too (it leaves a thread-local count that a forked
    worker inherits): the same bits in this process and in a pool's workers."""
    from engine.linalg import single_threaded_blas
    from workflow.pools import process_pool

    with single_threaded_blas():
        pass
    here = {_solution_bits(k) for k in range(4)}
    with process_pool(2) as pool:
        assert pool is not None
        there = set(pool.map(_solution_bits, range(4)))
    assert len(here) == 1 and here == there
    assert next(iter(here))[0] == 1, "one MKL thread"


def _solution_bits(_: int = 0) -> tuple[int, bytes]:
    """MKL's thread count during a factorisation, and the solution's bytes, of a matrix with
    enough rows (14 400) for PARDISO to share its work between threads."""
    A = _laplacian(120, 0.3)
    factor = factor_symmetric(A, library="pardiso")
    threads = int(factor._analysis._solver.libmkl.MKL_Get_Max_Threads())
    return threads, factor.solve(np.linspace(0.0, 1.0, A.shape[0])).tobytes()


def _random_blocks(seed: int, n_nodes: int = 40, m: int = 90):
    rng = np.random.default_rng(seed)
    pairs = np.array([rng.choice(n_nodes, 2, replace=False) for _ in range(m)])
    pairs[1] = pairs[0][::-1]                                   # one pair twice, turned
    blocks = rng.normal(size=(m, 12, 12))
    rows = np.sort(rng.choice(6 * n_nodes, 5 * n_nodes, replace=False))
    return pairs, blocks, n_nodes, rows


def test_the_scatter_assembles_what_the_block_assembly_does():
    """SchurScatter (a path's tangents assembled by one weighted count per entry) against the block
    assembly with the free rows and columns selected: the same pattern, every diagonal entry
    stored in the triangle, the same values to rounding; kept by the ordering while the pattern
    holds."""
    from engine.linalg import assemble_blocks
    from engine.structure.condensed import FillOrdering
    from engine.structure.solvers import _upper_with_diagonal

    pairs, blocks, n_nodes, rows = _random_blocks(3)
    ordering = FillOrdering()
    scatter = ordering.scatter(pairs, n_nodes, rows)
    whole = sp.csr_matrix(assemble_blocks(blocks, pairs, n_nodes)[rows][:, rows])
    whole.sort_indices()
    upper = _upper_with_diagonal(whole)
    for ours, theirs in ((scatter.whole(blocks), whole), (scatter.upper(blocks), upper)):
        assert np.array_equal(ours.indptr, theirs.indptr) and np.array_equal(ours.indices, theirs.indices)
        assert np.abs(ours.data - theirs.data).max() <= 1e-14 * np.abs(theirs.data).max()
    triangle = scatter.upper(blocks)                             # each row starts at its diagonal
    assert np.array_equal(triangle.indices[triangle.indptr[:-1]], np.arange(len(rows)))
    assert ordering.scatter(pairs.copy(), n_nodes, rows.copy()) is scatter
    assert ordering.scatter(pairs[:-1], n_nodes, rows) is not scatter


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso is not installed")
def test_a_path_tangent_factored_through_the_scatter_solves_and_counts_as_the_assembled_one():
    """A condensed factor of a frame large enough for PARDISO (over PARDISO_FROM_DOFS), with a
    non-symmetric tangent: made with a path's ordering (the scatter) and without (the assembly),
    the same solutions to 1e-10 and the same inertia."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from frame_speed import model

    from engine.structure.beam_elements import element_mesh
    from engine.structure.condensed import CondensedFactor, FillOrdering
    from engine.structure.corotational import _Corotational

    frame, supports, loads = model(500, 2)
    cr = _Corotational(frame, supports)
    x = cr.X + 1e-3 * np.random.default_rng(1).normal(size=cr.X.shape)     # off the initial state
    _, state = cr.internal_forces(x, np.tile(np.eye(3), (cr.n_all, 1, 1)))
    tangent = cr.tangent(state)
    el = element_mesh(frame)
    args = (tangent, el.connectivity, len(el.nodes), el.n_original, cr.free, 2)
    kept, plain = CondensedFactor(*args, ordering=FillOrdering()), CondensedFactor(*args)
    assert kept.library == plain.library == "pardiso" and 6 * el.n_original > PARDISO_FROM_DOFS
    b = np.random.default_rng(2).normal(size=len(cr.free))
    assert np.abs(kept.solve(b) - plain.solve(b)).max() <= 1e-10 * np.abs(plain.solve(b)).max()
    assert kept.negative_pivots == plain.negative_pivots


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso is not installed")
def test_factors_on_a_kept_analysis_are_the_bits_of_fresh_ones_and_give_their_slots_back():
    """A path's tangents share their pattern, so PARDISO's ordering and symbolic factorisation are
    kept (PardisoAnalysis). Three shifted Laplacians of one pattern: each factor made in a slot of
    the kept analysis solves with the bits of a fresh handle's and counts the closed form's negative
    eigenvalues; with every slot live the next factor takes a handle of its own; a slot is free
    again once its factor is gone; another pattern is not taken."""
    from engine.structure.solvers import PardisoAnalysis, _upper_with_diagonal, factor_upper

    n, shifts = 30, (0.0, 0.5, 2.3)
    k = np.arange(1, n + 1)
    one = 2 - 2 * np.cos(np.pi * k / (n + 1))
    negatives = [int(np.sum((one[:, None] + one[None, :]).ravel() - shift < 0)) for shift in shifts]
    uppers = [_upper_with_diagonal(_laplacian(n, shift)) for shift in shifts]
    b = np.random.default_rng(4).normal(size=(n * n, 2))
    analysis = PardisoAnalysis(uppers[0], slots=2)
    kept = [factor_upper(upper, analysis) for upper in uppers]
    assert [factor._shared for factor in kept] == [True, True, False] and not analysis.available
    for factor, upper, count in zip(kept, uppers, negatives):
        fresh = factor_upper(upper)
        assert factor.solve(b).tobytes() == fresh.solve(b).tobytes()
        assert factor.negative_pivots == fresh.negative_pivots == count
    del kept[0]
    assert analysis.available
    again = factor_upper(uppers[2], analysis)
    assert again._shared and again.solve(b).tobytes() == kept[-1].solve(b).tobytes()
    assert analysis.factor(_upper_with_diagonal(_laplacian(20, 0.0))) is None
