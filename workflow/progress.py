"""Progress on stderr: a rich live line per stage (stage, step, elapsed), or plain log lines.

Rich output is used when stderr is a terminal and not ``--quiet``; otherwise each stage
prints one line when it ends (so CI logs and pipes stay readable).
"""

from __future__ import annotations

import sys
import time

__all__ = ["Progress", "format_number"]


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

    def stage_done(self, name: str, status: str, seconds: float, *, findings: int = 0) -> None:
        """One line per stage: its status (yellow with its count of findings, when it has any)."""
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
            worst = "" if row["worst"] is None else f": {format_number(row['worst'])}{unit}"
            limit_text = "" if row["limit"] is None else f" (limit {format_number(row['limit'])}{unit})"
            parts = escape(", ".join(row["worst_parts"][:3]))
            self._console.print(f"  [red]{row['kind']}[/red] x{row['count']}{worst}{limit_text}"
                                f"{' at ' + parts if parts else ''}")
            if row["fix"]:
                self._console.print(f"      fix: {escape(row['fix'])}", soft_wrap=True)
        self._stage = None

    def message(self, text: str) -> None:
        if self.enabled and self._console is not None:
            self._console.print(text)


def format_number(value: float) -> str:
    """A value as an engineer writes it: 3 significant figures, no scientific notation for
    everyday magnitudes."""
    value = float(value)
    if value == 0 or 1e-3 <= abs(value) < 1e6:
        return f"{value:.3g}" if abs(value) < 1000 else f"{value:.0f}"
    return f"{value:.3e}"
