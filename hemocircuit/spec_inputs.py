"""Fit and sensitivity specs under the one input policy (:mod:`hemocircuit.inputs`).

A spec is read like a netlist (regular file, size, UTF-8, YAML depth/alias/expansion limits),
and every file it names (a dataset's ``file``, ``start_from``, a ``protocol``, a sensitivity
spec's ``fit_error``) is a name relative to the spec's folder that must lie in the *allowed
folders* of the spec (:func:`spec_access`): the spec's project, the netlist's project, the
bundled netlists and ``--allow-path`` folders (API: ``allow_paths=``).  Files outside are
refused before they are opened, so nothing of them can appear in an error message.

Every error is a :class:`~hemocircuit.errors.FitSpecError` naming the spec file and the key
(``datasets[1].file``, ``method.n``) and saying how to fix it; values from a spec or a data
file are quoted only as a short escaped excerpt (:func:`shown`).
"""
from __future__ import annotations

import math
import os
import reprlib

from . import inputs, limits
from .access import BUNDLED, Access, project_root
from .errors import FitSpecError, NetlistError

_REPR = reprlib.Repr()
_REPR.maxstring = _REPR.maxother = 60
_REPR.maxlist = _REPR.maxtuple = _REPR.maxdict = _REPR.maxset = 6
_REPR.maxlevel = 3


def shown(value, n=80) -> str:
    """A short, escaped rendering of ``value`` for an error message: strings repr'd and cut,
    lists and mappings to a few items and levels (an aliased document is never expanded)."""
    try:
        text = _REPR.repr(value)
    except Exception:  # noqa: BLE001 - a message must not fail on an odd value
        text = f"<{type(value).__name__}>"
    return text if len(text) <= n else text[:n] + "..."


def spec_access(spec_path, netlist_path=None, allow_paths=None) -> Access:
    """The folders the files named in a spec may lie in: the spec's project (the nearest
    folder above it with pyproject.toml or .git, else its own folder), the netlist's project,
    the bundled netlists and ``allow_paths`` (``--allow-path``)."""
    folders = [project_root(os.path.abspath(str(spec_path)))]
    if netlist_path is not None:
        folders.append(project_root(os.path.abspath(str(netlist_path))))
    if os.path.isdir(BUNDLED):
        folders.append(BUNDLED)
    return Access(folders + [str(p) for p in (allow_paths or [])])


def _as_spec_error(exc, spec_file, key, what=None):
    """An input error (of the spec or of a file it names) as a FitSpecError naming the spec
    file and the key; the other file's name is kept in the message."""
    msg = getattr(exc, "bare_message", str(exc))
    other = getattr(exc, "file", None)
    if other and os.path.abspath(str(other)) != os.path.abspath(str(spec_file)) and str(other) not in msg:
        if what and msg.startswith(what + " "):  # 'data file is not UTF-8' -> 'data file X is not UTF-8'
            msg = f"{what} {other}{msg[len(what):]}"
        else:
            msg = f"{what + ' ' if what else ''}{other}: {msg}"
    return FitSpecError(msg, file=spec_file, key=key)


def read_spec(path, what="spec", access=None, named_by=None, key=None):
    """The mapping of a spec file (YAML under the input limits).  ``named_by``: the spec that
    names this one (its key ``key``), for the error messages; then ``access`` applies."""
    path = os.path.abspath(inputs.check_path(path, what))
    try:
        return inputs.read_yaml(path, what, access)
    except NetlistError as exc:
        if named_by:
            raise _as_spec_error(exc, named_by, key, what) from None
        raise FitSpecError(exc.bare_message, file=path) from None


def resolve(name, spec_file, access, what, key, extensions=None) -> str:
    """The absolute path of a file named in a spec (relative to the spec's folder), checked
    against ``access`` (None: a spec built in Python, whose paths are the caller's own choice,
    relative to the current folder); ``extensions``: the endings it may have (e.g. ('.yaml',))."""
    if not isinstance(name, str) or not name.strip():
        raise FitSpecError(f"expected the name of a {what} (relative to the spec's folder), got {shown(name)}",
                           file=spec_file, key=key)
    if "\x00" in name:
        raise FitSpecError(f"{shown(name)}: a file name cannot contain a NUL byte", file=spec_file, key=key)
    if len(name) > 4096:
        raise FitSpecError(f"a file name of {len(name):,} characters; give a real file name", file=spec_file,
                           key=key)
    base = os.path.dirname(os.path.abspath(str(spec_file))) if spec_file else os.getcwd()
    path = os.path.normpath(name if os.path.isabs(name) else os.path.join(base, name))
    if access is not None and not access.allows(path):
        raise FitSpecError(f"the {what} {shown(name, 200)} is outside the allowed folders {access.folders}: a spec "
                           "reads files only inside its own project, the netlist's project and the bundled "
                           "netlists; move the file there, or allow its folder with --allow-path DIR (API: "
                           "allow_paths=[DIR])", file=spec_file, key=key)
    if extensions and not path.lower().endswith(tuple(extensions)):
        raise FitSpecError(f"{what} {shown(name)} should be a {' or '.join(extensions)} file", file=spec_file,
                           key=key)
    return path


def read(kind, path, what, access, spec_file, key, **kw):
    """``inputs.read_<kind>(path, what, access)`` with its errors as FitSpecErrors naming the
    spec file and key (``kind``: text, yaml, json, csv_rows)."""
    fn = getattr(inputs, f"read_{kind}")
    try:
        return fn(path, what, access, **kw)
    except NetlistError as exc:
        raise _as_spec_error(exc, spec_file, key, what) from None


# ------------------------------------------------------------------ values ----------
def integer(value, spec_file, key, lo=None, hi=None, limit_name=None, flag=None):
    """``value`` as an int within [lo, hi] (``limit_name``: hi is that limit, named in the
    error with how to raise it); a clear error otherwise."""
    label = f" ({flag})" if flag else ""
    if isinstance(value, bool) or not isinstance(value, int):
        if isinstance(value, float) and value.is_integer() and abs(value) < 2 ** 63:
            value = int(value)
        else:
            raise FitSpecError(f"expected an integer{label}, got {shown(value)}", file=spec_file, key=key)
    if lo is not None and value < lo:
        kind = {0: "a non-negative integer", 1: "a positive integer"}.get(lo, f"an integer of at least {lo}")
        raise FitSpecError(f"must be {kind}{label}, got {value}", file=spec_file, key=key)
    if limit_name is not None:
        hi = limits.limit(limit_name)
        if value > hi:
            raise FitSpecError(f"{value:,}{label} is more than allowed {limits.how_to_raise(limit_name)}",
                               file=spec_file, key=key)
    elif hi is not None and value > hi:
        raise FitSpecError(f"must be at most {hi}{label}, got {value}", file=spec_file, key=key)
    return value


def number(value, spec_file, key, lo=None, hi=None, lo_open=True, hi_open=True, what="a number"):
    """``value`` (a number, or a string of one) as a finite float within the bounds."""
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise FitSpecError(f"expected {what}, got {shown(value)}", file=spec_file, key=key)
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise FitSpecError(f"expected {what}, got {shown(value)}", file=spec_file, key=key) from None
    if not math.isfinite(x):
        raise FitSpecError(f"expected a finite number, got {shown(value)}", file=spec_file, key=key)
    if lo is not None and (x < lo or (lo_open and x == lo)):
        raise FitSpecError(f"must be {'>' if lo_open else '>='} {lo:g}, got {x:g}", file=spec_file, key=key)
    if hi is not None and (x > hi or (hi_open and x == hi)):
        raise FitSpecError(f"must be {'<' if hi_open else '<='} {hi:g}, got {x:g}", file=spec_file, key=key)
    return x


def text(value, spec_file, key, what="a name"):
    """A non-empty string (numbers are taken as their text, e.g. a column named 1)."""
    if isinstance(value, bool) or not isinstance(value, (str, int, float)) or str(value).strip() == "":
        raise FitSpecError(f"expected {what}, got {shown(value)}", file=spec_file, key=key)
    value = str(value)
    if len(value) > 1000:
        raise FitSpecError(f"expected {what}, got a string of {len(value):,} characters", file=spec_file, key=key)
    return value


def unknown_keys(given, allowed, spec_file, key=None, what="key(s)"):
    """A clear error for keys of a mapping that are not ``allowed``."""
    unknown = [k for k in given if k not in allowed]
    if unknown:
        from .errors import did_you_mean
        names = ", ".join(shown(k, 40) for k in unknown[:5]) + (f", and {len(unknown) - 5} more"
                                                                if len(unknown) > 5 else "")
        raise FitSpecError(f"unknown {what} [{names}]{did_you_mean(unknown[0], allowed)}; allowed: "
                           f"{', '.join(sorted(allowed))}", file=spec_file, key=key)


def check_limit(count, name, spec_file, key, what):
    """``count`` of ``what`` within the limit ``name`` (hemocircuit.limits), else a clear error."""
    if count > limits.limit(name):
        raise FitSpecError(f"{what}: {count:,}, more than allowed {limits.how_to_raise(name)}", file=spec_file,
                           key=key)
