"""Shared fixtures: the real surfaces folder (skipped when absent) and small meshes."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SURFACES = Path(os.environ.get("GRIDSHELL_SURFACES", ROOT.parent / "shared" / "data" / "surfaces"))
SURFACE_FILES = sorted(SURFACES.glob("*.ply")) if SURFACES.is_dir() else []


def real_surfaces():
    """pytest params over the real roof surfaces, or one skipped param when the folder is absent."""
    if not SURFACE_FILES:
        return [pytest.param(None, marks=pytest.mark.skip(reason=f"no surfaces folder at {SURFACES}"))]
    return [pytest.param(p, id=p.stem) for p in SURFACE_FILES]


@pytest.fixture
def square_grid():
    """A flat 1 m x 1 m square split into 8 x 8 x 2 triangles: (vertices, faces)."""
    from engine.geometry.parametric import grid_triangles

    n = 8
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    return vertices, grid_triangles(n, n)


def small_project():
    """The mock-up template scaled down for tests: 14 cells, two imperfection shapes."""
    from importlib import resources

    from workflow.config import load_project

    project = load_project(resources.files("templates") / "mockup.toml")
    return project.model_copy(update={
        "surface": project.surface.model_copy(update={"parameters": {**project.surface.parameters, "divisions": 12}}),
        "remesh": project.remesh.model_copy(update={"n_cells": 14, "lloyd_iterations": 30}),
        "analysis": project.analysis.model_copy(update={"n_modes": 3, "imperfection_shapes": ["linear", "mode1"],
                                                        "elements_per_beam": 2}),
        "fabrication": project.fabrication.model_copy(update={
            "sheets": project.fabrication.sheets.model_copy(update={"width": 2.0, "height": 1.25}),
            "joints": project.fabrication.joints.model_copy(update={"combined_step": True})}),
    })


@pytest.fixture(scope="session")
def small_run(tmp_path_factory):
    """The whole workflow on the small mock-up, once per test session: (project, output folder)."""
    from workflow.progress import Progress
    from workflow.runner import run_project
    from workflow.stages import STAGES

    project = small_project()
    out = tmp_path_factory.mktemp("small") / "out"
    summary = run_project(project, out, STAGES, progress=Progress(enabled=False))
    assert summary.message is None, summary.message
    return project, out
