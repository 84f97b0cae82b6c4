"""Ideal pressure and flow sources (constant, waveform, or built-in sine term).

value(t) = value + waveform(t) + amplitude * sin(2 pi frequency (t - start) + phase) for t >= start.
The built-in sine term has numeric parameters so that a batch of frequency-response runs can
give every member its own frequency; general waveforms are given in ``value`` (see waveforms).
"""
from __future__ import annotations

import math

import numpy as np

from hemocircuit.component import Component, Drive, Param, kernel_method
from hemocircuit.netlist import GROUND
from hemocircuit.kernels.stamps import branch, imposed_flow

from .common import jit as _jit


def _sine_params(unit):
    return {
        "amplitude": Param(unit, default=f"0 {unit}", doc="amplitude of the built-in sine term"),
        "frequency": Param("Hz", default="0 Hz", lower=0.0, doc="frequency of the built-in sine term"),
        "phase": Param("rad", default="0 rad", doc="phase of the built-in sine term"),
        "start": Param("s", default="0 s", lower=0.0, doc="time the sine term starts"),
    }


# p = [value, amplitude, frequency, phase, start] (the ``parameters`` order; the circuit kernel
# has already added the waveform's value to p[0]); no states, options or observables.
@_jit
def kernel_value(p, t):
    """value(t) = p[value] (with the waveform's value added) + the built-in sine term."""
    s = 0.0
    if t >= p[4]:
        s = p[1] * math.sin(2 * np.pi * p[2] * (t - p[4]) + p[3])
    return p[0] + s


@_jit
def pressure_stamp(p, x, u, t, iopt, A, b):
    branch(A, b, 0, 1, 2, kernel_value(p, t))  # local unknowns [P_node, P_ref, q]: P_node - P_ref = value


@_jit
def flow_stamp(p, x, u, t, iopt, A, b):
    imposed_flow(b, 0, 1, kernel_value(p, t))  # local unknowns [P_a, P_b]: q = value from a to b


class _Source(Component):
    """What both sources share: an input drives their value, which has a built-in sine term."""

    waveform_params = ("value",)
    drive = Drive(value="value", amplitude="amplitude", frequency="frequency", phase="phase", start="start")
    time_dependent = True
    time_switch = "amplitude"  # no sine: a constant value

    def breakpoints(self, p, t0, t1):
        """Sine starts in (t0, t1) of the elements whose sine term is on (amplitude != 0)."""
        # either may vary over a batch alone (a sweep of the amplitude with one start, or of the start)
        start, amp = np.broadcast_arrays(np.asarray(p["start"], dtype=float), np.asarray(p["amplitude"], dtype=float))
        return sorted({float(s) for s, a in zip(start.reshape(-1), amp.reshape(-1)) if a != 0 and t0 < s < t1})


class PressureSource(_Source):
    """Imposes P(node) - P(ref) = value(t) [mmHg]; supplies whatever flow the circuit draws."""

    type_name = "pressure_source"
    svzerod_blocks = ("PRESSURE",)  # their PRESSURE boundary condition
    terminals = ("node", "ref")
    parameters = {"value": Param("mmHg", doc="constant pressure (or a waveform)"), **_sine_params("mmHg")}
    role = "pressure"
    kernel = kernel_method(pressure_stamp)

    def branches(self):
        return (("node", "ref"),)

    def drive_output(self, eid, nodes):
        """P(node) when the reference is ground (otherwise no column holds the difference)."""
        return f"P({nodes[0]})" if nodes[1] == GROUND and nodes[0] != GROUND else None


class FlowSource(_Source):
    """Imposes a flow value(t) [mL/s] from terminal ``a`` through the source to ``b``."""

    type_name = "flow_source"
    svzerod_blocks = ("FLOW",)  # their FLOW boundary condition
    terminals = ("a", "b")
    parameters = {"value": Param("mL/s", doc="constant flow (or a waveform)"), **_sine_params("mL/s")}
    role = "flow"
    kernel = kernel_method(flow_stamp)

    def drive_output(self, eid, nodes):
        return f"Q({eid})"
