"""Features extractors for SB3 policies on leg-env's tasks.

``CommandGains`` gives a command-following task's networks the observation and its products with the command: the
first layer then holds, besides its weights on the state, weights that change linearly with the command (a gain
schedule), where an MLP on the observation alone has to build such products from its nonlinearities. Name it in
``train/hyperparams/ppo.yml`` (or ``--params``) by its class path::

    policy_kwargs:
      features_extractor_class: train.features.CommandGains
"""

from __future__ import annotations

import gymnasium as gym
import torch as th
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

__all__ = ["CommandGains"]


class CommandGains(BaseFeaturesExtractor):
    """The observation ``x`` (``(n,)`` Box) followed by ``x * x[command]``: ``2 n`` features, no parameters.

    Args:
        observation_space: a flat ``Box`` observation space.
        command: the index of the command entry (by default the hop task's, ``leg_env.tasks.base.Obs.command``).
            With ``VecNormalize`` the command the products see is the normalised one, centred on the commands'
            mean.

    Raises:
        TypeError: the space is not a flat ``Box``, or ``command`` is not an int.
        ValueError: ``command`` is not an index of the observation.
    """

    def __init__(self, observation_space: gym.spaces.Box, command: int | None = None):
        if not isinstance(observation_space, gym.spaces.Box) or len(observation_space.shape) != 1:
            raise TypeError(f"CommandGains needs a flat Box observation space, got {observation_space}")
        if command is None:
            from leg_env.tasks.base import Obs

            command = int(Obs.command)
        if isinstance(command, bool) or not isinstance(command, int):
            raise TypeError(f"CommandGains: command must be an int index, got {command!r}")
        n = observation_space.shape[0]
        if not 0 <= command < n:
            raise ValueError(f"CommandGains: command must index the observation's {n} entries, got {command}")
        super().__init__(observation_space, features_dim=2 * n)
        self.command = command

    def forward(self, observations: th.Tensor) -> th.Tensor:
        x = observations if observations.is_floating_point() else observations.float()  # float64 kept (derivatives)
        return th.cat([x, x * x[:, self.command : self.command + 1]], dim=1)
