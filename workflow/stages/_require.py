"""Import an engine or fabrication function for a stage, or report the stage as not available."""

from __future__ import annotations

import importlib
from typing import Any

from ..runner import StageNotAvailable

__all__ = ["require"]


def require(stage: str, module: str, *names: str) -> Any:
    """The named attributes of ``module``; ``StageNotAvailable`` naming the stage if any is missing."""
    try:
        loaded = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name and module.startswith(exc.name):
            raise StageNotAvailable(f"stage '{stage}' is not available in this version of gridshell "
                                    f"({module} is missing)") from None
        raise
    missing = [n for n in names if not hasattr(loaded, n)]
    if missing:
        raise StageNotAvailable(f"stage '{stage}' is not available in this version of gridshell "
                                f"({module} lacks {', '.join(missing)})")
    values = [getattr(loaded, n) for n in names]
    return values[0] if len(values) == 1 else values
