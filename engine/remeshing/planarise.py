"""Planar cells by Gauss-Newton on nodes and planes: the end game of the face optimisation.

Unknowns: the free node coordinates (three per interior node, one along the surface boundary
per sliding node; fixed nodes have none) and one plane per cell of four or more nodes.
Energy (m^2), with d_i the distance of node i from the reference surface, theta a cell's
corner angle, l a beam's length and L the mean beam length at the start:

    sum_cells W_f sum_nodes (n_f . (x_i - c_f))^2           planarity: node distance from the cell's plane
  + W_r sum_cells ||C x - R(x)||^2                          regularity: mean-free regular targets R
  + w_c sum_nodes d_i^2 + sum_nodes W_i (d_i - b)_+^2       closeness: soft, and a band of half-width b
  + g sum_corners W L^2 (theta_min - theta)_+^2 + g sum_beams W (l_min - l)_+^2   shape guards

Each Gauss-Newton step refits the planes (their optimum for the current nodes) and eliminates
them exactly: per cell, the three directions in which a change of plane absorbs the residuals
(turning about its two in-plane axes, shifting along the normal) are projected out (variable
projection, Golub and Pereyra 1973, with Kaufman's 1975 approximation). The system then has the
node DOFs only, with the pattern of the Shape-Up matrix and the cell block W_f P (x) n n^T.
Closeness is linearised along the direction to the closest surface point (point-to-plane), so
nodes slide along the surface freely; the regular targets are held during a step (as in the
local/global iterations) and refitted after it. Levenberg-Marquardt damping (Marquardt's
diagonal scaling, Nielsen's update) keeps every accepted step downhill in the true energy, and
no node moves more than ``max_step`` L in one step (the band and the guards are hinges that the
linear model sees only near their limits; a long step could jump across one).

Penalty schedule: every cell's weight W_f starts at ``start_weight`` (W_r + w_c) and grows by
``growth`` after every step that leaves that cell beyond the goal (``stop_share`` times the
tolerance), up to ``max_weight`` (W_r + w_c): a quadratic penalty that tends to the hard
constraint where it is needed without stiffening the cells that are already planar. The band
and the guards at a node take the largest weight of its cells (the guards ``guard_share`` times
it), so planarity never wins over them: without the guards the penalty finds planar cells by
closing corners to 0 degrees where the geometry leaves no other way.

The matrix changes with the planes, so every trial step is a new sparse LU factorisation
(SuperLU); the count is reported.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..geometry.projections import corner_angles

__all__ = ["PlanariseSettings", "PlanariseReport", "planarise", "cell_planes", "corner_angles"]

#: Guards and the band enter the Gauss-Newton model (curvature only) once within this factor of
#: their limit, so that the model sees a hinge before a step crosses it.
GUARD_MARGIN = 1.3


@dataclass(frozen=True, kw_only=True)
class PlanariseSettings:
    """Tolerance, band and limit (m), relative weights and the penalty schedule.

    tolerance: largest wanted node distance from its cell's plane; the steps stop once every cell
    is within ``stop_share * tolerance`` and every moving node within ``limit`` of the surface;
    band: half-width of the closeness band (nodes inside it are free to leave the surface);
    iterations: largest number of Gauss-Newton steps. A corner may not close below
    min(min_angle_deg, angle_share * its start angle), a beam not shorten below
    min_length_share * its start length, nor below ``min_beam_length`` (m; the shortest buildable
    beam, which a shorter beam is pushed back to).
    """

    tolerance: float
    band: float
    limit: float
    regularity_weight: float = 4.0
    closeness_weight: float = 1.0
    iterations: int = 80
    start_weight: float = 10.0
    growth: float = 4.0
    max_weight: float = 1e5
    stop_share: float = 0.9
    min_angle_deg: float = 20.0
    angle_share: float = 0.75
    min_length_share: float = 0.5
    min_beam_length: float = 0.0
    guard_share: float = 10.0
    max_step: float = 0.1


@dataclass(frozen=True, kw_only=True)
class PlanariseReport:
    """What the end game did: steps taken, trial steps rejected, factorisations, the largest
    relative cell weight W_f / (W_r + w_c) at the end, whether tolerance and limit were reached,
    and the largest planarity error and node distance to the surface at the end (m)."""

    iterations: int
    rejected_steps: int
    factorisations: int
    planarity_weight: float
    reached: bool
    planarity_max_m: float
    closeness_max_m: float


def cell_planes(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Best-fit planes of (f,k,3) cells: centroids (f,3), in-plane axes (f,2,3), unit normals
    (f,3) and the signed node distances from the plane (f,k), m."""
    centroid = points.mean(axis=1)
    q = points - centroid[:, None]
    _, _, vt = np.linalg.svd(q, full_matrices=False)
    normal = vt[:, 2]
    return centroid, vt[:, :2], normal, np.einsum("fki,fi->fk", q, normal)


def planarity_terms(groups: dict[int, np.ndarray], x: np.ndarray, weights: dict[int, np.ndarray] | None = None,
                    hessian: bool = True):
    """Planarity energy sum_f w_f sum_i (n_f . (x_i - c_f))^2 (m^2) of the cells ``groups``
    {k: (f_k, k) node ids} at nodes ``x`` (n,3), and the largest |n_f . (x_i - c_f)| per cell
    {k: (f_k,)} (m). With ``hessian``, also the Gauss-Newton Hessian of half the energy with
    each cell's plane eliminated (COO rows, cols, values over the 3n node DOFs, node-major) and
    its gradient (n,3)."""
    rows, cols, vals = [], [], []
    gradient = np.zeros_like(x)
    energy, largest = 0.0, {}
    for k, faces in groups.items():
        f = len(faces)
        w = np.ones(f) if weights is None else weights[k]
        points = x[faces]
        _, axes, normal, r = cell_planes(points)
        energy += float(np.sum(w[:, None] * r**2))
        largest[k] = np.abs(r).max(axis=1)
        if not hessian:
            continue
        q = points - points.mean(axis=1, keepdims=True)
        # P = I - projections onto the plane's three directions (mutually orthogonal: PCA axes)
        projector = np.broadcast_to(np.eye(k) - 1.0 / k, (f, k, k)).copy()
        for a in range(2):
            g = np.einsum("fki,fi->fk", q, axes[:, a])
            norm = np.sqrt(np.einsum("fk,fk->f", g, g))
            g = g / np.maximum(norm, 1e-300)[:, None] * (norm > 1e-300)[:, None]
            projector -= g[:, :, None] * g[:, None, :]
        nn = w[:, None, None] * normal[:, :, None] * normal[:, None, :]
        block = projector[:, :, None, :, None] * nn[:, None, :, None, :]  # (f, i, a, j, b) = w P_ij n_a n_b
        dof = (3 * faces[:, :, None] + np.arange(3)).reshape(f, 3 * k)
        rows.append(np.repeat(dof, 3 * k, axis=1).ravel())
        cols.append(np.tile(dof, (1, 3 * k)).ravel())
        vals.append(block.ravel())
        np.add.at(gradient, faces.ravel(), ((w[:, None] * r)[:, :, None] * normal[:, None, :]).reshape(-1, 3))
    if not hessian:
        return energy, largest
    empty = [np.zeros(0, np.int64)]
    return (energy, largest, np.concatenate(rows or empty), np.concatenate(cols or empty),
            np.concatenate(vals or [np.zeros(0)]), gradient)


def _add_rows(ids: np.ndarray, jacobian: np.ndarray, residual: np.ndarray, weight: np.ndarray | float,
              parts: list, gradient: np.ndarray) -> None:
    """Add w J^T J and w J^T r of scalar residual rows r (m,) with Jacobian blocks (m, p, 3) on
    node ids (m, p) to the COO parts and the gradient (n,3) (of half the energy)."""
    if len(residual) == 0:
        return
    m, p = ids.shape
    w = np.broadcast_to(np.asarray(weight, dtype=float), (m,))
    flat = jacobian.reshape(m, 3 * p)
    dof = (3 * ids[:, :, None] + np.arange(3)).reshape(m, 3 * p)
    parts.append((np.repeat(dof, 3 * p, axis=1).ravel(), np.tile(dof, (1, 3 * p)).ravel(),
                  (w[:, None, None] * flat[:, :, None] * flat[:, None, :]).ravel()))
    np.add.at(gradient, ids.ravel(), ((w * residual)[:, None, None] * jacobian).reshape(-1, 3))


def _angle_rows(x: np.ndarray, corners: np.ndarray, minimum: np.ndarray):
    """Corners closing to within GUARD_MARGIN of their limit: (their rows in ``corners`` (m,),
    Jacobian of -theta (m,3,3), residual (theta_min - theta)_+ (m,)) rad."""
    theta = corner_angles(x, corners)
    active = np.flatnonzero(theta < GUARD_MARGIN * minimum)
    c = corners[active]
    u, v = x[c[:, 0]] - x[c[:, 1]], x[c[:, 2]] - x[c[:, 1]]
    lu, lv = np.linalg.norm(u, axis=1), np.linalg.norm(v, axis=1)
    uh, vh = u / np.maximum(lu, 1e-300)[:, None], v / np.maximum(lv, 1e-300)[:, None]
    cos, sin = np.cos(theta[active]), np.maximum(np.sin(theta[active]), 1e-3)
    d_a = -(vh - cos[:, None] * uh) / (lu * sin)[:, None]  # d theta / d a
    d_b = -(uh - cos[:, None] * vh) / (lv * sin)[:, None]
    jacobian = -np.stack([d_a, -(d_a + d_b), d_b], axis=1)
    return active, jacobian, np.maximum(minimum[active] - theta[active], 0.0)


def _length_rows(x: np.ndarray, beams: np.ndarray, minimum: np.ndarray):
    """Beams shortening to within GUARD_MARGIN of their limit: (their rows in ``beams`` (m,),
    Jacobian of -l (m,2,3), residual (l_min - l)_+ (m,)) m."""
    d = x[beams[:, 1]] - x[beams[:, 0]]
    length = np.linalg.norm(d, axis=1)
    active = np.flatnonzero(length < GUARD_MARGIN * minimum)
    e = d[active] / np.maximum(length[active], 1e-300)[:, None]
    return active, np.stack([e, -e], axis=1), np.maximum(minimum[active] - length[active], 0.0)


def _basis(n: int, free: np.ndarray, slide_ids: np.ndarray, tangents: np.ndarray) -> sp.csr_matrix:
    """(3n, m) admissible displacements: 3 per free node, one along the tangent per sliding node."""
    rows = np.r_[(3 * free[:, None] + np.arange(3)).ravel(), (3 * slide_ids[:, None] + np.arange(3)).ravel()]
    cols = np.r_[np.arange(3 * len(free)), 3 * len(free) + np.repeat(np.arange(len(slide_ids)), 3)]
    vals = np.r_[np.ones(3 * len(free)), tangents.ravel()]
    return sp.csr_matrix((vals, (rows, cols)), shape=(3 * n, 3 * len(free) + len(slide_ids)))


class _EndGame:
    """The energy of the module docstring, its Gauss-Newton model and the penalty weights."""

    def __init__(self, x, groups, interior, sliding, closest, centering, regular, beams, settings, reference):
        self.settings = settings
        self.n = len(x)
        self.groups = {k: f for k, f in groups.items() if k >= 4}
        self.moving = interior | sliding
        self.closest, self.centering, self.regular, self.beams = closest, centering, regular, beams
        self.w_r, self.w_c = settings.regularity_weight, settings.closeness_weight
        self.base = max(self.w_r + self.w_c, 1e-12)
        self.weights = {k: np.full(len(f), settings.start_weight * self.base) for k, f in self.groups.items()}
        self.regularity_hessian = (sp.kron(centering.T @ centering, sp.eye(3), format="csr")
                                   if self.w_r > 0 else None)
        self.corners = np.concatenate([np.stack([np.roll(f, 1, axis=1), f, np.roll(f, -1, axis=1)], axis=2)
                                       .reshape(-1, 3) for f in groups.values()])
        self.min_angle = np.minimum(np.radians(settings.min_angle_deg),
                                    settings.angle_share * corner_angles(reference, self.corners))
        lengths = np.linalg.norm(reference[beams[:, 1]] - reference[beams[:, 0]], axis=1)
        self.min_length = np.maximum(settings.min_length_share * lengths, settings.min_beam_length)
        self.scale = float(lengths.mean()) if len(beams) else 1.0
        self.refresh()

    def refresh(self) -> None:
        """Band and guard weights from the cell weights: the largest at each node."""
        node = np.full(self.n, self.settings.start_weight * self.base)
        for k, faces in self.groups.items():
            np.maximum.at(node, faces.ravel(), np.repeat(self.weights[k], k))
        self.node_weight = node
        self.corner_weight = node[self.corners].max(axis=1)
        self.beam_weight = node[self.beams].max(axis=1) if len(self.beams) else np.zeros(0)

    def distances(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n,) distance to the surface and (n,3) unit direction from the closest point (the
        surface normal there for a node on the surface)."""
        q, normal = self.closest(x)
        d = x - q
        distance = np.linalg.norm(d, axis=1)
        on = distance <= 1e-12 * self.scale
        return distance, np.where(on[:, None], normal, d / np.maximum(distance, 1e-300)[:, None])

    def energy(self, x: np.ndarray) -> float:
        s = self.settings
        planar = planarity_terms(self.groups, x, self.weights, hessian=False)[0]
        distance = self.distances(x)[0][self.moving]
        over = np.maximum(distance - s.band, 0.0)
        angle = np.maximum(self.min_angle - corner_angles(x, self.corners), 0.0)
        short = np.maximum(self.min_length - np.linalg.norm(x[self.beams[:, 1]] - x[self.beams[:, 0]], axis=1), 0.0)
        e = (planar + float(np.sum(self.node_weight[self.moving] * over**2)) + self.w_c * float(np.sum(distance**2))
             + s.guard_share * (self.scale**2 * float(np.sum(self.corner_weight * angle**2))
                                + float(np.sum(self.beam_weight * short**2))))
        if self.w_r > 0:
            e += self.w_r * float(np.sum((self.centering @ x - self.regular(x)) ** 2))
        return e

    def model(self, x: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
        """Gauss-Newton Hessian (3n, 3n) and gradient (3n,) of half the energy at x."""
        s = self.settings
        _, _, rows, cols, vals, gradient = planarity_terms(self.groups, x, self.weights)
        parts = [(rows, cols, vals)]
        distance, direction = self.distances(x)
        ids = np.flatnonzero(self.moving)
        _add_rows(ids[:, None], direction[ids, None, :], distance[ids], self.w_c, parts, gradient)
        out = ids[distance[ids] > s.band / GUARD_MARGIN]
        _add_rows(out[:, None], direction[out, None, :], np.maximum(distance[out] - s.band, 0.0),
                  self.node_weight[out], parts, gradient)
        active, jacobian, residual = _angle_rows(x, self.corners, self.min_angle)
        _add_rows(self.corners[active], self.scale * jacobian, self.scale * residual,
                  s.guard_share * self.corner_weight[active], parts, gradient)
        active, jacobian, residual = _length_rows(x, self.beams, self.min_length)
        _add_rows(self.beams[active], jacobian, residual, s.guard_share * self.beam_weight[active], parts, gradient)
        rows, cols, vals = (np.concatenate(v) for v in zip(*parts))
        hessian = sp.csr_matrix((vals, (rows, cols)), shape=(3 * self.n, 3 * self.n))
        if self.regularity_hessian is not None:
            hessian = hessian + self.w_r * self.regularity_hessian
            gradient += self.w_r * (self.centering.T @ (self.centering @ x - self.regular(x)))
        return hessian, gradient.ravel()

    def status(self, x: np.ndarray) -> tuple[dict[int, np.ndarray], float, float]:
        """Largest planarity error per cell, overall (m), and the largest moving node's distance (m)."""
        per_cell = planarity_terms(self.groups, x, hessian=False)[1]
        worst = max((float(v.max()) for v in per_cell.values()), default=0.0)
        distance = float(self.distances(x)[0][self.moving].max()) if self.moving.any() else 0.0
        return per_cell, worst, distance

    def raise_weights(self, per_cell: dict[int, np.ndarray], goal: float) -> bool:
        """Grow the weights of the cells beyond ``goal``; True if any grew."""
        top = self.settings.max_weight * self.base
        raised = False
        for k, w in self.weights.items():
            behind = (per_cell[k] > goal) & (w < top)
            if behind.any():
                w[behind] = np.minimum(w[behind] * self.settings.growth, top)
                raised = True
        if raised:
            self.refresh()
        return raised

    def strongest(self) -> float:
        return max((float(w.max()) for w in self.weights.values()), default=self.settings.start_weight * self.base)


def planarise(x: np.ndarray, groups: dict[int, np.ndarray], *, interior: np.ndarray, sliding: np.ndarray,
              closest: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
              slide: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
              centering: sp.csr_matrix, regular: Callable[[np.ndarray], np.ndarray],
              beams: np.ndarray, settings: PlanariseSettings, reference: np.ndarray | None = None,
              progress: Callable[[int], None] | None = None) -> tuple[np.ndarray, PlanariseReport]:
    """Planar cells near ``x`` (n,3) m by Gauss-Newton with the planes eliminated (module docstring).

    groups: {k: (f_k, k) node ids} of all cells (cells of three nodes enter the regularity and the
    guards only); interior, sliding: (n,) bool, nodes with three DOFs and nodes sliding along the
    boundary (the others are fixed); closest(points) -> (closest surface points, unit surface
    normals there); slide(points) -> (closest boundary points, unit boundary tangents there);
    centering: the (rows, n) mean-free rows of the cells in ``groups`` order; regular(x) ->
    (rows, 3) mean-free regular targets in the same order; beams: (e,2) node ids; reference:
    (n,3) the nodes whose corner angles and beam lengths set the guards' limits (default ``x``;
    the optimiser passes the grid as it came, so that corners an earlier phase closed reopen).
    ``progress(step)`` is called after every step. Returns the new nodes and a report.
    """
    x = np.array(x, dtype=float)
    n = len(x)
    s = settings
    free, slide_ids = np.flatnonzero(interior), np.flatnonzero(sliding)
    tangents = np.zeros((0, 3))
    if len(slide_ids):
        x[sliding], tangents = slide(x[sliding])
    game = _EndGame(x, groups, interior, sliding, closest, centering, regular, beams, s,
                    x if reference is None else np.asarray(reference, dtype=float))
    goal = s.stop_share * s.tolerance
    steps = rejected = factorisations = 0
    damping, boost = 1e-4, 2.0
    current = game.energy(x)
    per_cell, largest, distance = game.status(x)
    while steps < s.iterations and len(free) + len(slide_ids) > 0:
        if largest <= goal and distance <= s.limit:
            break
        hessian, gradient = game.model(x)
        basis = _basis(n, free, slide_ids, tangents)
        reduced = (basis.T @ hessian @ basis).tocsc()
        rhs = -(basis.T @ gradient)
        diagonal = reduced.diagonal()
        marquardt = np.maximum(diagonal, 1e-9 * max(float(diagonal.max()), 1e-300))
        accepted = False
        for _attempt in range(12):
            step = spla.spsolve((reduced + sp.diags(damping * marquardt)).tocsc(), rhs)
            factorisations += 1
            predicted = float(step @ (damping * marquardt * step + rhs))
            move = (basis @ step).reshape(n, 3)
            longest = float(np.linalg.norm(move, axis=1).max())
            if longest > s.max_step * game.scale:
                move *= s.max_step * game.scale / longest
                predicted = np.nan
            trial = x + move
            trial_tangents = tangents
            if len(slide_ids):
                trial[sliding], trial_tangents = slide(trial[sliding])
            value = game.energy(trial)
            if np.isfinite(value) and value < current:
                # Nielsen's damping update from the gain ratio (Madsen, Nielsen, Tingleff 2004)
                gain = (current - value) / max(predicted, 1e-300) if np.isfinite(predicted) else 0.5
                damping = max(damping * max(1 / 3, 1 - (2 * gain - 1) ** 3), 1e-12)
                x, tangents, current, boost, accepted = trial, trial_tangents, value, 2.0, True
                break
            rejected += 1
            damping *= boost
            boost *= 2.0
        steps += 1
        if progress is not None:
            progress(steps)
        if not accepted:
            break
        per_cell, largest, distance = game.status(x)
        if game.raise_weights(per_cell, goal):
            current = game.energy(x)
    per_cell, largest, distance = game.status(x)
    report = PlanariseReport(iterations=steps, rejected_steps=rejected, factorisations=factorisations,
                             planarity_weight=game.strongest() / game.base,
                             reached=bool(largest <= s.tolerance and distance <= s.limit),
                             planarity_max_m=largest, closeness_max_m=distance)
    return x, report
