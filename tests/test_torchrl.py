"""TorchRL: ``GymEnv`` on the registered id and ``GymWrapper`` on the native batch behave as on Gymnasium's own envs."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.vector import AutoresetMode
from torchrl.envs import GymEnv, GymWrapper
from torchrl.envs.utils import check_env_specs

import leg_env

ENV_ID = leg_env.ENV_ID
SEED = 3
NUM_ENVS = 4
STEPS = 100
MAX_STEPS = 25  # short episodes: the batched rollouts cross several resets
ENV_KWARGS = dict(reset_noise_scale=0.05, torque_limit=45.0)
ACTION_BIAS = (0.6, -0.6)  # pushes the robot over: episodes terminate as well as truncate


def actions(steps: int, shape: tuple, seed: int = 0) -> torch.Tensor:
    noise = 1.5 * np.random.default_rng(seed).uniform(-1.0, 1.0, size=(steps, *shape))
    return torch.as_tensor(noise + np.asarray(ACTION_BIAS), dtype=torch.float32)


class Replay:
    """A TorchRL policy that plays a fixed action sequence."""

    def __init__(self, sequence: torch.Tensor):
        self.sequence, self.t = sequence, 0

    def __call__(self, td):
        td.set("action", self.sequence[self.t])
        self.t += 1
        return td


def test_gym_env_makes_the_registered_env_and_matches_gymnasium():
    """GymEnv passes frameskip to gym.make and drops it on our TypeError; its rollout is the Gymnasium env's."""
    env = GymEnv(ENV_ID, **ENV_KWARGS)
    assert env.wrapper_frame_skip == 1  # frameskip was refused by the env and taken over by the wrapper
    check_env_specs(env, seed=SEED)
    sequence = actions(STEPS, (2,))
    td = env.rollout(STEPS, Replay(sequence), auto_reset=False, tensordict=env.reset(seed=SEED), break_when_any_done=True)

    ref = gym.make(ENV_ID, **ENV_KWARGS)
    obs, _ = ref.reset(seed=SEED)
    n = td.shape[0]
    assert 3 < n < STEPS  # the bias makes the episode terminate
    for t in range(n):
        np.testing.assert_array_equal(td["observation"][t].numpy(), obs)
        obs, reward, terminated, truncated, _ = ref.step(sequence[t].numpy())
        np.testing.assert_array_equal(td["next", "observation"][t].numpy(), obs)
        assert td["next", "reward"][t].item() == np.float32(reward)
        assert (td["next", "terminated"][t].item(), td["next", "truncated"][t].item()) == (terminated, truncated)
    assert terminated


def test_gym_env_frame_skip_is_taken_over_by_the_wrapper():
    env = GymEnv(ENV_ID, frame_skip=2, **ENV_KWARGS)
    assert env.wrapper_frame_skip == 2
    td = env.rollout(3)
    assert td["next", "observation"].shape == (3, 12)


@pytest.mark.parametrize("mode", [AutoresetMode.DISABLED, AutoresetMode.SAME_STEP])
def test_gym_wrapper_on_make_vec_equals_it_on_sync_vector_env(mode):
    """The native batch under GymWrapper gives TorchRL exactly what Gymnasium's SyncVectorEnv gives it, across resets."""
    kwargs = dict(num_envs=NUM_ENVS, max_episode_steps=MAX_STEPS, **ENV_KWARGS)
    ours = GymWrapper(gym.make_vec(ENV_ID, autoreset_mode=mode, **kwargs))
    sync = GymWrapper(gym.make_vec(ENV_ID, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, **kwargs))
    assert ours.batch_size == (NUM_ENVS,)
    check_env_specs(ours, seed=SEED)
    sequence = actions(STEPS, (NUM_ENVS, 2), seed=1)
    rollouts = []
    for env in (ours, sync):
        env.set_seed(SEED)
        rollouts.append(env.rollout(STEPS, Replay(sequence), break_when_any_done=False))
    a, b = rollouts
    assert a.shape == (NUM_ENVS, STEPS)
    for key in (("observation",), ("next", "observation"), ("next", "reward"), ("next", "terminated"), ("next", "truncated")):
        torch.testing.assert_close(a[key], b[key], rtol=0, atol=0, msg=f"{key} differ")
    done = a["next", "done"]
    assert a["next", "terminated"].sum() >= 3 and a["next", "truncated"].sum() >= 3
    # after an end, the next step starts a fresh episode (a reset state, not the final one)
    env_i, t = [int(k) for k in torch.nonzero(done[..., 0])[0]]
    assert not torch.equal(a["observation"][env_i, t + 1], a["next", "observation"][env_i, t])


def test_gym_wrapper_refuses_next_step_autoreset():
    """TorchRL's own rule: Gymnasium's default NEXT_STEP mode does not fit its reset model."""
    with pytest.raises(RuntimeError, match="SAME_STEP or DISABLED"):
        GymWrapper(gym.make_vec(ENV_ID, num_envs=2))
