"""Member checks of circular hollow sections to EN 1993-1-1 (2005 + AC 2009), vectorised.

Per member, from the section forces at both ends of the linear ULS analysis:
- section class from d/t and epsilon = sqrt(235 MPa / fy) (5.5, Table 5.2: 50, 70, 90 eps^2);
  class 4 (local shell buckling, EN 1993-1-6) is not covered and counts as failing, measured by
  d/t over the class 3 limit;
- shear (6.2.6, A_v = 2 A / pi) with torsion (6.2.7: Bredt's shear stress, V_pl,T,Rd of 6.2.7(9)),
  and the reduced yield strength for bending where V_Ed > V_pl,T,Rd / 2 (6.2.8);
- utilisations are load factors: the cross-section's is 1 / the factor by which all its forces may
  grow together (so 2.0 needs twice the resistance), which passes exactly where the clauses do;
- axial force with biaxial bending (6.2.9): class 1-2 with the resultant moment against
  M_N,Rd = M_pl,Rd (1 - n^1.7) (6.2.9.1(6) with alpha = beta = 2; the CHS formula of
  EN 1993-1-1:2022 8.2.9.1), reported as the factor by which N and M may grow together;
  class 3 with the linear elastic stress N / A + M / W_el <= fy / gamma_M0 (6.2.9.2); both
  reported as the factor by which N, M, V and T may grow together;
- flexural buckling (6.3.1) with chi on the curve of Table 6.2 (hot-finished a, cold-formed c,
  otherwise the material's), and compression with biaxial bending (6.3.3, equations 6.61 and
  6.62) with the interaction factors of Annex B, Table B.1 for hollow sections (CHS are not
  susceptible to lateral-torsional buckling: chi_LT = 1) and C_m of Table B.3 for the linear
  moment between the beam's end moments (loads reach the beams at the nodes).
The buckling length is given per member (node to node by default, or from the buckling modes).
Not checked: class 4 sections, the thickness dependence of fy (the catalogues stop at 16 mm),
joints, fatigue, fire.

``simplified_checks`` keeps the earlier stated simplification (linear interaction, elastic moduli,
interaction factors 1) for other materials and for ``[analysis] checks = "simplified"``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from .catalogue import chs_properties
from .checks import buckling_reduction
from .sections import Material

__all__ = ["EndForces", "TubeChecks", "chs_checks", "simplified_checks", "buckling_alpha", "section_class",
           "CHECKED", "NOT_CHECKED", "ChecksMethod"]

#: The member checks: EN 1993-1-1 (:func:`chs_checks`) or the stated simplification (:func:`simplified_checks`).
ChecksMethod = Literal["en1993", "simplified"]

CHECKED = ("section class (Table 5.2)", "axial force with biaxial bending (6.2.9)", "shear with torsion (6.2.6-6.2.8)",
           "flexural buckling (6.3.1)", "compression with biaxial bending, Annex B (6.3.3)")
NOT_CHECKED = ("class 4 sections (EN 1993-1-6)", "fy reduced for walls over 16 mm", "joints and welds (EN 1993-1-8)",
               "fatigue", "fire")

# EN 1993-1-1 Table 6.1 imperfection factors of the curves of Table 6.2 for hollow sections
_CURVES = {"hot-finished": 0.21, "cold-formed": 0.49}


def buckling_alpha(process: str | None, material: Material) -> float:
    """Imperfection factor: curve a for hot-finished, c for cold-formed steel tubes (Table 6.2),
    else the material's own."""
    if material.kind == "steel" and process in _CURVES:
        return _CURVES[process]
    return material.buckling_alpha


def section_class(diameter: np.ndarray, thickness: np.ndarray, fy: float) -> np.ndarray:
    """Class 1-4 of tubes in compression (EN 1993-1-1 Table 5.2, sheet 3)."""
    eps2 = 235e6 / fy
    ratio = np.asarray(diameter, float) / np.asarray(thickness, float)
    return np.select([ratio <= 50 * eps2, ratio <= 70 * eps2, ratio <= 90 * eps2], [1, 2, 3], 4)


@dataclass(frozen=True)
class EndForces:
    """What the checks need of each member's end forces (b,): N at both ends (b,2) tension +, the
    bending moments My, Mz at both ends (b,2, the same sign at both ends for a uniform moment), the
    largest resultant shear V (N) and torsion T (N m)."""

    N: np.ndarray
    My: np.ndarray
    Mz: np.ndarray
    V: np.ndarray
    T: np.ndarray

    @classmethod
    def of(cls, beam_end_forces: np.ndarray) -> "EndForces":
        """From (b,2,6) section forces [N, Vy, Vz, T, My, Mz] (engine.structure.frame.LinearResult)."""
        f = np.asarray(beam_end_forces, dtype=float)
        return cls(N=f[:, :, 0], My=f[:, :, 4], Mz=f[:, :, 5], V=np.hypot(f[:, :, 1], f[:, :, 2]).max(axis=1),
                   T=np.abs(f[:, :, 3]).max(axis=1))

    def column(self) -> "EndForces":
        """The same forces shaped (b,1, ...) to broadcast against (1,s) candidate tubes."""
        return EndForces(N=self.N[:, None], My=self.My[:, None], Mz=self.Mz[:, None], V=self.V[:, None],
                         T=self.T[:, None])


def _equivalent_moment_factor(M: np.ndarray) -> np.ndarray:
    """C_m of Table B.3 for a linear moment: 0.6 + 0.4 psi >= 0.4, psi the smaller end moment over
    the larger (both signs as the frame gives them: equal signs are single curvature)."""
    a, b = M[..., 0], M[..., 1]
    large = np.where(np.abs(a) >= np.abs(b), a, b)
    small = np.where(np.abs(a) >= np.abs(b), b, a)
    psi = np.divide(small, large, out=np.ones_like(large), where=np.abs(large) > 0)
    return np.maximum(0.6 + 0.4 * psi, 0.4)


@dataclass(frozen=True, kw_only=True)
class TubeChecks:
    """Utilisations per member (arrays that broadcast like the inputs): utilisation = the largest;
    cross_section (6.2.9), shear (6.2.6-6.2.8), torsion (6.2.7), buckling (6.3.3, 0 in tension),
    section_class, slenderness (relative), chi, buckling_length (m), class_4 (d/t over the class 3
    limit, > 1 where class 4), governing (names, only for one tube per member)."""

    utilisation: np.ndarray
    cross_section: np.ndarray
    shear: np.ndarray
    torsion: np.ndarray
    buckling: np.ndarray
    section_class: np.ndarray
    slenderness: np.ndarray
    chi: np.ndarray
    buckling_length: np.ndarray
    class_4: np.ndarray
    axial_force: np.ndarray
    governing: list[str] | None = None


_NAMES = ("cross-section N+M (6.2.9)", "shear (6.2.6)", "torsion (6.2.7)", "buckling N+M (6.3.3)",
          "section class 4 (not covered)")


#: the same checks' names in the simplified method, which follows no clause
_SIMPLIFIED_NAMES = ("cross-section", "shear", "torsion", "flexural buckling", "section class 4 (not covered)")


def _governing(parts: list[np.ndarray], names: tuple[str, ...] = _NAMES) -> list[str] | None:
    """The name of the largest part per member; None for candidate matrices (b, s), which the
    sizing checks by the thousand and never names."""
    if np.broadcast(*parts).ndim != 1:
        return None
    return [names[k] for k in np.stack(np.broadcast_arrays(*parts)).argmax(axis=0)]


def _cross_section_load_factor(n: np.ndarray, m: np.ndarray, v: np.ndarray, tau: np.ndarray,
                               plastic: np.ndarray) -> np.ndarray:
    """1 / lambda, lambda the factor by which N, M, V and T may grow together until the section
    yields: n, m, v and tau are N / N_pl,Rd, M / M_c,Rd, V / V_pl,Rd and tau_t / tau_Rd at lambda = 1.
    At lambda: V_pl,T,Rd = (1 - lambda tau) V_pl,Rd (6.2.7(9)); rho = (2 s - 1)^2 where s = lambda v /
    (1 - lambda tau) > 1/2 (6.2.8); class 1-2 yield where lambda m / (1 - rho) > 1 - (lambda n)^1.7
    (6.2.9.1), class 3 where lambda n + lambda m / (1 - rho) > 1 (6.2.9.2); s >= 1 fails in shear."""
    n, m, v, tau, plastic = np.broadcast_arrays(*(np.asarray(x, float) for x in (n, m, v, tau)),
                                                np.asarray(plastic, bool))
    largest = np.maximum.reduce([n, m, v + tau])
    upper = 1.0 / np.maximum(largest, 1e-300)
    lower = np.zeros_like(upper)
    for _ in range(50):
        mid = 0.5 * (lower + upper)
        remaining = np.maximum(1.0 - mid * tau, 1e-300)
        s = mid * v / remaining
        rho = np.where(s > 0.5, (2 * np.minimum(s, 1.0) - 1) ** 2, 0.0)
        bending = mid * m / np.maximum(1.0 - rho, 1e-300)
        yields = np.where(plastic, bending + (mid * n) ** 1.7 > 1.0, mid * n + bending > 1.0)
        over = (s >= 1.0) | (mid * tau >= 1.0) | yields
        upper = np.where(over, mid, upper)
        lower = np.where(over, lower, mid)
    return np.where(largest > 0, 1.0 / np.maximum(lower, 1e-300), 0.0)


def chs_checks(forces: EndForces, diameter: np.ndarray, thickness: np.ndarray, material: Material, *,
               alpha: float, buckling_length: np.ndarray) -> TubeChecks:
    """EN 1993-1-1 checks of tubes (diameter, thickness in m) under ``forces``; arrays broadcast
    (members (b,) against one tube each, or (b,1) forces against (1,s) candidate tubes)."""
    D, t = np.asarray(diameter, float), np.asarray(thickness, float)
    p = chs_properties(D, t)
    fy, g0, g1 = material.fy, material.gamma_M0, material.gamma_M1
    cls = section_class(D, t, fy)
    plastic = cls <= 2
    class_4 = (D / t) / (90 * 235e6 / fy)
    # shear with torsion (6.2.6, 6.2.7(9)), and the yield strength left for bending (6.2.8)
    tau_Rd = fy / np.sqrt(3) / g0
    mean_radius = (D - t) / 2
    torsion = forces.T / (2 * np.pi * mean_radius**2 * t) / tau_Rd
    v = forces.V / (2 * p["A"] / np.pi * tau_Rd)
    # V <= V_pl,T,Rd = (1 - tau_t / tau_Rd) V_pl,Rd is v + torsion <= 1: the utilisation in shear
    shear = np.where(forces.V > 0, v + torsion, 0.0)
    # axial force and biaxial bending (6.2.9): the resultant moment of each end, the worse end,
    # with the yield strength that the shear leaves (6.2.8)
    N_abs = np.abs(forces.N).max(axis=-1)
    M_res = np.hypot(forces.My, forces.Mz).max(axis=-1)
    W = np.where(plastic, p["W_pl"], p["W_el"])
    n, m = N_abs / (p["A"] * fy / g0), M_res / (W * fy / g0)
    cross_section = _cross_section_load_factor(n, m, v, torsion, plastic)
    # flexural buckling with bending (6.3.1, 6.3.3, Annex B)
    L = np.asarray(buckling_length, float)
    N_cr = np.pi**2 * material.E * p["I"] / L**2
    slenderness = np.sqrt(p["A"] * fy / N_cr)
    chi = buckling_reduction(slenderness, alpha)
    compression = np.maximum(-forces.N, 0.0).max(axis=-1)
    n_b = compression / (chi * p["A"] * fy / g1)
    My, Mz = np.abs(forces.My).max(axis=-1), np.abs(forces.Mz).max(axis=-1)
    Cy, Cz = _equivalent_moment_factor(forces.My), _equivalent_moment_factor(forces.Mz)
    M_Rd1 = W * fy / g1
    k_plastic = lambda C: C * (1 + np.minimum(slenderness - 0.2, 0.8) * n_b)  # noqa: E731 (Table B.1, hollow)
    k_elastic = lambda C: C * (1 + 0.6 * np.minimum(slenderness, 1.0) * n_b)  # noqa: E731
    kyy = np.where(plastic, k_plastic(Cy), k_elastic(Cy))
    kzz = np.where(plastic, k_plastic(Cz), k_elastic(Cz))
    kyz = np.where(plastic, 0.6 * kzz, kzz)
    kzy = np.where(plastic, 0.6 * kyy, 0.8 * kyy)
    eq61 = n_b + (kyy * My + kyz * Mz) / M_Rd1
    eq62 = n_b + (kzy * My + kzz * Mz) / M_Rd1
    buckling = np.where(compression > 0, np.maximum(eq61, eq62), 0.0)
    class_4_part = np.where(cls == 4, class_4, 0.0)
    parts = [cross_section, shear, torsion, buckling, class_4_part]
    utilisation = np.maximum.reduce(np.broadcast_arrays(*parts))
    return TubeChecks(utilisation=utilisation, cross_section=cross_section, shear=shear, torsion=torsion,
                      buckling=buckling, section_class=cls, slenderness=slenderness, chi=chi,
                      buckling_length=np.broadcast_to(L, slenderness.shape), class_4=class_4,
                      axial_force=forces.N.mean(axis=-1), governing=_governing(parts))


def simplified_checks(forces: EndForces, A: float | np.ndarray, I: float | np.ndarray, W_el: float | np.ndarray,
                      material: Material, *, alpha: float, buckling_length: np.ndarray,
                      Wz_el: float | np.ndarray | None = None) -> TubeChecks:
    """The stated simplification (engine.design.checks: linear interaction with elastic moduli, interaction
    factors 1) over arrays of sections (A, the weaker I, W_el about y and ``Wz_el`` about z, default
    the same; SI, broadcasting)."""
    fy, g0, g1 = material.fy, material.gamma_M0, material.gamma_M1
    N = forces.N.mean(axis=-1)
    My_Rd = W_el * fy / g0
    Mz_Rd = My_Rd if Wz_el is None else Wz_el * fy / g0
    bending = np.abs(forces.My).max(axis=-1) / My_Rd + np.abs(forces.Mz).max(axis=-1) / Mz_Rd
    cross_section = np.abs(N) / (A * fy / g0) + bending
    L = np.asarray(buckling_length, float)
    slenderness = np.sqrt(A * fy / (np.pi**2 * material.E * I / L**2))
    chi = buckling_reduction(slenderness, alpha)
    buckling = np.where(N < 0, np.maximum(-N, 0.0) / (chi * A * fy / g1) + bending, 0.0)
    zero = np.zeros(np.broadcast(cross_section, buckling).shape)
    parts = [cross_section, zero, zero, buckling, zero]
    return TubeChecks(utilisation=np.maximum(cross_section, buckling), cross_section=cross_section, shear=zero,
                      torsion=zero, buckling=buckling, section_class=np.zeros(zero.shape, int),
                      slenderness=slenderness, chi=chi, buckling_length=np.broadcast_to(L, zero.shape),
                      class_4=zero, axial_force=N, governing=_governing(parts, _SIMPLIFIED_NAMES))
