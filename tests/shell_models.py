"""Published shell benchmark models, shared by the tests and benchmarks/shell_scaling.py."""

from __future__ import annotations

import numpy as np

from engine.geometry.parametric import grid_triangles
from engine.mesh import TriMesh
from engine.structure.loads import LoadCase
from engine.structure.shell import ShellMaterial, analyse_shell, shell_nodal_loads
from engine.structure.supports import Supports

#: MacNeal & Harder (1985): vertical deflection at the midside of the free edge.
SCORDELIS_LO_REFERENCE = 0.3024
#: MacNeal & Harder (1985): radial deflection under the loads (18 degree hole).
HEMISPHERE_REFERENCE = 0.094
#: Timoshenko & Woinowsky-Krieger, centre deflection of square plates under uniform load, x q a^4 / D.
PLATE_SIMPLY_SUPPORTED = 0.00406
PLATE_CLAMPED = 0.00126


def scordelis_lo(divisions: int) -> tuple[float, float, TriMesh]:
    """The Scordelis-Lo roof (R 25, L 50, 40 degrees, t 0.25, E 4.32e8, nu 0, 90 per area), full roof
    with 2*divisions x 2*divisions cells; returns (midside deflection, equilibrium error, mesh)."""
    radius, length, angle = 25.0, 50.0, np.radians(40.0)
    phi, y = np.meshgrid(np.linspace(-angle, angle, 2 * divisions + 1), np.linspace(0, length, 2 * divisions + 1),
                         indexing="ij")
    vertices = np.c_[radius * np.sin(phi).ravel(), y.ravel(), radius * np.cos(phi).ravel()]
    mesh = TriMesh(vertices=vertices, faces=grid_triangles(2 * divisions, 2 * divisions), name="scordelis-lo")
    ends = np.flatnonzero((np.isclose(y, 0) | np.isclose(y, length)).ravel())
    middle = np.flatnonzero(np.isclose(y, length / 2).ravel())
    supports = Supports.merge([(ends, np.array([1, 0, 1, 0, 0, 0], bool)),   # rigid diaphragms
                               (middle, np.array([0, 1, 0, 0, 0, 0], bool))])  # symmetry: no axial motion
    thickness = 0.25
    loads = shell_nodal_loads(mesh, LoadCase(name="weight", area_true=[0, 0, -90.0]), thickness=thickness, density=0)
    result = analyse_shell(mesh, supports, loads, thickness=thickness, material=ShellMaterial(E=4.32e8, nu=0.0))
    node = np.flatnonzero((np.isclose(phi, angle) & np.isclose(y, length / 2)).ravel())[0]
    return float(-result.displacements[node, 2]), result.equilibrium_error, mesh


def pinched_hemisphere(divisions: int) -> tuple[float, float]:
    """Quarter of the pinched hemisphere with an 18 degree hole (R 10, t 0.04, E 6.825e7, nu 0.3,
    unit loads in and out); returns (mean radial deflection under the loads, equilibrium error)."""
    radius = 10.0
    phi, theta = np.meshgrid(np.linspace(np.radians(18), np.pi / 2, divisions + 1),
                             np.linspace(0, np.pi / 2, divisions + 1), indexing="ij")
    vertices = np.c_[(radius * np.sin(phi) * np.cos(theta)).ravel(), (radius * np.sin(phi) * np.sin(theta)).ravel(),
                     (radius * np.cos(phi)).ravel()]
    mesh = TriMesh(vertices=vertices, faces=grid_triangles(divisions, divisions), name="hemisphere")
    xz_plane = np.flatnonzero(np.isclose(theta, 0).ravel())
    yz_plane = np.flatnonzero(np.isclose(theta, np.pi / 2).ravel())
    top = np.flatnonzero((np.isclose(phi, np.radians(18)) & np.isclose(theta, 0)).ravel())
    supports = Supports.merge([(xz_plane, np.array([0, 1, 0, 1, 0, 1], bool)),
                               (yz_plane, np.array([1, 0, 0, 0, 1, 1], bool)),
                               (top, np.array([0, 0, 1, 0, 0, 0], bool))])
    a = np.flatnonzero((np.isclose(phi, np.pi / 2) & np.isclose(theta, 0)).ravel())[0]
    b = np.flatnonzero((np.isclose(phi, np.pi / 2) & np.isclose(theta, np.pi / 2)).ravel())[0]
    loads = np.zeros((mesh.n_vertices, 6))
    loads[a, 0], loads[b, 1] = 1.0, -1.0
    result = analyse_shell(mesh, supports, loads, thickness=0.04, material=ShellMaterial(E=6.825e7, nu=0.3))
    return float(0.5 * (result.displacements[a, 0] - result.displacements[b, 1])), result.equilibrium_error


def square_plate(divisions: int, clamped: bool) -> tuple[float, float]:
    """Unit square plate (t 0.01, E 1e7, nu 0.3) under unit pressure; returns (centre deflection
    x D / (q a^4), equilibrium error)."""
    xs = np.linspace(0.0, 1.0, divisions + 1)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    mesh = TriMesh(vertices=np.c_[x.ravel(), y.ravel(), np.zeros(x.size)], faces=grid_triangles(divisions, divisions))
    edge = np.flatnonzero((np.isclose(x, 0) | np.isclose(x, 1) | np.isclose(y, 0) | np.isclose(y, 1)).ravel())
    flags = np.array([1, 1, 1, 1, 1, 0], bool) if clamped else np.array([1, 1, 1, 0, 0, 0], bool)
    supports = Supports.merge([(edge, flags)])
    E, nu, t = 1e7, 0.3, 0.01
    loads = shell_nodal_loads(mesh, LoadCase(name="q", area_true=[0, 0, -1.0]), thickness=t, density=0)
    result = analyse_shell(mesh, supports, loads, thickness=t, material=ShellMaterial(E=E, nu=nu))
    centre = int(np.argmin(np.linalg.norm(mesh.vertices[:, :2] - 0.5, axis=1)))
    rigidity = E * t**3 / (12 * (1 - nu**2))
    return float(-result.displacements[centre, 2] * rigidity), result.equilibrium_error
