"""Parametric surfaces for the project templates (lengths in metres).

- ``mockup``: the thesis's 2.4 m x 2.4 m funicular, form-found by force density over
  the square plan, pinned along the whole boundary (our choice; METHOD.md section 7).
- ``cap``: shallow spherical cap over a circle, span / rise = 21.43 by default.
- ``vault``: circular barrel vault over a rectangle.
- ``hypar``: hyperbolic paraboloid z = c x y over a square.
- ``courtyard``: a free-form roof over a rectangle with a central rectangular opening.
Each returns a clean ``TriMesh``; the mock-up also returns its form-finding record.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay

from ..errors import InputError
from ..mesh import TriMesh
from .form_finding import FormFindingResult, force_density
from .surfaces import clean_mesh

__all__ = ["TEMPLATES", "MockupResult", "mockup", "cap", "vault", "hypar", "courtyard", "grid_triangles"]

TEMPLATES = ("mockup", "cap", "vault", "hypar", "courtyard")

#: The most triangles a template builds: twice the 100k-triangle shell of benchmarks/shell_scaling.py.
#: Beyond it a mistyped parameter (divisions = 1_000, length = 1e9) would fill the memory before any check.
MAX_TEMPLATE_TRIANGLES = 200_000


def _positive(**values: float) -> None:
    for key, value in values.items():
        if not 0 < value < np.inf:
            raise InputError(f"surface parameter {key} = {value!r} must be positive and finite")


def _not_too_fine(n_triangles: int, *parameters: str) -> None:
    """Refuse parameters that would build more than MAX_TEMPLATE_TRIANGLES triangles, naming them."""
    if n_triangles > MAX_TEMPLATE_TRIANGLES:
        names = parameters[0] if len(parameters) == 1 else f"{', '.join(parameters[:-1])} and {parameters[-1]}"
        raise InputError(f"the surface parameters ({names}) give a template mesh of {n_triangles:,} triangles, "
                         f"more than the {MAX_TEMPLATE_TRIANGLES:,} a template builds",
                         hint=f"lower surface.parameters.{parameters[0]}, or give the surface as a mesh file")


def grid_triangles(nx: int, ny: int, mask: np.ndarray | None = None) -> np.ndarray:
    """Triangles of an (nx+1) x (ny+1) node grid (node id = i * (ny+1) + j).

    Diagonals alternate in a checkerboard so the pattern is symmetric about both mid-lines
    when nx and ny are even. ``mask`` (nx, ny) bool keeps only the chosen cells.
    """
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    keep = np.ones((nx, ny), dtype=bool) if mask is None else mask
    i, j = i[keep], j[keep]
    a = i * (ny + 1) + j
    b, c, d = a + (ny + 1), a + (ny + 2), a + 1
    flip = ((i + j) % 2 == 1) ^ ((i >= nx / 2) ^ (j >= ny / 2))
    t1 = np.where(flip[:, None], np.stack([a, b, d], 1), np.stack([a, b, c], 1))
    t2 = np.where(flip[:, None], np.stack([b, c, d], 1), np.stack([a, c, d], 1))
    return np.concatenate([t1, t2])


def _plan_grid(size_x: float, size_y: float, nx: int, ny: int) -> np.ndarray:
    x, y = np.meshgrid(np.linspace(-size_x / 2, size_x / 2, nx + 1),
                       np.linspace(-size_y / 2, size_y / 2, ny + 1), indexing="ij")
    return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)


@dataclass(frozen=True, kw_only=True)
class MockupResult:
    """The mock-up surface, its form-finding record and the force density used."""

    mesh: TriMesh
    form_finding: FormFindingResult
    force_density: float
    applied_load: float


def mockup(*, span: float = 2.4, rise: float = 0.45, divisions: int = 24,
           load_per_area: float = 1000.0) -> MockupResult:
    """Funicular shell over a square plan of side ``span`` (m), pinned along its boundary.

    A square net with ``divisions`` bays per side carries a uniform vertical load
    ``load_per_area`` (N/m^2 on plan, lumped to the nodes by tributary plan area). One
    force density, found in closed form because heights scale with 1/q, gives the
    crown height ``rise``. The net's edges are the grid lines; each bay is split into two
    triangles for the surface mesh.
    """
    _positive(span=span, rise=rise, load_per_area=load_per_area)
    if divisions < 4 or divisions % 2:
        raise InputError(f"surface parameter divisions = {divisions} must be an even number >= 4")
    _not_too_fine(2 * divisions**2, "divisions")
    nodes = _plan_grid(span, span, divisions, divisions)
    triangles = grid_triangles(divisions, divisions)
    n = divisions + 1
    i, j = np.divmod(np.arange(len(nodes)), n)
    fixed = (i == 0) | (j == 0) | (i == divisions) | (j == divisions)
    i0, j0 = np.meshgrid(np.arange(divisions), np.arange(divisions + 1), indexing="ij")
    horizontal = np.stack([i0 * n + j0, (i0 + 1) * n + j0], -1).reshape(-1, 2)
    vertical = np.stack([j0 * n + i0, j0 * n + i0 + 1], -1).reshape(-1, 2)
    edges = np.concatenate([horizontal, vertical])
    bay = span / divisions
    tributary = np.where(fixed, 0.0, bay * bay)
    loads = np.zeros((len(nodes), 3))
    loads[:, 2] = tributary * load_per_area  # upward on the inverted (compression) form
    unit = force_density(nodes, edges, 1.0, loads, fixed)
    q = unit.nodes[:, 2].max() / rise
    result = force_density(nodes, edges, q, loads, fixed)
    mesh, _ = clean_mesh(result.nodes, triangles, name="mockup")
    return MockupResult(mesh=mesh, form_finding=result, force_density=float(q),
                        applied_load=float(loads[:, 2].sum()))


def cap(*, span: float = 20.0, span_to_rise: float = 21.43, rings: int = 12) -> TriMesh:
    """Spherical cap over a circle of diameter ``span`` (m) with rise span / span_to_rise."""
    _positive(span=span, span_to_rise=span_to_rise)
    if rings < 2:
        raise InputError(f"surface parameter rings = {rings} must be >= 2")
    _not_too_fine(6 * rings**2, "rings")
    radius_plan = span / 2
    rise = span / span_to_rise
    sphere = (radius_plan**2 + rise**2) / (2 * rise)
    pts = [np.zeros(2)]
    for k in range(1, rings + 1):
        r = radius_plan * k / rings
        t = np.linspace(0, 2 * np.pi, 6 * k, endpoint=False) + (np.pi / (6 * k) if k % 2 else 0)
        pts.append(np.stack([r * np.cos(t), r * np.sin(t)], 1))
    plan = np.vstack(pts)
    triangles = Delaunay(plan).simplices
    z = np.sqrt(np.maximum(sphere**2 - (plan**2).sum(1), 0)) - (sphere - rise)
    mesh, _ = clean_mesh(np.column_stack([plan, z]), triangles, name="cap")
    return mesh


def vault(*, span: float = 10.0, length: float = 15.0, rise: float = 3.0, divisions: int = 24) -> TriMesh:
    """Circular barrel vault: arch of ``span`` and ``rise`` across y, extruded along x for ``length``."""
    _positive(span=span, length=length, rise=rise)
    if divisions < 2:
        raise InputError(f"surface parameter divisions = {divisions} must be >= 2")
    if rise > span / 2:
        raise InputError(f"vault rise {rise} m must not exceed half the span ({span / 2} m)")
    radius = (span**2 / 4 + rise**2) / (2 * rise)
    half_angle = np.arcsin(span / (2 * radius))
    n_arc = divisions
    n_len = max(2, int(round(min(divisions * length / span / 2, MAX_TEMPLATE_TRIANGLES))) * 2)
    _not_too_fine(2 * n_len * n_arc, "divisions", "length", "span")
    s, t = np.meshgrid(np.linspace(-length / 2, length / 2, n_len + 1),
                       np.linspace(-half_angle, half_angle, n_arc + 1), indexing="ij")
    nodes = np.stack([s.ravel(), radius * np.sin(t.ravel()), radius * np.cos(t.ravel()) - (radius - rise)], 1)
    mesh, _ = clean_mesh(nodes, grid_triangles(n_len, n_arc), name="vault")
    return mesh


def hypar(*, span: float = 10.0, rise: float = 2.0, divisions: int = 20) -> TriMesh:
    """Hyperbolic paraboloid z = rise * (2x/span)(2y/span) over a square of side ``span``."""
    _positive(span=span, rise=rise)
    if divisions < 2:
        raise InputError(f"surface parameter divisions = {divisions} must be >= 2")
    _not_too_fine(2 * divisions**2, "divisions")
    nodes = _plan_grid(span, span, divisions, divisions)
    nodes[:, 2] = rise * (2 * nodes[:, 0] / span) * (2 * nodes[:, 1] / span)
    mesh, _ = clean_mesh(nodes, grid_triangles(divisions, divisions), name="hypar")
    return mesh


def courtyard(*, length: float = 30.0, width: float = 20.0, opening_length: float = 10.0,
              opening_width: float = 6.0, rise: float = 3.0, divisions: int = 30) -> TriMesh:
    """Free-form roof over a ``length`` x ``width`` rectangle with a central opening.

    Both the outer edge and the opening's edge stay at z = 0 (two boundary loops); the
    roof rises between them with a gentle wave along the long side.
    """
    _positive(length=length, width=width, opening_length=opening_length, opening_width=opening_width, rise=rise)
    if opening_length >= length or opening_width >= width:
        raise InputError("the courtyard opening must be smaller than the roof")
    nx = max(6, divisions)
    ny = max(6, int(round(min(nx * width / length, MAX_TEMPLATE_TRIANGLES))))
    _not_too_fine(2 * nx * ny, "divisions", "width", "length")
    xs = np.unique(np.concatenate([np.linspace(-length / 2, length / 2, nx + 1),
                                   [-opening_length / 2, opening_length / 2]]))
    ys = np.unique(np.concatenate([np.linspace(-width / 2, width / 2, ny + 1),
                                   [-opening_width / 2, opening_width / 2]]))
    nx, ny = len(xs) - 1, len(ys) - 1
    x, y = np.meshgrid(xs, ys, indexing="ij")
    cx, cy = 0.5 * (xs[:-1] + xs[1:]), 0.5 * (ys[:-1] + ys[1:])
    inside = (np.abs(cx)[:, None] < opening_length / 2) & (np.abs(cy)[None, :] < opening_width / 2)
    triangles = grid_triangles(nx, ny, mask=~inside)
    px, py = x.ravel(), y.ravel()
    to_outer = np.minimum(length / 2 - np.abs(px), width / 2 - np.abs(py))
    to_inner = np.maximum(np.abs(px) - opening_length / 2, np.abs(py) - opening_width / 2)
    t = np.clip(to_outer / np.maximum(to_outer + np.maximum(to_inner, 0), 1e-12), 0, 1)
    z = rise * np.sin(np.pi * t) * (1 + 0.15 * np.cos(2 * np.pi * px / length))
    z[to_inner <= 0] = 0.0
    mesh, _ = clean_mesh(np.stack([px, py, z], 1), triangles, name="courtyard")
    return mesh

