"""Section sizing: the lightest grouped tubes of a catalogue that pass the member checks, the
deflection limit and the linear buckling limit.

The iteration of the fully stressed design, with the stiffness constraints as a floor on the
second moment of area:
1. analyse the current design (linear static ULS and SLS, linear buckling);
2. per beam, the lightest tube that passes every member check under those forces, has at least
   the beam's floor on I, and (after ``free_rounds``) is no lighter than the beam's last tube, so
   that the iteration cannot cycle;
3. where the deflection or lambda_LB misses its limit, the floors on I grow where the strain
   energy of the SLS displacements or of the first buckling mode is, per kg (``_stiffening``);
4. group the beams by that demand into at most ``groups`` tubes of the least mass (an exact
   partition of the beams sorted by demand, each group the lightest tube all of its beams pass);
5. repeat until the grouped design is unchanged and passes under its own forces.
It stops with a reason where no catalogue tube passes a beam.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .catalogue import Catalogue

__all__ = ["DesignState", "Design", "size_sections", "group_by_demand"]


@dataclass(frozen=True, kw_only=True)
class DesignState:
    """A design's linear response: utilisation (b, s) of every beam with every catalogue tube
    under this design's forces, deflection (m, SLS), lambda_LB (None: nothing in compression), and
    each beam's share (b,) of the strain energy of the SLS displacements and of the first buckling
    mode (None: stiffen uniformly)."""

    utilisation: np.ndarray
    deflection: float
    lambda_LB: float | None
    deflection_energy: np.ndarray | None = None
    buckling_energy: np.ndarray | None = None


@dataclass(frozen=True, kw_only=True)
class Design:
    """Per beam its tube (index into the catalogue); iterations (list of dicts); converged; reason
    when not; the last state's utilisation of the chosen tubes."""

    tube: np.ndarray
    iterations: list[dict] = field(default_factory=list)
    converged: bool = True
    reason: str | None = None
    failing_beam: int | None = None


def group_by_demand(required: np.ndarray, feasible: np.ndarray, lengths: np.ndarray, mass_per_length: np.ndarray,
                    groups: int) -> np.ndarray:
    """Tube per beam: at most ``groups`` distinct tubes of the least total mass.

    required (b,) the lightest feasible tube of each beam; feasible (b, s) which tubes each beam
    may take; tubes sorted by mass. The beams sorted by required tube split into contiguous
    groups (dynamic programming over the distinct demands); a group takes the lightest tube that
    is feasible for all of its beams.
    """
    levels, level_of = np.unique(required, return_inverse=True)
    m, s = len(levels), feasible.shape[1]
    if m <= groups:
        return required.copy()
    infeasible = np.zeros((m + 1, s), dtype=int)
    np.add.at(infeasible[1:], level_of, ~feasible)
    infeasible = np.cumsum(infeasible, axis=0)
    length_by_level = np.bincount(level_of, weights=lengths, minlength=m)
    cumulative_length = np.concatenate([[0.0], np.cumsum(length_by_level)])
    tube = np.full((m, m), -1, dtype=int)
    cost = np.full((m, m), np.inf)
    for a in range(m):
        for b in range(a, m):
            ok = (infeasible[b + 1] - infeasible[a]) == 0
            if ok.any():
                c = int(np.argmax(ok))
                tube[a, b] = c
                cost[a, b] = mass_per_length[c] * (cumulative_length[b + 1] - cumulative_length[a])
    best = np.full((groups + 1, m + 1), np.inf)
    cut = np.zeros((groups + 1, m + 1), dtype=int)
    best[0, 0] = 0.0
    for k in range(1, groups + 1):
        for j in range(1, m + 1):
            options = best[k - 1, :j] + cost[:j, j - 1]
            i = int(np.argmin(options))
            best[k, j], cut[k, j] = options[i], i
    k = int(np.argmin(best[1:, m])) + 1
    tube_of_level = np.zeros(m, dtype=int)
    j = m
    while j > 0:
        i = cut[k, j]
        tube_of_level[i:j] = tube[i, j - 1]
        j, k = i, k - 1
    return tube_of_level[level_of]


def _stiffening(state: DesignState, tube: np.ndarray, lengths: np.ndarray, mass: np.ndarray,
                deflection_limit: float, required_load_factor: float | None) -> np.ndarray:
    """(b,) factor on each beam's I for the stiffness limits missed. Where the strain energy shares
    w are known, the missing ratio f goes to the beams of most energy per kg (the Rayleigh quotient
    grows by sum w_i s_i): s_i = 1 + (f - 1) e_i / sum_j w_j e_j, e_i = w_i / m_i; else uniform."""
    scale = np.ones(len(tube))
    misses = [(state.deflection / deflection_limit, state.deflection_energy)]
    if required_load_factor is not None and state.lambda_LB is not None:
        misses.append((required_load_factor / max(state.lambda_LB, 1e-12), state.buckling_energy))
    for ratio, shares in misses:
        if ratio <= 1.0:
            continue
        ratio *= 1.02
        if shares is None or not np.isfinite(shares).all() or shares.sum() <= 0:
            scale = np.maximum(scale, ratio)
            continue
        density = shares / (mass[tube] * lengths)
        scale = np.maximum(scale, 1.0 + (ratio - 1.0) * density / float((shares * density).sum()))
    return scale


def size_sections(analyse: Callable[[np.ndarray], DesignState], catalogue: Catalogue, lengths: np.ndarray,
                  density: float, *, start: np.ndarray, groups: int, deflection_limit: float,
                  required_load_factor: float | None, stiffness_floor: np.ndarray | None = None,
                  max_iterations: int = 25, free_rounds: int = 4,
                  progress: Callable[[str], None] | None = None) -> Design:
    """Size every beam from ``catalogue`` (see the module docstring). analyse(tube indices (b,))
    gives the state of a design; start (b,) its first design; stiffness_floor (b,) m^4, an I
    each beam must reach (the non-linear rounds raise it); required_load_factor None skips the
    lambda_LB limit."""
    lengths = np.asarray(lengths, dtype=float)
    mass = catalogue.mass_per_length(density)
    I_floor = np.zeros(len(lengths)) if stiffness_floor is None else np.asarray(stiffness_floor, float).copy()
    tube = np.asarray(start, dtype=int).copy()
    floor_tube = np.zeros(len(lengths), dtype=int)
    iterations: list[dict] = []
    for iteration in range(1, max_iterations + 1):
        state = analyse(tube)
        chosen = state.utilisation[np.arange(len(tube)), tube]
        passes = bool(chosen.max() <= 1.0 and state.deflection <= deflection_limit
                      and (required_load_factor is None or state.lambda_LB is None
                           or state.lambda_LB >= required_load_factor)
                      and np.all(catalogue.I[tube] >= I_floor * (1 - 1e-9)))
        record = {"iteration": iteration, "mass_kg": float((mass[tube] * lengths).sum()),
                  "max_utilisation": float(chosen.max()), "deflection_m": state.deflection,
                  "lambda_LB": state.lambda_LB, "tubes": int(len(np.unique(tube)))}
        iterations.append(record)
        if progress:
            progress(f"sizing {iteration}: {record['mass_kg']:.0f} kg, utilisation {record['max_utilisation']:.2f}")
        stiffer = max(state.deflection / deflection_limit,
                      1.0 if required_load_factor is None or state.lambda_LB is None
                      else required_load_factor / max(state.lambda_LB, 1e-12))
        if stiffer > 1.0:
            scale = _stiffening(state, tube, lengths, mass, deflection_limit, required_load_factor)
            # never past the stiffest tube: a limit it cannot meet is said at the end
            I_floor = np.minimum(np.maximum(I_floor, scale * catalogue.I[tube]), catalogue.I.max())
        if iteration > free_rounds:
            floor_tube = np.maximum(floor_tube, tube)
        allowed = ((catalogue.I[None, :] >= I_floor[:, None] * (1 - 1e-9))
                   & (np.arange(len(catalogue))[None, :] >= floor_tube[:, None]))
        feasible = allowed & (state.utilisation <= 1.0)
        has = np.any(feasible, axis=1)  # an array: ndarray.any's stubs allow a scalar for any axis
        if not has.all():
            # no tube passes these beams under this design's forces: they take their least utilised
            # tube, and the iteration goes on (stiffer neighbours may take load off them)
            least = np.argmin(np.where(allowed, state.utilisation, np.inf), axis=1)
            within = allowed & (state.utilisation <= state.utilisation[np.arange(len(tube)), least][:, None])
            feasible = np.where(has[:, None], feasible, within)
        required = np.argmax(feasible, axis=1)
        grouped = group_by_demand(required, feasible, lengths, mass, groups)
        if np.array_equal(grouped, tube) and (passes or not has.all() or stiffer > 1.0):
            if passes:
                return Design(tube=tube, iterations=iterations)
            if not has.all():
                beam = int(np.flatnonzero(~has)[np.argmax(chosen[~has])])
                return Design(tube=tube, iterations=iterations, converged=False, failing_beam=beam,
                              reason="no catalogue tube passes this beam")
            return Design(tube=tube, iterations=iterations, converged=False,
                          reason="no catalogue tube is stiff enough for the deflection or buckling limit")
        tube = grouped
    return Design(tube=tube, iterations=iterations, converged=False,
                  reason=f"the sizing did not settle in {max_iterations} iterations")
