"""Warm starts for PPO (``python -m train.ppo --init-from ...``): a trained policy's networks, or the LQR cloned.

* ``copy_policy(model, folder)``: the networks of an SB3 policy folder, copied parameter by parameter; a first
  layer that reads more observation entries than the source's gets zero weights for the new ones.
* ``clone_controller(model, controller, env_id, env_kwargs, seed)``: behaviour cloning. The batched env is run
  under the controller's actions plus uniform noise (so that the states cover the controller's own
  neighbourhood, as DAgger's do), every visited observation is labelled with the controller's noise-free
  action, and the policy's mean action (the actor network) is fitted to the labels by least squares (Adam).
  The value network and ``log_std`` keep their initial values: PPO learns the first and explores with the
  second. The start policy then acts as the controller does, and PPO improves it on the task's reward.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["copy_policy", "clone_controller", "CLONE_ENVS", "CLONE_STEPS", "CLONE_NOISE", "CLONE_EPOCHS"]

CLONE_ENVS = 256  # robots run at once to collect the cloning data
CLONE_STEPS = 400  # control steps of each (4 s: the push task's first pushes included)
CLONE_NOISE = 0.2  # half-width of the uniform noise on the applied actions (action units)
CLONE_EPOCHS = 30  # passes over the data
CLONE_BATCH = 1024


def copy_policy(model, folder: Path) -> None:
    """Copy the networks of the SB3 policy in ``folder`` (its ``model.zip``) into ``model``.

    Raises:
        FileNotFoundError: no ``model.zip`` in ``folder``.
        ValueError: a parameter is missing or of another shape (another ``net_arch`` or action size); the
            message names it.
    """
    import torch
    from stable_baselines3 import PPO

    model_file = Path(folder) / "model.zip"
    if not model_file.is_file():
        raise FileNotFoundError(f"init_from: model file not found: {model_file}")
    source = PPO.load(model_file, device="cpu").policy.state_dict()
    target = model.policy.state_dict()
    for name, value in target.items():
        if name not in source:
            raise ValueError(f"init_from: {model_file} has no parameter {name!r} (another policy architecture)")
        src = source[name]
        with torch.no_grad():
            if src.shape == value.shape:
                value.copy_(src)
            elif src.ndim == 2 and src.shape[0] == value.shape[0] and src.shape[1] < value.shape[1]:
                value.zero_()
                value[:, : src.shape[1]] = src
            else:
                raise ValueError(f"init_from: parameter {name!r} has shape {tuple(src.shape)} in {model_file}, {tuple(value.shape)} here")
    model.policy.load_state_dict(target)


def clone_controller(model, controller, env_id: str, env_kwargs: dict, seed: int) -> float:
    """Fit ``model``'s actor to ``controller`` (behaviour cloning, module docstring); returns the final RMS error.

    The data come from ``gymnasium.make_vec(env_id, CLONE_ENVS, **env_kwargs)`` seeded ``seed``; the fit uses
    torch's generator seeded ``seed``, so a warm start is reproducible.
    """
    import gymnasium as gym
    import torch

    rng = np.random.default_rng(seed)
    envs = gym.make_vec(env_id, num_envs=CLONE_ENVS, **env_kwargs)
    obs, _ = envs.reset(seed=seed)
    observations, labels = [], []
    for _ in range(CLONE_STEPS):
        action, _ = controller.predict(obs)
        observations.append(obs.copy())
        labels.append(np.asarray(action, dtype=np.float32))
        noisy = np.clip(action + rng.uniform(-CLONE_NOISE, CLONE_NOISE, action.shape), -1.0, 1.0).astype(np.float32)
        obs = envs.step(noisy)[0]
    envs.close()
    x = torch.as_tensor(np.concatenate(observations), dtype=torch.float32)
    y = torch.as_tensor(np.concatenate(labels), dtype=torch.float32)
    policy = model.policy
    actor = list(policy.mlp_extractor.policy_net.parameters()) + list(policy.action_net.parameters())
    optimiser = torch.optim.Adam(actor, lr=1e-3)
    generator = torch.Generator().manual_seed(seed)

    def mean_action(batch):
        return policy.action_net(policy.mlp_extractor.forward_actor(policy.extract_features(batch, policy.pi_features_extractor)))

    for _ in range(CLONE_EPOCHS):
        order = torch.randperm(x.shape[0], generator=generator)
        for start in range(0, x.shape[0], CLONE_BATCH):
            rows = order[start : start + CLONE_BATCH]
            loss = torch.mean((mean_action(x[rows]) - y[rows]) ** 2)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
    with torch.no_grad():
        return float(torch.sqrt(torch.mean((mean_action(x) - y) ** 2)))
