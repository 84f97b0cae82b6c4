"""One policy for every file hemocircuit reads.

Netlists, protocols, waveform tables, svZeroDSolver models, fit and sensitivity specs and their
data, result files read by ``show`` and ``conformance``: all are read through this module, so
every one of them is

* inside the allowed folders when another file names it (:class:`~hemocircuit.access.Access`:
  the project of the file given on the command line, the bundled netlists, ``--allow-path``);
  a file the user names on the command line is the user's own choice and is not checked
  against folders, but everything below holds for it too;
* a regular file (a FIFO, a device such as ``/dev/zero``, a socket or a folder is refused
  before it is opened for reading, so nothing blocks or reads without end);
* within a size limit (:mod:`hemocircuit.limits`, ``FILE_MB`` or ``RESULT_MB``), read with at
  most that many bytes even if the file grows meanwhile;
* UTF-8 text, and YAML within the depth, alias and expansion limits (no alias bomb, no
  unbounded recursion), JSON within the depth limit;
* recorded: each file read in a :func:`recording` block is listed with its size and SHA-256,
  so provenance names exactly what was loaded (and hashes the bytes that were parsed).

Errors name the file and say how to fix it; they never quote more than a short escaped excerpt
of a file's contents.
"""
from __future__ import annotations

import contextlib
import hashlib
import os
import re
import stat

import yaml

from . import limits
from .errors import NetlistError, excerpt


# a file that cannot be read under the policy (outside the allowed folders, not a regular file,
# too large, not UTF-8, not valid YAML/JSON, over a limit) is a malformed input like any other
InputError = NetlistError


# ------------------------------------------------------------------ what was read ----------
class Sources:
    """The files read during one :func:`recording` block, in order: {real path: (bytes, sha256)}."""

    def __init__(self):
        self.files: dict = {}

    def add(self, path, data: bytes):
        self.files.setdefault(path, (len(data), hashlib.sha256(data).hexdigest()))

    def merge(self, other: "Sources"):
        for p, v in other.files.items():
            self.files.setdefault(p, v)

    @property
    def paths(self):
        return list(self.files)

    def sha256(self) -> str:
        """One SHA-256 over the files in order (each file's size and digest, so moving a byte
        from one file to the next changes it; file names do not enter: a moved project keeps
        its hash)."""
        return combined_sha256(self.files.values())


def combined_sha256(entries) -> str:
    h = hashlib.sha256()
    for size, digest in entries:
        h.update(f"{size}:{digest}\n".encode())
    return h.hexdigest()


_recorders: list = []


@contextlib.contextmanager
def recording():
    """``with recording() as sources:`` every file read inside the block is added to ``sources``
    (also to an enclosing block's)."""
    src = Sources()
    _recorders.append(src)
    try:
        yield src
    finally:
        _recorders.remove(src)


# ------------------------------------------------------------------ the checks ----------
def check_path(path, what="file", flag=None):
    """``path`` as a string, refusing what the file system cannot name (a NUL byte, an empty
    name) with a clear error instead of a ValueError."""
    path = os.fspath(path)
    label = f"{flag} " if flag else ""
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    if not path:
        raise InputError(f"{label}{what}: an empty file name")
    if "\x00" in path:
        raise InputError(f"{label}{what} {excerpt(path, 80)}: a file name cannot contain a NUL byte")
    return path


def _open_regular(path, what, access=None, where=None, size_limit="FILE_MB"):
    """An open binary file object of ``path``, checked: allowed folder, regular file, size."""
    path = check_path(path, what)
    where = dict(where or {})
    where.setdefault("file", path)
    if access is not None and not access.allows(path):
        raise InputError(f"{what} {excerpt(path, 200)} is outside the allowed folders {access.folders}: files "
                         "named inside another file are read only inside its project (or the bundled "
                         "netlists); move the file there, or allow its folder with --allow-path DIR "
                         "(API: allow_paths=[DIR])", **where)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError(f"{what} not found: {path}", **where) from None
    except OSError as exc:
        raise InputError(f"{what} {path}: cannot read ({exc.strerror or exc})", **where) from None
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"{what} {path} is a folder; give a file", **where)
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{what} {path} is not a regular file (a device, FIFO or socket); give a file", **where)
    cap = limits.limit(size_limit) * 2 ** 20
    if st.st_size > cap:
        raise InputError(f"{what} is {st.st_size / 2 ** 20:.1f} MiB, larger than allowed "
                         f"{limits.how_to_raise(size_limit)}", **where)
    try:
        # O_NONBLOCK: should the path have become a FIFO since the check, the open does not wait
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise InputError(f"{what} {path}: cannot read ({exc.strerror or exc})", **where) from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise InputError(f"{what} {path} is not a regular file; give a file", **where)
    return os.fdopen(fd, "rb"), cap


def read_bytes(path, what="file", access=None, where=None, size_limit="FILE_MB") -> bytes:
    """The contents of ``path`` under the policy (see the module's docstring); recorded."""
    fh, cap = _open_regular(path, what, access, where, size_limit)
    with fh:
        try:
            data = fh.read(cap + 1)
        except OSError as exc:
            raise InputError(f"{what} {path}: cannot read ({exc.strerror or exc})", file=str(path)) from None
    if len(data) > cap:
        raise InputError(f"{what} grew past {cap // 2 ** 20} MiB while read {limits.how_to_raise(size_limit)}",
                         file=str(path))
    real = os.path.realpath(path)
    for rec in _recorders:
        rec.add(real, data)
    return data


def read_text(path, what="file", access=None, where=None, size_limit="FILE_MB") -> str:
    """The UTF-8 text of ``path`` under the policy (a BOM is dropped)."""
    data = read_bytes(path, what, access, where, size_limit)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise InputError(f"{what} is not UTF-8 text (byte 0x{data[exc.start]:02x} on line {line}); save it as "
                         "UTF-8 (spreadsheets: 'CSV UTF-8')", file=str(path)) from None


# ------------------------------------------------------------------ YAML ----------
class _UniqueKeys:
    """Rejects a key repeated in one mapping (PyYAML keeps the last one silently, so
    ``{R: 1 mmHg*s/mL, R: 2 mmHg*s/mL}`` would hide a typo)."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            try:
                key = self.construct_object(key_node, deep=True)
                hash(key)
            except (TypeError, yaml.YAMLError):
                continue  # unhashable keys: PyYAML itself reports them
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping", node.start_mark, f"found duplicate key {key!r}",
                    key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


class UniqueKeyLoader(_UniqueKeys, yaml.SafeLoader):
    """A safe YAML loader that rejects a key repeated in one mapping."""


# libyaml's parser (about 5x faster on netlists of thousands of elements), same constructor
# and resolver; an invalid file is re-read with the pure-Python loader for its exact message
_FastUniqueKeyLoader = (type("_FastUniqueKeyLoader", (_UniqueKeys, yaml.CSafeLoader), {})
                        if getattr(yaml, "__with_libyaml__", False) else None)

# ``value: ${Pic}`` inside a flow mapping ``{...}`` is not valid YAML (the braces are flow
# indicators), yet it is the documented netlist shape.  Before parsing, every ``${name}`` becomes
# ``$(name)`` (same length, so YAML error columns stay right), and back afterwards.
_REF_TEXT = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)\}")
_REF_SAFE = re.compile(r"\$\(([A-Za-z_][A-Za-z0-9_]*)\)")
_ALIAS = re.compile(r"(?:^|[\s\[{,:])\*[^\s*]", re.M)  # a YAML alias (*name), or the odd false alarm


def _may_nest_deeper(text, limit) -> bool:
    """A cheap upper bound on the YAML nesting: flow brackets open at once plus the widest
    indentation (each block level takes at least one column); True if it could exceed ``limit``."""
    import numpy as np

    br = np.frombuffer(re.sub(r"[^\[\]{}]", "", text).encode(), dtype=np.uint8)
    if br.size and np.cumsum(np.where((br == ord("[")) | (br == ord("{")), 1, -1)).max() > limit // 2:
        return True
    indent = max((len(m.group(0)) for m in re.finditer(r"^[ \t?:-]+", text, re.M)), default=0)
    return indent > limit // 2


def _restore_refs(value, path, refs, depth=0, memo=None, lim=None):
    """Check the nesting depth and the length of strings (and turn ``$(name)`` back to
    ``${name}`` when ``refs``).  A node shared through a YAML alias is converted once and stays
    shared (an alias bomb is not expanded here)."""
    if lim is None:
        lim, memo = (limits.limit("YAML_DEPTH"), limits.limit("VALUE_CHARS")), {}
    if depth > lim[0]:
        raise InputError(f"YAML nested more than {depth - 1} levels deep {limits.how_to_raise('YAML_DEPTH')}",
                         file=path)
    if isinstance(value, str):
        if len(value) > lim[1]:
            limits.check_value_length(value, {"file": path}, f"the value {excerpt(value, 40)}")
        return _REF_SAFE.sub(lambda m: "${" + m.group(1) + "}", value) if refs and "$(" in value else value
    if isinstance(value, (list, dict)):
        key = id(value)
        if key in memo:
            return memo[key][1]
        if isinstance(value, list):
            out = [_restore_refs(v, path, refs, depth + 1, memo, lim) for v in value]
        else:
            out = {_restore_refs(k, path, refs, depth + 1, memo, lim): _restore_refs(v, path, refs, depth + 1, memo,
                                                                                     lim)
                   for k, v in value.items()}
        memo[key] = (value, out)  # the original is kept alive, so its id is not reused
        return out
    return value


def parse_yaml(text, path, refs=False):
    """Parse YAML ``text`` (of file ``path``, for messages) within the limits: depth, aliases,
    expanded size, value length; repeated keys refused.  ``refs``: ``${name}`` may stand
    unquoted in flow mappings (netlists)."""
    try:
        if refs:
            text = _REF_TEXT.sub(lambda m: "$(" + m.group(1) + ")", text)
        loader = _FastUniqueKeyLoader or UniqueKeyLoader
        if _ALIAS.search(text) or _may_nest_deeper(text, limits.limit("YAML_DEPTH")):
            # aliases can multiply the document, and libyaml's composer recurses (a crash, not
            # an error, at tens of thousands of levels): scan the event stream first
            limits.check_yaml(text, path, loader)
        try:
            data = yaml.load(text, Loader=loader)
        except yaml.YAMLError:
            data = yaml.load(text, Loader=UniqueKeyLoader)  # raises again, with the snippet
        return _restore_refs(data, path, refs)
    except yaml.YAMLError as exc:
        msg = str(exc)
        raise InputError(f"not valid YAML: {msg[:600]}{'...' if len(msg) > 600 else ''}", file=path) from None
    except (RecursionError, MemoryError):
        raise InputError(f"the YAML is too deeply nested or too large to read {limits.how_to_raise('YAML_DEPTH')}",
                         file=path) from None


def read_yaml(path, what="file", access=None, where=None, refs=False):
    """A YAML file under the policy (see :func:`parse_yaml`)."""
    return parse_yaml(read_text(path, what, access, where), str(path), refs)


# ------------------------------------------------------------------ JSON ----------
def parse_json(text, path, allow_nan=False):
    """JSON ``text`` within the depth limit (Python's parser recurses).  Not through YAML:
    PyYAML reads YAML 1.1, where a JSON number such as 9.0219259e7 is a string.  NaN and
    Infinity (not JSON, though Python writes them) are refused unless ``allow_nan``."""
    import json

    depth = limits.limit("YAML_DEPTH")
    # an upper bound on the nesting from the brackets, ignoring strings (a false alarm costs a scan)
    if text.count("[") + text.count("{") > depth and _json_depth(text) > depth:
        raise InputError(f"the JSON is nested more than {depth} levels deep {limits.how_to_raise('YAML_DEPTH')}",
                         file=path)
    try:
        return json.loads(text) if allow_nan else json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}", file=path) from None
    except ValueError as exc:  # NaN / Infinity, or an integer of more than 4300 digits
        raise InputError(f"not valid JSON: {exc}", file=path) from None
    except RecursionError:
        raise InputError("the JSON is too deeply nested to read", file=path) from None


def _no_constant(name):
    raise ValueError(f"{name} is not a JSON number; write a finite number")


def _json_depth(text) -> int:
    """The deepest bracket nesting of JSON ``text``, strings left out (vectorised: a 5 MB model
    in tens of milliseconds)."""
    import numpy as np

    b = np.frombuffer(text.replace("\\\\", "").replace('\\"', "").encode(), dtype=np.uint8)
    quote = b == ord('"')
    outside = (np.cumsum(quote) - quote) % 2 == 0  # before an opening quote, or after a closing one
    step = np.where(outside & ((b == ord("[")) | (b == ord("{"))), 1, 0) - \
        np.where(outside & ((b == ord("]")) | (b == ord("}"))), 1, 0)
    return int(np.cumsum(step).max()) if b.size else 0


def read_json(path, what="file", access=None, where=None, size_limit="FILE_MB", allow_nan=False):
    """A JSON file under the policy."""
    return parse_json(read_text(path, what, access, where, size_limit), str(path), allow_nan)


# ------------------------------------------------------------------ CSV ----------
def read_csv_rows(path, what="CSV file", access=None, where=None, size_limit="FILE_MB", comments=True):
    """The rows of a CSV file under the policy (lists of strings; empty rows and, with
    ``comments``, rows whose first cell starts with '#' dropped)."""
    import csv
    import io

    text = read_text(path, what, access, where, size_limit)
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise InputError(f"{what} is not valid CSV ({exc})", file=str(path)) from None
    return [r for r in rows if r and not (comments and r[0].lstrip().startswith("#"))]
