"""Property-based: valid project files and meshes mutated at random. ``gridshell validate`` either
accepts the project or stops with exit 2 and one message (an error line, its details indented
under it, at most one hint, no library internals); it never shows a traceback. ``gridshell run
--until surface`` on a mutated mesh leaves either a complete stage folder or none, and nothing
half-written."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, example, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from workflow.cli import main  # noqa: E402

TEMPLATES = Path(__file__).resolve().parents[1] / "templates"

#: Values a person might type, right or wrong.
VALUES = st.sampled_from([
    "0", "-1", "1e9", "nan", "inf", "-inf", "true", '""', '"50 mmm"', '"50 mm"', '"3 kN/m^2"', '"abc"',
    "[]", "[1, 2]", '["boundary"]', "{}", '{ a = 1 }', "2.5", "1_000", '"0.5 kN/m^2"', '"12 m"', "0.0",
    '"steel_s355"', '"circular_hollow"', '"m"', '"km"', "[[1]]", '"""x"""', "12", "3.0e-3",
])


def _cli(*args: str) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(list(args))
    return code, err.getvalue()


def _one_message(code: int, err: str) -> None:
    assert "Traceback" not in err
    assert code in (0, 2), (code, err)
    if code == 2:  # an "error:" line, its details indented under it, at most one hint
        lines = [line for line in err.splitlines() if line.strip()]
        assert lines and lines[0].startswith("error: "), err
        assert all(line.startswith("  ") for line in lines[1:]), err
        assert sum("hint:" in line for line in lines) <= 1, err
        for internal in ("pydantic", "function-before", "[type=", "errors.pydantic.dev", "Error("):
            assert internal not in err, err


@st.composite
def mutated_projects(draw) -> str:
    """A template's TOML with one to three edits: a value replaced, a line dropped or doubled, an
    unknown key or a stray line added."""
    name = draw(st.sampled_from(["mockup", "cap", "vault", "hypar", "courtyard"]))
    lines = (TEMPLATES / f"{name}.toml").read_text(encoding="utf-8").splitlines()
    for _ in range(draw(st.integers(1, 3))):
        assignments = [i for i, line in enumerate(lines) if re.match(r"^\s*[A-Za-z_\"][^=]*=", line)]
        i = draw(st.sampled_from(assignments))
        action = draw(st.sampled_from(["value", "drop", "double", "unknown", "stray"]))
        key = lines[i].split("=", 1)[0].rstrip()
        if action == "value":
            lines[i] = f"{key} = {draw(VALUES)}"
        elif action == "drop":
            del lines[i]
        elif action == "double":
            lines.insert(i, lines[i])
        elif action == "unknown":
            lines.insert(i + 1, f"{draw(st.sampled_from(['colour', 'n_cell', 'thickness_mm', 'x']))} = {draw(VALUES)}")
        else:
            lines.insert(i, draw(st.sampled_from(["[section]", "[[supports]]", "garbage", "= 3", "[loads.cases.x]"])))
    return "\n".join(lines) + "\n"


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=mutated_projects())
@example(text='[surface]\ntemplate = "vault"\n[surface.parameters]\ndivisions = -1\n')  # found by this test
@example(text='[surface]\ntemplate = "vault"\n[surface.parameters]\ndivisions = 1_000\n')  # found by this test: 24 GB
def test_a_mutated_project_is_valid_or_one_message(tmp_path_factory, text):
    folder = tmp_path_factory.mktemp("project")
    (folder / "project.toml").write_text(text, encoding="utf-8")
    _one_message(*_cli("validate", str(folder / "project.toml")))


FINITE = st.floats(-50.0, 50.0, allow_nan=False)
COORDINATE = st.one_of(FINITE, FINITE, FINITE, st.sampled_from([float("nan"), float("inf"), 1e12, 0.0]))


@st.composite
def meshes(draw) -> str:
    """An OBJ: a few vertices (some maybe not finite or huge) and faces (some maybe degenerate,
    repeated or pointing past the vertices)."""
    n = draw(st.integers(0, 12))
    vertices = [[draw(COORDINATE) for _ in range(3)] for _ in range(n)]
    faces = draw(st.lists(st.lists(st.integers(-2, n + 1), min_size=2, max_size=5), max_size=14))
    text = [f"v {x} {y} {z}" for x, y, z in vertices]
    text += ["f " + " ".join(str(i) for i in face) for face in faces]
    if draw(st.booleans()):
        text.insert(draw(st.integers(0, len(text))), draw(st.sampled_from(["vt 0 0", "o x", "garbage", "f", "v 1"])))
    return "\n".join(text) + "\n"


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mesh=meshes(), supports=st.sampled_from(["boundary", "flagged"]))
@example(mesh="v 1\nv 0.0 0.0 0.0\nf 0 0 0\n", supports="boundary")   # found by this test: a one-coordinate vertex
def test_a_damaged_mesh_is_valid_or_one_message(tmp_path_factory, mesh, supports):
    folder = tmp_path_factory.mktemp("mesh")
    (folder / "roof.obj").write_text(mesh, encoding="ascii")
    (folder / "project.toml").write_text(f'[surface]\nfile = "roof.obj"\n\n[[supports]]\nselect = "{supports}"\n')
    _one_message(*_cli("validate", str(folder / "project.toml")))


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mesh=meshes())
@example(mesh="v 1\nv 0.0 0.0 0.0\nv 0.0 0.0 0.0\nf 0 0 0\n")
def test_a_run_on_a_damaged_mesh_leaves_a_whole_stage_or_none(tmp_path_factory, mesh):
    folder = tmp_path_factory.mktemp("run")
    (folder / "roof.obj").write_text(mesh, encoding="ascii")
    out = folder / "out"
    code, err = _cli("run", "--surface", str(folder / "roof.obj"), "--out", str(out), "--until", "surface",
                     "--quiet")
    _one_message(code, err)
    if out.is_dir():
        assert not [p.name for p in out.iterdir() if p.name.startswith(".") and p.name != ".gridshell.lock"]
        stage = out / "01-surface"
        assert (code == 0) == stage.is_dir(), "a stage folder exactly when the stage ran"
