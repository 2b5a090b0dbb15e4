"""The report page: self-contained HTML, and in headless Chromium no console errors, every image
loads and the 3D view draws."""

from __future__ import annotations

import io
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from workflow.report import Figure, Section, Table, Viewer, render_report

from .browser import ARTIFACTS, check_page, chromium_driver


def _png(colour: str) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2, 1.5), dpi=60)
    ax.plot([0, 1], [0, 1], color=colour)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    plt.close(fig)
    return buffer.getvalue()


def _hexagon_patch():
    angles = np.arange(6) * np.pi / 3
    ring = np.c_[np.cos(angles), np.sin(angles), 0.2 * np.ones(6)]
    nodes = np.vstack([ring, [[2.0, 0.0, 0.0]]])
    beams = np.array([[i, (i + 1) % 6] for i in range(6)] + [[0, 6]])
    return nodes, beams, [np.arange(6)]


class _Collector(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.sources: list[str] = []
        self.links: list[str] = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag in ("img", "script") and attrs.get("src"):
            self.sources.append(attrs["src"])
        if tag == "link" and attrs.get("href"):
            self.links.append(attrs["href"])


def _page() -> str:
    nodes, beams, panels = _hexagon_patch()
    summary = Section(title="Summary", tables=[Table(name="verdicts", caption="Verdicts",
                                                     columns=["check", "value", "result"],
                                                     rows=[["utilisation", 0.5, True], ["lambda_LB", 1.2, False]],
                                                     verdict_column="result")])
    sections = [Section(title="Figures </script> & <b>escapes</b>",
                        figures=[Figure(name="a", caption="first", png=_png("red")),
                                 Figure(name="b", caption="second", png=_png("blue"))])]
    viewer = Viewer(nodes=nodes, beams=beams, panels=panels, supports=np.array([1, 0, 0, 0, 0, 0, 1], bool),
                    beam_values=np.linspace(-1, 1, len(beams)))
    return render_report(title="Test <report>", subtitle="unit", summary=summary, sections=sections, viewer=viewer)


def test_page_is_self_contained_and_escaped():
    page = _page()
    collector = _Collector()
    collector.feed(page)
    assert collector.sources, "the page has images"
    assert all(s.startswith("data:image/png;base64,") for s in collector.sources)
    assert not collector.links
    assert "http://" not in page and "https://" not in page
    assert "Test &lt;report&gt;" in page and "&lt;b&gt;escapes&lt;/b&gt;" in page
    assert 'class="pass">pass<' in page and 'class="fail">FAIL<' in page
    assert "{{" not in page


@pytest.mark.browser
def test_synthetic_report_in_chromium(tmp_path: Path):
    page = tmp_path / "report.html"
    page.write_text(_page(), encoding="utf-8")
    driver = chromium_driver()
    try:
        state = check_page(driver, page, ARTIFACTS / "report_synthetic.png")
    finally:
        driver.quit()
    assert state["errors"] == []
    assert len(state["images"]) == 2
    assert all(complete and width > 0 for _, complete, width in state["images"])
    width, height, ink = state["canvas"]
    assert width > 100 and height > 100
    assert ink > 200, "the 3D view drew its beams and panels"


@pytest.mark.slow
@pytest.mark.browser
def test_report_of_a_small_project_in_chromium(small_run):
    _, out = small_run
    page = out / "report.html"
    assert page.is_file()
    assert (out / "report" / "figures").is_dir() and list((out / "report" / "figures").glob("*.png"))
    assert list((out / "report" / "tables").glob("*.csv"))
    driver = chromium_driver()
    try:
        state = check_page(driver, page, ARTIFACTS / "report_small_project.png")
    finally:
        driver.quit()
    assert state["errors"] == []
    assert len(state["images"]) >= 8
    assert all(complete and width > 0 for _, complete, width in state["images"])
    assert state["canvas"][2] > 500
    # the text as the reader sees it: no raw keys, no e-notation; sections numbered 1, 2, 3, ...
    assert RAW_TEXT.findall(state["text"]) == []
    numbers = [int(m[1]) for m in map(re.compile(r"(\d+)\. ").match, state["headings"]) if m]
    assert len(numbers) >= 6 and numbers == list(range(1, len(numbers) + 1)), state["headings"]
    # the modes, the assembly and the sheets across the page; the other pictures in columns
    widths = {name: (width, row) for name, width, row in state["figures"]}
    for name in ("figure-06-analysis-modes", "figure-07-fabrication-assembly-steps_strip",
                 "figure-07-fabrication-panels-sheets"):
        assert widths[name][0] >= 0.98 * widths[name][1], (name, widths[name])
    assert widths["figure-06-analysis-axial"][0] < 0.6 * widths["figure-06-analysis-axial"][1]


#: What a raw key or a computer's number looks like in the page's text: a word ending in a unit
#: suffix (max_displacement_m, N1_max_N_per_m, planarity_max_mm) or a number in e-notation.
RAW_TEXT = re.compile(r"\b\w+_(?:m|mm|N|kN|N_per_m|kg|deg|m2|mm2|Pa|MPa|s)\b|_N_per_m|\d[eE][+-]?\d")


class _Cells(HTMLParser):
    """Every table cell's text and every link of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.cells: list[str] = []
        self.hrefs: list[str] = []
        self._in_cell = False

    def handle_starttag(self, tag, attrs):
        if tag in ("td", "th"):
            self._in_cell = True
            self.cells.append("")
        if tag == "a" and dict(attrs).get("href"):
            self.hrefs.append(dict(attrs)["href"])

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self._in_cell = False

    def handle_data(self, data):
        if self._in_cell:
            self.cells[-1] += data


def _json_keys(value, into: set[str]) -> set[str]:
    if isinstance(value, dict):
        into.update(value)
        for v in value.values():
            _json_keys(v, into)
    elif isinstance(value, list):
        for v in value:
            _json_keys(v, into)
    return into


def test_the_report_reads_like_an_engineers_no_raw_keys_no_e_notation_and_its_links_work(small_run):
    """Every table cell of the small job's report: none is a key of the stages' JSON (the labels
    are words with units), no number is written 1.2e-07, and every link opens a file of the run."""
    import json
    import re

    _, out = small_run
    parser = _Cells()
    parser.feed((out / "report.html").read_text(encoding="utf-8"))
    keys: set[str] = set()
    for path in out.glob("*/*.json"):
        _json_keys(json.loads(path.read_text(encoding="utf-8")), keys)
    keys = {k for k in keys if "_" in k}  # one-word keys ("nodes") are words
    assert len(parser.cells) > 100
    raw = sorted({c.strip() for c in parser.cells} & keys)
    assert raw == [], f"raw keys in the report: {raw}"
    scientific = [c for c in parser.cells if re.search(r"\d[eE][+-]?\d", c)]
    assert scientific == []
    assert [c for c in parser.cells if "lambda_" in c] == [], "a symbol written as its key"
    # a column of zeros that stand for "not classified" (the simplified checks) is left out
    import pandas as pd

    classes = pd.read_csv(out / "06-analysis" / "members.csv").get("section_class")
    if classes is not None and not classes.any():
        assert not any(c.startswith("section class") for c in parser.cells)
    assert parser.hrefs and all((out / href).is_file() for href in parser.hrefs), parser.hrefs
    assert not (out / "report" / "report.html").exists(), "one report page"


def _tables(page: str) -> list[list[list[str]]]:
    """Every table of a page as rows of cell texts, the header row first."""
    import html as html_lib

    tables = []
    for table in re.findall(r"<table.*?</table>", page, re.S):
        rows = [[html_lib.unescape(re.sub(r"<[^>]+>", "", cell)).strip()
                 for cell in re.findall(r"<t[dh][^>]*>(.*?)</t[dh]>", row, re.S)]
                for row in re.findall(r"<tr.*?</tr>", table, re.S)]
        tables.append([row for row in rows if row])
    return tables


def test_each_quantity_of_the_report_has_one_unit(small_run):
    """A column's header names one unit; a table with a unit column gives each row's. Across the
    whole report a quantity is always in the same unit (not planarity in m here and mm there)."""
    _, out = small_run
    tables = _tables((out / "report.html").read_text(encoding="utf-8"))
    assert len(tables) >= 8
    units: dict[str, set[str]] = {}
    for header, *rows in tables:
        assert all(len(re.findall(r"\(([^()]*)\)", h)) <= 1 for h in header), header
        for h in header:
            named = re.fullmatch(r"(.+?) \(([^()]*(?:m|g|N|deg|%|Pa|m\^?2))\)", h)
            if named:
                units.setdefault(named[1], set()).add(named[2])
        if "unit" in header:
            unit = header.index("unit")
            for row in rows:
                units.setdefault(row[0], set()).add(row[unit])
    assert len(units) > 30
    assert {k: v for k, v in units.items() if len(v) > 1} == {}


@pytest.mark.parametrize("value, page, terminal", [
    (1234567, "1\u202f234\u202f567", "1 234 567"), (0.0368, "0.0368", "0.0368"),
    (9.937e-07, "9.94 \u00d7 10\u207b\u2077", "9.94e-07"), (203.2, "203", "203"), (float("inf"), "\u221e", "inf"),
    (None, "-", "-"), (True, "yes", "yes")])
def test_one_number_format_for_the_report_and_the_terminal(value, page, terminal):
    """The report and the run's last lines write numbers the same way; the terminal's in ASCII."""
    from workflow.labels import format_value

    assert format_value(value) == page
    assert format_value(value, text=True) == terminal and terminal.isascii()


def test_a_finding_that_counts_parts_reads_as_a_whole_number_and_a_length_keeps_its_decimals():
    """A finding's measure in beams or cells is written "63", not "63.0", in its JSON and in the
    report's findings table; a length measure stays a float."""
    import json

    from engine.findings import Finding, findings_table
    from workflow.report import _format

    removed = Finding(kind="beams_removed", parts=["grid"], measure=63.0, limit=0.0, unit="beams").to_dict()
    coarsened = Finding(kind="grid_coarsened", parts=["grid"], measure=np.int64(412), limit=1500.0, unit="cells")
    cut = Finding(kind="cut_length", parts=["B0007"], measure=117.5, limit=120.0, unit="mm").to_dict()
    rows = findings_table(json.loads(json.dumps([removed, coarsened.to_dict(), cut])))
    shown = {row["kind"]: (_format(row["worst"]), _format(row["limit"])) for row in rows}
    assert shown == {"beams_removed": ("63", "0"), "grid_coarsened": ("412", "1\u202f500"),
                     "cut_length": ("118", "120")}
    assert isinstance(removed["measure"], int) and isinstance(cut["measure"], float)


def test_the_findings_table_gives_lengths_in_millimetres_as_the_verdicts_do():
    """A deflection found in metres reads 5 976 against 76.4 mm in the findings table, the unit of
    the same check in the verdicts table; counts and load factors are left as they are."""
    from engine.findings import Finding
    from workflow.stages.report import _in_mm, findings_rows

    deflection = Finding(kind="deflection", parts=["N0023"], measure=5.976, limit=0.0764, unit="m").to_dict()
    buckling = Finding(kind="buckling", parts=["mode 1"], measure=0.0157, limit=1.5).to_dict()
    rows = {row[0]: row[2:5] for row in findings_rows([deflection, buckling])}
    assert rows["deflection"] == [pytest.approx(5976.0), pytest.approx(76.4), "mm"]
    assert rows["deflection"] == list(_in_mm(5.976, 0.0764, "m"))  # the verdicts' conversion
    assert rows["buckling"] == [0.0157, 1.5, ""]


def test_the_report_says_where_each_imperfect_paths_load_factor_was_read(small_run):
    """The imperfection table's 'read at' follows analysis.json: a limit point, the tolerable
    deflection reached first, or the highest load factor carried."""
    import json

    _, out = small_run
    analysis = json.loads((out / "06-analysis" / "analysis.json").read_text(encoding="utf-8"))
    expected = {i["shape"]: ("limit point" if i["limit_point"] else "tolerable deflection"
                             if i["tolerable_deflection_reached"] else "highest carried")
                for i in analysis["imperfections"]}
    tables = _tables((out / "report.html").read_text(encoding="utf-8"))
    (table,) = [t for t in tables if t[0][:3] == ["imperfection", "non-linear load factor", "read at"]]
    assert {row[0]: row[2] for row in table[1:]} == expected
    assert analysis["tolerable_deflection_m"] > 0


def test_the_job_table_says_what_each_load_case_holds():
    from workflow.config import LoadCaseSpec
    from workflow.stages.report import load_case_text

    dead = LoadCaseSpec(self_weight=1.0, panels=1.0, area_true="0.25 kN/m^2")
    assert load_case_text("dead", dead, 245.25) == "dead (beams' weight, panels 245 N/m^2, 250 N/m^2 per true area)"
    assert load_case_text("dead", dead, 0.0) == "dead (beams' weight, 250 N/m^2 per true area)"  # panels off
    wind = LoadCaseSpec(area_true=[300.0, 0.0, 100.0])
    assert load_case_text("wind", wind, 245.25) == "wind ([300, 0, 100] N/m^2 per true area)"
    snow = LoadCaseSpec(area_plan="1 kN/m^2", self_weight=1.35)
    assert load_case_text("snow", snow, 245.25) == "snow (beams' weight x 1.35, 1000 N/m^2 on plan)"


def test_the_job_table_gives_a_section_as_its_designation_reads():
    """A tube D x t, a hollow rectangle h x b x t (it read "4.8 mm x 120 mm x 72 mm"), a solid
    rectangle h x b."""
    from workflow.config import SectionConfig
    from workflow.stages.report import section_text

    assert section_text(SectionConfig(kind="circular_hollow", diameter="48.3 mm", thickness="2.5 mm")) == \
        "circular_hollow 48.3 mm x 2.5 mm"
    assert section_text(SectionConfig(kind="rectangular_hollow", height="120 mm", width="72 mm",
                                      thickness="4.8 mm")) == "rectangular_hollow 120 mm x 72 mm x 4.8 mm"
    assert section_text(SectionConfig(kind="solid_rectangle", height="200 mm", width="100 mm")) == \
        "solid_rectangle 200 mm x 100 mm"


def test_the_job_table_says_which_tube_the_grid_was_made_again_for():
    """OUT/fitted_grid.json as the courtyard template wrote it with size_sections and
    fit_grid_to_tubes, and a record whose tubes still outgrew the grid."""
    from workflow.stages.report import fitted_grid_text

    fitted = {"rounds": [{"round": 1, "section_before": "CHS 114.3x6.3", "largest_sized": "CHS 193.7x5"},
                         {"round": 2, "section_before": "CHS 193.7x5", "largest_sized": "CHS 273x6.3"}],
              "section": "CHS 273x6.3", "section_mm": [273.0, 6.3], "largest_sized": "CHS 273x10", "fits": True}
    assert fitted_grid_text(fitted) == ("CHS 273x6.3: made again 2 times for the sized tubes "
                                        "(CHS 114.3x6.3 -> CHS 193.7x5 -> CHS 273x6.3)")
    once = {**fitted, "rounds": fitted["rounds"][:1], "section": "CHS 193.7x5", "largest_sized": "CHS 273x6.3",
            "fits": False}
    assert fitted_grid_text(once) == ("CHS 193.7x5: made again once for the sized tubes (CHS 114.3x6.3 -> "
                                      "CHS 193.7x5); CHS 273x6.3 sized larger still")


def test_a_value_beside_its_limit_never_reads_as_equal_to_it_when_it_is_not():
    """A cut of 359.6 mm against a limit of 360 mm is written with the digit that tells them apart
    (360.0 beside it), on the page's findings table and in the terminal's summary; equal values and those 3 digits
    already part keep 3 (an unseen 1500-cell dome's run said "360 mm (limit 360 mm)")."""
    import io

    from rich.console import Console

    from engine.findings import Finding
    from workflow.labels import format_against
    from workflow.progress import Progress
    from workflow.report import Table, _table_html

    assert format_against(359.6, 360.0) == ("359.6", "360.0")
    assert format_against(359.96, 360.0, text=True) == ("359.96", "360.00")
    assert format_against(1.6, 1.0) == ("1.60", "1.00")
    assert format_against(360.0, 360.0) == ("360", "360")
    assert format_against(None, 1.0) == ("-", "1.00")
    table = Table(name="findings", caption="", columns=["kind", "count", "worst", "limit", "unit"],
                  rows=[["cut length", 1, np.float64(359.6), 360.0, "mm"]])
    assert "<td>359.6</td><td>360.0</td>" in _table_html(table)
    progress = Progress(enabled=True)
    progress._console = Console(file=io.StringIO(), width=200)
    finding = Finding(kind="cut_length", parts=["B4105"], measure=359.6, limit=360.0, unit="mm").to_dict()
    progress.findings([finding])
    assert "359.6 mm (limit 360.0 mm)" in progress._console.file.getvalue()
