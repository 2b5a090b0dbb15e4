"""Issue 18, "trust every run": user mistakes are one message in TOML words, before any stage runs;
progress reaches pipes; buckling modes come out the same on every run."""

from __future__ import annotations

import re

import pytest

from workflow.config import ConfigError, parse_project

INTERNALS = re.compile(r"function-|list\[|dict\[|<lambda>|Input should be a valid list|Settings\b|\bstr\b|\bfloat\b")


def _config_error(data: dict) -> list[str]:
    """The lines of the ConfigError a project dictionary raises, without its header and hint."""
    with pytest.raises(ConfigError) as info:
        parse_project(data)
    lines = str(info.value).splitlines()
    return [line.strip() for line in lines[1:] if not line.strip().startswith("hint:")]


# --- 2. unit errors: one line with the key, the value and a valid example -------------------------

@pytest.mark.parametrize("where, key, value, example", [
    ({"loads": {"cases": {"dead": {"area_true": "0.5 kN"}}}}, "loads.cases.dead.area_true", "'0.5 kN'",
     "'0.5 kN/m^2'"),
    ({"loads": {"cases": {"snow": {"area_plan": "1 kN/m"}}}}, "loads.cases.snow.area_plan", "'1 kN/m'",
     "'0.5 kN/m^2'"),
    ({"loads": {"cases": {"dead": {"area_true": [0, 0, "2 kN"]}}}}, "loads.cases.dead.area_true[2]", "'2 kN'",
     "'0.5 kN/m^2'"),
    ({"section": {"kind": "solid_round", "diameter": "5 kg"}}, "section.diameter", "'5 kg'", "'50 mm'"),
    ({"material": {"E": "210 m"}}, "material.E", "'210 m'", "'210 GPa'"),
    ({"material": {"density": "7850 kg"}}, "material.density", "'7850 kg'", "'7850 kg/m^3'"),
    ({"fabrication": {"sheets": {"sizes": [["1 m", "2 kg"]]}}}, "fabrication.sheets.sizes[0][1]", "'2 kg'",
     "'50 mm'"),
    ({"supports": [{"select": "nearest", "points": [[0, 0, "1 s"]]}]}, "supports[0].points[0][2]", "'1 s'",
     "'50 mm'"),
])
def test_a_unit_error_is_one_line_with_key_value_and_example(where, key, value, example):
    lines = _config_error({"surface": {"template": "cap"}, **where})
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"{key} = {value}:"), lines
    assert example in lines[0] and not INTERNALS.search(lines[0]), lines


def test_the_unit_error_names_what_the_unit_measures():
    """pint's dimensionality ("[mass] * [length] / [time] ** 2") is not shown; the kind in words is."""
    (line,) = _config_error({"surface": {"template": "cap"}, "loads": {"cases": {"dead": {"area_true": "0.5 kN"}}}})
    assert "force" in line and "area load" in line and "[mass]" not in line


@pytest.mark.parametrize("where, key, expected", [
    ({"loads": {"cases": {"dead": {"area_true": {"q": 1}}}}}, "loads.cases.dead.area_true", "a number or a list"),
    ({"supports": [{"select": "boundary", "restraint": 5}]}, "supports[0].restraint", "a text or a list"),
])
def test_a_value_no_branch_takes_gets_one_line_saying_what_is_allowed(where, key, expected):
    lines = _config_error({"surface": {"template": "cap"}, **where})
    assert len(lines) == 1 and lines[0].startswith(key) and expected in lines[0], lines
    assert not INTERNALS.search(lines[0]), lines
