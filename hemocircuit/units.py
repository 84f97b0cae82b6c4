"""Units: parsing quantities at load time, and the one SI <-> vasculature boundary.

The circuit (nodes, flows, compliance volumes) works in mmHg, mL and s; the arteriole
works in SI (Pa, m, N, s, mol/L).  Quantities are parsed with pint *only at load time*
(netlists, --set, protocols); the hot path sees plain floats in each parameter's declared
unit.  Conversions between the two systems go through the constants below, nowhere else.
"""
from __future__ import annotations

import functools
import re
from typing import TYPE_CHECKING

from .errors import HemocircuitError

if TYPE_CHECKING:
    import pint


@functools.lru_cache(maxsize=1)
def registry():
    """The pint registry, made on first use (importing pint costs ~0.5 s that commands such as
    ``--help`` never need).  Parsed definitions are cached in the user's cache folder."""
    import pint

    try:
        return pint.UnitRegistry(cache_folder=":auto:")
    except OSError:  # pragma: no cover - no writable cache folder
        return pint.UnitRegistry()


def __getattr__(name):  # ``ureg`` as before, built lazily
    if name == "ureg":
        return registry()
    raise AttributeError(name)


def Q_(*args, **kwargs):  # noqa: N802 - pint's conventional name
    return registry().Quantity(*args, **kwargs)


# --- the one boundary between circuit units (mmHg, mL, s) and SI --------------------
# pint's conventional mmHg (13.5951 g/cm^3 * 9.80665 m/s^2 * 1 mm) and cmH2O, written out so
# that importing the package needs no pint (tests/test_units.py checks them against pint)
PA_PER_MMHG = 133.322387415  # Pa/mmHg
PA_PER_CMH2O = 98.0665  # Pa/cmH2O
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


@functools.lru_cache(maxsize=256)
def _target(unit: str):
    return Q_(1, unit)


_CONVERTED: dict = {}  # (text, unit) -> magnitude: netlists repeat the same values many times
_MEMO: dict = {}  # (kind, key as JSON) -> a JSON value: other results of pint (memo())


class _DiskCache:
    """Conversions pint made in earlier runs ((text, unit) -> magnitude) and other results of
    pint (:func:`memo`), kept in the user's cache folder per pint version, so that a warm run of a netlist needs no pint at all (its
    import and registry cost ~0.6 s).  Only successful string conversions are stored; errors
    always go through pint again.  The file is replaced atomically at exit when it grew."""

    def __init__(self):
        self.path = None
        self.loaded = False
        self.dirty = False

    def load(self):
        import json
        import os
        from importlib.util import find_spec
        from pathlib import Path

        import atexit

        self.loaded = True
        atexit.register(self.save)
        try:
            import hashlib

            # the installed pint, by its package file's time stamp and size (importlib.metadata's
            # version() costs 25 ms of imports, half of what the cache saves)
            st = Path(find_spec("pint").origin).stat()
            version = f"{st.st_mtime_ns:x}-{st.st_size}"
            rules = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:12]  # our parsing rules
            folder = Path(os.environ.get("HEMOCIRCUIT_CACHE_DIR") or Path.home() / ".cache" / "hemocircuit")
            self.path = folder / f"units-pint-{version}-{rules}.json"
            data = json.loads(self.path.read_text()) if self.path.exists() else {}
            for text, unit, value in data.get("converted", []):  # text None: a bare number's factor
                _CONVERTED.setdefault((text, unit), float(value))
            for kind, key, value in data.get("memo", []):
                _MEMO.setdefault((kind, key), value)
        except (OSError, ValueError, TypeError, AttributeError):  # (no pint found: find_spec gives None)
            self.path = None  # no cache: every conversion goes through pint

    def save(self):
        import json
        import os

        if not (self.dirty and self.path):
            return
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.path.with_suffix(f".{os.getpid()}.tmp")
            rows = [[t, u, v] for (t, u), v in list(_CONVERTED.items())[:20000]]
            memo = [[kind, key, v] for (kind, key), v in list(_MEMO.items())[:20000]]
            tmp.write_text(json.dumps({"converted": rows, "memo": memo}))
            os.replace(tmp, self.path)
        except OSError:
            pass


_DISK = _DiskCache()


def parse_quantity(value, unit: str, what: str = "value") -> float:
    """Parse ``value`` (e.g. '0.4 mmHg*s/mL', 60, '4 cmH2O') and return its magnitude in ``unit``.

    A bare number is accepted only for dimensionless units (explicit units everywhere else,
    so a netlist never silently mixes mmHg and Pa).
    """
    if isinstance(value, str):
        if not _DISK.loaded:
            _DISK.load()
        key = (value, unit)
        hit = _CONVERTED.get(key)
        if hit is None:
            hit = _parse_quantity(value, unit, what)
            if len(_CONVERTED) > 65536:
                _CONVERTED.clear()
            _CONVERTED[key] = hit
            _DISK.dirty = True
        return hit
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        # a bare number is valid only for a dimensionless unit: cache that unit's factor
        if not _DISK.loaded:
            _DISK.load()
        factor = _CONVERTED.get((None, unit))  # None: never a string input's key
        if factor is None:
            out = _parse_quantity(value, unit, what)  # raises for a dimensioned unit
            _CONVERTED[(None, unit)] = _parse_quantity(1.0, unit, what)
            _DISK.dirty = True
            return out
        return float(value) * factor
    return _parse_quantity(value, unit, what)


def _parse_quantity(value, unit: str, what: str) -> float:
    if isinstance(value, bool):
        raise UnitError(f"{what}: expected a quantity in {unit}, got boolean {value!r}")
    target = _target(unit)
    if isinstance(value, (int, float)):
        if target.dimensionless:
            return float(value) * float(Q_(1, "dimensionless").to(unit).magnitude)
        raise UnitError(f"{what}: the number {value!r} has no unit; write it with a unit of {unit}, "
                        f"e.g. '{value} {unit}'")
    import pint

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
    import pint

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
    import pint

    try:
        return float(Q_(1, from_unit).to(to_unit).magnitude)
    except pint.DimensionalityError:
        raise UnitError(f"cannot convert {from_unit} to {to_unit}") from None


def si_factor(unit: str) -> float:
    """Factor from ``unit`` to coherent SI base units."""
    return memo("si_factor", unit, lambda: float(Q_(1, unit).to_base_units().magnitude))


def memo(kind: str, key, compute):
    """``compute()`` (a JSON value: numbers, strings, lists), remembered under (kind, key) here
    and in the disk cache of earlier runs, so that a warm run needs no pint (its import alone
    is ~0.5 s).  ``key`` must be JSON (it is stored as its JSON text); what raises is never
    remembered."""
    import json

    if not _DISK.loaded:
        _DISK.load()
    k = (kind, json.dumps(key))
    if k not in _MEMO:
        value = compute()
        if len(_MEMO) > 65536:
            _MEMO.clear()
        _MEMO[k] = json.loads(json.dumps(value))  # as a later run reads it back (tuples as lists)
        _DISK.dirty = True
    return _MEMO[k]


def check_unit(unit: str) -> None:
    """Raise UnitError if ``unit`` is not a unit pint understands."""
    try:
        Q_(1, unit)
    except Exception as exc:
        raise UnitError(f"unknown unit {unit!r}: {exc}") from None
