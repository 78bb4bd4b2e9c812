"""The shipped plain-PPO policies (``policies/ppo_balance``, ``ppo_push_v1``, ``ppo_hop_v1``, ``ppo_hop_v2``, ``ppo_hop_v3``): a
network alone, and their cards' episodes as they score them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from train.evaluate import load_policy, run_episodes
from train.residual import ResidualPolicy

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = {  # policy folder: the task it was trained and is evaluated on
    "ppo_balance": "leg_env/PlanarLegBalance-v0",
    "ppo_push_v1": "leg_env/PlanarLegPush-v1",
    "ppo_hop_v1": "leg_env/PlanarLegHop-v1",
    "ppo_hop_v2": "leg_env/PlanarLegHop-v2",
    "ppo_hop_v3": "leg_env/PlanarLegHop-v3",
}
EVAL_KWARGS = {  # the evaluation env of a policy selected on other than the task as registered (its table.md's)
    "ppo_push_v1": {"push_force": [50.0, 50.0]},  # selected at 50 N pushes; scored on the push curve
}


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_scratch_policy_is_plain_ppo_on_the_registered_task(name):
    folder, env_id = ROOT / "policies" / name, SHIPPED[name]
    policy = load_policy(folder)
    assert not isinstance(policy, ResidualPolicy)
    assert policy.env_kwargs == EVAL_KWARGS.get(name, {})  # the training env's shaping is its own
    config = (folder / "config.yaml").read_text()
    assert "residual: null" in config and "init_from: null" in config and f"env_id: {env_id}" in config


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_scratch_policy_reproduces_its_card_on_held_out_seeds(name):
    """The first ten held-out episodes of ``eval/policy.json`` (seeds 10000+), replayed: the same seeds, at most one
    fall more or fewer, and the same mean return to 10%. (On the machine that wrote a card they are the same episodes,
    returns to 1e-3. Elsewhere they need not be: the network's float32 arithmetic depends on the CPU, torch picking
    its kernels by the instruction set, and a hopping gait amplifies the difference. The ``ppo_hop_v1`` card, written
    on an Intel Xeon, replays on an AMD EPYC with nine returns within 2% and one episode that fell there surviving
    here: a mean 4.5% higher. The balance policy's episodes replay to the bit.)"""
    folder, env_id = ROOT / "policies" / name, SHIPPED[name]
    card = json.loads((folder / "eval" / "policy.json").read_text())
    recorded = card["per_episode"][:10]
    summary, _ = run_episodes(load_policy(folder), [e["seed"] for e in recorded], EVAL_KWARGS.get(name), env_id=env_id)
    mine = summary["per_episode"]
    assert [e["seed"] for e in mine] == [e["seed"] for e in recorded]
    assert abs(sum(e["survived"] for e in mine) - sum(e["survived"] for e in recorded)) <= 1
    assert sum(e["return"] for e in mine) == pytest.approx(sum(e["return"] for e in recorded), rel=0.1)


def test_shipped_push_policy_reproduces_its_push_curve_at_its_90_percent_impulse():
    """``ppo_push_v1``'s card: the push curve's survival at its 90% impulse and at the next magnitude, replayed on the
    same 100 held-out episodes (every push of an episode at that magnitude), the same to the episode."""
    from train.task_metrics import push_survival

    folder = ROOT / "policies" / "ppo_push_v1"
    card = json.loads((folder / "eval" / "push_curve.json").read_text())
    best = card["impulse_90"]["ppo_push_v1"]
    rows = card["curves"]["ppo_push_v1"]
    k = next(i for i, row in enumerate(rows) if row["impulse"] == pytest.approx(best))
    forces = [rows[k]["force"], rows[k + 1]["force"]]
    replayed = push_survival(load_policy(folder), forces, 100, card["seeds"][0], EVAL_KWARGS["ppo_push_v1"], "leg_env/PlanarLegPush-v1")
    assert [r["survival_rate"] for r in replayed] == [rows[k]["survival_rate"], rows[k + 1]["survival_rate"]]
    assert replayed[0]["survival_rate"] >= 0.9 > replayed[1]["survival_rate"]
