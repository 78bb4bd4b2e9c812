"""The batched base of the model-based controllers: SB3's ``predict`` for one observation or a batch, and the
per-robot state that a controller keeps between calls.

A controller names the observation widths it reads (``widths``), allocates its per-robot arrays for a batch of
``n`` robots (``_allocate``), starts rows anew (``_start``: at the first call, after ``reset`` or a change of the
batch size, and wherever SB3's ``episode_start`` is true) and maps a batch of observations ``(N, width)`` to
actions in [-1, 1] (``act``). It reads the observation by the task's named columns (``leg_env.tasks.base.Obs``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["BatchedController"]


class BatchedController:
    """SB3-style ``predict`` over a batch with per-robot state (module docstring)."""

    widths: tuple[int, ...] = ()
    """The observation widths the controller reads (the first is its task's)."""
    task: str = ""
    """The task(s) whose observation it reads, for the error message."""
    dtype = None
    """The dtype the observation is read as (None: as given)."""

    _n = 0  # the batch size of the per-robot state (0: none yet)

    def reset(self) -> None:
        """Start every robot anew at the next ``predict``."""
        self._n = 0

    def _allocate(self, n: int) -> None:
        """Make the per-robot arrays of a batch of ``n`` robots (none by default)."""

    def _start(self, rows: np.ndarray, batch: np.ndarray) -> None:
        """Start the robots of ``rows`` (a boolean mask) anew, at their observations ``batch`` (nothing by default)."""

    def act(self, batch: np.ndarray) -> np.ndarray:
        """Actions ``(N, 2)`` float32 in [-1, 1] for the observations ``batch`` ``(N, width)``."""
        raise NotImplementedError

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3-style ``predict``: actions in [-1, 1] for one observation ``(width,)`` or a batch ``(N, width)``.

        Returns:
            ``(action, None)`` with ``action`` float32 of shape (2,) or (N, 2).

        Raises:
            ValueError: the observation is not of one of ``widths``, or not 1- or 2-dimensional.
        """
        obs = np.asarray(observation) if self.dtype is None else np.asarray(observation, dtype=self.dtype)
        if obs.ndim not in (1, 2) or obs.shape[-1] not in self.widths:
            shapes = ", ".join(f"({w},) or (N, {w})" for w in self.widths)
            raise ValueError(f"observation must have shape {shapes} ({self.task}), got {obs.shape}")
        batch = obs.reshape(-1, obs.shape[-1])
        n = batch.shape[0]
        if self._n != n:
            self._n = n
            self._allocate(n)
            self._start(np.ones(n, dtype=bool), batch)
        if episode_start is not None:
            self._start(np.asarray(episode_start, dtype=bool).reshape(-1), batch)
        action = self.act(batch)
        return (action[0] if obs.ndim == 1 else action), None
