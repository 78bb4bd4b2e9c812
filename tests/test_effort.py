"""Effort and smoothness in every task: the observed last action, the action-rate and power charges, the torque
applied (``info["torque"]``) and the motor model, against their formulas, the state and the energy balance."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import leg_env
from leg_env.physics.dynamics import com_position  # noqa: F401  (the physics, imported as the envs do)

IDS = ("leg_env/PlanarLegStance-v0", "leg_env/PlanarLegBalance-v1", "leg_env/PlanarLegPush-v2", "leg_env/PlanarLegHop-v4")
STEPS = 150


def _actions(n: int, seed: int) -> np.ndarray:
    """Random actions, a third of their entries beyond the box (clipped by the env), and bursts of bang-bang."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-1.6, 1.6, size=(n, 2))
    a[40:60] = np.sign(a[40:60])
    return (0.5 * a + np.array([0.0, -0.45])).astype(np.float32)


def _hold(env) -> np.ndarray:
    u = env.unwrapped
    return np.clip(u.nominal.tau / np.asarray(u.config.torque_limit), -1.0, 1.0)


OFF = dict(action_rate_weight=0.0, action_change_weight=0.0, power_weight=0.0, observe_action=False)
EFFORT = {  # each id's effort settings (action_rate_weight, action_change_weight, power_weight, observe_action), as its docstring gives them
    "leg_env/PlanarLegStance-v0": (0.0, 0.0, 0.0, False),
    "leg_env/PlanarLegBalance-v1": (0.0, 0.2, 0.0, True),
    "leg_env/PlanarLegPush-v2": (0.2, 0.0, 0.0, True),
    "leg_env/PlanarLegHop-v4": (0.0, 1.0, 0.006, True),
}


@pytest.mark.parametrize("env_id", IDS)
def test_each_id_charges_and_observes_what_its_docstring_says(env_id):
    """The registered weights and observation width, and the motor an ideal torque source on every id."""
    env = gym.make(env_id)
    obs, _ = env.reset(seed=1)
    u = env.unwrapped
    assert (u.config.action_rate_weight, u.config.action_change_weight, u.config.power_weight, u.config.observe_action) == EFFORT[env_id]
    assert u.config.motor_speed == np.inf
    plain = gym.make(env_id, observe_action=False)
    assert obs.shape[0] == plain.observation_space.shape[0] + 2 * u.config.observe_action


@pytest.mark.parametrize("env_id", IDS)
def test_with_the_settings_off_nothing_is_charged_or_observed_and_the_torque_is_the_scaled_action(env_id):
    env = gym.make(env_id, **OFF)
    obs, _ = env.reset(seed=1)
    u = env.unwrapped
    assert u.config.action_rate_weight == 0.0 and u.config.power_weight == 0.0 and u.config.motor_speed == np.inf
    assert not u.config.observe_action and obs.shape == u.task.observation_space(u.params, u.config).shape
    limit = np.asarray(u.config.torque_limit)
    for a in _actions(60, 2):
        _, reward, terminated, _, info = env.step(a)
        assert info["reward_action_rate"] == 0.0 and info["reward_power"] == 0.0
        np.testing.assert_array_equal(info["torque"], np.clip(a.astype(np.float64), -1.0, 1.0) * limit)
        assert reward == sum(info[k] for k in u.task.reward_keys)
        if terminated:
            break


@pytest.mark.parametrize("env_id", IDS)
def test_the_action_rate_and_power_charges_are_their_formulas_and_the_last_action_is_observed(env_id):
    """``reward_action_rate = -(w_r |a - a_last|^2 + w_c |a - a_last|_1)`` (clipped actions; after a reset ``a_last`` holds the nominal
    posture), ``reward_power = -w_p sum_j max(0, tau_j dq_j) / dt`` with ``tau`` the torques held over the step and
    ``dq`` the joints' change read from the state; the observation ends with the last action, and is the plain one
    before it, bit for bit."""
    w_rate, w_change, w_power = 0.7, 0.3, 0.013
    env = gym.make(env_id, action_rate_weight=w_rate, action_change_weight=w_change, power_weight=w_power, observe_action=True)
    plain = gym.make(env_id, observe_action=False)
    u = env.unwrapped
    dt = u.dt
    for seed in (0, 3):
        obs, _ = env.reset(seed=seed)
        obs_plain, _ = plain.reset(seed=seed)
        last = _hold(env)
        assert obs.shape[0] == obs_plain.shape[0] + 2 and np.array_equal(obs[:-2], obs_plain)
        np.testing.assert_array_equal(obs[-2:], last.astype(np.float32))
        paid = positive = 0
        for a in _actions(STEPS, seed):
            q_before = u.state[0].copy()
            obs, reward, terminated, truncated, info = env.step(a)
            obs_plain, _, terminated_plain, _, info_plain = plain.step(a)
            assert np.array_equal(obs[:-2], obs_plain) and terminated == terminated_plain
            clipped = np.clip(a.astype(np.float64), -1.0, 1.0)
            np.testing.assert_array_equal(obs[-2:], clipped.astype(np.float32))
            if info["numerical_failure"]:
                break
            rate, change = np.sum((clipped - last) ** 2), np.sum(np.abs(clipped - last))
            assert info["reward_action_rate"] == pytest.approx(-(w_rate * rate + w_change * change), rel=1e-12, abs=1e-15)
            work = np.asarray(info["torque"]) * (u.state[0][3:5] - q_before[3:5])
            assert info["reward_power"] == pytest.approx(-w_power * np.maximum(work, 0.0).sum() / dt, rel=1e-12, abs=1e-15)
            for key in u.task.reward_keys:  # every other term is the plain task's
                if key not in ("reward_action_rate", "reward_power"):
                    assert info[key] == info_plain[key], key
            assert reward == pytest.approx(sum(info[k] for k in u.task.reward_keys), rel=1e-12, abs=1e-12)
            paid += rate > 0.0
            positive += bool(np.any(work > 0.0)) and bool(np.any(work < 0.0))
            last = clipped
            if terminated or truncated:
                break
        assert paid > 20
    assert positive > 0  # steps with a joint doing positive work and one braking: only the first is charged


@pytest.mark.parametrize("env_id", IDS)
def test_a_batch_observes_and_charges_each_row_as_its_single_env(env_id):
    kwargs = dict(action_rate_weight=0.4, action_change_weight=0.1, power_weight=0.02, observe_action=True, motor_speed=12.0)
    n = 4
    envs = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
    singles = [gym.make(env_id, **kwargs) for _ in range(n)]
    obs, _ = envs.reset(seed=7)
    for i, single in enumerate(singles):
        np.testing.assert_array_equal(obs[i], single.reset(seed=7 + i)[0])
    rng = np.random.default_rng(5)
    done = np.zeros(n, dtype=bool)
    for _ in range(80):
        a = rng.uniform(-1.3, 1.3, size=(n, 2)).astype(np.float32)
        obs, reward, terminated, truncated, info = envs.step(a)
        for i, single in enumerate(singles):
            if done[i]:
                continue
            o, r, t, _, inf = single.step(a[i])
            np.testing.assert_array_equal(obs[i], o)
            assert reward[i] == r and info["reward_action_rate"][i] == inf["reward_action_rate"]
            assert info["reward_power"][i] == inf["reward_power"]
            np.testing.assert_array_equal(info["torque"][i], inf["torque"])
            done[i] = t
        if done.all():
            break


def test_the_motor_model_scales_the_torque_by_the_joint_speed_at_the_steps_start():
    """``torque = a torque_limit clip(1 - w / motor_speed, 0, 1)`` per joint, ``w`` the joint's speed in the torque's
    direction at the step's start (braking: the whole torque); against the formula, and against the ideal-source task
    driven by those torques as actions (the same trajectory)."""
    w0 = 9.0
    motor = gym.make("leg_env/PlanarLegBalance-v1", motor_speed=w0, reset_noise_scale=0.05)
    ideal = gym.make("leg_env/PlanarLegBalance-v1", reset_noise_scale=0.05)
    limit = np.asarray(motor.unwrapped.config.torque_limit)
    scaled = braking = 0
    for seed in range(3):
        motor.reset(seed=seed)
        ideal.reset(seed=seed)
        for a in _actions(120, 10 + seed):
            qd = motor.unwrapped.state[1][3:5].copy()
            commanded = np.clip(a.astype(np.float64), -1.0, 1.0) * limit
            along = np.sign(commanded) * qd
            expected = commanded * np.clip(1.0 - along / w0, 0.0, 1.0)
            _, _, terminated, _, info = motor.step(a)
            np.testing.assert_allclose(info["torque"], expected, rtol=1e-15, atol=0.0)
            scaled += int(np.sum((along > 0.0) & (commanded != 0.0)))
            braking += int(np.sum(along < 0.0))
            _, _, terminated_ideal, _, info_ideal = ideal.step((expected / limit).astype(np.float64))
            np.testing.assert_allclose(info_ideal["torque"], expected, rtol=1e-14, atol=1e-12)
            np.testing.assert_allclose(ideal.unwrapped.state[0], motor.unwrapped.state[0], rtol=0.0, atol=1e-9)
            assert terminated == terminated_ideal
            if terminated:
                break
    assert scaled > 50 and braking > 50


@pytest.mark.parametrize("env_id", ["leg_env/PlanarLegBalance-v1", "leg_env/PlanarLegHop-v4"])
def test_the_applied_torque_books_the_energy_with_the_motor_model(env_id):
    """The torques of ``info["torque"]`` are those the physics applied: their work ``sum tau_j dq_j`` over the steps,
    with the push's and less the slip's and impacts' dissipation, is the change of the energy computed from the state
    (``info["energy"]``), with the motor model on."""
    env = gym.make(env_id, motor_speed=6.0)
    _, info = env.reset(seed=4)
    u = env.unwrapped
    e0, booked = info["energy"], 0.0
    for a in _actions(100, 4):
        q_before = u.state[0].copy()
        _, _, terminated, _, info = env.step(a)
        work = float(np.dot(info["torque"], u.state[0][3:5] - q_before[3:5]))
        assert work == pytest.approx(info["work_actuators"], rel=1e-12, abs=1e-12)
        booked += work - info["dissipation_slip"] - info["dissipation_impacts"]
        if terminated:
            break
    assert abs(info["energy"] - e0 - booked) < 1e-6 * (1.0 + abs(e0))


def test_the_controllers_read_an_observation_that_ends_with_the_last_action_as_the_plain_one():
    from policies.hopper import HopperController
    from policies.lqr import LQRController
    from policies.stepping import SteppingController

    for env_id, make in (("leg_env/PlanarLegBalance-v1", LQRController), ("leg_env/PlanarLegPush-v2", SteppingController),
                         ("leg_env/PlanarLegHop-v4", HopperController)):  # fmt: skip
        env = gym.make(env_id, observe_action=True)
        obs, _ = env.reset(seed=2)
        u = env.unwrapped
        a, b = (make(u.params, u.config) if make is not LQRController else make(u.params) for _ in range(2))
        for _ in range(50):
            blind = obs.copy()
            blind[-2:] = np.nan  # the last action: not read
            act = a.predict(obs)[0]
            np.testing.assert_array_equal(act, b.predict(blind)[0])
            obs, _, terminated, _, _ = env.step(act)
            if terminated:
                break


@pytest.mark.parametrize(
    "kwargs, error, field",
    [
        ({"motor_speed": 0.0}, ValueError, "motor_speed"),
        ({"motor_speed": -3.0}, ValueError, "motor_speed"),
        ({"motor_speed": float("nan")}, ValueError, "motor_speed"),
        ({"motor_speed": "fast"}, TypeError, "motor_speed"),
        ({"action_rate_weight": -0.1}, ValueError, "action_rate_weight"),
        ({"action_change_weight": float("nan")}, ValueError, "action_change_weight"),
        ({"power_weight": float("inf")}, ValueError, "power_weight"),
        ({"observe_action": 1}, TypeError, "observe_action"),
    ],
)
def test_bad_effort_settings_are_refused_by_name(kwargs, error, field):
    for env_id in IDS:
        with pytest.raises(error, match=field):
            gym.make(env_id, **kwargs)


def test_set_config_refuses_to_change_the_observations_width():
    env = gym.make("leg_env/PlanarLegBalance-v1").unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="observation's shape"):
        env.set_config(observe_action=False)
    env.set_config(action_rate_weight=0.5, power_weight=0.01, motor_speed=20.0)  # weights and the motor may change
    _, _, _, _, info = env.step(np.array([1.0, -1.0], dtype=np.float32))
    assert info["reward_action_rate"] < 0.0 and leg_env.ENV_IDS


def test_on_the_push_task_standing_smoothly_earns_more_than_the_same_stance_with_chatter():
    """The push task's weights make chatter cost what it does not buy: the stepping controller, and the same
    controller with a dither of +-0.15 on both torques, its sign flipped every step, stand through the same unpushed
    episodes (the same outcome), and the smooth one earns more on each, by at least 0.02 a step (the charge on a
    change of 0.3 in both entries is 0.036); with the effort settings off (the task before them), the dither costs
    less than half as much."""
    from policies.stepping import SteppingController

    kwargs = dict(push_force=(0.0, 0.0), reset_noise_scale=0.02)
    gaps = {}
    for name, extra in (("task", {}), ("off", dict(OFF, ctrl_cost_weight=0.01, drift_angle_weight=1.0))):
        env = gym.make("leg_env/PlanarLegPush-v2", **kwargs, **extra)
        u = env.unwrapped
        gaps[name] = []
        for seed in (0, 1, 2):
            returns = []
            for dither in (0.0, 0.15):
                controller = SteppingController(u.params, u.config)
                obs, _ = env.reset(seed=seed)
                total, steps = 0.0, 0
                for t in range(400):
                    a, _ = controller.predict(obs, deterministic=True)
                    a = np.clip(a + dither * (-1.0) ** t, -1.0, 1.0).astype(np.float32)
                    obs, reward, terminated, truncated, _ = env.step(a)
                    total, steps = total + reward, steps + 1
                    assert not terminated, f"{name} seed {seed} dither {dither} fell at step {t}"
                returns.append(total)
            gaps[name].append((returns[0] - returns[1]) / steps)
    assert min(gaps["task"]) > 0.02, gaps
    assert max(gaps["off"]) < 0.5 * min(gaps["task"]), gaps


def test_on_the_balance_task_a_jitter_of_a_few_hundredths_costs_in_proportion_to_the_action_rate():
    """The balance task charges the action's change in absolute value, so that a stance that jitters earns less than
    the same stance held still: the LQR, and the LQR with a dither of +-0.02 on both torques, its sign flipped every
    step (an action rate of 0.04), stand through the same episodes, and the still one earns more on each by at least
    0.014 a step (the charge is 0.2 x 0.08 = 0.016); the squared charge alone (0.2 per unit), at the same weight,
    tells them apart by less than a tenth of that."""
    from policies.lqr import LQRController

    gaps = {}
    for name, extra in (("task", {}), ("squared", dict(action_change_weight=0.0, action_rate_weight=0.2))):
        env = gym.make("leg_env/PlanarLegBalance-v1", reset_noise_scale=0.01, **extra)
        u = env.unwrapped
        gaps[name] = []
        for seed in (0, 1, 2):
            returns = []
            for dither in (0.0, 0.02):
                controller = LQRController(u.params)
                obs, _ = env.reset(seed=seed)
                total = 0.0
                for t in range(300):
                    a, _ = controller.predict(obs, deterministic=True)
                    a = np.clip(a + dither * (-1.0) ** t, -1.0, 1.0).astype(np.float32)
                    obs, reward, terminated, _, _ = env.step(a)
                    total += reward
                    assert not terminated, f"{name} seed {seed} dither {dither} fell at step {t}"
                returns.append(total)
            gaps[name].append((returns[0] - returns[1]) / 300)
    assert min(gaps["task"]) > 0.014, gaps
    assert max(gaps["squared"]) < 0.1 * min(gaps["task"]), gaps
