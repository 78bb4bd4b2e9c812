"""Training and evaluation on every task: train.ppo and train.evaluate take any task id, the Zoo file has
an entry per task, the model-based baselines, and the task metrics (hop apexes, push survival)."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

import leg_env
from policies.hopper import HopperController
from policies.lqr import LQRController
from train.evaluate import EvalArgs, evaluate, load_policy, run_episodes
from train.ppo import TrainArgs, train
from train.episodes import push_survival
from train.task_metrics import HopTracker, largest_survived_impulse

ROOT = Path(__file__).resolve().parents[1]
TASK_IDS = ("leg_env/PlanarLegBalance-v1", "leg_env/PlanarLegPush-v2", "leg_env/PlanarLegHop-v4")
TINY = ["n_envs:4", "n_steps:32", "batch_size:64", "n_epochs:1"]


def test_zoo_file_has_an_entry_per_task():
    entries = yaml.safe_load((ROOT / "train" / "hyperparams" / "ppo.yml").read_text())
    assert set(leg_env.ENV_IDS) <= set(entries)


@pytest.mark.sb3
@pytest.mark.parametrize("env_id", TASK_IDS)
def test_train_and_evaluate_take_any_task(env_id, tmp_path):
    out = train(TrainArgs(out=tmp_path / "run", env_id=env_id, params=list(TINY), total_timesteps=128, eval_freq=128,
                          eval_episodes=2, checkpoint_freq=0, progress_bar=False, verbose=0))  # fmt: skip
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert config["env_id"] == env_id
    policy = load_policy(out)
    env = gym.make(env_id)
    assert policy.model.observation_space.shape == env.observation_space.shape
    result = evaluate(EvalArgs(policy=str(out), episodes=2, plot=False))  # the task from the run's config
    summary = json.loads((result / "policy.json").read_text())
    assert summary["env_id"] == env_id
    assert set(summary["mean_reward_terms"]) == set(env.unwrapped.task.reward_terms)


def test_lqr_reads_the_unilateral_observation():
    env = gym.make("leg_env/PlanarLegBalance-v1")
    lqr = load_policy("lqr", env_id="leg_env/PlanarLegBalance-v1")
    assert isinstance(lqr, LQRController)
    obs, _ = env.reset(seed=3)
    action, _ = lqr.predict(obs)
    pinned = LQRController(env.unwrapped.params, env.unwrapped.config).predict(obs[:12])[0]
    np.testing.assert_array_equal(action, pinned)  # the same entries, the same gain
    with pytest.raises(ValueError, match="observation"):
        lqr.predict(np.zeros(13))


def test_hopper_is_loaded_for_the_hop_task_and_is_batched():
    hopper = load_policy("hopper", env_id="leg_env/PlanarLegHop-v4")
    assert isinstance(hopper, HopperController)
    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=3)
    obs, _ = envs.reset(seed=5)
    batch, _ = hopper.predict(obs)
    singles = []
    for row in obs:
        hopper.reset()
        singles.append(hopper.predict(row)[0])
    np.testing.assert_array_equal(batch, np.stack(singles))
    assert batch.shape == (3, 2) and np.all(np.abs(batch) <= 1.0)
    with pytest.raises(ValueError, match="22"):
        hopper.predict(np.zeros(19))


def test_hop_tracker_apex_is_the_ballistic_apex():
    """A robot thrown upwards with zero torques: the tracker's apex is the same at every instant of the
    flight and lies above the highest sampled COM height by at most g dt^2 / 8."""
    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=1)
    envs.reset(seed=0)
    q, _, _ = envs.state
    q = q[0].copy()
    q[1] += 0.05  # the foot 5 cm above the ground
    qd = np.zeros(5)
    qd[1] = 1.0
    obs, info = envs.reset(seed=0, options={"qpos": q, "qvel": qd})
    tracker = HopTracker(record=0)
    tracker.start(envs, obs, info)
    heights = []
    while True:
        obs, _, _, _, info = envs.step(np.zeros((1, 2)))
        if info["contact_mode"][0] != "flight":
            break
        tracker.step(envs, obs, np.zeros((1, 2)), info, np.ones(1, dtype=bool))
        heights.append(tracker.series["com_height"][-1])
    apex = np.asarray(tracker.series["apex"])
    assert len(apex) > 10
    np.testing.assert_allclose(apex, apex[0], rtol=0, atol=1e-9)
    g, dt = envs.params.g, envs.dt
    assert 0.0 <= apex[0] - max(heights) <= g * dt * dt / 8 + 1e-12
    assert tracker.summary()["hops"] == 0  # it started in flight: no lift-off was seen


def test_hop_tracker_counts_hops_and_errors_of_the_hopper():
    hopper = HopperController()
    summary, series = run_episodes(hopper, [10_000], record=0, env_id="leg_env/PlanarLegHop-v4")
    assert {"hops", "mean_abs_apex_error", "rms_apex_error", "mean_hop_period", "mean_landing_impulse"} <= set(summary)
    hop = series["hop"]
    assert len(hop["com_height"]) == summary["per_episode"][0]["length"]
    flying = ~np.isnan(np.asarray(hop["apex"]))  # apexes exist in flight only
    assert summary["hops"] == int(flying[0]) + int(np.sum(flying[1:] & ~flying[:-1]))  # it starts standing
    assert summary["hops"] > 0


def test_hop_tracker_splits_the_apex_errors_by_command():
    """The bands cover the task's command range in equal widths; every hop falls in the band of its command, and the
    bands' hop-weighted mean is the summary's signed mean; the evaluation table shows one row per band."""
    from train.evaluate import format_table
    from train.task_metrics import COMMAND_BANDS

    hopper = HopperController()
    summary, _ = run_episodes(hopper, list(range(10_000, 10_012)), env_id="leg_env/PlanarLegHop-v4")
    bands = summary["apex_error_by_command"]
    assert len(bands) == COMMAND_BANDS
    np.testing.assert_allclose([b["low"] for b in bands] + [bands[-1]["high"]], np.linspace(0.05, 0.15, COMMAND_BANDS + 1))
    assert sum(b["hops"] for b in bands) == summary["hops"] > 0
    with_hops = [b for b in bands if b["hops"]]
    weighted = sum(b["hops"] * b["mean_apex_error"] for b in with_hops) / summary["hops"]
    assert weighted == pytest.approx(summary["mean_apex_error"], rel=1e-12)
    assert all(np.isnan(b["mean_apex_error"]) for b in bands if not b["hops"])
    table = format_table({"hopper": summary, "again": summary}).splitlines()
    rows = [line for line in table if line.startswith("| ... at commands")]
    assert rows[0].startswith("| ... at commands 5-7 cm (hops) |") and rows[-1].startswith("| ... at commands 13-15 cm (hops) |")
    assert len(rows) == COMMAND_BANDS
    # by hand: hops of known commands and errors in a tracker of the range 2-6 cm
    tracker = HopTracker()
    tracker._command_range = (0.02, 0.06)
    tracker.errors, tracker.commands = [0.01, -0.01, 0.03, -0.02], [0.02, 0.0279, 0.06, 0.035]
    by = tracker.by_command()
    assert [b["hops"] for b in by] == [2, 1, 0, 0, 1]  # bands of 0.8 cm: 2-2.8, 2.8-3.6, ...; 3.5 cm in the second
    assert by[0]["mean_apex_error"] == pytest.approx(0.0) and by[1]["mean_apex_error"] == pytest.approx(-0.02)
    assert by[4]["mean_apex_error"] == pytest.approx(0.03)  # the range's top command is in the last band
    tracker._command_range = (0.1, 0.1)
    assert [(b["low"], b["high"], b["hops"]) for b in tracker.by_command()] == [(0.1, 0.1, 4)]


def test_push_survival_uses_the_same_seeds_and_fixed_forces():
    lqr = load_policy("lqr", env_id="leg_env/PlanarLegPush-v2")
    rows = push_survival(lqr, [0.0, 200.0], episodes=4, seed=10_000)
    assert [r["force"] for r in rows] == [0.0, 200.0]
    assert rows[0]["survival_rate"] == 1.0  # no push: the LQR balances
    assert rows[1]["survival_rate"] == 0.0  # 20 N s: far beyond standing recovery
    assert rows[1]["impulse"] == pytest.approx(20.0)
    assert largest_survived_impulse(rows) == 0.0
    assert largest_survived_impulse([{"impulse": 1.0, "survival_rate": 1.0}, {"impulse": 2.0, "survival_rate": 0.9},
                                     {"impulse": 3.0, "survival_rate": 0.5}, {"impulse": 4.0, "survival_rate": 0.95}]) == 2.0  # fmt: skip


def test_push_curve_needs_the_push_task(tmp_path):
    with pytest.raises(ValueError, match="PlanarLegPush-v2"):
        evaluate(EvalArgs(policy="lqr", env_id="leg_env/PlanarLegBalance-v1", episodes=1, push_curve=True, out=tmp_path, plot=False))


def _ppo_on(env_id: str, net_arch=(16, 16)):
    from stable_baselines3 import PPO

    from leg_env.sb3 import make_sb3_vec_env

    return PPO("MlpPolicy", make_sb3_vec_env(2, seed=0, env_id=env_id), n_steps=16, batch_size=32, device="cpu", seed=0,
               policy_kwargs={"net_arch": list(net_arch)})  # fmt: skip


@pytest.mark.sb3
def test_warm_start_copies_a_policy_and_pads_new_inputs(tmp_path):
    import torch

    from train.warmstart import copy_policy

    source = _ppo_on("leg_env/PlanarLegStance-v0")  # 12 observations
    source.save(tmp_path / "model.zip")
    target = _ppo_on("leg_env/PlanarLegBalance-v1")  # 18
    copy_policy(target, tmp_path)
    src, dst = source.policy.state_dict(), target.policy.state_dict()
    first = "mlp_extractor.policy_net.0.weight"
    assert torch.equal(dst[first][:, :12], src[first]) and not dst[first][:, 12:].any()
    assert torch.equal(dst["action_net.weight"], src["action_net.weight"])
    obs = gym.make("leg_env/PlanarLegBalance-v1").reset(seed=2)[0]
    np.testing.assert_allclose(target.predict(obs, deterministic=True)[0], source.predict(obs[:12], deterministic=True)[0], atol=1e-6)
    with pytest.raises(ValueError, match="shape"):
        copy_policy(_ppo_on("leg_env/PlanarLegBalance-v1", net_arch=(8, 8)), tmp_path)
    with pytest.raises(FileNotFoundError, match="model.zip"):
        copy_policy(target, tmp_path / "nowhere")


@pytest.mark.sb3
def test_clone_controller_fits_the_lqr(monkeypatch):
    import train.warmstart as warmstart

    monkeypatch.setattr(warmstart, "CLONE_ENVS", 32)
    monkeypatch.setattr(warmstart, "CLONE_STEPS", 60)
    monkeypatch.setattr(warmstart, "CLONE_EPOCHS", 1500)  # about the Adam steps of the full-size data's 30 epochs
    model = _ppo_on("leg_env/PlanarLegBalance-v1", net_arch=(64, 64))
    lqr = load_policy("lqr", env_id="leg_env/PlanarLegBalance-v1")
    envs = gym.make_vec("leg_env/PlanarLegBalance-v1", num_envs=64)
    obs, _ = envs.reset(seed=99)  # states not in the cloning data

    def error():
        return float(np.sqrt(np.mean((model.predict(obs, deterministic=True)[0] - lqr.predict(obs)[0]) ** 2)))

    before = error()
    rms = warmstart.clone_controller(model, lqr, "leg_env/PlanarLegBalance-v1", {}, seed=0)
    held_out = error()
    assert rms < 0.05 and held_out < 0.15 and held_out < before / 2  # fits its data, and carries over to fresh states


@pytest.mark.sb3
def test_residual_env_applies_the_controller_plus_the_scaled_correction():
    from leg_env.sb3 import make_sb3_vec_env
    from train.residual import ResidualVecEnv, residual_action

    np.testing.assert_array_equal(residual_action(np.array([0.5, -0.9]), np.array([3.0, -0.5]), 0.3), np.float32([0.8, -1.0]))
    lqr = load_policy("lqr", env_id="leg_env/PlanarLegPush-v2")
    wrapped = ResidualVecEnv(make_sb3_vec_env(3, seed=7, env_id="leg_env/PlanarLegPush-v2"), lqr, 0.5)
    plain = make_sb3_vec_env(3, seed=7, env_id="leg_env/PlanarLegPush-v2")
    obs_w, obs_p = wrapped.reset(), plain.reset()
    rng = np.random.default_rng(0)
    for _ in range(30):
        correction = rng.uniform(-1, 1, (3, 2)).astype(np.float32)
        obs_w, _, _, _ = wrapped.step(correction)
        obs_p, _, _, _ = plain.step(residual_action(lqr.predict(obs_p)[0], correction, 0.5))
        np.testing.assert_array_equal(obs_w, obs_p)


@pytest.mark.sb3
def test_residual_run_reloads_as_the_sum(tmp_path):
    from train.residual import ResidualPolicy

    out = train(TrainArgs(out=tmp_path / "run", env_id="leg_env/PlanarLegHop-v4", residual="hopper", residual_scale=0.2,
                          params=list(TINY), total_timesteps=128, eval_freq=128, eval_episodes=2, checkpoint_freq=0,
                          progress_bar=False, verbose=0))  # fmt: skip
    policy = load_policy(out)
    assert isinstance(policy, ResidualPolicy) and policy.scale == 0.2
    obs = gym.make("leg_env/PlanarLegHop-v4").reset(seed=4)[0]
    hopper = HopperController()
    expected = np.clip(hopper.predict(obs)[0] + 0.2 * np.clip(policy.network.predict(obs)[0], -1, 1), -1, 1)
    policy.reset()
    np.testing.assert_allclose(policy.predict(obs)[0], expected, atol=1e-6)
    with pytest.raises(ValueError, match="residual"):
        TrainArgs(out=tmp_path / "x", residual="pid")
