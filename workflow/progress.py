"""Progress on stderr: a rich live line per stage (stage, step, elapsed), or plain log lines.

Rich output is used when stderr is a terminal and not ``--quiet``; otherwise each stage
prints one line when it ends (so CI logs and pipes stay readable).
"""

from __future__ import annotations

import sys
import time

__all__ = ["Progress"]


class Progress:
    """Stage and step reporter. ``enabled=False`` prints nothing."""

    def __init__(self, *, enabled: bool = True, live: bool | None = None) -> None:
        self.enabled = enabled
        self.live = enabled and (sys.stderr.isatty() if live is None else live)
        self._stage: str | None = None
        self._started = 0.0
        self._status = None
        self._console = None
        if self.enabled:
            from rich.console import Console

            self._console = Console(stderr=True, highlight=False)

    def stage_start(self, name: str) -> None:
        self._stage, self._started = name, time.perf_counter()
        if self.live and self._console is not None:
            self._status = self._console.status(f"[bold]{name}[/bold] starting")
            self._status.start()

    def step(self, text: str, fraction: float | None = None) -> None:
        if not self.enabled or self._stage is None:
            return
        elapsed = time.perf_counter() - self._started
        share = f" {100 * fraction:3.0f}%" if fraction is not None else ""
        line = f"[bold]{self._stage}[/bold]: {text}{share}  ({elapsed:5.1f} s)"
        if self._status is not None:
            self._status.update(line)

    def stage_done(self, name: str, status: str, seconds: float) -> None:
        if self._status is not None:
            self._status.stop()
            self._status = None
        if self.enabled and self._console is not None:
            colour = {"ran": "green", "cached": "cyan", "failed": "red"}.get(status, "yellow")
            self._console.print(f"  {name:<12} [{colour}]{status:<13}[/{colour}] {seconds:7.1f} s")
        self._stage = None

    def message(self, text: str) -> None:
        if self.enabled and self._console is not None:
            self._console.print(text)
