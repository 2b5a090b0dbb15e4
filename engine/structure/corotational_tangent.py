"""The co-rotational beam element's tangent stiffness in closed form, compiled.

The element end forces are f = R^T K_local d (``engine.structure.corotational``): the element
frame R has rows (e1, y, z), e1 along the chord and z the mean of the nodal z axes off the chord;
d holds the elongation and the end rotations, each the log map of R times the nodal triad. Their
derivative with respect to the end translations and spins has two parts, K_local's through d
(the material part) and f's turning with R (the geometric part). Each end rotation theta changes
by J_l(theta)^-1 times the spin of R T relative to R, J_l being the left Jacobian of the
exponential map. The forces depend on the end positions through the chord only, so the columns of
end a's translations are minus those of end b's.

One element at a time in a numba loop (``cache=True``: the first call in a fresh checkout compiles
it, later processes load it). Vectorised numpy over the elements made some 60 temporaries of
(9, m), and was slower than 9 finite differences of the force kernel (docs/decisions.md).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["element_tangents"]


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
        c0, c1, c2 = xb[0, e] - xa[0, e], xb[1, e] - xa[1, e], xb[2, e] - xa[2, e]
        length = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        e1[0], e1[1], e1[2] = c0 / length, c1 / length, c2 / length
        for i in range(3):
            up[i] = 0.5 * (Ra[i, 2, e] + Rb[i, 2, e])
        up_e1 = up[0] * e1[0] + up[1] * e1[1] + up[2] * e1[2]
        for i in range(3):
            z[i] = up[i] - up_e1 * e1[i]
        norm = np.sqrt(z[0] ** 2 + z[1] ** 2 + z[2] ** 2)
        if norm < 1e-6:                      # the frame by local_axes: left to the caller
            bad[e] = True
            continue
        for i in range(3):
            z[i] /= norm
        y[0], y[1], y[2] = z[1] * e1[2] - z[2] * e1[1], z[2] * e1[0] - z[0] * e1[2], z[0] * e1[1] - z[1] * e1[0]
        for j in range(3):
            R[0, j], R[1, j], R[2, j] = e1[j], y[j], z[j]
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
            for i in range(3):
                for k in range(3):
                    M[i, k] = R[i, 0] * Rn[0, k, e] + R[i, 1] * Rn[1, k, e] + R[i, 2] * Rn[2, k, e]
            cosine = min(max((M[0, 0] + M[1, 1] + M[2, 2] - 1.0) / 2.0, -1.0), 1.0)
            angle = np.arccos(cosine)
            sine = np.sin(angle)
            factor = angle / (2.0 * sine) if sine > 1e-9 else 0.5
            t0, t1, t2 = (M[2, 1] - M[1, 2]) * factor, (M[0, 2] - M[2, 0]) * factor, (M[1, 0] - M[0, 1]) * factor
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
