"""Hyperparameters of the trainers: RL Baselines3 Zoo's file format (``train/hyperparams/ppo.yml``, one entry
per env id, literals only), ``key:value`` overrides from the command line, and paths as a run's config
records them. Shared by ``train.ppo`` and ``train.rllib``."""

from __future__ import annotations

from pathlib import Path

import yaml

__all__ = ["DEFAULT_HYPERPARAMS", "ZOO_KEYS", "PPO_KEYS", "CHUNKED_PPO_KEYS", "parse_override", "load_hyperparams", "linear_schedule_start",
           "class_at", "display_path"]

DEFAULT_HYPERPARAMS = Path(__file__).resolve().parent / "hyperparams" / "ppo.yml"

# keys of a Zoo entry that are not PPO constructor arguments
ZOO_KEYS = ("n_envs", "n_timesteps", "policy", "normalize", "env_kwargs", "callback")
PPO_KEYS = (
    "learning_rate",
    "n_steps",
    "batch_size",
    "n_epochs",
    "gamma",
    "gae_lambda",
    "clip_range",
    "clip_range_vf",
    "normalize_advantage",
    "ent_coef",
    "vf_coef",
    "max_grad_norm",
    "use_sde",
    "sde_sample_freq",
    "target_kl",
    "stats_window_size",
    "policy_kwargs",
    "bounds_loss_coef",  # train.chunked_ppo.ChunkedPPO's: a charge on the mean action beyond the action box
    "temporal_smoothness_coef",  # ChunkedPPO's: the mean action's change between consecutive observations (CAPS)
    "spatial_smoothness_coef",  # ChunkedPPO's: the mean action's change under a small noise on the observation (CAPS)
    "spatial_smoothness_sigma",  # ChunkedPPO's: that noise's std
    "smoothness_share",  # ChunkedPPO's: the share of the samples the smoothness charges are computed on
)
CHUNKED_PPO_KEYS = ("bounds_loss_coef", "temporal_smoothness_coef", "spatial_smoothness_coef", "spatial_smoothness_sigma",
                    "smoothness_share")
"""The keys of ``PPO_KEYS`` that are ``train.chunked_ppo.ChunkedPPO``'s own terms of the update: SB3's ``PPO``, the Zoo and
RLlib's PPO have none of them."""


def parse_override(item: str) -> tuple[str, object]:
    """``"key:value"`` as ``(key, value)``, the value read as a YAML literal (``learning_rate:1.0e-3``)."""
    key, sep, value = item.partition(":")
    if not sep or not key:
        raise ValueError(f"hyperparameter override must be key:value, got {item!r}")
    return key.strip(), yaml.safe_load(value)


def linear_schedule_start(value) -> float | None:
    """The initial value of a Zoo schedule literal ``"lin_<initial>"`` (a linear decay to 0 over the run), None for a
    number; ``ValueError`` for any other string."""
    if not isinstance(value, str):
        return None
    kind, _, initial = value.partition("_")
    if kind != "lin":
        raise ValueError(f"unknown schedule {value!r}; use a number or 'lin_<initial value>'")
    return float(initial)


def load_hyperparams(path: Path, env_id: str, overrides: list[str] = ()) -> dict:
    """The Zoo-format entry for ``env_id`` in ``path``, with ``key:value`` overrides applied."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"hyperparameter file not found: {path}")
    data = yaml.safe_load(path.read_text()) or {}
    if env_id not in data:
        raise KeyError(f"{path} has no entry for {env_id!r} (entries: {sorted(data)})")
    hp = dict(data[env_id])
    hp.update(parse_override(item) for item in overrides)
    unknown = set(hp) - set(ZOO_KEYS) - set(PPO_KEYS)
    if unknown:
        raise ValueError(f"unknown hyperparameter(s) {sorted(unknown)} for {env_id} in {path}")
    return hp


def class_at(path: str, base: type, key: str, kind: str) -> type:
    """The subclass of ``base`` that the class path ``path`` (``"train.features.CommandGains"``) names, as the file's
    ``key`` gives it; ``ValueError`` naming ``key`` if it cannot be imported or is not ``kind``."""
    import importlib

    module, _, name = str(path).rpartition(".")
    try:
        cls = getattr(importlib.import_module(module), name, None) if module else None
    except ImportError as e:
        raise ValueError(f"{key}: cannot import {path!r} ({e})") from e
    if not (isinstance(cls, type) and issubclass(cls, base)):
        raise ValueError(f"{key}: {path!r} is not {kind}")
    return cls


def display_path(path: Path) -> str:
    """``path`` relative to the working directory when it lies below it (no machine paths in configs)."""
    path = Path(path).resolve()
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)
