"""Materials and cross-section properties against closed forms and published tables."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from engine.design.sections import MATERIALS, material, section_from_spec
from engine.errors import InputError

KNOWN = ["steel_s235", "steel_s355", "aluminium_6063", "aluminium_6061", "glulam_gl24h", "pla", "petg"]


@pytest.mark.parametrize("name", KNOWN)
def test_every_material_is_known_and_physically_plausible(name):
    m = material(name)
    assert m.name == name and m.kind in ("steel", "aluminium", "timber", "polymer")
    assert 0 < m.fy < m.E and 0 < m.G < m.E and m.gamma_M0 >= 1.0 and m.gamma_M1 >= 1.0
    if m.kind in ("steel", "aluminium"):
        # isotropic metals: G = E / (2 (1 + nu)) with nu 0.29..0.33
        assert 0.28 < m.E / (2 * m.G) - 1 < 0.34


def test_values_quoted_from_the_standards():
    """EN 1993-1-1 3.2.6: E = 210 GPa; EN 10025-2: fy 235 / 355 MPa; EN 1999-1-1: E = 70 GPa;
    EN 14080 GL24h: E0,mean = 11 500 MPa, f_m,k = 24 MPa."""
    assert material("steel_s355").fy == 355e6 and material("steel_s235").fy == 235e6
    assert material("steel_s235").E == 210e9 and material("aluminium_6063").E == 70e9
    assert material("glulam_gl24h").E == 11.5e9 and material("glulam_gl24h").fy == 24e6
    assert set(KNOWN) <= set(MATERIALS)


def test_material_values_can_be_overridden_with_replace():
    steel = material("steel_s355")
    softer = dataclasses.replace(steel, E=200e9, fy=300e6)
    assert softer.E == 200e9 and softer.fy == 300e6 and softer.G == steel.G and steel.E == 210e9


def test_unknown_material_lists_the_known_ones():
    with pytest.raises(InputError) as error:
        material("unobtainium")
    assert "glulam_gl24h" in error.value.hint


def test_solid_round_closed_forms():
    d = 0.05
    s = section_from_spec("solid_round", diameter=d)
    assert s.A == pytest.approx(np.pi * d**2 / 4)
    assert s.Iy == pytest.approx(np.pi * d**4 / 64) and s.J == pytest.approx(np.pi * d**4 / 32)
    assert s.Wy_pl / s.Wy_el == pytest.approx(16 / (3 * np.pi))   # shape factor of a solid circle
    assert s.radius_of_gyration_min == pytest.approx(d / 4)


def test_thin_circular_tube_tends_to_the_thin_wall_formulas():
    """Thin wall: A -> pi D t, I -> pi D^3 t / 8 (with the mean diameter)."""
    D, t = 0.5, 0.0005
    s = section_from_spec("circular_hollow", diameter=D, thickness=t)
    assert s.A == pytest.approx(np.pi * (D - t) * t, rel=1e-6)
    assert s.Iy == pytest.approx(np.pi * (D - t) ** 3 * t / 8, rel=1e-5)
    assert s.Wy_pl / s.Wy_el == pytest.approx(4 / np.pi, rel=0.01)   # thin tube shape factor


def test_square_hollow_section_torsion_is_bredt():
    """SHS 100 x 100 x 5 (sharp corners): J = 4 A_m^2 t / perimeter = (b - t)^3 t = 95^3 x 5 mm^4."""
    s = section_from_spec("rectangular_hollow", height=0.1, width=0.1, thickness=0.005)
    assert s.J == pytest.approx(0.095**3 * 0.005)
    assert s.Iy == pytest.approx(s.Iz) and s.outer_height == 0.1


def test_solid_square_torsion_matches_saint_venant():
    """Square bar: J = 0.1406 a^4 (Saint-Venant series, Roark table 10.7 case 4)."""
    s = section_from_spec("solid_rectangle", height=0.04, width=0.04)
    assert s.J == pytest.approx(0.1406 * 0.04**4, rel=0.005)


@pytest.mark.parametrize("kind, dims", [
    ("circular_hollow", {"diameter": 0.05}),
    ("circular_hollow", {"diameter": 0.05, "thickness": -0.001}),
    ("rectangular_hollow", {"height": 0.1, "width": 0.02, "thickness": 0.01}),
    ("solid_rectangle", {"height": 0.1}),
    ("i_beam", {"height": 0.1}),
])
def test_bad_dimensions_are_input_errors(kind, dims):
    with pytest.raises(InputError):
        section_from_spec(kind, **dims)
