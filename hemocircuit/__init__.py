"""hemocircuit: lumped-parameter (0D) hemodynamic circuits.

    import hemocircuit as hc
    c = hc.load("netlists/payne06_passive.yaml")
    op = c.operating_point()          # steady state
    sw = c.dc_sweep("Pa.value", "20:200:5 mmHg")
    tr = c.simulate(t_end=100)        # transient
    tr.save("run.csv"); hc.Result.load("run.csv")   # results: columns with units, provenance

Circuit units: pressure mmHg, flow mL/s, volume mL, time s (see hemocircuit.units).
"""
import os as _os
import sys as _sys

# The engine is compiled at LLVM -O1, not numba's default -O3, and without LLVM's loop
# vectorizer (numba's default has it on): the same run speed (its loops are short: vasomotion,
# the body model, a decomposed heart), a shorter first compile (docs/performance.md).
# Each only when the user has not set it and numba is not loaded yet (then the user's numba
# keeps its settings); process-wide, as numba's settings are.  The compile helpers get this
# process's settings (kernels.prebuild.helper_env).
ENGINE_NUMBA_SETTINGS = {"NUMBA_OPT": "1", "NUMBA_LOOP_VECTORIZE": "0"}
if "numba" not in _sys.modules:
    for _name, _value in ENGINE_NUMBA_SETTINGS.items():
        _os.environ.setdefault(_name, _value)

from .errors import HemocircuitError, NetlistError, SolverError, TopologyError  # noqa: E402,F401

from .version import __version__  # noqa: E402,F401

_LAZY = {"Circuit", "assemble", "load"}


def __getattr__(name):
    """The circuit API is imported on first use, so that ``hemocircuit --help`` and other light
    commands do not pay for numpy, scipy, pint and numba (PEP 562)."""
    if name in _LAZY:
        from . import circuit  # (it attaches the analysis methods to Circuit)

        return getattr(circuit, name)
    if name == "Result":  # every analysis's result; Result.load(path) reads a result file
        from .results import Result

        return Result
    raise AttributeError(f"module 'hemocircuit' has no attribute {name!r}")
