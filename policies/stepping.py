"""A capture-point stepping controller for ``leg_env/PlanarLegPush-v0``: the LQR, and a hop when the COM runs away.

The stance LQR (``policies.lqr``) keeps the foot planted; a push whose impulse moves the capture point

    x_cp = x_com + x_com' / sqrt(g / y_com)        (relative to the foot, ``policies.gated.capture_point``)

more than about 4 cm from the foot leaves it nothing to push against, and it falls (90% survival up to
2.25 N s). This controller watches the capture point at every step. While the foot is on the ground under
the LQR and ``|x_cp| > band``, it hands over to the hopper (``policies.hopper.HopperController`` with the
recovery gains ``policies.gated.HOP_GAINS`` and the command ``hop_command``), whose flight phase places the
foot at Raibert's neutral point ahead of the moving COM; after ``hop_steps`` control steps, once the foot is
on the ground again, the LQR takes over at the new foothold. The hopper's row is started afresh at each
hand-over (its dead-reckoned start is the hand-over point).

Per-robot state: the mode (LQR or hop) and the steps since the last hand-over; ``predict`` takes
``episode_start`` (every such robot starts under the LQR, whose first observation is checked as any
other), ``reset()`` starts every robot anew at the next call, as does a change of batch size.
"""

from __future__ import annotations

import numpy as np

from leg_env.params import LegParams

from .gated import HOP_GAINS, capture_point

__all__ = ["SteppingController"]

_CONTACT = 15  # observation entry: 1 while the foot is on the ground (leg_env.tasks.stance, unilateral)


class SteppingController:
    """The LQR, with a hop whenever the capture point leaves ``[-band, band]`` (module docstring).

    Args:
        params: the robot (``LegParams``, a dict, or None for the defaults).
        config: the task (``StanceConfig``/``PushConfig`` or a dict; None: the balance task's defaults).
        band: the largest capture-point offset from the foot the LQR keeps [m].
        hop_steps: the least control steps of a hop before the LQR may take over (on the ground).
        hop_command: the apex command given to the hopper [m of COM rise].
        hop_gains: the hopper's keyword arguments (default ``policies.gated.HOP_GAINS``).

    Attributes:
        hopping: per robot, whether the hopper is in charge; steps: control steps since the last hand-over.
    """

    def __init__(self, params=None, config=None, band: float = 0.04, hop_steps: int = 30, hop_command: float = 0.06,
                 hop_gains: dict | None = None):  # fmt: skip
        from leg_env.tasks.hop import HopConfig
        from leg_env.tasks.stance import StanceConfig
        from policies.hopper import HopperController
        from policies.lqr import LQRController

        self.params = LegParams.from_any(params)
        if config is None:
            config = StanceConfig(contact="unilateral")
        elif isinstance(config, dict):
            config = StanceConfig.from_kwargs(config)
        self.config = config
        self.lqr = LQRController(self.params, config)
        shared = {k: getattr(config, k) for k in ("dt", "torque_limit", "mu", "nominal_knee")}
        self.hopper = HopperController(self.params, HopConfig.from_kwargs(shared), **(HOP_GAINS if hop_gains is None else hop_gains))
        self.band, self.hop_steps, self.hop_command = float(band), int(hop_steps), float(hop_command)
        self._n = 0

    def reset(self) -> None:
        """Start every robot anew at the next ``predict``."""
        self._n = 0

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3-style ``predict``: actions in [-1, 1] for one observation (18,) or a batch (N, 18)."""
        obs = np.asarray(observation)
        if obs.shape[-1:] != (18,) or obs.ndim not in (1, 2):
            raise ValueError(f"observation must have shape (18,) or (N, 18) (the unilateral balance and push tasks), got {obs.shape}")
        batch = obs.reshape(-1, 18)
        n = batch.shape[0]
        if self._n != n:
            self._n = n
            self.hopping, self.steps = np.zeros(n, dtype=bool), np.zeros(n, dtype=np.int64)
        if episode_start is not None:
            starts = np.asarray(episode_start, dtype=bool).reshape(-1)
            self.hopping[starts], self.steps[starts] = False, 0
        contact = batch[:, _CONTACT] > 0.5
        land = self.hopping & contact & (self.steps >= self.hop_steps)
        self.hopping[land], self.steps[land] = False, 0
        trigger = ~self.hopping & contact & (np.abs(capture_point(batch, self.params)) > self.band)
        self.hopping[trigger], self.steps[trigger] = True, 0
        action, _ = self.lqr.predict(batch)
        if self.hopping.any():
            hop_obs = np.concatenate([batch.astype(np.float32), np.full((n, 1), self.hop_command, dtype=np.float32)], axis=1)
            hop_action, _ = self.hopper.predict(hop_obs, episode_start=trigger)
            action[self.hopping] = hop_action[self.hopping]
        self.steps += 1
        return (action[0] if obs.ndim == 1 else action), None
