"""Residual PPO: the network learns a correction added to a model-based controller's action.

``python -m train.ppo --residual hopper --residual-scale 0.3`` trains PPO on the env as seen through
``ResidualVecEnv``: the action applied to the robots is ``clip(a_base(obs) + scale * clip(a, -1, 1), -1, 1)``,
where ``a_base`` is the controller's (``lqr``, ``hopper``: ``train.policy_loading.BASELINES``) at the same
observation and ``a`` the network's. SB3's initial actor outputs about 0 (its action layer is initialised
with gain 0.01), so training starts from the controller itself and explores around it. The shipped policy is
``ResidualPolicy``: the same sum at evaluation (``train.evaluate.load_policy`` builds it from the run's
``config.yaml``). It is a PPO policy whose prior is the controller, and is reported as such.

A stateful controller (the hopper keeps per-robot phases and a dead-reckoned position) is given each
batch once per step, with ``episode_start`` set where a sub-env's episode has just begun.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.vec_env import VecEnvWrapper

__all__ = ["ResidualVecEnv", "ResidualPolicy", "residual_action"]


def residual_action(base: np.ndarray, correction: np.ndarray, scale: float) -> np.ndarray:
    """``clip(base + scale * clip(correction, -1, 1), -1, 1)`` as float32."""
    correction = np.clip(np.asarray(correction, dtype=np.float64), -1.0, 1.0)
    return np.clip(np.asarray(base, dtype=np.float64) + scale * correction, -1.0, 1.0).astype(np.float32)


class ResidualVecEnv(VecEnvWrapper):
    """An SB3 ``VecEnv`` whose actions are corrections to ``controller``'s (module docstring)."""

    def __init__(self, venv, controller, scale: float):
        super().__init__(venv)
        self.controller, self.scale = controller, float(scale)
        self._obs = None
        self._starts = None

    def reset(self):
        self._obs = self.venv.reset()
        self._starts = np.ones(self.num_envs, dtype=bool)
        return self._obs

    def step_async(self, actions) -> None:
        base, _ = self.controller.predict(self._obs, episode_start=self._starts)
        self.venv.step_async(residual_action(base, actions, self.scale))

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        self._obs, self._starts = obs, np.asarray(dones, dtype=bool).copy()
        return obs, rewards, dones, infos


class ResidualPolicy:
    """A trained residual network and its controller, with SB3's ``predict`` on raw observations."""

    def __init__(self, network, controller, scale: float):
        self.network, self.controller, self.scale = network, controller, float(scale)
        self.env_kwargs, self.path, self.env_id = network.env_kwargs, network.path, network.env_id

    def reset(self) -> None:
        if hasattr(self.controller, "reset"):
            self.controller.reset()

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        base, _ = self.controller.predict(observation, episode_start=episode_start)
        correction, _ = self.network.predict(observation, deterministic=deterministic)
        return residual_action(base, correction, self.scale), None
