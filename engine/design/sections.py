"""Beam materials and cross-sections.

Values are characteristic (nominal) ones from the standards named per material; partial
factors are the recommended ones. The printed polymers are small-scale mock-up materials whose
values vary with the printer and settings: treat their checks as indicative.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["Material", "Section", "material", "section_from_spec", "MATERIALS"]


@dataclass(frozen=True)
class Material:
    """E, G (Pa), density (kg/m^3), fy: yield or characteristic strength (Pa), partial factors
    gamma_M0 (cross-sections) and gamma_M1 (member buckling), kind, buckling_alpha: imperfection
    factor of the buckling curve used for members (EN 1993-1-1 table 6.1 style)."""

    name: str
    E: float
    G: float
    density: float
    fy: float
    gamma_M0: float = 1.0
    gamma_M1: float = 1.0
    kind: str = "steel"
    buckling_alpha: float = 0.21


MATERIALS: dict[str, Material] = {
    # EN 1993-1-1: E 210 GPa, G 81 GPa; hot-finished hollow sections on buckling curve a
    "steel_s235": Material("steel_s235", 210e9, 81e9, 7850.0, 235e6, 1.0, 1.0, "steel", 0.21),
    "steel_s355": Material("steel_s355", 210e9, 81e9, 7850.0, 355e6, 1.0, 1.0, "steel", 0.21),
    # EN 1999-1-1 table 3.2b, extruded tubes: f0 = 160 MPa (6063-T6), 240 MPa (6061-T6); gamma_M1 1.1;
    # buckling with the steel formula and curve c (alpha 0.49) as a simplification of EN 1999's class A curve
    "aluminium_6063": Material("aluminium_6063", 70e9, 27e9, 2700.0, 160e6, 1.1, 1.1, "aluminium", 0.49),
    "aluminium_6061": Material("aluminium_6061", 70e9, 27e9, 2700.0, 240e6, 1.1, 1.1, "aluminium", 0.49),
    # EN 14080 GL24h: E0,mean 11.5 GPa, G 0.65 GPa, mean density 420, fc,0,k = fm,k = 24 MPa;
    # gamma_M 1.25 with k_mod 0.8 folded in (1.25 / 0.8 = 1.5625)
    "glulam_gl24h": Material("glulam_gl24h", 11.5e9, 0.65e9, 420.0, 24e6, 1.5625, 1.5625, "timber", 0.49),
    # printed polymers (indicative, 100 % infill): tensile strength about 50 MPa; factor 2
    "pla": Material("pla", 3.5e9, 1.3e9, 1240.0, 50e6, 2.0, 2.0, "polymer", 0.49),
    "petg": Material("petg", 2.1e9, 0.78e9, 1270.0, 50e6, 2.0, 2.0, "polymer", 0.49),
}


def material(name: str) -> Material:
    """The named material; InputError listing the known ones otherwise."""
    try:
        return MATERIALS[name]
    except KeyError:
        raise InputError(f"unknown material {name!r}", hint=f"use one of {', '.join(sorted(MATERIALS))}") from None


@dataclass(frozen=True)
class Section:
    """Cross-section properties in m: A (m^2), Iy about local y (the section's height along local
    z, the surface normal), Iz, J (m^4), elastic and plastic moduli (m^3), outer height (along z)
    and width (along y)."""

    kind: str
    A: float
    Iy: float
    Iz: float
    J: float
    Wy_el: float
    Wz_el: float
    Wy_pl: float
    Wz_pl: float
    outer_height: float
    outer_width: float

    @property
    def radius_of_gyration_min(self) -> float:
        return float(np.sqrt(min(self.Iy, self.Iz) / self.A))


def _positive(key: str, value: float | None) -> float:
    """The dimension itself once it is given and positive; InputError otherwise."""
    if value is None or not value > 0:
        raise InputError(f"section: {key} must be positive, got {value}")
    return value


def section_from_spec(kind: str, *, diameter: float | None = None, thickness: float | None = None,
                      height: float | None = None, width: float | None = None) -> Section:
    """Properties of a circular_hollow (diameter, thickness), rectangular_hollow (height, width,
    thickness), solid_round (diameter) or solid_rectangle (height, width) section, in m."""
    pi = np.pi
    if kind == "circular_hollow":
        diameter, thickness = _positive("diameter", diameter), _positive("thickness", thickness)
        if 2 * thickness >= diameter:
            raise InputError(f"section: wall {thickness} m too thick for diameter {diameter} m")
        inner = diameter - 2 * thickness
        I = pi / 64 * (diameter**4 - inner**4)
        W_el, W_pl = 2 * I / diameter, (diameter**3 - inner**3) / 6
        return Section(kind, pi / 4 * (diameter**2 - inner**2), I, I, 2 * I, W_el, W_el, W_pl, W_pl, diameter, diameter)
    if kind == "rectangular_hollow":
        height, width = _positive("height", height), _positive("width", width)
        thickness = _positive("thickness", thickness)
        if 2 * thickness >= min(height, width):
            raise InputError("section: wall too thick for the rectangle")
        h, b, t = height, width, thickness
        hi, bi = h - 2 * t, b - 2 * t
        Iy, Iz = (b * h**3 - bi * hi**3) / 12, (h * b**3 - hi * bi**3) / 12
        mean_area = (h - t) * (b - t)
        J = 4 * mean_area**2 * t / (2 * ((h - t) + (b - t)))  # Bredt
        return Section(kind, h * b - hi * bi, Iy, Iz, J, 2 * Iy / h, 2 * Iz / b, (b * h**2 - bi * hi**2) / 4,
                       (h * b**2 - hi * bi**2) / 4, h, b)
    if kind == "solid_round":
        diameter = _positive("diameter", diameter)
        d = diameter
        I = pi * d**4 / 64
        return Section(kind, pi * d**2 / 4, I, I, 2 * I, pi * d**3 / 32, pi * d**3 / 32, d**3 / 6, d**3 / 6, d, d)
    if kind == "solid_rectangle":
        height, width = _positive("height", height), _positive("width", width)
        h, b = height, width
        long, short = max(h, b), min(h, b)
        J = long * short**3 * (1 / 3 - 0.21 * short / long * (1 - short**4 / (12 * long**4)))  # Roark
        return Section(kind, h * b, b * h**3 / 12, h * b**3 / 12, J, b * h**2 / 6, h * b**2 / 6, b * h**2 / 4,
                       h * b**2 / 4, h, b)
    raise InputError(f"unknown section kind {kind!r}",
                     hint="use circular_hollow, rectangular_hollow, solid_round or solid_rectangle")
