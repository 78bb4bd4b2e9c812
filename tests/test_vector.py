"""The natively batched VectorEnv: registration, parity with single envs, seeding, errors, rendering."""

import os
import pickle
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode

import leg_env
from leg_env.envs.single import LegEnv
from leg_env.envs.vector import LegVectorEnv
from leg_env.tasks.stance import TASK as STANCE

REWARD_KEYS = STANCE.reward_keys

ENV_ID = leg_env.ENV_ID
NUM_ENVS = 4
SEED = 11
STEPS = 150
MAX_STEPS = 25  # short episodes, so truncations happen alongside terminations
ACTION_SCALE = 1.5  # beyond the limits: exercises clipping
ACTION_BIAS = (0.6, -0.6)  # pushes the robot over: episodes also terminate
AUTORESET_MODES = [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP]
# non-default arguments, so that a dropped argument shows up as a mismatch
ENV_KWARGS = dict(params={"m_b": 9.0, "l2": 0.55}, reset_noise_scale=0.05, ctrl_cost_weight=0.02, torque_limit=45.0)


def random_actions(steps: int, n: int, seed: int = 0) -> np.ndarray:
    noise = ACTION_SCALE * np.random.default_rng(seed).uniform(-1.0, 1.0, size=(steps, n, 2))
    return (noise + np.asarray(ACTION_BIAS)).astype(np.float32)


def make_pair(mode: AutoresetMode, n: int = NUM_ENVS, **kwargs):
    """Ours (by make_vec's default) and Gymnasium's SyncVectorEnv over single envs, same arguments."""
    kwargs = {**ENV_KWARGS, **kwargs}
    ours = gym.make_vec(ENV_ID, num_envs=n, autoreset_mode=mode, max_episode_steps=MAX_STEPS, **kwargs)
    sync = gym.make_vec(
        ENV_ID, num_envs=n, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode},
        max_episode_steps=MAX_STEPS, **kwargs,
    )  # fmt: skip
    return ours, sync


def assert_same(a, b, what: str) -> None:
    assert data_equivalence(a, b, exact=True), f"{what} differ:\n{a}\n{b}"


def as_sync_info(info: dict) -> dict:
    """Our info as SyncVectorEnv shapes it: it drops the reward terms on a step where no sub-env stepped."""
    if "_reward_alive" in info and not info["_reward_alive"].any():
        return {k: v for k, v in info.items() if k.lstrip("_") not in REWARD_KEYS}
    return info


# ------------------------------------------------------------------ registration and spaces


# Gymnasium marks every id with a newer version registered (PlanarLegBalance-v1) as out of date: its one notice
@pytest.mark.filterwarnings("error", "ignore:.*PlanarLegStance-v0 is out of date:DeprecationWarning")
def test_make_vec_uses_the_native_class_by_default():
    envs = gym.make_vec(ENV_ID, num_envs=3)
    assert type(envs) is LegVectorEnv
    assert envs.num_envs == 3 and envs.max_episode_steps == 1000
    assert envs.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    assert envs.spec.id == ENV_ID
    same = gym.make_vec(ENV_ID, num_envs=2, autoreset_mode="SameStep", max_episode_steps=7, dt=0.02)
    assert same.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP and same.max_episode_steps == 7
    assert same.metadata["render_fps"] == 50 and same.dt == 0.02


def test_spaces_and_metadata_match_the_single_env():
    envs = LegVectorEnv(5, **ENV_KWARGS)
    single = gym.make(ENV_ID, **ENV_KWARGS)
    assert envs.single_observation_space == single.observation_space
    assert envs.single_action_space == single.action_space
    assert envs.observation_space.shape == (5, 12) and envs.action_space.shape == (5, 2)
    assert envs.metadata["render_fps"] == single.metadata["render_fps"]
    obs, info = envs.reset(seed=0)
    assert envs.observation_space.contains(obs)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"num_envs": 0},
        {"num_envs": 2.0},
        {"max_episode_steps": 0},
        {"autoreset_mode": "EveryStep"},
        {"render_mode": "human"},
        {"render_envs": 0},
        {"config": {"not_a_setting": 1.0}},
        {"torque_limit": 1.0},  # cannot hold the nominal posture
    ],
)
def test_bad_arguments_raise(kwargs):
    kwargs = {"num_envs": 2, **kwargs}
    with pytest.raises(ValueError):
        LegVectorEnv(**kwargs)


def test_unknown_keyword_argument_is_a_type_error():
    with pytest.raises(TypeError, match="unexpected keyword argument 'not_a_setting'"):
        LegVectorEnv(2, not_a_setting=1.0)


# ------------------------------------------------------------------ parity


@pytest.mark.parametrize("mode", AUTORESET_MODES)
def test_sub_env_i_is_a_single_env_seeded_seed_plus_i(mode):
    """The bar: each row matches a single env (TimeLimit) reset with seed + i, across autoresets."""
    envs = LegVectorEnv(NUM_ENVS, autoreset_mode=mode, max_episode_steps=MAX_STEPS, **ENV_KWARGS)
    singles = [gym.make(ENV_ID, max_episode_steps=MAX_STEPS, **ENV_KWARGS) for _ in range(NUM_ENVS)]
    obs, _ = envs.reset(seed=SEED)
    for i, env in enumerate(singles):
        single_obs, _ = env.reset(seed=SEED + i)
        np.testing.assert_array_equal(obs[i], single_obs)
    pending = [False] * NUM_ENVS  # NEXT_STEP: this single env resets instead of stepping
    ends = {"terminated": 0, "truncated": 0}
    for actions in random_actions(STEPS, NUM_ENVS):
        obs, reward, terminated, truncated, info = envs.step(actions)
        for i, env in enumerate(singles):
            if pending[i]:
                single_obs, _ = env.reset()
                assert (reward[i], terminated[i], truncated[i]) == (0.0, False, False)
                assert not info["_reward_alive"][i] and info["reward_alive"][i] == 0.0
                np.testing.assert_array_equal(obs[i], single_obs)
                pending[i] = False
                continue
            single_obs, single_reward, single_term, single_trunc, single_info = env.step(actions[i])
            assert (reward[i], terminated[i], truncated[i]) == (single_reward, single_term, single_trunc)
            step_info = info if mode == AutoresetMode.NEXT_STEP or not (single_term or single_trunc) else info["final_info"]
            for key in REWARD_KEYS + ("normal_force", "base_drift", "foot_error", "unilateral_violation"):
                assert step_info[key][i] == single_info[key], key
            np.testing.assert_array_equal(step_info["contact_force"][i], single_info["contact_force"])
            ends["terminated"] += single_term
            ends["truncated"] += single_trunc
            if single_term or single_trunc:
                if mode == AutoresetMode.SAME_STEP:
                    np.testing.assert_array_equal(info["final_obs"][i], single_obs)
                    single_obs, _ = env.reset()
                else:
                    pending[i] = True
            np.testing.assert_array_equal(obs[i], single_obs)
    assert ends["terminated"] >= 3 and ends["truncated"] >= 3, ends


@pytest.mark.parametrize("mode", AUTORESET_MODES)
def test_everything_equals_sync_vector_env(mode):
    """Observations, rewards, flags and the whole info (keys, values, masks, final_*) equal SyncVectorEnv's."""
    ours, sync = make_pair(mode)
    assert_same(ours.reset(seed=SEED), sync.reset(seed=SEED), "reset")
    ended = 0
    for t, actions in enumerate(random_actions(STEPS, NUM_ENVS, seed=1)):
        step_ours, step_sync = ours.step(actions), sync.step(actions)
        step_ours = (*step_ours[:4], as_sync_info(step_ours[4]))
        for name, a, b in zip(("obs", "reward", "terminated", "truncated", "info"), step_ours, step_sync):
            assert_same(a, b, f"step {t} {name}")
        ended += int(np.sum(step_ours[2] | step_ours[3]))
    assert ended >= 6


@pytest.mark.parametrize("mode", AUTORESET_MODES)
def test_all_sub_envs_ending_together(mode):
    """Every sub-env truncates on the same step: SyncVectorEnv then drops the reward keys, we keep them."""
    ours, sync = make_pair(mode, reset_noise_scale=0.0)
    hold = np.tile(ours.nominal.tau / np.asarray(ours.config.torque_limit), (NUM_ENVS, 1))
    assert_same(ours.reset(seed=SEED), sync.reset(seed=SEED), "reset")
    period = MAX_STEPS + 1 if mode == AutoresetMode.NEXT_STEP else MAX_STEPS  # NEXT_STEP spends a step resetting
    for t in range(1, 2 * MAX_STEPS + 3):
        step_ours, step_sync = ours.step(hold), sync.step(hold)
        assert_same((*step_ours[:4], as_sync_info(step_ours[4])), step_sync, f"step {t}")
        assert step_ours[3].all() == (t % period == MAX_STEPS % period)
        assert not step_ours[2].any()
        if mode == AutoresetMode.NEXT_STEP and t == MAX_STEPS + 1:  # everyone resets
            assert "reward_alive" not in step_sync[4] and not step_ours[4]["_reward_alive"].any()


def test_partial_reset_with_reset_mask_equals_sync_vector_env():
    ours, sync = make_pair(AutoresetMode.DISABLED)
    assert_same(ours.reset(seed=SEED), sync.reset(seed=SEED), "reset")
    for t, actions in enumerate(random_actions(STEPS, NUM_ENVS, seed=2)):
        out_ours, out_sync = ours.step(actions), sync.step(actions)
        assert_same((*out_ours[:4], as_sync_info(out_ours[4])), out_sync, f"step {t}")
        ended = out_ours[2] | out_ours[3]
        if ended.any():
            with pytest.raises(ValueError, match="DISABLED"):
                ours.step(actions)
            options = {"reset_mask": ended}
            assert_same(ours.reset(options=dict(options)), sync.reset(options=dict(options)), f"reset at {t}")


def test_gymnasium_vector_wrappers_see_the_same_episodes():
    ours, sync = make_pair(AutoresetMode.NEXT_STEP)
    ours, sync = gym.wrappers.vector.RecordEpisodeStatistics(ours), gym.wrappers.vector.RecordEpisodeStatistics(sync)
    ours.reset(seed=SEED)
    sync.reset(seed=SEED)
    for actions in random_actions(60, NUM_ENVS, seed=3):
        info_ours, info_sync = ours.step(actions)[-1], sync.step(actions)[-1]
        assert ("episode" in info_ours) == ("episode" in info_sync)
        if "episode" in info_ours:
            for key in ("r", "l"):
                np.testing.assert_array_equal(info_ours["episode"][key], info_sync["episode"][key])
            np.testing.assert_array_equal(info_ours["_episode"], info_sync["_episode"])


# ------------------------------------------------------------------ episode bookkeeping


def test_reward_is_the_sum_of_its_terms_and_truncation_is_at_the_limit():
    hold = LegVectorEnv(3, max_episode_steps=10, reset_noise_scale=0.0)
    obs, _ = hold.reset(seed=0)
    action = np.tile(hold.nominal.tau / np.asarray(hold.config.torque_limit), (3, 1))
    for t in range(1, 31):
        obs, reward, terminated, truncated, info = hold.step(action)
        np.testing.assert_array_equal(reward, sum(info[key] for key in REWARD_KEYS))
        assert not terminated.any()
        assert truncated.all() == (t % 11 == 10) and (truncated.any() == truncated.all())
        assert hold.elapsed_steps.tolist() == [0 if t % 11 == 0 else t % 11] * 3


def test_seeding_is_reproducible():
    a, b = LegVectorEnv(3, **ENV_KWARGS), LegVectorEnv(3, **ENV_KWARGS)
    obs_a, _ = a.reset(seed=5)
    obs_b, _ = b.reset(seed=[5, 6, 7])
    np.testing.assert_array_equal(obs_a, obs_b)
    assert len({row.tobytes() for row in obs_a}) == 3  # the sub-envs differ
    for actions in random_actions(80, 3):
        assert_same(a.step(actions), b.step(actions), "step")
    # seed=None continues each generator, as for a single env
    assert_same(a.reset(), b.reset(), "unseeded reset")
    obs_c, _ = a.reset(seed=6)
    np.testing.assert_array_equal(obs_c[:2], obs_b[1:])
    fresh = [LegVectorEnv(3).reset()[0] for _ in range(2)]
    assert not np.array_equal(*fresh)


def test_explicit_start_state_and_reset_mask():
    envs = LegVectorEnv(3)
    single = LegEnv()
    q = single.nominal.q + np.array([0.0, 0.0, 0.05, -0.1, 0.2])
    qd = np.array([0.0, 0.0, 0.1, 0.0, -0.2])
    obs, info = envs.reset(options={"qpos": q, "qvel": qd})
    single_obs, single_info = single.reset(options={"qpos": q, "qvel": qd})
    for i in range(3):
        np.testing.assert_array_equal(obs[i], single_obs)
        np.testing.assert_array_equal(info["contact_force"][i], single_info["contact_force"])
    envs.step(np.zeros((3, 2)))
    before, _, _ = envs.state
    obs, info = envs.reset(seed=1, options={"reset_mask": np.array([False, True, False])})
    after, _, _ = envs.state
    np.testing.assert_array_equal(after[[0, 2]], before[[0, 2]])
    assert info["_normal_force"].tolist() == [False, True, False] and info["normal_force"][0] == 0.0
    np.testing.assert_array_equal(obs[1], single.reset(seed=2)[0])
    with pytest.raises(ValueError):
        envs.reset(options={"qpos": np.zeros(4)})
    with pytest.raises(ValueError):
        envs.reset(options={"reset_mask": np.zeros(3, dtype=bool)})
    with pytest.raises(ValueError):
        envs.reset(options={"flying": True})


@pytest.mark.parametrize(
    "actions, match",
    [
        (np.zeros((3, 2)), r"shape"),
        (np.zeros((4, 3)), r"shape"),
        ("fast", r"array of numbers"),
        (np.array([[0.0, 0.0], [0.0, 0.0], [np.nan, 0.0], [0.0, np.inf]]), r"sub-env\(s\) \[2, 3\]"),
    ],
)
def test_bad_actions_raise_and_leave_the_state_untouched(actions, match):
    envs, twin = LegVectorEnv(4), LegVectorEnv(4)
    envs.reset(seed=3)
    twin.reset(seed=3)
    with pytest.raises(ValueError, match=match):
        envs.step(actions)
    for a, b in zip(envs.state, twin.state):
        np.testing.assert_array_equal(a, b)
    assert envs.elapsed_steps.tolist() == [0, 0, 0, 0]
    good = random_actions(1, 4)[0]
    assert_same(envs.step(good), twin.step(good), "step after a rejected action")


def test_pickle_keeps_arguments_and_state():
    envs = LegVectorEnv(3, autoreset_mode=AutoresetMode.SAME_STEP, max_episode_steps=9, **ENV_KWARGS)
    envs.reset(seed=4)
    actions = random_actions(40, 3)
    for a in actions[:20]:
        envs.step(a)
    copy = pickle.loads(pickle.dumps(envs))
    assert copy.params == envs.params and copy.config == envs.config and copy.max_episode_steps == 9
    for a in actions[20:]:
        assert_same(envs.step(a), copy.step(a), "step after unpickling")


def test_bit_generator_rows_draw_what_python_draws():
    """Compiled draws equal ``rng.random`` and advance the generators alike; other bit generators
    fall back to Python; pickling keeps the streams."""
    from leg_env.envs.generators import BitGeneratorRows

    def gens():
        return [np.random.Generator(np.random.PCG64(s)) for s in range(5)] + [np.random.Generator(np.random.Philox(9))]

    rows_obj, python = BitGeneratorRows(6), gens()
    for i, g in enumerate(gens()):
        rows_obj[i] = g
    for rows in (np.array([0, 2, 4]), np.array([4, 0]), np.array([1, 5, 3])):  # the last one mixes in Philox
        out = np.empty((rows.size, 6))
        rows_obj.draw(rows, out)
        expected = np.array([python[i].random(6) for i in rows.tolist()])
        np.testing.assert_array_equal(out, expected)
    copy = pickle.loads(pickle.dumps(rows_obj))
    a, b = np.empty((5, 3)), np.empty((5, 3))
    rows_obj.draw(np.arange(5), a)
    copy.draw(np.arange(5), b)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, np.array([python[i].random(3) for i in range(5)]))


# ------------------------------------------------------------------ rendering


def test_rgb_array_frames_of_the_first_sub_envs():
    envs = LegVectorEnv(5, render_mode="rgb_array", width=160, height=120, render_envs=3)
    single = LegEnv(render_mode="rgb_array", width=160, height=120)
    envs.reset(seed=0)
    single.reset(seed=1)
    frames = envs.render()
    assert isinstance(frames, tuple) and len(frames) == 3
    for frame in frames:
        assert frame.shape == (120, 160, 3) and frame.dtype == np.uint8
        assert frame.std() > 10.0  # not blank
    np.testing.assert_array_equal(frames[1], single.render())
    with pytest.warns(UserWarning, match="render_mode"):
        assert LegVectorEnv(2).render() is None


# ------------------------------------------------------------------- threads

_THREADED_SCRIPT = """
import numpy as np, gymnasium as gym, leg_env
outs = []
for threads in (1, 2):
    env = gym.make_vec("leg_env/PlanarLegStance-v0", num_envs=257, num_threads=threads)
    obs, _ = env.reset(seed=5)
    rng = np.random.default_rng(5)
    rows = [obs]
    for _ in range(200):
        obs, rew, term, trunc, info = env.step(rng.uniform(-1.0, 1.0, size=(257, 2)))
        rows += [obs, rew, term, trunc, info["normal_force"]]
    outs.append(rows)
same = all(np.array_equal(a, b) for a, b in zip(*outs))
print("SAME" if same else "DIFFERENT")
"""


def test_threaded_kernel_is_bitwise_the_serial_one():
    """Two numba threads split the batch; every output equals the one-thread run exactly."""
    env = dict(os.environ, NUMBA_NUM_THREADS="2")
    out = subprocess.run([sys.executable, "-c", _THREADED_SCRIPT], env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().endswith("SAME"), out.stdout


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2", 10_000])
def test_bad_num_threads_raise(bad):
    with pytest.raises(ValueError, match="num_threads"):
        LegVectorEnv(num_envs=2, num_threads=bad)


def test_np_random_seed_and_reset_mask_errors_follow_sync_vector_env():
    """``np_random_seed`` is the tuple of each sub-env's seed and a reset mask of the wrong type is a TypeError,
    as in Gymnasium's ``SyncVectorEnv``."""
    n = 3
    native = gym.make_vec("leg_env/PlanarLegStance-v0", num_envs=n, vectorization_mode="vector_entry_point")
    sync = gym.make_vec("leg_env/PlanarLegStance-v0", num_envs=n, vectorization_mode="sync")
    for envs in (native, sync):
        envs.reset(seed=5)
    assert native.np_random_seed == sync.np_random_seed == (5, 6, 7)
    mask = np.array([False, True, False])
    for envs in (native, sync):
        envs.reset(seed=[None, 40, None], options={"reset_mask": mask})
    assert native.np_random_seed == sync.np_random_seed == (5, 40, 7)
    # Gymnasium 1.2 (RLlib's pin) asserts in SyncVectorEnv where later releases raise TypeError / ValueError;
    # the native env raises the later releases' errors with either
    old_sync = tuple(int(v) for v in gym.__version__.split(".")[:2]) < (1, 3)
    for envs in (native, sync):
        lenient = envs is sync and old_sync
        with pytest.raises(AssertionError if lenient else TypeError):
            envs.reset(options={"reset_mask": [True, False, True]})
        with pytest.raises(AssertionError if lenient else TypeError):
            envs.reset(options={"reset_mask": np.ones(n, dtype=np.int64)})
        with pytest.raises(AssertionError if lenient else ValueError):
            envs.reset(options={"reset_mask": np.ones(n + 1, dtype=np.bool_)})


def test_info_names_each_contact_mode_and_refuses_a_corrupt_one_without_writing_it():
    """The compiled info pass gives each robot's mode, which the builder names; a mode outside 0..3 in ``out`` (a
    corrupted array) is a ValueError, and a spec row that would read or write outside its row or block is refused by
    the pass, never a crash."""
    from leg_env._core import kernels
    from leg_env.physics.contact import MODE_NAMES

    envs = gym.make_vec("leg_env/PlanarLegBalance-v1", num_envs=4)
    envs.reset(seed=0)
    envs.step(np.zeros((4, 2), dtype=np.float32))
    out, state = envs._out.copy(), envs._state.copy()
    out["mode"] = [0, 1, 2, 3]
    columns = envs._info_builder.columns(out, state)
    assert columns["contact_mode"].tolist() == [MODE_NAMES[m] for m in range(4)]
    out["mode"][2] = 4
    with pytest.raises(ValueError, match="contact mode"):
        envs._info_builder.columns(out, state)
    out["mode"][2] = -1
    with pytest.raises(ValueError, match="contact mode"):
        envs._info_builder.columns(out, state)
    out["mode"][2] = 2
    spec, counts, _ = envs._info_builder._column_spec(out.dtype, state.dtype, False)
    blocks = [np.empty((counts["d"], 4)), np.empty((counts["i"], 4), dtype=np.int64), np.empty((counts["?"], 4), dtype=np.bool_),
              np.empty((counts["v"], 4, 2))]
    for row, column, value in ((0, 1, out.dtype.itemsize - 4), (0, 0, 2), (0, 2, 7), (0, 3, counts["d"]), (0, 1, -8)):
        bad = spec.copy()
        bad[row, column] = value
        before = [b.copy() for b in blocks]
        with pytest.raises(ValueError, match="spec"):
            kernels.info_columns(bad, out, state, *blocks)
        assert all(np.array_equal(x, y, equal_nan=True) for x, y in zip(blocks, before))
    envs.close()


def test_contact_mode_is_the_mode_hybrid_step_takes():
    """``contact_mode``: each robot's mode as ``hybrid_step`` takes it (a copy); from the state, the torques and it the
    physics API's step gives the env's next state and mode; ``info`` names the same mode; a single env gives the
    vector's first robot's; the pinned foot sticks."""
    from leg_env.physics.contact import FLIGHT, MODE_NAMES, STICK
    from leg_env.physics.hybrid import hybrid_step
    from policies.hopper import HopperController

    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=3, vectorization_mode="vector_entry_point")
    single = gym.make("leg_env/PlanarLegHop-v4").unwrapped
    e, hopper = envs.unwrapped, HopperController()
    obs, _ = envs.reset(seed=7)
    single.reset(seed=7)
    seen = set()
    for _ in range(120):
        q, qd, anchor = e.state
        mode = e.contact_mode
        mode[:] = -1  # a copy: the env's own is untouched
        mode = e.contact_mode
        assert mode.dtype == np.int64 and single.contact_mode == mode[0]
        action = hopper.predict(obs)[0]
        obs, _, terminated, truncated, info = envs.step(action)
        single.step(action[0])
        assert not (terminated | truncated).any()
        r = hybrid_step(q, qd, info["torque"], e.params, e.config.mu, mode, anchor[:, 0], dt=e.config.dt,
                        substeps=e.config.substeps, max_angle=e.config.max_angle)
        np.testing.assert_array_equal(r.q, e.state[0])
        np.testing.assert_array_equal(r.mode, e.contact_mode)
        assert [MODE_NAMES[m] for m in e.contact_mode] == list(info["contact_mode"])
        seen |= set(e.contact_mode.tolist())
    assert {STICK, FLIGHT} <= seen
    envs.close()
    pinned = gym.make_vec("leg_env/PlanarLegStance-v0", num_envs=2, vectorization_mode="vector_entry_point")
    pinned.reset(seed=0)
    assert (pinned.unwrapped.contact_mode == STICK).all()
