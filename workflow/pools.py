"""Worker processes for the stages' independent pieces of work (the remesh's starts, the
non-linear paths, the grids of a comparison)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager

from fabrication.workers import exit_with_parent

__all__ = ["process_pool"]


@contextmanager
def process_pool(workers: int | None) -> Iterator[ProcessPoolExecutor | None]:
    """A pool of ``workers`` processes (default: one per core), or None with one worker (the work
    then runs here, one piece after another). Its workers end with this process
    (fabrication.workers.exit_with_parent). They are forked: they run numpy, scipy and the engine's
    kernels only, never the CAD kernel, whose thread pool a forked child cannot use."""
    count = workers or os.cpu_count() or 1
    if count < 2:
        yield None
        return
    with ProcessPoolExecutor(max_workers=count, initializer=exit_with_parent, initargs=(os.getpid(),)) as pool:
        yield pool

