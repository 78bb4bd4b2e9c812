r"""The hybrid control step: exact unilateral contact with event-located transitions (lesson section 5).

The foot is in one of the modes of ``leg_env.physics.contact`` (stick, slip forward / backward, flight), carried
as state with the stick contact point ``anchor``; the ground is the line ``y = anchor[1]`` (``0`` in
the environments). A control step of length ``dt`` holds the torques and is integrated by RK4
substeps in the current mode (``leg_env.physics.integrate._rk4_substep``: the same step rule and the same
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

Mode choice (``leg_env.physics.contact``), at the start of every control step (the torques jump there) and
after every reset map: a foot above the ground, or leaving it, flies; a foot hitting the ground gets
the impact map first; a sliding foot slips or flies; a foot at rest gets the one consistent mode of
the four closed forms. Past the Painleve bound the documented rule of ``leg_env.physics.contact`` applies
(stick "jam", or flight, or a tangential sticking impulse) and is counted.

Zeno: at most ``MAX_EVENTS`` (8) located events per control step. After that the robot is
"settled" for the rest of the step: the contact-leaving witnesses (``LIFTOFF``, ``SLIP_ONSET``) are
off and a foot on the ground stays in contact; a flying foot still lands and a sliding one still
stops (at most ``2 MAX_EVENTS`` events in all). A touchdown slower than ``SETTLE_SPEED`` (1e-6 m/s)
also settles the robot into contact for the rest of the step. Every settle is counted.

What a step accumulates (``HybridStep``'s fields; the compiled core's ``leg_record``): the contact impulse of the continuous modes
(its mean over the step is the mean contact force, impacts excluded), the sum of impact impulses,
the time in each mode, the slip distance, the actuator work ``tau . (q1, q2)(end) - (q1, q2)(start)``
(exact: the joint angles are continuous and the torques constant), the friction dissipation (RK4
quadrature of ``-lam_x x_f'``), the kinetic energy lost in impulses and the work of a horizontal force
``F = p[LOAD_X]`` on the torso's COM (a push, held over the step like the torques:
``F (x_b(end) - x_b(start))``, exact), so that
``E(end) - E(start) = work + work_load - slip_dissipation - impact_dissipation`` up to the RK4 error.
The force enters every mode's dynamics and so every witness and mode choice; impulses are unaffected
(a finite force does no impulsive work). ``rk4_steps`` counts the step's work: the RK4 steps it integrated, the
step rule's (``leg_env.physics.integrate``) plus, for each located event, the substep that crossed it and the shorter
re-integrations that located it.

Every function here runs in the compiled core (``leg_env/_core``, C, built at install); this module
broadcasts and validates the arrays around it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .. import checks
from .._core import kernels
from .arrays import F64, NQ, NU, batched, core_params, finite_rows, vec
from .contact import FLIGHT, SLIP_BACKWARD, SLIP_FORWARD, STICK, checked_mu, scalar_field, contact_mode
from .dynamics import foot_position
from .integrate import DT, MAX_ANGLE, SUBSTEPS, checked_steps
from .layout import RECORD
from .params import LegParams

__all__ = ["hybrid_step", "HybridStep", "LIFTOFF", "SLIP_ONSET", "SLIDING_STOP", "TOUCHDOWN", "EVENT_NAMES",
           "MAX_EVENTS", "LOG_SIZE", "GROUND_TOL", "SETTLE_SPEED", "ROOT_TIME"]

LIFTOFF, SLIP_ONSET, SLIDING_STOP, TOUCHDOWN = kernels.LIFTOFF, kernels.SLIP_ONSET, kernels.SLIDING_STOP, kernels.TOUCHDOWN
EVENT_NAMES = ("liftoff", "slip_onset", "sliding_stop", "touchdown")
MAX_EVENTS = kernels.MAX_EVENTS  # located events per control step before the robot is settled (Zeno guard): 8
LOG_SIZE = kernels.LOG_SIZE  # events per step can reach 2 MAX_EVENTS; each is logged
GROUND_TOL = kernels.GROUND_TOL  # a foot within this height of the ground [m] is on it: 1e-9
SETTLE_SPEED = kernels.SETTLE_SPEED  # a touchdown slower than this [m/s] settles the robot into contact: 1e-6
ROOT_TIME = kernels.ROOT_TIME  # event location: bracket length [s]: 1e-12


class HybridStep(NamedTuple):
    """What ``hybrid_step`` returns; every field has the batch's leading shape ``(...)`` first."""

    q: np.ndarray  # (..., 5) configuration at the end of the step
    qd: np.ndarray  # (..., 5) velocity at the end of the step
    mode: np.ndarray  # (...) int, contact mode at the end (leg_env.physics.contact constants)
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
    rk4_steps: np.ndarray  # (...) int, RK4 steps integrated, the re-integrations that located the events included


def _initial_modes(qf, qdf, tf, mu, p: LegParams) -> np.ndarray:
    """Modes of states given without one: flight above the ground, else the contact's consistent mode."""
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
        mode: ``(...)`` contact modes (``leg_env.physics.contact`` constants) or None: flight for a foot above
            ``GROUND_TOL``, else ``contact_mode`` under ``tau``. The step re-chooses it anyway where
            the state requires (a stick keeps its anchor).
        anchor_x: ``(...)`` stick contact points [m]; None: the feet's current ``x``.
        dt, substeps, max_angle: the step rule of ``leg_env.physics.integrate.stance_step``.
        load_x: ``(...)`` or scalar horizontal force on the torso's COM held over the step [N] (a push:
            ``M qdd + h = S^T tau + Jc^T lam + (F, 0, 0, 0, 0)``, ``leg_env.physics.dynamics``); its work is ``work_load``.

    Returns:
        ``HybridStep``: the new state and mode, and what the step did.
    """
    call = prepared_call(q, qd, tau, p, mu, mode, anchor_x, dt, substeps, max_angle, load_x)
    kernels.hybrid_step(*call.arguments)
    return call.result()


class PreparedCall(NamedTuple):
    """A hybrid step's arguments checked and laid out for the compiled core (``prepared_call``)."""

    lead: tuple  # the call's leading shape
    arguments: tuple  # q, qd, tau, p, load, mu, mode, anchor, dt, substeps, max_angle, record: the core's order
    dt: float

    def result(self) -> "HybridStep":
        """The ``HybridStep`` the core wrote into the arguments."""
        qf, qdf, _, _, _, _, modes, anchor, _, _, _, record = self.arguments
        lead, dt = self.lead, self.dt

        def r(x, tail=()):
            return np.ascontiguousarray(x).reshape(lead + tail)

        return HybridStep(
            q=r(qf, (NQ,)),
            qd=r(qdf, (NQ,)),
            mode=r(modes),
            anchor_x=r(anchor[:, 0].copy()),
            lam_mean=r(record["impulse"] / dt, (2,)),
            impulse=r(record["kick"], (2,)),
            stick_time=r(record["stick_time"]),
            slip_time=r(record["slip_time"]),
            flight_time=r(record["flight_time"]),
            slip_distance=r(record["slip_distance"]),
            work=r(record["work"]),
            work_load=r(record["work_load"]),
            slip_dissipation=r(record["slip_dissipation"]),
            impact_dissipation=r(record["impact_dissipation"]),
            events=r(record["events"].astype(np.int64)),
            painleve=r(record["painleve"].astype(np.int64)),
            settles=r(record["settles"].astype(np.int64)),
            event_time=r(record["event_time"], (LOG_SIZE,)),
            event_kind=r(record["event_kind"].astype(np.int64), (LOG_SIZE,)),
            rk4_steps=r(record["rk4_steps"].astype(np.int64)),
        )


def _plain(a, n: int, width: int) -> bool:
    """``a`` is already what the core reads: a float64, C-ordered, aligned ``(n, width)`` array."""
    return (type(a) is np.ndarray and a.dtype is F64 and a.shape == (n, width) and a.flags.c_contiguous
            and a.flags.aligned)


def _fast_call(q, qd, tau, p, mu, mode, anchor_x, dt, substeps, max_angle, load_x) -> PreparedCall | None:
    """``prepared_call`` of the calls a controller's loop makes (``(N, 5)`` float64 states and ``(N, 2)`` torques
    as the core reads them, a robot's ``LegParams``, a number ``mu``, ``(N,)`` int64 modes, the anchors the feet's, a
    number or ``(N,)`` float64 load, the step rule's defaults), with one test each for what the full checks would
    refuse; None for any other call (the full checks then make it, or name what is wrong)."""
    n = q.shape[0] if type(q) is np.ndarray and q.ndim == 2 else -1
    if not (_plain(q, n, NQ) and _plain(qd, n, NQ) and _plain(tau, n, NU) and type(p) is LegParams and anchor_x is None
            and type(mode) is np.ndarray and mode.dtype == np.int64 and mode.shape == (n,)
            and type(mu) in (float, np.float64) and dt == DT and substeps == SUBSTEPS and max_angle == MAX_ANGLE):
        return None
    if type(load_x) in (float, np.float64):
        load = np.full(n, load_x)
    elif type(load_x) is np.ndarray and load_x.dtype is F64 and load_x.shape == (n,):
        load = load_x.copy()
    else:
        return None
    if n == 0 or not (math.isfinite(mu) and mu >= 0.0 and math.isfinite(float(q.sum() + qd.sum() + tau.sum() + load.sum()))
                      and int(mode.min()) >= 0 and int(mode.max()) <= 3):
        return None
    foot = np.empty((n, 2))
    kernels.foot(q, p.array, foot)
    if foot[:, 1].min() < -GROUND_TOL:
        return None
    anchor = np.zeros((n, 2))
    anchor[:, 0] = foot[:, 0]
    record = np.empty(n, dtype=RECORD)
    arguments = (q.copy(), qd.copy(), tau, p.array, load, np.full(n, float(mu)), mode.copy(), anchor, float(dt),
                 int(substeps), float(max_angle), record)
    return PreparedCall((n,), arguments, float(dt))


def prepared_call(q, qd, tau, p: LegParams, mu, mode, anchor_x, dt, substeps, max_angle, load_x) -> PreparedCall:
    """``hybrid_step``'s arguments checked (an error names the argument) and laid out for the compiled core."""
    fast = _fast_call(q, qd, tau, p, mu, mode, anchor_x, dt, substeps, max_angle, load_x)
    if fast is not None:
        return fast
    dt, substeps, max_angle = checked_steps(dt, substeps, max_angle)
    lead, (qf, qdf, tf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")), ("tau", vec(tau, NU, "tau")))
    qf, qdf = qf.copy(), qdf.copy()
    finite_rows(("q", qf), ("qd", qdf), ("tau", tf))
    n = qf.shape[0]
    mu_f = checked_mu(mu, lead)
    foot = foot_position(qf, p)
    if np.any(foot[:, 1] < -GROUND_TOL):
        raise ValueError(f"q puts the foot below the ground (y_f = {foot[:, 1].min():.3e} m < -{GROUND_TOL} m)")
    if mode is None:
        modes = _initial_modes(qf, qdf, tf, mu_f, p)
    else:
        m = scalar_field(mode, lead, "mode")
        if not np.all((m == STICK) | (m == SLIP_FORWARD) | (m == SLIP_BACKWARD) | (m == FLIGHT)):
            raise ValueError(f"mode must be one of STICK, SLIP_FORWARD, SLIP_BACKWARD, FLIGHT (0-3), got {checks.shown(mode)}")
        modes = m.astype(np.int64)
    anchor = np.zeros((n, 2))
    if anchor_x is None:
        anchor[:, 0] = foot[:, 0]
    else:
        anchor[:, 0] = scalar_field(anchor_x, lead, "anchor_x")
        if not np.all(np.isfinite(anchor[:, 0])):
            raise ValueError("anchor_x must be finite")
    load = scalar_field(load_x, lead, "load_x")
    if not np.all(np.isfinite(load)):
        raise ValueError("load_x must be finite")
    record = np.empty(n, dtype=RECORD)
    return PreparedCall(lead, (qf, qdf, tf, core_params(p), load, mu_f, modes, anchor, dt, substeps, max_angle, record), dt)

