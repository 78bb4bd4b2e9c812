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

import numpy as np
from numba import njit

from .dynamics import NQ, NU, _batched, _flight_one, _foot_one, _stance_one, _vec, params_array
from .params import LegParams

__all__ = ["stance_step", "flight_step", "project_stance", "project_velocity", "step_inplace"]

_RK4_C = np.array([0.0, 0.5, 0.5, 1.0])
_RK4_W = np.array([1.0, 2.0, 2.0, 1.0]) / 6.0


@njit(cache=True, inline="always")
def _project_one(q, qd, p, anchor):
    """Put the foot exactly on ``anchor`` and make ``Jc qd = 0`` by moving only the base."""
    l1, l2 = p[6], p[7]
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    w1 = qd[2] + qd[3]
    w2 = w1 + qd[4]
    s1, co1, s2, co2 = np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2)
    q[0] = anchor[0] - l1 * co1 - l2 * co2
    q[1] = anchor[1] - l1 * s1 - l2 * s2
    qd[0] = l1 * s1 * w1 + l2 * s2 * w2
    qd[1] = -(l1 * co1 * w1 + l2 * co2 * w2)


@njit(cache=True, inline="always")
def _substeps_for(qd, dt, substeps, max_angle):
    """RK4 steps for this control step: at least ``substeps``, and enough that no link
    turns, and no joint moves, by more than ``max_angle`` per RK4 step at the current rates."""
    w = max(abs(qd[2]), abs(qd[3]), abs(qd[4]), abs(qd[2] + qd[3]), abs(qd[2] + qd[3] + qd[4]))
    need = w * dt / max_angle
    if need > substeps:
        if need > 4096.0:  # non-finite or absurd rates: cap the work, the caller flags the state
            return 4096
        return int(np.ceil(need))
    return substeps


@njit(cache=True, inline="always")
def _rk4_one(q, qd, tau, p, anchor, dt, substeps, max_angle, stance, lam_mean, work):
    """One control step of RK4 on one robot, in place; ``work`` is (6, 5) scratch."""
    q0, qd0, qs, qds, acc_q, acc_qd = work[0], work[1], work[2], work[3], work[4], work[5]
    substeps = _substeps_for(qd, dt, substeps, max_angle)
    h = dt / substeps
    qdd = np.empty(NQ)
    lam = np.zeros(2)
    lam_mean[0] = 0.0
    lam_mean[1] = 0.0
    for _ in range(substeps):
        for j in range(NQ):
            q0[j] = q[j]
            qd0[j] = qd[j]
            qs[j] = q[j]
            qds[j] = qd[j]
            acc_q[j] = 0.0
            acc_qd[j] = 0.0
        for st in range(4):
            if st > 0:
                ch = _RK4_C[st] * h
                for j in range(NQ):
                    # previous stage slope: (qds, qdd); new stage state from y0
                    qs[j] = q0[j] + ch * qds[j]
                for j in range(NQ):
                    qds[j] = qd0[j] + ch * qdd[j]
            if stance:
                _stance_one(qs, qds, tau, p, qdd, lam)
            else:
                _flight_one(qs, qds, tau, p, qdd)
            w = _RK4_W[st]
            for j in range(NQ):
                acc_q[j] += w * qds[j]
                acc_qd[j] += w * qdd[j]
            lam_mean[0] += w * lam[0]
            lam_mean[1] += w * lam[1]
        for j in range(NQ):
            q[j] = q0[j] + h * acc_q[j]
            qd[j] = qd0[j] + h * acc_qd[j]
        if stance:
            _project_one(q, qd, p, anchor)
    lam_mean[0] /= substeps
    lam_mean[1] /= substeps


@njit(cache=True)
def step_inplace(q, qd, tau, p, anchor, dt, substeps, max_angle, stance, lam_mean):
    """Advance a batch by one control step in place.

    Args:
        q, qd: ``(N, 5)`` float64 states, overwritten.
        tau: ``(N, 2)`` torques held over the step.
        p: ``(11,)`` parameter array (``LegParams.array``).
        anchor: ``(N, 2)`` foot contact points (read only in stance).
        dt: control period [s]; substeps: least number of RK4 steps per control period.
        max_angle: largest rotation [rad] of any link per RK4 step at the step's initial
            rates; fast motions get more RK4 steps (``np.inf`` gives fixed steps).
        stance: True for the pinned-foot model, False for flight.
        lam_mean: ``(N, 2)`` output, mean contact force over the step (zero in flight).
    """
    work = np.empty((6, NQ))
    for i in range(q.shape[0]):
        _rk4_one(q[i], qd[i], tau[i], p, anchor[i], dt, substeps, max_angle, stance, lam_mean[i], work)


@njit(cache=True)
def _project_batch(q, qd, p, anchor):
    for i in range(q.shape[0]):
        _project_one(q[i], qd[i], p, anchor[i])


DT = 0.01  # default control period [s]
SUBSTEPS = 4  # default least number of RK4 steps per control period
MAX_ANGLE = 0.02  # default largest link rotation per RK4 step [rad]


def _checked_steps(dt: float, substeps: int, max_angle: float) -> tuple[float, int, float]:
    max_angle = float(max_angle)
    if not max_angle > 0.0:
        raise ValueError(f"max_angle must be > 0 radians (np.inf for fixed steps), got {max_angle!r}")
    dt = float(dt)
    if not np.isfinite(dt) or dt <= 0.0:
        raise ValueError(f"dt must be a positive finite number of seconds, got {dt!r}")
    if int(substeps) != substeps or substeps < 1:
        raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
    return dt, int(substeps), max_angle


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
    q = _vec(q, NQ, "q")
    anchor = foot_position(q, p) if anchor is None else _vec(anchor, 2, "anchor")
    lead, (qf, qdf, tf, af) = _batched(q, _vec(qd, NQ, "qd"), _vec(tau, NU, "tau"), anchor)
    qf, qdf = qf.copy(), qdf.copy()
    lam = np.empty((qf.shape[0], 2))
    step_inplace(qf, qdf, tf, params_array(p), af, dt, substeps, max_angle, True, lam)
    return qf.reshape(lead + (NQ,)), qdf.reshape(lead + (NQ,)), lam.reshape(lead + (2,))


def flight_step(q, qd, tau, p: LegParams, dt: float = DT, substeps: int = SUBSTEPS, max_angle: float = MAX_ANGLE):
    """One flight control step (no contact) of RK4, stepped as in ``stance_step``. Returns ``(q_next, qd_next)``."""
    dt, substeps, max_angle = _checked_steps(dt, substeps, max_angle)
    lead, (qf, qdf, tf) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"), _vec(tau, NU, "tau"))
    qf, qdf = qf.copy(), qdf.copy()
    lam = np.empty((qf.shape[0], 2))
    step_inplace(qf, qdf, tf, params_array(p), np.zeros((qf.shape[0], 2)), dt, substeps, max_angle, False, lam)
    return qf.reshape(lead + (NQ,)), qdf.reshape(lead + (NQ,))


def project_stance(q, qd, p: LegParams, anchor):
    """Coordinate-partitioning projection: move only the base so the foot is at ``anchor`` and ``Jc qd = 0``."""
    lead, (qf, qdf, af) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"), _vec(anchor, 2, "anchor"))
    qf, qdf = qf.copy(), qdf.copy()
    _project_batch(qf, qdf, params_array(p), af)
    return qf.reshape(lead + (NQ,)), qdf.reshape(lead + (NQ,))


def project_velocity(q, qd, p: LegParams) -> np.ndarray:
    """Euclidean projection of ``qd`` onto the nullspace of ``Jc(q)``: ``qd - Jc^T (Jc Jc^T)^-1 Jc qd`` (solved)."""
    from .dynamics import contact_jacobian

    qd = _vec(qd, NQ, "qd")
    Jc = contact_jacobian(q, p)
    JJt = Jc @ np.swapaxes(Jc, -1, -2)
    y = np.linalg.solve(JJt, (Jc @ qd[..., None]))
    return qd - (np.swapaxes(Jc, -1, -2) @ y)[..., 0]
