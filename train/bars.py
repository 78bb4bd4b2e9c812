"""Acceptance bars of the unilateral tasks, as data, and the check of one policy's held-out evaluation against them.

A bar is one number of a policy's held-out evaluation (100 episodes) and its threshold. The check takes what
``train.evaluate`` produces for a policy and its controllers on the same episodes: one summary per controller, the
policy first, each with its ``env_id`` and ``env_kwargs``, the motion measures (``motion``, ``train.motion``),
``both_survived`` and, on the push task, ``no_push``; ``push_impulse_90`` where the push curve was measured.

The task is read from the env id's name with its version stripped (``leg_env/PlanarLegHop-v4``: ``PlanarLegHop``),
so every version of a task has the same bars:

- **balance** (``PlanarLegBalance``; controllers gated and LQR): survival >= 98%; mean return >= the gated
  controller's and >= the LQR's; torso tilt RMS, action rate and actuator power <= the gated controller's;
- **hop** (``PlanarLegHop``; the hopper): survival >= 98%; >= 10 hops (of 50 ms or more) per episode; mean
  absolute apex error <= 1.5 cm; mean COM drift at the end of the episodes (those that ran their 10 s) <= 5 cm;
  COM excursion, action rate, saturated share, actuator power and peak normal force <= the hopper's; torso tilt
  RMS <= 8 degrees;
- **push** (``PlanarLegPush``; the stepping controller): the largest push impulse survived in 90% of the
  episodes (the push curve, ``train.evaluate --push-curve``) >= 6.0 N s; with no push at all (``no_push``): every
  episode survived, no flight, action rate <= 0.01, actuator power <= 2 W; pushed at 5 N s (an evaluation env
  with ``push_force`` (50, 50)): action rate <= 0.10, saturated share <= 10%, actuator power <= 2 times the
  stepping controller's;
- **push on randomised robots** (``PlanarLegPush`` evaluated with ``randomize``): survival >= 90% with every push
  at 3.4 N s (``push_force`` (34, 34)).

Which episodes: a bar with a fixed threshold is measured on all the evaluation's episodes; a comparison with a
controller on the episodes that both survive (``train.motion.both_survived``: a falling robot's actions swing),
except the return, which is compared on all of them. A bar tied to an evaluation env (the pushes at 5 N s) is
measured only on evaluations of that env. A bar whose number the results lack (no run of its controller, no push
curve, another env) is not measured (``passed`` None), and a policy meets every bar only when each one is measured
and passed. A measured nan (no episode both survive, none ran its 10 s) fails.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Sequence

__all__ = ["Bar", "BarCheck", "TASK_BARS", "RANDOMIZED_TASK_BARS", "task_name", "bars_for", "bar_controllers",
           "check_bars", "meets_every_bar", "bars_table"]  # fmt: skip

ALL = "all episodes"
BOTH_SURVIVED = "episodes both survive"
NO_PUSH = "no push"
"""Which episodes a bar's number comes from: the evaluation's, those the policy and the bar's controller both
survive, or the same seeds with no push at all (the push task's ``no_push``)."""

BALANCE_SURVIVAL = 0.98
HOP_SURVIVAL = 0.98
HOP_HOPS_PER_EPISODE = 10.0
HOP_APEX_ERROR = 0.015  # [m]
HOP_DRIFT = 0.05  # [m]
HOP_TILT_RMS = 8.0  # [deg]
PUSH_IMPULSE_90 = 6.0  # [N s]
NO_PUSH_SURVIVAL = 1.0
NO_PUSH_FLIGHTS = 0.0  # per episode
NO_PUSH_ACTION_RATE = 0.01
NO_PUSH_ACTUATOR_POWER = 2.0  # [W]
PUSHED_FORCE = (50.0, 50.0)  # [N] over the task's 0.1 s push: 5 N s
PUSHED_ACTION_RATE = 0.10
PUSHED_SATURATED_SHARE = 0.10
PUSHED_POWER_FACTOR = 2.0  # times the stepping controller's
RANDOMIZED_PUSH_FORCE = (34.0, 34.0)  # [N]: 3.4 N s
RANDOMIZED_PUSH_SURVIVAL = 0.90


@dataclass(frozen=True)
class Bar:
    """One acceptance bar: ``measure`` of the policy's evaluation at least or at most ``bound``, or ``bound`` times
    the same measure of ``controller``."""

    label: str
    """What is measured, as the tables name it."""
    measure: str
    """The key of the number in a summary, or in its ``motion`` (``train.motion.KEYS``)."""
    at_least: bool
    """True: the measure must be >= the threshold; False: <=."""
    bound: float
    """The threshold, or with a ``controller`` the factor of that controller's measure."""
    controller: str | None = None
    """The controller compared with (a name of ``train.policy_loading.BASELINES``), or None for a fixed threshold."""
    episodes: str = ALL
    """``ALL``, ``BOTH_SURVIVED`` or ``NO_PUSH``."""
    env: tuple[tuple[str, object], ...] = ()
    """Evaluation env arguments the bar needs (``(("push_force", (50.0, 50.0)),)``); measured only on such an env."""
    context: str = ""
    """Where the bar holds, heading its description (``"pushed at 5 N s"``)."""
    scale: float = 1.0
    """Factor from the measure's unit to the shown one (100: metres to centimetres, or a share to percent)."""
    pattern: str = "{:.3g}"
    """How a shown number is written."""

    def show(self, value: float | None) -> str:
        """``value`` (in the measure's unit) as the tables write it."""
        if value is None:
            return "-"
        return "nan" if math.isnan(value) else self.pattern.format(self.scale * value)

    @property
    def description(self) -> str:
        """The bar in words: ``"survival >= 98%"``, ``"actuator power <= 2x stepping's (episodes both survive)"``."""
        sign = ">=" if self.at_least else "<="
        if self.controller is None:
            text = f"{self.label} {sign} {self.show(self.bound)}"
        else:
            factor = "" if self.bound == 1.0 else f"{self.bound:g}x "
            text = f"{self.label} {sign} {factor}{self.controller}'s"
            if self.episodes == BOTH_SURVIVED:
                text += f" ({BOTH_SURVIVED})"
        return f"{self.context}: {text}" if self.context else text


@dataclass(frozen=True)
class BarCheck:
    """A bar checked on one evaluation: the number measured, the threshold it had to meet, and whether it did
    (None: not measured, ``note`` says why)."""

    description: str
    measured: float | None
    threshold: float | None
    passed: bool | None
    note: str = ""
    bar: Bar | None = None

    def as_dict(self) -> dict:
        """The check as a JSON-ready dict (without its bar)."""
        return {"description": self.description, "measured": self.measured, "threshold": self.threshold, "passed": self.passed,
                **({"note": self.note} if self.note else {})}  # fmt: skip

    def cell(self) -> str:
        """The check as a table cell: pass or fail with the number measured (and a controller's threshold)."""
        if self.passed is None:
            return f"not measured ({self.note})" if self.note else "not measured"
        show = self.bar.show if self.bar is not None else (lambda v: f"{v:.3g}")
        verdict = "pass" if self.passed else "**fail**"
        relative = self.bar is not None and self.bar.controller is not None
        notes = ([f"bar {show(self.threshold)}"] if relative else []) + ([self.note] if self.note else [])
        return f"{verdict}: {show(self.measured)}" + (f" ({'; '.join(notes)})" if notes else "")


BALANCE_BARS = (
    Bar("survival", "survival_rate", True, BALANCE_SURVIVAL, scale=100.0, pattern="{:.0f}%"),
    Bar("mean return", "mean_return", True, 1.0, "gated", pattern="{:.1f}"),
    Bar("mean return", "mean_return", True, 1.0, "lqr", pattern="{:.1f}"),
    Bar("torso tilt RMS", "tilt_rms", False, 1.0, "gated", BOTH_SURVIVED, pattern="{:.2f} deg"),
    Bar("action rate", "action_rate", False, 1.0, "gated", BOTH_SURVIVED),
    Bar("actuator power", "actuator_power", False, 1.0, "gated", BOTH_SURVIVED, pattern="{:.2f} W"),
)
HOP_BARS = (
    Bar("survival", "survival_rate", True, HOP_SURVIVAL, scale=100.0, pattern="{:.0f}%"),
    Bar("hops of 50 ms+ per episode", "hops_per_episode", True, HOP_HOPS_PER_EPISODE, pattern="{:.1f}"),
    Bar("mean abs apex error", "mean_abs_apex_error", False, HOP_APEX_ERROR, scale=100.0, pattern="{:.2f} cm"),
    Bar("mean COM drift at the end", "mean_drift_10s", False, HOP_DRIFT, scale=100.0, pattern="{:.2f} cm"),
    Bar("COM excursion", "com_excursion", False, 1.0, "hopper", BOTH_SURVIVED, scale=100.0, pattern="{:.2f} cm"),
    Bar("action rate", "action_rate", False, 1.0, "hopper", BOTH_SURVIVED),
    Bar("saturated share", "saturated_share", False, 1.0, "hopper", BOTH_SURVIVED, scale=100.0, pattern="{:.1f}%"),
    Bar("actuator power", "actuator_power", False, 1.0, "hopper", BOTH_SURVIVED, pattern="{:.2f} W"),
    Bar("peak normal force", "peak_normal_force", False, 1.0, "hopper", BOTH_SURVIVED, pattern="{:.2f} m g"),
    Bar("torso tilt RMS", "tilt_rms", False, HOP_TILT_RMS, pattern="{:.1f} deg"),
)
_PUSHED = (("push_force", PUSHED_FORCE),)
PUSH_BARS = (
    Bar("push impulse survived 90% of the time", "push_impulse_90", True, PUSH_IMPULSE_90, pattern="{:.2f} N s"),
    Bar("survival", "survival_rate", True, NO_PUSH_SURVIVAL, episodes=NO_PUSH, context="with no push", scale=100.0, pattern="{:.0f}%"),
    Bar("flights per episode", "flights_per_episode", False, NO_PUSH_FLIGHTS, episodes=NO_PUSH, context="with no push", pattern="{:.1f}"),
    Bar("action rate", "action_rate", False, NO_PUSH_ACTION_RATE, episodes=NO_PUSH, context="with no push"),
    Bar("actuator power", "actuator_power", False, NO_PUSH_ACTUATOR_POWER, episodes=NO_PUSH, context="with no push", pattern="{:.2f} W"),
    Bar("action rate", "action_rate", False, PUSHED_ACTION_RATE, env=_PUSHED, context="pushed at 5 N s"),
    Bar("saturated share", "saturated_share", False, PUSHED_SATURATED_SHARE, env=_PUSHED, context="pushed at 5 N s", scale=100.0, pattern="{:.1f}%"),
    Bar("actuator power", "actuator_power", False, PUSHED_POWER_FACTOR, "stepping", BOTH_SURVIVED, env=_PUSHED, context="pushed at 5 N s",
        pattern="{:.2f} W"),
)  # fmt: skip
RANDOMIZED_PUSH_BARS = (
    Bar("survival", "survival_rate", True, RANDOMIZED_PUSH_SURVIVAL, env=(("push_force", RANDOMIZED_PUSH_FORCE),),
        context="randomised robots pushed at 3.4 N s", scale=100.0, pattern="{:.0f}%"),
)  # fmt: skip

TASK_BARS = {"PlanarLegBalance": BALANCE_BARS, "PlanarLegHop": HOP_BARS, "PlanarLegPush": PUSH_BARS}
"""Each task's bars, by the name of its env id without the version."""
RANDOMIZED_TASK_BARS = {"PlanarLegPush": RANDOMIZED_PUSH_BARS}
"""A task's bars when its evaluation draws randomised robots (``randomize``); a task not here keeps its own."""


def task_name(env_id: str) -> str:
    """The env id's name without its namespace and version: ``leg_env/PlanarLegPush-v2`` gives ``PlanarLegPush``."""
    return re.sub(r"-v\d+$", "", env_id.split("/")[-1])


def bars_for(env_id: str, env_kwargs: dict | None = None) -> tuple[Bar, ...]:
    """The bars of ``env_id``'s task, evaluated with ``env_kwargs`` (randomised robots have their own); none for a
    task without bars."""
    name = task_name(env_id)
    if (env_kwargs or {}).get("randomize") and name in RANDOMIZED_TASK_BARS:
        return RANDOMIZED_TASK_BARS[name]
    return TASK_BARS.get(name, ())


def bar_controllers(env_id: str, env_kwargs: dict | None = None) -> tuple[str, ...]:
    """The controllers the task's bars compare a policy with, each once, in the bars' order."""
    return tuple(dict.fromkeys(bar.controller for bar in bars_for(env_id, env_kwargs) if bar.controller is not None))


def _same(value, wanted) -> bool:
    """Whether an env argument equals a bar's (a sequence compared entry by entry as floats)."""
    if isinstance(wanted, tuple):
        try:
            return len(value) == len(wanted) and all(float(v) == w for v, w in zip(value, wanted))
        except TypeError:
            return False
    return value == wanted


def _number(summary: dict | None, measure: str) -> float | None:
    """The measure's number in a summary (at its top or in its ``motion``), None if it has none."""
    if summary is None:
        return None
    value = summary[measure] if measure in summary else summary.get("motion", {}).get(measure)
    return None if value is None else float(value)


def _episodes(result: dict, bar: Bar, other: str | None) -> dict | None:
    """The summary of ``result`` over the bar's episodes (beside the controller ``other``), None if it has none."""
    if bar.episodes == NO_PUSH:
        return result.get("no_push")
    if bar.episodes == BOTH_SURVIVED:
        return result.get("both_survived", {}).get(other)
    return result


def _check(bar: Bar, results: dict[str, dict], policy: str, env_kwargs: dict) -> BarCheck:
    """One bar on the results of ``policy`` and its controllers."""
    missing = [key for key, wanted in bar.env if not (key in env_kwargs and _same(env_kwargs[key], wanted))]
    if missing:
        needed = ", ".join(f"{key} {wanted}" for key, wanted in bar.env)
        return BarCheck(bar.description, None, None, None, f"needs an evaluation env with {needed}", bar)
    if bar.controller is not None and (bar.controller == policy or bar.controller not in results):
        why = f"the policy is {policy} itself" if bar.controller == policy else f"no {bar.controller} run"
        return BarCheck(bar.description, None, None, None, why, bar)
    measured = _number(_episodes(results[policy], bar, bar.controller), bar.measure)
    threshold = bar.bound
    if bar.controller is not None:
        reference = _number(_episodes(results[bar.controller], bar, policy), bar.measure)
        threshold = None if reference is None else bar.bound * reference
    if measured is None or threshold is None:
        where = {NO_PUSH: " with no push", BOTH_SURVIVED: " on the episodes both survive"}.get(bar.episodes, "")
        return BarCheck(bar.description, measured, threshold, None, f"no {bar.measure}{where} in the results", bar)
    passed = measured >= threshold if bar.at_least else measured <= threshold  # False when either is nan
    none_both = bar.episodes == BOTH_SURVIVED and results[policy]["both_survived"][bar.controller].get("episodes") == 0
    return BarCheck(bar.description, measured, threshold, bool(passed), "no episode both survive" if none_both else "", bar)


def check_bars(results: dict[str, dict], env_id: str | None = None) -> list[BarCheck]:
    """Check the policy of ``results`` against its task's bars: one ``BarCheck`` per bar, in the bars' order.

    ``results`` is ``train.evaluate``'s for one policy and its controllers on the same episodes (one summary per
    name, the policy first; a controller under its name in ``train.policy_loading.BASELINES``). The task is
    ``env_id``, else the policy's summary's ``env_id``; the evaluation env is its ``env_kwargs``. An empty list for
    a task without bars.
    """
    policy = next(iter(results))
    env_id = env_id or results[policy]["env_id"]
    env_kwargs = results[policy].get("env_kwargs") or {}
    return [_check(bar, results, policy, env_kwargs) for bar in bars_for(env_id, env_kwargs)]


def meets_every_bar(checks: Sequence[BarCheck]) -> bool:
    """Whether every bar was measured and passed (and there is at least one)."""
    return bool(checks) and all(check.passed is True for check in checks)


def bars_table(columns: dict[str, Sequence[BarCheck]]) -> str:
    """A Markdown table of the bars, one row per bar and one column per policy (each checked on the same bars),
    then a row saying whether each policy meets every bar."""
    names = list(columns)
    first = list(columns[names[0]])
    lines = ["| bar | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for k, check in enumerate(first):
        lines.append(f"| {check.description} | " + " | ".join(list(columns[n])[k].cell() for n in names) + " |")
    lines.append("| **every bar** | " + " | ".join("**yes**" if meets_every_bar(columns[n]) else "no" for n in names) + " |")
    return "\n".join(lines)
