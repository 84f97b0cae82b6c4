"""Units: parsing quantities at load time, and the one SI <-> vasculature boundary.

The circuit (nodes, flows, compliance volumes) works in mmHg, mL and s; the arteriole
works in SI (Pa, m, N, s, mol/L).  Quantities are parsed with pint *only at load time*
(netlists, --set, protocols); the hot path sees plain floats in each parameter's declared
unit.  Conversions between the two systems go through the constants below, nowhere else.
"""
from __future__ import annotations

import functools
import re

import pint

from .errors import HemocircuitError

ureg = pint.UnitRegistry()
# pint knows mmHg and cmH2O (conventional, 9.80665 m/s^2 and 13.5951 g/cm^3).
Q_ = ureg.Quantity

# --- the one boundary between circuit units (mmHg, mL, s) and SI --------------------
PA_PER_MMHG = float(Q_(1, "mmHg").to("Pa").magnitude)  # 133.322387415 Pa/mmHg
PA_PER_CMH2O = float(Q_(1, "cmH2O").to("Pa").magnitude)  # 98.0665 Pa/cmH2O
M3_PER_ML = 1e-6  # m^3/mL
CIRCUIT_UNITS = {"pressure": "mmHg", "flow": "mL/s", "volume": "mL", "time": "s"}


def mmhg_to_pa(p):
    """Pressure mmHg -> Pa (works on arrays)."""
    return p * PA_PER_MMHG


def pa_to_mmhg(p):
    """Pressure Pa -> mmHg (works on arrays)."""
    return p / PA_PER_MMHG


def ml_to_m3(v):
    """Volume mL -> m^3 (also flow mL/s -> m^3/s)."""
    return v * M3_PER_ML


def m3_to_ml(v):
    """Volume m^3 -> mL (also flow m^3/s -> mL/s)."""
    return v / M3_PER_ML


class UnitError(HemocircuitError):
    """A value could not be parsed or has the wrong dimension."""


_NUMBER = re.compile(r"^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*$")


# an integer literal (not part of a name such as cmH2O, not a float or 1e-3)
_INT_LITERAL = re.compile(r"(?<![\w.])(\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)(?![\w.])")


def _float_literals(text: str) -> str:
    """'10**10**10 mmHg' -> '10.0**10.0**10.0 mmHg': pint evaluates integer literals with Python
    integers, whose powers can take unbounded time and memory; floats overflow at once."""
    return _INT_LITERAL.sub(lambda m: m.group(1) if any(c in m.group(1) for c in ".eE") else m.group(1) + ".0",
                            text)


@functools.lru_cache(maxsize=4096)
def _parse(text: str):
    try:
        return Q_(_float_literals(text)) if not _NUMBER.match(text) else Q_(float(text), "dimensionless")
    except Exception as exc:  # pint raises many different types
        raise UnitError(f"cannot parse quantity {text!r}: {exc}") from None


def parse_quantity(value, unit: str, what: str = "value") -> float:
    """Parse ``value`` (e.g. '0.4 mmHg*s/mL', 60, '4 cmH2O') and return its magnitude in ``unit``.

    A bare number is accepted only for dimensionless units (explicit units everywhere else,
    so a netlist never silently mixes mmHg and Pa).
    """
    if isinstance(value, bool):
        raise UnitError(f"{what}: expected a quantity in {unit}, got boolean {value!r}")
    target = Q_(1, unit)
    if isinstance(value, (int, float)):
        if target.dimensionless:
            return float(value) * float(Q_(1, "dimensionless").to(unit).magnitude)
        raise UnitError(f"{what}: the number {value!r} has no unit; write it with a unit of {unit}, "
                        f"e.g. '{value} {unit}'")
    if isinstance(value, pint.Quantity):
        q = value
    elif isinstance(value, str):
        q = _parse(value)
    else:
        raise UnitError(f"{what}: expected a quantity in {unit}, got {type(value).__name__} {value!r}")
    try:
        if q.dimensionless and not target.dimensionless and _NUMBER.match(str(value)):
            raise UnitError(f"{what}: {value!r} has no unit; give it in {unit}")
        return float(q.to(unit).magnitude)
    except pint.DimensionalityError:
        try:
            dim = q.dimensionality
        except (ArithmeticError, ValueError, TypeError):
            dim = "?"
        raise UnitError(f"{what}: {value!r} has dimension {dim}, expected a unit of "
                        f"{unit} ({target.dimensionality})") from None
    except (ArithmeticError, ValueError, TypeError) as exc:  # overflow, complex magnitudes, ...
        raise UnitError(f"{what}: cannot convert {value!r} to {unit}: {exc}") from None


def parse_with_unit(value) -> "pint.Quantity":
    """Parse a value into a pint Quantity (numbers are dimensionless)."""
    if isinstance(value, pint.Quantity):
        return value
    if isinstance(value, bool):
        raise UnitError(f"expected a quantity, got boolean {value!r}")
    if isinstance(value, (int, float)):
        return Q_(float(value), "dimensionless")
    if isinstance(value, str):
        return _parse(value)
    raise UnitError(f"expected a quantity, got {type(value).__name__} {value!r}")


def conversion_factor(from_unit: str, to_unit: str) -> float:
    """Multiplicative factor from ``from_unit`` to ``to_unit`` (same dimension)."""
    try:
        return float(Q_(1, from_unit).to(to_unit).magnitude)
    except pint.DimensionalityError:
        raise UnitError(f"cannot convert {from_unit} to {to_unit}") from None


def si_factor(unit: str) -> float:
    """Factor from ``unit`` to coherent SI base units."""
    return float(Q_(1, unit).to_base_units().magnitude)


def check_unit(unit: str) -> None:
    """Raise UnitError if ``unit`` is not a unit pint understands."""
    try:
        Q_(1, unit)
    except Exception as exc:
        raise UnitError(f"unknown unit {unit!r}: {exc}") from None
