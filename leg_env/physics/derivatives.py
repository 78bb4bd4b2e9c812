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

The unilateral ground (``hybrid_step_jacobians``): the derivative of ``hybrid_step`` through every event it locates
(touchdown with its impact map, lift-off, slip onset, sliding stop). Across an event at time ``s`` in a substep the
located state is ``x(s) = Phi(x0, s)`` with ``g(x(s)) = 0`` for the event's witness ``g``; differentiating,
``ds = -(dg/dx dPhi/dx0 dx0) / (dg/dx dPhi/ds)``, and the state just past the event moves by
``dPhi/dx0 dx0 + dPhi/ds ds`` before the reset map's derivative applies: the saltation matrix of the discrete map. The
rest of the step has ``dt - s`` left, so the later substeps' lengths move with ``ds`` too. Where no derivative exists
(a grazing event, two at once, the Painleve rule, a Zeno settle) the robot is flagged and its ``A``, ``B`` are NaN.

Each Jacobian is checked in the tests against centred finite differences of the step and against complex-step
differentiation of an independent RK4 step built on the SymPy Lagrangian's ``M``, ``h`` and ``Jc``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._core import kernels
from .arrays import NQ, NU, batched, core_params, finite_rows, vec
from .dynamics import foot_position
from .hybrid import HybridStep, prepared_call
from .integrate import DT, MAX_ANGLE, SUBSTEPS, checked_steps
from .params import PARAM_NAMES, LegParams

__all__ = ["StepJacobians", "HybridJacobians", "stance_step_jacobians", "flight_step_jacobians", "hybrid_step_jacobians",
           "action_jacobians",
           "GRAZING", "SIMULTANEOUS", "PAINLEVE", "SETTLED", "UNDEFINED_NAMES", "NX"]

NX = 2 * NQ  # the state (q, qd)
NPD = len(PARAM_NAMES) + 1  # P's columns: LegParams' fields in order, then mu

# Why the derivative of a hybrid step does not exist (bits of HybridJacobians.undefined; 0: it exists)
GRAZING = 1  # a located event's witness crossed zero tangentially: the event's time has no derivative
SIMULTANEOUS = 2  # two witnesses crossed at once: the events' order, and so the map, changes with the state
PAINLEVE = 4  # the Painleve rule chose the mode (no consistent contact force): the map is not smooth there
SETTLED = 8  # a Zeno settle (a touchdown slower than SETTLE_SPEED, or MAX_EVENTS events) held the foot down
UNDEFINED_NAMES = {GRAZING: "grazing", SIMULTANEOUS: "simultaneous", PAINLEVE: "painleve", SETTLED: "settled"}


class StepJacobians(NamedTuple):
    """A control step and its derivatives (every array with the call's leading axes)."""

    q: np.ndarray  # (..., 5) q after the step
    qd: np.ndarray  # (..., 5) qd after the step
    lam_mean: np.ndarray  # (..., 2) the mean contact force over the step [N] (zero in flight)
    A: np.ndarray  # (..., 10, 10) d(q, qd) after / d(q, qd) before
    B: np.ndarray  # (..., 10, 2) d(q, qd) after / d(tau_hip, tau_knee) [per N m]
    P: np.ndarray | None = None  # (..., 10, 12) d(q, qd) after / d(LegParams' fields in order, mu), with params=True


class HybridJacobians(NamedTuple):
    """A hybrid control step and its derivatives (every array with the call's leading axes)."""

    step: HybridStep  # what hybrid_step returns
    A: np.ndarray  # (..., 10, 10) d(q, qd) after / d(q, qd) before; NaN where the derivative does not exist
    B: np.ndarray  # (..., 10, 2) d(q, qd) after / d(tau_hip, tau_knee) [per N m]; NaN likewise
    undefined: np.ndarray  # (...) int: why the derivative does not exist (GRAZING | SIMULTANEOUS | PAINLEVE | SETTLED), 0 where it does
    P: np.ndarray | None = None  # (..., 10, 12) d(q, qd) after / d(LegParams' fields in order, mu), with params=True; NaN likewise

    @property
    def defined(self) -> np.ndarray:
        """(...) bool: where the derivative exists (and ``A``, ``B`` hold it)."""
        return self.undefined == 0


def _rk4_jacobians(q, qd, tau, p, anchor, dt, substeps, max_angle, stance: bool, params: bool) -> StepJacobians:
    dt, substeps, max_angle = checked_steps(dt, substeps, max_angle)
    q = vec(q, NQ, "q")
    follow = stance and anchor is None
    if stance:
        anchor = foot_position(q, p) if anchor is None else vec(anchor, 2, "anchor")
    else:
        anchor = np.zeros(2)
    lead, (qf, qdf, tf, af) = batched(("q", q), ("qd", vec(qd, NQ, "qd")), ("tau", vec(tau, NU, "tau")), ("anchor", anchor))
    qf, qdf = qf.copy(), qdf.copy()
    finite_rows(("q", qf), ("qd", qdf), ("tau", tf), ("anchor", af))
    n = qf.shape[0]
    lam, A, B = np.empty((n, 2)), np.empty((n, NX * NX)), np.empty((n, NX * NU))
    P = np.empty((n, NX * NPD)) if params else None
    kernels.rk4_jacobians(qf, qdf, tf, core_params(p), np.zeros(n), af, dt, substeps, max_angle, stance, follow, lam, A, B, P)
    return StepJacobians(
        qf.reshape(lead + (NQ,)), qdf.reshape(lead + (NQ,)), lam.reshape(lead + (2,)), A.reshape(lead + (NX, NX)),
        B.reshape(lead + (NX, NU)), None if P is None else P.reshape(lead + (NX, NPD)),
    )


def stance_step_jacobians(
    q, qd, tau, p: LegParams, dt: float = DT, substeps: int = SUBSTEPS, anchor=None, max_angle: float = MAX_ANGLE,
    params: bool = False,
) -> StepJacobians:
    """``leg_env.physics.integrate.stance_step`` (the foot pinned at ``anchor``) and its Jacobians ``A``, ``B``.

    Takes exactly ``stance_step``'s arguments, and gives the same step (bit for bit) with its derivatives. With
    ``anchor=None`` the anchor is the foot of ``q`` and its derivative follows ``q``; a given anchor is held. With
    ``params=True`` also ``P``, the derivative by the robot's parameters (``LegParams``' fields in order) and ``mu``
    (zero here: the pinned foot has no friction).

    Raises:
        ValueError: as ``stance_step``: an array of the wrong shape, or a setting of the step rule out of range (the
            message names it).
    """
    return _rk4_jacobians(q, qd, tau, p, anchor, dt, substeps, max_angle, True, params)


def flight_step_jacobians(q, qd, tau, p: LegParams, dt: float = DT, substeps: int = SUBSTEPS, max_angle: float = MAX_ANGLE,
                          params: bool = False) -> StepJacobians:
    """``leg_env.physics.integrate.flight_step`` (no contact) and its Jacobians ``A``, ``B`` (``lam_mean`` is zero);
    with ``params=True`` also ``P``, as ``stance_step_jacobians``.

    Raises:
        ValueError: as ``flight_step``.
    """
    return _rk4_jacobians(q, qd, tau, p, None, dt, substeps, max_angle, False, params)


def hybrid_step_jacobians(
    q, qd, tau, p: LegParams, mu, mode=None, anchor_x=None, dt: float = DT, substeps: int = SUBSTEPS,
    max_angle: float = MAX_ANGLE, load_x=0.0, params: bool = False,
) -> HybridJacobians:
    """``leg_env.physics.hybrid.hybrid_step`` on the unilateral ground and its Jacobians ``A``, ``B``.

    Takes exactly ``hybrid_step``'s arguments and gives the same step (bit for bit, in ``.step``) with its
    derivatives through every located event: the crossing substep differentiated at its located length, that length's
    derivative from the event's witness (``ds = -dg / (dg/ds)``, the saltation of the discrete map), the reset map
    (the touchdown's placement on the ground, the impact map in whichever of its branches it took, the sticking
    impulse of a sliding stop) and the later substeps, whose lengths move with the event's time. With
    ``anchor_x=None`` the stick anchor is the foot of ``q`` and its derivative follows ``q``; a given anchor is held.
    The substep counts and the sequence of events and modes are held: ``A`` is the derivative of the branch the step
    took.

    With ``params=True`` also ``P``, the derivative by the robot's parameters (``LegParams``' fields in order) and the
    friction coefficient ``mu`` (last): for system identification. Where the derivative does not exist
    (``undefined``: a grazing event, two events at once, the Painleve rule, a Zeno settle), ``A``, ``B`` and ``P`` are
    NaN and ``defined`` is False.

    Raises:
        ValueError: as ``hybrid_step`` (the message names the argument).
    """
    call = prepared_call(q, qd, tau, p, mu, mode, anchor_x, dt, substeps, max_angle, load_x)
    n = call.arguments[0].shape[0]
    A, B, undefined = np.empty((n, NX * NX)), np.empty((n, NX * NU)), np.empty(n, np.int64)
    P = np.empty((n, NX * NPD)) if params else None
    kernels.hybrid_jacobians(*call.arguments, anchor_x is None, A, B, undefined, P)
    lead = call.lead
    return HybridJacobians(call.result(), A.reshape(lead + (NX, NX)), B.reshape(lead + (NX, NU)), undefined.reshape(lead),
                           None if P is None else P.reshape(lead + (NX, NPD)))


def action_jacobians(state, robots, actions, *, dt: float, substeps: int, max_angle: float, motor_speed: float,
                     unilateral: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Jacobians of an environment's next control step from its current states, in its action units.

    What ``LegVectorEnv.jacobians`` computes, from the env's arrays: ``state`` ``(N,)`` rows of its state (``q``,
    ``qd``, ``anchor``, ``mode``, ``load``), ``robots`` ``(N,)`` or ``(1,)`` rows of its robots (parameters, friction,
    torque limits), ``actions`` ``(N, 2)`` finite. The torque of an action entry is ``clip(a, -1, 1)`` times its
    limit, through the motor model (``motor_speed``; ``inf``: an ideal torque source) at the joint's speed.

    Returns:
        ``(A, B, undefined)``: ``A`` ``(N, 10, 10)`` = d(q, qd) after / d(q, qd) now, with the motor model's
        dependence on the joint speeds; ``B`` ``(N, 10, 2)`` = d(q, qd) after / d action: the torque's derivative
        times the limit, from inside the range at a bound and 0 beyond it; ``undefined`` ``(N,)`` as
        ``HybridJacobians.undefined`` (0 on the pinned foot). The anchor is the state's, held (the env carries it).
    """
    n = state.shape[0]
    robots = np.broadcast_to(robots, (n,)) if robots.shape[0] == 1 else robots
    p = np.ascontiguousarray(robots["p"]).view(np.float64).reshape(n, -1)
    limit = np.asarray(robots["torque_limit"], dtype=np.float64)
    a = np.asarray(actions, dtype=np.float64)
    q, qd = state["q"].copy(), state["qd"].copy()
    tau_c = np.clip(a, -1.0, 1.0) * limit
    dtau_da = np.where(np.abs(a) <= 1.0, limit, 0.0)
    dtau_dw = np.zeros((n, NU))
    if np.isinf(motor_speed):
        tau = tau_c
    else:  # tau = tau_c clip(1 - s w / w0, 0, 1), s the torque's sign: the speed in its direction costs torque
        w = qd[:, 3:5]
        along = np.where(tau_c > 0.0, w, -w)
        raw = 1.0 - along / motor_speed
        factor = np.clip(raw, 0.0, 1.0)
        inside = (raw > 0.0) & (raw < 1.0) & (tau_c != 0.0)
        tau = tau_c * factor
        dtau_da = dtau_da * factor
        dtau_dw = np.where(inside, -np.abs(tau_c) / motor_speed, 0.0)
    tau = np.ascontiguousarray(tau)
    A, B = np.empty((n, NX * NX)), np.empty((n, NX * NU))
    anchor = np.ascontiguousarray(state["anchor"])
    load = np.ascontiguousarray(state["load"], dtype=np.float64)
    if unilateral:
        from .layout import RECORD

        undefined = np.empty(n, np.int64)
        mode = state["mode"].astype(np.int64)
        kernels.hybrid_jacobians(q, qd, tau, p, load, np.ascontiguousarray(robots["mu"], dtype=np.float64), mode,
                                 anchor.copy(), dt, substeps, max_angle, np.empty(n, RECORD), False, A, B, undefined, None)
    else:
        undefined = np.zeros(n, np.int64)
        kernels.rk4_jacobians(q, qd, tau, p, load, anchor, dt, substeps, max_angle, True, False, np.empty((n, 2)), A, B, None)
    A, B = A.reshape(n, NX, NX), B.reshape(n, NX, NU)
    A[:, :, 8:10] += B * dtau_dw[:, None, :]  # the motor's torque falls with the joint's speed (q1', q2')
    return A, B * dtau_da[:, None, :], undefined
