"""Weighted least squares for a :class:`~hemocircuit.fitting.problem.FitProblem`.

* Optimiser: ``scipy.optimize.least_squares``, trust-region reflective ('trf') with the
  parameter bounds.  It works in u in [0, 1]^p: the bounds of z mapped onto [0, 1], with
  z = log10(p) for log-scaled parameters and z = p otherwise.
* Jacobian: forward differences with the step rule of ``hemocircuit.derivatives.fd_steps``
  (scale 1 in u, i.e. the bound width).  All p
  perturbed parameter sets are ONE batched model evaluation (the circuit is a batch).
  A step that would leave the bounds is taken backwards.  Through a transient the residual is
  only as accurate as the integrator, so the relative step is sqrt(rtol) there.
* Multi-start: a Latin hypercube of the bounds in z (scipy.stats.qmc, seeded), plus the start
  values; the starts run in parallel processes (``hemocircuit.execution.run_chunks``).
* Uncertainty at the optimum: covariance s^2 (J^T J)^-1 with J = d residual / d p in the
  declared units and s^2 = SSR / (m - p), the residual variance; standard errors, correlation
  matrix.  A linear model gives exactly the linear-regression standard errors.
"""
from __future__ import annotations

import time
import warnings

import numpy as np

from ..derivatives import FD_REL, fd_steps
from .experiments import TransientExperiment

LN10 = np.log(10.0)


class Space:
    """The optimiser's coordinates of a problem's parameters p: z = log10(p) for log-scaled
    parameters, z = p otherwise, mapped onto u = (z - z_lower) / (z_upper - z_lower) in [0, 1]
    so that every coordinate has the same scale (the bounds of a cell length in m and of an
    exponent differ by 10^5)."""

    def __init__(self, problem):
        self.log = problem.log
        lo, hi = problem.bounds
        self.z_lower, self.z_upper = self._z(lo), self._z(hi)
        self.width = self.z_upper - self.z_lower
        self.lower, self.upper = np.zeros(len(lo)), np.ones(len(lo))
        rel = [np.sqrt(d.experiment.rtol) for d in problem.datasets if isinstance(d.experiment, TransientExperiment)]
        self.rel = max([FD_REL] + rel)

    def _z(self, P):
        P = np.asarray(P, float)
        return np.where(self.log, np.log10(np.where(self.log, P, 1.0)), P)

    def to_z(self, P):
        """u of parameter values P (declared units)."""
        return (self._z(P) - self.z_lower) / self.width

    def to_p(self, U):
        Z = self.z_lower + np.asarray(U, float) * self.width
        return np.where(self.log, 10.0 ** np.where(self.log, Z, 0.0), Z)

    def dz_dp(self, P):
        """du/dp at P."""
        return np.where(self.log, 1.0 / (np.asarray(P, float) * LN10), 1.0) / self.width

    def steps(self, u):
        """Per-parameter finite-difference steps (backwards where u + h would leave the bounds):
        the rule of derivatives.fd_steps with scale 1 (the bound width)."""
        h = fd_steps(u, np.ones_like(u), self.rel)
        return np.where(u + h > self.upper, -h, h)


def residual_and_jacobian(problem, space, z, f0=None):
    """(f (m,), J_z (m, p)): residuals at z and their z-derivatives, the p perturbed sets
    (and, if f0 is None, z itself) evaluated as ONE batch."""
    z = np.asarray(z, float)
    p = len(z)
    h = space.steps(z)
    Z = np.repeat(z[None, :], p + (f0 is None), axis=0)
    k0 = 1 if f0 is None else 0
    Z[np.arange(p) + k0, np.arange(p)] += h
    R = problem.residuals(problem.values_from_array(space.to_p(Z)))
    f = R[0] if f0 is None else np.asarray(f0, float)
    J = (R[k0:] - f[None, :]) / h[:, None]
    return f, np.where(np.isfinite(J), J, 0.0).T


def latin_starts(space, n, seed):
    """n Latin-hypercube points in z, seeded."""
    from scipy.stats import qmc
    if n <= 0:
        return np.zeros((0, len(space.lower)))
    u = qmc.LatinHypercube(d=len(space.lower), seed=seed).random(n)
    return qmc.scale(u, space.lower, space.upper)


def run_start(problem, z0, settings):
    """One least-squares run from u0 = z0.  Returns a dict (z0, z (final u), cost, nfev, njev,
    status, message, seconds); cost = SSR / 2 (scipy's convention) or inf if the start failed.

    settings['bounds'] = 'transform' (default): trf without bounds on w, u = (1 + sin w)/2,
    so u stays in [0, 1] and the bounds hold; 'reflective': trf with the bounds directly.
    Measured on the kuo91 passive stage (4 parameters, exact data): 'transform' converges in 6
    evaluations to 1e-6, 'reflective' is at 0.3 % after 100 (its scaling by the distance to
    the bounds shortens every step, even with bounds far from the path)."""
    from scipy.optimize import least_squares

    space = Space(problem)
    u0 = np.clip(np.asarray(z0, float), space.lower, space.upper)
    transform = settings.get("bounds", "transform") == "transform"
    cache = {}

    def to_u(w):
        return 0.5 * (1.0 + np.sin(w)) if transform else w

    def fun(w):
        u = to_u(w)
        f = problem.residuals(problem.values_from_array(space.to_p(u)))[0]
        cache["u"], cache["f"] = np.array(u), f
        return f

    def jac(w):
        u = to_u(w)
        f0 = cache["f"] if "u" in cache and np.array_equal(cache["u"], u) else None
        J = residual_and_jacobian(problem, space, u, f0)[1]
        return J * (0.5 * np.cos(w))[None, :] if transform else J

    t0 = time.perf_counter()
    try:
        w0 = np.arcsin(np.clip(2.0 * u0 - 1.0, -1 + 1e-12, 1 - 1e-12)) if transform else u0
        f0 = fun(w0)
        if not np.all(np.isfinite(f0)):
            raise ValueError("the model failed at the start point")
        kw = {} if transform else {"bounds": (space.lower, space.upper)}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            res = least_squares(fun, w0, jac=jac, method="trf", max_nfev=settings["max_nfev"],
                                ftol=settings["ftol"], xtol=settings["xtol"], gtol=settings["gtol"], **kw)
        out = {"z0": u0, "z": np.clip(to_u(res.x), 0.0, 1.0), "cost": float(res.cost), "nfev": int(res.nfev),
               "njev": int(res.njev or 0), "status": int(res.status), "message": str(res.message)}
    except (ValueError, np.linalg.LinAlgError) as exc:
        out = {"z0": u0, "z": u0, "cost": np.inf, "nfev": 0, "njev": 0, "status": -1, "message": str(exc)}
    out["seconds"] = time.perf_counter() - t0
    return out


_WORKER = {}  # the problem handed to forked worker processes (see run_starts)


def _run_chunk(chunk):
    problem, settings = _WORKER["problem"], _WORKER["settings"]
    return [(i, run_start(problem, z0, settings)) for i, z0 in chunk]


def run_starts(problem, Z0, settings, workers=None, progress=False):
    """run_start for every row of Z0, in parallel processes (forked: they inherit the problem).
    Returns the results in the order of Z0."""
    from ..execution import default_workers, run_chunks, split

    items = list(enumerate(np.asarray(Z0, float)))
    workers = max(1, min(workers or settings.get("workers") or default_workers(), len(items)))  # no idle workers
    _WORKER.update(problem=problem, settings=settings)
    try:
        chunks = split(items, workers)
        results = run_chunks(_run_chunk, chunks, workers=workers, progress=progress, desc="starts")
    finally:
        _WORKER.clear()
    out = [None] * len(items)
    for part in results:
        for i, r in part:
            out[i] = r
    return out


def uncertainty(problem, space, u):
    """Standard errors, correlation matrix and diagnostics at u (declared units).

    cov = s^2 (J^T J)^-1 with J = d residual / d p, computed through the well-scaled u
    coordinates (J_u = J dp/du; cov_p = D cov_u D, D = diag(dp/du)) with a pseudo-inverse.  A
    parameter with weight on a direction that the data do not determine (singular value of
    J_u below 1e-8 of the largest) gets an infinite standard error: it is not identifiable.

    Returns a dict: p, se, corr, cov, dof, s2 (residual variance), ssr, cond (condition number
    of J_u^T J_u), unidentifiable (bool per parameter), f (residuals), J (m x p)."""
    f, Ju = residual_and_jacobian(problem, space, u)
    P = space.to_p(u)
    dudp = space.dz_dp(P)
    J = Ju * dudp[None, :]
    m, p = J.shape
    ssr = float(np.sum(f ** 2))
    dof = m - p
    s2 = ssr / dof if dof > 0 else np.nan
    _, sv, Vt = np.linalg.svd(Ju, full_matrices=False)
    small = sv < 1e-8 * sv[0] if sv.size and sv[0] > 0 else np.ones(p, bool)
    unident = np.any(np.abs(Vt[small]) > 1e-3, axis=0) if small.any() else np.zeros(p, bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        cond = float((sv[0] / sv[-1]) ** 2) if sv.size and sv[-1] > 0 else np.inf
        cov_u = np.linalg.pinv(Ju.T @ Ju, rcond=1e-16) * s2
        D = 1.0 / dudp
        cov = cov_u * np.outer(D, D)
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        se = np.where(unident, np.inf, se)
        corr = cov / np.outer(np.sqrt(np.diag(cov)), np.sqrt(np.diag(cov)))
    return {"p": P, "se": se, "corr": corr, "cov": cov, "dof": dof, "s2": s2, "ssr": ssr, "cond": cond,
            "unidentifiable": unident, "f": f, "J": J}


def on_bounds(space, z, tol=1e-3):
    """'lower' / 'upper' / '' per parameter: within tol of the bound width (in z) of a bound.
    The thesis warns that an optimum resting on a bound is suspect."""
    w = space.upper - space.lower
    return ["lower" if zi - lo <= tol * wi else "upper" if hi - zi <= tol * wi else ""
            for zi, lo, hi, wi in zip(z, space.lower, space.upper, w)]


def fit_problem(problem, settings=None, workers=None, progress=False):
    """Multi-start weighted least squares.  Returns a dict with 'starts' (every run),
    'best' (its index), 'z', 'p', the uncertainty at the best point, 'bounds_hit', 'rms'
    (per dataset), 'predictions' and 'seconds'."""
    from .spec import check_settings

    given = {k: v for k, v in (settings or {}).items() if v is not None}
    settings = check_settings({**problem.spec.settings, **given}, problem.spec.file,
                              {k: f"--{k.replace('_', '-')}" for k in given})
    space = Space(problem)
    t0 = time.perf_counter()
    Z0 = latin_starts(space, settings["starts"], settings["seed"])
    if settings["start_current"]:
        Z0 = np.vstack([np.clip(space.to_z(problem.start), space.lower, space.upper)[None, :], Z0])
    starts = run_starts(problem, Z0, settings, workers=workers, progress=progress)
    best = int(np.argmin([s["cost"] for s in starts]))
    if not np.isfinite(starts[best]["cost"]):
        from ..errors import SolverError
        raise SolverError("every start failed: " + "; ".join(s["message"] for s in starts[:3]),
                          where=f"fitting {problem.spec.file}")
    z = starts[best]["z"]
    unc = uncertainty(problem, space, z)
    values = problem.values_from_array(unc["p"])
    preds = problem.predict(values)
    return {"settings": settings, "starts": starts, "best": best, "z": z, "p": unc["p"], **unc,
            "bounds_hit": on_bounds(space, z), "rms": problem.rms_of(preds)[0],
            "rms_error": float(problem.rms_of(preds)[0].sum()), "predictions": [q[0] for q in preds],
            "targets": [t[0] for t in problem.targets(preds)], "tied": {k: float(v[0]) for k, v in
                                                                       problem.tied_values(values).items()},
            "seconds": time.perf_counter() - t0}
