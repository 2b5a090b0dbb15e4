"""Quantities with units in project files, parsed with pint at the boundary only.

A value may be a bare number (taken as SI: m, Pa, N, kg/m^3, N/m^2) or a string with a
unit ("50 mm", "210 GPa", "0.5 kN/m^2"). ``to_si`` converts to the SI base unit of the
expected dimension and returns a plain float; pint never reaches the engine.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Annotated, Any

from pydantic import BeforeValidator

__all__ = ["DIMENSIONS", "to_si", "Length", "Stress", "AreaLoad", "Density", "Force", "Moment",
           "LineLoad", "Angle"]

DIMENSIONS: dict[str, tuple[str, str, str]] = {
    # name: (pint dimensionality, SI unit, example)
    "length": ("[length]", "m", "'50 mm'"),
    "stress": ("[mass] / [length] / [time] ** 2", "Pa", "'210 GPa'"),
    "area load": ("[mass] / [length] / [time] ** 2", "N/m^2", "'0.5 kN/m^2'"),
    "density": ("[mass] / [length] ** 3", "kg/m^3", "'7850 kg/m^3'"),
    "force": ("[length] * [mass] / [time] ** 2", "N", "'2 kN'"),
    "moment": ("[length] ** 2 * [mass] / [time] ** 2", "N*m", "'1 kN*m'"),
    "line load": ("[mass] / [time] ** 2", "N/m", "'1 kN/m'"),
    "angle": ("", "rad", "'15 deg'"),
}


@lru_cache(maxsize=1)
def _registry():
    import pint

    return pint.UnitRegistry()


def to_si(value: Any, dimension: str) -> float:
    """The SI magnitude of ``value`` (number or string with unit) of the named dimension.

    Raises ``ValueError`` with a message naming the expected dimension and an example.
    """
    dimensionality, si_unit, example = DIMENSIONS[dimension]
    if isinstance(value, bool):
        raise ValueError(f"expected a {dimension} such as {example} or a number in {si_unit}, got a boolean")
    if isinstance(value, (int, float)):
        return float(value)
    if not isinstance(value, str):
        raise ValueError(f"expected a {dimension} such as {example} or a number in {si_unit}")
    ureg = _registry()
    try:
        quantity = ureg.Quantity(value.replace("^", "**"))
    except Exception:
        raise ValueError(f"cannot read {value!r} as a {dimension}; write it like {example}") from None
    if not hasattr(quantity, "dimensionality"):
        return float(quantity)
    if quantity.dimensionless and dimensionality == "":
        return float(quantity.to("radian").magnitude) if str(quantity.units) != "dimensionless" else float(quantity.magnitude)
    if quantity.dimensionless:
        return float(quantity.magnitude)
    if quantity.dimensionality != ureg.Quantity(1, si_unit.replace("^", "**")).dimensionality:
        raise ValueError(f"{value!r} is not a {dimension} (its unit {quantity.units:~} measures "
                         f"{quantity.dimensionality}); write it like {example}")
    return float(quantity.to(si_unit.replace("^", "**")).magnitude)


def _si(dimension: str):
    return BeforeValidator(lambda v: to_si(v, dimension) if not isinstance(v, (list, tuple, dict)) else v)


Length = Annotated[float, _si("length")]
Stress = Annotated[float, _si("stress")]
AreaLoad = Annotated[float, _si("area load")]
Density = Annotated[float, _si("density")]
Force = Annotated[float, _si("force")]
Moment = Annotated[float, _si("moment")]
LineLoad = Annotated[float, _si("line load")]
Angle = Annotated[float, _si("angle")]
