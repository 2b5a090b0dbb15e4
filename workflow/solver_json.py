"""The solver-level JSON interfaces (docs/formats.md) of ``gridshell frame`` and ``gridshell shell``:
a frame or shell model, its supports and loads in as a JSON object, the engine's results out as one.
Reading and checking the objects is interface work, so it lives here and the engine stays numerics."""

from __future__ import annotations

from typing import Any

import numpy as np

from engine.errors import InputError
from engine.mesh import TriMesh
from engine.structure.corotational import nonlinear_static
from engine.structure.frame import FrameModel, factor_stiffness, linear_buckling, linear_static
from engine.structure.loads import LoadCase
from engine.structure.shell import ShellMaterial, analyse_shell, shell_nodal_loads
from engine.structure.supports import DOF_NAMES, Supports

__all__ = ["require", "node_table", "model_from_json", "solve_frame_json", "solve_shell_json"]


def require(data: dict, key: str, where: str, hint: str = "see docs/formats.md") -> Any:
    """data[key], or an InputError naming ``where`` and the missing key."""
    if key not in data:
        raise InputError(f"{where}: missing key '{key}'", hint=hint)
    return data[key]


def node_table(table: Any, name: str, n: int, where: str) -> tuple[np.ndarray, np.ndarray]:
    """(node ids (k,), values (k,6)) of an object keyed by node index with lists of 6 values
    (supports' flags, loads' forces and moments), each node in 0..n-1."""
    if not isinstance(table, dict):
        raise InputError(f"{where}: '{name}' must be an object keyed by node index")
    nodes, values = [], []
    for key, value in table.items():
        try:
            node = int(key)
        except ValueError:
            raise InputError(f"{where}: '{name}' key {key!r} is not a node index") from None
        if not 0 <= node < n:
            raise InputError(f"{where}: '{name}' node {node} is out of range 0..{n - 1}")
        if not isinstance(value, (list, tuple)) or len(value) != 6:
            raise InputError(f"{where}: '{name}' of node {node} must be a list of 6 values")
        nodes.append(node)
        values.append(value)
    return np.array(nodes, dtype=np.int64), np.array(values, dtype=float).reshape(len(nodes), 6)


# ----------------------------------------------------------------------------- frame

def model_from_json(data: dict) -> tuple[FrameModel, Supports, np.ndarray]:
    """(FrameModel, Supports, loads (n,6)) from the solver-level JSON object (docs/formats.md)."""
    try:
        nodes = np.array(require(data, "nodes", "frame model"), dtype=float)
    except (TypeError, ValueError):
        raise InputError("frame model: nodes must be [[x, y, z], ...]") from None
    beams = require(data, "beams", "frame model")
    if not isinstance(beams, list) or not beams:
        raise InputError("frame model: beams must be a non-empty list")
    fields = {k: [] for k in ("nodes", "E", "G", "A", "Iy", "Iz", "J", "up")}
    for i, beam in enumerate(beams):
        for key in fields:
            if key == "up" and key not in beam:
                fields[key].append([0.0, 0.0, 1.0])
                continue
            fields[key].append(require(beam, key, f"frame model: beam {i}"))
    n = len(nodes)
    releases = None
    if any("releases" in beam for beam in beams):
        releases = np.array([beam.get("releases", [[0] * 6, [0] * 6]) for beam in beams], dtype=bool)
    model = FrameModel(nodes=nodes, beams=np.array(fields["nodes"]), E=fields["E"], G=fields["G"], A=fields["A"],
                       Iy=fields["Iy"], Iz=fields["Iz"], J=fields["J"], up=np.array(fields["up"], dtype=float),
                       elements_per_beam=int(data.get("elements_per_beam", 1)), releases=releases)
    support_nodes, flags = node_table(require(data, "supports", "frame model"), "supports", n, "frame model")
    supports = Supports(nodes=support_nodes, restraints=flags.astype(bool))
    load_nodes, forces = node_table(data.get("loads", {}), "loads", n, "frame model")
    loads = np.zeros((n, 6))
    np.add.at(loads, load_nodes, forces)
    return model, supports, loads


def solve_frame_json(data: dict, *, analysis: str = "linear", modes: int = 6,
                     control: tuple[int, str] | None = None, max_load_factor: float | None = None) -> dict:
    """Solve a frame model given as a JSON object; return the result object (docs/formats.md)."""
    if analysis not in ("linear", "buckling", "nonlinear"):
        raise InputError(f"frame: analysis must be linear, buckling or nonlinear, got {analysis!r}")
    model, supports, loads = model_from_json(data)
    stiffness = factor_stiffness(model, supports)
    linear = linear_static(model, supports, loads, stiffness=stiffness)
    result = {"displacements": linear.displacements.tolist(),
              "reactions": {str(int(n)): linear.reactions[n].tolist() for n in supports.nodes},
              "buckling_factors": [], "path": [], "limit_load_factor": None,
              "equilibrium_error": linear.equilibrium_error}
    if analysis == "buckling":
        result["buckling_factors"] = linear_buckling(model, supports, loads, n_modes=modes,
                                                     stiffness=stiffness).factors.tolist()
    if analysis == "nonlinear":
        if control is None:
            node = int(np.argmax(np.linalg.norm(linear.displacements[:, :3], axis=1)))
            dof = int(np.argmax(np.abs(linear.displacements[node, :3])))
        else:
            node, name = control
            if name not in DOF_NAMES:
                raise InputError(f"frame: control DOF must be one of {', '.join(DOF_NAMES)}, got {name!r}")
            dof = DOF_NAMES.index(name)
        run = nonlinear_static(model, supports, loads, control=(int(node), dof),
                               max_load_factor=max_load_factor if max_load_factor is not None else 10.0,
                               max_steps=200)
        result["path"] = run.path.tolist()
        result["limit_load_factor"] = run.limit_load_factor
        result["displacements"] = run.displacements.tolist()
    return result


# ----------------------------------------------------------------------------- shell

_HINT = "see docs/formats.md: nodes, triangles, thickness, material, supports, loads"


def solve_shell_json(model: dict) -> dict:
    """Solve a shell model given as a JSON object (docs/formats.md) and return the result object."""
    try:
        vertices = np.array(require(model, "nodes", "shell model", hint=_HINT), dtype=float)
        triangles = np.array(require(model, "triangles", "shell model", hint=_HINT), dtype=np.int64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"shell model: nodes must be [[x,y,z],...] and triangles [[i,j,k],...] ({exc})") from None
    if vertices.ndim != 2 or vertices.shape[1] != 3 or triangles.ndim != 2 or triangles.shape[1] != 3:
        raise InputError("shell model: nodes must be [[x,y,z],...] and triangles [[i,j,k],...]")
    if triangles.size and (triangles.min() < 0 or triangles.max() >= len(vertices)):
        raise InputError(f"shell model: a triangle refers to a node outside 0..{len(vertices) - 1}")
    material_data = require(model, "material", "shell model", hint=_HINT)
    try:
        material = ShellMaterial(E=float(material_data["E"]), nu=float(material_data["nu"]),
                                 density=float(material_data.get("density", 0.0)))
    except (KeyError, TypeError) as exc:
        raise InputError(f"shell model: material needs E and nu ({exc})") from None
    thickness = float(require(model, "thickness", "shell model", hint=_HINT))
    mesh = TriMesh(vertices=vertices, faces=triangles, name="model")
    n = len(vertices)
    support_table = require(model, "supports", "shell model", hint=_HINT)
    support_nodes, flags = node_table(support_table, "supports", n, "shell model")
    supports = Supports(nodes=support_nodes, restraints=flags.astype(bool))
    load_nodes, forces = node_table(model.get("loads", {}), "loads", n, "shell model")
    loads = np.zeros((n, 6))
    np.add.at(loads, load_nodes, forces)
    area_load = np.asarray(model.get("area_load", [0.0, 0.0, 0.0]), dtype=float)
    if area_load.shape != (3,):
        raise InputError("shell model: area_load must be [qx, qy, qz]")
    case = LoadCase(name="model", self_weight=1.0 if model.get("self_weight", False) else 0.0, area_true=area_load)
    loads += shell_nodal_loads(mesh, case, thickness=thickness, density=material.density)
    result = analyse_shell(mesh, supports, loads, thickness=thickness, material=material)
    return {
        "displacements": result.displacements.tolist(),
        "membrane_forces": [{"N1": float(a), "N2": float(b), "direction": d.tolist()}
                            for (a, b), d in zip(result.face_principal_forces, result.face_principal_directions)],
        "reactions": {str(int(node)): result.reactions[node].tolist() for node in supports.nodes},
        "equilibrium_error": result.equilibrium_error,
    }
