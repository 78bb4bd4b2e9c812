"""The seeds ``leg_env.rllib`` gives the env runners' batches: injective, and what the sub-envs get.

These need no Ray (``leg_env.rllib`` imports it only to register), so they run in both venvs of
``make test``; the RLlib training itself is tested in ``tests/rllib/``.
"""

import itertools
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest

import leg_env
from leg_env.rllib import RunnerSeeds, make_env, on_environment_created, sub_env_seed

NUM_ENVS = 4


def named(worker_index: int, seed: int = 0, evaluation: bool = False, restart: int = 0) -> RunnerSeeds:
    """A runner's batch as RLlib builds it, named by the callback as RLlib calls it."""
    env = make_env({"num_envs": NUM_ENVS, "restart": restart})
    runner = SimpleNamespace(env=gym.wrappers.vector.DictInfoToList(env), config=SimpleNamespace(seed=seed, in_evaluation=evaluation))
    on_environment_created(env_runner=runner, env=env.unwrapped, env_context=SimpleNamespace(worker_index=worker_index))
    return env


def test_sub_env_seeds_are_injective():
    values = [0, 1, 2, 63]
    keys = list(itertools.product(values, [0, 1, 2], [False, True], values, values))
    seeds = [sub_env_seed(*key) for key in keys]
    assert len(set(seeds)) == len(keys)


def test_without_the_wrapper_runners_would_share_episodes():
    # why RunnerSeeds exists: RLlib resets runner w with config.seed + w, the batch seeds sub-env i with that + i
    obs1, _ = gym.make_vec(leg_env.ENV_ID, num_envs=NUM_ENVS).reset(seed=0 + 1)
    obs2, _ = gym.make_vec(leg_env.ENV_ID, num_envs=NUM_ENVS).reset(seed=0 + 2)
    np.testing.assert_array_equal(obs1[1:], obs2[:-1])


@pytest.mark.parametrize("bad", [dict(seed=-1), dict(restart=1 << 16), dict(worker_index=1 << 32), dict(vector_index=-1)])
def test_sub_env_seed_rejects_what_it_cannot_pack(bad):
    key = dict(seed=0, restart=0, evaluation=False, worker_index=0, vector_index=0) | bad
    with pytest.raises(ValueError, match=next(iter(bad))):
        sub_env_seed(**key)


def test_runners_draw_different_episodes_and_the_same_ones_again():
    # RLlib resets runner w with seed config.seed + w: runners 1 and 2 get seeds 1 and 2
    obs1, _ = named(1).reset(seed=1)
    obs2, _ = named(2).reset(seed=2)
    starts = np.concatenate([obs1, obs2])
    assert len({row.tobytes() for row in starts}) == 2 * NUM_ENVS  # no start state appears twice
    np.testing.assert_array_equal(named(1).reset(seed=1)[0], obs1)  # reproducible
    for other in (named(1, seed=1), named(1, evaluation=True), named(1, restart=1)):
        assert not np.isin(other.reset(seed=1)[0][:, 2], obs1[:, 2]).any()


def test_sub_env_i_is_the_single_env_with_its_seed():
    batch = named(3, seed=7)
    obs, _ = batch.reset(seed=10)
    for i, seed in enumerate(batch.seeds()):
        assert seed == sub_env_seed(7, 0, False, 3, i)
        single, _ = gym.make(leg_env.ENV_ID).reset(seed=seed)
        np.testing.assert_array_equal(obs[i], single)


def test_an_unnamed_batch_refuses_an_int_seed():
    env = make_env({"num_envs": 2})
    with pytest.raises(RuntimeError, match="on_environment_created"):
        env.reset(seed=0)
    env.reset(seed=None)  # fresh entropy is fine


def test_make_env_builds_the_native_batch_with_the_env_arguments():
    env = make_env({"env_id": leg_env.ENV_ID, "env_kwargs": {"contact": "unilateral"}, "num_envs": 3})
    assert type(env.unwrapped).__name__ == "LegVectorEnv"
    assert env.num_envs == 3 and env.single_observation_space.shape == (18,)
    with pytest.raises(ValueError, match="num_env"):
        make_env({"num_env": 3})
