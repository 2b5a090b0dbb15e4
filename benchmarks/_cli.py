"""The command line the benchmarks run: the checkout's own gridshell, else the module; how a run of
it ended, and the case tables of the benchmarks that run one command per case."""

from __future__ import annotations

import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def gridshell_command() -> list[str]:
    """The gridshell command of the checkout's .venv or of this interpreter, else ``python -m workflow.cli``."""
    for candidate in (ROOT / ".venv" / "bin" / "gridshell", Path(sys.executable).parent / "gridshell"):
        if candidate.is_file():
            return [str(candidate)]
    return [sys.executable, "-m", "workflow.cli"]


@dataclass
class Ended:
    """How one ``gridshell`` command ended: its exit code (-1 on time-out), its stderr, its
    seconds, and whether it wrote ``report.html`` and exited 0."""

    code: int
    stderr: str
    seconds: float
    report: bool

    def error(self, tail: int) -> str:
        """The first ``error`` line of stderr, else its last ``tail`` characters."""
        return next((line for line in self.stderr.splitlines() if line.startswith("error")),
                    self.stderr.strip()[-tail:])

    def refused_with(self, text: str) -> bool:
        """Exit 2 with ``text`` in the message and no traceback: a refusal as meant."""
        return self.code == 2 and text in self.stderr and "Traceback" not in self.stderr


def run_gridshell(arguments: list[str], run_dir: Path, timeout: float) -> Ended:
    """Run ``gridshell ARGUMENTS`` (writing into ``run_dir``) and say how it ended."""
    started = time.perf_counter()
    try:
        done = subprocess.run([*gridshell_command(), *arguments], capture_output=True, text=True, timeout=timeout)
        code, stderr = done.returncode, done.stderr
    except subprocess.TimeoutExpired:
        code, stderr = -1, f"timed out after {timeout:.0f} s"
    seconds = time.perf_counter() - started
    return Ended(code, stderr, seconds, (run_dir / "report.html").is_file() and code == 0)


def table_header(name_width: int) -> str:
    """The header of the case table: case, exit, seconds, report, as meant, what was said."""
    return f"{'case':<{name_width}} {'exit':>4} {'s':>7} {'report':>6} {'as meant':>8}  said"


def table_row(row: dict, name_width: int, said_width: int) -> str:
    """One case's row (``name``, ``exit``, ``seconds``, ``report``, ``expected``, ``said``)."""
    return (f"{row['name']:<{name_width}} {row['exit']:>4} {row['seconds']:>7} {'yes' if row['report'] else 'no':>6} "
            f"{'yes' if row['expected'] else 'NO':>8}  {row['said'][:said_width]}")
