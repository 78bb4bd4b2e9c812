"""A model-predictive push-recovery controller for ``leg_env/PlanarLegPush-v2``: iLQR through the contact events on
the exact Jacobians of the hybrid step, around the stepping controller, while a push is being recovered from.

**When it plans.** Standing, the stepping controller's LQR holds the robot still on a fraction of a watt, and there
is nothing for a plan to improve. Once the stepping controller's push observer starts a recovery hop
(``policies.stepping``: ``|F_hat| > force_threshold``), and until ``after_hop`` control steps after the hop has
handed over to the LQR again, the controller plans (``policies.ilqr``): the stepping controller in closed loop (its
hop, its hand-over, the LQR after it; no new hop starts inside a plan) plus a correction of its action at every step,
improved by one iteration of iLQR on the step's exact Jacobians, with the saltation of each lift-off and touchdown.
Elsewhere it acts as the stepping controller does.

**The push inside the plan.** The push is not observed; the stepping controller's observer reads it (``F_hat``, the
whole-body momentum balance) while the foot sticks. With ``model_push`` the plan holds the last such reading over the
rest of the push (its duration is the task's ``push_duration``, counted from the observation that first saw it), as a
horizontal force on the torso (``hybrid_step``'s ``load_x``); without, the plan assumes no force and the next control
step's plan sees the push's effect.

**Cost** per step of the plan, in residuals ``r`` (``cost = |r|^2``):

* ``tilt``, ``tilt_rate``: ``th_b / tilt_scale``, ``th_b' / tilt_rate_scale``: the torso upright and still;
* ``speed``: ``x_com' / speed_scale``: the push's momentum taken out;
* ``balance``: ``(x_com - x_foot) / balance_scale`` on the ground: the COM over the foot, where the LQR can hold it;
* ``limit``: how far a joint is inside the last ``limit_margin`` of its range, over ``limit_scale`` (the stepping
  controller's hops that fail mostly straighten the knee past its limit at the push-off);
* ``effort``, ``power``, the corrections: as every plan of ``policies.ilqr``;
* without derivative: ``fall_cost`` a step where the plan has fallen (the task's ends: the base too low, the torso
  past its angle, a joint out of its range).

The controller reads only the observation (18 entries of the unilateral ground, as the stepping controller does),
the model (``LegParams``) and the task (``PushConfig``).
"""

from __future__ import annotations

import copy

import numpy as np

from leg_env.physics import contact as _contact
from leg_env.physics.dynamics import foot_position
from leg_env.physics.params import LegParams
from leg_env.tasks.base import OBS_DIM_UNILATERAL, Obs
from policies.ilqr import PilotILQR
from policies.stepping import SteppingController

__all__ = ["PushMPC"]


class PushMPC(PilotILQR):
    """iLQR model-predictive push recovery around the stepping controller, with SB3's ``predict`` (module docstring).

    Args:
        params: the robot (``LegParams``, a dict, or None for the defaults).
        config: the task (``PushConfig`` or a dict of its fields; None: the defaults).
        horizon: the plan's length in control steps (40: a recovery hop and its landing).
        steps, iterations, warm_start, regularisation, effort_weight, power_weight, smooth_weight, clip_smoothing,
            law_step: the iLQR's (``policies.ilqr.PilotILQR``; ``policies.mpc.HopMPC`` gives their reasons).
        tilt_scale, tilt_rate_scale, speed_scale, balance_scale, limit_scale: the residuals' scales [rad, rad/s,
            m/s, m, rad].
        limit_margin: [rad] from each end of the joints' ranges.
        fall_cost: the cost of a step fallen. terminal_weight: the last step's state residuals' weight.
        after_hop: control steps after a hop's hand-over during which the controller still plans.
        model_push: hold the observed push over the rest of its duration inside the plan.
        stepping: the stepping controller's keywords (``SteppingController``; None: its defaults).

    After each ``predict``, ``planning`` ``(N,)`` marks the robots that planned, and ``planned``, ``cost`` and
    ``pick`` hold their plans (``policies.ilqr.PilotILQR``), in the order of those robots.

    Raises:
        TypeError: an unknown keyword. ValueError: a setting out of its range (the message names it).
    """

    widths = (21, 19)
    task = "PlanarLegPush-v2: 21 entries, 19 without observe_action"
    pilot_state = SteppingController.continuous_state + SteppingController.discrete_state
    n_residuals = 6

    def __init__(
        self,
        params: LegParams | dict | None = None,
        config=None,
        horizon: int = 40,
        steps: tuple = (1.0, 0.5, 0.25),
        iterations: int = 1,
        warm_start: bool = False,
        regularisation: float = 10.0,
        tilt_scale: float = 0.2,
        tilt_rate_scale: float = 2.0,
        speed_scale: float = 0.5,
        balance_scale: float = 0.1,
        limit_margin: float = 0.1,
        limit_scale: float = 0.02,
        effort_weight: float = 0.01,
        power_weight: float = 0.0,
        smooth_weight: float = 0.3,
        fall_cost: float = 100.0,
        terminal_weight: float = 1.0,
        after_hop: int = 20,
        model_push: bool = True,
        clip_smoothing: float = 0.05,
        law_step: float = 1e-5,
        stepping: dict | None = None,
    ):
        from leg_env.tasks.push import PushConfig

        p = LegParams.from_any(params)
        c = config if isinstance(config, PushConfig) else PushConfig.from_kwargs(config)
        if int(after_hop) < 0:
            raise ValueError(f"after_hop must be at least 0, got {after_hop}")
        self._setup(p, c, horizon, steps, iterations, warm_start, regularisation, effort_weight, power_weight,
                    smooth_weight, clip_smoothing, law_step,
                    positive=dict(tilt_scale=tilt_scale, tilt_rate_scale=tilt_rate_scale, speed_scale=speed_scale,
                                  balance_scale=balance_scale, limit_scale=limit_scale),
                    nonnegative=dict(limit_margin=limit_margin, fall_cost=fall_cost, terminal_weight=terminal_weight))
        self.scales = dict(tilt=tilt_scale, tilt_rate=tilt_rate_scale, speed=speed_scale, balance=balance_scale,
                           limit=limit_scale)
        self.limit_margin, self.fall_cost = float(limit_margin), float(fall_cost)
        self.terminal_weight = float(terminal_weight)
        self.after_hop, self.model_push = int(after_hop), bool(model_push)
        self.stepping_settings = dict(stepping or {})
        self._template = SteppingController(p, c, **self.stepping_settings)  # checks them
        self.planning = np.zeros(0, dtype=bool)

    # ---- per-robot state

    def _new_pilot(self, n: int):
        s = copy.copy(self._template)  # the LQR is shared (it keeps no state), the hopper copied
        s.hopper = copy.copy(self._template.hopper)
        s._n = s.hopper._n = n
        return s

    def _allocate(self, n: int) -> None:
        self._plan = np.zeros((n, self.horizon, 2))
        self._pilot = SteppingController(self.params, self.config, **self.stepping_settings)  # along the robot's own trajectory
        self._pilot._n = n
        self._pilot._allocate(n)
        self._probe = self._new_pilot(0)
        self._push_force, self._push_left = np.zeros(n), np.zeros(n, dtype=np.int64)
        self.planning = np.zeros(n, dtype=bool)

    def _start(self, rows: np.ndarray, batch: np.ndarray) -> None:
        self._plan[rows] = 0.0
        self._pilot._start(rows, batch)
        self._push_force[rows], self._push_left[rows] = 0.0, 0

    def _snapshot(self, rows: np.ndarray, start: np.ndarray):
        """The pilot's state at ``rows`` as the step's law finds it (its gate passed; the hopper of a hop starting now
        started): a plan's source."""
        pilot = self._pilot
        if pilot.hopper._n != pilot._n:  # no robot has hopped yet: the hopper as it is made
            pilot = copy.copy(pilot)
            pilot.hopper = copy.copy(pilot.hopper)
            pilot.hopper._allocate(pilot._n)
            pilot.hopper._start(np.ones(pilot._n, dtype=bool))
        source = self._pilot_rows(pilot, rows)
        source.hopper._start(start[rows])
        return source

    # ---- cost

    def residuals(self, x: np.ndarray, stance: np.ndarray, ctx: dict) -> np.ndarray:
        """The state's residuals ``(..., 6)`` (module docstring) for states ``x`` ``(..., 10)``; ``stance``: the steps
        that end on the ground (``_charged``)."""
        s, c, mg = self.scales, self.config, self.limit_margin
        xc, _, vxc, _ = self.com(x)
        foot_x = foot_position(x[..., :5], self.params)[..., 0]
        lo_h, hi_h = c.hip_range
        lo_k, hi_k = c.knee_range
        return np.stack([
            x[..., 2] / s["tilt"],
            x[..., 7] / s["tilt_rate"],
            vxc / s["speed"],
            np.where(stance, (xc - foot_x) / s["balance"], 0.0),
            (np.maximum(lo_h + mg - x[..., 3], 0.0) - np.maximum(x[..., 3] - hi_h + mg, 0.0)) / s["limit"],
            (np.maximum(lo_k + mg - x[..., 4], 0.0) - np.maximum(x[..., 4] - hi_k + mg, 0.0)) / s["limit"],
        ], axis=-1)

    def _charged(self, modes):
        return modes[:, 1:] != _contact.FLIGHT

    def _penalty(self, roll, ctx) -> np.ndarray:
        """``fall_cost`` where the plan's state ends the task's episode."""
        c = self.config
        x = roll["X"][:, 1:]
        lo_h, hi_h = c.hip_range
        lo_k, hi_k = c.knee_range
        fallen = ((x[..., 1] < c.min_base_height) | (np.abs(x[..., 2]) > c.max_torso_angle)
                  | (x[..., 3] < lo_h) | (x[..., 3] > hi_h) | (x[..., 4] < lo_k) | (x[..., 4] > hi_k))
        return self.fall_cost * fallen

    def _load(self, t: int, ctx: dict):
        return np.where(t < ctx["push_left"], ctx["push"], 0.0)

    # ---- the stepping controller inside the plan

    def _law(self, s, x, mode, ctx) -> np.ndarray:
        """The stepping controller's torques at model states ``x`` after its gate (its hand-over, then the hop or the
        LQR), in float64; the hopper reads the COM's travel since the hop began from the model, where it
        dead-reckons it (so that no state of the plan's law is hidden from its derivative)."""
        obs = self._observation(x, mode, ctx["like"])
        s.hand_over(mode != _contact.FLIGHT, obs[:, Obs.vy_b])
        tau = s.lqr.torque(obs)
        if s.hopping.any():
            s.hopper._x0 = self.com(x)[0] - ctx["x_hop"]  # the COM's travel since the hop began, exact on the model
            tau = np.where(s.hopping[:, None], s.hopper.torque(obs), tau)
        s._age = s._age + 1
        s._cool = s._cool - 1
        return tau

    def _context(self, batch: np.ndarray, rows: np.ndarray, source, x: np.ndarray) -> dict:
        """The plans' context for the robots ``rows`` (``source``: their pilot, ``_snapshot``; ``x``: their states,
        ``state``'s): the stepping controller's observation's entries that the state does not set (``like``, with the
        hop's command), the push held and its steps left, and where the COM was when the hop began (``x_hop``, the
        plan's frame)."""
        like = np.zeros((int(rows.sum()), OBS_DIM_UNILATERAL + 4))
        like[:, :OBS_DIM_UNILATERAL] = batch[rows, :OBS_DIM_UNILATERAL]
        like[:, Obs.command] = self._pilot.hop_command
        left = self._push_left[rows] if self.model_push else np.zeros(len(like), dtype=np.int64)
        x_hop = self.com(x)[0] - source.hopper._x0
        return dict(like=like, push=self._push_force[rows].copy(), push_left=left.copy(), x_hop=x_hop)

    def exact_actions(self, batch: np.ndarray) -> np.ndarray:
        """``act``'s actions in float64 (the stepping controller's where no robot plans)."""
        self._check_finite(batch)
        pilot = self._pilot
        contact = pilot.observe(batch)
        start = pilot.gate(contact)
        if self.model_push:
            self._push_left[start] = self.config.push_steps - 1
            read = (start | (self._push_left > 0)) & (pilot._run >= 2)
            self._push_force[read] = pilot.push_estimate[read]
        rows = pilot.hopping | (pilot._cool > pilot.cooldown - self.after_hop)
        source = self._snapshot(rows, start) if rows.any() else None
        action = pilot.follow(batch, contact, start).astype(np.float64)
        self.planning = rows
        if source is not None:
            q, qd, mode = self.state(batch[rows])
            ctx = self._context(batch, rows, source, np.concatenate([q, qd], axis=1))
            V = self._plan[rows]
            action[rows] = self._plan_actions(source, q, qd, mode, ctx, V)
            self._plan[rows] = V
        else:  # nobody planned
            self.planned, self.cost, self.pick = np.zeros((0, self.horizon + 1, 10)), np.zeros(0), np.zeros(0, dtype=np.int64)
        self._plan[~rows] = 0.0
        self._push_left = np.maximum(self._push_left - 1, 0)
        return action
