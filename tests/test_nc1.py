"""DSTV NC1 files re-read by a parser written here from the format's description (blocks of
two-letter names, one value per line in the ST block), not by the writer's code."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

#: the ST block's fields in order (DSTV NC1: order, drawing, phase, piece, grade, quantity, profile,
#: code, length, saw length, height, width, flange and web thickness, radius, kg/m, paint m2/m,
#: web and flange start and end cuts, four text lines)
ST_FIELDS = ["order", "drawing", "phase", "piece", "grade", "quantity", "profile", "code", "length", "saw_length",
             "height", "width", "flange_thickness", "web_thickness", "radius", "kg_per_m", "paint_m2_per_m",
             "web_start_cut", "web_end_cut", "flange_start_cut", "flange_end_cut", "text1", "text2", "text3",
             "text4"]


def parse_nc1(text: str) -> dict:
    """{"ST": {field: value}, "SI": [lines], "BO": [(face, x, y, diameter)], "EN": True}."""
    blocks: dict[str, list[str]] = {}
    current = None
    for line in text.splitlines():
        if line.startswith("**") or not line.strip():
            continue
        if not line.startswith(" "):
            current = line.strip()
            assert len(current) == 2 and current.isalpha() and current.isupper(), line
            blocks[current] = []
            continue
        blocks[current].append(line.strip())
    assert list(blocks)[0] == "ST" and list(blocks)[-1] == "EN"
    st = dict(zip(ST_FIELDS, blocks["ST"], strict=True))
    holes = []
    for line in blocks.get("BO", []):
        face, x, y, d, *_ = line.split()
        holes.append((face, float(x.rstrip("uso")), float(y), float(d)))
    return {"ST": st, "SI": blocks.get("SI", []), "BO": holes, "EN": "EN" in blocks}


def test_every_beam_has_an_nc1_file_that_agrees_with_the_cut_list(small_run):
    project, out = small_run
    folder = out / "07-fabrication" / "beams"
    cut = pd.read_csv(folder / "cutlist.csv")
    cut = cut[cut["cut_length_mm"] > 0]
    files = sorted((folder / "nc1").glob("*.nc1"))
    assert [f.stem for f in files] == sorted(cut["id"])
    fabrication = json.loads((out / "07-fabrication" / "fabrication.json").read_text())
    assert fabrication["nc1_files"] == len(files)
    D, t = 1000 * project.section.diameter, 1000 * project.section.thickness
    for row in cut.itertuples():
        nc1 = parse_nc1((folder / "nc1" / f"{row.id}.nc1").read_text())
        st = nc1["ST"]
        assert st["piece"] == row.id and st["code"] == "RO" and st["profile"] == row.profile
        assert float(st["length"]) == pytest.approx(row.cut_length_mm, abs=0.01)
        assert float(st["height"]) == pytest.approx(D) and float(st["web_thickness"]) == pytest.approx(t)
        assert float(st["paint_m2_per_m"]) == pytest.approx(np.pi * D / 1000, rel=1e-3)
        mass = float(st["kg_per_m"]) * row.cut_length_mm / 1000
        assert mass == pytest.approx(row.mass_kg, rel=2e-3, abs=2e-4)
        assert any(row.id in line for line in nc1["SI"])
        # a pin hole near each end, inside the piece, symmetric
        xs = sorted(x for _, x, _, _ in nc1["BO"])
        assert len(xs) == 2 and 0 < xs[0] < xs[1] < row.cut_length_mm
        assert xs[0] == pytest.approx(row.cut_length_mm - xs[1], abs=0.02)


def test_steel_joints_put_a_bolt_hole_where_the_fin_plate_reaches():
    """Steel hub joints: the fin plate goes one diameter into the slotted tube, its bolt at half of
    that; the NC1 has the bolt holes of the joint's bolt diameter, and the grade of the material."""
    from fabrication.joints import JointSettings
    from fabrication.nc1 import nc1_pieces, nc1_text

    table = pd.DataFrame({"id": ["B0001", "B0002"], "profile": ["CHS 114.3x6.3"] * 2, "cut_length_mm": [2000.0, 0.0],
                          "end_angle_start_deg": [0.0, 0.0], "end_angle_end_deg": [0.0, 0.0]})
    settings = JointSettings(kind="steel", bolt_hole_mm=18.0)
    pieces = nc1_pieces(table, np.array([114.3, 114.3]), np.array([6.3, 6.3]), np.array([16.8, 16.8]), settings,
                        "steel_s355")
    assert len(pieces) == 1  # a beam of no cut length has no file (its finding says why)
    nc1 = parse_nc1(nc1_text(pieces[0], order="job", drawing="plan"))
    assert nc1["ST"]["grade"] == "S355"
    assert [(x, d) for _, x, _, d in nc1["BO"]] == [(pytest.approx(57.15), 18.0), (pytest.approx(2000 - 57.15), 18.0)]


def test_a_rectangular_hollow_section_is_an_m_profile_of_its_height_and_width():
    """An RHS 200 x 100 x 8 beam: code M, height and width as given, the wall as flange and web,
    the paint area its perimeter, the bolt holes across the web at half its height."""
    from fabrication.joints import JointSettings
    from fabrication.nc1 import nc1_pieces, nc1_text

    table = pd.DataFrame({"id": ["B0001"], "profile": ["RHS 200x100x8"], "cut_length_mm": [3000.0],
                          "end_angle_start_deg": [0.0], "end_angle_end_deg": [0.0]})
    pieces = nc1_pieces(table, np.array([200.0]), np.array([8.0]), np.array([35.8]), JointSettings(kind="steel"),
                        "steel_s355", widths_mm=np.array([100.0]))
    nc1 = parse_nc1(nc1_text(pieces[0], order="job", drawing="plan"))
    st = nc1["ST"]
    assert (st["code"], float(st["height"]), float(st["width"])) == ("M", 200.0, 100.0)
    assert float(st["flange_thickness"]) == float(st["web_thickness"]) == 8.0
    assert float(st["paint_m2_per_m"]) == pytest.approx(0.6)
    # the fin plate reaches one size (the larger side) into the section, its bolt at half of that
    assert [(x, y) for _, x, y, _ in nc1["BO"]] == [(100.0, 100.0), (2900.0, 100.0)]
