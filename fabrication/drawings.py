"""Plan drawings of the grid-shell: DXF (mm) and an A3 landscape PDF with the same content.

Content: beams (plan projection), node ids N0001 at nodes, beam ids B0001 at mid-beam,
panel ids P0001 at cell centres, support symbols, overall plan dimensions and a title
block. Ids (shared by every fabrication file): node i -> N{i+1:04d}, beam k (row k of
``PolyMesh.edges``) -> B{k+1:04d}, face f -> P{f+1:04d}, joint of node i -> J{i+1:04d}.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from engine.errors import InputError
from engine.mesh import PolyMesh
from fabrication.dxf import PLAN_LAYERS, new_document, save_dxf
from fabrication.files import atomic_path, file_date

from .ids import beam_id, joint_id, node_id, panel_id

__all__ = ["write_plan_drawings", "node_id", "beam_id", "panel_id", "joint_id"]

_A3_MM = (420, 297)
_A3_LANDSCAPE_IN = (_A3_MM[0] / 25.4, _A3_MM[1] / 25.4)
#: The scales a plan is drawn at (1:n), as an architect's or engineer's drawing states them.
STANDARD_SCALES = (1, 2, 5, 10, 20, 25, 50, 100, 200, 250, 500, 1000, 2000, 2500, 5000, 10000, 20000, 50000)


def drawing_scale(extent_mm, paper_mm) -> int:
    """The smallest standard scale n (1:n) at which ``extent_mm`` (width, height) fits ``paper_mm``."""
    need = float(np.max(np.asarray(extent_mm, float) / np.asarray(paper_mm, float)))
    return next((n for n in STANDARD_SCALES if n >= need), int(np.ceil(need)))


def _scale_bar(ax, scale: int) -> None:
    """A scale bar of five black and white segments, some 60 mm of paper long, at the frame's
    bottom left, with its length in m."""
    target = 60.0 * scale  # mm in the model
    step = 10 ** np.floor(np.log10(target / 5))
    segment = max(step * m for m in (1, 2, 5, 10) if 5 * step * m <= 1.2 * target)
    x0, y0 = ax.get_xlim()[0] + 8.0 * scale, ax.get_ylim()[0] + 6.0 * scale
    height = 2.0 * scale
    for k in range(5):
        ax.add_patch(_rectangle((x0 + k * segment, y0), segment, height, "black" if k % 2 == 0 else "white"))
    ax.text(x0, y0 + 1.6 * height, "0", ha="center", va="bottom", fontsize=7)
    ax.text(x0 + 5 * segment, y0 + 1.6 * height, f"{5 * segment / 1000:g} m", ha="center", va="bottom", fontsize=7)


def _rectangle(corner, width: float, height: float, colour: str):
    from matplotlib.patches import Rectangle

    return Rectangle(corner, width, height, facecolor=colour, edgecolor="black", linewidth=0.5)


def _support_nodes(polymesh: PolyMesh, support_nodes: np.ndarray | None) -> np.ndarray:
    if support_nodes is None:
        return np.flatnonzero(polymesh.supports)
    nodes = np.asarray(support_nodes, dtype=np.int64).ravel()
    if nodes.size and (nodes.min() < 0 or nodes.max() >= polymesh.n_nodes):
        raise InputError(f"support node index out of range 0..{polymesh.n_nodes - 1}",
                         hint="support_nodes are 0-based node indices of the grid-shell")
    return nodes


def write_plan_drawings(polymesh: PolyMesh, folder: str | os.PathLike, *, project_name: str,
                        support_nodes: np.ndarray | None = None) -> tuple[Path, Path]:
    """Write ``folder/plan.dxf`` and ``folder/plan.pdf`` (plan view, mm); returns both paths.

    ``support_nodes`` (k,) int: supported node indices; default ``polymesh.supports``.
    """
    if polymesh.n_nodes == 0 or len(polymesh.edges) == 0:
        raise InputError("the grid-shell has no beams to draw")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    supports = _support_nodes(polymesh, support_nodes)
    plan = polymesh.nodes[:, :2] * 1e3
    beams = polymesh.edges
    height = float(max(np.median(polymesh.beam_lengths) * 1e3 * 0.08, 1.0))
    centres = np.array([plan[f].mean(axis=0) for f in polymesh.faces]).reshape(-1, 2)
    title = [project_name, f"Plan view - {polymesh.n_nodes} nodes, {len(beams)} beams, {polymesh.n_faces} cells",
             f"Total beam length {polymesh.total_length:.2f} m - supports {len(supports)}",
             f"Units: mm - date {drawing_date()}"]
    dxf_path = _write_dxf(folder / "plan.dxf", plan, beams, centres, supports, height, title)
    pdf_path = _write_pdf(folder / "plan.pdf", plan, beams, centres, supports, title)
    return dxf_path, pdf_path


def drawing_date() -> str:
    """The title block's date (ISO): fabrication.files.file_date, SOURCE_DATE_EPOCH when set,
    else today."""
    return file_date().date().isoformat()


def _write_dxf(target: Path, plan: np.ndarray, beams: np.ndarray, centres: np.ndarray, supports: np.ndarray,
               height: float, title: list[str]) -> Path:
    doc = new_document(PLAN_LAYERS, setup=True)
    msp = doc.modelspace()
    for a, b in beams:
        msp.add_line(tuple(plan[a]), tuple(plan[b]), dxfattribs={"layer": "BEAMS"})
    lo, hi = plan.min(axis=0), plan.max(axis=0)
    gap = 6 * height
    crowded = _dxf_labels(msp, plan, beams, centres, height, obstacles=np.array([
        [lo[0], lo[1] - gap - 2.5 * height, hi[0], lo[1] - gap + 2.5 * height],
        [lo[0] - gap - 2.5 * height, lo[1], lo[0] - gap + 2.5 * height, hi[1]]]))
    if crowded:
        title = [*title, f"{crowded} ids drawn at their parts without room (they may overlap)"]
    if not len(msp.query('LINE[layer=="LABELS_LEADERS"]')):
        doc.layers.remove("LABELS_LEADERS")
    size = 2.0 * height
    for i in supports:
        x, y = plan[i]
        msp.add_lwpolyline([(x, y), (x - size / 2, y - size), (x + size / 2, y - size)], close=True,
                           dxfattribs={"layer": "SUPPORTS"})
    # drawing units are mm: the text is the measurement itself (ezdxf's own style scales by 100)
    override = {"dimtxt": height * 1.5, "dimasz": height, "dimexe": height * 0.5, "dimexo": height * 0.5,
                "dimdec": 0, "dimlfac": 1.0}
    msp.add_linear_dim(base=(lo[0], lo[1] - gap), p1=(lo[0], lo[1]), p2=(hi[0], lo[1]), angle=0,
                       override=override, dxfattribs={"layer": "DIMENSIONS"}).render()
    msp.add_linear_dim(base=(lo[0] - gap, lo[1]), p1=(lo[0], lo[1]), p2=(lo[0], hi[1]), angle=90,
                       override=override, dxfattribs={"layer": "DIMENSIONS"}).render()
    # title block: a frame with the text lines, under the plan, right-aligned with it
    line_h = 2.5 * height
    width = max(hi[0] - lo[0], 40 * height) * 0.5
    x0, y0 = hi[0] - width, lo[1] - gap - 3 * line_h - len(title) * line_h
    top = y0 + (len(title) + 1) * line_h
    msp.add_lwpolyline([(x0, y0), (hi[0], y0), (hi[0], top), (x0, top)], close=True, dxfattribs={"layer": "TITLE"})
    for j, text in enumerate(title):
        msp.add_text(text, height=1.6 * height if j == 0 else height,
                     dxfattribs={"layer": "TITLE", "insert": (x0 + 0.5 * line_h, y0 + (len(title) - j) * line_h)})
    save_dxf(doc, target)
    return target


DXF_CAP_HEIGHT = 0.7
"""A TEXT entity's height (its capitals) as a share of the type's em, which the label boxes use."""

DXF_SMALLEST_LABEL = 0.15
"""The plan.dxf's ids step down to this share of their first height to find room; what has none
then is drawn at its part and counted in the title block."""


def _dxf_labels(msp, plan: np.ndarray, beams: np.ndarray, centres: np.ndarray, height: float,
                obstacles: np.ndarray) -> int:
    """Node, beam and panel ids of plan.dxf placed without overlap (beside their part, or farther with
    a leader line on LABELS_LEADERS), at ``height`` mm or smaller; returns how many found no room
    and are drawn at their part."""
    from ezdxf.enums import TextEntityAlignment

    pt = 25.4 / 72.0
    em = height / DXF_CAP_HEIGHT / pt            # the first height as a type size in pt at scale 1
    texts, points, anchor, placement = _label_places(
        plan, beams, _id_anchors(plan, beams, centres), em, 1.0, None, obstacles, min_font=DXF_SMALLEST_LABEL * em,
        far_rings=(1.2, 1.8, 2.6, 3.6, 5.0), gap=0.15 * em * pt)
    layers = np.repeat(["LABELS_NODES", "LABELS_BEAMS", "LABELS_PANELS"], [len(plan), len(beams), len(centres)])
    where = np.where(placement.placed[:, None], placement.centre, anchor)
    for i, text in enumerate(texts):
        t = msp.add_text(text, height=float(DXF_CAP_HEIGHT * points[i] * pt), dxfattribs={"layer": str(layers[i])})
        t.set_placement((float(where[i, 0]), float(where[i, 1])), align=TextEntityAlignment.MIDDLE_CENTER)
    for i in np.flatnonzero(placement.leader):
        msp.add_line(tuple(anchor[i]), tuple(placement.centre[i]), dxfattribs={"layer": "LABELS_LEADERS"})
    return placement.left_out


def _text_box_mm(texts: list[str], points: float) -> np.ndarray:
    """Width and height (len, 2) on paper (mm) of labels set in matplotlib's font at ``points``: the
    ink width of each text's shape (its digits as 8s: the widest) plus a fifth of an em, and 1.2 em
    of height (ascent and descent)."""
    import re

    shapes = [re.sub(r"[0-9]", "8", t) for t in texts]
    widths = _shape_widths_mm(set(shapes), points)
    pt = 25.4 / 72.0
    return np.array([[widths[s], 1.2 * points * pt] for s in shapes]).reshape(-1, 2)


def _shape_widths_mm(shapes, points: float) -> dict[str, float]:
    """Paper width (mm) of each text shape at ``points``: its ink width plus a fifth of an em."""
    from matplotlib.textpath import TextPath

    pt = 25.4 / 72.0
    return {shape: (TextPath((0, 0), shape, size=points).get_extents().width + 0.2 * points) * pt
            for shape in shapes}


def _id_shape_counts(prefix: str, count: int) -> dict[str, int]:
    """How many of the ids prefix0001 .. of ``count`` parts have each shape (digits as 8s): N8888 for
    the first 9999, N88888 for the next 90000, ..."""
    counts = {}
    for digits in range(4, max(4, len(str(count))) + 1):
        first, last = (1 if digits == 4 else 10 ** (digits - 1)), min(count, 10 ** digits - 1)
        if last >= first:
            counts[prefix + "8" * digits] = last - first + 1
    return counts


def _id_anchors(plan: np.ndarray, beams: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Where each id's part is on the plan (nodes + beams + panels, 2), in the plan's unit: the
    nodes, the beams' middles and the cells' centres, in id order."""
    mid = 0.5 * (plan[beams[:, 0]] + plan[beams[:, 1]]) if len(beams) else np.zeros((0, 2))
    return np.concatenate([plan, mid, centres.reshape(-1, 2)])


MIN_LABEL_POINTS = 3.0
"""The smallest type the plan's ids are set in (pt); ids that find no room at it are left out."""

_BEAM_POINTS = 0.8
"""The beams' ids are set at this share of the nodes' and panels' type size."""


def _label_places(plan: np.ndarray, beams: np.ndarray, anchor: np.ndarray, font: float, scale: float,
                  bounds: tuple[float, float, float, float] | None, obstacles: np.ndarray, *,
                  min_font: float = MIN_LABEL_POINTS, far_rings: tuple[float, ...] = (1.2, 1.8, 2.6),
                  gap: float | None = None, keep: np.ndarray | None = None):
    """Node, beam and panel ids placed without overlap (model mm), nodes choosing first, then beams,
    then panels: at ``font`` pt (beams at 0.8 of it), or smaller by steps of 0.8 down to
    ``min_font`` until every id has room; ``far_rings`` are the leader lines' reaches in typical
    label widths (the median of every id's, kept or not), ``gap`` the clear space round a label
    (model mm; 0.3 mm of paper by default). ``anchor``: _id_anchors of the plan. ``keep`` (nodes +
    beams + panels,) bool: measure and place only these ids (a tile of the plan).
    Returns texts, point sizes, anchors and the placement (fabrication.label_placement) of the ids
    placed (all, or those of ``keep``)."""
    from .label_placement import place_labels, ring_offsets

    nn, nb = len(plan), len(beams)
    counts = (nn, nb, len(anchor) - nn - nb)
    kept = np.arange(len(anchor)) if keep is None else np.flatnonzero(keep)
    kind = np.searchsorted([nn, nn + nb], kept, side="right")          # 0 node, 1 beam, 2 panel
    number = kept - np.array([0, nn, nn + nb])[kind]
    texts = [(node_id, beam_id, panel_id)[k](i) for k, i in zip(kind.tolist(), number.tolist())]
    groups = [np.flatnonzero(kind == k) for k in range(3)]
    shares = (1.0, _BEAM_POINTS, 1.0)
    ends = beams[number[groups[1]]]
    along = plan[ends[:, 1]] - plan[ends[:, 0]]
    normal = np.column_stack([-along[:, 1], along[:, 0]])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    shape_counts = [_id_shape_counts(prefix, n) for prefix, n in zip("NBP", counts)]
    # the eight places round a node, the first again to make nine, as the beams and panels have
    node_unit = np.array([[1, 1], [-1, 1], [1, -1], [-1, -1], [1, 0], [-1, 0], [0, 1], [0, -1], [1, 1]], float)
    k = len(node_unit)
    while True:
        points = np.array(shares)[kind] * font
        size = np.zeros((len(kept), 2))
        every_width = []            # the widths of every id of the plan, as shapes and their counts
        for group, share, shape_count in zip(groups, shares, shape_counts):
            size[group] = _text_box_mm([texts[i] for i in group], share * font)
            widths = _shape_widths_mm(shape_count, share * font)
            every_width.append(np.repeat([widths[s] for s in shape_count], list(shape_count.values())))
        size *= scale
        w, h = size[:, :1], size[:, 1:]
        near = np.zeros((len(kept), k, 2))
        nodes, beam_ids, panels = groups
        # nodes: the eight places round the node, touching it
        reach = np.concatenate([0.5 * w[nodes] + 0.2 * h[nodes], 0.6 * h[nodes]], axis=1)
        near[nodes] = node_unit[None, :, :] * reach[:, None, :]
        # beams: at 0.5, 0.35 and 0.65 of the beam, on it or beside it
        for j, (t, side) in enumerate([(t, s) for t in (0.0, -0.15, 0.15) for s in (0.0, 0.8, -0.8)]):
            near[beam_ids, j] = t * along + side * h[beam_ids] * normal
        # panels: the centre, then round it
        near[panels, 1:] = ring_offsets(1.0, k - 1)[None, :, :] * h[panels, None, :]
        every_width = np.concatenate(every_width) * scale
        typical = float(np.median(every_width)) if len(every_width) else 1.0
        far = np.concatenate([ring_offsets(r * typical, 12, phase=0.26) for r in far_rings])
        placement = place_labels(anchor[kept], size, near, far, bounds=bounds, obstacles=obstacles,
                                 gap=0.3 * scale if gap is None else gap)
        if not placement.left_out or font <= min_font:
            return texts, points, anchor[kept], placement
        font = max(0.8 * font, min_font)


_FRAME = (0.04, 0.12, 0.92, 0.84)
"""The plan's frame on an A3 sheet, as fractions of the sheet (left, bottom, width, height)."""

TILE_POINTS = 5.0
"""The type size the plan's tile sheets set the ids in; they step down to TILE_MIN_POINTS."""

TILE_MIN_POINTS = 4.0

MAX_TILE_SHEETS = 64
"""The most tile sheets a plan is split into; ids still without room are counted."""


def _sheet(title_lines: list[str]):
    """An A3 landscape figure with the plan's axes in its frame and the title block at its foot."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=_A3_LANDSCAPE_IN)
    FigureCanvasAgg(fig)
    ax = fig.add_axes(_FRAME)
    ax.axis("off")
    fig.text(0.96, 0.03, "\n".join(title_lines), ha="right", va="bottom", fontsize=9,
             bbox={"boxstyle": "square", "facecolor": "white", "edgecolor": "black"})
    return fig, ax


def _window(centre: np.ndarray, scale: int) -> tuple[float, float, float, float]:
    """The model window (x0, y0, x1, y1, mm) the frame shows at 1:``scale`` round ``centre``."""
    paper = np.array([_A3_MM[0] * _FRAME[2], _A3_MM[1] * _FRAME[3]])
    lo, hi = centre - 0.5 * scale * paper, centre + 0.5 * scale * paper
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def _draw_plan(ax, window, plan: np.ndarray, beams: np.ndarray, supports: np.ndarray, labels) -> None:
    """Beams, supports and placed ids (texts, points, anchors, placement, colours) in ``window``."""
    from matplotlib.collections import LineCollection

    ax.set_xlim(window[0], window[2])
    ax.set_ylim(window[1], window[3])
    # only the beams whose box meets the window: the PDF writer draws every segment of a collection
    # as its own path, clipped or not (a large roof's 26 tiles drew all its beams on each sheet)
    ends = plan[beams]
    seen = ((ends[:, :, 0].max(axis=1) >= window[0]) & (ends[:, :, 0].min(axis=1) <= window[2])
            & (ends[:, :, 1].max(axis=1) >= window[1]) & (ends[:, :, 1].min(axis=1) <= window[3]))
    ax.add_collection(LineCollection(ends[seen], colors="k", linewidths=0.6))
    texts, points, anchor, placement, colours = labels
    leaders = np.flatnonzero(placement.leader)
    if len(leaders):
        ax.add_collection(LineCollection(np.stack([anchor[leaders], placement.centre[leaders]], axis=1),
                                         colors="0.55", linewidths=0.3))
    for i in np.flatnonzero(placement.placed):
        ax.text(*placement.centre[i], texts[i], fontsize=points[i], color=colours[i], ha="center",
                va="center_baseline")
    if len(supports):
        ax.plot(plan[supports, 0], plan[supports, 1], "^", color="tab:red", markersize=6, linestyle="none")


def _label_colours(plan, beams, centres) -> np.ndarray:
    return np.repeat(["tab:green", "tab:blue", "tab:purple"], [len(plan), len(beams), len(centres)])


def _write_pdf(target: Path, plan: np.ndarray, beams: np.ndarray, centres: np.ndarray, supports: np.ndarray,
               title: list[str]) -> Path:
    """plan.pdf: the whole plan on its first A3 sheet, with the overall dimensions and the ids that
    have room; where some have none, the plan again in tiles, one sheet each at a larger scale,
    each id on the sheet of the tile its part's anchor is in (with a key plan of the tiles)."""
    from matplotlib.backends.backend_pdf import PdfPages

    lo, hi = plan.min(axis=0), plan.max(axis=0)
    span = hi - lo
    gap = 0.06 * span.max()
    # a true scale: the frame shows scale x its paper size of the plan, centred
    paper = np.array([_A3_MM[0] * _FRAME[2], _A3_MM[1] * _FRAME[3]])
    scale = drawing_scale(span + 3 * gap, paper)
    window = _window(0.5 * (lo + hi) - 0.5 * gap, scale)  # the dimensions take 2 gaps left and under, 1 beyond
    font = float(np.clip(240 / np.sqrt(max(len(plan), 1)), 1.0, 7.0))
    # no label outside the frame, on the dimensions or on the scale bar
    text = 12.0 * scale      # 8 pt dimension text with room
    obstacles = np.array([
        [lo[0], lo[1] - gap - 0.2 * text, hi[0], lo[1] - gap + text],
        [lo[0] - gap - text, lo[1], lo[0] - gap + 0.2 * text, hi[1]],
        [window[0], window[1], window[0] + 90.0 * scale, window[1] + 16.0 * scale]])
    anchor = _id_anchors(plan, beams, centres)
    texts, points, _, placement = _label_places(plan, beams, anchor, font, scale, window, obstacles)
    colours = _label_colours(plan, beams, centres)
    tiles = _tiles(plan, beams, anchor, lo, hi, len(texts), int(placement.placed.sum())) \
        if placement.left_out else []
    notes = [f"Scale 1:{scale} on A3 ({_A3_MM[0]} x {_A3_MM[1]} mm)"]
    if tiles:
        sheets = f"sheet 1 of {len(tiles) + 1}"
        notes.append(f"{placement.left_out} of {len(texts)} ids left out here: each id is on one of sheets "
                     f"2-{len(tiles) + 1}")
        left_out = sum(t["placement"].left_out for t in tiles)
        if left_out:
            notes.append(f"{left_out} ids left out for space on those too (plan.dxf and the lists have every part)")
    elif placement.left_out:
        sheets = "sheet 1 of 1"
        notes.append(f"{placement.left_out} of {len(texts)} ids left out for space (plan.dxf and the lists "
                     "have every part)")
    else:
        sheets = "sheet 1 of 1"
    fig, ax = _sheet([*title, *notes, sheets])
    _draw_plan(ax, window, plan, beams, supports, (texts, points, anchor, placement, colours))
    ax.annotate("", xy=(lo[0], lo[1] - gap), xytext=(hi[0], lo[1] - gap), arrowprops={"arrowstyle": "<->", "lw": 0.8})
    ax.text(0.5 * (lo[0] + hi[0]), lo[1] - gap, f"{span[0]:.0f}", ha="center", va="bottom", fontsize=8)
    ax.annotate("", xy=(lo[0] - gap, lo[1]), xytext=(lo[0] - gap, hi[1]), arrowprops={"arrowstyle": "<->", "lw": 0.8})
    ax.text(lo[0] - gap, 0.5 * (lo[1] + hi[1]), f"{span[1]:.0f}", ha="right", va="center", rotation=90, fontsize=8)
    for tile in tiles:   # the tiles' edges; their sheets' key plans say which is which
        ax.add_patch(_outline(tile["core"], "tab:red", zorder=5))
    _scale_bar(ax, scale)
    with atomic_path(target) as tmp:
        with PdfPages(tmp, metadata={"CreationDate": file_date()}) as pdf:
            pdf.savefig(fig)
            for k, tile in enumerate(tiles):
                pdf.savefig(_tile_sheet(tile, k + 2, len(tiles) + 1, plan, beams, supports, colours, title,
                                        [t["core"] for t in tiles]))
    return target


def _outline(box, colour: str, zorder: float = 1.0):
    """A dashed rectangle round ``box`` (x0, y0, x1, y1)."""
    from matplotlib.patches import Rectangle

    x0, y0, x1, y1 = box
    return Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, edgecolor=colour, linewidth=0.8, linestyle="--",
                     zorder=zorder)


def _tiles(plan, beams, anchor, lo, hi, n_ids: int, n_placed: int) -> list[dict]:
    """The plan cut into tiles of the frame's shape, as few as give every id room at TILE_POINTS
    (down to TILE_MIN_POINTS), at most MAX_TILE_SHEETS: each tile's core (x0, y0, x1, y1, mm),
    scale, window and the placement of the ids whose anchor (_id_anchors, mm) is in its core. Empty
    tiles are dropped."""
    paper = np.array([_A3_MM[0] * _FRAME[2], _A3_MM[1] * _FRAME[3]])
    span = np.maximum(hi - lo, 1e-9)

    def rows_for(columns: int) -> int:
        return max(1, int(np.ceil(span[1] / (span[0] / columns * paper[1] / paper[0]) - 1e-9)))

    def cut(columns: int) -> list[dict]:
        rows = rows_for(columns)
        width, height = span[0] / columns, span[1] / rows
        column = np.minimum(((anchor[:, 0] - lo[0]) / width).astype(int), columns - 1)
        row = np.minimum(((anchor[:, 1] - lo[1]) / height).astype(int), rows - 1)
        tiles = []
        for r in range(rows - 1, -1, -1):          # top row first, as a drawing set is read
            for c in range(columns):
                keep = (column == c) & (row == r)
                if not keep.any():
                    continue
                core = (lo[0] + c * width, lo[1] + r * height, lo[0] + (c + 1) * width, lo[1] + (r + 1) * height)
                scale = drawing_scale(1.25 * np.array([width, height]), paper)
                window = _window(0.5 * (np.array(core[:2]) + np.array(core[2:])), scale)
                obstacles = np.array([[window[0], window[1], window[0] + 90.0 * scale, window[1] + 16.0 * scale]])
                labels = _label_places(plan, beams, anchor, TILE_POINTS, scale, window, obstacles,
                                       min_font=TILE_MIN_POINTS, keep=keep)
                tiles.append({"core": core, "scale": scale, "window": window, "keep": keep, "labels": labels,
                              "placement": labels[3]})
        return tiles

    # the area the ids need grows as the type's square: from the first sheet's share, a first guess
    columns = max(2, int(np.ceil(np.sqrt(n_ids / max(n_placed, 1) * 1.5))))
    while columns > 2 and columns * rows_for(columns) > MAX_TILE_SHEETS:
        columns -= 1
    while True:
        tiles = cut(columns)
        if not sum(t["placement"].left_out for t in tiles) or (columns + 1) * rows_for(columns + 1) > MAX_TILE_SHEETS:
            return tiles
        columns += 1


def _tile_sheet(tile: dict, number: int, count: int, plan, beams, supports, colours, title: list[str], cores):
    """One tile of the plan on an A3 sheet, its core's edges dashed, with a key plan of the tiles."""
    texts, points, where, placement = tile["labels"]
    notes = [f"Part of the plan: tile {number - 1} of {count - 1}, scale 1:{tile['scale']} on A3 "
             f"({_A3_MM[0]} x {_A3_MM[1]} mm)", f"sheet {number} of {count}"]
    if placement.left_out:
        notes.insert(1, f"{placement.left_out} of {len(texts)} ids of this tile left out for space")
    fig, ax = _sheet([*title, *notes])
    _draw_plan(ax, tile["window"], plan, beams, supports,
               (texts, points, where, placement, colours[np.flatnonzero(tile["keep"])]))
    ax.add_patch(_outline(tile["core"], "tab:red"))
    _scale_bar(ax, tile["scale"])
    # the key plan: every tile, this one filled
    key = fig.add_axes((0.04, 0.01, 0.16, 0.10))
    key.axis("off")
    key.set_aspect("equal")
    # one path for the whole key plan (as a collection, each beam was a path of its own on every sheet)
    lines = np.full((len(beams), 3, 2), np.nan)
    lines[:, :2] = plan[beams]
    key.plot(lines[:, :, 0].ravel(), lines[:, :, 1].ravel(), color="0.7", linewidth=0.2, solid_capstyle="butt")
    for k, core in enumerate(cores):
        box = _outline(core, "tab:red" if k + 2 == number else "0.4")
        if k + 2 == number:
            box.set_fill(True)
            box.set_alpha(0.35)
        key.add_patch(box)
    lo, hi = plan.min(axis=0), plan.max(axis=0)
    key.set_xlim(lo[0], hi[0])
    key.set_ylim(lo[1], hi[1])
    return fig
