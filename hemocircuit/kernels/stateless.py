"""Kernel functions shared by element types without a stamp, states or observables (resistors,
sources, a pool with no nodes): nothing to stamp, integrate or observe."""
from .jit import njit


@njit(cache=True, nogil=True)
def no_derivs(p, x, u, t, iopt, dx):
    pass


@njit(cache=True, nogil=True)
def no_observables(p, x, iopt, out):
    pass


@njit(cache=True, nogil=True)
def no_stamp(p, x, u, t, iopt, A, b):
    pass
