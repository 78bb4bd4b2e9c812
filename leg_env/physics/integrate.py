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

Every function here runs in the compiled core (``leg_env/_core``, C, built at install); this module
broadcasts and validates the arrays around it.
"""

from __future__ import annotations

import math

import numpy as np

from .. import checks
from .._core import kernels
from .arrays import F64, LOAD_X, NP, NQ, NU, batched, core_params, finite_rows, params_array, single_robot, vec
from .dynamics import contact_jacobian, foot_position
from .params import LegParams

DT = 0.01  # default control period [s]
SUBSTEPS = 2  # default least number of RK4 steps per control period
MAX_ANGLE = 0.02  # default largest link rotation per RK4 step [rad]
MAX_SUBSTEPS = 4096  # most RK4 steps per control period: the step rule's cap, and the largest accepted ``substeps``

__all__ = ["stance_step", "flight_step", "project_stance", "project_velocity", "step_inplace"]


def step_inplace(q, qd, tau, p, anchor, dt, substeps, max_angle, stance, lam_mean):
    """Advance a batch by one control step in place (the compiled core's RK4 step).

    Args:
        q, qd: ``(N, 5)`` C-contiguous float64 states, overwritten.
        tau: ``(N, 2)`` torques held over the step.
        p: ``(11,)`` parameter array (``LegParams.array``: no load), or ``(12,)`` with the horizontal force
            on the torso's COM last (``leg_env.physics.dynamics.params_array(p, load_x)``).
        anchor: ``(N, 2)`` foot contact points (read only in stance).
        dt: control period [s]; substeps: least number of RK4 steps per control period.
        max_angle: largest rotation [rad] of any link per RK4 step at the step's initial
            rates; fast motions get more RK4 steps (``np.inf`` gives fixed steps).
        stance: True for the pinned-foot model, False for flight.
        lam_mean: ``(N, 2)`` output, mean contact force over the step (zero in flight).

    Raises:
        ValueError: ``p`` has another length, an array has the wrong shape, type or order, or a setting of
            the step rule is out of range (the message names it).
    """
    p = params_array(p)  # real numbers, 11 valid LegParams fields (or 12 with the load): the error names p or the field
    try:
        n = np.asarray(q).size // NQ  # the robots q holds, if its size is a multiple of 5 (the core says so if not)
    except (TypeError, ValueError):
        n = 0
    load = np.full(n, p[LOAD_X] if p.shape[0] > NP else 0.0)
    kernels.rk4_step(q, qd, tau, np.ascontiguousarray(p[:NP]), load, anchor, dt, substeps, max_angle, stance, lam_mean)


def checked_steps(dt: float, substeps: int, max_angle: float) -> tuple[float, int, float]:
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

    Raises:
        ValueError: an array of the wrong shape, or holding NaN or inf, or a setting of the step rule out of range
            (the message names it; nothing is changed).
    """
    dt, substeps, max_angle = checked_steps(dt, substeps, max_angle)
    if single_robot(q, qd, tau):
        # one robot: the same kernel on (1, n) views, without the broadcasting machinery
        if anchor is None:
            anchor = foot_position(q, p)
        if type(anchor) is np.ndarray and anchor.shape == (2,) and anchor.dtype is F64 and anchor.flags.c_contiguous and anchor.flags.aligned:
            if not math.isfinite(sum(q.tolist()) + sum(qd.tolist()) + sum(tau.tolist()) + sum(anchor.tolist())):
                # one test for the fast path (a sum that overflows finite entries: finite_rows passes them)
                finite_rows(("q", q[None]), ("qd", qd[None]), ("tau", tau[None]), ("anchor", anchor[None]))
            q1, qd1, lam = q.reshape(1, NQ).copy(), qd.reshape(1, NQ).copy(), np.empty((1, 2))
            step_inplace(q1, qd1, tau.reshape(1, NU), core_params(p), anchor.reshape(1, 2), dt, substeps, max_angle,
                         True, lam)
            return q1[0], qd1[0], lam[0]
    q = vec(q, NQ, "q")
    anchor = foot_position(q, p) if anchor is None else vec(anchor, 2, "anchor")
    lead, (qf, qdf, tf, af) = batched(("q", q), ("qd", vec(qd, NQ, "qd")), ("tau", vec(tau, NU, "tau")), ("anchor", anchor))
    finite_rows(("q", qf), ("qd", qdf), ("tau", tf), ("anchor", af))
    qf, qdf = qf.copy(), qdf.copy()
    lam = np.empty((qf.shape[0], 2))
    step_inplace(qf, qdf, tf, core_params(p), af, dt, substeps, max_angle, True, lam)
    return qf.reshape(lead + (NQ,)), qdf.reshape(lead + (NQ,)), lam.reshape(lead + (2,))


def flight_step(q, qd, tau, p: LegParams, dt: float = DT, substeps: int = SUBSTEPS, max_angle: float = MAX_ANGLE):
    """One flight control step (no contact) of RK4, stepped as in ``stance_step``. Returns ``(q_next, qd_next)``.

    Raises:
        ValueError: as ``stance_step``.
    """
    dt, substeps, max_angle = checked_steps(dt, substeps, max_angle)
    lead, (qf, qdf, tf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")), ("tau", vec(tau, NU, "tau")))
    finite_rows(("q", qf), ("qd", qdf), ("tau", tf))
    qf, qdf = qf.copy(), qdf.copy()
    lam = np.empty((qf.shape[0], 2))
    step_inplace(qf, qdf, tf, core_params(p), np.zeros((qf.shape[0], 2)), dt, substeps, max_angle, False, lam)
    return qf.reshape(lead + (NQ,)), qdf.reshape(lead + (NQ,))


def project_stance(q, qd, p: LegParams, anchor):
    """Coordinate-partitioning projection: move only the base so the foot is at ``anchor`` and ``Jc qd = 0``."""
    lead, (qf, qdf, af) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")), ("anchor", vec(anchor, 2, "anchor")))
    qf, qdf = qf.copy(), qdf.copy()
    kernels.project(qf, qdf, core_params(p), af)
    return qf.reshape(lead + (NQ,)), qdf.reshape(lead + (NQ,))


def project_velocity(q, qd, p: LegParams) -> np.ndarray:
    """Euclidean projection of ``qd`` onto the nullspace of ``Jc(q)``: ``qd - Jc^T (Jc Jc^T)^-1 Jc qd`` (solved)."""
    lead, (qf, qdf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")))
    Jc = contact_jacobian(qf, p)
    JJt = Jc @ np.swapaxes(Jc, -1, -2)
    y = np.linalg.solve(JJt, (Jc @ qdf[..., None]))
    return (qdf - (np.swapaxes(Jc, -1, -2) @ y)[..., 0]).reshape(lead + (NQ,))
