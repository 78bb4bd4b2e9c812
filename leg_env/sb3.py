"""A Stable-Baselines3 ``VecEnv`` over the natively batched ``LegVectorEnv``.

SB3 does not accept ``gymnasium.vector.VectorEnv`` objects (``gymnasium.make_vec`` output), and its
own ``DummyVecEnv`` steps one single environment at a time. ``LegStanceVecEnv`` gives SB3 the batch
directly, one kernel call per step, with SB3's semantics::

    from stable_baselines3 import PPO
    from leg_env.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env(64, seed=0)            # VecNormalize / VecMonitor / VecCheckNan wrap it as usual
    model = PPO("MlpPolicy", venv).learn(50_000)

Importing this module needs ``stable-baselines3`` (the ``train`` extra).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvObs, VecEnvStepReturn

from . import checks
from .envs.vector import LegVectorEnv

__all__ = ["LegStanceVecEnv", "make_sb3_vec_env"]

# attributes whose single-environment meaning differs from the batched env's
_SINGLE_ATTRIBUTES = {"observation_space": "single_observation_space", "action_space": "single_action_space"}


class LegStanceVecEnv(VecEnv):
    """SB3 ``VecEnv`` whose sub-environments are the rows of one ``LegVectorEnv`` (any task).

    The batched env must autoreset in ``SAME_STEP`` mode (``make_sb3_vec_env`` builds it so).
    ``step`` returns ``(obs, rewards, dones, infos)`` as SB3 expects: ``rewards`` float32,
    ``dones = terminated | truncated``, and ``infos`` a list of one dict per sub-env with the reward
    terms and contact keys of the single environment's ``info`` for that step, ``"TimeLimit.truncated"``
    (True only when the time limit ended an episode that did not also terminate) and, for sub-envs
    whose episode ended, ``"terminal_observation"``: the last observation before the reset (the
    returned ``obs`` row is already the next episode's first). ``reset_infos`` holds each sub-env's
    latest reset ``info``.

    ``step_info`` is the step's info as columns over the sub-envs (``{key: (num_envs,) or (num_envs, 2)}``,
    the same values as the per-env dicts, the ended sub-envs' last step included). With
    ``per_env_info=False`` the per-env dicts carry only what SB3 reads (``"TimeLimit.truncated"`` and
    ``"terminal_observation"``): building a dict of every key for every sub-env is the adapter's largest cost
    (about 1 us per sub-env and step), so a trainer that logs from ``step_info`` runs faster without them.

    ``seed(s)`` seeds sub-env ``i`` with ``s + i`` at the next ``reset``, exactly like
    ``gymnasium.make("leg_env/PlanarLegStance-v0")`` reset with that seed, and ``set_options``
    passes ``qpos`` / ``qvel`` (the same keys for every sub-env) to it. A rejected ``reset`` (bad seeds
    or options) changes nothing and keeps the pending seeds and options; ``step`` before the first
    ``reset`` raises ``gymnasium.error.ResetNeeded`` before anything changes.

    The sub-envs share one batched env, so attributes and methods are that env's:
    ``get_attr(name)`` returns its attribute for each requested index (``observation_space`` and
    ``action_space`` are the single-env spaces), ``set_attr`` sets it for all sub-envs (a strict
    subset raises ``ValueError``), ``env_method`` calls the method once and returns its result for
    each index, and ``env_is_wrapped`` is False (no Gymnasium wrappers). ``get_images`` returns one
    frame per sub-env (``render_mode="rgb_array"``; of the first ``render_envs`` if the batched env
    was given that), and ``metadata["render_fps"]`` is the env's real rate, ``1 / dt``, so SB3's
    ``VecVideoRecorder`` plays videos at real speed.
    """

    def __init__(self, env: LegVectorEnv, per_env_info: bool = True):
        if not isinstance(env, LegVectorEnv):
            raise TypeError(f"env must be an (unwrapped) LegVectorEnv, got {type(env).__name__}")
        if env.autoreset_mode != AutoresetMode.SAME_STEP:
            raise ValueError(
                f"SB3 resets a sub-env in the step that ends it: build the env with autoreset_mode=AutoresetMode.SAME_STEP, "
                f"got {env.autoreset_mode}"
            )
        if not isinstance(per_env_info, bool):
            raise TypeError(f"per_env_info must be a bool, got {checks.shown(per_env_info)}")
        self.env = env
        self.per_env_info = per_env_info
        self.step_info: dict[str, np.ndarray] = {}
        self._actions: np.ndarray | None = None
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)
        self.metadata = {**self.metadata, "render_fps": env.metadata["render_fps"]}  # SB3's VecEnv sets render_modes only

    # ---------------------------------------------------------------- API

    def reset(self) -> VecEnvObs:
        seeds = self._seeds if any(s is not None for s in self._seeds) else None
        obs, info = self.env.reset(seed=seeds, options=self._merged_options())
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = _per_env_infos(info, None, self.env.state_keys)
        _add_params(self.reset_infos, info, range(self.num_envs))
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_wait() called without a step_async(actions) before it")
        actions, self._actions = self._actions, None
        env = self.env
        obs, rewards, terminated, truncated, info = env.step(actions)
        keys = env.reward_keys + env.state_keys
        columns = {key: info[key] for key in keys}
        final = info.get("final_info")
        ended = None
        if final is not None:  # the sub-envs reset in this step report their last step, not their reset (SB3's way)
            ended = np.flatnonzero(info["_final_info"])
            for key in keys:
                column = columns[key].copy()
                column[ended] = final[key][ended]
                columns[key] = column
        columns["TimeLimit.truncated"] = truncated & ~terminated
        self.step_info = columns
        infos = _per_env_infos(columns, None, (*keys, "TimeLimit.truncated") if self.per_env_info else ("TimeLimit.truncated",))
        if ended is not None:
            rows = ended.tolist()
            for i in rows:
                infos[i]["terminal_observation"] = info["final_obs"][i]
            for i, reset_info in zip(rows, _per_env_infos(info, rows, env.state_keys)):
                self.reset_infos[i] = reset_info
            _add_params(self.reset_infos, info, rows)
        return obs, rewards.astype(np.float32), terminated | truncated, infos

    def close(self) -> None:
        self.env.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        if self.render_mode != "rgb_array":
            warnings.warn(f"The render mode is {self.render_mode}, but this method assumes it is `rgb_array` to obtain images.")
            return [None for _ in range(self.num_envs)]
        return list(self.env.render())

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        value = getattr(self.env, _SINGLE_ATTRIBUTES.get(attr_name, attr_name))
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        if sorted(set(self._get_indices(indices))) != list(range(self.num_envs)):
            raise ValueError(f"the sub-envs share one batched env: set {attr_name!r} for all of them (indices=None)")
        setattr(self.env, _SINGLE_ATTRIBUTES.get(attr_name, attr_name), value)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        result = getattr(self.env, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    # ------------------------------------------------------------ helpers

    def _merged_options(self) -> dict | None:
        """The per-sub-env reset options as the batched env's: ``None``, or ``qpos`` / ``qvel`` rows."""
        if not any(self._options):
            return None
        keys = set(self._options[0])
        if any(set(o) != keys for o in self._options):
            raise ValueError("set_options: every sub-env needs the same option keys (the batch resets together)")
        return {key: np.stack([checks.real_array(f"set_options {key!r}", o[key], "real numbers") for o in self._options]) for key in keys}




def _add_params(infos: list[dict], info: dict, rows) -> None:
    """Put ``params`` (and ``params_rejected``) of a vector ``info`` into the per-env dicts of ``rows``."""
    if "params" not in info:
        return
    params, mask = info["params"], info["_params"]
    names = [key for key in params if not key.startswith("_")]
    for i in rows:
        if mask[i]:
            infos[i]["params"] = {name: params[name][i].item() for name in names}
            if "params_rejected" in info:
                infos[i]["params_rejected"] = info["params_rejected"][i].item()


def _per_env_infos(columns: dict, rows, keys) -> list[dict]:
    """Per-row dicts of ``keys`` from their columns (a vector ``info``) for ``rows`` (None: every row): numbers
    as Python's, arrays as the row's."""
    if rows is not None:
        rows = np.fromiter(rows, dtype=np.intp)
    values = []
    for key in keys:
        column = columns[key] if rows is None else columns[key][rows]
        values.append(list(column) if column.ndim > 1 else column.tolist())
    if not keys:
        return [{} for _ in range(len(rows))]
    if len(keys) == 1:  # SB3's own key alone (per_env_info=False): 8x faster than the general case
        key = keys[0]
        return [{key: value} for value in values[0]]
    return [dict(zip(keys, row)) for row in zip(*values)]


def make_sb3_vec_env(num_envs: int, seed: int | None = None, env_id: str | None = None, per_env_info: bool = True,
                     **env_kwargs: Any) -> LegStanceVecEnv:
    """``LegStanceVecEnv(LegVectorEnv(num_envs, autoreset_mode=SAME_STEP, **env_kwargs), per_env_info)``.

    ``env_kwargs`` are the batched env's arguments (``task``, ``max_episode_steps`` defaulting to the
    registered 1000, ``params``, ``config``, any config field, ``render_mode``...). ``env_id`` (a registered
    id, ``leg_env.tasks.REGISTRY``) gives the task and the id's arguments (``env_kwargs`` override them).
    With ``seed``, the first ``reset`` seeds sub-env ``i`` with ``seed + i``.
    """
    if env_id is not None:
        from .tasks import REGISTRY

        if env_id not in REGISTRY:
            raise ValueError(f"env_id must be one of {sorted(REGISTRY)}, got {env_id!r}")
        task, fixed = REGISTRY[env_id]
        env_kwargs = {"task": task, **fixed, **env_kwargs}
    mode = env_kwargs.pop("autoreset_mode", AutoresetMode.SAME_STEP)
    if AutoresetMode(mode) != AutoresetMode.SAME_STEP:
        raise ValueError(f"the SB3 adapter needs autoreset_mode SAME_STEP, got {mode!r}")
    if not isinstance(per_env_info, bool):  # before the batch is built
        raise TypeError(f"per_env_info must be a bool, got {checks.shown(per_env_info)}")
    venv = LegStanceVecEnv(LegVectorEnv(num_envs, autoreset_mode=AutoresetMode.SAME_STEP, **env_kwargs), per_env_info)
    if seed is not None:
        venv.seed(seed)
    return venv
