"""The code stays clean by the rules in pyproject.toml's [tool.ruff] and [tool.mypy]: a finding fails the suite
with the tool's report."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ["engine", "fabrication", "workflow", "tests", "benchmarks"]


def test_ruff_finds_nothing():
    pytest.importorskip("ruff")
    # --no-cache: a test run leaves no .ruff_cache in the checkout
    run = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", *FOLDERS],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, f"ruff check {' '.join(FOLDERS)} found problems:\n{run.stdout}{run.stderr}"


def test_mypy_finds_nothing():
    # the files, library overrides and exclusions are pyproject.toml's; no cache left in the checkout
    pytest.importorskip("mypy")
    run = subprocess.run([sys.executable, "-m", "mypy", "--config-file", "pyproject.toml", "--cache-dir", os.devnull],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, f"mypy (pyproject.toml's [tool.mypy]) found problems:\n{run.stdout}{run.stderr}"
