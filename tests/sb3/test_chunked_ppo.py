"""``train.chunked_ppo.ChunkedPPO`` makes SB3's PPO update, whatever the chunk size."""

from __future__ import annotations

import json
from collections import deque
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO

from leg_env.sb3 import make_sb3_vec_env
from train.chunked_ppo import ChunkedPPO, FastTanh

N_ENVS, N_STEPS = 16, 32  # one rollout of 512 samples
LOGGED = ("train/policy_gradient_loss", "train/value_loss", "train/entropy_loss", "train/approx_kl", "train/clip_fraction", "train/loss")


def _one_update(algo, **kwargs):
    """A model of ``algo`` after one rollout of the hop task and one update (everything seeded alike)."""
    venv = make_sb3_vec_env(N_ENVS, seed=3, env_id="leg_env/PlanarLegHop-v4", per_env_info=False)
    settings = dict(n_steps=N_STEPS, batch_size=256, n_epochs=3, learning_rate=3e-3, seed=0, device="cpu",
                    policy_kwargs={"net_arch": [32, 32]})
    settings.update(kwargs)
    model = algo("MlpPolicy", venv, **settings)
    model.learn(N_ENVS * N_STEPS)
    venv.close()
    return model


def _parameters(model) -> dict:
    return {name: value.detach().clone() for name, value in model.policy.state_dict().items()}


@pytest.mark.parametrize(
    "settings",
    [
        {},
        {"ent_coef": 0.01, "clip_range_vf": 0.1, "normalize_advantage": False},
        {"target_kl": 1e-4},  # stops early, on the whole minibatch's KL, before the step that would exceed it
        # Adam's steps do not depend on the gradient's scale: plain SGD, unclipped, checks the gradient itself
        {"max_grad_norm": 1e9, "learning_rate": 1e-4, "policy_kwargs": {"net_arch": [32, 32], "optimizer_class": torch.optim.SGD}},
    ],
    ids=["default", "entropy-vf-clip", "target-kl", "sgd"],
)
@pytest.mark.parametrize("chunk", [1, 48, 128])
def test_chunked_update_is_ppo_update(settings, chunk):
    torch.set_num_threads(1)
    reference = _one_update(PPO, **settings)
    chunked = _one_update(ChunkedPPO, update_chunk=chunk, **settings)
    before = _parameters(PPO("MlpPolicy", make_sb3_vec_env(N_ENVS, seed=3, env_id="leg_env/PlanarLegHop-v4"), seed=0,
                             device="cpu", policy_kwargs=settings.get("policy_kwargs", {"net_arch": [32, 32]})))
    after_ref, after = _parameters(reference), _parameters(chunked)
    moved = max((after_ref[k] - before[k]).abs().max().item() for k in before)
    assert moved > 1e-3  # the update did something (and the two models began alike: same seed)
    for name in after_ref:
        # round-off: float32's resolution of the parameter, and of the update (which Adam amplifies for gradients near its eps)
        np.testing.assert_allclose(after[name].numpy(), after_ref[name].numpy(), rtol=1e-6, atol=1e-4 * moved, err_msg=name)
    for key in LOGGED:
        got, want = chunked.logger.name_to_value[key], reference.logger.name_to_value[key]
        # the losses are means of O(1) terms (normalised advantages times ratios) that can cancel to 1e-5: float32's
        # round-off of such a mean over a rollout of 512 samples, summed in another order, is about 1e-6
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=2e-6, err_msg=key)
    assert chunked._n_updates == reference._n_updates


def test_minibatch_within_one_chunk_is_sb3_bit_for_bit():
    torch.set_num_threads(1)
    fast = {"net_arch": [32, 32], "activation_fn": FastTanh}  # SB3's PPO with the activation ChunkedPPO swaps in
    reference, chunked = _one_update(PPO, policy_kwargs=fast), _one_update(ChunkedPPO, update_chunk=256)
    after_ref, after = _parameters(reference), _parameters(chunked)
    for name in after_ref:
        assert torch.equal(after[name], after_ref[name]), name


def test_saved_model_loads_as_either_class(tmp_path):
    model = _one_update(ChunkedPPO, update_chunk=64)
    model.save(tmp_path / "model.zip")
    again = ChunkedPPO.load(tmp_path / "model.zip", device="cpu")
    assert again.update_chunk == 64
    assert again.update_precision == "float32"
    plain = PPO.load(tmp_path / "model.zip", device="cpu")
    assert plain.policy_kwargs.get("activation_fn", torch.nn.Tanh) is torch.nn.Tanh  # the saved model is SB3's
    assert any(type(m) is torch.nn.Tanh for m in plain.policy.modules())
    assert not any(type(m) is torch.nn.Tanh for m in again.policy.modules())
    obs = np.random.default_rng(0).normal(size=(64, *model.observation_space.shape)).astype(np.float32)
    np.testing.assert_allclose(plain.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0], rtol=0, atol=1e-5)


def test_fast_tanh_is_tanh():
    x = torch.cat([torch.linspace(-40.0, 40.0, 200_001), torch.tensor([0.0, -0.0, 1e30, -1e30, float("inf"), -float("inf")])])
    y = FastTanh()(x)
    assert y.dtype == torch.float32
    np.testing.assert_allclose(y.numpy(), torch.tanh(x).numpy(), rtol=0, atol=2.5e-7)
    assert torch.isnan(FastTanh()(torch.tensor([float("nan")]))).all()
    x64 = torch.linspace(-3.0, 3.0, 41, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(FastTanh(), (x64,))
    (grad,) = torch.autograd.grad(FastTanh()(x64).sum(), x64)
    np.testing.assert_allclose(grad.detach().numpy(), 1.0 - np.tanh(x64.detach().numpy()) ** 2, rtol=1e-12, atol=1e-15)
    low = torch.linspace(-3.0, 3.0, 101).bfloat16()
    assert FastTanh()(low).dtype == torch.bfloat16
    np.testing.assert_allclose(FastTanh()(low).float().numpy(), np.tanh(low.float().numpy()), rtol=0, atol=1e-2)


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16])
def test_fast_tanh_without_a_gradient_is_the_same_bits_and_leaves_its_input(dtype):
    def bits(t):
        return t.detach().view(torch.int16 if dtype == torch.bfloat16 else torch.int32)

    x = torch.cat([torch.linspace(-12.0, 12.0, 4097), torch.tensor([0.0, -0.0, float("inf"), -float("inf"), float("nan")])]).to(dtype)
    graded = x.clone().requires_grad_(True)
    with_grad = FastTanh()(graded)
    assert with_grad.grad_fn is not None  # the autograd function's path
    kept = x.clone()
    plain = FastTanh()(x)  # no input needs a gradient: the in-place path
    with torch.no_grad():
        under_no_grad = FastTanh()(graded)
    for y in (plain, under_no_grad):
        assert y.grad_fn is None and y.dtype == dtype
        assert torch.equal(bits(y), bits(with_grad))
    assert torch.equal(bits(x), bits(kept))


def test_bfloat16_update_is_close_to_float32():
    """The bfloat16 update moves the parameters as the float32 one does, up to bfloat16's rounding of the hidden
    layers; its logged statistics agree; and the rollouts are float32 (the same actions before the update)."""
    torch.set_num_threads(1)
    before = _parameters(PPO("MlpPolicy", make_sb3_vec_env(N_ENVS, seed=3, env_id="leg_env/PlanarLegHop-v4"), seed=0,
                             device="cpu", policy_kwargs={"net_arch": [32, 32]}))
    full = _one_update(ChunkedPPO, update_chunk=128)
    low = _one_update(ChunkedPPO, update_chunk=128, update_precision="bfloat16")
    for name in before:
        step_full, step_low = (full.policy.state_dict()[name] - before[name]), (low.policy.state_dict()[name] - before[name])
        assert step_full.abs().max() > 0 and step_low.dtype == torch.float32
        cosine = torch.nn.functional.cosine_similarity(step_full.flatten(), step_low.flatten(), dim=0).item()
        assert cosine > 0.999, (name, cosine)  # 0.9998 or more when written
        assert 0.98 < (step_low.norm() / step_full.norm()).item() < 1.02, name
        assert not torch.equal(step_low, step_full), name  # the bfloat16 arithmetic did run
    for key in LOGGED:
        np.testing.assert_allclose(low.logger.name_to_value[key], full.logger.name_to_value[key], rtol=0.05, atol=2e-3, err_msg=key)


@pytest.mark.parametrize("precision, error", [("float16", ValueError), ("bf16", ValueError), (16, TypeError), (None, TypeError)])
def test_bad_update_precision(precision, error):
    with pytest.raises(error, match="update_precision"):
        ChunkedPPO("MlpPolicy", make_sb3_vec_env(2, seed=0), update_precision=precision, n_steps=8, batch_size=16, device="cpu")


@pytest.mark.parametrize("chunk, error", [(0, ValueError), (-5, ValueError), (2.5, TypeError), (True, TypeError), ("64", TypeError)])
def test_bad_update_chunk(chunk, error):
    venv = make_sb3_vec_env(2, seed=0)
    with pytest.raises(error, match="update_chunk"):
        ChunkedPPO("MlpPolicy", venv, update_chunk=chunk, n_steps=8, batch_size=16, device="cpu")


def test_training_speed_benchmark_runs_one_case():
    """``benchmarks/bench_train.py`` measures one case in a fresh process and reports its shares (tiny budget)."""
    script = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_train.py"
    for algo in ("chunked", "bfloat16", "sb3", "smooth-0.25"):  # the last: benchmarks/bench_smoothness.py's case
        done = subprocess.run([sys.executable, str(script), "--one", "leg_env/PlanarLegHop-v4", "1", algo, "--rollouts", "2"],
                              capture_output=True, text=True, timeout=300, check=False)
        assert done.returncode == 0, done.stderr[-2000:]
        result = json.loads([line for line in done.stdout.splitlines() if line.startswith("RESULT ")][-1][len("RESULT "):])
        assert result["algo"] == algo and result["precision"] in ("float32", "bfloat16") and result["rate"] > 0 and result["gradient_steps"] == 8  # 4 epochs of 2 minibatches
        assert abs(result["rollout"] + result["update"] - 1.0) < 0.05 and 0.0 < result["env"] < result["rollout"]
        assert result["chunked_terms"] == (["smoothness_share", "spatial_smoothness_coef", "temporal_smoothness_coef"] if algo == "smooth-0.25" else [])


def test_training_speed_benchmark_takes_a_configuration_with_chunked_terms():
    """The balance configuration holds ``ChunkedPPO``'s own terms: timed as it is, SB3's reference runs without them
    (SB3's ``PPO`` takes none), and the smoothness benchmark's reference without its smoothness charges."""
    from train.hyperparameters import CHUNKED_PPO_KEYS, load_hyperparams

    root = Path(__file__).resolve().parents[2]
    own = sorted(k for k in CHUNKED_PPO_KEYS if load_hyperparams(root / "train" / "hyperparams" / "ppo.yml", "leg_env/PlanarLegBalance-v1").get(k))
    assert own  # else this test tests nothing
    script = root / "benchmarks" / "bench_train.py"
    expected = {"chunked": own, "sb3": [], "smooth-0": [k for k in own if k == "bounds_loss_coef"]}
    for algo, terms in expected.items():
        done = subprocess.run([sys.executable, str(script), "--one", "leg_env/PlanarLegBalance-v1", "1", algo, "--rollouts", "2"],
                              capture_output=True, text=True, timeout=300, check=False)
        assert done.returncode == 0, done.stderr[-2000:]
        result = json.loads([line for line in done.stdout.splitlines() if line.startswith("RESULT ")][-1][len("RESULT "):])
        assert result["chunked_terms"] == terms, algo


def test_default_chunk_is_per_torch_thread():
    from train.chunked_ppo import UPDATE_CHUNK

    model = ChunkedPPO("MlpPolicy", make_sb3_vec_env(2, seed=0), n_steps=8, batch_size=16, device="cpu")
    threads = torch.get_num_threads()
    try:
        for k in (1, 2):
            torch.set_num_threads(k)
            assert model.update_chunk is None and model.chunk == k * UPDATE_CHUNK
    finally:
        torch.set_num_threads(threads)
    assert ChunkedPPO("MlpPolicy", make_sb3_vec_env(2, seed=0), update_chunk=100, n_steps=8, batch_size=16, device="cpu").chunk == 100


def test_episode_buffers_are_filled_as_sb3_fills_them():
    """``ChunkedPPO._update_info_buffer`` (which visits only the infos holding ``episode`` or ``is_success``) leaves
    the episode buffers as SB3's does, for any mix of infos and dones."""
    venv = make_sb3_vec_env(2, seed=0)
    models = [algo("MlpPolicy", venv, n_steps=8, batch_size=16, device="cpu") for algo in (PPO, ChunkedPPO)]
    for model in models:  # as learn() sets them up, long enough to keep every entry
        model.ep_info_buffer, model.ep_success_buffer = deque(maxlen=1000), deque(maxlen=1000)
    rng = np.random.default_rng(0)
    for step in range(50):
        infos = []
        for i in range(6):
            info = {"TimeLimit.truncated": bool(rng.integers(2))}
            if rng.random() < 0.3:
                info["episode"] = {"r": float(step), "l": i, "t": 0.0}
            if rng.random() < 0.3:
                info["is_success"] = bool(rng.integers(2)) if rng.random() < 0.9 else None
            infos.append(info)
        dones = rng.random(6) < 0.5 if step % 5 else None
        for model in models:
            model._update_info_buffer(infos, dones)
    reference, chunked = models
    assert list(chunked.ep_info_buffer) == list(reference.ep_info_buffer) and len(reference.ep_info_buffer) > 10
    assert list(chunked.ep_success_buffer) == list(reference.ep_success_buffer) and len(reference.ep_success_buffer) > 5


def _bounded_update(coef: float, precision: str = "float32"):
    """One SGD step on one rollout of the hop task, the policy's mean action held at (3, -2) (beyond both ends of
    the box [-1, 1]) by a zero action-net weight; returns the model and its action net's bias before the step."""
    torch.set_num_threads(1)
    venv = make_sb3_vec_env(N_ENVS, seed=3, env_id="leg_env/PlanarLegHop-v4", per_env_info=False)
    model = ChunkedPPO("MlpPolicy", venv, n_steps=N_STEPS, batch_size=N_ENVS * N_STEPS, n_epochs=1, learning_rate=1e-3,
                       max_grad_norm=1e9, seed=0, device="cpu", update_chunk=128, update_precision=precision,
                       bounds_loss_coef=coef, policy_kwargs={"net_arch": [32, 32], "optimizer_class": torch.optim.SGD})
    with torch.no_grad():
        model.policy.action_net.weight.zero_()
        model.policy.action_net.bias.copy_(torch.tensor([3.0, -2.0]))
    bias = model.policy.action_net.bias.detach().clone()
    model.learn(N_ENVS * N_STEPS)
    venv.close()
    return model, bias


@pytest.mark.parametrize("precision", ["float32", "bfloat16"])
def test_bounds_loss_charges_the_mean_beyond_the_box(precision):
    """With the mean action at (3, -2) for every sample, the charge is (3 - 1.1)^2 + (-1.1 + 2)^2 = 4.42 per sample,
    its gradient on the action net's bias (2 * 1.9, -2 * 0.9): one SGD step moves that bias by exactly
    ``-lr * coef * (3.8, -1.8)`` more than PPO's own loss does."""
    coef, lr = 0.5, 1e-3
    plain, start = _bounded_update(0.0, precision)
    charged, start_again = _bounded_update(coef, precision)
    assert torch.equal(start, start_again)
    assert "train/bounds_loss" not in plain.logger.name_to_value
    np.testing.assert_allclose(charged.logger.name_to_value["train/bounds_loss"], 4.42, rtol=1e-6)
    extra = (charged.policy.action_net.bias - plain.policy.action_net.bias).detach().numpy()
    np.testing.assert_allclose(extra, -lr * coef * np.array([3.8, -1.8]), rtol=1e-3)
    assert charged.logger.name_to_value["train/loss"] > plain.logger.name_to_value["train/loss"] + coef * 4.0


def test_bounds_loss_does_not_touch_a_mean_inside_the_box():
    """A mean within 1.1 of the box's centre costs nothing: the update is the one without the charge, bit for bit."""
    torch.set_num_threads(1)
    reference = _one_update(ChunkedPPO, update_chunk=128)
    charged = _one_update(ChunkedPPO, update_chunk=128, bounds_loss_coef=0.5)  # a fresh policy's means are near 0
    assert charged.logger.name_to_value["train/bounds_loss"] == 0.0
    after_ref, after = _parameters(reference), _parameters(charged)
    for name in after_ref:
        assert torch.equal(after[name], after_ref[name]), name


@pytest.mark.parametrize("coef, error", [(-0.1, ValueError), (float("nan"), ValueError), (float("inf"), ValueError),
                                         ("0.1", TypeError), (True, TypeError), (None, TypeError)])
def test_bad_bounds_loss_coef(coef, error):
    with pytest.raises(error, match="bounds_loss_coef"):
        ChunkedPPO("MlpPolicy", make_sb3_vec_env(2, seed=0), bounds_loss_coef=coef, n_steps=8, batch_size=16, device="cpu")


def test_bounds_loss_needs_a_box_action_space():
    import gymnasium as gym

    with pytest.raises(ValueError, match="bounds_loss_coef applies to a Box"):
        ChunkedPPO("MlpPolicy", gym.make("CartPole-v1"), bounds_loss_coef=0.1, n_steps=8, batch_size=8, device="cpu")
    ChunkedPPO("MlpPolicy", gym.make("CartPole-v1"), n_steps=8, batch_size=8, device="cpu")  # without it, any space


def test_bounds_loss_coef_survives_save_and_load(tmp_path):
    model = ChunkedPPO("MlpPolicy", make_sb3_vec_env(2, seed=0), bounds_loss_coef=0.25, n_steps=8, batch_size=16, device="cpu")
    model.save(tmp_path / "model.zip")
    assert ChunkedPPO.load(tmp_path / "model.zip", device="cpu").bounds_loss_coef == 0.25
    PPO.load(tmp_path / "model.zip", device="cpu")  # still SB3's model


def test_torch_tanh_is_sb3_bit_for_bit_and_use_tanh_switches_both_ways():
    """``tanh="torch"`` keeps SB3's ``nn.Tanh``: within one chunk the update is SB3's PPO's, bit for bit; ``use_tanh``
    swaps a model's activations either way without changing what the policy computes (beyond float32's rounding)."""
    torch.set_num_threads(1)
    reference, chunked = _one_update(PPO), _one_update(ChunkedPPO, update_chunk=256, tanh="torch")
    assert chunked.tanh == "torch" and not any(isinstance(m, FastTanh) for m in chunked.policy.modules())
    after_ref, after = _parameters(reference), _parameters(chunked)
    for name in after_ref:
        assert torch.equal(after[name], after_ref[name]), name
    obs = np.random.default_rng(1).normal(size=(64, *chunked.observation_space.shape)).astype(np.float32)
    before = chunked.predict(obs, deterministic=True)[0]
    chunked.use_tanh("fast")
    assert chunked.tanh == "fast" and sum(type(m) is FastTanh for m in chunked.policy.modules()) == 4  # two per network
    assert not any(type(m) is torch.nn.Tanh for m in chunked.policy.modules())
    np.testing.assert_allclose(chunked.predict(obs, deterministic=True)[0], before, rtol=0, atol=1e-5)
    chunked.use_tanh("torch")
    assert sum(type(m) is torch.nn.Tanh for m in chunked.policy.modules()) == 4
    assert not any(isinstance(m, FastTanh) for m in chunked.policy.modules())


def test_saved_tanh_choice_comes_back_on_load(tmp_path):
    model = ChunkedPPO("MlpPolicy", make_sb3_vec_env(2, seed=0), tanh="torch", n_steps=8, batch_size=16, device="cpu")
    model.save(tmp_path / "model.zip")
    again = ChunkedPPO.load(tmp_path / "model.zip", device="cpu")
    assert again.tanh == "torch" and not any(isinstance(m, FastTanh) for m in again.policy.modules())


@pytest.mark.parametrize("tanh, error", [("sigmoid", ValueError), ("", ValueError), (None, TypeError), (1, TypeError)])
def test_bad_tanh(tanh, error):
    with pytest.raises(error, match="tanh"):
        ChunkedPPO("MlpPolicy", make_sb3_vec_env(2, seed=0), tanh=tanh, n_steps=8, batch_size=16, device="cpu")
    model = ChunkedPPO("MlpPolicy", make_sb3_vec_env(2, seed=0), n_steps=8, batch_size=16, device="cpu")
    with pytest.raises(error, match="tanh"):
        model.use_tanh(tanh)
    assert model.tanh == "fast" and any(type(m) is FastTanh for m in model.policy.modules())


class _RolloutCopy:
    """An SB3 callback that keeps, at the end of each rollout (before the update), the buffer's observations and
    episode starts and the policy's mean actions at them, computed by SB3's own ``get_distribution``, and a copy of
    the policy."""

    def __new__(cls):
        import copy

        from stable_baselines3.common.callbacks import BaseCallback

        class Copy(BaseCallback):
            def _on_step(self) -> bool:
                return True

            def _on_rollout_end(self) -> None:
                buffer = self.model.rollout_buffer
                obs = torch.as_tensor(buffer.observations.reshape(-1, buffer.observations.shape[-1]))
                with torch.no_grad():
                    mean = self.model.policy.get_distribution(obs).distribution.mean.numpy()
                self.copies.append((buffer.observations.copy(), buffer.episode_starts.copy(), mean.reshape(*buffer.observations.shape[:2], -1)))
                self.policies.append(copy.deepcopy(self.model.policy))

        keeper = Copy()
        keeper.copies, keeper.policies = [], []
        return keeper


def _smoothed(temporal: float = 0.0, spatial: float = 0.0, sigma: float = 0.05, rollouts: int = 1, epochs: int = 1, lr: float = 1e-3,
              share: float = 1.0):
    """A model after ``rollouts`` rollouts of the push task, each followed by one update of ``epochs`` epochs on the
    whole rollout as one minibatch, in chunks of 128; and the ``_RolloutCopy`` that kept the rollouts."""
    torch.set_num_threads(1)
    venv = make_sb3_vec_env(N_ENVS, seed=3, env_id="leg_env/PlanarLegPush-v2", per_env_info=False)
    model = ChunkedPPO("MlpPolicy", venv, n_steps=N_STEPS, batch_size=N_ENVS * N_STEPS, n_epochs=epochs, learning_rate=lr,
                       seed=0, device="cpu", update_chunk=128, temporal_smoothness_coef=temporal, spatial_smoothness_coef=spatial,
                       spatial_smoothness_sigma=sigma, smoothness_share=share, policy_kwargs={"net_arch": [32, 32]})
    keeper = _RolloutCopy()
    model.learn(rollouts * N_ENVS * N_STEPS, callback=keeper)
    venv.close()
    return model, keeper


def _temporal_distance(obs, starts, mean) -> float:
    """The mean of ``|mu(s_t) - mu(s_t+1)|_2`` (smoothed at 0 by ``SMOOTHNESS_EPS``, as charged) over the consecutive
    steps of one episode in a rollout, from its arrays ``(n_steps, n_envs, ...)``."""
    from train.chunked_ppo import SMOOTHNESS_EPS

    d = np.sqrt(((mean[1:] - mean[:-1]) ** 2).sum(axis=-1) + SMOOTHNESS_EPS)
    same = starts[1:] == 0
    return float(d[same].mean())


def test_temporal_smoothness_is_the_mean_actions_change_within_episodes():
    """The logged charge of the first update's one minibatch (taken before the step) is the mean distance between the
    mean actions of consecutive observations of an episode, computed here from the rollout with SB3's own
    ``get_distribution``; the rollout holds episode ends, which the charge must skip."""
    model, keeper = _smoothed(temporal=0.5)
    obs, starts, mean = keeper.copies[0]
    assert starts[1:].sum() > 0  # some episodes ended within the rollout
    expected = _temporal_distance(obs, starts, mean)
    all_pairs = float(np.linalg.norm(mean[1:] - mean[:-1], axis=-1).mean())
    assert abs(all_pairs - expected) > 1e-3 * expected  # skipping the episode ends matters here
    np.testing.assert_allclose(model.logger.name_to_value["train/temporal_smoothness"], expected, rtol=1e-5)


@pytest.mark.parametrize("option", ["temporal", "spatial"])
def test_smoothness_charges_make_the_mean_action_smooth(option):
    """Weighted far above PPO's loss, each charge drives the mean action's change (between consecutive observations of
    the last rollout, or under a noise of std 0.05 on its observations) far below what the same training without it
    leaves."""
    plain, plain_kept = _smoothed(rollouts=4, epochs=4)
    charged, charged_kept = _smoothed(rollouts=4, epochs=4, **{option: 20.0})
    if option == "temporal":
        after_plain, after = (_temporal_distance(*kept.copies[-1]) for kept in (plain_kept, charged_kept))
    else:
        after_plain, after = (_spatial_distance(model.policy, kept.copies[-1][0], 0.05) for model, kept in
                              ((plain, plain_kept), (charged, charged_kept)))
    assert after_plain > 1e-3
    assert after < 0.3 * after_plain, (after_plain, after)


def _spatial_distance(policy, obs: np.ndarray, sigma: float, seed: int = 1) -> float:
    """The mean over ``obs`` of ``|mu(s) - mu(s + e)|_2``, ``e ~ N(0, sigma^2 I)`` drawn here."""
    obs = torch.as_tensor(obs.reshape(-1, obs.shape[-1]))
    shifted = obs + sigma * torch.randn(obs.shape, generator=torch.Generator().manual_seed(seed))
    with torch.no_grad():
        a, b = (policy.get_distribution(x).distribution.mean for x in (obs, shifted))
    return float(torch.linalg.norm(a - b, dim=-1).mean())


@pytest.mark.parametrize("sigma", [0.05, 1.0])
def test_spatial_smoothness_is_the_change_under_the_noise(sigma):
    """The logged charge of the first update's one minibatch (taken before the step) is the mean action's change under
    a noise of std ``sigma`` on the observation: a Monte Carlo estimate of it from the rollout with the policy before
    the update, with noise drawn here, agrees within its sampling error (512 samples); a noise of another size does
    not."""
    model, keeper = _smoothed(spatial=0.5, sigma=sigma)
    logged = model.logger.name_to_value["train/spatial_smoothness"]
    policy, obs = keeper.policies[0], keeper.copies[0][0]
    np.testing.assert_allclose(logged, _spatial_distance(policy, obs, sigma), rtol=0.15)
    assert not np.isclose(logged, _spatial_distance(policy, obs, sigma / 4), rtol=0.3)


def test_no_smoothness_charge_leaves_the_update_alone():
    """Weights of 0 are the update without the options, bit for bit, and log nothing of them."""
    torch.set_num_threads(1)
    reference = _one_update(ChunkedPPO, update_chunk=128)
    zero = _one_update(ChunkedPPO, update_chunk=128, temporal_smoothness_coef=0.0, spatial_smoothness_coef=0.0)
    assert "train/temporal_smoothness" not in zero.logger.name_to_value
    after_ref, after = _parameters(reference), _parameters(zero)
    for name in after_ref:
        assert torch.equal(after[name], after_ref[name]), name


@pytest.mark.parametrize("share", [1.0, 0.25])
def test_smoothness_charges_do_not_depend_on_the_chunks(share):
    """The charged subset and the charges are the minibatch's, whatever ``update_chunk``: an update in chunks of 48
    is the update in one chunk to float32's round-off (the spatial noise drawn alike: the same torch seed, one
    draw per charged chunk in order, so it is left out here)."""
    torch.set_num_threads(1)
    settings = dict(temporal_smoothness_coef=2.0, smoothness_share=share, max_grad_norm=1e9, learning_rate=1e-4,
                    policy_kwargs={"net_arch": [32, 32], "optimizer_class": torch.optim.SGD})
    whole, chunked = (_one_update(ChunkedPPO, update_chunk=chunk, **settings) for chunk in (512, 48))
    after_whole, after = _parameters(whole), _parameters(chunked)
    for name in after_whole:
        np.testing.assert_allclose(after[name].numpy(), after_whole[name].numpy(), rtol=1e-5, atol=1e-6, err_msg=name)
    np.testing.assert_allclose(chunked.logger.name_to_value["train/temporal_smoothness"],
                               whole.logger.name_to_value["train/temporal_smoothness"], rtol=1e-5)


def test_smoothness_on_a_share_of_the_samples():
    """On a quarter of the samples the logged charges are means over about a quarter of them: within sampling error of
    the means over all (512 samples, a fresh policy, the same rollout); the smoothing still works (the charged
    policy's temporal change far below the plain one's)."""
    full, kept_full = _smoothed(temporal=0.5, spatial=0.5)
    quarter, kept_quarter = _smoothed(temporal=0.5, spatial=0.5, share=0.25)
    assert np.array_equal(kept_full.copies[0][0], kept_quarter.copies[0][0])  # the same rollout
    for key in ("train/temporal_smoothness", "train/spatial_smoothness"):
        np.testing.assert_allclose(quarter.logger.name_to_value[key], full.logger.name_to_value[key], rtol=0.3)
    plain, kept_plain = _smoothed(rollouts=4, epochs=4)
    charged, kept_charged = _smoothed(temporal=20.0, rollouts=4, epochs=4, share=0.25)
    assert _temporal_distance(*kept_charged.copies[-1]) < 0.3 * _temporal_distance(*kept_plain.copies[-1])


@pytest.mark.parametrize("name", ["temporal_smoothness_coef", "spatial_smoothness_coef", "spatial_smoothness_sigma"])
@pytest.mark.parametrize("value, error", [(-0.1, ValueError), (float("nan"), ValueError), (float("inf"), ValueError),
                                          ("0.1", TypeError), (True, TypeError), (None, TypeError)])
def test_bad_smoothness_settings(name, value, error):
    with pytest.raises(error, match=name):
        ChunkedPPO("MlpPolicy", make_sb3_vec_env(2, seed=0), n_steps=8, batch_size=16, device="cpu", **{name: value})


def test_smoothness_needs_box_spaces_and_survives_save_and_load(tmp_path):
    import gymnasium as gym

    with pytest.raises(ValueError, match="temporal_smoothness_coef applies to a Box"):
        ChunkedPPO("MlpPolicy", gym.make("CartPole-v1"), temporal_smoothness_coef=0.1, n_steps=8, batch_size=8, device="cpu")
    for share, error in ((0.0, ValueError), (1.5, ValueError), (float("nan"), ValueError), ("0.5", TypeError)):
        with pytest.raises(error, match="smoothness_share"):
            ChunkedPPO("MlpPolicy", make_sb3_vec_env(2, seed=0), smoothness_share=share, n_steps=8, batch_size=16, device="cpu")
    with pytest.raises(ValueError, match="spatial_smoothness_sigma must be positive"):
        ChunkedPPO("MlpPolicy", make_sb3_vec_env(2, seed=0), spatial_smoothness_sigma=0.0, n_steps=8, batch_size=16, device="cpu")
    model = ChunkedPPO("MlpPolicy", make_sb3_vec_env(2, seed=0), temporal_smoothness_coef=0.25, spatial_smoothness_coef=0.5,
                       spatial_smoothness_sigma=0.1, n_steps=8, batch_size=16, device="cpu")
    model.save(tmp_path / "model.zip")
    loaded = ChunkedPPO.load(tmp_path / "model.zip", device="cpu")
    assert (loaded.temporal_smoothness_coef, loaded.spatial_smoothness_coef, loaded.spatial_smoothness_sigma) == (0.25, 0.5, 0.1)
