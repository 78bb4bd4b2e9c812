"""Loading a policy: a trained SB3 run (``model.zip``, ``vecnormalize.pkl``, ``config.yaml``), a ``python -m
train.rllib`` run or checkpoint, or a model-based controller by name, each as an object with SB3's ``predict``.

``train.evaluate``, ``train.ppo``, ``train.curves`` and ``train.export`` load policies through ``load_policy``;
``train.evaluate`` re-exports it (``from train.evaluate import load_policy`` keeps working).
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np

from leg_env import ENV_ID  # importing leg_env registers the env

__all__ = ["BASELINES", "PolicyNotFoundError", "PolicyLoadError", "TrainedPolicy", "load_policy", "read_run_config"]


class PolicyNotFoundError(FileNotFoundError):
    """The policy folder or one of its files is missing; the message names the path."""


class PolicyLoadError(ValueError):
    """A policy file exists but cannot be read as what it should be; the message names the file."""


class TrainedPolicy:
    """A trained SB3 model with the observation normalisation it was trained with.

    ``predict`` has SB3's signature and takes raw env observations of its task, one ``(n,)`` or a batch ``(N, n)``.
    """

    def __init__(self, model, vec_normalize=None, env_kwargs: dict | None = None, path: Path | None = None, env_id: str | None = None):
        self.model = model
        self.vec_normalize = vec_normalize
        self.env_kwargs = dict(env_kwargs or {})
        self.path = path
        self.env_id = env_id  # the task it was trained on (its config.yaml's env_id), None if unknown

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        obs = np.asarray(observation, dtype=np.float32)
        if self.vec_normalize is not None:
            obs = self.vec_normalize.normalize_obs(obs)
        return self.model.predict(obs, state=state, episode_start=episode_start, deterministic=deterministic)


def read_run_config(folder: Path) -> dict:
    """A run folder's ``config.yaml`` as a mapping ({} if it has none); ``PolicyLoadError`` if it is not one."""
    path = folder / "config.yaml"
    if not path.is_file():
        return {}
    import yaml

    try:
        config = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        raise PolicyLoadError(f"cannot read the run configuration {path}: {e}") from e
    if not isinstance(config, dict):
        raise PolicyLoadError(f"the run configuration {path} is not a mapping")
    return config


def _lqr(params, config):
    from policies.lqr import LQRController

    return LQRController(params, config)


def _hopper(params, config):
    from policies.hopper import HopperController

    return HopperController(params, config)


def _gated(params, config):
    from policies.gated import GatedController

    return GatedController(params, config)


def _stepping(params, config):
    from policies.stepping import SteppingController

    return SteppingController(params, config)


def _mpc(params, config):
    from leg_env.tasks.push import PushConfig
    from policies.mpc import HopMPC
    from policies.push_mpc import PushMPC

    return PushMPC(params, config) if isinstance(config, PushConfig) else HopMPC(params, config)


BASELINES = {"lqr": _lqr, "hopper": _hopper, "gated": _gated, "stepping": _stepping, "mpc": _mpc}
"""The model-based controllers by name: ``(params, config) -> controller`` with ``predict``."""


def load_policy(path, env_kwargs: dict | None = None, env_id: str | None = None):
    """A policy with ``predict(obs)`` from a run/policy folder (or its ``model.zip``), or a baseline's name.

    A folder written by ``python -m train.rllib``, its ``best/`` or ``last/``, or one of its checkpoints, loads as a
    ``train.rllib.RLlibPolicy`` (needs the ``rllib`` extra).

    A baseline (``BASELINES``: ``"lqr"``, ``"hopper"``, ``"gated"``, ``"stepping"``, ``"mpc"``) is built for the env ``env_id`` made with ``env_kwargs``. For a folder,
    ``env_kwargs`` (default: the run's ``eval_env_kwargs``) are kept as the policy's ``env_kwargs``,
    the evaluation env's arguments.

    Raises:
        PolicyNotFoundError: the folder, ``model.zip`` or (when the run normalised) ``vecnormalize.pkl``
            is missing; the message names the path (a ``FileNotFoundError``).
        PolicyLoadError: a file exists but is corrupt or of the wrong kind; the message names it.
    """
    if isinstance(path, str) and path.lower() in BASELINES:
        import gymnasium as gym

        kwargs = {k: v for k, v in (env_kwargs or {}).items() if k not in ("render_mode", "width", "height")}
        env = gym.make(env_id or ENV_ID, **kwargs).unwrapped  # the task's params and config, checked
        return BASELINES[path.lower()](env.params, env.config)

    from train.rllib import is_rllib_checkpoint, is_rllib_policy, is_rllib_run

    path = Path(path)
    if is_rllib_run(path) or is_rllib_checkpoint(path) or is_rllib_policy(path):  # python -m train.rllib's
        return _rllib_policy(path, env_kwargs)
    return _sb3_policy(path, env_kwargs)


def _rllib_policy(path: Path, env_kwargs: dict | None):
    """``load_policy`` of a ``train.rllib`` run folder, policy folder or checkpoint."""
    from train.rllib import RLlibPolicy

    try:
        policy = RLlibPolicy.load(path)
    except FileNotFoundError as e:
        raise PolicyNotFoundError(str(e)) from e
    except ValueError as e:
        raise PolicyLoadError(str(e)) from e
    if env_kwargs is not None:
        policy.env_kwargs = dict(env_kwargs)
    return policy


def _sb3_policy(path: Path, env_kwargs: dict | None):
    """``load_policy`` of an SB3 run or policy folder, or its ``model.zip``."""
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    folder = path.parent if path.suffix == ".zip" else path
    model_file = path if path.suffix == ".zip" else folder / "model.zip"
    if not folder.is_dir():
        raise PolicyNotFoundError(f"policy folder not found: {folder}")
    if not model_file.is_file():
        raise PolicyNotFoundError(f"model file not found: {model_file}")
    config = read_run_config(folder)
    try:
        model = PPO.load(model_file, device="cpu")
    except Exception as e:  # SB3 raises zipfile, pickle, torch or key errors on a bad archive
        raise PolicyLoadError(f"cannot load the model file {model_file}: {type(e).__name__}: {e}") from e
    vec_normalize = _observation_statistics(folder, config, model, model_file)
    if env_kwargs is None:
        env_kwargs = config.get("eval_env_kwargs", config.get("env_kwargs")) or {}
    policy = TrainedPolicy(model, vec_normalize, env_kwargs, folder, env_id=config.get("env_id"))
    residual = config.get("residual")
    if residual:  # a residual on a model-based controller (train.residual): the policy is their sum
        if not isinstance(residual, dict) or residual.get("controller") not in BASELINES:
            raise PolicyLoadError(f"the run configuration {folder / 'config.yaml'} has an unknown residual {residual!r}")
        return with_controller(policy, residual, config.get("env_kwargs") or {}, policy.env_id)
    return policy


def _observation_statistics(folder: Path, config: dict, model, model_file: Path):
    """The ``VecNormalize`` of ``folder`` that normalises the policy's observations, or None (the run did not
    normalise them)."""
    from stable_baselines3.common.vec_env import VecNormalize

    stats_file = folder / "vecnormalize.pkl"
    if config.get("normalize", True) is False and not stats_file.exists():
        return None
    if not stats_file.is_file():
        raise PolicyNotFoundError(f"normalisation statistics not found: {stats_file}")
    try:
        with open(stats_file, "rb") as f:
            vec_normalize = pickle.load(f)
    except Exception as e:
        raise PolicyLoadError(f"cannot load the normalisation statistics {stats_file}: {type(e).__name__}: {e}") from e
    if not isinstance(vec_normalize, VecNormalize):
        raise PolicyLoadError(f"{stats_file} does not hold VecNormalize statistics (got {type(vec_normalize).__name__})")
    vec_normalize.training = False
    vec_normalize.norm_reward = False
    if not vec_normalize.norm_obs:
        return None  # only returns were normalised: the policy reads raw observations
    if vec_normalize.obs_rms.mean.shape != model.observation_space.shape:
        raise PolicyLoadError(
            f"{stats_file} has statistics for observations of shape {vec_normalize.obs_rms.mean.shape}, "
            f"the model in {model_file} expects {model.observation_space.shape}"
        )
    return vec_normalize


def with_controller(network, residual: dict, env_kwargs: dict, env_id: str | None):
    """``network`` as a residual on its controller (``train.residual.ResidualPolicy``): ``residual`` is a run
    configuration's ``{"controller": name, "scale": s}``, the controller built for ``env_id`` with ``env_kwargs``."""
    from train.residual import ResidualPolicy

    controller = load_policy(residual["controller"], env_kwargs=env_kwargs, env_id=env_id)
    return ResidualPolicy(network, controller, residual["scale"])
