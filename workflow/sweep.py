"""``gridshell sweep``: the points of a parameter grid run on Dask, stages shared where they can be.

A sweep file names a project, the last stage to run and lists of values for dotted project keys;
the points are the product of those lists (in file order, the last key varying fastest)::

    project = "project.toml"        # relative to the sweep file
    until = "analysis"              # last stage run for each point (default "analysis")
    [parameters]
    "field.max_size_ratio" = [1.0, 2.0]
    "remesh.n_cells" = [60, 120]

Every point gets the normal output folder of a run, ``OUT/points/NNNN/``, with its manifest and
cache. A stage's cache key is its configuration and its upstream keys (workflow.runner), so
points that agree on every key upstream of a stage share that stage: the stages form a tree over
the points, and each run of stages between two branchings is one task, run in the folder of the
first point below it. The points below get its stage folders as hard links (copies where links
are impossible) with their manifest entries, so their own cache sees them as done. A point whose
stages are all up to date in its folder is not run at all: a killed sweep, rerun, recomputes only
what had not finished, and a finished sweep's rerun only reads the manifests.

A task that fails fails the points below it, each with the message; the others carry on. The
results are one row per point in ``OUT/sweep.csv`` and ``OUT/sweep.parquet`` and pictures in
``OUT/sweep.html`` (see :func:`write_results`).

Each point runs with one process: ``remesh.workers``, ``analysis.workers`` and ``fabrication.workers`` are 1 unless
the sweep varies them (the cache keys leave worker counts out: they change no result).
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any, Callable

from engine.errors import GridshellError, InputError

__all__ = ["SweepSpec", "Point", "load_sweep", "sweep_points", "plan_tasks", "run_sweep", "FIGURES"]

#: The figures of a point's analysis.json in the results, with their keys there.
FIGURES = {"lambda_LB": "lambda_LB", "lambda_NL_worst": "lambda_NL_worst", "delta_L_m": "delta_L_m",
           "total_beam_length_m": "total_beam_length_m", "beam_mass_kg": "beam_mass_kg", "n_nodes": "nodes",
           "n_beams": "beams", "max_utilisation": "max_utilisation"}
#: Keys a point's project gets unless the sweep varies them: one process per point.
ONE_PROCESS = {"remesh.workers": 1, "analysis.workers": 1, "fabrication.workers": 1}
#: The longest the progress stays silent (s).
PROGRESS_INTERVAL_S = 10.0


@dataclasses.dataclass(frozen=True)
class SweepSpec:
    """A sweep file read: its path, the project file, its TOML data, the last stage, the parameters."""

    file: Path
    project_file: Path
    project_data: dict
    until: str
    parameters: dict[str, list]


@dataclasses.dataclass(frozen=True)
class Point:
    """One point: its number (1-based), its values (key -> value), its project and its folder."""

    number: int
    values: dict[str, Any]
    project: Any
    folder: Path


def _stage_names() -> list[str]:
    from .stages import STAGES

    return [s.name for s in STAGES]


def load_sweep(path: str | Path) -> SweepSpec:
    """Read and check a sweep file: InputError naming the key for a missing project file, an unknown
    stage, a key that is not a project key, a value that is not a list, or an empty grid."""
    from .config import is_project_key, read_toml

    path = Path(path)
    data = read_toml(path, "sweep file", hint='write one with project = "project.toml" and a [parameters] table')
    unknown = sorted(set(data) - {"project", "until", "parameters"})
    if unknown:
        raise InputError(f"{path}: unknown key {unknown[0]!r}", hint="a sweep file has project, until and [parameters]")
    if not isinstance(data.get("project"), str):
        raise InputError(f"{path}: project = \"FILE\" is missing",
                         hint="name the project file, relative to the sweep file")
    project_file = (path.parent / data["project"]).resolve()
    if project_file.is_dir():
        project_file = project_file / "project.toml"
    if not project_file.is_file():
        raise InputError(f"{path}: project = {data['project']!r}: {project_file} does not exist")
    until = data.get("until", "analysis")
    names = _stage_names()
    if until not in names:
        raise InputError(f"{path}: until = {until!r} is not a stage", hint=f"stages are {', '.join(names)}")
    parameters = data.get("parameters")
    if not isinstance(parameters, dict) or not parameters:
        raise InputError(f"{path}: [parameters] is missing or empty",
                         hint='list values for dotted project keys, e.g. "remesh.n_cells" = [60, 120]')
    for key, values in parameters.items():
        if not is_project_key(key):
            raise InputError(f"{path}: [parameters] {key!r} is not a project key",
                             hint='keys are dotted project keys, e.g. "remesh.n_cells" or "field.max_size_ratio"')
        if not isinstance(values, list) or not values:
            raise InputError(f"{path}: [parameters] {key!r} must be a non-empty list of values",
                             hint=f'e.g. "{key}" = [{values!r}]' if not isinstance(values, list) else None)
    project_data = read_toml(project_file, "project file")
    return SweepSpec(file=path, project_file=project_file, project_data=project_data, until=until,
                     parameters={k: list(v) for k, v in parameters.items()})


def _with(data: dict, key: str, value: Any) -> None:
    """Set the dotted ``key`` of the TOML ``data`` (in place), making tables on the way."""
    from .config import set_key

    try:
        set_key(data, key, value)
    except GridshellError as exc:
        raise InputError(f"[parameters] {exc.args[0]}") from None


def sweep_points(spec: SweepSpec, out_dir: Path) -> list[Point]:
    """The points of the grid (product of the lists, the last key fastest), each validated: a value
    the project's validation rejects is an InputError naming the key and the value."""
    from .config import check_inputs, parse_project

    keys = list(spec.parameters)
    points = []
    for number, combination in enumerate(itertools.product(*spec.parameters.values()), start=1):
        values = dict(zip(keys, combination))
        data = copy.deepcopy(spec.project_data)
        for key, value in {**{k: v for k, v in ONE_PROCESS.items() if k not in values}, **values}.items():
            _with(data, key, value)
        try:
            project = parse_project(data, source=f"{spec.file} point {number}", base_dir=spec.project_file.parent)
            check_inputs(project)
        except GridshellError as exc:
            shown = ", ".join(f"{k} = {v!r}" for k, v in values.items())
            raise InputError(f"{spec.file}: [parameters] point {number} ({shown}) is not a valid project: "
                             f"{' '.join(str(exc.args[0] if exc.args else exc).split())}",
                             hint=getattr(exc, "hint", None)) from None
        points.append(Point(number=number, values=values, project=project,
                            folder=Path(out_dir) / "points" / f"{number:04d}"))
    return points


# ------------------------------------------------------------------------------------------ the plan


@dataclasses.dataclass
class Task:
    """Stages ``first``..``last`` (indices into the stages) of the points ``points`` (numbers), run in
    ``home`` with the project of the first of them, after ``parent`` (a Task, or None)."""

    id: int
    first: int
    last: int
    points: list[int]
    home: Path
    project: Any
    parent: "Task | None"


def stage_keys(project, until: str) -> list[str]:
    """The cache keys of the stages up to ``until`` for ``project`` (workflow.runner)."""
    from .runner import _stage_key, cache_version
    from .stages import STAGES

    version, keys, out = cache_version(), {}, []
    for stage in STAGES:
        keys[stage.name] = _stage_key(stage, project, keys, version)
        out.append(keys[stage.name])
        if stage.name == until:
            break
    return out


def plan_tasks(points: list[Point], keys: dict[int, list[str]]) -> list[Task]:
    """Tasks over the tree of stages the points share (``keys``: point number -> stage keys), parents
    before children: a task ends where its points part (their next keys differ) or at the last stage."""
    by_number = {p.number: p for p in points}
    depth = len(next(iter(keys.values())))
    tasks: list[Task] = []

    def split(members: list[int], first: int, parent: Task | None) -> None:
        level = first
        while level < depth - 1 and len({keys[m][level + 1] for m in members}) == 1:
            level += 1
        home = by_number[members[0]]
        task = Task(id=len(tasks), first=first, last=level, points=members, home=home.folder,
                    project=home.project, parent=parent)
        tasks.append(task)
        if level == depth - 1:
            return
        groups: dict[str, list[int]] = {}
        for m in members:
            groups.setdefault(keys[m][level + 1], []).append(m)
        for group in groups.values():
            split(group, level + 1, task)

    roots: dict[str, list[int]] = {}
    for p in points:
        roots.setdefault(keys[p.number][0], []).append(p.number)
    for group in roots.values():
        split(group, 0, None)
    return tasks


# ------------------------------------------------------------------------------------------ the folders


def _read_manifest(folder: Path) -> dict:
    try:
        return json.loads((Path(folder) / "manifest.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def up_to_date(folder: Path, keys: list[str]) -> bool:
    """Whether every stage with these keys has valid results in ``folder`` (the runner's own test:
    its key, its artifacts, and the upstream results it was made from)."""
    from .runner import _still_valid, made_from
    from .stages import STAGES

    entries = {s.get("name"): s for s in _read_manifest(folder).get("stages", [])}
    return all(_still_valid(entries.get(stage.name), key, Path(folder), made_from(stage.depends, entries.get))
               for stage, key in zip(STAGES, keys))


def _link_tree(source: Path, target: Path) -> None:
    def link(src: str, dst: str) -> None:
        try:
            os.link(src, dst)
        except OSError:
            shutil.copy2(src, dst)

    shutil.copytree(source, target, copy_function=link)


def seed(target: Path, source: Path, names: list[str], project) -> None:
    """Give ``target`` the stages ``names`` of ``source`` (hard links) and their manifest entries,
    unless it has them up to date already; its manifest keeps its own entries of the other stages.
    Holds ``target``'s lock."""
    from fabrication.files import write_text_atomic

    from .outdir import run_lock
    from .runner import _still_valid
    from .stages import STAGES

    source, target = Path(source), Path(target)
    if source.resolve() == target.resolve():
        return
    theirs = {s["name"]: s for s in _read_manifest(source).get("stages", [])}
    by_name = {s.name: s for s in STAGES}
    with run_lock(target):
        manifest = _read_manifest(target)
        mine = {s["name"]: s for s in manifest.get("stages", [])}
        for name in names:
            entry = theirs[name]
            if _still_valid(mine.get(name), entry["key"], target):
                continue
            stage = by_name[name]
            shutil.rmtree(target / stage.folder, ignore_errors=True)
            if (source / stage.folder).is_dir():
                _link_tree(source / stage.folder, target / stage.folder)
            for published in stage.published:
                (target / published).unlink(missing_ok=True)
                if (source / published).is_file():
                    os.link(source / published, target / published)
            mine[name] = entry
        base = manifest or _read_manifest(source)
        ordered = [mine.get(s.name) or {"name": s.name, "folder": s.folder, "status": "not run"} for s in STAGES]
        write_text_atomic(target / "manifest.json", json.dumps(
            {**base, "out_dir": str(target.resolve()), "config": project.model_dump(mode="json"),
             "stages": ordered}, indent=2))


#: How long a task waits (s) for its folder while another process runs it: Dask runs a task again
#: when it takes a worker for lost (a pause, a network split) although that worker goes on with it.
TASK_LOCK_WAIT_S = 3600.0
TASK_LOCK_POLL_S = 2.0


def run_task(task: Task, names: list[str], parent: dict | None = None) -> dict:
    """Run one task (on a Dask worker or here): seed its folder from the parent's, run its stages.
    Returns {"status": "ok" | "failed", "message", "home", "seconds"}; never raises. Where another
    process holds the folder (the same task run twice), it waits for it, up to TASK_LOCK_WAIT_S,
    and then finds its stages in the cache."""
    started = time.perf_counter()
    if parent is not None and parent["status"] != "ok":
        return {**parent, "seconds": 0.0}
    try:
        from threadpoolctl import threadpool_limits

        from .outdir import RunInProgress
        from .progress import Progress
        from .runner import run_project
        from .stages import STAGES

        while True:
            try:
                if parent is not None:
                    seed(task.home, Path(parent["home"]), names[:task.first], task.project)
                with threadpool_limits(1):
                    summary = run_project(task.project, task.home, STAGES, until=names[task.last],
                                          progress=Progress(enabled=False))
                break
            except RunInProgress:
                if time.perf_counter() - started > TASK_LOCK_WAIT_S:
                    raise
                time.sleep(TASK_LOCK_POLL_S)
        if summary.message:
            raise GridshellError(summary.message)
    except BaseException as exc:  # noqa: BLE001 - a failing point is a row, not the end of the sweep
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if isinstance(exc, KeyboardInterrupt):
            raise
        return {"status": "failed", "message": f"{names[task.first]}..{names[task.last]}: {text}",
                "home": str(task.home), "seconds": time.perf_counter() - started}
    return {"status": "ok", "message": "", "home": str(task.home), "seconds": time.perf_counter() - started}


# ------------------------------------------------------------------------------------------ running


def _client(scheduler: str | None, workers: int | None):
    """A Dask client: on the cluster at ``scheduler``, or on a LocalCluster of ``workers`` processes
    (default: the cores) with one thread each."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError) as exc:
            raise InputError(f"--scheduler {scheduler}: no Dask scheduler answers there ({exc})",
                             hint="start one with: dask scheduler, and workers with: dask worker ADDRESS") from None
    count = workers or os.cpu_count() or 1
    dask.config.set({"distributed.worker.daemon": False, "distributed.admin.system-monitor.gil.enabled": False})
    cluster = LocalCluster(n_workers=count, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=40)
    return Client(cluster), cluster


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 60} min {seconds % 60:02d} s" if seconds >= 60 else f"{seconds} s"


def run_sweep(spec: SweepSpec, out_dir: Path, *, scheduler: str | None = None, workers: int | None = None,
              say: Callable[[str], None] | None = None) -> list[dict]:
    """Run every point not up to date (on Dask), then write the results; returns the rows."""
    say = say or (lambda text: None)
    out_dir = Path(out_dir)
    points = sweep_points(spec, out_dir)
    names = _stage_names()
    names = names[:names.index(spec.until) + 1]
    keys = {p.number: stage_keys(p.project, spec.until) for p in points}
    todo = [p for p in points if not up_to_date(p.folder, keys[p.number])]
    started = time.perf_counter()
    outcome: dict[int, dict] = {p.number: {"status": "ok", "message": "", "seconds": 0.0} for p in points}
    say(f"sweep: {len(points)} points, {len(points) - len(todo)} up to date, {len(todo)} to run "
        f"(stages up to {spec.until}) -> {out_dir}")
    if todo:
        tasks = plan_tasks(todo, keys)
        say(f"sweep: {len(tasks)} tasks ({sum(t.last - t.first + 1 for t in tasks)} stage runs for "
            f"{len(todo) * len(names)} stages of the points)")
        client, cluster = _client(scheduler, workers)
        try:
            _run_on(client, tasks, todo, names, outcome, started, say)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    rows = [_row(p, outcome[p.number], spec) for p in points]
    write_results(rows, spec, out_dir)
    failed = sum(r["status"] != "ok" for r in rows)
    say(f"sweep: {len(rows) - failed} points ok, {failed} failed in {_duration(time.perf_counter() - started)}")
    return rows


def _run_on(client, tasks: list[Task], todo: list[Point], names: list[str], outcome: dict, started: float,
            say: Callable[[str], None]) -> None:
    """Submit the tasks, each child when its parent has finished (with the parent's result as a plain
    value, so that the scheduler spreads the children over the workers rather than keeping them
    where the parent ran), and follow them to the end: a progress line when points finish, and at
    least every PROGRESS_INTERVAL_S."""
    from distributed import wait

    children: dict[int, list[Task]] = {}
    for task in tasks:
        if task.parent is not None:
            children.setdefault(task.parent.id, []).append(task)
    by_key: dict[str, Task] = {}

    def submit(task: Task, parent: dict | None):
        future = client.submit(run_task, task, names, parent, key=f"sweep-task-{task.id}", pure=False)
        by_key[future.key] = task
        return future

    by_number = {p.number: p for p in todo}
    seconds: dict[int, float] = {}
    pending = {submit(task, None) for task in tasks if task.parent is None}
    finished = failed = 0
    told = time.perf_counter()
    while pending:
        try:
            done, pending = wait(pending, timeout=PROGRESS_INTERVAL_S, return_when="FIRST_COMPLETED")
        except TimeoutError:
            done = set()
        points_before = finished
        for future in done:
            task = by_key[future.key]
            result = future.result()
            seconds[task.id] = result.get("seconds", 0.0)
            pending |= {submit(child, result) for child in children.get(task.id, [])}
            if task.last != len(names) - 1:
                continue
            home = Path(result["home"])
            for number in task.points:
                point = by_number[number]
                outcome[number] = {"status": result["status"], "message": result["message"],
                                   "seconds": sum(seconds.get(t.id, 0.0) for t in _chain(task))}
                if result["status"] == "ok" and point.folder.resolve() != home.resolve():
                    seed(point.folder, home, names, point.project)
                finished += 1
                failed += result["status"] != "ok"
        now = time.perf_counter()
        if finished > points_before or now - told >= PROGRESS_INTERVAL_S:
            running = sum(len([k for k in keys if str(k).startswith("sweep-task-")])
                          for keys in client.processing().values())
            elapsed = now - started
            left = elapsed / finished * (len(todo) - finished) if finished else None
            say(f"sweep: {finished}/{len(todo)} points done, {failed} failed, {running} tasks on the workers, "
                f"{_duration(elapsed)} elapsed" + (f", about {_duration(left)} left"
                                                   if left is not None and finished < len(todo) else ""))
            told = now


def _chain(task: Task) -> list[Task]:
    out = []
    while task is not None:
        out.append(task)
        task = task.parent
    return out


def _computed_seconds(folder: Path, names: list[str]) -> float:
    """Seconds the stages ``names`` of the run in ``folder`` took when they were computed (shared
    stages in full; the manifest's ``computed_s``)."""
    entries = {s.get("name"): s for s in _read_manifest(folder).get("stages", [])}
    return float(sum(entries.get(n, {}).get("computed_s", entries.get(n, {}).get("duration_s", 0.0)) or 0.0
                     for n in names))


def _row(point: Point, outcome: dict, spec: SweepSpec) -> dict:
    """The results row of a point: its values, status, message, seconds (to compute its stages,
    shared ones in full) and figures."""
    names = _stage_names()
    seconds = (_computed_seconds(point.folder, names[:names.index(spec.until) + 1])
               if outcome["status"] == "ok" else outcome["seconds"])
    row: dict[str, Any] = {"point": point.number, **point.values, "status": outcome["status"],
                           "message": outcome["message"], "seconds": round(seconds, 3)}
    analysis = point.folder / "06-analysis" / "analysis.json"
    figures = {}
    if outcome["status"] == "ok" and analysis.is_file():
        try:
            figures = json.loads(analysis.read_text(encoding="utf-8"))
        except ValueError:
            figures = {}
    for column, key in FIGURES.items():
        value = figures.get(key)
        row[column] = float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None
    row["folder"] = str(Path("points") / point.folder.name)
    return row


# ------------------------------------------------------------------------------------------ results


def write_results(rows: list[dict], spec: SweepSpec, out_dir: Path) -> dict[str, Path]:
    """``sweep.csv`` and ``sweep.parquet`` (one row per point: point, a column per parameter key as
    named in the file, status, message, seconds, the FIGURES, folder) and ``sweep.html`` (each figure
    against each parameter, and the Pareto front of mass against lambda_NL_worst). Atomic writes."""
    import pandas as pd

    from fabrication.files import atomic_path, write_text_atomic

    from .plots.sweep import sweep_html

    out_dir.mkdir(parents=True, exist_ok=True)
    frame = pd.DataFrame(rows)
    for column in ("n_nodes", "n_beams"):
        frame[column] = frame[column].astype("Int64")
    paths = {"csv": out_dir / "sweep.csv", "parquet": out_dir / "sweep.parquet", "html": out_dir / "sweep.html"}
    with atomic_path(paths["csv"]) as tmp:
        frame.to_csv(tmp, index=False)
    with atomic_path(paths["parquet"]) as tmp:
        frame.to_parquet(tmp, index=False)
    write_text_atomic(paths["html"], sweep_html(frame, list(spec.parameters), title=spec.file.stem))
    return paths


def cmd_sweep(args) -> int:
    """The ``gridshell sweep`` command."""
    spec = load_sweep(args.sweep)
    out_dir = Path(args.out) if args.out else Path("out") / spec.file.stem
    say = (lambda text: None) if args.quiet else (lambda text: print(text, file=sys.stderr, flush=True))
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers {args.workers}: give 1 or more")
    if args.workers is not None and args.scheduler:
        raise InputError("--workers applies to the local cluster; a --scheduler cluster has its own workers")
    run_sweep(spec, out_dir, scheduler=args.scheduler, workers=args.workers, say=say)
    print(f"results: {(out_dir / 'sweep.csv').resolve()}")
    print(f"plots: {(out_dir / 'sweep.html').resolve()}")
    return 0
