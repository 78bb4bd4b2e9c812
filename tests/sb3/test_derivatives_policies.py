"""The step's Jacobians on states from rollouts of the shipped PPO policies (beside the random actions and the
controllers of ``tests/test_derivatives.py``): five-point differences of the step, per kind of event; the pinned task's
policy against centred differences of ``stance_step``."""

from __future__ import annotations

from pathlib import Path

import pytest

from test_derivatives import FD_RTOL, FD_RTOL_EVENT, hybrid_fd_check, pinned_fd_check
from train.policy_loading import load_policy

POLICIES = Path(__file__).resolve().parents[2] / "policies"


@pytest.mark.parametrize("env_id, folder", [
    ("leg_env/PlanarLegBalance-v1", "ppo_balance"),
    ("leg_env/PlanarLegPush-v2", "ppo_push_v2"),
    ("leg_env/PlanarLegHop-v4", "ppo_hop_v4"),
])
def test_hybrid_jacobians_on_the_shipped_policies_rollouts(env_id, folder, capsys):
    policy = load_policy(POLICIES / folder)
    assert policy.env_id == env_id
    rows, worst = [], {}
    hybrid_fd_check(env_id, policy, worst, rows)
    with capsys.disabled():
        print(f"\n{folder}: " + "; ".join(rows))
    assert worst["no event"] <= FD_RTOL
    assert max((v for k, v in worst.items() if k != "no event"), default=0.0) <= FD_RTOL_EVENT
    if folder == "ppo_hop_v4":  # the policy hops: its rollouts land
        assert "touchdown" in worst


def test_pinned_jacobians_on_the_shipped_policys_rollouts():
    policy = load_policy(POLICIES / "ppo_stance")
    n, same, err_A, err_B = pinned_fd_check([policy])
    assert n >= 5_000 and same.mean() > 0.99
    assert err_A.max() <= 1e-6 and err_B.max() <= 1e-6
