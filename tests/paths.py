"""Paths shared by the core tests (imported as a plain module: 'conftest' is ambiguous)."""
import os
from pathlib import Path

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
NETLISTS = TESTS / "netlists"
BAD = NETLISTS / "bad"
PAYNE06 = ROOT / "netlists" / "payne06_passive.yaml"
#: svZeroDSolver's shared cases (../shared/svzerod beside the checkout; $SVZEROD_CASES moves it)
SHARED_SVZEROD = os.environ.get("SVZEROD_CASES", str(ROOT.parent / "shared" / "svzerod"))
