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
    from engine.parametric import grid_triangles

    n = 8
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    return vertices, grid_triangles(n, n)
