"""The guiding field: D and A semantics, Voro(1,1), direction on a vault, symmetry, smoothing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine.errors import InputError
from engine.geometry.parametric import grid_triangles, mockup, vault
from engine.mesh import TriMesh
from engine.remeshing.field import (
    AnisotropyMap,
    FieldSettings,
    Orientation,
    SizeMap,
    guiding_field,
    principal_forces,
    smooth_directions,
    smooth_scalar,
    symmetrise,
)


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


def test_analytic_barrel_vault_direction_and_size():
    """Arch action of a circular barrel vault (radius R, angle t from the crown) under a weight g
    per unit area: hoop force N_t = -g R cos t along the arch, a small longitudinal force along x.
    The field must run along the arch tangent (0, cos t, -sin t) and give the smallest cells at
    the crown, where |N_t| is largest."""
    span, rise = 10.0, 3.0
    mesh = vault(span=span, length=15.0, rise=rise, divisions=16)
    radius = (span**2 / 4 + rise**2) / (2 * rise)
    v = mesh.vertices
    t = np.arctan2(v[:, 1], v[:, 2] + radius - rise)
    tangent = np.c_[np.zeros_like(t), np.cos(t), -np.sin(t)]
    hoop = -1.0e3 * radius * np.cos(t)
    tensors = _tensors(hoop, 0.1 * hoop, tangent, mesh.vertex_normals)
    field = guiding_field(mesh, tensors, FieldSettings(max_size_ratio=2.0, max_aspect=2.0))
    alignment = np.abs(np.einsum("ni,ni->n", field.direction, tangent))
    assert alignment.min() > 0.99
    crown, springing = np.abs(t) < 0.1, np.abs(t) > 0.9 * np.abs(t).max()
    assert field.size[crown].mean() < field.size[springing].mean()
    assert field.size.max() / field.size.min() == pytest.approx(2.0, rel=1e-9)
    # |N1| / |N2| = 10 everywhere: the energy criterion sqrt(10) = 3.16 is bounded by A = 2
    assert np.allclose(field.anisotropy, 2.0)


def test_barrel_vault_direction_runs_along_the_arch():
    """The shell under self-weight on its two springing lines: the larger force is the arch's."""
    pytest.importorskip("engine.structure.shell")
    from engine.structure.loads import LoadCase
    from engine.structure.shell import ShellMaterial, analyse_shell, shell_nodal_loads
    from engine.structure.supports import Supports

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
    # (the triangulation itself is not mirror-symmetric)
    assert np.mean(alignment > 0.995) > 0.95 and alignment.min() > 0.98
    unsymmetric = guiding_field(mesh, tensors, FieldSettings())
    assert not np.allclose(unsymmetric.size, unsymmetric.size[mirror], rtol=1e-3)
    assert symmetrise(mesh, field, planes[:1]).size == pytest.approx(field.size)
    # a bound A reached by a few vertices is still reached after the averaging, symmetrically
    bounded = guiding_field(mesh, tensors, FieldSettings(max_aspect=1.55, symmetry_planes=planes))
    assert bounded.anisotropy.max() == pytest.approx(1.55, rel=1e-9)
    assert np.allclose(bounded.anisotropy, bounded.anisotropy[mirror], rtol=1e-9)


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


def test_energy_anisotropy_is_the_square_root_of_the_force_ratio():
    """METHOD.md 2: a = sqrt(|N1|/|N2|) for forces of the same sign, bounded by A; a uniaxial field
    (N2 = 0) is the limit and gets A; forces of opposite sign get opposite_sign_anisotropy."""
    mesh = _flat_square(8)
    n = mesh.n_vertices
    x_axis = np.tile([1.0, 0.0, 0.0], (n, 1))
    settings = FieldSettings(max_aspect=3.0, smoothing_iterations=0, direction_smoothing_iterations=0)
    for ratio, expected in ((4.0, 2.0), (2.0, np.sqrt(2.0)), (25.0, 3.0), (np.inf, 3.0)):
        n2 = np.full(n, 0.0 if np.isinf(ratio) else -1.0 / ratio)
        field = guiding_field(mesh, _tensors(-np.ones(n), n2, x_axis, mesh.vertex_normals), settings)
        assert np.allclose(field.anisotropy, expected), ratio
        assert np.allclose(np.abs(field.direction[:, 0]), 1.0)
    mixed = guiding_field(mesh, _tensors(-np.ones(n), np.full(n, 0.25), x_axis, mesh.vertex_normals),
                          FieldSettings(max_aspect=3.0, opposite_sign_anisotropy=1.5))
    assert np.allclose(mixed.anisotropy, 1.5)


def test_energy_size_map_follows_the_two_thirds_power():
    """Equal strain energy per cell: h = (n / n_max)^(-2/3), capped at D on the low-force side
    (without clamping and smoothing); if n varies too little for the law to reach D, the exponent
    is raised just enough. The linear map spans [1, D] whatever the range of n."""
    mesh = _flat_square(8)
    x = mesh.vertices[:, 0]
    D = 2.0
    exact = FieldSettings(max_size_ratio=D, clamp_percentiles=(0.0, 100.0), smoothing_iterations=0)
    for force_ratio in (D**1.5, 8.0, 1.5):
        level = 1.0 + (force_ratio - 1.0) * (x - x.min()) / np.ptp(x)
        tensors = _tensors(-level, -0.5 * level, np.tile([0.0, 1.0, 0.0], (len(x), 1)), mesh.vertex_normals)
        field = guiding_field(mesh, tensors, exact)
        # the -2/3 law where it spans at least D; below that, the power that just reaches D
        power = 2.0 / 3.0 if force_ratio ** (2 / 3) >= D else np.log(D) / np.log(force_ratio)
        assert np.allclose(field.size, np.minimum((level / level.max()) ** -power, D), rtol=1e-12), force_ratio
        assert field.size.max() / field.size.min() == pytest.approx(D, rel=1e-9)
        linear = guiding_field(mesh, tensors, FieldSettings(max_size_ratio=D, size_map="linear",
                                                            clamp_percentiles=(0.0, 100.0), smoothing_iterations=0))
        t = (level - level.min()) / np.ptp(level)
        assert np.allclose(linear.size, D - (D - 1.0) * t)


def test_cotangent_smoothing_keeps_constants_and_reduces_variation():
    mesh = vault(divisions=10)
    assert np.allclose(smooth_scalar(mesh, np.full(mesh.n_vertices, -2.0), 7, laplacian="cotangent"), -2.0)
    noisy = np.random.default_rng(3).random(mesh.n_vertices)
    smoothed = smooth_scalar(mesh, noisy, 5, laplacian="cotangent")
    edges = mesh.edges
    variation = lambda v: np.abs(v[edges[:, 0]] - v[edges[:, 1]]).sum()  # noqa: E731
    assert variation(smoothed) < 0.5 * variation(noisy)
    assert noisy.min() <= smoothed.min() and smoothed.max() <= noisy.max(), "a convex average: no overshoot"
    # obtuse triangles (negative cotangents): a spike must not push any neighbour below zero
    n = 8
    xs = np.linspace(0.0, 1.0, n + 1)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    jitter = 0.04 * np.random.default_rng(4).standard_normal(x.size)
    skewed = TriMesh(vertices=np.c_[x.ravel() + jitter, 0.3 * y.ravel(), np.zeros(x.size)], faces=grid_triangles(n, n))
    spikes = np.stack([smooth_scalar(skewed, np.eye(skewed.n_vertices)[k], 1, laplacian="cotangent")
                       for k in range(skewed.n_vertices)])
    assert spikes.min() >= 0.0


def test_bad_settings_are_input_errors():
    with pytest.raises(InputError, match="D"):
        FieldSettings(max_size_ratio=0.5)
    with pytest.raises(InputError, match="A"):
        FieldSettings(max_aspect=0.9)
    with pytest.raises(InputError, match="size_map"):
        FieldSettings(size_map="cubic")
    with pytest.raises(InputError, match="iterations"):
        FieldSettings(smoothing_iterations=-1)
    with pytest.raises(InputError, match="normal"):
        FieldSettings(symmetry_planes=(((0, 0, 0), (0, 0, 0)),))
    with pytest.raises(InputError, match="two"):
        FieldSettings(symmetry_planes=(((0, 0, 0), (1, 0, 0)),) * 3)
    with pytest.raises(InputError, match="opposite"):
        FieldSettings(opposite_sign_anisotropy=0.5)
    assert FieldSettings(anisotropy_map="linear").anisotropy_map is AnisotropyMap.LINEAR
    mesh = _flat_square(4)
    with pytest.raises(InputError, match="membrane forces"):
        guiding_field(mesh, np.zeros((3, 3, 3)), FieldSettings())


from .conftest import SURFACES  # noqa: E402  (GRIDSHELL_SURFACES or ../shared/data/surfaces)


@pytest.mark.skipif(not (SURFACES / "Shell.ply").is_file(), reason="real surfaces not available")
def test_real_surface_field_keeps_D_and_A():
    """A real roof (thesis dataset Shell.ply) with a synthetic gravity-like force field: compression
    along the steepest descent, larger low down. The bounds hold and the directions are unit tangents."""
    from workflow.surface_io import read_surface

    vertices, faces, _ = read_surface(SURFACES / "Shell.ply")
    mesh = TriMesh(vertices=vertices, faces=faces)
    normals = mesh.vertex_normals
    descent = np.array([0.0, 0.0, -1.0]) - normals[:, 2:3] * -normals  # -z projected on the tangent plane
    descent = np.where(np.linalg.norm(descent, axis=1)[:, None] > 1e-6, descent, [[1.0, 0.0, 0.0]])
    z = mesh.vertices[:, 2]
    n1 = -(1.0 + 9.0 * (z.max() - z) / np.ptp(z))
    field = guiding_field(mesh, _tensors(n1, 0.2 * n1, descent, normals), FieldSettings(max_size_ratio=2.5))
    assert field.size.max() / field.size.min() == pytest.approx(2.5, rel=1e-9)
    assert 1.0 <= field.anisotropy.min() and field.anisotropy.max() <= 2.0 + 1e-12
    assert np.allclose(np.linalg.norm(field.direction, axis=1), 1.0)
    assert np.abs(np.einsum("ni,ni->n", field.direction, normals)).max() < 1e-9
    assert field.size[z < np.percentile(z, 10)].mean() < field.size[z > np.percentile(z, 90)].mean()


def _png_size(path: Path) -> tuple[int, int]:
    import matplotlib.image

    image = matplotlib.image.imread(path)
    return image.shape[1], image.shape[0]


def test_plots_write_pngs_that_read_back(tmp_path):
    pytest.importorskip("matplotlib")
    from workflow.plots.field import plot_field
    from workflow.plots.shell import plot_principal_forces

    mesh = vault(divisions=8)
    v = mesh.vertices
    tangent = np.c_[np.zeros(len(v)), np.ones(len(v)), np.zeros(len(v))]
    tensors = _tensors(-(1.0 + v[:, 0] ** 2), 0.3 * np.ones(len(v)), tangent, mesh.vertex_normals)
    field = guiding_field(mesh, tensors, FieldSettings())
    path = plot_field(mesh, field, tmp_path / "field.png", title="vault")
    assert path.stat().st_size > 1000
    face_tensors = tensors[mesh.faces].mean(axis=1)
    values, directions = principal_forces(face_tensors, mesh.face_normals)
    forces = plot_principal_forces(mesh, values, directions, tmp_path / "forces.png",
                                   support_nodes=np.flatnonzero(np.isclose(np.abs(v[:, 1]), np.abs(v[:, 1]).max())))
    assert forces.stat().st_size > 1000
    # the figures are 13 x 5.8 in and 9 x 8 in at 150 dpi
    assert _png_size(path) == (1950, 870)
    assert _png_size(forces) == (1350, 1200)
    assert not list(tmp_path.glob("*.tmp*")), "atomic saving leaves no temporary file"


def _compression_along_x(mesh: TriMesh) -> np.ndarray:
    """N1 = -10 along x, N2 = -2 along y: cells of aspect sqrt(5), capped at A, along x."""
    n = mesh.n_vertices
    return _tensors(np.full(n, -10.0), np.full(n, -2.0), np.tile([1.0, 0.0, 0.0], (n, 1)), mesh.vertex_normals)


def test_across_turns_the_direction_by_ninety_degrees_and_keeps_size_and_aspect():
    mesh = vault()
    x = mesh.vertices[:, 0]
    tensors = _tensors(-(1.0 + x - x.min()), np.full(mesh.n_vertices, -0.2), np.tile([1.0, 0.0, 0.0],
                       (mesh.n_vertices, 1)), mesh.vertex_normals)
    along = guiding_field(mesh, tensors, FieldSettings())
    across = guiding_field(mesh, tensors, FieldSettings(orientation=Orientation.ACROSS))
    assert FieldSettings().orientation is Orientation.ALONG
    assert np.array_equal(along.size, across.size) and np.array_equal(along.anisotropy, across.anisotropy)
    assert np.allclose(np.einsum("ni,ni->n", along.direction, across.direction), 0.0)
    assert np.allclose(np.einsum("ni,ni->n", across.direction, across.normals), 0.0, atol=1e-12)
    assert np.allclose(np.linalg.norm(across.direction, axis=1), 1.0)
    with pytest.raises(InputError, match="orientation must be one of"):
        FieldSettings(orientation="sideways")


@pytest.mark.parametrize("orientation, long_axis", [("along", 0), ("across", 1)])
def test_remeshed_cells_are_long_along_the_stress_or_across_it(orientation, long_axis):
    from engine.remeshing.voronoi import RemeshSettings, remesh

    mesh = _flat_square()
    field = guiding_field(mesh, _compression_along_x(mesh), FieldSettings(orientation=orientation))
    grid = remesh(mesh, field, RemeshSettings(n_cells=60)).polymesh
    interior = [f for f, edge in zip(grid.faces, grid.face_boundary) if not edge]
    # each cell's long axis: the first principal axis of its nodes
    axes = np.array([np.linalg.svd(grid.nodes[f] - grid.nodes[f].mean(axis=0))[2][0] for f in interior])
    stretch = np.array([np.divide(*np.linalg.svd(grid.nodes[f] - grid.nodes[f].mean(axis=0))[1][:2])
                        for f in interior])
    assert len(interior) >= 15 and np.median(stretch) > 1.3
    assert np.mean(np.abs(axes[:, long_axis]) > np.cos(np.radians(30))) > 0.8
