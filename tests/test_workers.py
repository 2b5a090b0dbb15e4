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
