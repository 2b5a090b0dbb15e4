"""``gridshell sweep``: the sweep file's checks, the plan of shared stages, the Pareto front, and
real sweeps on a local cluster and on a separate ``dask scheduler`` with two ``dask worker``
processes, killed and resumed, against plain runs."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from engine.errors import InputError
from engine.remeshing.field import Orientation
from workflow.cli import main
from workflow.config import KEYS_LEFT_OUT_AT_DEFAULT, STAGE_SECTIONS, load_project
from workflow.plots.sweep import pareto_front
from workflow.runner import NOT_IN_KEYS, _section_value, _stage_key, cache_version
from workflow.stages import STAGES
from workflow.sweep import Point, load_sweep, plan_tasks, sweep_points

ROOT = Path(__file__).resolve().parents[1]
GRIDSHELL = [sys.executable, "-m", "workflow.cli"]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


def _sweep(tmp_path: Path, parameters: str, *, until: str = "remesh", template: str = "mockup") -> Path:
    assert main(["init", str(tmp_path / "proj"), "--template", template]) == 0
    path = tmp_path / "sweep.toml"
    path.write_text(f'project = "proj/project.toml"\nuntil = "{until}"\n[parameters]\n{parameters}\n')
    return path


@pytest.mark.parametrize("parameters, said", [
    ('"remesh.n_cels" = [40, 60]', "'remesh.n_cels' is not a project key"),
    ('"remesh" = [40, 60]', "'remesh' is not a project key"),
    ('"remesh.n_cells" = 40', "'remesh.n_cells' must be a non-empty list"),
    ('"remesh.n_cells" = []', "'remesh.n_cells' must be a non-empty list"),
    ('"remesh.n_cells" = [40, -3]', "point 2 (remesh.n_cells = -3) is not a valid project"),
    ('"section.diameter" = ["50 mmm"]', "point 1 (section.diameter = '50 mmm') is not a valid project"),
])
def test_bad_sweeps_exit_2_naming_the_key_before_anything_runs(tmp_path, capsys, parameters, said):
    path = _sweep(tmp_path, parameters)
    capsys.readouterr()
    assert main(["sweep", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert said in err and "Traceback" not in err and err.count("\n") <= 3
    assert not (tmp_path / "out" / "points").exists()


def test_a_sweep_file_needs_its_project_a_stage_and_parameters(tmp_path, capsys):
    path = tmp_path / "sweep.toml"
    for text, said in [('until = "analysis"\n[parameters]\n"remesh.n_cells" = [1]', 'project = "FILE" is missing'),
                       ('project = "nope.toml"\n[parameters]\n"remesh.n_cells" = [1]', "nope.toml does not exist"),
                       ('project = "p.toml"\nuntil = "shop"\n[parameters]\n"remesh.n_cells" = [1]',
                        "until = 'shop' is not a stage"),
                       ('project = "p.toml"\n', "[parameters] is missing or empty"),
                       ('project = "p.toml"\nseeds = [1]\n[parameters]\n"remesh.n_cells" = [1]',
                        "unknown key 'seeds'")]:
        (tmp_path / "p.toml").write_text("")
        path.write_text(text)
        assert main(["sweep", str(path)]) == 2
        assert said in capsys.readouterr().err


def _points(n: int) -> list[Point]:
    return [Point(number=k + 1, values={}, project=None, folder=Path(f"/p/{k + 1:04d}")) for k in range(n)]


def test_the_plan_runs_each_shared_stage_once_and_children_after_parents():
    # 4 points over 4 stages: all share stage 0; points 1-2 and 3-4 share stage 1; stage 2: 1, 2 and 3-4
    keys = {1: ["a", "b1", "c1", "d1"], 2: ["a", "b1", "c2", "d2"], 3: ["a", "b2", "c3", "d3"],
            4: ["a", "b2", "c3", "d4"]}
    tasks = plan_tasks(_points(4), keys)
    runs = {(k, level) for t in tasks for level in range(t.first, t.last + 1) for k in [keys[t.points[0]][level]]}
    distinct = {(key, level) for ks in keys.values() for level, key in enumerate(ks)}
    assert runs == distinct and sum(t.last - t.first + 1 for t in tasks) == len(distinct)  # each once
    seen = set()
    for t in tasks:
        assert t.parent is None or t.parent.id in seen
        seen.add(t.id)
        if t.parent is not None:
            assert t.first == t.parent.last + 1 and set(t.points) <= set(t.parent.points)
        assert t.home == Path(f"/p/{t.points[0]:04d}")
    leaves = [t for t in tasks if t.last == 3]
    assert sorted(p for t in leaves for p in t.points) == [1, 2, 3, 4]
    # identical points share everything: one task
    assert len(plan_tasks(_points(3), {1: list("wxyz"), 2: list("wxyz"), 3: list("wxyz")})) == 1


def _stage_keys(project) -> dict[str, str]:
    """Every stage's cache key of ``project``, as the runner computes them."""
    version, out = cache_version(), {}
    for stage in STAGES:
        out[stage.name] = _stage_key(stage, project, out, version)
    return out


def test_worker_counts_are_not_in_the_cache_keys(tmp_path):
    assert main(["init", str(tmp_path / "p"), "--template", "cap"]) == 0
    project = load_project(tmp_path / "p" / "project.toml")
    keys = _stage_keys

    one = project.model_copy(update={"analysis": project.analysis.model_copy(update={"workers": 1}),
                                     "fabrication": project.fabrication.model_copy(update={"workers": 1})})
    other = project.model_copy(update={"analysis": project.analysis.model_copy(update={"n_modes": 7})})
    assert keys(one) == keys(project)
    assert keys(other)["analysis"] != keys(project)["analysis"] and keys(other)["shell"] == keys(project)["shell"]


def test_later_keys_at_their_default_leave_the_cache_keys_as_they_were(tmp_path):
    assert main(["init", str(tmp_path / "p"), "--template", "cap"]) == 0
    project = load_project(tmp_path / "p" / "project.toml")
    keys = _stage_keys

    def changed(section: str, **update):
        return project.model_copy(update={section: getattr(project, section).model_copy(update=update)})

    plain = keys(project)
    # the keys of a project that does not give orientation or statics_rounds: as before they existed
    before = {}
    for stage in STAGES:
        config = {name: _section_value(project, name) for name in STAGE_SECTIONS.get(stage.name, ())}
        for name, later in KEYS_LEFT_OUT_AT_DEFAULT.items():
            for key in later:
                config.get(name, {}).pop(key, None)
        config = {name: {k: v for k, v in value.items() if k not in NOT_IN_KEYS} if isinstance(value, dict)
                  else value for name, value in config.items()}
        payload = {"stage": stage.name, "version": cache_version(), "config": config,
                   "upstream": {d: before[d] for d in stage.depends},
                   "external": stage.external(project) if stage.external else None}
        before[stage.name] = hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()
    assert plain == before
    across = keys(changed("field", orientation=Orientation.ACROSS))
    assert across["field"] != plain["field"] and across["shell"] == plain["shell"]
    rounds = changed("remesh", statics_rounds=2)
    assert keys(rounds)["remesh"] != plain["remesh"] and keys(rounds)["field"] == plain["field"]
    # with rounds the remesh analyses its grids: the analysis keys it takes are in its key, the others not
    finer = rounds.model_copy(update={"analysis": rounds.analysis.model_copy(update={"elements_per_beam": 2})})
    modes = rounds.model_copy(update={"analysis": rounds.analysis.model_copy(update={"n_modes": 9})})
    assert keys(finer)["remesh"] != keys(rounds)["remesh"] and keys(modes)["remesh"] == keys(rounds)["remesh"]
    assert keys(changed("analysis", elements_per_beam=2))["remesh"] == plain["remesh"]


def test_a_point_whose_upstream_results_were_remade_is_not_up_to_date(tmp_path):
    """The sweep skips a point only where the runner would take every stage from the cache: a shell
    made from surface results that have since been remade with other bytes (``gridshell run --only
    surface --force`` in the point's folder) is stale, as the runner finds it."""
    from workflow.runner import file_digest, results_digest
    from workflow.sweep import up_to_date

    def entry(name: str, folder: str, text: str, made_from: dict) -> dict:
        path = tmp_path / folder / f"{name}.txt"
        path.parent.mkdir(exist_ok=True)
        path.write_text(text)
        return {"name": name, "folder": folder, "status": "ran", "key": f"key-{name}", "made_from": made_from,
                "artifacts": [{"path": f"{folder}/{name}.txt", "sha256": file_digest(path),
                               "bytes": path.stat().st_size}]}

    surface = entry("surface", "01-surface", "the roof", {})
    shell = entry("shell", "02-shell", "its statics", {"surface": results_digest(surface)})

    def write(*entries):
        (tmp_path / "manifest.json").write_text(json.dumps({"stages": list(entries)}))

    write(surface, shell)
    assert up_to_date(tmp_path, ["key-surface", "key-shell"])
    write(entry("surface", "01-surface", "the roof, remade otherwise", {}), shell)
    assert not up_to_date(tmp_path, ["key-surface", "key-shell"])
    assert up_to_date(tmp_path, ["key-surface"])  # the surface itself is whole


def test_a_sweep_over_statics_rounds_is_accepted(tmp_path):
    path = _sweep(tmp_path, '"remesh.statics_rounds" = [1, 2]\n"field.orientation" = ["along", "across"]',
                  until="analysis", template="cap")
    points = sweep_points(load_sweep(path), tmp_path / "out")
    assert [(p.project.remesh.statics_rounds, p.project.field.orientation.value) for p in points] == [
        (1, "along"), (1, "across"), (2, "along"), (2, "across")]
    bad = _sweep(tmp_path / "bad", '"remesh.statics_rounds" = [0]')
    with pytest.raises(InputError, match="remesh.statics_rounds = 0"):
        sweep_points(load_sweep(bad), tmp_path / "out")


def test_the_pareto_front_is_what_no_other_point_dominates():
    rng = np.random.default_rng(0)
    mass, factor = rng.uniform(1, 10, 60), rng.uniform(1, 5, 60)
    factor[3] = np.nan
    front = pareto_front(mass, factor)
    for i in range(60):
        dominated = any(mass[j] <= mass[i] and factor[j] >= factor[i] and (mass[j] < mass[i] or factor[j] > factor[i])
                        for j in range(60) if j != i and np.isfinite(factor[j]))
        assert front[i] == (np.isfinite(factor[i]) and not dominated)
    assert front.sum() >= 1


# ------------------------------------------------------------------------------------------ real sweeps


def _rows(out: Path) -> list[dict]:
    import pandas as pd

    csv = pd.read_csv(out / "sweep.csv")
    parquet = pd.read_parquet(out / "sweep.parquet")
    assert list(csv.columns) == list(parquet.columns) and len(csv) == len(parquet)
    assert np.allclose(csv["seconds"], parquet["seconds"])
    return csv.to_dict("records")


@pytest.mark.slow
def test_a_sweep_on_a_dask_scheduler_with_two_workers(tmp_path):
    """A real ``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1, and a 4-point sweep
    through --scheduler: every point reaches its last stage, the shared stages are computed once
    (the points hold the same files), and the results list the points with their values."""
    path = _sweep(tmp_path, '"field.max_size_ratio" = [1.0, 2.0]\n"remesh.n_cells" = [30, 40]')
    dask = str(Path(sys.executable).parent / "dask")
    file = tmp_path / "scheduler.json"
    processes = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                   "--scheduler-file", str(file)], env=ENV, stderr=subprocess.DEVNULL,
                                  start_new_session=True)]
    try:
        for _ in range(300):
            if file.is_file() and file.stat().st_size:
                break
            time.sleep(0.1)
        address = json.loads(file.read_text())["address"]
        for _ in range(2):
            processes.append(subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--nworkers", "1",
                                               "--no-dashboard"], env=ENV, stderr=subprocess.DEVNULL,
                                              start_new_session=True))
        from distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        out = tmp_path / "out"
        run = subprocess.run([*GRIDSHELL, "sweep", str(path), "--out", str(out), "--scheduler", address],
                             env=ENV, capture_output=True, text=True, timeout=900)
        assert run.returncode == 0, run.stderr
    finally:
        for process in processes:
            os.killpg(process.pid, signal.SIGTERM)
        for process in processes:
            process.wait(timeout=30)
    rows = _rows(out)
    assert [(r["point"], r["field.max_size_ratio"], r["remesh.n_cells"]) for r in rows] == [
        (1, 1.0, 30), (2, 1.0, 40), (3, 2.0, 30), (4, 2.0, 40)]
    assert all(r["status"] == "ok" for r in rows)
    shells = {(out / "points" / f"{n:04d}" / "02-shell" / "shell.json").stat().st_ino for n in range(1, 5)}
    fields = {(out / "points" / f"{n:04d}" / "03-field" / "field.json").stat().st_ino for n in range(1, 5)}
    assert len(shells) == 1 and len(fields) == 2  # one shell for all, one field per size ratio
    for n in range(1, 5):
        manifest = json.loads((out / "points" / f"{n:04d}" / "manifest.json").read_text())
        status = {s["name"]: s["status"] for s in manifest["stages"]}
        assert status["remesh"] in ("ran", "cached") and status["optimize"] == "not run"
    assert "4 points" in (out / "sweep.html").read_text()


@pytest.mark.slow
def test_a_points_figures_equal_a_plain_run_and_a_killed_sweep_resumes(tmp_path):
    """Two points to the analysis on a local cluster of two workers; the first is killed half-way
    and the sweep rerun: what had finished is not computed again, and each point's figures equal
    those of a plain ``gridshell run`` of its values."""
    path = _sweep(tmp_path, '"remesh.n_cells" = [30, 40]', until="analysis")
    out = tmp_path / "out"
    command = [*GRIDSHELL, "sweep", str(path), "--out", str(out), "--workers", "2", "--quiet"]
    sweep = subprocess.Popen(command, env=ENV, start_new_session=True)
    manifest = out / "points" / "0001" / "manifest.json"
    try:
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline and sweep.poll() is None:
            stages = json.loads(manifest.read_text())["stages"] if manifest.is_file() else []
            if any(s["name"] == "remesh" and s["status"] == "ran" for s in stages):
                break
            time.sleep(0.2)
        assert sweep.poll() is None, "the sweep was still running when it was killed"
    finally:
        os.killpg(sweep.pid, signal.SIGKILL)
        sweep.wait()
    finished = {s["name"]: s["key"] for s in json.loads(manifest.read_text())["stages"] if s["status"] == "ran"}
    assert "remesh" in finished
    rerun = subprocess.run(command, env=ENV, capture_output=True, text=True, timeout=900)
    assert rerun.returncode == 0, rerun.stderr
    stages = {s["name"]: s for s in json.loads(manifest.read_text())["stages"]}
    for name, key in finished.items():  # finished before the kill: kept, not computed again
        assert stages[name]["key"] == key and stages[name]["status"] == "cached", (name, stages[name]["status"])
    rows = _rows(out)
    assert all(r["status"] == "ok" for r in rows)
    # a rerun of the finished sweep reads the manifests only
    started = time.perf_counter()
    again = subprocess.run(command, env=ENV, capture_output=True, text=True, timeout=120)
    assert again.returncode == 0 and time.perf_counter() - started < 30
    import pandas as pd

    assert pd.DataFrame(_rows(out)).equals(pd.DataFrame(rows))
    # the second point against a plain run of its values
    project = (tmp_path / "proj" / "project.toml").read_text()
    plain = tmp_path / "plain"
    plain.mkdir()
    (plain / "project.toml").write_text(_with_cells(project, 40))
    run = subprocess.run([*GRIDSHELL, "run", str(plain / "project.toml"), "--out", str(plain / "out"),
                          "--until", "analysis", "--quiet"], env=ENV, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    mine = json.loads((out / "points" / "0002" / "06-analysis" / "analysis.json").read_text())
    theirs = json.loads((plain / "out" / "06-analysis" / "analysis.json").read_text())
    for column, key in [("lambda_LB", "lambda_LB"), ("lambda_NL_worst", "lambda_NL_worst"),
                        ("delta_L_m", "delta_L_m"), ("beam_mass_kg", "beam_mass_kg"), ("n_nodes", "nodes")]:
        assert mine[key] == pytest.approx(theirs[key], rel=1e-9)
        assert rows[1][column] == pytest.approx(theirs[key], rel=1e-9)


def _with_cells(project: str, cells: int) -> str:
    """The project text with [remesh] n_cells set to ``cells`` (the line replaced, or added)."""
    head, rest = project.split("[remesh]\n", 1)
    body, tail = (rest.split("\n[", 1) + [""])[:2]
    lines = [line for line in body.splitlines() if not line.strip().startswith("n_cells")]
    return head + "[remesh]\n" + f"n_cells = {cells}\n" + "\n".join(lines) + ("\n[" + tail if tail else "")


def test_a_failing_task_is_a_row_and_fails_only_the_points_below_it(tmp_path):
    """A task whose stage raises returns ``failed`` with the stage range and the message (it does not
    raise); a child of a failed task reports the same failure without running; the results row
    carries them."""
    from tests.generated_surfaces import generate_surface, write_ply
    from workflow.config import project_from_surface
    from workflow.sweep import SweepSpec, Task, _row, run_task

    surface = generate_surface(0)
    path = tmp_path / "roof.ply"
    write_ply(surface, path)
    project = project_from_surface(str(path), "flagged")
    path.unlink()  # gone after validation: the surface stage fails when it runs
    names = [s.name for s in STAGES][:3]
    root = Task(id=0, first=0, last=1, points=[1, 2], home=tmp_path / "points" / "0001", project=project, parent=None)
    child = Task(id=1, first=2, last=2, points=[2], home=tmp_path / "points" / "0002", project=project, parent=root)
    failed = run_task(root, names, None)
    assert failed["status"] == "failed" and failed["message"].startswith("surface..shell: ")
    assert "roof.ply" in failed["message"]
    below = run_task(child, names, failed)
    assert below["status"] == "failed" and below["message"] == failed["message"]
    assert not (tmp_path / "points" / "0002").exists()
    spec = SweepSpec(file=tmp_path / "s.toml", project_file=path, project_data={}, until="field",
                     parameters={"remesh.seed": [1, 2]})
    row = _row(Point(number=2, values={"remesh.seed": 2}, project=project, folder=child.home), below, spec)
    assert row["status"] == "failed" and row["message"] == failed["message"] and row["lambda_NL_worst"] is None


def test_a_task_run_twice_waits_for_the_other_and_reads_its_stages(tmp_path, monkeypatch):
    """Dask runs a task again when it takes its worker for lost (a paused or cut-off worker goes on
    with it): the second run waits while the first holds the point's folder, then finds the stages
    in the cache and reports ok, where it had failed the point with "in use by another run". A
    folder held for longer than the wait fails the point with that message."""
    import threading

    from workflow import sweep as sweep_module
    from workflow.outdir import run_lock
    from workflow.runner import run_project
    from workflow.sweep import Task, run_task

    project = load_project(ROOT / "templates" / "mockup.toml")
    names = [s.name for s in STAGES][:2]
    home = tmp_path / "points" / "0001"
    run_project(project, home, STAGES, until=names[-1])  # the first run's stages, done
    task = Task(id=0, first=0, last=1, points=[1], home=home, project=project, parent=None)
    monkeypatch.setattr(sweep_module, "TASK_LOCK_POLL_S", 0.05)
    held, release = threading.Event(), threading.Event()

    def first_run_still_holding():
        with run_lock(home):
            held.set()
            release.wait(10)

    holder = threading.Thread(target=first_run_still_holding)
    holder.start()
    held.wait(10)
    threading.Timer(0.5, release.set).start()
    result = run_task(task, names)
    holder.join()
    assert result["status"] == "ok" and result["seconds"] >= 0.4, result
    manifest = json.loads((home / "manifest.json").read_text())
    assert [s["status"] for s in manifest["stages"][:2]] == ["cached", "cached"]

    monkeypatch.setattr(sweep_module, "TASK_LOCK_WAIT_S", 0.2)
    release.clear()
    holder = threading.Thread(target=first_run_still_holding)
    holder.start()
    held.wait(10)
    try:
        result = run_task(task, names)
    finally:
        release.set()
        holder.join()
    assert result["status"] == "failed" and "in use by another gridshell run" in result["message"]
