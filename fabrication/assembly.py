"""Assembly sequence of the grid-shell: which beams and panels go up in which order, and
where temporary props are needed.

Greedy, from the supports inward: the structure grows one cell at a time (a step adds the
missing beams of one cell). At each step the candidate cells are those sharing a node with
what is built (at the start: with a support); a handful, ranked by how few beams they miss
and how close they are (along the beams) to a support, are analysed as partial frames under
their own weight (and the weight of the panels placed) with ``engine.structure.frame.linear_static``,
and the one needing fewest new props, then deflecting least, is built. A partial structure
that is a mechanism gets a temporary prop (a fully restrained support) at its dangling end
(the built node farthest, along the beams, from any support or prop); one deflecting more
than the limit gets a prop at the node of largest displacement. Props are removed as soon
as the structure stands within the limit without them. A panel follows in the step that
completes its ring of beams.

On a grid of more than ANALYSED_RUNS cells, the cells go up in runs of consecutive steps, each
taking the best-ranked cell unanalysed; the state after a run is analysed and propped where it
needs it, and a run that does not stand even so is taken again one analysed step at a time. A
1500-cell roof is planned in some 20 s instead of 5 min; its props are placed per run, so there
may be a few more of them.
"""

from __future__ import annotations

import csv
import functools
import heapq
import io
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from engine.errors import InputError, MechanismError
from engine.mesh import PolyMesh
from fabrication.drawings import beam_id, node_id, panel_id
from fabrication.files import save_figure_png, write_text_atomic
from fabrication.plan_view import is_wide_plan, plan_height_in, plan_limits

__all__ = ["AssemblyStep", "AssemblySequence", "plan_assembly", "write_assembly", "partial_frame_deflection",
           "deflections_without_props", "step_groups", "step_image_name", "MAX_STEP_IMAGES"]

GRAVITY = 9.81  # m/s^2
CANDIDATES_PER_STEP = 4
_PINNED = np.array([1, 1, 1, 0, 0, 0], dtype=bool)
_FIXED = np.ones(6, dtype=bool)
_BEAM_KEYS = ("E", "G", "A", "Iy", "Iz", "J", "mass_per_length")


@dataclass(frozen=True, kw_only=True)
class AssemblyStep:
    """One step: beams (row indices of ``PolyMesh.edges``) and panels (face indices) added,
    props (node indices) standing after the step, props_added (the new ones), the largest
    displacement of the partial structure (m) and the nodes first joined in this step."""

    step: int
    beams: list[int]
    panels: list[int]
    props: list[int]
    largest_deflection_m: float
    nodes_built: list[int] = field(default_factory=list)
    props_added: list[int] = field(default_factory=list)


@dataclass(frozen=True, kw_only=True)
class AssemblySequence:
    """The steps in order, the deflection limit used (m), the support nodes and the number
    of frame analyses run."""

    steps: list[AssemblyStep]
    deflection_limit_m: float
    support_nodes: np.ndarray
    n_analyses: int

    @property
    def largest_deflection_m(self) -> float:
        return max((s.largest_deflection_m for s in self.steps), default=0.0)

    @property
    def props_used(self) -> list[int]:
        """Every node that carried a prop at some step, in order of first use."""
        seen: list[int] = []
        for s in self.steps:
            seen += [p for p in s.props_added if p not in seen]
        return seen

    @property
    def props(self) -> list[int]:
        """Every node that carried a prop at some step, sorted."""
        return sorted(self.props_used)


# ----------------------------------------------------------------------------- analysis

def _beam_up_vectors(polymesh: PolyMesh) -> np.ndarray:
    """(b, 3) local z for each beam: the mean normal of the cells it borders (global z where
    none; global x for a beam along that normal)."""
    edges = polymesh.edges
    lookup = {(int(a), int(b)): k for k, (a, b) in enumerate(edges)}
    up = np.zeros((len(edges), 3))
    nodes = polymesh.nodes
    for loop in polymesh.faces:
        p = nodes[loop]
        normal = np.cross(p - p.mean(0), np.roll(p, -1, axis=0) - p.mean(0)).sum(0)
        normal /= max(np.linalg.norm(normal), 1e-300)
        for a, b in zip(loop, np.roll(loop, -1)):
            up[lookup[(min(a, b), max(a, b))]] += normal
    up[np.linalg.norm(up, axis=1) < 1e-9] = [0.0, 0.0, 1.0]
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    direction = nodes[edges[:, 1]] - nodes[edges[:, 0]]
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    up[np.abs(np.einsum("ij,ij->i", up, direction)) > 0.999] = [1.0, 0.0, 0.0]
    return up


@dataclass
class _Model:
    """Everything fixed over the sequence, for fast partial analyses."""

    polymesh: PolyMesh
    beam: dict
    up: np.ndarray  # (b, 3)
    beam_weight: np.ndarray  # (b,) N
    face_load: np.ndarray  # (f,) N per panel (area load x cell area)
    supports: np.ndarray  # (k,) int
    support_flags: np.ndarray  # (6,) bool
    n_analyses: int = 0


def _build_model(polymesh: PolyMesh, support_nodes: np.ndarray, beam: dict, panel_area_load: float,
                 support_restraint: str, up: np.ndarray | None = None) -> _Model:
    n_beams = len(polymesh.edges)
    mass = np.broadcast_to(np.asarray(beam["mass_per_length"], float), (n_beams,))
    up = _beam_up_vectors(polymesh) if up is None else np.broadcast_to(np.asarray(up, float), (n_beams, 3))
    return _Model(polymesh=polymesh, beam=dict(beam), up=up, beam_weight=mass * GRAVITY * polymesh.beam_lengths,
                  face_load=panel_area_load * polymesh.face_areas(), supports=np.asarray(support_nodes, np.int64),
                  support_flags=_PINNED if support_restraint == "pinned" else _FIXED)


def _per_beam(value, beams: np.ndarray):
    value = np.asarray(value, float)
    return value if value.ndim == 0 else value[beams]


def _partial_frame(model: _Model, beams: np.ndarray, panels: np.ndarray, props: list[int]):
    """(frame, supports, loads, used): the partial frame of ``beams`` under its own weight and that
    of ``panels``, on the supports it touches and fully fixed ``props``; ``used`` (k,) are its
    nodes' grid-shell indices, in the frame's order."""
    from engine.structure.frame import FrameModel
    from engine.structure.supports import Supports

    pm = model.polymesh
    beams = np.asarray(beams, dtype=np.int64)
    used, local = np.unique(pm.edges[beams], return_inverse=True)
    local = local.reshape(-1, 2)
    index = -np.ones(pm.n_nodes, dtype=np.int64)
    index[used] = np.arange(len(used))
    loads = np.zeros((len(used), 6))
    np.add.at(loads[:, 2], local[:, 0], -0.5 * model.beam_weight[beams])
    np.add.at(loads[:, 2], local[:, 1], -0.5 * model.beam_weight[beams])
    for f in panels:
        loop = pm.faces[f]
        np.add.at(loads[:, 2], index[loop], -model.face_load[f] / len(loop))
    held = [(index[model.supports[np.isin(model.supports, used)]], model.support_flags)]
    prop_nodes = [p for p in props if index[p] >= 0]
    if prop_nodes:
        held.append((index[np.array(prop_nodes)], _FIXED))
    supports = Supports.merge(held)
    if len(supports.nodes) == 0:
        raise MechanismError("the partial structure touches no support", n_modes=6)
    b = model.beam
    frame = FrameModel(nodes=pm.nodes[used], beams=local, E=_per_beam(b["E"], beams), G=_per_beam(b["G"], beams),
                       A=_per_beam(b["A"], beams), Iy=_per_beam(b["Iy"], beams), Iz=_per_beam(b["Iz"], beams),
                       J=_per_beam(b["J"], beams), up=model.up[beams], elements_per_beam=1)
    return frame, supports, loads, used


def partial_frame_deflection(model: _Model, beams: np.ndarray, panels: np.ndarray,
                             props: list[int]) -> tuple[float, np.ndarray]:
    """Largest translation (m) of the partial frame made of ``beams`` (indices into
    ``polymesh.edges``) under its own weight and the weight of ``panels`` (face indices),
    held by the supports it touches (``support_flags``) and fully fixed ``props``; and the
    (n_nodes,) translation magnitude per grid-shell node (0 where not built). Beam weight is
    lumped half to each end. Raises ``engine.errors.MechanismError`` for a mechanism."""
    from engine.structure.frame import linear_static

    frame, supports, loads, used = _partial_frame(model, beams, panels, props)
    model.n_analyses += 1
    result = linear_static(frame, supports, loads)
    translation = np.linalg.norm(result.displacements[:, :3], axis=1)
    full = np.zeros(model.polymesh.n_nodes)
    full[used] = translation
    return float(translation.max()), full


def deflections_without_props(model: _Model, beams: np.ndarray, panels: np.ndarray, props: list[int],
                              trials: list[list[int]]) -> list[float | None]:
    """``partial_frame_deflection``'s largest translation (m) of one partial frame held by each
    of ``trials`` (subsets of ``props``) instead of ``props``; None where it is a mechanism.

    The stiffness is factored once, with every prop held. Releasing a set D of prop DOFs adds
    them back through the Schur complement S = K_DD - K_DF K_FF^-1 K_FD: u_D = S^-1 (f_D - K_DF
    u0) with u0 = K_FF^-1 f_F, and u_F = u0 - K_FF^-1 K_FD u_D (6 solves per prop, shared by
    the trials, instead of a factorisation per trial). S not positive definite (an eigenvalue
    under TINY_PIVOT of K's largest diagonal entry) is a mechanism, as the factor's tiny pivots
    say in the direct analysis. Raises MechanismError where the frame with every prop held is
    one."""
    from engine.structure.condensed import TINY_PIVOT
    from engine.structure.frame import factor_stiffness

    frame, supports, loads, used = _partial_frame(model, beams, panels, props)
    stiffness = factor_stiffness(frame, supports)
    model.n_analyses += 1
    position = {int(node): k for k, node in enumerate(used)}
    supported = set(model.supports.tolist())
    # a prop's DOFs that a permanent support does not hold (props stand on unsupported nodes)
    own = {p: 6 * position[p] + np.flatnonzero(~model.support_flags if p in supported else _FIXED)
           for p in dict.fromkeys(props) if p in position}
    D = np.concatenate([np.zeros(0, np.int64), *own.values()])
    K = stiffness.K.tocsr()
    free, f = stiffness.free, loads.ravel()
    u0 = stiffness.lu.solve(f[free])
    K_FD = K[free][:, D].toarray()
    X = stiffness.lu.solve(K_FD) if len(D) else K_FD
    K_DD = K[D][:, D].toarray()
    scale = float(np.abs(K.diagonal()).max())
    start = np.cumsum([0] + [len(d) for d in own.values()])
    out: list[float | None] = []
    for trial in trials:
        freed = np.concatenate([np.zeros(0, np.int64)] + [np.arange(start[k], start[k + 1])
                                                         for k, p in enumerate(own) if p not in trial])
        S = K_DD[np.ix_(freed, freed)] - K_FD[:, freed].T @ X[:, freed]
        if len(freed) and np.linalg.eigvalsh(0.5 * (S + S.T))[0] <= TINY_PIVOT * scale:
            out.append(None)
            continue
        u_D = np.linalg.solve(S, f[D[freed]] - K_FD[:, freed].T @ u0) if len(freed) else np.zeros(0)
        u = np.zeros(len(f))
        u[free] = u0 - X[:, freed] @ u_D
        u[D[freed]] = u_D
        out.append(float(np.linalg.norm(u.reshape(-1, 6)[:, :3], axis=1).max()))
    return out


def _dangling_end(model: _Model, beams: np.ndarray, props: list[int]) -> int:
    """The built node farthest along the built beams from every support and prop."""
    pm = model.polymesh
    adjacency: dict[int, list[tuple[int, float]]] = {}
    for (a, b), length in zip(pm.edges[beams], pm.beam_lengths[beams]):
        adjacency.setdefault(int(a), []).append((int(b), float(length)))
        adjacency.setdefault(int(b), []).append((int(a), float(length)))
    sources = [int(s) for s in model.supports if int(s) in adjacency] + [p for p in props if p in adjacency]
    distance = {s: 0.0 for s in sources}
    heap = [(0.0, s) for s in sources]
    while heap:
        d, u = heapq.heappop(heap)
        if d > distance.get(u, np.inf):
            continue
        for v, length in adjacency[u]:
            if d + length < distance.get(v, np.inf):
                distance[v] = d + length
                heapq.heappush(heap, (d + length, v))
    candidates = [n for n in adjacency if n not in sources]
    if not candidates:  # pragma: no cover - everything is held
        return int(pm.edges[beams[0], 0])
    return int(max(candidates, key=lambda n: distance.get(n, np.inf)))


def _analyse_with_props(model: _Model, beams: np.ndarray, panels: np.ndarray, props: list[int],
                        limit: float, max_new_props: int = 3) -> tuple[float, list[int]]:
    """Deflection of a partial state, adding props (dangling end for a mechanism, largest
    displacement over the limit) until it stands within the limit or ``max_new_props``."""
    props = list(props)
    added: list[int] = []
    supported = set(model.supports.tolist())
    while True:
        try:
            deflection, movement = partial_frame_deflection(model, beams, panels, props)
        except MechanismError:
            if len(added) >= max_new_props:
                return np.inf, added
            node = _dangling_end(model, beams, props)
            props.append(node)
            added.append(node)
            continue
        if deflection <= limit or len(added) >= max_new_props:
            return deflection, added
        node = int(np.argmax(movement))
        if node in props or node in supported:  # pragma: no cover - cannot help
            return deflection, added
        props.append(node)
        added.append(node)


#: Frame analyses are run for at most about this many states of a large grid: beyond it the cells
#: are built in runs of consecutive steps, and the state after each run is analysed (see
#: plan_assembly).
ANALYSED_RUNS = 150
#: Deflections of two candidate cells this close (relative) are equal: the cell ranked first
#: (fewest missing beams, nearest a support) goes up. On a symmetric roof mirror-image cells
#: deflect the same to round-off, which otherwise picked between them.
SAME_DEFLECTION = 1e-9
#: Cells whose distances from the supports (along the beams) differ by less than this share of
#: the mean beam are equally near (see _Growth.options).
SAME_DISTANCE = 1e-6


def _ranks_before(key: tuple[int, float], best: tuple[int, float]) -> bool:
    """Whether a candidate cell of (new props, deflection) ``key`` is built before the ``best``
    so far: fewer props, else a deflection smaller by more than SAME_DEFLECTION (a finite one
    before one that is not)."""
    (props, deflection), (best_props, best_deflection) = key, best
    if props != best_props:
        return props < best_props
    if not np.isfinite(best_deflection):
        return bool(np.isfinite(deflection))
    return bool(deflection < best_deflection - SAME_DEFLECTION * abs(best_deflection))


class _Growth:
    """What is built (beams, nodes, panels) and the cells' incidences, for ranking the next cells."""

    def __init__(self, polymesh: PolyMesh, support_nodes: np.ndarray) -> None:
        from scipy.sparse import coo_matrix, csr_matrix
        from scipy.sparse.csgraph import dijkstra

        edges, faces = polymesh.edges, polymesh.faces
        lookup = {(int(a), int(b)): k for k, (a, b) in enumerate(edges)}
        self.face_beams = [np.array(sorted({lookup[(min(a, b), max(a, b))] for a, b in zip(loop, np.roll(loop, -1))}))
                           for loop in faces]
        self.face_nodes = [np.asarray(loop) for loop in faces]
        rows = np.repeat(np.arange(len(faces)), [len(b) for b in self.face_beams])
        self.cell_beams = csr_matrix((np.ones(len(rows)), (rows, np.concatenate(self.face_beams))),
                                     shape=(len(faces), len(edges)))
        rows = np.repeat(np.arange(len(faces)), [len(n) for n in self.face_nodes])
        self.cell_nodes = csr_matrix((np.ones(len(rows)), (rows, np.concatenate(self.face_nodes))),
                                     shape=(len(faces), polymesh.n_nodes))
        # distance along the beams from the nearest support, to rank cells "from the supports inward"
        lengths = polymesh.beam_lengths
        graph = coo_matrix((np.r_[lengths, lengths],
                            (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])),
                           shape=(polymesh.n_nodes,) * 2).tocsr()
        from_support = dijkstra(graph, indices=support_nodes, min_only=True)
        self.distance = np.array([from_support[loop].mean() for loop in self.face_nodes])
        # ranked to SAME_DISTANCE of the mean beam, so that mirror-image cells tie exactly and the
        # lower id goes first, whatever the last digits of their distances
        self.rank = np.round(self.distance / (SAME_DISTANCE * max(float(lengths.mean()), 1e-300)))
        self.edges = edges
        self.beams = np.zeros(len(edges), dtype=bool)
        self.nodes = np.zeros(polymesh.n_nodes, dtype=bool)
        self.panels = np.zeros(len(faces), dtype=bool)
        self.supported = np.zeros(polymesh.n_nodes, dtype=bool)
        self.supported[support_nodes] = True

    def copy(self) -> "_Growth":
        other = object.__new__(_Growth)
        other.__dict__.update(self.__dict__)
        other.beams, other.nodes, other.panels = self.beams.copy(), self.nodes.copy(), self.panels.copy()
        return other

    def options(self, count: int) -> list[tuple[np.ndarray, np.ndarray]]:
        """The ``count`` best next cells as (missing beams, panels completed with them): cells
        sharing a node with what is built (at first: with a support), fewest missing beams first,
        then nearest a support; a part not reachable through cells starts nearest a support."""
        missing = self.cell_beams @ (~self.beams).astype(float)
        touching = self.nodes if self.nodes.any() else self.supported
        open_cells = (missing > 0) & (self.cell_nodes @ touching.astype(float) > 0)
        if not open_cells.any():
            open_cells = missing > 0
            chosen = [int(np.flatnonzero(open_cells)[np.argmin(self.rank[open_cells])])]
        else:
            cells = np.flatnonzero(open_cells)
            chosen = cells[np.lexsort((self.rank[cells], missing[cells]))][:count].tolist()
        out = []
        for f in chosen:
            todo = self.face_beams[f][~self.beams[self.face_beams[f]]]
            done = self.beams.copy()
            done[todo] = True
            completed = np.flatnonzero(~self.panels & (self.cell_beams @ (~done).astype(float) == 0))
            out.append((todo, completed))
        return out

    def build(self, todo: np.ndarray, panels: np.ndarray) -> list[int]:
        """Add ``todo`` beams and ``panels``; returns the nodes first joined."""
        ends = self.edges[todo].ravel()
        new_nodes = sorted(set(ends[~self.nodes[ends]].tolist()))
        self.beams[todo] = True
        self.nodes[ends] = True
        self.panels[panels] = True
        return new_nodes


def plan_assembly(polymesh: PolyMesh, support_nodes: np.ndarray, beam: dict, *, panel_area_load: float = 0.0,
                  deflection_limit_m: float | None = None, candidates_per_step: int = CANDIDATES_PER_STEP,
                  support_restraint: str = "pinned", up: np.ndarray | None = None,
                  analysed_runs: int | None = ANALYSED_RUNS,
                  progress: Callable[[str, float], None] | None = None) -> AssemblySequence:
    """Greedy assembly sequence from the supports inward (see the module docstring).

    support_nodes (k,) int: supported node indices. beam: dict with E, G (Pa), A (m^2), Iy, Iz,
    J (m^4), mass_per_length (kg/m), each a scalar or (n_beams,) per beam. panel_area_load:
    weight of the cladding, N/m^2 of cell area, applied once a panel is placed.
    deflection_limit_m: largest allowed displacement of a partial structure before a prop is
    added (default: span / 500, span = the larger plan dimension). support_restraint:
    "pinned" (translations held) or "fixed" for the permanent supports; props are fixed.
    up (b, 3): each beam's local z (default: mean normal of the adjacent cells).
    analysed_runs: on a grid of more cells than this, a run of n_cells / analysed_runs steps
    takes the best-ranked cell each, unanalysed (their ``largest_deflection_m`` is NaN), and the
    state after the run is analysed; where it needs a prop or deflects over the limit, those
    steps are taken again one at a time, each analysed (None: every step analysed).
    progress(message, fraction): optional callback after each step.
    """
    support_nodes = np.unique(np.asarray(support_nodes, dtype=np.int64).ravel())
    if support_nodes.size == 0:
        raise InputError("plan_assembly needs at least one support node", hint="pass the grid-shell's supports")
    if support_nodes.min() < 0 or support_nodes.max() >= polymesh.n_nodes:
        raise InputError(f"support node index out of range 0..{polymesh.n_nodes - 1}")
    missing = [k for k in _BEAM_KEYS if k not in beam]
    if missing:
        raise InputError(f"beam properties missing: {', '.join(missing)}",
                         hint="beam = dict(E=, G=, A=, Iy=, Iz=, J=, mass_per_length=) in SI units")
    if support_restraint not in ("pinned", "fixed"):
        raise InputError(f"support_restraint {support_restraint!r} must be 'pinned' or 'fixed'")
    span = float(np.ptp(polymesh.nodes[:, :2], axis=0).max())
    limit = span / 500 if deflection_limit_m is None else float(deflection_limit_m)
    model = _build_model(polymesh, support_nodes, beam, panel_area_load, support_restraint, up)
    run_length = 1 if not analysed_runs else max(1, -(-polymesh.n_faces // analysed_runs))
    growth = _Growth(polymesh, support_nodes)
    props: list[int] = []
    steps: list[AssemblyStep] = []

    def add_step(todo, panels, deflection: float, added: list[int], new_nodes: list[int]) -> None:
        steps.append(AssemblyStep(step=len(steps) + 1, beams=[int(k) for k in todo],
                                  panels=[int(g) for g in panels], props=list(props),
                                  largest_deflection_m=float(deflection), nodes_built=new_nodes,
                                  props_added=list(added)))
        if progress is not None:
            progress(f"assembly step {len(steps)}", float(growth.beams.mean()))

    def settled(deflection: float, added: list[int]) -> float:
        """Take on the ``added`` props; when none was added, remove those the built structure no
        longer needs (all together, else one at a time, oldest first). The deflection then."""
        nonlocal props
        props = props + added
        if added or not props:
            return deflection
        trials = [[]] + [[p for p in props if p != q] for q in props[:3]]
        try:
            values = deflections_without_props(model, np.flatnonzero(growth.beams), np.flatnonzero(growth.panels),
                                               props, trials)
        except MechanismError:  # pragma: no cover - the state with every prop was analysed standing
            return deflection
        for trial, value in zip(trials, values):
            if value is not None and value <= limit:
                props = trial
                return value
        return deflection

    def analysed_step() -> None:
        best = None
        for todo, completed in growth.options(candidates_per_step):
            beams_after = np.concatenate([np.flatnonzero(growth.beams), todo])
            panels_after = np.concatenate([np.flatnonzero(growth.panels), completed]).astype(np.int64)
            deflection, added = _analyse_with_props(model, beams_after, panels_after, props, limit)
            if best is None or _ranks_before((len(added), deflection), best[0]):
                best = ((len(added), deflection), todo, completed, deflection, added)
        _, todo, completed, deflection, added = best
        new_nodes = growth.build(todo, completed)
        add_step(todo, completed, settled(deflection, added), added, new_nodes)

    def run_of_steps() -> bool:
        """Up to run_length best-ranked cells, the state after them analysed and propped where it
        deflects over the limit (at most 3 new props, at the last step): kept (True) when it then
        stands within the limit, else undone (False)."""
        nonlocal growth
        before = growth.copy()
        taken = []
        for _ in range(run_length):
            if growth.beams.all():
                break
            (todo, completed), = growth.options(1)
            taken.append((todo, completed, growth.build(todo, completed)))
        deflection, added = _analyse_with_props(model, np.flatnonzero(growth.beams), np.flatnonzero(growth.panels),
                                                props, limit)
        if not deflection <= limit:
            growth = before
            return False
        for todo, completed, new_nodes in taken[:-1]:
            add_step(todo, completed, np.nan, [], new_nodes)
        todo, completed, new_nodes = taken[-1]  # the props the run's end needs stand from its last step
        add_step(todo, completed, settled(deflection, added), added, new_nodes)
        return True

    while not growth.beams.all():
        if run_length > 1 and run_of_steps():
            continue
        for _ in range(run_length):  # one at a time, each analysed
            if growth.beams.all():
                break
            analysed_step()
    return AssemblySequence(steps=steps, deflection_limit_m=limit, support_nodes=support_nodes,
                            n_analyses=model.n_analyses)


# ----------------------------------------------------------------------------- files

#: The most step images: beyond it each image shows as many consecutive steps as it takes.
MAX_STEP_IMAGES = 100


def step_groups(n_steps: int, max_images: int | None = MAX_STEP_IMAGES) -> list[range]:
    """Consecutive steps (0-based) drawn together: one step per image, or, beyond ``max_images``
    steps, ``max_images`` runs of consecutive steps whose lengths differ by at most one."""
    count = n_steps if not max_images or n_steps <= max_images else max_images
    bounds = np.linspace(0, n_steps, count + 1).round().astype(int)
    return [range(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]


def step_image_name(group: range, n_steps: int, runs: bool = False) -> str:
    """``step_007.png`` for one step, ``steps_101-115.png`` for a run of steps (``runs``: the
    images show runs; 1-based, zero-padded to the digits of the last step, at least three)."""
    width = max(3, len(str(n_steps)))
    first, last = group.start + 1, group.stop
    return f"steps_{first:0{width}d}-{last:0{width}d}.png" if runs else f"step_{first:0{width}d}.png"


def write_assembly(sequence: AssemblySequence, polymesh: PolyMesh, folder: str | os.PathLike, *,
                   max_step_images: int | None = MAX_STEP_IMAGES) -> dict:
    """Write ``folder/sequence.csv`` (step, parts, props, largest_deflection_mm),
    ``folder/steps/step_001.png``... (plan: built dark, new red, props as markers; beyond
    ``max_step_images`` steps, one image per run of steps, ``steps_001-015.png``, see
    step_groups; None: one per step) and ``folder/steps_strip.png`` (up to 8 thumbnails).
    Returns a summary dict: csv (path), steps, step_images, props (N... ids of every node
    propped at some step), largest_deflection_mm."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["step", "parts", "props", "largest_deflection_mm"])
    for s in sequence.steps:
        parts = [beam_id(k) for k in s.beams] + [panel_id(f) for f in s.panels]
        writer.writerow([s.step, " ".join(parts), " ".join(node_id(p) for p in s.props),
                         f"{s.largest_deflection_m * 1e3:.3f}" if np.isfinite(s.largest_deflection_m) else ""])
    csv_path = write_text_atomic(folder / "sequence.csv", buffer.getvalue())

    n = len(sequence.steps)
    groups = step_groups(n, max_step_images)
    (folder / "steps").mkdir(exist_ok=True)
    canvas = _StepCanvas(sequence, polymesh)
    runs = len(groups) < n
    for group in groups:
        canvas.save(group, folder / "steps" / step_image_name(group, n, runs))
    _strip(sequence, polymesh, folder / "steps_strip.png")
    finite = [s.largest_deflection_m for s in sequence.steps if np.isfinite(s.largest_deflection_m)]
    return {"csv": str(csv_path), "steps": n, "step_images": len(groups),
            "props": [node_id(p) for p in sequence.props_used],
            "largest_deflection_mm": 1e3 * max(finite, default=0.0),
            "deflection_limit_mm": 1e3 * sequence.deflection_limit_m, "analyses": sequence.n_analyses}


def _draw_state(ax, sequence: AssemblySequence, polymesh: PolyMesh, k: int) -> None:
    """Step ``k`` (0-based) on ``ax``: the strip's thumbnails."""
    from matplotlib.collections import LineCollection, PolyCollection

    plan = polymesh.nodes[:, :2]
    edges = polymesh.edges
    before_beams = [b for s in sequence.steps[:k] for b in s.beams]
    before_panels = [f for s in sequence.steps[:k] for f in s.panels]
    step = sequence.steps[k]
    ax.set_aspect("equal")
    ax.axis("off")
    if before_panels:
        ax.add_collection(PolyCollection([plan[polymesh.faces[f]] for f in before_panels], facecolors="0.8",
                                         edgecolors="none"))
    if step.panels:
        ax.add_collection(PolyCollection([plan[polymesh.faces[f]] for f in step.panels], facecolors="#f4a6a6",
                                         edgecolors="none"))
    ax.add_collection(LineCollection(plan[edges], colors="0.88", linewidths=0.5))
    if before_beams:
        ax.add_collection(LineCollection(plan[edges[before_beams]], colors="0.15", linewidths=1.0))
    ax.add_collection(LineCollection(plan[edges[step.beams]], colors="red", linewidths=1.6))
    s = sequence.support_nodes
    ax.plot(plan[s, 0], plan[s, 1], "^", color="tab:blue", markersize=3, linestyle="none")
    if step.props:
        ax.plot(plan[step.props, 0], plan[step.props, 1], "X", color="darkorange", markersize=5, linestyle="none")
    _frame(ax, plan)
    ax.set_title(f"step {step.step}", fontsize=8)


def _frame(ax, plan: np.ndarray) -> None:
    x_limits, y_limits = plan_limits(plan)
    ax.set_xlim(*x_limits)
    ax.set_ylim(*y_limits)


class _StepCanvas:
    """One figure for every step image: the grid and the supports drawn once, and per image only
    what was built before (dark), what the steps add (red), the props and the title changed. The
    panels' and beams' matplotlib paths are made once, in the order they go up, so that an image
    takes slices of them: what is built before a step is a prefix of that order (making the paths
    again for every image was a third of the images' time on a 1500-cell roof)."""

    def __init__(self, sequence: AssemblySequence, polymesh: PolyMesh) -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.collections import LineCollection, PolyCollection
        from matplotlib.figure import Figure

        self.sequence, self.polymesh = sequence, polymesh
        self.plan = plan = polymesh.nodes[:, :2]
        steps = sequence.steps
        panels = [f for s in steps for f in s.panels]
        beams = [b for s in steps for b in s.beams]
        self.panel_paths = PolyCollection([plan[polymesh.faces[f]] for f in panels]).get_paths() if panels else []
        self.beam_paths = LineCollection(plan[polymesh.edges[beams]].reshape(-1, 2, 2)).get_paths() if beams else []
        # where each step's parts start in those orders
        self.panel_starts = np.cumsum([0] + [len(s.panels) for s in steps])
        self.beam_starts = np.cumsum([0] + [len(s.beams) for s in steps])
        if is_wide_plan(plan):  # across a wider picture, as deep as the plan needs, the title above
            height = plan_height_in(plan, 8.6, labels_in=0.9, least_in=0.8)
            self.figure, box = Figure(figsize=(9, height)), (0.02, 0.02, 0.96, 1 - 0.85 / height)
        else:
            self.figure, box = Figure(figsize=(6, 6)), (0.02, 0.02, 0.96, 0.86)
        FigureCanvasAgg(self.figure)
        ax = self.figure.add_axes(box)
        ax.set_aspect("equal")
        ax.axis("off")
        self.built_panels = ax.add_collection(_showing("PolyCollection")([], facecolors="0.8", edgecolors="none"))
        self.new_panels = ax.add_collection(_showing("PolyCollection")([], facecolors="#f4a6a6", edgecolors="none"))
        ax.add_collection(LineCollection(self.plan[polymesh.edges], colors="0.88", linewidths=0.5))
        self.built_beams = ax.add_collection(_showing("LineCollection")([], colors="0.15", linewidths=1.4))
        self.new_beams = ax.add_collection(_showing("LineCollection")([], colors="red", linewidths=2.4))
        s = sequence.support_nodes
        ax.plot(self.plan[s, 0], self.plan[s, 1], "^", color="tab:blue", markersize=6, linestyle="none")
        (self.props,) = ax.plot([], [], "X", color="darkorange", markersize=10, linestyle="none")
        _frame(ax, self.plan)
        self.ax = ax

    def save(self, group: range, target: Path) -> None:
        """Draw the steps of ``group`` (0-based, consecutive) and write them to ``target`` (PNG)."""
        steps, plan = self.sequence.steps, self.plan
        added = steps[group.start:group.stop]
        first, end = self.panel_starts[group.start], self.panel_starts[group.stop]
        self.built_panels.show(self.panel_paths[:first])
        self.new_panels.show(self.panel_paths[first:end])
        first, end = self.beam_starts[group.start], self.beam_starts[group.stop]
        self.built_beams.show(self.beam_paths[:first])
        self.new_beams.show(self.beam_paths[first:end])
        last = added[-1]
        self.props.set_data(plan[last.props, 0], plan[last.props, 1])
        if len(added) == 1:
            parts = [beam_id(b) for b in last.beams] + [panel_id(f) for f in last.panels]
            text = f"Step {last.step} of {len(steps)}: " + ", ".join(parts[:8]) + (" ..." if len(parts) > 8 else "")
        else:  # the parts of each step are in sequence.csv
            n_beams, n_panels = sum(len(s.beams) for s in added), sum(len(s.panels) for s in added)
            text = f"Steps {added[0].step}-{last.step} of {len(steps)}: {n_beams} beams, {n_panels} panels"
        shown = [node_id(p) for p in last.props]
        props = ", ".join(shown[:6]) + (f" and {len(shown) - 6} more" if len(shown) > 6 else "") or "none"
        analysed = [s.largest_deflection_m for s in added if np.isfinite(s.largest_deflection_m)]
        deflection = f"{max(analysed) * 1e3:.2f} mm" if analysed else "not analysed"
        self.ax.set_title(f"{text}\nprops: {props} | "
                          f"largest deflection {deflection}", fontsize=9)
        save_figure_png(self.figure, target, dpi=100)


@functools.cache
def _showing(kind: str):
    """A subclass of the matplotlib collection ``kind`` (PolyCollection, LineCollection) whose
    ``show(paths)`` draws paths made beforehand by a collection of its kind, instead of making
    them again from vertices."""
    from matplotlib import collections

    class Showing(getattr(collections, kind)):  # type: ignore[misc]
        def show(self, paths: list) -> None:
            self._paths = paths   # what set_verts / set_segments end with
            self.stale = True

    Showing.__name__ = Showing.__qualname__ = f"{kind}Showing"
    return Showing


def _strip(sequence: AssemblySequence, polymesh: PolyMesh, target: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    n = len(sequence.steps)
    picks = np.unique(np.linspace(0, n - 1, min(8, n)).round().astype(int)) if n else []
    plan = polymesh.nodes[:, :2]
    wide = is_wide_plan(plan)  # then two a row, each as deep as the plan needs
    cols = min(max(len(picks), 1), 2 if wide else 4)
    rows = -(-max(len(picks), 1) // cols)
    cell = (6.0, plan_height_in(plan, 6.0, labels_in=0.4, least_in=0.6)) if wide else (3.3, 3.3)
    fig = Figure(figsize=(cell[0] * cols, cell[1] * rows + 0.4))
    FigureCanvasAgg(fig)
    for j, k in enumerate(picks):
        _draw_state(fig.add_subplot(rows, cols, j + 1), sequence, polymesh, int(k))
    fig.suptitle(f"{len(picks)} of the {n} steps: built (dark), added in the step (red), supports (blue), "
                 "temporary props (orange)", fontsize=10)
    save_figure_png(fig, target, dpi=100, bbox_inches="tight")
