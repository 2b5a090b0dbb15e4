"""gridshell engine: pure computation on numpy arrays (meshes, shell and frame FE, fields, remeshing).

Imports nothing from ``workflow`` or ``fabrication``; heavy optional libraries are imported lazily.
"""

import logging

from .errors import ConvergenceError, GridshellError, InputError, MechanismError, MeshError, SelectionError
from .mesh import PolyMesh, TriMesh
from .structure.loads import LimitState, LoadCase, LoadCombination
from .structure.supports import Supports

logging.getLogger(__name__).addHandler(logging.NullHandler())  # the CLI adds handlers (--verbose)

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
