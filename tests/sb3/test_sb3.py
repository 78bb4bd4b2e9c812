"""The Stable-Baselines3 VecEnv adapter: SB3's VecEnv contract, its wrappers, and PPO on it."""

from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from stable_baselines3 import PPO
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecCheckNan, VecMonitor, VecNormalize

import leg_env
from leg_env.envs.vector import LegVectorEnv
from leg_env.info import KEYS
from leg_env.tasks.stance import TASK as STANCE

from leg_env.sb3 import LegStanceVecEnv, make_sb3_vec_env

REWARD_KEYS = STANCE.reward_keys
STATE_KEYS = tuple(key for key, _ in KEYS)

ENV_ID = leg_env.ENV_ID
NUM_ENVS = 4
SEED = 7
STEPS = 120
MAX_STEPS = 20
ENV_KWARGS = dict(reset_noise_scale=0.05, torque_limit=45.0)
ACTION_BIAS = (0.6, -0.6)  # pushes the robot over: episodes terminate as well as truncate


def random_actions(steps: int, n: int = NUM_ENVS, seed: int = 0) -> np.ndarray:
    noise = 1.5 * np.random.default_rng(seed).uniform(-1.0, 1.0, size=(steps, n, 2))
    return (noise + np.asarray(ACTION_BIAS)).astype(np.float32)


def dummy_vec_env(n: int = NUM_ENVS, **kwargs) -> DummyVecEnv:
    """SB3's reference: one gym.make env per sub-env."""
    return DummyVecEnv([lambda: gym.make(ENV_ID, max_episode_steps=MAX_STEPS, **ENV_KWARGS, **kwargs) for _ in range(n)])


def assert_info_equal(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        if isinstance(a[key], np.ndarray):
            assert a[key].dtype == b[key].dtype
            np.testing.assert_array_equal(a[key], b[key])
        else:
            assert type(a[key]) is type(b[key]) and a[key] == b[key], key


# ------------------------------------------------------------------ the VecEnv contract


def test_equals_dummy_vec_env_over_single_envs():
    """Obs, rewards, dones and every info dict (terminal_observation, TimeLimit.truncated) equal DummyVecEnv's."""
    ours = make_sb3_vec_env(NUM_ENVS, seed=SEED, max_episode_steps=MAX_STEPS, **ENV_KWARGS)
    ref = dummy_vec_env()
    ref.seed(SEED)
    np.testing.assert_array_equal(ours.reset(), ref.reset())
    for i in range(NUM_ENVS):
        assert_info_equal(ours.reset_infos[i], ref.reset_infos[i])
    counts = {"terminal": 0, "time_limit": 0}
    for actions in random_actions(STEPS):
        obs, rewards, dones, infos = ours.step(actions)
        ref_obs, ref_rewards, ref_dones, ref_infos = ref.step(actions)
        np.testing.assert_array_equal(obs, ref_obs)
        assert rewards.dtype == ref_rewards.dtype and dones.dtype == ref_dones.dtype
        np.testing.assert_array_equal(rewards, ref_rewards)
        np.testing.assert_array_equal(dones, ref_dones)
        for i in range(NUM_ENVS):
            assert_info_equal(infos[i], ref_infos[i])
            assert_info_equal(ours.reset_infos[i], ref.reset_infos[i])
            counts["terminal"] += dones[i] and not infos[i]["TimeLimit.truncated"]
            counts["time_limit"] += infos[i]["TimeLimit.truncated"]
    assert counts["terminal"] >= 3 and counts["time_limit"] >= 3, counts


def test_terminal_observation_is_the_last_observation_before_the_reset():
    venv = make_sb3_vec_env(NUM_ENVS, seed=SEED, max_episode_steps=MAX_STEPS, **ENV_KWARGS)
    singles = [gym.make(ENV_ID, max_episode_steps=MAX_STEPS, **ENV_KWARGS) for _ in range(NUM_ENVS)]
    venv.reset()
    for i, env in enumerate(singles):
        env.reset(seed=SEED + i)
    ended = 0
    for actions in random_actions(STEPS):
        obs, _, dones, infos = venv.step(actions)
        for i, env in enumerate(singles):
            last, _, terminated, truncated, _ = env.step(actions[i])
            assert dones[i] == (terminated or truncated)
            if dones[i]:
                np.testing.assert_array_equal(infos[i]["terminal_observation"], last)
                assert not np.array_equal(obs[i], last)  # the returned row already starts the next episode
                last, _ = env.reset()
                ended += 1
            else:
                assert "terminal_observation" not in infos[i]
            np.testing.assert_array_equal(obs[i], last)
    assert ended >= 6


def test_time_limit_truncated_only_at_the_limit():
    venv = make_sb3_vec_env(3, seed=0, max_episode_steps=10, reset_noise_scale=0.0)
    hold = np.tile(venv.env.nominal.tau / np.asarray(venv.env.config.torque_limit), (3, 1))  # never falls
    venv.reset()
    for t in range(1, 26):
        _, _, dones, infos = venv.step(hold)
        assert dones.tolist() == [t % 10 == 0] * 3
        assert [info["TimeLimit.truncated"] for info in infos] == [t % 10 == 0] * 3
        assert [("terminal_observation" in info) for info in infos] == [t % 10 == 0] * 3
    # an episode that terminates on its last step is not a time-limit truncation
    falls = make_sb3_vec_env(8, seed=1, max_episode_steps=12)
    falls.reset()
    checked = 0
    for actions in random_actions(80, 8):
        _, _, dones, infos = falls.step(actions)
        for done, info in zip(dones, infos):
            if info["TimeLimit.truncated"]:
                assert done and info["reward_alive"] > 0.0  # healthy: not terminated
            checked += done
    assert checked > 0


def test_infos_carry_the_single_env_keys():
    venv = make_sb3_vec_env(2, seed=0)
    venv.reset()
    assert set(venv.reset_infos[0]) == set(STATE_KEYS)
    _, rewards, _, infos = venv.step(np.zeros((2, 2), dtype=np.float32))
    for reward, info in zip(rewards, infos):
        assert set(REWARD_KEYS + STATE_KEYS) | {"TimeLimit.truncated"} == set(info)
        assert np.float32(sum(info[key] for key in REWARD_KEYS)) == reward
        assert info["contact_force"].shape == (2,)


def test_step_info_columns_and_lean_infos_match_the_per_env_dicts():
    """``step_info`` holds every sub-env's info values (the ended ones' last step); with per_env_info=False the
    dicts carry only TimeLimit.truncated and terminal_observation, and everything else is the same."""
    full = make_sb3_vec_env(NUM_ENVS, seed=SEED, max_episode_steps=MAX_STEPS, **ENV_KWARGS)
    lean = make_sb3_vec_env(NUM_ENVS, seed=SEED, max_episode_steps=MAX_STEPS, per_env_info=False, **ENV_KWARGS)
    np.testing.assert_array_equal(full.reset(), lean.reset())
    ended = 0
    for actions in random_actions(STEPS):
        obs, rewards, dones, infos = full.step(actions)
        lean_obs, lean_rewards, lean_dones, lean_infos = lean.step(actions)
        np.testing.assert_array_equal(obs, lean_obs)
        np.testing.assert_array_equal(rewards, lean_rewards)
        np.testing.assert_array_equal(dones, lean_dones)
        for i in range(NUM_ENVS):
            expected = {k: infos[i][k] for k in ("TimeLimit.truncated", "terminal_observation") if k in infos[i]}
            assert_info_equal(lean_infos[i], expected)
            for key in set(infos[i]) - {"terminal_observation"}:
                for columns in (full.step_info, lean.step_info):
                    value = columns[key][i]
                    assert (np.array_equal(value, infos[i][key]) if isinstance(value, np.ndarray) else value == infos[i][key]), key
        ended += int(dones.sum())
    assert ended >= 6


def test_per_env_info_must_be_a_bool():
    with pytest.raises(TypeError, match="per_env_info"):
        make_sb3_vec_env(2, per_env_info="no")
    with pytest.raises(TypeError, match="per_env_info"):
        LegStanceVecEnv(make_sb3_vec_env(2).env, per_env_info=1)


def test_reward_terms_logger_reads_the_columns_as_it_reads_the_dicts():
    """The logger's rollout means from the adapter's columns (found under VecNormalize) equal those it
    computes from the per-env dicts of another kind of VecEnv."""
    from train.callbacks import RewardTermsLogger, leg_adapter

    lean = VecNormalize(make_sb3_vec_env(NUM_ENVS, seed=SEED, max_episode_steps=MAX_STEPS, per_env_info=False, **ENV_KWARGS))
    assert isinstance(leg_adapter(lean), LegStanceVecEnv) and leg_adapter(dummy_vec_env(1)) is None
    ref = dummy_vec_env()
    ref.seed(SEED)
    logged = []
    for venv in (lean, ref):
        logger = RewardTermsLogger(REWARD_KEYS)
        logger.model = SimpleNamespace(get_env=lambda venv=venv: venv)  # what training_env reads
        logger.locals = {}
        logger._on_rollout_start()
        venv.reset()
        for actions in random_actions(40):
            logger.locals["infos"] = venv.step(actions)[3]
            logger._on_step()
        logged.append({key: total / logger._count for key, total in logger._sums.items()})
    assert logged[0].keys() == logged[1].keys() and len(logged[0]) == len(REWARD_KEYS) + 2
    for key in logged[0]:
        assert logged[0][key] == pytest.approx(logged[1][key], rel=1e-12, abs=1e-12), key


# ------------------------------------------------------------------ SB3 wrappers and PPO


def test_vec_normalize_round_trips(tmp_path):
    venv = VecNormalize(make_sb3_vec_env(NUM_ENVS, seed=SEED, max_episode_steps=MAX_STEPS), gamma=0.99)
    venv.reset()
    for actions in random_actions(60):
        _, _, dones, infos = venv.step(actions)
        for i in np.flatnonzero(dones):  # the terminal observation is normalised as well
            assert np.abs(infos[i]["terminal_observation"]).max() <= venv.clip_obs
    path = tmp_path / "vecnormalize.pkl"
    venv.save(str(path))
    loaded = VecNormalize.load(str(path), make_sb3_vec_env(NUM_ENVS, max_episode_steps=MAX_STEPS))
    for name in ("mean", "var", "count"):
        np.testing.assert_array_equal(getattr(loaded.obs_rms, name), getattr(venv.obs_rms, name))
        np.testing.assert_array_equal(getattr(loaded.ret_rms, name), getattr(venv.ret_rms, name))
    raw = venv.get_original_obs()
    np.testing.assert_array_equal(loaded.normalize_obs(raw), venv.normalize_obs(raw))
    assert loaded.observation_space == venv.observation_space and loaded.num_envs == NUM_ENVS


def test_vec_monitor_records_episodes():
    venv = VecMonitor(make_sb3_vec_env(NUM_ENVS, seed=SEED, max_episode_steps=MAX_STEPS))
    venv.reset()
    returns = np.zeros(NUM_ENVS)
    lengths = np.zeros(NUM_ENVS, dtype=int)
    episodes = 0
    for actions in random_actions(60):
        _, rewards, dones, infos = venv.step(actions)
        returns += rewards
        lengths += 1
        for i in np.flatnonzero(dones):
            episode = infos[i]["episode"]
            assert episode["l"] == lengths[i] <= MAX_STEPS
            assert episode["r"] == pytest.approx(returns[i], abs=1e-4)
            returns[i], lengths[i] = 0.0, 0
            episodes += 1
    assert episodes >= NUM_ENVS


def test_vec_check_nan_raises_nothing():
    venv = VecCheckNan(make_sb3_vec_env(NUM_ENVS, seed=SEED, max_episode_steps=MAX_STEPS), raise_exception=True)
    venv.reset()
    for actions in random_actions(60):
        venv.step(actions)


def test_ppo_trains_on_the_adapter():
    venv = VecCheckNan(VecNormalize(VecMonitor(make_sb3_vec_env(8, seed=0, max_episode_steps=50))), raise_exception=True)
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=2, seed=0, device="cpu")
    model.learn(512)
    assert model.num_timesteps == 512 and len(model.ep_info_buffer) > 0
    actions, _ = model.predict(venv.reset(), deterministic=True)
    assert actions.shape == (8, 2)


# ------------------------------------------------------------------ the rest of the VecEnv API


def test_seed_and_set_options_reach_the_next_reset():
    venv = make_sb3_vec_env(3)
    assert venv.seed(5) == [5, 6, 7]
    twin = LegVectorEnv(3)
    np.testing.assert_array_equal(venv.reset(), twin.reset(seed=5)[0])
    np.testing.assert_array_equal(venv.reset(), twin.reset()[0])  # seeds are used once, then generators continue
    q = venv.env.nominal.q + np.array([0.0, 0.0, 0.05, -0.1, 0.2])
    venv.set_options({"qpos": q})
    single_obs, _ = gym.make(ENV_ID).reset(options={"qpos": q})
    np.testing.assert_array_equal(venv.reset(), np.tile(single_obs, (3, 1)))


def test_attributes_and_methods_come_from_the_shared_batch():
    venv = make_sb3_vec_env(3)
    assert venv.get_attr("observation_space") == [venv.observation_space] * 3  # single-env spaces
    assert venv.get_attr("dt", indices=[0, 2]) == [0.01, 0.01]
    assert venv.has_attr("params") and not venv.has_attr("no_such_thing")
    venv.set_attr("render_envs", 2)
    assert venv.env.render_envs == 2
    with pytest.raises(ValueError, match="share"):
        venv.set_attr("render_envs", 1, indices=[0])
    results = venv.env_method("reset", seed=1, indices=[1])  # one call on the batch, one result per index
    assert len(results) == 1
    np.testing.assert_array_equal(results[0][0], LegVectorEnv(3).reset(seed=1)[0])
    assert venv.env_is_wrapped(Monitor) == [False, False, False]
    venv.close()


def test_render_and_get_images():
    venv = make_sb3_vec_env(4, seed=0, render_mode="rgb_array", width=96, height=64, render_envs=2)
    venv.reset()
    images = venv.get_images()
    assert len(images) == 2 and images[0].shape == (64, 96, 3)
    assert venv.render().shape[2] == 3
    with pytest.warns(UserWarning):
        assert make_sb3_vec_env(2).get_images() == [None, None]


def test_needs_a_same_step_env():
    with pytest.raises(ValueError, match="SAME_STEP"):
        LegStanceVecEnv(LegVectorEnv(2))
    with pytest.raises(TypeError):
        LegStanceVecEnv(gym.make(ENV_ID))
    with pytest.raises(ValueError):
        make_sb3_vec_env(2, autoreset_mode=AutoresetMode.NEXT_STEP)


def test_set_config_reaches_the_vector_env_by_env_method():
    """A curriculum's path (``train.callbacks.ConfigSchedule``): VecEnv.env_method to ``LegVectorEnv.set_config``."""
    from leg_env.tasks.base import Obs

    venv = make_sb3_vec_env(4, seed=0, env_id="leg_env/PlanarLegHop-v4", command_range=[0.02, 0.15])
    venv.env_method("set_config", command_range=(0.1, 0.1))
    assert np.allclose(venv.reset()[:, Obs.command], 0.1)
    with pytest.raises(ValueError, match="would widen"):
        venv.env_method("set_config", command_range=(0.1, 0.2))
