"""Shared set-up of the matplotlib pictures: Agg backend, atomic PNG saving."""

from __future__ import annotations

from pathlib import Path

from fabrication.files import atomic_path

__all__ = ["pyplot", "save_png"]


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_png(fig, path: Path, dpi: int = 130) -> Path:
    """Save ``fig`` as PNG atomically and close it."""
    plt = pyplot()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    plt.close(fig)
    return Path(path)
