"""One setting at a time: the quick start on a roof no setting was tuned on, run cold through every
stage with one project setting (or a few that go together) changed from its default to a value a
user may well give.

    .venv/bin/python benchmarks/unusual_settings.py [--seed 460] [--cells 80] [--out out/unusual_settings]
        [--match NAME,...] [--timeout SECONDS]

The roof is the generated surface of ``--seed`` (tests/generated_surfaces.py, flagged supports), in
a project of the quick start's settings. Each case adds TOML to it: a value in a table overrides the
base's, a table the base lacks is added. A case reaches report.html (exit 0) unless it is meant to
be refused, with an error naming its key (exit 2, no traceback). The script prints one row per case
(exit code, seconds, report.html, the analysis's verdicts and the findings by kind, or the first
line of the error) and exits 1 when a case ends otherwise than meant.
"""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _cli import run_gridshell, table_header, table_row  # noqa: E402


@dataclass
class Case:
    """A name, the TOML it adds to the base project, and the text the refusal must hold where the
    settings are meant to be refused."""

    name: str
    toml: str
    refused: str | None = None


CASES = [
    Case("base", ""),
    # the field
    Case("uniform_field", "[field]\nmax_size_ratio = 1.0\nmax_aspect = 1.0"),
    Case("strong_grading", "[field]\nmax_size_ratio = 5.0\nmax_aspect = 4.0"),
    Case("across", '[field]\norientation = "across"'),
    Case("linear_maps", '[field]\nsize_map = "linear"\nanisotropy_map = "linear"'),
    Case("no_smoothing", "[field]\nsmoothing_iterations = 0\ndirection_smoothing_iterations = 0"),
    Case("symmetry_not_there", "[field]\nsymmetry_planes = [{ point = [0, 0, 0], normal = [1, 0, 0] }]",
         refused="[field] symmetry_planes[0]"),
    # the remesh
    Case("statics_rounds_3", "[remesh]\nstatics_rounds = 3"),
    Case("no_lloyd", "[remesh]\nlloyd_iterations = 0"),
    Case("isotropic_grid", '[remesh]\ngrid = "isotropic"'),
    Case("quad_grid", '[remesh]\ngrid = "quad"'),
    Case("triangular_grid", '[remesh]\ngrid = "triangular"'),
    Case("statics_quad_grid", '[remesh]\ngrid = "statics_quad"'),
    Case("keep_cells", "[remesh]\ncoarsen_for_joints = false"),
    # the optimisation
    Case("not_optimised", "[optimize]\niterations = 0"),
    Case("not_planar", "[optimize]\nplanar = false"),
    Case("cells_not_split", "[optimize]\nsplit_cells = false"),
    Case("cells_planarised", "[optimize]\nplanarise_cells = true"),
    # the analysis
    Case("one_element_per_beam", "[analysis]\nelements_per_beam = 1"),
    Case("linear_only", "[analysis]\nnonlinear = false"),
    Case("mode_imperfections", '[analysis]\nimperfection_shapes = ["mode1", "mode2", "mode3"]\nn_modes = 3'),
    Case("simplified_checks", '[analysis]\nchecks = "simplified"'),
    Case("buckling_lengths_from_modes", '[analysis]\nbuckling_length = "buckling_modes"'),
    Case("sized_tubes", "[design]\nsize_sections = true"),
    # sections, materials, joints
    Case("rhs_steel", '[material]\nname = "steel_s235"\n[section]\nkind = "rectangular_hollow"\n'
                      'height = "120 mm"\nwidth = "80 mm"\nthickness = "5 mm"'),
    Case("glulam", '[material]\nname = "glulam_gl24h"\n[section]\nkind = "solid_rectangle"\n'
                   'height = "200 mm"\nwidth = "160 mm"'),
    Case("aluminium_sockets", '[material]\nname = "aluminium_6061"\n[section]\nkind = "circular_hollow"\n'
                              'diameter = "30 mm"\nthickness = "2 mm"\n[fabrication.joints]\nkind = "socket"'),
    Case("sockets_not_engraved", '[fabrication.joints]\nkind = "socket"\nengrave = false'),
    Case("joints_in_one_step", "[fabrication.joints]\ncombined_step = true"),
    # panels and sheets
    Case("no_panels", "[fabrication.panels]\nenabled = false"),
    Case("panels_with_grain", '[fabrication.panels]\ngrain = "slope"'),
    Case("panels_with_fixings", '[fabrication.panels]\nhole_diameter = "8 mm"\nhole_inset = "25 mm"'),
    Case("small_sheets", '[fabrication.sheets]\nwidth = "1000 mm"\nheight = "500 mm"\nrotations = false'),
    # supports and loads
    Case("fixed_supports", '[[supports]]\nselect = "flagged"\nrestraint = "fixed"'),
    Case("rollers_and_a_column", '[[supports]]\nselect = "boundary"\nrestraint = "roller_z"\n'
                                 '[[supports]]\nselect = "nearest"\npoints = [[0, 0, 100]]\nrestraint = "pinned"'),
    Case("wind_and_point_load", '[loads.cases.wind]\narea_true = ["0.3 kN/m^2", 0, "0.2 kN/m^2"]\n'
                                '[[loads.cases.wind.points]]\nnearest = [0, 0, 10]\nforce = [0, 0, "-5 kN"]\n'
                                '[loads.combinations.ULS]\nlimit_state = "ULS"\n'
                                'factors = { dead = 1.35, snow = 1.5, wind = 0.9 }'),
    Case("no_loads", ""),
    Case("thin_shell", '[shell]\nthickness = "5 mm"'),
    # settings that cannot be: refused with the key named
    Case("aspect_under_one", "[field]\nmax_aspect = 0.5", refused="max_aspect"),
    Case("rollers_only", '[[supports]]\nselect = "boundary"\nrestraint = "roller_z"', refused="[[supports]]"),
    Case("sized_rods", '[section]\nkind = "solid_round"\ndiameter = "30 mm"\n[design]\nsize_sections = true',
         refused="size_sections"),
]

_BASE_LOADS = ('[loads.cases.dead]\nself_weight = 1.0\npanels = 1.0\narea_true = "0.25 kN/m^2"\n'
               '[loads.cases.snow]\narea_plan = "1 kN/m^2"\n'
               '[loads.combinations.ULS]\nlimit_state = "ULS"\nfactors = { dead = 1.35, snow = 1.5 }\n'
               '[loads.combinations.SLS]\nlimit_state = "SLS"\nfactors = { dead = 1.0, snow = 1.0 }\n')


def _merged(base: dict, extra: dict) -> dict:
    out = dict(base)
    for key, value in extra.items():
        out[key] = _merged(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def _toml(table: dict, prefix: str = "") -> str:
    """TOML text of a table of tables, strings, numbers, booleans, lists and inline tables."""
    def value(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{json.dumps(k)} = {value(x)}" for k, x in v.items()) + " }"
        return repr(v)

    plain = {k: v for k, v in table.items() if not isinstance(v, dict)
             and not (isinstance(v, list) and v and all(isinstance(x, dict) for x in v) and prefix == "")}
    lines = [f"{json.dumps(k) if '.' in k else k} = {value(v)}" for k, v in plain.items()]
    for k, v in table.items():
        if isinstance(v, dict):
            name = f"{prefix}{k}"
            lines += ["", f"[{name}]", _toml(v, name + ".")]
        elif k not in plain:  # an array of tables at the top: [[supports]]
            for item in v:
                lines += ["", f"[[{prefix}{k}]]", _toml(item, f"{prefix}{k}.")]
    return "\n".join(lines)


def project_text(case: Case, surface: Path, cells: int) -> str:
    """The base project (the quick start's settings on ``surface``) with the case's TOML merged in."""
    base = tomllib.loads(f'[project]\nname = "{case.name}"\n[surface]\nfile = {json.dumps(str(surface))}\n'
                         f'[remesh]\nn_cells = {cells}\n' + ("" if case.name == "no_loads" else _BASE_LOADS))
    base["supports"] = [{"select": "flagged", "restraint": "pinned"}]
    extra = tomllib.loads(case.toml)
    return _toml(_merged(base, extra)) + "\n"


def _findings(run_dir: Path) -> str:
    manifest = run_dir / "manifest.json"
    if not manifest.is_file():
        return ""
    stages = json.loads(manifest.read_text()).get("stages", {})
    kinds = Counter(f["kind"] for s in (stages.values() if isinstance(stages, dict) else stages)
                    for f in s.get("findings", []))
    return ",".join(f"{k}:{n}" for k, n in sorted(kinds.items()))


def _verdicts(run_dir: Path) -> str:
    path = run_dir / "06-analysis" / "analysis.json"
    if not path.is_file():
        return ""
    verdicts = json.loads(path.read_text()).get("verdicts", [])
    failed = [v["kind"] for v in verdicts if not v["pass"]]
    return f"fail {','.join(failed)}" if failed else f"pass {len(verdicts)}/{len(verdicts)}"


def run_case(case: Case, surface: Path, out: Path, cells: int, timeout: float) -> dict:
    """Write the case's project, run it cold, and say how it ended."""
    folder = out / "projects"
    folder.mkdir(parents=True, exist_ok=True)
    project = folder / f"{case.name}.toml"
    project.write_text(project_text(case, surface, cells), encoding="utf-8")
    run_dir = out / "runs" / case.name
    ended = run_gridshell(["run", str(project), "--out", str(run_dir), "--quiet", "--force"], run_dir, timeout)
    if case.refused is None:
        expected = ended.report and "Traceback" not in ended.stderr
    else:
        expected = ended.refused_with(case.refused)
    said = ended.error(160) if ended.code else f"{_verdicts(run_dir)}; {_findings(run_dir) or 'no finding'}"
    return {"name": case.name, "exit": ended.code, "seconds": round(ended.seconds, 1), "report": ended.report,
            "expected": expected, "said": said}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=460, help="the generated roof's seed")
    parser.add_argument("--cells", type=int, default=80)
    parser.add_argument("--out", type=Path, default=Path("out/unusual_settings"))
    parser.add_argument("--match", default="", help="only the cases whose name holds one of these (comma-separated)")
    parser.add_argument("--timeout", type=float, default=1200.0, help="seconds per run")
    args = parser.parse_args()
    from tests.generated_surfaces import generate_surface, write_ply

    generated = generate_surface(args.seed)
    surface = write_ply(generated, args.out / "surfaces" / f"{generated.name}.ply").resolve()
    wanted = [m for m in args.match.split(",") if m]
    cases = [c for c in CASES if not wanted or any(m in c.name for m in wanted)]
    print(f"unusual_settings: {len(cases)} cases on {generated.name} ({generated.span_m:.1f} m span), "
          f"{args.cells} cells, into {args.out}")
    print(table_header(28))
    rows = []
    for case in cases:
        row = run_case(case, surface, args.out, args.cells, args.timeout)
        rows.append(row)
        print(table_row(row, 28, 120), flush=True)
    met = sum(r["expected"] for r in rows)
    print(f"{met} of {len(rows)} ended as meant (the report, or a refusal naming the key)")
    return 0 if met == len(rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
