r"""Exact derivatives of the control step: the Jacobians of the step as computed.

A control step maps the state ``x = (q, qd)`` (10 entries: ``x_b, y_b, th_b, q1, q2`` and their rates) and the
torques ``tau`` held over it to the next state. Its Jacobians

* ``A = d x(t + dt) / d x(t)``, ``(..., 10, 10)``,
* ``B = d x(t + dt) / d tau``, ``(..., 10, 2)``,

are computed here in the compiled core, batched, alongside the step itself (forward mode: a tangent matrix is
carried through every RK4 stage). They are the derivatives of the discrete map the step computes, not of the
continuous flow it approximates: every RK4 stage at its own state, the contact's projection after every substep,
and the substep count of the step rule (``leg_env.physics.integrate``) held. The substep count is a whole number
chosen from the rates at the step's start; where a perturbation would change it, the map jumps, and ``A`` is the
derivative of the branch the step took.

Pinned foot (``stance_step_jacobians``). The foot is held at ``anchor`` and every substep projects the base back
onto it (coordinate partitioning, ``leg_env.physics.integrate``). On the contact's manifold (the foot on the
anchor, ``Jc qd = 0``) the dynamics depend on the leg's angles and rates only. With ``anchor=None`` the anchor is
the foot of ``q``, as in ``stance_step``, and moves with it: moving the whole robot along the ground moves the
next state with it (``A`` maps ``dx_b`` to ``dx_b``). With a given ``anchor`` the anchor is held: the base's
position and velocity before the step do not enter the next state (their columns of ``A`` are zero), as the
projection discards them. Off the manifold, ``A`` is the derivative of what the step does there: project at the
end of the first substep.

Flight (``flight_step_jacobians``): the free robot, no projection.

Each Jacobian is checked in the tests against centred finite differences of the step and against complex-step
differentiation of an independent RK4 step built on the SymPy Lagrangian's ``M``, ``h`` and ``Jc``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._core import kernels
from .arrays import NQ, NU, batched, core_params, vec
from .dynamics import foot_position
from .integrate import DT, MAX_ANGLE, SUBSTEPS, checked_steps
from .params import LegParams

__all__ = ["StepJacobians", "stance_step_jacobians", "flight_step_jacobians", "NX"]

NX = 2 * NQ  # the state (q, qd)


class StepJacobians(NamedTuple):
    """A control step and its derivatives (every array with the call's leading axes)."""

    q: np.ndarray  # (..., 5) q after the step
    qd: np.ndarray  # (..., 5) qd after the step
    lam_mean: np.ndarray  # (..., 2) the mean contact force over the step [N] (zero in flight)
    A: np.ndarray  # (..., 10, 10) d(q, qd) after / d(q, qd) before
    B: np.ndarray  # (..., 10, 2) d(q, qd) after / d(tau_hip, tau_knee) [per N m]


def _rk4_jacobians(q, qd, tau, p, anchor, dt, substeps, max_angle, stance: bool) -> StepJacobians:
    dt, substeps, max_angle = checked_steps(dt, substeps, max_angle)
    q = vec(q, NQ, "q")
    follow = stance and anchor is None
    if stance:
        anchor = foot_position(q, p) if anchor is None else vec(anchor, 2, "anchor")
    else:
        anchor = np.zeros(2)
    lead, (qf, qdf, tf, af) = batched(("q", q), ("qd", vec(qd, NQ, "qd")), ("tau", vec(tau, NU, "tau")), ("anchor", anchor))
    qf, qdf = qf.copy(), qdf.copy()
    n = qf.shape[0]
    lam, A, B = np.empty((n, 2)), np.empty((n, NX * NX)), np.empty((n, NX * NU))
    kernels.rk4_jacobians(qf, qdf, tf, core_params(p), np.zeros(n), af, dt, substeps, max_angle, stance, follow, lam, A, B)
    return StepJacobians(
        qf.reshape(lead + (NQ,)), qdf.reshape(lead + (NQ,)), lam.reshape(lead + (2,)), A.reshape(lead + (NX, NX)),
        B.reshape(lead + (NX, NU)),
    )


def stance_step_jacobians(
    q, qd, tau, p: LegParams, dt: float = DT, substeps: int = SUBSTEPS, anchor=None, max_angle: float = MAX_ANGLE
) -> StepJacobians:
    """``leg_env.physics.integrate.stance_step`` (the foot pinned at ``anchor``) and its Jacobians ``A``, ``B``.

    Takes exactly ``stance_step``'s arguments, and gives the same step (bit for bit) with its derivatives. With
    ``anchor=None`` the anchor is the foot of ``q`` and its derivative follows ``q``; a given anchor is held.

    Raises:
        ValueError: as ``stance_step``: an array of the wrong shape, or a setting of the step rule out of range (the
            message names it).
    """
    return _rk4_jacobians(q, qd, tau, p, anchor, dt, substeps, max_angle, True)


def flight_step_jacobians(q, qd, tau, p: LegParams, dt: float = DT, substeps: int = SUBSTEPS, max_angle: float = MAX_ANGLE
                          ) -> StepJacobians:
    """``leg_env.physics.integrate.flight_step`` (no contact) and its Jacobians ``A``, ``B`` (``lam_mean`` is zero).

    Raises:
        ValueError: as ``flight_step``.
    """
    return _rk4_jacobians(q, qd, tau, p, None, dt, substeps, max_angle, False)
