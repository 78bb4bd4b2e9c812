"""``info["ending"]``: why an episode ended, the first limit it passed, checked against the state the step left."""

import gymnasium as gym
import numpy as np
import pytest

import leg_env
from leg_env import ENDINGS

TASKS = [
    ("leg_env/PlanarLegStance-v0", {"reset_noise_scale": 0.3}),
    ("leg_env/PlanarLegStance-v0", {"terminate_on_contact_loss": True, "contact_loss_threshold": 10.0, "reset_noise_scale": 0.6}),
    ("leg_env/PlanarLegBalance-v1", {"reset_noise_scale": 0.2}),
    ("leg_env/PlanarLegPush-v2", {"push_force": [40.0, 80.0]}),
    ("leg_env/PlanarLegHop-v4", {}),
]


def expected_ending(q: np.ndarray, trig: np.ndarray, anchor: np.ndarray, config, lost: bool) -> str:
    """The ending of a robot at the state ``q`` (the trig of ``q``, its foot's ``anchor``), written from the task's
    documented limits: the first that holds, in ``ENDINGS``' order."""
    checks = [
        ("torso_angle", abs(q[2]) > config.max_torso_angle),
        ("base_height", q[1] - anchor[1] < config.min_base_height),
        ("hip_low", q[3] < config.hip_range[0]),
        ("hip_high", q[3] > config.hip_range[1]),
        ("knee_low", q[4] < config.knee_range[0]),
        ("knee_high", q[4] > config.knee_range[1]),
        ("base_below_knee", trig[0] > 0.0),  # the knee's height above the base, l1 sin(th_b + q1), is positive
        ("contact_lost", lost),
    ]
    return next((name for name, hit in checks if hit), "none")


@pytest.mark.parametrize("env_id, kwargs", TASKS, ids=["pinned", "pinned-contact-loss", "balance", "push", "hop"])
def test_each_ending_is_the_first_limit_the_state_passed(env_id, kwargs):
    """In a vector env under random and saturated actions, at every step and row: terminated exactly where the
    ending is not "none", and the ending the first of the task's limits that the state after the step passes (a
    numerical failure aside, which undoes the step); the episodes end in more than one way."""
    n = 64
    envs = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
    core = envs.unwrapped
    config = core.config
    rng = np.random.default_rng(0)
    envs.reset(seed=0)
    seen = set()
    restarted = np.zeros(n, dtype=bool)  # rows the step resets (next-step autoreset): their info is the reset's
    for step in range(300):
        scale = 1.0 if step % 3 else 3.0  # past the action bounds too: clipped
        _, _, terminated, truncated, info = envs.step(rng.uniform(-scale, scale, (n, 2)))
        ending = info["ending"]
        assert ending.dtype.kind == "i" and np.all((ending >= 0) & (ending < len(ENDINGS)))
        np.testing.assert_array_equal(terminated[~restarted], ending[~restarted] != 0)
        assert not terminated[restarted].any()
        state = core._state
        for i in np.flatnonzero(terminated | restarted):
            if info["numerical_failure"][i]:
                assert ENDINGS[ending[i]] == "numerical_failure"
                continue
            contact_lost = bool(getattr(config, "terminate_on_contact_loss", False)) and (
                info["normal_force"][i] < config.contact_loss_threshold or info.get("flight_time", np.zeros(n))[i] > 0.0)
            want = expected_ending(state["q"][i], state["trig"][i], state["anchor"][i], config, contact_lost)
            assert ENDINGS[ending[i]] == want, (step, i, state["q"][i])
            seen.add(want)
        restarted = terminated | truncated
    envs.close()
    assert len(seen) >= 2, seen


def test_a_single_env_reports_the_ending_of_its_vector_row():
    """The single env's ``info["ending"]`` is the vector env's, row for row, over the same seeds and actions."""
    seeds, steps = [3, 4, 5], 200
    rng = np.random.default_rng(1)
    actions = rng.uniform(-1, 1, (steps, len(seeds), 2))
    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=len(seeds), vectorization_mode="vector_entry_point")
    envs.reset(seed=seeds)
    vector_endings = []
    for t in range(steps):
        vector_endings.append(envs.step(actions[t])[4]["ending"].copy())
    vector_endings = np.array(vector_endings)
    for k, seed in enumerate(seeds):
        env = gym.make("leg_env/PlanarLegHop-v4")
        env.reset(seed=seed)
        for t in range(steps):
            _, _, terminated, truncated, info = env.step(actions[t, k])
            assert info["ending"] == vector_endings[t, k] and isinstance(info["ending"], int)
            if terminated or truncated:
                assert terminated == (info["ending"] != 0)
                break
        assert terminated, "the case needs an episode that ends"
