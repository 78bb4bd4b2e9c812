"""A model-predictive hopping controller for ``leg_env/PlanarLegHop-v4``: iLQR through the contact events on the
exact Jacobians of the hybrid step, around the hopper.

**The plan.** At every control step the controller rebuilds the robot's state from the observation and rolls a plan
out over ``horizon`` control steps (1 s: the rest of a hop and the next one) on the simulator's own step
(``leg_env.physics.derivatives.hybrid_step_jacobians``: the map the env steps, its touchdowns, impacts, lift-offs and
stick/slip changes located inside the step). The plan is the hopper (``policies.hopper``: Raibert's servos; a deeper crouch
than its default and a dwell at the crouch's bottom) in closed loop, plus a correction ``v_t`` of its action at every step, ``a_t = clip(pi(x_t) + v_t, -1, 1)``. One iteration of
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
and the task (``HopConfig``). Its plans are rolled out in the compiled core (``_rollout``: ``kernels.hop_rollout``, the
hopper's law, its differences and the step with its Jacobians over a whole plan in one call), as is the backward
pass; its compute grows linearly with the horizon and the line search's steps, and per robot it falls with the batch
(``benchmarks/bench_mpc.py``). The iLQR itself is ``policies.ilqr``'s, which the push task's MPC
(``policies.push_mpc``) shares.
"""

from __future__ import annotations

import numpy as np

from leg_env._core import kernels
from leg_env.physics import contact as _contact
from leg_env.physics.params import LegParams
from leg_env.tasks.base import Obs
from policies.hopper import HopperController
from policies.ilqr import PilotILQR

__all__ = ["HopMPC"]


class HopMPC(PilotILQR):
    """iLQR model-predictive hopping controller with SB3's ``predict`` (module docstring).

    Args:
        params: the robot (``LegParams``, a dict, or None for the defaults).
        config: the task (``HopConfig`` or a dict of its fields; None: the defaults).
        horizon: the plan's length in control steps (100: 1 s, the rest of a hop and the next).
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
            deeper crouch, ``crouch=(0.05, 0.5)`` (on 24 episodes of 10 s the torso's tilt fell from 8.7 to 5.4 degrees
            RMS, the apex error and the power alike), and a dwell at the crouch's bottom until 0.45 s after the
            touchdown, ``dwell=0.45`` (about the same work a hop over a longer stance: on 96 episodes of seeds 60000..
            the positive actuator work per second fell from 48.1 to 40.5 W on the 87 the hopper survives, the
            hopper's 44.1 W, the apex error from 0.89 to 0.82 cm, with a horizon of 1 s and ``stance_grace`` 0.8 s).
        fall_cost: the cost of a step fallen or too long on the ground; stance_cost: of a step on the ground past
            stance_grace [s].
        clip_smoothing: the width of the band inside the action's bounds over which the backward pass's clip
            derivative fades from 1 to 0 (``clip_derivative``; 0: the clip's own 0 or 1) [action units].
        law_step: the step of the centred differences of the hopper's law inside the plan [m, rad, m/s, rad/s]: at
            1e-6 their rounding alone made the MPC's law disagree with itself under a change of the state of 1e-6.
        replan_every: plan at every this many control steps (1: every step), and sooner where the contact mode is
            not the plan's; in between, the hopper's action plus the last plan's correction at that step and the backward
            pass's feedback on the state's departure from the plan (``policies.ilqr.PilotILQR._follow_held``).

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
        horizon: int = 100,
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
        stance_grace: float = 0.8,
        stance_cost: float = 10.0,
        crouch_limit: float = 1.6,
        charge_apex: str = "flight",
        warm_start: bool = False,
        iterations: int = 1,
        hopper: dict | None = None,
        clip_smoothing: float = 0.05,
        law_step: float = 1e-5,
        replan_every: int = 1,
    ):
        from leg_env.physics.dynamics import com_position
        from leg_env.tasks.base import nominal_state
        from leg_env.tasks.hop import HopConfig

        p = LegParams.from_any(params)
        c = config if isinstance(config, HopConfig) else HopConfig.from_kwargs(config)
        if charge_apex not in ("flight", "liftoff"):
            raise ValueError(f"charge_apex must be 'flight' or 'liftoff', got {charge_apex!r}")
        self._setup(p, c, horizon, steps, iterations, warm_start, regularisation, effort_weight, power_weight,
                    smooth_weight, clip_smoothing, law_step,
                    positive=dict(apex_scale=apex_scale, tilt_scale=tilt_scale, tilt_rate_scale=tilt_rate_scale,
                                  drift_scale=drift_scale, drift_rate_scale=drift_rate_scale, limit_scale=limit_scale),
                    nonnegative=dict(limit_margin=limit_margin, fall_cost=fall_cost, terminal_weight=terminal_weight,
                                     stance_grace=stance_grace, stance_cost=stance_cost),
                    replan_every=replan_every)
        self.y_stand = float(com_position(nominal_state(p, c).q, p)[1])
        self.scales = dict(apex=apex_scale, tilt=tilt_scale, tilt_rate=tilt_rate_scale, drift=drift_scale,
                           drift_rate=drift_rate_scale, limit=limit_scale)
        self.limit_margin, self.fall_cost = float(limit_margin), float(fall_cost)
        self.terminal_weight = float(terminal_weight)
        self.stance_grace, self.stance_cost = float(stance_grace), float(stance_cost)
        self.crouch_limit, self.charge_apex = float(crouch_limit), charge_apex
        self.hopper_settings = dict(crouch=(0.05, 0.5), dwell=0.45) if hopper is None else dict(hopper)
        HopperController(p, c, **self.hopper_settings)  # checks them

    pilot_state = HopperController.continuous_state + HopperController.discrete_state
    n_residuals = 7

    # ---- per-robot state

    def _new_pilot(self, n: int):
        h = HopperController(self.params, self.config, **self.hopper_settings)
        h._n = n
        return h

    def _allocate(self, n: int) -> None:
        self._plan = np.zeros((n, self.horizon, 2))  # the corrections v added to the hopper's actions
        # the hopper along the robot's own trajectory, whose state each plan starts from
        self._pilot = HopperController(self.params, self.config, **self.hopper_settings)
        self._pilot._n = n
        self._pilot._allocate(n)
        self._pilot._start(np.ones(n, dtype=bool))
        self._probe = HopperController(self.params, self.config, **self.hopper_settings)  # the numpy rollout's differences
        self._allocate_held(n)

    def _start(self, rows: np.ndarray, batch: np.ndarray | None = None) -> None:
        self._plan[rows] = 0.0
        self._pilot._start(rows)
        self._since[rows] = self.replan_every

    # ---- cost

    def residuals(self, x: np.ndarray, flight: np.ndarray, ctx: dict) -> np.ndarray:
        """The state's residuals ``(..., 7)`` (module docstring) for states ``x`` ``(..., 10)``; ``flight``: the steps
        whose apex is charged (``_charged``); ``ctx["target"]``, ``ctx["x_ref"]``: the apex's target height and the
        COM's start [m]."""
        s, c, g = self.scales, self.config, self.params.g
        target, x_ref = ctx["target"], ctx["x_ref"]
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

    def _charged(self, modes):
        """The steps ``(N, H)`` whose end state's apex is charged: every step that ends in flight (``charge_apex="flight"``)
        or only those that lift off (``"liftoff"``)."""
        if self.charge_apex == "flight":
            return modes[:, 1:] == _contact.FLIGHT
        return (modes[:, 1:] == _contact.FLIGHT) & (modes[:, :-1] != _contact.FLIGHT)

    def _penalty(self, roll, ctx) -> np.ndarray:
        """``fall_cost`` where the state has fallen or the robot has not hopped for too long, ``stance_cost`` where it
        has stood past ``stance_grace``."""
        c, p = self.config, self.params
        x, ground, stance = roll["X"][:, 1:], roll["ground"][:, 1:], roll["stance"][:, 1:]
        knee_y = x[..., 1] + p.l1 * np.sin(x[..., 2] + x[..., 3])
        fallen = (x[..., 1] < c.min_base_height) | (x[..., 1] < knee_y) | (np.abs(x[..., 2]) > c.max_torso_angle)
        return self.fall_cost * (fallen | (ground > c.max_ground_time)) + self.stance_cost * (stance > self.stance_grace)

    def _track(self, roll, ctx) -> None:
        """The plan's time on the ground since its last hop (``ground``) and in its current stance (``stance``), from
        its modes and each step's time in flight: a hop is a flight of at least the task's ``min_flight`` (counted
        from the plan's start)."""
        c, modes, flight_time = self.config, roll["modes"], roll["flight_time"]
        n, H = flight_time.shape
        steps = np.arange(H)
        flying = modes[:, 1:] == _contact.FLIGHT  # whether step t ends in flight
        flown = np.cumsum(np.where(flying, flight_time, 0.0), axis=1)
        run = flown - np.maximum.accumulate(np.where(flying, 0.0, flown), axis=1)  # the flight so far, at a step in flight
        hopped = flying & (run >= c.min_flight)
        since = np.concatenate([[0.0], np.cumsum(np.full(H, c.dt))])  # m steps of dt, summed as the clock sums them

        def clock(start, reset):
            """start + dt per step, from 0 again after each step where ``reset``."""
            last = np.maximum.accumulate(np.where(reset, steps, -1), axis=1)
            out = np.cumsum(np.concatenate([start[:, None], np.full((n, H), c.dt)], axis=1), axis=1)
            out[:, 1:] = np.where(last >= 0, since[steps - last], out[:, 1:])
            return out

        ground = np.asarray(ctx["ground"], dtype=np.float64)
        roll["ground"] = clock(ground, hopped)
        roll["stance"] = clock(np.where(modes[:, 0] == _contact.FLIGHT, 0.0, ground), flying)

    # ---- the hopper inside the plan

    def _rollout(self, source, q, qd, mode, ctx, V, nominal=None, k=None, K=None, jacobians=False, copies=1):
        """``PilotILQR._rollout`` compiled (``leg_env._core.kernels.hop_rollout``: the hopper's law, its derivative
        and the step inside one call per batch of plans): the same plans, to the bit without the line search's
        feedback ``k + K dx`` and to rounding with it."""
        n, H = V.shape[0], self.horizon
        tile = lambda a: np.tile(a, copies) if copies > 1 else a  # noqa: E731
        flat = lambda a: None if a is None else np.ascontiguousarray(a, dtype=np.float64).reshape(n, -1)  # noqa: E731
        X, modes = np.empty((n, H + 1, 10)), np.empty((n, H + 1), dtype=np.int64)
        out = dict(X=X, modes=modes, U=np.empty((n, H, 2)), V=np.empty((n, H, 2)), flight_time=np.empty((n, H)))
        if jacobians:
            out.update(A=np.empty((n, H, 10, 10)), B=np.empty((n, H, 10, 2)), Du=np.empty((n, H, 2, 10)),
                       D=np.empty((n, H, 2)))
        c = self.config
        kernels.hop_rollout(
            np.ascontiguousarray(q, dtype=np.float64), np.ascontiguousarray(qd, dtype=np.float64), mode.astype(np.int64),
            tile(source._bias), tile(source._apex), tile(source._phase), tile(source._was_flight), tile(source._since_touchdown),
            np.ascontiguousarray(ctx["like"][:, Obs.command]), np.ascontiguousarray(ctx["x_ref"], dtype=np.float64),
            self.params.array, source._gains[None], flat(V), flat(k), flat(K), flat(nominal), c.dt, c.substeps,
            c.max_angle, c.mu, self.law_step, self.clip_smoothing, X.reshape(n, -1), modes, out["U"].reshape(n, -1),
            out["V"].reshape(n, -1), out["flight_time"], *(flat(out[name]) if jacobians else None for name in ("A", "B", "Du", "D")))
        self._track(out, ctx)
        return out

    def _law(self, h, x, mode, ctx) -> np.ndarray:
        """The hopper's torques at model states ``x`` (the COM's drift exact on the model, where the hopper
        dead-reckons it)."""
        h._x0 = self.com(x)[0] - ctx["x_ref"]
        return h.torque(self._observation(x, mode, ctx["like"]))

    def exact_actions(self, batch: np.ndarray) -> np.ndarray:
        """``act``'s actions in float64, before their rounding to float32 (for the closed loop's derivatives)."""
        self._check_finite(batch)
        q, qd, mode = self.state(batch)
        x = np.concatenate([q, qd], axis=1)
        ctx = dict(like=np.array(batch[:, :22], dtype=np.float64), target=self.y_stand + batch[:, Obs.command],
                   x_ref=self.com(x)[0] - batch[:, Obs.com_drift],
                   ground=np.array(batch[:, Obs.ground_time], dtype=np.float64))
        due = self._due(mode)
        action = np.empty((len(q), 2))
        if due.all():
            action[:] = self._plan_actions(self._pilot, q, qd, mode, ctx, self._plan)
        elif due.any():
            V = self._plan[due]
            action[due] = self._plan_actions(self._pilot_rows(self._pilot, due), q[due], qd[due], mode[due],
                                             {name: value[due] for name, value in ctx.items()}, V)
            self._plan[due] = V
        pi = self._law(self._pilot, x, mode, ctx) / self.torque_limit  # the pilot follows the robot
        if not due.all():
            action[~due] = self._follow_held(~due, x[~due], pi[~due])
        self._hold(due)
        return action
