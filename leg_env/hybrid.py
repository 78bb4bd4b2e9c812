r"""The hybrid control step: exact unilateral contact with event-located transitions (lesson section 5).

The foot is in one of the modes of ``leg_env.contact`` (stick, slip forward / backward, flight), carried
as state with the stick contact point ``anchor``; the ground is the line ``y = anchor[1]`` (``0`` in
the environments). A control step of length ``dt`` holds the torques and is integrated by RK4
substeps in the current mode (``leg_env.integrate._rk4_substep``: the same step rule and the same
projections as the pinned model), with every mode change located inside its substep.

Transitions, each a named witness (Drake's ``examples/rod2d`` habit) that fires when it goes from
``>= 0`` to ``< 0`` over a substep:

==================  ===============  =========================================  ========================================
event               modes            witness                                    reset map, then
==================  ===============  =========================================  ========================================
``LIFTOFF``         stick, slip      ``lam_y`` (normal force)                   mode choice (usually flight)
``SLIP_ONSET``      stick            ``mu lam_y - |lam_x|`` (sticking slack)    mode choice: slip opposite to ``lam_x``
``SLIDING_STOP``    slip             ``sigma x_f'`` (sliding velocity)          sticking impulse (a round-off residual),
                                                                                mode choice: stick or reversed slip
``TOUCHDOWN``       flight           ``y_f`` (foot height)                      impact map (``contact.impact_map``),
                                                                                mode choice
==================  ===============  =========================================  ========================================

Location: the substep is re-integrated from its start with a shorter length ``s`` (one RK4 step,
the stage-1 derivative reused) and the earliest crossing of the active witnesses is bracketed by the
Illinois variant of regula falsi until the bracket is shorter than ``ROOT_TIME`` (1e-12 s). The
state just past the root (witness ``< 0``) is kept, so the old mode is inconsistent there; the rest
of the control step is integrated in the new mode, with the step rule re-applied to the post-event
rates.

Mode choice (``leg_env.contact``), at the start of every control step (the torques jump there) and
after every reset map: a foot above the ground, or leaving it, flies; a foot hitting the ground gets
the impact map first; a sliding foot slips or flies; a foot at rest gets the one consistent mode of
the four closed forms. Past the Painleve bound the documented rule of ``leg_env.contact`` applies
(stick "jam", or flight, or a tangential sticking impulse) and is counted.

Zeno: at most ``MAX_EVENTS`` (8) located events per control step. After that the robot is
"settled" for the rest of the step: the contact-leaving witnesses (``LIFTOFF``, ``SLIP_ONSET``) are
off and a foot on the ground stays in contact; a flying foot still lands and a sliding one still
stops (at most ``2 MAX_EVENTS`` events in all). A touchdown slower than ``SETTLE_SPEED`` (1e-6 m/s)
also settles the robot into contact for the rest of the step. Every settle is counted.

What a step accumulates (``ACC_*`` columns of ``acc``): the contact impulse of the continuous modes
(its mean over the step is the mean contact force, impacts excluded), the sum of impact impulses,
the time in each mode, the slip distance, the actuator work ``tau . (q1, q2)(end) - (q1, q2)(start)``
(exact: the joint angles are continuous and the torques constant), the friction dissipation (RK4
quadrature of ``-lam_x x_f'``), the kinetic energy lost in impulses and the work of a horizontal force
``F = p[LOAD_X]`` on the torso's COM (a push, held over the step like the torques:
``F (x_b(end) - x_b(start))``, exact), so that
``E(end) - E(start) = work + work_load - slip_dissipation - impact_dissipation`` up to the RK4 error.
The force enters every mode's dynamics and so every witness and mode choice; impulses are unaffected
(a finite force does no impulsive work).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ._jit import CACHE
from .contact import (
    FLIGHT,
    IMPACT_PAINLEVE,
    REST_SPEED,
    SLIP_BACKWARD,
    SLIP_FORWARD,
    STICK,
    _foot_response,
    _foot_velocity,
    _impact_core,
    _impulse_velocity,
    _mode_at_rest,
    _mode_sliding,
)
from .dynamics import LOAD_X, NQ, NU, _batched, _vec, _kernel_params
from .integrate import DT, MAX_ANGLE, SUBSTEPS, _accel, _checked_steps, _rk4_substep, _substeps_for_rates
from .params import LegParams

__all__ = [
    "hybrid_step",
    "HybridStep",
    "LIFTOFF",
    "SLIP_ONSET",
    "SLIDING_STOP",
    "TOUCHDOWN",
    "EVENT_NAMES",
    "MAX_EVENTS",
    "LOG_SIZE",
    "GROUND_TOL",
    "SETTLE_SPEED",
    "ROOT_TIME",
    "ACC_DIM",
]

LIFTOFF, SLIP_ONSET, SLIDING_STOP, TOUCHDOWN = 0, 1, 2, 3
EVENT_NAMES = ("liftoff", "slip_onset", "sliding_stop", "touchdown")
MAX_EVENTS = 8  # located events per control step before the robot is settled (Zeno guard)
LOG_SIZE = 2 * MAX_EVENTS  # events per step can reach 2 MAX_EVENTS; each is logged
GROUND_TOL = 1e-9  # a foot within this height of the ground [m] is on it
SETTLE_SPEED = 1e-6  # a touchdown slower than this [m/s] settles the robot into contact
ROOT_TIME = 1e-12  # event location: bracket length [s]
_ROOT_ITERATIONS = 100

# columns of the accumulator row of one control step
(
    ACC_IMPULSE_X, ACC_IMPULSE_Y,  # integral of the contact force over the continuous modes [N s]
    ACC_KICK_X, ACC_KICK_Y,  # sum of impact impulses [N s]
    ACC_STICK_TIME, ACC_SLIP_TIME, ACC_FLIGHT_TIME,  # [s]
    ACC_SLIP_DISTANCE,  # [m]
    ACC_WORK, ACC_SLIP_DISSIPATION, ACC_IMPACT_DISSIPATION,  # [J]
    ACC_EVENTS, ACC_PAINLEVE, ACC_SETTLES,  # counts
    ACC_WORK_LOAD,  # work of the horizontal force on the torso's COM, F (x_b(end) - x_b(start)) [J]
    ACC_DIM,
) = range(16)  # fmt: skip


@njit(cache=CACHE, inline="always")
def _is_slip(mode):
    return mode == SLIP_FORWARD or mode == SLIP_BACKWARD


@njit(cache=CACHE, inline="always")
def _sigma(mode):
    return 1.0 if mode == SLIP_FORWARD else -1.0


@njit(cache=CACHE, inline="always")
def _foot(X, p):
    """Foot position and velocity ``(x_f, y_f, x_f', y_f')`` of the packed state ``X``."""
    l1, l2 = p[6], p[7]
    s1, co1, s2, co2 = X[10], X[11], X[12], X[13]
    w1 = X[7] + X[8]
    w2 = w1 + X[9]
    vfx, vfy = _foot_velocity(s1, co1, s2, co2, X[5], X[6], w1, w2, p)
    return X[0] + l1 * co1 + l2 * co2, X[1] + l1 * s1 + l2 * s2, vfx, vfy


@njit(cache=CACHE, inline="always")
def _rates(X):
    return X[7] + X[8], X[7] + X[8] + X[9]


@njit(cache=CACHE, inline="always")
def _derivative(mode, mu, X, t_hip, t_knee, p):
    w1, w2 = _rates(X)
    return _accel(mode, mu, X[10], X[11], X[12], X[13], w1, w2, t_hip, t_knee, p)


# ---------------------------------------------------------------- witnesses (one per transition)


@njit(cache=CACHE, inline="always")
def _liftoff_witness(lam_y):
    """Normal force: compressive (``> 0``) to tensile; Drake's ``NormalForceWitness``."""
    return lam_y


@njit(cache=CACHE, inline="always")
def _slip_onset_witness(lam_x, lam_y, mu):
    """Sticking slack ``mu lam_y - |lam_x|``: the stick force leaves the friction cone."""
    return mu * lam_y - abs(lam_x)


@njit(cache=CACHE, inline="always")
def _sliding_stop_witness(vfx, sigma):
    """Sliding velocity ``sigma x_f'``: the slip comes to rest."""
    return sigma * vfx


@njit(cache=CACHE, inline="always")
def _touchdown_witness(y_f, ground):
    """Foot height above the ground: reaching it moving down."""
    return y_f - ground


@njit(cache=CACHE, inline="always")
def _witnesses(mode, mu, X, k, anchor, p):
    """The mode's two witnesses at ``X`` (``k``: its derivative and force there); ``inf`` fills a missing one.

    stick: (``LIFTOFF``, ``SLIP_ONSET``); slip: (``LIFTOFF``, ``SLIDING_STOP``); flight: (``TOUCHDOWN``, -).
    """
    if mode == FLIGHT:
        return _touchdown_witness(_foot(X, p)[1], anchor[1]), np.inf
    if mode == STICK:
        return _liftoff_witness(k[6]), _slip_onset_witness(k[5], k[6], mu)
    return _liftoff_witness(k[6]), _sliding_stop_witness(_foot(X, p)[2], _sigma(mode))


@njit(cache=CACHE, inline="always")
def _event_kinds(mode):
    if mode == FLIGHT:
        return TOUCHDOWN, -1
    if mode == STICK:
        return LIFTOFF, SLIP_ONSET
    return LIFTOFF, SLIDING_STOP


@njit(cache=CACHE, inline="always")
def _watched(kind, settled, events):
    """Whether a transition is watched: leaving contact is off once settled, everything past the hard cap."""
    if kind < 0 or events >= 2 * MAX_EVENTS:
        return False
    return not (settled and (kind == LIFTOFF or kind == SLIP_ONSET))


# ---------------------------------------------------------------- reset maps and mode choice


@njit(cache=CACHE)
def _kick(X, Px, Py, p, acc):
    """Apply the foot impulse ``P`` to ``X``'s velocity; book it and the kinetic energy it removes."""
    s1, co1, s2, co2 = X[10], X[11], X[12], X[13]
    _, _, _, B1x, B1y, B2x, B2y, _, _, _, _ = _foot_response(s1, co1, s2, co2, p)
    _, _, vfx0, vfy0 = _foot(X, p)
    d0, d1, d2, d3, d4 = _impulse_velocity(s1, co1, s2, co2, B1x, B1y, B2x, B2y, Px, Py, p)
    X = (X[0], X[1], X[2], X[3], X[4], X[5] + d0, X[6] + d1, X[7] + d2, X[8] + d3, X[9] + d4, s1, co1, s2, co2)
    _, _, vfx1, vfy1 = _foot(X, p)
    acc[ACC_KICK_X] += Px
    acc[ACC_KICK_Y] += Py
    acc[ACC_IMPACT_DISSIPATION] += -0.5 * (Px * (vfx0 + vfx1) + Py * (vfy0 + vfy1))  # Delta T = P . (v- + v+) / 2
    return X


@njit(cache=CACHE)
def _stop_foot(X, p, acc):
    """The sticking impulse ``-Lambda^-1 v_f``: the foot at rest."""
    Lxx, Lxy, Lyy, _, _, _, _, _, _, _, _ = _foot_response(X[10], X[11], X[12], X[13], p)
    _, _, vfx, vfy = _foot(X, p)
    Px, Py, _ = _impact_core(vfx, vfy, np.inf, Lxx, Lxy, Lyy)
    return _kick(X, Px, Py, p, acc)


@njit(cache=CACHE)
def _choose_mode(mode, X, anchor, t_hip, t_knee, mu, p, exclude, settled, acc):
    """The consistent mode at ``X`` (module docstring); applies the impulses it needs.

    ``mode`` is the current one (a stick that stays keeps its anchor), ``exclude`` a mode that a
    transition has just made inconsistent (or -1). Returns ``(mode, X)`` and updates ``anchor[0]``.
    """
    _, y_f, vfx, vfy = _foot(X, p)
    if y_f - anchor[1] > GROUND_TOL or vfy > REST_SPEED:
        return FLIGHT, X
    s1, co1, s2, co2 = X[10], X[11], X[12], X[13]
    if vfy < -REST_SPEED:  # hitting the ground: the impact first
        Lxx, Lxy, Lyy, _, _, _, _, _, _, _, _ = _foot_response(s1, co1, s2, co2, p)
        Px, Py, status = _impact_core(vfx, vfy, mu, Lxx, Lxy, Lyy)
        if status == IMPACT_PAINLEVE:
            acc[ACC_PAINLEVE] += 1.0
        X = _kick(X, Px, Py, p, acc)
        _, _, vfx, vfy = _foot(X, p)
    w1, w2 = _rates(X)
    new = -1
    if abs(vfx) > REST_SPEED:
        new, painleve = _mode_sliding(s1, co1, s2, co2, w1, w2, t_hip, t_knee, mu, 1.0 if vfx > 0.0 else -1.0, p)
        if painleve:
            acc[ACC_PAINLEVE] += 1.0
        if new < 0:  # no consistent force: a tangential impact stops the foot
            X = _stop_foot(X, p, acc)
        elif new == FLIGHT and settled:
            new = SLIP_FORWARD if vfx > 0.0 else SLIP_BACKWARD
            acc[ACC_SETTLES] += 1.0
    if new < 0:  # at rest
        new, painleve = _mode_at_rest(s1, co1, s2, co2, w1, w2, t_hip, t_knee, mu, p, exclude)
        if painleve:
            acc[ACC_PAINLEVE] += 1.0
        if new == FLIGHT and settled:
            new = STICK
            acc[ACC_SETTLES] += 1.0
    if new == STICK:
        x_f, y_f, vfx, vfy = _foot(X, p)
        if mode != STICK:
            anchor[0] = x_f
        if vfx != 0.0 or vfy != 0.0:
            X = _stop_foot(X, p, acc)
    return new, X


@njit(cache=CACHE)
def _locate(mode, mu, X, k, h, X1, k1, lx1, ly1, pw1, t_hip, t_knee, anchor, p, watch_a, watch_b):
    """Earliest crossing of the watched witnesses inside the substep ``X -> X1`` of length ``h``.

    Illinois regula falsi on the substep length ``s`` (one RK4 step from ``X`` with the same stage-1
    derivative ``k``); for a touchdown, Newton steps on the foot height with its velocity as the
    derivative, kept inside the bracket (the notes' recipe: 2-3 steps instead of about 10). Returns ``(s, X_s, k_s, lx, ly, power, kind)`` at the bracket's end past the root.
    """
    wa, wb = _witnesses(mode, mu, X, k, anchor, p)
    fa = min(wa if watch_a else np.inf, wb if watch_b else np.inf)
    wa, wb = _witnesses(mode, mu, X1, k1, anchor, p)
    fb = min(wa if watch_a else np.inf, wb if watch_b else np.inf)
    a, b = 0.0, h
    Xb, kb, lxb, lyb, pwb = X1, k1, lx1, ly1, pw1
    side = 0
    s_next = -1.0  # a Newton proposal for the touchdown witness, whose derivative is the foot's y velocity
    for _ in range(_ROOT_ITERATIONS):
        if b - a <= ROOT_TIME:
            break
        s = s_next if a < s_next < b else b - fb * (b - a) / (fb - fa)
        if not (a < s < b):
            s = 0.5 * (a + b)
        Xs, lxs, lys, pws = _rk4_substep(mode, mu, anchor, X, k, s, t_hip, t_knee, p, 0.0, 0.0)
        ks = _derivative(mode, mu, Xs, t_hip, t_knee, p)
        wa, wb = _witnesses(mode, mu, Xs, ks, anchor, p)
        fs = min(wa if watch_a else np.inf, wb if watch_b else np.inf)
        if fs < 0.0:
            b, fb, Xb, kb, lxb, lyb, pwb = s, fs, Xs, ks, lxs, lys, pws
            if side == -1:
                fa *= 0.5
            side = -1
        else:
            a, fa = s, fs
            if side == 1:
                fb *= 0.5
            side = 1
        s_next = -1.0
        if mode == FLIGHT:
            vfy = _foot(Xs, p)[3]
            if vfy < 0.0:  # Newton, nudged past the root so that the bracket closes
                s_next = s - fs / vfy + (0.25 * ROOT_TIME if fs >= 0.0 else -0.25 * ROOT_TIME)
    wa, wb = _witnesses(mode, mu, Xb, kb, anchor, p)
    kind_a, kind_b = _event_kinds(mode)
    if watch_b and (not watch_a or wb < wa):
        return b, Xb, kb, lxb, lyb, pwb, kind_b
    return b, Xb, kb, lxb, lyb, pwb, kind_a


@njit(cache=CACHE)
def _transition(kind, mode, X, anchor, t_hip, t_knee, mu, p, settled, acc):
    """The reset map of event ``kind`` at ``X`` (just past it), then the mode choice; returns ``(mode, X, settled)``."""
    if kind == TOUCHDOWN:
        _, y_f, _, vfy = _foot(X, p)
        X = (X[0], X[1] - (y_f - anchor[1]), X[2], X[3], X[4], X[5], X[6], X[7], X[8], X[9], X[10], X[11], X[12], X[13])
        if -vfy < SETTLE_SPEED and not settled:
            settled = True
            acc[ACC_SETTLES] += 1.0
    elif kind == SLIDING_STOP:
        X = _stop_foot(X, p, acc)
    new, X = _choose_mode(mode, X, anchor, t_hip, t_knee, mu, p, mode if kind != TOUCHDOWN else -1, settled, acc)
    return new, X, settled


@njit(cache=CACHE, inline="always")
def _book(mode, h, X0, X1, lx, ly, power, p, acc):
    """Add a substep of length ``h`` in ``mode`` from ``X0`` to ``X1`` to the accumulators."""
    acc[ACC_IMPULSE_X] += h * lx
    acc[ACC_IMPULSE_Y] += h * ly
    if mode == STICK:
        acc[ACC_STICK_TIME] += h
    elif mode == FLIGHT:
        acc[ACC_FLIGHT_TIME] += h
    else:
        acc[ACC_SLIP_TIME] += h
        acc[ACC_SLIP_DISTANCE] += _sigma(mode) * (_foot(X1, p)[0] - _foot(X0, p)[0])
        acc[ACC_SLIP_DISSIPATION] += h * power


@njit(cache=CACHE, inline="always")
def _steady(mode, mu, anchor, X, k, t, t_left, n_left, t_hip, t_knee, p, acc):
    """Substeps in ``mode`` while no witness of it is negative at a substep's end.

    A substep that ends with one negative is not taken: the general loop of ``_hybrid_from`` redoes it
    from the same state, with the same arithmetic, and locates the event. Called with ``mode`` a
    constant, so that the compiler specialises the RK4 stages to that mode's dynamics.
    """
    while n_left > 0:
        h = t_left / n_left
        X1, lx, ly, power = _rk4_substep(mode, mu, anchor, X, k, h, t_hip, t_knee, p, 0.0, 0.0)
        k1 = _derivative(mode, mu, X1, t_hip, t_knee, p)
        w1a, w1b = _witnesses(mode, mu, X1, k1, anchor, p)
        if w1a < 0.0 or w1b < 0.0:
            break
        _book(mode, h, X, X1, lx, ly, power, p, acc)
        X, k = X1, k1
        t += h
        t_left -= h
        n_left -= 1
    return X, k, t, t_left, n_left


@njit(cache=CACHE, inline="always")
def _hybrid_from(q, qd, tau, p, mu, mode, anchor, dt, substeps, max_angle, s1, co1, s2, co2, acc, log_t, log_k):
    """One hybrid control step of one robot, in place; returns the mode at its end.

    ``q, qd`` (5,) world state, ``anchor`` (2,) the stick contact point (``anchor[1]`` is the ground's
    height; ``anchor[0]`` is rewritten: the contact point in stick, else the foot's ``x``), ``s1 ... co2``
    the sines/cosines of ``q``'s link angles. ``acc`` (``ACC_DIM``,) and ``log_t``, ``log_k``
    (``LOG_SIZE``,): ``acc`` is overwritten with the step's accumulators, and the first
    ``acc[ACC_EVENTS]`` entries of the log with its events (time since the step start, and kind).
    """
    t_hip, t_knee = tau[0], tau[1]
    for j in range(acc.shape[0]):
        acc[j] = 0.0
    X = (q[0], q[1], q[2], q[3], q[4], qd[0], qd[1], qd[2], qd[3], qd[4], s1, co1, s2, co2)
    settled = False
    events = 0
    # the mode under this step's torques: a stick that stays consistent, or a foot in the air, keeps its
    # mode without the full choice (the common cases); anything else goes through _choose_mode
    k = _derivative(mode, mu, X, t_hip, t_knee, p)
    keep = False
    if mode == STICK:
        keep = k[6] >= 0.0 and mu * k[6] - abs(k[5]) >= 0.0
    elif mode == FLIGHT:
        _, y_f, _, vfy = _foot(X, p)
        keep = y_f - anchor[1] > GROUND_TOL or vfy > REST_SPEED
    if not keep:
        mode, X = _choose_mode(mode, X, anchor, t_hip, t_knee, mu, p, -1, settled, acc)
        k = _derivative(mode, mu, X, t_hip, t_knee, p)
    t = 0.0
    t_left = dt
    n_left = _substeps_for_rates(X[7], X[8], X[9], dt, substeps, max_angle)
    # the common cases (a stick while balancing, a flight) with the mode a constant, which the compiler
    # specialises; the general loop below goes on from where they stop
    if mode == STICK:
        X, k, t, t_left, n_left = _steady(STICK, mu, anchor, X, k, t, t_left, n_left, t_hip, t_knee, p, acc)
    elif mode == FLIGHT:
        X, k, t, t_left, n_left = _steady(FLIGHT, mu, anchor, X, k, t, t_left, n_left, t_hip, t_knee, p, acc)
    kind_a, kind_b = _event_kinds(mode)
    w0a, w0b = _witnesses(mode, mu, X, k, anchor, p)  # carried from substep to substep
    while n_left > 0:
        h = t_left / n_left
        X1, lx, ly, power = _rk4_substep(mode, mu, anchor, X, k, h, t_hip, t_knee, p, 0.0, 0.0)
        k1 = _derivative(mode, mu, X1, t_hip, t_knee, p)
        w1a, w1b = _witnesses(mode, mu, X1, k1, anchor, p)
        watch_a = _watched(kind_a, settled, events) and w0a >= 0.0
        watch_b = _watched(kind_b, settled, events) and w0b >= 0.0
        if not ((watch_a and w1a < 0.0) or (watch_b and w1b < 0.0)):
            _book(mode, h, X, X1, lx, ly, power, p, acc)
            X, k, w0a, w0b = X1, k1, w1a, w1b
            t += h
            t_left -= h
            n_left -= 1
            continue
        s, Xs, ks, lx, ly, power, kind = _locate(
            mode, mu, X, k, h, X1, k1, lx, ly, power, t_hip, t_knee, anchor, p, watch_a, watch_b
        )
        _book(mode, s, X, Xs, lx, ly, power, p, acc)
        t += s
        t_left -= s
        if events < log_t.shape[0]:
            log_t[events] = t
            log_k[events] = kind
        events += 1
        if events >= MAX_EVENTS and not settled:
            settled = True
            acc[ACC_SETTLES] += 1.0
        mode, X, settled = _transition(kind, mode, Xs, anchor, t_hip, t_knee, mu, p, settled, acc)
        # the rest of the step in the new mode, by the step rule at the post-event rates
        n_left = max(n_left, _substeps_for_rates(X[7], X[8], X[9], t_left, 1, max_angle))
        k = _derivative(mode, mu, X, t_hip, t_knee, p)
        kind_a, kind_b = _event_kinds(mode)
        w0a, w0b = _witnesses(mode, mu, X, k, anchor, p)
    if mode != STICK:
        anchor[0] = _foot(X, p)[0]
    acc[ACC_EVENTS] = events
    acc[ACC_WORK] = t_hip * (X[3] - q[3]) + t_knee * (X[4] - q[4])
    acc[ACC_WORK_LOAD] = p[LOAD_X] * (X[0] - q[0])  # exact: F constant over the step, x_b continuous
    for j in range(5):
        q[j] = X[j]
        qd[j] = X[5 + j]
    return mode


@njit(cache=CACHE)
def _hybrid_batch(q, qd, tau, p, load, mu, mode, anchor, dt, substeps, max_angle, acc, log_t, log_k):
    pi = p.copy()
    for i in range(q.shape[0]):
        th1 = q[i, 2] + q[i, 3]
        th2 = th1 + q[i, 4]
        pi[LOAD_X] = load[i]
        mode[i] = _hybrid_from(
            q[i], qd[i], tau[i], pi, mu[i], mode[i], anchor[i], dt, substeps, max_angle,
            np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2), acc[i], log_t[i], log_k[i],
        )  # fmt: skip


class HybridStep(NamedTuple):
    """What ``hybrid_step`` returns; every field has the batch's leading shape ``(...)`` first."""

    q: np.ndarray  # (..., 5) configuration at the end of the step
    qd: np.ndarray  # (..., 5) velocity at the end of the step
    mode: np.ndarray  # (...) int, contact mode at the end (leg_env.contact constants)
    anchor_x: np.ndarray  # (...) the stick contact point's x, else the foot's x [m]
    lam_mean: np.ndarray  # (..., 2) mean contact force over the step, impulses excluded [N]
    impulse: np.ndarray  # (..., 2) sum of impact (and tangential) impulses on the foot [N s]
    stick_time: np.ndarray  # (...) [s]
    slip_time: np.ndarray  # (...) [s]
    flight_time: np.ndarray  # (...) [s]
    slip_distance: np.ndarray  # (...) [m]
    work: np.ndarray  # (...) actuator work [J]
    work_load: np.ndarray  # (...) work of the horizontal force on the torso's COM [J]
    slip_dissipation: np.ndarray  # (...) energy dissipated by sliding friction [J]
    impact_dissipation: np.ndarray  # (...) kinetic energy lost in impulses [J]
    events: np.ndarray  # (...) int, located transitions
    painleve: np.ndarray  # (...) int, uses of the Painleve rule
    settles: np.ndarray  # (...) int, Zeno settles
    event_time: np.ndarray  # (..., LOG_SIZE) time of each event since the step's start [s], NaN after the last
    event_kind: np.ndarray  # (..., LOG_SIZE) int, LIFTOFF / SLIP_ONSET / SLIDING_STOP / TOUCHDOWN, -1 after the last


def _initial_modes(qf, qdf, tf, mu, p: LegParams) -> np.ndarray:
    """Modes of states given without one: flight above the ground, else the contact's consistent mode."""
    from .contact import contact_mode
    from .dynamics import foot_position

    mode = np.where(foot_position(qf, p)[:, 1] > GROUND_TOL, FLIGHT, STICK).astype(np.int64)
    on = mode == STICK
    if on.any():
        mode[on] = contact_mode(qf[on], qdf[on], tf[on], p, mu[on])
    return mode


def hybrid_step(
    q, qd, tau, p: LegParams, mu, mode=None, anchor_x=None, dt: float = DT, substeps: int = SUBSTEPS, max_angle: float = MAX_ANGLE,
    load_x=0.0,
) -> HybridStep:
    """One control step of the leg on the unilateral ground ``y = 0`` (module docstring).

    Args:
        q, qd: ``(..., 5)`` world state; the foot must not be below the ground by more than ``GROUND_TOL``.
        tau: ``(..., 2)`` hip and knee torques held over the step [N m].
        p: physical parameters. mu: friction coefficient (>= 0, finite), scalar or per robot.
        mode: ``(...)`` contact modes (``leg_env.contact`` constants) or None: flight for a foot above
            ``GROUND_TOL``, else ``contact_mode`` under ``tau``. The step re-chooses it anyway where
            the state requires (a stick keeps its anchor).
        anchor_x: ``(...)`` stick contact points [m]; None: the feet's current ``x``.
        dt, substeps, max_angle: the step rule of ``leg_env.integrate.stance_step``.
        load_x: ``(...)`` or scalar horizontal force on the torso's COM held over the step [N] (a push:
            ``M qdd + h = S^T tau + Jc^T lam + (F, 0, 0, 0, 0)``, ``leg_env.dynamics``); its work is ``work_load``.

    Returns:
        ``HybridStep``: the new state and mode, and what the step did.
    """
    from .contact import _checked_mu
    from .dynamics import foot_position

    dt, substeps, max_angle = _checked_steps(dt, substeps, max_angle)
    lead, (qf, qdf, tf) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"), _vec(tau, NU, "tau"))
    qf, qdf = qf.copy(), qdf.copy()
    n = qf.shape[0]
    mu_f = _checked_mu(mu, lead)
    foot = foot_position(qf, p)
    if np.any(foot[:, 1] < -GROUND_TOL):
        raise ValueError(f"the foot is below the ground (y_f = {foot[:, 1].min():.3e} m < -{GROUND_TOL} m)")
    if mode is None:
        modes = _initial_modes(qf, qdf, tf, mu_f, p)
    else:
        modes = np.ascontiguousarray(np.broadcast_to(np.asarray(mode, dtype=np.int64), lead).reshape(-1)).copy()
        if np.any((modes < STICK) | (modes > FLIGHT)):
            raise ValueError(f"mode must be one of STICK, SLIP_FORWARD, SLIP_BACKWARD, FLIGHT (0-3), got {mode!r}")
    anchor = np.zeros((n, 2))
    anchor[:, 0] = foot[:, 0] if anchor_x is None else np.broadcast_to(np.asarray(anchor_x, dtype=np.float64), lead).reshape(-1)
    acc = np.empty((n, ACC_DIM))
    log_t = np.full((n, LOG_SIZE), np.nan)
    log_k = np.full((n, LOG_SIZE), -1, dtype=np.int64)
    load = np.ascontiguousarray(np.broadcast_to(np.asarray(load_x, dtype=np.float64), lead).reshape(-1))
    if not np.all(np.isfinite(load)):
        raise ValueError("load_x must be finite")
    _hybrid_batch(qf, qdf, tf, _kernel_params(p), load, mu_f, modes, anchor, dt, substeps, max_angle, acc, log_t, log_k)

    def r(x, tail=()):
        return x.reshape(lead + tail)

    return HybridStep(
        q=r(qf, (NQ,)),
        qd=r(qdf, (NQ,)),
        mode=r(modes),
        anchor_x=r(anchor[:, 0].copy()),
        lam_mean=r(acc[:, ACC_IMPULSE_X:ACC_IMPULSE_Y + 1] / dt, (2,)),
        impulse=r(acc[:, ACC_KICK_X:ACC_KICK_Y + 1].copy(), (2,)),
        stick_time=r(acc[:, ACC_STICK_TIME].copy()),
        slip_time=r(acc[:, ACC_SLIP_TIME].copy()),
        flight_time=r(acc[:, ACC_FLIGHT_TIME].copy()),
        slip_distance=r(acc[:, ACC_SLIP_DISTANCE].copy()),
        work=r(acc[:, ACC_WORK].copy()),
        work_load=r(acc[:, ACC_WORK_LOAD].copy()),
        slip_dissipation=r(acc[:, ACC_SLIP_DISSIPATION].copy()),
        impact_dissipation=r(acc[:, ACC_IMPACT_DISSIPATION].copy()),
        events=r(acc[:, ACC_EVENTS].astype(np.int64)),
        painleve=r(acc[:, ACC_PAINLEVE].astype(np.int64)),
        settles=r(acc[:, ACC_SETTLES].astype(np.int64)),
        event_time=r(log_t, (LOG_SIZE,)),
        event_kind=r(log_k, (LOG_SIZE,)),
    )
