"""The report's sections in thesis order: (key, module of this package).  A section module has
``TITLE``, ``CHAPTER``, ``LABELS`` (thesis figure labels) and ``run(ctx)`` (core.Context)."""
from __future__ import annotations

import importlib

SECTIONS = [
    "ch4_steady",
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
