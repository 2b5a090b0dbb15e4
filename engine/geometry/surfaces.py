"""Surface preparation: cleaning and checking of input meshes.

``clean_mesh`` turns raw arrays (from any reader) into a valid ``TriMesh``: it merges
duplicate vertices, drops degenerate and duplicate faces and unused vertices, orients
every patch consistently with its normals up (or outward for steep patches), and checks
that the result is manifold, free of NaN, and made of one or more disk-like patches
(holes allowed). Each problem raises ``MeshError`` saying where it is and what to do.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..errors import MeshError
from ..mesh import TriMesh, boundary_loops, unique_edges, unique_rows
from .seams import SEAM_SAG, join_seams

__all__ = ["CleanReport", "clean_mesh", "UP_AXES", "to_z_up", "normal_shares"]

UP_AXES = ("z", "y", "x", "-z", "-y", "-x")
"""The axes a mesh file may have modelled as up (Rhino: z; Blender, SketchUp and glTF exports: y)."""

# proper rotations taking each axis to +z: new (x, y, z) = old coordinates picked and signed
_TO_Z_UP = {"z": ((0, 1), (1, 1), (2, 1)), "y": ((0, 1), (2, -1), (1, 1)), "x": ((2, -1), (1, 1), (0, 1)),
            "-z": ((0, 1), (1, -1), (2, -1)), "-y": ((0, 1), (2, 1), (1, -1)), "-x": ((2, 1), (1, 1), (0, -1))}


def to_z_up(vertices: np.ndarray, up: str) -> np.ndarray:
    """The vertices (n, 3) of a mesh modelled with ``up`` (one of UP_AXES) as up, rotated so that it
    points along +z (a rotation: lengths, areas and handedness are kept). Vertices that are not
    (n, 3) come back as they are, for clean_mesh to report."""
    try:
        picks = _TO_Z_UP[up]
    except KeyError:
        raise ValueError(f"up axis {up!r}: allowed are {', '.join(UP_AXES)}") from None
    vertices = np.asarray(vertices, dtype=float)
    if up == "z" or vertices.ndim != 2 or vertices.shape[1:] != (3,):
        return vertices
    return np.stack([sign * vertices[:, axis] for axis, sign in picks], axis=1)


def normal_shares(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted mean of |n . e_x|, |n . e_y|, |n . e_z| over the triangles: (3,), each in [0, 1].
    A roof modelled with z up has its largest share on z; a hemisphere has 0.5 on z and 0.25 on x
    and y; a mesh exported with y up has it on y."""
    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    cross = cross[np.isfinite(cross).all(axis=1)]
    total = np.linalg.norm(cross, axis=1).sum()
    if not total > 0:
        return np.zeros(3)
    return np.abs(cross).sum(axis=0) / total



@dataclass(kw_only=True)
class CleanReport:
    """What ``clean_mesh`` changed; every count is zero for an already clean mesh."""

    merged_vertices: int = 0
    degenerate_faces: int = 0
    duplicate_faces: int = 0
    unused_vertices: int = 0
    flipped_faces: int = 0
    stray_pieces: int = 0
    welded_vertices: int = 0
    stitched_vertices: int = 0
    patches: int = 0
    boundary_loops: int = 0
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> dict:
        return dict(self.__dict__)


def _where(points: np.ndarray) -> str:
    shown = ", ".join("(" + ", ".join(f"{c:.3f}" for c in p) + ")" for p in points[:3])
    more = f" and {len(points) - 3} more" if len(points) > 3 else ""
    return f"at {shown}{more}"


#: A connected piece of the surface under this share of its largest piece's area is a stray (a
#: leftover triangle or strip of an export): it is removed, and the cleaning notes say where.
STRAY_SHARE = 0.01


def _without_strays(faces: np.ndarray, patch: np.ndarray,
                    vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[tuple[int, np.ndarray]]]:
    """(faces, patch labels, [(face count, centre) of each stray removed]): ``faces`` less the pieces
    (``patch`` labels) under STRAY_SHARE of the largest piece's area, labels renumbered."""
    corners = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    per_patch = np.bincount(patch, weights=area)
    stray = per_patch < STRAY_SHARE * per_patch.max()
    if not stray.any():
        return faces, patch, []
    removed = [(int(np.sum(patch == p)), corners[patch == p].reshape(-1, 3).mean(axis=0))
               for p in np.flatnonzero(stray)]
    keep = ~stray[patch]
    return faces[keep], (np.cumsum(~stray) - 1)[patch[keep]], removed


def _used_only(vertices: np.ndarray, flagged: np.ndarray,
               faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, flags, faces) without the vertices no face uses, the faces renumbered."""
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    return vertices[used], flagged[used], (np.cumsum(used) - 1)[faces]


def _merge_duplicates(vertices: np.ndarray, tolerance: float) -> np.ndarray:
    """Representative index per vertex: vertices closer than ``tolerance`` share one."""
    pairs = cKDTree(vertices).query_pairs(tolerance, output_type="ndarray")
    n = len(vertices)
    if len(pairs) == 0:
        return np.arange(n)
    graph = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    first = np.full(labels.max() + 1, n)
    np.minimum.at(first, labels, np.arange(n))
    return first[labels]


def _orientation_flips(m: int, fa: np.ndarray, fb: np.ndarray, same: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """(flip per face, patch label per face, patch count) of m faces whose pairs (fa, fb) share an edge,
    ``same`` where both run it the same way (so exactly one of them must flip). Each patch is walked
    breadth-first from its first face; a face's flip is the parity of ``same`` along its tree path,
    found by pointer jumping (a vectorised pass per doubling of the path, not a loop per face)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import breadth_first_order, connected_components

    graph = sp.csr_matrix((np.r_[same, same].astype(np.int8) + 1, (np.r_[fa, fb], np.r_[fb, fa])), shape=(m, m))
    n_labels, label = connected_components(graph, directed=False)
    parent = np.arange(m)
    for root in np.unique(label, return_index=True)[1]:
        order, predecessors = breadth_first_order(graph, root, directed=False, return_predecessors=True)
        parent[order[1:]] = predecessors[order[1:]]
    children = np.flatnonzero(parent != np.arange(m))
    parity = np.zeros(m, dtype=bool)
    if len(children):
        parity[children] = np.asarray(graph[children, parent[children]]).ravel() == 2
    while np.any(parent[parent] != parent):
        parity ^= parity[parent]
        parent = parent[parent]
    return parity, label, int(n_labels)


def _orient(faces: np.ndarray, vertices: np.ndarray) -> tuple[np.ndarray, int, np.ndarray]:
    """Consistent orientation per connected patch; returns (faces, n_flipped, patch label per face)."""
    m = len(faces)
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2)
    key = np.sort(directed, axis=1)
    _, edge_id = unique_rows(key, return_inverse=True)
    edge_id = edge_id.ravel()
    owner = np.repeat(np.arange(m), 3)
    order = np.argsort(edge_id, kind="stable")
    sorted_edges = edge_id[order]
    starts = np.flatnonzero(np.r_[True, sorted_edges[1:] != sorted_edges[:-1]])
    counts = np.diff(np.r_[starts, len(sorted_edges)])
    pair_starts = starts[counts == 2]
    a, b = order[pair_starts], order[pair_starts + 1]
    fa, fb = owner[a], owner[b]
    same_direction = directed[a, 0] == directed[b, 0]

    flip, label, n_labels = _orientation_flips(m, fa, fb, same_direction)
    wrong = np.flatnonzero(flip[fa] ^ same_direction != flip[fb])
    if len(wrong):
        f = int(fa[wrong[0]])
        raise MeshError(f"the surface is not orientable (a Moebius-like band) near face {f} "
                        f"{_where(vertices[faces[f]].mean(axis=0, keepdims=True))}",
                        hint="a grid-shell surface needs two sides; remodel this part of the surface")
    faces = faces.copy()
    faces[flip] = faces[flip][:, ::-1]

    # one orientation choice per patch: normals up, or outward where the patch is steep
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = np.linalg.norm(cross, axis=1)
    flip_patch = np.zeros(n_labels, dtype=bool)
    for p in range(n_labels):
        sel = label == p
        up = cross[sel, 2].sum() / max(area[sel].sum(), 1e-300)
        if abs(up) > 0.05:
            flip_patch[p] = up < 0
        else:
            centre = corners[sel].mean(axis=(0, 1))
            out = np.einsum("ij,ij->", cross[sel], corners[sel].mean(axis=1) - centre)
            flip_patch[p] = out < 0
    patch_flip = flip_patch[label]
    faces[patch_flip] = faces[patch_flip][:, ::-1]
    return faces, int(np.count_nonzero(flip ^ patch_flip)), label


def clean_mesh(vertices: np.ndarray, faces: np.ndarray, flagged: np.ndarray | None = None, *,
               name: str = "surface", merge_tolerance: float | None = None) -> tuple[TriMesh, CleanReport]:
    """Clean and check a raw triangle mesh; returns the clean ``TriMesh`` and what changed.

    vertices: (n, 3) m; faces: (m, 3) vertex ids; flagged: (n,) bool support flags,
    carried through merging (a merged vertex is flagged if any of its copies was).
    merge_tolerance: distance (m) under which vertices merge; default 1e-7 of the
    bounding-box diagonal. Raises ``MeshError`` naming the problem, where it is, and the fix.
    """
    report = CleanReport()
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) < 3:
        raise MeshError(f"{name}: needs at least 3 vertices with x, y, z; got an array of shape {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise MeshError(f"{name}: needs triangular faces; got an array of shape {faces.shape}",
                        hint="triangulate the surface in your modeller before export")
    faces = faces.astype(np.int64)
    flagged = np.zeros(len(vertices), dtype=bool) if flagged is None else np.asarray(flagged, dtype=bool)

    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        ids = np.flatnonzero(bad)
        raise MeshError(f"{name}: {len(ids)} vertex(es) have NaN or infinite coordinates (vertex ids "
                        f"{ids[:10].tolist()}{' ...' if len(ids) > 10 else ''})",
                        hint="re-export the surface; delete or repair those vertices in your modeller")
    if faces.min() < 0 or faces.max() >= len(vertices):
        bad_faces = np.flatnonzero((faces < 0).any(axis=1) | (faces >= len(vertices)).any(axis=1))
        raise MeshError(f"{name}: faces {bad_faces[:10].tolist()} refer to vertices that do not exist "
                        f"(the file has {len(vertices)} vertices)",
                        hint="the file is truncated or corrupt; re-export it")

    diagonal = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    if diagonal == 0:
        raise MeshError(f"{name}: all vertices are at one point")
    tolerance = 1e-7 * diagonal if merge_tolerance is None else merge_tolerance

    representative = _merge_duplicates(vertices, tolerance)
    report.merged_vertices = int(np.count_nonzero(representative != np.arange(len(vertices))))
    merged_flags = np.zeros(len(vertices), dtype=bool)
    np.logical_or.at(merged_flags, representative, flagged)
    faces = representative[faces]

    corners = vertices[faces]
    twice_area = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    degenerate = repeated | (twice_area <= 1e-12 * diagonal**2)
    report.degenerate_faces = int(degenerate.sum())
    faces = faces[~degenerate]

    _, keep = unique_rows(np.sort(faces, axis=1), return_index=True)
    report.duplicate_faces = len(faces) - len(keep)
    faces = faces[np.sort(keep)]
    if len(faces) == 0:
        raise MeshError(f"{name}: no valid face is left after removing degenerate ones")

    vertices, faces, joined, welded, stitched = join_seams(vertices, faces)
    if welded:
        report.welded_vertices = welded
        np.logical_or.at(merged_flags, joined, merged_flags.copy())
        representative = joined[representative]
        report.notes.append(f"{welded} vertex(es) of seams left open between parts welded to the other side, each "
                            f"closer to it than {100 * SEAM_SAG:g} % of its edges' length")
    if stitched:
        report.stitched_vertices = stitched
        merged_flags = np.r_[merged_flags, np.zeros(len(vertices) - len(merged_flags), dtype=bool)]
        representative = np.r_[representative, np.arange(len(representative), len(vertices))]
        report.notes.append(f"{stitched} vertex(es) of seams between separately meshed parts stitched (T-junctions: "
                            f"a vertex of one part on an edge of the other)")

    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    report.unused_vertices = int(np.count_nonzero(~used & (representative == np.arange(len(vertices)))))
    vertices, flagged, faces = _used_only(vertices, merged_flags, faces)

    key = np.sort(np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1)
    edges, counts = unique_rows(key, return_counts=True)
    if (counts > 2).any():
        over = edges[counts > 2]
        raise MeshError(f"{name}: {len(over)} non-manifold edge(s), shared by more than two faces, "
                        f"{_where(vertices[over].mean(axis=1))}",
                        hint="a grid-shell surface must be a manifold sheet: delete the extra faces "
                             "(fins, double layers) at those points")

    faces, report.flipped_faces, patch = _orient(faces, vertices)
    faces, patch, stray = _without_strays(faces, patch, vertices)
    if len(stray):
        report.stray_pieces = len(stray)
        report.notes.append(f"{len(stray)} stray piece(s) of {int(sum(n for n, _ in stray))} face(s) removed, each "
                            f"under {100 * STRAY_SHARE:g} % of the surface's largest piece "
                            f"{_where(np.array([c for _, c in stray]))}")
        vertices, flagged, faces = _used_only(vertices, flagged, faces)
        edges = unique_edges(faces)

    faces_per_vertex = np.bincount(faces.ravel(), minlength=len(vertices))
    edges_per_vertex = np.bincount(edges.ravel(), minlength=len(vertices))
    pinched = np.flatnonzero(edges_per_vertex - faces_per_vertex > 1)
    if len(pinched):
        raise MeshError(f"{name}: {len(pinched)} non-manifold vertex(es) where separate parts touch at one "
                        f"point {_where(vertices[pinched])}",
                        hint="separate the parts or join them along an edge")

    loops = boundary_loops(faces)
    report.patches = int(patch.max() + 1)
    report.boundary_loops = len(loops)
    loop_patch = [patch[np.flatnonzero((faces == loop[0]).any(axis=1))[0]] for loop in loops]
    for p in range(report.patches):
        sel = faces[patch == p]
        vs = np.unique(sel)
        patch_edges = np.stack([sel, np.roll(sel, -1, axis=1)], axis=-1).reshape(-1, 2)
        n_edges = len(unique_rows(np.sort(patch_edges, axis=1)))
        n_loops = sum(1 for lp in loop_patch if lp == p)
        euler = len(vs) - n_edges + len(sel)
        where = _where(vertices[vs].mean(axis=0, keepdims=True))
        if n_loops == 0:
            raise MeshError(f"{name}: patch {p} ({len(sel)} faces, centred {where}) is closed, with no boundary",
                            hint="a grid-shell needs an open surface with an edge to support; "
                                 "cut the closed surface open")
        if euler != 2 - n_loops:
            genus = (2 - n_loops - euler) // 2
            raise MeshError(f"{name}: patch {p} (centred {where}) is not disk-like: it has {genus} handle(s) "
                            f"(Euler characteristic {euler} with {n_loops} boundary loop(s))",
                            hint="holes are fine, handles (tunnels) are not; remodel the surface as a sheet with holes")
    if report.patches > 1:
        report.notes.append(f"{report.patches} separate patches")
    return TriMesh(vertices=vertices, faces=faces, flagged=flagged, name=name), report
