"""The stage runner: caching by hash, reruns downstream only, atomic stage folders, manifest."""

from __future__ import annotations

import dataclasses
import inspect
import json
from pathlib import Path

import pytest

from workflow.config import parse_project
from workflow.runner import Stage, run_project


def _stages(calls: list[str], fail: str | None = None, seen: dict | None = None):
    """Four stages, each writing its name and returning it with its upstream results (``seen``
    records what each was called with)."""
    def make(name):
        def run(*, project, ctx, **upstream):
            calls.append(name)
            if seen is not None:
                seen[name] = upstream
            (ctx.folder / f"{name}.txt").write_text(name)
            if name == fail:
                (ctx.folder / "half.txt").write_text("half")
                raise RuntimeError("boom")
            return name

        return run

    def load(folder, project):
        return (folder / f"{folder.name.split('-')[1]}.txt").read_text() + " (loaded)"

    names = [("surface", ()), ("shell", ("surface",)), ("field", ("shell",)), ("remesh", ("field",))]
    return [Stage(name=n, folder=f"0{i + 1}-{n}", run=make(n), load=load, depends=d) for i, (n, d) in enumerate(names)]


def _project(ratio=2.0, thickness=None):
    return parse_project({"surface": {"template": "cap"}, "field": {"max_size_ratio": ratio},
                          "shell": {"thickness": thickness}})


def _statuses(out):
    return {s["name"]: s["status"] for s in json.loads((out / "manifest.json").read_text())["stages"]}


def test_second_run_is_cached(tmp_path):
    calls: list[str] = []
    run_project(_project(), tmp_path, _stages(calls))
    assert calls == ["surface", "shell", "field", "remesh"]
    calls.clear()
    run_project(_project(), tmp_path, _stages(calls))
    assert calls == []
    assert set(_statuses(tmp_path).values()) == {"cached"}


def test_config_change_reruns_that_stage_and_later_only(tmp_path):
    calls: list[str] = []
    run_project(_project(), tmp_path, _stages(calls))
    calls.clear()
    run_project(_project(ratio=3.0), tmp_path, _stages(calls))
    assert calls == ["field", "remesh"]
    assert _statuses(tmp_path) == {"surface": "cached", "shell": "cached", "field": "ran", "remesh": "ran"}
    calls.clear()
    run_project(_project(ratio=3.0, thickness=0.1), tmp_path, _stages(calls))
    assert calls == ["shell", "field", "remesh"]


def test_changed_artifact_invalidates_cache_and_force_reruns(tmp_path):
    calls: list[str] = []
    run_project(_project(), tmp_path, _stages(calls))
    (tmp_path / "02-shell" / "shell.txt").write_text("edited by hand")
    calls.clear()
    run_project(_project(), tmp_path, _stages(calls))
    assert calls == ["shell"]
    calls.clear()
    run_project(_project(), tmp_path, _stages(calls), force=True)
    assert calls == ["surface", "shell", "field", "remesh"]


@pytest.mark.parametrize("damage", ["truncated", "deleted", "same size"])
def test_a_damaged_or_missing_artifact_reruns_its_stage(tmp_path, damage):
    """An artifact whose sha256 no longer matches the manifest (cut short, removed, or changed in
    place at the same size) makes its stage run again; the stages after it, given the same result,
    stay cached."""
    calls: list[str] = []
    run_project(_project(), tmp_path, _stages(calls))
    artifact = tmp_path / "03-field" / "field.txt"
    if damage == "truncated":
        artifact.write_text("")
    elif damage == "deleted":
        artifact.unlink()
    else:
        artifact.write_text("FIELD")
    calls.clear()
    run_project(_project(), tmp_path, _stages(calls))
    assert calls == ["field"]
    assert artifact.read_text() == "field"
    assert _statuses(tmp_path) == {"surface": "cached", "shell": "cached", "field": "ran", "remesh": "cached"}


def test_until_and_only(tmp_path):
    calls: list[str] = []
    run_project(_project(), tmp_path, _stages(calls), until="shell")
    assert calls == ["surface", "shell"]
    assert _statuses(tmp_path)["field"] == "not run"
    calls.clear()
    run_project(_project(), tmp_path, _stages(calls), only="field")
    assert calls == ["field"]


def test_a_run_until_an_earlier_stage_keeps_the_later_stages_cache(tmp_path):
    calls: list[str] = []
    run_project(_project(), tmp_path, _stages(calls))
    run_project(_project(), tmp_path, _stages(calls), until="shell")
    calls.clear()
    run_project(_project(), tmp_path, _stages(calls))
    assert calls == []
    assert set(_statuses(tmp_path).values()) == {"cached"}


def test_failed_stage_leaves_no_half_written_folder(tmp_path):
    calls: list[str] = []
    with pytest.raises(RuntimeError):
        run_project(_project(), tmp_path, _stages(calls, fail="field"))
    assert not (tmp_path / "03-field").exists()
    assert not list(tmp_path.glob(".03-field*"))
    statuses = _statuses(tmp_path)
    assert statuses["field"] == "failed" and statuses["remesh"] == "not run"


def test_a_stage_is_called_with_its_upstream_results_run_or_loaded(tmp_path):
    seen: dict = {}
    run_project(_project(), tmp_path, _stages([], seen=seen))
    assert seen == {"surface": {}, "shell": {"surface": "surface"}, "field": {"shell": "shell"},
                    "remesh": {"field": "field"}}
    seen.clear()
    run_project(_project(ratio=3.0), tmp_path, _stages([], seen=seen))
    assert seen == {"field": {"shell": "shell (loaded)"}, "remesh": {"field": "field"}}


def test_a_stage_takes_some_of_the_stages_it_depends_on(tmp_path):
    seen: dict = {}
    stages = _stages([], seen=seen)
    stages[3] = dataclasses.replace(stages[3], depends=("shell", "field"), takes=("field",))
    run_project(_project(), tmp_path, stages)
    assert seen["remesh"] == {"field": "field"}


def test_the_stages_take_what_their_run_functions_ask_for():
    """Each registered stage's run has one keyword per stage it takes, named after it, and those
    stages come before it and are among the stages in its key."""
    from workflow.stages import STAGES

    names = [s.name for s in STAGES]
    for index, stage in enumerate(STAGES):
        run, load = stage.run.target(), stage.load.target()  # the registry imports them when called
        assert run.__module__ == load.__module__ == f"workflow.stages.{stage.name}"
        parameters = list(inspect.signature(run).parameters)
        assert parameters == [*stage.inputs, "project", "ctx"], stage.name
        assert set(stage.inputs) <= set(stage.depends) <= set(names[:index]), stage.name
        assert list(inspect.signature(load).parameters) == ["folder", "project"], stage.name


def test_the_stage_registry_imports_no_stage_until_it_runs():
    """A run whose stages are all cached loads none of the stages' libraries: the registry imports
    no stage module, nor pandas, OCP or matplotlib, until a stage's run, load or external digest
    is called."""
    import subprocess
    import sys

    code = ("import sys\n"
            "from workflow.stages import STAGES\n"
            "assert [s.name for s in STAGES][0] == 'surface'\n"
            "print(sorted(m for m in sys.modules if m.startswith('workflow.stages.') or m.split('.')[0] in "
            "('pandas', 'OCP', 'build123d', 'matplotlib')))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[1])
    assert out.stdout.strip() == "[]", out.stdout


def test_manifest_records_artifacts_config_and_versions(tmp_path):
    run_project(_project(), tmp_path, _stages([]))
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    shell = next(s for s in manifest["stages"] if s["name"] == "shell")
    assert shell["artifacts"][0]["path"] == "02-shell/shell.txt" and len(shell["artifacts"][0]["sha256"]) == 64
    assert manifest["config"]["field"]["max_size_ratio"] == 2.0
    assert "numpy" in manifest["versions"] and "python" in manifest["versions"]


def _stages_writing(calls: list[str], contents: dict[str, str]):
    """The four stages of ``_stages``, each writing ``contents[name]`` (its name by default) after
    what its upstream stage wrote."""
    def make(name):
        def run(*, project, ctx, **upstream):
            calls.append(name)
            text = "".join(f"{value}/" for value in upstream.values()) + contents.get(name, name)
            (ctx.folder / f"{name}.txt").write_text(text)
            return text

        return run

    def load(folder, project):
        return (folder / f"{folder.name.split('-')[1]}.txt").read_text()

    names = [("surface", ()), ("shell", ("surface",)), ("field", ("shell",)), ("remesh", ("field",))]
    return [Stage(name=n, folder=f"0{i + 1}-{n}", run=make(n), load=load, depends=d) for i, (n, d) in enumerate(names)]


def test_a_stage_remade_with_other_results_by_only_force_reruns_the_stages_made_from_it(tmp_path):
    calls: list[str] = []
    run_project(_project(), tmp_path, _stages_writing(calls, {}))
    # remade with the same results: nothing downstream is stale
    calls.clear()
    run_project(_project(), tmp_path, _stages_writing(calls, {}), only="shell", force=True)
    run_project(_project(), tmp_path, _stages_writing(calls, {}))
    assert calls == ["shell"]
    # remade with other results (as new code would): the stages made from them run again, once
    calls.clear()
    run_project(_project(), tmp_path, _stages_writing(calls, {"shell": "other"}), only="shell", force=True)
    run_project(_project(), tmp_path, _stages_writing(calls, {"shell": "other"}))
    assert calls == ["shell", "field", "remesh"]
    calls.clear()
    run_project(_project(), tmp_path, _stages_writing(calls, {"shell": "other"}))
    assert calls == []
    entries = {s["name"]: s for s in json.loads((tmp_path / "manifest.json").read_text())["stages"]}
    shell_files = {a["path"] for a in entries["shell"]["artifacts"]}
    assert shell_files == {"02-shell/shell.txt"} and set(entries["field"]["made_from"]) == {"shell"}


def test_the_cache_version_follows_every_source_and_data_file_and_nothing_else(tmp_path):
    from workflow.runner import cache_version, product_version, source_digest

    for package in ("engine", "fabrication", "workflow"):
        (tmp_path / package / "sub").mkdir(parents=True)
        (tmp_path / package / "a.py").write_text("x = 1\n")
        (tmp_path / package / "sub" / "b.py").write_text("y = 2\n")
    (tmp_path / "engine" / "data").mkdir()
    (tmp_path / "engine" / "data" / "tubes.csv").write_text("D,t\n60.3,3.2\n")
    first = source_digest(tmp_path)
    (tmp_path / "README.md").write_text("outside the packages")
    (tmp_path / "workflow" / "__pycache__").mkdir()
    (tmp_path / "workflow" / "__pycache__" / "a.cpython-311.pyc").write_bytes(b"byte code")
    assert source_digest(tmp_path) == first
    (tmp_path / "engine" / "data" / "tubes.csv").write_text("D,t\n60.3,4.0\n")
    assert source_digest(tmp_path) != first  # a catalogue changes results as code does
    (tmp_path / "engine" / "data" / "tubes.csv").write_text("D,t\n60.3,3.2\n")
    assert source_digest(tmp_path) == first
    (tmp_path / "fabrication" / "sub" / "b.py").write_text("y = 3\n")
    changed = source_digest(tmp_path)
    assert changed != first
    (tmp_path / "fabrication" / "sub" / "b.py").rename(tmp_path / "fabrication" / "b.py")
    assert source_digest(tmp_path) not in (first, changed)  # a moved module is other code
    assert cache_version().startswith(product_version() + "+")


def _reading(section_reads: dict[str, str], calls: list[str]):
    """The four stages of ``_stages``, each reading the dotted project key ``section_reads[name]``
    (if any) and using its value."""
    def make(name):
        def run(*, project, ctx, **upstream):
            calls.append(name)
            value = project
            for part in section_reads.get(name, "").split(".") if name in section_reads else ():
                value = getattr(value, part)
            (ctx.folder / f"{name}.txt").write_text(f"{name} {value!s}")
            return name

        return run

    stages = _stages([])
    return [dataclasses.replace(s, run=make(s.name)) for s in stages]


def test_a_stage_reads_its_own_and_its_upstream_sections_only(tmp_path):
    """A stage's cache key holds its sections (STAGE_SECTIONS) and its upstream stages' keys, so a
    stage may read those sections and no other: reading another would leave a stale cache when it
    changes. The runner hands each stage a view of the project that refuses the others."""
    from workflow.stage_view import UndeclaredSetting

    calls: list[str] = []
    # field reads its own section, remesh reads field's (upstream) and shell's through the chain
    run_project(_project(), tmp_path, _reading({"field": "field.max_size_ratio", "remesh": "shell.thickness"}, calls))
    assert calls == ["surface", "shell", "field", "remesh"]
    assert (tmp_path / "03-field" / "field.txt").read_text() == "field 2.0"
    # shell reads the field section, which is downstream of it: refused, with the stage named
    with pytest.raises(UndeclaredSetting, match=r"the shell stage read \[field\]"):
        run_project(_project(ratio=5.0), tmp_path / "b", _reading({"shell": "field.max_size_ratio"}, []))
    # a key of a section declared only in part ("project.name" for surface): the rest is refused
    with pytest.raises(UndeclaredSetting, match=r"\[project.description\]"):
        run_project(_project(), tmp_path / "c", _reading({"surface": "project.description"}, []))
    run_project(_project(), tmp_path / "d", _reading({"surface": "project.name"}, []))


def test_renaming_the_project_remakes_the_files_that_carry_its_name(tmp_path):
    """The name titles every stage's pictures and names the NC1 order and the IFC project, so it is
    in the first stage's key (and through it in every later one)."""
    calls: list[str] = []
    named = parse_project({"project": {"name": "a"}, "surface": {"template": "cap"}})
    run_project(named, tmp_path, _stages(calls))
    calls.clear()
    run_project(named.model_copy(update={"project": named.project.model_copy(update={"description": "x"})}),
                tmp_path, _stages(calls))
    assert calls == []
    run_project(parse_project({"project": {"name": "b"}, "surface": {"template": "cap"}}), tmp_path, _stages(calls))
    assert calls == ["surface", "shell", "field", "remesh"]


def test_a_setting_outside_the_view_refuses_every_use():
    from workflow.stage_view import UndeclaredSetting, stage_view

    view = stage_view(_project(), ("field", "fabrication.joints"), "field")
    assert view.field.max_size_ratio == 2.0
    assert view.fabrication.joints.kind == _project().fabrication.joints.kind
    for use in (lambda: view.shell.thickness, lambda: view.fabrication.beams.stock_length,
                lambda: float(view.fabrication.panels), lambda: f"{view.loads}", lambda: bool(view.material),
                lambda: view.remesh + 1, lambda: list(view.supports)):
        with pytest.raises(UndeclaredSetting):
            use()
    assert "not in the cache key" in repr(view.shell)
