"""What the shared environments need from a task: ``Task``, one per task module (its ``TASK``).

A task module (``leg_env/tasks/<name>.py``) holds everything about its task and nothing else: its
frozen config dataclass (a ``StanceConfig`` subclass: the physics settings, limits and weights every
task shares, and its own), its observation, reward terms and termination, written once in the compiled
core (``leg_env/_core/tasks.c``: ``assess`` after a control step, ``start`` after a reset, on the
structured arrays of ``leg_env.layout``), its reset distribution (what it draws from the robot's generator
beyond the posture noise), its documentation (the module docstring, in Gymnasium's order) and, in
``leg_env.tasks.REGISTRY``, its ids. The physics (``leg_env.step``), the single and vector environments
(``leg_env.envs``), the ``info`` builder (``leg_env.info``), the SB3 adapter, rendering and training are
written once for every task.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Callable

import numpy as np

from .. import layout
from .._core import kernels

__all__ = ["Task"]


def _no_draws(config) -> int:
    return 0


@dataclass(frozen=True, eq=False)
class Task:
    """A task as the shared environments see it (every field is read by ``leg_env.envs``).

    Attributes:
        name: the module name under ``leg_env.tasks``; also the name of its fields in ``leg_env.layout``.
        config_cls: the config dataclass (``StanceConfig`` or a subclass; ``from_kwargs``, ``settings``).
        reward_terms: names of the reward terms, in the order they are summed (``info["reward_<name>"]``):
            ``out["terms"][:, :len(reward_terms)]``.
        kernel: the task's number in the compiled core (``env_task`` of ``leg_env/_core/env.h``).
        observation_space: ``(params, config) -> gymnasium.spaces.Box`` of one robot.
        info_names: the task's own ``out`` fields that ``info`` carries (push: ``push_force``, ``work_push``).
        state_info: the task's own ``state`` fields that ``info`` carries (hop: ``command``).
        draws: ``config -> int``: uniforms the task draws at every reset, after the posture noise.
        columns: ``(draws (k, n), config) -> {field: (k, ...) values}``: the task's own state fields of ``k``
            fresh robots from their draws (None when the task has none).
    """

    name: str
    config_cls: type
    reward_terms: tuple
    kernel: int
    observation_space: Callable
    info_names: tuple = ()
    state_info: tuple = ()
    draws: Callable = _no_draws
    columns: Callable | None = None

    def assess(self, state, robots, settings, out, obs) -> None:
        """The task after a control step of every robot (``leg_env.step.physics_range``), in place: the
        observation, the reward terms (they sum to the reward), the extras and the flags."""
        kernels.assess(self.kernel, state, robots, settings, out, obs)

    def step(self, state, robots, settings, out, obs, lo: int = 0, hi: int | None = None) -> None:
        """One control step of robots ``lo .. hi - 1`` and the task after it, in place: bitwise
        ``leg_env.step.physics_range`` then ``assess`` of those rows, in one compiled call that releases the
        GIL (so that chunks of rows can run in threads) and keeps each block of rows in cache between the two."""
        kernels.step(self.kernel, lo, state.shape[0] if hi is None else hi, state, robots, settings, out, obs)

    def start(self, state, robots, settings, out, obs, noise=None, scale: float = 0.0) -> None:
        """Freshly reset robots put on their contact and evaluated without stepping (reward terms zero): at
        ``state["q"], ["qd"], ["anchor"]`` if ``noise`` is None, else at each robot's nominal posture plus
        ``uniform(-scale, scale)`` noise from the ``(N, 6)`` uniforms ``noise`` (``leg_env.step``)."""
        kernels.start(self.kernel, state, robots, settings, out, obs, noise, scale)

    @cached_property
    def state_dtype(self) -> np.dtype:
        return layout.state_dtype(self.name)

    @cached_property
    def out_dtype(self) -> np.dtype:
        return layout.out_dtype(self.name)

    @property
    def reward_keys(self) -> tuple:
        return tuple(f"reward_{name}" for name in self.reward_terms)

    def task_columns(self, draws: np.ndarray, config) -> dict:
        """The task's own state fields of ``k`` fresh robots from their ``(k, draws(config))`` draws."""
        if self.columns is None:
            return {}
        return self.columns(draws, config)
