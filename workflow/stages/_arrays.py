"""Saving and loading frozen result dataclasses as .npz (arrays) with a JSON side-car for scalars."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from fabrication.files import atomic_path

__all__ = ["save_result", "load_result"]


def save_result(result: Any, path: Path) -> Path:
    """Write every array field of a dataclass to ``path`` (.npz); scalars go in as 0-d arrays."""
    arrays: dict[str, np.ndarray] = {}
    for f in dataclasses.fields(result):
        value = getattr(result, f.name)
        if value is None:
            continue
        if isinstance(value, (np.ndarray, int, float, bool, np.generic)):
            arrays[f.name] = np.asarray(value)
        elif isinstance(value, (list, tuple)) and all(isinstance(v, np.ndarray) for v in value) and value:
            for i, v in enumerate(value):
                arrays[f"{f.name}__{i}"] = v
        elif isinstance(value, (str, dict, list, tuple)):
            arrays[f"{f.name}__json"] = np.array(json.dumps(value, default=float))
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, **arrays)
    return path


def load_result(cls: type, path: Path) -> Any:
    """Rebuild a dataclass saved by ``save_result`` (fields missing from the file get defaults)."""
    with np.load(path, allow_pickle=False) as data:
        values: dict[str, Any] = {}
        lists: dict[str, dict[int, np.ndarray]] = {}
        for key in data.files:
            if key.endswith("__json"):
                values[key[:-6]] = json.loads(str(data[key]))
            elif "__" in key:
                name, index = key.rsplit("__", 1)
                lists.setdefault(name, {})[int(index)] = data[key]
            else:
                array = data[key]
                values[key] = array.item() if array.ndim == 0 else array
        for name, items in lists.items():
            values[name] = tuple(items[i] for i in sorted(items))
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in values.items() if k in names})
