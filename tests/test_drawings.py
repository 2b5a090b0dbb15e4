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
        return tuple(sorted([tuple(np.round(np.asarray(p, float)[:2], 6)),
                             tuple(np.round(np.asarray(q, float)[:2], 6))]))

    drawn = {key(line.dxf.start, line.dxf.end) for line in lines}
    expected = {key(plan[a], plan[b]) for a, b in mesh.edges}
    assert drawn == expected
    node_labels = [t.dxf.text for t in msp.query('TEXT[layer=="LABELS_NODES"]')]
    assert "N0001" in node_labels and len(node_labels) == mesh.n_nodes
    beam_labels = [t for t in msp.query('TEXT[layer=="LABELS_BEAMS"]')]
    assert sorted(t.dxf.text for t in beam_labels) == [beam_id(k) for k in range(len(mesh.edges))]
    # beam label k sits by the middle of beam k: within two of its heights' reach of it
    for t in beam_labels:
        k = int(t.dxf.text[1:]) - 1
        a, b = mesh.edges[k]
        reach = np.linalg.norm(np.asarray(t.dxf.align_point, float)[:2] - 0.5 * (plan[a] + plan[b]))
        assert reach <= 2.0 * t.dxf.height
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


@pytest.mark.parametrize("extent, paper, expected", [((2400, 2400), (386, 249), 10),
                                                     ((100_000, 40_000), (386, 249), 500),
                                                     ((240, 100), (386, 249), 1), ((386, 249), (386, 249), 1),
                                                     ((387, 100), (386, 249), 2)])
def test_plans_are_drawn_at_the_smallest_standard_scale_that_fits(extent, paper, expected):
    from fabrication.drawings import STANDARD_SCALES, drawing_scale

    scale = drawing_scale(extent, paper)
    assert scale == expected and scale in STANDARD_SCALES
    assert all(e / scale <= p for e, p in zip(extent, paper))


def _pdf_glyphs(path) -> list[list[tuple[str, tuple[float, float, float, float]]]]:
    """Every character drawn on each page of a PDF with its box (pt), read by PDFium (pypdfium2, not
    by matplotlib): one list per page. The boxes are PDFium's loose ones, the font's advance width
    by its ascent and descent, so that two characters of one word touch."""
    import pypdfium2 as pdfium

    pages = []
    document = pdfium.PdfDocument(str(path))
    try:
        for page in document:
            text = page.get_textpage()
            glyphs = []
            for i in range(text.count_chars()):
                char = text.get_text_range(i, 1)
                if char.strip():
                    glyphs.append((char, tuple(text.get_charbox(i, loose=True))))
            pages.append(glyphs)
    finally:
        document.close()
    return pages


def _pdf_words(glyphs) -> list[str]:
    """The words of a PDF from its glyphs: characters on one baseline whose boxes touch."""
    words = []
    rows: dict[float, list] = {}
    for text, (x0, y0, x1, y1) in glyphs:
        rows.setdefault(round(y0, 1), []).append((x0, x1, text))
    for row in rows.values():
        row.sort()
        word, end = "", None
        for x0, x1, text in row:
            if end is not None and x0 - end > 0.25 * (x1 - x0):
                words.append(word)
                word = ""
            word, end = word + text, x1
        words.append(word)
    return words


def _overlapping_glyphs(glyphs) -> list:
    """Pairs of characters whose boxes, shrunk by 15 % of their smaller side, still overlap."""
    from scipy.spatial import cKDTree

    boxes = np.array([b for _, b in glyphs])
    shrink = 0.15 * np.minimum(boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1])[:, None]
    inner = np.concatenate([boxes[:, :2] + shrink, boxes[:, 2:] - shrink], axis=1)
    centre, half = 0.5 * (inner[:, :2] + inner[:, 2:]), 0.5 * (inner[:, 2:] - inner[:, :2])
    near = np.array(sorted(cKDTree(centre).query_pairs(2.0 * float(np.linalg.norm(half, axis=1).max()))),
                    dtype=np.int64).reshape(-1, 2)
    a, b = near[:, 0], near[:, 1]
    apart = (np.abs(centre[a] - centre[b]) >= half[a] + half[b]).any(axis=1)
    return [(glyphs[i], glyphs[j]) for i, j in near[~apart]]


def _ids(words: list[str]) -> list[str]:
    return [w for w in words if len(w) == 5 and w[0] in "NBP" and w[1:].isdigit()]


@pytest.mark.parametrize("rows, cols", [(3, 4), (8, 10), pytest.param(30, 40, marks=pytest.mark.slow)])
def test_plan_pdf_labels_do_not_overlap(tmp_path, rows, cols):
    """No two characters on a page of the plan PDF overlap (so no two ids, dimensions or title lines
    do), and every id is drawn: on the first sheet, or, where it has no room there, once on the
    sheets of the plan's tiles, which the first sheet's title block names."""
    pytest.importorskip("pypdfium2")
    mesh = hex_polymesh(rows, cols)
    _, pdf_path = write_plan_drawings(mesh, tmp_path, project_name="Labels")
    pages = _pdf_glyphs(pdf_path)
    assert sum(len(g) for g in pages) > 100
    for number, glyphs in enumerate(pages):
        assert _overlapping_glyphs(glyphs) == [], f"sheet {number + 1}"
    words = [_pdf_words(glyphs) for glyphs in pages]
    first = _ids(words[0])
    assert len(first) == len(set(first)), "an id drawn twice"
    expected = ([node_id(i) for i in range(mesh.n_nodes)] + [beam_id(k) for k in range(len(mesh.edges))]
                + [panel_id(f) for f in range(mesh.n_faces)])
    text = " ".join(words[0])
    assert f"sheet 1 of {len(pages)}" in text
    if len(pages) == 1:
        assert sorted(first) == sorted(expected) and "left out" not in text
    else:
        assert f"ids left out here: each id is on one of sheets 2-{len(pages)}" in text
        tiles = [i for w in words[1:] for i in _ids(w)]
        assert sorted(tiles) == sorted(expected), "each id once on the tile sheets"


def _jittered(rows: int, cols: int, share: float, seed: int):
    """hex_polymesh with its nodes moved at random by up to ``share`` of the cell radius: short
    beams and crowded nodes, as a remeshed grid has."""
    mesh = hex_polymesh(rows, cols)
    rng = np.random.default_rng(seed)
    nodes = mesh.nodes.copy()
    nodes[:, :2] += rng.uniform(-1, 1, (len(nodes), 2)) * share * 0.18 * np.ptp(mesh.nodes[:, 0]) / 2.4
    return type(mesh)(nodes=nodes, faces=mesh.faces, boundary=mesh.boundary, supports=mesh.supports)


@pytest.mark.parametrize("rows, cols, jitter", [(3, 4, 0.0), (8, 10, 0.0), (6, 8, 0.45),
                                                pytest.param(16, 20, 0.45, marks=pytest.mark.slow)])
def test_plan_dxf_labels_do_not_overlap(tmp_path, rows, cols, jitter):
    """The plan.dxf's ids as ezdxf measures them (its own font metrics, not the writer's): no two
    overlap, each part's id is there once, and an id away from its part has a leader line from it."""
    from ezdxf import bbox

    mesh = _jittered(rows, cols, jitter, seed=rows) if jitter else hex_polymesh(rows, cols)
    dxf_path, _ = write_plan_drawings(mesh, tmp_path, project_name="Labels")
    msp = ezdxf.readfile(dxf_path).modelspace()
    texts = [t for t in msp.query("TEXT") if t.dxf.layer in ("LABELS_NODES", "LABELS_BEAMS", "LABELS_PANELS")]
    expected = ([node_id(i) for i in range(mesh.n_nodes)] + [beam_id(k) for k in range(len(mesh.edges))]
                + [panel_id(f) for f in range(mesh.n_faces)])
    assert sorted(t.dxf.text for t in texts) == sorted(expected)
    boxes = np.array([[b.extmin.x, b.extmin.y, b.extmax.x, b.extmax.y]
                      for b in (bbox.extents([t]) for t in texts)])
    a, b = np.triu_indices(len(boxes), 1)
    overlap = ((boxes[a, 0] < boxes[b, 2]) & (boxes[b, 0] < boxes[a, 2])
               & (boxes[a, 1] < boxes[b, 3]) & (boxes[b, 1] < boxes[a, 3]))
    pairs = [(texts[i].dxf.text, texts[j].dxf.text) for i, j in zip(a[overlap], b[overlap])]
    title = " ".join(t.dxf.text for t in msp.query('TEXT[layer=="TITLE"]'))
    assert pairs == [] or f"{len(pairs)} ids drawn at their parts" in title, pairs[:5]
    assert pairs == []
    # where each id's part is, in plan mm
    plan = mesh.nodes[:, :2] * 1e3
    parts = {**{node_id(i): plan[i] for i in range(mesh.n_nodes)},
             **{beam_id(k): plan[e].mean(axis=0) for k, e in enumerate(mesh.edges)},
             **{panel_id(f): plan[face].mean(axis=0) for f, face in enumerate(mesh.faces)}}
    leaders = [(np.asarray(line.dxf.start, float)[:2], np.asarray(line.dxf.end, float)[:2])
               for line in msp.query('LINE[layer=="LABELS_LEADERS"]')]
    for t, box in zip(texts, boxes):
        centre = 0.5 * (box[:2] + box[2:])
        size = max(box[2] - box[0], box[3] - box[1])
        if np.linalg.norm(centre - parts[t.dxf.text]) > 1.5 * size:
            assert any(np.allclose(start, parts[t.dxf.text]) and np.linalg.norm(end - centre) < 0.5 * size
                       for start, end in leaders), t.dxf.text


@pytest.mark.parametrize("count", [0, 1, 660, 9999, 10001, 12345])
def test_id_shapes_are_counted_as_the_ids_measure(count):
    """A tile measures only its own ids; the leader lines' reach (the median width of every id of
    the plan) comes from the ids' shapes and their counts, and is the median of every id measured."""
    from fabrication.drawings import _id_shape_counts, _shape_widths_mm, _text_box_mm

    counts = _id_shape_counts("B", count)
    assert sum(counts.values()) == count
    widths = _shape_widths_mm(counts, 4.0)
    every = np.repeat([widths[s] for s in counts], list(counts.values()))
    measured = _text_box_mm([beam_id(k) for k in range(count)], 4.0)[:, 0]
    assert np.array_equal(np.sort(every), np.sort(measured))
