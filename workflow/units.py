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
    """pint's registry, its parsed definitions kept in the user's cache folder: parsing them took
    0.55-0.65 s of every command (a cached default job is some 3 s), loading them 0.07 s. Where
    that folder cannot be used, the definitions are parsed as before."""
    import pint

    try:
        return pint.UnitRegistry(cache_folder=":auto:")
    except Exception:  # noqa: BLE001 - a cache that cannot be read or written is only slower
        return pint.UnitRegistry()


def _a(noun: str) -> str:
    """The noun with its indefinite article ("a length", "an area load")."""
    return f"{'an' if noun[0] in 'aeiou' else 'a'} {noun}"


_OTHER_KINDS = {"mass": "kg", "time": "s", "area": "m^2", "volume": "m^3", "temperature": "K",
                "mass per length": "kg/m", "speed": "m/s"}


def _kind(quantity, expected: str) -> str | None:
    """What a quantity of the wrong dimension measures, in words ("force", "mass"), if known."""
    ureg = _registry()
    named = {name: si for name, (_, si, _) in DIMENSIONS.items() if name != expected}
    for name, unit in {**named, **_OTHER_KINDS}.items():
        if quantity.dimensionality == ureg.Quantity(1, unit.replace("^", "**")).dimensionality:
            return name
    return None


def to_si(value: Any, dimension: str) -> float:
    """The SI magnitude of ``value`` (number or string with unit) of the named dimension.

    Raises ``ValueError`` with a message naming the expected dimension and an example; it does
    not repeat the value (the caller names the key and the value).
    """
    dimensionality, si_unit, example = DIMENSIONS[dimension]
    expected = f"expected {_a(dimension)} such as {example} or a number in {si_unit}"
    if isinstance(value, bool):
        raise ValueError(f"{expected}, got true/false")
    if isinstance(value, (int, float)):
        return float(value)
    if not isinstance(value, str):
        raise ValueError(expected)
    ureg = _registry()
    try:
        quantity = ureg.Quantity(value.replace("^", "**"))
    except Exception:
        raise ValueError(f"cannot read {value!r} as {_a(dimension)}; write it like {example}") from None
    if not hasattr(quantity, "dimensionality"):
        return float(quantity)
    if quantity.dimensionless and dimensionality == "":
        if str(quantity.units) != "dimensionless":
            return float(quantity.to("radian").magnitude)
        return float(quantity.magnitude)
    if quantity.dimensionless:
        return float(quantity.magnitude)
    if quantity.dimensionality != ureg.Quantity(1, si_unit.replace("^", "**")).dimensionality:
        kind = _kind(quantity, dimension)
        what = f"a unit of {kind}, not of {dimension}" if kind else f"not a unit of {dimension}"
        raise ValueError(f"{quantity.units:~} is {what}; write {_a(dimension)} like {example}")
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
