"""Stage ``shell``: the surface as a continuous thin shell under its supports and loads.

Artifacts (02-shell/): shell.npz (every field of ``engine.structure.shell.ShellResult``),
shell.json (the load combination used, thickness, largest displacement, force ranges,
equilibrium check, the surface's triangles and those analysed, and ``analysed_on``: why a copy was
analysed, where one was: a surface of more than ``shell.max_triangles``, or of slivers, is
analysed on a well-shaped copy) and stress.png (principal membrane force crosses).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from engine.errors import MechanismError
from engine.geometry.edge_split import sliver_share
from engine.remeshing.analysis_mesh import copy_triangles
from engine.structure.loads import LoadCase, LoadCombination, combine
from engine.structure.shell import ShellMaterial, ShellResult, analyse_shell, shell_nodal_loads
from fabrication.files import write_text_atomic

from ..config import Project
from ..plots.shell import plot_principal_forces
from ..runner import StageContext
from ._arrays import load_result, save_result
from .surface import SurfaceResult

__all__ = ["run", "load", "shell_load_case", "notional_thickness"]


def notional_thickness(project: Project, mesh) -> float:
    """The shell thickness: the project's, or span / 100 with span the larger plan extent (METHOD.md 1)."""
    if project.shell.thickness is not None:
        return project.shell.thickness
    lo, hi = mesh.bounds
    return float(max(hi[0] - lo[0], hi[1] - lo[1]) / 100.0)


def shell_load_case(project: Project, cases: dict[str, LoadCase],
                    combinations: dict[str, LoadCombination]) -> LoadCase:
    """The load of the shell analysis: ``shell.combination`` (a combination or a case), else the
    first SLS combination, else all cases added."""
    name = project.shell.combination
    if name is None:
        sls = [n for n, c in combinations.items() if c.limit_state.value == "SLS"]
        name = sls[0] if sls else None
    if name in combinations:
        return combine(cases, combinations[name])
    if name in cases:
        return cases[name]
    return combine(cases, LoadCombination(name="all", limit_state="SLS", factors={n: 1.0 for n in cases}))


def run(surface: SurfaceResult, project: Project, ctx: StageContext) -> ShellResult:
    mesh = surface.mesh
    thickness = notional_thickness(project, mesh)
    case = shell_load_case(project, surface.load_cases, surface.combinations)
    material = ShellMaterial(E=project.shell.E, nu=project.shell.nu, density=project.shell.density)
    ctx.step("loads")
    loads = shell_nodal_loads(mesh, case, thickness=thickness, density=project.shell.density)
    limit = project.shell.max_triangles
    copy = copy_triangles(mesh, limit)
    why = None
    if copy is not None:
        why = (f"the surface's {mesh.n_faces} triangles are more than [shell] max_triangles = {limit}"
               if mesh.n_faces > limit else
               f"{100 * sliver_share(mesh.vertices, mesh.faces):.0f} % of the surface's area is in slivers "
               f"(triangles over about 6 times longer than wide), far too stiff as flat shell facets")
        ctx.step(f"{mesh.n_faces} triangles: solving a well-shaped copy of about {copy}")
    else:
        ctx.step(f"solving {mesh.n_vertices * 6} DOF")
    try:
        spread = replace(case, point_nodes=None, point_forces=None)  # the loads over the area
        result = analyse_shell(mesh, surface.supports, loads, thickness=thickness, material=material,
                               max_triangles=limit, distributed=lambda facets: shell_nodal_loads(
                                   facets, spread, thickness=thickness, density=project.shell.density))
    except MechanismError as error:
        error.hint = ('support more of the surface or restrain more directions: [[supports]] select and '
                      'restraint = "pinned" instead of rollers (with --surface: --supports boundary)')
        raise
    ctx.step("writing")
    save_result(result, ctx.folder / "shell.npz")
    n1, n2 = result.face_principal_forces[:, 0], result.face_principal_forces[:, 1]
    summary = {"load_case": case.name, "thickness_m": thickness, "E_Pa": project.shell.E, "nu": project.shell.nu,
               "max_displacement_m": float(np.linalg.norm(result.displacements[:, :3], axis=1).max()),
               "N1_max_N_per_m": float(n1.max()), "N2_min_N_per_m": float(n2.min()),
               "equilibrium_error": float(result.equilibrium_error), "solver": result.solver,
               "total_load_N": [float(x) for x in result.load_total[:3]],
               "total_reaction_N": [float(x) for x in result.reactions[:, :3].sum(axis=0)],
               "surface_triangles": mesh.n_faces, "analysed_triangles": result.analysed_triangles}
    if why is not None:
        summary["analysed_on"] = f"a well-shaped copy of {result.analysed_triangles} triangles: {why}"
    write_text_atomic(ctx.folder / "shell.json", json.dumps(summary, indent=1))
    ctx.step("drawing")
    plot_principal_forces(mesh, result.face_principal_forces, result.face_principal_directions,
                          ctx.folder / "stress.png", support_nodes=surface.supports.nodes,
                          title=f"{project.project.name}: principal membrane forces ({case.name})")
    return result


def load(folder: Path, project: Project) -> ShellResult:
    return load_result(ShellResult, folder / "shell.npz")
