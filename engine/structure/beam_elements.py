"""The space frame's model and its beam elements: 3D Euler-Bernoulli beams with 6 DOF per node
(ux, uy, uz, rx, ry, rz), each beam split into ``elements_per_beam`` elements, with the element
kernels (local stiffness, geometric stiffness, transformation) vectorised over all elements, the
assembly, the restrained DOFs of the supports and the factor of the free stiffness (a singular one
is a mechanism, named).

Local axes: x along the beam, z the beam's ``up`` vector made perpendicular to x (the strong axis:
Iy is about local y, bending in the x-z plane), y = z cross x. Units: any consistent set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import InputError, MechanismError
from ..linalg import assemble_blocks, block_diagonal, count_free_rigid_modes, free_rigid_motions, node_dofs
from .condensed import CondensedFactor, FillOrdering
from .supports import Supports

__all__ = ["FrameModel", "ElementMesh", "element_mesh", "local_stiffness", "geometric_stiffness", "transformation",
           "element_dofs", "assemble", "element_geometry", "restrained_dofs", "check_rigid_modes",
           "factor_free_stiffness", "condensed_factor", "factor_or_none", "factor_with_inertia", "check_loads",
           "condense", "released_zero"]


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




# ----------------------------------------------------------------------------- mesh of elements

@dataclass(frozen=True)
class ElementMesh:
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


def element_mesh(model: FrameModel, nodes: np.ndarray | None = None) -> ElementMesh:
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
    return ElementMesh(nodes=all_nodes, connectivity=connectivity, beam=beam, up=model.up[beam], E=model.E[beam],
                     G=model.G[beam], A=model.A[beam], Iy=model.Iy[beam], Iz=model.Iz[beam], J=model.J[beam],
                     first=first, last=last, n_original=n, released=released)


def released_zero(K: np.ndarray, released: np.ndarray | None) -> np.ndarray:
    """Zero the rows and columns of released local DOFs."""
    if released is None:
        return K
    keep = (~released).astype(float)
    return K * keep[:, :, None] * keep[:, None, :]


def condense(K: np.ndarray, released: np.ndarray | None) -> np.ndarray:
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


def local_axes(x_axis: np.ndarray, up: np.ndarray) -> np.ndarray:
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


def local_stiffness(L: np.ndarray, el: ElementMesh) -> np.ndarray:
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


def geometric_stiffness(L: np.ndarray, N: np.ndarray, el: ElementMesh) -> np.ndarray:
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


def transformation(R: np.ndarray) -> np.ndarray:
    """(m,12,12) global-to-local transformation of two-node elements with frames R (m,3,3)."""
    return block_diagonal(R, 4)


def element_dofs(connectivity: np.ndarray) -> np.ndarray:
    """(m,12) node-major DOF indices of two-node elements."""
    return node_dofs(connectivity)


def assemble(K_elements: np.ndarray, dofs: np.ndarray, n_dofs: int) -> sp.csc_matrix:
    """Global matrix from element matrices (m,12,12) on the node-major DOFs (m,12) of element_dofs."""
    return assemble_blocks(K_elements, dofs[:, ::6] // 6, n_dofs // 6)


def element_geometry(el: ElementMesh, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = nodes[el.connectivity[:, 1]] - nodes[el.connectivity[:, 0]]
    L = np.linalg.norm(d, axis=1)
    return L, local_axes(d / L[:, None], el.up)


# ----------------------------------------------------------------------------- supports, solving

def restrained_dofs(supports: Supports, n_original: int, n_all: int) -> np.ndarray:
    if len(supports.nodes) and (supports.nodes.max() >= n_original or supports.nodes.min() < 0):
        raise InputError(f"frame: a support node is out of range 0..{n_original - 1}")
    mask = np.zeros((n_all, 6), dtype=bool)
    mask[:n_original] = supports.dof_mask(n_original)
    return mask.ravel()


def check_rigid_modes(nodes: np.ndarray, restrained: np.ndarray) -> None:
    """Raise MechanismError when the restrained DOFs (6n,) bool leave rigid-body motions free, naming them."""
    free_modes = count_free_rigid_modes(nodes, restrained)
    if free_modes:
        raise MechanismError(f"the frame is a mechanism: its supports leave {free_modes} rigid-body mode(s) free "
                             f"({', '.join(free_rigid_motions(nodes, restrained))})",
                             n_modes=free_modes, hint="support more nodes or restrain more directions")


def short_beam_hint(beam_lengths: np.ndarray | None) -> str | None:
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


def factor_free_stiffness(K_elements: np.ndarray, el: ElementMesh, free: np.ndarray,
                          beam_lengths: np.ndarray | None = None, *,
                          ordering: FillOrdering | None = None, compiled: bool = False) -> CondensedFactor:
    """Factor of the stiffness on the free DOFs from the element matrices (m,12,12) in global
    axes, the beams' internal nodes condensed out (``engine.structure.condensed``); a singular matrix is a
    mechanism, named with its count. ``ordering``: kept between factorisations of one pattern;
    ``compiled``: CondensedFactor's."""
    try:
        lu = condensed_factor(K_elements, el, free, ordering, compiled=compiled)
    except RuntimeError as exc:
        raise MechanismError("the frame is a mechanism: its stiffness matrix is singular", n_modes=1,
                             hint="check for loose beams or nodes held by pinned ends only") from exc
    tiny = lu.tiny_pivots
    if tiny:
        raise MechanismError(f"the frame is a mechanism with {tiny} free mode(s) beyond rigid-body motion",
                             n_modes=tiny,
                             hint=short_beam_hint(beam_lengths) or "check for loose beams, beams released at both "
                             "ends (a free spin about their axis) or nodes joined by pinned ends only")
    return lu


def condensed_factor(K_elements: np.ndarray, el: ElementMesh, free: np.ndarray,
                     ordering: FillOrdering | None = None, library: str = "auto",
                     compiled: bool = False) -> CondensedFactor:
    """The condensed factor (``engine.structure.condensed``) of element matrices on ``el``'s free DOFs;
    ``library``: S's (engine.structure.solvers.library_for); ``compiled``: CondensedFactor's."""
    return CondensedFactor(K_elements, el.connectivity, len(el.nodes), el.n_original, free,
                           len(el.connectivity) // len(el.first), ordering=ordering, library=library,
                           compiled=compiled)


def factor_or_none(K_elements: np.ndarray, el: ElementMesh, free: np.ndarray,
                   ordering: FillOrdering | None = None, library: str = "auto",
                   compiled: bool = False) -> CondensedFactor | None:
    """The condensed factor, or None where the matrix is singular (an exactly zero pivot, or one
    PARDISO perturbed)."""
    try:
        lu = condensed_factor(K_elements, el, free, ordering, library, compiled)
    except RuntimeError:
        return None
    return None if lu.singular else lu


def factor_with_inertia(K_elements: np.ndarray, el: ElementMesh, free: np.ndarray,
                        ordering: FillOrdering | None = None, compiled: bool = False) -> tuple[CondensedFactor, int]:
    """The condensed factor and its count of negative pivots. Raises RuntimeError where the matrix
    is singular (as factor_or_none's None). ``compiled``: CondensedFactor's."""
    lu = condensed_factor(K_elements, el, free, ordering, compiled=compiled)
    if lu.singular:
        raise RuntimeError("Factor is singular (a pivot perturbed)")
    return lu, lu.negative_pivots


def check_loads(loads: np.ndarray, n: int) -> np.ndarray:
    loads = np.asarray(loads, dtype=float)
    if loads.shape != (n, 6) or not np.all(np.isfinite(loads)):
        raise InputError(f"frame: loads must be a finite ({n}, 6) array, got {loads.shape}")
    return loads
