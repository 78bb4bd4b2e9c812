"""The push-recovery controller of ``leg_env/PlanarLegPush-v2`` (``policies.stepping``): its push observer against
the force the task applied, its gate, its per-robot state in a batch, its loading by name, and that it survives
pushes the LQR falls from."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import leg_env  # noqa: F401  (registers the ids)
from leg_env.physics.dynamics import com_position
from policies.gated import GatedController
from policies.lqr import LQRController
from policies.recovery import com_from_observation
from policies.stepping import SteppingController
from train.evaluate import BASELINES, load_policy
from train.episodes import push_survival

ENV_ID = "leg_env/PlanarLegPush-v2"


def _robot():
    u = gym.make(ENV_ID).unwrapped
    return u.params, u.config


def test_com_from_observation_is_the_com_and_its_derivative():
    env = gym.make(ENV_ID)
    p = env.unwrapped.params
    rng = np.random.default_rng(1)
    for seed in range(5):
        obs = env.reset(seed=seed)[0].astype(np.float64)
        obs[5:10] = rng.uniform(-1.0, 1.0, 5)
        q, qd, e = obs[:5], obs[5:10], 1e-6
        v = (com_position(q + e * qd, p) - com_position(q - e * qd, p)) / (2 * e)
        c = com_position(q, p)
        x, y, vx = com_from_observation(obs, p)
        assert (x, y) == pytest.approx((c[0], c[1]), abs=1e-12) and vx == pytest.approx(v[0], abs=1e-8)


def test_push_observer_reads_the_applied_force_on_its_first_step():
    """On the first step of each push (foot sticking), ``F_hat`` is the task's force; with no push it is ~0.

    Standing, the reading errs by what the torque's change over a step does to the ground force (the trapezoid
    sees only the state's): a few newtons in the reset's transient, well under the 20 N gate, then hundredths.
    """
    n = 32
    params, config = _robot()
    envs = gym.make_vec(ENV_ID, num_envs=n, push_force=(10.0, 60.0))
    obs, _ = envs.reset(seed=500)
    ctl = SteppingController(params, config, force_threshold=1e9)  # observe only: the LQR acts throughout
    lqr = LQRController(params, config)
    pushed, previous = np.zeros(n), np.zeros(n)
    started = np.zeros(n, dtype=bool)
    checked, quiet, settled = 0, [], []
    for step in range(160):
        action, _ = ctl.predict(obs)
        np.testing.assert_array_equal(action, lqr.predict(obs)[0])  # never hops above an infinite threshold
        first = (pushed != 0.0) & (ctl.push_estimate != 0.0)  # the estimate of the step that the push began
        for i in np.flatnonzero(first):
            assert ctl.push_estimate[i] == pytest.approx(pushed[i], rel=0.05), f"robot {i}"
            checked += 1
        started |= previous != 0.0
        quiet.extend(ctl.push_estimate[~started])  # before any push: standing
        if step >= 20:
            settled.extend(ctl.push_estimate[~started])
        obs, _, terminated, _, info = envs.step(action)
        force = info["push_force"]
        pushed = np.where((force != 0.0) & (previous == 0.0) & ~terminated, force, 0.0)  # a push's first step only
        previous = force
    assert checked >= n // 2  # most robots' first push (at 0.8-1.2 s) was read
    assert np.max(np.abs(quiet)) < 0.5 * SteppingController(params, config).force_threshold  # the reset's transient
    assert len(settled) > 1000 and np.max(np.abs(settled)) < 0.5  # after 20 steps: under 0.5 N


def test_gate_hops_for_large_pushes_only_and_hands_back_to_the_lqr():
    params, config = _robot()
    for force, hops in ((10.0, False), (35.0, True)):
        envs = gym.make_vec(ENV_ID, num_envs=8, push_force=(force, force), push_interval=(100.0, 100.0))
        obs, _ = envs.reset(seed=40)
        ctl = SteppingController(params, config)
        lqr = LQRController(params, config)
        hopped = np.zeros(8, dtype=bool)
        for _ in range(400):
            action, _ = ctl.predict(obs)
            hopped |= ctl.hopping
            same = np.all(action == lqr.predict(obs)[0], axis=1)
            assert same[~ctl.hopping].all()  # the LQR whenever no hop is on
            obs, _, terminated, _, _ = envs.step(action)
            assert not terminated.any()
        assert (hopped == hops).all()
        assert not ctl.hopping.any()  # every hop has handed back


def test_survives_pushes_the_lqr_falls_from():
    """At 3.4 N s (1.5 times the LQR's 90% level), four pushes an episode: the LQR falls, the controller stands."""
    params, config = _robot()
    stepping = push_survival(SteppingController(params, config), [34.0], episodes=16, seed=10000)[0]
    lqr = push_survival(LQRController(params, config), [34.0], episodes=16, seed=10000)[0]
    assert stepping["survival_rate"] >= 15 / 16
    assert lqr["survival_rate"] <= 1 / 16


def test_batch_equals_single_robots_and_episode_start_restarts_a_row():
    n, steps = 4, 220
    params, config = _robot()
    kwargs = dict(push_force=(40.0, 40.0), first_push=(0.8, 0.8))
    envs = gym.make_vec(ENV_ID, num_envs=n, **kwargs)
    obs, _ = envs.reset(seed=7)
    batch = SteppingController(params, config)
    actions = []
    for _ in range(steps):
        a, _ = batch.predict(obs)
        actions.append(a)
        obs, _, terminated, _, _ = envs.step(a)
        assert not terminated.any()
    actions = np.stack(actions, axis=1)
    for i in range(n):
        single = SteppingController(params, config)
        env = gym.make(ENV_ID, **kwargs)
        o, _ = env.reset(seed=7 + i)
        for k in range(steps):
            a = single.predict(o)[0]
            np.testing.assert_allclose(a, actions[i, k], atol=1e-6, err_msg=f"robot {i}, step {k}")
            o = env.step(a)[0]
    # a robot mid-hop whose episode restarts is the LQR again, with a fresh observer; the others go on
    envs.reset(seed=7)
    batch.reset()
    for _ in range(steps):  # up to robot 0's hop (its push comes at 0.8 s)
        if batch.hopping[0]:
            break
        obs, *_ = envs.step(batch.predict(obs)[0])
    assert batch.hopping[0]
    others = batch.hopping[1:].copy()
    flags = np.zeros(n, dtype=bool)
    flags[0] = True
    batch.predict(obs, episode_start=flags)
    assert not batch.hopping[0] and batch.push_estimate[0] == 0.0
    np.testing.assert_array_equal(batch.hopping[1:] | ~others, True)  # the other rows' hops go on


@pytest.mark.parametrize(
    "name, cls, env_id, kwargs",
    [
        ("stepping", SteppingController, ENV_ID, {"com_weight": 2.0}),
        ("gated", GatedController, "leg_env/PlanarLegBalance-v1", {"alive_bonus": 10.0}),
    ],
)
def test_recovery_controllers_load_by_name_for_their_task(name, cls, env_id, kwargs):
    """``train.evaluate`` builds each by name with the task's config and the run's ``env_kwargs``; both refuse
    observations that are not the unilateral balance tasks' (18 entries)."""
    assert name in BASELINES
    ctl = load_policy(name, env_id=env_id, env_kwargs=kwargs)
    assert isinstance(ctl, cls)
    assert all(getattr(ctl.config, k) == v for k, v in kwargs.items()) and ctl.config.contact == "unilateral"
    assert ctl.hopper.config.mu == ctl.config.mu == gym.make(env_id).unwrapped.config.mu
    assert ctl.hopper.config.dt == ctl.config.dt and ctl.hopper.torque_limit.tolist() == list(ctl.config.torque_limit)
    for bad in (np.zeros(12), np.zeros((2, 3, 18))):
        with pytest.raises(ValueError, match="observation"):
            ctl.predict(bad)


@pytest.mark.parametrize("make", [SteppingController, LQRController])
def test_controllers_do_not_read_the_push_tasks_com_entry(make):
    """The push task's entry 18 (the COM's x from its start) is not read by the model-based controllers: on the same
    seeds, with that entry replaced by NaN, they act the same, step after step (the push curve's references are
    those of the balance observation)."""
    params, config = _robot()
    controllers = [make(params, config) if make is SteppingController else make(params) for _ in range(2)]
    envs = gym.make_vec(ENV_ID, num_envs=8, push_force=(45.0, 45.0))
    obs, _ = envs.reset(seed=3)
    assert obs.shape == (8, 21)
    hops = 0
    for _ in range(300):
        blind = obs.copy()
        blind[:, 18] = np.nan
        acts = [c.predict(o, deterministic=True)[0] for c, o in zip(controllers, (obs, blind))]
        assert np.array_equal(acts[0], acts[1]) and np.all(np.isfinite(acts[0]))
        obs, _, _, _, info = envs.step(acts[0])
        hops += int(np.sum(info["contact_mode"] == "flight"))
    assert hops > 0 or make is LQRController  # the stepping controller hopped: its hop read no entry 18 either
