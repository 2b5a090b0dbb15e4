"""Project files: the templates validate; bad keys, units and values give precise errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from engine.design.en1993 import ChecksMethod
from engine.errors import InputError
from engine.remeshing.field import AnisotropyMap, FieldSettings, SizeMap
from engine.remeshing.optimize import OptimizeSettings
from engine.remeshing.voronoi import RemeshSettings
from engine.structure.protocol import TOLERABLE_DEFLECTION_RATIO, ImperfectionShape, ProtocolSettings
from fabrication.joints import JointKind, JointSettings
from fabrication.limits import BuildLimits
from fabrication.settings import BeamSettings, PanelSettings, SheetSettings
from workflow import config
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


def test_units_convert_where_pints_cache_folder_cannot_be_used(monkeypatch):
    """The registry keeps pint's parsed definitions in the user's cache folder; where that fails
    (a read-only home, a broken cache file) the definitions are parsed instead."""
    import pint

    from workflow import units

    made = []

    class Registry(pint.UnitRegistry):
        def __init__(self, *args, **kwargs):
            made.append(kwargs.get("cache_folder"))
            if kwargs.get("cache_folder"):
                raise PermissionError("read-only cache folder")
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(pint, "UnitRegistry", Registry)
    units._registry.cache_clear()
    try:
        assert units.to_si("50 mm", "length") == pytest.approx(0.05)
        assert made == [":auto:", None]
    finally:
        units._registry.cache_clear()


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


# ----------------------------------------------------------------------------- one schema per setting

def _socket_project():
    """The mock-up with printed sockets, whose panels and sheets are fabrication's own defaults."""
    return parse_project({"surface": {"template": "mockup"}, "fabrication": {"joints": {"kind": "socket"}}})


_SPAN = 30.0
_TUBE = {"profile_name": "CHS 48.3x3.2", "material_name": "steel_s355", "density": 7850.0, "area_m2": 4.5e-4,
         "outer_size_mm": 48.3}

#: Per section with to_settings: (its class, the default section's settings, the settings' own defaults
#: with only what to_settings is given or maps on purpose). Beside the defaults: the remesher has no
#: default size target (the section's is DEFAULT_CELLS); the optimiser's ``planar`` moves nodes, which
#: the section does with planar and planarise_cells only (off by default); the imperfection amplitude
#: is L/300 of the span given.
_DEFAULTS = {
    "field": (config.FieldConfig, lambda: config.FieldConfig().to_settings(), FieldSettings),
    "remesh": (config.RemeshConfig, lambda: config.RemeshConfig().to_settings(),
               lambda: RemeshSettings(n_cells=config.DEFAULT_CELLS)),
    "optimize": (config.OptimizeConfig,
                 lambda: config.OptimizeConfig().to_settings(min_beam_length_mm=150.0, min_corner_angle_deg=25.0,
                                                             max_cell_stretch=3.0),
                 lambda: OptimizeSettings(min_beam_length=0.15, min_corner_angle_deg=25.0, max_cell_stretch=3.0,
                                          planar=False)),
    "analysis": (config.AnalysisConfig, lambda: config.AnalysisConfig().to_settings(_SPAN),
                 lambda: ProtocolSettings(amplitude=_SPAN / 300.0,
                                          max_displacement=_SPAN / TOLERABLE_DEFLECTION_RATIO)),
    "fabrication.joints": (config.JointsConfig, lambda: config.JointsConfig(kind="socket").to_settings(),
                           JointSettings),
    "fabrication.beams": (config.BeamsConfig, lambda: config.BeamsConfig().to_settings(**_TUBE),
                          lambda: BeamSettings(**_TUBE)),
    "fabrication.panels": (config.PanelsConfig, lambda: _socket_project().fabrication.panels.to_settings(),
                           PanelSettings),
    "fabrication.sheets": (config.SheetsConfig, lambda: _socket_project().fabrication.sheets.to_settings(),
                           lambda: [SheetSettings()]),
}


@pytest.mark.parametrize("name", list(_DEFAULTS))
def test_a_default_section_builds_its_settings_with_their_own_defaults(name):
    """One default per setting: a section's default and its dataclass's may not drift apart."""
    _, built, own = _DEFAULTS[name]
    assert built() == own()


def test_every_section_that_builds_settings_is_checked():
    sections = {cls for cls in vars(config).values() if isinstance(cls, type) and issubclass(cls, config._Section)
                and "to_settings" in vars(cls)}
    assert sections == {cls for cls, _, _ in _DEFAULTS.values()}


def test_build_limits_default_to_the_joints_own():
    assert config.FabricationConfig().build_limits(12.0) == BuildLimits.of(JointSettings(), 12.0)
    steel = parse_project({"surface": {"template": "mockup"}})       # a 48.3 mm steel tube: steel joints
    assert steel.fabrication.joints.kind == "steel"
    assert steel.fabrication.panels.to_settings().material_name == "laminated glass"
    assert steel.fabrication.sheets.to_settings() == [SheetSettings(width_mm=6000.0, height_mm=3210.0)]


def test_lengths_become_millimetres_in_the_settings():
    project = parse_project({"surface": {"template": "mockup"},
                             "fabrication": {"joints": {"kind": "socket", "wall": "2.5 mm", "hub_radius": "20 mm"},
                                             "beams": {"stock_length": "4 m", "min_cut_length": "120 mm"},
                                             "panels": {"clearance": "1 mm"},
                                             "sheets": {"width": "2 m", "height": "1 m", "sizes": [["3 m", "1.5 m"]]}}})
    f = project.fabrication
    assert (f.joints.to_settings().wall_mm, f.joints.to_settings().hub_radius_mm) == (2.5, 20.0)
    assert f.beams.to_settings(**_TUBE).stock_length_mm == 4000.0
    assert f.build_limits(48.3).min_cut_length_mm == 120.0
    assert f.panels.to_settings().clearance_mm == 1.0
    assert [(s.width_mm, s.height_mm) for s in f.sheets.to_settings()] == [(2000.0, 1000.0), (3000.0, 1500.0)]
    assert project.section.outer_size_mm() == pytest.approx(48.3)


def test_choices_are_the_engines_types(tmp_path):
    fields = {name: cls.model_fields for name, (cls, _, _) in _DEFAULTS.items()}
    assert fields["field"]["size_map"].annotation is SizeMap
    assert fields["field"]["anisotropy_map"].annotation is AnisotropyMap
    assert fields["fabrication.joints"]["kind"].annotation == JointKind | None
    assert fields["analysis"]["checks"].annotation == ChecksMethod
    assert fields["analysis"]["imperfection_shapes"].annotation == list[ImperfectionShape]
    assert parse_project({"surface": {"template": "cap"}, "field": {"size_map": "linear"}}).field.size_map \
        is SizeMap.LINEAR
    message = _error(tmp_path, '[surface]\ntemplate = "cap"\n[field]\nsize_map = "cubic"\n')
    assert "field.size_map = 'cubic': not allowed; expected one of 'energy' or 'linear'" in message


#: (TOML table, its values, the key the error names, settings that refuse the same in their own units):
#: a project file's mistakes are caught by the schema, naming the key, before the settings' own checks
#: (which stay for callers of the engine and of fabrication).
_REFUSED = [
    ("field", {"max_size_ratio": 0.5}, "field.max_size_ratio", FieldSettings, {"max_size_ratio": 0.5}),
    ("field", {"max_aspect": 0.9}, "field.max_aspect", FieldSettings, {"max_aspect": 0.9}),
    ("field", {"opposite_sign_anisotropy": 0.5}, "field.opposite_sign_anisotropy", FieldSettings,
     {"opposite_sign_anisotropy": 0.5}),
    ("field", {"clamp_percentiles": [60.0, 40.0]}, "field.clamp_percentiles", FieldSettings,
     {"clamp_percentiles": (60.0, 40.0)}),
    ("field", {"smoothing_iterations": -1}, "field.smoothing_iterations", FieldSettings, {"smoothing_iterations": -1}),
    ("remesh", {"n_cells": 3}, "remesh.n_cells", RemeshSettings, {"n_cells": 3}),
    ("remesh", {"mean_beam_length": -0.5}, "remesh.mean_beam_length", RemeshSettings, {"mean_beam_length": -0.5}),
    ("remesh", {"total_length": 0.0}, "remesh.total_length", RemeshSettings, {"total_length": 0.0}),
    ("remesh", {"lloyd_iterations": -1}, "remesh.lloyd_iterations", RemeshSettings,
     {"n_cells": 100, "lloyd_iterations": -1}),
    ("optimize", {"closeness_weight": -1.0}, "optimize.closeness_weight", OptimizeSettings, {"closeness_weight": -1.0}),
    ("optimize", {"iterations": -5}, "optimize.iterations", OptimizeSettings, {"iterations": -5}),
    ("optimize", {"planarity_iterations": 2.5}, "optimize.planarity_iterations", OptimizeSettings,
     {"planarity_iterations": 2.5}),
    ("optimize", {"planarity_tolerance": 0.0}, "optimize.planarity_tolerance", OptimizeSettings,
     {"planarity_tolerance": 0.0}),
    ("fabrication.panels", {"thickness": 0.0}, "fabrication.panels.thickness", PanelSettings, {"thickness_mm": 0.0}),
    ("fabrication.panels", {"density": -1.0}, "fabrication.panels.density", PanelSettings, {"density": -1.0}),
    ("fabrication.panels", {"clearance": "-1 mm"}, "fabrication.panels.clearance", PanelSettings,
     {"clearance_mm": -1.0}),
    ("fabrication.panels", {"hole_diameter": "-1 mm"}, "fabrication.panels.hole_diameter", PanelSettings,
     {"hole_diameter_mm": -1.0}),
    ("fabrication.panels", {"hole_inset": "-1 mm"}, "fabrication.panels.hole_inset", PanelSettings,
     {"hole_inset_mm": -1.0}),
    ("fabrication.panels", {"planarity_tolerance": "-1 mm"}, "fabrication.panels.planarity_tolerance", PanelSettings,
     {"planarity_tolerance_mm": -1.0}),
    ("fabrication.panels", {"grain": "diagonal"}, "fabrication.panels.grain", PanelSettings, {"grain": "diagonal"}),
    ("fabrication.joints", {"clearance": "-0.1 mm"}, "fabrication.joints.clearance", JointSettings,
     {"clearance_mm": -0.1}),
    ("fabrication.joints", {"wall": 0.0}, "fabrication.joints.wall", JointSettings, {"wall_mm": 0.0}),
    ("fabrication.joints", {"min_wall": "-1 mm"}, "fabrication.joints.min_wall", JointSettings, {"min_wall_mm": -1.0}),
    ("fabrication.joints", {"pin_hole": 0.0}, "fabrication.joints.pin_hole", JointSettings, {"pin_hole_mm": 0.0}),
    ("fabrication.joints", {"hub_radius": 0.0}, "fabrication.joints.hub_radius", JointSettings,
     {"hub_radius_mm": 0.0}),
    ("fabrication.joints", {"sleeve_length": "-5 mm"}, "fabrication.joints.sleeve_length", JointSettings,
     {"sleeve_length_mm": -5.0}),
    ("fabrication.joints", {"plate_thickness": 0.0}, "fabrication.joints.plate_thickness", JointSettings,
     {"plate_thickness_mm": 0.0}),
    ("fabrication.joints", {"bolt_hole": "-1 mm"}, "fabrication.joints.bolt_hole", JointSettings,
     {"bolt_hole_mm": -1.0}),
    ("fabrication.beams", {"stock_length": 0.0}, "fabrication.beams.stock_length", BeamSettings,
     {**_TUBE, "stock_length_mm": 0.0}),
    ("fabrication.beams", {"kerf": "-1 mm"}, "fabrication.beams.kerf", BeamSettings, {**_TUBE, "kerf_mm": -1.0}),
    ("fabrication.sheets", {"width": 0.0, "height": 0.6}, "fabrication.sheets.width", SheetSettings,
     {"width_mm": 0.0}),
    ("fabrication.sheets", {"spacing": "-1 mm"}, "fabrication.sheets.spacing", SheetSettings, {"spacing_mm": -1.0}),
    ("fabrication.sheets", {"margin": "-1 mm"}, "fabrication.sheets.margin", SheetSettings, {"margin_mm": -1.0}),
    ("fabrication.sheets", {"margin": "2 m"}, "fabrication.sheets: margin = 2000 mm leaves no room", SheetSettings,
     {"margin_mm": 2000.0, "width_mm": 6000.0, "height_mm": 3210.0}),
]


@pytest.mark.parametrize("table, values, key, settings, same", _REFUSED, ids=[r[2].split(":")[0] + str(i)
                                                                              for i, r in enumerate(_REFUSED)])
def test_the_schema_refuses_what_the_settings_refuse(table, values, key, settings, same):
    with pytest.raises(InputError):
        settings(**same)
    data: dict = {"surface": {"template": "mockup"}}
    node = data
    for part in table.split("."):
        node = node.setdefault(part, {})
    node.update(values)
    with pytest.raises(ConfigError) as info:
        parse_project(data)
    assert key in str(info.value)


_RANGES = [r for r in _REFUSED if r[3] in (JointSettings, BeamSettings, PanelSettings, SheetSettings)
           and "leaves no room" not in r[2]]


@pytest.mark.parametrize("settings, same", [r[3:] for r in _RANGES], ids=[r[2] for r in _RANGES])
def test_the_fabrication_settings_name_the_setting_and_the_fix(settings, same):
    name = next(k for k in same if k not in _TUBE or settings is not BeamSettings)
    with pytest.raises(InputError) as refused:
        settings(**same)
    assert f"setting {name} = {same[name]!r} must be" in str(refused.value)
    assert refused.value.hint.startswith(f"set {name} ")


def test_the_panels_grain_values_are_the_fabrication_settings_own():
    """[fabrication.panels] grain offers exactly the grains fabrication knows (one table)."""
    import typing

    from fabrication.settings import GRAIN_DIRECTIONS
    from workflow.config import PanelsConfig

    assert typing.get_args(PanelsConfig.model_fields["grain"].annotation) == tuple(GRAIN_DIRECTIONS)
    assert PanelsConfig().grain == "none"


# ------------------------------------------------------------------ a small surface is built as a model

def _roof_file(tmp_path: Path, span_m: float, scale: float = 1.0) -> Path:
    """A generated roof of ``span_m`` across on plan, written in units of 1/``scale`` m."""
    from tests.generated_surfaces import generate_surface

    surface = generate_surface(3, kind="dome", span_m=span_m, n_vertices=300)
    path = tmp_path / f"roof-{span_m:g}-{scale:g}.obj"
    lines = [f"v {x * scale:.6f} {y * scale:.6f} {z * scale:.6f}" for x, y, z in surface.vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in surface.faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_surface_under_four_metres_without_a_section_is_built_with_the_mockups_kit(tmp_path):
    mockup = load_project(TEMPLATES / "mockup.toml")
    for path, units in ((_roof_file(tmp_path, 1.5), "m"), (_roof_file(tmp_path, 1.5, scale=1000.0), "mm")):
        project = parse_project({"surface": {"file": str(path), "file_units": units}})
        assert project.section == mockup.section and project.material.name == mockup.material.name
        assert project.fabrication.joints.kind == "socket" and project.fabrication.panels.material == "acrylic"
        assert "1.5 m across" in project.scale_note and "[section]" in project.scale_note
    # a real roof, or a project that names its section or its material, keeps what it says
    roof = parse_project({"surface": {"file": str(_roof_file(tmp_path, 12.0))}})
    assert roof.scale_note is None and roof.section.diameter == pytest.approx(0.0483)
    assert roof.fabrication.joints.kind == "steel"
    small = str(_roof_file(tmp_path, 1.5))
    given = parse_project({"surface": {"file": small}, "section": {"diameter": "60.3 mm", "thickness": "4 mm"}})
    assert given.scale_note is None and given.section.diameter == pytest.approx(0.0603)
    assert given.material.name == roof.material.name
    named = parse_project({"surface": {"file": small}, "material": {"name": "steel_s235"}})
    assert named.scale_note is None and named.section == roof.section


def test_the_quick_start_of_a_small_surface_says_it_is_a_model_and_keeps_its_cells(tmp_path, capsys):
    """A 2.4 m roof (the mock-up's size) at the quick start's 120 cells: built with the model kit it
    keeps its cells; with a real roof's steel nodes (named by its material) it is remeshed with
    fewer, as its joints take more than its beams are long."""
    import json

    from workflow.cli import main

    path = _roof_file(tmp_path, 2.4)
    steel = tmp_path / "steel.toml"
    steel.write_text(f'[surface]\nfile = {json.dumps(str(path))}\n[material]\nname = "steel_s355"\n')
    built = {}
    for name, command in (("model", ["--surface", str(path)]), ("steel", [str(steel)])):
        out = tmp_path / name
        assert main(["run", *command, "--out", str(out), "--until", "remesh"]) == 0
        built[name] = json.loads((out / "04-remesh" / "remesh.json").read_text())["coarsened"]
        err = capsys.readouterr().err
        assert ("built as a model" in err and "2.4 m across" in err) == (name == "model")
    assert built["model"] == {"cells_asked": 120, "cells_built": 120, "remeshes": 0}
    assert built["steel"]["remeshes"] >= 1 and built["steel"]["cells_built"] < 60


def test_a_project_whose_only_load_is_self_weight_is_told_so_by_validate(tmp_path, capsys):
    """With no [loads] the beams' own weight is the only load, and validate says the verdicts leave
    out the rest; a project with an area load or a point load is not told so."""
    import json

    from workflow.cli import main
    from workflow.config import LoadsConfig

    assert LoadsConfig().self_weight_only
    assert not LoadsConfig.model_validate({"cases": {"dead": {"self_weight": 1.0, "area_plan": "1 kN/m^2"}}}
                                          ).self_weight_only
    assert not LoadsConfig.model_validate({"cases": {"wind": {"area_true": [100.0, 0.0, 0.0]}}}).self_weight_only
    assert not LoadsConfig.model_validate({"cases": {"p": {"points": [{"node": 0, "force": [0, 0, -1e3]}]}}}
                                          ).self_weight_only
    path = _roof_file(tmp_path, 12.0)
    bare, loaded = tmp_path / "bare.toml", tmp_path / "loaded.toml"
    bare.write_text(f"[surface]\nfile = {json.dumps(str(path))}\n")
    loaded.write_text(bare.read_text() + '[loads.cases.dead]\nself_weight = 1.0\narea_true = "0.5 kN/m^2"\n')
    for project, told in ((bare, True), (loaded, False)):
        assert main(["validate", str(project)]) == 0
        err = capsys.readouterr().err
        assert ("own weight alone" in err and "[loads.cases]" in err) == told, err


def test_the_default_dead_load_carries_the_panels_weight(tmp_path):
    """With no [loads], the dead case is the beams' own weight and the panels': their thickness x
    density x g per true area, downward (10 mm glass 245.25 N/m^2, 3 mm acrylic 35.02 N/m^2); none
    where panels are off."""
    from engine.structure.loads import GRAVITY
    from workflow.config import OWN_WEIGHT_NOTE, SELF_WEIGHT_NOTE, parse_project
    from workflow.stages.surface import build_surface, resolve_loads

    def dead(extra: dict) -> tuple[object, list[str]]:
        project = parse_project({"surface": {"template": "cap"}, **extra})
        cases, _ = resolve_loads(build_surface(project)[0], project)
        return cases["dead"].area_true, project.notes

    glass, notes = dead({})
    assert glass == pytest.approx([0.0, 0.0, -0.010 * 2500.0 * GRAVITY]) and OWN_WEIGHT_NOTE in notes
    acrylic, _ = dead({"material": {"name": "aluminium_6063"}, "section": {"kind": "circular_hollow",
                                                                          "diameter": "12 mm", "thickness": "1.5 mm"}})
    assert acrylic == pytest.approx([0.0, 0.0, -0.003 * 1190.0 * GRAVITY])
    off, notes = dead({"fabrication": {"panels": {"enabled": False}}})
    assert off == pytest.approx([0.0, 0.0, 0.0]) and SELF_WEIGHT_NOTE in notes


def test_panels_in_no_load_case_are_a_note_naming_the_case_and_the_weight():
    from workflow.config import parse_project

    def note(loads: dict) -> str | None:
        return parse_project({"surface": {"template": "cap"}, "loads": {"cases": loads}}).panels_left_out

    left_out = note({"dead": {"self_weight": 1.0}, "snow": {"area_plan": "1 kN/m^2"}})
    assert left_out is not None and "[loads.cases.dead]" in left_out and "245 N/m^2" in left_out
    assert note({"dead": {"self_weight": 1.0, "panels": 1.0}}) is None
    assert note({"dead": {"self_weight": 1.0, "area_true": "0.5 kN/m^2"}}) is None   # glazing given as a load
    assert note({"dead": {"self_weight": 1.0, "area_true": "0.2 kN/m^2"}}) is not None
    assert note({"snow": {"area_plan": "1 kN/m^2"}}) is not None                        # not a permanent case


@pytest.mark.parametrize("name", ["mockup", "cap", "vault", "hypar", "courtyard"])
def test_every_template_carries_its_panels(name):
    from workflow.cli import _template_path
    from workflow.config import load_project

    assert load_project(_template_path(name)).panels_left_out is None


def test_the_surface_stage_reads_the_panels_weight_only_where_a_case_carries_it():
    """Its cache key holds the panels' thickness, density and on/off where a case has ``panels``,
    and nothing of [fabrication.panels] otherwise (a panel clearance changed re-runs no analysis)."""
    from workflow.config import PANEL_WEIGHT_KEYS, parse_project, stage_sections

    carried = parse_project({"surface": {"template": "cap"}})
    given = parse_project({"surface": {"template": "cap"},
                           "loads": {"cases": {"dead": {"self_weight": 1.0, "area_true": "0.5 kN/m^2"}}}})
    assert set(PANEL_WEIGHT_KEYS) <= set(stage_sections("surface", carried))
    assert not any(k.startswith("fabrication") for k in stage_sections("surface", given))


def test_a_progress_message_keeps_the_tables_it_names(capsys):
    """Messages name TOML tables in brackets ([section], [loads.cases]); they print as written,
    not taken for styles and dropped."""
    from workflow.progress import Progress

    Progress(enabled=True, live=False).message("add them as [loads.cases]; [design] choose = \"best\"")
    assert "add them as [loads.cases]; [design] choose = \"best\"" in capsys.readouterr().err
