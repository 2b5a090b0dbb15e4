"""Sections against steel tables and member checks against hand calculations (EN 1993-1-1)."""

from __future__ import annotations

import numpy as np
import pytest

from engine.design.checks import buckling_reduction, member_checks
from engine.design.sections import material, section_from_spec
from engine.errors import InputError


def test_circular_hollow_section_matches_the_tables():
    """CHS 48.3 x 3.2 (EN 10210-2 tables): A = 4.53 cm^2, I = 11.6 cm^4, Wel = 4.80 cm^3, Wpl = 6.52 cm^3."""
    s = section_from_spec("circular_hollow", diameter=0.0483, thickness=0.0032)
    assert s.A == pytest.approx(4.53e-4, rel=0.005)
    assert s.Iy == pytest.approx(11.6e-8, rel=0.01) and s.Iz == s.Iy and s.J == pytest.approx(2 * s.Iy)
    assert s.Wy_el == pytest.approx(4.80e-6, rel=0.01)
    assert s.Wy_pl == pytest.approx(6.52e-6, rel=0.01)


def test_rectangular_sections():
    """RHS 100 x 50 x 4 with sharp corners: A = 100 x 50 - 92 x 42 = 1136 mm^2 (tables with rounded
    corners: 10.95 cm^2)."""
    s = section_from_spec("rectangular_hollow", height=0.1, width=0.05, thickness=0.004)
    assert s.A == pytest.approx(11.36e-4, rel=1e-9)
    assert s.Iy == pytest.approx(1.0 / 12 * (0.05 * 0.1**3 - 0.042 * 0.092**3))
    assert s.Iy > s.Iz
    solid = section_from_spec("solid_rectangle", height=0.2, width=0.1)
    assert solid.J == pytest.approx(0.2 * 0.1**3 * 0.229, rel=0.01)  # Roark: beta = 0.229 for a/b = 2


def test_euler_buckling_curve_values():
    """EN 1993-1-1 table values: chi(curve a, lambda 1.0) = 0.6656, chi(curve c, lambda 0.5) = 0.8430."""
    assert buckling_reduction(np.array([1.0]), 0.21)[0] == pytest.approx(0.6656, abs=5e-4)
    assert buckling_reduction(np.array([0.5]), 0.49)[0] == pytest.approx(0.8430, abs=5e-4)
    assert buckling_reduction(np.array([0.1]), 0.49)[0] == 1.0


def test_member_check_by_hand():
    """CHS 48.3 x 3.2 S355, L = 2 m, N = -30 kN, My = 0.5 kNm: hand calculation."""
    s, m = section_from_spec("circular_hollow", diameter=0.0483, thickness=0.0032), material("steel_s355")
    forces = np.zeros((1, 2, 6))
    forces[0, :, 0] = -30e3
    forces[0, 0, 4] = 0.5e3
    result = member_checks(forces, np.array([2.0]), s, m)
    slenderness = 2.0 / np.sqrt(s.Iy / s.A) / (np.pi * np.sqrt(210e9 / 355e6))
    phi = 0.5 * (1 + 0.21 * (slenderness - 0.2) + slenderness**2)
    chi = 1 / (phi + np.sqrt(phi**2 - slenderness**2))
    expected = 30e3 / (chi * s.A * 355e6) + 0.5e3 / (s.Wy_el * 355e6)
    assert result.slenderness[0] == pytest.approx(slenderness)
    assert result.utilisation[0] == pytest.approx(expected)
    assert result.governing[0] == "flexural buckling"
    forces[0, :, 0] = 30e3   # tension: no buckling
    tension = member_checks(forces, np.array([2.0]), s, m)
    assert tension.utilisation[0] == pytest.approx(30e3 / (s.A * 355e6) + 0.5e3 / (s.Wy_el * 355e6))
    assert tension.governing[0] == "cross-section"


def test_unknown_material_and_bad_sections_are_input_errors():
    with pytest.raises(InputError, match="steel_s355"):
        material("steel_s999")
    with pytest.raises(InputError):
        section_from_spec("circular_hollow", diameter=0.01, thickness=0.006)
