"""What the study says of each roof (``benchmarks/study.py``, ``roof_descriptors``): checked on
surfaces whose curvature and proportions are known in closed form, with shell results made up so
that their shares are known by construction."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))


def _roof(folder: Path, height, forces_of) -> None:
    """A 10 m x 6 m grid of triangles z = height(x, y) with the stages' files where the study reads
    them (its spacing sweep's first point); ``forces_of(centroids)``: principal forces (m, 2)."""
    import trimesh

    xs, ys = np.linspace(-5, 5, 21), np.linspace(-3, 3, 13)
    x, y = np.meshgrid(xs, ys, indexing="ij")
    vertices = np.column_stack([x.ravel(), y.ravel(), height(x.ravel(), y.ravel())])
    index = np.arange(len(vertices)).reshape(len(xs), len(ys))
    a, b, c, d = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    faces = np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    point = folder / "spacing" / "voronoi" / "out" / "points" / "0001"
    for stage in ("01-surface", "02-shell", "03-field"):
        (point / stage).mkdir(parents=True)
    trimesh.Trimesh(vertices, faces, process=False).export(point / "01-surface" / "surface.ply")
    edge = np.flatnonzero(np.isclose(np.abs(vertices[:, 0]), 5.0))           # the two short sides
    supports = {str(i): [1, 1, 1, 0, 0, 0] for i in edge}
    (point / "01-surface" / "supports.json").write_text(json.dumps({"supports": supports}))
    centroids = vertices[faces].mean(axis=1)
    forces = forces_of(centroids)
    membrane = np.column_stack([forces, np.zeros(len(faces))])
    np.savez(point / "02-shell" / "shell.npz", face_principal_forces=forces, face_membrane_forces=membrane,
             face_moments=0.05 * membrane)                                  # |M| / |N| = 50 mm everywhere
    (point / "03-field" / "field.json").write_text(json.dumps({"mean_aspect": 1.5}))


def test_a_hypar_is_anticlastic_and_a_dome_synclastic_with_their_rise_span_and_forces(tmp_path):
    from study import roof_descriptors

    def mixed_left(c):                    # x < 0: tension and compression; x > 0: both compressive
        return np.where((c[:, 0] < 0)[:, None], [[2.0, -3.0]], [[-1.0, -4.0]])

    _roof(tmp_path / "hypar", lambda x, y: 0.04 * x * y, mixed_left)
    _roof(tmp_path / "dome", lambda x, y: 2.5 * (1 - (x / 5) ** 2 / 2 - (y / 3) ** 2 / 2), mixed_left)
    hypar, dome = roof_descriptors(tmp_path / "hypar"), roof_descriptors(tmp_path / "dome")
    assert hypar["anticlastic_share"] == pytest.approx(1.0)          # K = -c^2 / (1 + ...)^2 < 0
    assert dome["anticlastic_share"] == pytest.approx(0.0)
    assert hypar["span_m"] == pytest.approx(10.0)
    assert hypar["rise_to_span"] == pytest.approx(0.04 * 2 * 5 * 3 / 10)   # z from -0.6 to 0.6
    assert dome["rise_to_span"] == pytest.approx(2.5 / 10)          # an elliptic paraboloid, 0 at the corners
    assert hypar["supported_share"] == pytest.approx(2 * 13 / (2 * 21 + 2 * 11))
    assert hypar["mixed_share"] == pytest.approx(0.5) and hypar["biaxial_compression_share"] == pytest.approx(0.5)
    assert hypar["eccentricity_mm"] == pytest.approx(50.0)
    assert hypar["field_mean_aspect"] == 1.5
    assert roof_descriptors(tmp_path / "none") is None


def test_the_roof_table_sets_the_default_design_against_the_quad_grid_and_the_control(tmp_path):
    from study import roof_table

    lines = [{"question": "spacing", "surface": "cap", "L_tot_m": n, "design": d, "lambda_NL_worst": v, "ok": ok,
              "at_limit": limit}
             for n, d, v, ok, limit in ((100, "Voro(2,2)", 1.2, 3, 1), (100, "quad 0", 1.0, 1, 1),
                                        (100, "isotropic CVT", 0.8, 3, 0), (200, "Voro(2,2)", 1.5, 3, 3),
                                        (200, "quad 0", 3.0, 1, 0), (200, "isotropic CVT", None, 0, 0))]
    text, rows = roof_table(lines, tmp_path)
    assert rows[0]["voronoi_over_quad"] == pytest.approx([1.2, 0.5])
    assert rows[0]["voronoi_over_control"][0] == pytest.approx(1.5) and rows[0]["voronoi_over_control"][1] is None
    assert "| cap | - |" in text and "1.20, 0.50" in text and "| 4/6, 1/2 |" in text


def test_the_verdicts_count_apart_the_pairs_that_both_reached_a_limit_point():
    """A pair counts as buckling only where every run of both designs reached a limit point; the
    others' load factors are loads at the tolerable deflection."""
    from study import verdicts

    def line(length, design, value, at_limit):
        return {"surface": "cap", "L_tot_m": length, "design": design, "lambda_NL_worst": value, "ok": 3,
                "at_limit": at_limit, "delta_L_mm": 10.0, "L_tot_median_m": length,
                "lambda_LB": 2.0 if design == "quad 0" else 3.0}

    lines = [line(100, "Voro(2,2)", 1.2, 3), line(100, "quad 0", 1.0, 3),      # both buckle: Voronoi higher
             line(200, "Voro(2,2)", 0.5, 2), line(200, "quad 0", 1.0, 3),      # one Voronoi run stopped at span/50
             line(300, "Voro(2,2)", 0.9, 3), line(300, "quad 0", 1.0, 3)]      # both buckle: quad higher
    row = next(r for r in verdicts(lines).splitlines() if r.startswith("| Voro(2,2) | quad 0 |"))
    assert "| 1 of 3 | 0.90 | 0.50-1.20 | 1.50 | 1.00 |" in row and row.endswith("| 1 of 2 (median 1.05) |")


def _reference(folder: Path, deflection_m: float, limit_m: float) -> Path:
    """A study run's spacing sweep at the cap's section: Voro(2,2) at three lengths."""
    out = folder / "spacing" / "voronoi" / "out"
    rows = []
    for k, (length, grid) in enumerate([(100.0, "voronoi"), (200.0, "voronoi"), (200.0, "isotropic"),
                                        (300.0, "voronoi")]):
        point = out / "points" / f"{k + 1:04d}" / "06-analysis"
        point.mkdir(parents=True)
        (point / "analysis.json").write_text(json.dumps({"deflection_limit_m": limit_m}))
        rows.append(f"{length},{grid},ok,{deflection_m if length == 200.0 else 99.0},points/{k + 1:04d}")
    (out / "sweep.csv").write_text("remesh.total_length,remesh.grid,status,delta_L_m,folder\n" + "\n".join(rows))
    return folder


def test_a_roof_too_soft_at_the_caps_section_takes_the_lightest_tube_stiff_enough(tmp_path):
    """The second moment of area goes as delta_0 / limit, from the tube formula, not the table's."""
    import pandas as pd
    from study import ROOT, stiff_section

    catalogue = pd.read_csv(ROOT / "engine" / "data" / "en10210_chs.csv", comment="#")
    D, t = catalogue["diameter_mm"], catalogue["thickness_mm"]
    inertia = np.pi * (D**4 - (D - 2 * t) ** 4) / 64                         # mm^4
    cap = float(np.pi * (114.3**4 - (114.3 - 12.6) ** 4) / 64)
    name, diameter, wall, over = stiff_section(_reference(tmp_path / "soft", 0.9, 0.09))
    assert over == pytest.approx(10.0)
    lightest = catalogue[inertia >= 10 * cap].sort_values("mass_kg_per_m").iloc[0]
    assert (diameter, wall) == (lightest["diameter_mm"], lightest["thickness_mm"])
    assert np.pi * (diameter**4 - (diameter - 2 * wall) ** 4) / 64 >= 10 * cap * (1 - 1e-3)
    assert stiff_section(_reference(tmp_path / "stiff", 0.05, 0.09))[:3] == ("CHS 114.3x6.3", 114.3, 6.3)
    assert stiff_section(tmp_path / "none") is None


def test_a_pair_that_both_carried_the_largest_load_factor_has_no_verdict():
    """Paths that carry the protocol's largest load factor stop there: two such designs tie by
    construction, not by strength, and one of them against a weaker design still counts."""
    from study import CEILING, verdicts

    from engine.structure.protocol import ProtocolSettings

    assert CEILING == ProtocolSettings().max_load_factor

    def line(length, design, value):
        return {"surface": "shell", "L_tot_m": length, "design": design, "lambda_NL_worst": value, "ok": 1,
                "at_limit": 0, "delta_L_mm": 1.0, "L_tot_median_m": length, "lambda_LB": 20.0}

    lines = [line(100, "Voro(2,2)", 5.0), line(100, "quad 0", CEILING),
             line(200, "Voro(2,2)", CEILING), line(200, "quad 0", CEILING)]
    row = next(r for r in verdicts(lines).splitlines() if r.startswith("| Voro(2,2) | quad 0 |"))
    assert "| 0 of 1 | 0.50 |" in row
