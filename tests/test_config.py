"""Project files: the templates validate; bad keys, units and values give precise errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from workflow.config import ConfigError, load_project, parse_project
from workflow.units import to_si

TEMPLATES = Path(__file__).resolve().parents[1] / "templates"


@pytest.mark.parametrize("name", ["mockup", "cap", "vault", "hypar", "courtyard"])
def test_templates_validate(name):
    project = load_project(TEMPLATES / f"{name}.toml")
    assert project.surface.template == name


@pytest.mark.parametrize("name", ["mockup", "cap", "vault", "hypar", "courtyard"])
def test_templates_cite_only_files_the_repository_has(name):
    """`gridshell init` copies a template to the user: a document it cites (METHOD.md, docs/...)
    must be one they have, in the repository."""
    import re

    root = TEMPLATES.parent
    cited = re.findall(r"[\w./-]+\.md\b", (TEMPLATES / f"{name}.toml").read_text(encoding="utf-8"))
    assert [c for c in cited if not (root / c).is_file() and not (root / "docs" / c).is_file()] == []


@pytest.mark.parametrize("text, dimension, expected", [
    ("50 mm", "length", 0.05), ("2.4 m", "length", 2.4), (3, "length", 3.0),
    ("210 GPa", "stress", 210e9), ("0.5 kN/m^2", "area load", 500.0), ("7850 kg/m^3", "density", 7850.0),
    ("2 kN", "force", 2000.0), ("180 deg", "angle", 3.141592653589793), ("1 kN*m", "moment", 1000.0),
])
def test_units_convert_to_si(text, dimension, expected):
    assert to_si(text, dimension) == pytest.approx(expected)


@pytest.mark.parametrize("text, dimension", [("5 kg", "length"), ("2 m", "stress"), ("fast", "length"),
                                             (True, "length")])
def test_wrong_units_are_rejected(text, dimension):
    with pytest.raises(ValueError, match=dimension):
        to_si(text, dimension)


def _error(tmp_path, text: str) -> str:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_project(path)
    return str(info.value)


def test_unknown_key_names_file_key_and_allowed(tmp_path):
    message = _error(tmp_path, '[surface]\ntemplate = "cap"\n[field]\nmax_ratio = 2\n')
    assert "bad.toml" in message and "field.max_ratio" in message
    assert "max_size_ratio" in message and "max_aspect" in message


def test_wrong_unit_names_key_value_and_expected(tmp_path):
    message = _error(tmp_path, '[surface]\ntemplate = "cap"\n[section]\nkind = "solid_round"\ndiameter = "5 kg"\n')
    assert "section.diameter" in message and "'5 kg'" in message and "length" in message


def test_bad_value_names_allowed_values(tmp_path):
    message = _error(tmp_path, '[surface]\ntemplate = "dome"\n')
    assert "surface.template" in message and "'dome'" in message and "mockup" in message


def test_out_of_range_value(tmp_path):
    message = _error(tmp_path, '[surface]\ntemplate = "cap"\n[field]\nmax_aspect = 0.5\n')
    assert "field.max_aspect" in message and "0.5" in message and "greater than or equal to 1" in message


def test_bad_restraint_and_missing_selection_parameters(tmp_path):
    message = _error(tmp_path, '[surface]\ntemplate = "cap"\n[[supports]]\nselect = "plane"\nrestraint = "glued"\n')
    assert "supports[0].restraint" in message and "pinned" in message
    message = _error(tmp_path, '[surface]\ntemplate = "cap"\n[[supports]]\nselect = "plane"\n')
    assert "needs point, normal" in message


def test_combination_with_unknown_case(tmp_path):
    message = _error(tmp_path, '[surface]\ntemplate = "cap"\n[loads.cases.dead]\nself_weight = 1\n'
                               '[loads.combinations.ULS]\nlimit_state = "ULS"\nfactors = { dead = 1.35, wind = 1.5 }\n')
    assert "wind" in message and "dead" in message


def test_not_toml_and_missing_file(tmp_path):
    assert "not valid TOML" in _error(tmp_path, "[surface\n")
    with pytest.raises(ConfigError, match="does not exist"):
        load_project(tmp_path / "nothing.toml")


def test_units_in_project_are_si_inside():
    project = parse_project({"surface": {"template": "mockup"},
                             "section": {"kind": "circular_hollow", "diameter": "12 mm", "thickness": "1.5 mm"},
                             "loads": {"cases": {"snow": {"area_plan": "0.5 kN/m^2"}}}})
    assert project.section.diameter == pytest.approx(0.012)
    assert project.loads.cases["snow"].area_vector("area_plan") == pytest.approx([0, 0, -500.0])


def test_relative_surface_path_resolves_against_project_file(tmp_path):
    (tmp_path / "sub").mkdir()
    path = tmp_path / "sub" / "p.toml"
    path.write_text('[surface]\nfile = "roof.obj"\n')
    assert Path(load_project(path).surface.file) == (tmp_path / "sub" / "roof.obj").resolve()
