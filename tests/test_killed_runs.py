"""Killed, concurrent and damaged runs, with real processes and signals: one run per output folder,
nothing left behind by a killed run (neither files nor worker processes), and the next run gives
the artifacts an uninterrupted run gives."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from tests.test_runner import _project, _stages
from workflow.outdir import LOCK_NAME, RunInProgress, run_lock
from workflow.runner import run_project

ROOT = Path(__file__).resolve().parents[1]
GRIDSHELL = [sys.executable, "-m", "workflow.cli"]


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False
    return state != "Z"


def _descendants(pid: int) -> set[int]:
    """Every process below ``pid`` (from /proc's parent ids)."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parents[int(entry.name)] = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (FileNotFoundError, ProcessLookupError, IndexError, ValueError):
                pass
    out, frontier = set(), {pid}
    while frontier:
        frontier = {child for child, parent in parents.items() if parent in frontier} - out
        out |= frontier
    return out


def _wait_gone(pids: set[int], seconds: float) -> set[int]:
    end = time.monotonic() + seconds
    while time.monotonic() < end and any(_alive(p) for p in pids):
        time.sleep(0.1)
    return {p for p in pids if _alive(p)}


def test_a_second_run_on_a_locked_folder_stops_naming_the_holder(tmp_path):
    calls: list[str] = []
    with run_lock(tmp_path):
        with pytest.raises(RunInProgress, match=f"pid {os.getpid()}") as caught:
            run_project(_project(), tmp_path, _stages(calls))
    assert "--out" in caught.value.hint and calls == []
    run_project(_project(), tmp_path, _stages(calls))  # released with the block
    assert calls == ["surface", "shell", "field", "remesh"]


def test_the_cli_exits_2_while_another_process_holds_the_folder(tmp_path):
    (tmp_path / "project.toml").write_text('[surface]\ntemplate = "mockup"\n')
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys, time
        from workflow.outdir import run_lock
        with run_lock({str(tmp_path / 'out')!r}):
            print("locked", flush=True)
            time.sleep(60)
        """)], cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        done = subprocess.run([*GRIDSHELL, "run", str(tmp_path / "project.toml"), "--out", str(tmp_path / "out")],
                              cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert done.returncode == 2
        assert f"pid {holder.pid}" in done.stderr and "Traceback" not in done.stderr
        assert not (tmp_path / "out" / "01-surface").exists()
    finally:
        holder.kill()
        holder.wait()
    # the kernel released the killed holder's lock: the folder is free again
    with run_lock(tmp_path / "out"):
        pass


def test_leftovers_of_a_killed_run_are_removed_and_nothing_else(tmp_path):
    calls: list[str] = []
    run_project(_project(), tmp_path, _stages(calls))
    stale = tmp_path / ".02-shell.k3j4l5"
    stale.mkdir()
    (stale / ".joints.abc.step").write_text("ISO-10303-21; half")
    (tmp_path / ".manifest.x1y2.json").write_text("{")
    (tmp_path / ".keep").write_text("a user's file")
    (tmp_path / "notes.txt").write_text("a user's file")
    run_project(_project(), tmp_path, _stages(calls))
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted([".keep", "notes.txt", LOCK_NAME, "manifest.json", "01-surface", "02-shell", "03-field",
                           "04-remesh"])


_POOL = """
import os, sys, time
from concurrent.futures import ProcessPoolExecutor
from fabrication.workers import exit_with_parent

with ProcessPoolExecutor(max_workers=2, initializer={init}, initargs=(os.getpid(),)) as pool:
    pids = set()
    futures = [pool.submit(time.sleep, 120) for _ in range(2)]
    time.sleep(1.0)
    print(" ".join(str(p) for p in pool._processes), flush=True)
    time.sleep(120)
"""


@pytest.mark.parametrize("watch", [True, False])
def test_pool_workers_end_within_seconds_of_their_parents_sigkill(watch):
    """With exit_with_parent as the initializer the workers are gone 3 s after the parent's
    SIGKILL; without it (the control) they are still there."""
    script = _POOL.format(init="exit_with_parent" if watch else "None")
    parent = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, stdout=subprocess.PIPE, text=True)
    workers = {int(p) for p in parent.stdout.readline().split()}
    try:
        assert len(workers) == 2 and all(_alive(p) for p in workers)
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        left = _wait_gone(workers, 3.0)
        assert left == (set() if watch else workers)
    finally:
        for pid in workers:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


def _sigkill_when(command: list[str], ready, *, poll_s: float = 0.2, seconds: float = 600.0) -> set[int]:
    """Start ``command``, SIGKILL it as soon as ``ready()`` holds while it has worker processes,
    and return those workers' pids."""
    run = subprocess.Popen(command, cwd=ROOT)
    below: set[int] = set()
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end and run.poll() is None and not below:
            if ready():
                below = _descendants(run.pid)
            time.sleep(poll_s)
        assert below, "the run had its workers when it was killed"
        run.send_signal(signal.SIGKILL)
        run.wait()
    finally:
        if run.poll() is None:
            run.kill()
    return below


#: Formats that must be byte-identical between two runs of the same input on one day (the files
#: that carry a date carry the day, fabrication.files.file_date: STEP, PDF, XLSX, IFC and 3DM
#: headers); pictures are compared by their pixels. That is every file a run writes.
DETERMINISTIC = (".csv", ".json", ".obj", ".ply", ".npz", ".stl", ".dxf", ".nc1", ".html", ".step", ".pdf", ".xlsx",
                 ".ifc", ".3dm")


def _hashes(out: Path) -> dict[str, str]:
    """sha256 of every deterministic artifact of a run, from its manifest."""
    return {a["path"]: a["sha256"] for stage in json.loads((out / "manifest.json").read_text())["stages"]
            for a in stage.get("artifacts", []) if a["path"].endswith(DETERMINISTIC)}


def _suffixes(out: Path) -> set[str]:
    """The suffixes of a run's artifacts (every file its manifest lists)."""
    return {Path(a["path"]).suffix for stage in json.loads((out / "manifest.json").read_text())["stages"]
            for a in stage.get("artifacts", [])}


def _different_pictures(a: Path, b: Path) -> list[str]:
    import numpy as np
    from PIL import Image

    out = []
    for path in sorted(a.rglob("*.png")):
        other = b / path.relative_to(a)
        if not other.is_file() or not np.array_equal(np.asarray(Image.open(path)), np.asarray(Image.open(other))):
            out.append(path.relative_to(a).as_posix())
    return out


@pytest.mark.slow
def test_a_run_killed_during_fabrication_leaves_nothing_and_the_next_run_heals(tmp_path):
    """SIGKILL of `gridshell run` (the default job) while its joint workers build: within 5 s no
    process of it is left; the next run removes the temporary folder, reuses the stages that were
    complete, and writes the same files, byte for byte, as an uninterrupted run (pictures: the
    same pixels)."""
    reference = tmp_path / "reference"
    subprocess.run([*GRIDSHELL, "run", "--out", str(reference), "--quiet"], cwd=ROOT, check=True, timeout=900)
    out = tmp_path / "killed"
    def building_joints() -> bool:
        if not list(out.glob(".07-fabrication.*/joints")):
            return False
        time.sleep(3.0)  # the workers are building joints
        return True

    below = _sigkill_when([*GRIDSHELL, "run", "--out", str(out), "--quiet"], building_joints)
    assert list(out.glob(".07-fabrication.*")), "the run reached fabrication"
    assert _wait_gone(below, 5.0) == set(), "no worker outlives the killed run"
    assert list(out.glob(".07-fabrication.*")), "the kill left its temporary folder"
    subprocess.run([*GRIDSHELL, "run", "--out", str(out), "--quiet"], cwd=ROOT, check=True, timeout=900)
    assert not [p.name for p in out.iterdir() if p.name.startswith(".") and p.name != LOCK_NAME]
    statuses = {s["name"]: s["status"] for s in json.loads((out / "manifest.json").read_text())["stages"]}
    assert statuses["analysis"] == "cached" and statuses["fabrication"] == "ran"
    # same input, same bytes: every stage's files (the killed run ran the stages before
    # fabrication itself), and the same pixels in every picture
    mine, theirs = _hashes(out), _hashes(reference)
    assert len(mine) > 100 and set(mine) == set(theirs)
    assert _suffixes(out) <= {*DETERMINISTIC, ".png"}, "every file is compared: by its bytes or its pixels"
    assert sorted(k for k in mine if mine[k] != theirs[k]) == []
    assert _different_pictures(out, reference) == []


@pytest.mark.slow
def test_a_run_killed_during_its_nonlinear_paths_leaves_no_worker_and_heals(tmp_path):
    """SIGKILL of `gridshell run` while the analysis's process pool runs the non-linear paths:
    within 5 s no worker is left, and the next run writes the analysis an uninterrupted run writes."""
    reference = tmp_path / "reference"
    until = ["--until", "analysis", "--quiet"]
    subprocess.run([*GRIDSHELL, "run", "--out", str(reference), *until], cwd=ROOT, check=True, timeout=900)
    out = tmp_path / "killed"
    below = _sigkill_when([*GRIDSHELL, "run", "--out", str(out), *until],
                          lambda: bool(list(out.glob(".06-analysis.*"))), poll_s=0.05)
    assert _wait_gone(below, 5.0) == set(), "no path worker outlives the killed run"
    subprocess.run([*GRIDSHELL, "run", "--out", str(out), *until], cwd=ROOT, check=True, timeout=900)
    assert not [p.name for p in out.iterdir() if p.name.startswith(".") and p.name != LOCK_NAME]
    for name in ("analysis.json", "members.csv", "response.csv"):
        assert (out / "06-analysis" / name).read_bytes() == (reference / "06-analysis" / name).read_bytes(), name


@pytest.mark.parametrize("damage", ["truncated", "same size"])
def test_the_cli_reruns_the_stage_of_a_damaged_artifact_and_only_it(tmp_path, damage):
    """Two `gridshell run` processes on the default job with an artifact of the field stage damaged
    between them (cut short, or changed in place at the same size): the second run makes the field
    again, byte for byte as before, and keeps the stages before and after it cached."""
    out = tmp_path / "out"
    command = [*GRIDSHELL, "run", "--out", str(out), "--until", "remesh", "--quiet"]
    subprocess.run(command, cwd=ROOT, check=True, timeout=600, capture_output=True)
    artifact = out / "03-field" / "field.npz"
    original = artifact.read_bytes()
    if damage == "truncated":
        artifact.write_bytes(original[: len(original) // 2])
    else:
        artifact.write_bytes(original[:-1] + bytes([original[-1] ^ 0xFF]))
    done = subprocess.run(command, cwd=ROOT, timeout=600, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    statuses = {s["name"]: s["status"] for s in json.loads((out / "manifest.json").read_text())["stages"]}
    assert {k: statuses[k] for k in ("surface", "shell", "field", "remesh")} == {
        "surface": "cached", "shell": "cached", "field": "ran", "remesh": "cached"}
    assert artifact.read_bytes() == original
