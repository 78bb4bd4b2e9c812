"""Every registered task id through the shared environments: checkers, determinism, pickling, vector /
single parity bit for bit, the SB3 contract, the push schedule and the push's effect in the env."""

from __future__ import annotations

import pickle
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env, data_equivalence
from gymnasium.vector import AutoresetMode

import leg_env
from leg_env import physics as dyn
from leg_env.tasks import REGISTRY

NEW_IDS = ("leg_env/PlanarLegBalance-v1", "leg_env/PlanarLegPush-v2", "leg_env/PlanarLegHop-v4")
REMOVED = {  # removed id: the current id of its task, which Gymnasium's error names ("" where the name has none)
    "leg_env/PlanarLegPush-v0": "leg_env/PlanarLegPush-v2",
    "leg_env/PlanarLegPush-v1": "leg_env/PlanarLegPush-v2",
    "leg_env/PlanarLegHop-v0": "leg_env/PlanarLegHop-v4",
    "leg_env/PlanarLegHop-v1": "leg_env/PlanarLegHop-v4",
    "leg_env/PlanarLegHop-v2": "leg_env/PlanarLegHop-v4",
    "leg_env/PlanarLegHop-v3": "leg_env/PlanarLegHop-v4",
    "leg_env/PlanarLegStance-v1": "",
    "leg_env/PlanarLegBalance-v0": "leg_env/PlanarLegBalance-v1",
}
ALL_IDS = tuple(REGISTRY)
NUM_ENVS = 4
SEED = 5
STEPS = 120
MAX_STEPS = 40
# frequent pushes, so that short test episodes have them
FAST_PUSHES = dict(first_push=(0.05, 0.15), push_interval=(0.1, 0.2), push_force=(40.0, 160.0))
KWARGS = {
    "leg_env/PlanarLegStance-v0": dict(reset_noise_scale=0.05, ctrl_cost_weight=0.02),
    "leg_env/PlanarLegBalance-v1": dict(ctrl_cost_weight=0.02, params={"m_b": 9.0}),
    "leg_env/PlanarLegPush-v2": dict(FAST_PUSHES, com_weight=2.0, params={"l2": 0.55}, quiet_share=0.4, quiet_flight_scale=3.0),
    "leg_env/PlanarLegHop-v4": dict(command_range=(0.06, 0.12), impact_weight=0.7, reset_noise_scale=0.03),
}


def actions(steps: int, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (0.8 * rng.uniform(-1.0, 1.0, size=(steps, n, 2)) + np.array([0.0, -0.45])).astype(np.float32)


def test_every_task_id_is_registered():
    assert set(ALL_IDS) <= set(gym.registry) and set(NEW_IDS) <= set(ALL_IDS) and leg_env.ENV_IDS == ALL_IDS


def test_one_id_per_task_none_out_of_date_and_a_removed_id_refused_naming_the_current_one():
    """Each task has one id, and making it draws no warning (Gymnasium calls an id out of date when a higher
    version of its name is registered). A removed version of a task is refused with Gymnasium's error naming the
    current id; the removed ``PlanarLegStance-v1`` (the balance task's id before it had a name of its own) is refused too."""
    import warnings

    from gymnasium.error import DeprecatedEnv, VersionNotFound

    names = [env_id.rsplit("-v", 1)[0] for env_id in leg_env.ENV_IDS]
    assert len(set(names)) == len(names) == len({task for task, _ in REGISTRY.values()}) + 1  # stance: pinned and unilateral
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for env_id in leg_env.ENV_IDS:
            gym.make(env_id).reset(seed=0)
            gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point").reset(seed=0)
    for old, current in REMOVED.items():
        assert old not in gym.registry
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            with pytest.raises(DeprecatedEnv if current else VersionNotFound, match=current or "v1"):
                gym.make(old)


BALANCE_V1 = dict(contact="unilateral", reset_noise_scale=0.05, unilateral_weight=2.0, drift_angle_weight=10.0,
                  ctrl_cost_weight=0.05, action_change_weight=0.2, observe_action=True)
"""``PlanarLegBalance-v1`` as ``PlanarLegStance-v0``'s arguments, as its docstring gives them."""


def test_balance_is_stance_on_the_unilateral_ground_with_a_larger_noise_and_effort_charged():
    env = gym.make("leg_env/PlanarLegBalance-v1").unwrapped
    assert env.config.contact == "unilateral" and env.config.reset_noise_scale == 0.05 and env.config.mu == 0.5
    assert env.observation_space.shape == (20,)
    stance = gym.make("leg_env/PlanarLegStance-v0", **BALANCE_V1)
    a = actions(50, 1)[:, 0]
    env = gym.make("leg_env/PlanarLegBalance-v1")
    assert data_equivalence(env.reset(seed=3), stance.reset(seed=3), exact=True)
    for x in a:
        assert data_equivalence(env.step(x), stance.step(x), exact=True)


@pytest.mark.parametrize("env_id", NEW_IDS)
def test_gymnasium_env_checker(env_id):
    env = gym.make(env_id, render_mode="rgb_array").unwrapped
    check_env(env, skip_render_check=False)


@pytest.mark.sb3
@pytest.mark.parametrize("env_id", NEW_IDS)
def test_sb3_env_checker(env_id):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    sb3_check_env(gym.make(env_id), warn=True)


@pytest.mark.parametrize("env_id", NEW_IDS)
def test_same_seed_same_rollout_also_after_later_resets(env_id):
    runs = []
    for _ in range(2):
        env = gym.make(env_id, max_episode_steps=MAX_STEPS, **KWARGS[env_id])
        out = [env.reset(seed=SEED)]
        for a in actions(STEPS, 1)[:, 0]:
            step = env.step(a)
            out.append(step)
            if step[2] or step[3]:
                out.append(env.reset())
        runs.append(out)
    assert data_equivalence(runs[0], runs[1], exact=True)


@pytest.mark.parametrize("env_id", NEW_IDS)
def test_pickle_round_trips_arguments_and_state(env_id):
    env = gym.make(env_id, **KWARGS[env_id]).unwrapped
    env.reset(seed=SEED)
    for a in actions(30, 1)[:, 0]:
        env.step(a)
    copy = pickle.loads(pickle.dumps(env))
    assert copy.config == env.config and copy.params == env.params and copy.task.name == env.task.name
    for a in actions(40, 1, seed=2)[:, 0]:
        assert data_equivalence(env.step(a), copy.step(a), exact=True)
    venv = gym.make_vec(env_id, num_envs=3, **KWARGS[env_id])
    venv.reset(seed=SEED)
    vcopy = pickle.loads(pickle.dumps(venv))
    for a in actions(30, 3, seed=4):
        assert data_equivalence(venv.step(a), vcopy.step(a), exact=True)


def _as_sync_info(info: dict, reward_keys) -> dict:
    """Our info as SyncVectorEnv shapes it: no reward terms on a step where no sub-env stepped, and strings
    (``contact_mode``) in object arrays (ours are numpy string arrays; the values are compared exactly)."""
    if "_reward_alive" in info and not info["_reward_alive"].any():
        info = {k: v for k, v in info.items() if k.lstrip("_") not in reward_keys}
    return _strings_as_objects(info)


def _strings_as_objects(x):
    """String arrays as object arrays, with None where their mask says no value (as SyncVectorEnv fills
    them; the native batch has ``""`` there, kept for bitwise v0)."""
    if isinstance(x, dict):
        out = {}
        for k, v in x.items():
            v = _strings_as_objects(v)
            if isinstance(v, np.ndarray) and v.dtype == object and f"_{k}" in x and k != "final_obs":
                v = v.copy()
                v[~x[f"_{k}"]] = None
            out[k] = v
        return out
    if isinstance(x, np.ndarray) and x.dtype.kind == "U":
        return x.astype(object)
    return x


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("env_id", NEW_IDS)
def test_native_batch_equals_sync_vector_env_bit_for_bit(env_id, mode):
    """Observations, rewards, flags and the whole info of the native batch equal SyncVectorEnv's over single envs."""
    kwargs = KWARGS[env_id]
    ours = gym.make_vec(env_id, num_envs=NUM_ENVS, autoreset_mode=mode, max_episode_steps=MAX_STEPS, **kwargs)
    sync = gym.make_vec(
        env_id, num_envs=NUM_ENVS, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode},
        max_episode_steps=MAX_STEPS, **kwargs,
    )  # fmt: skip
    obs, info = ours.reset(seed=SEED)
    assert data_equivalence((obs, _strings_as_objects(info)), sync.reset(seed=SEED), exact=True)
    ended = 0
    pushed = 0
    for t, a in enumerate(actions(STEPS, NUM_ENVS, seed=1)):
        step_ours, step_sync = ours.step(a), sync.step(a)
        step_ours = (*step_ours[:4], _as_sync_info(step_ours[4], ours.unwrapped.reward_keys))
        for name, x, y in zip(("obs", "reward", "terminated", "truncated", "info"), step_ours, step_sync):
            assert data_equivalence(x, y, exact=True), f"step {t} {name} differ:\n{x}\n{y}"
        ended += int(np.sum(step_ours[2] | step_ours[3]))
        if "push_force" in step_ours[4]:
            pushed += int(np.sum(step_ours[4]["push_force"] != 0.0))
    assert ended >= 4
    if env_id == "leg_env/PlanarLegPush-v2":
        assert pushed >= 10


_THREADED_SCRIPT = """
import sys
import numpy as np, gymnasium as gym, leg_env
from gymnasium.utils.env_checker import data_equivalence
sys.path.insert(0, "tests")
from test_tasks import KWARGS, NEW_IDS, SEED, actions
for env_id in NEW_IDS:
    runs = []
    for threads in (1, 2):
        envs = gym.make_vec(env_id, num_envs=64, num_threads=threads, **KWARGS[env_id])
        out = [envs.reset(seed=SEED)]
        out += [envs.step(x) for x in actions(60, 64, seed=3)]
        runs.append(out)
    print(env_id, "SAME" if data_equivalence(runs[0], runs[1], exact=True) else "DIFFERENT")
"""


def test_threaded_batch_is_bitwise_the_serial_one():
    """Two numba threads split the physics of the batch (a process with a pool of 2): every output of every
    new task equals the one-thread run exactly."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_NUM_THREADS="2")
    out = subprocess.run([sys.executable, "-c", _THREADED_SCRIPT], env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    lines = [line for line in out.stdout.splitlines() if line.startswith("leg_env/")]
    assert lines == [f"{env_id} SAME" for env_id in NEW_IDS], out.stdout


@pytest.mark.sb3
@pytest.mark.parametrize("env_id", NEW_IDS)
def test_sb3_adapter_contract(env_id):
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from leg_env.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env(NUM_ENVS, seed=SEED, env_id=env_id, max_episode_steps=MAX_STEPS, **KWARGS[env_id])
    task = venv.env.task
    obs = venv.reset()
    assert obs.shape == (NUM_ENVS,) + venv.observation_space.shape
    assert set(venv.reset_infos[0]) == set(venv.env.state_keys)
    wrapped = VecNormalize(VecMonitor(make_sb3_vec_env(NUM_ENVS, seed=SEED, env_id=env_id, **KWARGS[env_id])))
    wrapped.reset()
    done_seen = 0
    for a in actions(STEPS, NUM_ENVS, seed=6):
        obs, rewards, dones, infos = venv.step(a)
        wrapped.step(a)
        assert rewards.dtype == np.float32 and dones.dtype == np.bool_ and len(infos) == NUM_ENVS
        for i, info in enumerate(infos):
            assert set(task.reward_keys) <= set(info) and set(task.info_names) <= set(info)
            assert np.isclose(sum(info[k] for k in task.reward_keys), rewards[i], rtol=1e-6, atol=1e-5)
            if dones[i]:
                done_seen += 1
                assert info["terminal_observation"].shape == venv.observation_space.shape
    assert done_seen >= 4
    bad = {"ctrl_cost_weight": -1.0, "com_weight": "1", "command_range": (0.2, 0.1)}
    field = {NEW_IDS[0]: "ctrl_cost_weight", PUSH: "com_weight", HOP: "command_range"}[env_id]
    with pytest.raises(ValueError, match=field):  # ArgumentTypeError is a ValueError too
        make_sb3_vec_env(2, env_id=env_id, **{field: bad[field]})


def test_push_schedule_follows_the_config_and_is_not_observed():
    """The schedule drawn at reset (the task's state columns): first push at 0.8-1.2 s, then every 2-3 s,
    0.1 s long, 20-150 N of either sign; the env applies exactly that force on those steps, and nothing
    of it is in the observation."""
    env = gym.make("leg_env/PlanarLegPush-v2").unwrapped
    signs = []
    for seed in range(40):
        env.reset(seed=seed)
        starts, forces = env._state["push_start"][0], env._state["push_force"][0]
        assert np.all(starts == np.rint(starts)) and 80 <= starts[0] <= 120
        assert np.all((np.diff(starts) >= 200) & (np.diff(starts) <= 300))
        assert np.all((np.abs(forces) >= 20.0) & (np.abs(forces) <= 150.0))
        signs += np.sign(forces).tolist()
    assert 0.3 < np.mean(np.array(signs) > 0) < 0.7
    env = gym.make("leg_env/PlanarLegPush-v2", reset_noise_scale=0.0).unwrapped  # stands still until pushed
    env.reset(seed=3)
    first, force = int(env._state["push_start"][0, 0]), env._state["push_force"][0, 0]
    hold = (env.nominal.tau / np.asarray(env.config.torque_limit)).astype(np.float32)
    seen = []
    for _ in range(first + 10):
        obs, _, term, _, info = env.step(hold)
        seen.append(info["push_force"])
        assert obs.shape == (21,)
    assert seen[:first] == [0.0] * first and seen[first:] == [force] * 10


def test_quiet_episodes_have_no_push_and_leave_the_pushed_episodes_as_drawn():
    """``quiet_share``: that share of the episodes (one more uniform, the last of the reset's draws) has no push at
    all; the other episodes' schedules are the ones drawn without quiet episodes, and without them (the default)
    the env draws what it always drew."""
    plain = gym.make("leg_env/PlanarLegPush-v2").unwrapped
    mixed = gym.make("leg_env/PlanarLegPush-v2", quiet_share=0.3).unwrapped
    assert plain.task.draws(plain.config) == 24 and mixed.task.draws(mixed.config) == 25
    quiet = []
    for seed in range(300):
        plain.reset(seed=seed)
        mixed.reset(seed=seed)
        assert not plain._state["quiet"][0]
        quiet.append(bool(mixed._state["quiet"][0]))
        if quiet[-1]:
            assert np.all(mixed._state["push_start"][0] >= 2**30)
        else:
            assert np.array_equal(mixed._state["push_start"][0], plain._state["push_start"][0])
            assert np.array_equal(mixed._state["push_force"][0], plain._state["push_force"][0])
    assert abs(np.mean(quiet) - 0.3) < 4 * np.sqrt(0.3 * 0.7 / 300)  # a binomial share, 4 standard deviations
    env = gym.make("leg_env/PlanarLegPush-v2", quiet_share=1.0, first_push=(0.01, 0.02), push_interval=(0.1, 0.1)).unwrapped
    env.reset(seed=2)
    hold = (env.nominal.tau / np.asarray(env.config.torque_limit)).astype(np.float32)
    assert all(env.step(hold)[4]["push_force"] == 0.0 for _ in range(300))


def test_quiet_scales_charge_flight_and_the_actions_change_in_quiet_episodes_only():
    """In a quiet episode ``reward_unilateral`` is ``-quiet_flight_scale unilateral_weight flight_time / dt`` and
    ``reward_action_rate`` ``quiet_change_scale`` times the task's charge; the motion and every other term are the
    unscaled episode's. In an episode with pushes the scales change nothing."""
    rng = np.random.default_rng(4)
    acts = np.repeat(rng.uniform(-1.0, 1.0, size=(12, 2)), 5, axis=0).astype(np.float32)  # held 5 steps: hops
    for share, scaled in ((1.0, True), (0.0, False)):
        kw = dict(quiet_share=share, action_change_weight=0.1)
        base = gym.make("leg_env/PlanarLegPush-v2", **kw).unwrapped
        env = gym.make("leg_env/PlanarLegPush-v2", quiet_flight_scale=6.0, quiet_change_scale=3.0, **kw).unwrapped
        base.reset(seed=9)
        env.reset(seed=9)
        flight = 0.0
        for a in acts:
            o0, r0, t0, _, i0 = base.step(a)
            o1, r1, t1, _, i1 = env.step(a)
            assert np.array_equal(o0, o1) and t0 == t1
            flight += i1["flight_time"]
            k_flight, k_change = (6.0, 3.0) if scaled else (1.0, 1.0)
            expected = -k_flight * env.config.unilateral_weight * i1["flight_time"] / env.dt
            assert i1["reward_unilateral"] == pytest.approx(expected, rel=1e-12, abs=0.0)
            assert i1["reward_action_rate"] == pytest.approx(k_change * i0["reward_action_rate"], rel=1e-12, abs=0.0)
            for name in set(env.task.reward_keys) - {"reward_unilateral", "reward_action_rate"}:
                assert i1[name] == i0[name]
            if t0:
                break
        assert flight > 0.0  # the episode did leave the ground


def test_push_moves_the_robot_as_the_momentum_balance_says():
    """In the env: per step, m (v_com(end) - v_com(start)) = dt (contact_force + (push, 0) - (0, m g)) + impulse."""
    env = gym.make("leg_env/PlanarLegPush-v2", **FAST_PUSHES).unwrapped
    env.reset(seed=1)
    p = env.params
    m = p.total_mass
    hold = (env.nominal.tau / np.asarray(env.config.torque_limit)).astype(np.float32)
    pushed = 0
    for _ in range(60):
        q0, qd0, _ = env.state
        obs, r, term, trunc, info = env.step(hold)
        if info["numerical_failure"]:
            break
        q1, qd1, _ = env.state
        dP = m * (_v_com(q1, qd1, p) - _v_com(q0, qd0, p))
        expected = env.dt * (info["contact_force"] + np.array([info["push_force"], -m * p.g])) + info.get("impulse", 0.0)
        assert np.abs(dP - expected).max() < 1e-6, (dP, expected, info["push_force"])
        assert info["work_push"] == pytest.approx(info["push_force"] * (q1[0] - q0[0]), abs=1e-12)
        pushed += info["push_force"] != 0.0
        if term:
            break
    assert pushed >= 5


def _v_com(q, qd, p):
    m = p.total_mass
    a, b = p.m1 * p.c1 + p.m2 * p.l1, p.m2 * p.c2
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    w1 = qd[2] + qd[3]
    w2 = w1 + qd[4]
    return np.array([qd[0] - (a * np.sin(th1) * w1 + b * np.sin(th2) * w2) / m, qd[1] + (a * np.cos(th1) * w1 + b * np.cos(th2) * w2) / m])


def test_push_energy_balance_over_an_episode():
    env = gym.make("leg_env/PlanarLegPush-v2", **FAST_PUSHES).unwrapped
    _, info = env.reset(seed=2)
    e0 = info["energy"]
    booked = 0.0
    hold = (env.nominal.tau / np.asarray(env.config.torque_limit)).astype(np.float32)
    for a in actions(80, 1, seed=9)[:, 0] * 0.3 + hold:
        _, _, term, _, info = env.step(a)
        booked += info["work_actuators"] + info["work_push"] - info["dissipation_slip"] - info["dissipation_impacts"]
        if term or info["numerical_failure"]:
            break
    assert abs(info["energy"] - e0 - booked) < 1e-5 * (1.0 + abs(e0))


def test_hop_reward_peaks_at_the_commanded_apex_on_scripted_hops():
    """Ballistic hops (the robot thrown straight up, its posture held; flights longer than ``min_flight``) whose COM
    apex is ``rise`` above standing: from
    the step that lands the hop, observation entry 21 is ``rise`` and the height term is its weight times
    ``exp(-(e / height_scale)^2) + exp(-(e / height_scale_fine)^2)``, ``e = rise - command``: largest at the
    command, where it is twice the weight. Before the landing nothing is paid."""
    from leg_env.tasks.base import Obs

    env = gym.make("leg_env/PlanarLegHop-v4", reset_noise_scale=0.0).unwrapped
    obs, info = env.reset(seed=4)
    command = env._state["command"][0]
    assert info["command"] == command
    assert obs[Obs.command] == np.float32(command) and 0.05 <= command <= 0.15
    cfg, p = env.config, env.params
    hold = (env.nominal.tau / np.asarray(cfg.torque_limit)).astype(np.float32)
    lift = 0.005  # the foot 5 mm above the ground
    rises = np.r_[np.linspace(0.04, 0.25, 43), command]  # flights of 0.17 s or more: hops (min_flight 0.15 s)
    rewards = []
    for rise in rises:
        q = env.nominal.q.copy()
        q[1] += lift
        qd = np.zeros(5)
        qd[1] = np.sqrt(2.0 * p.g * (rise - lift))  # apex: y_stand + lift + v^2 / (2 g) = y_stand + rise
        landing = int((qd[1] + np.sqrt(qd[1] ** 2 + 2.0 * p.g * lift)) / p.g / env.dt)  # the step the foot lands in
        obs, _ = env.reset(seed=4, options={"qpos": q, "qvel": qd})
        assert obs[Obs.contact] == 0.0  # in flight
        for k in range(200):  # no torque in flight (the joints stay still); the posture held from the landing on
            obs, _, term, _, info = env.step(hold if k >= landing else np.zeros(2, dtype=np.float32))
            assert not term
            if info["contact_mode"] != "flight":
                break
            assert info["reward_height"] == 0.0 and obs[Obs.last_apex] == 0.0  # no hop landed yet
        assert info["contact_mode"] != "flight"
        assert obs[Obs.last_apex] == pytest.approx(rise, abs=1e-6)
        e = rise - command
        expected = cfg.height_weight * (np.exp(-((e / cfg.height_scale) ** 2)) + np.exp(-((e / cfg.height_scale_fine) ** 2)))
        assert info["reward_height"] == pytest.approx(expected, rel=1e-6, abs=1e-9), (rise, command)
        rewards.append(info["reward_height"])
    rewards = np.array(rewards)
    assert rewards[-1] == pytest.approx(2.0 * cfg.height_weight, rel=1e-9)  # the peak, at the command
    assert np.all(rewards[:-1] <= rewards[-1])
    assert abs(rises[np.argmax(rewards[:-1])] - command) <= 0.0025


def _throw(env) -> dict:
    """Reset options that throw the robot up at 1 m/s from its nominal posture."""
    q, qd = env.nominal.q.copy(), np.zeros(5)
    q[1] += 0.001
    qd[1] = 1.0
    return {"qpos": q, "qvel": qd}


def _probe_action(seed: int, k: int, random_action, obs, hopper, hold, thrown) -> np.ndarray:
    """The action at step ``k`` of the hop reward tests' episode ``seed``: the hopper's on seed 7; the posture held
    after the throw and for the first 1.5 s of odd seeds; else random torques with, now and then, a kick of the knee."""
    if seed == 7:
        return hopper.predict(obs)[0].astype(np.float32)
    if thrown is not None or seed % 2 and k < 150:
        return hold
    return random_action if k % 60 < 30 else np.float32([0.0, -1.0]) if k % 60 < 36 else np.float32([0.0, 1.0])


def test_hop_pays_the_last_landed_hops_apex_at_every_step_while_hopping():
    """The hop's reward and observation, modelled step by step from the contact modes, flight times, the COM and the
    state, over random torques with knee kicks, standing, a throw, and the model-based hopper (``_probe_action``).

    The motion is the unilateral balance's (``PlanarLegStance-v0`` on the unilateral ground with the hop's effort
    settings, the same posture noise: the hop draws its command after it): the same first 18 observation entries and
    the same last action after the hop's own (entries 22-23), ends, alive bonus, control, action-change and power
    charges. Entry 19 is the COM's x from its start; entry 20 the ground time, since the end of the last flight of at
    least ``min_flight`` (or the start); entry 21 the apex rise above standing of the last hop the robot landed (0
    before the first). The height term is its weight times the sum of the two Gaussian kernels (5 cm, 1 cm) of that
    hop's apex error (the apex of its arc, ``y + y'^2 / 2g`` in flight), paid while the ground time is at most
    ``max_ground_time``, and never on a step that falls; flights shorter than a hop change nothing. The alive
    bonus stops with it. The other terms are their formulas: ``-30 dx^2``, ``-10 th_b^2``, ``-0.5 (|P| / m)^2``,
    ``-slip_distance / dt``; ``reward_limit`` is 0."""
    from leg_env.tasks.base import Obs
    from policies.hopper import HopperController

    registered = gym.make("leg_env/PlanarLegHop-v4")
    cfg = registered.unwrapped.config
    assert cfg.max_ground_time == 1.0 and cfg.min_flight == 0.15 and cfg.height_scale_fine == 0.01
    assert (cfg.drift_com_weight, cfg.tilt_weight, cfg.impact_weight, cfg.slip_weight) == (30.0, 10.0, 0.5, 1.0)
    assert registered.observation_space.shape == (24,)
    # a ground time of 0.3 s at most, shorter than the hopper's stance: the term stops and starts again within an
    # episode; commands of 10 cm or more, whose hops by the hopper fly longer than min_flight (0.15 s)
    hop = gym.make("leg_env/PlanarLegHop-v4", reset_noise_scale=0.002, max_ground_time=0.3, command_range=(0.10, 0.15)).unwrapped
    effort = {k: getattr(cfg, k) for k in ("ctrl_cost_weight", "action_rate_weight", "action_change_weight", "power_weight", "observe_action")}
    stance = gym.make("leg_env/PlanarLegStance-v0", contact="unilateral", reset_noise_scale=0.002, **effort).unwrapped
    hold = (hop.nominal.tau / np.asarray(hop.config.torque_limit)).astype(np.float32)
    cfg, p = hop.config, hop.params
    m = p.total_mass
    y_stand = dyn.com_position(hop.nominal.q, p)[1]
    hopper = HopperController(p, cfg)
    paid = stopped = short_flights = hops = unpaid = 0
    for seed in range(8):
        thrown = _throw(hop) if seed == 6 else None
        o0, _ = stance.reset(seed=seed, options=thrown)
        o3, i3 = hop.reset(seed=seed, options=thrown)
        hopper.reset()
        x0 = i3["com_position"][0]
        run, ground, arc, held, arc_rise, rise = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        assert np.array_equal(o0[:18], o3[:18]) and np.array_equal(o0[18:], o3[22:]) and o3[Obs.last_apex] == 0.0 and o3[Obs.com_drift] == 0.0 and o3[Obs.ground_time] == 0.0
        for k, a in enumerate(actions(300, 1, seed=seed)[:, 0]):
            a = _probe_action(seed, k, a, o3, hopper, hold, thrown)
            o0, _, t0, _, i0 = stance.step(a)
            o3, r3, t3, _, i3 = hop.step(a)
            assert np.array_equal(o0[:18], o3[:18]) and np.array_equal(o0[18:], o3[22:]) and t0 == t3
            flight = i3["contact_mode"] == "flight"
            landed = not flight and run > 0.0
            length = run + i3["flight_time"]
            if flight:
                (y, vy), command = (i3["com_position"][1], i3["com_velocity"][1]), i3["command"]
                err = y + vy * vy / (2.0 * p.g) - (y_stand + command)
                arc = np.exp(-((err / cfg.height_scale) ** 2)) + np.exp(-((err / cfg.height_scale_fine) ** 2))
                arc_rise = err + command  # the arc's apex above standing
            if landed and length >= cfg.min_flight:
                held, rise, hops = arc, arc_rise, hops + 1
            assert o3[Obs.last_apex] == pytest.approx(np.float32(rise), rel=1e-6, abs=1e-7)
            short_flights += bool(landed and length < cfg.min_flight)
            run = run + i3["flight_time"] if flight else 0.0
            ground = 0.0 if run >= cfg.min_flight else ground + hop.dt
            assert i3["ground_time"] == ground and o3[Obs.ground_time] == np.float32(ground)
            dx = i3["com_position"][0] - x0
            assert o3[Obs.com_drift] == np.float32(dx)
            expected = 0.0 if t3 or ground > cfg.max_ground_time else cfg.height_weight * held
            assert i3["reward_height"] == pytest.approx(expected, rel=1e-9, abs=1e-12), (seed, k)
            assert i3["reward_alive"] == (i0["reward_alive"] if ground <= cfg.max_ground_time else 0.0)
            assert all(i3[key] == i0[key] for key in ("reward_ctrl", "reward_action_rate", "reward_power")) and i3["reward_limit"] == 0.0
            th_b = hop.state[0][2]
            P = np.asarray(i3["impulse"])
            assert i3["reward_drift"] == pytest.approx(-cfg.drift_com_weight * dx * dx, rel=1e-9, abs=1e-15)
            assert i3["reward_tilt"] == pytest.approx(-cfg.tilt_weight * th_b * th_b, rel=1e-9, abs=1e-15)
            assert i3["reward_impact"] == pytest.approx(-cfg.impact_weight * (P @ P) / m**2, rel=1e-9, abs=1e-15)
            assert i3["reward_slip"] == pytest.approx(-cfg.slip_weight * i3["slip_distance"] / hop.dt, rel=1e-9, abs=1e-15)
            assert r3 == pytest.approx(sum(i3[key] for key in hop.task.reward_keys), rel=1e-6, abs=1e-6)
            paid += expected > 0.0
            stopped += held > 0.0 and ground > cfg.max_ground_time and not t3
            unpaid += i0["reward_alive"] > 0.0 and i3["reward_alive"] == 0.0
            if t0:
                break
    assert hops >= 4 and paid > 100 and stopped > 0 and short_flights > 0 and unpaid > 0


def test_hop_command_schedule_changes_the_command_every_period_and_judges_each_hop_by_its_own():
    """With ``command_period`` the command is drawn at the reset as before, and ``COMMANDS_AHEAD`` more after it
    from the same generator: each holds for ``command_steps`` control steps, then the next takes over from the
    next step (the observation and ``info["command"]`` show it after the step that ends the last one's period),
    and after the last the command holds. Up to the first change the episode is the registered v3's, step for
    step. The height term of a flight is the kernel of its apex error against the command in force during the
    step (modelled here as in the v3 test above, over the model-based hopper). The registered v3 has no schedule."""
    from leg_env.tasks.hop import COMMANDS_AHEAD, command_steps
    from policies.hopper import HopperController

    assert gym.make("leg_env/PlanarLegHop-v4").unwrapped.config.command_period == float("inf")
    plain = gym.make("leg_env/PlanarLegHop-v4").unwrapped
    env = gym.make("leg_env/PlanarLegHop-v4", command_period=0.5).unwrapped
    cfg, period = env.config, command_steps(env.config)
    assert period == 50 and command_steps(plain.config) == 0
    y_stand = dyn.com_position(env.nominal.q, env.params)[1]
    hopper = HopperController(env.params, env.config)
    changes = hops = 0
    for seed in range(3):
        o, info = env.reset(seed=seed)
        op, infop = plain.reset(seed=seed)
        assert np.array_equal(o, op) and info["command"] == infop["command"]
        lo, hi = cfg.command_range
        ahead = env._state["next_commands"][0].copy()
        assert np.all((lo <= ahead) & (ahead <= hi)) and len(set(ahead.tolist())) == COMMANDS_AHEAD
        hopper.reset()
        command, run, held, arc = info["command"], 0.0, 0.0, 0.0
        for k in range(400):
            a = hopper.predict(o)[0].astype(np.float32)
            o, _, terminated, _, info = env.step(a)
            if k < period:
                op, _, tp, _, infop = plain.step(a)
                same = np.arange(o.size) != 18 if k == period - 1 else slice(None)  # the command shown changes after the period's last step
                assert np.array_equal(o[same], op[same]) and tp == terminated and info["reward_height"] == infop["reward_height"]
            flight = info["contact_mode"] == "flight"
            landed = not flight and run > 0.0
            length = run + info["flight_time"]
            if flight:  # the arc's apex against the command this step was taken under
                y, vy = info["com_position"][1], info["com_velocity"][1]
                err = y + vy * vy / (2.0 * env.params.g) - (y_stand + command)
                arc = np.exp(-((err / cfg.height_scale) ** 2)) + np.exp(-((err / cfg.height_scale_fine) ** 2))
            if landed and length >= cfg.min_flight:
                held, hops = arc, hops + 1
            run = run + info["flight_time"] if flight else 0.0
            if not terminated and info["ground_time"] <= cfg.max_ground_time:
                assert info["reward_height"] == pytest.approx(cfg.height_weight * held, rel=1e-9, abs=1e-12), (seed, k)
            turn = (k + 1) // period  # commands taken up after this step
            expected = ahead[turn - 1] if 1 <= turn <= COMMANDS_AHEAD else (ahead[-1] if turn > COMMANDS_AHEAD else command)
            changes += info["command"] != command
            assert info["command"] == expected and o[18] == np.float32(expected), (seed, k)
            command = info["command"]
            if terminated:
                break
    assert changes >= 2 * COMMANDS_AHEAD and hops >= 10
    for bad in (0.0, -1.0, 0.001, float("nan")):
        with pytest.raises(ValueError, match="command_period"):
            gym.make("leg_env/PlanarLegHop-v4", command_period=bad)


def test_hop_prefers_hopping_to_the_command_to_bouncing():
    """On the same episodes the model-based hopper (hops to the command) earns the height term several times over
    what a fixed bounce of low hops earns: the bounce's flights, however many, are paid no more than its apex."""
    results = {}
    for name in ("hopper", "bounce"):
        env = gym.make(HOP).unwrapped
        from policies.hopper import HopperController

        hopper = HopperController(env.params, env.config)
        total = 0.0
        for seed in range(3):
            obs, _ = env.reset(seed=seed, options=None)
            hopper.reset()
            for k in range(400):
                if name == "hopper":
                    a = hopper.predict(obs)[0]
                else:  # the knee kicked out and back every 80 ms: short, low hops
                    a = np.float32([0.0, 1.0]) if k % 8 < 3 else np.float32([0.0, -0.6])
                obs, _, terminated, _, info = env.step(a)
                total += info["reward_height"]
                if terminated:
                    break
        results[name] = total
    assert results["hopper"] > 3.0 * results["bounce"], results


def test_hop_with_min_flight_zero_pays_each_landed_flight_from_its_landing():
    """With ``min_flight=0`` every flight is a hop: the held apex (entry 21) and the height term change only at the
    step that lands a flight."""
    from leg_env.tasks.base import Obs
    from policies.hopper import HopperController

    env = gym.make("leg_env/PlanarLegHop-v4", min_flight=0.0).unwrapped
    hopper = HopperController(env.params, env.config)
    obs, _ = env.reset(seed=3)
    hopper.reset()
    changes, was_flight, apex = [], False, 0.0
    for _ in range(300):
        obs, _, terminated, _, info = env.step(hopper.predict(obs)[0])
        flight = info["contact_mode"] == "flight"
        if obs[Obs.last_apex] != apex:
            changes.append(was_flight and not flight)
            apex = obs[Obs.last_apex]
        assert (info["reward_height"] > 0.0) == (apex != 0.0 and info["ground_time"] <= env.config.max_ground_time)
        was_flight = flight
        if terminated:
            break
    assert len(changes) >= 2 and all(changes)


def test_hop_pays_nothing_for_standing_and_the_alive_bonus_for_a_second():
    """Holding the nominal posture (no hop) earns no height term, and the alive bonus only for the first second on
    the ground (``max_ground_time``)."""
    env = gym.make("leg_env/PlanarLegHop-v4", reset_noise_scale=0.0, command_range=(0.0, 0.0)).unwrapped
    env.reset(seed=0)
    hold = (env.nominal.tau / np.asarray(env.config.torque_limit)).astype(np.float32)
    steps = [env.step(hold) for _ in range(150)]
    assert not any(s[2] for s in steps)  # it stands
    assert sum(s[4]["reward_height"] for s in steps) == 0.0
    assert 99.0 <= sum(s[4]["reward_alive"] for s in steps) <= 100.0


def test_hop_landing_impulse_is_charged():
    env = gym.make("leg_env/PlanarLegHop-v4", reset_noise_scale=0.0).unwrapped
    q = env.nominal.q.copy()
    q[1] += 0.001
    qd = np.zeros(5)
    qd[1] = -1.0  # landing at 1 m/s
    env.reset(seed=0, options={"qpos": q, "qvel": qd})
    hold = (env.nominal.tau / np.asarray(env.config.torque_limit)).astype(np.float32)
    _, _, _, _, info = env.step(hold)
    P = info["impulse"]
    assert P[1] > 0.0
    m = env.params.total_mass
    assert info["reward_impact"] == pytest.approx(-env.config.impact_weight * (P @ P) / m**2, rel=1e-12)


def test_hop_near_drift_charge_is_capped_and_changes_nothing_else():
    """``drift_near_weight = w`` with ``drift_near_cap = c`` adds ``-c (1 - exp(-w dx^2 / c))`` to the quadratic drift
    term, ``dx`` the COM's x from its start (read from the quadratic charge of the same episode, ``-w_0 dx^2``): about
    ``-w dx^2`` near the start, never below ``-c``; with ``c`` infinite, ``-w dx^2``. The motion, the observation and
    every other term are those of the registered task."""
    quadratic = gym.make("leg_env/PlanarLegHop-v4").unwrapped
    assert quadratic.config.drift_near_weight == 0.0 and quadratic.config.drift_near_cap == float("inf")
    w0, w, cap = quadratic.config.drift_com_weight, 390.0, 1.0
    capped = gym.make("leg_env/PlanarLegHop-v4", drift_near_weight=w, drift_near_cap=cap).unwrapped
    uncapped = gym.make("leg_env/PlanarLegHop-v4", drift_near_weight=w).unwrapped
    q, qd = quadratic.nominal.q.copy(), np.zeros(5)
    q[1] += 0.001
    qd[0], qd[1] = 1.5, 1.0  # thrown up and forward: the COM leaves its start far enough to saturate the charge
    hold = (quadratic.nominal.tau / np.asarray(quadratic.config.torque_limit)).astype(np.float32)
    far = near = 0
    for options in ({"qpos": q, "qvel": qd}, None):  # the throw, then standing from a noisy start
        for env in (quadratic, capped, uncapped):
            env.reset(seed=3, options=options)
        for k in range(200):
            o0, r0, t0, _, i0 = quadratic.step(hold)
            o1, r1, t1, _, i1 = capped.step(hold)
            o2, r2, t2, _, i2 = uncapped.step(hold)
            assert np.array_equal(o0, o1) and np.array_equal(o0, o2) and t0 == t1 == t2
            assert all(i0[key] == i1[key] == i2[key] for key in i0 if key.startswith("reward_") and key != "reward_drift")
            assert r1 - i1["reward_drift"] == pytest.approx(r0 - i0["reward_drift"], rel=1e-12, abs=1e-12)
            dx2 = -i0["reward_drift"] / w0
            near_charge = i1["reward_drift"] - i0["reward_drift"]
            assert near_charge == pytest.approx(cap * np.expm1(-w * dx2 / cap), rel=1e-9, abs=1e-14)
            assert -cap - 1e-15 <= near_charge <= 0.0
            assert i2["reward_drift"] == pytest.approx(-(w0 + w) * dx2, rel=1e-12, abs=1e-15)
            if w * dx2 < 0.02 * cap:
                near += 1
                assert near_charge == pytest.approx(-w * dx2, rel=0.011, abs=1e-15)
            far += w * dx2 > 3.0 * cap  # within 5% of the cap
            if t0:
                break
    assert far > 0 and near > 0
    for field, value in (("drift_near_cap", 0.0), ("drift_near_weight", -1.0)):
        with pytest.raises(ValueError, match=field):
            gym.make("leg_env/PlanarLegHop-v4", **{field: value})


def test_hop_limit_charge_is_the_squared_depth_inside_the_ranges_margins_and_changes_nothing_else():
    """With ``limit_weight = w`` the term ``reward_limit`` is ``-w`` times the squared depth of the hip and of the knee
    inside the last ``limit_margin`` of their ranges (0 elsewhere), from the state after the step; registered, it is
    0. The motion, the observation and every other term are those of the registered task. Random torques with knee
    kicks, which take the knee to both ends of its range."""
    plain = gym.make("leg_env/PlanarLegHop-v4").unwrapped
    assert plain.config.limit_weight == 0.0
    w, margin = 400.0, 0.2
    charged = gym.make("leg_env/PlanarLegHop-v4", limit_weight=w, limit_margin=margin).unwrapped
    cfg = plain.config
    inside, outside = set(), 0
    for seed in range(6):
        for env in (plain, charged):
            env.reset(seed=seed)
        for k, a in enumerate(actions(300, 1, seed=seed)[:, 0]):
            a = a if k % 40 < 25 else np.float32([0.0, -1.0]) if k % 40 < 32 else np.float32([1.0, 1.0])
            o0, r0, t0, _, i0 = plain.step(a)
            o1, r1, t1, _, i1 = charged.step(a)
            assert np.array_equal(o0, o1) and t0 == t1 and i0["reward_limit"] == 0.0
            assert all(i0[key] == i1[key] for key in i0 if key.startswith("reward_") and key != "reward_limit")
            q = charged.state[0]
            expected = 0.0
            for j, (lo, hi) in ((3, cfg.hip_range), (4, cfg.knee_range)):
                depth = max(lo + margin - q[j], q[j] - (hi - margin), 0.0)
                expected += depth * depth
                if depth > 0.0:
                    inside.add((j, q[j] > 0.5 * (lo + hi)))
            outside += expected == 0.0
            assert i1["reward_limit"] == pytest.approx(-w * expected, rel=1e-12, abs=1e-15)
            assert r1 == pytest.approx(r0 + i1["reward_limit"], rel=1e-12, abs=1e-12)
            if t0:
                break
    assert {(4, False), (4, True)} <= inside and outside > 0  # the knee in both margins, and steps in neither
    with pytest.raises(ValueError, match="limit_margin"):
        gym.make("leg_env/PlanarLegHop-v4", limit_margin=-0.1)


def test_push_reward_charges_the_com_leaving_the_start():
    env = gym.make("leg_env/PlanarLegPush-v2", com_weight=3.0, reset_noise_scale=0.0).unwrapped
    env.reset(seed=0)
    q = env.nominal.q.copy()
    q[0] += 0.2  # the base (and COM) 0.2 m forward of the start, the foot with it
    _, info = env.reset(seed=0, options={"qpos": q})
    obs, r, *_, info = env.step((env.nominal.tau / np.asarray(env.config.torque_limit)).astype(np.float32))
    # the reference is the start of this episode: a small step later the COM term is tiny
    assert -1e-3 < info["reward_com"] <= 0.0
    assert r == pytest.approx(sum(info[k] for k in env.task.reward_keys), abs=0.0)


def test_push_observes_the_com_from_its_start_and_charges_it():
    """Entry 18 is the whole-body COM's x from the episode's start, what the COM term charges: 0 at the start,
    ``info["com_position"][0] - x0`` after every step, single and batched, through pushes and hops; the other 18
    entries are the unilateral balance's (the same motion under the same actions, without the pushes' 0 N), and
    ``reward_com = -com_weight dx^2``."""
    from leg_env.tasks.push import OBS_COM_DRIFT

    assert OBS_COM_DRIFT == 18
    kw = dict(FAST_PUSHES, reset_noise_scale=0.05)
    env = gym.make("leg_env/PlanarLegPush-v2", **kw)
    quiet = gym.make("leg_env/PlanarLegPush-v2", **dict(kw, push_force=(0.0, 0.0)))
    stance = gym.make("leg_env/PlanarLegStance-v0", contact="unilateral", reset_noise_scale=0.05)
    assert env.observation_space.shape == (21,)
    assert env.observation_space.low[18] == -np.inf and env.observation_space.high[18] == np.inf
    acts = actions(STEPS, 1, seed=3)
    for seed in (0, 7):
        (o1, i1), (oq, _), (os_, _) = env.reset(seed=seed), quiet.reset(seed=seed), stance.reset(seed=seed)
        x0 = i1["com_position"][0]
        assert o1[OBS_COM_DRIFT] == 0.0 and np.array_equal(oq[:18], os_) and np.array_equal(o1[:18], os_)
        moved = 0.0
        for a in acts[:, 0]:
            o1, r1, t1, tr1, i1 = env.step(a)
            oq, _, tq, _, _ = quiet.step(a)
            os_, _, ts, _, _ = stance.step(a)
            assert np.array_equal(oq[:18], os_) and tq == ts
            dx = i1["com_position"][0] - x0
            assert o1[OBS_COM_DRIFT] == np.float32(dx)
            assert i1["reward_com"] == pytest.approx(-env.unwrapped.config.com_weight * dx * dx, rel=1e-9, abs=1e-15)
            moved = max(moved, abs(float(o1[OBS_COM_DRIFT])))
            if t1 or tr1 or tq:
                break
        assert moved > 0.01  # the pushes moved it
    vec = gym.make_vec("leg_env/PlanarLegPush-v2", num_envs=3, vectorization_mode="vector_entry_point", **kw)
    obs, info = vec.reset(seed=2)
    x0 = info["com_position"][:, 0].copy()
    assert np.all(obs[:, OBS_COM_DRIFT] == 0.0)
    for a in actions(20, 3, seed=4):
        obs, _, term, trunc, info = vec.step(a)
        assert not np.any(term | trunc)
        assert np.array_equal(obs[:, OBS_COM_DRIFT], (info["com_position"][:, 0] - x0).astype(np.float32))


PUSH, HOP = "leg_env/PlanarLegPush-v2", "leg_env/PlanarLegHop-v4"
BAD_CONFIGS = [
    (PUSH, {"push_force": (50.0, 20.0)}, ValueError, "push_force"),
    (PUSH, {"push_force": (-1.0, 20.0)}, ValueError, "push_force"),
    (PUSH, {"push_force": "big"}, TypeError, "push_force"),
    (PUSH, {"push_force": (True, 60)}, TypeError, "push_force"),
    (PUSH, {"push_duration": 0.0}, ValueError, "push_duration"),
    (PUSH, {"push_duration": float("nan")}, ValueError, "push_duration"),
    (PUSH, {"push_interval": (0.0, 1.0)}, ValueError, "push_interval"),
    (PUSH, {"first_push": (1.0, float("inf"))}, ValueError, "first_push"),
    (PUSH, {"com_weight": -1.0}, ValueError, "com_weight"),
    (PUSH, {"com_weight": True}, TypeError, "com_weight"),
    (PUSH, {"com_weight": 10**400}, ValueError, "com_weight"),
    (PUSH, {"quiet_share": 1.5}, ValueError, "quiet_share"),
    (PUSH, {"quiet_share": float("nan")}, ValueError, "quiet_share"),
    (PUSH, {"quiet_flight_scale": -1.0}, ValueError, "quiet_flight_scale"),
    (PUSH, {"quiet_change_scale": "2"}, TypeError, "quiet_change_scale"),
    (PUSH, {"unilateral_weight": "0.5"}, TypeError, "unilateral_weight"),
    (PUSH, {"contact": "pinned"}, ValueError, "contact"),
    (HOP, {"contact": "pinned"}, ValueError, "contact"),
    (HOP, {"command_range": (0.2, 0.1)}, ValueError, "command_range"),
    (HOP, {"command_range": (-0.1, 0.1)}, ValueError, "command_range"),
    (HOP, {"command_range": 0.1}, TypeError, "command_range"),
    (HOP, {"height_scale": 0.0}, ValueError, "height_scale"),
    (HOP, {"height_scale_fine": -0.01}, ValueError, "height_scale_fine"),
    (HOP, {"height_weight": float("inf")}, ValueError, "height_weight"),
    (HOP, {"impact_weight": "1"}, TypeError, "impact_weight"),
    (HOP, {"slip_weight": -2.0}, ValueError, "slip_weight"),
    (HOP, {"drift_com_weight": 1j}, TypeError, "drift_com_weight"),
    (HOP, {"tilt_weight": np.nan}, ValueError, "tilt_weight"),
    (HOP, {"max_ground_time": 0.0}, ValueError, "max_ground_time"),
    (HOP, {"max_ground_time": float("inf")}, ValueError, "max_ground_time"),
    (HOP, {"min_flight": -0.01}, ValueError, "min_flight"),
]


@pytest.mark.parametrize("env_id, kwargs, error, field", BAD_CONFIGS, ids=[f"{i.split('/')[1]}-{k}" for i, k, _, _ in BAD_CONFIGS])
def test_task_config_is_checked_by_the_one_validation_path(env_id, kwargs, error, field):
    """``leg_env.checks`` refuses every bad task field (wrong type: ``ArgumentTypeError``, a ``TypeError``;
    out of range, NaN, overflow: ``ValueError``), naming it, through every constructor (the SB3 adapter's
    in ``test_sb3_adapter_contract``)."""
    with pytest.raises(error, match=field):
        gym.make(env_id, **kwargs)
    with pytest.raises(error, match=field):
        gym.make_vec(env_id, num_envs=2, **kwargs)


def test_unknown_keyword_is_a_type_error_for_every_task():
    for env_id in ALL_IDS:
        with pytest.raises(TypeError, match="unexpected keyword argument 'nope'"):
            gym.make(env_id, nope=1)


def test_push_kernel_param_array_is_the_lesson_params_and_a_load():
    p = leg_env.LegParams()
    a = dyn.params_array(p, 12.5)
    assert a.shape == (12,) and a[dyn.LOAD_X] == 12.5 and np.array_equal(a[:11], p.array)


RECOVERIES = Path(__file__).resolve().parents[1] / "policies" / "baselines" / "balance_recoveries"


@pytest.mark.parametrize("path", sorted(RECOVERIES.glob("*.npy")), ids=lambda p: p.stem)
def test_balance_starts_every_controller_fails_are_recoverable(path):
    """The saved action sequences survive the seven starts the LQR and PPO fail (the evidence that the
    task's 95% bar is not capped by the physics): replayed open loop from their seeds, whole episodes."""
    seed = int(path.stem.rsplit("_", 1)[1])
    actions = np.load(path)
    env = gym.make("leg_env/PlanarLegBalance-v1")
    env.reset(seed=seed)
    for t, action in enumerate(actions):
        _, _, terminated, truncated, info = env.step(action)
        assert not terminated, (seed, t)
        assert not info["numerical_failure"] and info["painleve_fallbacks"] == 0
    assert truncated and t == 999
    q, qd, _ = env.unwrapped.state
    assert abs(q[2]) < 0.01 and np.abs(qd).max() < 0.05  # it ends balanced, not merely alive
