"""The command line: bad input ends with exit code 2 and one message, never a traceback."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from workflow.cli import main


def _run(capsys, *argv):
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_missing_project_file(capsys, tmp_path):
    code, out, err = _run(capsys, "run", str(tmp_path / "nope.toml"))
    assert code == 2 and "does not exist" in err and "Traceback" not in err


def test_bad_key_in_project(capsys, tmp_path):
    path = tmp_path / "p.toml"
    path.write_text('[surface]\ntemplate = "cap"\ncolour = "red"\n')
    code, out, err = _run(capsys, "validate", str(path))
    assert code == 2 and "surface.colour" in err and "p.toml" in err


def test_bad_mesh(capsys, tmp_path):
    path = tmp_path / "bad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    code, out, err = _run(capsys, "run", "--surface", str(path), "--out", str(tmp_path / "o"), "--quiet")
    assert code == 2 and "NaN" in err and "Traceback" not in err


def test_empty_selection(capsys, tmp_path):
    path = tmp_path / "p.toml"
    path.write_text('[surface]\ntemplate = "hypar"\n'
                    '[[supports]]\nselect = "box"\nlower = [50, 50, 0]\nupper = [60, 60, 1]\n')
    code, out, err = _run(capsys, "run", str(path), "--out", str(tmp_path / "o"), "--quiet")
    assert code == 2 and "supports[0]" in err and "matched no node" in err


def test_flagged_without_red_vertices(capsys, tmp_path):
    path = tmp_path / "roof.obj"
    from engine.geometry.parametric import hypar

    hypar(divisions=4).to_trimesh().export(path)
    code, out, err = _run(capsys, "run", "--surface", str(path), "--supports", "flagged",
                          "--out", str(tmp_path / "o"), "--quiet")
    assert code == 2 and "flagged" in err and "red" in err


def test_contradictory_options(capsys, tmp_path):
    code, out, err = _run(capsys, "run", "p.toml", "--surface", "x.obj")
    assert code == 2 and "not both" in err
    code, out, err = _run(capsys, "run", "--until", "nonsense", "--out", str(tmp_path / "o"), "--quiet")
    assert code == 2 and "unknown stage" in err


def test_debug_shows_the_traceback(tmp_path):
    result = subprocess.run([sys.executable, "-m", "workflow.cli", "--debug", "run", str(tmp_path / "nope.toml")],
                            capture_output=True, text=True)
    assert result.returncode != 0 and "Traceback" in result.stderr


def test_init_writes_a_valid_project(capsys, tmp_path):
    code, out, err = _run(capsys, "init", str(tmp_path / "job"), "--template", "courtyard")
    assert code == 0
    code, out, err = _run(capsys, "validate", str(tmp_path / "job" / "project.toml"))
    assert code == 0 and "valid" in out
    code, out, err = _run(capsys, "init", str(tmp_path / "job"), "--template", "courtyard")
    assert code == 2 and "already exists" in err
    code, out, err = _run(capsys, "init", str(tmp_path / "job2"), "--template", "blob")
    assert code == 2 and "templates:" in err


def test_quick_start_surface_stage(capsys, tmp_path):
    from engine.geometry.parametric import vault

    path = tmp_path / "vault.stl"
    vault(divisions=8).to_trimesh().export(path)
    out_dir = tmp_path / "o"
    code, out, err = _run(capsys, "run", "--surface", str(path), "--out", str(out_dir), "--until", "surface", "--quiet")
    assert code == 0
    supports = json.loads((out_dir / "01-surface" / "supports.json").read_text())["supports"]
    assert len(supports) > 0 and all(flags == [1, 1, 1, 0, 0, 0] for flags in supports.values())
    assert (out_dir / "01-surface" / "surface.png").stat().st_size > 10_000
    manifest = json.loads((out_dir / "manifest.json").read_text())
    assert manifest["stages"][0]["status"] == "ran"


def test_default_job_surface_stage(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = _run(capsys, "run", "--until", "surface", "--quiet")
    assert code == 0 and (tmp_path / "out" / "mockup" / "01-surface" / "surface.ply").is_file()
    info = json.loads((tmp_path / "out" / "mockup" / "01-surface" / "surface.json").read_text())
    assert info["form_finding"]["equilibrium_residual"] < 1e-6
    import trimesh

    mesh = trimesh.load(tmp_path / "out" / "mockup" / "01-surface" / "surface.ply", process=False)
    assert np.ptp(mesh.vertices[:, 0]) == pytest.approx(2.4)


def _cli(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "workflow.cli", *args], capture_output=True, text=True, cwd=cwd)


def test_verbose_logs_why_each_stage_runs_or_is_cached(tmp_path):
    """-v logs each stage's reason to run (first run, a changed artifact) or its cache hit; -vv also
    its steps; without the flag nothing of it reaches stderr (the library's loggers have a
    NullHandler only)."""
    project, out = tmp_path / "job" / "project.toml", tmp_path / "o"
    assert _cli("init", str(project.parent), "--template", "cap").returncode == 0
    base = ("run", str(project), "--out", str(out), "--until", "shell", "--quiet")
    first = _cli("-v", *base)
    assert first.returncode == 0
    assert "workflow.runner: stage surface: runs (not run before" in first.stderr
    assert "stage shell: ran in" in first.stderr
    (out / "02-shell" / "shell.json").write_text("{}")                  # damaged: only the shell reruns
    second = _cli("-v", *base)
    assert "stage surface: cached" in second.stderr
    assert "stage shell: runs (02-shell/shell.json changed" in second.stderr
    quiet = _cli(*base, "--force")
    assert quiet.returncode == 0 and "workflow.runner" not in quiet.stderr and "engine." not in quiet.stderr
    steps = _cli("-vv", *base, "--force")
    assert "stage shell: solving" in steps.stderr and "engine.structure.solvers: factored" in steps.stderr


def test_the_library_logs_nothing_without_an_application_handler():
    """A warning from an engine module, with no logging configured, is swallowed by the package's
    NullHandler instead of Python's last-resort handler printing it."""
    code = ("import logging, engine.structure.solvers; "
            "logging.getLogger('engine.structure.solvers').warning('should not print'); "
            "import fabrication, workflow; logging.getLogger('workflow.runner').warning('nor this')")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0 and result.stderr == ""



def test_run_without_project_takes_the_folders_project_toml(capsys, tmp_path, monkeypatch):
    """`gridshell init DIR`, then `gridshell run` in DIR runs that project (here the cap, not the
    mock-up) to out/DIR; with no project.toml there, the mock-up runs (test above)."""
    import tomllib

    job = tmp_path / "myroof"
    assert _run(capsys, "init", str(job), "--template", "cap")[0] == 0
    monkeypatch.chdir(job)
    code, out, err = _run(capsys, "run", "--until", "surface", "--quiet")
    assert code == 0 and "no PROJECT given" in err
    manifest = json.loads((job / "out" / "myroof" / "manifest.json").read_text())
    cap = tomllib.loads((job / "project.toml").read_text())["project"]["name"]
    assert manifest["project_file"] == str((job / "project.toml").resolve())
    assert manifest["config"]["project"]["name"] == cap != "mockup"


def test_cells_and_set_replace_the_project_files_values_for_one_run(capsys, tmp_path):
    job = tmp_path / "job"
    assert _run(capsys, "init", str(job), "--template", "cap")[0] == 0
    written = (job / "project.toml").read_text()
    out_dir = tmp_path / "o"
    code, out, err = _run(capsys, "run", str(job), "--cells", "77", "--set", "field.max_size_ratio=1.5",
                          "--set", "section.diameter=60.3 mm", "--out", str(out_dir), "--until", "surface", "--quiet")
    assert code == 0, err
    config = json.loads((out_dir / "manifest.json").read_text())["config"]
    assert config["remesh"]["n_cells"] == 77
    assert config["field"]["max_size_ratio"] == 1.5
    assert config["section"]["diameter"] == pytest.approx(0.0603)  # "60.3 mm" read as text, then as a length
    assert (job / "project.toml").read_text() == written               # the file itself is not changed


def test_cells_on_a_quick_start_surface(capsys, tmp_path):
    from engine.geometry.parametric import vault

    path = tmp_path / "vault.stl"
    vault(divisions=8).to_trimesh().export(path)
    out_dir = tmp_path / "o"
    code, out, err = _run(capsys, "run", "--surface", str(path), "--cells", "45", "--out", str(out_dir),
                          "--until", "surface", "--quiet")
    assert code == 0, err
    assert json.loads((out_dir / "manifest.json").read_text())["config"]["remesh"]["n_cells"] == 45


@pytest.mark.parametrize("argv, says", [
    (["--set", "remesh.n_cellz=3"], "'remesh.n_cellz' is not a project key"),
    (["--set", "remesh"], "give KEY=VALUE"),
    (["--set", "remesh=3"], "'remesh' is not a project key"),          # a table, not a setting
    (["--set", "remesh.n_cells=many"], "--set remesh.n_cells='many'"),  # the project's validation, the flag named
    (["--cells", "0"], "--cells 0"),
])
def test_bad_set_or_cells_exits_2_naming_the_flag(capsys, tmp_path, argv, says):
    job = tmp_path / "job"
    assert _run(capsys, "init", str(job), "--template", "cap")[0] == 0
    code, out, err = _run(capsys, "run", str(job), *argv, "--out", str(tmp_path / "o"), "--until", "surface",
                          "--quiet")
    assert code == 2 and says in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_parse_setting_reads_toml_values_and_keeps_other_text():
    from workflow.config import parse_setting

    assert parse_setting("remesh.n_cells=300") == ("remesh.n_cells", 300)
    assert parse_setting("field.max_size_ratio = 2.5") == ("field.max_size_ratio", 2.5)
    assert parse_setting('project.name="a b"') == ("project.name", "a b")
    assert parse_setting("section.thickness=3.2 mm") == ("section.thickness", "3.2 mm")


def test_validate_takes_the_same_settings_as_run(capsys, tmp_path):
    job = tmp_path / "job"
    assert _run(capsys, "init", str(job), "--template", "cap")[0] == 0
    project = str(job / "project.toml")
    assert _run(capsys, "validate", project, "--cells", "90", "--set", "field.max_size_ratio=1.5")[0] == 0
    code, out, err = _run(capsys, "validate", project, "--set", "field.max_size_ratio=-1")
    assert code == 2 and "--set field.max_size_ratio=-1" in err and "Traceback" not in err
