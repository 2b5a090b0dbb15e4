"""Tube catalogues and EN 1993-1-1 member checks of circular hollow sections, against published
tables, a published worked example and hand calculations that follow the clauses."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from engine.design.catalogue import CATALOGUES, DATA, catalogue
from engine.design.en1993 import EndForces, buckling_alpha, chs_checks, section_class, simplified_checks
from engine.design.sections import material
from engine.errors import InputError

S355 = material("steel_s355")


def _forces(N=0.0, My=(0.0, 0.0), Mz=(0.0, 0.0), Vz=0.0, T=0.0) -> EndForces:
    f = np.zeros((1, 2, 6))
    f[0, :, 0] = N
    f[0, :, 2] = Vz
    f[0, :, 3] = T
    f[0, :, 4] = My
    f[0, :, 5] = Mz
    return EndForces.of(f)


def _check(D, t, forces, L=1.0, alpha=0.21):
    return chs_checks(forces, np.array([D]), np.array([t]), S355, alpha=alpha, buckling_length=np.array([L]))


@pytest.mark.parametrize("name,D,t,A_cm2,I_cm4,W_el,W_pl,i_cm,kg_m", [
    # SCI P363 (the Blue Book), hot-finished CHS to EN 10210-2
    ("CHS 48.3x3.2", 48.3, 3.2, 4.53, 11.6, 4.80, 6.52, 1.60, 3.56),
    ("CHS 114.3x6.3", 114.3, 6.3, 21.4, 313, 54.7, 73.6, 3.82, 16.8),
    ("CHS 168.3x8", 168.3, 8.0, 40.3, 1300, 154, 206, 5.67, 31.6),
])
def test_the_hot_finished_catalogue_matches_the_published_tables(name, D, t, A_cm2, I_cm4, W_el, W_pl, i_cm, kg_m):
    cat = catalogue("EN 10210-2 CHS")
    k = cat.index(D / 1000, t / 1000)
    assert k is not None and cat.names[k] == name
    assert cat.A[k] * 1e4 == pytest.approx(A_cm2, rel=0.005)
    assert cat.I[k] * 1e8 == pytest.approx(I_cm4, rel=0.005)
    assert cat.W_el[k] * 1e6 == pytest.approx(W_el, rel=0.005)
    assert cat.W_pl[k] * 1e6 == pytest.approx(W_pl, rel=0.005)
    assert cat.i[k] * 100 == pytest.approx(i_cm, rel=0.005)
    assert cat.mass_per_length(7850.0)[k] == pytest.approx(kg_m, rel=0.005)


@pytest.mark.parametrize("name", sorted(CATALOGUES))
def test_every_catalogue_row_states_the_properties_of_its_dimensions(name):
    """The files' own columns (what a reader sees) agree with the tubes' closed forms, the source is
    named, and the tubes come sorted from light to heavy."""
    file, _ = CATALOGUES[name]
    text = (DATA / file).read_text()
    assert text.startswith("# EN ")
    rows = list(csv.DictReader(line for line in text.splitlines() if not line.startswith("#")))
    assert len(rows) >= 15
    for row in rows:
        D, t = float(row["diameter_mm"]), float(row["thickness_mm"])
        d = D - 2 * t
        assert float(row["area_cm2"]) == pytest.approx(math.pi * t * (D - t) / 100, rel=1e-3)
        assert float(row["I_cm4"]) == pytest.approx(math.pi * (D**4 - d**4) / 64 / 1e4, rel=1e-3)
        assert float(row["W_pl_cm3"]) == pytest.approx((D**3 - d**3) / 6 / 1e3, rel=1e-3)
    cat = catalogue(name)
    assert len(cat) == len(rows) and np.all(np.diff(cat.A) >= 0)


def test_a_project_catalogue_file_and_its_errors(tmp_path):
    own = tmp_path / "tubes.csv"
    own.write_text("# our stock\ndiameter_mm,thickness_mm\n60.3,4\n48.3,3.2\n")
    cat = catalogue("tubes.csv", base_dir=tmp_path)
    assert cat.names == ["CHS 48.3x3.2", "CHS 60.3x4"] and cat.process is None
    bad = tmp_path / "bad.csv"
    bad.write_text("diameter_mm,thickness_mm\n40,25\n")
    with pytest.raises(InputError, match="2 x thickness < diameter"):
        catalogue(bad)
    with pytest.raises(InputError, match="neither a shipped catalogue nor a file"):
        catalogue(tmp_path / "missing.csv")


def test_published_worked_example_chs_76x2_s355():
    """ecalcubox.com, 'CHS Capacity Check to EN1993-1-1': CHS 76 x 2, S355, L_e = 10 m:
    d/t = 38, class 2; N_c,Rd = 165.06 kN; V_pl,Rd = 60.67 kN; M_c,Rd = 3.89 kN m; N_cr = 6.60 kN;
    lambda-bar = 5.00; chi = 0.038 (curve a); N_b,Rd = 6.34 kN."""
    D, t, L = 0.076, 0.002, 10.0
    assert section_class(np.array(D), np.array(t), 355e6) == 2
    assert 1 / _check(D, t, _forces(N=1.0), L=0.01).cross_section[0] / 1e3 == pytest.approx(165.06, abs=0.01)
    assert 1 / _check(D, t, _forces(Vz=1.0)).shear[0] / 1e3 == pytest.approx(60.67, abs=0.01)
    assert 1 / _check(D, t, _forces(My=(1.0, 1.0))).cross_section[0] / 1e3 == pytest.approx(3.89, abs=0.005)
    compression = _check(D, t, _forces(N=-1.0), L=L)
    assert compression.slenderness[0] == pytest.approx(5.00, abs=0.005)
    assert compression.chi[0] == pytest.approx(0.038, abs=0.0005)
    assert 1 / compression.buckling[0] / 1e3 == pytest.approx(6.34, abs=0.005)
    assert compression.governing == ["buckling N+M (6.3.3)"]


def test_section_class_limits_of_table_5_2():
    """d/t limits 50, 70, 90 eps^2 with eps^2 = 235 / fy: for S355 33.1, 46.3 and 59.6."""
    eps2 = 235 / 355
    t = 0.004
    for limit, cls in ((50, 1), (70, 2), (90, 3)):
        assert section_class(np.array(limit * eps2 * t * 0.999), np.array(t), 355e6) == cls
        assert section_class(np.array(limit * eps2 * t * 1.001), np.array(t), 355e6) == cls + 1
    slender = _check(0.2, 0.0025, _forces(N=-1.0))
    assert slender.section_class[0] == 4 and slender.utilisation[0] > 1.0
    assert slender.governing == ["section class 4 (not covered)"]


def test_axial_force_and_bending_by_hand_6_2_9():
    """Class 1 CHS 114.3 x 6.3 in S355: n = N / N_pl,Rd, m = M / M_pl,Rd with the resultant of My and
    Mz; the utilisation u puts (N, M) / u on M_N,Rd = M_pl,Rd (1 - n^1.7)."""
    D, t = 0.1143, 0.0063
    A = math.pi * t * (D - t)
    W_pl = (D**3 - (D - 2 * t) ** 3) / 6
    N, My, Mz = 300e3, 12e3, 9e3
    u = _check(D, t, _forces(N=N, My=(My, My), Mz=(Mz, Mz))).cross_section[0]
    n, m = N / (A * 355e6) / u, math.hypot(My, Mz) / (W_pl * 355e6) / u
    assert m == pytest.approx(1 - n**1.7, abs=1e-9)
    assert 0.5 < u < 1.0


def test_shear_reduces_the_bending_resistance_6_2_8():
    """V = 0.75 V_pl,Rd: rho = (2 x 0.75 - 1)^2 = 0.25, so M_pl,Rd falls to 0.75 of itself. The
    check passes exactly where M <= 0.75 M_pl,Rd, and at its utilisation u the forces / u lie on the
    clause's boundary."""
    D, t = 0.1143, 0.0063
    A = math.pi * t * (D - t)
    V_pl = 2 * A / math.pi * 355e6 / math.sqrt(3)
    M_pl = (D**3 - (D - 2 * t) ** 3) / 6 * 355e6
    for M, passes in ((0.74 * M_pl, True), (0.76 * M_pl, False)):
        checks = _check(D, t, _forces(Vz=0.75 * V_pl, My=(M, M)))
        assert checks.shear[0] == pytest.approx(0.75)
        assert (checks.cross_section[0] <= 1.0) == passes
        u = checks.cross_section[0]
        s = 0.75 / u
        rho = (2 * s - 1) ** 2 if s > 0.5 else 0.0
        assert M / u == pytest.approx((1 - rho) * M_pl, rel=1e-9)
    assert _check(D, t, _forces(Vz=1.2 * V_pl)).shear[0] == pytest.approx(1.2)  # fails in shear, finitely


def test_torsion_by_bredt_6_2_7():
    """Thin-walled tube: tau = T / (2 A_m t) with A_m = pi r_m^2 against fy / sqrt(3)."""
    D, t, T = 0.1143, 0.0063, 5e3
    r_m = (D - t) / 2
    tau = T / (2 * math.pi * r_m**2 * t)
    assert _check(D, t, _forces(T=T)).torsion[0] == pytest.approx(tau / (355e6 / math.sqrt(3)))
    # with a shear force: V <= V_pl,T,Rd = (1 - tau / tau_Rd) V_pl,Rd (6.2.7(9))
    V_pl = 2 * math.pi * t * (D - t) / math.pi * 355e6 / math.sqrt(3)
    both = _check(D, t, _forces(T=T, Vz=0.5 * V_pl))
    assert both.shear[0] == pytest.approx(0.5 + tau / (355e6 / math.sqrt(3)))


def test_compression_and_bending_by_hand_annex_b():
    """CHS 114.3 x 6.3 S355, L = 3 m, N = -250 kN, My = 6 kN m at one end and -3 kN m at the other
    (double curvature, psi = -0.5, C_my = 0.6 + 0.4 psi = 0.4), curve a. Class 1 (d/t = 18.1 < 33.1).
    Annex B Table B.1 (hollow sections): k_yy = C_my (1 + (lambda - 0.2) n) <= C_my (1 + 0.8 n),
    k_zy = 0.6 k_yy; equation 6.61 governs: n + k_yy My / (W_pl fy)."""
    D, t, L, N, M1, M2 = 0.1143, 0.0063, 3.0, 250e3, 6e3, -3e3
    A = math.pi * t * (D - t)
    I = math.pi * (D**4 - (D - 2 * t) ** 4) / 64
    W_pl = (D**3 - (D - 2 * t) ** 3) / 6
    lam = math.sqrt(A * 355e6 / (math.pi**2 * 210e9 * I / L**2))
    phi = 0.5 * (1 + 0.21 * (lam - 0.2) + lam**2)
    chi = 1 / (phi + math.sqrt(phi**2 - lam**2))
    n = N / (chi * A * 355e6)
    k_yy = 0.4 * (1 + min(lam - 0.2, 0.8) * n)
    expected = n + k_yy * abs(M1) / (W_pl * 355e6)
    checks = _check(D, t, _forces(N=-N, My=(M1, M2)), L=L)
    assert checks.section_class[0] == 1
    assert checks.slenderness[0] == pytest.approx(lam)
    assert checks.buckling[0] == pytest.approx(expected)
    # a uniform moment (single curvature, C_my = 1) is the worse case
    uniform = _check(D, t, _forces(N=-N, My=(M1, M1)), L=L)
    assert uniform.buckling[0] == pytest.approx(n + (1 + min(lam - 0.2, 0.8) * n) * M1 / (W_pl * 355e6))


def test_buckling_curves_of_table_6_2():
    assert buckling_alpha("hot-finished", S355) == 0.21
    assert buckling_alpha("cold-formed", S355) == 0.49
    assert buckling_alpha("extruded", material("aluminium_6063")) == material("aluminium_6063").buckling_alpha


def test_candidates_broadcast_like_single_checks():
    """A (b,1) column of forces against (1,s) tubes gives, per cell, what the single check gives."""
    cat = catalogue("EN 10210-2 CHS")
    rng = np.random.default_rng(3)
    f = rng.normal(scale=[20e3, 1e3, 1e3, 100, 2e3, 2e3], size=(5, 2, 6))
    L = rng.uniform(0.5, 3.0, 5)
    forces = EndForces.of(f)
    matrix = chs_checks(forces.column(), cat.diameter[None, :], cat.thickness[None, :], S355, alpha=0.21,
                        buckling_length=L[:, None]).utilisation
    for k in (0, 17, len(cat) - 1):
        single = chs_checks(forces, np.full(5, cat.diameter[k]), np.full(5, cat.thickness[k]), S355, alpha=0.21,
                            buckling_length=L).utilisation
        assert np.allclose(matrix[:, k], single)
    simple = simplified_checks(forces, cat.A[3], cat.I[3], cat.W_el[3], S355, alpha=0.21, buckling_length=L)
    assert simple.utilisation.shape == (5,)
