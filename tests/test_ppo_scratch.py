"""The shipped plain-PPO policies (``policies/ppo_balance``, ``ppo_hop_v1``, ``ppo_hop_v2``, ``ppo_hop_v3``): a network alone, and
their cards' episodes as they score them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from train.evaluate import load_policy, run_episodes
from train.residual import ResidualPolicy

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = {  # policy folder: the task it was trained and is evaluated on
    "ppo_balance": "leg_env/PlanarLegBalance-v0",
    "ppo_hop_v1": "leg_env/PlanarLegHop-v1",
    "ppo_hop_v2": "leg_env/PlanarLegHop-v2",
    "ppo_hop_v3": "leg_env/PlanarLegHop-v3",
}


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_scratch_policy_is_plain_ppo_on_the_registered_task(name):
    folder, env_id = ROOT / "policies" / name, SHIPPED[name]
    policy = load_policy(folder)
    assert not isinstance(policy, ResidualPolicy)
    assert policy.env_kwargs == {}  # evaluated on the task as registered; the training env's shaping is its own
    config = (folder / "config.yaml").read_text()
    assert "residual: null" in config and "init_from: null" in config and f"env_id: {env_id}" in config


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_scratch_policy_reproduces_its_card_on_held_out_seeds(name):
    """The first ten held-out episodes of ``eval/policy.json`` (seeds 10000+), replayed: the same survival, lengths
    and returns."""
    folder, env_id = ROOT / "policies" / name, SHIPPED[name]
    card = json.loads((folder / "eval" / "policy.json").read_text())
    recorded = card["per_episode"][:10]
    summary, _ = run_episodes(load_policy(folder), [e["seed"] for e in recorded], env_id=env_id)
    for mine, theirs in zip(summary["per_episode"], recorded):
        assert mine["seed"] == theirs["seed"] and mine["survived"] == theirs["survived"] and mine["length"] == theirs["length"]
        assert mine["return"] == pytest.approx(theirs["return"], abs=1e-3)
