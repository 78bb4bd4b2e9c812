"""The one batched episode runner: every evaluation of a policy (``train.evaluate``, the push curve, the periodic
evaluation during training, the learning curves' held-out scores, ``train.falls``' audit of a policy as it is
trained) runs its episodes through ``run_batch``.

One episode per seed, all in one native batch (``gymnasium.make_vec`` of a leg-env id), sub-env ``i`` seeded
with ``seeds[i]``: the same episode, step for step, as ``gymnasium.make(env_id)`` reset with that seed (the
batch's rows are the single env's; ``tests/test_episodes.py`` checks it). The policy sees the whole batch at
every step, with SB3's ``episode_start`` for controllers that keep a state per robot. A sub-env whose episode
has ended is autoreset by the batch and stepped on with the others, but nothing of it is counted any more.

What an evaluation measures beyond returns, lengths and survival is a ``Watcher``: it gets the batch's
observations and ``info`` after the reset and after every step, with the mask of the episodes still running
(``train.motion.Motion``: how the robot moves). ``evaluate_now`` is the in-training evaluation of either trainer
(``train.run``): the summary of one batch.
"""

from __future__ import annotations

from typing import Callable, Protocol, Sequence

import numpy as np

__all__ = ["Batch", "Watcher", "make_batch", "run_batch", "policy_predict", "evaluate_now", "HOP_EVAL_KEYS", "push_survival"]


class Watcher(Protocol):
    """What an evaluation measures besides returns, lengths and survival (``run_batch`` calls it)."""

    def start(self, envs, obs: np.ndarray, info: dict) -> None:
        """After the reset: ``obs`` ``(N, n)`` and the reset's ``info`` of the batch ``envs``."""

    def step(self, envs, obs: np.ndarray, actions: np.ndarray, info: dict, active: np.ndarray) -> None:
        """After a step: its ``obs``, the ``actions`` taken ``(N, 2)``, its ``info``; ``active``: the rows whose
        episode was running before this step (this step is theirs)."""


class Batch:
    """The episodes of one ``run_batch``: per-episode ``returns``, ``lengths`` and ``survived`` (reached the time
    limit without a fall), in the order of the seeds."""

    def __init__(self, seeds: Sequence[int], returns: np.ndarray, lengths: np.ndarray, survived: np.ndarray):
        self.seeds = [int(s) for s in seeds]
        self.returns, self.lengths, self.survived = returns, lengths, survived

    @property
    def survival_rate(self) -> float:
        return float(self.survived.mean())


def make_batch(env_id: str, episodes: int, env_kwargs: dict | None = None, record: int | None = None, frames: bool = False,
               size: int = 320):
    """The native batch of ``episodes`` sub-envs of ``env_id`` with ``env_kwargs``; with ``frames``, rendering
    (``rgb_array``, ``size`` pixels square) the sub-envs up to ``record``."""
    import gymnasium as gym

    kwargs = dict(env_kwargs or {})
    if frames and record is not None:
        kwargs.update(render_mode="rgb_array", width=size, height=size, render_envs=record + 1)
    return gym.make_vec(env_id, num_envs=episodes, vectorization_mode="vector_entry_point", **kwargs)


def policy_predict(policy, deterministic: bool = True) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``(obs, episode_start) -> actions`` of anything with SB3's ``predict``, deterministic unless asked (then the
    policy draws its actions, as in training); a policy with a ``reset()`` (a controller keeping a state per robot)
    is reset here, before its first call."""
    if hasattr(policy, "reset"):
        policy.reset()

    def predict(obs, episode_start):
        action, _ = policy.predict(obs, episode_start=episode_start, deterministic=deterministic)
        return action

    return predict


def run_batch(predict: Callable[[np.ndarray, np.ndarray], np.ndarray], envs, seeds: Sequence[int],
              watchers: Sequence[Watcher] = ()) -> Batch:
    """Run one episode per seed in the native batch ``envs`` (``len(seeds)`` sub-envs) to its end.

    Args:
        predict: ``(obs (N, n), episode_start (N,) bool) -> actions (N, 2)`` (``policy_predict`` makes one).
        envs: a leg-env batch (``make_batch``), autoreset on the next step (its default).
        seeds: sub-env ``i``'s seed.
        watchers: further measurements (``Watcher``).

    Returns:
        The ``Batch`` of returns, lengths and survival.
    """
    n = envs.num_envs
    if len(seeds) != n:
        raise ValueError(f"run_batch needs one seed per sub-env: {n} sub-envs, {len(seeds)} seeds")
    obs, info = envs.reset(seed=[int(s) for s in seeds])
    for watcher in watchers:
        watcher.start(envs, obs, info)
    done = np.zeros(n, dtype=bool)
    starts = np.ones(n, dtype=bool)
    returns = np.zeros(n)
    lengths = np.zeros(n, dtype=np.int64)
    survived = np.zeros(n, dtype=bool)
    while not done.all():
        actions = np.asarray(predict(obs, starts), dtype=np.float64).reshape(n, 2)
        obs, reward, terminated, truncated, info = envs.step(actions)
        active = ~done
        returns[active] += reward[active]
        lengths[active] += 1
        for watcher in watchers:
            watcher.step(envs, obs, actions, info, active)
        ended = (terminated | truncated) & active
        survived[ended] = truncated[ended] & ~terminated[ended]
        done |= ended
        starts = terminated | truncated
    return Batch(seeds, returns, lengths, survived)


class _Drift:
    """The squared base drift summed over every step of the episodes (a ``Watcher``)."""

    def start(self, envs, obs, info) -> None:
        self.sum_sq = 0.0

    def step(self, envs, obs, actions, info, active) -> None:
        d = info["base_drift"][active]
        self.sum_sq += float(np.dot(d, d))


def evaluate_now(policy, envs, seed: int) -> dict:
    """One deterministic episode of ``policy`` (SB3's ``predict`` on raw observations) in each sub-env of the
    native batch ``envs``, sub-env ``i`` seeded ``seed + i`` (``run_batch``), summarised.

    Returns per-episode ``returns`` and ``lengths``, their means, the survival rate (episodes ended by the time
    limit, not by a fall), the RMS base drift over all steps [m], ``motion``: how the robot moved (``train.motion``:
    torso tilt, action rate, saturated share, actuator power, peak normal force, flights, COM excursion, over every
    episode, as ``train.evaluate`` reports them); on the hop task also its measures of Solved
    (``train.task_metrics.HopTracker``, as ``train.evaluate`` reports them): ``hops_per_episode``,
    ``mean_abs_apex_error`` and ``mean_apex_error`` [m] (nan without a hop), ``mean_drift_10s`` [m] (nan if no
    episode ran to its end) and ``apex_error_by_command`` (``HopTracker.by_command``).
    """
    from leg_env.tasks.hop import HopConfig
    from train.motion import Motion
    from train.task_metrics import HopTracker

    drift, motion = _Drift(), Motion()
    hop = HopTracker() if isinstance(envs.config, HopConfig) else None
    batch = run_batch(policy_predict(policy), envs, range(seed, seed + envs.num_envs), [drift, motion] + ([] if hop is None else [hop]))
    result = {
        "mean_return": float(batch.returns.mean()),
        "std_return": float(batch.returns.std()),
        "mean_length": float(batch.lengths.mean()),
        "survival_rate": batch.survival_rate,
        "rms_base_drift": float(np.sqrt(drift.sum_sq / batch.lengths.sum())),
        "returns": batch.returns.round(4).tolist(),
        "lengths": batch.lengths.tolist(),
        "motion": motion.summary(),
    }
    if hop is not None:
        hop.end(batch.survived)
        summary = hop.summary()
        result.update({key: summary[key] for key in HOP_EVAL_KEYS})
        result["apex_error_by_command"] = summary["apex_error_by_command"]
    return result


HOP_EVAL_KEYS = ("hops_per_episode", "mean_abs_apex_error", "mean_apex_error", "mean_drift_10s")
"""The hop task's measures that the in-training evaluation adds (``evaluate_now``)."""


def push_survival(controller, forces, episodes: int, seed: int, env_kwargs: dict | None = None,
                  env_id: str = "leg_env/PlanarLegPush-v2") -> list[dict]:
    """Survival rate of ``controller`` on the push task ``env_id`` with every push of magnitude ``F``, for each ``F``.

    ``episodes`` episodes per magnitude, episode ``i`` seeded ``seed + i`` (the same seeds, so the same
    push times and signs, at every magnitude and for every controller). Returns one dict per force:
    ``force`` [N], ``impulse`` [N s] (``F`` times the push's duration), ``survival_rate``, ``episodes``.
    """
    rows = []
    for force in forces:
        kwargs = {**(env_kwargs or {}), "push_force": (float(force), float(force))}
        envs = make_batch(env_id, episodes, kwargs)
        duration = envs.config.push_steps * envs.config.dt
        try:
            batch = run_batch(policy_predict(controller), envs, range(seed, seed + episodes))
        finally:
            envs.close()
        rows.append({"force": float(force), "impulse": float(force) * duration, "survival_rate": batch.survival_rate, "episodes": episodes})
    return rows
