"""Paths shared by the core tests (imported as a plain module: 'conftest' is ambiguous)."""
from pathlib import Path

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
NETLISTS = TESTS / "netlists"
BAD = NETLISTS / "bad"
PAYNE06 = ROOT / "netlists" / "payne06_passive.yaml"
