"""Initial conditions: named state overrides ``{ID.STATE: value}`` (like SPICE ``.ic``).

A transient starts from the operating point; ``ic`` replaces some of its states, e.g.
``{'Cv.V': '20 mL', 'art.Ca': '1e-7 M'}`` (``hemocircuit tran --ic Cv.V=20mL``).  A value is
a quantity string with a unit, or a plain number taken in the state's declared unit.  The
other states keep their operating-point values; nothing is re-solved, so the start may be
off any conservation law the circuit has (that is the point of an initial condition).  An
``ic`` that names every state is the whole start: no operating point is computed (an imported
svZeroDSolver closed loop starts from their initial_condition, as their runs do).
"""
from __future__ import annotations

import difflib

import numpy as np

from .errors import NetlistError
from .units import UnitError, parse_quantity
from .names import split_path


def state_index(circuit, name: str) -> int:
    """Index of state ``ID.STATE`` in the state vector; a clear error naming close matches."""
    try:
        return circuit.state_names.index(name)
    except ValueError:
        pass
    close = difflib.get_close_matches(name, circuit.state_names, n=5, cutoff=0.5)
    hint = f"did you mean {', '.join(close)}?" if close else f"states: {', '.join(circuit.state_names)}"
    raise NetlistError(f"initial condition: no state '{name}'; {hint}", file=circuit.file,
                       element=split_path(name)[0] if split_path(name)[0] in circuit.elements else None)


def names_every_state(circuit, ic: dict | None) -> bool:
    """True if ``ic`` gives a value to every state of ``circuit`` (then it is the whole start)."""
    return bool(ic) and circuit.nx > 0 and len({state_index(circuit, str(k)) for k in ic}) == circuit.nx


def apply_ic(circuit, x, ic: dict | None) -> np.ndarray:
    """A copy of the state vector ``x`` (nx,) with the states named in ``ic`` overridden."""
    x = np.array(x, dtype=float).reshape(-1)
    for name, value in (ic or {}).items():
        k = state_index(circuit, str(name))
        unit = circuit.state_units[k]
        if hasattr(value, "to"):  # a pint quantity
            x[k] = float(value.to(unit).magnitude)
            continue
        try:
            x[k] = parse_quantity(value, unit, f"initial condition {name}") if isinstance(value, str) else float(value)
        except UnitError as exc:
            raise NetlistError(str(exc), file=circuit.file) from None
        except (TypeError, ValueError):
            raise NetlistError(f"initial condition {name} = {value!r} is not a number with a unit of {unit}",
                               file=circuit.file) from None
        if not np.isfinite(x[k]):
            raise NetlistError(f"initial condition {name} = {value!r} is not finite", file=circuit.file)
    return x
