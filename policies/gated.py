"""A gated recovery controller for ``leg_env/PlanarLegBalance-v1``: a short backward hop from bad starts, then the LQR.

On the unilateral ground the stance LQR (``policies.lqr``) falls from every start whose capture point is far
behind the foot: with the foot planted, the torso swings to its 1 rad limit. One small backward hop moves the
foot under the falling COM, and the LQR then balances (``policies/baselines/balance_recoveries/``). This
controller makes that choice once per episode, at its first observation:

    x_cp = x_com + x_com' / sqrt(g / y_com)        (the linear inverted pendulum's capture point, relative to the foot)

* ``x_cp < threshold`` (default -4 cm): the hopper (``policies.hopper.HopperController``, with the gains
  ``HOP_GAINS`` and a hop command of ``hop_command``) for the first ``hop_steps`` control steps, then the LQR;
* otherwise the LQR throughout.

``x_com`` and ``y_com`` are the whole-body COM relative to the foot, computed from the observation's base
position (entries 0-1, relative to the contact point), angles (2-4) and rates (5-9), as in
``leg_env.physics.dynamics.com_position``. The rule and its constants were found on the evaluation seeds 10000..10099
of ``train.evaluate`` (96/100 survive there); ``policies/baselines/gated/README.md`` reports it on fresh seeds.

The controller is batch-capable and keeps per-robot state: the decision, the step count since the episode
start and the hopper's own phase and dead-reckoned position (one ``HopperController`` for the batch, each
robot's row started afresh when that robot's hop starts). ``predict`` takes ``episode_start`` (SB3's
convention: true where a robot's observation is the first of an episode, as ``train.residual`` passes it);
``reset()`` starts every robot anew at the next call, as ``train.evaluate.run_episodes`` uses it. A
change of batch size also starts every robot anew.
"""

from __future__ import annotations

import numpy as np

from leg_env.physics.params import LegParams
from policies.base import BatchedController
from policies.recovery import com_from_observation, lqr_and_hopper

__all__ = ["GatedController", "HOP_GAINS", "capture_point"]

HOP_GAINS = dict(
    touchdown_length=0.8631167676204533,
    speed_gain=0.29486700045576825,
    position_gain=0.4302061674394624,
    stance_time=0.4561448313134052,
    liftoff_knee=0.6060534044908222,
    crouch=(0.015345456636464716, 0.19026296491139122),
    sink_speed=1.1802858335314026,
    crouch_decel=7.111144241633681,
)
"""The hopper's gains for the recovery hop (found by a random search on the seven starts that no planted
controller survives; ``policies.hopper.HopperController``'s arguments)."""


def capture_point(obs, params: LegParams) -> np.ndarray:
    """The capture point ``x_com + x_com' / sqrt(g / y_com)`` relative to the foot [m], for observations ``(..., >=10)``."""
    x_com, y_com, vx_com = com_from_observation(obs, params)
    return x_com + vx_com / np.sqrt(params.g / np.maximum(y_com, 1e-9))


class GatedController(BatchedController):
    """Hop back from a start whose capture point is behind ``threshold``, else the LQR (module docstring).

    Args:
        params: the robot (``LegParams``, a dict, or None for the defaults).
        config: the task (``StanceConfig`` or a dict of its fields; None: defaults): the LQR's cost, ``dt`` and
            torque limits; the hopper reads the same ``dt``, ``mu``, ``torque_limit`` and nominal posture.
        threshold: the capture point below which the episode starts with a hop [m].
        hop_steps: control steps of the hopper before the LQR takes over.
        hop_command: the apex command given to the hopper [m of COM rise].
        hop_gains: the hopper's keyword arguments (default ``HOP_GAINS``).

    Attributes:
        lqr, hopper: the two controllers; hopping: the per-robot decision of the current episodes (bool ``(N,)``);
        steps: control steps since each robot's episode started.
    """

    def __init__(
        self,
        params: LegParams | dict | None = None,
        config=None,
        threshold: float = -0.04,
        hop_steps: int = 30,
        hop_command: float = 0.06,
        hop_gains: dict | None = None,
    ):
        from leg_env.tasks.base import StanceConfig

        gains = HOP_GAINS if hop_gains is None else hop_gains
        self.params, self.config, self.lqr, self.hopper = lqr_and_hopper(params, config, StanceConfig, gains)
        self.threshold, self.hop_steps, self.hop_command = float(threshold), int(hop_steps), float(hop_command)

    widths, task = (18, 20), "the unilateral balance: 18 entries, 20 with observe_action (the last action is not read)"

    def decide(self, observation) -> np.ndarray:
        """Whether each robot, at this (first) observation of its episode, hops: ``capture_point < threshold``."""
        return capture_point(observation, self.params) < self.threshold

    def _allocate(self, n: int) -> None:
        self.hopping, self.steps = np.zeros(n, dtype=bool), np.zeros(n, dtype=np.int64)

    def _start(self, rows: np.ndarray, batch: np.ndarray) -> None:
        if rows.any():
            self.hopping[rows] = self.decide(batch[rows])
            self.steps[rows] = 0

    def act(self, batch: np.ndarray) -> np.ndarray:
        action, _ = self.lqr.predict(batch)
        hop = self.hopping & (self.steps < self.hop_steps)
        if hop.any():
            self.hopper.act_on(batch, self.hop_command, hop & (self.steps == 0), hop, action)
        self.steps += 1
        return action
