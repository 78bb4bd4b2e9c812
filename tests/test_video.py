"""Rendering wrappers on the batch: Gymnasium's RecordVideo and HumanRendering, SB3's VecVideoRecorder.

Each needs one frame per sub-env from ``render()`` and the env's real frame rate in
``metadata["render_fps"]`` (``1 / dt``). Videos are written by MoviePy (its ffmpeg comes with
``imageio-ffmpeg``) and read back here; ``HumanRendering`` draws into a window of SDL's dummy driver.
"""

import gymnasium as gym
import imageio_ffmpeg
import numpy as np
import pygame
import pytest

import leg_env

ENV_ID = leg_env.ENV_ID
NUM_ENVS = 8
SIZE = 48  # pixels: small frames keep the videos cheap
DT = 0.02  # a non-default control period: the videos must play at 1 / dt = 50 frames per second
ENV_KWARGS = dict(num_envs=NUM_ENVS, render_mode="rgb_array", width=SIZE, height=SIZE, dt=DT)


def read_video(path) -> tuple[dict, np.ndarray]:
    frames = imageio_ffmpeg.read_frames(str(path))
    try:
        meta = next(frames)
        width, height = meta["size"]
        return meta, np.array([np.frombuffer(f, dtype=np.uint8).reshape(height, width, 3) for f in frames])
    finally:
        frames.close()


def tiles(image: np.ndarray, rows: int, cols: int) -> list[np.ndarray]:
    """The ``rows x cols`` tiles of ``image``, row by row."""
    return [image[r * SIZE : (r + 1) * SIZE, c * SIZE : (c + 1) * SIZE] for r in range(rows) for c in range(cols)]


def start_frames(seed: int) -> tuple:
    """Every sub-env's frame right after ``reset(seed=seed)``, from a twin batch."""
    twin = gym.make_vec(ENV_ID, **ENV_KWARGS)
    twin.reset(seed=seed)
    return twin.render()


def test_render_draws_every_sub_env_unless_limited():
    envs = gym.make_vec(ENV_ID, **ENV_KWARGS)
    envs.reset(seed=0)
    frames = envs.render()
    assert len(frames) == NUM_ENVS and all(f.shape == (SIZE, SIZE, 3) for f in frames)
    assert envs.metadata["render_fps"] == 50
    limited = gym.make_vec(ENV_ID, render_envs=3, **ENV_KWARGS)
    limited.reset(seed=0)
    assert len(limited.render()) == 3


def test_record_video_records_every_sub_env_at_the_real_rate(tmp_path):
    envs = gym.make_vec(ENV_ID, max_episode_steps=10, **ENV_KWARGS)
    envs = gym.wrappers.vector.RecordVideo(envs, str(tmp_path / "videos"), episode_trigger=lambda episode: episode == 0, disable_logger=True)
    envs.reset(seed=0)
    for _ in range(12):  # one 10-step episode, then the first step of the next one ends the video
        envs.step(np.zeros((NUM_ENVS, 2)))
    envs.close()
    (video,) = (tmp_path / "videos").glob("*.mp4")
    meta, frames = read_video(video)
    assert meta["fps"] == 50.0
    assert len(frames) >= 10  # the reset and 10 steps (MoviePy may drop the last frame)
    assert frames.shape[1:] == (2 * SIZE, 4 * SIZE, 3)  # 8 sub-envs tiled 2 x 4
    for tile, frame in zip(tiles(frames[0], 2, 4), start_frames(0)):
        assert np.abs(tile.astype(int) - frame).mean() < 8.0  # each tile is its sub-env (h264 is lossy)


@pytest.mark.sb3
def test_vec_video_recorder_on_the_sb3_adapter(tmp_path):
    from stable_baselines3.common.vec_env import VecVideoRecorder  # SB3 only here: the RLlib venv runs the rest

    from leg_env.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env(seed=0, **ENV_KWARGS)
    assert venv.metadata["render_fps"] == 50
    venv = VecVideoRecorder(venv, str(tmp_path), record_video_trigger=lambda step: step == 0, video_length=10)
    venv.reset()
    for _ in range(11):
        venv.step(np.zeros((NUM_ENVS, 2)))
    venv.close()
    (video,) = tmp_path.glob("*.mp4")
    meta, frames = read_video(video)
    assert meta["fps"] == 50.0
    assert len(frames) >= 10
    assert frames.shape[1:] == (3 * SIZE, 3 * SIZE, 3)  # SB3 tiles 8 images 3 x 3
    for tile, frame in zip(tiles(frames[0], 3, 3), start_frames(0)):
        assert np.abs(tile.astype(int) - frame).mean() < 8.0


def test_human_rendering_shows_every_sub_env():
    envs = gym.wrappers.vector.HumanRendering(gym.make_vec(ENV_ID, **ENV_KWARGS), screen_size=(3 * SIZE, 3 * SIZE))
    assert envs.render_mode == "human" and envs.metadata["render_fps"] == 50
    envs.reset(seed=0)
    window = pygame.surfarray.array3d(envs.window).transpose(1, 0, 2)  # (height, width, 3)
    for tile, frame in zip(tiles(window, 3, 3), start_frames(0)):
        np.testing.assert_array_equal(tile, frame)  # 3 x 3 grid at scale 1: the frames themselves
    assert not tiles(window, 3, 3)[-1].any()  # the ninth cell stays empty
    envs.step(np.zeros((NUM_ENVS, 2)))
    envs.close()
