"""Ideal pressure and flow sources (constant, waveform, or built-in sine term).

value(t) = value + waveform(t) + amplitude * sin(2 pi frequency (t - start) + phase) for t >= start.
The built-in sine term has numeric parameters so that a batch of frequency-response runs can
give every member its own frequency; general waveforms are given in ``value`` (see waveforms).
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Component, Param, flow_branch, pressure_branch


def _sine_term(p, t):
    t = np.asarray(t, dtype=float)
    on = t >= p["start"]
    return np.where(on, p["amplitude"] * np.sin(2 * np.pi * p["frequency"] * (t - p["start"]) + p["phase"]), 0.0)


def _sine_params(unit):
    return {
        "amplitude": Param(unit, default=f"0 {unit}", doc="amplitude of the built-in sine term"),
        "frequency": Param("Hz", default="0 Hz", lower=0.0, doc="frequency of the built-in sine term"),
        "phase": Param("rad", default="0 rad", doc="phase of the built-in sine term"),
        "start": Param("s", default="0 s", lower=0.0, doc="time the sine term starts"),
    }


class PressureSource(Component):
    """Imposes P(node) - P(ref) = value(t) [mmHg]; supplies whatever flow the circuit draws."""

    type_name = "pressure_source"
    terminals = ("node", "ref")
    parameters = {"value": Param("mmHg", doc="constant pressure (or a waveform)"), **_sine_params("mmHg")}
    waveform_params = ("value",)
    role = "pressure"
    time_dependent = True

    def branches(self):
        return (("node", "ref"),)

    def varies_in_time(self, p):
        return bool(np.any(p["amplitude"] != 0))

    def value(self, p, t, src):
        return p["value"] + (0.0 if src is None else src) + _sine_term(p, t)

    def stamp(self, p, x, u, t, src=None):
        return pressure_branch(self.value(p, t, src) + np.zeros(x.shape[:2]))


class FlowSource(Component):
    """Imposes a flow value(t) [mL/s] from terminal ``a`` through the source to ``b``."""

    type_name = "flow_source"
    terminals = ("a", "b")
    parameters = {"value": Param("mL/s", doc="constant flow (or a waveform)"), **_sine_params("mL/s")}
    waveform_params = ("value",)
    role = "flow"
    time_dependent = True

    varies_in_time = PressureSource.varies_in_time

    def stamp(self, p, x, u, t, src=None):
        return flow_branch(PressureSource.value(self, p, t, src) + np.zeros(x.shape[:2]))
