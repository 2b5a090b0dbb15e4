"""The grid made again for the tubes that were sized (``[design] fit_grid_to_tubes = true``).

The remesh and optimize stages fit the grid to the joints of the project's ``[section]``: the
shortest beam two joints leave room for, the smallest angle between beams. Sizing may then choose
larger tubes, whose larger joints need longer beams (a 219 mm node where the grid was made for
114 mm ones clashes with its neighbours). So where the largest sized tube is larger than
``[section]``, the run goes on with ``[section]`` = that tube: the remesh, the optimisation and the
sizing run again (the sizing from there may choose smaller tubes for most beams, never needing
larger joints than the grid now allows for) - at most ``MAX_REFITS`` times. Each round makes the
beams longer, and on some roofs their moments then ask for larger tubes again (the courtyard
template: CHS 114.3 -> 193.7 -> 273 -> 323.9, and 33 clashing joints). So the last round sizes
within its grid's tube (``[design] max_diameter``, the walls grow instead), and the tubes fit the
joints the grid was made for; where no tube that size passes, the sizing says so as it would for
any catalogue. ``OUT/fitted_grid.json`` records each round; a rerun starts from the section
recorded there, so that it finds its stages cached. The stages after the analysis run once, for
the grid that fits.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

from fabrication.files import write_text_atomic

from .config import Project
from .stages.sizing import profile_name

__all__ = ["run_with_fitted_grid", "MAX_REFITS"]

#: Rounds of remeshing for larger sized tubes, at most.
MAX_REFITS = 2


def _largest_sized(out_dir: Path) -> dict | None:
    try:
        design = json.loads((out_dir / "06-analysis" / "analysis.json").read_text(encoding="utf-8")).get("design")
    except (OSError, ValueError):
        return None
    if not design or not design.get("groups"):
        return None
    return max(design["groups"], key=lambda g: (g["diameter_mm"], g["thickness_mm"]))


def run_with_fitted_grid(project: Project, out_dir: Path, stages, *, say: Callable[[str], None], **run) -> tuple:
    """run_project, then the refits where the sized tubes outgrow [section]; (project, summary)."""
    from .runner import run_project

    out_dir = Path(out_dir)
    names = [s.name for s in stages]
    until = run.get("until")
    if (not (project.design.size_sections and project.design.fit_grid_to_tubes) or run.get("only")
            or (until is not None and names.index(until) < names.index("analysis"))):
        return project, run_project(project, out_dir, stages, **run)
    record = out_dir / "fitted_grid.json"
    rounds = []
    earlier = _earlier_fit(record, project)
    if earlier is not None:  # a rerun: start from the section the grid was made for last time
        rounds = earlier["rounds"]
        project = _with_tube(project, *earlier["section_mm"], capped=len(rounds) >= MAX_REFITS)
    # up to the analysis first: the later stages are made once, for the grid that fits
    summary = run_project(project, out_dir, stages, **{**run, "until": "analysis"})
    for number in range(len(rounds) + 1, MAX_REFITS + 1):
        largest = _largest_sized(out_dir)
        if summary.message or largest is None or _fits(largest, project):
            break
        before = profile_name(project)
        last = number == MAX_REFITS
        say(f"the sized tubes (largest {largest['profile']}) are larger than the grid's joints were made for "
            f"([section] {before}): the grid is made again for {largest['profile']} ({number} of {MAX_REFITS}; "
            f"[design] fit_grid_to_tubes = false keeps it)"
            + ("; the last round sizes tubes up to that diameter, thicker walls instead" if last else ""))
        rounds.append({"round": number, "section_before": before, "largest_sized": largest["profile"]})
        project = _with_tube(project, largest["diameter_mm"], largest["thickness_mm"], capped=last)
        summary = run_project(project, out_dir, stages, **{**run, "until": "analysis", "force": False})
    if rounds:
        final = _largest_sized(out_dir)
        if final is not None and not _fits(final, project):
            say(f"after {len(rounds)} rounds the grid is made for {profile_name(project)}, and the sizing chose "
                f"{final['profile']} for some beams: their joints may not fit (the fabrication's findings name "
                f"them); fewer [remesh] n_cells or smaller joints ([fabrication.joints]) leave more room")
        write_text_atomic(record, json.dumps({
            "rounds": rounds, "section": profile_name(project),
            "section_mm": [1000 * project.section.diameter, 1000 * project.section.thickness],
            "largest_sized": None if final is None else final["profile"],
            "fits": final is None or _fits(final, project)}, indent=1))
    else:
        record.unlink(missing_ok=True)  # an earlier run's record, of a grid this run did not make
    if not summary.message and until != "analysis":
        summary = run_project(project, out_dir, stages, **{**run, "force": False})
    return project, summary


def _fits(group: dict, project: Project) -> bool:
    """Whether a sized group's tube (analysis.json design group) is no larger than [section]'s."""
    return group["diameter_mm"] <= 1000 * project.section.diameter + 0.01


def _with_tube(project: Project, diameter_mm: float, thickness_mm: float, *, capped: bool = False) -> Project:
    """``project`` with [section] that tube; ``capped``: and sized within its diameter ([design]
    max_diameter, or the one given where that is smaller)."""
    diameter = diameter_mm / 1000.0
    section = project.section.model_copy(update={"diameter": diameter, "thickness": thickness_mm / 1000.0})
    update: dict = {"section": section}
    if capped:
        given = project.design.max_diameter
        update["design"] = project.design.model_copy(
            update={"max_diameter": diameter if given is None else min(given, diameter)})
    return project.model_copy(update=update)


def _earlier_fit(record: Path, project: Project) -> dict | None:
    """An earlier run's record that began from this project's section (None otherwise)."""
    try:
        fitted = json.loads(record.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not fitted.get("rounds") or fitted["rounds"][0]["section_before"] != profile_name(project):
        return None
    return fitted
