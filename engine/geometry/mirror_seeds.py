"""Mirror-symmetric seeds and clusters of the Voronoi remesher (engine/remeshing/voronoi.py) for one or two
perpendicular symmetry planes: the clustered mesh's mirror maps; the seeds kept in the fundamental
region (on the positive side of every plane), those near a plane moved onto it, and mirrored; the
labels of that region mirrored onto the rest after each clustering; and mirrored pairs of clusters
that follow each other along a plane merged into one cluster on it (docs/decisions.md, issue 13).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .fine_mesh import _Fine
from .symmetry import reflect

__all__ = ["MIRROR_MATCH", "ON_PLANE", "SEED_SNAP", "JUNCTION_ROUNDS"]

#: Two vertices are mirrors of each other when one's image lies within this share of the mean
#: edge length of the surface's mesh (not of its subdivision: subdividing a mesh does not make it
#: more or less symmetric): the clustered mesh must be symmetric for its clusters to be.
MIRROR_MATCH = 0.5
#: A vertex within this share of the mean edge length of a plane is on it.
ON_PLANE = 0.01
#: A seed within this share of the seed spacing of a symmetry plane is moved onto it.
SEED_SNAP = 0.25
#: Rounds of merging consecutive mirrored pairs of clusters along a plane (_merged_pairs) and
#: clustering again, per clustering.
JUNCTION_ROUNDS = 3


@dataclass
class _Mirrors:
    """The clustered mesh's mirror maps through the symmetry planes (perpendicular, one or two):
    per plane each vertex's mirror and whether it is its own (on the plane); for each vertex its
    image in the fundamental region (on the positive side of every plane, a plane's vertices
    included) and through which planes it gets there. Also what every clustering step reuses: the
    mesh's mean edge length and centroid, and per plane the region's vertices on it (with their
    k-d tree) and the mesh edges within one mean edge of it."""

    planes: tuple
    maps: list
    fixed: list
    sides: list
    flips: list
    image: np.ndarray
    edge: float = 0.0
    centre: np.ndarray | None = None
    on: list = field(default_factory=list)
    on_trees: list = field(default_factory=list)
    near_edges: list = field(default_factory=list)
    nearest_on: dict = field(default_factory=dict)   # _nearest_on_planes' vertices and trees


def _nearest_on_planes(fine: _Fine, mirrors: _Mirrors, combination: tuple, points: np.ndarray,
                       in_region: bool = False) -> np.ndarray | None:
    """The vertex nearest each of ``points`` (vertex ids) among those on every plane flagged in
    ``combination`` (``in_region``: and in the fundamental region), or None where there is none;
    the candidates and their k-d tree kept on ``mirrors``."""
    key = (combination, in_region)
    if key not in mirrors.nearest_on:
        on = _on_planes(mirrors, combination)
        if in_region:
            on &= mirrors.image == np.arange(len(fine.vertices))
        candidates = np.flatnonzero(on)
        mirrors.nearest_on[key] = (candidates, cKDTree(fine.vertices[candidates]) if len(candidates) else None)
    candidates, tree = mirrors.nearest_on[key]
    if tree is None:
        return None
    return candidates[tree.query(fine.vertices[points])[1]]


def _on_planes(mirrors: _Mirrors, combination: tuple) -> np.ndarray:
    """(n,) bool: the clustered mesh's vertices on every plane whose flag is set in ``combination``."""
    on = np.ones(len(mirrors.image), dtype=bool)
    for plane, wanted in enumerate(combination):
        if wanted:
            on &= mirrors.fixed[plane]
    return on


def _mirrors(fine: _Fine, planes: tuple) -> _Mirrors | None:
    """The mirror maps of ``fine`` through ``planes``, or None without planes, for planes that are
    not perpendicular, or where the clustered mesh's vertices are not symmetric (MIRROR_MATCH).
    Kept on ``fine`` for its later clusterings."""
    if not planes:
        return None
    if planes not in fine.mirrors:
        fine.mirrors[planes] = _mirror_maps(fine, planes)
    return fine.mirrors[planes]


def _mirror_maps(fine: _Fine, planes: tuple) -> _Mirrors | None:
    normals = [np.asarray(n, dtype=float) / np.linalg.norm(n) for _, n in planes]
    if len(normals) == 2 and abs(float(normals[0] @ normals[1])) > 1e-6:
        return None
    if fine.tree is None:
        fine.tree = cKDTree(fine.vertices)
    x = fine.vertices
    edge = float(np.linalg.norm(x[fine.edges[:, 1]] - x[fine.edges[:, 0]], axis=1).mean())
    # the surface's mean edge: each subdivision quarters the triangles and halves the edges
    surface_edge = edge * max(1.0, float(np.sqrt(len(x) / max(fine.n_surface_vertices, 1))))
    tolerance = MIRROR_MATCH * surface_edge
    every = np.arange(len(x))
    maps, sides = [], []
    for plane, normal in zip(planes, normals):
        distance, mirror = fine.tree.query(reflect(x, plane))
        if distance.max() > tolerance or not np.array_equal(mirror[mirror], every):
            return None
        maps.append(mirror)
        sides.append((x - np.asarray(plane[0], dtype=float)) @ normal)
    image, flips = every, []
    for mirror, side in zip(maps, sides):
        flip = side[image] < -ON_PLANE * edge
        image = np.where(flip, mirror[image], image)
        flips.append(flip)
    fixed = [m == every for m in maps]
    region = image == every
    E = fine.edges
    on = [np.flatnonzero(f & region) for f in fixed]
    return _Mirrors(planes=planes, maps=maps, fixed=fixed, sides=sides, flips=flips, image=image, edge=edge,
                    centre=x.mean(axis=0), on=on, on_trees=[cKDTree(x[o]) if len(o) else None for o in on],
                    near_edges=[np.flatnonzero((np.abs(side[E[:, 0]]) <= edge) & (np.abs(side[E[:, 1]]) <= edge))
                                for side in sides])


def _symmetric_seeds(fine: _Fine, mirrors: _Mirrors, seeds: np.ndarray, lloyd: bool = False
                     ) -> tuple[np.ndarray, list]:
    """(seeds, sigma): the seeds in the fundamental region, those within SEED_SNAP of the seed
    spacing of a plane moved to the nearest vertex on it, and their mirror images; sigma per plane
    maps each seed's index to its mirror's. ``lloyd``: the seeds of a Lloyd step (from symmetric
    centroids), none moved."""
    reps = np.unique(seeds[mirrors.image[seeds] == seeds])
    reach = 0.0 if lloyd else SEED_SNAP * np.sqrt(fine.areas.sum() / max(len(seeds), 1))
    near = np.array([np.abs(side[reps]) < reach for side in mirrors.sides])
    for combination in sorted({tuple(column) for column in near.T if any(column)}):
        chosen = np.flatnonzero(np.all(near.T == combination, axis=1))
        nearest = _nearest_on_planes(fine, mirrors, combination, reps[chosen], in_region=True)
        if nearest is not None:
            reps[chosen] = nearest
    orbit = [np.unique(reps)]
    for mirror in mirrors.maps:
        orbit = orbit + [mirror[o] for o in orbit]
    seeds = np.unique(np.concatenate(orbit))
    return seeds, [np.searchsorted(seeds, mirror[seeds]) for mirror in mirrors.maps]


def _symmetric_clusters(fine: _Fine, mirrors: _Mirrors, seeds: np.ndarray, sigma: list, result,
                        moments: np.ndarray):
    """``result`` (engine.remeshing.clustering.ClusteringResult) with the labels of the fundamental region
    mirrored onto the rest, centroids and energies of the mirrored labels; None where that leaves a
    cluster empty or in pieces. In the region, a cluster whose seed lies outside it gives its
    vertices to its mirror image's (the border of the two is the plane; the vertices on a plane go
    to the region's side)."""
    from ..remeshing.clustering import ClusteringResult, _accumulate, centroids_of, label_pieces

    inside = np.searchsorted(seeds, mirrors.image[seeds])
    labels = inside[result.labels][mirrors.image]
    for p in reversed(range(len(mirrors.maps))):
        labels = np.where(mirrors.flips[p], sigma[p][labels], labels)
    count = len(result.centroids)
    if np.count_nonzero(np.bincount(labels, minlength=count)) != count or label_pieces(labels, fine.edges) != count:
        return None
    S, _ = _accumulate(labels, moments, count)
    centred = centroids_of(S)
    return ClusteringResult(labels=labels, centroids=centred + mirrors.centre,
                            energy=S[:, 9] - np.einsum("ki,ki->k", S[:, 6:9], centred), sweeps=result.sweeps,
                            moves=result.moves)


def _onto_planes(fine: _Fine, mirrors: _Mirrors, seeds: np.ndarray, sigma: list) -> np.ndarray:
    """``seeds`` (of a Lloyd step, in the order of the clusters of the last symmetric clustering)
    with those of the clusters that are their own mirror through some planes (sigma) moved to the
    nearest vertex on those planes: snapped off the plane, such a cluster would split into a mirrored
    pair (or vanish) at the next clustering."""
    seeds = seeds.copy()
    own = np.array([mirror == np.arange(len(seeds)) for mirror in sigma])
    for combination in sorted({tuple(column) for column in own.T if any(column)}):
        chosen = np.flatnonzero(np.all(own.T == combination, axis=1))
        nearest = _nearest_on_planes(fine, mirrors, combination, seeds[chosen])
        if nearest is not None:
            seeds[chosen] = nearest
    return seeds


def _merged_pairs(fine: _Fine, mirrors: _Mirrors, seeds: np.ndarray, sigma: list, result) -> np.ndarray | None:
    """The seeds with mirrored pairs of clusters merged where two such pairs follow each other along
    a plane, or None where none do. The four clusters of two consecutive pairs meet at one point of
    the plane, which no symmetric grid splits into valence-3 nodes (an extra beam there would part
    clusters that are not mirrors), so the extraction collapses it into a valence-4 node; a
    honeycomb symmetric about a line has a cluster centred on it between any two pairs. Two pairs
    are consecutive where a mesh edge within one mean edge length of the plane (an end in the
    fundamental region) joins clusters of both; of the two, the pair of the smaller weight becomes
    one cluster, its seed the vertex on the plane (in the fundamental region) nearest the pair's
    mean centroid. One junction per orbit under the mirrors, taken in order of the mesh edges."""
    x = fine.vertices
    E = fine.edges
    labels = result.labels
    n = len(seeds)
    weight = np.bincount(labels, weights=fine.areas * fine.inverse_h2, minlength=n)
    region = mirrors.image == np.arange(len(x))
    orbit = np.searchsorted(seeds, mirrors.image[seeds])  # each cluster's representative in the region
    taken = set(seeds.tolist())

    def into_region(point: np.ndarray) -> np.ndarray:
        for plane in mirrors.planes:
            if (point - np.asarray(plane[0], dtype=float)) @ np.asarray(plane[1], dtype=float) < 0:
                point = reflect(point[None, :], plane)[0]
        return point

    merged: dict[int, int] = {}  # representative replaced -> its new seed on the plane
    for on, on_tree, near, flip_map in zip(mirrors.on, mirrors.on_trees, mirrors.near_edges, sigma):
        if not len(on):
            continue
        ends = E[near]                                      # the mesh edges near the plane, in order
        la, lb = labels[ends[:, 0]], labels[ends[:, 1]]
        straddle = flip_map != np.arange(n)
        touching = np.zeros(n, dtype=bool)
        across = (la != lb) & (flip_map[la] == lb)
        touching[la[across]] = True
        touching[lb[across]] = True
        junction = ((la != lb) & (flip_map[la] != lb) & straddle[la] & straddle[lb] & touching[la]
                    & touching[lb] & (region[ends[:, 0]] | region[ends[:, 1]]))
        for e in np.flatnonzero(junction):
            a, b = int(la[e]), int(lb[e])
            if orbit[a] in merged or orbit[b] in merged:
                continue
            wa, wb = weight[a] + weight[flip_map[a]], weight[b] + weight[flip_map[b]]
            chosen = a if (wa, a) <= (wb, b) else b
            centre = into_region(0.5 * (result.centroids[chosen] + result.centroids[flip_map[chosen]]))
            vertex = int(on[on_tree.query(centre)[1]])
            if vertex in taken:
                continue
            taken.add(vertex)
            merged[int(orbit[chosen])] = vertex
    if not merged:
        return None
    kept = [int(s) for i, s in enumerate(seeds) if orbit[i] == i and i not in merged] + list(merged.values())
    return np.unique(np.asarray(kept, dtype=np.int64))
