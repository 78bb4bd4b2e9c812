"""The shipped push policy (policies/ppo_push): it loads as the stepping controller plus PPO's correction and
survives pushes of 1.5 times the largest impulse the LQR survives 90% of the time."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

from policies.lqr import LQRController
from policies.stepping import SteppingController
from train.evaluate import load_policy
from train.residual import ResidualPolicy
from train.episodes import push_survival

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "policies" / "ppo_push"
ENV_ID = "leg_env/PlanarLegPush-v0"


def test_shipped_push_policy_loads_as_the_stepping_controller_plus_a_learnt_correction():
    policy = load_policy(SHIPPED)
    assert isinstance(policy, ResidualPolicy)
    assert isinstance(policy.controller, SteppingController)
    assert policy.scale == 0.1
    assert policy.env_kwargs == {"push_force": [40.0, 60.0]}  # its in-training evaluation's pushes
    envs = gym.make_vec(ENV_ID, num_envs=8)
    obs, _ = envs.reset(seed=10_000)
    correction, _ = policy.network.predict(obs, deterministic=True)
    assert np.asarray(correction).shape == (8, 2)
    policy.reset()
    action, _ = policy.predict(obs)
    base, _ = SteppingController().predict(obs)
    np.testing.assert_allclose(action, np.clip(base + 0.1 * np.clip(correction, -1, 1), -1, 1), rtol=0, atol=1e-6)


def test_shipped_push_policy_survives_pushes_the_lqr_falls_from():
    """Four pushes an episode of 3.4 N s (1.5 x the LQR's 2.25 N s) and of 2.25 N s, on evaluation seeds."""
    policy = load_policy(SHIPPED)
    for force in (22.5, 34.0):
        assert push_survival(policy, [force], episodes=8, seed=10_000)[0]["survival_rate"] == 1.0
    task = gym.make(ENV_ID).unwrapped
    assert push_survival(LQRController(task.params, task.config), [34.0], episodes=8, seed=10_000)[0]["survival_rate"] == 0.0
