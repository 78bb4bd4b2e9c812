"""The one batched episode runner (train.episodes): its rows are the single env's episodes, an ended episode
counts no further, the policy gets SB3's episode_start, and train.evaluate, the push curve and the periodic
evaluation of training all run through it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import leg_env  # registers the ids
from policies.hopper import HopperController
from policies.lqr import LQRController
from policies.stepping import SteppingController
from train.episodes import make_batch, policy_predict, run_batch
from train.evaluate import load_policy, run_episodes
from train.episodes import push_survival


def single_env_episodes(make_policy, env_id: str, seeds, env_kwargs=None):
    """The reference: each seed's episode in its own ``gym.make`` env, one observation at a time."""
    returns, lengths, survived = [], [], []
    for seed in seeds:
        env = gym.make(env_id, **(env_kwargs or {}))
        policy = make_policy(env)
        obs, _ = env.reset(seed=int(seed))
        total, steps, terminated, truncated = 0.0, 0, False, False
        while not (terminated or truncated):
            action, _ = policy.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(np.asarray(action, dtype=np.float64))
            total += reward
            steps += 1
        returns.append(total)
        lengths.append(steps)
        survived.append(bool(truncated and not terminated))
        env.close()
    return np.array(returns), np.array(lengths), np.array(survived)


@pytest.mark.parametrize(
    "env_id, make_policy, env_kwargs",
    [
        ("leg_env/PlanarLegHop-v4", lambda env: HopperController(), {}),
        ("leg_env/PlanarLegStance-v0", lambda env: LQRController(env.unwrapped.params, env.unwrapped.config), {"reset_noise_scale": 0.3}),
        ("leg_env/PlanarLegPush-v2", lambda env: SteppingController(env.unwrapped.params, env.unwrapped.config), {"push_force": [50.0, 50.0]}),
    ],
    ids=["hopper", "lqr-pinned", "stepping-pushed"],
)
def test_each_row_of_the_batch_is_the_single_env_episode_of_its_seed(env_id, make_policy, env_kwargs):
    """Returns, lengths and survival of every episode equal, bit for bit, those of the single env reset with the same
    seed and stepped one observation at a time; the cases include episodes that end early (falls) beside ones that
    run to the time limit, so the batch stops counting an episode at its own end."""
    seeds = list(range(10_000, 10_008))
    ref_returns, ref_lengths, ref_survived = single_env_episodes(make_policy, env_id, seeds, env_kwargs)
    envs = make_batch(env_id, len(seeds), env_kwargs)
    batch = run_batch(policy_predict(make_policy(gym.make(env_id, **env_kwargs))), envs, seeds)
    envs.close()
    assert not ref_survived.all() and ref_lengths.max() == 1000, "the case needs both ends"
    np.testing.assert_array_equal(batch.lengths, ref_lengths)
    np.testing.assert_array_equal(batch.survived, ref_survived)
    np.testing.assert_array_equal(batch.returns, ref_returns)


class Recorder:
    """A policy that records what it is given and acts from a fixed table."""

    def __init__(self):
        self.starts, self.resets = [], 0

    def reset(self):
        self.resets += 1

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        self.starts.append(np.array(episode_start))
        return np.tile([1.0, -1.0], (obs.shape[0], 1)), None  # a strong, constant torque: falls come quickly


def test_the_policy_gets_episode_start_and_one_reset_and_watchers_the_running_rows():
    seeds = [3, 4, 5]
    policy, seen = Recorder(), []

    class Watch:
        def start(self, envs, obs, info):
            seen.append(("start", obs.shape))

        def step(self, envs, obs, actions, info, active):
            seen.append(("step", active.copy()))

    envs = make_batch("leg_env/PlanarLegBalance-v1", 3)
    batch = run_batch(policy_predict(policy), envs, seeds, [Watch()])
    envs.close()
    assert policy.resets == 1
    assert policy.starts[0].tolist() == [True, True, True]
    assert seen[0] == ("start", (3, 20))
    steps = [active for kind, active in seen[1:]]
    assert len(steps) == batch.lengths.max() == len(policy.starts)
    for i in range(3):  # a row is active for exactly its episode's steps, then never again
        column = np.array([a[i] for a in steps])
        assert column[: batch.lengths[i]].all() and not column[batch.lengths[i]:].any()
    assert not batch.survived.any()


def test_a_batch_needs_one_seed_per_sub_env():
    envs = make_batch("leg_env/PlanarLegStance-v0", 2)
    with pytest.raises(ValueError, match="one seed per sub-env"):
        run_batch(policy_predict(Recorder()), envs, [1, 2, 3])
    envs.close()
    with pytest.raises(ValueError, match="record"):
        run_episodes(Recorder(), [1, 2], record=2)


@pytest.mark.sb3
def test_evaluate_the_push_curve_and_the_training_evaluation_agree_on_the_same_episodes():
    """The three callers of the runner score the same seeds the same: train.evaluate's episodes, the periodic
    evaluation's (seeds seed + i) and the push curve's survival at one force."""
    from train.callbacks import evaluate_now  # SB3's callbacks: not in the RLlib venv (the Makefile's SB3_TESTS)

    env_id, kwargs = "leg_env/PlanarLegPush-v2", {"push_force": [50.0, 50.0]}
    env = gym.make(env_id)
    stepping = SteppingController(env.unwrapped.params, env.unwrapped.config)
    seeds = list(range(20_000, 20_006))
    summary, _ = run_episodes(stepping, seeds, kwargs, env_id=env_id)
    envs = make_batch(env_id, len(seeds), kwargs)
    periodic = evaluate_now(stepping, envs, seeds[0])
    envs.close()
    curve = push_survival(stepping, [50.0], len(seeds), seeds[0], {}, env_id)
    assert periodic["returns"] == [e["return"] for e in summary["per_episode"]]
    assert periodic["lengths"] == [e["length"] for e in summary["per_episode"]]
    assert periodic["survival_rate"] == summary["survival_rate"] == curve[0]["survival_rate"]
    assert 0.0 < summary["survival_rate"] < 1.0  # the force is one that some of the episodes fall from


@pytest.mark.sb3
def test_the_training_evaluation_reports_the_hop_measures_as_train_evaluate_does():
    """On the hop task the periodic evaluation adds the measures of Solved, the same as train.evaluate's on the same
    seeds; on another task it adds none."""
    from train.callbacks import HOP_EVAL_KEYS, evaluate_now

    hopper = load_policy("hopper", env_id="leg_env/PlanarLegHop-v4")
    seeds = list(range(20_000, 20_004))
    summary, _ = run_episodes(hopper, seeds, env_id="leg_env/PlanarLegHop-v4")
    envs = make_batch("leg_env/PlanarLegHop-v4", len(seeds))
    periodic = evaluate_now(hopper, envs, seeds[0])
    envs.close()
    assert periodic["returns"] == [e["return"] for e in summary["per_episode"]]
    assert {key: periodic[key] for key in HOP_EVAL_KEYS} == {key: summary[key] for key in HOP_EVAL_KEYS}
    np.testing.assert_equal(periodic["apex_error_by_command"], summary["apex_error_by_command"])  # nan in a band without hops
    assert periodic["hops_per_episode"] > 5 and 0.0 < periodic["mean_abs_apex_error"] < 0.1
    envs = make_batch("leg_env/PlanarLegBalance-v1", 2)
    assert not set(HOP_EVAL_KEYS) & set(evaluate_now(load_policy("lqr", env_id="leg_env/PlanarLegBalance-v1"), envs, 0))
    envs.close()


def test_an_evaluation_names_how_each_episode_ended():
    """train.evaluate's episodes carry each fall's ending as the single env reports it at the step the episode
    ended (survivors: "none"), the summary counts them, and the table shows the counts."""
    from train.evaluate import format_table

    env_id, kwargs = "leg_env/PlanarLegPush-v2", {"push_force": [50.0, 50.0]}
    env = gym.make(env_id, **kwargs)
    stepping = SteppingController(env.unwrapped.params, env.unwrapped.config)
    seeds = list(range(10_000, 10_008))
    summary, _ = run_episodes(stepping, seeds, kwargs, env_id=env_id)
    for episode in summary["per_episode"]:
        single = gym.make(env_id, **kwargs)
        obs, _ = single.reset(seed=episode["seed"])
        controller = SteppingController(single.unwrapped.params, single.unwrapped.config)
        ending, steps = "none", 0
        while True:
            action, _ = controller.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = single.step(np.asarray(action, dtype=np.float64))
            steps += 1
            if terminated or truncated:
                ending = leg_env.ENDINGS[info["ending"]] if terminated else "none"
                break
        assert (episode["ending"], episode["length"]) == (ending, steps), episode["seed"]
        assert (ending == "none") == episode["survived"]
    falls = [e["ending"] for e in summary["per_episode"] if not e["survived"]]
    assert falls and sum(summary["endings"].values()) == len(falls)
    assert summary["endings"] == {name: falls.count(name) for name in set(falls)}
    row = next(line for line in format_table({"stepping": summary}).splitlines() if "ended early" in line)
    assert all(f"{name} {count}" in row for name, count in summary["endings"].items())


class _Saturated:
    """Both joints pushed to their bound at every step: the torque is each robot's own limit."""

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(obs)
        return np.tile([1.0, -1.0], (obs.shape[0], 1)) if obs.ndim == 2 else np.array([1.0, -1.0]), state


def test_the_rms_torque_is_what_each_drawn_robot_got():
    """On randomised robots (each with its own torque limits) and with the motor model, train.evaluate's RMS torque is
    that of the torques the single env reports (info["torque"]), not the clipped action times the nominal limits."""
    env_id, kwargs = "leg_env/PlanarLegBalance-v1", {"randomize": True, "motor_speed": 20.0}
    seeds = list(range(10_000, 10_006))
    summary, _ = run_episodes(_Saturated(), seeds, kwargs, env_id=env_id)
    torque_sq, steps, nominal = np.zeros(2), 0, None
    for seed in seeds:
        env = gym.make(env_id, **kwargs)
        obs, _ = env.reset(seed=seed)
        nominal = np.asarray(env.unwrapped.config.torque_limit, dtype=np.float64)
        while True:
            obs, _, terminated, truncated, info = env.step(np.array([1.0, -1.0]))
            torque_sq += np.asarray(info["torque"], dtype=np.float64) ** 2
            steps += 1
            if terminated or truncated:
                break
    assert summary["steps"] == steps
    np.testing.assert_allclose(summary["rms_torque"], np.sqrt(torque_sq / steps), rtol=0, atol=1e-4)
    assert np.all(np.abs(np.asarray(summary["rms_torque"]) - nominal) > 0.05)
