"""leg-env: the planar floating-base leg as an exact, fast Gymnasium environment.

Importing the package registers every task id of ``leg_env.tasks.REGISTRY`` (``gymnasium.make`` and
``gymnasium.make_vec``), one per task: ``leg_env/PlanarLegStance-v0`` (balance on a pinned foot, the lesson's
model), ``leg_env/PlanarLegBalance-v1`` (balance on the unilateral ground), ``leg_env/PlanarLegPush-v2``
(recover from pushes) and ``leg_env/PlanarLegHop-v4`` (hop to a commanded height). Every id's entry points are
the generic ``leg_env.envs.LegEnv`` and ``LegVectorEnv`` with its task.

The package's rooms: ``leg_env.physics`` (the robot's model and time stepping, no Gymnasium), ``leg_env.tasks``
(one module per task), ``leg_env.envs`` (the single and vector environments), and beside them ``info``,
``randomize``, ``render``, ``sb3`` and ``rllib``. Importing stays cheap: the environments load on first use, and
pygame only when a frame is drawn. The physics and the tasks run in the compiled core (``leg_env/_core``, C,
built at install): nothing is compiled at run time.
"""

import gymnasium

from .physics.params import LegParams
from .tasks import REGISTRY

__all__ = ["LegParams", "StanceConfig", "LegEnv", "LegVectorEnv", "ENV_ID", "ENV_IDS", "ENDINGS"]
__version__ = "0.1.0"  # the package version's one source (pyproject.toml reads it)

ENV_ID = "leg_env/PlanarLegStance-v0"
ENV_IDS = tuple(REGISTRY)
"""Every task id."""

_SINGLE, _VECTOR = "leg_env.envs.single:LegEnv", "leg_env.envs.vector:LegVectorEnv"

for _id, (_task, _kw) in REGISTRY.items():
    if _id not in gymnasium.registry:
        gymnasium.register(id=_id, entry_point=_SINGLE, vector_entry_point=_VECTOR, max_episode_steps=1000, kwargs={"task": _task, **_kw})


def __getattr__(name: str):
    if name == "StanceConfig":
        from .tasks.base import StanceConfig

        return StanceConfig
    if name in ("LegEnv", "LegVectorEnv"):
        from . import envs

        return getattr(envs, name)
    if name == "ENDINGS":  # why an episode ended, by info["ending"]
        from .info import ENDINGS

        return ENDINGS
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
