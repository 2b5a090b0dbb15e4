"""The project file (TOML), validated by pydantic.

One section per concern: ``project``, ``surface``, ``supports`` (a list), ``loads``
(cases and combinations), ``material``, ``section``, and one section per stage
(``shell``, ``field``, ``remesh``, ``optimize``, ``analysis``, ``fabrication``,
``report``). Quantities may carry units; bare numbers are SI. Unknown keys are errors.
``load_project`` raises ``ConfigError`` naming the file, the key, the value and what is
allowed.

The sections of the engine's and fabrication's settings (field, remesh, optimize, analysis,
fabrication.joints/beams/panels/sheets) build them with ``to_settings()``: metres become the
fabrication's millimetres there and nowhere else, and where a setting has a default in its
dataclass the section's default is read from it (``_default_of``), so the two cannot drift.
Choices use the engine's own types (SizeMap, JointKind, ...). Every value a project file gives is
checked here, naming its key; the dataclasses' own checks stay for callers of the engine and of
fabrication that bypass the project file.
"""

from __future__ import annotations

import dataclasses
import functools
import re
import tomllib
import types
import typing
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, field_validator, model_validator

from engine.design.en1993 import ChecksMethod
from engine.errors import GridshellError, InputError
from engine.remeshing.field import AnisotropyMap, FieldSettings, Orientation, SizeMap
from engine.remeshing.grids import GridKind
from engine.remeshing.optimize import OptimizeSettings
from engine.remeshing.voronoi import RemeshSettings
from engine.structure.loads import GRAVITY
from engine.structure.protocol import TOLERABLE_DEFLECTION_RATIO, ImperfectionShape, ProtocolSettings
from engine.structure.supports import restraint_flags
from fabrication.joints import JointKind, JointSettings
from fabrication.limits import BuildLimits
from fabrication.settings import BeamSettings, PanelSettings, SheetSettings

from .surface_io import FILE_UNITS_M, file_scale_m
from .units import AreaLoad, Density, Force, Length, Stress

__all__ = ["ConfigError", "Project", "load_project", "parse_project", "read_toml", "project_from_surface",
           "check_inputs", "unusual_values", "STAGE_SECTIONS", "KEYS_LEFT_OUT_AT_DEFAULT", "stage_sections", "MM",
           "DEFAULT_CELLS"]

MM = 1000.0
"""Millimetres per metre: the project is in metres, fabrication's settings in millimetres."""
DEFAULT_CELLS = 120
"""The remesher's size target when [remesh] gives none."""


class ConfigError(GridshellError):
    """Raised when a project file is missing, is not TOML, or fails validation."""


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _default_value(settings: type, name: str, per: float = 1.0) -> Any:
    """The default of field ``name`` of the settings dataclass ``settings``, divided by ``per``
    (MM: its millimetres in the project's metres)."""
    default = next(f.default for f in dataclasses.fields(settings) if f.name == name)
    return default if per == 1.0 else default / per


def _default_of(settings: type, name: str, *, per: float = 1.0, **constraints: Any) -> Any:
    """A schema field whose default is the one of the settings it becomes (see ``_default_value``),
    with the schema's ``constraints`` (ge, gt, ...)."""
    return Field(_default_value(settings, name, per), **constraints)


Vector3 = Annotated[list[float], Field(min_length=3, max_length=3)]


class ProjectInfo(_Section):
    name: str = "gridshell"
    description: str = ""
    author: str = ""


SurfaceTemplate = Literal["mockup", "cap", "vault", "hypar", "courtyard"]


class SurfaceConfig(_Section):
    """Either ``file`` (OBJ, PLY, STL, OFF, 3DM; relative to the project file) or ``template``."""

    file: str | None = None
    file_units: Literal["m", "cm", "mm", "in", "ft"] = "m"
    """The unit the file's numbers are in. A Rhino .3dm states its own (its model units), which are
    used instead."""
    up_axis: Literal["z", "y", "x", "-z", "-y", "-x"] | None = None
    """The file's up axis, turned to +z before anything else (supports' boxes and planes are then in
    z-up coordinates). Unset: z, and a file that stands on its side is refused with a hint."""
    template: SurfaceTemplate | None = None
    parameters: dict[str, float | int | str] = Field(default_factory=dict)
    merge_tolerance: Length | None = None

    @model_validator(mode="after")
    def _one_source(self) -> "SurfaceConfig":
        if (self.file is None) == (self.template is None):
            raise ValueError("give exactly one of 'file' (a mesh file) or 'template' "
                             "(mockup, cap, vault, hypar, courtyard)")
        if self.file is not None and self.parameters:
            raise ValueError("'parameters' apply to templates only, not to a surface file")
        if self.template is not None and self.up_axis is not None:
            raise ValueError("'up_axis' applies to a surface file only; templates are made with z up")
        return self


class SupportSpec(_Section):
    """One support selection and its restraint.

    select: boundary | loop (with ``loop``) | plane (``point``, ``normal``, ``tolerance``) |
    box (``lower``, ``upper``) | flagged | ids (``ids``) | nearest (``points``).
    restraint: pinned | fixed | roller_x | roller_y | roller_z | six 0/1 flags.
    """

    select: Literal["boundary", "loop", "plane", "box", "flagged", "ids", "nearest"]
    restraint: str | list[int] = "pinned"
    loop: int | None = None
    point: list[Length] | None = None
    normal: list[float] | None = None
    tolerance: Length = 1e-3
    lower: list[Length] | None = None
    upper: list[Length] | None = None
    ids: list[int] | None = None
    points: list[list[Length]] | None = None

    @field_validator("restraint")
    @classmethod
    def _restraint(cls, value: str | list[int]) -> str | list[int]:
        restraint_flags(value)
        return value

    @model_validator(mode="after")
    def _required(self) -> "SupportSpec":
        needs = {"loop": ["loop"], "plane": ["point", "normal"], "box": ["lower", "upper"],
                 "ids": ["ids"], "nearest": ["points"]}.get(self.select, [])
        missing = [k for k in needs if getattr(self, k) is None]
        if missing:
            raise ValueError(f"select = '{self.select}' needs {', '.join(missing)}")
        for key in ("point", "normal", "lower", "upper"):
            value = getattr(self, key)
            if value is not None and len(value) != 3:
                raise ValueError(f"'{key}' must have 3 values [x, y, z]")
        if self.points is not None and any(len(p) != 3 for p in self.points):
            raise ValueError("'points' must be a list of [x, y, z]")
        return self


class PointLoadSpec(_Section):
    """A point load at ``node`` (0-based id) or at the node nearest to ``nearest`` [x, y, z].

    ``force`` is [Fx, Fy, Fz] in N (units allowed); ``moment`` optional [Mx, My, Mz] in N m.
    """

    node: int | None = None
    nearest: list[Length] | None = None
    force: list[Force] = Field(min_length=3, max_length=3)
    moment: list[float] = Field(default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3)

    @model_validator(mode="after")
    def _where(self) -> "PointLoadSpec":
        if (self.node is None) == (self.nearest is None):
            raise ValueError("give exactly one of 'node' or 'nearest'")
        return self


class LoadCaseSpec(_Section):
    """A load case. ``self_weight``: a factor on the beams' own weight; ``panels``: a factor on the
    panels' ([fabrication.panels] thickness x density x g, downward per true area, none where
    panels are off). Area loads: a single value is a downward load, or [qx, qy, qz] (N/m^2)."""

    self_weight: float = 0.0
    panels: float = 0.0
    area_true: AreaLoad | list[AreaLoad] = 0.0
    area_plan: AreaLoad | list[AreaLoad] = 0.0
    points: list[PointLoadSpec] = Field(default_factory=list)

    @field_validator("area_true", "area_plan")
    @classmethod
    def _vector(cls, value: float | list[float]) -> float | list[float]:
        if isinstance(value, list) and len(value) != 3:
            raise ValueError("an area load is one downward value or [qx, qy, qz]")
        return value

    def area_vector(self, which: str) -> list[float]:
        value = getattr(self, which)
        return list(value) if isinstance(value, list) else [0.0, 0.0, -float(value)]


class CombinationSpec(_Section):
    limit_state: Literal["ULS", "SLS"]
    factors: dict[str, float]


class LoadsConfig(_Section):
    cases: dict[str, LoadCaseSpec] = Field(
        default_factory=lambda: {"dead": LoadCaseSpec(self_weight=1.0, panels=1.0)})
    combinations: dict[str, CombinationSpec] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _known_cases(self) -> "LoadsConfig":
        for name, combo in self.combinations.items():
            unknown = sorted(set(combo.factors) - set(self.cases))
            if unknown:
                raise ValueError(f"combination '{name}' uses unknown load case(s) {unknown}; "
                                 f"defined cases: {sorted(self.cases)}")
        return self

    def combination_names(self, limit_state: str) -> list[str]:
        return [n for n, c in self.combinations.items() if c.limit_state == limit_state]

    @property
    def carries_panels(self) -> bool:
        """Whether some case carries the panels' own weight (a ``panels`` factor over 0)."""
        return any(case.panels > 0 for case in self.cases.values())

    @property
    def self_weight_only(self) -> bool:
        """Whether the grid-shell's own weight (beams, and panels where a case has them) is the only
        load: no case has an area or a point load (the default when a project gives no [loads])."""
        return not any(case.area_vector("area_true") != [0.0, 0.0, 0.0]
                       or case.area_vector("area_plan") != [0.0, 0.0, 0.0] or case.points
                       for case in self.cases.values())


SELF_WEIGHT_NOTE = ("the loads are the beams' own weight alone: the verdicts leave out the panels, finishes, snow "
                    "and wind; add them as [loads.cases] (README, Project files)")
"""What run and validate say of a project whose only load is the beams' self-weight."""
OWN_WEIGHT_NOTE = ("the loads are the grid-shell's own weight alone, its beams' and its panels': the verdicts leave "
                   "out finishes, snow and wind; add them as [loads.cases] (README, Project files)")
"""What run and validate say of a project loaded by the beams' and the panels' own weight only."""


class MaterialConfig(_Section):
    """Beam material: a named one (steel_s235, steel_s355, aluminium_6063, aluminium_6061,
    glulam_gl24h, pla, petg) with optional overrides of its properties."""

    name: str = "steel_s355"
    E: Stress | None = None
    G: Stress | None = None
    density: Density | None = None
    yield_strength: Stress | None = None


class SectionConfig(_Section):
    """Beam cross-section: circular_hollow (diameter, thickness), rectangular_hollow (height,
    width, thickness), solid_round (diameter), solid_rectangle (height, width)."""

    kind: Literal["circular_hollow", "rectangular_hollow", "solid_round", "solid_rectangle"] = "circular_hollow"
    diameter: Length | None = None
    thickness: Length | None = None
    height: Length | None = None
    width: Length | None = None

    @model_validator(mode="after")
    def _dimensions(self) -> "SectionConfig":
        needs = {"circular_hollow": ["diameter", "thickness"], "rectangular_hollow": ["height", "width", "thickness"],
                 "solid_round": ["diameter"], "solid_rectangle": ["height", "width"]}[self.kind]
        missing = [k for k in needs if getattr(self, k) is None]
        if missing:
            raise ValueError(f"section kind '{self.kind}' needs {', '.join(missing)}")
        for k in needs:
            if getattr(self, k) <= 0:
                raise ValueError(f"section {k} must be positive")
        if "thickness" in needs:
            sides = ["diameter"] if self.kind == "circular_hollow" else ["height", "width"]
            side = min(sides, key=lambda k: getattr(self, k))
            if 2 * self.thickness >= getattr(self, side):
                raise ValueError(f"thickness = {_mm(self.thickness)} is not less than half of {side} = "
                                 f"{_mm(getattr(self, side))}: the wall must be thinner than half the "
                                 f"{'tube' if side == 'diameter' else 'section'}; lower thickness or raise {side}")
        return self

    @field_validator("diameter", "height", "width", "thickness", mode="before")
    @classmethod
    def _bare_metres(cls, value: Any, info) -> Any:
        """A bare number is metres: a section dimension over 2 m (a thickness over 0.2 m) is a
        millimetre value written without its unit."""
        limit = 0.2 if info.field_name == "thickness" else 2.0
        if isinstance(value, (int, float)) and not isinstance(value, bool) and value > limit:
            what = {"thickness": "wall", "diameter": "tube"}.get(info.field_name, "section")
            raise ValueError(f'bare numbers are metres, so this is a {value:g} m {what}; write "{value:g} mm"')
        return value

    def dimensions(self) -> dict[str, float]:
        """The section's dimensions (m) by name, in the order a designation reads them: a tube's
        D x t, a rectangle's h x b (x t)."""
        return {k: getattr(self, k) for k in ("diameter", "height", "width", "thickness")
                if getattr(self, k) is not None}

    def size_key(self) -> str:
        """Where a fix names the section's outer size: ``[section] diameter``, or height and width."""
        return "[section] diameter" if self.kind in ("circular_hollow", "solid_round") else "[section] height, width"

    def outer_size_mm(self) -> float:
        """The beam's largest outer dimension in mm (tube or rod diameter, or the section height or width)."""
        return MM * (self.diameter if self.diameter is not None else max(self.height or 0.0, self.width or 0.0))


def _mm(value: float) -> str:
    return f"{value * 1000:g} mm"


class ShellConfig(_Section):
    """Continuous-shell analysis of the surface (METHOD.md 1). thickness None: span / 100.
    max_triangles: a surface with more triangles is analysed on a coarser copy of about that many, and
    one of slivers (a coarse CAD tessellation) on a well-shaped copy (engine.remeshing.analysis_mesh),
    its forces carried back to the surface."""

    thickness: Length | None = None
    E: Stress = 210e9
    nu: float = Field(0.3, ge=0.0, lt=0.5)
    density: Density = 7850.0
    combination: str | None = None
    max_triangles: int = Field(50_000, ge=1_000)


class SymmetryPlane(_Section):
    point: list[Length] = Field(min_length=3, max_length=3)
    normal: list[float] = Field(min_length=3, max_length=3)


class FieldConfig(_Section):
    """Guiding field (METHOD.md 2): D = max_size_ratio, A = max_aspect. orientation: cells elongated
    "along" the larger principal force (the thesis) or "across" it (turned by 90 degrees)."""

    max_size_ratio: float = _default_of(FieldSettings, "max_size_ratio", ge=1.0, le=20.0)
    max_aspect: float = _default_of(FieldSettings, "max_aspect", ge=1.0, le=20.0)
    size_map: SizeMap = _default_of(FieldSettings, "size_map")
    anisotropy_map: AnisotropyMap = _default_of(FieldSettings, "anisotropy_map")
    opposite_sign_anisotropy: float = _default_of(FieldSettings, "opposite_sign_anisotropy", ge=1.0)
    clamp_percentiles: tuple[float, float] = _default_of(FieldSettings, "clamp_percentiles")
    smoothing_iterations: int = _default_of(FieldSettings, "smoothing_iterations", ge=0)
    direction_smoothing_iterations: int = _default_of(FieldSettings, "direction_smoothing_iterations", ge=0)
    symmetry_planes: list[SymmetryPlane] = Field(default_factory=list, max_length=2)
    orientation: Orientation = _default_of(FieldSettings, "orientation")

    @field_validator("clamp_percentiles")
    @classmethod
    def _percentiles(cls, value: tuple[float, float]) -> tuple[float, float]:
        low, high = value
        if not 0.0 <= low < high <= 100.0:
            raise ValueError("give [low, high] percentiles of the force level with 0 <= low < high <= 100")
        return value

    def to_settings(self) -> FieldSettings:
        """The engine's field settings."""
        return FieldSettings(
            max_size_ratio=self.max_size_ratio, max_aspect=self.max_aspect, size_map=self.size_map,
            anisotropy_map=self.anisotropy_map, opposite_sign_anisotropy=self.opposite_sign_anisotropy,
            clamp_percentiles=tuple(self.clamp_percentiles), smoothing_iterations=self.smoothing_iterations,
            direction_smoothing_iterations=self.direction_smoothing_iterations,
            symmetry_planes=tuple((tuple(p.point), tuple(p.normal)) for p in self.symmetry_planes),
            orientation=self.orientation)


class RemeshConfig(_Section):
    """Size target: one of n_cells, mean_beam_length, total_length (default 120 cells).
    lloyd_iterations caps the Lloyd steps between clusterings at each level (the remesher takes at
    most 20 at its coarsest level and 3 at finer ones; 0: the clustering of the initial lattice).
    coarsen_for_joints: remesh with fewer cells when most beams are shorter than their joints take
    (a grid_coarsened finding says so); false keeps the cells asked for, and the joints clash.
    statics_rounds: 1 remeshes under the shell's field; N > 1 then rebuilds the field N - 1 times from
    the grid's own beam forces (linear, ULS) and remeshes with the same size target.
    grid: which grid the remesh builds (engine.remeshing.grids.GridKind): "voronoi" (the statics-aware grid,
    the default), "isotropic" (the same remesher under a uniform field, Voro(1,1): the control, it
    is optimised like the Voronoi grid), or a lattice clipped to the plan and lifted, not optimised:
    "quad" (squares along the plan's principal axes), "quad45" (at 45 degrees to them),
    "triangular", "statics_quad" (squares along the field's dominant direction, lines graded by
    its size). A lattice meets total_length within 1 %; n_cells or mean_beam_length give it the
    length of a regular lattice of that many cells, or of that spacing, over the surface's area
    (engine.remeshing.grids.lattice_total_length); coarsen_for_joints does not apply to lattices.
    workers: processes that cluster a small grid's starts side by side (default: one per core; the
    grid is the same with any count)."""

    n_cells: int | None = Field(None, ge=4)
    mean_beam_length: Length | None = Field(None, gt=0.0)
    total_length: Length | None = Field(None, gt=0.0)
    lloyd_iterations: int = _default_of(RemeshSettings, "lloyd_iterations", ge=0)
    seed: int = _default_of(RemeshSettings, "seed")
    coarsen_for_joints: bool = True
    statics_rounds: int = Field(1, ge=1, le=10)
    grid: GridKind = GridKind.VORONOI
    workers: int | None = Field(None, ge=1)

    @model_validator(mode="after")
    def _one_target(self) -> "RemeshConfig":
        given = [k for k in ("n_cells", "mean_beam_length", "total_length") if getattr(self, k) is not None]
        if len(given) > 1:
            raise ValueError(f"give one size target, not {', '.join(given)}")
        return self

    def to_settings(self, symmetry_planes: tuple = ()) -> RemeshSettings:
        """The engine's remesh settings: the size target given, else DEFAULT_CELLS cells; the grid is
        made symmetric about ``symmetry_planes`` ((point, normal) pairs: [field] symmetry_planes)."""
        target = {"n_cells": self.n_cells, "mean_beam_length": self.mean_beam_length,
                  "total_length": self.total_length}
        if all(v is None for v in target.values()):
            target["n_cells"] = DEFAULT_CELLS
        return RemeshSettings(**target, lloyd_iterations=self.lloyd_iterations, seed=self.seed,
                              symmetry_planes=tuple(symmetry_planes))


class OptimizeConfig(_Section):
    """Face optimisation (METHOD.md 4). Beams and panels are separate: the beam grid is made
    regular and close to the surface, and with ``planar`` every panel is planar within
    planarity_tolerance (relative to the mean beam length): a cell that is not planar and convex is
    glazed with planar convex pieces split along node-to-node diagonals (05-optimize/panels.obj),
    adding no beam. planarise_cells (off by default) also moves the nodes for planar cells (the
    planarity end game, planarity_iterations Gauss-Newton steps) and, with split_cells, adds beams
    where the boundary holds cells out of plane; it closes cell corners and shortens beams, which the
    joints may not take."""

    iterations: int = _default_of(OptimizeSettings, "iterations", ge=0)
    regularity_weight: float = _default_of(OptimizeSettings, "regularity_weight", ge=0)
    planarity_weight: float = _default_of(OptimizeSettings, "planarity_weight", ge=0)
    closeness_weight: float = _default_of(OptimizeSettings, "closeness_weight", ge=0)
    fairness_weight: float = _default_of(OptimizeSettings, "fairness_weight", ge=0)
    planar: bool = True
    planarity_tolerance: float = _default_of(OptimizeSettings, "planarity_tolerance", gt=0, lt=1)
    planarity_iterations: int = _default_of(OptimizeSettings, "planarity_iterations", ge=0)
    split_cells: bool = _default_of(OptimizeSettings, "split_cells")
    planarise_cells: bool = False

    def to_settings(self, *, min_beam_length_mm: float, min_corner_angle_deg: float,
                    max_cell_stretch: float) -> OptimizeSettings:
        """The engine's optimiser settings. The engine's ``planar`` moves the nodes for planar cells:
        that is ``planar`` with ``planarise_cells`` here (``planar`` alone glazes cells with planar
        pieces, no node moved). The shortest beam (mm), the smallest corner angle and the largest
        cell stretch come from the joints and the field."""
        return OptimizeSettings(regularity_weight=self.regularity_weight, planarity_weight=self.planarity_weight,
                                closeness_weight=self.closeness_weight, fairness_weight=self.fairness_weight,
                                iterations=self.iterations, planar=self.planar and self.planarise_cells,
                                planarity_tolerance=self.planarity_tolerance,
                                planarity_iterations=self.planarity_iterations, split_cells=self.split_cells,
                                min_beam_length=min_beam_length_mm / MM, min_corner_angle_deg=min_corner_angle_deg,
                                max_cell_stretch=max_cell_stretch)


class AnalysisConfig(_Section):
    """Beam grid-shell analysis (METHOD.md 5). imperfection_amplitude None: L/300 of the shorter plan side.
    workers: processes that run the non-linear paths side by side (default: one per core).
    tolerable_deflection_ratio: a non-linear path that reaches no limit point before a node has
    moved the shorter plan side over this ratio stops there, and its lambda_NL is the load factor
    there (EN 1993-1-6 8.7: the largest tolerable deformation; a soft roof that hangs as a net
    would otherwise "carry" max_load_factor metres out of shape)."""

    elements_per_beam: int = Field(4, ge=1, le=20)
    n_modes: int = _default_of(ProtocolSettings, "n_modes", ge=1, le=50)
    imperfection_amplitude: Length | None = None
    imperfection_shapes: list[ImperfectionShape] = Field(
        default_factory=lambda: list(_default_value(ProtocolSettings, "shapes")))
    nonlinear: bool = _default_of(ProtocolSettings, "nonlinear")
    max_load_factor: float = _default_of(ProtocolSettings, "max_load_factor", gt=0)
    required_load_factor: float = Field(1.5, gt=0)
    deflection_limit_ratio: float = Field(250.0, gt=0)
    tolerable_deflection_ratio: float = Field(TOLERABLE_DEFLECTION_RATIO, gt=0)
    buckling_length_factor: float = Field(1.0, gt=0)
    uls_combination: str | None = None
    sls_combination: str | None = None
    control_points: dict[str, list[Length]] = Field(default_factory=dict)
    workers: int | None = Field(None, ge=1)
    checks: ChecksMethod = "en1993"
    buckling_length: Literal["node_to_node", "buckling_modes"] = "node_to_node"

    def to_settings(self, span: float) -> ProtocolSettings:
        """The engine's protocol settings; ``span`` (m), the grid's shorter plan side, gives the
        imperfection amplitude L/300 where none is set and the tolerable deformation."""
        return ProtocolSettings(n_modes=self.n_modes, amplitude=self.imperfection_amplitude or span / 300.0,
                                shapes=tuple(self.imperfection_shapes), nonlinear=self.nonlinear,
                                max_load_factor=self.max_load_factor,
                                max_displacement=span / self.tolerable_deflection_ratio)


class DesignConfig(_Section):
    """Section sizing (engine.design.sizing): with size_sections, the lightest tubes of ``catalogue`` (a
    shipped one: "EN 10210-2 CHS", "EN 10219-2 CHS", "EN 755-8 aluminium tubes"; or a CSV file
    with diameter_mm and thickness_mm columns, relative to the project file), in at most
    ``groups`` distinct sections, that pass the member checks, the deflection limit and the
    buckling limits of [analysis]. nonlinear_rounds: how often the sections are stiffened and
    re-sized where lambda_NL_worst misses its limit. max_diameter: only tubes up to this outer
    diameter (e.g. the [section]'s, so that the joints the grid was made for fit: the walls grow
    instead). fit_grid_to_tubes: where the sized tubes are larger than [section], ``gridshell run``
    makes the grid again for the largest of them (its joints need longer beams, so it has fewer
    cells; workflow.design_loop); off, a ``tubes_outgrow_grid`` finding says so. choose = "best":
    ``gridshell run`` first runs the sweep of ``choose_from`` (dotted keys -> values, their
    product) up to the analysis and keeps the point with the highest lambda_NL_worst per kg among
    those that pass every check (workflow.choose)."""

    size_sections: bool = False
    catalogue: str = "EN 10210-2 CHS"
    groups: int = Field(3, ge=1, le=30)
    max_iterations: int = Field(25, ge=1, le=200)
    nonlinear_rounds: int = Field(2, ge=0, le=10)
    max_diameter: Length | None = None
    fit_grid_to_tubes: bool = False
    choose: Literal["as_given", "best"] = "as_given"
    choose_from: dict[str, list[Any]] = Field(default_factory=lambda: {
        "field.max_size_ratio": [1.0, 2.0, 3.0], "field.max_aspect": [1.0, 2.0]})

    @field_validator("choose_from")
    @classmethod
    def _candidates(cls, value: dict) -> dict:
        if not value or any(not isinstance(v, list) or not v for v in value.values()):
            raise ValueError("choose_from needs dotted project keys with non-empty lists of values")
        return value


class JointsConfig(_Section):
    """Joint kind: printed sockets ("socket", small tubes) or steel hub nodes with fin plates
    ("steel"); unset, steel for steel beams over 30 mm and sockets otherwise. min_angle: the
    smallest angle between two beams at a node (degrees; unset, 5 degrees above where the joint's
    own sleeves or fin plates collide, see fabrication.limits). combined_step: also write every
    joint into one joints/joints.step, where it comes under 30 MB (the J0001.step files hold the
    same solids)."""

    kind: JointKind | None = None
    min_angle: float | None = Field(None, gt=0.0, lt=120.0)
    hub_radius: Length | None = Field(None, gt=0.0)
    sleeve_length: Length | None = Field(None, gt=0.0)
    clearance: Length = _default_of(JointSettings, "clearance_mm", per=MM, ge=0.0)
    wall: Length = _default_of(JointSettings, "wall_mm", per=MM, gt=0.0)
    min_wall: Length = _default_of(JointSettings, "min_wall_mm", per=MM, gt=0.0)
    pin_hole: Length = _default_of(JointSettings, "pin_hole_mm", per=MM, gt=0.0)
    engrave: bool = _default_of(JointSettings, "engrave")
    plate_thickness: Length = _default_of(JointSettings, "plate_thickness_mm", per=MM, gt=0.0)
    bolt_hole: Length = _default_of(JointSettings, "bolt_hole_mm", per=MM, gt=0.0)
    combined_step: bool = False

    def to_settings(self) -> JointSettings:
        """Fabrication's joint settings (mm). The Project resolves an unset kind; a section on its
        own leaves it to JointSettings."""
        return JointSettings(**({} if self.kind is None else {"kind": self.kind}),
                             clearance_mm=MM * self.clearance, wall_mm=MM * self.wall, min_wall_mm=MM * self.min_wall,
                             pin_hole_mm=MM * self.pin_hole, engrave=self.engrave,
                             hub_radius_mm=None if self.hub_radius is None else MM * self.hub_radius,
                             sleeve_length_mm=None if self.sleeve_length is None else MM * self.sleeve_length,
                             plate_thickness_mm=MM * self.plate_thickness, bolt_hole_mm=MM * self.bolt_hole)


class BeamsConfig(_Section):
    """min_cut_length: the shortest tube a beam may be cut to (unset: both joints' reach into the
    tube plus half its diameter, at least one diameter); remesh and optimize collapse beams shorter
    than it plus their joints' set-backs."""

    stock_length: Length = _default_of(BeamSettings, "stock_length_mm", per=MM, gt=0.0)
    kerf: Length = _default_of(BeamSettings, "kerf_mm", per=MM, ge=0.0)
    min_cut_length: Length | None = Field(None, gt=0.0)

    def to_settings(self, *, profile_name: str, material_name: str, density: float, area_m2: float,
                    outer_size_mm: float) -> BeamSettings:
        """Fabrication's cut-list settings (mm), with the tube's names, density (kg/m^3), section
        area (m^2) and outer size (mm)."""
        return BeamSettings(profile_name=profile_name, material_name=material_name, density=density,
                            stock_length_mm=MM * self.stock_length, kerf_mm=MM * self.kerf, area_m2=area_m2,
                            outer_size_mm=outer_size_mm)


class PanelsConfig(_Section):
    """Unset material, thickness and density follow the joints: 3 mm acrylic (1190 kg/m^3) with
    printed sockets, 10 mm laminated glass (2500 kg/m^3) with steel joints."""

    enabled: bool = True
    thickness: Length | None = Field(None, gt=0.0)
    material: str | None = None
    density: Density | None = Field(None, gt=0.0)
    clearance: Length = _default_of(PanelSettings, "clearance_mm", per=MM, ge=0.0)
    hole_diameter: Length = _default_of(PanelSettings, "hole_diameter_mm", per=MM, ge=0.0)
    hole_inset: Length = _default_of(PanelSettings, "hole_inset_mm", per=MM, ge=0.0)
    planarity_tolerance: Length = _default_of(PanelSettings, "planarity_tolerance_mm", per=MM, ge=0.0)
    split_nonplanar: bool = _default_of(PanelSettings, "split_nonplanar")
    #: the panel direction laid along the sheets' grain, their length: none, x, y (plan axes) or slope
    grain: Literal["none", "x", "y", "slope"] = _default_of(PanelSettings, "grain")

    def to_settings(self) -> PanelSettings:
        """Fabrication's panel settings (mm), once the Project has resolved thickness, material and density."""
        return PanelSettings(thickness_mm=MM * self.thickness, material_name=self.material, density=self.density,
                             clearance_mm=MM * self.clearance, hole_diameter_mm=MM * self.hole_diameter,
                             hole_inset_mm=MM * self.hole_inset, planarity_tolerance_mm=MM * self.planarity_tolerance,
                             split_nonplanar=self.split_nonplanar, grain=self.grain)


class SheetsConfig(_Section):
    """Stock sheets: ``width`` x ``height``, and any further sizes in ``sizes`` ([[w, h], ...]); a
    panel goes on the first size it fits. Unset, they follow the joints: a 1200 x 600 mm laser bed
    with printed sockets; glass from jumbo 6000 x 3210 mm sheets with steel joints."""

    width: Length | None = Field(None, gt=0.0)
    height: Length | None = Field(None, gt=0.0)
    sizes: list[Annotated[list[Length], Field(min_length=2, max_length=2)]] = Field(default_factory=list)
    spacing: Length = _default_of(SheetSettings, "spacing_mm", per=MM, ge=0.0)
    margin: Length = _default_of(SheetSettings, "margin_mm", per=MM, ge=0.0)
    rotations: bool = _default_of(SheetSettings, "rotations")

    def to_settings(self) -> list[SheetSettings]:
        """Fabrication's stock sheets (mm) in the order panels are given to them: width x height,
        then ``sizes``; once the Project has resolved width and height."""
        sizes = [(self.width, self.height)] + [tuple(size) for size in self.sizes]
        return [SheetSettings(width_mm=MM * w, height_mm=MM * h, spacing_mm=MM * self.spacing,
                              margin_mm=MM * self.margin, rotations=self.rotations) for w, h in sizes]


class AssemblyConfig(_Section):
    deflection_limit: Length | None = None


class FabricationConfig(_Section):
    joints: JointsConfig = Field(default_factory=JointsConfig)
    beams: BeamsConfig = Field(default_factory=BeamsConfig)
    panels: PanelsConfig = Field(default_factory=PanelsConfig)
    sheets: SheetsConfig = Field(default_factory=SheetsConfig)
    assembly: AssemblyConfig = Field(default_factory=AssemblyConfig)
    workers: int | None = Field(None, ge=1)

    def build_limits(self, beam_size_mm: float) -> BuildLimits:
        """The shortest buildable beam and the smallest angle at a joint that the joints and beams
        give with a tube of outer size ``beam_size_mm``."""
        b = self.beams
        return BuildLimits.of(self.joints.to_settings(), beam_size_mm,
                              min_cut_length_mm=None if b.min_cut_length is None else MM * b.min_cut_length,
                              min_angle_deg=self.joints.min_angle)


#: The panels and stock sheets that [fabrication.panels] and [fabrication.sheets] leave unset follow
#: the joint kind (m, kg/m^3): with printed sockets fabrication's own defaults (PanelSettings,
#: SheetSettings: acrylic on a laser bed), with steel joints laminated glass from jumbo sheets.
_BY_JOINT: dict[str, dict[str, Any]] = {
    "socket": {"material": _default_value(PanelSettings, "material_name"),
               "thickness": _default_value(PanelSettings, "thickness_mm", MM),
               "density": _default_value(PanelSettings, "density"),
               "sheet": (_default_value(SheetSettings, "width_mm", MM),
                         _default_value(SheetSettings, "height_mm", MM))},
    "steel": {"material": "laminated glass", "thickness": 0.010, "density": 2500.0, "sheet": (6.0, 3.21)},
}


class ReportConfig(_Section):
    title: str | None = None


class Project(_Section):
    """A whole project file."""

    project: ProjectInfo = Field(default_factory=ProjectInfo)
    surface: SurfaceConfig
    supports: list[SupportSpec] = Field(default_factory=lambda: [SupportSpec(select="boundary")], min_length=1)
    loads: LoadsConfig = Field(default_factory=LoadsConfig)
    material: MaterialConfig = Field(default_factory=MaterialConfig)
    section: SectionConfig = Field(default_factory=lambda: SectionConfig(diameter=0.0483, thickness=0.0032))
    shell: ShellConfig = Field(default_factory=ShellConfig)
    field: FieldConfig = Field(default_factory=FieldConfig)
    remesh: RemeshConfig = Field(default_factory=RemeshConfig)
    optimize: OptimizeConfig = Field(default_factory=OptimizeConfig)
    analysis: AnalysisConfig = Field(default_factory=AnalysisConfig)
    design: DesignConfig = Field(default_factory=DesignConfig)
    fabrication: FabricationConfig = Field(default_factory=FabricationConfig)
    report: ReportConfig = Field(default_factory=ReportConfig)
    _scale_note: str | None = PrivateAttr(default=None)

    @property
    def scale_note(self) -> str | None:
        """One line where the project took MODEL_KIT for a small surface (parse_project), else None."""
        return self._scale_note

    @property
    def panel_weight_N_per_m2(self) -> float:
        """The panels' own weight per area (N/m^2): thickness x density x g; 0 where panels are off."""
        p = self.fabrication.panels
        if not p.enabled or p.thickness is None or p.density is None:
            return 0.0
        return float(p.thickness * p.density * GRAVITY)

    @property
    def carried_panel_weight_N_per_m2(self) -> float:
        """``panel_weight_N_per_m2`` where a load case carries the panels, else 0; [fabrication.panels]
        is read only in the first case (the surface stage's cache key holds it only then)."""
        return self.panel_weight_N_per_m2 if self.loads.carries_panels else 0.0

    @property
    def panels_left_out(self) -> str | None:
        """One line when the panels weigh something and no load case carries them: no case has
        ``panels``, and no case with the beams' weight has a downward area load as large."""
        weight = self.panel_weight_N_per_m2
        if weight <= 0 or self.loads.carries_panels:
            return None
        permanent = {n: c for n, c in self.loads.cases.items() if c.self_weight > 0}
        carried = max((-c.area_vector("area_true")[2] - c.area_vector("area_plan")[2] for c in permanent.values()),
                      default=0.0)
        if carried >= weight * (1 - PANEL_WEIGHT_ROUNDING):
            return None
        p = self.fabrication.panels
        where = f"[loads.cases.{next(iter(permanent))}]" if permanent else "a load case with self_weight = 1.0"
        return (f"the panels ({_mm(p.thickness)} {p.material or 'panels'}, {weight:.0f} N/m^2) are in no load case: "
                f"add panels = 1.0 to {where} (their weight from [fabrication.panels]), or an area load of at "
                f"least {weight:.0f} N/m^2")

    @property
    def notes(self) -> list[str]:
        """What validate prints as notes and run as progress: the model-kit line; the loads' when the
        grid-shell's own weight is the only one; the panels' when no load case carries them."""
        own_weight = []
        if self.loads.self_weight_only:
            own_weight = [OWN_WEIGHT_NOTE if self.carried_panel_weight_N_per_m2 > 0 else SELF_WEIGHT_NOTE]
        left_out = self.panels_left_out
        return ([self._scale_note] if self._scale_note else []) + own_weight + ([left_out] if left_out else [])

    @model_validator(mode="after")
    def _design_needs_tubes(self) -> "Project":
        if self.design.size_sections and self.section.kind != "circular_hollow":
            raise ValueError(f'design.size_sections sizes tubes from a catalogue of circular hollow sections, '
                             f'but [section] kind = "{self.section.kind}"; set kind = "circular_hollow" or '
                             f'size_sections = false')
        return self

    @model_validator(mode="after")
    def _fabrication_defaults(self) -> "Project":
        """Resolve the fabrication settings that follow the joint kind (see their sections)."""
        f = self.fabrication
        kind = f.joints.kind
        if kind is None:
            size = self.section.diameter or max(self.section.height or 0.0, self.section.width or 0.0)
            kind = "steel" if self.material.name.startswith("steel") and size > 0.03 else "socket"
        follow = _BY_JOINT[kind]
        p, s = f.panels, f.sheets
        if (s.width is None) != (s.height is None):
            raise ValueError("fabrication.sheets: give both width and height, or neither")
        for size in s.sizes:
            if min(size) <= 0:
                raise ValueError(f"fabrication.sheets.sizes: {size} must be two positive lengths")
        width, height = (s.width, s.height) if s.width is not None else follow["sheet"]
        for w, h in [(width, height)] + [tuple(size) for size in s.sizes]:
            if 2 * (MM * s.margin) >= min(MM * w, MM * h):  # as SheetSettings checks it
                raise ValueError(f"fabrication.sheets: margin = {_mm(s.margin)} leaves no room on a "
                                 f"{MM * w:g} x {MM * h:g} mm sheet")
        panels = p.model_copy(update={
            "material": p.material if p.material is not None else follow["material"],
            "thickness": p.thickness if p.thickness is not None else follow["thickness"],
            "density": p.density if p.density is not None else follow["density"]})
        fabrication = f.model_copy(update={"joints": f.joints.model_copy(update={"kind": kind}), "panels": panels,
                                           "sheets": s.model_copy(update={"width": width, "height": height})})
        return self.model_copy(update={"fabrication": fabrication})

    @model_validator(mode="after")
    def _combinations_exist(self) -> "Project":
        for key, name in (("shell.combination", self.shell.combination),
                          ("analysis.uls_combination", self.analysis.uls_combination),
                          ("analysis.sls_combination", self.analysis.sls_combination)):
            if name is not None and name not in self.loads.combinations and name not in self.loads.cases:
                raise ValueError(f"{key} = '{name}' is neither a load combination nor a load case; "
                                 f"defined: {sorted(self.loads.combinations) + sorted(self.loads.cases)}")
        return self


STAGE_SECTIONS: dict[str, tuple[str, ...]] = {
    # the project's name titles every stage's pictures and names the NC1 order and the IFC project
    "surface": ("project.name", "surface", "supports", "loads"),
    "shell": ("shell", "loads"),
    "field": ("field",),
    "remesh": ("remesh", "section", "material", "fabrication.joints", "fabrication.beams"),
    "optimize": ("optimize", "section", "material", "fabrication.joints", "fabrication.beams"),
    "analysis": ("analysis", "design", "material", "section", "loads"),
    "fabrication": ("fabrication", "material", "section"),
    "report": ("report", "project"),
}
"""The project sections (or dotted keys) each stage reads: its cache key. A stage may also read
those of the stages upstream of it (their keys are in its key); the runner lets it read nothing
else (workflow.stage_view)."""

#: Keys that came after runs were cached, left out of the cache keys at these defaults (what those
#: runs did), so that the caches of earlier runs stay valid.
KEYS_LEFT_OUT_AT_DEFAULT: dict[str, dict[str, Any]] = {
    "field": {"orientation": "along"},
    "remesh": {"statics_rounds": 1, "grid": "voronoi"},
}


#: A permanent area load this much under the panels' weight still carries them: loads are given to
#: two or three figures (the mock-up's 0.035 kN/m^2 for 3 mm acrylic, 35.02 N/m^2).
PANEL_WEIGHT_ROUNDING = 0.02
#: What the surface stage reads of the panels when a load case carries their weight.
PANEL_WEIGHT_KEYS = ("fabrication.panels.enabled", "fabrication.panels.thickness", "fabrication.panels.density")


def stage_sections(stage: str, project: "Project") -> tuple[str, ...]:
    """The project sections (or dotted keys) ``stage`` reads for ``project``: STAGE_SECTIONS; for a
    remesh with statics rounds the analysis keys its frame analyses take; for the surface's loads,
    where a case carries the panels, their weight's keys."""
    sections = STAGE_SECTIONS.get(stage, ())
    if stage == "surface" and project.loads.carries_panels:
        sections += PANEL_WEIGHT_KEYS
    if stage == "remesh" and project.remesh.statics_rounds > 1:
        sections += ("analysis.elements_per_beam", "analysis.uls_combination")
    return sections


def _unwrap(annotation: Any) -> Any:
    """Strip Annotated and Optional layers; a Union of models resolves to its first model."""
    while True:
        origin = typing.get_origin(annotation)
        if origin is Annotated:
            annotation = typing.get_args(annotation)[0]
        elif origin in (Union, types.UnionType):
            args = [a for a in typing.get_args(annotation) if a is not type(None)]
            models = [a for a in args if isinstance(a, type) and issubclass(a, BaseModel)]
            containers = [a for a in args if typing.get_origin(a) in (list, dict)]
            annotation = (models or containers or args)[0]
        else:
            return annotation


def _model_for(loc: tuple, model: type[BaseModel] = Project) -> type[BaseModel] | None:
    """The pydantic model class that owns the last key of ``loc`` (for listing allowed keys)."""
    current: Any = model
    for part in loc[:-1]:
        current = _unwrap(current)
        if isinstance(current, type) and issubclass(current, BaseModel):
            field_info = current.model_fields.get(str(part))
            if field_info is None:
                return None
            current = field_info.annotation
        elif typing.get_origin(current) is list:
            current = typing.get_args(current)[0]
        elif typing.get_origin(current) is dict:
            current = typing.get_args(current)[1]
        else:
            return None
    current = _unwrap(current)
    return current if isinstance(current, type) and issubclass(current, BaseModel) else None


_TAG = re.compile(r"(function-[a-z-]+|list|dict|tuple|set|frozenset|float|int|str|bool|literal|is-instance|"
                  r"nullable|lax-or-strict|json-or-python|chain|union|constrained-[a-z]+)(\[.*\])?")
_TAG_WORDS = {"float": "a number", "int": "a whole number", "str": "a text", "bool": "true or false",
              "list": "a list", "tuple": "a list", "dict": "a table"}


def _is_tag(part: Any) -> bool:
    """A pydantic location part that names a union branch or a validator, not a TOML key."""
    return isinstance(part, str) and _TAG.fullmatch(part) is not None


def _tag_word(tag: str) -> str:
    if tag.startswith("function-"):
        inner = tag[tag.index("[") + 1:-1].split(",")[-1].strip()
        return _TAG_WORDS.get(inner.split("[")[0], "a value")
    return _TAG_WORDS.get(tag.split("[")[0], "a value")


def _shape_matches(tag: str, value: Any) -> bool:
    """Whether a union branch takes values of the given value's shape: a list, a table or one value."""
    base = tag.split("[")[0]
    if isinstance(value, (list, tuple)):
        return base in ("list", "tuple", "set", "frozenset")
    if isinstance(value, dict):
        return base == "dict"
    return base not in ("list", "tuple", "set", "frozenset", "dict")


def _one_branch(items: list[dict]) -> list[dict]:
    """Of the errors of every branch of a union field, those of the branch the user meant: one
    whose own check has something to say (a unit), else the one whose shape (list or single value)
    matches the value; where no branch takes the value at all, one line listing what is allowed."""
    by_branch: dict[str, list[dict]] = {}
    for item in items:
        by_branch.setdefault(item["branch"], []).append(item)
    if len(by_branch) == 1:
        return items
    value = items[0]["field_input"]
    shaped = {tag: errs for tag, errs in by_branch.items() if _shape_matches(tag, value)}
    told = {tag: errs for tag, errs in (shaped or by_branch).items() if any(e["type"] == "value_error" for e in errs)}
    if told:
        return next(iter(told.values()))
    if len(shaped) == 1:
        errs = next(iter(shaped.values()))
        wrong_type = all(e["type"].endswith(("_type", "_parsing")) and e["clean"] == e["field"] for e in errs)
        if not wrong_type:
            return errs
    words = list(dict.fromkeys(_tag_word(tag) for tag in by_branch))
    expected = ", ".join(words[:-1]) + f" or {words[-1]}" if len(words) > 1 else words[0]
    return [{**items[0], "clean": items[0]["field"], "input": value, "type": "union", "msg": f"expected {expected}"}]


def _format_errors(error: ValidationError, source: str) -> str:
    """One line per mistake: the key, the value given and what is allowed, in TOML words
    (pydantic's union branches and validator names are left out)."""
    header = f"{source}: invalid project file" if not source.startswith("--") else f"{source}: invalid input"
    lines = [header]
    items: list[dict] = []
    for item in error.errors():
        loc = tuple(item["loc"])
        tag_at = next((i for i, p in enumerate(loc) if _is_tag(p)), None)
        clean = tuple(p for p in loc if not _is_tag(p))
        field_loc = loc[:tag_at] if tag_at is not None else clean
        items.append({**item, "clean": clean, "field": field_loc,
                      "branch": loc[tag_at] if tag_at is not None else "",
                      "field_input": item.get("input") if tag_at is None or tag_at == len(loc) - 1 else None})
    groups: dict[tuple, list[dict]] = {}
    for item in items:
        groups.setdefault(item["field"], []).append(item)
    for group in groups.values():
        if any(i["branch"] for i in group):
            field_inputs = [i for i in group if i["field_input"] is not None]
            whole = field_inputs[0]["field_input"] if field_inputs else group[0].get("input")
            group = _one_branch([{**i, "field_input": whole} for i in group])
        for item in group:
            loc = item["clean"]
            key = ".".join(str(p) if not isinstance(p, int) else f"[{p}]" for p in loc).replace(".[", "[")
            key = key or "(top level)"
            value = item.get("input")
            shown = repr(value) if not isinstance(value, dict) else "{...}"
            if item["type"] == "extra_forbidden":
                owner = _model_for(loc)
                allowed = ", ".join(owner.model_fields) if owner else "see the template"
                line = f"  {key} = {shown}: unknown key; allowed keys here: {allowed}"
            elif item["type"] == "missing":
                line = f"  {key}: required key is missing"
            elif item["type"] in ("literal_error", "enum"):
                expected = item.get("ctx", {}).get("expected", "")
                line = f"  {key} = {shown}: not allowed; expected one of {expected}"
            else:
                message = item["msg"].removeprefix("Value error, ")
                line = f"  {key}: {message}" if isinstance(value, dict) else f"  {key} = {shown}: {message}"
            if line not in lines:
                lines.append(line)
    return "\n".join(lines)


MODEL_ACROSS_M = 4.0
"""A surface file smaller than this across (m) whose project gives neither [section] nor [material]
is built as a model, with MODEL_KIT: the real roof's default steel tube (CHS 48.3 x 3.2) and its
steel nodes would leave a 1.5 m surface a dozen cells, each beam longer than two nodes' set-backs."""
MODEL_KIT: dict[str, dict[str, Any]] = {
    "material": {"name": "aluminium_6063"},
    "section": {"kind": "circular_hollow", "diameter": 0.012, "thickness": 0.0015},
}
"""The mock-up's kit (templates/mockup.toml): aluminium tubes 12 x 1.5 mm, which take printed sockets
and, through them, acrylic panels on a laser bed (the joint kind's defaults)."""


def parse_project(data: dict, *, source: str = "project", base_dir: Path | None = None) -> Project:
    """Validate a project dictionary; relative surface paths resolve against ``base_dir``. A surface
    file under MODEL_ACROSS_M across, with no [section] and no [material], takes MODEL_KIT
    (``Project.scale_note`` says so)."""
    try:
        project = Project.model_validate(data)
        across = None if "section" in data or "material" in data else _file_across_m(project, base_dir)
        if across is not None and SURFACE_EXTENT_M[0] <= across < MODEL_ACROSS_M:
            project = Project.model_validate({**data, **MODEL_KIT})
            project._scale_note = (
                f"the surface is {_distance(across)} across, under {MODEL_ACROSS_M:g} m: it is built as a model, "
                "with the mock-up's aluminium tubes 12 x 1.5 mm, printed sockets and acrylic panels "
                "(a project file's [section] and [material] choose others)")
    except ValidationError as exc:
        raise ConfigError(_format_errors(exc, source),
                          hint="compare with a template: gridshell init DIR --template mockup") from None
    if project.surface.file is not None and base_dir is not None:
        path = Path(project.surface.file)
        if not path.is_absolute():
            surface = project.surface.model_copy(update={"file": str((base_dir / path).resolve())})
            project = project.model_copy(update={"surface": surface})
    from engine.design.catalogue import CATALOGUES

    spec = project.design.catalogue
    if spec not in CATALOGUES and base_dir is not None and not Path(spec).is_absolute():
        design = project.design.model_copy(update={"catalogue": str((base_dir / spec).resolve())})
        project = project.model_copy(update={"design": design})
    return project


def _file_across_m(project: Project, base_dir: Path | None) -> float | None:
    """The size across (m) of ``project``'s surface file, as check_inputs measures it; None for a
    template, or a file that does not read (check_inputs then says why)."""
    if project.surface.file is None:
        return None
    path = Path(project.surface.file)
    if not path.is_absolute() and base_dir is not None:
        path = base_dir / path
    try:
        stat = path.resolve().stat()
        raw, stated = _raw_extent(str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    except (OSError, InputError):
        return None
    return raw * file_scale_m(stated, project.surface.file_units) if raw > 0 else None


@functools.lru_cache(maxsize=32)
def _raw_extent(path: str, mtime_ns: int, size: int) -> tuple[float, str | None]:
    """(the largest side of the bounding box of the mesh file ``path``, the unit the file states):
    in metres where it states one (a .3dm), else in its own units (the file's time and size key the
    cache: a sweep parses its project once per point)."""
    from .surface_io import read_surface_with_unit

    vertices, _, _, stated = read_surface_with_unit(path)
    return _largest_side(vertices), stated


def _largest_side(vertices: np.ndarray) -> float:
    """The largest side of the bounding box of the finite ``vertices`` (0 where none is)."""
    finite = vertices[np.isfinite(vertices).all(axis=1)]
    return float(np.ptp(finite, axis=0).max()) if len(finite) else 0.0


def is_project_key(key: str) -> bool:
    """Whether the dotted ``key`` names one setting of a project ("remesh.n_cells"), not a table."""
    parts = tuple(key.split("."))
    model = _model_for(parts)
    return model is not None and parts[-1] in model.model_fields and _model_for(parts + ("_",)) is None


def set_key(data: dict, key: str, value: Any) -> None:
    """Set the dotted ``key`` of the TOML ``data`` (in place), making tables on the way."""
    *tables, last = key.split(".")
    for name in tables:
        data = data.setdefault(name, {})
        if not isinstance(data, dict):
            raise ConfigError(f"{key!r}: {name} is not a table in the project")
    data[last] = value


def parse_setting(text: str, flag: str = "--set") -> tuple[str, Any]:
    """(key, value) of a command line's ``KEY=VALUE``: the value read as a TOML value (60, 2.5, true,
    [1, 2], "text"), else taken as text ("48.3 mm", "socket"); ConfigError naming ``flag`` for a
    key that is not a project key."""
    key, equals, value = text.partition("=")
    key = key.strip()
    if not equals or not key:
        raise ConfigError(f"{flag} {text!r}: give KEY=VALUE", hint=f"e.g. {flag} remesh.n_cells=300")
    if not is_project_key(key):
        raise ConfigError(f"{flag} {text!r}: {key!r} is not a project key",
                          hint='keys are dotted project keys, e.g. "remesh.n_cells" or "field.max_size_ratio"')
    try:
        parsed = tomllib.loads(f"value = {value.strip()}")["value"]
    except tomllib.TOMLDecodeError:
        parsed = value.strip()
    return key, parsed


def _source(source: str, settings: dict[str, Any] | None) -> str:
    if not settings:
        return source
    return f"{source} with " + ", ".join(f"--set {k}={v!r}" for k, v in settings.items())


def load_project(path: str | Path, settings: dict[str, Any] | None = None) -> Project:
    """Read and validate a TOML project file (a folder stands for its project.toml, as
    ``gridshell init DIR`` writes it); ``settings``: dotted keys and values that replace the
    file's (``gridshell run --set``)."""
    path = Path(path)
    if path.is_dir():
        if not (path / "project.toml").is_file():
            raise ConfigError(f"{path} is a folder without a project.toml",
                              hint=f"give the project file, or create one with: "
                                   f"gridshell init {path} --template mockup")
        path = path / "project.toml"
    data = read_toml(path, "project file", hint="create one with: gridshell init DIR --template mockup")
    for key, value in (settings or {}).items():
        set_key(data, key, value)
    return parse_project(data, source=_source(str(path), settings), base_dir=path.parent.resolve())


def read_toml(path: Path, what: str, *, hint: str | None = None) -> dict:
    """The TOML table of the file ``path``; ConfigError when it does not exist (``what`` names it,
    ``hint`` says what to do), is not TOML or is not text."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{what} {path} does not exist", hint=hint)
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a text file") from None


def project_from_surface(surface: str | Path, supports: str = "boundary", units: str = "m",
                         up: str | None = None, settings: dict[str, Any] | None = None) -> Project:
    """The quick-start project: a mesh file in ``units`` (m, cm, mm, in, ft) with ``up`` as its up
    axis (None: z, checked), supports 'boundary' or 'flagged', defaults elsewhere, but for the
    dotted keys of ``settings``."""
    from engine.geometry.surfaces import UP_AXES

    if supports not in ("boundary", "flagged"):
        raise ConfigError(f"--supports {supports!r}: allowed are boundary, flagged")
    if units not in FILE_UNITS_M:
        raise ConfigError(f"--surface-units {units!r}: allowed are {', '.join(FILE_UNITS_M)}")
    if up is not None and up not in UP_AXES:
        raise ConfigError(f"--surface-up {up!r}: allowed are {', '.join(UP_AXES)}")
    data = {"project": {"name": Path(surface).stem},
            "surface": {"file": str(Path(surface).resolve()), "file_units": units,
                        **({} if up is None else {"up_axis": up})},
            "supports": [{"select": supports, "restraint": "pinned"}]}
    for key, value in (settings or {}).items():
        set_key(data, key, value)
    return parse_project(data, source=_source(f"--surface {surface}", settings))


SURFACE_EXTENT_M = (0.1, 1000.0)
"""The sizes a surface may have across, in metres; outside them its file_units are taken to be wrong."""


def _distance(metres: float) -> str:
    if metres >= 1000:
        return f"{metres / 1000:.3g} km"
    return f"{metres:.3g} m" if metres >= 1 else f"{metres * 1000:.3g} mm"


SIDEWAYS_SHARE = 0.45
"""A file read with z up stands on its side when its normals' share on x or y (area-weighted mean
|n_x| or |n_y|) is over this and over twice their share on z: a roof exported with y up. Real roofs
have z at least 0.69 times the largest (a saddle on its corners), generated ones over 1.7 times."""


def _check_upright(vertices: np.ndarray, faces: np.ndarray, path: Path, quick_start: bool) -> None:
    from engine.geometry.surfaces import normal_shares

    if (vertices.ndim != 2 or vertices.shape[1:] != (3,) or faces.ndim != 2 or faces.shape[1:] != (3,)
            or not len(faces) or faces.min() < 0 or faces.max() >= len(vertices)):
        return                       # not a triangle mesh: the surface stage says what is wrong with it
    shares = normal_shares(vertices, faces)
    axis = int(np.argmax(shares[:2]))
    if not (shares[axis] > SIDEWAYS_SHARE and shares[2] < 0.5 * shares[axis]):
        return
    name = "xy"[axis]
    what = (f"{path.name} stands on its side: its faces face along {name} (mean |n_{name}| = "
            f"{shares[axis]:.2f}), hardly up (mean |n_z| = {shares[2]:.2f}), so it was likely modelled with "
            f"{name} up (Blender, SketchUp and glTF exports are)")
    if quick_start:
        raise ConfigError(f"--surface {path}: {what}",
                          hint=f"add --surface-up {name} (or -{name} if the roof then hangs downwards); "
                               "--surface-up z takes it as it is")
    raise ConfigError(f"[surface] up_axis: {what}",
                      hint=f'set [surface] up_axis = "{name}" (or "-{name}" if the roof then hangs downwards); '
                           'up_axis = "z" takes it as it is')


def check_inputs(project: Project, *, quick_start: bool = False) -> float | None:
    """The checks that read the input files but compute nothing, so that ``validate`` and ``run``
    stop at once where a stage would: the surface file exists and reads, its size across is
    plausible for its ``file_units`` (a mesh in millimetres read as metres is kilometres across),
    and ``flagged`` supports have flagged vertices to select. ``quick_start``: the project came
    from ``--surface``, so messages name the command-line options. Returns the surface's size
    across in metres (None for a template surface). Raises ``ConfigError``."""
    from .surface_io import read_surface_with_unit

    if project.design.size_sections:
        from engine.design.catalogue import catalogue

        try:
            catalogue(project.design.catalogue).up_to(project.design.max_diameter)
        except InputError as error:
            key = "max_diameter" if "max_diameter" in (error.hint or "") else "catalogue"
            raise ConfigError(f"[design] {key}: {error.args[0]}", hint=error.hint) from None
    config = project.surface
    if config.file is None:
        return None
    path = Path(config.file)
    if not path.is_file():
        if quick_start:
            raise ConfigError(f"--surface {path}: no such file",
                              hint="give the path of a mesh file (OBJ, PLY, STL, OFF or 3DM)")
        raise ConfigError(f"[surface] file: {path} does not exist",
                          hint="a relative path is read from the project file's folder; correct [surface] file")
    vertices, faces, flagged, stated = read_surface_with_unit(path)
    if config.up_axis is None:
        _check_upright(vertices, faces, path, quick_start)
    raw = _largest_side(vertices)
    unit = config.file_units
    across = raw * file_scale_m(stated, unit)
    low, high = SURFACE_EXTENT_M
    if stated and not low <= across <= high:  # the file's own unit is used, not file_units
        raise ConfigError(f"{'--surface' if quick_start else '[surface] file:'} {path}: the surface is "
                          f"{_distance(across)} across in the .3dm file's own units ({stated})",
                          hint="set the Rhino file's units to those it was drawn in (Rhino: _Units, without "
                               "scaling) and save it again; a .3dm is read in its own units, not --surface-units "
                               "or file_units")
    if raw > 0 and not low <= across <= high:
        likely = next((u for u in ("m", "mm", "cm", "ft", "in") if u != unit
                       and low <= raw * FILE_UNITS_M[u] <= high), "mm" if across > high else "m")
        if quick_start:
            raise ConfigError(f"--surface {path}: the surface is {_distance(across)} across, read in {unit} "
                              f"(--surface-units {unit}); in {likely} it would be "
                              f"{_distance(raw * FILE_UNITS_M[likely])}",
                              hint=f"add --surface-units {likely} (the unit the mesh was modelled in: "
                                   "m, cm, mm, in or ft)")
        raise ConfigError(f'[surface] file_units = "{unit}": the surface {path.name} is {_distance(across)} across; '
                          f'with file_units = "{likely}" it would be {_distance(raw * FILE_UNITS_M[likely])}',
                          hint=f'set [surface] file_units = "{likely}" (the unit the mesh was modelled in: '
                               "m, cm, mm, in or ft)")
    if not flagged.any():
        for index, spec in enumerate(project.supports):
            if spec.select == "flagged":
                if quick_start:
                    raise ConfigError(f"--supports flagged: {path.name} has no red (255, 0, 0) vertices to support",
                                      hint="use --supports boundary, or colour the support vertices red in a PLY")
                raise ConfigError(f'supports[{index}]: select = "flagged", but {path.name} has no red (255, 0, 0) '
                                  "vertices", hint='use select = "boundary", or select the supports by plane or box')
    return across


def _quantity(value: float, kind: str) -> str:
    """``value`` (SI) in the unit a project file would use for ``kind``."""
    def digits(x: float) -> str:  # three significant digits, never in scientific notation
        return np.format_float_positional(x, precision=3, unique=True, fractional=False, trim="-")

    if kind == "length":
        return f"{digits(value / 1000)} km" if value >= 1000 else _distance(value)
    if kind == "stress":
        return f"{digits(value / 1e9)} GPa" if abs(value) >= 1e9 else f"{digits(value / 1e6)} MPa"
    if kind == "density":
        return f"{digits(value)} kg/m^3"
    return f"{digits(value / 1e3)} kN/m^2"  # area load


#: The usual range of the quantities a project gives (SI; area loads: the largest component's
#: size). A value outside it is allowed but most likely a slip of unit or of digits (a "50 m" tube,
#: "2100 GPa"), so validate and run warn, naming the key. Loose bounds: tubes of a 5 mm model to a
#: metre, walls of 0.5 to 50 mm, from foams and plastics to steel and carbon fibre.
USUAL_RANGES: dict[str, tuple[str, float, float]] = {
    "section.diameter": ("length", 0.005, 1.0), "section.height": ("length", 0.005, 1.0),
    "section.width": ("length", 0.005, 1.0), "section.thickness": ("length", 0.0005, 0.05),
    "material.E": ("stress", 0.5e9, 500e9), "material.G": ("stress", 0.1e9, 200e9),
    "material.density": ("density", 100.0, 20_000.0), "material.yield_strength": ("stress", 5e6, 2000e6),
    "shell.thickness": ("length", 0.001, 2.0), "fabrication.panels.thickness": ("length", 0.0005, 0.1),
    "loads.cases.*.area_true": ("area load", 0.0, 50e3), "loads.cases.*.area_plan": ("area load", 0.0, 50e3),
}


def unusual_values(project: Project) -> list[str]:
    """One line per quantity of ``project`` outside USUAL_RANGES: the key, the value and the range."""
    values: list[tuple[str, str, float]] = []  # key, its USUAL_RANGES key, value
    for pattern in USUAL_RANGES:
        if pattern.startswith("loads.cases.*."):
            field = pattern.rsplit(".", 1)[1]
            for name, case in project.loads.cases.items():
                load = getattr(case, field)
                size = max((abs(v) for v in load), default=0.0) if isinstance(load, list) else abs(load)
                values.append((f"loads.cases.{name}.{field}", pattern, size))
            continue
        value = project
        for part in pattern.split("."):
            value = getattr(value, part)
        if value is not None:
            values.append((pattern, pattern, value))
    lines = []
    for key, pattern, value in values:
        kind, low, high = USUAL_RANGES[pattern]
        if not low <= value <= high:
            lines.append(f"{key} = {_quantity(value, kind)} is far outside the usual {_quantity(low, kind)} to "
                         f"{_quantity(high, kind)}; check its value and unit")
    return lines
