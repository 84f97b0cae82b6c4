"""svZeroDSolver ``ChamberSphere``: a spherical thick-walled chamber with hyperelastic passive
stress, wall viscosity and an active stress driven by a smoothed on/off activation
(Caruel et al. 2013, eq. 13a-b; Pfaller et al. 2019, eq. 12-16).

Equations (SimVascular/svZeroDSolver src/model/ChamberSphere.cpp, ``update_constant``,
``update_time``, ``update_solution``, ``get_elastance_values``), with R = r0 + r (r the radius
change, their variable ``radius``), v = dr/dt (``velo``), P = P_in - P_ref = P_out - P_ref:
    rho d0 dv/dt = R (P R - S d0) / r0^2                           (balance of momentum)
    S = tau + 4 (1 - C^-3)(W1 + C W2) + eta dC/dt (1 + 2 C^-6),  C = (R/r0)^2, dC/dt = 2 R v/r0^2
      = tau + 2 [eta v (2 r0^12 + R^12) + 2 R^5 (R^6 - r0^6)(W1 r0^2 + W2 R^2)] / (r0^2 R^11)
    dtau/dt = -|a| tau + max(a, 0) sigma_max,   a = f alpha_max + (1 - f) alpha_min,
    f = S+ S-,  S+- = (1 +- tanh((t_c - tsys|tdias)/steepness))/2,  t_c = fmod(t, T)
    dV/dt = 4 pi R^2 v = Q_in - Q_out,   P_in = P_out
(their |a| in the decay term and max(a, 0) in the drive are kept as written).
Units (the circuit's mmHg, mL = cm^3, s): rho [mmHg*s^2/cm^2] (mass/volume), thick0 d0,
radius0 r0 [cm], W1, W2, sigma_max [mmHg], eta [mmHg*s], alpha_max, alpha_min [1/s], tsys,
tdias, steepness, period [s].  States r [cm], v [cm/s], tau [mmHg], V [mL] (their ``volume``,
from its initial value: a volume store); observable S [mmHg] (their ``stress``).
Local unknowns [P_in, P_out, P_ref, q]: branch (in, out) with P_in = P_out carrying q = Q_out;
the wall's volume flow 4 pi R^2 v is drawn from ``in`` to ``ref``.
"""
from __future__ import annotations

import math

import numpy as np

from hemocircuit.component import Component, Observable, Param, State, Storage, kernel_method
from hemocircuit.kernels.stamps import branch, imposed_flow

from ..common import flow_observables, jit

PARAMS = {"rho": ("mmHg*s**2/cm**2", True, "wall density"), "thick0": ("cm", True, "wall thickness d0"),
      "radius0": ("cm", True, "reference radius r0"), "W1": ("mmHg", False, "material constant W1"),
      "W2": ("mmHg", False, "material constant W2"), "eta": ("mmHg*s", False, "wall viscosity"),
      "sigma_max": ("mmHg", False, "maximum active stress"),
      "alpha_max": ("1/s", False, "activation rate in systole"), "alpha_min": ("1/s", False, "activation rate in diastole"),
      "tsys": ("s", False, "systole start in the cycle"), "tdias": ("s", False, "diastole start in the cycle"),
      "steepness": ("s", True, "activation switch width"), "period": ("s", True, "cardiac period T")}


@jit
def sphere_stress(p, r, v, tau):
    """Their spherical stress S [mmHg] at radius change r, velocity v and active stress tau."""
    r0, W1, W2, eta = p[2], p[3], p[4], p[5]
    R = r + r0
    return tau + 2.0 * (v * eta * (2.0 * r0 ** 12 + R ** 12)
                        + 2.0 * R ** 5 * (R ** 6 - r0 ** 6) * (W1 * r0 ** 2 + W2 * R ** 2)) / (r0 ** 2 * R ** 11)


@jit
def sphere_activation(p, t):
    """(|a|, max(a, 0)) of their get_elastance_values at time t."""
    tc = np.fmod(t, p[12])
    f = 0.5 * (1.0 + math.tanh((tc - p[9]) / p[11])) * 0.5 * (1.0 - math.tanh((tc - p[10]) / p[11]))
    a = p[7] * f + p[8] * (1.0 - f)
    return abs(a), max(a, 0.0)


@jit
def sphere_wall_flow(p, x):
    """The wall's volume flow 4 pi R^2 v [mL/s] (= dV/dt)."""
    R = x[0] + p[2]
    return 4.0 * math.pi * R * R * x[1]


@jit
def sphere_derivs(p, x, u, t, iopt, dx):
    r, v, tau = x[0], x[1], x[2]
    R = r + p[2]
    S = sphere_stress(p, r, v, tau)
    a_abs, a_plus = sphere_activation(p, t)
    dx[0] = v
    dx[1] = R * ((u[0] - u[2]) * R - S * p[1]) / (p[2] ** 2 * p[0] * p[1])
    dx[2] = -a_abs * tau + a_plus * p[6]
    dx[3] = sphere_wall_flow(p, x)


@jit
def sphere_stamp(p, x, u, t, iopt, A, b):
    branch(A, b, 0, 1, 3, 0.0)  # P_in = P_out, carrying Q_out
    imposed_flow(b, 0, 2, sphere_wall_flow(p, x))


@jit
def sphere_observe(p, x, iopt, out):
    out[0] = x[3]
    out[1] = sphere_stress(p, x[0], x[1], x[2])


@jit
def sphere_report(p, x, u, t, iopt, out):
    sphere_observe(p, x, iopt, out)
    qv = sphere_wall_flow(p, x)
    out[2] = u[3] + qv  # Q_in
    out[3] = u[3] + 0.0 * qv  # Q_out


class ChamberSphere(Component):
    type_name = "chamber_sphere"
    svzerod_blocks = ("ChamberSphere",)
    terminals = ("in", "out", "ref")
    parameters = {k: Param(u, lower=0.0 if pos else None, lower_open=pos, doc=d) for k, (u, pos, d) in PARAMS.items()}
    time_dependent = True
    kernel = kernel_method(sphere_stamp, sphere_derivs, sphere_observe, ("V", "S"), report=sphere_report)
    BRANCHES = (("in", "out"),)
    EDGES = (("in", "out", "pressure"), ("in", "ref", "flow"))
    STATES = (State("r", "cm", 0.1, "radius change from radius0"), State("v", "cm/s", 1.0, "wall velocity dr/dt"),
              State("tau", "mmHg", 100.0, "active stress"), State("V", "mL", 10.0, "volume (from its initial value)"))
    STORAGES = (Storage("in", "ref", "V", state="V"),)
    OBSERVABLES = (Observable("V", "mL", "volume (from its initial value)", state_only=True),
                   Observable("S", "mmHg", "spherical wall stress", state_only=True),
                   *flow_observables("the chamber", "the chamber"))

