"""The framework's own exceptions.

Every error a user can cause (netlist, units, topology, solver) is a HemocircuitError
whose message names the netlist file, the element id and the node where that applies.
The CLI prints the message and exits non-zero; it never shows a traceback for these.
"""
from __future__ import annotations


class HemocircuitError(Exception):
    """Base class of every error the framework raises on purpose."""


class NetlistError(HemocircuitError):
    """A netlist (or protocol, or --set value) is malformed or unphysical."""

    def __init__(self, message: str, file=None, element=None, node=None):
        self.file, self.element, self.node = file, element, node
        where = []
        if file:
            where.append(f"{file}")
        if element:
            where.append(f"element '{element}'")
        if node:
            where.append(f"node '{node}'")
        super().__init__((": ".join([", ".join(where), message])) if where else message)
        self.bare_message = message


class TopologyError(NetlistError):
    """The circuit graph has no consistent solution (floating node, source loop, ...)."""


class SolverError(HemocircuitError):
    """A numerical solve failed.  Keeps what had been computed.

    Attributes: ``time`` (s, or None for static solves), ``state`` (dict name -> value),
    ``partial`` (the result object up to the failure, or None), ``where`` (text).
    """

    def __init__(self, message: str, time=None, state=None, partial=None, where=None):
        self.time, self.state, self.partial, self.where = time, state, partial, where
        parts = [message]
        if where:
            parts.append(f"while {where}")
        if time is not None:
            parts.append(f"at t = {time:.6g} s")
        if state:
            shown = ", ".join(f"{k}={v:.6g}" for k, v in list(state.items())[:12])
            parts.append(f"state: {shown}")
        super().__init__("; ".join(parts))


class FitSpecError(NetlistError):
    """A fit or sensitivity specification (hemocircuit fit, hemocircuit sensitivity) or a file it
    names is malformed.  The message names the spec file and the key (``datasets[1].sigma``,
    ``method.n``), and the data file and its column where one is at fault."""

    def __init__(self, message: str, file=None, key=None):
        self.key = key
        super().__init__(f"{key}: {message}" if key else message, file=file)


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM stopped a run.  A KeyboardInterrupt (so ``except KeyboardInterrupt``
    still catches it, and ``except Exception`` / ``except HemocircuitError`` do not).

    Attributes: ``signum`` (the signal), ``partial`` (the result of what had finished, marked
    partial, or None), ``chunk_results`` (for :func:`hemocircuit.execution.run_chunks`: the
    chunks' results, None where unfinished).  The CLI exits with 128 + signum (130, 143).
    """

    def __init__(self, signum=2, partial=None, chunk_results=None):
        import signal
        self.signum, self.partial, self.chunk_results = int(signum), partial, chunk_results
        try:
            self.signame = signal.Signals(self.signum).name
        except ValueError:
            self.signame = f"signal {self.signum}"
        super().__init__(f"interrupted by {self.signame}")

    @classmethod
    def of(cls, exc, partial=None, chunk_results=None):
        """``exc`` (a KeyboardInterrupt: SIGINT, or an Interrupted) as an Interrupted carrying
        ``partial`` / ``chunk_results`` (the signal kept)."""
        return cls(getattr(exc, "signum", 2), partial if partial is not None else getattr(exc, "partial", None),
                   chunk_results)


def did_you_mean(word, choices, n=3) -> str:
    """' (did you mean 'x' or 'y'?)' for the close matches of ``word`` among ``choices`` (or '')."""
    import difflib

    near = difflib.get_close_matches(str(word), [str(c) for c in choices], n=n, cutoff=0.6)
    if not near:
        return ""
    return " (did you mean " + " or ".join(repr(x) for x in near) + "?)"


def excerpt(text, limit=60) -> str:
    """A short, escaped excerpt of ``text`` for an error message (file contents are never
    quoted at length: a misnamed file may hold anything)."""
    text = str(text)
    short = text[:limit]
    return repr(short) + ("..." if len(text) > limit else "")
