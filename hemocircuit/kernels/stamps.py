"""The nodal stamps element types build their kernel ``stamp`` from (one element's local A, b;
rows and unknowns as in hemocircuit.component): a conductance, a pressure-defining branch, an
imposed flow.  Built-in types and plug-ins alike."""
from .jit import njit

_jit = njit(cache=True, nogil=True, error_model="numpy", _nrt=False)


@_jit
def conductance(A, i, j, g):
    """A conductance g [mL/s/mmHg] between local nodes i and j."""
    A[i, i] += g
    A[i, j] -= g
    A[j, i] -= g
    A[j, j] += g


@_jit
def branch(A, b, i, j, c, value, R=0.0):
    """Branch c from local node i to j: its flow q (unknown c) leaves i and enters j, and row c
    says P_i - P_j - R q = value (R: a series resistance, or a linearisation's slope)."""
    A[i, c] = 1.0
    A[j, c] = -1.0
    A[c, i] = 1.0
    A[c, j] = -1.0
    A[c, c] -= R
    b[c] = value


@_jit
def imposed_flow(b, i, j, q):
    """A flow q imposed from local node i to j (an inductor's state, a wall's motion)."""
    b[i] = -q
    b[j] = q
