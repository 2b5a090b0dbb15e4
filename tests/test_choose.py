"""[design] choose = "best": gridshell run keeps the candidate with the highest lambda_NL_worst per
kg, judged here from each candidate's own analysis.json, and computes nothing twice."""

from __future__ import annotations

import json

import pytest

from .test_compare import _tiny_mockup


@pytest.mark.slow
def test_run_keeps_the_candidate_with_the_most_load_factor_per_kg(tmp_path, capsys):
    from workflow.cli import main

    project = _tiny_mockup(tmp_path / "job")
    text = project.read_text(encoding="utf-8")
    text += ('\n[design]\nchoose = "best"\n'
             'choose_from = { "field.max_size_ratio" = [1.0, 2.0], "remesh.seed" = [1, 2] }\n')
    project.write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    assert main(["run", str(project), "--out", str(out), "--until", "analysis", "--quiet"]) == 0
    choice = json.loads((out / "choose" / "choice.json").read_text())
    assert len(choice["candidates"]) == 4
    # the best by the candidates' own files, not by what choice.json says of them
    scores = {}
    for candidate in choice["candidates"]:
        figures = json.loads((out / "choose" / "points" / f"{candidate['point']:04d}" / "06-analysis"
                              / "analysis.json").read_text())
        passes = all(v["pass"] for v in figures["verdicts"])
        scores[candidate["point"]] = (passes, figures["lambda_NL_worst"] / figures["beam_mass_kg"])
    best = max(scores, key=lambda p: scores[p])
    assert choice["chosen"]["point"] == best
    # the run went on with the chosen values, from the chosen point's stages (same inode: not recomputed)
    manifest = json.loads((out / "manifest.json").read_text())
    for key, value in choice["chosen"]["values"].items():
        section, name = key.split(".")
        assert manifest["config"][section][name] == value
    point = out / "choose" / "points" / f"{best:04d}"
    assert ((out / "06-analysis" / "analysis.json").stat().st_ino
            == (point / "06-analysis" / "analysis.json").stat().st_ino)
    statuses = {s["name"]: s["status"] for s in manifest["stages"]}
    assert statuses["analysis"] in ("ran", "cached")
    capsys.readouterr()
