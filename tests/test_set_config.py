"""``set_config`` of the single and the vector env: what a curriculum may change, when it takes effect, and what
it must refuse without touching the env."""

import pickle

import gymnasium as gym
import numpy as np
import pytest

import leg_env  # noqa: F401  (registers the ids)
from leg_env.tasks.base import Obs

HOP = "leg_env/PlanarLegHop-v4"
BALANCE = "leg_env/PlanarLegBalance-v1"


def vector(env_id: str, n: int = 8, **kwargs):
    return gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)


def snapshot(env) -> tuple:
    """Everything set_config may write: the config and the settings the compiled core reads."""
    return env.config, env._settings.tobytes()


@pytest.mark.parametrize("kind", ["single", "vector"])
def test_a_narrower_command_range_holds_from_the_next_reset(kind):
    if kind == "single":
        env = gym.make(HOP, command_range=(0.02, 0.15)).unwrapped
        space = env.observation_space
    else:
        env = vector(HOP, command_range=(0.02, 0.15))
        space = env.single_observation_space
    obs, _ = env.reset(seed=3)
    before = np.atleast_2d(obs)[:, Obs.command].copy()
    env.set_config(command_range=(0.02, 0.03))
    obs, _, _, _, _ = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert np.array_equal(np.atleast_2d(obs)[:, Obs.command], before)  # the episode under way keeps its command
    commands = []
    for seed in range(20):
        obs, _ = env.reset(seed=seed)
        commands.append(np.atleast_2d(obs)[:, Obs.command])
    commands = np.concatenate(commands)
    assert commands.min() >= np.float32(0.02) and commands.max() <= np.float32(0.03)
    assert commands.max() - commands.min() > 0.005  # drawn across the new range, not pinned to an end
    assert env.config.command_range == (0.02, 0.03)
    assert (env.single_observation_space if kind == "vector" else env.observation_space) == space  # the built space stays


@pytest.mark.parametrize("kind", ["single", "vector"])
def test_a_reward_weight_holds_from_the_next_step(kind):
    env = gym.make(BALANCE).unwrapped if kind == "single" else vector(BALANCE)
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    _, _, _, _, info = env.step(action)
    assert np.allclose(info["reward_alive"], 1.0)
    env.set_config(alive_bonus=3.5)
    _, _, _, _, info = env.step(action)
    assert np.allclose(info["reward_alive"], 3.5)


@pytest.mark.parametrize("kind", ["single", "vector"])
@pytest.mark.parametrize(
    "changes, error, match",
    [
        ({"command_range": (0.01, 0.06)}, ValueError, r"set_config\(command_range\).*observation space: entries \[18\]"),
        ({"command_range": (0.05, 0.2)}, ValueError, r"entries \[18\] would widen"),
        ({"nominal_knee": 0.7}, ValueError, r"set_config\(nominal_knee\).*the robot"),
        ({"torque_limit": 40.0}, ValueError, r"set_config\(torque_limit\).*the robot"),
        ({"mu": 0.4}, ValueError, r"set_config\(mu\).*the robot"),
        ({"min_base_height": 0.45}, ValueError, r"set_config\(min_base_height\).*posture limits"),
        ({"dt": 0.02}, ValueError, r"set_config\(dt\).*control period"),
        ({"contact": "pinned"}, ValueError, "contact"),
        ({"alive_bonus": float("nan")}, ValueError, "alive_bonus"),
        ({"command_range": (0.1, 0.05)}, ValueError, "command_range"),
        ({"hip_range": (-3.0, -2.5)}, ValueError, "already terminal"),
        ({"no_such_field": 1.0}, TypeError, "unexpected keyword argument 'no_such_field'"),
    ],
)
def test_refused_changes_name_the_field_and_change_nothing(kind, changes, error, match):
    env = gym.make(HOP).unwrapped if kind == "single" else vector(HOP)
    obs, _ = env.reset(seed=1)
    before = snapshot(env)
    state = tuple(a.copy() for a in env.state)
    with pytest.raises(error, match=match):
        env.set_config(**changes)
    assert snapshot(env) == before
    assert all(np.array_equal(a, b) for a, b in zip(env.state, state))


def test_the_changed_config_survives_pickling_and_equals_a_fresh_env():
    env = vector(BALANCE, n=4)
    env.set_config(drift_position_weight=100.0, reset_noise_scale=0.1)
    copy = pickle.loads(pickle.dumps(env))
    fresh = vector(BALANCE, n=4, drift_position_weight=100.0, reset_noise_scale=0.1)
    actions = np.random.default_rng(0).uniform(-1, 1, size=(30, 4, 2)).astype(np.float32)
    results = []
    for e in (env, copy, fresh):
        obs, _ = e.reset(seed=5)
        rewards = [e.step(a)[1] for a in actions]
        results.append((obs, np.array(rewards)))
    for obs, rewards in results[1:]:
        assert np.array_equal(obs, results[0][0]) and np.array_equal(rewards, results[0][1])

