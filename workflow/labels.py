"""What the report calls the figures of the stages' JSON: a label an engineer would say, one unit
and the scale into it, and numbers written as people write them (no ``e-07``).

A key without an entry in LABELS is read from its name: its unit suffix (``_m``, ``_N_per_m``,
``_deg``, ``_share``...) gives the unit and the rest, spaced, the label.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["LABELS", "label_of", "in_unit", "format_value", "figure_rows", "column_label"]

#: key -> (label, unit, factor from the stored value to the unit)
LABELS: dict[str, tuple[str, str, float]] = {
    # shell
    "load_case": ("load case", "", 1.0),
    "thickness_m": ("shell thickness", "mm", 1e3),
    "E_Pa": ("Young's modulus", "GPa", 1e-9),
    "nu": ("Poisson's ratio", "", 1.0),
    "max_displacement_m": ("largest displacement", "mm", 1e3),
    "N1_max_N_per_m": ("largest principal membrane force N1", "kN/m", 1e-3),
    "N2_min_N_per_m": ("smallest principal membrane force N2", "kN/m", 1e-3),
    "equilibrium_error": ("equilibrium error (residual / load)", "", 1.0),
    "total_load_N": ("total load", "kN", 1e-3),
    "total_reaction_N": ("total reaction", "kN", 1e-3),
    "surface_triangles": ("triangles of the surface", "", 1.0),
    "analysed_triangles": ("triangles analysed (a well-shaped copy where they differ)", "", 1.0),
    # field
    "max_size_ratio_D": ("size ratio bound D", "", 1.0),
    "max_aspect_A": ("aspect bound A", "", 1.0),
    "achieved_size_ratio": ("size ratio reached", "", 1.0),
    "achieved_max_aspect": ("largest aspect reached", "", 1.0),
    "mean_aspect": ("mean aspect", "", 1.0),
    "size_map": ("size from", "", 1.0),
    "anisotropy_map": ("anisotropy from", "", 1.0),
    "symmetry_planes": ("symmetry planes", "", 1.0),
    # grids
    "hexagon_share_interior": ("hexagons among interior cells", "%", 100.0),
    "valence3_share_interior": ("interior nodes with three beams", "%", 100.0),
    "size_correlation": ("size correlation with the field (Pearson)", "", 1.0),
    "size_rank_correlation": ("size rank correlation with the field (Spearman)", "", 1.0),
    "size_grading_slope": ("size grading slope", "", 1.0),
    "size_ratio_p5_p95": ("size ratio, 95th over 5th percentile", "", 1.0),
    "n_nodes": ("nodes", "", 1.0),
    "n_beams": ("beams", "", 1.0),
    "n_faces": ("cells", "", 1.0),
    "total_length_m": ("total beam length", "m", 1.0),
    "mean_beam_length_m": ("mean beam", "mm", 1e3),
    "shortest_beam_m": ("shortest beam", "mm", 1e3),
    "smallest_angle_deg": ("smallest cell corner", "deg", 1.0),
    "planarity_max_m": ("largest planarity error", "mm", 1e3),
    "planarity_p95_m": ("planarity error, 95th percentile", "mm", 1e3),
    "planarity_max_rel": ("largest planarity error / mean beam", "%", 100.0),
    "planarity_p95_rel": ("planarity error (95th percentile) / mean beam", "%", 100.0),
    "closeness_max_rel": ("largest distance to the surface / diagonal", "%", 100.0),
    "closeness_mean_rel": ("mean distance to the surface / diagonal", "%", 100.0),
    "closeness_max_beam_rel": ("largest distance to the surface / mean beam", "%", 100.0),
    "regularity": ("irregularity (spread of the sides, un-stretched)", "%", 100.0),
    "nonconvex_faces": ("non-convex cells", "", 1.0),
    "folded_cells": ("cells folded over (overlapping a neighbour)", "", 1.0),
    # analysis
    "uls_combination": ("ULS combination", "", 1.0),
    "sls_combination": ("SLS combination", "", 1.0),
    "delta_L_m": ("largest displacement, linear (SLS) delta_L", "mm", 1e3),
    "max_vertical_sls_m": ("largest vertical deflection (SLS)", "mm", 1e3),
    "deflection_limit_m": ("deflection limit", "mm", 1e3),
    "max_utilisation": ("largest member utilisation (ULS)", "", 1.0),
    "governing_member": ("governing member", "", 1.0),
    "lambda_LB": ("linear buckling load factor", "", 1.0),
    "lambda_NL_perfect": ("non-linear limit load factor, perfect", "", 1.0),
    "lambda_NL_worst": ("non-linear limit load factor, worst imperfection", "", 1.0),
    "worst_imperfection": ("worst imperfection", "", 1.0),
    "knock_down": ("knock-down (worst / perfect)", "", 1.0),
    "imperfection_amplitude_m": ("imperfection amplitude", "mm", 1e3),
    "tolerable_deflection_m": ("tolerable deflection of the non-linear paths", "mm", 1e3),
    "control_node": ("control node", "", 1.0),
    "beam_mass_kg": ("beam mass", "kg", 1.0),
    # fabrication
    "joints": ("joints", "", 1.0),
    "panels": ("panels", "", 1.0),
    "sheets": ("stock sheets used", "", 1.0),
    "sheet_utilisation": ("sheet area used", "%", 100.0),
    "bars_used": ("stock bars used", "", 1.0),
    "bars_lower_bound": ("stock bars, lower bound", "", 1.0),
    "min_cut_length_mm": ("minimum cut length", "mm", 1.0),
    "min_angle_deg": ("smallest angle at a joint", "deg", 1.0),
    "shortest_beam_mm_at_120deg": ("shortest buildable beam between 120-degree joints", "mm", 1.0),
    "shortest_cut_length_mm": ("shortest cut length", "mm", 1.0),
    "joints_with_a_problem": ("joints with a problem", "", 1.0),
    "joint_clashes": ("joint clashes (solids intersecting)", "", 1.0),
    "tube_clashes": ("tubes running into another tube or a joint", "", 1.0),
}

#: unit suffixes of keys, longest first: suffix -> (unit, factor)
_SUFFIXES: list[tuple[str, str, float]] = [
    ("_N_per_m", "kN/m", 1e-3), ("_kN_per_m", "kN/m", 1.0), ("_mm2", "mm2", 1.0), ("_mm3", "mm3", 1.0),
    ("_m2", "m2", 1.0), ("_deg", "deg", 1.0), ("_kg", "kg", 1.0), ("_kN", "kN", 1.0), ("_Pa", "MPa", 1e-6),
    ("_mm", "mm", 1.0), ("_share", "%", 100.0), ("_rel", "%", 100.0), ("_m", "m", 1.0), ("_N", "kN", 1e-3),
    ("_s", "s", 1.0),
]

#: table column names (CSV headers) -> what the report heads them with
_COLUMNS = {"length_m": "length (m)", "axial_force_kN": "axial force (kN)", "area_mm2": "area (mm2)",
            "perimeter_mm": "perimeter (mm)", "planarity_mm": "planarity (mm)", "thickness_mm": "thickness (mm)",
            "mass_kg": "mass (kg)", "cut_length_m": "cut length (m)",
            "largest_deflection_mm": "largest deflection (mm)", "vertex_count": "corners",
            "start_node": "start node", "end_node": "end node",
            "governing_check": "governing check", "lambda_NL": "non-linear limit load factor",
            "section_class": "section class (EN 1993-1-1)"}


def label_of(key: str) -> tuple[str, str, float]:
    """(label, unit, factor) of a JSON key: LABELS, else read from its unit suffix."""
    if key in LABELS:
        return LABELS[key]
    for suffix, unit, factor in _SUFFIXES:
        if key.endswith(suffix) and len(key) > len(suffix):
            return key[: -len(suffix)].replace("_", " "), unit, factor
    return key.replace("_", " "), "", 1.0


def column_label(name: str) -> str:
    """A CSV column's heading in the report."""
    if name in _COLUMNS:
        return _COLUMNS[name]
    label, unit, _ = label_of(name)
    return f"{label} ({unit})" if unit else label


_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


def format_value(value, digits: int = 3, *, text: bool = False) -> str:
    """A number as people write it: whole numbers with narrow no-break spaces between thousands (so
    that a table's column never breaks "6 000" over two lines), others to ``digits`` significant
    figures in plain decimals, and the very small as 1.2 x 10^-9 with superscripts (never
    ``1.2e-09``); booleans as yes/no, None as a dash. ``text``: for a terminal or a log, in ASCII
    (plain spaces, 1.2e-09 for the very small)."""
    space = " " if text else "\u202f"
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, int) or (isinstance(value, float) and value.is_integer() and abs(value) >= 1000):
        return f"{int(value):,}".replace(",", space)
    if isinstance(value, float):
        if math.isnan(value):
            return "-"
        if math.isinf(value):
            return ("" if value > 0 else "-") + ("inf" if text else "\u221e")
        if value == 0:
            return "0"
        magnitude = math.floor(math.log10(abs(value)))
        if magnitude < -3:
            if text:
                return f"{value:.{max(digits - 1, 0)}e}"
            mantissa = value / 10**magnitude
            return (f"{mantissa:.{max(digits - 1, 0)}f}".rstrip("0").rstrip(".")
                    + f" \u00d7 10{str(magnitude).translate(_SUPERSCRIPT)}")
        if magnitude >= digits:
            return f"{round(value):,}".replace(",", space)
        decimals = max(digits - 1 - magnitude, 0)
        return f"{value:.{decimals}f}"
    return str(value)


def format_against(value, limit, digits: int = 3, *, text: bool = False) -> tuple[str, str]:
    """A value and its limit as ``format_value`` writes them, with as many more significant digits
    (up to 6) as it takes for a value that is not its limit not to read as equal to it: a cut of
    359.6 mm against 360 mm, not 360 against 360."""
    for more in range(digits, 7):
        pair = format_value(value, more, text=text), format_value(limit, more, text=text)
        if pair[0] != pair[1] or not _numbers(value, limit) or float(value) == float(limit):
            return pair
    return pair


def _numbers(*values) -> bool:
    return all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))
               for v in values)


def figure_rows(values: dict, keys: tuple[str, ...] | None = None) -> list[list]:
    """Rows [label, value in its unit, unit] of ``values`` (``keys`` in their order, else all),
    nested values left out."""
    rows = []
    for key in keys if keys is not None else tuple(values):
        if key not in values or isinstance(values[key], (dict, list)):
            continue
        label, unit, _ = label_of(key)
        rows.append([label, in_unit(key, values[key]), unit])
    return rows


def in_unit(key: str, value):
    """A JSON figure's value in the unit label_of gives it (numbers scaled, anything else as is)."""
    factor = label_of(key)[2]
    if isinstance(value, (int, float)) and not isinstance(value, bool) and factor != 1.0:
        return float(value) * factor
    return value
