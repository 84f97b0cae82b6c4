"""Shared helpers for the core tests (the arteriole tests have their own conftest)."""
from pathlib import Path
import textwrap

import pytest

from paths import BAD, NETLISTS, PAYNE06, ROOT, TESTS  # noqa: F401


@pytest.fixture
def write(tmp_path):
    """write(text, name='net.yaml') -> Path: a dedented file under tmp_path (folders created)."""

    def _write(text, name="net.yaml"):
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text).lstrip("\n"))
        return path

    return _write
