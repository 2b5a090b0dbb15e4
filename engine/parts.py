"""Part labels, shared by every file a job writes: node i -> N0001, beam k (row k of the grid's
beams) -> B0001, panel p -> P0001, joint at node i -> J0001, stock sheet s -> SHEET01, stock bar
b -> BAR001. Indices are 0-based, labels 1-based."""

from __future__ import annotations

__all__ = ["node_id", "beam_id", "panel_id", "joint_id", "sheet_id", "bar_id"]


def node_id(i: int) -> str:
    """N0001 for node 0."""
    return f"N{int(i) + 1:04d}"


def beam_id(k: int) -> str:
    """B0001 for beam 0."""
    return f"B{int(k) + 1:04d}"


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
