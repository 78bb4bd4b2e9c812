"""``policies.push_mpc.PushMPC``: it plans only while a push is recovered from, its model is the env's step (the push
held over its duration), its backward pass differentiates the closed loop around the stepping controller, without
iterations it is the stepping controller, and it recovers from pushes the stepping controller falls at."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import leg_env  # noqa: F401  (registers the tasks)
from ilqr_checks import checked_backward, checked_gradients
from policies.push_mpc import PushMPC
from policies.stepping import SteppingController
from train.policy_loading import load_policy

PUSH = "leg_env/PlanarLegPush-v2"


def _envs(n, force, seed=60000):
    envs = gym.make_vec(PUSH, num_envs=n, vectorization_mode="vector_entry_point", push_force=(force, force))
    obs, _ = envs.reset(seed=seed)
    return envs, obs


def test_the_plan_predicts_the_env():
    """Where a robot plans, the plan's first state after the step is the env's next state (the observation's float32
    aside), through the hop's lift-off and touchdown; over a push's steps the plan holds the observed push, whose
    reading puts the base's speed after a step within a few percent of the push's own change of it."""
    envs, obs = _envs(4, 45.0)
    e = envs.unwrapped
    mpc = PushMPC(e.params, e.config)
    modes, compared, pushed = set(), 0, []
    for _ in range(220):
        action, _ = mpc.predict(obs)
        rows = mpc.planning.copy()
        predicted = mpc.planned[:, 1].copy() if rows.any() else None
        obs, _, terminated, _, info = envs.step(action)
        assert not terminated.any()
        if predicted is None:
            continue
        q, qd, _ = mpc.state(obs[rows])
        got = np.concatenate([q, qd], axis=1)
        modes.update(info["contact_mode"][rows])
        quiet = info["push_force"][rows] == 0.0
        # the observation's frame: the base relative to its contact point (translation along the ground is free)
        np.testing.assert_allclose(got[quiet, 1:], predicted[quiet, 1:], atol=2e-5)
        compared += quiet.sum()
        if (~quiet).any():
            pushed.append(np.abs(got[~quiet, 5] - predicted[~quiet, 5]).max())
    assert {"stick", "flight"} <= modes and compared >= 100  # through lift-offs and touchdowns
    change = 45.0 * e.config.dt / (e.params.m_b + e.params.m1 + e.params.m2)  # what the push does to the speed in a step
    assert len(pushed) >= 10 and max(pushed) < 0.2 * change and np.median(pushed) < 0.05 * change  # 0.11, 0.03 measured


def test_it_plans_only_while_recovering():
    """Unpushed, the stepping controller stands and nothing is planned; pushed, the planning starts with the hop."""
    envs, obs = _envs(3, 0.0)
    e = envs.unwrapped
    mpc, stepping = PushMPC(e.params, e.config), SteppingController(e.params, e.config)
    for _ in range(150):
        a, _ = mpc.predict(obs)
        b, _ = stepping.predict(obs)
        assert not mpc.planning.any()
        np.testing.assert_array_equal(a, b)
        obs, *_ = envs.step(a)


def test_backward_pass_differentiates_the_closed_loop():
    """The chain of the closed loop's ``A`` and ``B`` (the step's Jacobians under the held push, with the stepping
    controller's feedback: its hop and, after the hand-over, the LQR) gives the plan cost's gradient by the
    corrections that centred differences of the rolled-out cost give."""
    envs, obs = _envs(8, 55.0)
    e = envs.unwrapped
    mpc = PushMPC(e.params, e.config, horizon=40, steps=(), fall_cost=0.0, power_weight=1e-4, clip_smoothing=0.0)
    for _ in range(300):
        action, _ = mpc.predict(obs)
        if mpc.planning.sum() >= 4 and (mpc._push_left[mpc.planning] > 0).any():  # hops begun, a push still on
            break
        obs, *_ = envs.step(action)
    else:
        raise AssertionError("no step where four robots plan under a push")
    rows = mpc.planning
    source = mpc._snapshot(rows, np.zeros_like(rows))
    q, qd, mode = mpc.state(obs[rows])
    ctx = mpc._context(obs, rows, source, np.concatenate([q, qd], axis=1))
    assert checked_backward(mpc, source, q, qd, mode, ctx) < 1e-10  # the compiled pass is the numpy one
    checked = checked_gradients(mpc, source, q, qd, mode, ctx)
    assert checked >= 24


def test_without_iterations_it_is_the_stepping_controller():
    """No line-search step: the plan is the stepping controller's own closed loop, so the actions are the stepping
    controller's (the MPC's law in float64 on the state projected on its contact)."""
    envs, obs = _envs(4, 40.0)
    e = envs.unwrapped
    mpc = PushMPC(e.params, e.config, horizon=4, steps=())
    stepping = SteppingController(e.params, e.config)
    planned = 0
    for _ in range(300):
        a, _ = mpc.predict(obs)
        b, _ = stepping.predict(obs)
        planned += mpc.planning.sum()
        np.testing.assert_allclose(a, b, atol=2e-3)
        obs, *_ = envs.step(b)
    assert planned >= 100


def test_recovers_where_the_stepping_controller_falls():
    """One push of 60 N (6 N s) on eight robots: the stepping controller survives 5 (seeds 60000..60007); the MPC,
    planning on the same robots, 8."""
    survived = {}
    for name in ("stepping", "mpc"):
        envs, obs = _envs(8, 60.0)
        e = envs.unwrapped
        c = SteppingController(e.params, e.config) if name == "stepping" else PushMPC(e.params, e.config)
        alive = np.ones(8, dtype=bool)
        for _ in range(220):  # the first push comes at 0.8-1.2 s
            action, _ = c.predict(obs)
            obs, _, terminated, _, _ = envs.step(action)
            alive &= ~terminated
        survived[name] = int(alive.sum())
    assert survived["mpc"] >= survived["stepping"] + 3, survived


def test_loads_by_name_and_checks_its_input():
    policy = load_policy("mpc", env_id=PUSH)
    assert isinstance(policy, PushMPC)
    envs, obs = _envs(2, 60.0)
    action, _ = policy.predict(obs)
    assert action.shape == (2, 2) and action.dtype == np.float32 and np.all(np.abs(action) <= 1.0)
    with pytest.raises(ValueError, match="observation must have shape"):
        policy.predict(obs[:, :18])
    for bad_setting in (dict(horizon=1), dict(speed_scale=0.0), dict(after_hop=-1), dict(fall_cost=float("inf"))):
        with pytest.raises(ValueError, match=next(iter(bad_setting))):
            PushMPC(**bad_setting)
    with pytest.raises(TypeError):
        PushMPC(horizon_steps=10)
    with pytest.raises(TypeError):
        PushMPC(stepping=dict(threshold=10.0))  # the stepping controller's keywords are checked too
    bad = obs.copy()
    bad[1, 7] = np.inf
    state = (policy._plan.copy(), policy._pilot._v.copy(), policy._pilot._run.copy(), policy._push_left.copy())
    with pytest.raises(ValueError, match="observation must be finite: rows \\[1\\]"):
        policy.predict(bad)
    after = (policy._plan, policy._pilot._v, policy._pilot._run, policy._push_left)
    for before, now in zip(state, after):
        np.testing.assert_array_equal(now, before)  # nothing changed
