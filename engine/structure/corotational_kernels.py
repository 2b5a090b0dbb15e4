"""The co-rotational beam element's end forces and tangent stiffness, compiled.

The element end forces are f = R^T K_local d (``engine.structure.corotational``): the element
frame R has rows (e1, y, z), e1 along the chord and z the mean of the nodal z axes off the chord;
d holds the elongation and the end rotations, each the log map of R times the nodal triad. Their
derivative with respect to the end translations and spins has two parts, K_local's through d
(the material part) and f's turning with R (the geometric part). Each end rotation theta changes
by J_l(theta)^-1 times the spin of R T relative to R, J_l being the left Jacobian of the
exponential map. The forces depend on the end positions through the chord only, so the columns of
end a's translations are minus those of end b's.

One element at a time in numba loops (``cache=True``: the first call in a fresh checkout compiles
them, later processes load them). Vectorised numpy over the elements made some 60 temporaries of
(9, m) for the tangent, and was slower than 9 finite differences of the force kernel; the forces
in numpy take some 20 temporaries of (3, m) and a gather of the nodal triads (docs/decisions.md).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["element_states", "element_forces", "element_tangents", "spun_triads"]

#: Below this norm of the mean z off the chord the frame is local_axes', left to the caller.
DEGENERATE_UP = 1e-6


@njit(cache=True, nogil=True, inline="always")
def _frame(e, xa, xb, Ra, Rb, e1, up, z, y, R):  # pragma: no cover - compiled
    """The frame's rows of element e into R (and e1, up, z, y); (length, up . e1, |z off the
    chord|), the last under DEGENERATE_UP where the frame is not the chord's and the mean z."""
    c0, c1, c2 = xb[0, e] - xa[0, e], xb[1, e] - xa[1, e], xb[2, e] - xa[2, e]
    length = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    e1[0], e1[1], e1[2] = c0 / length, c1 / length, c2 / length
    for i in range(3):
        up[i] = 0.5 * (Ra[i, 2, e] + Rb[i, 2, e])
    up_e1 = up[0] * e1[0] + up[1] * e1[1] + up[2] * e1[2]
    for i in range(3):
        z[i] = up[i] - up_e1 * e1[i]
    norm = np.sqrt(z[0] ** 2 + z[1] ** 2 + z[2] ** 2)
    if norm < DEGENERATE_UP:
        return length, up_e1, norm
    for i in range(3):
        z[i] /= norm
    y[0], y[1], y[2] = z[1] * e1[2] - z[2] * e1[1], z[2] * e1[0] - z[0] * e1[2], z[0] * e1[1] - z[1] * e1[0]
    for j in range(3):
        R[0, j], R[1, j], R[2, j] = e1[j], y[j], z[j]
    return length, up_e1, norm


@njit(cache=True, nogil=True, inline="always")
def _end_rotation(R, Rn, e, M):  # pragma: no cover - compiled
    """The log map of R times the nodal triad Rn[..., e] (the end's local rotation, 3 floats)."""
    for i in range(3):
        for k in range(3):
            M[i, k] = R[i, 0] * Rn[0, k, e] + R[i, 1] * Rn[1, k, e] + R[i, 2] * Rn[2, k, e]
    # sin(angle) from the skew part and the angle by atan2: exact at small angles, where arccos of
    # the trace loses half the digits, and a third faster than arccos and sin
    v0, v1, v2 = 0.5 * (M[2, 1] - M[1, 2]), 0.5 * (M[0, 2] - M[2, 0]), 0.5 * (M[1, 0] - M[0, 1])
    sine = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    factor = np.arctan2(sine, 0.5 * (M[0, 0] + M[1, 1] + M[2, 2] - 1.0)) / sine if sine > 1e-9 else 1.0
    return v0 * factor, v1 * factor, v2 * factor


@njit(cache=True, nogil=True)
def _states(x, triads, a, b, R0, xa, xb, Ra, Rb):  # pragma: no cover - compiled
    for e in range(a.shape[0]):
        p, q = a[e], b[e]
        for i in range(3):
            xa[i, e] = x[p, i]
            xb[i, e] = x[q, i]
            for k in range(3):
                r0, r1, r2 = R0[k, 0, e], R0[k, 1, e], R0[k, 2, e]
                Ra[i, k, e] = triads[p, i, 0] * r0 + triads[p, i, 1] * r1 + triads[p, i, 2] * r2
                Rb[i, k, e] = triads[q, i, 0] * r0 + triads[q, i, 1] * r1 + triads[q, i, 2] * r2


@njit(cache=True, nogil=True)
def _spin(spins, triads, out):  # pragma: no cover - compiled
    R = np.empty((3, 3))
    for n in range(spins.shape[0]):
        x, y, z = spins[n, 0], spins[n, 1], spins[n, 2]
        angle = np.sqrt(x * x + y * y + z * z)
        if angle <= 1e-12:
            s, c = 1.0, 0.0
        else:
            s, c = np.sin(angle) / angle, (1.0 - np.cos(angle)) / (angle * angle)
        R[0, 0], R[1, 1], R[2, 2] = 1.0 - c * (y * y + z * z), 1.0 - c * (x * x + z * z), 1.0 - c * (x * x + y * y)
        R[0, 1], R[1, 0] = c * x * y - s * z, c * x * y + s * z
        R[0, 2], R[2, 0] = c * x * z + s * y, c * x * z - s * y
        R[1, 2], R[2, 1] = c * y * z - s * x, c * y * z + s * x
        for i in range(3):
            for k in range(3):
                out[n, i, k] = R[i, 0] * triads[n, 0, k] + R[i, 1] * triads[n, 1, k] + R[i, 2] * triads[n, 2, k]


@njit(cache=True, nogil=True)
def _forces(xa, xb, Ra, Rb, L0, K7, out):  # pragma: no cover - compiled
    m = xa.shape[1]
    bad = np.zeros(m, dtype=np.bool_)
    R = np.empty((3, 3))
    M = np.empty((3, 3))
    d = np.empty(7)
    f = np.empty(12)
    e1, up, z, y = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    for e in range(m):
        length, _, norm = _frame(e, xa, xb, Ra, Rb, e1, up, z, y, R)
        if norm < DEGENERATE_UP:
            bad[e] = True
            continue
        d[0], d[1], d[2] = _end_rotation(R, Ra, e, M)
        d[3] = length - L0[e]
        d[4], d[5], d[6] = _end_rotation(R, Rb, e, M)
        for i in range(12):
            s = 0.0
            for j in range(7):
                s += K7[e, i, j] * d[j]
            f[i] = s
        for block in range(0, 12, 3):
            for j in range(3):
                out[block + j, e] = f[block] * R[0, j] + f[block + 1] * R[1, j] + f[block + 2] * R[2, j]
    return bad


@njit(cache=True, nogil=True)
def _tangents(xa, xb, Ra, Rb, L0, K7, out):  # pragma: no cover - compiled
    m = xa.shape[1]
    bad = np.zeros(m, dtype=np.bool_)
    R = np.empty((3, 3))
    De1 = np.zeros((3, 9))
    Du = np.zeros((3, 9))
    Dz = np.empty((3, 9))
    Dy = np.empty((3, 9))
    spin = np.empty((3, 9))
    Dd = np.zeros((7, 9))
    d = np.empty(7)
    f = np.empty(12)
    K9 = np.empty((12, 9))
    phi = np.empty((3, 9))
    M = np.empty((3, 3))
    e1, up, z, y = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    for e in range(m):
        length, up_e1, norm = _frame(e, xa, xb, Ra, Rb, e1, up, z, y, R)
        if norm < DEGENERATE_UP:             # the frame by local_axes: left to the caller
            bad[e] = True
            continue
        # the frame's derivatives in the columns (chord 0-2, spin at a 3-5, spin at b 6-8)
        for i in range(3):
            for j in range(3):
                De1[i, j] = ((1.0 if i == j else 0.0) - e1[i] * e1[j]) / length
        for col, Rn in ((3, Ra), (6, Rb)):   # d(spin x v) = -W(v) d(spin), v the nodal z axis
            v0, v1, v2 = Rn[0, 2, e], Rn[1, 2, e], Rn[2, 2, e]
            Du[0, col + 1], Du[0, col + 2] = 0.5 * v2, -0.5 * v1
            Du[1, col + 0], Du[1, col + 2] = -0.5 * v2, 0.5 * v0
            Du[2, col + 0], Du[2, col + 1] = 0.5 * v1, -0.5 * v0
        for k in range(9):
            e1_du = e1[0] * Du[0, k] + e1[1] * Du[1, k] + e1[2] * Du[2, k]
            up_de1 = up[0] * De1[0, k] + up[1] * De1[1, k] + up[2] * De1[2, k]
            for i in range(3):
                Dz[i, k] = Du[i, k] - e1[i] * (e1_du + up_de1) - up_e1 * De1[i, k]
            z_dz = z[0] * Dz[0, k] + z[1] * Dz[1, k] + z[2] * Dz[2, k]
            for i in range(3):
                Dz[i, k] = (Dz[i, k] - z[i] * z_dz) / norm
            # y = z x e1
            Dy[0, k] = Dz[1, k] * e1[2] - Dz[2, k] * e1[1] + z[1] * De1[2, k] - z[2] * De1[1, k]
            Dy[1, k] = Dz[2, k] * e1[0] - Dz[0, k] * e1[2] + z[2] * De1[0, k] - z[0] * De1[2, k]
            Dy[2, k] = Dz[0, k] * e1[1] - Dz[1, k] * e1[0] + z[0] * De1[1, k] - z[1] * De1[0, k]
            # the frame's spin in its own axes
            spin[0, k] = y[0] * Dz[0, k] + y[1] * Dz[1, k] + y[2] * Dz[2, k]
            spin[1, k] = z[0] * De1[0, k] + z[1] * De1[1, k] + z[2] * De1[2, k]
            spin[2, k] = e1[0] * Dy[0, k] + e1[1] * Dy[1, k] + e1[2] * Dy[2, k]
        # the local deformations (rotations at a 0-2, elongation 3, rotations at b 4-6) and their rates
        d[3] = length - L0[e]
        for k in range(9):
            Dd[3, k] = e1[k] if k < 3 else 0.0
        for row, col, Rn in ((0, 3, Ra), (4, 6, Rb)):
            t0, t1, t2 = _end_rotation(R, Rn, e, M)
            d[row], d[row + 1], d[row + 2] = t0, t1, t2
            a2 = t0 * t0 + t1 * t1 + t2 * t2
            if a2 < 1e-8:
                kappa = 1.0 / 12.0 + a2 / 720.0
            else:
                half = 0.5 * np.sqrt(a2)
                kappa = (1.0 - half / np.tan(half)) / a2
            for k in range(9):
                for i in range(3):
                    phi[i, k] = spin[i, k] + (R[i, k - col] if col <= k < col + 3 else 0.0)
                p0, p1, p2 = phi[0, k], phi[1, k], phi[2, k]
                dot = t0 * p0 + t1 * p1 + t2 * p2
                # J_l^-1 p = p - theta x p / 2 + kappa (theta (theta . p) - a^2 p)
                Dd[row, k] = p0 - 0.5 * (t1 * p2 - t2 * p1) + kappa * (t0 * dot - a2 * p0)
                Dd[row + 1, k] = p1 - 0.5 * (t2 * p0 - t0 * p2) + kappa * (t1 * dot - a2 * p1)
                Dd[row + 2, k] = p2 - 0.5 * (t0 * p1 - t1 * p0) + kappa * (t2 * dot - a2 * p2)
        for i in range(12):
            s = 0.0
            for j in range(7):
                s += K7[e, i, j] * d[j]
            f[i] = s
            for k in range(9):
                s = 0.0
                for j in range(7):
                    s += K7[e, i, j] * Dd[j, k]
                K9[i, k] = s
        for block in range(0, 12, 3):
            for j in range(3):
                for k in range(9):
                    value = 0.0
                    for i in range(3):
                        value += K9[block + i, k] * R[i, j]
                    value += f[block] * De1[j, k] + f[block + 1] * Dy[j, k] + f[block + 2] * Dz[j, k]
                    # columns: translations at a (minus the chord's), spin at a, translations at b, spin at b
                    if k < 3:
                        out[e, block + j, 6 + k] = value
                        out[e, block + j, k] = -value
                    elif k < 6:
                        out[e, block + j, k] = value
                    else:
                        out[e, block + j, 3 + k] = value
    return bad


def element_tangents(xa: np.ndarray, xb: np.ndarray, Ra: np.ndarray, Rb: np.ndarray, L0: np.ndarray,
                     K7: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Element tangents (m, 12, 12) in global axes, and the elements (m,) bool whose frame is not
    the chord's and the mean z (the mean z along the chord), left at zero for the caller.

    xa, xb: end positions (3, m), m; Ra, Rb: nodal triads times the initial element frame
    transposed (3, 3, m); L0: initial lengths (m,), m; K7: the local stiffness's columns of the
    local deformations (rotations at a, elongation, rotations at b) (m, 12, 7)."""
    out = np.zeros((xa.shape[1], 12, 12))
    bad = _tangents(np.ascontiguousarray(xa), np.ascontiguousarray(xb), np.ascontiguousarray(Ra),
                    np.ascontiguousarray(Rb), np.ascontiguousarray(L0, dtype=float), K7, out)
    return out, bad


def element_states(x: np.ndarray, triads: np.ndarray, a: np.ndarray, b: np.ndarray,
                   R0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The elements' end positions xa, xb (3, m), m, and nodal triads times the initial element
    frame transposed, T R0^T, Ra, Rb (3, 3, m), from the nodes' positions x (n, 3), triads
    (n, 3, 3), the elements' end nodes a, b (m,) and the initial frames R0[i, j] as (3, 3, m)."""
    m = len(a)
    xa, xb = np.empty((3, m)), np.empty((3, m))
    Ra, Rb = np.empty((3, 3, m)), np.empty((3, 3, m))
    _states(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(triads, dtype=float),
            np.ascontiguousarray(a, dtype=np.int64), np.ascontiguousarray(b, dtype=np.int64),
            np.ascontiguousarray(R0), xa, xb, Ra, Rb)
    return xa, xb, Ra, Rb


def element_forces(xa: np.ndarray, xb: np.ndarray, Ra: np.ndarray, Rb: np.ndarray, L0: np.ndarray,
                   K7: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Element end forces (12, m) in global axes, and the elements (m,) bool whose frame is not the
    chord's and the mean z (the mean z along the chord), left at zero for the caller. The
    arguments as ``element_tangents``'."""
    out = np.zeros((12, xa.shape[1]))
    bad = _forces(np.ascontiguousarray(xa), np.ascontiguousarray(xb), np.ascontiguousarray(Ra),
                  np.ascontiguousarray(Rb), np.ascontiguousarray(L0, dtype=float), K7, out)
    return out, bad


def spun_triads(spins: np.ndarray, triads: np.ndarray) -> np.ndarray:
    """The nodal triads (n, 3, 3) turned by the spins (n, 3), rad: Rodrigues' matrix of each spin
    (``corotational._rotation_matrices``) times its triad."""
    out = np.empty((len(spins), 3, 3))
    _spin(np.ascontiguousarray(spins, dtype=float), np.ascontiguousarray(triads, dtype=float), out)
    return out
