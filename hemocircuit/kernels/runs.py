"""What the compiled integrators (Rosenbrock and BDF) share about a member's run: when a state
counts as on its hard limit, and the end of the run (its output rows not reached, its stats).

An importable module (not part of the engine template): the generated engines import these
(kernels.codegen), compiled once for every engine, without reference counting.
"""
from __future__ import annotations

import numpy as np

from .jit import njit

#: a state within this many times its atol above its hard limit counts as on it (held there,
#: not located as a crossing): 1e-3 atol, far below any error the step control admits
LIMIT_ON_BOUND = 1e-3
#: a held state's release inside a rejected step (engine_rosenbrock.release_fraction) is located
#: to 2^-RELEASE_HALVINGS of the step, and the step retried ending there when that is before
#: RELEASE_LAND_BELOW of it (later: the ordinary step-size rule)
RELEASE_HALVINGS = 12
RELEASE_LAND_BELOW = 0.95
#: the step after one that ends on a release is at most this fraction of it
RELEASE_NEXT = 0.3

#: the columns of a member's stats row, in order (CompiledSystem.integrate reads them by name)
STATS = ("status", "t", "steps", "rejected", "nfev", "limit_events")


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def finish_member(out, k_from, stats, m, status, t, nsteps, nrej, nfev, nev):
    """The end of member m's run in both integrators: its output rows from k_from on NaN (not
    reached: the run failed or stopped there) and its stats row (the columns of STATS: status,
    t reached, steps, rejected steps, f evaluations, limit events)."""
    for k in range(k_from, out.shape[0]):
        for i in range(out.shape[1]):
            out[k, i] = np.nan
    stats[m, 0] = status
    stats[m, 1] = t
    stats[m, 2] = nsteps
    stats[m, 3] = nrej
    stats[m, 4] = nfev
    stats[m, 5] = nev
