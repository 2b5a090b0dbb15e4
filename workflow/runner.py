"""The stage runner: ordered stages, hash-based caching, atomic stage folders, manifest.

Each stage declares its folder, the project sections it reads and the stages it needs.
Its cache key hashes the product version and a digest of its source code, its config sections,
the keys of the stages it depends on and any external input (the surface file's bytes). A stage is
called with the typed results of the stages it takes (run, or loaded from their artifacts when
cached), the project and a :class:`StageContext`; it returns its own result. A stage whose key and
artifacts are unchanged since the last run, and whose upstream results are still those it was made
from (``made_from`` in its manifest entry; ``--only STAGE --force`` may have remade them), is
skipped ("cached"). A stage writes into a temporary folder that replaces ``OUT/NN-stage`` only when
the stage succeeds, so an interrupted or failed run never leaves half-written artifacts under the
real name. ``OUT/manifest.json`` records every stage's status, duration, key and artifacts.
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import platform
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Any

from engine.errors import GridshellError
from fabrication.files import atomic_folder, write_text_atomic

from .config import KEYS_LEFT_OUT_AT_DEFAULT, Project, stage_sections
from .outdir import remove_leftovers, run_lock
from .progress import Progress
from .stage_view import stage_view

__all__ = ["Stage", "StageContext", "RunSummary", "run_project", "product_version", "cache_version",
           "STATUS_RAN", "STATUS_CACHED", "STATUS_FAILED", "STATUS_NOT_RUN"]

log = logging.getLogger(__name__)

STATUS_RAN, STATUS_CACHED, STATUS_FAILED, STATUS_NOT_RUN = "ran", "cached", "failed", "not run"


def product_version() -> str:
    try:
        return metadata.version("gridshell")
    except metadata.PackageNotFoundError:
        return "0+unknown"


def source_digest(root: Path, packages: tuple[str, ...] = ("engine", "fabrication", "workflow")) -> str:
    """A digest of the files of ``packages`` under ``root`` (their paths and bytes): the Python
    sources and the data they read (the tube catalogues), not Python's byte-code caches."""
    digest = hashlib.sha256()
    for package in packages:
        files = (p for p in (root / package).rglob("*")
                 if p.is_file() and "__pycache__" not in p.parts and p.suffix not in (".pyc", ".pyo"))
        for path in sorted(files):
            digest.update(path.relative_to(root).as_posix().encode() + b"\0")
            digest.update(path.read_bytes())
    return digest.hexdigest()


@functools.lru_cache(maxsize=1)
def cache_version() -> str:
    """The version that goes into every cache key: the product's and a digest of its sources and
    data, so that results made by other code (an upgrade, or a working copy changed since) are
    never taken from the cache."""
    return f"{product_version()}+{source_digest(Path(__file__).resolve().parents[1])[:16]}"


def results_digest(entry: dict | None) -> str | None:
    """One digest of a stage's results: its artifacts' paths and contents (None: no results)."""
    if not entry or not entry.get("artifacts"):
        return None
    pairs = sorted((a["path"], a["sha256"]) for a in entry["artifacts"])
    return hashlib.sha256(json.dumps(pairs).encode()).hexdigest()


def made_from(depends: tuple[str, ...], entry_of: Callable[[str], dict | None]) -> dict[str, str | None]:
    """The results digests of the stages in ``depends`` as they are now (``entry_of``: a stage's
    manifest entry by name): what a stage made now is made from, and a cached one must have been."""
    return {name: results_digest(entry_of(name)) for name in depends}


def solvers_describe() -> dict:
    """Which library factors the stiffness matrices here (engine.structure.solvers)."""
    from engine.structure.solvers import describe

    return describe()


def library_versions() -> dict[str, str]:
    out = {"python": platform.python_version(), "gridshell": product_version()}
    for name in ("numpy", "scipy", "trimesh", "pydantic", "pint", "ezdxf", "pandas", "shapely",
                 "build123d", "cadquery", "matplotlib", "rhino3dm", "pyacvd", "pyfe3d", "pypardiso", "mkl"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return out


def file_digest(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


@dataclass
class StageContext:
    """Where a stage writes and what it reports: its folder to write into (a temporary one until
    the stage succeeds), the run's output folder, progress, and the findings of the stages before
    it (``earlier_findings``, run or cached). A stage puts the seconds of its steps in
    ``timings``: they go into the manifest (``step_seconds``), never into an artifact, so that the
    same input gives the same bytes. Upstream results and the project are the stage's arguments,
    not the context's."""

    folder: Path
    out_dir: Path
    progress: Progress
    findings: list[dict] = field(default_factory=list)
    earlier_findings: list[dict] = field(default_factory=list)
    stage: str = ""
    timings: dict[str, float] = field(default_factory=dict)

    def step(self, text: str, fraction: float | None = None) -> None:
        """Report the current step of the stage (and optionally its completed fraction)."""
        log.debug("stage %s: %s", self.stage, text)
        self.progress.step(text, fraction)

    def report_findings(self, findings: list[dict]) -> None:
        """Record the stage's findings (engine.findings.Finding dicts): failing checks and what
        could not be built. They go into the manifest, the end of the run and the report."""
        self.findings.extend(findings)


@dataclass(frozen=True)
class Stage:
    """A registered stage.

    run(**upstream, project=..., ctx=...) -> result writes its artifacts into ctx.folder and
    returns the stage's result; ``upstream`` is the result of each stage in ``takes``, passed as
    the keyword named after that stage (``run(surface=..., shell=..., project=..., ctx=...)``).
    load(folder, project) -> result rebuilds that result from the artifacts of a cached run.
    depends: the stages whose keys go into this stage's key (what it reads, as results or as
    files); takes: those whose results it is called with (default: all of ``depends``).
    external(project) -> bytes digests of inputs outside the project file (e.g. a mesh file).
    published: files the stage writes outside its folder (relative to OUT, e.g. report.html),
    recorded and checked like its artifacts.
    """

    name: str
    folder: str
    run: Callable[..., Any]
    load: Callable[[Path, Project], Any]
    depends: tuple[str, ...] = ()
    takes: tuple[str, ...] | None = None
    external: Callable[[Project], str] | None = None
    published: tuple[str, ...] = ()

    @property
    def inputs(self) -> tuple[str, ...]:
        """The stages whose results ``run`` is called with."""
        return self.depends if self.takes is None else self.takes


@dataclass
class RunSummary:
    out_dir: Path
    stages: list[dict] = field(default_factory=list)
    stopped_at: str | None = None
    message: str | None = None

    @property
    def manifest_path(self) -> Path:
        return self.out_dir / "manifest.json"

    @property
    def findings(self) -> list[dict]:
        """Every finding of the stages run or cached, in stage order."""
        return [f for stage in self.stages for f in stage.get("findings", [])]


def _section_value(project: Project, path: str):
    """JSON of a project section named by a dotted path ("fabrication.joints")."""
    value = project
    for name in path.split("."):
        value = getattr(value, name)
    if hasattr(value, "model_dump"):
        return value.model_dump(mode="json")
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    return [item.model_dump(mode="json") for item in value]


#: Settings that change how a stage runs, not what it makes: left out of the cache keys.
NOT_IN_KEYS = ("workers", "choose", "choose_from", "fit_grid_to_tubes")
def _in_key(section: str, key: str, value) -> bool:
    """Whether a section's key goes into the cache key: not a worker count, not a later key at its default."""
    later = KEYS_LEFT_OUT_AT_DEFAULT.get(section, {})
    return key not in NOT_IN_KEYS and not (key in later and value == later[key])


def _stage_key(stage: Stage, project: Project, keys: dict[str, str], version: str) -> str:
    config = {name: _section_value(project, name) for name in stage_sections(stage.name, project)}
    config = {name: {k: v for k, v in value.items() if _in_key(name, k, v)} if isinstance(value, dict) else value
              for name, value in config.items()}
    payload = {"stage": stage.name, "version": version, "config": config,
               "upstream": {d: keys[d] for d in stage.depends},
               "external": stage.external(project) if stage.external else None}
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def readable_sections(stage: Stage, by_name: dict[str, Stage], project: Project) -> tuple[str, ...]:
    """The project sections ``stage`` may read: its own (its cache key) and those of every stage
    upstream of it, whose keys are in its key."""
    sections: list[str] = []
    seen: set[str] = set()
    todo = [stage.name]
    while todo:
        name = todo.pop()
        if name in seen or name not in by_name:
            continue
        seen.add(name)
        sections += stage_sections(name, project)
        todo += by_name[name].depends
    return tuple(dict.fromkeys(sections))


def _artifacts(folder: Path, out_dir: Path, published: tuple[str, ...] = ()) -> list[dict]:
    files = sorted(p for p in folder.rglob("*") if p.is_file()) if folder.is_dir() else []
    files += [out_dir / name for name in published if (out_dir / name).is_file()]
    return [{"path": p.relative_to(out_dir).as_posix(), "sha256": file_digest(p), "bytes": p.stat().st_size}
            for p in files]


def _still_valid(entry: dict | None, key: str, out_dir: Path, made_from: dict | None = None) -> bool:
    return _why_stale(entry, key, out_dir, made_from) is None


def _why_stale(entry: dict | None, key: str, out_dir: Path, made_from: dict | None = None) -> str | None:
    """Why a stage's cached result cannot be used (None: it can), in words for the log.
    made_from: the results digests of the stages it depends on, as they are now (None: not checked)."""
    if not entry:
        return "not run before"
    if entry.get("status") not in (STATUS_RAN, STATUS_CACHED):
        return f"last {entry.get('status')}"
    if entry.get("key") != key:
        return "its settings, the code or an upstream stage's settings changed"
    if made_from is not None:
        was = entry.get("made_from") or {}
        changed = [name for name, digest in made_from.items() if was.get(name) != digest]
        if changed:
            return f"the {changed[0]} stage's results changed since it ran"
    for artifact in entry.get("artifacts", []):
        path = out_dir / artifact["path"]
        if not path.is_file():
            return f"{artifact['path']} is missing"
        if path.stat().st_size != artifact["bytes"] or file_digest(path) != artifact["sha256"]:
            return f"{artifact['path']} changed"
    return None if entry.get("artifacts") else "it has no artifacts"


def _read_manifest(path: Path) -> dict:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def run_project(project: Project, out_dir: Path, stages: list[Stage], *, until: str | None = None,
                only: str | None = None, force: bool = False, progress: Progress | None = None,
                project_file: str | None = None) -> RunSummary:
    """Run (or skip when cached) the stages of a project in order; write OUT/manifest.json.

    until: stop after this stage; only: run just this stage (its inputs must be available);
    force: ignore the cache. The run holds OUT's lock (another run on OUT raises
    ``workflow.outdir.RunInProgress``) and first removes what a killed run left there
    (workflow.outdir).
    """
    names = [s.name for s in stages]
    for option, value in (("--until", until), ("--only", only)):
        if value is not None and value not in names:
            raise GridshellError(f"{option} {value!r}: unknown stage; stages are {', '.join(names)}")
    out_dir = Path(out_dir)
    with run_lock(out_dir):
        remove_leftovers(out_dir, [s.folder for s in stages], [p for s in stages for p in s.published])
        return _run(project, out_dir, stages, until=until, only=only, force=force, progress=progress,
                    project_file=project_file)


def _run(project: Project, out_dir: Path, stages: list[Stage], *, until: str | None, only: str | None,
         force: bool, progress: Progress | None, project_file: str | None) -> RunSummary:
    """run_project's body, with the lock held."""
    names = [s.name for s in stages]
    progress = progress or Progress(enabled=False)
    version = cache_version()
    manifest_path = out_dir / "manifest.json"
    previous = {s["name"]: s for s in _read_manifest(manifest_path).get("stages", [])}
    by_name = {s.name: s for s in stages}
    results: dict[str, Any] = {}
    keys: dict[str, str] = {}
    records: dict[str, dict] = {}
    summary = RunSummary(out_dir=out_dir)

    def result_of(name: str) -> Any:
        """The result of an earlier stage: this run's, or loaded from the artifacts of a cached one."""
        if name in results:
            return results[name]
        stage = by_name[name]
        entry = records.get(name) or previous.get(name)
        if not entry or entry.get("status") not in (STATUS_RAN, STATUS_CACHED) or entry.get("key") != keys.get(name):
            raise GridshellError(f"stage '{name}' has no up-to-date results in {out_dir}",
                                 hint=f"run the earlier stages first: gridshell run ... --until {name}")
        results[name] = stage.load(out_dir / stage.folder, view_of(stage))
        return results[name]

    def view_of(stage: Stage) -> Project:
        """The project as ``stage`` may read it (workflow.stage_view)."""
        return stage_view(project, readable_sections(stage, by_name, project), stage.name)

    def context(stage: Stage, folder: Path) -> StageContext:
        earlier = names[:names.index(stage.name)]
        return StageContext(folder=folder, out_dir=out_dir, progress=progress, stage=stage.name,
                            earlier_findings=[f for n in earlier for f in (records.get(n) or {}).get("findings", [])])

    def write_manifest() -> None:
        # stages after --until keep what an earlier run made (their cache is checked when they run)
        kept = {n: previous[n] for n in names[last + 1:] if n in previous} if summary.stopped_at is None else {}
        ordered = [records.get(n) or kept.get(n) or {"name": n, "folder": by_name[n].folder, "status": STATUS_NOT_RUN}
                   for n in names]
        manifest = {"product": "gridshell", "version": version,
                    "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                    "project_file": project_file, "out_dir": str(out_dir.resolve()),
                    "stopped_at": summary.stopped_at, "message": summary.message,
                    "stages": ordered, "config": project.model_dump(mode="json"),
                    "versions": library_versions(), "factorisation": solvers_describe()}
        write_text_atomic(manifest_path, json.dumps(manifest, indent=2))

    last = names.index(until) if until else len(names) - 1
    for index, stage in enumerate(stages):
        keys[stage.name] = _stage_key(stage, project, keys, version)
        if index > last:
            break
        if only is not None and stage.name != only:
            entry = previous.get(stage.name)
            if entry and entry.get("key") == keys[stage.name]:
                records[stage.name] = entry
            continue
        folder = out_dir / stage.folder
        entry = previous.get(stage.name)
        inputs = made_from(stage.depends, lambda name: records.get(name) or previous.get(name))
        stale = "--force" if force else _why_stale(entry, keys[stage.name], out_dir, inputs)
        if stale is None:
            log.info("stage %s: cached (key %s)", stage.name, keys[stage.name][:12])
            records[stage.name] = {**entry, "status": STATUS_CACHED, "duration_s": 0.0,
                                   "computed_s": entry.get("computed_s", entry.get("duration_s", 0.0))}
            progress.stage_done(stage.name, STATUS_CACHED, 0.0, findings=len(entry.get("findings", [])))
            summary.stages.append(records[stage.name])
            continue
        log.info("stage %s: runs (%s; key %s)", stage.name, stale, keys[stage.name][:12])
        progress.stage_start(stage.name)
        started = time.perf_counter()
        tmp = atomic_folder(out_dir, stage.folder)
        ctx = context(stage, tmp)
        try:
            upstream = {name: result_of(name) for name in stage.inputs}
            results[stage.name] = stage.run(**upstream, project=view_of(stage), ctx=ctx)
        except BaseException as exc:
            shutil.rmtree(tmp, ignore_errors=True)
            shutil.rmtree(folder, ignore_errors=True)
            records[stage.name] = {"name": stage.name, "folder": stage.folder, "status": STATUS_FAILED,
                                   "message": str(exc).splitlines()[0] if str(exc) else type(exc).__name__,
                                   "duration_s": round(time.perf_counter() - started, 3),
                                   "key": keys[stage.name], "artifacts": []}
            summary.stopped_at = stage.name
            log.info("stage %s: failed after %.1f s: %s", stage.name, time.perf_counter() - started, exc)
            progress.stage_done(stage.name, STATUS_FAILED, time.perf_counter() - started)
            write_manifest()
            raise
        shutil.rmtree(folder, ignore_errors=True)
        tmp.rename(folder)
        duration = time.perf_counter() - started
        records[stage.name] = {"name": stage.name, "folder": stage.folder, "status": STATUS_RAN,
                               "duration_s": round(duration, 3), "computed_s": round(duration, 3),
                               "key": keys[stage.name], "made_from": inputs,
                               "artifacts": _artifacts(folder, out_dir, stage.published),
                               "findings": ctx.findings,
                               **({"step_seconds": ctx.timings} if ctx.timings else {})}
        summary.stages.append(records[stage.name])
        log.info("stage %s: ran in %.1f s, %d finding(s)", stage.name, duration, len(ctx.findings))
        progress.stage_done(stage.name, STATUS_RAN, duration, findings=len(ctx.findings))
        write_manifest()
    write_manifest()
    return summary
