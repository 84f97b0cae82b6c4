"""The addresses through which the compiled Rosenbrock integrator calls a type set's functions.

``integrate_batch`` (engine_rosenbrock.py) takes prepare_static, rhs_into_at,
local_jacobian_into_at and release_fraction as numba first-class functions: :class:`Address`
objects (numba's wrapper-address protocol) carrying each function's compiled C entry point and
its signature.  Calling through an address instead of naming the function lets numba compile
the integrator from the functions' types alone, without their code: so a first run compiles the
integrator in its helper process while this one compiles the functions
(kernels.prebuild), and LLVM does not optimise and emit their code a second time inside it.
The layout and work tuples go by reference (kernels.refs): a call through an address passes a
few pointers, as a direct call does.

The signatures are exactly the types the integrator passes (numba checks them when it compiles
the integrator): :func:`signatures`.
"""
from __future__ import annotations

import numpy as np

#: the functions the integrator calls through addresses, in its argument order
NAMES = ("prepare_static", "rhs_into_at", "local_jacobian_into_at", "release_fraction")


def signatures(mod, lay, nx, P_all, scales, lim_i, lim_b, lim_r, atol) -> tuple:
    """The numba signatures of the NAMES functions as ``integrate_batch`` calls them, for its
    arguments P_all (B, slots), scales, lim_i, lim_b, lim_r and atol (their own types: a
    read-only array is another type) and a system of nx states."""
    import numba
    from numba import types

    f64, b1, i64 = types.float64, types.boolean, types.int64
    vx = numba.typeof(np.empty(max(nx, 1)))  # the integrator's own state vectors
    Pt = numba.typeof(P_all)
    row = Pt.copy(ndim=1, layout="C" if Pt.layout == "C" else "A")  # P_all[m]
    lt = numba.typeof(lay)
    wt = numba.typeof(mod.make_work.py_func(lay))  # make_work's type, from its Python twin
    jt = numba.typeof(mod.make_jac_work.py_func(lay))
    lr, wr, jr = types.CPointer(lt), types.CPointer(wt), types.CPointer(jt)  # by reference
    J = numba.typeof(np.empty((1, 1)))
    held = numba.typeof(np.zeros(1, dtype=np.bool_))
    st, li, lb, lrr, at = (numba.typeof(a) for a in (scales, lim_i, lim_b, lim_r, atol))
    return (types.none(f64, vx, row, lt, wt),
            b1(f64, vx, row, lr, wr, vx),
            i64(f64, vx, row, lr, wr, jr, st, J, vx, b1, vx, b1),
            types.Tuple((f64, i64))(f64, f64, f64, vx, vx, vx, row, lt, wt, li, lb, lrr, at, held, vx, vx, vx, vx))


def function_types(sigs) -> tuple:
    """The first-class function types of these signatures: the integrator's argument types for
    its addresses (what the helper compiles it for)."""
    from numba import types

    return tuple(types.FunctionType(s) for s in sigs)


def addresses(mod, sigs) -> tuple:
    """The address of each NAMES function of engine module ``mod`` for these signatures (each
    compiled here, or loaded from numba's cache); CompiledSystem keeps them per layout."""
    return tuple(address(getattr(mod, name), sig) for name, sig in zip(NAMES, sigs))


_Address = None


def address(dispatcher, sig):
    """``dispatcher`` compiled for ``sig`` (or loaded from numba's cache), as an object of
    numba's first-class function protocol: its C entry point and signature."""
    global _Address
    if _Address is None:  # numba is imported on first use
        from numba.core.types import WrapperAddressProtocol

        class Address(WrapperAddressProtocol):
            def __init__(self, dispatcher, sig):
                dispatcher.compile(sig.args)
                cres = dispatcher.get_compile_result(sig)
                if cres.signature.return_type != sig.return_type:
                    raise TypeError(f"{dispatcher.py_func.__name__} returns {cres.signature.return_type}, "
                                    f"not {sig.return_type}")
                self._sig = sig
                self._library = cres.library  # keeps the code while the address is in use
                self._addr = cres.library.get_pointer_to_function(cres.fndesc.llvm_cfunc_wrapper_name)

            def __wrapper_address__(self):
                return self._addr

            def signature(self):
                return self._sig

        _Address = Address
    return _Address(dispatcher, sig)


def single_run(mod, lay, nx, n_params, scales, lim_i, lim_b, lim_r) -> tuple:
    """(``integrate_batch``'s argument types, the NAMES signatures) in a run of one member, as
    CompiledSystem passes them (kernels.system: t_out, P and hmax read-only C arrays, X0, the
    breakpoints and atol writable ones, the method packed by tableaus.packed; the addresses
    last): what the two processes of a first run compile (kernels.prebuild)."""
    import numba

    from . import tableaus

    def read_only(a):
        a.setflags(write=False)
        return a

    P, atol = read_only(np.zeros((1, n_params))), np.ones(nx)
    args = (read_only(np.zeros((1, 2))), np.zeros((1, nx)), P, lay, scales, lim_i, lim_b, lim_r, np.zeros((1, 1)),
            np.zeros((1, 1)), 1e-6, atol, 1e-3, read_only(np.zeros(1)), 1,
            tableaus.packed(tableaus.DEFAULT, autonomous=0))
    sigs = signatures(mod, lay, nx, P, scales, lim_i, lim_b, lim_r, atol)
    return tuple(numba.typeof(a) for a in args) + function_types(sigs), sigs
