"""Values given as text on the command line: ``--set``/``--ic`` assignments, ranges and
quantities with units ('90mmHg' as well as '90 mmHg').

The parsing every front end shares (the CLI, the analyses' commands, fit and sensitivity
specs); no circuit is needed.  Errors are :class:`~hemocircuit.errors.HemocircuitError`s
naming the option.
"""
from __future__ import annotations

import re

from .errors import HemocircuitError


def assignments(items, flag="--set", form="ID.PARAM=VALUE", example="Pa.value=90mmHg"):
    """['ID.NAME=VALUE', ...] -> {ID.NAME: VALUE} ('90mmHg' spaced to '90 mmHg')."""
    out = {}
    for it in items or []:
        if "=" not in it:
            raise HemocircuitError(f"{flag} {it!r}: expected {form} (e.g. {example})")
        k, v = it.split("=", 1)
        out[k.strip()] = unit_spacing(v.strip())
    return out


def parse_sets(items):
    """The ``--set`` options (a list of 'ID.PARAM=VALUE', or None) as {ID.PARAM: VALUE}."""
    return assignments(items, "--set", "ID.PARAM=VALUE", "Pa.value=90mmHg")


def unit_spacing(v):
    """Accept '90mmHg' as well as '90 mmHg' (an exponent, '1e8', is part of the number)."""
    m = re.match(r"^([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)(?![eE][-+]?\d)\s*([A-Za-z].*)$", v)
    return f"{m.group(1)} {m.group(2)}" if m else v


def range_spacing(r):
    """'20:200:5mmHg' -> '20:200:5 mmHg'; exponents ('1e8') stay part of their number."""
    return re.sub(r"(\d)(?![eE][-+]?\d)([A-Za-z])", r"\1 \2", r, count=1)


def quantity_to(text, unit):
    """A command-line quantity in ``unit``: a bare number is taken in ``unit`` ('100' for
    --t-end is 100 s), else its own unit converts ('2min', '500 ms')."""
    from .units import parse_quantity
    return parse_quantity(unit_spacing(str(text)) if not str(text).replace(".", "").isdigit() else f"{text} {unit}",
                          unit)
