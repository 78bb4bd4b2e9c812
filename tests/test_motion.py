"""How a policy moves (train.motion): each measure against its definition computed step by step on single envs of the
same seeds, hand-made actions whose action rate and saturated share are known exactly, the restriction to the
episodes two controllers both survive, and the push task evaluated without pushes."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import leg_env  # registers the ids
from policies.hopper import HopperController
from policies.lqr import LQRController
from train.episodes import evaluate_now, make_batch, policy_predict, run_batch
from train.evaluate import EvalArgs, evaluate, load_policy, run_episodes
from train.motion import KEYS, PER_EPISODE, Motion

PINNED, BALANCE, HOP, PUSH = "leg_env/PlanarLegStance-v0", "leg_env/PlanarLegBalance-v1", "leg_env/PlanarLegHop-v4", "leg_env/PlanarLegPush-v2"


class Scripted:
    """A policy that plays ``table``'s rows in turn, the same action for every robot of the batch."""

    def __init__(self, table):
        self.table, self.t = np.asarray(table, dtype=np.float64), 0

    def reset(self):
        self.t = 0

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        action = self.table[self.t % len(self.table)]
        self.t += 1
        return (np.tile(action, (obs.shape[0], 1)) if obs.ndim == 2 else action.copy()), None


def lqr(env):
    return LQRController(env.unwrapped.params, env.unwrapped.config)


def direct(env_id: str, make_policy, seeds, env_kwargs=None) -> list[dict]:
    """The reference: each seed's episode in its own ``gym.make`` env, every measure by its definition, step by step."""
    episodes = []
    for seed in seeds:
        env = gym.make(env_id, **(env_kwargs or {}))
        robot = env.unwrapped
        policy = make_policy(env)
        if hasattr(policy, "reset"):
            policy.reset()
        obs, info = env.reset(seed=int(seed))
        weight = robot.robot_params.weight
        drawn = info.get("params")
        limit = np.array([drawn["hip_torque_limit"], drawn["knee_torque_limit"]] if drawn else robot.config.torque_limit, dtype=np.float64)
        q, x0, mode = robot.state[0], info["com_position"][0], info.get("contact_mode", "pinned")
        tilts, changes, saturated, work, forces, flights, away, pushes = [], [], 0, 0.0, [], 0, [], []
        previous, terminated, truncated = None, False, False
        while not (terminated or truncated):
            action, _ = policy.predict(obs, deterministic=True)
            action = np.asarray(action, dtype=np.float64)
            obs, _, terminated, truncated, info = env.step(action)
            a = np.clip(action, -1.0, 1.0)
            tilts.append(float(obs[2]))
            if previous is not None:
                changes += [abs(a[0] - previous[0]), abs(a[1] - previous[1])]
            previous = a
            saturated += int(abs(a[0]) >= 1.0) + int(abs(a[1]) >= 1.0)
            if "work_actuators" in info:
                step_work = info["work_actuators"]
            else:  # the pinned foot: the held torques times the joints' turn over the step
                after = robot.state[0]
                step_work = a[0] * limit[0] * (after[3] - q[3]) + a[1] * limit[1] * (after[4] - q[4])
                q = after
            work += max(0.0, step_work)
            forces.append(info["normal_force"] / (weight if weight > 0 else 1.0))
            now = info.get("contact_mode", "pinned")
            flights += now == "flight" and mode != "flight"
            mode = now
            away.append(abs(info["com_position"][0] - x0))
            pushes.append(info.get("push_force", 0.0))
        episodes.append({"length": len(tilts), "tilts": tilts, "changes": changes, "saturated": saturated, "work": work,
                         "peak": max(forces), "flights": flights, "excursion": max(away), "dt": robot.dt, "pushed": any(pushes)})  # fmt: skip
        env.close()
    return episodes


def pooled(episodes: list[dict]) -> dict:
    """The measures over the reference's episodes, by their definitions over all the steps."""
    steps = sum(e["length"] for e in episodes)
    seconds = steps * episodes[0]["dt"]
    changes = [c for e in episodes for c in e["changes"]]
    peaks = [e["peak"] for e in episodes]
    return {
        "episodes": len(episodes),
        "tilt_rms": float(np.degrees(np.sqrt(sum(t * t for e in episodes for t in e["tilts"]) / steps))),
        "action_rate": sum(changes) / len(changes),
        "saturated_share": sum(e["saturated"] for e in episodes) / (2 * steps),
        "actuator_power": sum(e["work"] for e in episodes) / seconds,
        "peak_normal_force": float(np.mean(peaks)),
        "peak_normal_force_max": max(peaks),
        "flights_per_episode": float(np.mean([e["flights"] for e in episodes])),
        "flights_per_10s": 10.0 * sum(e["flights"] for e in episodes) / seconds,
        "com_excursion": float(np.mean([e["excursion"] for e in episodes])),
    }


CASES = [
    # id, env id, the policy of an env, env kwargs, seeds
    ("lqr-balance", BALANCE, lqr, {"reset_noise_scale": 0.15}, range(10_000, 10_006)),
    ("hopper", HOP, lambda env: HopperController(), {}, range(10_000, 10_003)),
    ("lqr-pinned", PINNED, lqr, {"reset_noise_scale": 0.1}, range(10_000, 10_006)),
    ("lqr-pinned-randomised", PINNED, lqr, {"reset_noise_scale": 0.05, "randomize": True}, range(10_000, 10_004)),
    ("pinned-without-gravity", PINNED, lambda env: Scripted([[0.3, -0.2], [0.1, 0.4]]), {"params": {"g": 0.0}}, range(3)),
]


@pytest.mark.parametrize("env_id, make_policy, env_kwargs, seeds", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_each_measure_is_its_definition_on_single_envs_of_the_same_seeds(env_id, make_policy, env_kwargs, seeds):
    """train.evaluate's measures (per episode and over all) and the in-training evaluation's equal the definitions
    computed step by step on single envs of the same seeds: the unilateral ground (actuator work from info), the
    pinned foot (from the torques and the joints' turn), randomised robots (each its own weight and torque limits)
    and a robot without gravity (forces in newtons)."""
    seeds = list(seeds)
    reference = direct(env_id, make_policy, seeds, env_kwargs)
    policy = make_policy(gym.make(env_id, **env_kwargs))
    summary, _ = run_episodes(policy, seeds, env_kwargs, env_id=env_id)
    expected = pooled(reference)
    assert {k: summary["motion"][k] for k in KEYS} == pytest.approx(expected, rel=1e-9, abs=1e-12)
    for episode, ref in zip(summary["per_episode"], reference):
        one = pooled([ref])
        assert episode["length"] == ref["length"]
        assert episode["motion"] == pytest.approx({**{k: one.get(k) for k in PER_EPISODE}, "flights": ref["flights"]}, rel=1e-9, abs=1e-12)
    unit = "N" if env_kwargs.get("params", {}).get("g") == 0.0 else "m g"
    assert summary["motion"]["normal_force_unit"] == unit
    envs = make_batch(env_id, len(seeds), env_kwargs)
    periodic = evaluate_now(policy, envs, seeds[0])
    envs.close()
    assert periodic["motion"] == summary["motion"]
    assert expected["actuator_power"] > 0 and expected["peak_normal_force"] > 0 and expected["com_excursion"] > 0
    if env_id == PINNED:
        assert expected["flights_per_episode"] == 0
    else:
        assert expected["flights_per_episode"] > 0
    if env_id == HOP:  # every flight is a lift-off of the hop task's own tracker
        assert summary["hops"] == sum(r["flights"] for r in reference)


ACTIONS = [
    # actions played in turn, action rate, saturated share
    ([[1.0, -1.0], [-1.0, 1.0]], 2.0, 1.0),
    ([[0.2, 3.0]], 0.0, 0.5),  # the knee's 3 is clipped to the bound 1
    ([[0.0, 0.0], [0.5, -0.5]], 0.5, 0.0),
    ([[-4.0, 0.5], [-1.0, 0.0]], 0.25, 0.5),  # -4 and -1 are the same action once clipped
]


@pytest.mark.parametrize("table, rate, share", ACTIONS)
def test_hand_made_actions_have_their_exact_action_rate_and_saturated_share(table, rate, share):
    """Actions known in advance: the action rate and the saturated share are exactly theirs, on every episode and
    over all (the episodes' lengths differ: some fall)."""
    seeds = [1, 2, 3]
    watcher = Motion()
    envs = make_batch(PINNED, len(seeds), {"reset_noise_scale": 0.2})
    batch = run_batch(policy_predict(Scripted(table)), envs, seeds, [watcher])
    envs.close()
    per_episode = watcher.per_episode()
    assert np.all(batch.lengths > 2) and np.all(per_episode["length"] == batch.lengths)
    assert per_episode["action_rate"].tolist() == [rate] * 3 and per_episode["saturated_share"].tolist() == [share] * 3
    summary = watcher.summary()
    assert (summary["action_rate"], summary["saturated_share"], summary["episodes"]) == (rate, share, 3)


def test_an_episode_of_one_step_has_no_action_rate():
    motion = Motion()
    envs = make_batch(PINNED, 2, {"max_torso_angle": 1e-6})  # the first step ends it
    batch = run_batch(policy_predict(Scripted([[0.5, 0.5]])), envs, [0, 1], [motion])
    envs.close()
    assert batch.lengths.tolist() == [1, 1]
    assert np.isnan(motion.per_episode()["action_rate"]).all() and np.isnan(motion.summary()["action_rate"])
    assert motion.summary()["saturated_share"] == 0.0


def test_the_measures_on_the_episodes_both_controllers_survive(tmp_path):
    """train.evaluate restricts each controller's measures to the episodes that both it and the policy survive: the
    same measures as a batch of those episodes alone, for both; the controllers here fall on different episodes."""
    seeds = list(range(10_000, 10_012))
    out = evaluate(EvalArgs(policy="lqr", baseline=["gated"], env_id=BALANCE, env_kwargs=["reset_noise_scale:0.15"], episodes=12,
                            plot=False, out=tmp_path / "eval"))  # fmt: skip
    lqr_result, gated_result = (json.loads((out / f"{name}.json").read_text()) for name in ("lqr", "gated"))
    lived = {name: {e["seed"] for e in r["per_episode"] if e["survived"]} for name, r in (("lqr", lqr_result), ("gated", gated_result))}
    both = sorted(lived["lqr"] & lived["gated"])
    assert both and lived["lqr"] - lived["gated"] and lived["gated"] - lived["lqr"], "the case needs the controllers to differ"
    assert "no_push" not in lqr_result
    for name, result, other in (("lqr", lqr_result, "gated"), ("gated", gated_result, "lqr")):
        restricted = result["both_survived"][other]
        assert restricted["seeds"] == both and restricted["episodes"] == len(both)
        alone, _ = run_episodes(load_policy(name, env_id=BALANCE), both, {"reset_noise_scale": 0.15}, env_id=BALANCE)
        assert {k: restricted[k] for k in KEYS} == pytest.approx({k: alone["motion"][k] for k in KEYS}, rel=1e-12)
        assert restricted["flights_per_episode"] != result["motion"]["flights_per_episode"] or restricted["tilt_rms"] != result["motion"]["tilt_rms"]
    table = (out / "table.md").read_text()
    assert "Measured " in table.splitlines()[1]
    section = table.split("both lqr and each controller survive")[1]
    assert f"| episodes both survive | {len(both)} | {len(both)} |" in section


def test_the_push_task_is_also_evaluated_without_pushes(tmp_path):
    """On the push task every controller also runs the same seeds with push_force (0, 0): its measures there are
    those of single envs without a push (the reference checks that no step pushes), and they differ from the pushed
    ones; the table has the section and motion.png is drawn."""
    seeds = list(range(10_000, 10_003))
    out = evaluate(EvalArgs(policy="lqr", baseline=["stepping"], env_id=PUSH, env_kwargs=["push_force:[30.0, 30.0]"], episodes=3,
                            out=tmp_path / "eval"))  # fmt: skip
    for name in ("lqr", "stepping"):
        result = json.loads((out / f"{name}.json").read_text())
        calm = result["no_push"]
        assert calm["env_kwargs"] == {"push_force": [0.0, 0.0]}
        reference = direct(PUSH, lambda env: load_policy(name, env_id=PUSH), seeds, {"push_force": [0.0, 0.0]})
        assert not any(e["pushed"] for e in reference)
        expected = pooled(reference)
        assert {k: calm["motion"][k] for k in KEYS} == pytest.approx(expected, rel=1e-9)
        assert calm["survival_rate"] == 1.0 and calm["fell"] == [] and calm["motion"]["com_excursion"] < result["motion"]["com_excursion"]
    assert "How it moves without pushes" in (out / "table.md").read_text()
    assert (out / "motion.png").stat().st_size > 10_000


def test_a_motion_table_column_can_be_an_estimate_with_its_interval():
    """An ``Estimate`` column (the IQM across seeds, say) writes each measure as its point with the interval's ends."""
    from train.motion import Estimate, motion_table

    def summary(value: float) -> dict:
        return {**{key: value for key in KEYS}, "normal_force_unit": "m g"}

    table = motion_table({"seed 0": summary(2.0), "IQM [95% CI]": Estimate(summary(2.0), summary(1.0), summary(3.0))})
    assert table.splitlines()[0] == "| measure | seed 0 | IQM [95% CI] |"
    assert "| torso tilt RMS [deg] | 2.00 | 2.00 [1.00, 3.00] |" in table
    assert "| peak normal force, mean / max [m g] | 2.00 / 2.00 | 2.00 / 2.00 [1.00 / 1.00, 3.00 / 3.00] |" in table
