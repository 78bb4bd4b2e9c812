"""The shipped hop policy (policies/ppo_hop): it loads as the hopper plus PPO's correction and hops a few episodes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from policies.hopper import HopperController
from train.evaluate import load_policy, run_episodes
from train.residual import ResidualPolicy

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "policies" / "ppo_hop"
ENV_ID = "leg_env/PlanarLegHop-v0"
SEEDS = [10_000, 10_001, 10_055]  # evaluation seeds (never used in training); the hopper alone falls on the last two


def test_shipped_hop_policy_loads_as_the_hopper_plus_a_learnt_correction():
    policy = load_policy(SHIPPED)
    assert isinstance(policy, ResidualPolicy)
    assert isinstance(policy.controller, HopperController)
    assert policy.scale == 0.1
    assert policy.env_kwargs == {}  # evaluated on the task as registered
    import gymnasium as gym

    envs = gym.make_vec(ENV_ID, num_envs=8)
    obs, _ = envs.reset(seed=10_000)
    correction, _ = policy.network.predict(obs, deterministic=True)
    assert np.asarray(correction).shape == (8, 2)
    policy.controller.reset()
    action, _ = policy.predict(obs)
    base, _ = HopperController().predict(obs)
    np.testing.assert_allclose(action, np.clip(base + 0.1 * np.clip(correction, -1, 1), -1, 1), rtol=0, atol=1e-6)


def test_shipped_hop_policy_hops_at_the_command():
    policy = load_policy(SHIPPED)
    summary, _ = run_episodes(policy, SEEDS, env_id=ENV_ID)
    assert summary["survival_rate"] == 1.0
    assert summary["hops"] >= 10 * len(SEEDS)  # a hop about every 0.6 s over 10 s
    assert summary["mean_abs_apex_error"] < 0.03
    assert summary["max_drift_10s"] < 0.10
    assert summary["unilateral_violation_frac"] == 0.0
    # the learnt correction is what keeps these robots up: the hopper alone falls on 10001 and 10055
    alone, _ = run_episodes(HopperController(), SEEDS[1:], env_id=ENV_ID)
    assert alone["survival_rate"] == 0.0
