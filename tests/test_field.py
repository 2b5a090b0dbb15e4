"""The guiding field: D and A semantics, Voro(1,1), direction on a vault, symmetry, smoothing."""

from __future__ import annotations

import numpy as np
import pytest

from engine.errors import InputError
from engine.field import (AnisotropyMap, FieldSettings, SizeMap, guiding_field, principal_forces, smooth_directions,
                          smooth_scalar, symmetrise)
from engine.mesh import TriMesh
from engine.parametric import grid_triangles, mockup, vault


def _flat_square(n: int = 20) -> TriMesh:
    xs = np.linspace(-1.0, 1.0, n + 1)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    return TriMesh(vertices=np.c_[x.ravel(), y.ravel(), np.zeros(x.size)], faces=grid_triangles(n, n))


def _tensors(n1: np.ndarray, n2: np.ndarray, d1: np.ndarray, normals: np.ndarray) -> np.ndarray:
    d1 = d1 - np.einsum("ni,ni->n", d1, normals)[:, None] * normals
    d1 /= np.linalg.norm(d1, axis=1)[:, None]
    d2 = np.cross(normals, d1)
    return n1[:, None, None] * np.einsum("ni,nj->nij", d1, d1) + n2[:, None, None] * np.einsum("ni,nj->nij", d2, d2)


def _varying_stress(mesh: TriMesh) -> np.ndarray:
    """Compression growing across x, ratio N2/N1 falling towards the edges: a field that spans D and A."""
    x = mesh.vertices[:, 0]
    n1 = -(1.0 + 20.0 * (x - x.min()) / np.ptp(x))
    n2 = n1 * np.linspace(1.0, 0.05, mesh.n_vertices)[np.argsort(np.argsort(np.abs(mesh.vertices[:, 1])))]
    return _tensors(n1, n2, np.tile([1.0, 0.0, 0.0], (mesh.n_vertices, 1)), mesh.vertex_normals)


@pytest.mark.parametrize("size_map", list(SizeMap))
@pytest.mark.parametrize("anisotropy_map", list(AnisotropyMap))
@pytest.mark.parametrize("D, A", [(2.0, 2.0), (3.0, 1.5)])
def test_size_ratio_is_D_and_aspect_at_most_A(size_map, anisotropy_map, D, A):
    mesh = _flat_square()
    field = guiding_field(mesh, _varying_stress(mesh), FieldSettings(max_size_ratio=D, max_aspect=A, size_map=size_map,
                                                                    anisotropy_map=anisotropy_map))
    assert field.size.min() == pytest.approx(1.0)
    assert field.size.max() / field.size.min() == pytest.approx(D, rel=1e-9)
    assert field.anisotropy.min() >= 1.0
    assert field.anisotropy.max() <= A + 1e-12
    assert field.anisotropy.max() == pytest.approx(A, rel=0.02), "the stress varies enough to reach A"
    # smaller cells where the force is larger
    x = mesh.vertices[:, 0]
    assert field.size[x < -0.8].mean() > field.size[x > 0.8].mean()


def test_voro_1_1_is_uniform_and_isotropic():
    mesh = _flat_square()
    field = guiding_field(mesh, _varying_stress(mesh), FieldSettings(max_size_ratio=1.0, max_aspect=1.0))
    assert np.allclose(field.size, 1.0) and np.allclose(field.anisotropy, 1.0)


def test_metric_ellipse_axes():
    mesh = _flat_square(4)
    field = guiding_field(mesh, _varying_stress(mesh), FieldSettings(max_size_ratio=2.0, max_aspect=2.0))
    M = field.metric()
    u, h, a = field.direction, field.size, field.anisotropy
    along = (h * np.sqrt(a))[:, None] * u
    assert np.allclose(np.einsum("ni,nij,nj->n", along, M, along), 1.0)
    assert np.allclose(np.einsum("nij,nj->ni", M, field.normals), 0.0, atol=1e-12)


def test_principal_forces_pick_the_larger_magnitude():
    normals = np.tile([0.0, 0.0, 1.0], (2, 1))
    tensors = _tensors(np.array([1.0, -5.0]), np.array([-3.0, 2.0]), np.array([[1.0, 0, 0], [0, 1.0, 0]]), normals)
    values, direction = principal_forces(tensors, normals)
    assert np.allclose(values, [[-3.0, 1.0], [-5.0, 2.0]])
    assert abs(direction[0, 1]) == pytest.approx(1.0) and abs(direction[1, 1]) == pytest.approx(1.0)


def test_barrel_vault_direction_runs_along_the_arch():
    """The shell under self-weight on its two springing lines: the larger force is the arch's."""
    from engine.loads import LoadCase
    from engine.shell import ShellMaterial, analyse_shell, shell_nodal_loads
    from engine.supports import Supports

    mesh = vault(span=10.0, length=15.0, rise=3.0, divisions=16)
    y = mesh.vertices[:, 1]
    springings = np.flatnonzero(np.isclose(np.abs(y), np.abs(y).max()))
    supports = Supports.merge([(springings, np.array([1, 1, 1, 0, 0, 0], bool))])
    loads = shell_nodal_loads(mesh, LoadCase(name="g", self_weight=1.0), thickness=0.1, density=2400.0)
    result = analyse_shell(mesh, supports, loads, thickness=0.1, material=ShellMaterial(E=30e9, nu=0.2))
    field = guiding_field(mesh, result.vertex_membrane_forces, FieldSettings())
    middle = np.abs(mesh.vertices[:, 0]) < 3.0
    # the arch runs across y (in plan); its tangent has no x component
    assert np.median(np.abs(field.direction[middle, 0])) < 0.2


def test_symmetrisation_restores_symmetry():
    mesh = mockup(divisions=12).mesh
    rng = np.random.default_rng(1)
    x, y = mesh.vertices[:, 0], mesh.vertices[:, 1]
    n1 = -(1 + x**2 + 0.5 * y**2) * (1 + 0.3 * rng.random(mesh.n_vertices))
    n2 = 0.4 * n1 * (1 + 0.3 * rng.random(mesh.n_vertices))
    direction = np.c_[np.ones_like(x), 0.3 * rng.standard_normal(len(x)), np.zeros_like(x)]
    tensors = _tensors(n1, n2, direction, mesh.vertex_normals)
    planes = (((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)), ((0.0, 0.0, 0.0), (0.0, 1.0, 0.0)))
    field = guiding_field(mesh, tensors, FieldSettings(symmetry_planes=planes))
    from scipy.spatial import cKDTree

    _, mirror = cKDTree(mesh.vertices).query(mesh.vertices * [-1.0, 1.0, 1.0])
    assert np.allclose(field.size, field.size[mirror], rtol=1e-9)
    assert np.allclose(field.anisotropy, field.anisotropy[mirror], rtol=1e-9)
    reflected = field.direction[mirror] * [-1.0, 1.0, 1.0]
    alignment = np.abs(np.einsum("ni,ni->n", field.direction, reflected))
    # directions are defined up to where the averaged line tensor is nearly isotropic (corners)
    assert np.mean(alignment > 0.995) > 0.95 and alignment.min() > 0.98  # the triangulation itself is not mirror-symmetric
    unsymmetric = guiding_field(mesh, tensors, FieldSettings())
    assert not np.allclose(unsymmetric.size, unsymmetric.size[mirror], rtol=1e-3)
    assert symmetrise(mesh, field, planes[:1]).size == pytest.approx(field.size)


def test_smoothing_keeps_constants_and_reduces_variation():
    mesh = _flat_square()
    constant = np.full(mesh.n_vertices, 3.5)
    assert np.allclose(smooth_scalar(mesh, constant, 10), 3.5)
    noisy = np.random.default_rng(0).random(mesh.n_vertices)
    edges = mesh.edges
    variation = lambda v: np.abs(v[edges[:, 0]] - v[edges[:, 1]]).sum()  # noqa: E731
    smoothed = smooth_scalar(mesh, noisy, 5)
    assert variation(smoothed) < 0.5 * variation(noisy)
    assert smoothed.mean() == pytest.approx(noisy.mean(), rel=0.05)
    uniform = np.tile([np.cos(0.3), np.sin(0.3), 0.0], (mesh.n_vertices, 1))
    signs = np.where(np.random.default_rng(2).random(mesh.n_vertices) < 0.5, -1.0, 1.0)[:, None]
    kept = smooth_directions(mesh, uniform * signs, mesh.vertex_normals, 5)
    assert np.allclose(np.abs(kept @ uniform[0]), 1.0), "u and -u are the same line"


def test_bad_settings_are_input_errors():
    with pytest.raises(InputError, match="D"):
        FieldSettings(max_size_ratio=0.5)
    with pytest.raises(InputError, match="A"):
        FieldSettings(max_aspect=0.9)
