"""Equivalent continuum of regular beam tilings: closed forms and numerical homogenisation.

A planar rigid-jointed grid of beams (edge length l, axial stiffness EA (N), bending stiffness
EI (N m^2, the same in and out of plane unless stated), torsional stiffness GJ (N m^2)) acts at
large scale as a plate with membrane stiffness C (N/m) and bending stiffness D (N m), in Voigt
notation with engineering shear: [N_xx, N_yy, N_xy] = C [eps_xx, eps_yy, gamma_xy] and
[M_xx, M_yy, M_xy] = D [kappa_xx, kappa_yy, 2 kappa_xy].

``closed_form_stiffness`` evaluates the table of METHOD.md section 6 (thesis chapter 7) with the
2D bulk and shear moduli K, mu (C11 = K + mu, C12 = K - mu, C66 = mu) and their bending analogues
K_b, mu_b. ``homogenise`` computes C and D of any periodic cell of beams (the regular tilings of
``periodic_cell`` or a periodic Voronoi patch) with the frame elements of engine.structure.beam_elements: the
displacement is a macroscopic field (an affine membrane strain, or a quadratic deflection of
constant curvature with its rotations) plus a periodic fluctuation; the fluctuation minimising
the strain energy is solved for (one factorisation, six right-hand sides) and the energy per unit
area of the cell gives C and D column by column (0.5 e^T C e = W / area).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InputError

__all__ = [
    "TilingStiffness",
    "PeriodicCell",
    "Homogenised",
    "TILINGS",
    "closed_form_stiffness",
    "length_per_area",
    "equal_length_edges",
    "periodic_cell",
    "periodic_voronoi_cell",
    "homogenise",
]

TILINGS = ("triangle", "square", "hexagon")
SQ3 = float(np.sqrt(3.0))


def _check_tiling(tiling: str) -> None:
    if tiling not in TILINGS:
        raise InputError(f"unknown tiling {tiling!r}", hint=f"use one of {', '.join(TILINGS)}")


def _positive(**values: float) -> None:
    for key, value in values.items():
        if not (np.isfinite(value) and value > 0):
            raise InputError(f"tiling stiffness: {key} must be positive, got {value}")


def length_per_area(tiling: str, l: float) -> float:
    """Beam length per unit plan area (1/m) of the regular tiling with edge length l (m):
    triangle 2 sqrt3 / l, square 2 / l, hexagon 2 / (sqrt3 l)."""
    _check_tiling(tiling)
    _positive(l=l)
    return {"triangle": 2 * SQ3, "square": 2.0, "hexagon": 2 / SQ3}[tiling] / l


def equal_length_edges(length_per_unit_area: float) -> dict[str, float]:
    """Edge lengths (m) of the three tilings with one beam length per area (1/m); their ratio is
    l_triangle : l_square : l_hexagon = 3 : sqrt3 : 1."""
    _positive(length_per_unit_area=length_per_unit_area)
    return {t: length_per_area(t, 1.0) / length_per_unit_area for t in TILINGS}


@dataclass(frozen=True)
class TilingStiffness:
    """Membrane stiffness C (3,3) in N/m and bending stiffness D (3,3) in N m, Voigt notation with
    engineering shear and twist; the tiling name and edge length l (m)."""

    tiling: str
    l: float
    C: np.ndarray
    D: np.ndarray

    @property
    def membrane_modulus(self) -> float:
        """Young-type membrane stiffness E t (N/m) along x: C11 - C12^2 / C22 (= 4 K mu / (K + mu))."""
        return float(self.C[0, 0] - self.C[0, 1] ** 2 / self.C[1, 1])

    @property
    def bending_modulus(self) -> float:
        """Young-type bending stiffness E t^3 / 12 (N m) along x: D11 - D12^2 / D22."""
        return float(self.D[0, 0] - self.D[0, 1] ** 2 / self.D[1, 1])

    @property
    def equivalent_thickness(self) -> float:
        """t = sqrt(12 B / (E t)) (m): the solid plate with the grid's membrane-to-bending ratio."""
        return float(np.sqrt(12 * self.bending_modulus / self.membrane_modulus))

    @property
    def equivalent_modulus(self) -> float:
        """E (Pa) of that solid plate: (E t) / t."""
        return self.membrane_modulus / self.equivalent_thickness


def _voigt(K: float, mu: float) -> np.ndarray:
    return np.array([[K + mu, K - mu, 0.0], [K - mu, K + mu, 0.0], [0.0, 0.0, mu]])


def closed_form_stiffness(tiling: str, l: float, EA: float, EI: float, GJ: float) -> TilingStiffness:
    """Closed-form C and D of a regular tiling (METHOD.md section 6, thesis chapter 7):

    triangle: K = (sqrt3/2) EA/l, mu = (sqrt3/4) EA/l + 3 sqrt3 EI/l^3, K_b = (sqrt3/2) EI/l,
    mu_b = (sqrt3/4)(EI + GJ)/l; hexagon: K = EA/(2 sqrt3 l), mu = [l^3/(4 sqrt3 EI) +
    sqrt3 l/EA]^-1, K_b = EI/(2 sqrt3 l), mu_b = EI GJ/(sqrt3 l (EI + GJ)); square (beams along
    x and y): C11 = C22 = EA/l, C12 = 0, C66 = 6 EI/l^3, D11 = D22 = EI/l, D12 = 0,
    D66 = GJ/(2 l). l in m, EA in N, EI and GJ in N m^2.
    """
    _check_tiling(tiling)
    _positive(l=l, EA=EA, EI=EI, GJ=GJ)
    if tiling == "triangle":
        C = _voigt(SQ3 / 2 * EA / l, SQ3 / 4 * EA / l + 3 * SQ3 * EI / l**3)
        D = _voigt(SQ3 / 2 * EI / l, SQ3 / 4 * (EI + GJ) / l)
    elif tiling == "hexagon":
        C = _voigt(EA / (2 * SQ3 * l), 1.0 / (l**3 / (4 * SQ3 * EI) + SQ3 * l / EA))
        D = _voigt(EI / (2 * SQ3 * l), EI * GJ / (SQ3 * l * (EI + GJ)))
    else:
        C = np.diag([EA / l, EA / l, 6 * EI / l**3])
        D = np.diag([EI / l, EI / l, GJ / (2 * l)])
    return TilingStiffness(tiling, float(l), C, D)


# ----------------------------------------------------------------------------- periodic cells

@dataclass(frozen=True)
class PeriodicCell:
    """A periodic planar cell of beams: nodes (n,2) m in the cell; beams (b,2) node ids; shifts
    (b,2) int: the end node of beam k is node beams[k,1] translated by shifts[k] @ lattice;
    lattice (2,2) m: the two period vectors as rows."""

    nodes: np.ndarray
    beams: np.ndarray
    shifts: np.ndarray
    lattice: np.ndarray

    @property
    def area(self) -> float:
        """Plan area of the cell (m^2)."""
        return float(abs(np.linalg.det(self.lattice)))

    def beam_vectors(self) -> np.ndarray:
        """(b,2) vectors from each beam's start to its (translated) end, m."""
        return self.nodes[self.beams[:, 1]] + self.shifts @ self.lattice - self.nodes[self.beams[:, 0]]

    @property
    def length_per_area(self) -> float:
        """Beam length per unit area (1/m)."""
        return float(np.linalg.norm(self.beam_vectors(), axis=1).sum() / self.area)


def periodic_cell(tiling: str, l: float) -> PeriodicCell:
    """The smallest periodic cell of a regular tiling with edge length l (m): triangle (1 node,
    3 beams), square (1 node, 2 beams along x and y), hexagon (2 nodes, 3 beams)."""
    _check_tiling(tiling)
    _positive(l=l)
    if tiling == "triangle":
        lattice = l * np.array([[1.0, 0.0], [0.5, SQ3 / 2]])
        return PeriodicCell(np.zeros((1, 2)), np.zeros((3, 2), int), np.array([[1, 0], [0, 1], [-1, 1]]), lattice)
    if tiling == "square":
        return PeriodicCell(np.zeros((1, 2)), np.zeros((2, 2), int), np.array([[1, 0], [0, 1]]), l * np.eye(2))
    lattice = l * np.array([[SQ3, 0.0], [SQ3 / 2, 1.5]])
    nodes = l * np.array([[0.0, 0.0], [0.0, 1.0]])
    beams = np.array([[0, 1], [1, 0], [1, 0]])
    # node 1 at (0, l) joins node 0 below it and the translated nodes 0 at (+-sqrt3/2 l, 1.5 l)
    shifts = np.array([[0, 0], [0, 1], [-1, 1]])
    return PeriodicCell(nodes, beams, shifts, lattice)


def periodic_voronoi_cell(seeds: np.ndarray, lattice: np.ndarray) -> PeriodicCell:
    """The beams of the periodic Voronoi diagram of seeds (k,2) m repeated by lattice (2,2) (rows:
    period vectors): nodes are the Voronoi vertices folded into the cell, beams the Voronoi edges
    with their lattice shifts (each once). Needs at least one seed; seeds that coincide modulo the
    lattice raise InputError."""
    from scipy.spatial import Voronoi

    lattice = np.asarray(lattice, dtype=float)
    seeds = np.asarray(seeds, dtype=float).reshape(-1, 2)
    if lattice.shape != (2, 2) or abs(np.linalg.det(lattice)) < 1e-12 * max(np.abs(lattice).max(), 1e-300) ** 2:
        raise InputError("periodic Voronoi cell: lattice must be two independent period vectors (2,2)")
    inverse = np.linalg.inv(lattice)
    fractional = (seeds @ inverse) % 1.0
    if len(seeds) == 0:
        raise InputError("periodic Voronoi cell: no seeds")
    shifts = np.array([(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1)])
    copies = (fractional[None, :, :] + shifts[:, None, :]).reshape(-1, 2) @ lattice
    scale = np.sqrt(abs(np.linalg.det(lattice)))
    if len(np.unique(np.round(copies / (1e-9 * scale)), axis=0)) < len(copies):
        raise InputError("periodic Voronoi cell: two seeds coincide (modulo the lattice)")
    diagram = Voronoi(copies)
    k = len(seeds)
    central = np.arange(4 * k, 5 * k)          # shift (0, 0) is the fifth copy
    vertex_fraction = diagram.vertices @ inverse
    vertex_shift = np.floor(vertex_fraction + 1e-9).astype(np.int64)
    folded = (vertex_fraction - vertex_shift) % 1.0
    keys = np.round(folded / 1e-7).astype(np.int64) % int(round(1 / 1e-7))
    unique_keys, canonical = np.unique(keys, axis=0, return_inverse=True)
    canonical = canonical.ravel()
    node_positions = np.zeros((len(unique_keys), 2))
    node_positions[canonical] = folded @ lattice
    edges: dict[tuple[int, int, int, int], None] = {}
    for (p, q), ridge in zip(diagram.ridge_points, diagram.ridge_vertices):
        if -1 in ridge or not (np.isin(p, central) or np.isin(q, central)):
            continue
        a, b = ridge
        na, nb = int(canonical[a]), int(canonical[b])
        shift = vertex_shift[b] - vertex_shift[a]
        if na == nb and not shift.any():
            continue                          # a degenerate (zero-length) edge
        key = (na, nb, int(shift[0]), int(shift[1]))
        reverse = (nb, na, -int(shift[0]), -int(shift[1]))
        if reverse not in edges:
            edges[key] = None
    table = np.array(list(edges), dtype=np.int64).reshape(-1, 4)
    used, renumbered = np.unique(table[:, :2], return_inverse=True)   # vertices of the kept edges only
    return PeriodicCell(node_positions[used], renumbered.reshape(-1, 2), table[:, 2:], lattice)


# ----------------------------------------------------------------------------- homogenisation

@dataclass(frozen=True)
class Homogenised:
    """C (3,3) N/m and D (3,3) N m of a periodic cell (Voigt, engineering shear and twist), the
    cell area (m^2) and beam length per area (1/m)."""

    C: np.ndarray
    D: np.ndarray
    area: float
    length_per_area: float

    def as_tiling(self, name: str = "periodic", l: float = float("nan")) -> TilingStiffness:
        """The same figures as a TilingStiffness (for its moduli and equivalent thickness)."""
        return TilingStiffness(name, l, self.C, self.D)


def _frame_stiffness(nodes3: np.ndarray, beams: np.ndarray, EA: float, EI_out: float, EI_in: float,
                     GJ: float, elements_per_beam: int) -> tuple[sp.csr_matrix, int, np.ndarray]:
    """Global stiffness (6N,6N) of the frame elements of engine.structure.beam_elements for a planar patch with the
    beams' local z (strong-axis normal) = global z; returns K, N (nodes incl. internal ones) and
    their positions (N,3)."""
    from ..structure.beam_elements import (
        FrameModel,
        assemble,
        element_dofs,
        element_geometry,
        element_mesh,
        local_stiffness,
    )
    from ..structure.element_kernels import to_global

    # the rigidities as per-beam properties: E = EA and G = GJ with A = J = 1
    per_beam = np.ones(len(beams))
    model = FrameModel(nodes=nodes3, beams=beams, E=EA * per_beam, G=GJ * per_beam, A=per_beam,
                       Iy=EI_out / EA * per_beam, Iz=EI_in / EA * per_beam, J=per_beam,
                       up=np.array([0.0, 0.0, 1.0]), elements_per_beam=elements_per_beam)
    el = element_mesh(model)
    L, R = element_geometry(el, el.nodes)
    K_elements = to_global(R, local_stiffness(L, el))
    n_all = len(el.nodes)
    return assemble(K_elements, element_dofs(el.connectivity), 6 * n_all).tocsr(), n_all, el.nodes


def _macro_fields(points: np.ndarray) -> np.ndarray:
    """(6, N, 6) nodal displacements [ux uy uz rx ry rz] of the unit macro states at points (N,2):
    membrane eps_xx, eps_yy, gamma_xy (symmetric displacement gradient, no rotation) and bending
    kappa_xx, kappa_yy, 2 kappa_xy with w = -(kappa_xx x^2 + kappa_yy y^2 + 2 kappa_xy x y)/2
    (kappa = -w,ab), rx = dw/dy, ry = -dw/dx."""
    x, y = points[:, 0], points[:, 1]
    g = np.zeros((6, len(points), 6))
    g[0, :, 0] = x
    g[1, :, 1] = y
    g[2, :, 0], g[2, :, 1] = y / 2, x / 2
    for state, (kxx, kyy, kxy) in enumerate(((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 0.5)), start=3):
        g[state, :, 2] = -(kxx * x**2 + kyy * y**2 + 2 * kxy * x * y) / 2
        g[state, :, 3] = -(kyy * y + kxy * x)          # dw/dy
        g[state, :, 4] = kxx * x + kxy * y             # -dw/dx
    return g


def homogenise(cell: PeriodicCell, *, EA: float, EI: float, GJ: float, EI_in_plane: float | None = None,
               elements_per_beam: int = 1) -> Homogenised:
    """Effective C and D of a periodic cell of rigid-jointed beams by periodic homogenisation
    with the frame elements (EA N, EI out-of-plane and EI_in_plane (default EI) N m^2, GJ N m^2).

    Each beam end is a node of a patch (the cell's nodes and the translated copies its beams
    reach); the patch displacement is the macro field of each unit state plus a periodic
    fluctuation (copies share their cell node's fluctuation), which minimises the energy. One
    fluctuation translation is held (the rigid mode). Exact for the cubic beam elements because
    the macro fields are at most quadratic along each beam.
    """
    _positive(EA=EA, EI=EI, GJ=GJ)
    EI_in = EI if EI_in_plane is None else EI_in_plane
    _positive(EI_in_plane=EI_in)
    nodes = np.asarray(cell.nodes, dtype=float)
    beams = np.asarray(cell.beams, dtype=np.int64)
    shifts = np.asarray(cell.shifts, dtype=np.int64)
    n = len(nodes)
    if len(beams) == 0 or beams.min() < 0 or beams.max() >= n or shifts.shape != beams.shape:
        raise InputError("periodic cell: beams must be (b,2) node ids with (b,2) lattice shifts")
    # patch nodes: one per (cell node, shift) pair that occurs
    ends = np.concatenate([np.column_stack([beams[:, 0], np.zeros((len(beams), 2), int)]),
                           np.column_stack([beams[:, 1], shifts])])
    keys, inverse = np.unique(ends, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    patch_beams = np.column_stack([inverse[:len(beams)], inverse[len(beams):]])
    positions = nodes[keys[:, 0]] + keys[:, 1:] @ cell.lattice
    K, n_all, all_nodes = _frame_stiffness(np.column_stack([positions, np.zeros(len(positions))]), patch_beams,
                                           EA, EI, EI_in, GJ, elements_per_beam)
    n_patch = len(positions)
    # map: patch DOF = fluctuation DOF of its cell node; internal element nodes keep their own DOFs
    owner = np.concatenate([keys[:, 0], n + np.arange(n_all - n_patch)])
    rows = np.arange(6 * n_all)
    cols = (6 * owner[:, None] + np.arange(6)).ravel()
    n_fluct = 6 * (n + n_all - n_patch)
    M = sp.csr_matrix((np.ones(6 * n_all), (rows, cols)), shape=(6 * n_all, n_fluct))
    keep = np.setdiff1d(np.arange(n_fluct), [0, 1, 2])   # hold one node's fluctuation translations
    M = M[:, keep]
    K_reduced = (M.T @ K @ M).tocsc()
    macro = _macro_fields(all_nodes[:, :2]).reshape(6, -1).T      # (6 n_all, 6)
    rhs = -(M.T @ (K @ macro))
    lu = spla.splu(K_reduced)
    fluctuation = lu.solve(np.asarray(rhs))
    total = macro + M @ fluctuation
    energy = total.T @ (K @ total)                                  # (6,6) = 2 W_ij bilinear
    stiffness = 0.5 * (energy + energy.T) / cell.area
    C, D = stiffness[:3, :3], stiffness[3:, 3:]
    return Homogenised(C=C, D=D, area=cell.area, length_per_area=cell.length_per_area)
