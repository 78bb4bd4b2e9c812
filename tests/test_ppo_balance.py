"""The shipped plain-PPO balance policy (policies/ppo_balance): a network alone, and its card's episodes as it scores them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from train.evaluate import load_policy, run_episodes
from train.residual import ResidualPolicy

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "policies" / "ppo_balance"
ENV_ID = "leg_env/PlanarLegBalance-v0"


def test_shipped_balance_policy_is_plain_ppo_on_the_registered_task():
    policy = load_policy(SHIPPED)
    assert not isinstance(policy, ResidualPolicy)
    assert policy.env_kwargs == {}  # evaluated on the task as registered; the training env's shaping is its own
    config = (SHIPPED / "config.yaml").read_text()
    assert "residual: null" in config and "init_from: null" in config and f"env_id: {ENV_ID}" in config


def test_shipped_balance_policy_reproduces_its_card_on_held_out_seeds():
    """The first ten held-out episodes of ``eval/policy.json`` (seeds 10000+), replayed: the same survival and returns."""
    card = json.loads((SHIPPED / "eval" / "policy.json").read_text())
    recorded = card["per_episode"][:10]
    summary, _ = run_episodes(load_policy(SHIPPED), [e["seed"] for e in recorded], env_id=ENV_ID)
    for mine, theirs in zip(summary["per_episode"], recorded):
        assert mine["seed"] == theirs["seed"] and mine["survived"] == theirs["survived"] and mine["length"] == theirs["length"]
        assert mine["return"] == pytest.approx(theirs["return"], abs=1e-3)
