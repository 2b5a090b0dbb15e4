"""Stage ``surface``: the input surface, its supports and its load cases.

Artifacts (01-surface/): surface.ply (red vertices = supports), supports.json,
loads.json (cases in SI with resolved node ids, and combinations), surface.json (what
cleaning did, extent, form-finding record) and surface.png.
"""

from __future__ import annotations

import hashlib
import inspect
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.errors import GridshellError, InputError
from engine.geometry import parametric
from engine.geometry.edge_split import SLIVER_SHARE, sliver_share
from engine.geometry.surfaces import clean_mesh, to_z_up
from engine.mesh import TriMesh
from engine.remeshing.analysis_mesh import SLIVER_COPY_TRIANGLES, analysis_mesh
from engine.structure.loads import LimitState, LoadCase, LoadCombination
from engine.structure.supports import (
    Supports,
    restraint_flags,
    select_boundary,
    select_box,
    select_flagged,
    select_ids,
    select_loop,
    select_nearest,
    select_plane,
)
from fabrication.files import write_text_atomic

from ..config import Project, SupportSpec
from ..plots.surface import plot_surface
from ..runner import StageContext
from ..surface_io import file_scale_m, read_surface, read_surface_with_unit, write_surface_ply
from ..units import to_si

__all__ = ["SurfaceResult", "build_surface", "resolve_supports", "resolve_loads", "check_selections", "run", "load",
           "external"]

_COUNT_PARAMETERS = {"divisions", "rings"}
_RATIO_PARAMETERS = {"span_to_rise"}


@dataclass(frozen=True, kw_only=True)
class SurfaceResult:
    """The clean surface, its supports (vertex ids and restraints), its load cases (point loads on
    vertex ids) and combinations, and ``info`` (surface.json: what cleaning did, extent, ...)."""

    mesh: TriMesh
    supports: Supports
    load_cases: dict[str, LoadCase]
    combinations: dict[str, LoadCombination]
    info: dict


def _template_parameters(name: str, given: dict) -> dict:
    function = getattr(parametric, name)
    allowed = [p for p in inspect.signature(function).parameters if p != "self"]
    out = {}
    for key, value in given.items():
        if key not in allowed:
            raise InputError(f"surface.parameters.{key}: unknown parameter of template '{name}'; "
                             f"allowed: {', '.join(allowed)}")
        try:
            if key in _COUNT_PARAMETERS:
                if not isinstance(value, int) or isinstance(value, bool):
                    raise ValueError("must be a whole number")
                out[key] = value
            elif key in _RATIO_PARAMETERS:
                out[key] = float(value)
            else:
                out[key] = to_si(value, "area load" if key == "load_per_area" else "length")
        except ValueError as exc:
            raise InputError(f"surface.parameters.{key} = {value!r}: {exc}") from None
    return out


def build_surface(project: Project) -> tuple[TriMesh, dict]:
    """The clean surface of a project and a record of how it was made."""
    config = project.surface
    if config.template is not None:
        parameters = _template_parameters(config.template, dict(config.parameters))
        if config.template == "mockup":
            made = parametric.mockup(**parameters)
            info = {"source": "template mockup", "parameters": parameters,
                    "form_finding": {"method": "force density", "force_density_N_per_m": made.force_density,
                                     "applied_load_N": made.applied_load,
                                     "equilibrium_residual": made.form_finding.residual,
                                     "supports": "whole boundary pinned (z = 0)"}}
            return made.mesh, info
        mesh = getattr(parametric, config.template)(**parameters)
        return mesh, {"source": f"template {config.template}", "parameters": parameters}
    vertices, faces, flagged, stated = read_surface_with_unit(config.file)
    # a file that states its unit (a Rhino .3dm) is read in it, in metres: file_units is for the others
    vertices = to_z_up(vertices * file_scale_m(stated, config.file_units), config.up_axis or "z")
    mesh, report = clean_mesh(vertices, faces, flagged, name=Path(config.file).stem,
                              merge_tolerance=config.merge_tolerance)
    cleaning = report.to_json()
    share = sliver_share(mesh.vertices, mesh.faces)
    if share > SLIVER_SHARE:  # a coarse CAD tessellation: mesh it again, well shaped
        sliver_faces = mesh.n_faces
        mesh = analysis_mesh(mesh, SLIVER_COPY_TRIANGLES)
        cleaning["remeshed_slivers"] = sliver_faces
        cleaning["notes"] = [*cleaning["notes"], f"{100 * share:.0f} % of the area in slivers (triangles over about 6 "
                             f"times longer than wide, as a coarse CAD tessellation gives): its {sliver_faces} "
                             f"triangles meshed again into {mesh.n_faces} well-shaped ones on the same surface"]
    return mesh, {"source": str(config.file), "units": stated or config.file_units,
                  "units_from": "the file" if stated else "file_units", "cleaning": cleaning}


def _select(mesh: TriMesh, spec: SupportSpec) -> np.ndarray:
    points = mesh.vertices
    if spec.select == "boundary":
        return select_boundary(mesh.boundary_loops)
    if spec.select == "loop":
        return select_loop(mesh.boundary_loops, spec.loop)
    if spec.select == "plane":
        return select_plane(points, np.array(spec.point), np.array(spec.normal), spec.tolerance)
    if spec.select == "box":
        return select_box(points, np.array(spec.lower), np.array(spec.upper))
    if spec.select == "flagged":
        return select_flagged(mesh.flagged)
    if spec.select == "ids":
        return select_ids(mesh.n_vertices, spec.ids)
    return select_nearest(points, np.array(spec.points))


def resolve_supports(mesh: TriMesh, specs: list[SupportSpec]) -> Supports:
    """Union of the project's support selections on the surface's vertices."""
    parts = []
    for index, spec in enumerate(specs):
        try:
            parts.append((_select(mesh, spec), restraint_flags(spec.restraint)))
        except GridshellError as exc:
            exc.args = (f"supports[{index}]: {exc.args[0]}",)
            raise
    return Supports.merge(parts)


def resolve_loads(mesh: TriMesh, project: Project) -> tuple[dict[str, LoadCase], dict[str, LoadCombination]]:
    """Load cases with point loads resolved to vertex ids, and the combinations. A case's
    ``panels`` factor adds the panels' weight (``Project.carried_panel_weight_N_per_m2``) to its downward
    load per true area.

    Without combinations in the project, one SLS and one ULS combination are made:
    SLS = sum of all cases, ULS = 1.35 x (cases with self-weight) + 1.5 x (the others).
    """
    cases: dict[str, LoadCase] = {}
    panel_weight = project.carried_panel_weight_N_per_m2
    for name, spec in project.loads.cases.items():
        nodes, forces = [], []
        for index, point in enumerate(spec.points):
            try:
                if point.node is not None:
                    node = int(select_ids(mesh.n_vertices, [point.node])[0])
                else:
                    node = int(select_nearest(mesh.vertices, np.array(point.nearest))[0])
            except GridshellError as exc:
                exc.args = (f"loads.cases.{name}.points[{index}]: {exc.args[0]}",)
                raise
            nodes.append(node)
            forces.append([*point.force, *point.moment])
        area_true = np.array(spec.area_vector("area_true")) - [0.0, 0.0, spec.panels * panel_weight]
        cases[name] = LoadCase(name=name, self_weight=spec.self_weight,
                               area_true=area_true, area_plan=spec.area_vector("area_plan"),
                               point_nodes=np.array(nodes, dtype=np.int64) if nodes else None,
                               point_forces=np.array(forces) if forces else None)
    combinations = {name: LoadCombination(name=name, limit_state=LimitState(c.limit_state), factors=dict(c.factors))
                    for name, c in project.loads.combinations.items()}
    if not combinations:
        combinations["SLS"] = LoadCombination(name="SLS", limit_state=LimitState.SLS,
                                              factors={n: 1.0 for n in cases})
        combinations["ULS"] = LoadCombination(name="ULS", limit_state=LimitState.ULS,
                                              factors={n: (1.35 if c.self_weight else 1.5) for n, c in cases.items()})
    return cases, combinations


def check_selections(project: Project) -> int:
    """What the surface stage rejects before it writes anything, for ``validate``: the surface
    builds (a template in milliseconds; a file read and cleaned), it is symmetric about the
    [field] symmetry planes (the field stage's check_symmetry_planes), every support selection
    matches a node and every point load finds its node. Returns the number of supported nodes.
    Raises the stage's GridshellError, with the same message."""
    from .field import check_symmetry_planes

    mesh, _ = build_surface(project)
    check_symmetry_planes(mesh, project)
    supports = resolve_supports(mesh, project.supports)
    resolve_loads(mesh, project)
    return int(len(supports.nodes))


def _loads_json(cases: dict[str, LoadCase], combinations: dict[str, LoadCombination], project: Project) -> dict:
    factors = {n: c.panels for n, c in project.loads.cases.items() if c.panels}
    return {"units": "N, N/m^2, N m; self_weight is a factor on the structure's own weight",
            # the panels' weight, already in the area_true of the cases that carry it (by these factors)
            "panels": {"N_per_m2": project.carried_panel_weight_N_per_m2 if factors else None, "factors": factors},
            "cases": {n: {"self_weight": c.self_weight, "area_true": c.area_true.tolist(),
                          "area_plan": c.area_plan.tolist(), "point_nodes": c.point_nodes.tolist(),
                          "point_forces": c.point_forces.tolist()} for n, c in cases.items()},
            "combinations": {n: {"limit_state": c.limit_state.value, "factors": c.factors}
                             for n, c in combinations.items()}}


def run(project: Project, ctx: StageContext) -> SurfaceResult:
    ctx.step("building the surface")
    mesh, info = build_surface(project)
    for note in (info.get("cleaning") or {}).get("notes", []):
        ctx.step(f"cleaning: {note}")
    ctx.step("selecting supports")
    supports = resolve_supports(mesh, project.supports)
    cases, combinations = resolve_loads(mesh, project)
    flagged_mesh = TriMesh(vertices=mesh.vertices, faces=mesh.faces, name=mesh.name,
                           flagged=np.isin(np.arange(mesh.n_vertices), supports.nodes))
    info.update({"vertices": mesh.n_vertices, "faces": mesh.n_faces, "boundary_loops": len(mesh.boundary_loops),
                 "bounds_m": mesh.bounds.tolist(), "area_m2": mesh.area, "supported_nodes": int(len(supports.nodes))})
    ctx.step("writing files")
    write_surface_ply(flagged_mesh, ctx.folder / "surface.ply")
    write_text_atomic(ctx.folder / "supports.json", json.dumps(
        {"dofs": ["ux", "uy", "uz", "rx", "ry", "rz"], "supports": supports.to_json(),
         "selections": [s.model_dump(mode="json") for s in project.supports]}, indent=1))
    write_text_atomic(ctx.folder / "loads.json", json.dumps(_loads_json(cases, combinations, project), indent=1))
    write_text_atomic(ctx.folder / "surface.json", json.dumps(info, indent=1, default=float))
    ctx.step("drawing")
    plot_surface(mesh, supports.nodes, ctx.folder / "surface.png", title=f"{project.project.name}: {mesh.name}")
    return SurfaceResult(mesh=mesh, supports=supports, load_cases=cases, combinations=combinations, info=info)


def load(folder: Path, project: Project) -> SurfaceResult:
    vertices, faces, _ = read_surface(folder / "surface.ply")
    mesh = TriMesh(vertices=vertices, faces=faces,
                   name=project.surface.template or Path(project.surface.file).stem)
    support_data = json.loads((folder / "supports.json").read_text())["supports"]
    supports = Supports(nodes=np.array([int(k) for k in support_data], dtype=np.int64),
                        restraints=np.array(list(support_data.values()), dtype=bool).reshape(-1, 6))
    loads = json.loads((folder / "loads.json").read_text())
    cases = {n: LoadCase(name=n, self_weight=c["self_weight"], area_true=c["area_true"], area_plan=c["area_plan"],
                         point_nodes=np.array(c["point_nodes"], dtype=np.int64),
                         point_forces=np.array(c["point_forces"]).reshape(-1, 6)) for n, c in loads["cases"].items()}
    combinations = {n: LoadCombination(name=n, limit_state=LimitState(c["limit_state"]), factors=c["factors"])
                    for n, c in loads["combinations"].items()}
    info = json.loads((folder / "surface.json").read_text())
    return SurfaceResult(mesh=mesh, supports=supports, load_cases=cases, combinations=combinations, info=info)


def external(project: Project) -> str:
    """Digest of the surface file's bytes (templates have none)."""
    if project.surface.file is None:
        return ""
    path = Path(project.surface.file)
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else "missing"
