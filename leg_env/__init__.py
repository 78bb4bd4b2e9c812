"""leg-env: the planar floating-base leg as an exact, fast Gymnasium environment.

Importing the package registers ``leg_env/PlanarLegStance-v0`` (``gymnasium.make`` and
``gymnasium.make_vec``). It stays cheap: the environments, and the numba kernels behind them,
load on first use, and pygame only when a frame is drawn.
"""

import gymnasium

from .params import LegParams

__all__ = ["LegParams", "StanceConfig", "PlanarLegStanceEnv", "PlanarLegStanceVectorEnv", "ENV_ID"]
__version__ = "0.1.0"

ENV_ID = "leg_env/PlanarLegStance-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID,
        entry_point="leg_env.envs.stance:PlanarLegStanceEnv",
        vector_entry_point="leg_env.envs.vector:PlanarLegStanceVectorEnv",
        max_episode_steps=1000,
    )


def __getattr__(name: str):
    if name == "StanceConfig":
        from .task import StanceConfig

        return StanceConfig
    if name in ("PlanarLegStanceEnv", "PlanarLegStanceVectorEnv"):
        from . import envs

        return getattr(envs, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
