"""The shell, field, remesh and optimize stages on every real roof surface with its flagged
supports (the whole boundary where a file flags none). Skipped when the folder is absent."""

from __future__ import annotations

import numpy as np
import pytest

from .conftest import real_surfaces

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("path", real_surfaces())
def test_stages_run_on_real_surfaces(path, tmp_path):
    from workflow.config import project_from_surface
    from workflow.progress import Progress
    from workflow.runner import run_project
    from workflow.stages import STAGES
    from workflow.surface_io import read_surface

    _, _, flagged = read_surface(path)
    supports = "flagged" if flagged is not None and np.any(flagged) else "boundary"
    project = project_from_surface(str(path), supports)
    project = project.model_copy(update={"remesh": project.remesh.model_copy(update={"n_cells": 60,
                                                                                      "lloyd_iterations": 40})})
    out = tmp_path / path.stem
    summary = run_project(project, out, STAGES, until="optimize", progress=Progress(enabled=False))
    assert summary.message is None
    statuses = {s["name"]: s["status"] for s in summary.stages}
    assert all(statuses[name] == "ran" for name in ("surface", "shell", "field", "remesh", "optimize"))
    import json

    shell = json.loads((out / "02-shell" / "shell.json").read_text())
    assert shell["equilibrium_error"] < 1e-6
    field = json.loads((out / "03-field" / "field.json").read_text())
    assert field["achieved_size_ratio"] <= project.field.max_size_ratio + 1e-9
    remesh = json.loads((out / "04-remesh" / "remesh.json").read_text())
    assert remesh["valence3_share_interior"] > 0.95
    # the cells asked for, or fewer where the joints are too big for them (hyperbol2: 48.3 mm
    # steel nodes on a small saddle), which a finding says
    coarsened = remesh["coarsened"]["remeshes"] > 0
    assert remesh["n_faces"] > 40 or coarsened
    assert coarsened == any(f["kind"] == "grid_coarsened" for f in summary.findings)
    assert remesh["coarsened"]["cells_asked"] == 60 and remesh["coarsened"]["cells_built"] == remesh["n_faces"]
    assert np.isfinite(remesh["closeness_max_rel"])
    # the optimised grid, read back from its file, has no beam shorter than its joints and the
    # shortest cut take (what no optimisation lengthens is removed or collapsed, and said)
    from fabrication.limits import required_beam_lengths_m
    from workflow.stages.build_limits import build_limits_of
    from workflow.stages.polymesh_io import read_polymesh_obj

    grid = read_polymesh_obj(out / "05-optimize" / "gridshell.obj")
    assert np.all(grid.beam_lengths >= required_beam_lengths_m(grid, build_limits_of(project)) - 1e-9)
