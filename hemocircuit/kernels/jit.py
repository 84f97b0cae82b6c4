"""``njit`` for component kernels that imports numba only when a kernel is first used.

Loading the component registry imports every component module; with ``numba.njit`` at module
level that alone imports numba (~0.25 s), which commands that never run compiled code (``op``,
``--help``) do not need.  ``njit(**options)(fn)`` returns a :class:`LazyDispatcher`: the numba
dispatcher is made when numba compiles a caller that reads it as a global (numba types a global
through its ``_numba_type_``), so kernels calling kernels work unchanged, or when asked for
(``.dispatcher``).  Called from Python before that, it runs as the Python function it is (the one
definition of the equations, run by hemocircuit.elementwise without a compile); once compiled,
calls run the machine code.
"""
from __future__ import annotations

import functools
import types

import numpy as np


class LazyDispatcher:
    """A numba ``njit`` dispatcher created on first use (see the module docstring).  ``python``:
    what a call from Python runs however compiled the function is (an equation of scalars that
    also takes numpy arrays from Python: its Python function, or a numpy twin such as np.where)."""

    def __init__(self, fn, options, python=None):
        self.py_func = fn
        self._options = options
        self._dispatcher = None
        self._python = python
        #: the dispatcher compiled callers call when it is not the Python-callable one (see
        #: _numba_type_): made on first use
        self._callee = None
        functools.update_wrapper(self, fn)

    @property
    def dispatcher(self):
        if self._dispatcher is None:
            import numba

            self._dispatcher = numba.njit(**self._options)(self.py_func)
        return self._dispatcher

    @property
    def compiled(self) -> bool:
        """True once numba has made the Python-callable dispatcher (a compiled caller of a
        kernel function, or ``.dispatcher``)."""
        return self._dispatcher is not None

    @property
    def _numba_type_(self):
        """What numba.typeof reports, so what a compiled caller calls: the dispatcher, or for an
        equation (which Python calls as Python, never compiled) a twin compiled without the
        Python and C entry wrappers (numba builds, optimises and caches them for every
        function: ~0.05 s of each helper's compile, 2.5 s of the arteriole's kernels on the
        project's machine).  Its cache files are its own (``<name>.callee``): numba's cache
        index does not tell the two compilations apart, and a Python call of one without a
        wrapper would crash."""
        if self._python is None or self._options.get("inline") == "always":
            return self.dispatcher._numba_type_
        if self._callee is None:
            import numba

            twin = types.FunctionType(self.py_func.__code__, self.py_func.__globals__, self.py_func.__name__,
                                      self.py_func.__defaults__, self.py_func.__closure__)
            twin.__qualname__ = self.py_func.__qualname__ + ".callee"
            twin.__module__ = self.py_func.__module__
            opts = {**self._options, "no_cpython_wrapper": True, "no_cfunc_wrapper": True}
            self._callee = numba.njit(**opts)(twin)
        return self._callee._numba_type_

    def __call__(self, *args):
        if self._python is not None:
            return self._python(*args)
        if self._dispatcher is None:
            return self.py_func(*args)
        return self._dispatcher(*args)

    def __reduce__(self):  # pickled by name, as a module-level function is
        return _lookup, (self.__module__, self.__qualname__)

    def __repr__(self):
        return f"<lazy njit {self.__module__}.{self.__qualname__}>"


def _lookup(module: str, qualname: str):
    import importlib

    obj = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


def njit(**options):
    """Decorator: like ``numba.njit(**options)``, applied on first use."""
    return lambda fn: LazyDispatcher(fn, options)


def equation(**options):
    """Decorator of an equation written once for both paths: compiled like :func:`njit` when a
    kernel calls it, and run as the Python function it is when called from Python -- where its
    arguments may be numpy arrays (it uses operations that work on scalars in numba and on
    arrays in numpy: arithmetic, np.exp, np.maximum, ... and :func:`select` for a choice)."""
    return lambda fn: LazyDispatcher(fn, options, python=fn)


def _select_scalar(cond, a, b):
    return a if cond else b


#: ``select(cond, a, b)``: ``a if cond else b`` compiled, ``np.where(cond, a, b)`` from Python
#: (both a and b are evaluated: keep them free of side effects and cheap)
select = LazyDispatcher(_select_scalar, dict(cache=True, nogil=True, inline="always"), python=np.where)
