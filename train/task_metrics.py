"""Task-specific evaluation: hop metrics per episode, and push survival against the push impulse.

Both are used by ``python -m train.evaluate`` (``train.evaluate``), which runs every task's common
metrics; these add what a task's own question needs:

* **Hop** (``HopTracker``): every flight phase is one hop. Its apex is ballistic, so it is known at any
  instant of the flight, ``y_apex = y_com + y_com'^2 / (2 g)``, and needs no apex event; the apex error is
  ``y_apex - (y_stand + dh*)``. The hop period is the time between successive lift-offs, the landing
  impulse the norm of the step's impact impulse (``info["impulse"]``) at each touchdown, the drift the
  COM's horizontal displacement from the episode's start at its end. ``hops_per_episode`` counts the
  flights of at least ``LONG_FLIGHT`` (50 ms) per episode. ``apex_error_by_command`` splits the signed apex
  errors by the command of the hop into ``COMMAND_BANDS`` bands of equal width over the task's
  ``command_range``: where in the range a policy hops short or high.
* **Push** (``train.episodes.push_survival``): episodes of ``PlanarLegPush-v2`` with every push of one magnitude (the
  range ``push_force`` set to ``(F, F)``; signs and times as the task draws them), run as one batch per
  magnitude (``train.episodes.run_batch``); survival is reaching the time limit.
"""

from __future__ import annotations

import numpy as np

from leg_env.tasks.base import Obs

__all__ = ["HopTracker", "is_push_task", "largest_survived_impulse", "LONG_FLIGHT", "COMMAND_BANDS"]

LONG_FLIGHT = 0.05
"""A flight of at least this long [s] is a hop in ``hops_per_episode`` (shorter ones are stumbles)."""

COMMAND_BANDS = 5
"""``HopTracker.summary()["apex_error_by_command"]`` has this many bands of the command range."""


class HopTracker:
    """Hop metrics of ``PlanarLegHop`` episodes, a ``train.episodes.Watcher`` of a batch (module docstring).

    ``run_batch`` feeds it the batch after the reset and after every step; ``end(survived)`` closes the
    episodes and ``summary()`` gives the metrics over every hop of every episode. ``series`` keeps, per step of
    the episode of row ``record`` (None: none), the COM height, its target and the apex estimate, for the plot of
    a few hops.
    """

    def __init__(self, record: int | None = None):
        self.record = record
        self.errors: list[float] = []  # apex error of every hop [m]
        self.commands: list[float] = []  # the command [m] of every hop, in the order of errors
        self.periods: list[float] = []  # time between successive lift-offs [s]
        self.landings: list[float] = []  # |impact impulse| at each touchdown [N s]
        self.drifts: list[float] = []  # |x_com(end) - x_com(start)| of each episode that ran to its end [m]
        self.hops_per_episode: list[int] = []
        self.long_hops_per_episode: list[int] = []  # flights of at least LONG_FLIGHT seconds
        self.series: dict = {}
        self._command_range = (0.0, 0.0)

    def start(self, envs, obs, info: dict) -> None:
        """New episodes from the batch's reset ``obs`` ``(N, n)`` and ``info`` (the COM comes from ``info``)."""
        from leg_env.physics.dynamics import com_position
        from leg_env.tasks.base import nominal_state

        params, config = envs.params, envs.config
        self._command_range = tuple(float(c) for c in config.command_range)
        self._dt, self._g = envs.dt, params.g
        self._standing = float(com_position(nominal_state(params, config).q, params)[1])
        n = obs.shape[0]
        self._x0 = np.array(info["com_position"][:, 0], dtype=np.float64)
        self._x_end = self._x0.copy()
        self._t = np.zeros(n)
        self._flying = obs[:, Obs.contact] < 0.5
        self._last_liftoff = np.full(n, np.nan)
        self._hops = np.zeros(n, dtype=np.int64)
        self._flight_time = np.zeros(n)
        self._long = np.zeros(n, dtype=np.int64)
        if self.record is not None:
            self.series = {"com_height": [], "target": self._standing + float(info["command"][self.record]), "apex": []}

    def step(self, envs, obs, actions, info: dict, active: np.ndarray) -> None:
        x, y = info["com_position"][:, 0], info["com_position"][:, 1]
        vy = info["com_velocity"][:, 1]
        target = self._standing + info["command"]  # the command the observation shows (a schedule changes it)
        self._t[active] += self._dt
        flying = info["contact_mode"] == "flight"
        self._flight_time[active] += info["flight_time"][active]  # this flight's time so far (the step's share of it)
        landed = active & ~flying & self._flying  # a touchdown in this step: the flight is over
        self._long[landed] += self._flight_time[landed] >= LONG_FLIGHT
        self._flight_time[active & ~flying] = 0.0
        apex = np.where(flying, y + vy * vy / (2.0 * self._g), np.nan)
        lifted = np.flatnonzero(active & flying & ~self._flying)  # a lift-off in this step: one hop, its apex known now
        self.errors.extend((apex[lifted] - target[lifted]).tolist())
        self.commands.extend(np.asarray(info["command"], dtype=np.float64)[lifted].tolist())
        self._hops[lifted] += 1
        again = lifted[~np.isnan(self._last_liftoff[lifted])]
        self.periods.extend((self._t[again] - self._last_liftoff[again]).tolist())
        self._last_liftoff[lifted] = self._t[lifted]
        impulse = np.hypot(info["impulse"][:, 0], info["impulse"][:, 1])
        self.landings.extend(impulse[active & (impulse > 0.0)].tolist())
        self._flying = np.where(active, flying, self._flying)
        self._x_end = np.where(active, x, self._x_end)
        r = self.record
        if r is not None and active[r]:
            self.series["com_height"].append(float(y[r]))
            self.series["apex"].append(float(apex[r]))

    def end(self, survived: np.ndarray) -> None:
        """Close the episodes (an episode's drift counts when it ran to the time limit)."""
        self.hops_per_episode.extend(self._hops.tolist())
        self.long_hops_per_episode.extend((self._long + (self._flying & (self._flight_time >= LONG_FLIGHT))).tolist())
        self.drifts.extend(np.abs(self._x_end - self._x0)[np.asarray(survived, dtype=bool)].tolist())

    def by_command(self) -> list[dict]:
        """The hops' signed apex errors in ``COMMAND_BANDS`` bands of equal width over the command range: one dict per
        band, ``low`` and ``high`` [m] (the last band includes ``high``), ``hops`` and ``mean_apex_error`` [m] (nan
        without hops). One band if the range is a single command."""
        low, high = self._command_range
        e, c = np.asarray(self.errors), np.asarray(self.commands)
        edges = np.linspace(low, high, COMMAND_BANDS + 1) if high > low else np.array([low, high])
        band = np.clip(np.searchsorted(edges, c, side="right") - 1, 0, len(edges) - 2)
        rows = []
        for k in range(len(edges) - 1):
            in_band = band == k
            rows.append({"low": float(edges[k]), "high": float(edges[k + 1]), "hops": int(in_band.sum()),
                         "mean_apex_error": float(e[in_band].mean()) if in_band.any() else float("nan")})  # fmt: skip
        return rows

    def summary(self) -> dict:
        e = np.asarray(self.errors)
        return {
            "hops": int(e.size),
            "mean_abs_apex_error": float(np.mean(np.abs(e))) if e.size else float("nan"),
            "rms_apex_error": float(np.sqrt(np.mean(e * e))) if e.size else float("nan"),
            "mean_apex_error": float(np.mean(e)) if e.size else float("nan"),
            "mean_hop_period": float(np.mean(self.periods)) if self.periods else float("nan"),
            "hops_per_episode": float(np.mean(self.long_hops_per_episode)) if self.long_hops_per_episode else 0.0,
            "mean_drift_10s": float(np.mean(self.drifts)) if self.drifts else float("nan"),
            "max_drift_10s": float(np.max(self.drifts)) if self.drifts else float("nan"),
            "mean_landing_impulse": float(np.mean(self.landings)) if self.landings else 0.0,
            "max_landing_impulse": float(np.max(self.landings)) if self.landings else 0.0,
            "apex_error_by_command": self.by_command(),
        }


def is_push_task(env_id: str) -> bool:
    """Whether ``env_id`` is the push-recovery task (``PlanarLegPush-v2``), or a task of the push module."""
    from leg_env.tasks import REGISTRY

    return REGISTRY.get(env_id, (None, {}))[0] == "push"


def largest_survived_impulse(rows: list[dict], level: float = 0.9) -> float:
    """The largest impulse whose survival rate is at least ``level``, with every smaller one's too (0 if none)."""
    best = 0.0
    for row in sorted(rows, key=lambda r: r["impulse"]):
        if row["survival_rate"] < level:
            break
        best = row["impulse"]
    return best
