"""The output folder of a run: one run at a time, and nothing left over from a killed one.

A run holds an exclusive lock on ``OUT/.gridshell.lock`` (``fcntl.flock``: the kernel releases it
when the process ends, however it ends, so a killed run never leaves a stale lock). A second run on
the same folder stops at once with one message naming the run that holds it. Holding the lock, a
run removes what a killed run left: temporary stage folders (``.NN-stage.XXXX``) and temporary
files of the manifest and the published files (``.manifest.XXXX.json``); nothing else is touched.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import sys
from collections.abc import Iterator
from datetime import datetime, timezone
from pathlib import Path

from engine.errors import GridshellError

__all__ = ["LOCK_NAME", "RunInProgress", "run_lock", "remove_leftovers"]

LOCK_NAME = ".gridshell.lock"


class RunInProgress(GridshellError):
    """Another run holds the output folder's lock."""


@contextlib.contextmanager
def run_lock(out_dir: Path) -> Iterator[Path]:
    """Hold the exclusive lock of ``out_dir`` for the block; RunInProgress if another run has it."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / LOCK_NAME
    handle = open(path, "a+", encoding="utf-8")
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "another process"
            raise RunInProgress(f"{out_dir} is in use by another gridshell run ({holder})",
                                hint="wait for it to end, or give this run another folder with --out") from None
        handle.seek(0)
        handle.truncate()
        started = datetime.now(timezone.utc).isoformat(timespec="seconds")
        handle.write(f"pid {os.getpid()}, started {started}: {' '.join(sys.argv[:3])}\n")
        handle.flush()
        yield path
    finally:
        handle.close()  # releases the lock


def remove_leftovers(out_dir: Path, stage_folders: list[str], published: list[str]) -> list[str]:
    """Remove the temporary folders and files a killed run left in ``out_dir`` (call it holding
    the lock): ``.<stage folder>.*`` folders and ``.<stem>.*<suffix>`` files of the manifest and
    the published files. Returns the names removed."""
    out_dir = Path(out_dir)
    prefixes = tuple(f".{name}." for name in stage_folders)
    files = [Path(name) for name in ["manifest.json", *published]]
    removed = []
    for entry in out_dir.iterdir() if out_dir.is_dir() else []:
        name = entry.name
        if entry.is_dir() and name.startswith(prefixes):
            shutil.rmtree(entry, ignore_errors=True)
        elif entry.is_file() and any(name.startswith(f".{f.stem}.") and name.endswith(f.suffix) for f in files):
            entry.unlink(missing_ok=True)
        else:
            continue
        removed.append(name)
    return sorted(removed)
