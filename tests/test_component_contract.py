"""The component contract (hemocircuit/component.py, docs/components.md), checked generically on
every registered component type -- the built-in library and any plug-in installed through the
entry-point group -- with no knowledge of particular types:

* declarations: terminals, parameters, options, states, observables, storages, edges,
  branches, the drive, hard limits, defaults and outputs of interest name each other
  consistently, and every unit parses with pint;
* the numerical hooks return the documented shapes and types (stamp, derivatives, observe,
  default/initial states, dc_stamp, breakpoints, limited_states);
* the kernel functions compiled give what they give as Python (the one definition, run both
  ways); the flows an element stamps into its nodes fill the volume it stores (conservation);
  the analytic partials of ``derivs_jac`` match central differences of ``derivs``.
  (Closed forms of the simple types: tests/test_kernels_simple.py.)

Parameter values: each type's defaults (its preset for the current options) for every option
combination, the values of its elements in the bundled netlists (with the states and local
pressures of the circuit's DC guess), and, for a required parameter that no netlist gives, a
value inside its declared bounds.
"""
from __future__ import annotations

import glob
import math
import numbers
import zlib

import numpy as np
import pytest

from hemocircuit.component import Component, Drive
from hemocircuit.registry import component_types
from hemocircuit.units import Q_, parse_quantity

from paths import NETLISTS, ROOT
from options import option_combinations

TYPES = component_types()
ROLES = {"conductive", "pressure", "flow"}
B, E = 2, 3  # batch and elements of the shape checks


def _okey(opts):
    return tuple(sorted((k, repr(v)) for k, v in opts.items()))


# ------------------------------------------------------------------ samples ----------------
@pytest.fixture(scope="module")
def netlist_samples():
    """{type name: [(options, p (1, E'), x (1, E', S), u (1, E', L))]} from the bundled
    netlists: bound parameters (expressions evaluated), DC-guess states and local unknowns."""
    import hemocircuit as hc
    from hemocircuit.analyses.op import dc_guess

    out, seen = {}, set()
    files = sorted(glob.glob(str(ROOT / "netlists" / "*.yaml"))) + [str(NETLISTS / "base_rc.yaml")]
    for f in files:
        c = hc.load(f)
        new = [(g.comp.type_name, _okey(g.comp.opts)) for g in c.groups]
        if all(k in seen for k in new):
            continue
        X = dc_guess(c)
        u, plist, _ = c.evaluate(0.0, X, want="u")
        for g, p in zip(c.groups, plist):
            key = (g.comp.type_name, _okey(g.comp.opts))
            if key in seen:
                continue
            seen.add(key)
            pp = {k: np.array(np.broadcast_to(v, (1, g.E)), dtype=float) for k, v in p.items()}
            out.setdefault(g.comp.type_name, []).append((dict(g.comp.opts), pp, X[:, g.sidx], u[:, g.uidx]))
    return out


def _inside(par):
    """A value inside the parameter's declared bounds (for a required one no netlist gives)."""
    lo, hi = par.lower, par.upper
    if lo is not None and hi is not None:
        return 0.5 * (lo + hi)
    if lo is not None:
        return lo + 1.0
    if hi is not None:
        return hi - 1.0
    return 1.0


def default_params(cls, opts, netlist_samples):
    """{name: float} from the type's defaults / preset for ``opts``; a required parameter takes
    the value of the type's first element in the bundled netlists, else one inside its bounds."""
    comp = cls(opts)
    pre = comp.defaults()
    given = netlist_samples.get(cls.type_name, [])
    vals = {}
    for name, par in cls.parameters.items():
        d = pre.get(name, par.default)
        if d is None:
            vs = [float(s[1][name][0, 0]) for s in given if np.isfinite(s[1][name][0, 0])]
            vals[name] = vs[0] if vs else _inside(par)
        elif isinstance(d, numbers.Number) and not isinstance(d, bool):
            vals[name] = float(d)  # presets are numbers in the declared unit
        else:
            vals[name] = parse_quantity(d, par.unit, name)
    return vals


def _local_unknowns(comp, shape):
    """Plausible local unknowns: node pressures falling from 80 mmHg, branch flows of 1 mL/s."""
    K, M = len(comp.local_nodes), len(comp.branches())
    u = np.empty(shape + (K + M,))
    u[..., :K] = 80.0 * 0.6 ** np.arange(K)
    u[..., K:] = 1.0
    return u


def samples_of(cls, netlist_samples):
    """[(component, p (1, E'), x, u)]: defaults for every option combination, then the
    netlists' elements."""
    out = []
    for opts in option_combinations(cls):
        comp = cls(opts)
        vals = default_params(cls, opts, netlist_samples)
        p = {k: np.full((1, 1), v) for k, v in vals.items()}
        if comp.check(p):
            continue
        x = np.array(np.broadcast_to(comp.default_states(p), (1, 1, len(comp.states()))))
        out.append((comp, p, x, _local_unknowns(comp, (1, 1))))
    for opts, p, x, u in netlist_samples.get(cls.type_name, []):
        out.append((cls(opts), p, x, u))
    return out


NAMES = sorted(TYPES)


# --------------------------------------------------------------- declarations --------------
def _unit_ok(unit):
    Q_(1, unit)  # raises on a unit pint cannot parse


@pytest.mark.parametrize("name", NAMES)
def test_declarations_are_consistent(name):
    cls = TYPES[name]
    assert issubclass(cls, Component) and cls.type_name == name
    assert len(set(cls.terminals)) == len(cls.terminals)
    assert cls.role in ROLES
    for pname, par in cls.parameters.items():
        _unit_ok(par.unit)
        if isinstance(par.default, str):
            parse_quantity(par.default, par.unit, pname)
    assert set(cls.waveform_params) <= set(cls.parameters)
    d = cls.drive
    assert d is None or isinstance(d, Drive)
    if d is not None:
        named = [n for n in (d.value, d.amplitude, d.frequency, d.phase, d.start) if n is not None]
        assert set(named) <= set(cls.parameters), named
    for opts in option_combinations(cls):
        comp = cls(opts)
        nodes = comp.local_nodes
        assert len(set(nodes)) == len(nodes)
        states = [s.name for s in comp.states()]
        assert len(set(states)) == len(states)
        for s in comp.states():
            _unit_ok(s.unit)
            assert s.scale > 0
        obs = {o.name: o for o in comp.observables()}
        assert len(obs) == len(comp.observables())
        for o in obs.values():
            _unit_ok(o.unit)
        for a, b in comp.branches():
            assert a in nodes and b in nodes
        for a, b, role in comp.edges():
            assert a in nodes and b in nodes and role in ROLES
        for st in comp.storages():
            assert st.plus in nodes and st.minus in nodes
            assert st.volume in obs and obs[st.volume].state_only
            assert st.state is None or st.state in states
        for sname, bound, reset in comp.hard_limits():
            assert sname in states and isinstance(bound, float) and (reset is None or reset in states)
        assert set(comp.volume_observables()) <= set(obs)
        assert set(comp.outputs_of_interest()) <= set(obs) | set(states)
        assert set(comp.defaults()) <= set(cls.parameters)
        assert set(comp.steady_opts) <= set(cls.options)
        assert isinstance(comp.has_dc_stamp(), bool) and isinstance(comp.dc_short(), bool)
        col = comp.drive_output("X", ["n1", "ground"] + ["n2"] * max(0, len(cls.terminals) - 2))
        assert col is None or isinstance(col, str)
        iopt = comp.kernel_options()
        assert isinstance(iopt, np.ndarray) and iopt.dtype == np.int64 and iopt.ndim == 1


# --------------------------------------------------------------- hook shapes ---------------
def _batch(p, x, u):
    """The sample repeated to (B, E) parameter sets x elements."""
    def rep(a):
        return np.repeat(np.repeat(a[:, :1], E, axis=1), B, axis=0)
    return {k: rep(v) for k, v in p.items()}, rep(x), rep(u)


@pytest.mark.parametrize("name", NAMES)
def test_hooks_return_the_documented_shapes(name, netlist_samples):
    cls = TYPES[name]
    for comp, p1, x1, u1 in samples_of(cls, netlist_samples):
        p, x, u = _batch(p1, x1, u1)
        S, L = len(comp.states()), len(comp.local_nodes) + len(comp.branches())
        assert x.shape == (B, E, S) and u.shape == (B, E, L)
        A, b = comp.stamp(p, x, None if comp.linear_in_pressure else u, 0.0, None)
        assert np.ndim(A) == 4 and np.ndim(b) == 3
        A = np.broadcast_to(A, (B, E, L, L))
        b = np.broadcast_to(b, (B, E, L))
        assert np.shape(comp.derivatives(p, x, u, 0.0, None)) == (B, E, S)
        full = comp.observe(p, x, u, 0.0, None)
        for o in comp.observables():
            assert o.name in full, o.name
            np.broadcast_to(full[o.name], (B, E))
        part = comp.observe(p, x, None, 0.0, None)
        for o in comp.observables():
            if o.state_only:
                np.broadcast_to(part[o.name], (B, E))
        np.broadcast_to(comp.default_states(p), (B, E, S))
        flows = np.einsum("beij,bej->bei", A, u) - b
        assert np.shape(comp.initial_states(p, u, flows, x)) == (B, E, S)
        # DC guess: writable copies in, same shapes out; ``keep`` elements keep their stamp
        keep = np.zeros(E, dtype=bool)
        keep[0] = True
        Ad, bd = comp.dc_stamp(p, np.array(A), np.array(b), keep)
        assert np.shape(Ad) == (B, E, L, L) and np.shape(bd) == (B, E, L)
        if not comp.has_dc_stamp():
            assert np.array_equal(Ad, A) and np.array_equal(bd, b)
        lim = comp.limited_states(p, x)
        assert lim.shape == x.shape and lim.dtype == bool
        for t0, t1 in ((0.0, 10.0), (-1.0, 1e3)):  # periodic elements list every cycle's
            bps = comp.breakpoints(p, t0, t1)
            assert isinstance(bps, (list, tuple))
            assert all(isinstance(v, numbers.Real) and t0 < v < t1 for v in bps)
        assert isinstance(comp.varies_in_time(p), (bool, np.bool_))


@pytest.mark.parametrize("name", NAMES)
def test_one_batched_parameter_broadcasts(name, netlist_samples):
    """A batch that varies one parameter only (a sweep, a fit's perturbation, a sensitivity
    sample): that parameter is (B, E), every other one (1, E).  The circuit stamps the
    elements with a constant matrix once with states (1, E) (Circuit._prepare) and evaluates
    everything else with the batch's states (B, E).  The hooks broadcast to the batch, and the
    last member's result is the one of its values alone."""
    cls = TYPES[name]
    for comp, p1, x1, u1 in samples_of(cls, netlist_samples):
        one = {k: np.repeat(v[:, :1], E, axis=1) for k, v in p1.items()}
        x = np.repeat(x1[:, :1], E, axis=1)
        u = np.repeat(u1[:, :1], E, axis=1)
        xb, ub = np.repeat(x, B, axis=0), np.repeat(u, B, axis=0)
        S, L = len(comp.states()), len(comp.local_nodes) + len(comp.branches())
        if not (comp.constant_matrix and comp.linear_in_pressure):
            x, u = xb, ub  # stamped with the batch's states, like every evaluation
        uu = None if comp.linear_in_pressure else u
        for k in comp.parameters:
            p = dict(one)
            p[k] = one[k] * (1.0 + 0.01 * np.arange(B))[:, None]
            where = f"{name} {comp.opts}, {k} batched"
            A, b = comp.stamp(p, x, uu, 0.0, None)
            A, b = np.broadcast_to(A, (B, E, L, L)), np.broadcast_to(b, (B, E, L))
            dx = np.broadcast_to(comp.derivatives(p, xb, ub, 0.0, None), (B, E, S))
            obs = comp.observe(p, xb, ub, 0.0, None)
            for o in comp.observables():
                np.broadcast_to(obs[o.name], (B, E))
            last = {n: v[-1:] if n == k else v for n, v in p.items()}
            A1, b1 = comp.stamp(last, x[-1:], None if uu is None else uu[-1:], 0.0, None)
            np.testing.assert_array_equal(np.broadcast_to(A1, (1, E, L, L))[0], A[-1], err_msg=where)
            np.testing.assert_array_equal(np.broadcast_to(b1, (1, E, L))[0], b[-1], err_msg=where)
            np.testing.assert_array_equal(np.broadcast_to(comp.derivatives(last, xb[-1:], ub[-1:], 0.0, None),
                                                          (1, E, S))[0], dx[-1], err_msg=where)
            # breakpoints of the batch: those of every member (here: of the last one's values)
            assert set(comp.breakpoints(last, 0.0, 1e3)) <= set(comp.breakpoints(p, 0.0, 1e3)), where


@pytest.mark.parametrize("name", NAMES)
def test_the_matrix_reads_only_its_declared_parameters(name, netlist_samples):
    """Component.matrix_params: A_loc does not change when any other parameter does (an
    expression on such a parameter leaves the element's nodal matrix constant, so the circuit
    and the compiled engine stamp it once per parameter set).  Every parameter moved by 30 %
    in turn, where its bounds allow."""
    cls = TYPES[name]
    for comp, p1, x1, u1 in samples_of(cls, netlist_samples):
        p, x, u = _batch(p1, x1, u1)
        uu = None if comp.linear_in_pressure else u
        A0 = np.array(np.broadcast_to(comp.stamp(p, x, uu, 0.0, None)[0], (B, E) + (u.shape[-1],) * 2))
        for k, par in comp.parameters.items():
            if comp.matrix_reads(k):
                continue
            moved = dict(p)
            v = p[k] * 1.3 if np.all(p[k] != 0) else p[k] + 1.0
            if par.upper is not None and np.any(v > par.upper):
                v = p[k] * 0.7
            moved[k] = v
            A1 = np.broadcast_to(comp.stamp(moved, x, uu, 0.0, None)[0], A0.shape)
            np.testing.assert_array_equal(A1, A0, err_msg=f"{name} {comp.opts}: A_loc reads {k}, "
                                                          f"which matrix_params leaves out")


def test_an_expression_on_a_parameter_the_matrix_does_not_read_keeps_it_constant():
    """The inertia netlists' L(r) (eq. inertia) is an expression of the arteriole's states, but
    the inductor's A_loc does not read L: its group stays constant in the circuit and in the
    compiled layout (cm = 1), and the arteriole's matrix still varies (cm = 0)."""
    import hemocircuit as hc
    from hemocircuit.kernels.layout import build_layout

    c = hc.load(ROOT / "netlists" / "vasomotion.yaml")
    groups = {g.comp.type_name: g for g in c.groups}
    assert groups["inductor"].exprs and groups["inductor"].constant
    assert not groups["arteriole"].constant
    lay = build_layout(c)
    et_of = {eid: k for k, eid in enumerate(e for g in c.groups for e in g.ids)}
    cm = lay.fields.cm
    assert cm[et_of["Lb"]] == 1 and cm[et_of["art"]] == 0


@pytest.mark.parametrize("name", [n for n in NAMES if TYPES[n].drive is not None and TYPES[n].drive.has_sine])
def test_sine_drive_breakpoints_follow_the_declared_parameters(name, netlist_samples):
    """A source's sine term switching on at its declared start is a breakpoint, and only
    while its amplitude is not zero."""
    cls = TYPES[name]
    d = cls.drive
    comp, p1, x1, u1 = samples_of(cls, netlist_samples)[0]
    p, _, _ = _batch(p1, x1, u1)
    p[d.start] = np.full((B, E), 2.5)
    p[d.amplitude] = np.zeros((B, E))
    assert list(comp.breakpoints(p, 0.0, 10.0)) == []
    p[d.amplitude][1, 2] = 1.0
    assert list(comp.breakpoints(p, 0.0, 10.0)) == [2.5]
    assert list(comp.breakpoints(p, 3.0, 10.0)) == []


# --------------------------------------------------------------- kernels -------------------
def _close(got, ref, what, scale_ref=None, floor=0.0):
    """got == ref to rounding: rtol 1e-10, atol 1e-12 x the largest |value| of ``scale_ref``
    (default ``ref``), and at least 1e-12 x ``floor`` (a number or one per value)."""
    ref = np.asarray(ref, dtype=float)
    sref = ref if scale_ref is None else np.asarray(scale_ref, dtype=float)
    scale = np.max(np.abs(sref[np.isfinite(sref)]), initial=0.0)
    atol = np.maximum(1e-12 * scale, 1e-12 * np.asarray(floor, dtype=float)) + 1e-300
    ok = np.isclose(got, ref, rtol=1e-10, atol=atol, equal_nan=True)
    if not np.all(ok):  # the message of a scalar tolerance: the largest one
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=float(np.max(atol)), equal_nan=True, err_msg=what)
        raise AssertionError(f"{what}: {np.asarray(got)[~ok]} != {ref[~ok]} (atol {atol})")


def _pmat(comp, p, n):
    return np.ascontiguousarray(np.stack([np.broadcast_to(p[nm], (1, n))[0] for nm in comp.parameters], axis=1),
                                dtype=float)


def _call_kernel(k, comp, pe, xe, ue, t, pick):
    """Every output of the kernel functions for one element, each function taken by ``pick``
    (its compiled dispatcher or its Python function): A, b, dx, the state-only observables,
    the report and (dx, Jx, Ju, flag) of derivs_jac, where the type has them."""
    iopt = comp.kernel_options()
    S, L = len(comp.states()), len(comp.local_nodes) + len(comp.branches())
    A, b, dx = np.zeros((L, L)), np.zeros(L), np.full(S, np.nan)
    ob = np.full(len(k.observables), np.nan)
    pick(k.stamp)(pe, xe, ue, t, iopt, A, b)
    pick(k.derivs)(pe, xe, ue, t, iopt, dx)
    pick(k.observe)(pe, xe, iopt, ob)
    out = [A, b, dx, ob]
    if k.report is not None:
        rep = np.full(len(comp.observables()), np.nan)
        pick(k.report)(pe, xe, ue, t, iopt, rep)
        out.append(rep)
    if k.derivs_jac is not None:
        d2, Jx, Ju = np.zeros(S), np.zeros((S, S)), np.zeros((S, L))
        flag = pick(k.derivs_jac)(pe, xe, ue, t, iopt, d2, Jx, Ju)
        out += [d2, Jx, Ju, np.array([float(flag)])]
    return out


def _compiled(fn):
    return getattr(fn, "dispatcher", fn)  # hemocircuit.kernels.jit.njit makes it on first use


def _python(fn):
    return fn.py_func


@pytest.mark.parametrize("name", NAMES)
def test_compiled_kernels_equal_their_python_functions(name, netlist_samples):
    """The one definition of a type's equations runs compiled in the engine and as Python
    everywhere else (hemocircuit.elementwise): both give the same numbers, to rounding, for
    every kernel function on the samples and on random points around them (states and local
    unknowns perturbed by up to 5 %, two times)."""
    cls = TYPES[name]
    if cls().kernel() is None:
        pytest.skip(f"'{name}' has no kernel (numpy path only)")
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    for comp, p, x, u in samples_of(cls, netlist_samples):
        k = comp.kernel()
        assert k.observables == tuple(o.name for o in comp.observables() if o.state_only)
        n = x.shape[1]
        pmat = _pmat(comp, p, n)
        scales = np.array([st.scale for st in comp.states()], dtype=float)
        for e in range(n):
            for draw in range(4):
                f = 1.0 if draw == 0 else 1.0 + 0.05 * rng.uniform(-1.0, 1.0)
                xe = np.ascontiguousarray(x[0, e] * (1.0 + 0.05 * rng.uniform(-1, 1, x.shape[-1]) * (draw > 0)))
                ue = np.ascontiguousarray(u[0, e] * f)
                for t in (0.0, 1.37):
                    with np.errstate(all="ignore"):
                        got = _call_kernel(k, comp, pmat[e], xe, ue, t, _compiled)
                        ref = _call_kernel(k, comp, pmat[e], xe, ue, t, _python)
                    for i, (g, r) in enumerate(zip(got, ref)):
                        # the rates (dx, and derivs_jac's): a near-steady sample's are the small
                        # rest of cancelling terms, so rounding is judged per state scale per second
                        rate = i == 2 or (k.derivs_jac is not None and i == len(got) - 4)
                        _close(g, r, f"{name} {comp.opts} element {e} draw {draw} t={t}: output {i}",
                               floor=scales if rate else 0.0)


def _stored_rate(comp, k, pe, xe, dx, iopt):
    """d/dt of the volume the element stores [mL/s]: the rate of each storage's state, or, for a
    volume derived from the states (an arteriolar bed's pi r^2 L n, the heart's chambers), the
    central difference of its observable along dx/dt."""
    names = [s.name for s in comp.states()]
    rate = 0.0
    for st in comp.storages():
        if st.state is not None:
            rate += dx[names.index(st.state)]
            continue
        j = k.observables.index(st.volume)
        size = np.maximum(np.abs(xe), [st.scale for st in comp.states()])
        h = 1e-6 / max(np.max(np.abs(dx) / size), 1e-300)
        vals = []
        for sgn in (1.0, -1.0):
            ob = np.zeros(len(k.observables))
            k.observe(pe, np.ascontiguousarray(xe + sgn * h * dx), iopt, ob)
            vals.append(ob[j])
        rate += (vals[0] - vals[1]) / (2 * h)
    return rate


@pytest.mark.parametrize("name", NAMES)
def test_stamped_flows_fill_the_stores(name, netlist_samples):
    """Conservation of blood, generically: the flows an element draws from its nodes (A u - b
    of its stamp, node rows), summed over every node but the reference side of its stores
    (``Storage.minus``, where a store's other plate takes the flow back), equal the rate of
    change of the volume it stores (its ``storages()``; 0 for an element without one), for
    any local unknowns -- the samples and random ones around them (not at a state held on a
    hard limit, ``limited_states``: a clamped compliance at V = 0 stops draining by design)."""
    cls = TYPES[name]
    if cls().kernel() is None:
        pytest.skip(f"'{name}' has no kernel (numpy path only)")
    rng = np.random.default_rng(7)
    for comp, p, x, u in samples_of(cls, netlist_samples):
        k = comp.kernel()
        iopt = comp.kernel_options()
        S, K = len(comp.states()), len(comp.local_nodes)
        L = K + len(comp.branches())
        minus = {st.minus for st in comp.storages()}
        rows = [j for j, nd in enumerate(comp.local_nodes) if nd not in minus]
        n = x.shape[1]
        pmat = _pmat(comp, p, n)
        limited = comp.limited_states(p, x)
        for e in range(n):
            if limited[0, e].any():
                continue  # a state held at its limit (a collapsed, clamped compliance): the model's choice
            for draw in range(3):
                ue = np.ascontiguousarray(u[0, e] + (draw > 0) * rng.uniform(-5.0, 5.0, L))
                xe = np.ascontiguousarray(x[0, e], dtype=float)
                for t in (0.0, 0.41):
                    A, b, dx = np.zeros((L, L)), np.zeros(L), np.zeros(S)
                    k.stamp(pmat[e], xe, ue, t, iopt, A, b)
                    k.derivs(pmat[e], xe, ue, t, iopt, dx)
                    flows = A @ ue - b
                    net = float(np.sum(flows[rows]))
                    rate = _stored_rate(comp, k, pmat[e], xe, dx, iopt)
                    scale = np.max(np.abs(flows[:K]), initial=0.0) + abs(rate) + 1e-12
                    assert abs(net - rate) <= 1e-6 * scale, (
                        f"{name} {comp.opts} element {e} t={t}: flows into the element {net!r}, "
                        f"stored volume rate {rate!r}")


@pytest.mark.parametrize("name", [n for n in NAMES if TYPES[n]().kernel() is not None
                                  and TYPES[n]().kernel().derivs_jac is not None])
def test_kernel_partials_match_differences_of_derivs(name, netlist_samples):
    """A kernel's optional derivs_jac (Kernel.derivs_jac): dx as its derivs, and partials in the
    states and local unknowns that central differences of derivs confirm (1e-5 of each row's
    size, columns weighted by max(|x|, the state's scale)), on every sample 0.1 % off it and
    shifted by 10 % of each state's scale (for the heart: every valve open); 0 where it does
    not apply.  Where derivs is not differentiable in a state at the point (its forward and
    backward differences disagree by more than 1e-3 of the row's size: a switch, such as a
    closed heart valve's flow on its bound), the entry is the forward quotient at the engine's
    step (the contract, hemocircuit.kernels), to 1e-6 of it."""
    from hemocircuit.derivatives import FD_REL

    cls = TYPES[name]
    checked = 0
    for comp, p, x, u in samples_of(cls, netlist_samples):
        k = comp.kernel()
        iopt = comp.kernel_options()
        S, L = len(comp.states()), len(comp.local_nodes) + len(comp.branches())
        scales = np.array([st.scale for st in comp.states()])
        n = x.shape[1]
        pmat = np.ascontiguousarray(np.stack([np.broadcast_to(p[nm], (1, n))[0] for nm in comp.parameters], axis=1))
        for e in range(n):
            ue = np.ascontiguousarray(u[0, e], dtype=float)
            for xe in (x[0, e] * 1.001, x[0, e] * 1.001 + 0.1 * scales):  # off an equilibrium
                xe = np.ascontiguousarray(xe, dtype=float)
                dx, Jx, Ju = np.zeros(S), np.zeros((S, S)), np.zeros((S, L))
                if k.derivs_jac(pmat[e], xe, ue, 0.0, iopt, dx, Jx, Ju) == 0:
                    continue
                ref = np.zeros(S)
                k.derivs(pmat[e], xe, ue, 0.0, iopt, ref)
                np.testing.assert_array_equal(dx, ref)
                if not np.all(np.isfinite(ref)):
                    continue  # outside the kernel's domain (the shifted point of a state near a limit)

                def derivs_at(v, c, step, of_x):
                    w = v.copy()
                    w[c] += step
                    d = np.zeros(S)
                    k.derivs(pmat[e], w if of_x else xe, ue if of_x else w, 0.0, iopt, d)
                    return d, w[c] - v[c]

                def diff(v, c, of_x):
                    """(central, forward - backward, the engine's forward quotient) in v[c]."""
                    h = 1e-6 * max(abs(v[c]), scales[c] if of_x else 1.0)
                    (up, _), (down, _) = derivs_at(v, c, h, of_x), derivs_at(v, c, -h, of_x)
                    fw, he = derivs_at(v, c, FD_REL * max(abs(v[c]), scales[c] if of_x else 1.0), of_x)
                    return (up - down) / (2 * h), (up - 2 * ref + down) / h, (fw - ref) / he

                Dx = [diff(xe, c, True) for c in range(S)]
                Du = [diff(ue, c, False) for c in range(L)]
                FDx, SWx, FQx = (np.stack([d[i] for d in Dx], axis=1) for i in range(3))
                FDu, SWu, _ = (np.stack([d[i] for d in Du], axis=1) for i in range(3))
                size = np.maximum(np.abs(xe), scales)
                row = np.max(np.abs(FDx) * size, axis=1, keepdims=True) + np.max(np.abs(FDu), axis=1, keepdims=True)
                smooth_x = np.abs(SWx) * size <= 1e-3 * row + 1e-300
                where = f"{name} {comp.opts} element {e} at {xe}"
                assert np.all(np.where(smooth_x, np.abs(Jx - FDx) * size <= 1e-5 * row + 1e-300,
                                       np.abs(Jx - FQx) <= 1e-6 * np.abs(FQx))), where
                assert np.all(np.abs(SWu) <= 1e-3 * row + 1e-300), where  # no kernel switches in u
                assert np.all(np.abs(Ju - FDu) <= 1e-5 * row + 1e-300), where
                checked += 1
    assert checked > 0


def test_every_type_is_sampled(netlist_samples):
    """Each registered type gets at least one parameter set (defaults or a netlist)."""
    for name, cls in TYPES.items():
        assert samples_of(cls, netlist_samples), name
        assert math.isfinite(sum(default_params(cls, cls.options and option_combinations(cls)[0] or {},
                                                netlist_samples).values())), name


#: parameters that make a type's linearisation vary across 0-100 mmHg (the sample's valve is
#: fully open or shut there, with a constant slope)
_SMOOTH = {"valve_tanh": {"Rmin": np.array([[0.5]]), "Rmax": np.array([[50.0]]), "steepness": np.array([[0.1]])}}


@pytest.mark.parametrize("name", ["arteriole", "log_compliance", "resistor", "valve_tanh", "chamber_sphere"])
def test_a_group_in_one_compiled_loop_equals_its_elements_one_by_one(name, netlist_samples, monkeypatch):
    """From LOOP_CALLS element calls on, a group's stamp, derivatives and observables run as one
    compiled loop over its (member, element) pairs (hemocircuit.kernels.loops): the same
    numbers, element by element, as the kernel functions called one element at a time, with
    per-element parameters, states and local unknowns (the samples repeated and perturbed, node
    pressures drawn from 0-100 mmHg), and at per-member times."""
    from hemocircuit import elementwise
    cls = TYPES[name]
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    comp, p, x, u = samples_of(cls, netlist_samples)[-1]
    B, E = 3, elementwise.LOOP_CALLS  # B x E calls: above the threshold
    f = 1.0 + 0.02 * rng.uniform(-1.0, 1.0, (B, E))
    p = {**p, **_SMOOTH.get(name, {})}
    pb = {n: np.broadcast_to(np.asarray(p[n])[:, :1], (1, E)) * f[:1] for n in comp.parameters}
    xb = np.broadcast_to(x[:1, :1], (B, E, x.shape[-1])) * f[..., None]
    ub = np.broadcast_to(u[:1, :1], (B, E, u.shape[-1])) * f[..., None]
    K = len(comp.local_nodes)
    ub[..., :K] = rng.uniform(0.0, 100.0, (B, E, K))  # node pressures either way round (valves open and shut)
    t = np.array([[0.0], [0.7], [1.37]])
    monkeypatch.setattr(elementwise, "LOOP_COMPILE_CALLS", 0)  # the loop even where it is not compiled yet
    with np.errstate(all="ignore"):
        looped = (elementwise.stamp(comp, pb, xb, ub, t), elementwise.derivatives(comp, pb, xb, ub, t),
                  elementwise.observe(comp, pb, xb, ub, t), elementwise.observe(comp, pb, xb, None, t))
        monkeypatch.setattr(elementwise, "LOOP_CALLS", 10 ** 9)
        single = (elementwise.stamp(comp, pb, xb, ub, t), elementwise.derivatives(comp, pb, xb, ub, t),
                  elementwise.observe(comp, pb, xb, ub, t), elementwise.observe(comp, pb, xb, None, t))
    for (a1, b1), (a2, b2) in [(looped[0], single[0])]:
        _close(a1, a2, f"{name}: A"), _close(b1, b2, f"{name}: b")
    _close(looped[1], single[1], f"{name}: dx/dt")
    for got, ref in zip(looped[2:], single[2:]):
        assert got.keys() == ref.keys()
        for key in ref:
            _close(got[key], ref[key], f"{name}: observable {key}")
    assert np.ptp(looped[0][0]) > 0 or np.ptp(looped[0][1]) > 0  # the elements differ: a real batch


@pytest.mark.parametrize("name", NAMES)
def test_a_type_that_reads_t_says_so(name, netlist_samples):
    """Component.time_dependent: a type whose kernel functions do not declare it gives the same
    stamp, derivatives and report at every t (the compiled Jacobian takes df/dt only from the
    time-dependent elements and those with waveforms or expressions: engine_jacobian's time
    column)."""
    cls = TYPES[name]
    if cls().kernel() is None or cls.time_dependent:
        pytest.skip(f"'{name}' has no kernel or declares time_dependent")
    for comp, p, x, u in samples_of(cls, netlist_samples):
        k = comp.kernel()
        pmat = _pmat(comp, p, x.shape[1])
        for e in range(x.shape[1]):
            xe, ue = np.ascontiguousarray(x[0, e]), np.ascontiguousarray(u[0, e])
            with np.errstate(all="ignore"):
                ref = _call_kernel(k, comp, pmat[e], xe, ue, 0.0, _python)
                for t in (0.37, 1.37, 12.3):
                    got = _call_kernel(k, comp, pmat[e], xe, ue, t, _python)
                    for i, (g, r) in enumerate(zip(got, ref)):
                        np.testing.assert_array_equal(g, r, err_msg=f"{name} {comp.opts} element {e}: output {i} "
                                                                    f"changes between t = 0 and {t} s, but the "
                                                                    "type does not declare time_dependent")


def test_a_group_loop_compiles_only_once_it_pays(netlist_samples, monkeypatch):
    """elementwise runs a group of >= LOOP_CALLS element calls in its compiled loop when that
    loop is ready (compiled, or in numba's cache), and otherwise only once this process has
    made LOOP_COMPILE_CALLS calls in such groups: a first short run's outputs stay Python
    (no ~0.9 s compile), a large circuit's right-hand side compiles its loop soon."""
    from hemocircuit import elementwise
    from hemocircuit.kernels import loops
    comp, p, x, u = samples_of(TYPES["resistor"], netlist_samples)[-1]
    k = comp.kernel()
    used = []
    monkeypatch.setattr(elementwise, "_seen", {})
    monkeypatch.setattr(elementwise, "ready", lambda fn, kind: False)  # a fresh install's first run
    monkeypatch.setattr(elementwise, "loop", lambda fn, kind: used.append(kind) or loops.loop(fn, kind))
    E = 100  # 100 calls a group: above LOOP_CALLS
    pb = {n: np.broadcast_to(np.asarray(p[n])[:, :1], (1, E)) for n in comp.parameters}
    xb, ub = np.zeros((1, E, 0)), np.broadcast_to(u[:1, :1], (1, E, u.shape[-1])).copy()
    first = elementwise.stamp(comp, pb, xb, ub, np.zeros((1, 1)))
    for _ in range(elementwise.LOOP_COMPILE_CALLS // E - 2):
        elementwise.stamp(comp, pb, xb, ub, np.zeros((1, 1)))
    assert used == []  # 9 900 calls: as Python
    last = elementwise.stamp(comp, pb, xb, ub, np.zeros((1, 1)))
    assert used == ["stamp"]  # the 100th group reaches 10 000 calls: the loop
    np.testing.assert_array_equal(first[0], last[0])
    np.testing.assert_array_equal(first[1], last[1])
