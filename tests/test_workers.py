"""fabrication.workers.run_steps: independent steps shared between the caller and idle workers."""

from __future__ import annotations

import os
import time
from concurrent.futures import ProcessPoolExecutor
from functools import partial

import pytest

from fabrication.workers import run_steps


def _pid_after(seconds: float, value: int) -> tuple[int, int]:
    time.sleep(seconds)
    return os.getpid(), value * value


def _fails() -> None:
    raise ValueError("step failed")


def test_every_step_runs_once_here_without_a_pool():
    calls: list[str] = []
    steps = {name: partial(_pid_after, 0.0, k) for k, name in enumerate("abc")}
    done = run_steps(steps, starting=calls.append)
    assert list(done) == ["a", "b", "c"] and calls == ["a", "b", "c"]
    assert [r for r, _, _ in done.values()] == [(os.getpid(), k * k) for k in range(3)]
    assert {w for _, _, w in done.values()} == {"here"}


def test_an_idle_worker_takes_steps_the_caller_has_not_started():
    """With one idle worker, the steps are split between this process and the worker's (other pid),
    each once, with the results a serial run gives, in the order given."""
    steps = {f"s{k}": partial(_pid_after, 0.4, k) for k in range(4)}
    with ProcessPoolExecutor(max_workers=1) as pool:
        pool.submit(int).result()  # the worker is up
        done = run_steps(steps, pool, idle=lambda: 1)
    assert list(done) == list(steps)
    assert [r[1] for r, _, _ in done.values()] == [k * k for k in range(4)]
    where = {name: (w, r[0]) for name, (r, _, w) in done.items()}
    assert {w for w, _ in where.values()} == {"here", "worker"}
    assert all((pid == os.getpid()) == (w == "here") for w, pid in where.values())


def test_a_busy_pool_takes_nothing():
    steps = {f"s{k}": partial(_pid_after, 0.05, k) for k in range(3)}
    with ProcessPoolExecutor(max_workers=1) as pool:
        done = run_steps(steps, pool, idle=lambda: 0)
    assert {w for _, _, w in done.values()} == {"here"}


def test_an_error_in_a_workers_step_is_raised_here():
    steps = {"slow": partial(_pid_after, 0.5, 1), "fails": _fails}
    with ProcessPoolExecutor(max_workers=1) as pool:
        pool.submit(int).result()
        with pytest.raises(ValueError, match="step failed"):
            run_steps(steps, pool, idle=lambda: 1)


def _cut_volume(size: float, wait_s: float = 0.0) -> float:
    """A box less a cylinder through it (build123d runs the boolean on OCCT's thread pool), mm3."""
    from build123d import Box, Cylinder

    time.sleep(wait_s)
    return (Box(size, size, size) - Cylinder(size / 4, 2 * size)).volume


@pytest.mark.timeout(300)
def test_steps_beside_the_joints_run_booleans_after_the_parent_ran_one(tmp_path):
    """The parent ran a parallel OCCT boolean (its thread pool exists) before the joints' workers
    started; the steps handed out once the joints are built still finish, with the volume this
    process computes (in a forked child the boolean waited for the pool's threads for ever)."""
    import numpy as np

    from engine.mesh import PolyMesh
    from fabrication.joints import JointSettings, JointsInBackground

    expected = _cut_volume(10.0)
    assert expected == pytest.approx(1000 - np.pi * 2.5**2 * 10, rel=1e-6)
    nodes = np.array([[x, y, 0.0] for y in (0.0, 0.2) for x in (0.0, 0.2, 0.4)])
    polymesh = PolyMesh(nodes=nodes, faces=(np.array([0, 1, 4, 3]), np.array([1, 2, 5, 4])))
    normals = np.tile([0.0, 0.0, 1.0], (6, 1))
    with JointsInBackground(polymesh, normals, 12.0, JointSettings(), tmp_path / "joints", workers=2) as joints:
        done = joints.run_steps({"here": partial(_cut_volume, 10.0, 8.0), "a": partial(_cut_volume, 10.0),
                                 "b": partial(_cut_volume, 10.0)})
    assert len(joints.reports) == 6
    assert "worker" in {w for _, _, w in done.values()}
    assert all(r == pytest.approx(expected) for r, _, _ in done.values())
