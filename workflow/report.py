"""The one-page report: sections of figures and tables, a verdict table and a 3D view.

The page is self-contained (figures embedded as data URIs, the viewer's script and the
geometry inline) so it opens offline from any folder; the same figures and tables are also
written next to it as PNG and CSV by the report stage. This module only builds the HTML.
"""

from __future__ import annotations

import base64
import html
import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from .labels import format_against, format_value

__all__ = ["Figure", "Table", "Section", "Viewer", "render_report", "viewer_geometry"]


@dataclass(frozen=True, kw_only=True)
class Figure:
    """A PNG picture with its caption; ``png`` is the file's bytes; ``wide`` spans the page's width
    (pictures of several panels: the modes, the assembly, the sheets)."""

    name: str
    caption: str
    png: bytes
    wide: bool = False


@dataclass(frozen=True, kw_only=True)
class Table:
    """A table: ``columns`` and ``rows`` of plain values; ``verdict`` colours a pass/fail column."""

    name: str
    caption: str
    columns: list[str]
    rows: list[list]
    verdict_column: str | None = None


@dataclass(frozen=True, kw_only=True)
class Section:
    """One part of the page: a heading, a paragraph, figures, tables and links to files."""

    title: str
    text: str = ""
    figures: list[Figure] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    links: list[tuple[str, str]] = field(default_factory=list)


@dataclass(frozen=True, kw_only=True)
class Viewer:
    """Geometry for the interactive view, in metres: nodes (n,3), beams (b,2), panels as node loops."""

    nodes: np.ndarray
    beams: np.ndarray
    panels: list[np.ndarray]
    supports: np.ndarray
    beam_values: np.ndarray | None = None
    beam_value_label: str = ""


def viewer_geometry(viewer: Viewer) -> dict:
    """The JSON the page's viewer draws (coordinates rounded to 0.1 mm, centred on the bounding box)."""
    nodes = np.asarray(viewer.nodes, dtype=float)
    centre = 0.5 * (nodes.min(axis=0) + nodes.max(axis=0))
    data = {"nodes": np.round(nodes - centre, 4).tolist(),
            "beams": np.asarray(viewer.beams, dtype=int).tolist(),
            "panels": [np.asarray(p, dtype=int).tolist() for p in viewer.panels],
            "supports": np.flatnonzero(np.asarray(viewer.supports, dtype=bool)).tolist()}
    if viewer.beam_values is not None:
        data["beamValues"] = np.round(np.asarray(viewer.beam_values, dtype=float), 6).tolist()
        data["beamValueLabel"] = viewer.beam_value_label
    return data


def _format(value, verdict: bool = False) -> str:
    """A cell's text: pass/FAIL in a verdict column, else as people write numbers (labels.format_value)."""
    if isinstance(value, np.generic):
        value = value.item()
    if verdict and isinstance(value, bool):
        return "pass" if value else "FAIL"
    return format_value(value)


def _table_html(table: Table) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in table.columns)
    body = []
    verdict_index = table.columns.index(table.verdict_column) if table.verdict_column in table.columns else None
    # a value beside its limit gets the digits that tell them apart (labels.format_against)
    paired = [(table.columns.index(name), table.columns.index("limit")) for name in ("value", "worst")
              if name in table.columns and "limit" in table.columns]
    for row in table.rows:
        texts = {}
        for i, j in paired:
            value, limit = (v.item() if isinstance(v, np.generic) else v for v in (row[i], row[j]))
            texts[i], texts[j] = format_against(value, limit)
        cells = []
        for i, value in enumerate(row):
            css = ""
            if i == verdict_index and isinstance(value, (bool, np.bool_)):
                css = ' class="pass"' if value else ' class="fail"'
            cell = texts[i] if i in texts else _format(value, verdict=i == verdict_index)
            cells.append(f"<td{css}>{html.escape(cell)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    caption = f"<caption>{html.escape(table.caption)}</caption>" if table.caption else ""
    return (f'<table id="table-{html.escape(table.name)}">{caption}<thead><tr>{head}</tr></thead>'
            f'<tbody>{"".join(body)}</tbody></table>')


def _figure_html(figure: Figure) -> str:
    data = base64.b64encode(figure.png).decode("ascii")
    wide = ' class="wide"' if figure.wide else ""
    return (f'<figure id="figure-{html.escape(figure.name)}"{wide}><img alt="{html.escape(figure.caption)}" '
            f'src="data:image/png;base64,{data}"><figcaption>{html.escape(figure.caption)}</figcaption></figure>')


def _section_html(section: Section) -> str:
    parts = [f"<section><h2>{html.escape(section.title)}</h2>"]
    if section.text:
        parts.append(f"<p>{html.escape(section.text)}</p>")
    for table in section.tables:
        parts.append(_table_html(table))
    if section.figures:
        parts.append('<div class="figures">' + "".join(_figure_html(f) for f in section.figures) + "</div>")
    if section.links:
        items = "".join(f'<li><a href="{html.escape(href)}">{html.escape(label)}</a></li>'
                        for label, href in section.links)
        parts.append(f'<ul class="files">{items}</ul>')
    parts.append("</section>")
    return "\n".join(parts)


def _asset(name: str) -> str:
    return resources.files("templates").joinpath(name).read_text(encoding="utf-8")


def render_report(*, title: str, subtitle: str, summary: Section, sections: list[Section],
                  viewer: Viewer | None) -> str:
    """The whole page as one HTML string (templates/report.html with templates/viewer.js inline)."""
    page = _asset("report.html")
    geometry = json.dumps(viewer_geometry(viewer)) if viewer is not None else "null"
    replacements = {
        "{{title}}": html.escape(title),
        "{{subtitle}}": html.escape(subtitle),
        "{{summary}}": _section_html(summary),
        "{{sections}}": "\n".join(_section_html(s) for s in sections),
        "{{viewer_script}}": _asset("viewer.js"),
        # "</" must not close the inline script early.
        "{{viewer_data}}": geometry.replace("</", "<\\/"),
    }
    for key, value in replacements.items():
        page = page.replace(key, value)
    return page


def figure_from_file(path: Path, caption: str, name: str | None = None, *, wide: bool = False) -> Figure | None:
    """A Figure from a PNG file, or None when the file does not exist."""
    path = Path(path)
    if not path.is_file():
        return None
    return Figure(name=name or path.stem, caption=caption, png=path.read_bytes(), wide=wide)
