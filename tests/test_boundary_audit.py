"""What a hostile audit of the compiled boundary found, each held by a test that fails on the code before its fix.

The audit (one-argument mutations of every entry point, extreme struct values, sanitizers, threads, fork, pickling)
found no crash, hang or memory error; these are the smaller defects it found: a value that escaped the float32
check, ranges and settings that overflowed or disagreed with what the parameters accept, a counter that could
wrap, aliased arrays, and three ways the native vector env differed from Gymnasium's ``SyncVectorEnv``.
"""
from __future__ import annotations

import threading

import gymnasium as gym
import numpy as np
import pytest

import leg_env
from leg_env._core import kernels
from leg_env.physics import LegParams, static_equilibrium, step_inplace

HOP, PUSH, STANCE = "leg_env/PlanarLegHop-v4", "leg_env/PlanarLegPush-v2", "leg_env/PlanarLegStance-v0"


def test_the_hop_refuses_a_robot_without_gravity():
    """The hop's apex is where gravity stops the rise: without it the task has no meaning (and its last-apex column
    divided by m g), so ``g = 0`` is refused by name, for the env's robot, a drawn one and one given at a reset."""
    with pytest.raises(ValueError, match="g"):
        gym.make(HOP, params={"g": 0.0})
    with pytest.raises(ValueError, match="'g'"):
        gym.make(HOP, randomize={"g": ("range", 0.0, 0.0)})
    env = gym.make(HOP).unwrapped
    with pytest.raises(ValueError, match="'g'"):
        env.reset(options={"params": {"g": 0.0}})
    gym.make(STANCE, params={"g": 0.0}).reset(seed=0)  # the balance has a meaning without gravity: still accepted


def test_every_observation_column_is_checked_for_float32_after_it_is_written():
    """A finite state whose observation does not fit float32 is a numerical failure, whichever column overflows: the
    hop's last-apex column (written after the check) gave ``inf`` with ``numerical_failure`` false."""
    envs = gym.make_vec(HOP, num_envs=2, vectorization_mode="vector_entry_point")
    envs.reset(seed=0)
    before = envs._obs.copy()
    envs._state["apex"][0] = 1e39  # beyond float32: the column the hop writes at every step
    obs, _, terminated, _, info = envs.step(np.zeros((2, 2), dtype=np.float32))
    assert np.isfinite(obs).all(), obs[0]
    assert info["numerical_failure"][0] and terminated[0] and not info["numerical_failure"][1]
    np.testing.assert_array_equal(obs[0], before[0])  # the last good observation


def test_a_randomised_g_is_zero_or_one_that_legparams_accepts():
    """``randomize={"g": ("range", 0, 1e-300)}`` drew values of ``g`` that ``LegParams`` refuses (``0 < g < 1e-6``)."""
    with pytest.raises(ValueError, match="'g'"):
        gym.make(STANCE, randomize={"g": ("range", 0.0, 1e-300)})
    with pytest.raises(ValueError, match="'g'"):
        gym.make(STANCE, randomize={"g": ("scale", 0.0, 1.0)})
    with pytest.raises(ValueError):
        LegParams(g=1e-300)
    gym.make(STANCE, randomize={"g": ("range", 0.0, 0.0)}).reset(seed=0)  # no gravity at all: accepted
    gym.make(STANCE, randomize={"g": ("scale", 0.9, 1.1)}).reset(seed=0)


@pytest.mark.parametrize("env_id, kwargs, field", [(HOP, {"command_period": 1e9}, "command_period"),
                                                   (PUSH, {"dt": 1e-12}, "push_duration")])
def test_a_setting_of_more_control_steps_than_an_int32_is_a_value_error_naming_it(env_id, kwargs, field):
    """``command_period=1e9`` (hop) and ``dt=1e-12`` (push) ended in numpy's bare ``OverflowError``."""
    with pytest.raises(ValueError, match=field):
        gym.make(env_id, **kwargs)


def test_the_push_step_counter_stops_instead_of_wrapping():
    """The push task's int32 step counter overflowed after 2^31 - 1 steps of one episode (undefined behaviour in C;
    the pushes then stopped): it stops at the largest int32."""
    envs = gym.make_vec(PUSH, num_envs=1, max_episode_steps=None, vectorization_mode="vector_entry_point")
    envs.reset(seed=0)
    top = np.iinfo(np.int32).max
    envs._state["steps"][0] = top - 2
    for _ in range(5):
        envs.step(np.zeros((1, 2), dtype=np.float32))
        assert envs._state["steps"][0] >= top - 1
    assert envs._state["steps"][0] == top


def test_an_array_written_may_not_share_memory_with_another_argument():
    """``step_inplace(q, q, ...)`` (the same array as ``q`` and ``qd``) was accepted and returned a wrong state; every
    entry point refuses a written array that overlaps another of its arguments, naming both, and changes nothing."""
    p = LegParams()
    q0, tau, _ = static_equilibrium(p)
    q = np.tile(q0, (2, 1))
    kept = q.copy()
    with pytest.raises(ValueError, match="q and qd"):
        step_inplace(q, q, np.tile(tau, (2, 1)), p.array, np.zeros((2, 2)), 0.01, 2, 0.02, True, np.zeros((2, 2)))
    np.testing.assert_array_equal(q, kept)
    buffer = np.zeros(7)  # out and lam_mean overlapping by one value
    with pytest.raises(ValueError, match="share memory"):
        kernels.com(q, np.zeros((2, 5)), p.array, buffer[:4], buffer[3:7])
    M = np.zeros((2, 25))
    with pytest.raises(ValueError, match="q and M"):
        kernels.mass_matrix(M.reshape(-1)[:10].reshape(2, 5), p.array, M)  # q inside the output's bytes


def test_the_vector_env_draws_each_seed_before_its_first_reset_as_sync_does():
    """``np_random_seed`` before the first reset was ``(None, None, None)`` where ``SyncVectorEnv`` draws the seeds; a
    reset without a seed then goes on from the generators drawn."""
    for mode in ("vector_entry_point", "sync"):
        envs = gym.make_vec(STANCE, num_envs=3, vectorization_mode=mode)
        seeds = envs.np_random_seed
        assert len(seeds) == 3 and all(isinstance(s, int) for s in seeds), (mode, seeds)
        envs.reset()
        assert envs.np_random_seed == seeds, mode


def test_one_number_as_the_actions_is_a_type_error_as_in_sync():
    """``step(0)`` raised ``ValueError`` where ``SyncVectorEnv`` raises ``TypeError``."""
    for mode in ("vector_entry_point", "sync"):
        envs = gym.make_vec(STANCE, num_envs=2, vectorization_mode=mode)
        envs.reset(seed=0)
        with pytest.raises(TypeError):
            envs.step(0)


def test_a_second_thread_stepping_the_same_vector_env_is_refused():
    """One vector env stepped from two Python threads at once neither raised nor serialised, and every row ended up
    different from a sequential run: the second caller is refused with a clear error while the first steps."""
    envs = gym.make_vec(STANCE, num_envs=50_000, vectorization_mode="vector_entry_point")  # a step of tens of ms, GIL released
    envs.reset(seed=0)
    actions = np.zeros((50_000, 2), dtype=np.float32)
    start, errors = threading.Barrier(2), []

    def stepper():
        start.wait()
        for _ in range(8):
            try:
                envs.step(actions)
            except RuntimeError as e:
                errors.append(str(e))

    threads = [threading.Thread(target=stepper) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors and all("another thread" in e for e in errors), errors[:1]
    assert envs.elapsed_steps.max() == 16 - len(errors)  # every step taken was taken whole, once


def test_num_envs_has_one_bound_checked_first_and_named():
    """``num_envs`` was accepted up to 2^31 - 1 while the generator table stops at 2^26: the one bound is the table's,
    checked before anything is made, and the error names ``num_envs``."""
    from leg_env.envs.vector import MAX_ENVS

    assert MAX_ENVS == kernels.MAX_ROWS == 2**26
    with pytest.raises(ValueError, match="num_envs"):
        gym.make_vec(STANCE, num_envs=kernels.MAX_ROWS + 1, vectorization_mode="vector_entry_point")
    with pytest.raises(ValueError, match="n must be"):
        kernels.Generators(kernels.MAX_ROWS + 1)
    assert leg_env.ENV_ID == STANCE
