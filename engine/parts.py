"""The grid's part labels: node i -> N0001, beam k (row k of the grid's beams) -> B0001, which the
engine's findings name. Indices are 0-based, labels 1-based. The fabricated parts' labels (joints,
panels, stock sheets and bars) are fabrication.ids', which re-exports these two."""

from __future__ import annotations

__all__ = ["node_id", "beam_id"]


def node_id(i: int) -> str:
    """N0001 for node 0."""
    return f"N{int(i) + 1:04d}"


def beam_id(k: int) -> str:
    """B0001 for beam 0."""
    return f"B{int(k) + 1:04d}"
