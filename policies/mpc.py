"""A model-predictive hopping controller for ``leg_env/PlanarLegHop-v4``: iLQR through the contact events on the
exact Jacobians of the hybrid step, around the hopper.

**The plan.** At every control step the controller rebuilds the robot's state from the observation and rolls a plan
out over ``horizon`` control steps (0.7 s: the rest of a hop and the next one) on the simulator's own step
(``leg_env.physics.derivatives.hybrid_step_jacobians``: the map the env steps, its touchdowns, impacts, lift-offs and
stick/slip changes located inside the step). The plan is the hopper (``policies.hopper``: Raibert's servos; a deeper crouch
than its default) in closed loop, plus a correction ``v_t`` of its action at every step, ``a_t = clip(pi(x_t) + v_t, -1, 1)``. One iteration of
iLQR improves the corrections:

* the backward pass is Gauss-Newton on the closed loop's Jacobians ``A_cl = A + B D dpi/dx`` and ``B_cl = B D``:
  ``A``, ``B`` the step's, each with the saltation of the events it located (so the pass sees how a torque in the push
  moves the lift-off and with it the apex), ``dpi/dx`` the hopper's derivative (centred differences, its phases held),
  ``D`` the clip's, faded to 0 over the last ``clip_smoothing`` before the limit (``clip_derivative``: the hopper's
  push puts a torque exactly on its limit, where the clip's own derivative is 0 or 1 by a rounding, and the law
  jumped with it);
* the line search rolls the corrected plans out on the simulator, with the feedback ``K dx`` of the backward pass,
  at step lengths ``steps``, and every robot keeps the plan of least cost (the uncorrected one among them).

The controller applies the first action. Each control step starts from the hopper's plan (``warm_start=False``):
carried over from step to step, the corrections learnt to exploit the horizon's end (a lift-off put off past the
horizon is a hop whose apex is not charged), crouched deeper and deeper and fell (10 of 24 episodes survived; 24 of
24 with a fresh plan each step).

**Cost** per step of the plan, in residuals ``r`` (``cost = |r|^2``):

* ``apex``: ``(y_com + y_com'^2 / 2g - y_stand - dh*) / apex_scale`` at every step in flight (``charge_apex="flight"``;
  ``"liftoff"`` charges it once, at the step that lifts off): the flight's ballistic apex on the command, the task's
  own apex (``leg_env.tasks.hop``);
* ``tilt``, ``tilt_rate``: ``th_b / tilt_scale``, ``th_b' / tilt_rate_scale``: the torso upright and still;
* ``drift``, ``drift_rate``: ``(x_com - x_com,0) / drift_scale``, ``x_com' / drift_rate_scale``: over the start;
* ``limit``: how far a joint is inside the last ``limit_margin`` of its range (the knee past ``crouch_limit``: a crouch
  too deep to rise from), over ``limit_scale``;
* ``effort``, ``power``: ``sqrt(effort_weight) a`` and ``sqrt(power_weight) max(0, tau_j q_j')`` per joint (the
  joints' positive power at the step's start [W]); ``smooth_weight |v|^2``: the corrections themselves;
* without derivative (the line search sees them, the backward pass does not): ``fall_cost`` a step where the plan has
  fallen (the task's fall) or not hopped for longer than the task's ``max_ground_time``, and ``stance_cost`` a step
  on the ground past ``stance_grace``.

The controller reads only the observation (the state is rebuilt from its entries: the base relative to the contact
point, the angles and rates, the contact flag and the slip direction; the COM's drift), the model (``LegParams``)
and the task (``HopConfig``). Its compute grows linearly with the horizon and the line search's steps; batched, the
cost per robot falls with the batch (``benchmarks/bench_mpc.py``).
"""

from __future__ import annotations

import numpy as np

from leg_env.physics import contact as _contact
from leg_env.physics.derivatives import hybrid_step_jacobians
from leg_env.physics.dynamics import com_state, foot_position
from leg_env.physics.hybrid import hybrid_step
from leg_env.physics.params import LegParams
from leg_env.tasks.base import Obs
from policies.base import BatchedController
from policies.hopper import HopperController

__all__ = ["HopMPC"]

_NX, _NU = 10, 2


class HopMPC(BatchedController):
    """iLQR model-predictive hopping controller with SB3's ``predict`` (module docstring).

    Args:
        params: the robot (``LegParams``, a dict, or None for the defaults).
        config: the task (``HopConfig`` or a dict of its fields; None: the defaults).
        horizon: the plan's length in control steps (70: 0.7 s, the rest of a hop and the next).
        steps: the line search's step lengths (the uncorrected plan is always a candidate).
        iterations: iLQR iterations per control step.
        warm_start: start each control step from the last plan's corrections (shifted a step) instead of none.
        regularisation: added to the backward pass's ``Q_vv`` (Levenberg-Marquardt) [cost per action^2].
        apex_scale, tilt_scale, tilt_rate_scale, drift_scale, drift_rate_scale, limit_scale: the residuals' scales
            [m, rad, rad/s, m, m/s, rad].
        charge_apex: ``"flight"`` (every step in flight) or ``"liftoff"`` (once per flight).
        effort_weight: per action^2; power_weight: per W^2 of a joint's positive power; smooth_weight: per
            correction^2.
        limit_margin: [rad] from each end of the joints' ranges; crouch_limit: the knee's largest angle before the
            limit residual [rad].
        terminal_weight: the last step's state residuals' weight (1: as every step).
        hopper: settings of the hopper inside the plan (``HopperController``'s keywords; None: its defaults but a
            deeper crouch, ``crouch=(0.05, 0.5)``: on 24 episodes of 10 s the torso's tilt fell from 8.7 to 5.4 degrees
            RMS, the apex error and the power alike).
        fall_cost: the cost of a step fallen or too long on the ground; stance_cost: of a step on the ground past
            stance_grace [s].
        clip_smoothing: the width of the band inside the action's bounds over which the backward pass's clip
            derivative fades from 1 to 0 (``clip_derivative``; 0: the clip's own 0 or 1) [action units].
        law_step: the step of the centred differences of the hopper's law inside the plan [m, rad, m/s, rad/s]: at
            1e-6 their rounding alone made the MPC's law disagree with itself under a change of the state of 1e-6.

    After each ``predict``, ``planned`` ``(N, horizon + 1, 10)`` holds the chosen plan's states (the first the robot's
    now), ``cost`` ``(N,)`` its cost and ``pick`` ``(N,)`` the line search's choice of the last iteration (the index of
    its step length in ``steps``, -1: the plan it started from). Setting ``hold_pick`` (an ``(N,)`` int array, or None)
    makes the line search take those choices whatever the costs: the derivative of the controller along one branch
    of its choice, as the step's derivative holds the step's events (``train.stability``).

    Raises:
        TypeError: an unknown keyword. ValueError: a setting out of its range (the message names it).
    """

    widths, task, dtype = (22, 24), "PlanarLegHop-v4: 24 entries, 22 without observe_action", np.float64

    def __init__(
        self,
        params: LegParams | dict | None = None,
        config=None,
        horizon: int = 70,
        steps: tuple = (1.0, 0.5, 0.25),
        regularisation: float = 10.0,
        apex_scale: float = 0.01,
        tilt_scale: float = 0.2,
        tilt_rate_scale: float = 2.0,
        drift_scale: float = 0.2,
        drift_rate_scale: float = 1.0,
        effort_weight: float = 0.01,
        power_weight: float = 0.0,
        smooth_weight: float = 0.3,
        limit_margin: float = 0.1,
        limit_scale: float = 0.02,
        fall_cost: float = 100.0,
        terminal_weight: float = 1.0,
        stance_grace: float = 0.5,
        stance_cost: float = 10.0,
        crouch_limit: float = 1.6,
        charge_apex: str = "flight",
        warm_start: bool = False,
        iterations: int = 1,
        hopper: dict | None = None,
        clip_smoothing: float = 0.05,
        law_step: float = 1e-5,
    ):
        from leg_env.physics.dynamics import com_position
        from leg_env.tasks.base import nominal_state
        from leg_env.tasks.hop import HopConfig

        self.params = p = LegParams.from_any(params)
        self.config = c = config if isinstance(config, HopConfig) else HopConfig.from_kwargs(config)
        if int(horizon) < 2:
            raise ValueError(f"horizon must be at least 2, got {horizon}")
        if int(iterations) < 1:
            raise ValueError(f"iterations must be at least 1, got {iterations}")
        if charge_apex not in ("flight", "liftoff"):
            raise ValueError(f"charge_apex must be 'flight' or 'liftoff', got {charge_apex!r}")
        positive = dict(law_step=law_step, apex_scale=apex_scale, tilt_scale=tilt_scale, tilt_rate_scale=tilt_rate_scale,
                        drift_scale=drift_scale, drift_rate_scale=drift_rate_scale, limit_scale=limit_scale)
        nonnegative = dict(regularisation=regularisation, effort_weight=effort_weight, power_weight=power_weight,
                           smooth_weight=smooth_weight, limit_margin=limit_margin, fall_cost=fall_cost,
                           terminal_weight=terminal_weight, stance_grace=stance_grace, stance_cost=stance_cost,
                           clip_smoothing=clip_smoothing)
        for name, value in positive.items():
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive and finite, got {value}")
        for name, value in nonnegative.items():
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and at least 0, got {value}")
        self.horizon = int(horizon)
        self.steps = tuple(float(s) for s in steps)
        self.regularisation = float(regularisation)
        self.y_stand = float(com_position(nominal_state(p, c).q, p)[1])
        self.torque_limit = np.asarray(c.torque_limit, dtype=np.float64) * np.ones(2)
        self.scales = dict(apex=apex_scale, tilt=tilt_scale, tilt_rate=tilt_rate_scale, drift=drift_scale,
                           drift_rate=drift_rate_scale, limit=limit_scale)
        self.effort_weight, self.smooth_weight = float(effort_weight), float(smooth_weight)
        self.power_weight = float(power_weight)
        self.limit_margin, self.fall_cost = float(limit_margin), float(fall_cost)
        self.terminal_weight = float(terminal_weight)
        self.stance_grace, self.stance_cost = float(stance_grace), float(stance_cost)
        self.crouch_limit, self.charge_apex = float(crouch_limit), charge_apex
        self.warm_start, self.iterations = bool(warm_start), int(iterations)
        self.clip_smoothing, self.law_step = float(clip_smoothing), float(law_step)
        self.hopper_settings = dict(crouch=(0.05, 0.5)) if hopper is None else dict(hopper)
        HopperController(p, c, **self.hopper_settings)  # checks them
        self._step_args = dict(dt=c.dt, substeps=c.substeps, max_angle=c.max_angle)
        self.hold_pick: np.ndarray | None = None
        self.pick = np.full(0, -1)

    # ---- per-robot state

    def _allocate(self, n: int) -> None:
        self._plan = np.zeros((n, self.horizon, _NU))  # the corrections v added to the hopper's actions
        # the hopper along the robot's own trajectory, whose state each plan starts from
        self._pilot = HopperController(self.params, self.config, **self.hopper_settings)
        self._pilot._n = n
        self._pilot._allocate(n)
        self._pilot._start(np.ones(n, dtype=bool))
        self._probe = HopperController(self.params, self.config, **self.hopper_settings)  # for the hopper's derivative

    def _start(self, rows: np.ndarray, batch: np.ndarray | None = None) -> None:
        self._plan[rows] = 0.0
        self._pilot._start(rows)

    # ---- the state from the observation

    def state(self, obs: np.ndarray):
        """``(q, qd, mode)`` of the robots of observations ``(N, 22 or 24)``, the contact point at ``x = 0``.

        The state is projected on its contact (float32 rounding puts a foot a little off the ground): a foot in
        contact is put on the ground, and a sticking foot at rest.
        """
        p = self.params
        n = obs.shape[0]
        q = np.array(obs[:, Obs.base_x:Obs.q2 + 1], dtype=np.float64)
        qd = np.array(obs[:, Obs.vx_b:Obs.w_q2 + 1], dtype=np.float64)
        contact = obs[:, Obs.contact] > 0.5
        slip = obs[:, Obs.slip]
        mode = np.full(n, _contact.FLIGHT, dtype=np.int64)
        mode[contact & (slip > 0.5)] = _contact.SLIP_FORWARD
        mode[contact & (slip < -0.5)] = _contact.SLIP_BACKWARD
        mode[contact & (np.abs(slip) <= 0.5)] = _contact.STICK
        th1, th2 = q[:, 2] + q[:, 3], q[:, 2] + q[:, 3] + q[:, 4]
        w1, w2 = qd[:, 2] + qd[:, 3], qd[:, 2] + qd[:, 3] + qd[:, 4]
        foot_y = foot_position(q, p)[:, 1]
        q[:, 1] -= np.where(contact, foot_y, np.minimum(foot_y, 0.0))  # on the ground, or not below it
        vfx = qd[:, 0] - p.l1 * np.sin(th1) * w1 - p.l2 * np.sin(th2) * w2
        vfy = qd[:, 1] + p.l1 * np.cos(th1) * w1 + p.l2 * np.cos(th2) * w2
        qd[:, 0] -= np.where(mode == _contact.STICK, vfx, 0.0)
        qd[:, 1] -= np.where(contact, vfy, 0.0)
        return q, qd, mode

    def com(self, x: np.ndarray):
        """The whole-body COM ``(x, y)`` and its velocity ``(x', y')`` of states ``x`` ``(..., 10)``."""
        pos, vel = com_state(x[..., :5], x[..., 5:], self.params)
        return pos[..., 0], pos[..., 1], vel[..., 0], vel[..., 1]

    # ---- cost

    def residuals(self, x: np.ndarray, flight: np.ndarray, target: np.ndarray, x_ref: np.ndarray) -> np.ndarray:
        """The state's residuals ``(..., 7)`` (module docstring) for states ``x`` ``(..., 10)``."""
        s, c, g = self.scales, self.config, self.params.g
        xc, yc, vxc, vyc = self.com(x)
        apex = np.where(flight, (yc + vyc**2 / (2.0 * g) - target) / s["apex"], 0.0)
        lo_h, hi_h = c.hip_range
        lo_k, hi_k = c.knee_range
        mg = self.limit_margin
        return np.stack([
            apex,
            x[..., 2] / s["tilt"],
            x[..., 7] / s["tilt_rate"],
            (xc - x_ref) / s["drift"],
            vxc / s["drift_rate"],
            (np.maximum(lo_h + mg - x[..., 3], 0.0) - np.maximum(x[..., 3] - hi_h + mg, 0.0)) / s["limit"],
            (np.maximum(lo_k + mg - x[..., 4], 0.0)
             - np.maximum(x[..., 4] - min(hi_k - mg, self.crouch_limit), 0.0)) / s["limit"],
        ], axis=-1)

    def _residual_jacobian(self, X, flight, target, x_ref, eps=1e-6):
        """``dr/dx`` ``(N, H, 7, 10)`` by centred differences of the residuals (closed forms, cheap)."""
        J = np.empty(X.shape[:2] + (7, _NX))
        for j in range(_NX):
            d = np.zeros(_NX)
            d[j] = eps
            J[..., j] = (self.residuals(X + d, flight, target, x_ref) - self.residuals(X - d, flight, target, x_ref)) / (2 * eps)
        return J

    def _penalty(self, x: np.ndarray, ground: np.ndarray, stance: np.ndarray) -> np.ndarray:
        """``fall_cost`` where the state has fallen or the robot has not hopped for too long."""
        c, p = self.config, self.params
        knee_y = x[..., 1] + p.l1 * np.sin(x[..., 2] + x[..., 3])
        fallen = (x[..., 1] < c.min_base_height) | (x[..., 1] < knee_y) | (np.abs(x[..., 2]) > c.max_torso_angle)
        return self.fall_cost * (fallen | (ground > c.max_ground_time)) + self.stance_cost * (stance > self.stance_grace)

    def action_residuals(self, x: np.ndarray, u: np.ndarray):
        """The action's residuals ``(..., 4)`` at states ``x`` ``(..., 10)`` and actions ``u`` ``(..., 2)``: the effort
        ``sqrt(effort_weight) u`` and the joints' positive power ``sqrt(power_weight) max(0, tau_j q_j')`` [W]; and
        their derivatives by ``u`` ``(..., 4, 2)`` and by ``x`` ``(..., 4, 10)``."""
        se, sp = np.sqrt(self.effort_weight), np.sqrt(self.power_weight)
        lim = self.torque_limit
        w = x[..., 8:10]  # the hip's and the knee's rates
        power = lim * u * w
        on = (power > 0.0).astype(np.float64)
        r = np.concatenate([se * u, sp * on * power], axis=-1)
        Ju = np.zeros(u.shape[:-1] + (4, 2))
        Jx = np.zeros(u.shape[:-1] + (4, _NX))
        Ju[..., 0, 0] = Ju[..., 1, 1] = se
        Ju[..., 2, 0] = sp * on[..., 0] * lim[0] * w[..., 0]
        Ju[..., 3, 1] = sp * on[..., 1] * lim[1] * w[..., 1]
        Jx[..., 2, 8] = sp * on[..., 0] * lim[0] * u[..., 0]
        Jx[..., 3, 9] = sp * on[..., 1] * lim[1] * u[..., 1]
        return r, Ju, Jx

    def _liftoffs(self, modes):
        """The steps ``(N, H)`` whose end state's apex is charged: every step that ends in flight (``charge_apex="flight"``)
        or only those that lift off (``"liftoff"``)."""
        if self.charge_apex == "flight":
            return modes[:, 1:] == _contact.FLIGHT
        return (modes[:, 1:] == _contact.FLIGHT) & (modes[:, :-1] != _contact.FLIGHT)

    def _cost(self, roll, target, x_ref):
        X, modes = roll["X"], roll["modes"]
        r = self.residuals(X[:, 1:], self._liftoffs(modes), target[:, None], x_ref[:, None])
        r[:, -1] *= np.sqrt(self.terminal_weight)
        ra = self.action_residuals(X[:, :-1], roll["U"])[0]
        return (np.sum(r**2, axis=(1, 2)) + np.sum(ra**2, axis=(1, 2))
                + self.smooth_weight * np.sum(roll["V"] ** 2, axis=(1, 2))
                + np.sum(self._penalty(X[:, 1:], roll["ground"][:, 1:], roll["stance"][:, 1:]), axis=1))

    # ---- the hopper inside the plan

    def _observation(self, x, mode, like):
        """The hopper's observation of model states ``x`` (the entries the state does not set as in ``like``)."""
        p = self.params
        obs = np.array(like, dtype=np.float64)
        obs[..., Obs.base_x:Obs.q2 + 1] = x[..., :5]
        obs[..., Obs.vx_b:Obs.w_q2 + 1] = x[..., 5:]
        obs[..., Obs.foot_height] = foot_position(x[..., :5], p)[..., 1]
        obs[..., Obs.contact] = mode != _contact.FLIGHT
        obs[..., Obs.slip] = np.where(mode == _contact.SLIP_FORWARD, 1.0, np.where(mode == _contact.SLIP_BACKWARD, -1.0, 0.0))
        return obs

    _HOPPER_STATE = HopperController.continuous_state + HopperController.discrete_state

    def _hopper_copy(self, source, copies: int = 1):
        """A hopper in ``source``'s state, its robots repeated ``copies`` times (a batch of plans per robot)."""
        h = HopperController(self.params, self.config, **self.hopper_settings)
        h._n = source._n * copies
        for name in self._HOPPER_STATE:
            setattr(h, name, np.tile(getattr(source, name), copies))
        return h

    def _hopper(self, h, x, mode, like, x_ref, derivative: bool):
        """The hopper's action (unclipped, in action units) at states ``x`` ``(N, 10)``, advancing ``h``; with
        ``derivative`` also its derivative by the state ``(N, 2, 10)`` (centred differences, its phases held), from the
        same call of the hopper's law (the state itself, then each coordinate moved by +-eps)."""
        n, eps = x.shape[0], self.law_step
        copies = 2 * _NX + 1 if derivative else 1
        dx = np.zeros((copies, 1, _NX))
        if derivative:
            dx[1 + np.arange(_NX), 0, np.arange(_NX)] = eps
            dx[1 + _NX + np.arange(_NX), 0, np.arange(_NX)] = -eps
        xs = (x[None] + dx).reshape(-1, _NX)
        law = h if copies == 1 else self._probe
        if copies > 1:
            for name in self._HOPPER_STATE:
                setattr(law, name, np.tile(getattr(h, name), copies))
        law._x0 = self.com(xs)[0] - np.tile(x_ref, copies)  # the COM's drift, exact on the model (the hopper dead-reckons it)
        tau = law.torque(self._observation(xs, np.tile(mode, copies), np.tile(like, (copies, 1))))
        tau = tau.reshape(copies, n, _NU) / self.torque_limit
        if copies == 1:
            return tau[0], None
        for name in self._HOPPER_STATE:  # the hopper advanced by the state's own row
            setattr(h, name, getattr(law, name)[:n].copy())
        h._vx = law._vx[:n].copy()
        dpi = np.moveaxis((tau[1:1 + _NX] - tau[1 + _NX:]) / (2 * eps), 0, -1)  # (N, 2, 10)
        return tau[0], dpi

    def clip_derivative(self, z: np.ndarray) -> np.ndarray:
        """The backward pass's derivative of ``clip(z, -1, 1)``: 1 where ``|z| <= 1 - w``, 0 where ``|z| >= 1``, a
        smoothstep between (``w = clip_smoothing``; 0: the clip's own 0 or 1).

        The hopper's push saturates a joint exactly (its torques scaled onto the limit), where the clip's derivative is
        1 on one side and 0 on the other: a rounding decided which, and with it the plan's gains, so that the law
        jumped under any perturbation of the state. The band gives a step at the limit no authority (a correction
        cannot raise a saturated torque) and fades it in continuously inside.
        """
        w = self.clip_smoothing
        if w == 0.0:
            return (np.abs(z) < 1.0).astype(np.float64)
        s = np.clip((1.0 - np.abs(z)) / w, 0.0, 1.0)
        return s * s * (3.0 - 2.0 * s)

    # ---- the model

    def _rollout(self, q, qd, mode, ground, like, x_ref, V, nominal=None, k=None, K=None, jacobians=False, copies=1):
        """Roll the hopper plus the corrections ``V`` ``(N, H, 2)`` (or the nominal's plus ``k + K dx``) out on the
        simulator; with ``jacobians`` also the closed loop's ``A``, ``B`` and the action's derivatives."""
        n, H = V.shape[0], self.horizon
        p, mu = self.params, self.config.mu
        h = self._hopper_copy(self._pilot, copies)
        X = np.empty((n, H + 1, _NX))
        X[:, 0, :5], X[:, 0, 5:] = q, qd
        modes = np.empty((n, H + 1), dtype=np.int64)
        modes[:, 0] = mode
        grounds = np.empty((n, H + 1))
        grounds[:, 0] = ground
        stance = np.empty((n, H + 1))
        stance[:, 0] = np.where(mode == _contact.FLIGHT, 0.0, ground)
        U, Vt = np.empty_like(V), np.empty_like(V)
        out = dict(X=X, modes=modes, ground=grounds, stance=stance, U=U, V=Vt)
        if jacobians:
            out.update(A=np.empty((n, H, _NX, _NX)), B=np.empty((n, H, _NX, _NU)), Du=np.empty((n, H, _NU, _NX)),
                       D=np.empty((n, H, _NU)))
        flight_run = np.zeros(n)
        for t in range(H):
            v = V[:, t]
            if k is not None:
                v = v + k[:, t] + np.einsum("nij,nj->ni", K[:, t], X[:, t] - nominal[:, t])
            pi, dpi = self._hopper(h, X[:, t], mode, like, x_ref, jacobians)
            u = np.clip(pi + v, -1.0, 1.0)
            Vt[:, t], U[:, t] = v, u
            tau = u * self.torque_limit
            if jacobians:
                J = hybrid_step_jacobians(X[:, t, :5], X[:, t, 5:], tau, p, mu, mode, None, **self._step_args)
                r = J.step
                bad = (J.undefined != 0)[:, None, None]
                D = self.clip_derivative(pi + v)
                Bt = np.where(bad, 0.0, J.B * self.torque_limit) * D[:, None, :]
                out["A"][:, t] = np.where(bad, np.eye(_NX), J.A) + Bt @ dpi
                out["B"][:, t] = Bt
                out["Du"][:, t] = D[:, :, None] * dpi
                out["D"][:, t] = D
            else:
                r = hybrid_step(X[:, t, :5], X[:, t, 5:], tau, p, mu, mode, None, **self._step_args)
            X[:, t + 1, :5], X[:, t + 1, 5:] = r.q, r.qd
            mode = modes[:, t + 1] = r.mode
            flying = mode == _contact.FLIGHT
            flight_run = np.where(flying, flight_run + r.flight_time, 0.0)
            grounds[:, t + 1] = np.where(flying & (flight_run >= self.config.min_flight), 0.0, grounds[:, t] + self.config.dt)
            stance[:, t + 1] = np.where(flying, 0.0, stance[:, t] + self.config.dt)
        return out

    # ---- iLQR

    def _backward(self, roll, target, x_ref):
        """Gains ``k`` ``(N, H, 2)``, ``K`` ``(N, H, 2, 10)`` of one Gauss-Newton iLQR backward pass on the
        corrections (the hopper's feedback inside ``A``)."""
        X, modes, U, V = roll["X"], roll["modes"], roll["U"], roll["V"]
        n, H = V.shape[:2]
        flight = self._liftoffs(modes)
        r = self.residuals(X[:, 1:], flight, target[:, None], x_ref[:, None])
        Jr = self._residual_jacobian(X[:, 1:], flight, target[:, None], x_ref[:, None])
        r[:, -1] *= np.sqrt(self.terminal_weight)
        Jr[:, -1] *= np.sqrt(self.terminal_weight)
        lx = np.einsum("nhri,nhr->nhi", Jr, r)  # half the cost's derivatives, of the state after each step
        lxx = np.einsum("nhri,nhrj->nhij", Jr, Jr)
        ws = self.smooth_weight
        D, Du = roll["D"], roll["Du"]  # u = clip(pi(x) + v): du/dv = D, du/dx = D dpi/dx
        Vx = np.zeros((n, _NX))
        Vxx = np.zeros((n, _NX, _NX))
        k = np.zeros((n, H, _NU))
        K = np.zeros((n, H, _NU, _NX))
        eye = np.eye(_NU)
        for t in range(H - 1, -1, -1):
            vx = lx[:, t] + Vx
            vxx = lxx[:, t] + Vxx
            At, Bt, Dt, Dxt, ut = roll["A"][:, t], roll["B"][:, t], D[:, t], Du[:, t], U[:, t]
            ra, Jau, Jax = self.action_residuals(X[:, t], ut)
            Jv = Jau * Dt[:, None, :]  # through u = clip(pi(x) + v)
            Jx = Jau @ Dxt + Jax
            JvT, JxT = np.swapaxes(Jv, 1, 2), np.swapaxes(Jx, 1, 2)
            Qx = np.einsum("nji,nj->ni", At, vx) + np.einsum("nij,nj->ni", JxT, ra)
            Qu = np.einsum("nji,nj->ni", Bt, vx) + np.einsum("nij,nj->ni", JvT, ra) + ws * V[:, t]
            VB = vxx @ Bt
            Qxx = np.swapaxes(At, 1, 2) @ vxx @ At + JxT @ Jx
            Quu = np.swapaxes(Bt, 1, 2) @ VB + JvT @ Jv + (ws + self.regularisation) * eye
            Qux = np.swapaxes(VB, 1, 2) @ At + JvT @ Jx
            kt = -np.linalg.solve(Quu, Qu[..., None])[..., 0]
            Kt = -np.linalg.solve(Quu, Qux)
            k[:, t], K[:, t] = kt, Kt
            KtT = np.swapaxes(Kt, 1, 2)
            Vx = Qx + np.einsum("nij,nj->ni", KtT, np.einsum("nij,nj->ni", Quu, kt) + Qu) + np.einsum("nji,nj->ni", Qux, kt)
            Vxx = Qxx + KtT @ Quu @ Kt + KtT @ Qux + np.swapaxes(Qux, 1, 2) @ Kt
            Vxx = 0.5 * (Vxx + np.swapaxes(Vxx, 1, 2))
        return k, K

    def act(self, batch: np.ndarray) -> np.ndarray:
        return self.exact_actions(batch).astype(np.float32)

    def exact_actions(self, batch: np.ndarray) -> np.ndarray:
        """``act``'s actions in float64, before their rounding to float32 (for the closed loop's derivatives)."""
        bad = ~np.isfinite(batch).all(axis=1)
        if bad.any():
            raise ValueError(f"observation must be finite: rows {np.flatnonzero(bad)[:5].tolist()} are not")
        q, qd, mode = self.state(batch)
        like = np.array(batch[:, :22], dtype=np.float64)
        target = self.y_stand + batch[:, Obs.command]
        x_ref = self.com(np.concatenate([q, qd], axis=1))[0] - batch[:, Obs.com_drift]
        ground = np.array(batch[:, Obs.ground_time], dtype=np.float64)
        if not self.warm_start:
            self._plan[:] = 0.0
        V = self._plan
        for _ in range(self.iterations):
            pick = np.full(len(q), -1)  # the line search's choice (-1: the plan it started from)
            roll = self._rollout(q, qd, mode, ground, like, x_ref, V, jacobians=True)
            best_cost = self._cost(roll, target, x_ref)
            best_V, best_U, best_X = roll["V"], roll["U"], roll["X"]
            k, K = self._backward(roll, target, x_ref)
            if self.steps:  # every step length's plan in one batch, robot-major within each length
                S = len(self.steps)
                tile = lambda a: np.tile(a, (S,) + (1,) * (a.ndim - 1))  # noqa: E731
                scale = np.repeat(np.asarray(self.steps), len(q))[:, None, None]
                trial = self._rollout(tile(q), tile(qd), tile(mode), tile(ground), tile(like), tile(x_ref), tile(roll["V"]),
                                      nominal=tile(roll["X"]), k=scale * tile(k), K=tile(K), copies=S)
                costs = self._cost(trial, tile(target), tile(x_ref)).reshape(S, len(q))
                for i in range(S):
                    cost = costs[i]
                    rows = slice(i * len(q), (i + 1) * len(q))
                    better = cost < best_cost if self.hold_pick is None else self.hold_pick == i
                    pick[better] = i
                    best_cost = np.where(better, cost, best_cost)
                    best_V = np.where(better[:, None, None], trial["V"][rows], best_V)
                    best_U = np.where(better[:, None, None], trial["U"][rows], best_U)
                    best_X = np.where(better[:, None, None], trial["X"][rows], best_X)
            V = best_V
            self.pick = pick
        action = best_U[:, 0].copy()
        self._plan[:, :-1] = best_V[:, 1:]
        self._plan[:, -1] = 0.0
        self._hopper(self._pilot, np.concatenate([q, qd], axis=1), mode, like, x_ref, False)  # the pilot follows the robot
        self.cost, self.planned = best_cost, best_X
        return action
