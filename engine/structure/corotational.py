"""Co-rotational non-linear static analysis of a space frame, with Crisfield's cylindrical
arc-length past limit points.

Each element's rigid motion is followed by its chord and the mean of its end triads; its
deformation is small in that frame, so the linear element of ``engine.structure.beam_elements`` holds there.
Newton iterations on the consistent tangent follow the path; the inertia of each step's factor
(its negative pivots) tells limit points from bifurcations.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConvergenceError, InputError
from ..linalg import single_threaded_blas
from .beam_elements import (
    FrameModel,
    check_loads,
    check_rigid_modes,
    condense,
    element_dofs,
    element_geometry,
    element_mesh,
    factor_free_stiffness,
    factor_or_none,
    factor_with_inertia,
    local_axes,
    local_stiffness,
    restrained_dofs,
)
from .condensed import FillOrdering
from .supports import Supports

__all__ = ["PathSettings", "NonlinearResult", "nonlinear_static"]

log = logging.getLogger(__name__)

#: The local end deformations of a co-rotational element: rotations at a (3-5), elongation (6),
#: rotations at b (9-11); its other local DOFs are zero by the element frame's definition.
LOCAL_DEFORMATIONS = (3, 4, 5, 6, 9, 10, 11)

#: From this many elements on, a path's internal forces, tangents, triads' updates and the
#: elimination of its beams' internal nodes are taken by compiled kernels (``corotational_kernels``,
#: ``block_inverse``; tangents in closed form: 0.0011 s against 0.0103 s by differences at 796
#: elements, 0.018 s against 0.060 s at 11 640). At every size: importing numba and loading the
#: kernels costs some 0.6 s once per process (forked workers inherit them), and a protocol runs a
#: dozen paths, each 2-3 times faster compiled (a 60-node frame's path 0.21 s against 0.59 s, the
#: mock-up's analysis stage 10.3 s against 15.5 s on one core; ``benchmarks/frame_speed.py
#: --tangents``). Tests and benchmarks raise it to run the differences.
COMPILED_FROM = 0


@dataclass(frozen=True, kw_only=True)
class NonlinearResult:
    """path (s,2): [load factor, control displacement] from [0, 0]; limit_load_factor: the first
    maximum of the load factor (None if not reached); negative_pivots (s,): negative pivots of the
    tangent stiffness at each point of the path (0 while stable; one more past a limit point or a
    bifurcation); displacements (n,6) at the limit point (or the last step); converged: False when
    a step failed to converge even at 1/256 of its arc; load_factors (s,); iterations (s,): Newton
    iterations of each step; monitored (s, k): the ``monitor`` DOFs along the path; factorisations:
    how many tangent stiffnesses were factored along the whole path (the dead load's included);
    tolerable_load_factor: where the path stopped at the tolerable deformation
    (``PathSettings.max_displacement``) before any limit point, the load factor there (else None)."""

    path: np.ndarray
    limit_load_factor: float | None
    negative_pivots: np.ndarray
    displacements: np.ndarray
    converged: bool = True
    load_factors: np.ndarray = field(default_factory=lambda: np.zeros(0))
    iterations: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    monitored: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    factorisations: int = 0
    tolerable_load_factor: float | None = None




def _rotation_matrices(vectors: np.ndarray) -> np.ndarray:
    """Rodrigues: (k,3) rotation vectors to (k,3,3) matrices, I + sin(a)/a W + (1 - cos(a))/a^2 W^2
    written out entry by entry (I + W below 1e-12 rad)."""
    angle = np.sqrt(np.einsum("ki,ki->k", vectors, vectors))
    small = angle <= 1e-12
    safe = np.where(small, 1.0, angle)
    s = np.where(small, 1.0, np.sin(angle) / safe)
    c = np.where(small, 0.0, (1 - np.cos(angle)) / safe**2)
    x, y, z = vectors.T
    R = np.empty((len(vectors), 3, 3))
    R[:, 0, 0], R[:, 1, 1], R[:, 2, 2] = 1 - c * (y * y + z * z), 1 - c * (x * x + z * z), 1 - c * (x * x + y * y)
    R[:, 0, 1], R[:, 1, 0] = c * x * y - s * z, c * x * y + s * z
    R[:, 0, 2], R[:, 2, 0] = c * x * z + s * y, c * x * z - s * y
    R[:, 1, 2], R[:, 2, 1] = c * y * z - s * x, c * y * z + s * x
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
        self.el = element_mesh(model)
        self.n_all = len(self.el.nodes)
        self.X = self.el.nodes.copy()
        self.L0, self.R0 = element_geometry(self.el, self.X)
        self.dofs = element_dofs(self.el.connectivity)
        self.restrained = restrained_dofs(supports, self.el.n_original, self.n_all)
        check_rigid_modes(self.el.nodes, self.restrained)
        self.free = np.flatnonzero(~self.restrained)
        self.R0_rows = np.ascontiguousarray(np.transpose(self.R0, (1, 2, 0)))        # R0[i, j] as (3, 3, m)
        self.K_local = condense(local_stiffness(self.L0, self.el), self.el.released)
        self.K7 = np.ascontiguousarray(self.K_local[:, :, LOCAL_DEFORMATIONS])
        K_rows = np.transpose(self.K_local, (1, 2, 0))                                # (12, 12, m)
        # the local deformations are the end rotations and the elongation only (node a at the
        # origin, node b on the axis), and a beam's stiffness couples few of them: per row of
        # the end forces, the columns of those it uses (22 of 144 products for prismatic beams)
        self.local_rows = []
        for i in range(12):
            columns = [j for j in LOCAL_DEFORMATIONS if np.any(K_rows[i, j])]
            self.local_rows.append((columns, np.ascontiguousarray(K_rows[i, columns])))
        self.ordering = FillOrdering()
        self.scatter = self.dofs.T.ravel()                                           # f (12, m) onto the DOFs
        self.step = 1e-8
        self.spins = [_rotation_matrices(self.step * np.eye(3)[k:k + 1])[0] for k in range(3)]

    def _kinematics(self, xa: np.ndarray, xb: np.ndarray, Ra: np.ndarray, Rb: np.ndarray):
        """The element frame and local deformations from the end positions (3, m) and the nodal
        triads times the initial element frame transposed, T R0^T (3, 3, m): the frame's rows
        (e1, y, z) (3 of (3, m)) and the local deformations d (12, m)."""
        chord = xb - xa
        length = np.sqrt(chord[0] ** 2 + chord[1] ** 2 + chord[2] ** 2)
        e1 = chord / length
        # nodal triads carry the initial element frame; their mean z orients the current frame
        up = 0.5 * (Ra[:, 2] + Rb[:, 2])
        z = up - (up[0] * e1[0] + up[1] * e1[1] + up[2] * e1[2]) * e1
        norm = np.sqrt(z[0] ** 2 + z[1] ** 2 + z[2] ** 2)
        bad = norm < 1e-6
        if np.any(bad):                                     # up along the chord: as local_axes
            z[:, bad] = local_axes(e1[:, bad].T, up[:, bad].T)[:, 2].T
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
        return R, d

    def _local_forces(self, d: np.ndarray) -> np.ndarray:
        """K_local d (12, m), over the terms that meet the local deformations."""
        f_local = np.zeros_like(d)
        for i, (columns, K_i) in enumerate(self.local_rows):
            if columns:
                row = K_i[0] * d[columns[0]]
                for K_ij, j in zip(K_i[1:], columns[1:]):
                    row += K_ij * d[j]
                f_local[i] = row
        return f_local

    def _end_forces(self, xa: np.ndarray, xb: np.ndarray, Ra: np.ndarray, Rb: np.ndarray):
        """Element end forces (12, m) in global axes from the end positions (3, m) and the nodal
        triads times the initial element frame transposed, T R0^T (3, 3, m) (``internal_forces``)."""
        R, d = self._kinematics(xa, xb, Ra, Rb)
        f_local = self._local_forces(d)
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

        if len(self.L0) >= COMPILED_FROM:
            from .corotational_kernels import element_forces, element_states  # numba: where it pays

            state = element_states(x, triads, a, b, R0)
            f_global, bad = element_forces(*state, self.L0, self.K7)
            if np.any(bad):                                 # the frame by local_axes
                f_global[:, bad] = self._end_forces(*state)[:, bad]
        else:
            state = (np.ascontiguousarray(x[a].T), np.ascontiguousarray(x[b].T), times_R0_T(triads[a]),
                     times_R0_T(triads[b]))
            f_global = self._end_forces(*state)
        out = np.bincount(self.scatter, weights=f_global.ravel(), minlength=6 * self.n_all)
        return out, state

    def tangent(self, state) -> np.ndarray:
        """Element tangent stiffnesses (m,12,12) in global axes: the derivative of the element
        end forces with respect to the end translations and spins (applied as in ``_update``); in
        closed form from COMPILED_FROM elements on (every size by default), by differences below."""
        if len(self.L0) >= COMPILED_FROM:
            return self.closed_form_tangent(state)
        return self.difference_tangent(state)

    def closed_form_tangent(self, state) -> np.ndarray:
        """``tangent`` in closed form (``engine.structure.corotational_kernels``), by differences
        where the mean z runs along the chord."""
        from .corotational_kernels import element_tangents  # numba: imported where it pays

        xa, xb, Ra, Rb = state
        K, bad = element_tangents(xa, xb, Ra, Rb, self.L0, self.K7)
        if np.any(bad):
            K[bad] = self.difference_tangent(state)[bad]
        return K

    def difference_tangent(self, state) -> np.ndarray:
        """``tangent`` by forward differences over all elements at once (9 evaluations of the
        element kernel, relative accuracy ~1e-8): the check of the closed form, and its stand-in
        where the element frame is local_axes'."""
        xa, xb, Ra, Rb = state
        base = self._end_forces(xa, xb, Ra, Rb)
        K = np.empty((12, 12, xa.shape[1]))
        h_translation = self.step * self.L0
        for column in range(3, 12):
            end, component = divmod(column, 6)
            x_pair, r_pair = [xa, xb], [Ra, Rb]
            if component < 3:
                shifted = x_pair[end].copy()
                shifted[component] += h_translation
                x_pair[end] = shifted
                h: np.ndarray | float = h_translation
            else:
                S, Rn = self.spins[component - 3], r_pair[end]
                r_pair[end] = np.stack([S[i, 0] * Rn[0] + S[i, 1] * Rn[1] + S[i, 2] * Rn[2] for i in range(3)])
                h = self.step
            K[:, column] = (self._end_forces(x_pair[0], x_pair[1], r_pair[0], r_pair[1]) - base) / h
        K[:, :3] = -K[:, 6:9]
        return np.ascontiguousarray(np.transpose(K, (2, 0, 1)))


def _update(x: np.ndarray, triads: np.ndarray, du: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions and triads moved by the DOF increments du (6 n,): translations added, triads
    turned by the spins (compiled from COMPILED_FROM nodes on)."""
    step = du.reshape(-1, 6)
    if len(x) >= COMPILED_FROM:
        from .corotational_kernels import spun_triads

        return x + step[:, :3], spun_triads(step[:, 3:], triads)
    return x + step[:, :3], _rotation_matrices(step[:, 3:]) @ triads


@dataclass(frozen=True)
class PathSettings:
    """Where the path stops and how closely it is followed: at ``max_load_factor``, after
    ``max_steps`` steps, or ``steps_past_limit`` steps past the first limit point; ``tolerance``:
    the residual norm relative to the norm of the applied load. ``reuse_factor``: the corrector
    iterates on the last factored tangent while each iteration at least halves the residual
    (modified Newton, refactored where it does not), instead of factoring at every iteration (full
    Newton, False); both converge to the same equilibria, the first with a fraction of the
    factorisations. ``limit_tolerance``: a step over the first maximum is not redone shorter where
    the parabola through the last points puts the peak within this share of the largest load
    factor found (0: always redone, up to 3 times). ``max_displacement``: the largest tolerable
    deformation (m): where a node's translation from the start first reaches it before a limit
    point, the path stops there (EN 1993-1-6's tolerable-deformation criterion for a path that
    stiffens instead of buckling: a net hanging under the load); None: no such bound."""

    max_load_factor: float = 10.0
    max_steps: int = 80
    tolerance: float = 1e-5
    steps_past_limit: int = 3
    reuse_factor: bool = True
    limit_tolerance: float = 2e-4
    max_displacement: float | None = None


def _peak_excess(before: float, at: float, *, back: float, after: float | None = None, ahead: float = 0.0,
                 slope: float | None = None) -> float:
    """How far the load factor's peak rises above ``at`` (the largest found), by the parabola in the
    arc length through ``before`` (``back`` behind) and ``at``, and either ``after`` (``ahead``
    beyond) or the ``slope`` at ``at``; inf where the points do not bracket a maximum."""
    if back <= 0:
        return np.inf
    if after is not None:
        if ahead <= 0:
            return np.inf
        curvature = (back * (after - at) + ahead * (before - at)) / (back * ahead * (back + ahead))
        slope = (after - at - curvature * ahead**2) / ahead
    elif slope is not None:
        curvature = (before - at + slope * back) / back**2
    else:
        return np.inf
    if curvature >= 0:
        return np.inf
    return float(-slope**2 / (4 * curvature))


def nonlinear_static(model: FrameModel, supports: Supports, loads: np.ndarray, *, control: tuple[int, int],
                     max_load_factor: float = 10.0, max_steps: int = 80, initial_loads: np.ndarray | None = None,
                     tolerance: float = 1e-5, steps_past_limit: int = 3,
                     max_displacement: float | None = None, monitor: list[tuple[int, int]] | None = None,
                     settings: PathSettings | None = None) -> NonlinearResult:
    """Geometrically non-linear static analysis with arc-length control.

    loads: reference load (n,6) scaled by the load factor; initial_loads: a dead load held
    constant (applied first, in load steps); control: (node, dof 0..5) whose displacement the
    path reports; monitor: further (node, dof) pairs recorded at every step in
    ``NonlinearResult.monitored`` (s, len(monitor)). The path stops ``steps_past_limit`` steps
    past the first limit point, at ``max_load_factor``, after ``max_steps``, or where a node's
    translation first reaches ``max_displacement`` (m) before any limit point (the load factor
    there is ``NonlinearResult.tolerable_load_factor``).

    Co-rotational elements (rigid motion from the chord and the mean of the end triads, local
    end rotations by the log map), Newton iterations on the consistent tangent (the exact
    derivative of the element forces, by vectorised forward differences), Crisfield's
    cylindrical arc-length with the step size adapted to about 5 iterations per step, the
    predictor's direction kept by the previous increment; a step that goes over the first maximum
    of the load factor is redone shorter (up to 3 times, 0.3 of the arc each) so the limit load
    factor is found within a small step. ``tolerance``: residual norm relative to the norm of
    the applied load. ``negative_pivots`` tells a limit point (a pivot turns negative at the
    maximum) from a bifurcation (pivots turn negative while the load still rises). ``settings``
    (PathSettings), when given, replaces the five stopping and tolerance keywords and sets whether
    the corrector reuses the factored tangent (by default it does).
    """
    if settings is None:
        settings = PathSettings(max_load_factor=max_load_factor, max_steps=max_steps, tolerance=tolerance,
                                steps_past_limit=steps_past_limit, max_displacement=max_displacement)
    with single_threaded_blas():
        return _nonlinear_static(model, supports, loads, control, settings, initial_loads, monitor)


def _nonlinear_static(model: FrameModel, supports: Supports, loads: np.ndarray, control: tuple[int, int],
                      settings: PathSettings, initial_loads: np.ndarray | None,
                      monitor: list[tuple[int, int]] | None) -> NonlinearResult:
    max_load_factor, max_steps = settings.max_load_factor, settings.max_steps
    tolerance, steps_past_limit = settings.tolerance, settings.steps_past_limit
    n = model.nodes.shape[0]
    loads = check_loads(loads, n)
    node, dof = control
    if not (0 <= node < n and 0 <= dof < 6):
        raise InputError(f"frame: control ({node}, {dof}) must be a node 0..{n - 1} and a DOF 0..5")
    cr = _Corotational(model, supports)
    free = cr.free
    factored = 0
    compiled = len(cr.L0) >= COMPILED_FROM        # the internal blocks by the compiled elimination

    def factor(cache, exact: bool = False):
        """The factored tangent at an element state, or None where it is singular. ``exact``: the
        whole tangent by SuperLU, where PARDISO would take its symmetric part (engine.structure.condensed)."""
        nonlocal factored
        factored += 1
        return factor_or_none(cr.tangent(cache), cr.el, free, cr.ordering, "superlu" if exact else "auto",
                              compiled=compiled)
    F_ref = np.zeros(6 * cr.n_all)
    F_ref[:6 * n] = loads.ravel()
    F_dead = np.zeros(6 * cr.n_all)
    if initial_loads is not None:
        F_dead[:6 * n] = check_loads(initial_loads, n).ravel()
    scale = max(float(np.linalg.norm(F_ref[free])), float(np.linalg.norm(F_dead[free])), 1e-300)
    x = cr.X.copy()
    triads = np.tile(np.eye(3), (cr.n_all, 1, 1))
    # the smallest correction the coordinates can take: below it an update is round-off (a model
    # whose members are so stiff that its whole path moves a few thousand ulps of its coordinates)
    floor = 4 * np.finfo(float).eps * float(np.sqrt(np.sum(cr.X**2) + 3 * cr.n_all))

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
            error = float(np.linalg.norm(r[free]))
            if error < tolerance * scale:
                return x, triads
            lu = factor(cache)
            if lu is None:
                return None
            du = np.zeros(6 * cr.n_all)
            du[free] = lu.solve(r[free])
            if error < 1e3 * tolerance * scale and np.linalg.norm(du[free]) < floor:
                return x, triads                     # the residual left is the coordinates' round-off
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
    lu = factor_free_stiffness(cr.tangent(cache), cr.el, free, ordering=cr.ordering, compiled=compiled)
    factored += 1
    u_ref = np.zeros(6 * cr.n_all)
    u_ref[free] = lu.solve(F_ref[free])
    arc = float(np.linalg.norm(u_ref[free]) * min(max_load_factor, 10.0) / 20.0)
    tolerable = settings.max_displacement

    def reach(x) -> float:
        """The largest translation of a node from the start, m."""
        return float(np.linalg.norm(x - cr.X, axis=1).max())
    if tolerable is not None:
        # the first step goes at most a tenth of the tolerable deformation: on a soft roof the
        # linear prediction is metres, and a few huge steps would pass over the path's shape
        linear_reach = float(np.linalg.norm(u_ref.reshape(-1, 6)[:, :3], axis=1).max())
        if linear_reach > 0:
            arc = min(arc, float(np.linalg.norm(u_ref[free])) * 0.1 * tolerable / linear_reach)
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
    arcs = [0.0]                      # the arc of the step to each point of the path
    refinements, arc_cap = 0, np.inf      # steps redone shorter near a critical point (at most 3)
    previous: np.ndarray | None = None
    limit = None
    limit_state = None
    past = 0
    converged_all = True
    tolerable_factor: float | None = None
    landings = 0                      # steps redone shorter to land on the tolerable deformation
    saved = None                      # the state before the last step, to redo it shorter
    # with reuse_factor, the factor of the corrector's last iteration where it was made there: one
    # correction (under the tolerance) from the step's end, it serves the next step's predictor and
    # its pivots count the negative eigenvalues there (and its solve for the reference load, made
    # there, is the predictor's)
    carried: tuple | None = None
    for _step in range(max_steps):
        du_f = None
        if carried is not None:
            (lu, negatives, du_f), carried = carried, None
        else:
            _, cache = residual(x, triads, lam)
            try:
                lu, negatives = factor_with_inertia(cr.tangent(cache), cr.el, free, cr.ordering, compiled)
            except RuntimeError:
                converged_all = False
                break
            factored += 1
        pivots[-1] = negatives                               # pivots of the tangent at this state
        if du_f is None:
            du_f = np.zeros(6 * cr.n_all)
            du_f[free] = lu.solve(F_ref[free])
        # the predictor follows the previous increment (at the start: the load's direction on a
        # stable tangent); the load factor falls along it once the path is past a maximum
        if previous is not None:
            direction = -1.0 if np.dot(previous[free], du_f[free]) < 0 else 1.0
        else:
            direction = -1.0 if negatives > 0 else 1.0
        # (the slope: d(load factor)/d(arc) past the top, read only once a maximum is passed)
        if saved is not None and limit is None and direction < 0 < lam and lam > saved[2] and refinements < 3 \
                and _peak_excess(saved[2], lam, back=arcs[-1], slope=-1 / max(float(np.linalg.norm(du_f[free])), 1e-300)
                                 ) > settings.limit_tolerance * lam:
            # the last step went over a maximum of the load factor: redo it shorter, to land
            # closer to the peak (each time 0.3 of the arc, held until the limit)
            refinements += 1
            x, triads, lam, previous, _, arc = saved
            arc *= 0.3
            arc_cap = arc
            saved = None
            for history in (path, monitored, pivots, factors, iterations, arcs):
                history.pop()
            continue
        accepted = False
        for _attempt in range(8):
            x_try, t_try, lam_try = x.copy(), triads.copy(), lam
            d_lam = direction * arc / max(float(np.linalg.norm(du_f[free])), 1e-300)
            total = d_lam * du_f
            x_try, t_try = _update(x_try, t_try, total)
            lam_try += d_lam
            ok = False
            correction_norm = np.inf
            # modified Newton: the step's factor (with its solve for the reference load) serves
            # the corrector while each iteration at least halves the residual, refreshed at the
            # current state after 8 uses. Where an iteration does not halve it (a strongly
            # non-linear step: Lee's frame, a cantilever rolled up by an end moment), the corrector
            # starts again from the prediction as full Newton, a factor at every iteration: the
            # scheme throughout with reuse_factor off.
            full = not settings.reuse_factor
            lu_i, df = (None, None) if full else (lu, du_f)
            predicted = (x_try, t_try, lam_try, total)
            first: tuple | None = None
            last_error, reused, restarted_at, fresh = np.inf, 0, 0, False
            for _iteration in range(25 if full else 40):
                r, cache = residual(x_try, t_try, lam_try)
                # relative to the load applied now; a tiny last correction also ends the iterations
                # when round-off (very stiff short elements) keeps the residual above the tolerance
                applied = max(float(np.linalg.norm(F_dead[free] + lam_try * F_ref[free])), 1e-12 * scale)
                error = float(np.linalg.norm(r[free])) / applied
                if error < tolerance or (error < 1e3 * tolerance
                                         and correction_norm < max(1e-10 * np.linalg.norm(total[free]), floor)):
                    ok = True
                    break
                if full and _iteration - restarted_at >= 25:          # as many as full Newton takes
                    break
                if first is None:
                    first = (r, cache, error)
                elif not full and error > 0.5 * last_error:
                    x_try, t_try, lam_try, total = predicted
                    r, cache, error = first
                    full, correction_norm, restarted_at = True, np.inf, _iteration
                fresh = full or lu_i is None or df is None or reused >= 8
                if fresh:
                    # on a step redone shorter, Newton's own tangent: where PARDISO factors its
                    # symmetric part (engine.structure.condensed), that may be what failed to converge (a
                    # cantilever rolled up by an end moment: tangents up to 6e-2 from symmetric)
                    lu_i = factor(cache, exact=_attempt > 0)
                    if lu_i is None:
                        break
                    df, dr = np.zeros(6 * cr.n_all), np.zeros(6 * cr.n_all)
                    both = lu_i.solve(np.column_stack((F_ref[free], r[free])))   # one pass over the factor
                    df[free], dr[free] = both[:, 0], both[:, 1]
                    reused = 0
                else:
                    # an old tangent's factor is only refined towards that old tangent: the
                    # symmetric part alone does as well for a corrector that iterates anyway
                    assert lu_i is not None
                    dr = np.zeros(6 * cr.n_all)
                    dr[free] = lu_i.solve(r[free], refine=False)
                assert df is not None
                last_error, reused = float(error), reused + 1
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
                correction_norm = float(np.linalg.norm(correction[free]))
                x_try, t_try = _update(x_try, t_try, correction)
                total = total + correction
                lam_try += float(dl)
            if ok:
                accepted = True
                break
            arc *= 0.5
        if not accepted:
            converged_all = False
            break
        landed = False
        if lam_try > max_load_factor >= lam and limit is None:
            # land exactly on the largest load factor asked for
            state = load_controlled(x, triads, F_dead + max_load_factor * F_ref)
            if state is not None:
                x_try, t_try = state
                lam_try, landed = max_load_factor, True
        if limit is None and lam_try < lam and lam > 0 and direction > 0 and refinements < 3 \
                and (_peak_excess(factors[-2], lam, back=arcs[-1], after=lam_try, ahead=arc)
                     > settings.limit_tolerance * lam):
            # the step went over a maximum of the load factor, and the peak may lie above the
            # largest load factor found by more than the tolerance: redo it shorter, to land closer
            # to the peak (each time 0.3 of the arc; the arc is then held until the limit)
            refinements += 1
            arc *= 0.3
            arc_cap = arc
            continue
        reached = reach(x_try) if tolerable is not None and limit is None and not lam_try < lam else 0.0
        if tolerable is not None and reached > tolerable:
            # the step passed the tolerable deformation on the way up (one that falls has passed a
            # limit point first): redo it aimed at it (at most 3 times) while it went more than
            # half the step too far, then read the load factor there off the step
            before = reach(x)              # past the bound already under the dead load alone: share 0
            share = float(np.clip((tolerable - before) / max(reached - before, 1e-300), 0.0, 1.0))
            if 0 < share < 0.5 and landings < 3:
                landings += 1
                arc *= max(share, 0.01)
                continue
            tolerable_factor = lam + share * (lam_try - lam)
        saved = (x, triads, lam, previous, negatives, arc)
        previous = total
        if limit is None and lam_try < lam and lam > 0:
            limit = lam
            limit_state = (x.copy(), triads.copy())
            arc_cap = np.inf
        x, triads, lam = x_try, t_try, lam_try
        if settings.reuse_factor and fresh and lu_i is not None and not landed:
            carried = (lu_i, lu_i.negative_pivots, df)
        path.append([lam, displacement_of(x, triads)])
        monitored.append(watched(x, triads))
        pivots.append(negatives)                             # provisional: set at the next step
        factors.append(lam)
        iterations.append(_iteration)
        arcs.append(arc)
        # automatic step size: aim at about 5 corrector iterations per step, counted from the
        # corrector's restart where it had one (more on a reused factor, which converges linearly,
        # would let the arcs grow until full Newton fails from the prediction near a critical point)
        arc = min(arc * float(np.clip(np.sqrt(5 / max(_iteration - restarted_at, 1)), 0.5, 2.0)), arc_cap)
        if limit is not None:
            past += 1
            if past >= steps_past_limit:
                break
        if lam >= max_load_factor or tolerable_factor is not None:
            break
    if len(path) > 1:                                        # pivots of the final state
        try:
            pivots[-1] = factor_with_inertia(cr.tangent(residual(x, triads, lam)[1]), cr.el, free, cr.ordering,
                                             compiled)[1]
            factored += 1
        except RuntimeError:
            pass
    log.info("non-linear path: %d steps, %d Newton iterations, %d factorisations, load factor %.4g, limit %s%s%s",
             len(path) - 1, int(np.sum(iterations)), factored, lam, "none" if limit is None else f"{limit:.4g}",
             "" if tolerable_factor is None else f", tolerable deformation at {tolerable_factor:.4g}",
             "" if converged_all else ", a step did not converge")
    if limit_state is None:
        limit_state = (x, triads)
    lx, lt = limit_state
    displacements = np.zeros((cr.n_all, 6))
    displacements[:, :3] = lx - cr.X
    displacements[:, 3:] = _rotation_vectors(lt)
    return NonlinearResult(path=np.array(path), limit_load_factor=limit, negative_pivots=np.array(pivots),
                           displacements=displacements[:n], converged=converged_all, load_factors=np.array(factors),
                           iterations=np.array(iterations), factorisations=factored,
                           tolerable_load_factor=tolerable_factor,
                           monitored=np.array(monitored, dtype=float).reshape(len(path), len(watch)))
