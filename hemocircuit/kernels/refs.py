"""Passing the engine's layout and work tuples to a compiled function by reference.

A numba function takes a tuple of arrays by value: every call passes each array's fields (seven
words an array; the layout and work tuples hold 61 arrays) and the callee reads the few it
uses.  ``ref(t)`` stores the tuple once in the caller's frame and gives a pointer
(``types.CPointer``); the callee reads ``r[0]``, and LLVM loads only the fields it uses.

A reference does not own the tuple: numba frees a tuple's arrays once its variable is dead
(its last use), and a call through the reference after that reads freed memory.  So ``ref`` is
taken in functions compiled without reference counting (``_nrt=False``: the caller owns the
tuple for the whole call), or, in one that allocates, with :func:`keep_alive` of the tuple after
the reference's last use.
"""
from __future__ import annotations

from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def ref(typingctx, val):
    """A pointer to a copy of ``val`` in the caller's frame (its entry block), valid for the
    caller's whole call; ``ptr[0]`` reads it back."""
    def codegen(context, builder, signature, args):
        slot = cgutils.alloca_once(builder, context.get_value_type(val))
        builder.store(args[0], slot)
        return slot

    return types.CPointer(val)(val), codegen


@intrinsic
def keep_alive(typingctx, val):
    """A use of ``val`` here: numba keeps its arrays until after this point (see the module
    docstring); it generates no code."""
    def codegen(context, builder, signature, args):
        return context.get_dummy_value()

    return types.none(val), codegen
