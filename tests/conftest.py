"""Shared helpers for the core tests (the arteriole tests have their own conftest)."""
from pathlib import Path
import textwrap

import pytest

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
NETLISTS = TESTS / "netlists"
BAD = NETLISTS / "bad"
PAYNE06 = ROOT / "netlists" / "payne06_passive.yaml"


@pytest.fixture
def write(tmp_path):
    """write(text, name='net.yaml') -> Path: a dedented file under tmp_path (folders created)."""

    def _write(text, name="net.yaml"):
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text).lstrip("\n"))
        return path

    return _write
