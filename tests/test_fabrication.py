"""Fabrication files of a whole small run, each re-read by a reader other than its writer."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytestmark = pytest.mark.slow


def _polymesh(out):
    from workflow.stages.polymesh_io import read_polymesh_obj

    return read_polymesh_obj(out / "05-optimize" / "gridshell.obj")


def test_joints_are_named_valid_watertight_solids(small_run):
    import trimesh
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.STEPControl import STEPControl_Reader

    _, out = small_run
    folder = out / "07-fabrication" / "joints"
    polymesh = _polymesh(out)
    connected = np.flatnonzero(polymesh.valence > 0)
    names = sorted(p.stem for p in folder.glob("J*.step"))
    assert names == [f"J{i + 1:04d}" for i in connected]
    summary = json.loads((out / "07-fabrication" / "fabrication.json").read_text())
    problems = {p["id"] for p in summary["joint_problems"]}
    for name in names[:6]:
        reader = STEPControl_Reader()
        assert reader.ReadFile(str(folder / f"{name}.step")) == IFSelect_RetDone
        reader.TransferRoots()
        shape = reader.OneShape()
        assert not shape.IsNull()
        text = (folder / f"{name}.step").read_text(errors="ignore")
        assert f"'{name}'" in text, "the solid carries the joint id as its product name"
        mesh = trimesh.load(folder / f"{name}.stl")
        assert mesh.is_watertight or name in problems, "a leaky STL is reported as a joint problem"
        assert mesh.volume > 0
    combined = (folder / "joints.step").read_text(errors="ignore")
    assert all(f"'{name}'" in combined for name in names)


def test_cut_list_matches_the_geometry_and_the_bars_fit(small_run):
    import pandas as pd

    _, out = small_run
    polymesh = _polymesh(out)
    beams = out / "07-fabrication" / "beams"
    table = pd.read_csv(beams / "cutlist.csv")
    assert len(table) == len(polymesh.edges)
    node_length = 1000 * polymesh.beam_lengths
    assert np.allclose(table["node_length_mm"], node_length, atol=0.06)
    assert np.allclose(table["cut_length_mm"] + table["setback_start_mm"] + table["setback_end_mm"],
                       table["node_length_mm"], atol=0.2)
    workbook = pd.read_excel(beams / "cutlist.xlsx", sheet_name=None)
    assert "summary" in workbook and len(workbook) >= 2
    profile_sheet = [v for k, v in workbook.items() if k != "summary"][0]
    assert profile_sheet.iloc[-1]["id"] == "TOTAL"
    assert profile_sheet.iloc[-1]["cut_length_mm"] == pytest.approx(table["cut_length_mm"].sum(), rel=1e-6)
    bars = pd.read_csv(beams / "bars.csv")
    pieces = " ".join(bars["pieces"]).split()
    assert sorted(pieces) == sorted(table["id"]), "every beam is cut exactly once"
    stock, kerf = 2000.0, 2.0
    for lengths in bars["lengths_mm"]:
        values = [float(x) for x in str(lengths).split()]
        assert sum(values) + kerf * len(values) <= stock + 1e-6
    lower_bound = int(np.ceil((table["cut_length_mm"].sum() + kerf * len(table)) / stock))
    assert len(bars) >= lower_bound


def test_panel_dxfs_reread_with_ezdxf(small_run):
    import ezdxf
    from shapely.geometry import Polygon

    _, out = small_run
    folder = out / "07-fabrication" / "panels"
    files = sorted(folder.glob("P*.dxf"))
    assert files
    for path in files[:8]:
        doc = ezdxf.readfile(path)
        auditor = doc.audit()
        assert not auditor.has_errors
        assert doc.header["$INSUNITS"] == 4
        cut = [e for e in doc.modelspace() if e.dxf.layer == "CUT" and e.dxftype() == "LWPOLYLINE"]
        assert len(cut) == 1 and cut[0].closed
        labels = [e for e in doc.modelspace() if e.dxf.layer == "ENGRAVE"]
        assert labels
        area = Polygon([p[:2] for p in cut[0].get_points()]).area
        assert area > 0


def test_sheets_hold_every_panel_without_overlap(small_run):
    import ezdxf
    from shapely.geometry import Polygon

    _, out = small_run
    folder = out / "07-fabrication" / "panels"
    panel_count = len(list(folder.glob("P*.dxf")))
    seen = 0
    for sheet in sorted((folder / "sheets").glob("S*.dxf")):
        doc = ezdxf.readfile(sheet)
        assert not doc.audit().has_errors
        parts = [Polygon([p[:2] for p in e.get_points()]) for e in doc.modelspace()
                 if e.dxf.layer == "CUT" and e.dxftype() == "LWPOLYLINE"]
        seen += len(parts)
        for i in range(len(parts)):
            for j in range(i + 1, len(parts)):
                assert parts[i].intersection(parts[j]).area < 1e-6
    assert seen == panel_count


def test_plan_drawings_and_whole_model(small_run):
    import ezdxf
    import rhino3dm

    _, out = small_run
    folder = out / "07-fabrication"
    doc = ezdxf.readfile(folder / "drawings" / "plan.dxf")
    assert not doc.audit().has_errors
    texts = {e.dxf.text for e in doc.modelspace().query("TEXT")}
    assert "N0001" in texts and "B0001" in texts
    assert (folder / "drawings" / "plan.pdf").read_bytes()[:4] == b"%PDF"
    model = rhino3dm.File3dm.Read(str(folder / "gridshell.3dm"))
    layers = {model.Layers[i].Name for i in range(len(model.Layers))}
    assert {"joints", "beams", "panels"} <= layers
    polymesh = _polymesh(out)
    assert len(model.Objects) >= polymesh.n_nodes + len(polymesh.edges)
    step = (folder / "gridshell.step").read_text(errors="ignore")
    assert "'J0001'" in step and "'B0001'" in step


def test_assembly_places_every_beam_once(small_run):
    import pandas as pd

    _, out = small_run
    polymesh = _polymesh(out)
    sequence = pd.read_csv(out / "07-fabrication" / "assembly" / "sequence.csv")
    parts = " ".join(sequence["parts"].fillna("")).split()
    beams = [p for p in parts if p.startswith("B")]
    assert sorted(beams) == sorted(f"B{k + 1:04d}" for k in range(len(polymesh.edges)))
    assert len(set(beams)) == len(beams)
