"""``[design] choose = "best"``: the design with the highest lambda_NL_worst per kg of a small sweep.

``gridshell run`` runs the sweep of ``[design] choose_from`` (its product, stages up to the
analysis, on a local Dask cluster as ``gridshell sweep`` does) in ``OUT/choose/``, keeps the point
whose lambda_NL_worst / beam mass is highest among those that pass every check of the analysis
(among all that ran where none passes), gives ``OUT`` that point's stages (hard links, so nothing is
computed twice) and goes on with the chosen values. ``OUT/choose/choice.json`` records every
candidate's figures and the choice; the sweep's own sweep.csv and sweep.html are beside it.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from engine.errors import InputError
from fabrication.files import write_text_atomic

from .config import Project, read_toml

__all__ = ["choose_best", "score"]


def score(figures: dict) -> float | None:
    """lambda_NL_worst per tonne of beams (None without both)."""
    lam, mass = figures.get("lambda_NL_worst"), figures.get("beam_mass_kg")
    if lam is None or not mass:
        return None
    return 1000.0 * float(lam) / float(mass)


def choose_best(project: Project, out_dir: Path, *, project_file: str | None, workers: int | None = None,
                settings: dict[str, Any] | None = None,
                say: Callable[[str], None] | None = None) -> tuple[Project, dict]:
    """The project with the chosen values and the choice (also in OUT/choose/choice.json);
    ``settings``: the dotted keys that replace the project file's (``gridshell run --set``)."""
    from .config import parse_project
    from .stages import STAGES
    from .sweep import SweepSpec, _with, run_sweep, seed, sweep_points

    say = say or (lambda text: None)
    out_dir = Path(out_dir)
    folder = out_dir / "choose"
    if project_file:
        data = read_toml(Path(project_file), "project file")
        base = Path(project_file).parent
        for key, value in (settings or {}).items():
            _with(data, key, value)
    else:  # a quick-start project (--surface): its settings as the sweep's base
        data, base = project.model_dump(mode="json", exclude_none=True), out_dir
    data.setdefault("design", {})["choose"] = "as_given"
    spec = SweepSpec(file=folder / "choose.toml", project_file=base / "project.toml", project_data=data,
                     until="analysis", parameters={k: list(v) for k, v in project.design.choose_from.items()})
    points = {p.number: p for p in sweep_points(spec, folder)}
    say(f"[design] choose = \"best\": {len(points)} candidates in {folder}")
    rows = run_sweep(spec, folder, workers=workers, say=say)
    candidates = []
    for row in rows:
        point = points[row["point"]]
        figures = {}
        path = point.folder / "06-analysis" / "analysis.json"
        if row["status"] == "ok" and path.is_file():
            figures = json.loads(path.read_text(encoding="utf-8"))
        candidates.append({"point": row["point"], "values": point.values, "status": row["status"],
                           "message": row["message"], "lambda_NL_worst": figures.get("lambda_NL_worst"),
                           "beam_mass_kg": figures.get("beam_mass_kg"), "score_per_t": score(figures),
                           "passes": bool(figures) and all(v["pass"] for v in figures.get("verdicts", []))})
    ranked = [c for c in candidates if c["score_per_t"] is not None]
    passing = [c for c in ranked if c["passes"]]
    if not ranked:
        raise InputError(f"[design] choose = \"best\": no candidate reached a non-linear load factor "
                         f"({len(candidates)} tried, see {folder / 'sweep.csv'})",
                         hint='set [design] choose = "as_given", or other [design] choose_from values')
    best = max(passing or ranked, key=lambda c: c["score_per_t"])
    chosen = points[best["point"]]
    choice = {"criterion": "lambda_NL_worst per tonne of beams, among the candidates that pass every check"
                           + ("" if passing else " (none passes: among all)"),
              "chosen": best, "candidates": candidates}
    write_text_atomic(folder / "choice.json", json.dumps(choice, indent=1, default=float))
    say("[design] choose: " + ", ".join(f"{k} = {v}" for k, v in chosen.values.items())
        + f" (lambda_NL_worst {best['lambda_NL_worst']:.3g}, {best['beam_mass_kg']:.0f} kg)")
    merged = json.loads(json.dumps(data))
    for key, value in chosen.values.items():
        _with(merged, key, value)
    merged["design"]["choose"] = "best"  # as the user asked: the choose keys are left out of the stages' keys
    chosen_project = parse_project(merged, source=f"{folder / 'choice.json'}", base_dir=base)
    names = [s.name for s in STAGES]
    seed(out_dir, chosen.folder, names[:names.index("analysis") + 1], chosen_project)
    return chosen_project, choice
