"""Worker processes that end with their parent.

A process pool's workers block on their task queue, whose pipe other workers hold open too: when
the parent is killed (SIGKILL, the OOM killer) they never see it close and live on, each holding
the memory of a CAD kernel. :func:`exit_with_parent` is the pools' initializer: the kernel sends
the worker SIGKILL when its parent dies (Linux ``PR_SET_PDEATHSIG``), and, on any POSIX system,
a thread checks every half second that the parent is still the one that started it.

:func:`run_steps` shares independent steps between the calling thread and a pool's workers as they
fall idle, so that a stage's last steps do not run one after another on one core while the other
has nothing left to do.
"""

from __future__ import annotations

import ctypes
import os
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Executor, Future, wait
from typing import Any

__all__ = ["exit_with_parent", "POLL_S", "run_steps", "StepOutcome"]

#: Seconds between two checks of the parent.
POLL_S = 0.5
_PR_SET_PDEATHSIG = 1


def _watch(parent: int) -> None:
    while True:
        if os.getppid() != parent:
            os._exit(1)
        time.sleep(POLL_S)


def exit_with_parent(parent: int) -> None:
    """Make this (worker) process end when process ``parent`` ends; a pool's ``initializer``,
    with ``initargs=(os.getpid(),)``."""
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, 9, 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - no prctl: the thread below still acts
            pass
    if os.getppid() != parent:  # the parent died before the watch started
        os._exit(1)
    threading.Thread(target=_watch, args=(parent,), name="parent-watch", daemon=True).start()


StepOutcome = tuple[Any, float, str]
"""A step's result, its seconds and where it ran ("here" or "worker")."""


def _timed(step: Callable[[], Any]) -> tuple[Any, float]:
    started = time.perf_counter()
    result = step()
    return result, time.perf_counter() - started


def run_steps(steps: dict[str, Callable[[], Any]], pool: Executor | None = None,
              idle: Callable[[], int] | None = None, poll_s: float = 0.1,
              starting: Callable[[str], None] | None = None) -> dict[str, StepOutcome]:
    """Run independent ``steps`` (name -> a function of no arguments; picklable, e.g. a
    functools.partial of a module-level function, where they may go to ``pool``), each once, and
    return each one's result, seconds and where it ran, in the order given.

    This thread takes the steps in order, one after another; meanwhile, whenever ``idle()`` says
    that a worker of ``pool`` has nothing to do (its other tasks handed out), the next step not yet
    taken goes to that worker. Without a pool every step runs here. An error of a step is raised
    here once every step handed out has ended. ``starting(name)`` is called as this thread starts
    a step (progress)."""
    order = list(steps)
    waiting = deque(order)
    lock = threading.Lock()
    sent: dict[str, Future] = {}
    outcome: dict[str, StepOutcome] = {}
    done = threading.Event()

    def hand_out(pool: Executor, idle: Callable[[], int]) -> None:
        while not done.is_set():
            with lock:
                free = idle() - sum(not f.done() for f in sent.values())
                while waiting and free > 0:
                    name = waiting.popleft()
                    sent[name] = pool.submit(_timed, steps[name])
                    free -= 1
                if not waiting:
                    break
            done.wait(poll_s)
        # a pool that starts its workers on demand starts them from this thread, and exit_with_parent
        # ends them with it (PR_SET_PDEATHSIG follows the thread): it lives until their steps have ended
        wait(list(sent.values()))

    dispatcher = None
    if pool is not None and idle is not None:
        dispatcher = threading.Thread(target=hand_out, args=(pool, idle), name="steps", daemon=True)
        dispatcher.start()
    error: BaseException | None = None
    try:
        while True:
            with lock:
                if not waiting:
                    break
                name = waiting.popleft()
            if starting is not None:
                starting(name)
            result, seconds = _timed(steps[name])
            outcome[name] = (result, seconds, "here")
    except BaseException as failure:  # noqa: BLE001 - raised below, once the workers' steps have ended
        error = failure
    finally:
        done.set()
        if dispatcher is not None:
            dispatcher.join()
    for name, future in sent.items():
        try:
            result, seconds = future.result()
            outcome[name] = (result, seconds, "worker")
        except BaseException as failure:  # noqa: BLE001 - the first error wins
            error = error or failure
    if error is not None:
        raise error
    return {name: outcome[name] for name in order}
