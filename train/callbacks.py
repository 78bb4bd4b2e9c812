"""Training callbacks: reward-term and contact-violation logging, periodic evaluation, checkpoints, and a schedule
of task settings (a curriculum)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from train.episodes import HOP_EVAL_KEYS, evaluate_now  # evaluate_now: train.episodes', also named here
from train.motion import KEYS as MOTION_KEYS
from train.run import Every

__all__ = [
    "RewardTermsLogger",
    "leg_adapter",
    "PeriodicEvaluation",
    "PeriodicCheckpoint",
    "FrozenActor",
    "ConfigSchedule",
    "DiscountSchedule",
    "LearningRateSchedule",
    "NoiseFloor",
    "CommandCurriculum",
    "zoo_callbacks",
    "evaluate_now",
]

VIOLATION_KEYS = ("unilateral_violation", "friction_violation")


class RewardTermsLogger(BaseCallback):
    """Log, per rollout, the mean of each ``reward_*`` info term per env step and the rate of contact violations.

    TensorBoard keys: ``rollout/reward_<term>`` (the task's terms: ``reward_keys``) and
    ``rollout/<unilateral|friction>_violation_rate``.
    """

    def __init__(self, reward_keys: tuple):
        super().__init__()
        self.reward_keys = tuple(reward_keys)
        self._sums = dict.fromkeys(self.reward_keys + VIOLATION_KEYS, 0.0)
        self._count = 0

    def _on_rollout_start(self) -> None:
        for key in self._sums:
            self._sums[key] = 0.0
        self._count = 0

    def _on_step(self) -> bool:
        sums = self._sums
        adapter = leg_adapter(self.training_env)
        if adapter is not None:  # the step's columns: no per-env dicts needed
            columns = adapter.step_info
            for key in sums:
                sums[key] += float(columns[key].sum())
            self._count += adapter.num_envs
            return True
        for info in self.locals["infos"]:
            for key in sums:
                sums[key] += info[key]
        self._count += len(self.locals["infos"])
        return True

    def _on_rollout_end(self) -> None:
        if self._count == 0:
            return
        for key in self.reward_keys:
            self.logger.record(f"rollout/{key}", self._sums[key] / self._count)
        for key in VIOLATION_KEYS:
            self.logger.record(f"rollout/{key}_rate", self._sums[key] / self._count)


def leg_adapter(venv):
    """The ``leg_env.sb3.LegStanceVecEnv`` under ``venv``'s wrappers, or None (another kind of VecEnv)."""
    from leg_env.sb3 import LegStanceVecEnv

    while venv is not None and not isinstance(venv, LegStanceVecEnv):
        venv = getattr(venv, "venv", None)
    return venv


class PeriodicEvaluation(BaseCallback):
    """The run's periodic evaluation (``train.run.Run.evaluate_if_due``), asked at every step; each result is logged
    to TensorBoard under ``eval/`` (how the robot moved under ``eval/motion/``).

    ``evaluate(steps)`` evaluates the policy when ``steps`` has passed the next multiple of the evaluation frequency
    (then returns the result; otherwise None): deterministic episodes of the model being trained, its observations
    normalised by the training ``VecNormalize``'s current statistics, rewards the env's own (unnormalised).
    """

    def __init__(self, evaluate: Callable[[int], dict | None]):
        super().__init__()
        self.evaluate = evaluate

    def _on_step(self) -> bool:
        result = self.evaluate(int(self.num_timesteps))
        if result is not None:
            for key in ("mean_return", "std_return", "mean_length", "survival_rate", "rms_base_drift", *HOP_EVAL_KEYS):
                if key in result:
                    self.logger.record(f"eval/{key}", result[key])
            for key in MOTION_KEYS[1:]:  # how the robot moved (train.motion)
                self.logger.record(f"eval/motion/{key}", result["motion"][key])
            self.logger.dump(self.num_timesteps)
        return True


class PeriodicCheckpoint(BaseCallback):
    """Call ``save()`` between PPO iterations, once the step counter has passed a multiple of ``checkpoint_freq``.

    A checkpoint is taken when a rollout starts: the previous rollout's update is done, and the
    step counter counts exactly the samples the model has learnt from. A run resumed from one goes
    through the same iterations, so it ends at the same step count as an uninterrupted run.
    ``rollout_start`` is the step counter at the start of the current rollout, and ``collecting``
    says whether a rollout is being collected (as opposed to the update that follows it).
    """

    def __init__(self, checkpoint_freq: int, save: Callable[[], None]):
        super().__init__()
        self.every = Every(checkpoint_freq)
        self.save = save
        self.rollout_start: int | None = None
        self.collecting = False

    def _init_callback(self) -> None:
        self.every.start_after(self.model.num_timesteps)

    def _on_rollout_start(self) -> None:
        self.rollout_start = self.model.num_timesteps
        self.collecting = True
        if self.every.due(self.model.num_timesteps):
            self.save()

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        self.collecting = False


class FrozenActor(BaseCallback):
    """Keep the actor (its network, action head and ``log_std``) fixed until ``until`` environment steps.

    For a warm start from a cloned controller (``train.warmstart``): the value network starts untrained, and
    PPO's first updates on its advantages would undo the clone; the critic learns first, on the clone's own
    rollouts. The parameters are frozen through ``requires_grad``, so the optimiser skips them, and thawed
    at the first rollout that starts at or after ``until`` (a resumed run past it starts thawed).
    """

    def __init__(self, until: int):
        super().__init__()
        self.until = int(until)

    def _actor(self):
        policy = self.model.policy
        return list(policy.mlp_extractor.policy_net.parameters()) + list(policy.action_net.parameters()) + [policy.log_std]

    def _init_callback(self) -> None:
        self._set(self.model.num_timesteps >= self.until)

    def _on_rollout_start(self) -> None:
        self._set(self.model.num_timesteps >= self.until)

    def _on_step(self) -> bool:
        return True

    def _set(self, trainable: bool) -> None:
        for parameter in self._actor():
            parameter.requires_grad_(trainable)


class ConfigSchedule(BaseCallback):
    """A curriculum: the training env's task settings as functions of the env steps done.

    ``schedule`` maps a config field to its points ``[[steps, value], ...]`` (steps increasing): the value is the
    first point's before it, the last point's after it, and linear in between, entry by entry for a pair such as
    ``command_range``. At the start of training (a resumed run too) and of every rollout, the fields whose value
    has moved are set on every training env by ``env_method("set_config", ...)`` (``LegEnv.set_config``: starts
    drawn after that use them; the env must be built with room for them, e.g. a ``command_range`` that holds
    every scheduled one). The evaluation env is not touched. In ``train/hyperparams/ppo.yml``, as the Zoo writes
    callbacks::

        callback:
          - train.callbacks.ConfigSchedule:
              schedule:
                command_range: [[6000000, [0.02, 0.06]], [36000000, [0.05, 0.15]]]

    TensorBoard keys: ``curriculum/<field>`` (``curriculum/<field>_<i>`` for each entry of a pair).
    """

    def __init__(self, schedule: dict, verbose: int = 0):
        super().__init__(verbose)
        if not isinstance(schedule, dict) or not schedule:
            raise ValueError(f"ConfigSchedule: schedule must be a non-empty mapping of field to points, got {schedule!r}")
        self.schedule = {str(field): _schedule_points(field, points) for field, points in schedule.items()}
        self._applied: dict = {}

    def values_at(self, steps: int) -> dict:
        """Each scheduled field's value after ``steps`` env steps (a float, or a tuple of floats for a pair)."""
        out = {}
        for field, (at, values, scalar) in self.schedule.items():
            column = tuple(float(np.interp(steps, at, values[:, j])) for j in range(values.shape[1]))
            out[field] = column[0] if scalar else column
        return out

    def _on_training_start(self) -> None:
        self._apply()

    def _on_rollout_start(self) -> None:
        self._apply()

    def _on_step(self) -> bool:
        return True

    def start_on(self, venv: VecEnv, model) -> None:
        """Set the values at ``model``'s steps on ``venv``: ``train.ppo`` calls it before ``learn`` (which resets the
        env), so that the first episodes start under the schedule."""
        self.set_on(venv, model.num_timesteps)

    def set_on(self, venv: VecEnv, steps: int) -> dict:
        """Set the values after ``steps`` env steps on ``venv`` (those that moved since the last call); returns
        them all."""
        values = self.values_at(steps)
        moved = {field: value for field, value in values.items() if self._applied.get(field) != value}
        if moved:
            venv.env_method("set_config", **moved)
            self._applied.update(moved)
        return values

    def _apply(self) -> None:
        values = self.set_on(self.training_env, self.model.num_timesteps)
        for field, value in values.items():
            if isinstance(value, tuple):
                for j, v in enumerate(value):
                    self.logger.record(f"curriculum/{field}_{j}", v)
            else:
                self.logger.record(f"curriculum/{field}", value)


class _ModelSchedule(BaseCallback):
    """A schedule of one of the model's hyperparameters over the env steps done: ``points`` ``[[steps, value], ...]``
    (steps increasing), the first point's value before it, the last point's after it, linear in between (as
    ``ConfigSchedule``), set on the model at the start of training (a resumed run too: ``start_on``) and of every
    rollout. A subclass names the value (``name``, in errors), checks it (``valid``) and sets it (``_put``)."""

    name = "value"
    log_key = ""

    def __init__(self, points, verbose: int = 0):
        super().__init__(verbose)
        at, values, scalar = _schedule_points(self.name, points)
        if not scalar or not np.all(self.valid(values)):
            raise ValueError(f"{type(self).__name__}: every {self.name} must be {self.valid_text}, got {points!r}")
        self.at, self.values = at, values[:, 0]

    def value_at(self, steps: int) -> float:
        """The value after ``steps`` env steps."""
        return float(np.interp(steps, self.at, self.values))

    def start_on(self, venv: VecEnv, model) -> None:
        """Set the value at ``model``'s steps before ``learn`` (``train.ppo`` calls it, as for ``ConfigSchedule``)."""
        self._put(model, self.value_at(model.num_timesteps))

    def _on_training_start(self) -> None:
        self._put(self.model, self.value_at(self.model.num_timesteps))

    def _on_rollout_start(self) -> None:
        value = self.value_at(self.model.num_timesteps)
        self._put(self.model, value)
        if self.log_key:
            self.logger.record(self.log_key, value)

    def _on_step(self) -> bool:
        return True


class DiscountSchedule(_ModelSchedule):
    """A schedule of PPO's discount ``gamma`` over the env steps done: ``points`` ``[[steps, gamma], ...]`` (steps
    increasing), the first point's value before it, the last point's after it, linear in between (as
    ``ConfigSchedule``). At the start of training (a resumed run too) and of every rollout, the model's ``gamma`` and
    its rollout buffer's (which computes the returns and advantages) are set. In ``train/hyperparams/ppo.yml``::

        callback:
          - train.callbacks.DiscountSchedule:
              points: [[36000000, 0.998], [45000000, 0.995]]

    TensorBoard key: ``train/gamma``.
    """

    name, log_key, valid_text = "gamma", "train/gamma", "a number in (0, 1]"

    @staticmethod
    def valid(values: np.ndarray) -> np.ndarray:
        return (values > 0.0) & (values <= 1.0)

    @staticmethod
    def _put(model, gamma: float) -> None:
        model.gamma = gamma
        if getattr(model, "rollout_buffer", None) is not None:
            model.rollout_buffer.gamma = gamma


class LearningRateSchedule(_ModelSchedule):
    """A schedule of the optimiser's learning rate over the env steps done: ``points`` ``[[steps, rate], ...]``
    (steps increasing), the first point's value before it, the last point's after it, linear in between (as
    ``ConfigSchedule``). At the start of training (a resumed run too) and of every rollout, the model's learning-rate
    schedule (``lr_schedule``, which SB3 applies to the optimiser at each update and logs as
    ``train/learning_rate``) becomes that value, whatever ``learning_rate`` says: SB3's own schedules are functions of
    the share of ``n_timesteps`` left, which a run continued past its planned length (or resumed with another) moves,
    where this one is tied to the env steps. In ``train/hyperparams/ppo.yml``::

        callback:
          - train.callbacks.LearningRateSchedule:
              points: [[45000000, 3.0e-4], [72000000, 3.0e-5]]
    """

    name, valid_text = "learning rate", "a finite number above 0"  # SB3 logs it: train/learning_rate

    @staticmethod
    def valid(values: np.ndarray) -> np.ndarray:
        return values > 0.0

    @staticmethod
    def _put(model, rate: float) -> None:
        model.lr_schedule = _Constant(rate)


class NoiseFloor(_ModelSchedule):
    """A floor under the policy's action noise, as a schedule over the env steps done: ``points`` ``[[steps, std],
    ...]`` (steps increasing), the first point's value before it, the last point's after it, linear in between (as
    ``ConfigSchedule``). At the start of training (a resumed run too) and of every rollout, every entry of the
    Gaussian policy's state-independent ``log_std`` below the log of the floor is raised to it, so that the rollout
    explores with a standard deviation of at least the floor in every action; the optimiser may lower it again
    within an update, and the next rollout starts from the floor. PPO's Gaussian policies learn their noise, and
    it shrinks as a policy gets precise; with a small noise the same step of the mean is a larger change of the
    policy (a larger KL divergence per update). In ``train/hyperparams/ppo.yml``::

        callback:
          - train.callbacks.NoiseFloor:
              points: [[0, 0.1]]

    A policy without a ``log_std`` parameter (state-dependent noise, a discrete action) is a ValueError at the start
    of training. TensorBoard key: ``train/std_floor``.
    """

    name, log_key, valid_text = "noise floor", "train/std_floor", "a finite standard deviation above 0"

    @staticmethod
    def valid(values: np.ndarray) -> np.ndarray:
        return values > 0.0

    @staticmethod
    def _put(model, std: float) -> None:
        import torch

        log_std = getattr(model.policy, "log_std", None)
        if not isinstance(log_std, torch.Tensor):
            raise ValueError(f"NoiseFloor: the policy {type(model.policy).__name__} has no state-independent log_std to hold up")
        with torch.no_grad():
            log_std.clamp_(min=float(np.log(std)))


class _Constant:
    """A constant learning-rate schedule that pickles (a model is saved with its ``lr_schedule``; loading gives it
    SB3's schedule of its ``learning_rate``, which ``start_on`` replaces in a resumed run)."""

    def __init__(self, value: float):
        self.value = float(value)

    def __call__(self, progress_remaining: float) -> float:
        return self.value


def _schedule_points(field, points) -> tuple[np.ndarray, np.ndarray, bool]:
    """A schedule's ``[[steps, value], ...]`` as ``(steps (k,), values (k, width), whether scalar)``; ValueError
    naming the field."""
    try:
        pairs = [(point[0], point[1]) for point in points]
        at = np.array([float(steps) for steps, _ in pairs])
        raw = [np.asarray(value, dtype=np.float64) for _, value in pairs]
        values = [np.atleast_1d(v) for v in raw]
    except (TypeError, ValueError, IndexError) as e:
        raise ValueError(f"ConfigSchedule: {field} must be a list of [steps, value] points, got {points!r}") from e
    if not pairs or any(v.ndim != 1 or v.shape != values[0].shape for v in values):
        raise ValueError(f"ConfigSchedule: {field} needs at least one point, all values of one shape, got {points!r}")
    stacked = np.stack(values)
    if not (np.all(np.isfinite(at)) and np.all(at >= 0) and np.all(np.diff(at) > 0) and np.all(np.isfinite(stacked))):
        raise ValueError(f"ConfigSchedule: {field}'s steps must be finite, >= 0 and increasing and its values finite, got {points!r}")
    return at, stacked, raw[0].ndim == 0


def zoo_callbacks(spec) -> list[BaseCallback]:
    """The callbacks of a Zoo ``callback`` entry: a class path, or a list of class paths and ``{class path:
    keyword arguments}`` mappings (``rl_zoo3``'s format). None gives none."""
    from train.hyperparameters import class_at

    if spec is None:
        return []
    items = spec if isinstance(spec, list) else [spec]
    callbacks = []
    for item in items:
        if isinstance(item, str):
            path, kwargs = item, {}
        elif isinstance(item, dict) and len(item) == 1:
            (path, kwargs), = item.items()
            kwargs = kwargs or {}
        else:
            raise ValueError(f"callback: each entry must be a class path or {{class path: arguments}}, got {item!r}")
        cls = class_at(path, BaseCallback, "callback", "an SB3 callback class")
        if not isinstance(kwargs, dict):
            raise ValueError(f"callback: the arguments of {path!r} must be a mapping, got {kwargs!r}")
        callbacks.append(cls(**kwargs))
    return callbacks


class CommandCurriculum(BaseCallback):
    """A curriculum of the hop task's commands driven by how well the policy hops to them.

    The training env's ``command_range`` moves from ``start`` to ``end`` (both bounds linearly) in ``levels`` steps,
    one level at a time, each once the policy has hopped to the commands of the level it is on: at least
    ``min_hops`` hops landed in training since the level began (read from the training env's raw observations: a
    hop lands where the last landed apex, ``Obs.last_apex``, changes), with a mean absolute apex error (that apex
    minus ``Obs.command``) of at most ``max_error`` [m] over the last ``min_hops`` of them. A fixed schedule widens
    the commands whatever the policy does; this one waits on the policy, as legged_gym's command curriculum
    widens velocity commands once they are tracked. The level only rises. It is kept in the model
    (``curriculum_level``), so a saved and resumed run goes on from it.

    TensorBoard keys: ``curriculum/command_level``, ``curriculum/command_range_0`` and ``_1``, and
    ``rollout/apex_error`` (the mean over the hops landed in the rollout).
    """

    def __init__(self, start, end, levels: int = 30, max_error: float = 0.015, min_hops: int = 2000, verbose: int = 0):
        super().__init__(verbose)
        self.start = np.asarray(start, dtype=np.float64)
        self.end = np.asarray(end, dtype=np.float64)
        if self.start.shape != (2,) or self.end.shape != (2,) or not (np.all(np.isfinite(self.start)) and np.all(np.isfinite(self.end))):
            raise ValueError(f"CommandCurriculum: start and end must be [low, high] pairs of numbers, got {start!r}, {end!r}")
        if isinstance(levels, bool) or not isinstance(levels, int) or levels < 1:
            raise ValueError(f"CommandCurriculum: levels must be a positive int, got {levels!r}")
        if not (isinstance(max_error, (int, float)) and np.isfinite(max_error) and max_error > 0):
            raise ValueError(f"CommandCurriculum: max_error must be a positive number [m], got {max_error!r}")
        if isinstance(min_hops, bool) or not isinstance(min_hops, int) or min_hops < 1:
            raise ValueError(f"CommandCurriculum: min_hops must be a positive int, got {min_hops!r}")
        self.levels, self.max_error, self.min_hops = levels, float(max_error), min_hops
        self._errors: list[np.ndarray] = []  # the apex errors of the hops landed on this level
        self._rollout: list[np.ndarray] = []
        self._last_apex: np.ndarray | None = None
        self._applied = None

    @property
    def level(self) -> int:
        return _curriculum_level(self.model)

    def command_range(self, level: int) -> tuple[float, float]:
        low, high = self.start + (self.end - self.start) * (level / self.levels)
        return float(low), float(high)

    def start_on(self, venv: VecEnv, model) -> None:
        """Set the range of ``model``'s level on ``venv``: ``train.ppo`` calls it before ``learn`` (which resets the
        env), so that the first episodes, of a resumed run too, start on that level."""
        self.set_on(venv, _curriculum_level(model))

    def set_on(self, venv: VecEnv, level: int) -> None:
        value = self.command_range(level)
        if value != self._applied:
            venv.env_method("set_config", command_range=value)
            self._applied = value

    def _on_training_start(self) -> None:
        if not hasattr(self.model, "curriculum_level"):
            self.model.curriculum_level = 0
        self._last_apex = None
        self.set_on(self.training_env, self.level)

    def _on_rollout_start(self) -> None:
        self.set_on(self.training_env, self.level)
        self._rollout = []

    def _on_step(self) -> bool:
        from leg_env.tasks.base import Obs

        obs = self.training_env.get_original_obs() if isinstance(self.training_env, VecNormalize) else self.locals["new_obs"]
        apex, command = obs[:, Obs.last_apex], obs[:, Obs.command]
        dones = np.asarray(self.locals["dones"], dtype=bool)
        if self._last_apex is not None:
            landed = (apex != self._last_apex) & ~dones  # a done row shows its next episode's start
            if landed.any():
                errors = np.abs(apex[landed] - command[landed])
                self._errors.append(errors)
                self._rollout.append(errors)
        self._last_apex = apex.copy()
        return True

    def _on_rollout_end(self) -> None:
        if self._rollout:
            self.logger.record("rollout/apex_error", float(np.concatenate(self._rollout).mean()))
        if sum(e.size for e in self._errors) >= self.min_hops and self.level < self.levels:
            recent = np.concatenate(self._errors)[-self.min_hops:]
            if recent.mean() <= self.max_error:
                self.model.curriculum_level = self.level + 1
                self._errors = []
            else:
                self._errors = [recent]
        low, high = self.command_range(self.level)
        self.logger.record("curriculum/command_level", self.level)
        self.logger.record("curriculum/command_range_0", low)
        self.logger.record("curriculum/command_range_1", high)


def _curriculum_level(model) -> int:
    """The command level a ``CommandCurriculum`` keeps in ``model`` (0 before the first)."""
    return int(getattr(model, "curriculum_level", 0))
