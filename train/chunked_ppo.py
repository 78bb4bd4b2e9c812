"""SB3's PPO with each minibatch's gradient summed over cache-sized chunks: the same update, faster on a CPU.

``ChunkedPPO`` is ``stable_baselines3.PPO`` in every respect (arguments, saving, loading, logging) but four, all
about speed:

* In ``train``, a minibatch larger than a chunk goes through the networks a chunk at a time, each chunk's share of
  the loss back-propagated before the next chunk's forward pass, and the optimiser steps once on the sum. The loss
  is a mean over the minibatch, so the summed gradient is the minibatch's gradient (up to the order of
  floating-point sums), and so are the update, the advantage normalisation (over the whole minibatch, as SB3's),
  the gradient clipping, the early stop on ``target_kl`` (checked on the whole minibatch before it steps) and the
  logged statistics. With 1024 envs and minibatches of 16,384 samples, each activation of a [128, 128] network is
  an 8 MB array, far larger than a core's cache; chunks of 4,096 samples per torch thread keep them in cache.
* The policy's ``torch.nn.Tanh`` activations are ``FastTanh``: ``2 sigmoid(2x) - 1``, the same function to
  float32's rounding, because torch's CPU ``tanh`` kernel is several times slower than its ``sigmoid`` on the
  project's AMD EPYC and took a quarter of a large-batch update there. On other CPUs torch's own is the faster (an
  Intel Xeon of the Sapphire Rapids class: 0.84 ms against 5.99 ms on a 16,384 x 128 array): ``tanh="torch"`` keeps
  it. A saved model is SB3's (its ``policy_kwargs`` name ``nn.Tanh``) and loads with ``PPO.load``.
* ``update_precision="bfloat16"`` runs the hidden layers of the update in bfloat16 (``torch.autocast``), the
  parameters, optimiser, output layers and losses staying float32: on a CPU with bfloat16 arithmetic the matrix
  products, most of the update, run about three times faster. ``train.ppo`` uses it on request
  (``--update-precision bfloat16``, or ``auto``: where the CPU has bfloat16 arithmetic); its default is float32.
* In the rollouts, the step's infos are searched for episode statistics with one pass over the list rather than two
  dictionary lookups per env (``_update_info_buffer``, the same buffers).

Two options change the update, both off by default:

* ``bounds_loss_coef`` adds to the loss a charge on the policy's mean action beyond its box (as rl_games's
  ``bounds_loss_coef``). SB3 clips a sampled action to the action space, so where the mean lies far outside it the
  sampled actions are all the bound: the exploration noise does nothing there and the mean drifts without a signal.
  With the charge the mean stays near the box, where the noise still moves the action.
* ``temporal_smoothness_coef`` and ``spatial_smoothness_coef`` regularise the mean action as CAPS does (Mysore et
  al., "Regularizing Action Policies for Smooth Control with Reinforcement Learning", ICRA 2021): the distance
  ``|mu(s_t) - mu(s_t+1)|_2`` between the mean actions of consecutive observations of an episode in the rollout, and
  ``|mu(s) - mu(s + e)|_2`` with ``e`` Gaussian of std ``spatial_smoothness_sigma`` in the observation the policy
  sees (normalised, where ``VecNormalize`` normalises it). A charge on the action's change in the task's reward is
  paid on the sampled actions, exploration noise included, so it also pushes the noise down; these charge the mean
  action only, and leave the exploration to the policy loss.

``benchmarks/bench_train.py`` measures each against SB3's own PPO in the same run
(``benchmarks/results/train_speed.md``). Minibatches no larger than a chunk, in float32, take SB3's ``train``
unchanged.
"""

from __future__ import annotations

import math

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.utils import explained_variance

from train.machine import TANHS, UPDATE_PRECISIONS

__all__ = ["ChunkedPPO", "FastTanh", "BOUNDS_MARGIN", "UPDATE_CHUNK", "SMOOTHNESS_EPS"]

BOUNDS_MARGIN = 1.1
"""``bounds_loss_coef`` charges a mean action beyond this many half-widths of the action box from its centre."""

SMOOTHNESS_EPS = 1.0e-8
"""Added to a squared distance under the square root of the smoothness charges: the gradient of ``|d|_2`` is
bounded at ``d = 0``."""

UPDATE_CHUNK = 4096
"""Samples per chunk and torch thread by default: on one thread the fastest of 1,024-16,384 here; on two, 8,192 was."""




class _SigmoidTanh(th.autograd.Function):
    """``tanh(x) = 2 sigmoid(2x) - 1``, with torch's own ``tanh`` backward (``1 - y^2``) on the saved output."""

    @staticmethod
    def forward(ctx, x: th.Tensor) -> th.Tensor:
        y = th.sigmoid(x * 2.0).mul_(2.0).sub_(1.0)
        ctx.save_for_backward(y)
        return y

    @staticmethod
    def backward(ctx, grad: th.Tensor) -> th.Tensor:
        (y,) = ctx.saved_tensors
        return th.ops.aten.tanh_backward(grad, y)


class FastTanh(th.nn.Tanh):
    """``torch.nn.Tanh`` computed as ``2 sigmoid(2x) - 1``: the same function to float32's rounding (within 2e-7),
    its gradient torch's own. torch's CPU ``tanh`` kernel is several times slower than its ``sigmoid`` (2.8 ms
    against 0.44 ms on a 16,384 x 128 float32 array on this project's 2-core machine), and SB3's ``MlpPolicy``
    spends a quarter of a large-batch update in it. Where no gradient is taken (the rollouts, ``predict``) the same
    operations run in place on one new array, without the autograd function: the same bits, in half the time on the
    rollouts' 1024 x 128 arrays."""

    def forward(self, x: th.Tensor) -> th.Tensor:
        if th.is_grad_enabled() and x.requires_grad:
            return _SigmoidTanh.apply(x)
        return th.mul(x, 2.0).sigmoid_().mul_(2.0).sub_(1.0)


def _check_tanh(tanh) -> None:
    if not isinstance(tanh, str):
        raise TypeError(f"tanh must be a str, got {type(tanh).__name__}")
    if tanh not in TANHS:
        raise ValueError(f"tanh must be one of {TANHS}, got {tanh!r}")


class ChunkedPPO(PPO):
    """``stable_baselines3.PPO`` whose minibatch gradients are summed over chunks of at most ``update_chunk`` samples.

    Args:
        update_chunk: the most samples that go through the networks at once in an update (a positive int), or
            None: ``UPDATE_CHUNK`` per torch thread (``torch.get_num_threads()`` when the update runs). It changes
            the speed, not the update.
        update_precision: ``"float32"`` (SB3's update), or ``"bfloat16"``: in the update, the hidden layers
            (``policy.mlp_extractor``) run under ``torch.autocast("cpu", torch.bfloat16)``, their matrix products
            in bfloat16 with float32 accumulation, while the parameters, the optimiser, the output layers, the
            action distribution and the losses stay float32. On a CPU with bfloat16 arithmetic (AVX512-BF16 or
            AMX) the products run about three times faster; elsewhere it is emulated and slower. The rollouts
            are float32 either way.
        tanh: how the networks compute their ``tanh`` activations: ``"fast"`` (``FastTanh``, the default) or
            ``"torch"`` (``torch.nn.Tanh``, SB3's). The same function to float32's rounding; which is faster depends on
            the CPU. ``use_tanh`` switches a model.
        bounds_loss_coef: the weight (a number >= 0; 0, the default, is SB3's loss) of a charge on the mean action
            ``mu`` of a ``Box`` action space beyond ``BOUNDS_MARGIN`` (1.1) times the box's half-width from its
            centre: ``sum_j max(0, mu_j - b_j)^2 + max(0, a_j - mu_j)^2`` per sample, ``[a_j, b_j]`` the widened box,
            averaged over the minibatch and added to PPO's loss; ``train/bounds_loss`` logs it. The rollouts are
            unchanged.
        temporal_smoothness_coef: the weight (a number >= 0; 0, the default, charges nothing) of
            ``|mu(s_t) - mu(s_t+1)|_2`` per sample whose next observation in the rollout belongs to the same episode
            (not the rollout's last step, nor an episode's last), summed and divided by the minibatch's size;
            ``train/temporal_smoothness`` logs its mean over those samples.
        spatial_smoothness_coef: the weight (>= 0; 0 charges nothing) of ``|mu(s) - mu(s + e)|_2`` per sample,
            ``e ~ N(0, spatial_smoothness_sigma^2 I)`` drawn afresh for each sample and each minibatch;
            ``train/spatial_smoothness`` logs its mean.
        spatial_smoothness_sigma: the std of ``e`` (a number > 0, 0.05 by default), in the units of the observation
            the policy sees.
        smoothness_share: the share of each minibatch's samples (in (0, 1], 1 by default) the smoothness charges are
            computed on, a random subset (the same whatever ``update_chunk``) scaled up to the minibatch's mean: each
            charged sample costs one more pass of the actor per charge, so a share of 0.25 keeps most of the update's
            speed. Every other argument is PPO's.

    Every ``torch.nn.Tanh`` of the policy is a ``FastTanh`` (the same function, faster); a saved model is SB3's
    and loads as ``PPO`` too.

    Raises:
        TypeError: ``update_chunk`` is not an int, ``update_precision`` or ``tanh`` not a str, ``bounds_loss_coef``
            or a smoothness setting not a real number.
        ValueError: ``update_chunk`` is not positive, ``update_precision`` not one of ``UPDATE_PRECISIONS``, ``tanh``
            not one of ``TANHS``, ``bounds_loss_coef`` or a smoothness weight negative or not finite,
            ``spatial_smoothness_sigma`` not positive and finite, or a charge on the mean action with an action space
            that is not a ``Box``.
    """

    def __init__(self, *args, update_chunk: int | None = None, update_precision: str = "float32", tanh: str = "fast",
                 bounds_loss_coef: float = 0.0, temporal_smoothness_coef: float = 0.0, spatial_smoothness_coef: float = 0.0,
                 spatial_smoothness_sigma: float = 0.05, smoothness_share: float = 1.0, **kwargs):
        if update_chunk is not None:
            if isinstance(update_chunk, bool) or not isinstance(update_chunk, (int, np.integer)):
                raise TypeError(f"update_chunk must be an int or None, got {type(update_chunk).__name__}")
            if update_chunk < 1:
                raise ValueError(f"update_chunk must be positive, got {update_chunk}")
            update_chunk = int(update_chunk)
        if not isinstance(update_precision, str):
            raise TypeError(f"update_precision must be a str, got {type(update_precision).__name__}")
        if update_precision not in UPDATE_PRECISIONS:
            raise ValueError(f"update_precision must be one of {UPDATE_PRECISIONS}, got {update_precision!r}")
        for name, value in (("bounds_loss_coef", bounds_loss_coef), ("temporal_smoothness_coef", temporal_smoothness_coef),
                            ("spatial_smoothness_coef", spatial_smoothness_coef), ("spatial_smoothness_sigma", spatial_smoothness_sigma)):
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if spatial_smoothness_sigma <= 0:
            raise ValueError(f"spatial_smoothness_sigma must be positive, got {spatial_smoothness_sigma}")
        if isinstance(smoothness_share, bool) or not isinstance(smoothness_share, (int, float, np.integer, np.floating)):
            raise TypeError(f"smoothness_share must be a real number, got {type(smoothness_share).__name__}")
        if not 0 < smoothness_share <= 1:
            raise ValueError(f"smoothness_share must be in (0, 1], got {smoothness_share}")
        _check_tanh(tanh)
        self.update_chunk = update_chunk
        self.update_precision = update_precision
        self.tanh = tanh
        self.bounds_loss_coef = float(bounds_loss_coef)
        self.temporal_smoothness_coef = float(temporal_smoothness_coef)
        self.spatial_smoothness_coef = float(spatial_smoothness_coef)
        self.spatial_smoothness_sigma = float(spatial_smoothness_sigma)
        self.smoothness_share = float(smoothness_share)
        super().__init__(*args, **kwargs)

    @property
    def _charges_mean(self) -> bool:
        """Whether the update charges the mean action (bounds or smoothness)."""
        return bool(self.bounds_loss_coef or self.temporal_smoothness_coef or self.spatial_smoothness_coef)

    def _update_info_buffer(self, infos: list[dict], dones: np.ndarray | None = None) -> None:
        """SB3's: the ``episode`` and ``is_success`` entries of the step's infos into the episode buffers, in the same
        order, visiting only the infos that hold one (SB3 looks up both keys in each of the ``n_envs`` dicts at every
        step)."""
        assert self.ep_info_buffer is not None and self.ep_success_buffer is not None
        for idx in [i for i, info in enumerate(infos) if "episode" in info or "is_success" in info]:
            maybe_ep_info, maybe_is_success = infos[idx].get("episode"), infos[idx].get("is_success")
            if maybe_ep_info is not None:
                self.ep_info_buffer.extend([maybe_ep_info])
            if maybe_is_success is not None and dones is not None and dones[idx]:
                self.ep_success_buffer.append(maybe_is_success)

    def _setup_model(self) -> None:
        charges = [name for name in ("bounds_loss_coef", "temporal_smoothness_coef", "spatial_smoothness_coef") if getattr(self, name)]
        if charges and not isinstance(self.action_space, spaces.Box):
            raise ValueError(f"{', '.join(charges)} appl{'ies' if len(charges) == 1 else 'y'} to a Box action space, "
                             f"got {type(self.action_space).__name__}")
        if self.spatial_smoothness_coef and not isinstance(self.observation_space, spaces.Box):
            raise ValueError(f"spatial_smoothness_coef applies to a Box observation space, got {type(self.observation_space).__name__}")
        super()._setup_model()
        self.use_tanh(self.tanh)

    def use_tanh(self, tanh: str) -> None:
        """Compute the policy's ``tanh`` activations as ``tanh`` says from now on: ``"fast"`` (``FastTanh``) or
        ``"torch"`` (``torch.nn.Tanh``). ``train.ppo`` calls it on a resumed model with the invocation's choice, as a
        resume may run on another CPU. Raises ``TypeError`` / ``ValueError`` naming ``tanh``."""
        _check_tanh(tanh)
        old, new = (th.nn.Tanh, FastTanh) if tanh == "fast" else (FastTanh, th.nn.Tanh)
        for parent in self.policy.modules():
            for name, child in parent.named_children():
                if type(child) is old:
                    setattr(parent, name, new())
        self.tanh = tanh

    @property
    def chunk(self) -> int:
        """The samples per chunk of the next update: ``update_chunk``, or ``UPDATE_CHUNK`` per torch thread."""
        return self.update_chunk if self.update_chunk is not None else UPDATE_CHUNK * th.get_num_threads()

    def train(self) -> None:
        """One PPO update on the rollout buffer (``PPO.train``), each minibatch's gradient summed over chunks."""
        chunk_size = self.chunk
        if self.batch_size <= chunk_size and self.update_precision == "float32" and not self._charges_mean:
            return super().train()
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        clip_range = self.clip_range(self._current_progress_remaining)  # type: ignore[operator]
        clip_range_vf = None
        if self.clip_range_vf is not None:
            clip_range_vf = self.clip_range_vf(self._current_progress_remaining)  # type: ignore[operator]

        entropy_losses, pg_losses, value_losses, clip_fractions, bounds_losses = [], [], [], [], []
        temporal_sums, spatial_sums = np.zeros(2), np.zeros(2)  # (sum of distances, samples)
        approx_kl_divs: list[float] = []
        loss_value = float("nan")
        continue_training = True
        successors = self._successors() if self.temporal_smoothness_coef else None
        for epoch in range(self.n_epochs):
            approx_kl_divs = []
            for rollout_data, rows in self._minibatches(successors is not None):
                batch = len(rollout_data.advantages)
                nexts = None
                if successors is not None:
                    nexts = successors[0][rows], successors[1][rows]
                advantages = rollout_data.advantages
                if self.normalize_advantage and batch > 1:
                    advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
                self.policy.optimizer.zero_grad()
                # sums over the minibatch: policy loss, value loss, entropy loss, clipped samples, KL estimate, bounds loss,
                # temporal distances and their samples, spatial distances and their samples, weighted smoothness charges
                sums = np.zeros(11)
                for start in range(0, batch, chunk_size):
                    chunk = slice(start, start + chunk_size)
                    sums += self._chunk_backward(rollout_data, advantages, chunk, batch, clip_range, clip_range_vf, nexts)
                policy_loss, value_loss, entropy_loss, clipped, kl, bounds_loss = sums[:6] / batch
                temporal_sums += sums[6:8]
                spatial_sums += sums[8:10]
                pg_losses.append(policy_loss)
                value_losses.append(value_loss)
                entropy_losses.append(entropy_loss)
                clip_fractions.append(clipped)
                approx_kl_divs.append(kl)
                bounds_losses.append(bounds_loss)
                loss_value = (policy_loss + self.ent_coef * entropy_loss + self.vf_coef * value_loss + self.bounds_loss_coef * bounds_loss
                              + sums[10] / batch)
                if self.target_kl is not None and kl > 1.5 * self.target_kl:
                    continue_training = False
                    if self.verbose >= 1:
                        print(f"Early stopping at step {epoch} due to reaching max kl: {kl:.2f}")
                    break
                th.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
                self.policy.optimizer.step()
            self._n_updates += 1
            if not continue_training:
                break

        explained_var = explained_variance(self.rollout_buffer.values.flatten(), self.rollout_buffer.returns.flatten())
        self.logger.record("train/entropy_loss", np.mean(entropy_losses))
        self.logger.record("train/policy_gradient_loss", np.mean(pg_losses))
        self.logger.record("train/value_loss", np.mean(value_losses))
        self.logger.record("train/approx_kl", np.mean(approx_kl_divs))
        self.logger.record("train/clip_fraction", np.mean(clip_fractions))
        self.logger.record("train/loss", loss_value)
        if self.bounds_loss_coef:
            self.logger.record("train/bounds_loss", np.mean(bounds_losses))
        if self.temporal_smoothness_coef and temporal_sums[1]:
            self.logger.record("train/temporal_smoothness", temporal_sums[0] / temporal_sums[1])
        if self.spatial_smoothness_coef and spatial_sums[1]:
            self.logger.record("train/spatial_smoothness", spatial_sums[0] / spatial_sums[1])
        self.logger.record("train/explained_variance", explained_var)
        if hasattr(self.policy, "log_std"):
            self.logger.record("train/std", th.exp(self.policy.log_std).mean().item())
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/clip_range", clip_range)
        if clip_range_vf is not None:
            self.logger.record("train/clip_range_vf", clip_range_vf)

    def _minibatches(self, with_rows: bool):
        """``(samples, rows)`` per minibatch of one epoch: ``RolloutBuffer.get``'s minibatches, and where ``with_rows``
        the rows of the flattened buffer each holds (drawn as ``get`` draws them; else None)."""
        if not with_rows:
            for samples in self.rollout_buffer.get(self.batch_size):
                yield samples, None
            return
        buffer = self.rollout_buffer
        total = buffer.buffer_size * buffer.n_envs
        if not buffer.generator_ready:
            next(buffer.get(total))  # flattens the buffer's arrays in place, as get's first minibatch does
        rows = np.random.permutation(total)
        for start in range(0, total, self.batch_size):
            chosen = rows[start:start + self.batch_size]
            yield buffer._get_samples(chosen), chosen

    def _successors(self) -> tuple[np.ndarray, np.ndarray]:
        """``(next_observations, has_next)`` of the rollout buffer's samples in its flattened order (env-major, as
        ``RolloutBuffer.swap_and_flatten``): the observation the policy saw at the next step of the same env, and
        whether that step exists in the rollout and belongs to the same episode (else the row is a copy, unused)."""
        buffer = self.rollout_buffer
        if buffer.generator_ready:
            raise RuntimeError("the rollout buffer was already flattened: the successors are taken before")
        obs = buffer.observations  # (n_steps, n_envs, *shape)
        following = np.concatenate([obs[1:], obs[-1:]], axis=0)
        has_next = np.zeros(buffer.episode_starts.shape, dtype=bool)
        has_next[:-1] = buffer.episode_starts[1:] == 0
        flat = buffer.swap_and_flatten
        return flat(following), flat(has_next[..., None]).reshape(-1)

    def _mean_actions(self, observations: th.Tensor) -> th.Tensor:
        """The policy's mean action at ``observations``, its hidden layers in ``update_precision``."""
        policy = self.policy
        features = policy.extract_features(observations)
        with th.autocast("cpu", dtype=th.bfloat16, enabled=self.update_precision == "bfloat16"):
            latent_pi = policy.mlp_extractor.forward_actor(features if policy.share_features_extractor else features[0])
        return policy.action_net(latent_pi.float())

    def _evaluate_actions(self, observations: th.Tensor, actions: th.Tensor):
        """``policy.evaluate_actions`` (the same operations), its hidden layers in ``update_precision``; also the
        mean action when the update charges it (else None)."""
        if self.update_precision == "float32" and not self._charges_mean:
            return (*self.policy.evaluate_actions(observations, actions), None)
        policy = self.policy
        features = policy.extract_features(observations)
        with th.autocast("cpu", dtype=th.bfloat16, enabled=self.update_precision == "bfloat16"):
            if policy.share_features_extractor:
                latent_pi, latent_vf = policy.mlp_extractor(features)
            else:
                latent_pi = policy.mlp_extractor.forward_actor(features[0])
                latent_vf = policy.mlp_extractor.forward_critic(features[1])
        distribution = policy._get_action_dist_from_latent(latent_pi.float())
        values = policy.value_net(latent_vf.float())
        mean = distribution.distribution.mean if self._charges_mean else None
        return values, distribution.log_prob(actions), distribution.entropy(), mean

    def _bounds_loss(self, mean: th.Tensor) -> th.Tensor:
        """The sum over the samples of ``mean`` (n, action dims) of the charge ``bounds_loss_coef`` weighs."""
        low, high = self.action_space.low.astype(np.float64), self.action_space.high.astype(np.float64)
        centre, half = (high + low) / 2, (high - low) / 2
        upper = th.as_tensor(centre + BOUNDS_MARGIN * half, dtype=mean.dtype)
        lower = th.as_tensor(centre - BOUNDS_MARGIN * half, dtype=mean.dtype)
        return ((mean - upper).clamp(min=0) ** 2 + (lower - mean).clamp(min=0) ** 2).sum()

    def _chunk_backward(self, data, advantages: th.Tensor, chunk: slice, batch: int, clip_range: float,
                        clip_range_vf: float | None, nexts: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """Back-propagate one chunk's share of the minibatch loss (its sums divided by the minibatch size ``batch``);
        returns the chunk's sums of the policy loss, the value loss, the entropy loss, the clipped samples, the KL
        estimate, the bounds loss, the temporal distances and the samples they cover, the spatial distances and their
        samples, and the weighted smoothness charges scaled to the whole chunk.
        ``nexts``: the minibatch's next observations and whether each has one (``_successors``), with
        ``temporal_smoothness_coef``."""
        actions = data.actions[chunk]
        if isinstance(self.action_space, spaces.Discrete):
            actions = actions.long().flatten()
        values, log_prob, entropy, mean = self._evaluate_actions(data.observations[chunk], actions)
        values = values.flatten()
        advantages = advantages[chunk]
        log_ratio = log_prob - data.old_log_prob[chunk]
        ratio = th.exp(log_ratio)
        policy_loss = -th.min(advantages * ratio, advantages * th.clamp(ratio, 1 - clip_range, 1 + clip_range)).sum()
        old_values = data.old_values[chunk]
        values_pred = values if clip_range_vf is None else old_values + th.clamp(values - old_values, -clip_range_vf, clip_range_vf)
        value_loss = ((data.returns[chunk] - values_pred) ** 2).sum()
        entropy_loss = log_prob.sum() if entropy is None else -entropy.sum()
        loss = policy_loss + self.ent_coef * entropy_loss + self.vf_coef * value_loss
        bounds_loss, temporal, covered, spatial = 0.0, 0.0, 0.0, 0.0
        if self.bounds_loss_coef:
            charge = self._bounds_loss(mean)
            loss = loss + self.bounds_loss_coef * charge
            bounds_loss = charge.item()
        # the smoothness charges on the minibatch's first ceil(share * batch) samples (a random subset: the minibatch is
        # shuffled), whatever the chunks, scaled up to the minibatch's mean; `charged` of them in this chunk
        size = len(mean) if mean is not None else 0
        subset = max(1, math.ceil(self.smoothness_share * batch))
        charged = max(0, min(size, subset - chunk.start))
        scale, smooth_loss, sampled = batch / subset, 0.0, 0.0
        if not charged:
            nexts = None
        if nexts is not None:
            rows = nexts[1][chunk][:charged]
            if rows.any():
                following = self.rollout_buffer.to_torch(nexts[0][chunk][:charged][rows])
                charge = _distances(mean[:charged][th.as_tensor(rows)], self._mean_actions(following)).sum()
                loss = loss + self.temporal_smoothness_coef * scale * charge
                temporal, covered = charge.item(), float(rows.sum())
                smooth_loss += self.temporal_smoothness_coef * scale * temporal
        if self.spatial_smoothness_coef and charged:
            observations = data.observations[chunk][:charged]
            shifted = observations + self.spatial_smoothness_sigma * th.randn_like(observations)
            charge = _distances(mean[:charged], self._mean_actions(shifted)).sum()
            loss = loss + self.spatial_smoothness_coef * scale * charge
            spatial, sampled = charge.item(), float(charged)
            smooth_loss += self.spatial_smoothness_coef * scale * spatial
        (loss / batch).backward()
        with th.no_grad():
            clipped = (th.abs(ratio - 1) > clip_range).sum()
            kl = ((ratio - 1) - log_ratio).sum()
        return np.array([policy_loss.item(), value_loss.item(), entropy_loss.item(), clipped.item(), kl.item(), bounds_loss,
                         temporal, covered, spatial, sampled, smooth_loss])


def _distances(a: th.Tensor, b: th.Tensor) -> th.Tensor:
    """``|a_i - b_i|_2`` per row, smoothed at 0 by ``SMOOTHNESS_EPS``."""
    return th.sqrt(((a - b) ** 2).sum(dim=-1) + SMOOTHNESS_EPS)
