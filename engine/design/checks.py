"""Member checks in the manner of Eurocode 3, simplified and stated.

Per member, from the section forces at both ends (largest values):
- cross-section: |N| / N_Rd + |My| / My_Rd + |Mz| / Mz_Rd <= 1 with N_Rd = A fy / gamma_M0 and
  elastic moment resistances W_el fy / gamma_M0 (the conservative linear interaction of
  EN 1993-1-1 6.2.1(7), valid for every section class that does not buckle locally);
- flexural buckling, members in compression: N_Ed / (chi A fy / gamma_M1) + |My| / My_Rd +
  |Mz| / Mz_Rd <= 1 (the interaction factors k of EN 1993-1-1 6.3.3 taken as 1), chi from
  6.3.1.2 with the material's buckling curve, the weaker axis and the buckling length
  k L (k = buckling_length_factor, L the node-to-node length).
Shear and torsion are not checked (small in grid-shells of tubes); say so in reports.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sections import Material, Section

__all__ = ["MemberChecks", "member_checks", "buckling_reduction"]


@dataclass(frozen=True, kw_only=True)
class MemberChecks:
    """utilisation (b,) = max of the checks; governing (b,) names; cross_section, buckling (b,);
    axial_force (b,) N (tension +, mean of both ends); slenderness (b,) relative."""

    utilisation: np.ndarray
    governing: list[str]
    cross_section: np.ndarray
    buckling: np.ndarray
    axial_force: np.ndarray
    slenderness: np.ndarray


def buckling_reduction(slenderness: np.ndarray, alpha: float) -> np.ndarray:
    """chi of EN 1993-1-1 6.3.1.2 for relative slenderness lambda-bar and imperfection factor alpha."""
    lam = np.asarray(slenderness, dtype=float)
    phi = 0.5 * (1 + alpha * (lam - 0.2) + lam**2)
    chi = 1.0 / (phi + np.sqrt(np.maximum(phi**2 - lam**2, 0.0)))
    return np.where(lam <= 0.2, 1.0, np.minimum(chi, 1.0))


def member_checks(beam_end_forces: np.ndarray, lengths: np.ndarray, section: Section, material: Material, *,
                  buckling_length_factor: float = 1.0) -> MemberChecks:
    """Utilisations of every member; beam_end_forces (b,2,6) section forces [N, Vy, Vz, T, My, Mz]."""
    from .en1993 import EndForces, simplified_checks  # it imports buckling_reduction from here

    checks = simplified_checks(EndForces.of(beam_end_forces), section.A, min(section.Iy, section.Iz),
                               section.Wy_el, material, alpha=material.buckling_alpha,
                               buckling_length=buckling_length_factor * np.asarray(lengths, dtype=float),
                               Wz_el=section.Wz_el)
    assert checks.governing is not None  # one section over the members (b,): the checks are named
    return MemberChecks(utilisation=checks.utilisation, governing=checks.governing,
                        cross_section=checks.cross_section, buckling=checks.buckling,
                        axial_force=checks.axial_force, slenderness=checks.slenderness)
