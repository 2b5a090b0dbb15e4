"""benchmarks/unusual_settings.py writes each case's project as the base project with the case's
TOML merged in: every case meant to run is a valid project with the case's values in it (read back
by the project's own parser), and the cases refused by their settings alone are refused naming the
key."""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from unusual_settings import CASES, project_text  # noqa: E402

from workflow.config import ConfigError, parse_project  # noqa: E402


def _leaves(table: dict, prefix: str = ""):
    for key, value in table.items():
        if isinstance(value, dict):
            yield from _leaves(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_each_case_is_the_base_project_with_its_own_values(case, tmp_path):
    surface = tmp_path / "roof.ply"
    data = tomllib.loads(project_text(case, surface, 80))
    assert data["surface"]["file"] == str(surface) and data["remesh"]["n_cells"] == 80
    for key, value in _leaves(tomllib.loads(case.toml)):  # the case's values are the project's
        node = data
        for part in key.split("."):
            node = node[part]
        assert node == value, key
    if case.refused and case.refused in ("max_aspect", "size_sections"):
        with pytest.raises(ConfigError, match=case.refused):
            parse_project(data)
    else:
        parse_project(data)
