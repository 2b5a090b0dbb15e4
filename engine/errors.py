"""Exceptions raised by gridshell.

``GridshellError`` and its subclasses are *user* errors: bad input, a bad mesh, an
empty selection, a mechanism. The command line turns them into one clear message
and exit code 2. Any other exception is a bug and keeps its traceback.
"""

from __future__ import annotations

__all__ = [
    "GridshellError",
    "InputError",
    "MeshError",
    "SelectionError",
    "MechanismError",
    "ConvergenceError",
    "FabricationError",
]


class GridshellError(Exception):
    """Base class of every error caused by the user's input or model, not by a bug.

    ``hint`` says what to do about it; the CLI prints it under the message.
    """

    def __init__(self, message: str, *, hint: str | None = None) -> None:
        super().__init__(message)
        self.hint = hint

    def __str__(self) -> str:
        text = super().__str__()
        return f"{text}\n  hint: {self.hint}" if self.hint else text

    def __reduce__(self):
        # pickled by state, not by calling __init__ again: a subclass with required keyword
        # arguments (MechanismError's n_modes) then comes back from a worker process as itself
        return _rebuild, (type(self), self.args, self.__dict__)


def _rebuild(cls: type[GridshellError], args: tuple, state: dict) -> GridshellError:
    """A GridshellError of class ``cls`` from its arguments and attributes (unpickling)."""
    error = Exception.__new__(cls)
    error.args = args
    error.__dict__.update(state)
    return error


class InputError(GridshellError, ValueError):
    """Raised for a missing file, an unreadable format or a bad value."""


class MeshError(GridshellError, ValueError):
    """Raised when a surface mesh fails its checks (non-manifold, NaN, not disk-like...)."""


class SelectionError(GridshellError, ValueError):
    """Raised when a support or load selection matches no node."""


class MechanismError(GridshellError):
    """Raised when a structure is a mechanism: too few supports or a kinematic joint.

    ``n_modes`` is the number of free rigid-body or mechanism modes found.
    """

    def __init__(self, message: str, *, n_modes: int, hint: str | None = None) -> None:
        super().__init__(message, hint=hint)
        self.n_modes = n_modes


class ConvergenceError(GridshellError):
    """Raised when an iterative analysis does not converge within its settings."""


class FabricationError(RuntimeError):
    """A part could not be built or written: the CAD kernel's boolean or tessellation failed, or a
    STEP part file is not what its writer expects. Not the user's mistake; where a part fails, the
    fabrication stage reports it as a finding and carries on."""
