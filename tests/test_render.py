"""Rendering: headless ``rgb_array`` frames, a ``human`` window (SDL dummy driver in CI), lazy pygame."""

import os
import pickle
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

from leg_env import ENV_ID, LegEnv
from leg_env.render import FEASIBLE, VIOLATED, draw

SIZES = [(480, 480), (320, 200), (120, 360)]


def count(frame: np.ndarray, colour) -> int:
    return int(np.all(frame == np.array(colour, dtype=np.uint8), axis=-1).sum())


@pytest.mark.parametrize("width,height", SIZES)
def test_rgb_array_frame_shape_and_content(width, height):
    env = gym.make(ENV_ID, render_mode="rgb_array", width=width, height=height, reset_noise_scale=0.0)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (height, width, 3) and frame.dtype == np.uint8
    colours = np.unique(frame.reshape(-1, 3), axis=0)
    assert len(colours) >= 8  # sky, ground, links, torso, joints, arrow, ...
    assert count(frame, FEASIBLE) > 20 and count(frame, VIOLATED) == 0  # the nominal force is feasible


def test_violated_force_is_red_and_frames_follow_the_state():
    env = gym.make(ENV_ID, render_mode="rgb_array", reset_noise_scale=0.0)
    env.reset(seed=0)
    first = env.render()
    _, _, _, _, info = env.step(np.array([0.0, 1.0]))  # pulls on the ground
    assert info["unilateral_violation"]
    frame = env.render()
    assert count(frame, VIOLATED) > 20 and count(frame, FEASIBLE) == 0
    assert not np.array_equal(first, frame)


def test_draw_directly(params):
    q = np.array([0.0, 0.9, 0.2, -2.0, 0.8])
    frame = draw(q, np.zeros(2), np.array([10.0, 140.0]), params, violated=False, width=64, height=48)
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 3


def test_render_after_a_fall():
    env = gym.make(ENV_ID, render_mode="rgb_array")
    env.reset(seed=0)
    for _ in range(300):
        if env.step(np.zeros(2))[2]:
            break
    assert env.render().shape == (480, 480, 3)


def test_render_without_mode_warns_and_returns_none():
    env = LegEnv()
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


def test_rgb_array_needs_no_display():
    code = (
        "import sys, leg_env, gymnasium as gym\n"
        "assert 'pygame' not in sys.modules\n"
        "import leg_env.render\n"
        "assert 'pygame' not in sys.modules\n"
        "env = gym.make('leg_env/PlanarLegStance-v0', render_mode='rgb_array')\n"
        "env.reset(seed=0)\n"
        "assert 'pygame' not in sys.modules\n"
        "print(env.render().shape)\n"
    )
    environ = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=environ)
    assert out.stdout.strip() == "(480, 480, 3)"


def test_human_mode_opens_a_window_and_closes():
    # conftest sets SDL_VIDEODRIVER=dummy, so the window exists without a display
    env = gym.make(ENV_ID, render_mode="human", width=160, height=120)
    env.reset(seed=0)
    for _ in range(3):
        env.step(env.action_space.sample())
    assert env.render() is None
    assert env.unwrapped._viewer is not None
    clone = pickle.loads(pickle.dumps(env.unwrapped))  # a window does not travel
    assert clone._viewer is None
    env.close()
    env.close()  # closing twice is allowed


def test_a_push_shows_as_an_arrow_at_the_torso():
    """The push task's frames show the push (purple) while it acts, ending at the hip from the side it
    pushes from, and not before or after it."""
    from leg_env.render import PUSH, _Camera

    env = gym.make("leg_env/PlanarLegPush-v2", render_mode="rgb_array", push_force=(100.0, 100.0), first_push=(0.05, 0.05))
    env.reset(seed=1)
    assert count(env.render(), PUSH) == 0
    for _ in range(10):  # the push starts 0.05 s in and lasts 10 steps of 0.01 s
        _, _, _, _, info = env.step(np.zeros(2))
        if info["push_force"] != 0.0:
            break
    assert abs(info["push_force"]) == 100.0
    frame = env.render()
    purple = np.all(frame == np.array(PUSH, dtype=np.uint8), axis=-1)
    assert purple.sum() > 20
    q, _, anchor = env.unwrapped.state
    u = env.unwrapped
    hip_col = _Camera(anchor, u.params, u.width, u.height)(q[0], q[1])[0]
    columns = np.flatnonzero(purple.any(axis=0))
    side = np.sign(info["push_force"])  # a push to +x comes from the left of the hip
    assert np.all(side * (columns - hip_col) <= 2) and np.any(side * (columns - hip_col) < -20)
    for _ in range(10):
        _, _, terminated, _, info = env.step(np.zeros(2))
    assert info["push_force"] == 0.0 and count(env.render(), PUSH) == 0


@pytest.mark.parametrize("env_id", ["leg_env/PlanarLegStance-v0", "leg_env/PlanarLegHop-v4"])
def test_a_randomised_batch_draws_each_robot_with_its_own_parameters(env_id):
    """Every sub-env's frame is its own robot (its link lengths, its friction cone) at its own state, the frame
    the single env draws for that robot; with drawn lengths the nominal robot's frame differs."""
    from leg_env.envs.single import render_marks, robot_of_row

    n = 4
    envs = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", render_mode="rgb_array",
                        randomize={"l1": ("scale", 0.8, 1.2), "l2": ("scale", 0.8, 1.2), "mu": ("range", 0.3, 0.5)})
    envs.reset(seed=3)
    envs.step(np.zeros((n, 2), dtype=np.float32))
    u = envs.unwrapped
    frames = envs.render()
    q, _, anchor = u.state
    differs = 0
    for i in range(n):
        params, mu = robot_of_row(u._robots[i])
        violated, mode, impulse, push = render_marks(u._out, i, u.unilateral)
        lam = u._out["lam"][i]
        own = draw(q[i], anchor[i], lam, params, violated, u.width, u.height, mu, mode, impulse, push)
        nominal = draw(q[i], anchor[i], lam, u.params, violated, u.width, u.height, u.config.mu, mode, impulse, push)
        assert np.array_equal(frames[i], own), i
        differs += not np.array_equal(own, nominal)
    assert differs > 0
