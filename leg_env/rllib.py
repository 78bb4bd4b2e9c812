"""leg-env on Ray RLlib's new API stack: the env creator, and seeds that no two env runners share.

    import leg_env.rllib
    from ray.rllib.algorithms.ppo import PPOConfig

    config = (
        PPOConfig()
        .environment(leg_env.rllib.register(), env_config={"env_id": "leg_env/PlanarLegStance-v0", "env_kwargs": {}})
        .env_runners(num_envs_per_env_runner=64, gym_env_vectorize_mode="vector_entry_point")
        .callbacks(on_environment_created=leg_env.rllib.on_environment_created)
        .debugging(seed=0)
    )

``register()`` registers ``make_env`` with ``ray.tune.register_env`` under ``ENV_NAME``. In the
``vector_entry_point`` mode an env runner calls it once with its ``env_config`` plus ``num_envs``, and
it returns leg-env's native batch from ``gymnasium.make_vec``: one kernel call steps all the runner's
robots (no ``SyncVectorEnv`` of single envs). ``env_config`` holds ``env_id`` (any leg-env id, default
``leg_env/PlanarLegStance-v0``), ``env_kwargs`` (the env's arguments, e.g. ``contact="unilateral"``,
and ``num_threads``) and ``restart`` (see below).

Seeds. RLlib resets a runner's batch once, with ``seed = config.seed + worker_index`` (plus 10^6 on
evaluation runners), and the native batch seeds sub-env ``i`` with ``seed + i``: runner 1's sub-env 1
would replay runner 2's sub-env 0. The batch is therefore wrapped in ``RunnerSeeds``, which replaces
that seed by one per sub-env, ``sub_env_seed(config.seed, restart, evaluation, worker_index, i)``: an
injective packing of those five numbers into one integer, so two sub-envs of one run never share a
seed, whatever the number of runners and envs. ``worker_index`` reaches the wrapper through RLlib's
``on_environment_created`` callback (RLlib passes the creator a plain dict without it), which must
therefore be configured as above; a batch reset with a seed before it raises ``RuntimeError``.
``restart`` counts the resumes of a run, so that a resumed run draws new episodes.
"""

from __future__ import annotations

import gymnasium as gym

from . import ENV_ID

__all__ = ["ENV_NAME", "RunnerSeeds", "find_runner_seeds", "make_env", "register", "on_environment_created", "sub_env_seed"]

ENV_NAME = "leg_env_rllib"
"""The name ``register()`` gives the creator in Ray Tune's registry (``config.environment(ENV_NAME)``)."""

_FIELDS = (("restart", 16), ("evaluation", 1), ("worker_index", 32), ("vector_index", 32))
"""The fields packed below the config seed by ``sub_env_seed``, with their widths in bits."""


def sub_env_seed(seed: int, restart: int, evaluation: bool, worker_index: int, vector_index: int) -> int:
    """The seed of sub-env ``vector_index`` of env runner ``worker_index``: the five numbers side by side
    in one integer (``seed`` in the high bits), so different arguments never give the same seed."""
    value = int(seed)
    if value < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    for (name, bits), field in zip(_FIELDS, (restart, int(bool(evaluation)), worker_index, vector_index)):
        if not 0 <= int(field) < 1 << bits:
            raise ValueError(f"{name} must be in [0, 2**{bits}), got {field}")
        value = (value << bits) | int(field)
    return value


class RunnerSeeds(gym.vector.VectorWrapper):
    """Gives each sub-env of an env runner's batch its own seed in place of RLlib's ``seed + i``.

    ``reset(seed=s)`` with an int seeds sub-env ``i`` with ``sub_env_seed(base, restart, evaluation,
    worker_index, i)`` once ``set_runner`` has named the runner (``s`` itself is not used: RLlib
    derives it from the same config seed and worker index); ``seed=None`` continues every sub-env's
    generator, and a list of seeds passes through unchanged.
    """

    def __init__(self, env: gym.vector.VectorEnv, restart: int = 0):
        super().__init__(env)
        self.restart = int(restart)
        self.runner: tuple[int, bool, int] | None = None  # (config seed, evaluation, worker_index)

    def set_runner(self, seed: int | None, evaluation: bool, worker_index: int) -> None:
        """Name the env runner that owns this batch (RLlib's config seed, evaluation flag, worker index)."""
        self.runner = None if seed is None else (int(seed), bool(evaluation), int(worker_index))

    def seeds(self) -> list[int]:
        """The seed of every sub-env for the runner named by ``set_runner``."""
        if self.runner is None:
            raise RuntimeError(
                "RunnerSeeds got an int seed before its env runner was named: configure "
                "callbacks(on_environment_created=leg_env.rllib.on_environment_created)"
            )
        seed, evaluation, worker_index = self.runner
        return [sub_env_seed(seed, self.restart, evaluation, worker_index, i) for i in range(self.num_envs)]

    def reset(self, *, seed=None, options=None):
        if isinstance(seed, int):
            seed = self.seeds()
        return self.env.reset(seed=seed, options=options)


def make_env(env_config: dict) -> RunnerSeeds:
    """The native batch of ``env_config["num_envs"]`` robots (``gymnasium.make_vec``'s vector entry point)."""
    import leg_env  # noqa: F401  (registers the ids in this process, an env runner's too)

    env_config = dict(env_config)
    unknown = set(env_config) - {"env_id", "env_kwargs", "restart", "num_envs"}
    if unknown:
        raise ValueError(f"unknown env_config key(s) {sorted(unknown)}; expected env_id, env_kwargs, restart")
    env = gym.make_vec(
        env_config.get("env_id", ENV_ID),
        num_envs=int(env_config.get("num_envs", 1)),
        vectorization_mode="vector_entry_point",
        **dict(env_config.get("env_kwargs") or {}),
    )
    return RunnerSeeds(env, restart=env_config.get("restart", 0))


def register() -> str:
    """Register ``make_env`` with Ray Tune (in this process; Ray ships it to the env runners); returns ``ENV_NAME``."""
    from ray.tune.registry import register_env

    register_env(ENV_NAME, make_env)
    return ENV_NAME


def find_runner_seeds(env) -> RunnerSeeds:
    """The ``RunnerSeeds`` wrapper inside an env runner's env (RLlib wraps the creator's env further)."""
    wrapper = env
    while not isinstance(wrapper, RunnerSeeds):
        if not hasattr(wrapper, "env"):
            raise TypeError(f"{env} has no RunnerSeeds wrapper: was it made by {__name__}.make_env?")
        wrapper = wrapper.env
    return wrapper


def on_environment_created(*, env_runner, env, env_context, **kwargs) -> None:
    """RLlib callback: tell the runner's ``RunnerSeeds`` the config seed and the runner's worker index."""
    config = env_runner.config
    find_runner_seeds(env_runner.env).set_runner(config.seed, config.in_evaluation, env_context.worker_index)
