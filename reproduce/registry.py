"""The report's sections in thesis order: (key, module of this package).  A section module has
``TITLE``, ``CHAPTER``, ``LABELS`` (thesis figure labels) and ``run(ctx)`` (core.Context)."""
from __future__ import annotations

import importlib

SECTIONS = [
    "ch4_steady",
    "ch4_lee97",
    "ch4_fits",
    "ch4_kuo91",
    "ch4_sensitivity",
    "ch5_payne06",
    "ch5_phase",
    "ch5_downstream_no",
    "ch5_artcomp",
    "ch6_stability",
    "ch6_second_order",
    "ch6_vasomotion",
]


def load(key):
    """The section module ``key`` (an import failure surfaces as that section's failure)."""
    return importlib.import_module(f"{__package__}.{key}")


def check_keys(keys):
    """--only SECTION...: every key must be a section (a clear error listing them otherwise)."""
    from ..errors import HemocircuitError
    bad = [k for k in keys if k not in SECTIONS]
    if bad:
        raise HemocircuitError(f"--only: unknown section(s) {', '.join(bad)}; the sections are: {', '.join(SECTIONS)}")
    return list(keys)
