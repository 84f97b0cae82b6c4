"""The arteriole element's kernel functions called the way the tests of its physics need them."""
import numpy as np


MMHG = 133.322387415   # Pa per mmHg


def _element_call(art, x, P, dP, params, options, hook):
    """The element's kernel functions through its hooks at intramural pressure P and drop dP
    [Pa] (gauge: local pressures P +- dP/2 [mmHg], ref 0), states x (dict or array), all
    broadcast together."""
    opts = dict(options or {})
    el = art.Arteriole({k: opts[k] for k in ("ca_order", "kinetics", "passive") if k in opts})
    names = art.state_names(opts)
    x = np.asarray(art.pack(x, opts) if isinstance(x, dict) else x, dtype=float)
    shape = np.broadcast_shapes(x.shape[:-1], np.shape(P), np.shape(dP), *(np.shape(v) for v in params.values()))
    X = np.broadcast_to(x, shape + (len(names),)).reshape(1, -1, len(names))
    P, dP = np.broadcast_to(P, shape).reshape(-1) / MMHG, np.broadcast_to(dP, shape).reshape(-1) / MMHG
    U = np.stack([P + 0.5 * dP, P - 0.5 * dP, np.zeros_like(P)], axis=-1)[None]
    p = {k: np.broadcast_to(np.asarray(params[k], dtype=float), shape).reshape(1, -1) for k in el.parameters}
    if hook == "derivatives":
        d = el.derivatives(p, X, U, 0.0)[0]
        return {n: d[:, i].reshape(shape) for i, n in enumerate(names)}
    return {n: v[0].reshape(shape) for n, v in el.observe(p, X, U, 0.0).items()}


def rates(art, x, P, dP, params, options=None):
    """{state: d/dt} of the element (the kernel's derivs), shapes broadcast."""
    return _element_call(art, x, P, dP, params, options, "derivatives")


def observed(art, x, P, dP, params, options=None):
    """{observable: value} of the element (the kernel's report, circuit units: r in um, Q and
    q_out in mL/s for the bed, R in mmHg*s/mL, V in mL, the rest SI)."""
    return _element_call(art, x, P, dP, params, options, "observe")
