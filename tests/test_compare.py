"""``gridshell compare``: a grid that cannot be built or analysed is a failed row, the others are
compared, and the command ends with its table (exit 0), never with a traceback."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine.errors import InputError, MechanismError

#: the columns of compare.csv before status and message were added (docs/formats.md): kept, in order
FIRST_COLUMNS = ["grid", "nodes", "beams", "L_tot_m", "weight_kg", "delta_L_mm", "lambda_LB", "lambda_NL_perfect",
                 "lambda_NL_worst", "worst_shape", "limit_point", "knock_down"]

HEIGHT_FIELD = "the reference grids need a surface that is a height field over its plan"


def _tiny_mockup(folder: Path) -> Path:
    """The mock-up template at 14 cells, 3 modes and two imperfection shapes (a few seconds)."""
    import templates

    text = (Path(templates.__file__).parent / "mockup.toml").read_text(encoding="utf-8")
    for old, new in [("divisions = 24", "divisions = 12"), ("n_cells = 60", "n_cells = 14"),
                     ("lloyd_iterations = 80 ", "lloyd_iterations = 30 "),
                     ("elements_per_beam = 4", "elements_per_beam = 2"),
                     ("n_modes = 6", 'n_modes = 3\nimperfection_shapes = ["linear", "mode1"]\nworkers = 1')]:
        assert old in text, old
        text = text.replace(old, new, 1)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "project.toml").write_text(text, encoding="utf-8")
    return folder / "project.toml"


@pytest.fixture(scope="module")
def optimised(tmp_path_factory):
    """The tiny mock-up run up to optimize: (project file, output folder), shared by the tests."""
    from workflow.config import load_project
    from workflow.progress import Progress
    from workflow.runner import run_project
    from workflow.stages import STAGES

    folder = tmp_path_factory.mktemp("compare")
    project_file = _tiny_mockup(folder)
    out = folder / "out"
    summary = run_project(load_project(project_file), out, STAGES, until="optimize", progress=Progress(enabled=False))
    assert summary.message is None, summary.message
    return project_file, out


def test_a_grid_whose_protocol_raises_is_a_failed_row_and_the_others_are_computed(optimised, monkeypatch):
    from engine.remeshing import grids
    from workflow import compare
    from workflow.config import load_project

    project_file, out = optimised
    project = load_project(project_file)
    surface = compare._load_stage(project, out, "surface")
    voronoi = compare._load_stage(project, out, "optimize").polymesh
    built = {}
    real_quad, real_protocol = grids.quad_grid, compare._protocol

    def quad_grid(*args, **kwargs):
        built["quad"] = real_quad(*args, **kwargs)
        return built["quad"]

    def protocol(polymesh, *args, **kwargs):
        if polymesh is built.get("quad"):
            raise MechanismError("the frame is a mechanism: its supports leave 2 rigid-body mode(s) free",
                                 n_modes=2, hint="support more nodes or restrain more directions")
        return real_protocol(polymesh, *args, **kwargs)

    monkeypatch.setattr(grids, "quad_grid", quad_grid)
    monkeypatch.setattr(compare, "_protocol", protocol)
    results = compare.compare_grids(project, surface, voronoi, grids=("triangular", "quad", "voronoi"))
    assert list(results) == ["triangular", "quad", "Voro(2,2)"]
    grid, row = results["quad"]
    assert row.status == "failed" and grid is built["quad"]
    assert row.message == ("quad grid not analysed: the frame is a mechanism: its supports leave 2 rigid-body "
                           "mode(s) free; support more nodes or restrain more directions")
    assert "\n" not in row.message
    # the failed grid keeps what does not need the analysis: its size and length
    assert row.values["nodes"] == grid.n_nodes and row.values["L_tot_m"] == pytest.approx(grid.total_length)
    assert "lambda_LB" not in row.values and not row.curves
    for label in ("triangular", "Voro(2,2)"):
        grid, row = results[label]
        assert row.status == "ok" and row.message == ""
        assert row.values["lambda_LB"] > 0 and np.isfinite(row.values["delta_L_mm"])
        assert row.values["L_tot_m"] == pytest.approx(voronoi.total_length, rel=0.01)


def test_compare_exits_0_with_the_table_when_a_grid_cannot_be_built(optimised, monkeypatch, capsys):
    """As on BubbleShell (overhangs): the triangles cannot be built; the quad and Voronoi rows are
    computed, the table and the picture written, the triangles' row says why and what to do."""
    import pandas as pd

    from engine.remeshing import grids
    from workflow.cli import main

    def refuse(*_args, **_kwargs):
        raise InputError(HEIGHT_FIELD, hint="compare on a surface without overhangs or vertical parts")

    project_file, out = optimised
    stale = out / "compare" / "triangular.obj"
    stale.parent.mkdir(exist_ok=True)
    stale.write_text("# an older run's grid\n")
    monkeypatch.setattr(grids, "triangular_grid", refuse)
    assert main(["compare", str(project_file), "--out", str(out), "--quiet", "--grids", "triangular,quad,voronoi"]) == 0
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err + captured.out
    assert "triangular grid not built" in captured.err
    table = pd.read_csv(out / "compare" / "compare.csv")
    assert list(table.columns[:len(FIRST_COLUMNS)]) == FIRST_COLUMNS
    # status and message come next; the sizing's columns after them (empty without [design] sizing)
    assert list(table.columns[len(FIRST_COLUMNS):len(FIRST_COLUMNS) + 2]) == ["status", "message"]
    rows = table.set_index("grid")
    assert list(rows["status"]) == ["failed", "ok", "ok"]
    message = rows.loc["triangular", "message"]
    assert message.startswith("triangular grid not built: " + HEIGHT_FIELD) and "without overhangs" in message
    assert np.isnan(rows.loc["triangular", "lambda_LB"]) and rows.loc["quad", "lambda_LB"] > 0
    assert rows["message"].isna()[["quad", "Voro(2,2)"]].all()
    markdown = (out / "compare" / "compare.md").read_text()
    assert "Not compared" in markdown and message in markdown
    assert (out / "compare" / "response.png").stat().st_size > 2000
    assert not stale.exists(), "no grid file from an older run beside a failed row"
    assert (out / "compare" / "quad.obj").is_file()


def test_compare_grids_picks_the_rows_and_builds_the_control_and_the_statics_quads(optimised, capsys):
    """--grids: the 45-degree squares, the statics-aware quads and the isotropic control beside the
    Voronoi grid, each of its length within 1 %, in the table's order whatever the list's."""
    import pandas as pd

    from workflow.cli import main

    project_file, out = optimised
    assert main(["compare", str(project_file), "--out", str(out), "--quiet",
                 "--grids", "voronoi,isotropic,statics_quad,quad45"]) == 0
    assert "Traceback" not in capsys.readouterr().err
    table = pd.read_csv(out / "compare" / "compare.csv")
    assert list(table.columns[:len(FIRST_COLUMNS)]) == FIRST_COLUMNS
    assert list(table["grid"]) == ["quad45", "statics quad", "isotropic", "Voro(2,2)"]
    assert list(table["status"]) == ["ok"] * 4, list(table["message"])
    voronoi = table.set_index("grid").loc["Voro(2,2)", "L_tot_m"]
    assert np.allclose(table["L_tot_m"], voronoi, rtol=0.01)
    assert (table["lambda_LB"] > 0).all()
    assert (out / "compare" / "statics_quad.obj").is_file() and (out / "compare" / "isotropic.obj").is_file()
    assert main(["compare", str(project_file), "--out", str(out), "--quiet", "--grids", "hexagons"]) == 2
    assert "no grid called 'hexagons'" in capsys.readouterr().err


@pytest.mark.slow
def test_compare_on_the_courtyard_template(tmp_path, capsys):
    """The courtyard (an outline with a hole) at 60 cells: the three grids are compared, and the
    reference grids written have no beam under 5 % of their median (near-zero beams where lattice
    lines met the outline made the frame numerically singular)."""
    import pandas as pd

    from workflow.cli import main

    assert main(["init", str(tmp_path / "roof"), "--template", "courtyard"]) == 0
    project_file = tmp_path / "roof" / "project.toml"
    text = project_file.read_text()
    assert "n_cells = 150" in text
    project_file.write_text(text.replace("n_cells = 150", "n_cells = 60"))
    out = tmp_path / "out"
    assert main(["compare", str(project_file), "--out", str(out), "--quiet", "--grids", "triangular,quad,voronoi"]) == 0
    assert "Traceback" not in capsys.readouterr().err
    table = pd.read_csv(out / "compare" / "compare.csv")
    assert list(table["status"]) == ["ok", "ok", "ok"]
    for name in ("triangular", "quad"):
        lengths = _obj_beam_lengths(out / "compare" / f"{name}.obj")
        assert lengths.min() >= 0.05 * np.median(lengths), name


def _obj_beam_lengths(path: Path) -> np.ndarray:
    """Unique edge lengths of a polygon OBJ, read independently of the product's reader."""
    nodes, edges = [], set()
    for line in path.read_text().splitlines():
        parts = line.split()
        if parts and parts[0] == "v":
            nodes.append([float(c) for c in parts[1:4]])
        elif parts and parts[0] == "f":
            ids = [int(p.split("/")[0]) - 1 for p in parts[1:]]
            edges.update(tuple(sorted(e)) for e in zip(ids, ids[1:] + ids[:1]))
    nodes = np.array(nodes)
    pairs = np.array(sorted(edges))
    return np.linalg.norm(nodes[pairs[:, 1]] - nodes[pairs[:, 0]], axis=1)


@pytest.mark.slow
def test_compare_sizes_each_grid_and_the_voronoi_row_weighs_what_run_sizes(tmp_path, capsys):
    """--size-sections: every grid's tubes pass their checks, and the Voronoi row's sized mass is
    the mass that gridshell run's sized analysis finds on the same grid."""
    import json

    import pandas as pd

    import templates
    from workflow.cli import main

    text = (Path(templates.__file__).parent / "cap.toml").read_text(encoding="utf-8")
    text = text.replace("n_cells = 150", "n_cells = 40")
    assert "n_cells = 40" in text
    text += '\n[design]\nsize_sections = true\n'
    text = text.replace("[analysis]\n", '[analysis]\nimperfection_shapes = ["linear", "mode1"]\nn_modes = 3\n', 1)
    project = tmp_path / "project.toml"
    project.write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    assert main(["compare", str(project), "--out", str(out), "--quiet", "--grids", "triangular,quad,voronoi"]) == 0
    table = pd.read_csv(out / "compare" / "compare.csv")
    assert list(table.columns[:len(FIRST_COLUMNS)]) == FIRST_COLUMNS
    ok = table[table["status"] == "ok"]
    assert len(ok) == 3 and ok["all_checks_pass"].all() and (ok["max_utilisation"] <= 1.0).all()
    assert main(["run", str(project), "--out", str(out), "--until", "analysis", "--quiet"]) == 0
    design = json.loads((out / "06-analysis" / "analysis.json").read_text())["design"]
    voronoi = ok[ok["grid"].str.startswith("Voro")].iloc[0]
    assert voronoi["sized_mass_kg"] == pytest.approx(design["mass_after_kg"], rel=1e-6)
    capsys.readouterr()
