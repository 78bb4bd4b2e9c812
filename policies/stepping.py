"""A model-based push-recovery controller for ``leg_env/PlanarLegPush-v2``: the LQR, and a quick hop for large pushes.

With the foot planted, the only way to stop a push is the torso: the stance LQR (``policies.lqr``) turns it to
tilt the ground force, and from about 25 N over 0.1 s the torso reaches its 1 rad limit or the knee folds
(the LQR's 90% level is 2.25 N s). A larger push needs the foot to move, which for one leg is a hop. This
controller keeps the LQR for small pushes and hops for large ones; the hop is the hopper of ``policies.hopper``
(Raibert's decomposition) started at the push, with gains for one short, low hop (``STEP_GAINS``).

1. **Push observer.** The push is not observed, but its effect is. Over a control step in which the foot
   sticks at both ends, the whole-body momentum balance ``m dv_com/dt = F + lam_x`` gives

       F_hat = m (v_com(t) - v_com(t - dt)) / dt - (lam_x(t) + lam_x(t - dt)) / 2,

   with ``v_com`` the COM's horizontal velocity computed from the observation (base velocity, angles and
   rates) and ``lam_x`` the observed ground force (trapezoidal mean over the step). On the push's first step
   it reads the force to within a few percent (``tests/test_stepping.py``); impacts and slips make it
   unreliable, so it is read only between two sticking observations. An episode's first observation is not
   used: its ground force is not the one under the first step's torque (the torque is held over a step, and
   the trapezoid assumes the force changes only with the state).
2. **Gate.** ``|F_hat| > force_threshold`` (20 N), with the foot on the ground and not within ``cooldown``
   steps of the last hop, starts a hop for that robot; otherwise the LQR acts.
3. **Hop.** The hopper, started afresh for that robot (crouch, push, release; in flight the foot is placed at
   Raibert's neutral point plus a speed correction, which lands it ahead of the moving COM; in stance the
   ground force's moment steers the angular momentum), with the apex command ``hop_command``.
4. **Hand-over.** ``settle_steps`` steps after the touchdown, once the base sinks slower than
   ``exit_sink_speed``, the LQR takes over again (balancing about the new foot position); a hop that has not
   handed over after ``max_hop_steps`` does so then.

The gate's threshold and every hop gain were tuned together (``STEP_GAINS``' docstring); cooldown and the
step limit were fixed. The controller reads only the observation (18 entries) and the model (``LegParams``,
the task's config); it is batch-capable, and keeps per-robot state (the observer's last velocity and
force, the hop's phase and its step count, the hopper's own state). ``predict`` takes ``episode_start``
(SB3's convention, as ``train.residual`` passes it); ``reset()`` starts every robot anew at the next call.
"""

from __future__ import annotations

import numpy as np

from leg_env.physics.params import LegParams
from leg_env.tasks.base import Obs
from policies.base import BatchedController
from policies.hopper import HopperController
from policies.recovery import com_from_observation, lqr_and_hopper

__all__ = ["SteppingController", "STEP_GAINS"]

STEP_GAINS = dict(
    touchdown_length=0.9316408315229778,
    speed_gain=0.09262343161882315,
    stance_time=0.30616873970286645,
    position_gain=0.4847660648420858,
    liftoff_knee=0.5493350295473376,
    crouch=(0.01465658542439438, 0.022412998136002463),
    sink_speed=1.8945194011526976,
    crouch_decel=7.177531845898703,
)
"""The hopper's gains for the recovery hop (``policies.hopper.HopperController``'s arguments). Found with the
gate's settings (``force_threshold``, ``hop_command``, ``settle_steps``, ``exit_sink_speed``) by a cross-entropy
search over those 12 numbers: 12 candidates per round, each run on 160 robots with one push each of 22-40 N
(seeds 3000 + 1000 k in round k, none an evaluation seed), scored by survival over 3.5 s plus half the survival
below 28 N; 49 rounds, the mean of the best three kept, starting from the gated Stance-v1 hop's gains."""


class SteppingController(BatchedController):
    """The LQR, and a hop when the observed push exceeds ``force_threshold`` (module docstring).

    Args:
        params: the robot (``LegParams``, a dict, or None for the defaults).
        config: the task (``PushConfig``/``StanceConfig`` or a dict of its fields; None: ``PushConfig()``): the LQR's
            cost, ``dt``, ``mu`` and the torque limits.
        force_threshold: the observed push [N] above which a hop starts.
        hop_command: the apex command given to the hopper [m of COM rise].
        settle_steps: control steps after the touchdown before the LQR may take over.
        exit_sink_speed: the LQR takes over once the base sinks slower than this [m/s].
        max_hop_steps: a hop hands over after this many steps whatever its state.
        cooldown: control steps after a hand-over during which no hop starts.
        hop_gains: the hopper's keyword arguments (default ``STEP_GAINS``).

    Attributes:
        lqr, hopper: the two controllers; hopping: which robots are in a hop (bool ``(N,)``);
        push_estimate: each robot's last observed push ``F_hat`` [N] (0 where it was not read).
    """

    def __init__(
        self,
        params: LegParams | dict | None = None,
        config=None,
        force_threshold: float = 20.01988877859218,
        hop_command: float = 0.0795033823166908,
        settle_steps: int = 2,
        exit_sink_speed: float = 0.2872079559336835,
        max_hop_steps: int = 150,
        cooldown: int = 30,
        hop_gains: dict | None = None,
    ):
        from leg_env.tasks.push import PushConfig

        gains = STEP_GAINS if hop_gains is None else hop_gains
        self.params, self.config, self.lqr, self.hopper = lqr_and_hopper(params, config, PushConfig, gains)
        self.force_threshold, self.hop_command = float(force_threshold), float(hop_command)
        self.settle_steps, self.exit_sink_speed = int(settle_steps), float(exit_sink_speed)
        self.max_hop_steps, self.cooldown = int(max_hop_steps), int(cooldown)
        p = self.params
        self.mass = p.m_b + p.m1 + p.m2
        self.weight = self.mass * p.g

    widths, task = (18, 19, 20, 21), "the unilateral balance tasks: 18 entries, 19 on PlanarLegPush-v2, 2 more with observe_action (read: the first 18)"

    def _allocate(self, n: int) -> None:
        self.hopping, self.push_estimate = np.zeros(n, dtype=bool), np.zeros(n)
        self._age, self._landed_at, self._cool = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        self._flew, self._run = np.zeros(n, dtype=bool), np.zeros(n, dtype=np.int64)
        self._v, self._lam_x = np.zeros(n), np.zeros(n)

    def _start(self, rows: np.ndarray, batch: np.ndarray) -> None:
        self.hopping[rows] = False
        self.push_estimate[rows] = 0.0
        self._age[rows] = 0
        self._landed_at[rows] = -1
        self._flew[rows] = False
        self._cool[rows] = 0
        self._run[rows] = -1  # the reset's observation counts for nothing: its force is not under a step's torque

    continuous_state = ("_v", "_lam_x", "push_estimate") + tuple("hopper." + n for n in HopperController.continuous_state)
    """The per-robot state that moves with the robot: the observer's last COM velocity and ground force, its push
    estimate, and the hopper's."""
    discrete_state = ("hopping", "_age", "_landed_at", "_flew", "_cool", "_run") + tuple(
        "hopper." + n for n in HopperController.discrete_state)
    """The per-robot state that changes only at thresholds: the hop's flags and counters, the observer's run of
    sticking observations, and the hopper's."""

    def act(self, batch: np.ndarray) -> np.ndarray:
        contact = self.observe(batch)
        start = self.gate(contact)
        return self.follow(batch, contact, start)

    def observe(self, batch: np.ndarray) -> np.ndarray:
        """1. The push observer, between two sticking observations (``_run``: sticking observations in a row): sets
        ``push_estimate``; returns which robots' feet are on the ground."""
        _, _, v = com_from_observation(batch, self.params)
        lam_x = batch[:, Obs.lam_x].astype(np.float64) * self.weight
        contact = batch[:, Obs.contact] > 0.5
        self._run = np.where(contact & (batch[:, Obs.slip] == 0.0), self._run + 1, 0)
        self.push_estimate = np.where(
            self._run >= 2, self.mass * (v - self._v) / self.config.dt - 0.5 * (lam_x + self._lam_x), 0.0
        )
        self._v, self._lam_x = v, lam_x
        return contact

    def gate(self, contact: np.ndarray) -> np.ndarray:
        """2. The gate: the robots whose hop starts now (``(N,)`` bool)."""
        start = ~self.hopping & contact & (self._cool <= 0) & (np.abs(self.push_estimate) > self.force_threshold)
        self.hopping |= start
        self._age[start], self._landed_at[start], self._flew[start] = 0, -1, False
        return start

    def hand_over(self, contact: np.ndarray, vy_b: np.ndarray) -> None:
        """4. The hand-over: a hop ends ``settle_steps`` after its touchdown once the base sinks slower than
        ``exit_sink_speed``, or after ``max_hop_steps``."""
        self._flew |= self.hopping & ~contact
        touchdown = self.hopping & contact & self._flew & (self._landed_at < 0)
        self._landed_at[touchdown] = self._age[touchdown]
        settled = (self._landed_at >= 0) & (self._age - self._landed_at >= self.settle_steps) & (vy_b > -self.exit_sink_speed)
        done = self.hopping & (settled | (self._age >= self.max_hop_steps))
        self.hopping &= ~done
        self._cool[done] = self.cooldown

    def follow(self, batch: np.ndarray, contact: np.ndarray, start: np.ndarray) -> np.ndarray:
        """4. and 3.: the hand-over, then the hop or the LQR: actions ``(N, 2)`` float32."""
        self.hand_over(contact, batch[:, Obs.vy_b])
        action, _ = self.lqr.predict(batch)
        if self.hopping.any():
            self.hopper.act_on(batch, self.hop_command, start, self.hopping, action)
        self._age += 1
        self._cool -= 1
        return action
