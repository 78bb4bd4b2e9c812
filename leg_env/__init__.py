"""leg-env: the planar floating-base leg as an exact, fast Gymnasium environment.

Importing the package registers every task id of ``leg_env.tasks.REGISTRY`` (``gymnasium.make`` and
``gymnasium.make_vec``): ``leg_env/PlanarLegStance-v0`` (balance on a pinned foot, the lesson's model),
``leg_env/PlanarLegBalance-v0`` (balance on the unilateral ground), ``leg_env/PlanarLegPush-v0`` and ``-v1``
(recover from pushes) and ``leg_env/PlanarLegHop-v3`` (and its ``-v0`` to ``-v2``, whose height terms can be
collected without hopping to the command: Gymnasium warns that they are out of date); and, for one release, the
deprecated ``leg_env/PlanarLegStance-v1`` (the old id of ``PlanarLegBalance-v0``, which it makes with a
``DeprecationWarning``). Every id's entry points are the generic ``leg_env.envs.LegEnv`` and ``LegVectorEnv``
with its task.

The package's rooms: ``leg_env.physics`` (the robot's model and time stepping, no Gymnasium), ``leg_env.tasks``
(one module per task), ``leg_env.envs`` (the single and vector environments), and beside them ``info``,
``randomize``, ``render``, ``sb3`` and ``rllib``. Importing stays cheap: the environments load on first use, and
pygame only when a frame is drawn. The physics and the tasks run in the compiled core (``leg_env/_core``, C,
built at install): nothing is compiled at run time.
"""

import gymnasium

from .physics.params import LegParams
from .tasks import ALIASES, REGISTRY

__all__ = ["LegParams", "StanceConfig", "LegEnv", "LegVectorEnv", "ENV_ID", "ENV_IDS", "ENDINGS"]
__version__ = "0.1.0"  # the package version's one source (pyproject.toml reads it)

ENV_ID = "leg_env/PlanarLegStance-v0"
ENV_IDS = tuple(REGISTRY)
"""Every current task id (the deprecated aliases of ``leg_env.tasks.ALIASES`` are not listed)."""

_SINGLE, _VECTOR = "leg_env.envs.single:LegEnv", "leg_env.envs.vector:LegVectorEnv"

for _id, (_task, _kw) in REGISTRY.items():
    if _id not in gymnasium.registry:
        gymnasium.register(id=_id, entry_point=_SINGLE, vector_entry_point=_VECTOR, max_episode_steps=1000, kwargs={"task": _task, **_kw})

for _old, _new in ALIASES.items():
    if _old not in gymnasium.registry:
        _task, _kw = REGISTRY[_new]
        gymnasium.register(
            id=_old,
            entry_point="leg_env.envs.aliases:single",
            vector_entry_point="leg_env.envs.aliases:vector",
            max_episode_steps=1000,
            kwargs={"_alias": (_old, _new), "task": _task, **_kw},
        )
        # Gymnasium calls an id "out of date" when the registry holds a higher version of its name: the alias
        # is not a newer version of the pinned balance, so its spec carries no version
        gymnasium.registry[_old].version = None


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
