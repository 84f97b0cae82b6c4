"""Rosenbrock(-W) tableaus for the compiled integrator, packed into one named tuple.

The methods are written in the classical form (Hairer & Wanner II, IV.7):
W = I - gamma h J and, for stages s = 1..ns,

    W k_s = h f(t + c_s h, x + sum_j A_sj k_j) + h J sum_j G_sj k_j + h^2 d_s f_t,
    x_new = x + sum_s b_s k_s,   error estimate = sum_s e_s k_s  (e = b - embedded b).

The engine (engine_rosenbrock.integrate_batch) runs them in the transformed form of Hairer &
Wanner II (7.21) (as rodas.f does), on the stages u_s = sum_j Gamma_sj k_j (Gamma = G + gamma I),
with no product of J and a vector:

    W u_s = gamma h f(t + c_s h, x + sum_j a_sj u_j) + gamma sum_j C_sj u_j + gamma h^2 d_s f_t,
    x_new = x + sum_s m_s u_s,   error estimate = sum_s m_err_s u_s,

a = A Gamma^-1, C = diag(1/gamma) - Gamma^-1 (below its diagonal), m = b Gamma^-1,
m_err = e Gamma^-1 (:func:`transformed`).

Methods (coefficients copied from the sources named; ``_from_transformed`` converts the
transformed form u_i = sum_j Gamma_ij k_j of RODAS-type codes back to the classical one):

``ros34pw2``  Rang & Angermann 2005 (BIT 45:761), 4 stages (3 evaluations), order 3(2),
              L-stable, stiffly accurate, a W-method (order kept with an approximate Jacobian).
``ros34pw3``  same paper, order 4 with an exact Jacobian (3 as a W-method), A-stable
              (R(inf) = 0.63); its embedded solution is order 2 (measured), so q = 3.
``rodas4``    Hairer & Wanner's RODAS (coefficients of rodas.f, as in OrdinaryDiffEq.jl's
              Rodas4Tableau), 6 stages (5 evaluations), order 4(3), L-stable, stiffly accurate.
``rodas5p``   Steinebach 2023 (BIT 63:27, OrdinaryDiffEq.jl's Rodas5PTableau), 8 stages
              (7 evaluations), order 5(4), stiffly accurate.
RODAS-type methods assume a fairly exact Jacobian: the engine refreshes it every step for them
(``jac_reuse`` = 1; reusing it over 2 or 3 steps doubled the step count of the vasomotion run).

Dense output: where the method has one (``rodas5p``: Steinebach's, as in OrdinaryDiffEq.jl's
Rodas5PTableau h21..h48, order 4), x(t + theta h) =
(1 - theta) x + theta (x_new + (1 - theta) (D_1 + theta (D_2 + theta D_3))) with
D_m = sum_s H_ms k_s; the others use the cubic Hermite interpolant of (x, f) at both ends
(order 3), which limits a large step's accuracy between its ends.

Packed (what the engine reads, :class:`RosenbrockMethod`, by field name): the number of stages
ns, gamma, q the order of the error estimate (step-size exponent 1/q), the options
(jac_reuse, event_restart, soft_kinks, autonomous, local_jacobian, controller, land_releases:
:func:`packed`)
and the transformed coefficients a, C (ns, ns), m, m_err, c, d, reuse (ns,) -- reuse[s] = 1
when stage s evaluates f at the same point as stage s-1 (ROS4-type methods; the engine then
skips the evaluation) -- and H (nd, ns) over the transformed stages, nd the number of
dense-output rows (0: Hermite; at most 3).
Every field has the same type for every method and option (ints, floats, float64 arrays), so
one compiled integrator serves them all.
"""
from __future__ import annotations

import functools
from collections import namedtuple

import numpy as np

#: A method as the compiled integrator reads it (module docstring): ints, floats and read-only
#: C-contiguous float64 arrays
RosenbrockMethod = namedtuple("RosenbrockMethod", (
    "stages", "gamma", "q", "jac_reuse", "event_restart", "soft_kinks", "autonomous", "local_jacobian",
    "controller", "land_releases", "a", "C", "m", "m_err", "c", "d", "reuse", "H"))


def _no_dense(ns):
    """H of a method without its own dense output (0 rows: the engine uses cubic Hermite)."""
    return np.zeros((0, ns))


def _from_transformed(gamma, a, C, m, m_err):
    """Classical (A, G, b, e, c, d) from the transformed form (a, C, m, m_err) of
    Hairer & Wanner II (7.21): Gamma^-1 = diag(1/gamma) - C, A = a Gamma, b = m Gamma."""
    ns = len(m)
    Ginv = np.eye(ns) / gamma - np.asarray(C, dtype=float)
    Gam = np.linalg.inv(Ginv)
    A = np.asarray(a, dtype=float) @ Gam
    b = np.asarray(m, dtype=float) @ Gam
    e = np.asarray(m_err, dtype=float) @ Gam
    G = Gam - gamma * np.eye(ns)
    return A, G, b, e


# ROS34PW2 tableau (Hairer convention: W = I - gamma h J,
# W k_i = h f(t + c_i h, x + sum_j A_ij k_j) + h J sum_j G_ij k_j + h^2 d_i f_t)
ROS34PW2_GAMMA = 4.3586652150845900e-01
ROS34PW2_A = np.array([[0.0, 0.0, 0.0, 0.0],
                       [8.7173304301691801e-01, 0.0, 0.0, 0.0],
                       [8.4457060015369423e-01, -1.1299064236397981e-01, 0.0, 0.0],
                       [0.0, 0.0, 1.0, 0.0]])
ROS34PW2_G = np.array([[0.0, 0.0, 0.0, 0.0],
                       [-8.7173304301691801e-01, 0.0, 0.0, 0.0],
                       [-9.0338057013044082e-01, 5.4180672388095326e-02, 0.0, 0.0],
                       [2.4212380706095346e-01, -1.2232505839045147e+00, 5.4526025533510214e-01, 0.0]])
ROS34PW2_B_SOL = np.array([2.4212380706095346e-01, -1.2232505839045147e+00, 1.5452602553351023e+00,
                           4.3586652150845900e-01])
ROS34PW2_B_EMB = np.array([3.7810903145819369e-01, -9.6042292212423178e-02, 5.0000000000000000e-01,
                           2.1793326075422950e-01])


def _ros34pw2():
    return ROS34PW2_GAMMA, ROS34PW2_A, ROS34PW2_G, ROS34PW2_B_SOL, ROS34PW2_B_SOL - ROS34PW2_B_EMB, 3, _no_dense(4)


def _ros34pw3():
    gamma = 1.0685790213016289
    A = np.array([[0, 0, 0, 0],
                  [2.5155456020628817, 0, 0, 0],
                  [5.0777280103144085e-1, 0.75, 0, 0],
                  [1.3959081404277204e-1, -3.3111001065419338e-1, 8.2040559712714178e-1, 0]])
    Gam = np.array([[gamma, 0, 0, 0],
                    [-2.5155456020628817, gamma, 0, 0],
                    [-8.7991339217106512e-1, -9.6014187766190695e-1, gamma, 0],
                    [-4.1731389379448741e-1, 4.1091047035857703e-1, -1.3558873204765276, gamma]])
    b = np.array([2.2047681286931747e-1, 2.7828278331185935e-3, 7.1844787635140066e-3, 7.6955588053404989e-1])
    bhat = np.array([3.1300297285209688e-1, -2.8946895245112692e-1, 9.7646597959903003e-1, 0])
    return gamma, A, Gam - gamma * np.eye(4), b, b - bhat, 3, _no_dense(4)


def _rodas(gamma, a, C, order, H_transformed=None):
    """RODAS-type (stiffly accurate): the solution is the last stage's point plus u_ns, the
    embedded one the last stage's point (m = last row of a with 1, m_err = e_ns).
    ``H_transformed``: dense-output rows over the transformed stages u (u = Gamma k), returned
    over the classical ones as H Gamma (as b = m Gamma)."""
    a = np.asarray(a, dtype=float)
    ns = a.shape[0]
    m = a[-1].copy()
    m[-1] = 1.0
    m_err = np.zeros(ns)
    m_err[-1] = 1.0
    A, G, b, e = _from_transformed(gamma, a, C, m, m_err)
    H = _no_dense(ns)
    if H_transformed is not None:
        H = np.asarray(H_transformed, dtype=float) @ (G + gamma * np.eye(ns))
    return gamma, A, G, b, e, order, H


def _rodas4():
    a = [[0, 0, 0, 0, 0, 0],
         [1.544, 0, 0, 0, 0, 0],
         [0.9466785280815826, 0.2557011698983284, 0, 0, 0, 0],
         [3.314825187068521, 2.896124015972201, 0.9986419139977817, 0, 0, 0],
         [1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950, 0, 0],
         [1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950, 1, 0]]
    C = [[0, 0, 0, 0, 0, 0],
         [-5.6688, 0, 0, 0, 0, 0],
         [-2.430093356833875, -0.2063599157091915, 0, 0, 0, 0],
         [-0.1073529058151375, -9.594562251023355, -20.47028614809616, 0, 0, 0],
         [7.496443313967647, -10.24680431464352, -33.99990352819905, 11.70890893206160, 0, 0],
         [8.083246795921522, -7.981132988064893, -31.52159432874371, 16.31930543123136, -6.058818238834054, 0]]
    return _rodas(0.25, a, C, 4)


def _rodas5p():
    a = np.zeros((8, 8))
    a[1, :1] = [3.0]
    a[2, :2] = [2.849394379747939, 0.45842242204463923]
    a[3, :3] = [-6.954028509809101, 2.489845061869568, -10.358996098473584]
    a[4, :4] = [2.8029986275628964, 0.5072464736228206, -0.3988312541770524, -0.04721187230404641]
    a[5, :5] = [-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256,
                0.030198172008377946]
    a[6, :6] = list(a[5, :5]) + [1.0]
    a[7, :7] = list(a[5, :5]) + [1.0, 1.0]
    C = np.zeros((8, 8))
    C[1, :1] = [-14.155112264123755]
    C[2, :2] = [-17.97296035885952, -2.859693295451294]
    C[3, :3] = [147.12150275711716, -1.41221402718213, 71.68940251302358]
    C[4, :4] = [165.43517024871676, -0.4592823456491126, 42.90938336958603, -5.961986721573306]
    C[5, :5] = [24.854864614690072, -3.0009227002832186, 47.4931110020768, 5.5814197821558125, -0.6610691825249471]
    C[6, :6] = [30.91273214028599, -3.1208243349937974, 77.79954646070892, 34.28646028294783, -19.097331116725623,
                -28.087943162872662]
    C[7, :7] = [37.80277123390563, -3.2571969029072276, 112.26918849496327, 66.9347231244047, -40.06618937091002,
                -54.66780262877968, -9.48861652309627]
    # dense output (Steinebach 2023; OrdinaryDiffEq.jl h21..h28, h31..h38, h41..h48)
    H = [[25.948786856663858, -2.5579724845846235, 10.433815404888879, -2.3679251022685204,
          0.524948541321073, 1.1241088310450404, 0.4272876194431874, -0.17202221070155493],
         [-9.91568850695171, -0.9689944594115154, 3.0438037242978453, -24.495224566215796,
          20.176138334709044, 15.98066361424651, -6.789040303419874, -6.710236069923372],
         [11.419903575922262, 2.8879645146136994, 72.92137995996029, 80.12511834622643,
          -52.072871366152654, -59.78993625266729, -0.15582684282751913, 4.883087185713722]]
    return _rodas(0.21193756319429014, a, C, 5, H)


METHODS = {"ros34pw2": _ros34pw2, "ros34pw3": _ros34pw3, "rodas4": _rodas4, "rodas5p": _rodas5p}
#: accepted steps per Jacobian: W-methods stay consistent with an old one; RODAS-type need a
#: fresh one more often (measured on the vasomotion run, docs/performance.md)
JAC_REUSE = {"ros34pw2": 6, "ros34pw3": 6, "rodas4": 1, "rodas5p": 1}
#: the variable-order BDF method (engine_bdf.integrate_batch_bdf): no tableau, the engine's
#: other integrator
BDF = "bdf"
#: the engine's default method: RODAS5P (order 5, fresh element-local Jacobian each step).
#: Measured with the PI controller: the same CPU as ROS34PW2 at rtol 1e-5 and 55x
#: closer to the reference cycle; BDF 2-3x less CPU on the vasomotion run at rtol 1e-6 to 1e-8
#: (its Jacobian is kept: ~2.8 right-hand sides per step against ~8.8 plus a Jacobian) and its
#: limit cycle within 3.3e-5 of the reference at 1e-6, but it damps a slowly growing
#: oscillation: in the envelope map's member Pa = 70 mmHg, zeta = 0.2 its r max at t = 1000 s
#: is 4.3e-3 off a rtol 1e-9 reference at rtol 1e-6 (13 % of the amplitude), RODAS5P's 6.8e-4
#: at 1e-5 (2.6e-3 with the predictive controller, RODAS5P's default: its
#: longer steps cost accuracy on that member, docs/performance.md).  So BDF is used where it is
#: as accurate: the forced runs of ``freq``.
DEFAULT = "rodas5p"
#: step-size controllers (engine_rosenbrock.integrate_batch): "pi", Gustafsson's PI rule
#: h_new = 0.9 h err^(-0.7/q) err_prev^(0.4/q); "predictive", Gustafsson's predictive rule as in
#: Hairer & Wanner's RODAS/RADAU5 (IV.8 (8.21)): the smaller of the I rule 0.9 h err^(-1/q) and
#: 0.9 h (h / h_prev) (err_prev / err^2)^(1/q), err_prev >= 1e-2; growth within [0.2, 6]; after
#: a rejection, as their code, h 0.9 err^(-1/q) within [0.2 h, 0.9 h].  "predictive-halving": the
#: same, but a rejection at least halves the step (pi's rule).  Measured: predictive takes 20 % fewer steps and half
#: the rejections on the vasomotion envelope (rtol 1e-5), 4 % fewer on the vasomotion run at
#: 1e-6; predictive-halving gives shooting a smoother period map (closedLoopHeart_singleVessel
#: from 16 starts: 6.25 Anderson periods on average against 7.0), so periodic uses it.
CONTROLLERS = {"pi": 0, "predictive": 1, "predictive-halving": 2}
CONTROLLER = {"rodas5p": "predictive"}


def classical(name):
    """(gamma, A, G, b, e, q) of method ``name`` in the classical form."""
    return _method(name)[:6]


def dense(name):
    """The dense-output rows H (nd x ns) over the classical stages; nd = 0 without one."""
    return _method(name)[6]


def transformed(name):
    """(gamma, a, C, m, m_err, H) of method ``name`` over the transformed stages u = Gamma k
    (module docstring), from its classical form."""
    return _transform(*_method(name))


def _transform(gamma, A, G, b, e, q, H):
    Ginv = np.linalg.inv(G + gamma * np.eye(len(b)))
    C = np.tril(np.eye(len(b)) / gamma - Ginv, -1)
    return gamma, np.tril(A @ Ginv, -1), C, b @ Ginv, e @ Ginv, np.reshape(H, (-1, len(b))) @ Ginv


def _method(name):
    """(gamma, A, G, b, e, q, H) of method ``name``."""
    if name not in METHODS:
        raise ValueError(f"unknown integration method {name!r}: choose one of {sorted(METHODS)}")
    return METHODS[name]()


def packed(name="rodas5p", jac_reuse=None, event_restart=1, soft_kinks=1, autonomous=0,
           local_jacobian=1, controller=None, land_releases=1) -> RosenbrockMethod:
    """The method as the engine reads it (see the module docstring).  ``autonomous``: the
    circuit has no waveform and no time-dependent element, so df/dt = 0 is not evaluated.
    ``local_jacobian``: the state Jacobian element by element, composed through the nodal
    solve (engine_jacobian.local_jacobian_into_at) where it applies: 1 with the kernels' analytic
    partials where they have them (Kernel.derivs_jac), 2 by element-local differences only;
    0: one whole right-hand side differenced per state.  ``controller``: the step-size rule,
    ``"pi"``, ``"predictive"`` or ``"predictive-halving"`` (module docstring); default
    CONTROLLER[name].  ``land_releases``: a rejected step in which a state held on its hard
    limit is released (a closed valve opening) is retried ending just past the release
    (engine_rosenbrock.release_fraction); 0: the step-size controller alone finds it.  (Built
    once per set of arguments, its arrays read-only: packing costs ~0.5 ms, a third of a short
    run's Python time.)"""
    jr = JAC_REUSE.get(name) if jac_reuse is None else int(jac_reuse)
    ctrl = CONTROLLER.get(name, "pi") if controller is None else controller
    if ctrl not in CONTROLLERS:
        raise ValueError(f"unknown step-size controller {ctrl!r}: choose one of {sorted(CONTROLLERS)}")
    return _packed(name, jr, int(event_restart), int(soft_kinks), int(autonomous), int(local_jacobian),
                   CONTROLLERS[ctrl], int(land_releases))


@functools.lru_cache(maxsize=64)
def _packed(name, jr, event_restart, soft_kinks, autonomous, local_jacobian, controller, land_releases):
    classic = _method(name)
    gamma, A, G, b, e, q, _ = classic
    _, a, C, m, m_err, H = _transform(*classic)
    ns = len(b)
    c = A.sum(axis=1)
    d = gamma + G.sum(axis=1)
    reuse = np.zeros(ns)
    for s in range(1, ns):
        if np.allclose(A[s], A[s - 1], rtol=0, atol=1e-14):
            reuse[s] = 1.0

    def frozen(a):
        a = np.array(a, dtype=np.float64, order="C")
        a.setflags(write=False)
        return a

    return RosenbrockMethod(int(ns), float(gamma), float(q), int(jr), event_restart, soft_kinks, autonomous,
                            local_jacobian, int(controller), land_releases, frozen(a), frozen(C), frozen(m),
                            frozen(m_err), frozen(c), frozen(d), frozen(reuse), frozen(H))
