"""The blocks of an svZeroDSolver model as netlist elements: one translator per kind of block,
each taking the importer's state (:class:`~hemocircuit.svzerod.importer.Importer`: its value
readers, connection nodes, initial condition and the elements it collects).

Mapping (one element per block, named after it; blocks in components/svzerod/, each written as
the component type that declares it in ``svzerod_blocks``):
  vessels  BloodVessel -> blood_vessel, BloodVesselCRL -> blood_vessel_crl, BloodVesselRC
           (Rpd, Cp) -> blood_vessel_rc (a flow-through RC: Q_in = Q_out), ChamberSphere ->
           chamber_sphere, Resistance / Capacitance / Inductance (their one-element vessels) ->
           blood_vessel with the other two of R, C, L at 0
           (nodes [inlet, outlet, ground]; options capacitive/inductive from C, L != 0)
  junctions NORMAL_JUNCTION -> one node named after the junction (ideal: equal pressures,
           mass conservation); BloodVesselJunction -> one blood_vessel per outlet,
           ``J_outletname`` (their equations are exactly parallel R + stenosis + L branches)
  valves   ValveTanh, PiecewiseValve (nodes [upstream, downstream])
  chambers ChamberElastanceInductor(Exponential), LinearElastanceChamber (their
           activation_function as the option ``activation`` and its parameters), ChamberSphere
  heart    ClosedLoopHeartAndPulmonary -> element CLH between the nodes of its junctions
           J_heart_inlet and J_heart_outlet
  BCs      FLOW -> flow_source, PRESSURE -> pressure_source (their periodic time series as a
           ``periodic`` pwl waveform: one cycle), RESISTANCE -> resistance_bc,
           RCR -> rcr_bc, CORONARY -> coronary_bc, CORONARY_VAR_RES -> coronary_var_res_bc;
           ClosedLoopRCR and ClosedLoopCoronaryLeft/Right (tied to the heart by expressions)
           drain into J_heart_inlet
"""
from __future__ import annotations

from ..errors import did_you_mean
from ..units import parse_quantity
from .model import (CLOSED_LOOP_CORONARY, CORONARY_SIDE, HEART, HEART_IN, HEART_OUT, ONE_ELEMENT_VESSELS,
                    SUPPORTED_BC, SUPPORTED_VESSELS, as_float, check_period, ident, model_error,
                    quantity_text as fmt, show, shown_keys)


def vessels(imp, blocks):
    """Their vessels: a BloodVessel(CRL) with its capacitor and inductor where C, L != 0, a
    flow-through BloodVesselRC, a ChamberSphere listed among the vessels."""
    V, Q = imp.u["V"], imp.u["Q"]
    for v in blocks:
        name, typ = v["vessel_name"], v["zero_d_element_type"]
        imp.types.add(typ)
        if typ not in SUPPORTED_VESSELS:
            raise model_error(f"vessel '{name}': unknown zero_d_element_type {show(typ)}"
                              f"{did_you_mean(typ, SUPPORTED_VESSELS)} (supported: {', '.join(SUPPORTED_VESSELS)})",
                              name, imp.path)
        vals = v["zero_d_element_values"]
        if typ == "ChamberSphere":  # a chamber listed among their vessels
            chamber_sphere(imp, name, vals, imp.two_port("vessel", name))
            imp.q_in[name], imp.q_out[name] = f"{imp.ids[name]}.Q_in", f"{imp.ids[name]}.Q_out"
            continue
        if typ == "BloodVesselRC":  # a flow-through RC (Q_in = Q_out), not a CRL without L
            imp.only_keys(name, vals, ("Rpd", "Cp"))
            eid = imp.id_of(name)
            Cp = float(imp.value(name, vals, "Cp"))
            imp.add(eid, "BloodVesselRC", list(imp.two_port("vessel", name)) + ["ground"],
                    Rpd=fmt(imp.value(name, vals, "Rpd"), imp.uR), Cp=fmt(Cp, imp.uC))
            imp.q_in[name], imp.q_out[name] = f"{eid}.Q_in", f"{eid}.Q_out"
            imp.start(eid, "X", Cp * imp.ic(f"pressure:{imp.inlet[name][0]}:{name}"), V)
            continue
        if typ in ONE_ELEMENT_VESSELS:  # a BloodVessel with only its own value (model.ONE_ELEMENT_VESSELS)
            key, param = ONE_ELEMENT_VESSELS[typ]
            imp.only_keys(name, vals, (key,))
            vals = {"R_poiseuille": 0.0, param: imp.value(name, vals, key)}
        R = imp.value(name, vals, "R_poiseuille")
        C, L = imp.value(name, vals, "C", 0.0), imp.value(name, vals, "L", 0.0)
        S = imp.value(name, vals, "stenosis_coefficient", 0.0)
        n_in, n_out = imp.two_port("vessel", name)
        up, down = imp.inlet[name][0], imp.outlet[name][0]
        eid = imp.id_of(name)
        imp.add(eid, typ, [n_in, n_out, "ground"],
                R_poiseuille=fmt(R, imp.uR), C=fmt(C, imp.uC), L=fmt(L, imp.uL),
                stenosis_coefficient=fmt(S, imp.uS), capacitive=C != 0.0, inductive=L != 0.0, stenotic=S != 0.0)
        imp.q_in[name], imp.q_out[name] = f"{eid}.Q_in", f"{eid}.Q_out"
        p0, qi, qo = imp.ic(f"pressure:{up}:{name}"), imp.ic(f"flow:{up}:{name}"), imp.ic(f"flow:{name}:{down}")
        if C != 0.0:  # their capacitor pressure: P_in (CRL), P_in - (R + S|Q_in|) Q_in (BloodVessel)
            pc = p0 if typ == "BloodVesselCRL" else p0 - (float(R) + S * abs(qi)) * qi
            imp.start(eid, "V", C * pc, V, store=True)
        if L != 0.0:
            imp.start(eid, "Q_out", qo, Q)


def vessel_junctions(imp):
    """Their BloodVesselJunctions (junctions with resistances): one vessel per outlet."""
    for name, (jt, ins, outs, j) in imp.junctions.items():
        if jt != "BloodVesselJunction":
            continue
        if len(ins) != 1:
            raise model_error(f"junction '{name}': a BloodVesselJunction has exactly one inlet", name, imp.path)
        jv = j.get("junction_values") or {}
        lists = []
        for key in ("R_poiseuille", "L", "stenosis_coefficient"):
            if key == "R_poiseuille" and key not in jv:
                raise model_error(f"junction '{name}': missing junction_values.R_poiseuille (one value per outlet)",
                                  name, imp.path)
            lst = jv.get(key, [0.0] * len(outs))
            if not isinstance(lst, list) or len(lst) != len(outs):
                raise model_error(f"junction '{name}': '{key}' needs a list of one value per outlet ({len(outs)}), "
                                  f"got {show(lst)}", name, imp.path)
            lists.append(imp.numbers(name, lst, key))
        for o, R, L, S in zip(outs, *lists):
            eid = imp.id_of(f"{name}_{o}")
            imp.add(eid, "BloodVessel", [imp.node(ins[0], name), imp.node(name, o), "ground"],
                    R_poiseuille=fmt(R, imp.uR), L=fmt(L, imp.uL), stenosis_coefficient=fmt(S, imp.uS),
                    inductive=L != 0.0, stenotic=S != 0.0)
            imp.q_in[name + "->" + o] = f"{eid}.Q_out"
            if L != 0.0:
                imp.start(eid, "Q_out", imp.ic(f"flow:{name}:{o}"), imp.u["Q"])


def valves(imp, blocks):
    """Their valves {name: block}: two-port elements of Rmin, Rmax (and ValveTanh's steepness)."""
    for name, b in blocks.items():
        typ, prm = b["type"], b["params"]
        imp.types.add(typ)
        eid = imp.id_of(name)
        kw = {k: fmt(imp.value(name, prm, k), imp.uR) for k in ("Rmin", "Rmax")}
        if typ == "ValveTanh":
            kw["steepness"] = fmt(imp.value(name, prm, "Steepness"), f"1/({imp.u['P']})")
        imp.add(eid, typ, list(imp.two_port("valve", name)), **kw)
        imp.q_in[name] = imp.q_out[name] = f"{eid}.Q"


def chambers(imp, blocks):
    """Their chambers {name: block}: elastance chambers with their activation function, and
    ChamberSphere (its own activation)."""
    P, V, Q = imp.u["P"], imp.u["V"], imp.u["Q"]
    for name, b in blocks.items():
        typ, vals = b["type"], b.get("values") or {}
        imp.types.add(typ)
        if typ == "ChamberSphere":  # its own activation, no activation_function
            chamber_sphere(imp, name, vals, imp.two_port("chamber", name))
            imp.q_in[name], imp.q_out[name] = f"{imp.ids[name]}.Q_in", f"{imp.ids[name]}.Q_out"
            continue
        eid = imp.id_of(name)
        act = activation(imp, name, b.get("activation_function"))
        if typ == "ChamberElastanceInductor":
            kw = {k: fmt(imp.value(name, vals, k), imp.uE) for k in ("Emax", "Emin")}
            kw.update({k: fmt(imp.value(name, vals, k), V) for k in ("Vrd", "Vrs")})
            kw["Impedance"] = fmt(imp.value(name, vals, "Impedance"), imp.uL)
        elif typ == "ChamberElastanceInductorExponential":
            imp.only_keys(name, vals, ("Emax", "Kxp", "Kxv", "Vaso", "Impedance"))
            kw = {"Emax": fmt(imp.value(name, vals, "Emax"), imp.uE),
                  "Kxp": fmt(imp.value(name, vals, "Kxp"), P),
                  "Kxv": fmt(imp.value(name, vals, "Kxv"), f"1/({V})"),
                  "Vaso": fmt(imp.value(name, vals, "Vaso"), V),
                  "Impedance": fmt(imp.value(name, vals, "Impedance"), imp.uL)}
        else:
            kw = {k: fmt(imp.value(name, vals, k), imp.uE) for k in ("Emax", "Epass")}
            kw["Vrest"] = fmt(imp.value(name, vals, "Vrest"), V)
        imp.chamber_elements.append((eid, act))
        imp.add(eid, typ, list(imp.two_port("chamber", name)) + ["ground"], **kw, **act)
        imp.q_in[name], imp.q_out[name] = f"{eid}.Q_in", f"{eid}.Q_out"
        imp.start(eid, "Vc", imp.ic(f"Vc:{name}"), V, store=True)
        if typ != "LinearElastanceChamber":  # the inductor's flow
            imp.start(eid, "Q_out", imp.ic(f"flow:{name}:{imp.outlet[name][0]}"), Q)


def closed_loop_heart(imp, heart):
    """Their ClosedLoopHeartAndPulmonary block: element CLH between its junctions, of its own
    cardiac period."""
    V, Q = imp.u["V"], imp.u["Q"]
    prm = heart.get("parameters") or {}
    eid = imp.id_of(HEART)
    hp = heart_values(imp, prm)
    period = as_float(heart.get("cardiac_cycle_period"))
    if period is None or period <= 0:
        raise model_error(f"ClosedLoopHeartAndPulmonary: 'cardiac_cycle_period' must be a finite number > 0 [s], got "
                          f"{show(heart.get('cardiac_cycle_period'))}", HEART, imp.path)
    check_period(period, "ClosedLoopHeartAndPulmonary: 'cardiac_cycle_period'", HEART, imp.path)
    imp.note_period(period, HEART)
    imp.add(eid, "ClosedLoopHeartAndPulmonary", [imp.node(HEART_IN, HEART), imp.node(HEART, HEART_OUT), "ground"],
            period=fmt(period, "s"), **hp)
    imp.q_in[HEART], imp.q_out[HEART] = f"{eid}.Q_in", f"{eid}.Q_out"
    for st in ("V_RA", "V_RV", "V_LA", "V_LV"):
        imp.start(eid, st, imp.ic(f"{st}:{HEART}"), V, store=True)
    for st in ("Q_RA", "Q_RV", "Q_LA", "Q_LV"):
        imp.start(eid, st, imp.ic(f"{st}:{HEART}"), Q)
    imp.start(eid, "V_pul", imp.value(HEART, prm, "Cp") * imp.ic(f"P_pul:{HEART}"), V)
    imp.start(eid, "V_ao", imp.value(HEART, prm, "Cpa") * imp.ic(f"pressure:{HEART}:{HEART_OUT}"), V, store=True)


def boundary_conditions(imp, bcs, heart, steady=False):
    """Their boundary conditions {name: block}; ``heart``: the closed-loop heart block (or
    None); ``steady``: every time series at its mean.  Sets ``imp.closed``: every boundary
    condition drains into the heart (a closed loop)."""
    P, V, Q = imp.u["P"], imp.u["V"], imp.u["Q"]
    imp.closed = not any(b.get("bc_type") not in ("ClosedLoopRCR",) + CLOSED_LOOP_CORONARY for b in bcs.values())
    for name, b in bcs.items():
        typ = b.get("bc_type")
        if typ not in SUPPORTED_BC:
            raise model_error(f"boundary condition '{name}': unknown or unsupported bc_type {show(typ)}"
                              f"{did_you_mean(typ, SUPPORTED_BC)} (supported: {', '.join(SUPPORTED_BC)})", name,
                              imp.path)
        imp.types.add(typ)
        vals = b["bc_values"]  # a mapping (check_structure)
        eid = imp.id_of(name)
        if typ == "ClosedLoopRCR":
            n_in, n_out = imp.two_port("boundary condition", name)
            C = imp.value(name, vals, "C")
            imp.add(eid, "ClosedLoopRCR", [n_in, n_out, "ground"], Rp=fmt(imp.value(name, vals, "Rp"), imp.uR),
                    C=fmt(C, imp.uC), Rd=fmt(imp.value(name, vals, "Rd"), imp.uR))
            imp.q_in[name], imp.q_out[name] = f"{eid}.Q_in", f"{eid}.Q_out"
            imp.start(eid, "V", float(C) * imp.ic(f"P_c:{name}"), V, store=True)
            continue
        if typ in CLOSED_LOOP_CORONARY:
            closed_loop_coronary(imp, name, typ, vals, imp.two_port("boundary condition", name), heart)
            imp.q_in[name], imp.q_out[name] = f"{eid}.Q_in", f"{eid}.Q_out"
            continue
        ins, outs = imp.inlet.get(name, []), imp.outlet.get(name, [])
        if len(ins) + len(outs) != 1:
            raise model_error(f"boundary condition '{name}': connected to {len(ins) + len(outs)} blocks, needs 1 (a "
                              "boundary condition is the inlet or the outlet of one block)", name, imp.path)
        nd = imp.node(name, outs[0]) if outs else imp.node(ins[0], name)
        if typ == "FLOW":
            q, _ = imp.series(name, vals, "Q", Q, steady)
            imp.add(eid, "FLOW", ["ground", nd] if outs else [nd, "ground"], value=q)
            imp.flow_col[name] = f"Q({eid})"
            imp.pinned_q[nd] = (name, "Q")
        elif typ == "PRESSURE":
            p_, _ = imp.series(name, vals, "P", P, steady)
            imp.add(eid, "PRESSURE", [nd, "ground"], value=p_)
            imp.pinned_p[nd] = (name, "P")
        elif typ == "RESISTANCE":
            pd, _ = imp.series(name, vals, "Pd", P, steady)
            imp.add(eid, "RESISTANCE", [nd, "ground"], R=fmt(imp.value(name, vals, "R"), imp.uR), Pd=pd)
        elif typ == "RCR":
            pd, _ = imp.series(name, vals, "Pd", P, steady) if "Pd" in vals else (fmt(0.0, P), 0.0)
            C = imp.value(name, vals, "C")
            imp.add(eid, "RCR", [nd, "ground"], Rp=fmt(imp.value(name, vals, "Rp"), imp.uR),
                    C=fmt(C, imp.uC), Rd=fmt(imp.value(name, vals, "Rd"), imp.uR), Pd=pd)
            imp.start(eid, "V", float(C) * imp.ic(f"pressure_c:{name}"), V)  # their WindkesselBC's name
        elif typ == "CORONARY":
            pim, _ = imp.series(name, vals, "Pim", P, steady)
            imp.add(eid, "CORONARY", [nd, "ground"],
                    **{k: fmt(imp.value(name, vals, k), imp.uR) for k in ("Ra1", "Ra2", "Rv1")},
                    **{k: fmt(imp.value(name, vals, k), imp.uC) for k in ("Ca", "Cc")},
                    Pim=pim, P_v=fmt(imp.value(name, vals, "P_v"), P))
            coronary_start(imp, name, eid, vals, float(imp.value(name, vals, "Ra2")), ins, outs)
        elif typ == "CORONARY_VAR_RES":
            pim, _ = imp.series(name, vals, "Pim", P, steady)
            imp.add(eid, "CORONARY_VAR_RES", [nd, "ground"],
                    **{k: fmt(imp.value(name, vals, k), imp.uR) for k in ("Ra1", "Ra2_min", "Rv1", "Ra2_max")},
                    **{k: fmt(imp.value(name, vals, k), imp.uC) for k in ("Ca", "Cc")},
                    **{k: fmt(imp.value(name, vals, k), "s") for k in ("T_vc", "T_vr")},
                    Pim=pim, P_v=fmt(imp.value(name, vals, "P_v"), P))
            imp.timed_elements.append(eid)  # Ram(t) uses the model's cardiac period
            coronary_start(imp, name, eid, vals, float(imp.value(name, vals, "Ra2_min")), ins, outs)


def coronary_start(imp, name, eid, vals, Ram0, ins, outs):
    """Physical volumes of an open-loop coronary at their initial condition: their
    volume_im is Cc (P_im - Pim + Pim_0 - P_Cim_0), offset by its value at the start
    (OpenLoopCoronaryBC.cpp setup_initial_state_dependent_params: P_Cim_0 = P_a - Ram Q_am,
    P_a = P_in - Ra1 Q_in, Q_am = Q_in - Ca dP_a/dt with dP_a/dt = 0, Pim_0 = Pim(0))."""
    other = ins[0] if ins else outs[0]
    var = f"{other}:{name}" if ins else f"{name}:{other}"
    p_in, q_in = imp.ic(f"pressure:{var}"), imp.ic(f"flow:{var}")
    Pa = p_in - float(imp.value(name, vals, "Ra1")) * q_in
    pim = vals["Pim"]
    pim0 = float(pim[0] if isinstance(pim, list) else pim)
    Cc, V = float(imp.value(name, vals, "Cc")), imp.u["V"]
    imp.start(eid, "V_a", float(imp.value(name, vals, "Ca")) * Pa, V)
    imp.start(eid, "V_im", imp.ic(f"volume_im:{name}") + Cc * ((Pa - Ram0 * q_in) - pim0), V)


def chamber_sphere(imp, name, vals, nodes):
    """A ChamberSphere: parameters in this unit system's pressure, length and time (their
    case is SI read as numbers: any consistent system gives the same numbers); their
    internal variables radius, velo, stress, tau, volume as output columns with the factors
    from ours (cm, mmHg, mL)."""
    from hemocircuit.components.svzerod.chamber_sphere import PARAMS

    P, Lu, V = imp.u["P"], imp.u["L"], imp.u["V"]
    ours = {"mmHg*s**2/cm**2": f"({P})*s**2/({Lu})**2", "cm": Lu, "mmHg": P, "mmHg*s": f"({P})*s",
            "1/s": "1/s", "s": "s"}
    imp.only_keys(name, vals, tuple(k for k in PARAMS if k != "period"))
    eid = imp.id_of(name)
    kw = {k: fmt(imp.value(name, vals, k), ours[u]) for k, (u, _, _) in PARAMS.items() if k != "period"}
    imp.add(eid, "ChamberSphere", [nodes[0], nodes[1], "ground"], **kw)
    imp.timed_elements.append(eid)
    for their, ours_, unit, mine, state in (
            ("radius", f"{eid}.r", Lu, "cm", "r"), ("velo", f"{eid}.v", f"({Lu})/s", "cm/s", "v"),
            ("tau", f"{eid}.tau", P, "mmHg", "tau"), ("volume", f"V({eid})", V, "mL", "V"),
            ("stress", f"{eid}.S", P, "mmHg", None)):
        imp.extra_columns[f"{their}:{name}"] = (ours_, parse_quantity(f"1 {mine}", unit))
        if state is not None:
            imp.start(eid, state, imp.ic(f"{their}:{name}"), unit, store=state == "V")


def closed_loop_coronary(imp, name, typ, vals, nodes, heart):
    """A ClosedLoopCoronaryLeft/Right: a ``closed_loop_coronary`` whose intramyocardial
    pressure follows the heart's ventricle through expressions of the heart's parameters
    and of its state-only observable V_LV / V_RV."""
    if heart is None:
        raise model_error(f"boundary condition '{name}': {typ} needs a ClosedLoopHeartAndPulmonary block in "
                          "'closed_loop_blocks' (it reads the ventricular pressure of block CLH)", name, imp.path)
    imp.only_keys(name, vals, ("Ra", "Ram", "Rv", "Ca", "Cim"))
    im, E, Vu, Vv = CORONARY_SIDE[typ]
    h = imp.ids.get(HEART) or ident(HEART)
    eid = imp.ids[name]
    Ra, Ca = float(imp.value(name, vals, "Ra")), float(imp.value(name, vals, "Ca"))
    imp.add(eid, typ, [nodes[0], nodes[1], "ground"],
            **{k: fmt(imp.value(name, vals, k), imp.uR) for k in ("Ra", "Ram", "Rv")},
            **{k: fmt(imp.value(name, vals, k), imp.uC) for k in ("Ca", "Cim")},
            im=f"= {h}.{im}", E_s=f"= {h}.{E}", V_u=f"= {h}.{Vu}", V_vent=f"= {h}.{Vv}",
            period=f"= {h}.period")
    up = imp.inlet[name][0]
    p_in, q_in = imp.ic(f"pressure:{up}:{name}"), imp.ic(f"flow:{up}:{name}")
    imp.start(eid, "V_a", Ca * (p_in - Ra * q_in), imp.u["V"], store=True)
    imp.start(eid, "V_im", imp.ic(f"volume_im:{name}"), imp.u["V"], store=True)


def activation(imp, name, af):
    """Their activation_function mapping -> the chamber's option and parameters."""
    from hemocircuit.components.svzerod.activation import ACT_PARAMS, KINDS, USED

    if not isinstance(af, dict) or not isinstance(af.get("type"), str):
        raise model_error(f"chamber '{name}': needs 'activation_function' with a 'type' ({', '.join(KINDS)})",
                          name, imp.path)
    kind = af["type"]
    if kind not in KINDS:
        raise model_error(f"chamber '{name}': activation function {show(kind)} is not supported"
                          f"{did_you_mean(kind, KINDS)} (supported: {', '.join(KINDS)})", name, imp.path)
    unknown = sorted(str(k) for k in af if k != "type" and not str(k).startswith("_") and k not in USED[kind])
    if unknown:
        raise model_error(f"chamber '{name}': unknown parameter(s) {shown_keys(unknown)} for activation {kind}"
                          f"{did_you_mean(unknown[0], USED[kind])} (it takes {', '.join(USED[kind]) or 'none'})",
                          name, imp.path)
    units = dict(ACT_PARAMS)
    out = {"activation": kind}
    for k in USED[kind]:
        v = imp.value(name, af, k)
        out[k] = fmt(v, "s") if units[k] == "s" else float(v)
    return out


def heart_values(imp, prm):
    """Their ClosedLoopHeartAndPulmonary parameters with units of this unit system."""
    from hemocircuit.components.svzerod.closed_loop_heart_pulmonary import PARAMS

    P, V = imp.u["P"], imp.u["V"]
    ours = {"mmHg*s/mL": imp.uR, "mmHg*s**2/mL": imp.uL, "mL/mmHg": imp.uC, "mmHg/mL": imp.uE,
            "mmHg": P, "mL": V, "1/mL": f"1/({V})"}
    out = {}
    for k, (unit, _) in PARAMS.items():
        if k == "period":
            continue
        v = imp.value(HEART, prm, k)
        out[k] = float(v) if unit == "dimensionless" else fmt(v, ours[unit])
    unknown = sorted(str(k) for k in prm if not str(k).startswith("_") and k not in PARAMS)
    if unknown:
        raise model_error(f"ClosedLoopHeartAndPulmonary: unknown parameter(s) {shown_keys(unknown)}"
                          f"{did_you_mean(unknown[0], PARAMS)}", HEART, imp.path)
    return out
