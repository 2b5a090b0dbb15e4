"""Space-frame finite elements: linear static, linear buckling, co-rotational non-linear static.

3D Euler-Bernoulli beams with 6 DOF per node (ux, uy, uz, rx, ry, rz), rigid joints, each
beam split into ``elements_per_beam`` elements. Local axes: x along the beam, z the beam's
``up`` vector made perpendicular to x (the strong axis: Iy is about local y, bending in the
x-z plane), y = z cross x. Element kernels run over all elements at once; the stiffness is
assembled once per analysis and factored once. The non-linear analysis is co-rotational: each
element's rigid motion is followed by its chord and the mean of its end triads, its
deformation is small in that frame; Newton iterations with Crisfield's cylindrical arc-length
follow the path through limit points. Why our own elements and not pyfe3d: docs/decisions.md.

Units: any consistent set (SI in the workflow).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .condensed import CondensedFactor
from .errors import ConvergenceError, InputError, MechanismError
from .linalg import assemble_blocks, congruent
from .supports import Supports

__all__ = ["FrameModel", "FrameStiffness", "LinearResult", "BucklingResult", "NonlinearResult", "factor_stiffness",
           "linear_static", "linear_buckling",
           "nonlinear_static", "solve_frame_json", "DOF_NAMES"]

DOF_NAMES = ("ux", "uy", "uz", "rx", "ry", "rz")



@dataclass(frozen=True, kw_only=True)
class FrameModel:
    """nodes (n,3); beams (b,2) node ids; E, G, A, Iy, Iz, J (b,) per beam; up (b,3) the
    direction of each beam's local z (strong axis normal); elements_per_beam; releases (b,2,6)
    bool or None: True where a beam end does not transmit that local force or moment (a pin:
    the three rotations; a hinge about local y: ry only), condensed out of the element."""

    nodes: np.ndarray
    beams: np.ndarray
    E: np.ndarray
    G: np.ndarray
    A: np.ndarray
    Iy: np.ndarray
    Iz: np.ndarray
    J: np.ndarray
    up: np.ndarray
    elements_per_beam: int = 1
    releases: np.ndarray | None = None

    def __post_init__(self) -> None:
        nodes = np.asarray(self.nodes, dtype=float)
        beams = np.asarray(self.beams, dtype=np.int64).reshape(-1, 2)
        if nodes.ndim != 2 or nodes.shape[1] != 3 or not np.all(np.isfinite(nodes)):
            raise InputError("frame model: nodes must be a finite (n, 3) array")
        if len(beams) == 0:
            raise InputError("frame model: no beams")
        if beams.min() < 0 or beams.max() >= len(nodes):
            raise InputError(f"frame model: a beam refers to a node outside 0..{len(nodes) - 1}")
        if np.any(beams[:, 0] == beams[:, 1]):
            loop = int(np.argmax(beams[:, 0] == beams[:, 1]))
            raise InputError(f"frame model: beam {loop} starts and ends at one node")
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "beams", beams)
        for name in ("E", "G", "A", "Iy", "Iz", "J"):
            value = np.broadcast_to(np.asarray(getattr(self, name), dtype=float), (len(beams),)).copy()
            if not np.all(value > 0):
                raise InputError(f"frame model: {name} must be positive for every beam")
            object.__setattr__(self, name, value)
        up = np.broadcast_to(np.asarray(self.up, dtype=float), (len(beams), 3)).copy()
        object.__setattr__(self, "up", up)
        if int(self.elements_per_beam) < 1:
            raise InputError("frame model: elements_per_beam must be at least 1")
        object.__setattr__(self, "elements_per_beam", int(self.elements_per_beam))
        if self.releases is not None:
            releases = np.asarray(self.releases, dtype=bool)
            if releases.shape != (len(beams), 2, 6):
                raise InputError(f"frame model: releases must be ({len(beams)}, 2, 6) flags, got {releases.shape}")
            if np.any(releases[:, :, :3]):
                raise InputError("frame model: only moments and torsion (rx, ry, rz) can be released at beam ends")
            object.__setattr__(self, "releases", releases)
        lengths = np.linalg.norm(nodes[beams[:, 1]] - nodes[beams[:, 0]], axis=1)
        if np.any(lengths <= 1e-12 * max(np.ptp(nodes, axis=0).max(), 1e-300)):
            raise InputError(f"frame model: beam {int(np.argmin(lengths))} has zero length")


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


@dataclass(frozen=True, kw_only=True)
class NonlinearResult:
    """path (s,2): [load factor, control displacement] from [0, 0]; limit_load_factor: the first
    maximum of the load factor (None if not reached); negative_pivots (s,): negative pivots of the
    tangent stiffness at each point of the path (0 while stable; one more past a limit point or a
    bifurcation); displacements (n,6) at the limit point (or the last step); converged: False when
    a step failed to converge even at 1/256 of its arc; load_factors (s,); iterations (s,): Newton
    iterations of each step; monitored (s, k): the ``monitor`` DOFs along the path."""

    path: np.ndarray
    limit_load_factor: float | None
    negative_pivots: np.ndarray
    displacements: np.ndarray
    converged: bool = True
    load_factors: np.ndarray = field(default_factory=lambda: np.zeros(0))
    iterations: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    monitored: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))


# ----------------------------------------------------------------------------- mesh of elements

@dataclass(frozen=True)
class _Elements:
    nodes: np.ndarray        # (N,3) original nodes then internal nodes
    connectivity: np.ndarray  # (m,2)
    beam: np.ndarray         # (m,) beam of each element
    up: np.ndarray           # (m,3)
    E: np.ndarray
    G: np.ndarray
    A: np.ndarray
    Iy: np.ndarray
    Iz: np.ndarray
    J: np.ndarray
    first: np.ndarray        # (b,) first element of each beam
    last: np.ndarray         # (b,) last element of each beam
    n_original: int
    released: np.ndarray | None = None  # (m,12) released local DOFs per element


def _elements(model: FrameModel, nodes: np.ndarray | None = None) -> _Elements:
    nodes = model.nodes if nodes is None else nodes
    k = model.elements_per_beam
    b = len(model.beams)
    start, end = nodes[model.beams[:, 0]], nodes[model.beams[:, 1]]
    n = len(nodes)
    if k == 1:
        all_nodes = nodes
        connectivity = model.beams.copy()
    else:
        t = np.arange(1, k) / k
        internal = start[:, None] + t[None, :, None] * (end - start)[:, None]
        all_nodes = np.vstack([nodes, internal.reshape(-1, 3)])
        ids = np.empty((b, k + 1), dtype=np.int64)
        ids[:, 0], ids[:, -1] = model.beams[:, 0], model.beams[:, 1]
        ids[:, 1:-1] = n + np.arange(b * (k - 1)).reshape(b, k - 1)
        connectivity = np.stack([ids[:, :-1], ids[:, 1:]], axis=2).reshape(-1, 2)
    beam = np.repeat(np.arange(b), k)
    first, last = np.arange(b) * k, np.arange(b) * k + k - 1
    released = None
    if model.releases is not None and np.any(model.releases):
        released = np.zeros((b * k, 12), dtype=bool)
        released[first, :6] = model.releases[:, 0]
        released[last, 6:] |= model.releases[:, 1]
    return _Elements(nodes=all_nodes, connectivity=connectivity, beam=beam, up=model.up[beam], E=model.E[beam],
                     G=model.G[beam], A=model.A[beam], Iy=model.Iy[beam], Iz=model.Iz[beam], J=model.J[beam],
                     first=first, last=last, n_original=n, released=released)


def _released_zero(K: np.ndarray, released: np.ndarray | None) -> np.ndarray:
    """Zero the rows and columns of released local DOFs."""
    if released is None:
        return K
    keep = (~released).astype(float)
    return K * keep[:, :, None] * keep[:, None, :]


def _condense(K: np.ndarray, released: np.ndarray | None) -> np.ndarray:
    """Static condensation of released local DOFs: K_rr - K_rc K_cc^-1 K_cr, released rows and
    columns zero (the element transmits no force there)."""
    if released is None:
        return K
    K = K.copy()
    for pattern in np.unique(released, axis=0):
        if not pattern.any():
            continue
        rows = np.flatnonzero((released == pattern).all(axis=1))
        c = np.flatnonzero(pattern)
        r = np.flatnonzero(~pattern)
        block = K[rows]
        Kcc = block[:, c][:, :, c]
        Krc = block[:, r][:, :, c]
        correction = np.matmul(Krc, np.linalg.solve(Kcc, np.transpose(Krc, (0, 2, 1))))
        reduced = block[:, r][:, :, r] - correction
        block[:] = 0.0
        block[:, r[:, None], r[None, :]] = reduced
        K[rows] = block
    return K


def _local_axes(x_axis: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(m,3,3) rotation rows [x, y, z] with z the up vector made perpendicular to x."""
    z = up - np.einsum("mi,mi->m", up, x_axis)[:, None] * x_axis
    norm = np.linalg.norm(z, axis=1)
    bad = norm < 1e-6
    if np.any(bad):
        # up parallel to the beam: take global z, or global y for vertical beams
        fallback = np.where(np.abs(x_axis[bad, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[0.0, 1.0, 0.0]])
        z[bad] = fallback - np.einsum("mi,mi->m", fallback, x_axis[bad])[:, None] * x_axis[bad]
        norm[bad] = np.linalg.norm(z[bad], axis=1)
    z /= norm[:, None]
    y = np.cross(z, x_axis)
    return np.stack([x_axis, y, z], axis=1)


def _local_stiffness(L: np.ndarray, el: _Elements) -> np.ndarray:
    """(m,12,12) Euler-Bernoulli stiffness in local axes, DOFs [u v w rx ry rz] x 2."""
    m = len(L)
    K = np.zeros((m, 12, 12))
    EA = el.E * el.A / L
    GJ = el.G * el.J / L
    K[:, 0, 0] = K[:, 6, 6] = EA
    K[:, 0, 6] = K[:, 6, 0] = -EA
    K[:, 3, 3] = K[:, 9, 9] = GJ
    K[:, 3, 9] = K[:, 9, 3] = -GJ
    for I, (v, r, sign) in ((el.Iz, (1, 5, 1.0)), (el.Iy, (2, 4, -1.0))):
        a = 12 * el.E * I / L**3
        b = 6 * el.E * I / L**2 * sign
        c = 4 * el.E * I / L
        d = 2 * el.E * I / L
        vi, ri, vj, rj = v, r, v + 6, r + 6
        K[:, vi, vi] = K[:, vj, vj] = a
        K[:, vi, vj] = K[:, vj, vi] = -a
        K[:, vi, ri] = K[:, ri, vi] = K[:, vi, rj] = K[:, rj, vi] = b
        K[:, vj, ri] = K[:, ri, vj] = K[:, vj, rj] = K[:, rj, vj] = -b
        K[:, ri, ri] = K[:, rj, rj] = c
        K[:, ri, rj] = K[:, rj, ri] = d
    return K


def _geometric_stiffness(L: np.ndarray, N: np.ndarray, el: _Elements) -> np.ndarray:
    """(m,12,12) consistent geometric stiffness of an axial force N (tension +), local axes."""
    m = len(L)
    K = np.zeros((m, 12, 12))
    f = N / (30 * L)
    for v, r, sign in ((1, 5, 1.0), (2, 4, -1.0)):
        vi, ri, vj, rj = v, r, v + 6, r + 6
        K[:, vi, vi] = K[:, vj, vj] = 36 * f
        K[:, vi, vj] = K[:, vj, vi] = -36 * f
        b = 3 * L * f * sign
        K[:, vi, ri] = K[:, ri, vi] = K[:, vi, rj] = K[:, rj, vi] = b
        K[:, vj, ri] = K[:, ri, vj] = K[:, vj, rj] = K[:, rj, vj] = -b
        K[:, ri, ri] = K[:, rj, rj] = 4 * L**2 * f
        K[:, ri, rj] = K[:, rj, ri] = -L**2 * f
    polar = (el.Iy + el.Iz) / el.A
    K[:, 3, 3] = K[:, 9, 9] = N * polar / L
    K[:, 3, 9] = K[:, 9, 3] = -N * polar / L
    return K


def _transformation(R: np.ndarray) -> np.ndarray:
    m = len(R)
    T = np.zeros((m, 12, 12))
    for block in range(4):
        T[:, 3 * block:3 * block + 3, 3 * block:3 * block + 3] = R
    return T


def _dofs(connectivity: np.ndarray) -> np.ndarray:
    return (6 * connectivity[:, :, None] + np.arange(6)).reshape(len(connectivity), 12)


def _assemble(K_elements: np.ndarray, dofs: np.ndarray, n_dofs: int) -> sp.csc_matrix:
    """Global matrix from element matrices (m,12,12) on the node-major DOFs (m,12) of _dofs."""
    return assemble_blocks(K_elements, dofs[:, ::6] // 6, n_dofs // 6)


def _geometry(el: _Elements, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = nodes[el.connectivity[:, 1]] - nodes[el.connectivity[:, 0]]
    L = np.linalg.norm(d, axis=1)
    return L, _local_axes(d / L[:, None], el.up)


# ----------------------------------------------------------------------------- supports, solving

def _restrained(supports: Supports, n_original: int, n_all: int) -> np.ndarray:
    if len(supports.nodes) and (supports.nodes.max() >= n_original or supports.nodes.min() < 0):
        raise InputError(f"frame: a support node is out of range 0..{n_original - 1}")
    mask = np.zeros((n_all, 6), dtype=bool)
    mask[:n_original] = supports.dof_mask(n_original)
    return mask.ravel()


def _check_rigid_modes(nodes: np.ndarray, restrained: np.ndarray) -> None:
    from .shell import count_free_rigid_modes

    free_modes = count_free_rigid_modes(nodes, restrained)
    if free_modes:
        raise MechanismError(f"the frame is a mechanism: its supports leave {free_modes} rigid-body mode(s) free",
                             n_modes=free_modes, hint="support more nodes or restrain more directions")


def _short_beam_hint(beam_lengths: np.ndarray | None) -> str | None:
    """A hint naming beams so short (below 1e-3 of the median) that their stiffness swamps the
    rest in floating point: the "mechanism" is then numerical; merge their end nodes."""
    if beam_lengths is None or len(beam_lengths) == 0:
        return None
    short = np.flatnonzero(beam_lengths < 1e-3 * np.median(beam_lengths))
    if len(short) == 0:
        return None
    listed = ", ".join(f"{int(k)} ({beam_lengths[k]:.2g})" for k in short[np.argsort(beam_lengths[short])][:5])
    return (f"{len(short)} beam(s) are over 1000 times shorter than the median beam ({np.median(beam_lengths):.3g}): "
            f"{listed}; merge their end nodes (clean the grid) - such beams make the stiffness numerically singular")


def _factor(K_elements: np.ndarray, el: _Elements, free: np.ndarray,
            beam_lengths: np.ndarray | None = None) -> CondensedFactor:
    """Factor of the stiffness on the free DOFs from the element matrices (m,12,12) in global
    axes, the beams' internal nodes condensed out (``engine.condensed``); a singular matrix is a
    mechanism, named with its count."""
    try:
        lu = _condensed_factor(K_elements, el, free)
    except RuntimeError as exc:
        raise MechanismError("the frame is a mechanism: its stiffness matrix is singular", n_modes=1,
                             hint="check for loose beams or nodes held by pinned ends only") from exc
    diagonal = lu.pivots
    scale = np.abs(diagonal).max() if diagonal.size else 1.0
    tiny = np.abs(diagonal) <= 1e-12 * scale
    if np.any(tiny):
        raise MechanismError(f"the frame is a mechanism with {int(tiny.sum())} free mode(s) beyond rigid-body motion",
                             n_modes=int(tiny.sum()),
                             hint=_short_beam_hint(beam_lengths) or "check for loose beams, beams released at both "
                             "ends (a free spin about their axis) or nodes joined by pinned ends only")
    return lu


def _condensed_factor(K_elements: np.ndarray, el: _Elements, free: np.ndarray) -> CondensedFactor:
    return CondensedFactor(K_elements, el.connectivity, len(el.nodes), el.n_original, free,
                           len(el.connectivity) // len(el.first))


def _factor_or_none(K_elements: np.ndarray, el: _Elements, free: np.ndarray) -> CondensedFactor | None:
    try:
        return _condensed_factor(K_elements, el, free)
    except RuntimeError:
        return None


def _negative_pivots(K_elements: np.ndarray, el: _Elements, free: np.ndarray) -> tuple[CondensedFactor, int]:
    lu = _condensed_factor(K_elements, el, free)
    return lu, lu.negative_pivots


def _resultant(points: np.ndarray, forces: np.ndarray) -> np.ndarray:
    return np.concatenate([forces[:, :3].sum(axis=0), (np.cross(points, forces[:, :3]) + forces[:, 3:]).sum(axis=0)])


def _equilibrium_error(points: np.ndarray, loads: np.ndarray, reactions: np.ndarray) -> float:
    size = max(float(np.ptp(points, axis=0).max()), 1e-300)
    total = _resultant(points, loads)
    balance = total + _resultant(points, reactions)
    scale = np.linalg.norm(total[:3]) + np.linalg.norm(total[3:]) / size
    return float((np.linalg.norm(balance[:3]) + np.linalg.norm(balance[3:]) / size) / max(scale, 1e-300))


def _check_loads(loads: np.ndarray, n: int) -> np.ndarray:
    loads = np.asarray(loads, dtype=float)
    if loads.shape != (n, 6) or not np.all(np.isfinite(loads)):
        raise InputError(f"frame: loads must be a finite ({n}, 6) array, got {loads.shape}")
    return loads


# ----------------------------------------------------------------------------- linear analyses

@dataclass
class FrameStiffness:
    """The linear stiffness of a model on its supports, factored (factor_stiffness)."""
    el: _Elements
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
    el: _Elements
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
    el = _elements(model)
    n_all = len(el.nodes)
    restrained = _restrained(supports, el.n_original, n_all)
    _check_rigid_modes(el.nodes, restrained)
    L, R = _geometry(el, el.nodes)
    T = _transformation(R)
    K_local = _condense(_local_stiffness(L, el), el.released)
    K_elements = congruent(T, K_local)
    K = _assemble(K_elements, _dofs(el.connectivity), 6 * n_all)
    free = np.flatnonzero(~restrained)
    lu = _factor(K_elements, el, free,
                 np.linalg.norm(model.nodes[model.beams[:, 1]] - model.nodes[model.beams[:, 0]], axis=1))
    return FrameStiffness(el=el, L=L, R=R, T=T, K_local=K_local, K_elements=K_elements, K=K, restrained=restrained,
                          free=free, lu=lu)


def _solve_linear(model: FrameModel, supports: Supports, loads: np.ndarray,
                  stiffness: FrameStiffness | None = None) -> _Linear:
    loads = _check_loads(loads, model.nodes.shape[0])
    stiffness = stiffness if stiffness is not None else factor_stiffness(model, supports)
    el, free = stiffness.el, stiffness.free
    n_all = len(el.nodes)
    F = np.zeros(6 * n_all)
    F[:6 * el.n_original] = loads.ravel()
    u = np.zeros(6 * n_all)
    u[free] = stiffness.lu.solve(F[free])
    dofs = _dofs(el.connectivity)
    local_forces = np.matmul(stiffness.K_local, np.matmul(stiffness.T, u[dofs][:, :, None]))[:, :, 0]
    return _Linear(el=el, L=stiffness.L, R=stiffness.R, T=stiffness.T, K_local=stiffness.K_local, K=stiffness.K,
                   restrained=stiffness.restrained, free=free, lu=stiffness.lu, u=u, F=F, local_forces=local_forces,
                   stiffness=stiffness, K_elements=stiffness.K_elements)


def _beam_energy_shares(stiffness: "FrameStiffness", u: np.ndarray) -> np.ndarray:
    """(b,) each beam's share of the strain energy u' K u of a displacement field u (all DOFs)."""
    el = stiffness.el
    dofs = _dofs(el.connectivity)
    local_u = np.matmul(stiffness.T, u[dofs][:, :, None])
    energy = (np.matmul(stiffness.K_local, local_u) * local_u).sum(axis=(1, 2))
    per_beam = np.bincount(el.beam, weights=np.maximum(energy, 0.0), minlength=len(el.first))
    total = per_beam.sum()
    return per_beam / total if total > 0 else per_beam


def _section_forces(el: _Elements, local_forces: np.ndarray) -> np.ndarray:
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
                        equilibrium_error=_equilibrium_error(model.nodes, np.asarray(loads, float), reactions),
                        beam_energy=_beam_energy_shares(state.stiffness, state.u) if with_energy else None)


def linear_buckling(model: FrameModel, supports: Supports, loads: np.ndarray, n_modes: int = 6, *,
                    stiffness: FrameStiffness | None = None) -> BucklingResult:
    """Linear buckling: (K + lambda K_G) phi = 0 with K_G from the linear axial forces; the
    ``n_modes`` smallest positive factors (none when nothing is in compression).

    Lanczos (ARPACK) in the buckling spectral transformation about a shift sigma just below the
    first factor: (K + sigma K_G)^-1 K, whose eigenvalues lambda / (lambda - sigma) separate the
    wanted factors well (about 50 solves for 10 modes instead of 150 without a shift). sigma is
    0.95 of a rough first factor (a short Lanczos run on -K_G phi = mu K phi with the linear
    stiffness factor, which over-estimates lambda_1); Sylvester's law checks it: K + sigma K_G
    has no negative pivot only if no factor lies in (0, sigma), else sigma is halved.
    ``stiffness``: as for linear_static."""
    state = _solve_linear(model, supports, loads, stiffness)
    el = state.el
    N = state.local_forces[:, 6]
    KG_elements = congruent(state.T, _released_zero(_geometric_stiffness(state.L, N, el), el.released))
    K_G = _assemble(KG_elements, _dofs(el.connectivity), len(state.u))
    free = state.free
    minus_KG = (-K_G[free][:, free]).tocsr()
    size = len(free)
    k = int(min(max(n_modes, 1), size - 2))
    none = BucklingResult(factors=np.zeros(0), modes=np.zeros((0, el.n_original, 6)))
    if minus_KG.nnz == 0 or np.abs(minus_KG.data).max() == 0:
        return none
    K_free = _free_stiffness(state)
    stiffness_inverse = spla.LinearOperator((size, size), matvec=state.lu.solve, dtype=float)
    # a fixed start vector: ARPACK's own is drawn from OS entropy, and runs would differ in the last digits
    start = np.random.default_rng(0).standard_normal(size)
    with _single_threaded_blas():
        try:
            mu = spla.eigsh(minus_KG, k=1, M=K_free, Minv=stiffness_inverse, which="LA", tol=1e-2,
                            maxiter=ROUGH_MAXITER, return_eigenvectors=False, v0=start)
        except spla.ArpackNoConvergence as exc:
            # no rough estimate within its few hundred steps (it took minutes to fail on clustered
            # spectra): the Rayleigh quotients of the linear displacements and of the start vector
            # are below the largest mu, so the shift they give lies above lambda_1 and the
            # Sylvester check below halves it until it does not
            mu = exc.eigenvalues if len(exc.eigenvalues) else np.array([
                max(_rayleigh(minus_KG, K_free, v) for v in (state.u[free], start))])
        if mu.max() <= 1e-12 * abs(minus_KG).max() / abs(K_free).max():
            return none                                          # nothing buckles in compression
        sigma = 0.95 / float(mu.max())
        shifted = None
        for _ in range(SHIFT_HALVINGS):
            shifted = _factor_or_none(state.K_elements + sigma * KG_elements, el, free)
            if shifted is not None and shifted.negative_pivots == 0:
                break
            sigma *= 0.5
        else:
            raise ConvergenceError("linear buckling: no shift below the first buckling factor was found")
        operator = spla.LinearOperator((size, size), matvec=shifted.solve, dtype=float)
        try:
            values, vectors = spla.eigsh(K_free, k=k, M=minus_KG, sigma=sigma, OPinv=operator, mode="buckling",
                                         which="LA", tol=1e-10, maxiter=max(2000, 20 * size), v0=start)
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
    modes = modes.reshape(len(factors), -1, 6)[:, :el.n_original]
    peak = np.linalg.norm(modes[:, :, :3], axis=2).max(axis=1)
    modes = modes / np.where(peak > 0, peak, 1.0)[:, None, None]
    return BucklingResult(factors=factors, modes=_signed_modes(modes), beam_energy=energy)


#: Lanczos steps of the rough first buckling factor (it only places the shift).
ROUGH_MAXITER = 300
#: Halvings of the shift at most, until K + sigma K_G has no negative pivot (a factor 2**-20).
SHIFT_HALVINGS = 20


def _rayleigh(A: sp.spmatrix, B: sp.spmatrix, v: np.ndarray) -> float:
    """v'Av / v'Bv (0 for a zero vector)."""
    denominator = float(v @ (B @ v))
    return float(v @ (A @ v)) / denominator if denominator > 0 else 0.0


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


# ----------------------------------------------------------------------------- co-rotational

def _rotation_matrices(vectors: np.ndarray) -> np.ndarray:
    """Rodrigues: (k,3) rotation vectors to (k,3,3) matrices."""
    angle = np.linalg.norm(vectors, axis=1)
    safe = np.where(angle > 1e-12, angle, 1.0)
    axis = vectors / safe[:, None]
    K = np.zeros((len(vectors), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = axis[:, 2], -axis[:, 1], axis[:, 0]
    s, c = np.sin(angle)[:, None, None], (1 - np.cos(angle))[:, None, None]
    R = np.eye(3)[None] + s * K + c * (K @ K)
    small = angle <= 1e-12
    if np.any(small):
        v = vectors[small]
        W = np.zeros((len(v), 3, 3))
        W[:, 0, 1], W[:, 0, 2], W[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
        W[:, 1, 0], W[:, 2, 0], W[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
        R[small] = np.eye(3)[None] + W
    return R


def _rotation_vectors(R: np.ndarray) -> np.ndarray:
    """Inverse Rodrigues (log map) of (k,3,3) rotations with angles below pi."""
    cosine = np.clip((np.einsum("kii->k", R) - 1) / 2, -1.0, 1.0)
    angle = np.arccos(cosine)
    w = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)
    sine = np.sin(angle)
    factor = np.where(sine > 1e-9, angle / (2 * np.where(sine > 1e-9, sine, 1.0)), 0.5)
    return w * factor[:, None]


class _Corotational:
    """State and kernels of the co-rotational analysis.

    The element kernels work component-major: a vector per element is (3, m), a 3 x 3 matrix per
    element (3, 3, m), so that every product is a few contiguous operations on length-m rows
    (batched 3 x 3 matmuls on (m, 3, 3) stacks are several times slower)."""

    def __init__(self, model: FrameModel, supports: Supports):
        self.el = _elements(model)
        self.n_all = len(self.el.nodes)
        self.X = self.el.nodes.copy()
        self.L0, self.R0 = _geometry(self.el, self.X)
        self.dofs = _dofs(self.el.connectivity)
        self.restrained = _restrained(supports, self.el.n_original, self.n_all)
        _check_rigid_modes(self.el.nodes, self.restrained)
        self.free = np.flatnonzero(~self.restrained)
        self.R0_rows = np.ascontiguousarray(np.transpose(self.R0, (1, 2, 0)))        # R0[i, j] as (3, 3, m)
        self.K_local = _condense(_local_stiffness(self.L0, self.el), self.el.released)
        self.K_rows = np.ascontiguousarray(np.transpose(self.K_local, (1, 2, 0)))    # (12, 12, m)
        self.scatter = self.dofs.T.ravel()                                           # f (12, m) onto the DOFs
        self.step = 1e-8
        self.spins = [_rotation_matrices(self.step * np.eye(3)[k:k + 1])[0] for k in range(3)]

    def _end_forces(self, xa: np.ndarray, xb: np.ndarray, Ra: np.ndarray, Rb: np.ndarray):
        """Element end forces (12, m) in global axes from the end positions (3, m) and the nodal
        triads times the initial element frame transposed, T R0^T (3, 3, m) (``internal_forces``)."""
        chord = xb - xa
        length = np.sqrt(chord[0] ** 2 + chord[1] ** 2 + chord[2] ** 2)
        e1 = chord / length
        # nodal triads carry the initial element frame; their mean z orients the current frame
        up = 0.5 * (Ra[:, 2] + Rb[:, 2])
        z = up - (up[0] * e1[0] + up[1] * e1[1] + up[2] * e1[2]) * e1
        norm = np.sqrt(z[0] ** 2 + z[1] ** 2 + z[2] ** 2)
        bad = norm < 1e-6
        if np.any(bad):                                     # up along the chord: as _local_axes
            z[:, bad] = _local_axes(e1[:, bad].T, up[:, bad].T)[:, 2].T
            norm[bad] = 1.0
        z /= norm
        y = np.stack([z[1] * e1[2] - z[2] * e1[1], z[2] * e1[0] - z[0] * e1[2], z[0] * e1[1] - z[1] * e1[0]])
        R = (e1, y, z)                                      # rows of the element frame
        d = np.zeros((12, len(length)))
        d[6] = length - self.L0
        # local end rotations: nodal triad relative to the element frame, by the log map
        for offset, Rn in ((3, Ra), (9, Rb)):
            M = [[R[i][0] * Rn[0, k] + R[i][1] * Rn[1, k] + R[i][2] * Rn[2, k] for k in range(3)] for i in range(3)]
            cosine = np.clip((M[0][0] + M[1][1] + M[2][2] - 1) / 2, -1.0, 1.0)
            angle = np.arccos(cosine)
            sine = np.sin(angle)
            factor = np.where(sine > 1e-9, angle / (2 * np.where(sine > 1e-9, sine, 1.0)), 0.5)
            d[offset] = (M[2][1] - M[1][2]) * factor
            d[offset + 1] = (M[0][2] - M[2][0]) * factor
            d[offset + 2] = (M[1][0] - M[0][1]) * factor
        f_local = np.einsum("ijm,jm->im", self.K_rows, d)
        f_global = np.empty_like(f_local)
        for block in range(0, 12, 3):
            f = f_local[block:block + 3]
            for j in range(3):
                f_global[block + j] = f[0] * R[0][j] + f[1] * R[1][j] + f[2] * R[2][j]
        return f_global

    def internal_forces(self, x: np.ndarray, triads: np.ndarray) -> tuple[np.ndarray, object]:
        """Internal forces (6 n_all,) of positions x (n,3) and nodal triads (n,3,3); also the
        element state the tangent starts from."""
        a, b = self.el.connectivity[:, 0], self.el.connectivity[:, 1]
        R0 = self.R0_rows

        def times_R0_T(T):                                  # T R0^T, component-major
            T = np.transpose(T, (1, 2, 0))
            return np.stack([np.stack([T[i, 0] * R0[k, 0] + T[i, 1] * R0[k, 1] + T[i, 2] * R0[k, 2]
                                       for k in range(3)]) for i in range(3)])

        state = (np.ascontiguousarray(x[a].T), np.ascontiguousarray(x[b].T), times_R0_T(triads[a]),
                 times_R0_T(triads[b]))
        f_global = self._end_forces(*state)
        out = np.bincount(self.scatter, weights=f_global.ravel(), minlength=6 * self.n_all)
        return out, state

    def tangent(self, state) -> np.ndarray:
        """Element tangent stiffnesses (m,12,12) in global axes: the derivative of the element
        end forces with respect to the end translations and spins (applied as in ``_update``), by
        forward differences over all elements at once (12 evaluations of the element kernel,
        relative accuracy ~1e-8)."""
        xa, xb, Ra, Rb = state
        base = self._end_forces(xa, xb, Ra, Rb)
        K = np.empty((12, 12, xa.shape[1]))
        h_translation = self.step * self.L0
        for column in range(12):
            end, component = divmod(column, 6)
            x_pair, r_pair = [xa, xb], [Ra, Rb]
            if component < 3:
                shifted = x_pair[end].copy()
                shifted[component] += h_translation
                x_pair[end] = shifted
                h = h_translation
            else:
                S, Rn = self.spins[component - 3], r_pair[end]
                r_pair[end] = np.stack([S[i, 0] * Rn[0] + S[i, 1] * Rn[1] + S[i, 2] * Rn[2] for i in range(3)])
                h = self.step
            K[:, column] = (self._end_forces(x_pair[0], x_pair[1], r_pair[0], r_pair[1]) - base) / h
        return np.ascontiguousarray(np.transpose(K, (2, 0, 1)))


def _update(x: np.ndarray, triads: np.ndarray, du: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    step = du.reshape(-1, 6)
    return x + step[:, :3], _rotation_matrices(step[:, 3:]) @ triads


def nonlinear_static(model: FrameModel, supports: Supports, loads: np.ndarray, *, control: tuple[int, int],
                     max_load_factor: float = 10.0, max_steps: int = 80, initial_loads: np.ndarray | None = None,
                     tolerance: float = 1e-5, steps_past_limit: int = 3,
                     monitor: list[tuple[int, int]] | None = None) -> NonlinearResult:
    """Geometrically non-linear static analysis with arc-length control.

    loads: reference load (n,6) scaled by the load factor; initial_loads: a dead load held
    constant (applied first, in load steps); control: (node, dof 0..5) whose displacement the
    path reports; monitor: further (node, dof) pairs recorded at every step in
    ``NonlinearResult.monitored`` (s, len(monitor)). The path stops ``steps_past_limit`` steps
    past the first limit point, at ``max_load_factor`` or after ``max_steps``.

    Co-rotational elements (rigid motion from the chord and the mean of the end triads, local
    end rotations by the log map), Newton iterations on the consistent tangent (the exact
    derivative of the element forces, by vectorised forward differences), Crisfield's
    cylindrical arc-length with the step size adapted to about 5 iterations per step, the
    predictor's direction kept by the previous increment; a step that goes over the first maximum
    of the load factor is redone shorter (up to 3 times, 0.3 of the arc each) so the limit load
    factor is found within a small step. ``tolerance``: residual norm relative to the norm of
    the applied load. ``negative_pivots`` tells a limit point (a pivot turns negative at the
    maximum) from a bifurcation (pivots turn negative while the load still rises).
    """
    with _single_threaded_blas():
        return _nonlinear_static(model, supports, loads, control=control, max_load_factor=max_load_factor,
                                 max_steps=max_steps, initial_loads=initial_loads, tolerance=tolerance,
                                 steps_past_limit=steps_past_limit, monitor=monitor)


def _nonlinear_static(model: FrameModel, supports: Supports, loads: np.ndarray, *, control: tuple[int, int],
                      max_load_factor: float, max_steps: int, initial_loads: np.ndarray | None,
                      tolerance: float, steps_past_limit: int,
                      monitor: list[tuple[int, int]] | None) -> NonlinearResult:
    n = model.nodes.shape[0]
    loads = _check_loads(loads, n)
    node, dof = control
    if not (0 <= node < n and 0 <= dof < 6):
        raise InputError(f"frame: control ({node}, {dof}) must be a node 0..{n - 1} and a DOF 0..5")
    cr = _Corotational(model, supports)
    free = cr.free
    F_ref = np.zeros(6 * cr.n_all)
    F_ref[:6 * n] = loads.ravel()
    F_dead = np.zeros(6 * cr.n_all)
    if initial_loads is not None:
        F_dead[:6 * n] = _check_loads(initial_loads, n).ravel()
    scale = max(np.linalg.norm(F_ref[free]), np.linalg.norm(F_dead[free]), 1e-300)
    x = cr.X.copy()
    triads = np.tile(np.eye(3), (cr.n_all, 1, 1))

    def residual(x, triads, lam):
        f_int, cache = cr.internal_forces(x, triads)
        return F_dead + lam * F_ref - f_int, cache

    def displacement_of(x, triads):
        if dof < 3:
            return float(x[node, dof] - cr.X[node, dof])
        return float(_rotation_vectors(triads[node:node + 1])[0, dof - 3])

    def load_controlled(x, triads, target):
        for _ in range(40):
            f_int, cache = cr.internal_forces(x, triads)
            r = target - f_int
            if np.linalg.norm(r[free]) < tolerance * scale:
                return x, triads
            lu = _factor_or_none(cr.tangent(cache), cr.el, free)
            if lu is None:
                return None
            du = np.zeros(6 * cr.n_all)
            du[free] = lu.solve(r[free])
            x, triads = _update(x, triads, du)
        return None

    # dead load first (load control)
    if initial_loads is not None and np.any(F_dead):
        for fraction in np.linspace(0.25, 1.0, 4):
            state = load_controlled(x, triads, fraction * F_dead)
            if state is None:
                raise ConvergenceError("the dead load alone exceeds the structure's capacity (no equilibrium)")
            x, triads = state
    # first step size from a linear prediction reaching about max_load_factor / 20
    _, cache = residual(x, triads, 0.0)
    lu = _factor(cr.tangent(cache), cr.el, free)
    u_ref = np.zeros(6 * cr.n_all)
    u_ref[free] = lu.solve(F_ref[free])
    arc = np.linalg.norm(u_ref[free]) * min(max_load_factor, 10.0) / 20.0
    lam = 0.0
    watch = list(monitor or [])

    def watched(x, triads):
        return [float(x[n_, d_] - cr.X[n_, d_]) if d_ < 3 else float(_rotation_vectors(triads[n_:n_ + 1])[0, d_ - 3])
                for n_, d_ in watch]

    monitored = [watched(x, triads)]
    path = [[0.0, displacement_of(x, triads)]]
    pivots = [0]
    factors = [0.0]
    iterations = [0]
    desired_iterations = 5
    refinements, arc_cap = 0, np.inf      # steps redone shorter near a critical point (at most 3)
    previous = None
    limit = None
    limit_state = None
    past = 0
    converged_all = True
    saved = None                      # the state before the last step, to redo it shorter
    for _step in range(max_steps):
        _, cache = residual(x, triads, lam)
        try:
            lu, negatives = _negative_pivots(cr.tangent(cache), cr.el, free)
        except RuntimeError:
            converged_all = False
            break
        pivots[-1] = negatives                               # pivots of the tangent at this state
        du_f = np.zeros(6 * cr.n_all)
        du_f[free] = lu.solve(F_ref[free])
        # the predictor follows the previous increment (at the start: the load's direction on a
        # stable tangent); the load factor falls along it once the path is past a maximum
        if previous is not None:
            direction = -1.0 if np.dot(previous[free], du_f[free]) < 0 else 1.0
        else:
            direction = -1.0 if negatives > 0 else 1.0
        if saved is not None and limit is None and direction < 0 < lam and lam > saved[2] and refinements < 3:
            # the last step went over a maximum of the load factor: redo it shorter, to land
            # closer to the peak (each time 0.3 of the arc, held until the limit)
            refinements += 1
            x, triads, lam, previous, _, arc = saved
            arc *= 0.3
            arc_cap = arc
            saved = None
            for history in (path, monitored, pivots, factors, iterations):
                history.pop()
            continue
        accepted = False
        for _attempt in range(8):
            x_try, t_try, lam_try = x.copy(), triads.copy(), lam
            d_lam = direction * arc / max(np.linalg.norm(du_f[free]), 1e-300)
            total = d_lam * du_f
            x_try, t_try = _update(x_try, t_try, total)
            lam_try += d_lam
            ok = False
            correction_norm = np.inf
            for _iteration in range(25):
                r, cache = residual(x_try, t_try, lam_try)
                # relative to the load applied now; a tiny last correction also ends the iterations
                # when round-off (very stiff short elements) keeps the residual above the tolerance
                applied = max(np.linalg.norm(F_dead[free] + lam_try * F_ref[free]), 1e-12 * scale)
                error = np.linalg.norm(r[free]) / applied
                if error < tolerance or (error < 1e3 * tolerance
                                         and correction_norm < 1e-10 * np.linalg.norm(total[free])):
                    ok = True
                    break
                lu_i = _factor_or_none(cr.tangent(cache), cr.el, free)
                if lu_i is None:
                    break
                dr = np.zeros(6 * cr.n_all)
                df = np.zeros(6 * cr.n_all)
                dr[free] = lu_i.solve(r[free])
                df[free] = lu_i.solve(F_ref[free])
                # cylindrical constraint |total + dr + dl df| = arc
                a = df[free] @ df[free]
                b = 2 * df[free] @ (total[free] + dr[free])
                c = (total[free] + dr[free]) @ (total[free] + dr[free]) - arc**2
                disc = b * b - 4 * a * c
                if disc < 0:
                    dl = -b / (2 * a)
                else:
                    roots = ((-b + np.sqrt(disc)) / (2 * a), (-b - np.sqrt(disc)) / (2 * a))
                    dl = max(roots, key=lambda root: (total[free] + dr[free] + root * df[free]) @ total[free])
                correction = dr + dl * df
                correction_norm = np.linalg.norm(correction[free])
                x_try, t_try = _update(x_try, t_try, correction)
                total = total + correction
                lam_try += dl
            if ok:
                accepted = True
                break
            arc *= 0.5
        if not accepted:
            converged_all = False
            break
        if lam_try > max_load_factor >= lam and limit is None:
            # land exactly on the largest load factor asked for
            state = load_controlled(x, triads, F_dead + max_load_factor * F_ref)
            if state is not None:
                x_try, t_try = state
                lam_try = max_load_factor
        if limit is None and lam_try < lam and lam > 0 and direction > 0 and refinements < 3:
            # the step went over a maximum of the load factor: redo it shorter, to land closer
            # to the peak (each time 0.3 of the arc; the arc is then held until the limit)
            refinements += 1
            arc *= 0.3
            arc_cap = arc
            continue
        saved = (x, triads, lam, previous, negatives, arc)
        previous = total
        if limit is None and lam_try < lam and lam > 0:
            limit = lam
            limit_state = (x.copy(), triads.copy())
            arc_cap = np.inf
        x, triads, lam = x_try, t_try, lam_try
        path.append([lam, displacement_of(x, triads)])
        monitored.append(watched(x, triads))
        pivots.append(negatives)                             # provisional: set at the next step
        factors.append(lam)
        iterations.append(_iteration)
        # automatic step size: aim at about `desired` corrector iterations per step
        arc = min(arc * float(np.clip(np.sqrt(desired_iterations / max(_iteration, 1)), 0.5, 2.0)), arc_cap)
        if limit is not None:
            past += 1
            if past >= steps_past_limit:
                break
        if lam >= max_load_factor:
            break
    if len(path) > 1:                                        # pivots of the final state
        try:
            pivots[-1] = _negative_pivots(cr.tangent(residual(x, triads, lam)[1]), cr.el, free)[1]
        except RuntimeError:
            pass
    if limit_state is None:
        limit_state = (x, triads)
    lx, lt = limit_state
    displacements = np.zeros((cr.n_all, 6))
    displacements[:, :3] = lx - cr.X
    displacements[:, 3:] = _rotation_vectors(lt)
    return NonlinearResult(path=np.array(path), limit_load_factor=limit, negative_pivots=np.array(pivots),
                           displacements=displacements[:n], converged=converged_all, load_factors=np.array(factors),
                           iterations=np.array(iterations),
                           monitored=np.array(monitored, dtype=float).reshape(len(path), len(watch)))


def _single_threaded_blas():
    """Limit BLAS to one thread where threadpoolctl is available: the eigensolver and the path
    following do many small vector operations, for which BLAS threads on a busy machine cost
    more than they bring (10 buckling modes of a 64k-DOF model: 2.2 s instead of 5.6 s)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


# ----------------------------------------------------------------------------- JSON interface

def _require(data: dict, key: str, where: str = "frame model"):
    if key not in data:
        raise InputError(f"{where}: missing key '{key}'", hint="see docs/formats.md")
    return data[key]


def _node_table(table, name: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(table, dict):
        raise InputError(f"frame model: '{name}' must be an object keyed by node index")
    nodes, values = [], []
    for key, value in table.items():
        try:
            node = int(key)
        except ValueError:
            raise InputError(f"frame model: '{name}' key {key!r} is not a node index") from None
        if not 0 <= node < n:
            raise InputError(f"frame model: '{name}' node {node} is out of range 0..{n - 1}")
        if not isinstance(value, (list, tuple)) or len(value) != 6:
            raise InputError(f"frame model: '{name}' of node {node} must be a list of 6 values")
        nodes.append(node)
        values.append(value)
    return np.array(nodes, dtype=np.int64), np.array(values, dtype=float).reshape(len(nodes), 6)


def model_from_json(data: dict) -> tuple[FrameModel, Supports, np.ndarray]:
    """(FrameModel, Supports, loads (n,6)) from the solver-level JSON object (docs/formats.md)."""
    try:
        nodes = np.array(_require(data, "nodes"), dtype=float)
    except (TypeError, ValueError):
        raise InputError("frame model: nodes must be [[x, y, z], ...]") from None
    beams = _require(data, "beams")
    if not isinstance(beams, list) or not beams:
        raise InputError("frame model: beams must be a non-empty list")
    fields = {k: [] for k in ("nodes", "E", "G", "A", "Iy", "Iz", "J", "up")}
    for i, beam in enumerate(beams):
        for key in fields:
            if key == "up" and key not in beam:
                fields[key].append([0.0, 0.0, 1.0])
                continue
            fields[key].append(_require(beam, key, f"frame model: beam {i}"))
    n = len(nodes)
    releases = None
    if any("releases" in beam for beam in beams):
        releases = np.array([beam.get("releases", [[0] * 6, [0] * 6]) for beam in beams], dtype=bool)
    model = FrameModel(nodes=nodes, beams=np.array(fields["nodes"]), E=fields["E"], G=fields["G"], A=fields["A"],
                       Iy=fields["Iy"], Iz=fields["Iz"], J=fields["J"], up=np.array(fields["up"], dtype=float),
                       elements_per_beam=int(data.get("elements_per_beam", 1)), releases=releases)
    support_nodes, flags = _node_table(_require(data, "supports"), "supports", n)
    supports = Supports(nodes=support_nodes, restraints=flags.astype(bool))
    load_nodes, forces = _node_table(data.get("loads", {}), "loads", n)
    loads = np.zeros((n, 6))
    np.add.at(loads, load_nodes, forces)
    return model, supports, loads


def solve_frame_json(data: dict, *, analysis: str = "linear", modes: int = 6,
                     control: tuple[int, str] | None = None, max_load_factor: float | None = None) -> dict:
    """Solve a frame model given as a JSON object; return the result object (docs/formats.md)."""
    if analysis not in ("linear", "buckling", "nonlinear"):
        raise InputError(f"frame: analysis must be linear, buckling or nonlinear, got {analysis!r}")
    model, supports, loads = model_from_json(data)
    stiffness = factor_stiffness(model, supports)
    linear = linear_static(model, supports, loads, stiffness=stiffness)
    result = {"displacements": linear.displacements.tolist(),
              "reactions": {str(int(n)): linear.reactions[n].tolist() for n in supports.nodes},
              "buckling_factors": [], "path": [], "limit_load_factor": None,
              "equilibrium_error": linear.equilibrium_error}
    if analysis == "buckling":
        result["buckling_factors"] = linear_buckling(model, supports, loads, n_modes=modes,
                                                     stiffness=stiffness).factors.tolist()
    if analysis == "nonlinear":
        if control is None:
            node = int(np.argmax(np.linalg.norm(linear.displacements[:, :3], axis=1)))
            dof = int(np.argmax(np.abs(linear.displacements[node, :3])))
        else:
            node, name = control
            if name not in DOF_NAMES:
                raise InputError(f"frame: control DOF must be one of {', '.join(DOF_NAMES)}, got {name!r}")
            dof = DOF_NAMES.index(name)
        run = nonlinear_static(model, supports, loads, control=(int(node), dof),
                               max_load_factor=max_load_factor if max_load_factor is not None else 10.0,
                               max_steps=200)
        result["path"] = run.path.tolist()
        result["limit_load_factor"] = run.limit_load_factor
        result["displacements"] = run.displacements.tolist()
    return result
