"""Iterated statics-awareness: a project remeshed again under the field of its own beam forces."""

from __future__ import annotations

import json
import re

from workflow.cli import main
from workflow.config import load_project
from workflow.stages import remesh as remesh_stage


def test_a_cap_with_two_statics_rounds_runs_to_the_analysis(tmp_path, capsys):
    assert main(["init", str(tmp_path / "x"), "--template", "cap"]) == 0
    path = tmp_path / "x" / "project.toml"
    text = re.sub(r"(?m)^n_cells = \d+$", "n_cells = 40\nstatics_rounds = 2", path.read_text())
    path.write_text(re.sub(r"(?m)^\[analysis\]$", "[analysis]\nnonlinear = false", text))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--until", "analysis", "--quiet"]) == 0
    remesh = json.loads((out / "04-remesh" / "remesh.json").read_text())
    rounds = remesh["statics_rounds"]
    assert [r["round"] for r in rounds] == [1, 2] and [r["field"] for r in rounds] == ["shell", "beam forces"]
    assert all(abs(r["cells"] / 40 - 1) <= 0.12 for r in rounds)  # symmetric: cells come in mirror orbits
    assert 0.8 < rounds[1]["total_length_m"] / rounds[0]["total_length_m"] < 1.25
    assert (out / "04-remesh" / "field_round_2.png").stat().st_size > 0
    # the optimiser follows the field the grid was made under: the remesh's result carries it,
    # the same when loaded from a cached run
    loaded = remesh_stage.load(out / "04-remesh", load_project(path))
    field = loaded.rounds_field
    assert field is not None and field.size.min() == 1.0 and field.anisotropy.max() <= 2.0 + 1e-12
    shell_field = object()
    assert loaded.field(shell_field) is field  # type: ignore[arg-type]
    single = remesh_stage.RemeshedGrid(loaded.polymesh)
    assert single.field(shell_field) is shell_field  # type: ignore[arg-type]
    analysis = json.loads((out / "06-analysis" / "analysis.json").read_text())
    assert analysis["lambda_LB"] is not None and analysis["lambda_NL_worst"] is None
    manifest = json.loads((out / "manifest.json").read_text())
    assert {s["name"]: s["status"] for s in manifest["stages"]}["analysis"] == "ran"
