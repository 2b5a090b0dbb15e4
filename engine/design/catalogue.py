"""Catalogues of circular hollow sections: the tubes a design may be sized from.

Shipped catalogues are CSV files in ``engine/data`` whose header lines name their source
(EN 10210-2 hot-finished and EN 10219-2 cold-formed steel CHS, EN 755-8 aluminium tubes). A
project may give its own CSV with at least ``diameter_mm`` and ``thickness_mm`` (and optionally
``name``); the properties are then computed from the nominal dimensions, as the standards do.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["Catalogue", "catalogue", "CATALOGUES", "chs_properties"]

DATA = Path(__file__).resolve().parents[1] / "data"

# name -> (file, manufacturing process); the process picks the buckling curve of EN 1993-1-1 Table 6.2
CATALOGUES: dict[str, tuple[str, str]] = {
    "EN 10210-2 CHS": ("en10210_chs.csv", "hot-finished"),
    "EN 10219-2 CHS": ("en10219_chs.csv", "cold-formed"),
    "EN 755-8 aluminium tubes": ("en755_aluminium_tubes.csv", "extruded"),
}


def chs_properties(diameter: np.ndarray, thickness: np.ndarray) -> dict[str, np.ndarray]:
    """Nominal properties of tubes of outer ``diameter`` and wall ``thickness`` (m): A (m^2), I, J
    (m^4), W_el, W_pl (m^3), i (m)."""
    D = np.asarray(diameter, dtype=float)
    t = np.asarray(thickness, dtype=float)
    d = D - 2 * t
    A = np.pi / 4 * (D**2 - d**2)
    I = np.pi / 64 * (D**4 - d**4)
    return {"A": A, "I": I, "J": 2 * I, "W_el": 2 * I / D, "W_pl": (D**3 - d**3) / 6, "i": np.sqrt(I / A)}


@dataclass(frozen=True, eq=False)
class Catalogue:
    """Tubes sorted by mass per metre (lightest first); arrays (s,) in SI: diameter, thickness (m),
    A (m^2), I (m^4), W_el, W_pl (m^3); names (s,); process: hot-finished, cold-formed or extruded
    (None for a project's own list: the material's buckling curve then applies); source: the
    header lines of the file."""

    name: str
    names: list[str]
    diameter: np.ndarray
    thickness: np.ndarray
    process: str | None
    source: str
    # chs_properties of the tubes, set by __post_init__
    A: np.ndarray = field(init=False, repr=False)
    I: np.ndarray = field(init=False, repr=False)
    J: np.ndarray = field(init=False, repr=False)
    W_el: np.ndarray = field(init=False, repr=False)
    W_pl: np.ndarray = field(init=False, repr=False)
    i: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        for key, value in chs_properties(self.diameter, self.thickness).items():
            object.__setattr__(self, key, value)

    def __len__(self) -> int:
        return len(self.names)

    def mass_per_length(self, density: float) -> np.ndarray:
        """kg/m of every tube of a material of ``density`` (kg/m^3)."""
        return self.A * density

    def up_to(self, max_diameter: float | None) -> "Catalogue":
        """The tubes of outer diameter at most ``max_diameter`` (m; all for None); InputError when none."""
        if max_diameter is None:
            return self
        keep = self.diameter <= max_diameter + 1e-9
        if not keep.any():
            raise InputError(f"section catalogue {self.name}: no tube of {1000 * max_diameter:g} mm or less",
                             hint=f"[design] max_diameter: at least {1000 * self.diameter.min():g} mm "
                                  "for this catalogue")
        return Catalogue(name=self.name, names=[n for n, k in zip(self.names, keep) if k],
                         diameter=self.diameter[keep], thickness=self.thickness[keep], process=self.process,
                         source=self.source)

    def index(self, diameter: float, thickness: float) -> int | None:
        """The tube of these dimensions (m, to 0.01 mm), or None."""
        hit = np.flatnonzero((np.abs(self.diameter - diameter) < 1e-5) & (np.abs(self.thickness - thickness) < 1e-5))
        return int(hit[0]) if len(hit) else None


def _name(diameter_mm: float, thickness_mm: float) -> str:
    return f"CHS {diameter_mm:g}x{thickness_mm:g}"


def catalogue(spec: str | Path, *, base_dir: Path | None = None) -> Catalogue:
    """A shipped catalogue by name (CATALOGUES), or a CSV file (relative to ``base_dir``)."""
    if str(spec) in CATALOGUES:
        file, process = CATALOGUES[str(spec)]
        path, name = DATA / file, str(spec)
    else:
        path = Path(spec)
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        process, name = None, path.stem
        if not path.is_file():
            raise InputError(f"section catalogue {spec!r} is neither a shipped catalogue nor a file",
                             hint=f"[design] catalogue: one of {', '.join(repr(k) for k in CATALOGUES)}, or a CSV "
                                  "with diameter_mm and thickness_mm columns")
    lines = path.read_text(encoding="utf-8").splitlines()
    source = "\n".join(line.lstrip("# ") for line in lines if line.startswith("#"))
    rows = list(csv.DictReader(line for line in lines if line.strip() and not line.startswith("#")))
    try:
        D = np.array([float(r["diameter_mm"]) for r in rows]) / 1000
        t = np.array([float(r["thickness_mm"]) for r in rows]) / 1000
    except (KeyError, TypeError, ValueError):
        raise InputError(f"section catalogue {path}: every row needs numbers in diameter_mm and thickness_mm",
                         hint="[design] catalogue: a CSV file whose header has diameter_mm,thickness_mm") from None
    if not len(rows) or np.any(D <= 0) or np.any(t <= 0) or np.any(2 * t >= D):
        raise InputError(f"section catalogue {path}: needs at least one tube, each with 0 < 2 x thickness < diameter",
                         hint="[design] catalogue: correct the file's rows")
    names = [r.get("name") or _name(1000 * d, 1000 * w) for r, d, w in zip(rows, D, t)]
    order = np.lexsort((D, chs_properties(D, t)["A"]))
    return Catalogue(name=name, names=[names[i] for i in order], diameter=D[order], thickness=t[order],
                     process=process, source=source)
