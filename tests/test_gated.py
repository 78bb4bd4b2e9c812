"""The gated recovery controller of ``leg_env/PlanarLegBalance-v1`` (``policies.gated``): its capture-point rule,
its per-robot state in a batch, its loading by name, and a residual run on it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import leg_env  # noqa: F401  (registers the ids)
from leg_env.physics.dynamics import com_position
from policies.gated import HOP_GAINS, GatedController, capture_point
from policies.hopper import HopperController
from policies.lqr import LQRController
from train.evaluate import load_policy

ENV_ID = "leg_env/PlanarLegBalance-v1"
HOP_SEEDS = (10003, 10023, 10025, 10038, 10045, 10062, 10074)  # capture point < -4.5 cm: the LQR falls


def _start(seed):
    env = gym.make(ENV_ID)
    obs, _ = env.reset(seed=seed)
    return env, obs


def test_capture_point_is_the_com_plus_its_velocity_term():
    env, _ = _start(0)
    p = env.unwrapped.params
    rng = np.random.default_rng(0)
    for seed in range(10000, 10020):
        obs = env.reset(seed=seed)[0].astype(np.float64)
        obs[5:10] += rng.uniform(-0.5, 0.5, 5)  # any velocity, not only the reset's
        q, qd, e = obs[:5], obs[5:10], 1e-6
        c = com_position(q, p)
        v = (com_position(q + e * qd, p) - com_position(q - e * qd, p)) / (2 * e)
        assert capture_point(obs, p) == pytest.approx(c[0] + v[0] / np.sqrt(p.g / c[1]), abs=1e-9)


def _hop_obs(obs, command):
    """The hop task's observation of a balance observation and a command: the entries after the command are not read
    by the hopper (NaN would show if they were)."""
    from leg_env.tasks.base import Obs

    hop = np.full(22, np.nan, dtype=np.float32)
    hop[:18], hop[Obs.command] = obs[:18], command  # the balance entries, not the last action after them
    return hop


def test_decision_follows_the_capture_point_rule():
    env, _ = _start(0)
    u = env.unwrapped
    starts = np.stack([env.reset(seed=s)[0] for s in range(10000, 10100)])
    cp = capture_point(starts, u.params)
    gated = GatedController(u.params, u.config)
    decided = gated.decide(starts)
    np.testing.assert_array_equal(decided, cp < -0.04)
    hopped = set(np.flatnonzero(decided) + 10000)
    assert set(HOP_SEEDS) <= hopped and len(hopped) < 20  # the seven bad starts hop, most starts do not
    # the first action: the hopper's on a hopping start, the LQR's otherwise; the threshold moves the choice
    lqr = LQRController(u.params, u.config)
    for seed in (10003, 10000):
        obs = env.reset(seed=seed)[0]
        hopper = HopperController(u.params, None, **HOP_GAINS)
        expect = hopper.predict(_hop_obs(obs, 0.06))[0] if seed in HOP_SEEDS else lqr.predict(obs)[0]
        np.testing.assert_array_equal(GatedController(u.params, u.config).predict(obs)[0], expect)
        assert not np.array_equal(expect, (lqr.predict(obs)[0] if seed in HOP_SEEDS else hopper.predict(_hop_obs(obs, 0.06))[0]))
    never = GatedController(u.params, u.config, threshold=-1.0)
    np.testing.assert_array_equal(never.predict(env.reset(seed=10003)[0])[0], lqr.predict(env.reset(seed=10003)[0])[0])


def _episode(controller, seed, steps=1000):
    env, obs = _start(seed)
    if hasattr(controller, "reset"):
        controller.reset()
    for k in range(steps):
        obs, _, terminated, truncated, _ = env.step(controller.predict(obs)[0])
        if terminated:
            return k + 1
    return steps


def test_gated_controller_recovers_a_start_the_lqr_falls_from():
    env, _ = _start(0)
    u = env.unwrapped
    assert _episode(LQRController(u.params, u.config), 10003) < 1000
    gated = GatedController(u.params, u.config)
    assert _episode(gated, 10003) == 1000
    assert gated.hopping[0] and gated.steps[0] == 1000
    assert _episode(gated, 10000) == 1000 and not gated.hopping[0]  # reset() re-decides


def test_batch_equals_single_robots_and_episode_start_restarts_a_row():
    n, seed0, steps = 8, 10020, 60  # sub-env i is the single env seeded 10020 + i: 10023 and 10025 hop
    envs = gym.make_vec(ENV_ID, num_envs=n)
    obs, _ = envs.reset(seed=seed0)
    u = gym.make(ENV_ID).unwrapped
    batch = GatedController(u.params, u.config)
    actions = []
    for _ in range(steps):
        a, _ = batch.predict(obs)
        actions.append(a)
        obs, _, terminated, _, _ = envs.step(a)
        assert not terminated.any()
    actions = np.stack(actions, axis=1)
    assert batch.hopping.sum() == 2
    for i in range(n):
        single = GatedController(u.params, u.config)
        env, o = _start(seed0 + i)
        for k in range(steps):
            a = single.predict(o)[0]
            np.testing.assert_allclose(a, actions[i, k], atol=1e-6, err_msg=f"robot {i}, step {k}")
            o = env.step(a)[0]
    # a new episode in one row: that row re-decides from its observation and restarts its count, the others go on
    starts = np.stack([gym.make(ENV_ID).reset(seed=s)[0] for s in (10003,) * n])
    flags = np.zeros(n, dtype=bool)
    flags[0] = True
    before = batch.steps.copy()
    batch.predict(starts, episode_start=flags)
    assert batch.hopping[0] and batch.steps[0] == 1
    np.testing.assert_array_equal(batch.steps[1:], before[1:] + 1)


@pytest.mark.sb3
def test_residual_on_the_gated_controller_reloads_as_the_sum(tmp_path):
    from train.ppo import TrainArgs, train
    from train.residual import ResidualPolicy

    out = train(TrainArgs(out=tmp_path / "run", env_id=ENV_ID, residual="gated", residual_scale=0.1,
                          params=["n_envs:4", "n_steps:32", "batch_size:64", "n_epochs:1"], total_timesteps=128,
                          eval_freq=128, eval_episodes=2, checkpoint_freq=0, progress_bar=False, verbose=0))  # fmt: skip
    policy = load_policy(out)
    assert isinstance(policy, ResidualPolicy) and isinstance(policy.controller, GatedController)
    env, obs = _start(10003)
    u = env.unwrapped
    expected = np.clip(GatedController(u.params, u.config).predict(obs)[0] + 0.1 * np.clip(policy.network.predict(obs)[0], -1, 1), -1, 1)
    policy.reset()
    np.testing.assert_allclose(policy.predict(obs)[0], expected, atol=1e-6)
