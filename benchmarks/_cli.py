"""The command line the benchmarks run: the checkout's own gridshell, else the module."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def gridshell_command() -> list[str]:
    """The gridshell command of the checkout's .venv or of this interpreter, else ``python -m workflow.cli``."""
    for candidate in (ROOT / ".venv" / "bin" / "gridshell", Path(sys.executable).parent / "gridshell"):
        if candidate.is_file():
            return [str(candidate)]
    return [sys.executable, "-m", "workflow.cli"]
