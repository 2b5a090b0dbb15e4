"""The settings of the fabrication modules that load pandas or shapely (beams, panels, sheets).

They live apart from those modules so that the project schema (workflow.config), which builds
them and reads their defaults, loads neither: a run whose stages are all cached does not. The
modules re-export them (``fabrication.beams.BeamSettings``, ``fabrication.panels.PanelSettings``,
``fabrication.nesting_sheets.SheetSettings``). Lengths in mm, as in every fabrication module.
"""

from __future__ import annotations

from dataclasses import dataclass

from engine.errors import InputError

__all__ = ["BeamSettings", "PanelSettings", "SheetSettings", "check_ranges"]


def check_ranges(settings: object, what: str, *, positive: tuple[str, ...] = (),
                 zero_or_positive: tuple[str, ...] = ()) -> None:
    """Refuse settings whose fields named in ``positive`` are not above zero, or those in
    ``zero_or_positive`` below it (NaN fails both; None, a setting left unset, passes), with an
    InputError naming ``what`` ("panel", ...), the field and the fix."""
    for name, allowed, fix in [*((n, "positive", "above zero") for n in positive),
                               *((n, "zero or positive", "to zero or more") for n in zero_or_positive)]:
        value = getattr(settings, name)
        if value is None or (value > 0 if allowed == "positive" else value >= 0):
            continue
        raise InputError(f"{what} setting {name} = {value!r} must be {allowed}", hint=f"set {name} {fix}")


@dataclass(frozen=True, kw_only=True)
class BeamSettings:
    """Profile and material names, density (kg/m^3), stock bar length and saw kerf (mm), section
    area (m^2) for the mass, and the outer size (mm) for the solids and set-backs."""

    profile_name: str
    material_name: str
    density: float
    stock_length_mm: float = 6000.0
    kerf_mm: float = 3.0
    area_m2: float = 0.0
    outer_size_mm: float = 0.0

    def __post_init__(self) -> None:
        check_ranges(self, "beam", positive=("density", "stock_length_mm"),
                     zero_or_positive=("kerf_mm", "area_m2", "outer_size_mm"))


#: The panel directions that can run along a sheet's grain (PanelSettings.grain): a plan axis, or
#: the fall line (-z in the panel's plane); "none" keeps no grain.
GRAIN_DIRECTIONS: dict[str, tuple[float, float, float] | None] = {
    "none": None, "x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "slope": (0.0, 0.0, -1.0)}


@dataclass(frozen=True, kw_only=True)
class PanelSettings:
    """Panel material and cutting settings (lengths in mm, density in kg/m^3). ``grain``: the
    direction of each panel laid along the sheets' grain, their length (x): "none" (the nesting
    turns panels freely), "x" or "y" (that plan axis, projected onto the panel) or "slope" (the
    panel's fall line); a panel is then turned only by a half turn from there."""

    thickness_mm: float = 3.0
    material_name: str = "acrylic"
    density: float = 1190.0
    clearance_mm: float = 2.0
    hole_diameter_mm: float = 0.0
    hole_inset_mm: float = 10.0
    planarity_tolerance_mm: float = 2.0
    split_nonplanar: bool = False
    grain: str = "none"

    def __post_init__(self) -> None:
        check_ranges(self, "panel", positive=("thickness_mm", "density"),
                     zero_or_positive=("clearance_mm", "hole_diameter_mm", "hole_inset_mm", "planarity_tolerance_mm"))
        if self.grain not in GRAIN_DIRECTIONS:
            raise InputError(f"panel setting grain = {self.grain!r} must be one of {', '.join(GRAIN_DIRECTIONS)}",
                             hint=f"set grain to one of {', '.join(GRAIN_DIRECTIONS)}")


@dataclass(frozen=True, kw_only=True)
class SheetSettings:
    """Sheet size, gap between parts, border margin (mm) and whether parts may rotate."""

    width_mm: float = 1200.0
    height_mm: float = 600.0
    spacing_mm: float = 4.0
    margin_mm: float = 10.0
    rotations: bool = True

    def __post_init__(self) -> None:
        check_ranges(self, "sheet", positive=("width_mm", "height_mm"), zero_or_positive=("spacing_mm", "margin_mm"))
        if 2 * self.margin_mm >= min(self.width_mm, self.height_mm):
            raise InputError(f"sheet margin {self.margin_mm} mm leaves no room on a "
                             f"{self.width_mm} x {self.height_mm} mm sheet")
