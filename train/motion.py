"""How a policy moves: posture, action, effort, contact and wandering, measured on the episodes of the one runner.

Roboticists judge a gait by how it moves, not only by its return. ``Motion`` is a ``train.episodes.Watcher``: on
the episodes of ``run_batch`` it measures each episode, and ``pool`` sums the measures up over any set of episodes
(all of them, or those that two controllers both survive: ``both_survived``). ``train.evaluate`` reports them for
every controller and ``train.episodes.evaluate_now`` for each evaluation during training.

Actions are taken as the env applies them, clipped to ``[-1, 1]`` (the compiled core clips every entry). Per
episode of ``L`` control steps of ``dt`` seconds (``PER_EPISODE``):

- ``tilt_rms`` [deg]: the RMS of the torso angle ``th_b`` (observation entry ``Obs.th_b``) after each step;
- ``action_rate``: the mean of ``|a_t - a_{t-1}|`` over both entries and the steps ``t = 2 .. L`` (an episode's first
  action has nothing to change from; nan when ``L = 1``). A constant action has rate 0, one alternating between
  +1 and -1 has rate 2;
- ``saturated_share``: the share of the ``2 L`` action entries at a bound, ``|a| >= 1``;
- ``actuator_power`` [W]: the positive work of the hip and knee torques per second, ``sum_t max(0, W_t) / (L dt)``,
  with ``W_t`` the work over step ``t``: ``info["work_actuators"]`` on the unilateral ground; on the pinned foot,
  whose ``info`` has no such key, ``tau . (q_after - q_before)`` over the hip and knee angles (``q[3:5]`` of the
  state), which is that work exactly, the torques being held over the step (``tau = a * torque_limit``, with the
  episode's own robot's limits when robots are randomised);
- ``peak_normal_force`` [body weights]: the largest ``info["normal_force"]`` (the step's mean normal force; on the
  unilateral ground without the impact impulses of a landing, which ``info["impulse"]`` carries) divided by the
  episode's robot's weight ``m g``; for a robot with ``g = 0``, which has no weight, in newtons;
- ``flights``: the flight phases, steps after which the contact mode (``info["contact_mode"]``) is ``"flight"`` and
  before which (or at the reset) it was not; 0 on the pinned foot, which never leaves the ground. A flight that
  starts and ends within one control step is not seen;
- ``com_excursion`` [m]: the largest horizontal distance of the whole-body COM (``info["com_position"][0]``) from
  where it was at the reset, over the episode's steps.

Over a set of episodes (``pool``, ``KEYS``): ``tilt_rms`` over all their steps, ``action_rate`` over all their
steps after the first, ``saturated_share`` over all their action entries, ``actuator_power`` as their positive work
over their simulated time; ``peak_normal_force`` the mean of the episodes' peaks and ``peak_normal_force_max`` the
largest; ``flights_per_episode`` their mean and ``flights_per_10s`` all flights per 10 s of simulated time;
``com_excursion`` the mean of the episodes'. ``episodes`` counts them; over no episode every measure is nan.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from leg_env.physics.params import PARAM_NAMES, LegParams
from leg_env.tasks.base import Obs

__all__ = ["Motion", "KEYS", "PER_EPISODE", "pool", "pool_records", "both_survived", "Estimate", "motion_table", "motion_sections"]

PER_EPISODE = ("tilt_rms", "action_rate", "saturated_share", "actuator_power", "peak_normal_force", "flights", "com_excursion")
"""The measures of one episode (module docstring), in ``Motion.per_episode()``."""
KEYS = ("episodes", "tilt_rms", "action_rate", "saturated_share", "actuator_power", "peak_normal_force", "peak_normal_force_max",
        "flights_per_episode", "flights_per_10s", "com_excursion")  # fmt: skip
"""The measures over a set of episodes (module docstring), in ``pool``'s result (with ``normal_force_unit``)."""
JOINTS = slice(3, 5)
"""The hip and knee angles ``q1, q2`` in ``q = [x_b, y_b, th_b, q1, q2]``."""


def _robots(envs, info: dict) -> tuple[np.ndarray, np.ndarray]:
    """Each row's weight ``m g`` [N] and torque limits ``(N, 2)`` [N m]: the env's robot, or the row's own one drawn at
    the reset (``info["params"]``, ``leg_env.randomize``)."""
    n = envs.num_envs
    weight = np.full(n, envs.params.weight)
    limit = np.tile(np.asarray(envs.config.torque_limit, dtype=np.float64), (n, 1))
    params = info.get("params")
    if params is not None:
        names = [k for k in PARAM_NAMES if k in params]
        for i in np.flatnonzero(params["_" + names[0]]):
            weight[i] = LegParams(**{k: float(params[k][i]) for k in names}).weight
            limit[i] = params["hip_torque_limit"][i], params["knee_torque_limit"][i]
    return weight, limit


class Motion:
    """The measures of the module docstring for each episode of a ``run_batch`` (a ``train.episodes.Watcher``).

    After the run, ``per_episode()`` gives each episode's measures and ``summary()`` (``pool``) those over all of
    them. ``weight`` holds each episode's robot's weight [N], the divisor of its normal force (0 for a robot with
``g = 0``, whose force is then in newtons).
    """

    def start(self, envs, obs: np.ndarray, info: dict) -> None:
        n = obs.shape[0]
        self.dt = float(envs.dt)
        weight, self._limit = _robots(envs, info)
        self.weight = weight
        self.unit = "m g" if np.all(weight > 0) else ("N" if not np.any(weight > 0) else "m g (N without gravity)")
        self._divisor = np.where(weight > 0, weight, 1.0)
        self._unilateral = "contact_mode" in info  # the unilateral ground's info has the mode and the actuators' work
        self._q = None if self._unilateral else envs.state[0][:, JOINTS].copy()
        self._flying = info["contact_mode"] == "flight" if "contact_mode" in info else np.zeros(n, dtype=bool)
        self._x0 = np.array(info["com_position"][:, 0], dtype=np.float64)
        self._previous = np.zeros((n, 2))
        self.steps = np.zeros(n, dtype=np.int64)
        self.tilt_sq, self.rate_sum, self.saturated, self.work = np.zeros(n), np.zeros(n), np.zeros(n, dtype=np.int64), np.zeros(n)
        self.peak_force, self.flights, self.excursion = np.full(n, -np.inf), np.zeros(n, dtype=np.int64), np.zeros(n)

    def step(self, envs, obs: np.ndarray, actions: np.ndarray, info: dict, active: np.ndarray) -> None:
        a = np.clip(actions, -1.0, 1.0)
        tilt = obs[:, Obs.th_b].astype(np.float64)
        self.tilt_sq[active] += tilt[active] * tilt[active]
        later = active & (self.steps > 0)
        self.rate_sum[later] += np.abs(a[later] - self._previous[later]).sum(axis=1)
        self._previous[active] = a[active]
        self.saturated[active] += np.count_nonzero(np.abs(a[active]) >= 1.0, axis=1)
        self.steps[active] += 1
        if self._unilateral:
            work = np.asarray(info["work_actuators"], dtype=np.float64)
            flying = info["contact_mode"] == "flight"
            self.flights[active & flying & ~self._flying] += 1
            self._flying = np.where(active, flying, self._flying)
        else:
            q = envs.state[0][:, JOINTS]
            work = np.sum(a * self._limit * (q - self._q), axis=1)
            self._q = q
        self.work[active] += np.maximum(work[active], 0.0)
        force = np.asarray(info["normal_force"], dtype=np.float64) / self._divisor
        self.peak_force[active] = np.maximum(self.peak_force[active], force[active])
        away = np.abs(np.asarray(info["com_position"][:, 0], dtype=np.float64) - self._x0)
        self.excursion[active] = np.maximum(self.excursion[active], away[active])

    def per_episode(self) -> dict[str, np.ndarray]:
        """Each episode's ``length`` (steps) and ``PER_EPISODE`` measures, as arrays in the order of the seeds."""
        steps = self.steps
        changes = 2 * (steps - 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return {
                "length": steps.copy(),
                "tilt_rms": np.degrees(np.sqrt(self.tilt_sq / steps)),
                "action_rate": np.where(changes > 0, self.rate_sum / np.maximum(changes, 1), np.nan),
                "saturated_share": self.saturated / (2 * steps),
                "actuator_power": self.work / (steps * self.dt),
                "peak_normal_force": self.peak_force.copy(),
                "flights": self.flights.copy(),
                "com_excursion": self.excursion.copy(),
            }

    def records(self) -> list[dict]:
        """``per_episode()`` as one dict of floats per episode (without ``length``), for a JSON file."""
        table = self.per_episode()
        return [{key: float(table[key][i]) for key in PER_EPISODE} for i in range(len(self.steps))]

    def summary(self, mask: np.ndarray | None = None) -> dict:
        """``pool`` over all episodes, or those of the boolean ``mask``."""
        table = self.per_episode()
        if mask is not None:
            table = {key: values[np.asarray(mask, dtype=bool)] for key, values in table.items()}
        return {**pool(table, self.dt), "normal_force_unit": self.unit}


def pool(table: dict[str, np.ndarray], dt: float) -> dict:
    """The measures over a set of episodes (``KEYS``, module docstring) from each one's ``length`` and ``PER_EPISODE``
    measures (arrays, as ``Motion.per_episode`` gives them), with a control period of ``dt`` [s]."""
    length = np.asarray(table["length"], dtype=np.float64)
    n = len(length)
    if n == 0:
        return {"episodes": 0, **{key: float("nan") for key in KEYS[1:]}}
    v = {key: np.asarray(table[key], dtype=np.float64) for key in PER_EPISODE}
    steps, changes = length.sum(), np.maximum(length - 1.0, 0.0)
    rate = np.where(changes > 0, v["action_rate"], 0.0)
    return {
        "episodes": n,
        "tilt_rms": float(np.sqrt(np.sum(length * v["tilt_rms"] ** 2) / steps)),
        "action_rate": float(np.sum(changes * rate) / changes.sum()) if changes.sum() > 0 else float("nan"),
        "saturated_share": float(np.sum(length * v["saturated_share"]) / steps),
        "actuator_power": float(np.sum(length * v["actuator_power"]) / steps),
        "peak_normal_force": float(v["peak_normal_force"].mean()),
        "peak_normal_force_max": float(v["peak_normal_force"].max()),
        "flights_per_episode": float(v["flights"].mean()),
        "flights_per_10s": float(10.0 * v["flights"].sum() / (steps * dt)),
        "com_excursion": float(v["com_excursion"].mean()),
    }


def pool_records(episodes: Sequence[dict], dt: float, unit: str = "m g") -> dict:
    """``pool`` over per-episode records of ``train.evaluate`` (each with its ``length`` and its ``motion``, the
    ``PER_EPISODE`` measures)."""
    table = {"length": np.array([e["length"] for e in episodes], dtype=np.int64)}
    table.update({key: np.array([e["motion"][key] for e in episodes], dtype=np.float64) for key in PER_EPISODE})
    return {**pool(table, dt), "normal_force_unit": unit}


def both_survived(results: dict[str, dict], policy: str, dt: float) -> None:
    """For each controller of ``results`` (``train.evaluate``'s summaries on the same seeds) other than ``policy``,
    the measures of both restricted to the episodes that both survive, added in place: ``results[name]
    ["both_survived"][policy]`` and ``results[policy]["both_survived"][name]``, each ``pool_records`` of its own
    episodes with the ``seeds`` kept."""
    mine = results[policy]["per_episode"]
    for name, result in results.items():
        if name == policy:
            continue
        theirs = result["per_episode"]
        if [e["seed"] for e in theirs] != [e["seed"] for e in mine]:
            raise ValueError(f"both_survived needs the same episodes: {name} ran other seeds than {policy}")
        keep = [k for k, (a, b) in enumerate(zip(mine, theirs)) if a["survived"] and b["survived"]]
        seeds = [mine[k]["seed"] for k in keep]
        for this, other in ((result, policy), (results[policy], name)):
            episodes = [this["per_episode"][k] for k in keep]
            this.setdefault("both_survived", {})[other] = {"seeds": seeds, **pool_records(episodes, dt, this["motion"]["normal_force_unit"])}


def _cell(value: float, pattern: str) -> str:
    return pattern.format(value) if np.isfinite(value) else "-"


_ROWS = (
    # label, cells of a measure summary
    ("torso tilt RMS [deg]", lambda m: _cell(m["tilt_rms"], "{:.2f}")),
    ("action rate (mean abs change per step)", lambda m: _cell(m["action_rate"], "{:.3g}")),
    ("saturated action entries", lambda m: _cell(100 * m["saturated_share"], "{:.1f}%")),
    ("actuator power (positive work) [W]", lambda m: _cell(m["actuator_power"], "{:.2f}")),
    ("peak normal force, mean / max [{unit}]", lambda m: _cell(m["peak_normal_force"], "{:.2f}") + " / " + _cell(m["peak_normal_force_max"], "{:.2f}")),
    ("flights per episode / per 10 s", lambda m: _cell(m["flights_per_episode"], "{:.1f}") + " / " + _cell(m["flights_per_10s"], "{:.1f}")),
    ("COM excursion from the start [cm]", lambda m: _cell(100 * m["com_excursion"], "{:.2f}")),
)


@dataclass(frozen=True)
class Estimate:
    """A column of ``motion_table`` that estimates the measures with an interval (the IQM of several policies' and its
    confidence interval, say): three dicts of ``KEYS``, the point estimates and the interval's ends."""

    point: dict
    low: dict
    high: dict


def _column_cell(cell, column: dict | Estimate) -> str:
    """A row's cell of one column: the measure, or an estimate with its interval in brackets."""
    if isinstance(column, Estimate):
        return f"{cell(column.point)} [{cell(column.low)}, {cell(column.high)}]"
    return cell(column)


def motion_table(columns: dict[str, dict | Estimate], extra: Sequence[tuple[str, Sequence[str]]] = ()) -> str:
    """A Markdown table of the measures (``pool``'s summaries, or ``Estimate``s of them), one column per name of
    ``columns``; ``extra`` rows ``(label, cells)`` come first."""
    names = list(columns)
    summaries = [c.point if isinstance(c, Estimate) else c for c in columns.values()]
    units = {summary.get("normal_force_unit", "m g") for summary in summaries}
    unit = units.pop() if len(units) == 1 else "m g, or N"
    lines = ["| measure | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]
    lines += [f"| {label} | " + " | ".join(cells) + " |" for label, cells in extra]
    lines += [f"| {label.format(unit=unit)} | " + " | ".join(_column_cell(cell, columns[n]) for n in names) + " |" for label, cell in _ROWS]
    return "\n".join(lines)


def motion_sections(results: dict[str, dict]) -> list[str]:
    """``train.evaluate``'s tables of how the robot moves, from its ``results`` (one summary per controller, the policy
    first): over all episodes; on the episodes that both the policy and each other controller survive (results
    with ``both_survived``), a pair of columns per controller; without pushes (results with ``no_push``)."""
    names = list(results)
    sections = ["How it moves, over all episodes:\n\n" + motion_table({n: results[n]["motion"] for n in names})]
    first = names[0]
    if len(names) > 1 and "both_survived" in results[first]:
        columns = {}
        for name in names[1:]:
            columns[f"{first} (beside {name})"] = results[first]["both_survived"][name]
            columns[name] = results[name]["both_survived"][first]
        counts = [str(c["episodes"]) for c in columns.values()]
        sections.append(f"How it moves on the episodes that both {first} and each controller survive:\n\n"
                        + motion_table(columns, [("episodes both survive", counts)]))  # fmt: skip
    if all("no_push" in results[n] for n in names):
        calm = [results[n]["no_push"] for n in names]
        extra = [("survival rate", [f"{100 * c['survival_rate']:.0f}%" for c in calm]), ("mean return", [f"{c['mean_return']:.2f}" for c in calm])]
        sections.append("How it moves without pushes (`push_force` (0, 0), the same seeds):\n\n"
                        + motion_table({n: c["motion"] for n, c in zip(names, calm)}, extra))  # fmt: skip
    return sections
