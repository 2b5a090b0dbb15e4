"""Progress on stderr: a rich live line per stage (stage, step, elapsed), or plain log lines.

Rich output is used when stderr is a terminal and not ``--quiet``. Otherwise (CI logs, pipes,
``make demo | tee``) a stage prints a plain line with its current step and elapsed time at least
every ``PLAIN_INTERVAL_S`` seconds while it runs, and one line when it ends.
"""

from __future__ import annotations

import os
import sys
import threading
import time

from .labels import format_against

__all__ = ["Progress", "PLAIN_INTERVAL_S"]

PLAIN_INTERVAL_S = 10.0
"""The longest a running stage stays silent on a pipe."""

_PLAIN_LOCK = threading.Lock()
# Held while a plain line is written. A fork (the joint workers) waits for the line to finish,
# so no child starts with a half-written line's stream lock held by a thread it does not have.
if hasattr(os, "register_at_fork"):
    os.register_at_fork(before=_PLAIN_LOCK.acquire, after_in_parent=_PLAIN_LOCK.release,
                        after_in_child=_PLAIN_LOCK.release)


class Progress:
    """Stage and step reporter. ``enabled=False`` prints nothing.

    Without the live line, ``interval`` (s) is the longest gap between plain lines of a running
    stage: a step prints one when the last is that old, and with ``heartbeat`` a background
    thread prints the current step when no step comes. ``clock`` gives seconds (tests pass a fake).
    """

    def __init__(self, *, enabled: bool = True, live: bool | None = None, interval: float = PLAIN_INTERVAL_S,
                 heartbeat: bool = True, clock=time.perf_counter) -> None:
        self.enabled = enabled
        self.live = enabled and (sys.stderr.isatty() if live is None else live)
        self.interval = float(interval)
        self._heartbeat = heartbeat
        self._clock = clock
        self._stage: str | None = None
        self._started = 0.0
        self._status = None
        self._console = None
        self._text = ""
        self._fraction: float | None = None
        self._last_line = 0.0
        self._beating: tuple[threading.Thread, threading.Event] | None = None
        if self.enabled:
            from rich.console import Console

            self._console = Console(stderr=True, highlight=False)

    @property
    def _plain(self) -> bool:
        return self.enabled and not self.live and self._console is not None

    def stage_start(self, name: str) -> None:
        self._stop_beating()
        self._stage, self._started = name, self._clock()
        self._text, self._fraction, self._last_line = "starting", None, self._started
        if self.live and self._console is not None:
            self._status = self._console.status(f"[bold]{name}[/bold] starting")
            self._status.start()
        elif self._plain and self._heartbeat:
            stop = threading.Event()
            thread = threading.Thread(target=self._beat, args=(stop,), name="gridshell-progress", daemon=True)
            self._beating = (thread, stop)
            thread.start()

    def step(self, text: str, fraction: float | None = None) -> None:
        if not self.enabled or self._stage is None:
            return
        self._text, self._fraction = text, fraction
        elapsed = self._clock() - self._started
        share = f" {100 * fraction:3.0f}%" if fraction is not None else ""
        line = f"[bold]{self._stage}[/bold]: {text}{share}  ({elapsed:5.1f} s)"
        if self._status is not None:
            self._status.update(line)
        elif self._plain:
            self._plain_line()

    def _plain_line(self) -> None:
        """The stage, its current step and share, and the time it has run, when the last line
        is ``interval`` old."""
        with _PLAIN_LOCK:
            now = self._clock()
            if self._stage is None or now - self._last_line < self.interval:
                return
            self._last_line = now
            share = f" {100 * self._fraction:3.0f}%" if self._fraction is not None else ""
            self._console.print(f"  {self._stage:<12} {self._text}{share}  ({now - self._started:.0f} s)",
                                markup=False, highlight=False, soft_wrap=True)

    def _beat(self, stop: threading.Event) -> None:
        """The heartbeat thread: a plain line whenever ``interval`` passes without one."""
        while True:
            with _PLAIN_LOCK:
                due = self._last_line + self.interval - self._clock()
            if stop.wait(max(due, 0.0)):
                return
            self._plain_line()

    def _stop_beating(self) -> None:
        if self._beating is not None:
            thread, stop = self._beating
            stop.set()
            thread.join()
            self._beating = None

    def stage_done(self, name: str, status: str, seconds: float, *, findings: int = 0) -> None:
        """One line per stage: its status (yellow with its count of findings, when it has any)."""
        self._stop_beating()
        if self._status is not None:
            self._status.stop()
            self._status = None
        if self.enabled and self._console is not None:
            colour = {"ran": "green", "cached": "cyan", "failed": "red"}.get(status, "yellow")
            if findings and status in ("ran", "cached"):
                colour = "yellow"
            note = f"  {findings} finding{'s' if findings != 1 else ''}" if findings else ""
            self._console.print(f"  {name:<12} [{colour}]{status:<13}[/{colour}] {seconds:7.1f} s{note}")

    def findings(self, findings: list[dict], limit: int = 12) -> None:
        """The failing checks and what could not be built, in red: one line per kind with its
        count, worst value, limit, governing part and the fix."""
        if not self.enabled or self._console is None or not findings:
            return
        from rich.markup import escape

        from engine.findings import findings_table

        rows = findings_table(findings)
        self._console.print(f"[bold red]{len(findings)} finding{'s' if len(findings) != 1 else ''}[/bold red] "
                            "(failing checks and parts that cannot be built as drawn):")
        for row in rows[:limit]:
            unit = f" {row['unit']}" if row["unit"] else ""
            worst_text, limit_value = format_against(row["worst"], row["limit"], text=True)
            worst = "" if row["worst"] is None else f": {worst_text}{unit}"
            limit_text = "" if row["limit"] is None else f" (limit {limit_value}{unit})"
            parts = escape(", ".join(row["worst_parts"][:3]))
            self._console.print(f"  [red]{row['kind']}[/red] x{row['count']}{worst}{limit_text}"
                                f"{' at ' + parts if parts else ''}")
            if row["fix"]:
                self._console.print(f"      fix: {escape(row['fix'])}", soft_wrap=True)
        self._stage = None

    def message(self, text: str) -> None:
        """Print one line of plain text: brackets are kept (they name TOML tables, not styles)."""
        if self.enabled and self._console is not None:
            self._console.print(text, markup=False, highlight=False, soft_wrap=True)


