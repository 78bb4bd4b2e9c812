"""leg-env: the planar floating-base leg as an exact, fast Gymnasium environment.

Importing the package registers every task id of ``leg_env.tasks.REGISTRY`` (``gymnasium.make`` and
``gymnasium.make_vec``): ``leg_env/PlanarLegStance-v0``, ``leg_env/PlanarLegStance-v1``,
``leg_env/PlanarLegPush-v0`` and ``leg_env/PlanarLegHop-v0``. It stays cheap: the environments load on first use,
and pygame only when a frame is drawn. The physics and the tasks run in the compiled core (``leg_env/_core``,
C, built at install): nothing is compiled at run time.
"""

import gymnasium

from .params import LegParams
from .tasks import REGISTRY

__all__ = ["LegParams", "StanceConfig", "PlanarLegStanceEnv", "PlanarLegStanceVectorEnv", "ENV_ID", "ENV_IDS"]
__version__ = "0.1.0"

ENV_ID = "leg_env/PlanarLegStance-v0"
ENV_IDS = tuple(REGISTRY)

for _id, (_task, _kwargs) in REGISTRY.items():
    if _id in gymnasium.registry:
        continue
    if _task == "stance":  # the balance task's own classes (and documentation)
        gymnasium.register(
            id=_id,
            entry_point="leg_env.envs.stance:PlanarLegStanceEnv",
            vector_entry_point="leg_env.envs.vector:PlanarLegStanceVectorEnv",
            max_episode_steps=1000,
            kwargs=dict(_kwargs),
        )
    else:
        gymnasium.register(
            id=_id,
            entry_point="leg_env.envs.single:LegEnv",
            vector_entry_point="leg_env.envs.vector:LegVectorEnv",
            max_episode_steps=1000,
            kwargs={"task": _task, **_kwargs},
        )


def __getattr__(name: str):
    if name == "StanceConfig":
        from .tasks.stance import StanceConfig

        return StanceConfig
    if name in ("PlanarLegStanceEnv", "PlanarLegStanceVectorEnv"):
        from . import envs

        return getattr(envs, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
