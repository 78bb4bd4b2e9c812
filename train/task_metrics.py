"""Task-specific evaluation: hop metrics per episode, and push survival against the push impulse.

Both are used by ``python -m train.evaluate`` (``train.evaluate``), which runs every task's common
metrics; these add what a task's own question needs:

* **Hop** (``HopTracker``): every flight phase is one hop. Its apex is ballistic, so it is known at any
  instant of the flight, ``y_apex = y_com + y_com'^2 / (2 g)``, and needs no apex event; the apex error is
  ``y_apex - (y_stand + dh*)``. The hop period is the time between successive lift-offs, the landing
  impulse the norm of the step's impact impulse (``info["impulse"]``) at each touchdown, the drift the
  COM's horizontal displacement from the episode's start at its end. ``hops_per_episode`` counts the
  flights of at least ``LONG_FLIGHT`` (50 ms) per episode.
* **Push** (``push_survival``): episodes of ``PlanarLegPush-v0`` with every push of one magnitude (the
  range ``push_force`` set to ``(F, F)``; signs and times as the task draws them), run as one native batch
  per magnitude with the controller's batched ``predict``; survival is reaching the time limit.
"""

from __future__ import annotations

import numpy as np

from leg_env.tasks.stance import Obs

__all__ = ["HopTracker", "is_push_task", "push_survival", "largest_survived_impulse", "LONG_FLIGHT"]

LONG_FLIGHT = 0.05
"""A flight of at least this long [s] is a hop in ``hops_per_episode`` (shorter ones are stumbles)."""


class HopTracker:
    """Hop metrics of ``PlanarLegHop`` episodes (v0 and v1), fed one step at a time (module docstring).

    ``start(env, obs)`` after each reset, ``step(env, obs, info)`` after each step, ``summary()`` at the end
    over every episode. Also keeps, per step of the current episode, the COM height, its target and the
    apex estimate (``series``) for the plot of a few hops.
    """

    def __init__(self):
        self.errors: list[float] = []  # apex error of every hop [m]
        self.periods: list[float] = []  # time between successive lift-offs [s]
        self.landings: list[float] = []  # |impact impulse| at each touchdown [N s]
        self.drifts: list[float] = []  # |x_com(end) - x_com(start)| of each episode that ran to its end [m]
        self.hops_per_episode: list[int] = []
        self.long_hops_per_episode: list[int] = []  # flights of at least LONG_FLIGHT seconds

    def start(self, env, obs, info: dict) -> None:
        """A new episode from its reset's ``obs`` and ``info`` (the COM comes from ``info``)."""
        u = env.unwrapped
        self._p, self._dt, self._g = u.params, u.dt, u.params.g
        from leg_env.dynamics import com_position
        from leg_env.tasks.stance import nominal_state

        self._standing = float(com_position(nominal_state(u.params, u.config).q, u.params)[1])
        self._target = self._standing + float(info["command"])
        self._x0 = float(info["com_position"][0])
        self._t, self._flying, self._last_liftoff, self._hops = 0.0, obs[Obs.contact] < 0.5, None, 0
        self._flight_time, self._long = 0.0, 0
        self.series = {"com_height": [], "target": self._target, "apex": []}

    def step(self, env, obs, info) -> None:
        (x, y), vy = info["com_position"].tolist(), float(info["com_velocity"][1])
        target = self._standing + float(info["command"])  # the command the observation shows (a schedule changes it)
        self._t += self._dt
        flying = info["contact_mode"] == "flight"
        self._flight_time += float(info["flight_time"])  # this flight's time so far (the step's share of it)
        if not flying and self._flying:  # a touchdown in this step: the flight is over
            self._long += self._flight_time >= LONG_FLIGHT
        if not flying:
            self._flight_time = 0.0
        apex = y + vy * vy / (2.0 * self._g) if flying else np.nan
        if flying and not self._flying:  # a lift-off in this step: one hop, its apex known now
            self.errors.append(apex - target)
            self._hops += 1
            if self._last_liftoff is not None:
                self.periods.append(self._t - self._last_liftoff)
            self._last_liftoff = self._t
        impulse = float(np.hypot(*info["impulse"]))
        if impulse > 0.0:
            self.landings.append(impulse)
        self._flying = flying
        self._x_end = x
        self.series["com_height"].append(y)
        self.series["apex"].append(apex)

    def end(self, survived: bool) -> None:
        """Close the episode (its drift counts when it ran to the time limit)."""
        self.hops_per_episode.append(self._hops)
        self.long_hops_per_episode.append(self._long + (self._flying and self._flight_time >= LONG_FLIGHT))
        if survived:
            self.drifts.append(abs(self._x_end - self._x0))

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
        }


def is_push_task(env_id: str) -> bool:
    """Whether ``env_id`` is a registered version of the push-recovery task (``PlanarLegPush-v0``, ``-v1``)."""
    from leg_env.tasks import REGISTRY

    return REGISTRY.get(env_id, (None, {}))[0] == "push"


def push_survival(controller, forces, episodes: int, seed: int, env_kwargs: dict | None = None,
                  env_id: str = "leg_env/PlanarLegPush-v0") -> list[dict]:
    """Survival rate of ``controller`` on the push task ``env_id`` with every push of magnitude ``F``, for each ``F``.

    ``episodes`` episodes per magnitude, episode ``i`` seeded ``seed + i`` (the same seeds, so the same
    push times and signs, at every magnitude and for every controller). Returns one dict per force:
    ``force`` [N], ``impulse`` [N s] (``F`` times the push's duration), ``survival_rate``, ``episodes``.
    """
    import gymnasium as gym

    rows = []
    for force in forces:
        kwargs = {**(env_kwargs or {}), "push_force": (float(force), float(force))}
        envs = gym.make_vec(env_id, num_envs=episodes, **kwargs)
        duration = envs.config.push_steps * envs.config.dt
        obs, _ = envs.reset(seed=seed)
        alive = np.ones(episodes, dtype=bool)
        done = np.zeros(episodes, dtype=bool)
        if hasattr(controller, "reset"):
            controller.reset()
        while not done.all():
            action, _ = controller.predict(obs, deterministic=True)
            obs, _, terminated, truncated, _ = envs.step(np.asarray(action, dtype=np.float32).reshape(episodes, 2))
            fresh = ~done  # autoreset starts new episodes after an end: count each sub-env's first only
            alive &= ~(terminated & fresh)
            done |= (terminated | truncated) & fresh
        envs.close()
        rows.append({"force": float(force), "impulse": float(force) * duration, "survival_rate": float(alive.mean()), "episodes": episodes})
    return rows


def largest_survived_impulse(rows: list[dict], level: float = 0.9) -> float:
    """The largest impulse whose survival rate is at least ``level``, with every smaller one's too (0 if none)."""
    best = 0.0
    for row in sorted(rows, key=lambda r: r["impulse"]):
        if row["survival_rate"] < level:
            break
        best = row["impulse"]
    return best
