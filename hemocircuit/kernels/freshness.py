"""Keep numba's on-disk caches of the compiled kernels consistent with their sources.

Numba keys a cached function by its own source file (time stamp and size) only.  A kernel that
calls a compiled function of another file -- the chamber kernels call activation.py's, the
arteriole kernel the constants of its physics modules -- keeps the machine code of the old
callee after that file alone changes (an editable install after ``git pull``, a local edit):
silently wrong numbers.  :func:`ensure_fresh` keeps one key over every source file compiled
code is built from (:func:`sources`); when the key differs from the one recorded for this
numba cache location, it deletes the numba cache files of all those sources, once per process,
before anything is compiled.  The engine modules carry the same key in their name
(codegen._fingerprint), so they are rebuilt as well.  Plug-in components in other packages
are keyed by their own files only (numba's rule).
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path


def cache_dir() -> Path:
    """The folder of the compiled engines and their markers (HEMOCIRCUIT_CACHE_DIR, default
    ~/.cache/hemocircuit), created on first use."""
    d = Path(os.environ.get("HEMOCIRCUIT_CACHE_DIR") or Path.home() / ".cache" / "hemocircuit") / "kernels"
    d.mkdir(parents=True, exist_ok=True)
    return d


_HERE = Path(__file__).resolve().parent
_checked = False


def sources() -> list[Path]:
    """Every source file whose code or constants the compiled kernels contain: the components
    package (built-in component types and their physics), this kernels package (among them
    the engine's template files engine_*.py), units.py, derivatives.py (the difference step
    FD_REL, which the engine and the heart's partials read) and linalg.py (the LU the engine
    calls)."""
    import hemocircuit.components as comps

    roots = [Path(p).resolve() for p in comps.__path__] + [_HERE]
    files = sorted({f for r in roots for f in r.rglob("*.py") if "__pycache__" not in f.parts})
    return files + [_HERE.parent / "units.py", _HERE.parent / "derivatives.py", _HERE.parent / "linalg.py"]


def key(files=None) -> str:
    """Hash of the sources' names and contents."""
    h = hashlib.sha256()
    for f in files or sources():
        h.update(str(f.name).encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def _numba_dirs(py_file: Path) -> list[Path]:
    """Where numba may cache functions of ``py_file`` (its locators: $NUMBA_CACHE_DIR, the
    file's __pycache__, the user-wide cache), without importing numba."""
    sub = py_file.parent
    name = f"{sub.name}_{hashlib.sha1(str(sub).encode()).hexdigest()}"
    out = [sub / "__pycache__"]
    if os.environ.get("NUMBA_CACHE_DIR"):
        out.append(Path(os.environ["NUMBA_CACHE_DIR"]) / name)
    out.append(Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "numba" / name)
    return out


def _stamp() -> Path:

    where = os.environ.get("NUMBA_CACHE_DIR", "") + "|" + str(_HERE)
    return cache_dir() / f"kernel-sources-{hashlib.sha256(where.encode()).hexdigest()[:10]}.key"


def ensure_fresh() -> None:
    """Once per process: delete the numba caches of the kernels' sources if any source changed
    since the key was last recorded for this cache location (see the module docstring)."""
    global _checked
    if _checked:
        return
    _checked = True
    files = sources()
    now = key(files)
    stamp = _stamp()
    try:
        if stamp.read_text().strip() == now:
            return
    except OSError:
        pass
    for f in files:
        for d in _numba_dirs(f):
            for pattern in (f"{f.stem}.*.nbi", f"{f.stem}.*.nbc"):
                for cached in d.glob(pattern):
                    try:
                        cached.unlink()
                    except OSError:  # not ours to delete, or gone meanwhile
                        pass
    try:
        tmp = stamp.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(now + "\n")
        os.replace(tmp, stamp)
    except OSError:  # a read-only cache folder: checked again by the next process
        pass
