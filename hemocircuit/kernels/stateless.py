"""Kernel functions shared by element types without states or observables (resistors,
sources): nothing to integrate, nothing to observe."""
from .jit import njit


@njit(cache=True, nogil=True)
def no_derivs(p, x, u, t, iopt, dx):
    pass


@njit(cache=True, nogil=True)
def no_observables(p, x, iopt, out):
    pass
