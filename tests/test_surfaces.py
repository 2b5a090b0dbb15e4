"""Surface reading, cleaning and checking; the parametric templates; force-density form-finding."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from engine.errors import InputError, MeshError
from engine.geometry import parametric
from engine.geometry.form_finding import force_density
from engine.geometry.surfaces import clean_mesh
from workflow.surface_io import read_surface, write_surface_ply

from .conftest import real_surfaces


def _red_vertices(path) -> int:
    """Independent count of pure red vertices: the PLY text itself, or numpy's reading of a
    binary little-endian PLY's vertex records."""
    data = path.read_bytes()
    end = data.index(b"end_header") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    n_vertices = int(next(l for l in header if l.startswith("element vertex")).split()[-1])
    vertex_props, element = [], None
    for line in header:
        if line.startswith("element"):
            element = line.split()[1]
        elif line.startswith("property") and element == "vertex":
            vertex_props.append(line.split()[1:])
    names = [p[-1] for p in vertex_props]
    if "format ascii" in header[1]:
        body = [l.split() for l in data[end:].decode("ascii").splitlines()[:n_vertices]]
        rgb = np.array([[row[names.index(c)] for c in ("red", "green", "blue")] for row in body], dtype=float)
    else:
        assert "binary_little_endian" in header[1]
        kinds = {"float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8", "uchar": "u1", "uint8": "u1",
                 "int": "<i4", "int32": "<i4", "uint": "<u4", "short": "<i2", "ushort": "<u2", "char": "i1"}
        dtype = np.dtype([(p[-1], kinds[p[0]]) for p in vertex_props])
        records = np.frombuffer(data, dtype=dtype, count=n_vertices, offset=end)
        rgb = np.stack([records[c].astype(float) for c in ("red", "green", "blue")], axis=1)
    return int(np.sum(np.all(rgb == [255, 0, 0], axis=1)))


@pytest.mark.parametrize("path", real_surfaces())
def test_real_surfaces_load_clean_with_their_flagged_supports(path):
    vertices, faces, flagged = read_surface(path)
    red = _red_vertices(path)
    assert flagged.sum() == red > 0
    mesh, report = clean_mesh(vertices, faces, flagged, name=path.stem)
    assert mesh.flagged.sum() == red
    assert mesh.to_trimesh().is_winding_consistent
    assert (mesh.face_normals[:, 2].mean()) > 0  # normals up
    assert len(mesh.boundary_loops) >= 1


def test_duplicate_vertices_are_merged(square_grid):
    vertices, faces = square_grid
    split_vertices = vertices[faces].reshape(-1, 3)  # every face with its own corners
    split_faces = np.arange(len(split_vertices)).reshape(-1, 3)
    mesh, report = clean_mesh(split_vertices, split_faces)
    assert mesh.n_vertices == len(vertices)
    assert report.merged_vertices == len(split_vertices) - len(vertices)
    assert mesh.area == pytest.approx(1.0)


def test_degenerate_and_duplicate_faces_are_dropped(square_grid):
    vertices, faces = square_grid
    vertices = np.vstack([vertices, [[0.5, 0.5, 0.0]]])  # a copy of an existing grid vertex
    faces = np.vstack([faces, [[0, 0, 1]], [[0, 1, 2]], faces[:3]])  # repeated index, collinear, duplicates
    mesh, report = clean_mesh(vertices, faces)
    assert report.degenerate_faces == 2 and report.duplicate_faces == 3
    assert mesh.n_faces == len(square_grid[1])


def test_inconsistent_orientation_is_fixed_with_normals_up(square_grid):
    vertices, faces = square_grid
    faces = faces.copy()
    faces[::3] = faces[::3, ::-1]
    mesh, report = clean_mesh(vertices, faces)
    assert report.flipped_faces > 0
    assert np.allclose(mesh.face_normals, [0, 0, 1])


def test_orientation_is_made_consistent_on_a_winding_surface_and_a_moebius_band_refused():
    """A helical strip (a long breadth-first walk) with a third of its faces wound back comes out with
    every inner edge run both ways; the same strip closed with a half twist has no two sides."""
    turns, n = 3, 240
    t = np.linspace(0, 2 * np.pi * turns, n + 1)
    rows = [np.c_[(10 + w) * np.cos(t), (10 + w) * np.sin(t), 0.5 * t] for w in (-1.0, 1.0)]
    vertices = np.vstack(rows)
    a, b = np.arange(n), np.arange(n) + 1
    faces = np.r_[np.c_[a, b, b + n + 1], np.c_[a, b + n + 1, a + n + 1]]
    faces[::3] = faces[::3, ::-1]
    mesh, report = clean_mesh(vertices, faces)
    assert report.flipped_faces > 0
    directed = np.stack([mesh.faces, np.roll(mesh.faces, -1, axis=1)], axis=-1).reshape(-1, 2)
    assert len(np.unique(directed, axis=0)) == len(directed)  # no edge run the same way twice

    u = np.linspace(0, 2 * np.pi, 61)[:-1]
    band = np.vstack([np.c_[(5 + w * np.cos(u / 2)) * np.cos(u), (5 + w * np.cos(u / 2)) * np.sin(u),
                            w * np.sin(u / 2)] for w in (-1.0, 1.0)])
    i = np.arange(60)
    j = (i + 1) % 60
    top, bottom = i, i + 60
    top_next = np.where(j == 0, 60, j)  # the half twist: the last edge joins the other row
    bottom_next = np.where(j == 0, 0, j + 60)
    moebius = np.r_[np.c_[top, top_next, bottom_next], np.c_[top, bottom_next, bottom]]
    with pytest.raises(MeshError, match="not orientable"):
        clean_mesh(band, moebius)


def test_non_manifold_edge_is_reported_with_its_place(square_grid):
    vertices, faces = square_grid
    vertices = np.vstack([vertices, [[0.06, 0.06, 0.5]]])
    a, b = faces[0][1:]  # an interior edge, already shared by two faces
    faces = np.vstack([faces, [[a, b, len(vertices) - 1]]])
    with pytest.raises(MeshError, match="non-manifold edge") as info:
        clean_mesh(vertices, faces)
    assert "at (" in str(info.value) and info.value.hint


def test_nan_is_reported_with_vertex_ids(square_grid):
    vertices, faces = square_grid
    vertices = vertices.copy()
    vertices[5, 2] = np.nan
    with pytest.raises(MeshError, match=r"NaN.*\[5\]"):
        clean_mesh(vertices, faces)


def test_closed_surface_and_handles_are_rejected():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    with pytest.raises(MeshError, match="closed"):
        clean_mesh(sphere.vertices, sphere.faces)
    torus = trimesh.creation.torus(major_radius=2.0, minor_radius=0.5)
    cut = torus.faces[~(torus.faces == 0).any(axis=1)]  # removing one vertex's star opens it; the handle stays
    with pytest.raises(MeshError, match="handle"):
        clean_mesh(torus.vertices, cut)


def test_pinched_vertex_is_rejected():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [-1, 0, 0], [-1, -1, 0.0]])
    faces = np.array([[0, 1, 2], [0, 3, 4]])
    with pytest.raises(MeshError, match="non-manifold vertex"):
        clean_mesh(vertices, faces)


def test_holes_and_several_patches_are_accepted():
    mesh = parametric.courtyard()
    assert len(mesh.boundary_loops) == 2
    other = parametric.hypar(divisions=4)
    vertices = np.vstack([mesh.vertices, other.vertices + [100, 0, 0]])
    faces = np.vstack([mesh.faces, other.faces + mesh.n_vertices])
    joined, report = clean_mesh(vertices, faces)
    assert report.patches == 2 and report.boundary_loops == 3


def test_a_stray_piece_is_removed_and_noted():
    """A leftover triangle floating over the roof (and flagged) goes, with its vertices and flag; the
    roof's faces, flags and area stay, and the notes say where the stray was."""
    roof = parametric.hypar(divisions=8)
    stray = np.array([[0.0, 0.0, 10.0], [0.1, 0.0, 10.0], [0.0, 0.1, 10.0]])
    vertices = np.vstack([roof.vertices, stray])
    faces = np.vstack([roof.faces, roof.n_vertices + np.array([[0, 1, 2]])])
    flagged = np.r_[np.arange(roof.n_vertices) < 3, True, True, True]
    clean, report = clean_mesh(vertices, faces, flagged)
    assert report.stray_pieces == 1 and report.patches == 1
    assert clean.n_faces == roof.n_faces and clean.n_vertices == roof.n_vertices
    assert clean.area == pytest.approx(roof.area, rel=1e-12)
    assert clean.flagged.sum() == 3
    assert any("stray" in note and "10.000" in note for note in report.notes)


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl", ".off"])
def test_mesh_formats_round_trip(tmp_path, suffix):
    source = parametric.hypar(divisions=6)
    path = tmp_path / f"roof{suffix}"
    source.to_trimesh().export(path)
    vertices, faces, _ = read_surface(path)
    mesh, _ = clean_mesh(vertices, faces)
    assert mesh.n_faces == source.n_faces and mesh.area == pytest.approx(source.area)


def test_rhino_3dm_mesh_is_read_in_metres(tmp_path):
    rhino3dm = pytest.importorskip("rhino3dm")
    source = parametric.hypar(divisions=4)
    model = rhino3dm.File3dm()
    model.Settings.ModelUnitSystem = rhino3dm.UnitSystem.Millimeters
    rmesh = rhino3dm.Mesh()
    for x, y, z in source.vertices * 1000:
        rmesh.Vertices.Add(float(x), float(y), float(z))
    for a, b, c in source.faces:
        rmesh.Faces.AddFace(int(a), int(b), int(c))
    model.Objects.AddMesh(rmesh)
    path = tmp_path / "roof.3dm"
    model.Write(str(path), 7)
    vertices, faces, _ = read_surface(path)
    mesh, _ = clean_mesh(vertices, faces)
    assert mesh.area == pytest.approx(source.area, rel=1e-6)


def _rhino_file(path, mesh, unit_system, scale):
    """``mesh`` written as a .3dm with ``unit_system``, its coordinates times ``scale``."""
    import rhino3dm

    model = rhino3dm.File3dm()
    model.Settings.ModelUnitSystem = unit_system
    rmesh = rhino3dm.Mesh()
    for x, y, z in mesh.vertices * scale:
        rmesh.Vertices.Add(float(x), float(y), float(z))
    for a, b, c in mesh.faces:
        rmesh.Faces.AddFace(int(a), int(b), int(c))
    model.Objects.AddMesh(rmesh)
    model.Write(str(path), 7)
    return path


@pytest.mark.parametrize("unit, per_metre", [("Feet", 1 / 0.3048), ("Inches", 1 / 0.0254), ("Meters", 1.0)])
def test_a_rhino_file_is_read_in_its_own_units_whatever_file_units_says(tmp_path, unit, per_metre):
    """A roof drawn in feet (or inches) in Rhino comes in at its size in metres, before and whatever
    [surface] file_units says: the .3dm states its unit (it was read as metres, 3.3 times too big)."""
    rhino3dm = pytest.importorskip("rhino3dm")
    from workflow.config import load_project
    from workflow.stages.surface import build_surface

    source = parametric.hypar(divisions=4)
    _rhino_file(tmp_path / "roof.3dm", source, getattr(rhino3dm.UnitSystem, unit), per_metre)
    (tmp_path / "p.toml").write_text('[surface]\nfile = "roof.3dm"\nfile_units = "mm"\n')
    mesh, info = build_surface(load_project(tmp_path / "p.toml"))
    assert mesh.area == pytest.approx(source.area, rel=1e-6)  # a Rhino mesh's vertices are single precision
    assert info["units_from"] == "the file"


def test_a_rhino_file_of_an_implausible_size_names_its_own_units(tmp_path, capsys):
    """A .3dm saved in millimetres with the roof's numbers in metres is 16 mm across: the message
    says that the file's units are used, not --surface-units, and no traceback."""
    rhino3dm = pytest.importorskip("rhino3dm")
    from workflow.cli import main

    path = _rhino_file(tmp_path / "roof.3dm", parametric.hypar(divisions=4), rhino3dm.UnitSystem.Millimeters, 1.0)
    code = main(["run", "--surface", str(path), "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "the .3dm file's own units (mm)" in err and "_Units" in err and "Traceback" not in err


def test_written_ply_keeps_flags(tmp_path):
    mesh = parametric.hypar(divisions=4)
    flagged = np.zeros(mesh.n_vertices, dtype=bool)
    flagged[[0, 3, 7]] = True
    from engine.mesh import TriMesh

    write_surface_ply(TriMesh(vertices=mesh.vertices, faces=mesh.faces, flagged=flagged), tmp_path / "s.ply")
    _, _, read_flags = read_surface(tmp_path / "s.ply")
    assert np.flatnonzero(read_flags).tolist() == [0, 3, 7]


def test_unreadable_inputs_are_input_errors(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        read_surface(tmp_path / "none.obj")
    (tmp_path / "roof.dwg").write_text("x")
    with pytest.raises(InputError, match="unknown format"):
        read_surface(tmp_path / "roof.dwg")
    (tmp_path / "empty.obj").write_text("# nothing\n")
    with pytest.raises(InputError):
        read_surface(tmp_path / "empty.obj")


def test_force_density_single_node_closed_form():
    """One free node hung from four corners: 4 q z = P."""
    nodes = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0], [0.3, 0.2, 5.0]])
    edges = np.array([[0, 4], [1, 4], [2, 4], [3, 4]])
    loads = np.zeros((5, 3))
    loads[4, 2] = 10.0
    result = force_density(nodes, edges, 2.0, loads, np.array([1, 1, 1, 1, 0], dtype=bool))
    assert result.nodes[4] == pytest.approx([0, 0, 10.0 / (4 * 2.0)])


def test_mockup_form_finding_is_in_equilibrium():
    made = parametric.mockup()
    assert made.form_finding.residual < 1e-6
    assert made.mesh.vertices[:, 2].max() == pytest.approx(0.45)
    lo, hi = made.mesh.bounds
    assert hi[:2] - lo[:2] == pytest.approx([2.4, 2.4])
    # independent check: the vertical forces of all edges at the crown node balance its load
    ff = made.form_finding
    crown = int(np.argmax(ff.nodes[:, 2]))
    neighbours = np.flatnonzero(np.isclose(np.linalg.norm(ff.nodes[:, :2] - ff.nodes[crown, :2], axis=1), 0.1))
    vertical = made.force_density * (ff.nodes[neighbours, 2] - ff.nodes[crown, 2]).sum()
    assert vertical + made.applied_load / 23**2 == pytest.approx(0.0, abs=1e-6 * made.applied_load)


@pytest.mark.parametrize("name", ["cap", "vault", "hypar", "courtyard"])
def test_templates_are_valid_open_surfaces(name):
    mesh = getattr(parametric, name)()
    assert mesh.to_trimesh().is_winding_consistent
    assert (mesh.face_normals[:, 2] > 0).mean() > 0.5


def test_cap_span_to_rise():
    mesh = parametric.cap(span=20.0, span_to_rise=21.43)
    assert 20.0 / np.ptp(mesh.vertices[:, 2]) == pytest.approx(21.43, rel=1e-3)


def test_bad_template_parameters():
    with pytest.raises(InputError, match="span"):
        parametric.cap(span=-1)
    with pytest.raises(InputError, match="divisions"):
        parametric.mockup(divisions=5)
    for name in ("mockup", "cap", "vault", "hypar", "courtyard"):  # inf passed "> 0" and reached Delaunay as NaN
        with pytest.raises(InputError, match="rise.*positive and finite"):
            getattr(parametric, name)(rise=float("inf")) if name != "cap" else parametric.cap(span_to_rise=np.inf)


@pytest.mark.parametrize("name, fine", [("mockup", {"divisions": 1000}), ("cap", {"rings": 400}),
                                        ("vault", {"divisions": 1000}), ("vault", {"length": 1e9}),
                                        ("hypar", {"divisions": 1000}), ("courtyard", {"divisions": 1000})])
def test_a_template_refuses_parameters_that_would_fill_the_memory(name, fine):
    """A mistyped parameter (divisions = 1_000, a length of 1e9 m) is refused by the triangle count it
    would build, before any array is made: the refusal names the parameter and the count, which is
    the mesh's own (2 per grid bay, 6 k per cap ring k summed)."""
    with pytest.raises(InputError, match=f"{next(iter(fine))}.*triangles") as refused:
        getattr(parametric, name)(**fine)
    assert refused.value.hint.startswith("lower surface.parameters.")
    # just under the bound the same template builds, with the count the check predicted
    assert len(parametric.hypar(divisions=316).faces) == 2 * 316**2 <= parametric.MAX_TEMPLATE_TRIANGLES
    assert len(parametric.cap(rings=20).faces) == 6 * 20**2
