"""The code stays clean by the rules in pyproject.toml's [tool.ruff]: a finding fails the suite with ruff's report."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("ruff")

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ["engine", "fabrication", "workflow", "tests", "benchmarks"]


def test_ruff_finds_nothing():
    # --no-cache: a test run leaves no .ruff_cache in the checkout
    run = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", *FOLDERS],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, f"ruff check {' '.join(FOLDERS)} found problems:\n{run.stdout}{run.stderr}"
