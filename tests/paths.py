"""Paths shared by the core tests (imported as a plain module: 'conftest' is ambiguous)."""
import os
from pathlib import Path

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
NETLISTS = TESTS / "netlists"
BAD = NETLISTS / "bad"
PAYNE06 = ROOT / "netlists" / "payne06_passive.yaml"
#: svZeroDSolver's shared cases: $SVZEROD_CASES, else ../shared/svzerod beside the checkout, else
#: the work area's (a clone elsewhere, as CI makes, still finds them); tests skip without them
_SHARED = [ROOT.parent / "shared" / "svzerod", Path("/work/shared/svzerod")]
SHARED_SVZEROD = os.environ.get("SVZEROD_CASES") or str(next((d for d in _SHARED if d.is_dir()), _SHARED[0]))
