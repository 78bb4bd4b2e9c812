"""Probe: what the hop task's reward pays each gait. For each policy, its reward terms summed per episode, when its
first hop is paid, and the apex errors of its paid hops (flights of ``min_flight`` or more), on deterministic episodes
of ``leg_env/PlanarLegHop-v4`` (seeds 40000.., fresh: no policy trained or was selected on them). What it found is in
``hop_probes.md`` ("What the task's reward prefers").

    .venv/bin/python research/hop_reward_terms.py [EPISODES] [POLICY ...]

POLICY: a baseline's name (``hopper``, ``mpc``) or a policy folder; by default the hopper, the hop MPC and
``policies/ppo_hop_v4``, 30 episodes. Run from a checkout of branch ``hop-flat-kernel`` it scores the same gaits with
the fine height kernel flat within 1 cm of the command.
"""
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import gymnasium as gym
import numpy as np

import leg_env  # noqa: F401  (registers the tasks)
from leg_env.tasks.hop import REWARD_TERMS
from train.policy_loading import load_policy

ENV_ID = "leg_env/PlanarLegHop-v4"
OBS_COMMAND, OBS_LAST_APEX = 18, 21


def score(policy, episodes: int) -> dict:
    totals = dict.fromkeys(REWARD_TERMS, 0.0)
    errors, first_paid, survived = [], [], 0
    for seed in range(40000, 40000 + episodes):
        env = gym.make(ENV_ID)
        obs, _ = env.reset(seed=seed)
        last_apex, paid = 0.0, None
        for t in range(1000):
            action, _ = policy.predict(obs[None], deterministic=True)
            obs, _, terminated, truncated, info = env.step(np.clip(action[0], -1.0, 1.0))
            for term in REWARD_TERMS:
                totals[term] += float(info[f"reward_{term}"])
            if obs[OBS_LAST_APEX] != last_apex:  # a hop landed: its apex is the one paid from now on
                last_apex = obs[OBS_LAST_APEX]
                errors.append(abs(float(obs[OBS_LAST_APEX] - obs[OBS_COMMAND])))
            if paid is None and info["reward_height"] > 0.0:
                paid = t
            if terminated or truncated:
                break
        survived += not terminated
        first_paid.append(np.nan if paid is None else paid)
    e = 100.0 * np.array(errors)
    return {
        "survival": survived / episodes,
        "first_paid_step": float(np.nanmedian(first_paid)),
        "hops_paid": len(e) / episodes,
        "apex_error_cm": (float(e.mean()), float(np.sqrt((e**2).mean())), float(np.mean(e < 1.0)), float(np.mean(e > 2.0))),
        "terms": {k: v / episodes for k, v in totals.items()},
    }


def main() -> None:
    episodes = int(sys.argv[1]) if len(sys.argv) > 1 else 30
    names = sys.argv[2:] or ["hopper", "mpc", str(ROOT / "policies/ppo_hop_v4")]
    for name in names:
        s = score(load_policy(name, env_id=ENV_ID), episodes)
        mean, rms, within, over = s["apex_error_cm"]
        print(f"{name}: survival {s['survival']:.0%}, first hop paid at step {s['first_paid_step']:.0f} (median), "
              f"{s['hops_paid']:.1f} hops paid an episode, apex error {mean:.2f} cm mean, {rms:.2f} RMS, "
              f"{within:.0%} within 1 cm, {over:.0%} over 2 cm")
        terms = s["terms"]
        effort = terms["ctrl"] + terms["action_rate"] + terms["power"]
        print("   per episode: " + ", ".join(f"{k} {v:.0f}" for k, v in terms.items())
              + f"; effort (ctrl + action_rate + power) {effort:.0f}; return {sum(terms.values()):.0f}")


if __name__ == "__main__":
    main()
