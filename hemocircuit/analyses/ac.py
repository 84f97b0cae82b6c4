"""Small-signal AC analysis: transfer functions from a source to any outputs.

Linearise at the operating point (``linearize``: central differences on the steady variant,
conservation laws projected out) and evaluate

    H(j w) = C (j w I - A)^-1 B + D,        w = 2 pi f,

for every frequency with one batched complex solve (thousands of frequencies in milliseconds).
The input is a source's drive parameter (``--input Pa`` means ``Pa.value`` for a pressure
source; any ``ID.PARAM`` is accepted), so H is in output unit per input unit, e.g. mL/s per
mmHg.  Without ``input`` / ``outputs`` the netlist's ``input:`` and ``outputs:`` (use ``ac``)
apply (see :mod:`hemocircuit.outputs`).

Reported per output:
  gain       |H|                                   [output unit / input unit]
  rel_gain   |H| * |p0 / y0| = |(dy/y0)/(dp/p0)|   [1]  (y0, p0 at the operating point)
  phase      arg H in degrees, positive when the output *leads* the input; unwrapped along
             frequency, with the lowest frequency's value in (-180, 180]
  H          the complex transfer function itself
"""
from __future__ import annotations

import re
import sys

import numpy as np

from ..errors import HemocircuitError, NetlistError
from ..units import UnitError, parse_quantity
from .linearize import linearize
from ..io import pyplot, save_figure
from ..provenance import clock, stamp
from ..results import Result


def parse_freqs(spec, per_decade=20):
    """Frequencies [Hz] from 'F1:F2 Hz' (log-spaced, ``per_decade`` points per decade, both
    ends included), 'F1:F2:STEP Hz' (linear) or a list '0.01,0.1,1 Hz'."""
    if not isinstance(spec, str):
        return np.atleast_1d(np.asarray(spec, dtype=float))
    text = re.sub(r"(\d)(?![eE][-+]?\d)([A-Za-z])", r"\1 \2", spec.strip(), count=1)  # '1e-3' stays whole
    parts = text.split(None, 1)
    body, unit = parts[0], (parts[1] if len(parts) > 1 else "Hz")
    try:
        if re.match(r"^[-+0-9.eE]+:[-+0-9.eE]+$", body):
            a, b = (parse_quantity(f"{v} {unit}", "Hz", "frequency") for v in body.split(":"))
            if not (0 < a < b):
                raise NetlistError(f"frequency range {spec!r}: need 0 < start < stop for log spacing")
            n = max(int(round(np.log10(b / a) * per_decade)), 1) + 1
            return np.logspace(np.log10(a), np.log10(b), n)
        from .dc import parse_range
        return parse_range(text if len(parts) > 1 else f"{body} {unit}", "Hz")
    except UnitError as exc:
        raise NetlistError(f"frequencies {spec!r}: {exc}") from None


def transfer(A, B, C, D, s):
    """H(s) = C (s I - A)^-1 B + D for the complex frequencies s (F,).

    A (..., n, n), B (..., n), C (..., ny, n), D (..., ny) -> H (..., ny, F).
    Solved as one batched complex linear system; a singular s I - A (s = 0 with an integrator)
    gives NaN at that frequency.
    """
    A = np.asarray(A, dtype=float)
    n = A.shape[-1]
    s = np.asarray(s, dtype=complex).reshape(-1)
    lead = A.shape[:-2]
    M = s[:, None, None] * np.eye(n) - A[..., None, :, :]  # (..., F, n, n)
    rhs = np.broadcast_to(np.asarray(B, dtype=complex)[..., None, :, None], M.shape[:-1] + (1,))
    try:
        X = np.linalg.solve(M, rhs)[..., 0]  # (..., F, n)
    except np.linalg.LinAlgError:
        X = np.full(M.shape[:-1], np.nan, dtype=complex)
        flat_M = M.reshape(-1, n, n)
        flat_r = rhs.reshape(-1, n)
        out = X.reshape(-1, n)
        for k in range(flat_M.shape[0]):
            try:
                out[k] = np.linalg.solve(flat_M[k], flat_r[k])
            except np.linalg.LinAlgError:
                pass
        X = out.reshape(M.shape[:-1])
    H = np.einsum("...yn,...fn->...yf", np.asarray(C, dtype=float), X) + np.asarray(D, dtype=float)[..., None]
    return H.reshape(lead + H.shape[-2:])


def unwrapped_phase(H):
    """arg H [deg] along the last axis, unwrapped, first value in (-180, 180]."""
    ph = np.unwrap(np.angle(H), axis=-1)
    first = ph[..., :1]
    shift = -2 * np.pi * np.ceil((first - np.pi) / (2 * np.pi))
    return np.degrees(ph + shift)


class ACResult(Result):
    """Result of :func:`ac_response`: a :class:`hemocircuit.results.Result` indexed by
    ``frequency`` [Hz], per output ``o`` and input ``p`` the columns ``gain(o/p)`` [output
    unit/input unit], ``rel_gain(o/p)`` [1], ``phase(o/p)`` [deg], ``re_H(o/p)``,
    ``im_H(o/p)`` [output unit/input unit].

    Attributes as arrays (F,) (or (B, F) for a batch circuit, whose table holds member 0):
    freq [Hz]; per output name: H[name] complex, gain[name], rel_gain[name], phase[name];
    y0[name] the operating-point value; p0 the input's value; input_unit, output_units; the
    linearisation ``lin``, operating point ``op``, ``eigenvalues`` and ``stable``.
    """

    def __init__(self, freq, input, p0, outputs, H, y0, units, lin, op):
        self.freq = freq
        self.input = input
        self.p0 = p0
        self.outputs = list(outputs)
        self.H = {n: H[..., k, :] for k, n in enumerate(outputs)}
        self.y0 = {n: y0[..., k] for k, n in enumerate(outputs)}
        self.gain = {n: np.abs(h) for n, h in self.H.items()}
        with np.errstate(divide="ignore", invalid="ignore"):
            # undefined (NaN) where the input or the output is 0 at the operating point (a flow
            # source whose mean is 0): there is no relative change to compare
            self.rel_gain = {n: np.where((np.asarray(p0) != 0)[..., None] & (np.asarray(self.y0[n]) != 0)[..., None],
                                         np.abs(h) * np.abs(np.asarray(p0)[..., None] / np.asarray(self.y0[n])[..., None]),
                                         np.nan)
                             for n, h in self.H.items()}
        self.phase = {n: unwrapped_phase(h) for n, h in self.H.items()}
        self.input_unit = units.get("input", "")
        self.output_units = {n: units.get(n, "") for n in self.outputs}
        self.lin = lin
        self.op = op
        # an unstable equilibrium still has a (formal) transfer function, but no periodic
        # steady state to measure it in: flag it
        lam = np.linalg.eigvals(lin.A_red)  # (n,) or (B, n)
        self.eigenvalues = lam
        self.stable = bool(np.all(lam.real < 1e-9 * np.max(np.abs(lam), initial=1e-300)))
        cols, cunits = {"frequency": np.asarray(freq, dtype=float)}, {"frequency": "Hz"}
        first = (lambda a: np.atleast_2d(a)[0])  # a batch's table holds its first member
        for n in self.outputs:
            u = f"{self.output_units[n]}/{self.input_unit}" if self.input_unit else self.output_units[n]
            for name, arr, unit in ((f"gain({n}/{input})", self.gain[n], u),
                                    (f"rel_gain({n}/{input})", self.rel_gain[n], "1"),
                                    (f"phase({n}/{input})", self.phase[n], "deg"),
                                    (f"re_H({n}/{input})", self.H[n].real, u),
                                    (f"im_H({n}/{input})", self.H[n].imag, u)):
                cols[name], cunits[name] = first(arr), unit
        super().__init__(cols, cunits, index=["frequency"])
        self.metadata["measures"] = {"input_value": float(np.atleast_1d(p0)[0]), "stable": self.stable,
                                     **{f"operating_point({n})": float(np.atleast_1d(self.y0[n])[0])
                                        for n in self.outputs}}


def ac_response(circuit, input=None, outputs=None, freqs="0.001:10 Hz", per_decade=20,
                t=0.0, op=None, x=None) -> ACResult:
    """Small-signal transfer functions from ``input`` to each of ``outputs``.

    circuit: a Circuit (or a batch circuit: arrays gain a leading batch axis).
    input:   source id (its drive parameter, e.g. 'Pa' -> 'Pa.value') or 'ID.PARAM'; default:
             the netlist's ``input:`` (:func:`hemocircuit.outputs.default_input`).
    outputs: output columns or derived names; default: the netlist's ``outputs:`` for 'ac'.
    freqs:   array [Hz] or a spec string (:func:`parse_freqs`).
    op / x:  the operating point to linearise about (computed when omitted).
    """
    from ..outputs import default_input, default_outputs
    from .op import operating_point

    started = clock()
    if input is None:
        input = default_input(circuit)
    if outputs is None:
        outputs = default_outputs(circuit, "ac")
    f = parse_freqs(freqs, per_decade)
    if np.any(f < 0):
        raise HemocircuitError("frequencies must be >= 0")
    outputs = [outputs] if isinstance(outputs, str) else list(outputs)
    if not outputs:
        raise HemocircuitError("ac_response needs at least one output")
    if x is None:
        op = op or operating_point(circuit, t)
        x = op.x
    lin = linearize(circuit, x, input=input, outputs=outputs, t=t)
    H = transfer(lin.A_red, lin.B_red, lin.C_red, lin.D, 2j * np.pi * f)
    units = dict(circuit.column_units())
    derived = circuit.netlist.derived or {}
    for n in outputs:
        if n not in units and n in derived:
            units[n] = str(derived[n].get("unit", ""))
    units["input"] = circuit.param_unit(lin.input)
    res = ACResult(f, lin.input, lin.p0, outputs, H, lin.y0, units, lin, op)
    return stamp(res, "ac", circuit, {"input": lin.input, "outputs": outputs, "freqs": freqs if isinstance(freqs, str)
                                      else None, "per_decade": per_decade, "t": t, "linearisation": "central differences"},
                 started)


# ------------------------------------------------------------------------------ plots -----
def plot_result(res, path, select=None, title=None):
    """Bode plot from a result's columns (fresh or reloaded): relative gain (log-log) and phase
    (deg, leading positive) against frequency, one line per output and grid member."""
    plt = pyplot()

    f = res["frequency"]
    names = [k[len("rel_gain("):-1] for k in res.keys() if k.startswith("rel_gain(")]
    if select:
        names = [n for n in names if n.split("/")[0] in select] or names
    from ..labels import members
    groups = members(res, [k for k in res.index if k != "frequency"])
    # the relative gain where every output has one; else |H| with its unit (an input or output
    # that is 0 at the operating point has no relative change)
    relative = all(np.isfinite(np.asarray(res[f"rel_gain({n})"], dtype=float)).any() for n in names)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
    for j, n in enumerate(names):
        for g, (glab, mask) in enumerate(groups):
            f = np.asarray(res["frequency"][mask], dtype=float)
            gain = np.asarray(res[f"gain({n})"][mask], dtype=float)
            lab = n.split("/")[0] + (f" ({glab})" if glab else
                                     f" (|H| at {f[0]:.3g} Hz: {gain[0]:.3g} {res.units[f'gain({n})']})")
            color = f"C{(g if len(groups) > 1 else j) % 10}"
            style = ["-", "--", ":", "-."][(j if len(groups) > 1 else 0) % 4]
            if relative:
                ax1.loglog(f, res[f"rel_gain({n})"][mask], style, color=color, label=lab)
            else:
                ax1.loglog(f, gain, style, color=color, label=lab)
            ax2.semilogx(f, res[f"phase({n})"][mask], style, color=color, label=lab)
    gain_units = {res.units[f"gain({n})"] for n in names}
    ax1.set_ylabel("relative gain (dy/y0)/(dp/p0) [1]" if relative else
                   f"gain |H| [{gain_units.pop()}]" if len(gain_units) == 1 else "gain |H| (units in the legend)")
    ax1.grid(alpha=0.3, which="both")
    ax1.legend(fontsize=8)
    ax2.axhline(0, color="k", lw=0.6)
    ax2.set_ylabel("phase [deg] (+ = output leads)")
    ax2.set_xlabel("frequency [Hz]")
    ax2.grid(alpha=0.3, which="both")
    ax1.set_title(title or res.figure_title())
    save_figure(fig, path)
    return str(path)


# ------------------------------------------------------------------------------ CLI -------
def _ac(args, c):
    return ac_response(c, input=args.input, outputs=args.output or None, freqs=args.freq, per_decade=args.per_decade)


def compute_ac(args, sets):
    """One --grid member (:func:`hemocircuit.commands.computed`)."""
    from ..commands import circuit_of_args
    return _ac(args, circuit_of_args(args, sets)[0])


def cmd_ac(args):
    from ..commands import computed, load_args, report_grid, save_outputs

    if args.grid:
        res = computed(args, compute_ac)
        show = [k for k in res.keys() if k.startswith(("rel_gain(", "phase("))]
        return report_grid(args, res, show)
    res = _ac(args, load_args(args)[0])
    outputs = res.outputs
    print(f"AC: {res.input} = {res.p0:.6g} {res.input_unit} -> {', '.join(outputs)}; "
          f"{len(res.freq)} frequencies {res.freq[0]:.4g}..{res.freq[-1]:.4g} Hz")
    sys.stdout.flush()
    if not res.stable:
        lam = res.eigenvalues.reshape(-1)
        k = int(np.argmax(lam.real))
        print(f"warning: the operating point is unstable (eigenvalue {lam[k].real:+.4g}{lam[k].imag:+.4g}j /s); "
              "the transfer function is formal (no periodic steady state to observe it in)", file=sys.stderr)
    relative = {n: bool(np.isfinite(res.rel_gain[n]).any()) for n in outputs}
    for n in outputs:
        u = res.output_units[n]
        g = res.rel_gain[n] if relative[n] else res.gain[n]
        k = int(np.nanargmax(g))
        rel = (f"relative {g[0]:.4g}" if relative[n] else
               f"no relative gain: {'the input' if res.p0 == 0 else 'the output'} is 0 at the operating point")
        print(f"  {n}: operating point {res.y0[n]:.6g} {u}; "
              f"gain at {res.freq[0]:.4g} Hz {res.gain[n][0]:.6g} {u}/{res.input_unit} "
              f"({rel}, phase {res.phase[n][0]:+.2f} deg); "
              f"{'relative-' if relative[n] else ''}gain peak {g[k]:.4g} at {res.freq[k]:.4g} Hz")
    if not args.quiet:
        show = [k for n in outputs for k in (f"{'rel_gain' if relative[n] else 'gain'}({n}/{res.input})",
                                             f"phase({n}/{res.input})")]
        print(res.summary(show=show, max_rows=0, where=args.out))
    save_outputs(args, res)


def register_cli(sub, common):
    sp = common(sub.add_parser("ac", help="small-signal transfer functions (Bode) at the operating point"))
    sp.add_argument("--input", help="source id (its drive parameter) or ID.PARAM "
                                    "(default: the netlist's 'input:', or its only source)")
    sp.add_argument("--output", action="append",
                    help="output column or derived name (repeatable; default: the netlist's 'outputs:')")
    sp.add_argument("--freq", default="0.001:10Hz",
                    help="F1:F2 UNIT (log-spaced), F1:F2:STEP UNIT (linear) or a list (default 0.001:10Hz)")
    sp.add_argument("--per-decade", type=int, default=20, help="points per decade for F1:F2 (default 20)")
    sp.set_defaults(func=cmd_ac)
