"""Shared helpers for the core tests (the arteriole tests have their own conftest)."""
import os
from pathlib import Path
import textwrap

import pytest

from paths import BAD, NETLISTS, PAYNE06, ROOT, TESTS  # noqa: F401

# One compiled engine for every registered type (hemocircuit.kernels.layout.engine_kernels): the
# suite meets a dozen sets of component types, each of which would otherwise compile its own
# engine (~30 s CPU each with cold caches, as on CI).  Results are bitwise the same; the
# per-set default is tested in test_compiled_engine.py with the variable set to "used".
os.environ.setdefault("HEMOCIRCUIT_ENGINE_TYPES", "all")
# runs compile their engine before integrating (the command line default builds it in the
# background and starts on the scipy path: tests would depend on timing)
os.environ.setdefault("HEMOCIRCUIT_COMPILE", "wait")


@pytest.fixture
def write(tmp_path):
    """write(text, name='net.yaml') -> Path: a dedented file under tmp_path (folders created)."""

    def _write(text, name="net.yaml"):
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text).lstrip("\n"))
        return path

    return _write
