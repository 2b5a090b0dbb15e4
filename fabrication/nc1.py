"""DSTV NC1 files for the tube saw: one file per beam, ``beams/nc1/B0001.nc1`` (mm, degrees).

A file has the blocks ST (the header: order, drawing, phase, piece, steel grade, quantity,
profile, profile code RO for round tubes, length, saw length, outer diameter, width (the
diameter again), wall as flange and web thickness, radius 0, kg/m, paint area m^2/m, web and
flange start and end cut angles, four text lines), SI (the piece id engraved on the web, 10 mm
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
    """One beam as the saw sees it (mm, kg/m, m^2/m, degrees); holes: (distance from the start,
    diameter) of each through hole."""

    piece: str
    profile: str
    grade: str
    length_mm: float
    diameter_mm: float
    wall_mm: float
    mass_per_m: float
    paint_m2_per_m: float
    start_cut_deg: float = 0.0
    end_cut_deg: float = 0.0
    holes: tuple[tuple[float, float], ...] = ()
    note: str = ""


def _number(value: float) -> str:
    return f"{value:.2f}"


def nc1_text(piece: Nc1Piece, *, order: str, drawing: str, phase: str = "1", quantity: int = 1) -> str:
    """The NC1 text of one piece."""
    header = [order, drawing, phase, piece.piece, piece.grade, str(quantity), piece.profile, "RO",
              _number(piece.length_mm), _number(piece.length_mm), _number(piece.diameter_mm),
              _number(piece.diameter_mm), _number(piece.wall_mm), _number(piece.wall_mm), _number(0.0),
              f"{piece.mass_per_m:.4f}", f"{piece.paint_m2_per_m:.4f}",
              _number(piece.start_cut_deg), _number(piece.end_cut_deg),
              _number(piece.start_cut_deg), _number(piece.end_cut_deg),
              piece.note or "-", "gridshell", "-", "-"]
    lines = ["ST", f"** {piece.piece} {piece.profile}", *(f"  {value}" for value in header)]
    lines += ["SI", f"  v {_number(10.0)}u {_number(0.5 * piece.diameter_mm)} 0.00 10r{piece.piece}"]
    if piece.holes:
        lines.append("BO")
        lines += [f"  v {_number(x)}u {_number(0.5 * piece.diameter_mm)} {_number(d)} 0.00" for x, d in piece.holes]
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


def nc1_pieces(table: pd.DataFrame, diameters_mm: np.ndarray, walls_mm: np.ndarray, masses_per_m: np.ndarray,
               joint_settings: JointSettings, material_name: str) -> list[Nc1Piece]:
    """A piece per beam of the cut list with a cut length (``diameters_mm`` etc. per beam): the
    joint's pin (socket) or bolt (steel) hole at each end, where the joint reaches into the tube."""
    steel = joint_settings.kind == "steel"
    hole = joint_settings.bolt_hole_mm if steel else joint_settings.pin_hole_mm
    note = "fin plate slots at both ends (see the joint drawings)" if steel else "ends into printed sockets"
    pieces = []
    for row, D, t, kg in zip(table.itertuples(index=False), diameters_mm, walls_mm, masses_per_m):
        length = float(row.cut_length_mm)
        if length <= 0:
            continue
        reach = (0.5 if steel else 0.6) * joint_sleeve_mm(joint_settings, float(D))
        holes = tuple((x, hole) for x in (reach, length - reach)) if length > 2 * reach else ()
        pieces.append(Nc1Piece(piece=row.id, profile=str(row.profile), grade=grade_name(material_name),
                               length_mm=length, diameter_mm=float(D), wall_mm=float(t), mass_per_m=float(kg),
                               paint_m2_per_m=float(np.pi * D / 1000.0),
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
