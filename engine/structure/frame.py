"""Space-frame analyses: linear static and linear buckling, on the beam elements of
``engine.structure.beam_elements``, with the stiffness assembled and factored once per model
(``factor_stiffness``) and passed to the analyses that follow one another; the co-rotational
non-linear path is in ``engine.structure.corotational`` and the solver-level JSON interface in
``workflow.solver_json``. Why our own elements and not pyfe3d: docs/decisions.md.

Units: any consistent set (SI in the workflow).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import ConvergenceError
from ..linalg import single_threaded_blas
from .beam_elements import (
    ElementMesh,
    FrameModel,
    assemble,
    check_loads,
    check_rigid_modes,
    condense,
    element_dofs,
    element_geometry,
    element_mesh,
    factor_free_stiffness,
    factor_or_none,
    geometric_stiffness,
    local_stiffness,
    released_zero,
    restrained_dofs,
    transformation,
)
from .condensed import CondensedFactor
from .corotational import NonlinearResult, nonlinear_static
from .element_kernels import to_global
from .loads import equilibrium_error
from .supports import DOF_NAMES, Supports

__all__ = ["FrameModel", "FrameStiffness", "LinearResult", "BucklingResult", "NonlinearResult", "factor_stiffness",
           "linear_static", "linear_buckling", "nonlinear_static", "DOF_NAMES"]


@dataclass(frozen=True, kw_only=True)
class LinearResult:
    """displacements (n,6) and reactions (n,6) in global axes; beam_end_forces (b,2,6): section
    forces [N, Vy, Vz, T, My, Mz] in each beam's local axes at its start and end, N > 0 in
    tension (at the end: the element's end forces; at the start: their negatives, so a beam
    carrying a constant N, T or M shows the same value at both ends); equilibrium_error:
    |loads + reactions| (forces, and moments about the origin over the model size) / |loads|;
    beam_energy (b,): each beam's share of the strain energy (sums to 1), where asked for."""

    displacements: np.ndarray
    reactions: np.ndarray
    beam_end_forces: np.ndarray
    equilibrium_error: float
    beam_energy: np.ndarray | None = None


@dataclass(frozen=True, kw_only=True)
class BucklingResult:
    """Positive buckling load factors (k,) ascending and mode shapes (k,n,6), largest translation 1,
    each mode signed so that its largest translation component is positive (``_signed_modes``);
    beam_energy (b,): each beam's share of the first mode's strain energy (where the stiffness
    that raises lambda_1 counts most)."""

    factors: np.ndarray
    modes: np.ndarray
    beam_energy: np.ndarray | None = None



# ----------------------------------------------------------------------------- linear analyses

@dataclass
class FrameStiffness:
    """The linear stiffness of a model on its supports, factored (factor_stiffness)."""
    el: ElementMesh
    L: np.ndarray
    R: np.ndarray
    T: np.ndarray
    K_local: np.ndarray
    K_elements: np.ndarray   # (m,12,12) in global axes
    K: sp.csc_matrix
    restrained: np.ndarray
    free: np.ndarray
    lu: CondensedFactor
    K_free: sp.csr_matrix | None = None      # K on the free DOFs, made when first needed


@dataclass
class _Linear:
    el: ElementMesh
    L: np.ndarray
    R: np.ndarray
    T: np.ndarray
    K_local: np.ndarray
    K: sp.csc_matrix
    restrained: np.ndarray
    free: np.ndarray
    lu: CondensedFactor
    u: np.ndarray
    F: np.ndarray
    local_forces: np.ndarray
    stiffness: FrameStiffness
    K_elements: np.ndarray


def factor_stiffness(model: FrameModel, supports: Supports) -> FrameStiffness:
    """The linear stiffness of ``model`` on ``supports``, assembled and factored: pass it to the
    analyses that follow one another on one model (serviceability and ultimate loads, then
    buckling) so that they factor it once, and drop it after them (it holds the factor)."""
    el = element_mesh(model)
    n_all = len(el.nodes)
    restrained = restrained_dofs(supports, el.n_original, n_all)
    check_rigid_modes(el.nodes, restrained)
    L, R = element_geometry(el, el.nodes)
    T = transformation(R)
    K_local = condense(local_stiffness(L, el), el.released)
    K_elements = to_global(R, K_local)
    K = assemble(K_elements, element_dofs(el.connectivity), 6 * n_all)
    free = np.flatnonzero(~restrained)
    lu = factor_free_stiffness(K_elements, el, free,
                               np.linalg.norm(model.nodes[model.beams[:, 1]] - model.nodes[model.beams[:, 0]], axis=1),
                               compiled=True)
    return FrameStiffness(el=el, L=L, R=R, T=T, K_local=K_local, K_elements=K_elements, K=K, restrained=restrained,
                          free=free, lu=lu)


def _solve_linear(model: FrameModel, supports: Supports, loads: np.ndarray,
                  stiffness: FrameStiffness | None = None) -> _Linear:
    loads = check_loads(loads, model.nodes.shape[0])
    stiffness = stiffness if stiffness is not None else factor_stiffness(model, supports)
    el, free = stiffness.el, stiffness.free
    n_all = len(el.nodes)
    F = np.zeros(6 * n_all)
    F[:6 * el.n_original] = loads.ravel()
    u = np.zeros(6 * n_all)
    u[free] = stiffness.lu.solve(F[free])
    dofs = element_dofs(el.connectivity)
    local_forces = np.matmul(stiffness.K_local, np.matmul(stiffness.T, u[dofs][:, :, None]))[:, :, 0]
    return _Linear(el=el, L=stiffness.L, R=stiffness.R, T=stiffness.T, K_local=stiffness.K_local, K=stiffness.K,
                   restrained=stiffness.restrained, free=free, lu=stiffness.lu, u=u, F=F, local_forces=local_forces,
                   stiffness=stiffness, K_elements=stiffness.K_elements)


def _beam_energy_shares(stiffness: "FrameStiffness", u: np.ndarray) -> np.ndarray:
    """(b,) each beam's share of the strain energy u' K u of a displacement field u (all DOFs)."""
    el = stiffness.el
    dofs = element_dofs(el.connectivity)
    local_u = np.matmul(stiffness.T, u[dofs][:, :, None])
    energy = (np.matmul(stiffness.K_local, local_u) * local_u).sum(axis=(1, 2))
    per_beam = np.bincount(el.beam, weights=np.maximum(energy, 0.0), minlength=len(el.first))
    total = per_beam.sum()
    return per_beam / total if total > 0 else per_beam


def _section_forces(el: ElementMesh, local_forces: np.ndarray) -> np.ndarray:
    out = np.zeros((len(el.first), 2, 6))
    out[:, 0] = -local_forces[el.first, :6]
    out[:, 1] = local_forces[el.last, 6:]
    return out


def linear_static(model: FrameModel, supports: Supports, loads: np.ndarray, *,
                  stiffness: FrameStiffness | None = None, with_energy: bool = False) -> LinearResult:
    """Linear static analysis under nodal loads (n,6) on the original nodes; ``stiffness``: the
    model's factored stiffness on these supports (factor_stiffness), else factored here;
    ``with_energy``: also each beam's share of the strain energy (``beam_energy``; the sizing's)."""
    state = _solve_linear(model, supports, loads, stiffness)
    n = state.el.n_original
    reactions_all = (state.K @ state.u - state.F).reshape(-1, 6)
    reactions_all[~state.restrained.reshape(-1, 6)] = 0.0
    displacements = state.u.reshape(-1, 6)[:n]
    reactions = reactions_all[:n]
    return LinearResult(displacements=displacements, reactions=reactions,
                        beam_end_forces=_section_forces(state.el, state.local_forces),
                        equilibrium_error=equilibrium_error(model.nodes, np.asarray(loads, float), reactions),
                        beam_energy=_beam_energy_shares(state.stiffness, state.u) if with_energy else None)


def linear_buckling(model: FrameModel, supports: Supports, loads: np.ndarray, n_modes: int = 6, *,
                    stiffness: FrameStiffness | None = None) -> BucklingResult:
    """Linear buckling: (K + lambda K_G) phi = 0 with K_G from the linear axial forces; the
    ``n_modes`` smallest positive factors (none when nothing is in compression).

    Lanczos (ARPACK) in the buckling spectral transformation about a shift sigma just below the
    first factor: (K + sigma K_G)^-1 K, whose eigenvalues lambda / (lambda - sigma) separate the
    wanted factors well (about 50 solves for 10 modes instead of 150 without a shift). sigma is
    0.95 of a rough first factor (``_rough_first_factor``: a few Lanczos steps on -K_G phi = mu K
    phi with the linear stiffness factor, which over-estimate lambda_1); Sylvester's law checks
    it: K + sigma K_G has no negative pivot only if no factor lies in (0, sigma), else sigma is
    halved.
    ``stiffness``: as for linear_static."""
    state = _solve_linear(model, supports, loads, stiffness)
    el = state.el
    N = state.local_forces[:, 6]
    KG_elements = to_global(state.R, released_zero(geometric_stiffness(state.L, N, el), el.released))
    K_G = assemble(KG_elements, element_dofs(el.connectivity), len(state.u))
    free = state.free
    minus_KG = (-K_G[free][:, free]).tocsr()
    size = len(free)
    k = int(min(max(n_modes, 1), size - 2))
    none = BucklingResult(factors=np.zeros(0), modes=np.zeros((0, el.n_original, 6)))
    if minus_KG.nnz == 0 or np.abs(minus_KG.data).max() == 0:
        return none
    K_free = _free_stiffness(state)
    # a fixed start vector: ARPACK's own is drawn from OS entropy, and runs would differ in the last digits
    start = np.random.default_rng(0).standard_normal(size)
    with single_threaded_blas():
        mu = _rough_first_factor(minus_KG, K_free, state.lu.solve, start)
        if mu <= 1e-12 * abs(minus_KG).max() / abs(K_free).max():
            return none                                          # nothing buckles in compression
        sigma = 0.95 / mu
        shifted = None
        for _ in range(SHIFT_HALVINGS):
            shifted = factor_or_none(state.K_elements + sigma * KG_elements, el, free, compiled=True)
            if shifted is not None and shifted.negative_pivots == 0:
                break
            sigma *= 0.5
        else:
            raise ConvergenceError("linear buckling: no shift below the first buckling factor was found")
        operator = spla.LinearOperator((size, size), matvec=shifted.solve, dtype=float)
        try:
            values, vectors = spla.eigsh(K_free, k=k, M=minus_KG, sigma=sigma, OPinv=operator, mode="buckling",
                                         which="LA", tol=EIGEN_TOLERANCE, maxiter=max(2000, 20 * size), v0=start)
        except spla.ArpackNoConvergence as exc:
            values, vectors = exc.eigenvalues, exc.eigenvectors
            if len(values) == 0:
                raise ConvergenceError("linear buckling: the eigenvalue solver did not converge") from exc
    # factors at infinity (directions K_G does not load) come back huge or of either sign
    positive = (values > 0) & (values < 1e12 * sigma)
    factors = values[positive]
    vectors = vectors[:, positive]
    order = np.argsort(factors)
    factors, vectors = factors[order], vectors[:, order]
    modes = np.zeros((len(factors), len(state.u)))
    modes[:, free] = vectors.T
    energy = _beam_energy_shares(state.stiffness, modes[0]) if len(factors) else None
    modes = modes.reshape(len(factors), len(state.u) // 6, 6)[:, :el.n_original]  # no factor: (0, n, 6)
    peak = np.linalg.norm(modes[:, :, :3], axis=2).max(axis=1)
    modes = modes / np.where(peak > 0, peak, 1.0)[:, None, None]
    return BucklingResult(factors=factors, modes=_signed_modes(modes), beam_energy=energy)


#: ARPACK's relative tolerance on the buckling factors. Its Ritz values land far closer than asked
#: (the 5000-node frame's ten factors at 1e-8 equal those at 1e-10 to 1e-15), and 1e-10 cost 15 %
#: more solves (``benchmarks/frame_speed.py``).
EIGEN_TOLERANCE = 1e-8
#: Lanczos steps of the rough first buckling factor at most (it only places the shift), and the
#: relative change of its estimate between steps under which it stops. The 5000-node frame of
#: ``benchmarks/frame_speed.py`` stops after 10 steps at 1.024 lambda_1 (ARPACK's k=1 run to 1e-2
#: took 31 solves, 1.3 s).
ROUGH_STEPS, ROUGH_CHANGE = 40, 5e-3
#: Halvings of the shift at most, until K + sigma K_G has no negative pivot (a factor 2**-20).
SHIFT_HALVINGS = 20


def _rough_first_factor(minus_KG: sp.spmatrix, K: sp.spmatrix, solve: Callable[[np.ndarray], np.ndarray],
                        start: np.ndarray) -> float:
    """The largest Ritz value mu of -K_G phi = mu K phi after a few Lanczos steps in the K inner
    product (``solve``: K^-1 by its factor; 0 when -K_G has no positive direction). Ritz values
    approach the extreme eigenvalue from inside, so 1 / mu >= lambda_1: a shift below it is
    checked by the factor's inertia, never assumed. Each step is one solve and one product with
    -K_G (K w = -K_G v needs no product with K); the basis is orthogonalised in full, twice."""
    n = len(start)
    steps = int(min(ROUGH_STEPS, n))
    basis, images = np.empty((steps, n)), np.empty((steps, n))     # v_j and K v_j
    image = K @ start
    norm = float(np.sqrt(start @ image))
    vector, image = start / norm, image / norm
    alphas: list[float] = []
    betas: list[float] = []
    estimate = 0.0
    for j in range(steps):
        basis[j], images[j] = vector, image
        load = minus_KG @ vector                                    # K w
        w = solve(load)
        alphas.append(float(vector @ load))
        for _ in range(2):
            c = basis[:j + 1] @ load
            w -= c @ basis[:j + 1]
            load = load - c @ images[:j + 1]
        beta = float(np.sqrt(max(w @ load, 0.0)))
        tridiagonal = np.diag(alphas) + np.diag(betas, 1) + np.diag(betas, -1)
        previous, estimate = estimate, float(np.linalg.eigvalsh(tridiagonal)[-1])
        if beta <= 1e-12 * max(abs(alphas[-1]), 1e-300):
            break                                                   # an invariant subspace: exact
        if j >= 3 and estimate > 0 and abs(estimate - previous) <= ROUGH_CHANGE * estimate:
            break
        betas.append(beta)
        vector, image = w / beta, load / beta
    return max(estimate, 0.0)


MODE_SIGN_TIE = 1e-3
"""Translation components within this share of a mode's largest count as equally large."""


def _signed_modes(modes: np.ndarray) -> np.ndarray:
    """Modes (k, n, 6) with a sign that does not depend on the eigensolver's start vector: each
    mode's translation component of largest magnitude is positive, of components equal to within
    ``MODE_SIGN_TIE`` the one of lowest index (node, then x, y, z), so a symmetric mode's sign does
    not follow rounding either."""
    if len(modes) == 0:
        return modes
    translations = np.abs(modes[:, :, :3].reshape(len(modes), -1))
    largest = translations.max(axis=1, keepdims=True)
    first = np.argmax(translations >= (1.0 - MODE_SIGN_TIE) * largest, axis=1)
    value = modes[:, :, :3].reshape(len(modes), -1)[np.arange(len(modes)), first]
    return modes * np.where(value < 0, -1.0, 1.0)[:, None, None]


def _free_stiffness(state: _Linear) -> sp.csr_matrix:
    """The stiffness on the free DOFs (CSR, for products), kept with the factored stiffness."""
    stiffness = state.stiffness
    if stiffness.K_free is None:
        stiffness.K_free = stiffness.K[stiffness.free][:, stiffness.free].tocsr()
    return stiffness.K_free
