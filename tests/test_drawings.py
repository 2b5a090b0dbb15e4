"""Plan drawings: DXF re-read with ezdxf (audit, layers, ids, dimensions), PDF is a PDF."""

from __future__ import annotations

import numpy as np
import pytest

from engine.errors import InputError
from fabrication.drawings import beam_id, joint_id, node_id, panel_id, write_plan_drawings
from tests.test_panels import hex_polymesh

ezdxf = pytest.importorskip("ezdxf")


def test_ids():
    assert (node_id(0), beam_id(9), panel_id(99), joint_id(1233)) == ("N0001", "B0010", "P0100", "J1234")


def test_plan_dxf_and_pdf(tmp_path):
    mesh = hex_polymesh(3, 4)
    supports = np.flatnonzero(mesh.supports)
    assert supports.size > 0
    dxf_path, pdf_path = write_plan_drawings(mesh, tmp_path / "plan", project_name="Test shell",
                                             support_nodes=supports)
    assert dxf_path.name == "plan.dxf" and pdf_path.name == "plan.pdf"
    data = pdf_path.read_bytes()
    assert data.startswith(b"%PDF") and b"%%EOF" in data[-64:] and len(data) > 1000
    doc = ezdxf.readfile(dxf_path)
    assert not doc.audit().has_errors
    assert doc.header["$INSUNITS"] == 4
    layers = {layer.dxf.name for layer in doc.layers}
    assert {"BEAMS", "LABELS_NODES", "LABELS_BEAMS", "SUPPORTS", "DIMENSIONS", "TITLE"} <= layers
    msp = doc.modelspace()
    # every beam drawn once, end points at the plan nodes in mm
    lines = msp.query('LINE[layer=="BEAMS"]')
    assert len(lines) == len(mesh.edges)
    plan = mesh.nodes[:, :2] * 1e3
    def key(p, q):
        return tuple(sorted([tuple(np.round(np.asarray(p, float)[:2], 6)), tuple(np.round(np.asarray(q, float)[:2], 6))]))

    drawn = {key(line.dxf.start, line.dxf.end) for line in lines}
    expected = {key(plan[a], plan[b]) for a, b in mesh.edges}
    assert drawn == expected
    node_labels = [t.dxf.text for t in msp.query('TEXT[layer=="LABELS_NODES"]')]
    assert "N0001" in node_labels and len(node_labels) == mesh.n_nodes
    beam_labels = [t for t in msp.query('TEXT[layer=="LABELS_BEAMS"]')]
    assert sorted(t.dxf.text for t in beam_labels) == [beam_id(k) for k in range(len(mesh.edges))]
    # beam label k sits at the middle of beam k
    for t in beam_labels:
        k = int(t.dxf.text[1:]) - 1
        a, b = mesh.edges[k]
        assert np.allclose(np.asarray(t.dxf.align_point, float)[:2], 0.5 * (plan[a] + plan[b]))
    assert len(msp.query('LWPOLYLINE[layer=="SUPPORTS"]')) == supports.size
    # overall dimensions equal the plan extents
    dims = msp.query('DIMENSION[layer=="DIMENSIONS"]')
    assert len(dims) == 2
    measured = sorted(d.get_measurement() for d in dims)
    assert measured == pytest.approx(sorted(np.ptp(plan, axis=0)), rel=1e-9)
    title = " ".join(t.dxf.text for t in msp.query('TEXT[layer=="TITLE"]'))
    assert "Test shell" in title and "mm" in title


def test_default_supports_and_bad_index(tmp_path):
    mesh = hex_polymesh(2, 2)
    dxf_path, _ = write_plan_drawings(mesh, tmp_path, project_name="x")
    doc = ezdxf.readfile(dxf_path)
    assert len(doc.modelspace().query('LWPOLYLINE[layer=="SUPPORTS"]')) == int(mesh.supports.sum())
    with pytest.raises(InputError):
        write_plan_drawings(mesh, tmp_path, project_name="x", support_nodes=np.array([mesh.n_nodes]))


@pytest.mark.parametrize("extent, paper, expected", [((2400, 2400), (386, 249), 10), ((100_000, 40_000), (386, 249), 500),
                                                     ((240, 100), (386, 249), 1), ((386, 249), (386, 249), 1),
                                                     ((387, 100), (386, 249), 2)])
def test_plans_are_drawn_at_the_smallest_standard_scale_that_fits(extent, paper, expected):
    from fabrication.drawings import STANDARD_SCALES, drawing_scale

    scale = drawing_scale(extent, paper)
    assert scale == expected and scale in STANDARD_SCALES
    assert all(e / scale <= p for e, p in zip(extent, paper))
