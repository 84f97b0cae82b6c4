"""numba keys a cached function by its own file only; kernels.freshness deletes the numba caches
of every kernel source when any of them changed (a kernel calling into an edited file would
otherwise keep the old machine code), and the engine name carries the same key."""
import numpy as np

from hemocircuit.kernels import codegen, freshness


def _setup(tmp_path, monkeypatch):
    src = tmp_path / "pkg"
    src.mkdir()
    a, b = src / "kern_a.py", src / "kern_b.py"
    a.write_text("def f():\n    return 1\n")
    b.write_text("def g():\n    return 2\n")
    cache = src / "__pycache__"
    cache.mkdir()
    monkeypatch.setenv("HEMOCIRCUIT_CACHE_DIR", str(tmp_path / "hc"))
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setattr(freshness, "sources", lambda: [a, b])
    return a, b, cache


def _fake_numba_files(cache):
    files = [cache / "kern_a.f-1.py311.nbi", cache / "kern_a.f-1.py311.0.nbc", cache / "kern_b.g-1.py311.nbi"]
    for f in files:
        f.write_bytes(b"x")
    return files


def _check(monkeypatch):
    monkeypatch.setattr(freshness, "_checked", False)
    freshness.ensure_fresh()


def test_caches_deleted_when_any_source_changes(tmp_path, monkeypatch):
    a, b, cache = _setup(tmp_path, monkeypatch)
    files = _fake_numba_files(cache)
    _check(monkeypatch)  # no key recorded yet: whatever is cached may be stale
    assert not any(f.exists() for f in files)
    files = _fake_numba_files(cache)
    _check(monkeypatch)  # same sources: the caches stay
    assert all(f.exists() for f in files)
    b.write_text("def g():\n    return 3\n")  # only b changes: a's cache (it may call g) goes too
    _check(monkeypatch)
    assert not any(f.exists() for f in files)
    unrelated = cache / "other.h-1.py311.nbi"
    unrelated.write_bytes(b"x")
    a.write_text("def f():\n    return 4\n")
    _check(monkeypatch)
    assert unrelated.exists()  # numba files of modules that are not kernel sources are left


def test_once_per_process(tmp_path, monkeypatch):
    a, b, cache = _setup(tmp_path, monkeypatch)
    _check(monkeypatch)
    files = _fake_numba_files(cache)
    b.write_text("def g():\n    return 5\n")
    freshness.ensure_fresh()  # already checked in this process: nothing is read or deleted
    assert all(f.exists() for f in files)


def test_key_covers_contents_and_every_component_file(tmp_path):
    names = {f.name for f in freshness.sources()}
    # a kernel file, the files its kernels call into, and what the engine header reads
    assert {"compiled.py", "activation.py", "linear_elastance_chamber.py", "engine_nodal.py", "engine_jacobian.py",
            "engine_rosenbrock.py", "engine_bdf.py", "dense.py", "runs.py", "waveforms.py", "expressions.py",
            "codegen.py", "tableaus.py", "units.py", "derivatives.py", "linalg.py"} <= names
    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("x = 1\n")
    b.write_text("y = 2\n")
    before = freshness.key([a, b])
    b.write_text("y = 3\n")  # one character of one file
    assert freshness.key([a, b]) != before


def test_engine_name_changes_with_the_key(monkeypatch):
    from hemocircuit.registry import component_types

    kernels = [component_types()["resistor"]().kernel()]
    before = codegen._fingerprint(kernels)
    monkeypatch.setattr(freshness, "key", lambda files=None: "0" * 16)
    after = codegen._fingerprint(kernels)
    assert before[0] == after[0] and before[1] != after[1]  # same type set, other source version
    assert np.all([len(k) == 12 for k in after])
