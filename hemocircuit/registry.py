"""Finding component types: scan the ``hemocircuit.components`` package, then entry points.

No central list to edit: a module (or sub-package) in ``components/`` that defines a
:class:`~hemocircuit.component.Component` subclass with a ``type_name`` is a component type.
Third parties register theirs under the entry-point group ``hemocircuit.components``
(the entry point names a Component subclass or a module containing some).
"""
from __future__ import annotations

import functools
import importlib
import inspect
import os
import pkgutil
import re
import warnings
from collections.abc import Mapping
from types import MappingProxyType

from .component import Component
from .errors import HemocircuitError

ENTRY_POINT_GROUP = "hemocircuit.components"


def _classes_in(module):
    for _, obj in inspect.getmembers(module, inspect.isclass):
        if issubclass(obj, Component) and obj is not Component and obj.type_name:
            yield obj


@functools.lru_cache(maxsize=1)
def component_types() -> dict[str, type[Component]]:
    """Map type name -> Component subclass, for every component found."""
    from . import components as pkg
    from .kernels.freshness import ensure_fresh

    ensure_fresh()  # before any kernel is compiled or loaded from numba's cache

    found: dict[str, type[Component]] = {}

    def add(cls, origin):
        other = found.get(cls.type_name)
        if other is not None and other is not cls:
            raise HemocircuitError(f"component type '{cls.type_name}' is defined twice: "
                                   f"{other.__module__} and {origin}")
        found[cls.type_name] = cls

    for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
        module = importlib.import_module(info.name)
        for cls in _classes_in(module):
            add(cls, info.name)
    from importlib import metadata  # (22 ms: only when every type is looked for)

    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        obj = ep.load()
        classes = [obj] if inspect.isclass(obj) else list(_classes_in(obj))
        for cls in classes:
            add(cls, f"entry point {ep.name}")
            _say_if_legacy(cls, ep.name)
    return found


def _say_if_legacy(cls, entry):
    """Warn (once: the registry is built once) about a plug-in type written against the
    vectorised numpy hooks, without kernel functions: it still runs, on the numpy path only."""
    try:
        legacy = cls().kernel() is None
    except Exception:  # noqa: BLE001 - a type that needs options to build: judged when used
        return
    if legacy:
        warnings.warn(f"component type '{cls.type_name}' (entry point {entry}) has no kernel functions: circuits "
                      "with it run on the numpy path only (no compiled engine, slower); to port it, write its "
                      "equations as kernel functions and delete its numpy hooks (docs/components.md)",
                      stacklevel=2)


def get_type(name: str) -> type[Component] | None:
    """The Component subclass of type ``name`` (None if there is none).  A built-in type is
    imported alone, found through :func:`_builtin_index` (a netlist of four types does not
    import the 20 svZeroDSolver blocks: ~60 ms of an ``op`` run); anything else, or a name
    the index cannot settle, goes through the full registry (:func:`component_types`)."""
    if component_types.cache_info().currsize == 0:
        module = _builtin_index().get(name)
        if module is not None:
            from .kernels.freshness import ensure_fresh

            ensure_fresh()  # as component_types: before any kernel is loaded
            found = [cls for cls in _classes_in(importlib.import_module(module)) if cls.type_name == name]
            if len(found) == 1:
                return found[0]
    return component_types().get(name)


_TYPE_NAME = re.compile(r"""^[ \t]+type_name\s*=\s*["']([^"']+)["']""", re.MULTILINE)


@functools.lru_cache(maxsize=1)
def _builtin_index() -> dict[str, str]:
    """{type name: the module of ``hemocircuit.components`` that defines it} read from the
    sources (``type_name = "..."`` in a class body), without importing them; a name written in
    two modules is left out (the full registry then reports it)."""
    from . import components as pkg

    root = pkg.__path__[0]
    index, twice = {}, set()
    for folder, _, files in os.walk(root):
        for f in files:
            if not f.endswith(".py"):
                continue
            path = os.path.join(folder, f)
            rel = os.path.relpath(path, root)[:-3].replace(os.sep, ".")
            module = pkg.__name__ + ("" if rel == "__init__" else "." + rel.removesuffix(".__init__"))
            try:
                with open(path, encoding="utf-8") as fh:
                    names = _TYPE_NAME.findall(fh.read())
            except OSError:
                continue
            for n in names:
                if index.get(n, module) != module:
                    twice.add(n)
                index[n] = module
    return {n: m for n, m in index.items() if n not in twice}


@functools.lru_cache(maxsize=1)
def svzerod_block_types() -> Mapping[str, str]:
    """Map svZeroDSolver block type -> the component type that implements it
    (Component.svzerod_blocks, each class's own), for every component found."""
    found: dict[str, str] = {}
    for name, cls in component_types().items():
        for block in vars(cls).get("svzerod_blocks", ()):  # its own: a subclass implements none by inheriting
            if found.get(block, name) != name:
                raise HemocircuitError(f"svZeroDSolver block '{block}' is implemented twice: component types "
                                       f"'{found[block]}' and '{name}'")
            found[block] = name
    return MappingProxyType(found)  # cached: read-only
