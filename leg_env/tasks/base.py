"""What the shared environments need from a task: ``Task``, one per task module (its ``TASK``).

A task module (``leg_env/tasks/<name>.py``) holds everything about its task and nothing else: its
frozen config dataclass (a ``StanceConfig`` subclass: the physics settings, limits and weights every
task shares, and its own), its observation, reward terms and termination, written once in the compiled
core (``leg_env/_core/tasks.c``: ``assess`` after a control step, ``start`` after a reset, on the packed
arrays of ``leg_env.step``), its reset distribution (what it draws from the robot's generator beyond the posture
noise), its documentation (the module docstring, in Gymnasium's order) and, in ``leg_env.tasks.REGISTRY``,
its ids. The physics kernel (``leg_env.step``), the single and vector environments (``leg_env.envs``),
the SB3 adapter, rendering and training are written once for every task.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .._core import kernels
from ..step import OUT_BASE, STATE_DIM

__all__ = ["Task"]


def _no_draws(config) -> int:
    return 0


@dataclass(frozen=True, eq=False)
class Task:
    """A task as the shared environments see it (every field is read by ``leg_env.envs``).

    Attributes:
        name: the module name under ``leg_env.tasks``.
        config_cls: the config dataclass (``StanceConfig`` or a subclass; ``from_kwargs``, ``array``,
            ``task_array``).
        reward_terms: names of the reward terms, in the order they are summed (``info["reward_<name>"]``);
            ``out[:, OUT_BASE:OUT_BASE + len(reward_terms)]``.
        info_names: the task's own ``info`` keys, one float column each after the reward terms.
        state_names: the task's own per-robot state columns after ``leg_env.step.STATE_DIM``.
        kernel: the task's number in the compiled core (``leg_env/_core/env.h``, ``env_task``): its kernels
            are ``assess`` and ``start`` below, and ``kernels.Batch(kernel, ...)`` steps a single env.
        observation_space: ``(params, config) -> gymnasium.spaces.Box`` of one robot.
        draws: ``config -> int``: uniforms the task draws at every reset, after the posture noise.
        columns: ``(draws (k, n), config) -> (k, len(state_names))`` the task's state columns of ``k``
            fresh robots from their draws (None when the task has no state columns).
    """

    name: str
    config_cls: type
    reward_terms: tuple
    kernel: int
    observation_space: Callable
    info_names: tuple = ()
    state_names: tuple = ()
    draws: Callable = _no_draws
    columns: Callable | None = None

    def assess(self, state, consts, out, obs, flags) -> None:
        """The task after a control step of every robot (``leg_env.step.physics_range``), in place: the
        observation, the reward terms (they sum to the reward), the extras and ``flags``."""
        kernels.assess(self.kernel, state, consts, out, obs, flags)

    def start(self, state, consts, out, obs, flags) -> None:
        """The task at freshly started robots (after ``leg_env.step.physics_start``): reward terms zero."""
        kernels.start(self.kernel, state, consts, out, obs, flags)

    @property
    def state_dim(self) -> int:
        return STATE_DIM + len(self.state_names)

    @property
    def out_dim(self) -> int:
        return OUT_BASE + len(self.reward_terms) + len(self.info_names)

    @property
    def out_terms(self) -> slice:
        return slice(OUT_BASE, OUT_BASE + len(self.reward_terms))

    @property
    def out_info(self) -> slice:
        return slice(OUT_BASE + len(self.reward_terms), self.out_dim)

    @property
    def reward_keys(self) -> tuple:
        return tuple(f"reward_{name}" for name in self.reward_terms)

    def task_columns(self, draws: np.ndarray, config) -> np.ndarray:
        """``(k, len(state_names))`` task state columns from the ``(k, draws(config))`` task draws."""
        if self.columns is None:
            return np.zeros((draws.shape[0], 0))
        return self.columns(draws, config)
