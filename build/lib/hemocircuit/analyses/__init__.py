"""Analyses.  Each module is one analysis (a function of a circuit and settings, plus an
optional ``register_cli``).  This package imports nothing heavy itself, so the CLI can list
the commands cheaply; :func:`attach` (called by ``hemocircuit.circuit``) makes the common
analyses available as Circuit methods (``c.simulate()``, ``c.operating_point()``, ...), each
importing its module on first call."""
from importlib import import_module

METHODS = {"operating_point": "op", "dc_sweep": "dc", "simulate": "transient", "ac_response": "ac",
           "stability_sweep": "stability", "frequency_response": "freq", "envelope": "envelope"}


def _method(name, module):
    def method(self, *args, **kwargs):
        return getattr(import_module(f"{__name__}.{module}"), name)(self, *args, **kwargs)

    method.__name__ = name
    method.__doc__ = f"``hemocircuit.analyses.{module}.{name}(circuit, ...)`` as a method."
    return method


def attach(circuit_class):
    for name, module in METHODS.items():
        setattr(circuit_class, name, _method(name, module))


def __getattr__(name):  # ``from hemocircuit.analyses import simulate`` still works, lazily
    if name in METHODS:
        return getattr(import_module(f"{__name__}.{METHODS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
