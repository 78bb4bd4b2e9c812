"""Time stepping for the planar leg: RK4 with exact contact projection (lesson section 5).

A control step of length ``dt`` is ``n`` classical RK4 steps of ``h = dt / n`` with
``n = max(substeps, ceil(dt * w_max / max_angle))``, ``w_max`` the largest absolute link
rate at the start of the step: slow (balancing) motion takes ``substeps`` steps, fast motion
(a fall) takes more, so that no link turns by more than ``max_angle`` per RK4 step. The rule
is deterministic; ``max_angle=np.inf`` gives plain fixed-step RK4.
In stance, after every RK4 step the state is projected back onto the contact manifold
by coordinate partitioning: the independent coordinates ``(th_b, q1, q2)`` and their
rates are what RK4 integrates, and the base position and velocity are then set so
that the foot sits exactly on its anchor ``p_f*`` and ``Jc qd = 0``::

    (x_b, y_b)   = p_f* - l1 (cos th1, sin th1) - l2 (cos th2, sin th2)
    (x_b, y_b)'  = -(dp_f/d th1) th1' - (dp_f/d th2) th2'

The stance dynamics of the independent coordinates do not depend on ``x_b, y_b`` or
their rates (translation invariance), so this is exactly RK4 on the reduced ODE: the
integrator keeps its 4th order and the foot drift stays at round-off (~1e-15 m).

Each step also returns the mean contact force over the step, the RK4-weighted
average of the stage forces, i.e. the contact impulse divided by ``dt``.

One kernel serves one robot and a batch: single-robot calls are a batch of one.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._jit import CACHE
from .contact import FLIGHT, SLIP_BACKWARD, SLIP_FORWARD, STICK, _slip_core
from .dynamics import _F64, LOAD_X, NP, NQ, NU, _batched, _flight_core, _single_robot, _stance_core, _vec, _kernel_params
from . import checks
from .params import LegParams

DT = 0.01  # default control period [s]
SUBSTEPS = 2  # default least number of RK4 steps per control period
MAX_ANGLE = 0.02  # default largest link rotation per RK4 step [rad]
MAX_SUBSTEPS = 4096  # most RK4 steps per control period: the step rule's cap, and the largest accepted ``substeps``

__all__ = ["stance_step", "flight_step", "project_stance", "project_velocity", "step_inplace"]

_RK4_C = np.array([0.0, 0.5, 0.5, 1.0])
_RK4_W = np.array([1.0, 2.0, 2.0, 1.0]) / 6.0


@njit(cache=CACHE, inline="always")
def _project_core(s1, co1, s2, co2, w1, w2, anchor, p):
    """Base position and velocity that put the foot on ``anchor`` with ``Jc qd = 0``."""
    l1, l2 = p[6], p[7]
    x = anchor[0] - l1 * co1 - l2 * co2
    y = anchor[1] - l1 * s1 - l2 * s2
    vx = l1 * s1 * w1 + l2 * s2 * w2
    vy = -(l1 * co1 * w1 + l2 * co2 * w2)
    return x, y, vx, vy


@njit(cache=CACHE, inline="always")
def _project_one(q, qd, p, anchor):
    """Put the foot exactly on ``anchor`` and make ``Jc qd = 0`` by moving only the base."""
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    w1 = qd[2] + qd[3]
    w2 = w1 + qd[4]
    q[0], q[1], qd[0], qd[1] = _project_core(np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2), w1, w2, anchor, p)


@njit(cache=CACHE, inline="always")
def _substeps_for_rates(va, vb, vc, dt, substeps, max_angle):
    """RK4 steps for a control step of length ``dt``: at least ``substeps``, and enough that no link
    turns, and no joint moves, by more than ``max_angle`` per RK4 step at the rates ``th_b', q1', q2'``."""
    w = max(abs(va), abs(vb), abs(vc), abs(va + vb), abs(va + vb + vc))
    need = w * dt / max_angle
    if need > substeps:
        if need > MAX_SUBSTEPS:  # infinite or absurd rates: cap the work, the caller flags the state
            return MAX_SUBSTEPS
        return int(np.ceil(need))
    return substeps  # also for NaN rates: the state is already lost, the caller flags it


@njit(cache=CACHE, inline="always")
def _substeps_for(qd, dt, substeps, max_angle):
    """``_substeps_for_rates`` at the velocity ``qd``."""
    return _substeps_for_rates(qd[2], qd[3], qd[4], dt, substeps, max_angle)


@njit(cache=CACHE, inline="always")
def _accel(mode, mu, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, p):
    """``(qdd[0..4], lam_x, lam_y)`` of the contact mode ``mode`` (``leg_env.contact``'s constants)."""
    if mode == STICK:
        return _stance_core(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, p)
    if mode == FLIGHT:
        xdd, ydd, thbdd, q1dd, q2dd = _flight_core(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, p)
        return xdd, ydd, thbdd, q1dd, q2dd, 0.0, 0.0
    return _slip_core(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, mu, 1.0 if mode == SLIP_FORWARD else -1.0, p)


# Taylor coefficients of sin(d) and cos(d) - 1, for |d| <= _TURN_MAX: the first omitted terms,
# d^11/11! and d^12/12!, are below 3e-19 there, far under the double rounding of the results.
_S3, _S5, _S7, _S9 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0
_C2, _C4, _C6, _C8, _C10 = -0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0
_TURN_MAX = 0.1


@njit(cache=CACHE, inline="always")
def _turn(s, c, d):
    """``(sin(th + d), cos(th + d))`` from ``s = sin th``, ``c = cos th`` by angle addition.

    Within a control step the links turn by little (``max_angle`` per RK4 step at the initial
    rates), so ``sin d`` and ``cos d - 1`` come from short Taylor series instead of a library
    call; larger (or non-finite) ``d`` falls back to ``np.sin`` / ``np.cos``.
    """
    if abs(d) <= _TURN_MAX:
        d2 = d * d
        d4 = d2 * d2
        sd = d + d * d2 * ((_S3 + d2 * _S5) + d4 * (_S7 + d2 * _S9))
        cm = d2 * ((_C2 + d2 * _C4) + d4 * ((_C6 + d2 * _C8) + d4 * _C10))
    else:
        sd = np.sin(d)
        cm = np.cos(d) - 1.0
    return s + (s * cm + c * sd), c + (c * cm - s * sd)


@njit(cache=CACHE, inline="always")
def _rk4_substep(mode, mu, anchor, X, k1, h, t_hip, t_knee, p, lx, ly):
    """One classical RK4 step of length ``h`` in contact mode ``mode``, then the mode's projection.

    ``X = (x, y, a, b, c, vx, vy, va, vb, vc, s1, co1, s2, co2)``: ``q``, ``qd`` and the sines/cosines
    of ``th1 = a + b`` and ``th2 = th1 + c``; ``k1`` the accelerations and force at ``X`` (``_accel``).
    The dynamics depend only on the link angles through their sines/cosines, and on their rates:
    every stage turns the sines/cosines by its angle increment (``_turn``), and the trigonometry after
    the step serves the projection and the next step's first stage. The projection keeps the foot on
    its contact: at ``anchor`` with ``Jc qd = 0`` in stick, on the line ``y = anchor[1]`` with zero normal
    velocity in slip (coordinate partitioning: only the base moves); none in flight.

    Returns ``(X_next, lx, ly, power)``: ``lx, ly`` are the inputs plus the RK4-weighted stage force
    ``sum_k w_k lam_k`` (``h`` times it is the contact impulse of the step), ``power`` the RK4-weighted
    dissipated power of friction, ``sum_k w_k (-lam_x x_f')_k`` (slip only, else 0).
    """
    x, y, a, b, c, vx, vy, va, vb, vc, s1, co1, s2, co2 = X
    ax1, ay1, aa1, ab1, ac1, lx1, ly1 = k1
    ch = _RK4_C[1] * h  # stage offsets: h/2, h/2, h
    W0, W1 = _RK4_W[0], _RK4_W[1]  # weights 1/6, 2/6, 2/6, 1/6
    w1, w2 = va + vb, va + vb + vc
    # stage 2: y0 + h/2 k1
    vx2, vy2, va2, vb2, vc2 = vx + ch * ax1, vy + ch * ay1, va + ch * aa1, vb + ch * ab1, vc + ch * ac1
    S1, C1 = _turn(s1, co1, ch * w1)
    S2, C2 = _turn(s2, co2, ch * w2)
    w1_2, w2_2 = va2 + vb2, va2 + vb2 + vc2
    ax2, ay2, aa2, ab2, ac2, lx2, ly2 = _accel(mode, mu, S1, C1, S2, C2, w1_2, w2_2, t_hip, t_knee, p)
    power = 0.0
    if mode == SLIP_FORWARD or mode == SLIP_BACKWARD:
        l1, l2 = p[6], p[7]
        power = W0 * -lx1 * (vx - l1 * s1 * w1 - l2 * s2 * w2) + W1 * -lx2 * (vx2 - l1 * S1 * w1_2 - l2 * S2 * w2_2)
    # stage 3: y0 + h/2 k2
    vx3, vy3, va3, vb3, vc3 = vx + ch * ax2, vy + ch * ay2, va + ch * aa2, vb + ch * ab2, vc + ch * ac2
    S1, C1 = _turn(s1, co1, ch * w1_2)
    S2, C2 = _turn(s2, co2, ch * w2_2)
    w1_3, w2_3 = va3 + vb3, va3 + vb3 + vc3
    ax3, ay3, aa3, ab3, ac3, lx3, ly3 = _accel(mode, mu, S1, C1, S2, C2, w1_3, w2_3, t_hip, t_knee, p)
    if mode == SLIP_FORWARD or mode == SLIP_BACKWARD:
        power += W1 * -lx3 * (vx3 - p[6] * S1 * w1_3 - p[7] * S2 * w2_3)
    # stage 4: y0 + h k3
    vx4, vy4, va4, vb4, vc4 = vx + h * ax3, vy + h * ay3, va + h * aa3, vb + h * ab3, vc + h * ac3
    S1, C1 = _turn(s1, co1, h * w1_3)
    S2, C2 = _turn(s2, co2, h * w2_3)
    ax4, ay4, aa4, ab4, ac4, lx4, ly4 = _accel(mode, mu, S1, C1, S2, C2, va4 + vb4, va4 + vb4 + vc4, t_hip, t_knee, p)
    if mode == SLIP_FORWARD or mode == SLIP_BACKWARD:
        power += W0 * -lx4 * (vx4 - p[6] * S1 * (va4 + vb4) - p[7] * S2 * (va4 + vb4 + vc4))
    # y1 = y0 + h (k1 + 2 k2 + 2 k3 + k4) / 6
    da = h * (W0 * va + W1 * va2 + W1 * va3 + W0 * va4)
    db = h * (W0 * vb + W1 * vb2 + W1 * vb3 + W0 * vb4)
    dc = h * (W0 * vc + W1 * vc2 + W1 * vc3 + W0 * vc4)
    x = x + h * (W0 * vx + W1 * vx2 + W1 * vx3 + W0 * vx4)
    y = y + h * (W0 * vy + W1 * vy2 + W1 * vy3 + W0 * vy4)
    a, b, c = a + da, b + db, c + dc
    vx = vx + h * (W0 * ax1 + W1 * ax2 + W1 * ax3 + W0 * ax4)
    vy = vy + h * (W0 * ay1 + W1 * ay2 + W1 * ay3 + W0 * ay4)
    va = va + h * (W0 * aa1 + W1 * aa2 + W1 * aa3 + W0 * aa4)
    vb = vb + h * (W0 * ab1 + W1 * ab2 + W1 * ab3 + W0 * ab4)
    vc = vc + h * (W0 * ac1 + W1 * ac2 + W1 * ac3 + W0 * ac4)
    lx = lx + W0 * lx1 + W1 * lx2 + W1 * lx3 + W0 * lx4
    ly = ly + W0 * ly1 + W1 * ly2 + W1 * ly3 + W0 * ly4
    s1, co1 = _turn(s1, co1, da + db)
    s2, co2 = _turn(s2, co2, da + db + dc)
    if mode == STICK:  # the projection, on the trigonometry just computed
        x, y, vx, vy = _project_core(s1, co1, s2, co2, va + vb, va + vb + vc, anchor, p)
    elif mode != FLIGHT:  # slip: the foot on the ground line, its normal velocity zero
        y = anchor[1] - p[6] * s1 - p[7] * s2
        vy = -(p[6] * co1 * (va + vb) + p[7] * co2 * (va + vb + vc))
    return (x, y, a, b, c, vx, vy, va, vb, vc, s1, co1, s2, co2), lx, ly, power


@njit(cache=CACHE, inline="always")
def _rk4_one(q, qd, tau, p, anchor, dt, substeps, max_angle, stance, lam_mean):
    """One control step of RK4 on one robot, in place (``_rk4_from`` at the state's own trigonometry)."""
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    _rk4_from(q, qd, tau, p, anchor, dt, substeps, max_angle, stance, lam_mean, np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2))


@njit(cache=CACHE, inline="always")
def _rk4_from(q, qd, tau, p, anchor, dt, substeps, max_angle, stance, lam_mean, s1, co1, s2, co2):
    """One control step of RK4 on one robot, in place, given ``sin``/``cos`` of ``th1 = q[2] + q[3]``
    and ``th2 = th1 + q[4]`` (the caller may have them already: the task kernel keeps them).

    The state lives in scalars: ``(x, y, a, b, c)`` = ``q`` and ``(vx, vy, va, vb, vc)`` = ``qd``.
    The dynamics depend only on the link angles ``th1 = a + b``, ``th2 = th1 + c`` through their
    sines/cosines, and on their rates. Every stage and every RK4 step turns the sines/cosines by
    its angle increment (``_turn``), and the trigonometry after an RK4 step serves both the stance
    projection and the next step's first stage.
    """
    n = _substeps_for(qd, dt, substeps, max_angle)
    h = dt / n
    mode = STICK if stance else FLIGHT
    t_hip, t_knee = tau[0], tau[1]
    X = (q[0], q[1], q[2], q[3], q[4], qd[0], qd[1], qd[2], qd[3], qd[4], s1, co1, s2, co2)
    lx = 0.0
    ly = 0.0
    for _ in range(n):
        w1, w2 = X[7] + X[8], X[7] + X[8] + X[9]
        k1 = _accel(mode, 0.0, X[10], X[11], X[12], X[13], w1, w2, t_hip, t_knee, p)
        X, lx, ly, _ = _rk4_substep(mode, 0.0, anchor, X, k1, h, t_hip, t_knee, p, lx, ly)
    x, y, a, b, c, vx, vy, va, vb, vc = X[0], X[1], X[2], X[3], X[4], X[5], X[6], X[7], X[8], X[9]
    q[0], q[1], q[2], q[3], q[4] = x, y, a, b, c
    qd[0], qd[1], qd[2], qd[3], qd[4] = vx, vy, va, vb, vc
    lam_mean[0] = lx / n
    lam_mean[1] = ly / n


@njit(cache=CACHE)
def step_inplace(q, qd, tau, p, anchor, dt, substeps, max_angle, stance, lam_mean):
    """Advance a batch by one control step in place.

    Args:
        q, qd: ``(N, 5)`` float64 states, overwritten.
        tau: ``(N, 2)`` torques held over the step.
        p: ``(11,)`` parameter array (``LegParams.array``: no load), or ``(12,)`` with the horizontal force
            on the torso's COM last (``leg_env.dynamics.params_array(p, load_x)``).
        anchor: ``(N, 2)`` foot contact points (read only in stance).
        dt: control period [s]; substeps: least number of RK4 steps per control period.
        max_angle: largest rotation [rad] of any link per RK4 step at the step's initial
            rates; fast motions get more RK4 steps (``np.inf`` gives fixed steps).
        stance: True for the pinned-foot model, False for flight.
        lam_mean: ``(N, 2)`` output, mean contact force over the step (zero in flight).

    Raises:
        ValueError: ``p`` has another length.
    """
    if p.shape[0] != NP and p.shape[0] != NP + 1:
        raise ValueError("step_inplace: p must have 11 entries (LegParams.array) or 12 (params_array: then the load)")
    pl = np.empty(NP + 1)  # the kernels read the load at p[LOAD_X]: never past the end of an 11-entry array
    for j in range(NP):
        pl[j] = p[j]
    pl[LOAD_X] = p[LOAD_X] if p.shape[0] > NP else 0.0
    for i in range(q.shape[0]):
        _rk4_one(q[i], qd[i], tau[i], pl, anchor[i], dt, substeps, max_angle, stance, lam_mean[i])


@njit(cache=CACHE)
def _project_batch(q, qd, p, anchor):
    for i in range(q.shape[0]):
        _project_one(q[i], qd[i], p, anchor[i])



def _checked_steps(dt: float, substeps: int, max_angle: float) -> tuple[float, int, float]:
    return (
        checks.real("dt", dt, 0.0, math.inf, lo_open=True, hi_open=True, unit="s"),
        checks.integer("substeps", substeps, 1, MAX_SUBSTEPS, floats=True),
        checks.real("max_angle", max_angle, 0.0, math.inf, lo_open=True, unit="rad (inf for fixed steps)"),
    )


def stance_step(
    q, qd, tau, p: LegParams, dt: float = DT, substeps: int = SUBSTEPS, anchor=None, max_angle: float = MAX_ANGLE
):
    """One stance control step of RK4 with the foot pinned at ``anchor``.

    Args:
        q, qd: ``(..., 5)`` state, assumed on the contact manifold (see ``project_stance``).
        tau: ``(..., 2)`` hip and knee torques held over the step [N m].
        p: physical parameters.
        dt: control period [s].
        substeps: least number of RK4 steps per control period.
        anchor: ``(..., 2)`` foot contact point; default: the foot's current position.
        max_angle: largest link rotation per RK4 step [rad]; ``np.inf`` for fixed steps.

    Returns:
        ``(q_next, qd_next, lam_mean)``: the new state and the mean contact force over the step.
    """
    from .dynamics import foot_position

    dt, substeps, max_angle = _checked_steps(dt, substeps, max_angle)
    if _single_robot(q, qd, tau):
        # one robot: the same kernel on (1, n) views, without the broadcasting machinery
        if anchor is None:
            anchor = foot_position(q, p)
        if type(anchor) is np.ndarray and anchor.shape == (2,) and anchor.dtype is _F64 and anchor.flags.c_contiguous:
            q1, qd1, lam = q.reshape(1, NQ).copy(), qd.reshape(1, NQ).copy(), np.empty((1, 2))
            step_inplace(q1, qd1, tau.reshape(1, NU), _kernel_params(p), anchor.reshape(1, 2), dt, substeps, max_angle,
                         True, lam)
            return q1[0], qd1[0], lam[0]
    q = _vec(q, NQ, "q")
    anchor = foot_position(q, p) if anchor is None else _vec(anchor, 2, "anchor")
    lead, (qf, qdf, tf, af) = _batched(q, _vec(qd, NQ, "qd"), _vec(tau, NU, "tau"), anchor)
    qf, qdf = qf.copy(), qdf.copy()
    lam = np.empty((qf.shape[0], 2))
    step_inplace(qf, qdf, tf, _kernel_params(p), af, dt, substeps, max_angle, True, lam)
    return qf.reshape(lead + (NQ,)), qdf.reshape(lead + (NQ,)), lam.reshape(lead + (2,))


def flight_step(q, qd, tau, p: LegParams, dt: float = DT, substeps: int = SUBSTEPS, max_angle: float = MAX_ANGLE):
    """One flight control step (no contact) of RK4, stepped as in ``stance_step``. Returns ``(q_next, qd_next)``."""
    dt, substeps, max_angle = _checked_steps(dt, substeps, max_angle)
    lead, (qf, qdf, tf) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"), _vec(tau, NU, "tau"))
    qf, qdf = qf.copy(), qdf.copy()
    lam = np.empty((qf.shape[0], 2))
    step_inplace(qf, qdf, tf, _kernel_params(p), np.zeros((qf.shape[0], 2)), dt, substeps, max_angle, False, lam)
    return qf.reshape(lead + (NQ,)), qdf.reshape(lead + (NQ,))


def project_stance(q, qd, p: LegParams, anchor):
    """Coordinate-partitioning projection: move only the base so the foot is at ``anchor`` and ``Jc qd = 0``."""
    lead, (qf, qdf, af) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"), _vec(anchor, 2, "anchor"))
    qf, qdf = qf.copy(), qdf.copy()
    _project_batch(qf, qdf, _kernel_params(p), af)
    return qf.reshape(lead + (NQ,)), qdf.reshape(lead + (NQ,))


def project_velocity(q, qd, p: LegParams) -> np.ndarray:
    """Euclidean projection of ``qd`` onto the nullspace of ``Jc(q)``: ``qd - Jc^T (Jc Jc^T)^-1 Jc qd`` (solved)."""
    from .dynamics import contact_jacobian

    qd = _vec(qd, NQ, "qd")
    Jc = contact_jacobian(q, p)
    JJt = Jc @ np.swapaxes(Jc, -1, -2)
    y = np.linalg.solve(JJt, (Jc @ qd[..., None]))
    return qd - (np.swapaxes(Jc, -1, -2) @ y)[..., 0]
