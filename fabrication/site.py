"""The site origin of the fabrication files.

A roof drawn in site or survey coordinates (a grid-shell 5 000 km from the coordinate origin, as a
mesh exported from a georeferenced model comes) is built in a local frame: at millimetres, such
coordinates leave OCCT's modelling tolerance (1e-7 mm) under the spacing of doubles there (1e-6 mm
at 5e9 mm), so its faces are no longer planar to it, and an STL's single-precision coordinates
would round by metres. The fabrication files then hold coordinates from ``site_origin_m`` (whole
metres: the plan centre of the grid and its lowest point), which fabrication.json states; the IFC
model places its site there, so BIM tools show the roof where it stands.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FAR_FROM_ORIGIN_M", "site_origin_m"]

#: A grid with a node farther than this from the coordinate origin (m) is built in a local frame;
#: nearer, its coordinates are kept (at 1 km an STL's single precision still resolves 0.06 mm).
FAR_FROM_ORIGIN_M = 1000.0


def site_origin_m(nodes: np.ndarray) -> np.ndarray:
    """(3,) where the fabrication files' frame starts, m: zero for a grid within FAR_FROM_ORIGIN_M
    of the origin, else the centre of its plan and its lowest point, rounded to whole metres."""
    nodes = np.asarray(nodes, dtype=float)
    if not len(nodes) or np.linalg.norm(nodes, axis=1).max() <= FAR_FROM_ORIGIN_M:
        return np.zeros(3)
    low, high = nodes.min(axis=0), nodes.max(axis=0)
    return np.round([0.5 * (low[0] + high[0]), 0.5 * (low[1] + high[1]), low[2]])
