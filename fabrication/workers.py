"""Worker processes that end with their parent.

A process pool's workers block on their task queue, whose pipe other workers hold open too: when
the parent is killed (SIGKILL, the OOM killer) they never see it close and live on, each holding
the memory of a CAD kernel. :func:`exit_with_parent` is the pools' initializer: the kernel sends
the worker SIGKILL when its parent dies (Linux ``PR_SET_PDEATHSIG``), and, on any POSIX system,
a thread checks every half second that the parent is still the one that started it.
"""

from __future__ import annotations

import ctypes
import os
import sys
import threading
import time

__all__ = ["exit_with_parent", "POLL_S"]

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
