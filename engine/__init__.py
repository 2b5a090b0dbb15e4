"""gridshell engine: pure computation on numpy arrays (meshes, shell and frame FE, fields, remeshing).

Imports nothing from ``workflow`` or ``fabrication``; heavy optional libraries are imported lazily.
"""

from .errors import ConvergenceError, GridshellError, InputError, MechanismError, MeshError, SelectionError
from .loads import LimitState, LoadCase, LoadCombination
from .mesh import PolyMesh, TriMesh
from .supports import Supports

__all__ = [
    "ConvergenceError",
    "GridshellError",
    "InputError",
    "LimitState",
    "LoadCase",
    "LoadCombination",
    "MechanismError",
    "MeshError",
    "PolyMesh",
    "SelectionError",
    "Supports",
    "TriMesh",
]
