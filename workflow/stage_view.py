"""What a stage may read of the project: the sections in its cache key, and those of its upstream
stages (whose keys are in its key).

The runner calls each stage with ``stage_view(project, sections)``: the same Project, with every
section (or key of a section) outside ``sections`` replaced by a guard that raises
:class:`UndeclaredSetting` when it is used. So a stage that reads a setting its cache key does not
hold fails in the tests at its first run, instead of being taken from the cache after that setting
changed.
"""

from __future__ import annotations

from typing import Any, NoReturn

from pydantic import BaseModel

from .config import Project

__all__ = ["UndeclaredSetting", "stage_view"]


class UndeclaredSetting(RuntimeError):
    """A stage read a project setting that is not in its cache key (a bug: declare the section in
    ``workflow.config.STAGE_SECTIONS``)."""


class _Undeclared:
    """Stands for a setting outside a stage's sections: any use of it raises UndeclaredSetting."""

    __slots__ = ("_path", "_stage")

    def __init__(self, path: str, stage: str) -> None:
        object.__setattr__(self, "_path", path)
        object.__setattr__(self, "_stage", stage)

    def _refuse(self, *_: Any, **__: Any) -> NoReturn:
        path, stage = object.__getattribute__(self, "_path"), object.__getattribute__(self, "_stage")
        raise UndeclaredSetting(f"the {stage} stage read [{path}], which is not in its cache key; add it to "
                                f"STAGE_SECTIONS[{stage!r}] in workflow/config.py")

    def __getattr__(self, name: str) -> NoReturn:
        self._refuse()

    def __repr__(self) -> str:
        return f"<[{object.__getattribute__(self, '_path')}]: not in the cache key>"


for _name in ("__bool__", "__float__", "__int__", "__index__", "__iter__", "__len__", "__contains__", "__getitem__",
              "__eq__", "__ne__", "__lt__", "__le__", "__gt__", "__ge__", "__hash__", "__str__", "__format__",
              "__add__", "__radd__", "__sub__", "__rsub__", "__mul__", "__rmul__", "__truediv__", "__rtruediv__",
              "__pow__", "__neg__", "__abs__", "__round__", "__call__", "__setattr__", "__fspath__"):
    setattr(_Undeclared, _name, _Undeclared._refuse)


def _restricted(model: BaseModel, allowed: set[str], prefix: str, stage: str) -> BaseModel:
    """``model`` with every field not allowed (by itself, by a parent, or holding an allowed key)
    replaced by a guard."""
    update: dict[str, Any] = {}
    for name in type(model).model_fields:
        path = f"{prefix}{name}"
        if path in allowed:
            continue
        inner = [a for a in allowed if a.startswith(path + ".")]
        value = getattr(model, name)
        if inner and isinstance(value, BaseModel):
            update[name] = _restricted(value, allowed, path + ".", stage)
        else:
            update[name] = _Undeclared(path, stage)
    return model.model_copy(update=update) if update else model


def stage_view(project: Project, sections: tuple[str, ...] | list[str], stage: str) -> Project:
    """``project`` as ``stage`` may read it: the sections (or dotted keys, "fabrication.joints")
    in ``sections``, every other one a guard that raises UndeclaredSetting when used."""
    return _restricted(project, set(sections), "", stage)  # type: ignore[return-value]
