"""DSTV NC1 files for the tube saw: one file per beam, ``beams/nc1/B0001.nc1`` (mm, degrees).

A file has the blocks ST (the header: order, drawing, phase, piece, steel grade, quantity,
profile, profile code RO for round tubes or M for rectangular hollow sections, length, saw length,
height (a round tube's outer diameter), width (the diameter again), wall as flange and web
thickness, radius 0, kg/m, paint area m^2/m, web and flange start and end cut angles, four text
lines), SI (the piece id engraved on the web, 10 mm
from the start) and BO (the holes the joint needs: through holes across the tube at each end, for
the socket's pin or the steel joint's bolt), and ends with EN. Cuts are square (angles 0): the
joints take plain tube ends. The slot of a steel joint's fin plate is not in the file (text line 1
says so).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .files import write_text_atomic
from .joints import JointSettings, joint_sleeve_mm

__all__ = ["Nc1Piece", "nc1_pieces", "nc1_text", "write_nc1_files", "grade_name"]


@dataclass(frozen=True, kw_only=True)
class Nc1Piece:
    """One beam as the saw sees it (mm, kg/m, m^2/m, degrees): a round tube (``code`` RO) of outer
    diameter ``height_mm``, or a rectangular hollow section (M) ``height_mm`` by ``width_mm``;
    holes: (distance from the start, diameter) of each through hole, across the web."""

    piece: str
    profile: str
    grade: str
    length_mm: float
    height_mm: float
    wall_mm: float
    mass_per_m: float
    paint_m2_per_m: float
    start_cut_deg: float = 0.0
    end_cut_deg: float = 0.0
    holes: tuple[tuple[float, float], ...] = ()
    note: str = ""
    code: str = "RO"
    width_mm: float | None = None


def _number(value: float) -> str:
    return f"{value:.2f}"


def nc1_text(piece: Nc1Piece, *, order: str, drawing: str, phase: str = "1", quantity: int = 1) -> str:
    """The NC1 text of one piece."""
    width = piece.height_mm if piece.width_mm is None else piece.width_mm
    header = [order, drawing, phase, piece.piece, piece.grade, str(quantity), piece.profile, piece.code,
              _number(piece.length_mm), _number(piece.length_mm), _number(piece.height_mm),
              _number(width), _number(piece.wall_mm), _number(piece.wall_mm), _number(0.0),
              f"{piece.mass_per_m:.4f}", f"{piece.paint_m2_per_m:.4f}",
              _number(piece.start_cut_deg), _number(piece.end_cut_deg),
              _number(piece.start_cut_deg), _number(piece.end_cut_deg),
              piece.note or "-", "gridshell", "-", "-"]
    lines = ["ST", f"** {piece.piece} {piece.profile}", *(f"  {value}" for value in header)]
    lines += ["SI", f"  v {_number(10.0)}u {_number(0.5 * piece.height_mm)} 0.00 10r{piece.piece}"]
    if piece.holes:
        lines.append("BO")
        lines += [f"  v {_number(x)}u {_number(0.5 * piece.height_mm)} {_number(d)} 0.00" for x, d in piece.holes]
    lines.append("EN")
    return "\n".join(lines) + "\n"


def grade_name(material_name: str) -> str:
    """The grade as a fabricator writes it: S355, EN AW-6063, or the material name."""
    kind, _, grade = material_name.partition("_")
    if kind == "steel":
        return grade.upper()
    if kind == "aluminium":
        return f"EN AW-{grade}"
    return material_name


def nc1_pieces(table: pd.DataFrame, heights_mm: np.ndarray, walls_mm: np.ndarray, masses_per_m: np.ndarray,
               joint_settings: JointSettings, material_name: str, *,
               widths_mm: np.ndarray | None = None) -> list[Nc1Piece]:
    """A piece per beam of the cut list with a cut length: round tubes of outer diameter
    ``heights_mm``, or where ``widths_mm`` are given rectangular hollow sections (per beam, mm);
    the joint's pin (socket) or bolt (steel) hole at each end, where the joint reaches into it."""
    steel = joint_settings.kind == "steel"
    hole = joint_settings.bolt_hole_mm if steel else joint_settings.pin_hole_mm
    note = "fin plate slots at both ends (see the joint drawings)" if steel else "ends into printed sockets"
    widths = [None] * len(heights_mm) if widths_mm is None else widths_mm
    pieces = []
    for row, h, w, t, kg in zip(table.itertuples(index=False), heights_mm, widths, walls_mm, masses_per_m):
        length = float(row.cut_length_mm)
        if length <= 0:
            continue
        size = float(h) if w is None else max(float(h), float(w))  # the joint's size of this beam
        reach = (0.5 if steel else 0.6) * joint_sleeve_mm(joint_settings, size)
        holes = tuple((x, hole) for x in (reach, length - reach)) if length > 2 * reach else ()
        paint = np.pi * h / 1000.0 if w is None else 2.0 * (h + w) / 1000.0
        pieces.append(Nc1Piece(piece=row.id, profile=str(row.profile), grade=grade_name(material_name),
                               length_mm=length, height_mm=float(h), wall_mm=float(t), mass_per_m=float(kg),
                               paint_m2_per_m=float(paint), code="RO" if w is None else "M",
                               width_mm=None if w is None else float(w),
                               start_cut_deg=float(row.end_angle_start_deg), end_cut_deg=float(row.end_angle_end_deg),
                               holes=holes, note=note))
    return pieces


def write_nc1_files(pieces: list[Nc1Piece], folder: Path, *, order: str, drawing: str) -> list[Path]:
    """``folder/ID.nc1`` for every piece, each written atomically."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for piece in pieces:
        path = folder / f"{piece.piece}.nc1"
        write_text_atomic(path, nc1_text(piece, order=order, drawing=drawing))
        paths.append(path)
    return paths
