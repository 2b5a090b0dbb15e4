"""Issue 18, "trust every run": user mistakes are one message in TOML words, before any stage runs;
progress reaches pipes; buckling modes come out the same on every run."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from workflow.config import ConfigError, parse_project

INTERNALS = re.compile(r"function-|list\[|dict\[|<lambda>|Input should be a valid list|Settings\b|\bstr\b|\bfloat\b")


def _config_error(data: dict) -> list[str]:
    """The lines of the ConfigError a project dictionary raises, without its header and hint."""
    with pytest.raises(ConfigError) as info:
        parse_project(data)
    lines = str(info.value).splitlines()
    return [line.strip() for line in lines[1:] if not line.strip().startswith("hint:")]


# --- 2. unit errors: one line with the key, the value and a valid example -------------------------

@pytest.mark.parametrize("where, key, value, example", [
    ({"loads": {"cases": {"dead": {"area_true": "0.5 kN"}}}}, "loads.cases.dead.area_true", "'0.5 kN'",
     "'0.5 kN/m^2'"),
    ({"loads": {"cases": {"snow": {"area_plan": "1 kN/m"}}}}, "loads.cases.snow.area_plan", "'1 kN/m'",
     "'0.5 kN/m^2'"),
    ({"loads": {"cases": {"dead": {"area_true": [0, 0, "2 kN"]}}}}, "loads.cases.dead.area_true[2]", "'2 kN'",
     "'0.5 kN/m^2'"),
    ({"section": {"kind": "solid_round", "diameter": "5 kg"}}, "section.diameter", "'5 kg'", "'50 mm'"),
    ({"material": {"E": "210 m"}}, "material.E", "'210 m'", "'210 GPa'"),
    ({"material": {"density": "7850 kg"}}, "material.density", "'7850 kg'", "'7850 kg/m^3'"),
    ({"fabrication": {"sheets": {"sizes": [["1 m", "2 kg"]]}}}, "fabrication.sheets.sizes[0][1]", "'2 kg'",
     "'50 mm'"),
    ({"supports": [{"select": "nearest", "points": [[0, 0, "1 s"]]}]}, "supports[0].points[0][2]", "'1 s'",
     "'50 mm'"),
])
def test_a_unit_error_is_one_line_with_key_value_and_example(where, key, value, example):
    lines = _config_error({"surface": {"template": "cap"}, **where})
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"{key} = {value}:"), lines
    assert example in lines[0] and not INTERNALS.search(lines[0]), lines


def test_the_unit_error_names_what_the_unit_measures():
    """pint's dimensionality ("[mass] * [length] / [time] ** 2") is not shown; the kind in words is."""
    (line,) = _config_error({"surface": {"template": "cap"}, "loads": {"cases": {"dead": {"area_true": "0.5 kN"}}}})
    assert "force" in line and "area load" in line and "[mass]" not in line


@pytest.mark.parametrize("where, key, expected", [
    ({"loads": {"cases": {"dead": {"area_true": {"q": 1}}}}}, "loads.cases.dead.area_true", "a number or a list"),
    ({"supports": [{"select": "boundary", "restraint": 5}]}, "supports[0].restraint", "a text or a list"),
])
def test_a_value_no_branch_takes_gets_one_line_saying_what_is_allowed(where, key, expected):
    lines = _config_error({"surface": {"template": "cap"}, **where})
    assert len(lines) == 1 and lines[0].startswith(key) and expected in lines[0], lines
    assert not INTERNALS.search(lines[0]), lines


# --- 1. validate catches what run would reject; run says the same before any stage --------------

def _cli(capsys, *argv) -> tuple[int, str, str]:
    from workflow.cli import main

    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _project(tmp_path, text: str, name: str = "p.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def _validate_and_run(capsys, tmp_path, project) -> str:
    """validate and run of a bad project: both exit 2 with the same one message and no traceback,
    and run writes nothing (no stage ran)."""
    code, out, err = _cli(capsys, "validate", str(project))
    assert code == 2 and out == "" and "Traceback" not in err, (code, out, err)
    assert err.count("error:") == 1, err
    out_dir = tmp_path / "out"
    code, run_out, run_err = _cli(capsys, "run", str(project), "--out", str(out_dir), "--quiet")
    assert code == 2 and run_err == err, (run_err, err)
    assert not out_dir.exists()
    return err


def _mesh(path, scale: float = 1.0):
    """A 10 m hypar (engine.geometry.parametric) written to ``path`` with its coordinates times ``scale``."""
    from engine.geometry.parametric import hypar

    mesh = hypar(divisions=4).to_trimesh()
    mesh.apply_scale(scale)
    mesh.export(path)
    return path


def test_a_missing_surface_file_is_named_with_its_key_and_resolved_from_the_project_folder(
        capsys, tmp_path, monkeypatch):
    (tmp_path / "job").mkdir()
    project = _project(tmp_path / "job", '[surface]\nfile = "meshes/roof.obj"\n')
    monkeypatch.chdir(tmp_path)                          # not the project's folder
    err = _validate_and_run(capsys, tmp_path, project)
    assert "[surface] file" in err and str(tmp_path / "job" / "meshes" / "roof.obj") in err
    (tmp_path / "job" / "meshes").mkdir()
    _mesh(tmp_path / "job" / "meshes" / "roof.obj")
    code, out, err = _cli(capsys, "validate", str(project))
    assert code == 0 and "valid" in out and "10 m across" in out, (out, err)


@pytest.mark.parametrize("section, key", [
    ('diameter = "50 mm"\nthickness = "30 mm"', "diameter"),
    ('diameter = "50 mm"\nthickness = "25 mm"', "diameter"),
    ('kind = "rectangular_hollow"\nheight = "100 mm"\nwidth = "60 mm"\nthickness = "30 mm"', "width"),
])
def test_a_wall_not_thinner_than_half_the_section_is_caught_before_the_engine(capsys, tmp_path, section, key):
    project = _project(tmp_path, f'[surface]\ntemplate = "cap"\n[section]\n{section}\n')
    err = _validate_and_run(capsys, tmp_path, project)
    assert "section" in err and "thickness" in err and key in err and "lower thickness" in err


def test_the_wall_check_agrees_with_the_engine_section():
    """Just thinner than the radius passes both this check and engine.design.sections; the radius fails both."""
    from engine.design.sections import section_from_spec
    from engine.errors import InputError

    ok = parse_project({"surface": {"template": "cap"}, "section": {"diameter": 0.05, "thickness": 0.02499}})
    section_from_spec("circular_hollow", **ok.section.dimensions())
    with pytest.raises(InputError):
        section_from_spec("circular_hollow", diameter=0.05, thickness=0.025)
    (line,) = _config_error({"surface": {"template": "cap"}, "section": {"diameter": 0.05, "thickness": 0.025}})
    assert "thickness" in line and "diameter" in line


@pytest.mark.parametrize("section, key, fix", [
    ("diameter = 50\nthickness = \"3 mm\"", "section.diameter = 50", '"50 mm"'),
    ("diameter = \"50 mm\"\nthickness = 3", "section.thickness = 3", '"3 mm"'),
    ('kind = "solid_rectangle"\nheight = 300\nwidth = "100 mm"', "section.height = 300", '"300 mm"'),
])
def test_a_bare_millimetre_value_is_caught_as_metres(capsys, tmp_path, section, key, fix):
    project = _project(tmp_path, f'[surface]\ntemplate = "cap"\n[section]\n{section}\n')
    err = _validate_and_run(capsys, tmp_path, project)
    assert key in err and "bare numbers are metres" in err and f"write {fix}" in err


@pytest.mark.parametrize("section", ['diameter = 0.05\nthickness = 0.003', 'diameter = "50 m"\nthickness = "3 mm"',
                                     'kind = "solid_rectangle"\nheight = 1.2\nwidth = 0.2'])
def test_bare_metres_and_lengths_with_units_are_taken_as_given(section):
    import tomllib

    parse_project(tomllib.loads(f'[surface]\ntemplate = "cap"\n[section]\n{section}\n'))


@pytest.mark.parametrize("toml, line", [
    ('[section]\ndiameter = "50 m"\nthickness = "3 mm"',
     "section.diameter = 50 m is far outside the usual 5 mm to 1 m"),
    ('[material]\nE = "2100 GPa"', "material.E = 2100 GPa is far outside the usual 500 MPa to 500 GPa"),
    ('[loads.cases.snow]\narea_plan = [0, 0, "-800 kN/m^2"]',
     "loads.cases.snow.area_plan = 800 kN/m^2 is far outside"),
])
def test_a_quantity_far_outside_its_usual_range_is_a_warning_naming_the_key(capsys, tmp_path, toml, line):
    """validate passes (exit 0) and says so; run says the same before its first stage. (validate's
    notes, such as the one on a project loaded by self-weight alone, are progress in run: not under
    --quiet.)"""
    project = _project(tmp_path, f'[surface]\ntemplate = "cap"\n{toml}\n')
    code, out, err = _cli(capsys, "validate", str(project))
    assert code == 0 and "valid" in out, err
    assert err.count("warning:") == 1 and f"warning: {line}" in err and "check its value and unit" in err, err
    code, _, run_err = _cli(capsys, "run", str(project), "--out", str(tmp_path / "out"), "--until", "surface",
                            "--quiet")
    warnings = "".join(text for text in err.splitlines(keepends=True) if not text.startswith("note: "))
    assert code == 0 and run_err == warnings, run_err


def test_the_templates_and_the_defaults_give_no_warning():
    from workflow.config import load_project, unusual_values

    from .conftest import small_project

    templates = sorted((Path(__file__).resolve().parents[1] / "templates").glob("*.toml"))
    assert len(templates) >= 5
    assert {t.stem: unusual_values(load_project(t)) for t in templates} == {t.stem: [] for t in templates}
    assert unusual_values(parse_project({"surface": {"template": "cap"}})) == []
    assert unusual_values(small_project()) == []


def test_a_mesh_in_millimetres_read_as_metres_names_file_units(capsys, tmp_path):
    import trimesh

    mesh = _mesh(tmp_path / "roof.ply", scale=1000.0)           # 10 m modelled in mm: 10 000 units
    across = float(trimesh.load(mesh, process=False).extents.max())
    assert across == pytest.approx(10_000.0)
    project = _project(tmp_path, '[surface]\nfile = "roof.ply"\n')
    err = _validate_and_run(capsys, tmp_path, project)
    assert 'file_units = "mm"' in err and "10 km across" in err and "10 m" in err
    project = _project(tmp_path, '[surface]\nfile = "roof.ply"\nfile_units = "mm"\n')
    code, out, err = _cli(capsys, "validate", str(project))
    assert code == 0 and "10 m across" in out, err


def test_a_mesh_in_metres_read_as_millimetres_names_file_units(capsys, tmp_path):
    _mesh(tmp_path / "roof.obj")
    project = _project(tmp_path, '[surface]\nfile = "roof.obj"\nfile_units = "mm"\n')
    err = _validate_and_run(capsys, tmp_path, project)
    assert 'file_units = "m"' in err and "10 mm across" in err


def test_flagged_supports_on_a_mesh_without_red_vertices(capsys, tmp_path):
    _mesh(tmp_path / "roof.obj")
    project = _project(tmp_path, '[surface]\nfile = "roof.obj"\n[[supports]]\nselect = "flagged"\n')
    err = _validate_and_run(capsys, tmp_path, project)
    assert 'supports[0]: select = "flagged"' in err and "red" in err and 'select = "boundary"' in err


@pytest.mark.parametrize("selection, words", [
    ('select = "box"\nlower = [100, 100, 100]\nupper = [101, 101, 101]', "matched no node"),
    ('select = "ids"\nids = [99999]', "outside 0.."),
    ('select = "loop"\nloop = 3', "loop"),
])
def test_a_support_selection_matching_no_node_is_caught_by_validate(capsys, tmp_path, selection, words):
    """validate builds the surface (milliseconds for a template) and resolves the selections: it
    stops with the message the run's surface stage gives, before anything is written."""
    project = _project(tmp_path, f'[surface]\ntemplate = "cap"\n[[supports]]\n{selection}\n')
    code, out, err = _cli(capsys, "validate", str(project))
    assert code == 2 and out == "" and "Traceback" not in err and err.count("error:") == 1, err
    assert err.startswith("error: supports[0]: ") and words in err, err
    code, _, run_err = _cli(capsys, "run", str(project), "--out", str(tmp_path / "out"), "--quiet")
    assert code == 2 and run_err.splitlines()[0] == err.splitlines()[0], run_err
    code, out, err = _cli(capsys, "validate", str(_project(tmp_path, '[surface]\ntemplate = "cap"\n', "ok.toml")))
    assert code == 0 and "supported nodes" in out, err


@pytest.mark.parametrize("template", ["vault", "hypar"])
@pytest.mark.parametrize("divisions", [-1, 0, 1])
def test_too_few_divisions_of_a_template_is_one_message(capsys, tmp_path, template, divisions):
    """-1 divisions gave numpy's "negative dimensions are not allowed" as a traceback, 0 a mesh error."""
    project = _project(tmp_path, f'[surface]\ntemplate = "{template}"\n[surface.parameters]\n'
                                 f'divisions = {divisions}\n')
    code, out, err = _cli(capsys, "validate", str(project))
    assert code == 2 and "Traceback" not in err and err.count("error:") == 1, err
    assert f"divisions = {divisions} must be >= 2" in err
    code, _, run_err = _cli(capsys, "run", str(project), "--out", str(tmp_path / "out"), "--quiet")
    assert code == 2 and run_err.splitlines()[0] == err.splitlines()[0], run_err


# --- 4. the quick start speaks of its options, not of a project file ------------------------------

def _quick_start(capsys, tmp_path, *argv) -> str:
    out_dir = tmp_path / "out"
    code, out, err = _cli(capsys, "run", *argv, "--out", str(out_dir), "--quiet")
    assert code == 2 and "Traceback" not in err and err.count("error:") == 1, err
    assert not out_dir.exists()
    assert "project file" not in err and "supports = " not in err and "[[supports]]" not in err, err
    return err


def test_quick_start_missing_mesh(capsys, tmp_path):
    err = _quick_start(capsys, tmp_path, "--surface", str(tmp_path / "nope.obj"))
    assert "--surface" in err and "nope.obj" in err


def test_quick_start_flagged_without_red_vertices_says_the_option(capsys, tmp_path):
    _mesh(tmp_path / "roof.obj")
    err = _quick_start(capsys, tmp_path, "--surface", str(tmp_path / "roof.obj"), "--supports", "flagged")
    assert "--supports flagged" in err and "--supports boundary" in err and "red" in err


def test_quick_start_mesh_in_millimetres(capsys, tmp_path):
    _mesh(tmp_path / "roof.stl", scale=1000.0)
    err = _quick_start(capsys, tmp_path, "--surface", str(tmp_path / "roof.stl"))
    assert "--surface" in err and "10 km across" in err and "--surface-units mm" in err
    # with the unit given, the same mesh is 10 m across and passes the check
    from workflow.config import check_inputs, project_from_surface

    project = project_from_surface(tmp_path / "roof.stl", units="mm")
    assert check_inputs(project, quick_start=True) == pytest.approx(10.0)


def test_surface_units_need_a_surface(capsys, tmp_path):
    from workflow.cli import main

    assert main(["run", "--surface-units", "mm"]) == 2
    err = capsys.readouterr().err
    assert "--surface-units" in err and "file_units" in err and "Traceback" not in err


# --- a mesh exported with y up (Blender, SketchUp, glTF) stands on its side ------------------------

def _dome_y_up(path):
    """A generated dome (tests/generated_surfaces.py) written with y up: (x, y, z) -> (x, z, -y)."""
    import numpy as np
    import trimesh

    from tests.generated_surfaces import generate_surface

    surface = generate_surface(0)
    v = surface.vertices
    trimesh.Trimesh(np.stack([v[:, 0], v[:, 2], -v[:, 1]], axis=1), surface.faces, process=False).export(path)
    return surface


def test_a_mesh_with_y_up_is_refused_naming_up_axis(capsys, tmp_path):
    _dome_y_up(tmp_path / "roof.obj")
    err = _validate_and_run(capsys, tmp_path, _project(tmp_path, '[surface]\nfile = "roof.obj"\n'))
    assert "[surface] up_axis" in err and "stands on its side" in err and 'up_axis = "y"' in err
    err = _quick_start(capsys, tmp_path, "--surface", str(tmp_path / "roof.obj"))
    assert "--surface-up y" in err and "up_axis" not in err


def test_up_axis_turns_the_mesh_back_to_the_roof_it_was(capsys, tmp_path):
    """With up_axis = "y" the surface stage's mesh is the generated roof itself (a rotation keeps
    every vertex's distance; z is the height again)."""
    import numpy as np

    surface = _dome_y_up(tmp_path / "roof.obj")
    project = _project(tmp_path, '[surface]\nfile = "roof.obj"\nup_axis = "y"\n')
    code, out, err = _cli(capsys, "validate", str(project))
    assert code == 0, err
    from workflow.config import load_project
    from workflow.stages.surface import build_surface

    mesh, _ = build_surface(load_project(project))
    got = mesh.vertices[np.lexsort(mesh.vertices.T)]
    want = surface.vertices[np.lexsort(surface.vertices.T)]
    np.testing.assert_allclose(got, want, atol=1e-6)          # the OBJ keeps 8 digits


@pytest.mark.parametrize("up", ["z", "y", "x", "-z", "-y", "-x"])
def test_to_z_up_is_a_rotation_taking_the_axis_to_z(up):
    import numpy as np

    from engine.geometry.surfaces import to_z_up

    axis = {"x": [1, 0, 0], "y": [0, 1, 0], "z": [0, 0, 1]}[up[-1]]
    sign = -1.0 if up.startswith("-") else 1.0
    rotation = to_z_up(np.eye(3), up).T                     # columns: the images of e_x, e_y, e_z
    np.testing.assert_allclose(rotation @ (sign * np.array(axis, float)), [0, 0, 1])
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3))
    assert np.linalg.det(rotation) == pytest.approx(1.0)


def test_up_axis_is_for_files_only():
    lines = _config_error({"surface": {"template": "cap", "up_axis": "y"}})
    assert any("up_axis" in line for line in lines), lines


# --- 5. through a pipe, a long stage prints a line at least every 10 s ----------------------------

class _FakeClock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def _plain_lines(err: str, stage: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith(f"  {stage} ") and "ran" not in line]


def test_a_plain_line_at_least_every_interval_from_the_steps(capsys):
    from workflow.progress import PLAIN_INTERVAL_S, Progress

    assert PLAIN_INTERVAL_S <= 10.0
    clock = _FakeClock()
    progress = Progress(enabled=True, live=False, heartbeat=False, clock=clock)
    progress.stage_start("analysis")
    for i in range(1, 71):                                   # a step every 0.5 s for 35 s
        clock.now = 0.5 * i
        progress.step(f"non-linear, imperfection {i}", i / 70)
    progress.stage_done("analysis", "ran", clock.now)
    lines = _plain_lines(capsys.readouterr().err, "analysis")
    assert lines == ["  analysis     non-linear, imperfection 20  29%  (10 s)",
                     "  analysis     non-linear, imperfection 40  57%  (20 s)",
                     "  analysis     non-linear, imperfection 60  86%  (30 s)"]


def test_the_heartbeat_prints_the_current_step_when_no_step_comes(capsys):
    """One long step (a GNL run, a STEP export) still gives lines; none after the stage ends."""
    import time

    from workflow.progress import Progress

    progress = Progress(enabled=True, live=False, interval=0.05)
    progress.stage_start("fabrication")
    progress.step("joint solids", 0.5)
    err, waited = "", 0.0
    while len(_plain_lines(err, "fabrication")) < 3 and waited < 10.0:  # a busy machine schedules the beat late
        time.sleep(0.1)
        waited += 0.1
        err += capsys.readouterr().err
    progress.stage_done("fabrication", "ran", 0.5)
    time.sleep(0.2)
    err += capsys.readouterr().err
    lines = _plain_lines(err, "fabrication")
    assert len(lines) >= 3, err
    assert all("joint solids  50%" in line and line.endswith(" s)") for line in lines), lines
    assert err.rstrip().splitlines()[-1].split()[:2] == ["fabrication", "ran"], err


def test_plain_lines_through_a_pipe_and_the_live_line_on_a_terminal():
    """What a run chooses by itself: stderr a pipe (CI, `make demo | tee`) gives the plain lines,
    stderr a terminal the rich live line."""
    import subprocess
    import sys

    script = "import sys; from workflow.progress import Progress; print(Progress().live, file=sys.__stdout__)"
    root = Path(__file__).resolve().parents[1]
    piped = subprocess.run([sys.executable, "-c", script], cwd=root, capture_output=True, text=True, check=True)
    assert piped.stdout.strip() == "False"
    main, terminal = os.openpty()
    try:
        on_terminal = subprocess.run([sys.executable, "-c", script], cwd=root, stdout=subprocess.PIPE,
                                     stderr=terminal, text=True, check=True)
    finally:
        os.close(main)
        os.close(terminal)
    assert on_terminal.stdout.strip() == "True"


def test_no_plain_lines_when_quiet_or_live(capsys):
    from workflow.progress import Progress

    clock = _FakeClock()
    for progress in (Progress(enabled=False, clock=clock), Progress(enabled=True, live=True, clock=clock)):
        progress.stage_start("remesh")
        clock.now += 30.0
        progress.step("lloyd", 0.5)
        progress.stage_done("remesh", "ran", 30.0)
        assert progress._beating is None
    assert _plain_lines(capsys.readouterr().err, "remesh") == []


# --- 6. buckling modes: the same sign whatever the eigensolver's start ----------------------------

def _frame():
    """A two-storey 3D frame with a diagonal (no symmetry, so no repeated buckling factors),
    fixed feet, downward loads."""
    import numpy as np

    from engine.structure.frame import FrameModel
    from engine.structure.supports import Supports

    from .test_frame import space_frame_geometry

    nodes, beams, up = space_frame_geometry()
    b = len(beams)
    d, t = 0.1, 0.005                                      # a 100 x 5 mm steel tube
    A = np.pi / 4 * (d**2 - (d - 2 * t) ** 2)
    I = np.pi / 64 * (d**4 - (d - 2 * t) ** 4)
    model = FrameModel(nodes=nodes, beams=beams, E=np.full(b, 210e9), G=np.full(b, 81e9), A=np.full(b, A),
                       Iy=np.full(b, I), Iz=np.full(b, I), J=np.full(b, 2 * I), up=up, elements_per_beam=2)
    loads = np.zeros((len(nodes), 6))
    loads[4:, 2] = -np.linspace(1e5, 2e5, 8)
    loads[8:, 0] = 2e3
    return model, Supports(nodes=np.arange(4), restraints=np.ones((4, 6), bool)), loads


def _modes(monkeypatch, seed: int, flip: bool):
    """Buckling modes with the eigensolver started from ``seed``; ``flip`` negates every vector it
    returns (an eigenvector is one only up to its sign)."""
    from engine.structure import frame

    eigsh = frame.spla.eigsh

    def seeded(*args, **kwargs):
        kwargs["rng"] = seed
        out = eigsh(*args, **kwargs)
        if flip and isinstance(out, tuple):
            return out[0], -out[1]
        return out

    monkeypatch.setattr(frame.spla, "eigsh", seeded)
    model, supports, loads = _frame()
    result = frame.linear_buckling(model, supports, loads, n_modes=4)
    monkeypatch.setattr(frame.spla, "eigsh", eigsh)
    return result


def test_buckling_modes_have_the_same_sign_from_differently_seeded_starts(monkeypatch):
    import numpy as np

    first = _modes(monkeypatch, seed=1, flip=False)
    factors = first.factors
    assert len(factors) == 4 and np.all(np.diff(factors) > 1e-3 * factors[:-1])   # distinct: each mode is unique
    for seed, flip in ((2, False), (3, True), (12345, True)):
        again = _modes(monkeypatch, seed=seed, flip=flip)
        assert np.allclose(again.factors, factors, rtol=1e-8)
        assert np.allclose(again.modes, first.modes, atol=1e-6), (seed, flip)
    for mode in first.modes:                                # the rule itself, from the modes
        translations = mode[:, :3].ravel()
        assert translations[np.argmax(np.abs(translations))] > 0


def test_the_sign_rule_breaks_ties_by_the_lowest_index():
    import numpy as np

    from engine.structure.frame import _signed_modes

    modes = np.zeros((3, 2, 6))
    modes[0, 0, 2], modes[0, 1, 0] = -1.0, 1.0              # a tie: node 0's uz wins, so it turns positive
    modes[1, 0, 1], modes[1, 1, 1] = 1.0, -0.99995          # within the tie share: node 0 again
    modes[2, 0, 3], modes[2, 1, 2] = -5.0, -0.5             # rotations do not count
    signed = _signed_modes(modes)
    assert signed[0, 0, 2] == 1.0 and signed[0, 1, 0] == -1.0
    assert signed[1, 0, 1] == 1.0
    assert signed[2, 1, 2] == 0.5 and signed[2, 0, 3] == 5.0
    assert _signed_modes(np.zeros((0, 2, 6))).shape == (0, 2, 6)


def test_imperfection_names_follow_the_signed_mode():
    import numpy as np

    from engine.structure.protocol import ProtocolSettings, imperfection_shapes

    modes = np.zeros((1, 3, 6))
    modes[0, 1, 2] = -1.0
    settings = ProtocolSettings(amplitude=0.01, shapes=("mode1",))
    from engine.structure.frame import _signed_modes

    shapes = imperfection_shapes(settings, np.zeros((3, 6)), None, _signed_modes(modes))
    assert shapes["mode1+"][1, 2] == 0.01 and shapes["mode1-"][1, 2] == -0.01


# --- 3. hints name TOML keys, not Python classes ----------------------------------------------------

SETTINGS_HINTS_LEFT: set[str] = set()
"""Hints that still name a Settings class (none)."""


def _hints_naming_classes() -> dict[str, list[int]]:
    """Files and lines of ``hint=``/``fix=`` texts that name a Python class (``SheetSettings``)."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    classes = re.compile(r"\b[A-Z][A-Za-z]*(Settings|Config|Spec)\b")
    found: dict[str, list[int]] = {}
    for package in ("engine", "fabrication", "workflow"):
        for path in sorted((root / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.keyword) and node.arg in ("hint", "fix"):
                    texts = [n.value for n in ast.walk(node.value) if isinstance(n, ast.Constant)
                             and isinstance(n.value, str)]
                    if any(classes.search(text) for text in texts):
                        found.setdefault(str(path.relative_to(root)), []).append(node.value.lineno)
    return found


def test_hints_name_toml_keys_not_settings_classes():
    found = _hints_naming_classes()
    assert set(found) <= SETTINGS_HINTS_LEFT, found


def test_the_same_input_gives_the_same_analysis_files(tmp_path):
    """Two cold runs of the same project write byte-identical analysis CSVs and name the same
    worst imperfection (ARPACK starts from a fixed vector; modes are signed deterministically)."""
    from workflow.progress import Progress
    from workflow.runner import run_project
    from workflow.stages import STAGES

    from .conftest import small_project

    project = small_project()
    outs = [tmp_path / "a", tmp_path / "b"]
    for out in outs:
        run_project(project, out, STAGES, until="analysis", progress=Progress(enabled=False))
    for name in ("members.csv", "response.csv"):
        assert (outs[0] / "06-analysis" / name).read_bytes() == (outs[1] / "06-analysis" / name).read_bytes(), name
    # every file but the pictures, byte for byte: no seconds in remesh.json or analysis.json (the
    # manifest holds them), no clock anywhere
    files = sorted(p.relative_to(outs[0]) for p in outs[0].glob("0*/**/*") if p.is_file() and p.suffix != ".png")
    assert {"04-remesh/remesh.json", "06-analysis/analysis.json"} <= {f.as_posix() for f in files}
    assert [f.as_posix() for f in files if (outs[0] / f).read_bytes() != (outs[1] / f).read_bytes()] == []
    import json

    first, second = (json.loads((o / "06-analysis" / "analysis.json").read_text()) for o in outs)
    assert first["worst_imperfection"] == second["worst_imperfection"]
    assert first["buckling_factors"] == second["buckling_factors"]


def test_a_buckling_solve_that_fails_is_a_finding_and_the_analysis_completes(tmp_path, monkeypatch):
    """When the eigensolver does not converge, the analysis still writes its files, with a
    buckling_not_solved finding (the non-linear paths run without mode-shaped imperfections)."""
    import json

    import engine.structure.frame as frame
    from engine.errors import ConvergenceError
    from workflow.progress import Progress
    from workflow.runner import run_project
    from workflow.stages import STAGES

    from .conftest import small_project

    def fails(*args, **kwargs):
        raise ConvergenceError("linear buckling: the eigenvalue solver did not converge")

    monkeypatch.setattr(frame, "linear_buckling", fails)
    out = tmp_path / "out"
    summary = run_project(small_project(), out, STAGES, until="analysis", progress=Progress(enabled=False))
    analysis = json.loads((out / "06-analysis" / "analysis.json").read_text())
    assert analysis["lambda_LB"] is None
    kinds = [f["kind"] for f in summary.findings]
    assert "buckling_not_solved" in kinds
    assert all(not i["shape"].startswith("mode") for i in analysis["imperfections"])


def test_a_project_folder_stands_for_its_project_toml(tmp_path, capsys):
    from workflow.cli import main
    from workflow.config import load_project

    assert main(["init", str(tmp_path / "roof"), "--template", "cap"]) == 0
    assert load_project(tmp_path / "roof") == load_project(tmp_path / "roof" / "project.toml")
    (tmp_path / "empty").mkdir()
    assert main(["validate", str(tmp_path / "empty")]) == 2
    assert "folder without a project.toml" in capsys.readouterr().err


def test_compare_checks_its_inputs_as_run_does(capsys, tmp_path):
    from workflow.cli import main

    (tmp_path / "project.toml").write_text('[surface]\nfile = "missing.ply"\n')
    assert main(["compare", str(tmp_path / "project.toml"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "[surface] file" in err and "does not exist" in err
    assert not (tmp_path / "out" / "01-surface").exists()


def test_a_dxf_is_the_same_bytes_from_any_process(tmp_path):
    """ezdxf stamps times and GUIDs and orders its CLASSES by the hash seed; save_dxf fixes both:
    two processes with different hash seeds write the same file, which ezdxf reads back."""
    import hashlib
    import subprocess
    import sys

    import ezdxf

    script = ("import sys; from fabrication.dxf import CUTTING_LAYERS, new_document, save_dxf; "
              "d = new_document(CUTTING_LAYERS); d.modelspace().add_lwpolyline([(0, 0), (100, 0), (100, 50)], "
              "dxfattribs={'layer': 'CUT'}); save_dxf(d, sys.argv[1])")
    root = Path(__file__).resolve().parents[1]
    digests = []
    for seed in ("1", "2", "3"):
        path = tmp_path / f"p{seed}.dxf"
        subprocess.run([sys.executable, "-c", script, str(path)], cwd=root, check=True,
                       env={**os.environ, "PYTHONHASHSEED": seed})
        digests.append(hashlib.sha256(path.read_bytes()).hexdigest())
    assert len(set(digests)) == 1
    doc = ezdxf.readfile(tmp_path / "p1.dxf")
    assert doc.header["$INSUNITS"] == 4 and len(doc.modelspace().query("LWPOLYLINE")) == 1


def test_a_mechanism_is_reported_as_one_naming_the_supports(capsys, tmp_path):
    """Rollers round a cap's whole edge leave it free to slide and turn in plan: the run ends with
    exit 2 and one message that says mechanism and names the [[supports]] keys, no traceback."""
    project = _project(tmp_path, '[surface]\ntemplate = "cap"\n[surface.parameters]\nrings = 4\n'
                                 '[[supports]]\nselect = "boundary"\nrestraint = "roller_z"\n')
    code, out, err = _cli(capsys, "run", str(project), "--out", str(tmp_path / "out"), "--until", "shell", "--quiet")
    assert code == 2 and "Traceback" not in err and err.count("error:") == 1, err
    assert "mechanism" in err and "3 rigid-body mode" in err
    assert "[[supports]]" in err and "pinned" in err
