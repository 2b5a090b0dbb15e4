"""Part labels, shared by every file a job writes: joint at node i -> J0001, panel p -> P0001, stock
sheet s -> SHEET01, stock bar b -> BAR001; and the grid's own, node i -> N0001 and beam k (row k
of the grid's beams) -> B0001, which the engine's findings name too and so keeps in engine.parts.
Indices are 0-based, labels 1-based. Label parts here, never inline."""

from __future__ import annotations

from engine.parts import beam_id, node_id

__all__ = ["node_id", "beam_id", "panel_id", "joint_id", "sheet_id", "bar_id"]


def panel_id(p: int) -> str:
    """P0001 for panel 0."""
    return f"P{int(p) + 1:04d}"


def joint_id(i: int) -> str:
    """J0001 for the joint at node 0."""
    return f"J{int(i) + 1:04d}"


def sheet_id(s: int) -> str:
    """SHEET01 for stock sheet 0."""
    return f"SHEET{int(s) + 1:02d}"


def bar_id(b: int) -> str:
    """BAR001 for stock bar 0."""
    return f"BAR{int(b) + 1:03d}"
