r"""``leg_env/PlanarLegPush-v2``: recover from horizontal pushes on the torso, on the unilateral ground.

## Description
The robot, the physics and the balance task of ``PlanarLegStance`` (``leg_env.tasks.stance``), on the exact
unilateral ground (``contact="unilateral"``, the only model here: a pinned foot cannot step), with unannounced
horizontal pushes on the torso's centre of mass. A push is a force ``F`` along ``x`` at the torso's COM, held over whole control steps:

    M qdd + h = S^T tau + Jc^T lam + Q_push,    Q_push = J_b^T (F, 0) = (F, 0, 0, 0, 0)

``J_b = d(x_b, y_b)/dq = [I_2 0]``: the hip, and so the base point, sits at the torso's COM, so the push is
a generalised force on the base coordinates only and exerts no torque on the torso about its COM
(``leg_env.physics.dynamics``). It enters every contact mode's dynamics, the located events and the mode choice
(``leg_env.physics.hybrid``); the step's accumulators book its work ``F (x_b(end) - x_b(start))`` (exact: ``F`` is
constant over the step and ``x_b`` continuous through impacts), so that
``energy(t) - energy(0) = sum(work_actuators + work_push - dissipation_slip - dissipation_impacts)``.

Small pushes can be absorbed standing; the stance LQR of ``policies/lqr.py`` survives 20 N for 0.1 s
(2 N s) and falls at 40 N on the pinned model. Larger pushes need the foot to move: a hop that lands
the foot under the new position of the centre of mass.

## Push schedule (drawn at reset, not observed)
``max_pushes`` (8) pushes per episode, drawn at ``reset`` from the robot's own generator (3 uniforms
each, after the 6 of the posture noise): the first starts at ``first_push`` (uniform in [0.8, 1.2] s),
each next one ``push_interval`` (uniform in [2, 3] s) after the previous start; start times are rounded
to whole control steps. Each lasts ``push_duration`` (0.1 s, rounded to whole steps, at least one). Its
sign is + or - with probability 1/2 and its magnitude is uniform in ``push_force`` (default
[20, 150] N: 2 to 15 N s over 0.1 s, from what the LQR survives to far beyond). After the last
scheduled push (at least 15 s in) there are none. The push is not in the observation; ``info["push_force"]``
is the force held over the step, ``info["work_push"]`` its work.

Quiet episodes, a training option (all off by default): with ``quiet_share`` > 0 one more uniform, drawn after the
pushes', makes that share of the episodes quiet, with no push at all (the other episodes' pushes are the ones drawn
without the option). In a quiet episode the flight charge and the action's change charge are multiplied by
``quiet_flight_scale`` and ``quiet_change_scale``, so that a hop or a jitter with nothing to recover from can cost
more than one after a push; the policy is not told which episode it is in.

## Action and Observation Spaces
``Box(-1, 1, (2,))`` torques, as ``PlanarLegStance``. ``Box((21,), float32)``: the 18 entries of
``PlanarLegStance`` on the unilateral ground; entry 18 (``leg_env.tasks.push.OBS_COM_DRIFT``): the
whole-body COM's ``x`` from where the episode started, ``x_com - x_com,0`` [m], unbounded. That is what
``reward_com`` charges, and the base entry does not carry it (it is measured from the foot's contact point, which
moves with every step). Entries 19-20: the last action (hip, knee), clipped to ``[-1, 1]``, the one the action rate
is charged from (``observe_action``, ``PlanarLegStance``); after a reset, the action that holds the nominal posture.

## Rewards
``reward = reward_alive + reward_drift + reward_unilateral + reward_friction + reward_ctrl + reward_action_rate
+ reward_power + reward_com``, each in ``info``: the first seven are the balance task's (``PlanarLegStance``, which
gives each formula), with these weights:

- ``unilateral_weight = 0.5``: a recovery hop costs its flight time, ``-0.5 flight_time / dt`` per step, but is
  allowed; the base drift is measured from wherever the foot now stands (its contact point), so relocating the foot
  is not charged by it.
- ``drift_angle_weight = 10`` per rad^2 of torso tilt (``StanceConfig``'s default 1): a torso held 15 degrees off level
  costs 0.68 a step, so the posture that meets a push upright earns more than a lean that waits for it.
- ``ctrl_cost_weight = 0.05`` per unit of ``|a|^2`` (``StanceConfig``'s default 0.01), the actuator effort: about 0.012 a
  step to hold the nominal posture (the knee at about -0.48), 0.1 for both joints saturated.
- ``action_rate_weight = 0.2`` per unit of ``|a - a_last|^2``: an action that swings across its range step after
  step (a change of 2 in each entry) costs 1.6 a step, more than the alive bonus, where a smooth recovery's changes
  of a few hundredths cost nothing that matters. Without it, and without the last action in the observation, plain
  PPO learnt to recover by chattering: a change of about 0.7 per step, a third of the entries saturated and 65 W of
  actuator power while nobody pushed it.
- ``power_weight = 0``: positive mechanical power is measured (``train.motion``) but not charged. Charged at 0.005
  or 0.01 per W from the start of training, the power of the exploration noise alone (about 100 W) outweighed what
  a recovery hop earns, and plain PPO never found the hop in 15M steps.

``reward_com = -com_weight (x_com - x_com,0)^2`` (``com_weight = 1`` per m^2) charges the whole-body
centre of mass for moving away from where the episode started, so a hop is not free.

## Starting State, Episode End, Arguments
As ``PlanarLegStance`` (nominal posture, noise ``reset_noise_scale = 0.01``; falls and joint limits
terminate, ``info["ending"]`` naming which; 1000 steps). Every ``PushConfig`` field is a keyword argument, checked by ``leg_env.checks``.

| Parameter        | Default       | Description                                                    |
|------------------|---------------|----------------------------------------------------------------|
| `push_force`     | (20.0, 150.0) | range of the push magnitude [N], 0 <= low <= high              |
| `push_duration`  | 0.1           | [s], rounded to whole control steps (at least one)             |
| `first_push`     | (0.8, 1.2)    | range of the first push's start [s]                            |
| `push_interval`  | (2.0, 3.0)    | range of the time between push starts [s]                      |
| `com_weight`     | 1.0           | per m^2 of whole-body COM displacement along x                 |
| `quiet_share`    | 0.0           | share of the episodes with no push at all, in [0, 1]           |
| `quiet_flight_scale` | 1.0       | in a quiet episode, `reward_unilateral` times this             |
| `quiet_change_scale` | 1.0       | in a quiet episode, `reward_action_rate` times this            |
| `unilateral_weight` | 0.5        | per unit of flight time / dt                                   |
| `drift_angle_weight` | 10.0      | per rad^2 of torso tilt                                        |
| `ctrl_cost_weight` | 0.05        | per unit of `|a|^2`                                            |
| `action_rate_weight` | 0.2       | per unit of `|a - a_last|^2`                                   |
| `observe_action` | True          | the last action as entries 19-20                               |
| `contact`        | "unilateral"  | the only value                                                 |

## Solved
Survival (no termination in 1000 steps) on at least 90% of 100 evaluation episodes with the push
magnitude fixed at ``push_force[1]`` (150 N, 15 N s), on seeds not used in training. A second bar is
relative to the LQR: the push impulse survived 90% of the time at least 1.5 times the LQR's. The references
(``train.evaluate --push-curve``, every push of an episode at one magnitude, seeds 10000..10099): the stance
LQR (``policies/lqr.py``) survives 90% of the episodes up to 2.25 N s; the stepping controller
(``policies/stepping.py``: the LQR, and one quick hop for a push it cannot stand) up to 4.5 N s, and 3% of
the episodes with the task's own 20-150 N; the push MPC (``policies/push_mpc.py``: iLQR on the step's exact
Jacobians around the stepping controller while it recovers) up to 7.0 N s, within every bar below but the
randomised robots' (72%). The range's upper end is beyond both: most of it tells a
recovering policy from a falling one only in how long it lasts.

How a policy moves has bars of its own (``train.bars``, which ``train.evaluate`` and the learning pages check): the
90% level at least 6.0 N s; with no push at all, every episode survives with no flight, an action rate of at most
0.01 and an actuator power of at most 2 W (the controllers stand still on 0.2 W); pushed at 5 N s, an action rate of
at most 0.10, at most 10% of the action entries saturated and at most twice the stepping controller's actuator
power; on randomised robots (``randomize=True``) at least 90% survival at 3.4 N s.

## PPO from scratch
The configuration of ``train/hyperparams/ppo.yml`` (plain PPO, 1024 envs, batch 16384, 4 epochs, a discount of
0.998, an entropy bonus of 0.005, an initial action noise of std 0.61, 24M steps, no schedule) trains on pushes of
0-50 N (the first at 0.3-0.6 s, then every 1-3 s), starts of noise 0.05, ten times the balance task's weight on the
base offset and ten times the task's weight on the COM's distance from its start; its effort and smoothness charges
are the task's. Its in-training evaluations and the selection use pushes of 50 N. On 100 held-out episodes
(``benchmarks/results/learning/PlanarLegPush-v2``; seeds 11-15, seed 11 named as the shipped one before any trained)
every seed found the recovery hop by 12M steps and survives 98-100% of the episodes at 50 N; four seeds survive 90%
of the episodes up to 6.0 or 7.0 N s, one up to 5.75 N s (IQM 6.00 N s [5.83, 6.67]; the stepping controller 4.5
N s). Pushed at 5 N s they move as no policy on v1 did: the torso 3.9-5.2 degrees RMS off level (the stepping
controller 15.0), an action rate of 0.087-0.112 (v1's policy 0.66), 8.6-12.3% of the entries saturated (44%) and
15-17 W (79 W; the stepping controller 10.5 W). **No seed meets every bar**: with no push at all every seed hops
about once a second (11.8-13.4 flights an episode), with an action rate of 0.052-0.067 and 6.4-8.8 W where the
controllers stand still on 0.17 W; two seeds' action rate (0.103, 0.112) and two seeds' saturated share (10.7%,
12.3%) pushed at 5 N s, and one seed's 90% level, miss their bars too. Unpushed, the policy's action barely moves from
the holding torque, the base drifts a few centimetres from its place over the foot and a short hop puts the foot
back under it, although standing still as the controllers do would earn about 70 more an episode. Training twice as
long (48M steps, the action noise falling from std 0.17 to 0.08-0.10) left that unchanged (13.2 flights an episode,
with or without the entropy bonus): the hop that re-places the foot is a habit plain PPO does not leave. Each seed's 24M steps
took 9.9-11.4 minutes on one core of a 2-core AMD EPYC (Zen 4) beside another seed, evaluations included. The shipped
seed 11 (``policies/ppo_push_v2``) reaches 6.0 N s. Trained on randomised robots (``randomize=True``,
``train/hyperparams/ppo_randomized.yml``; seed 16, ``policies/ppo_push_randomized``) the configuration survives all
100 held-out randomised robots at 3.4 N s (the stepping controller 52%, the LQR none) and 90% of them up to 6.0 N s;
the nominal ``ppo_push_v2`` survives them all too (5.5 N s).

What was tried on the way (the power charged, a larger flight charge, calmer training pushes, no entropy bonus, gSDE)
is kept with the research records (``research/push_probes.md``).

## Version History
* v2: effort and smoothness are charged and the last action is observed (entries 19-20): the action's change
  (``action_rate_weight`` 0.2, was 0), the torque squared (``ctrl_cost_weight`` 0.05, was 0.01) and the torso's tilt
  (``drift_angle_weight`` 10, was 1). Plain PPO on v1 recovered from every push by chattering, pushed or not: its
  action moved by about 0.7 a step, with a third of the entries saturated and 65 W spent standing unpushed.
* v1 (removed): the whole-body COM's ``x`` from its start is observation entry 18: the COM term of the reward depends on it,
  and v0's observation did not carry it. On v0 plain PPO did not learn recovery: dense pushes taught a hop that
  never stops, which wandered and fell at small pushes; on v1 that hop stays within about a centimetre of its start.
* v0 (removed): initial version.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import checks
from .._core import kernels
from ..physics import layout
from .base import StanceConfig, Task, observation_space as _stance_space
from .stance import REWARD_TERMS as _STANCE_TERMS

__all__ = ["PushConfig", "TASK", "MAX_PUSHES", "REWARD_TERMS", "INFO_NAMES", "OBS_COM_DRIFT"]

MAX_STEPS = 2**31 - 1  # control steps a setting can count (an int32 of the compiled core)
OBS_COM_DRIFT = layout.OBS["push_com_drift"]  # 18: the COM's x from its start
MAX_PUSHES = kernels.PUSH_MAX  # pushes scheduled per episode (8): at least 0.8 + 7 x 2 s = 14.8 s of them
REWARD_TERMS = _STANCE_TERMS + ("com",)
N_TERMS = len(REWARD_TERMS)
INFO_NAMES = ("push_force", "work_push")
_DRAWS_PER_PUSH = 3  # start time, sign, magnitude
_BIG = 1.0e6
PUSH_RANGES = {
    # name: (low, high, unit) of each end of a range, or of the value
    "push_force": (0.0, _BIG, "N"),
    "push_duration": (0.0, 10.0, "s"),
    "first_push": (0.0, 1.0e4, "s"),
    "push_interval": (0.0, 1.0e4, "s"),
    "com_weight": (0.0, _BIG, ""),
    "quiet_share": (0.0, 1.0, ""),
    "quiet_flight_scale": (0.0, _BIG, ""),
    "quiet_change_scale": (0.0, _BIG, ""),
}
"""Accepted ranges of the ``PushConfig`` fields (``(low, high, unit)``; ``push_duration`` and the interval
must be positive)."""


@dataclass(frozen=True)
class PushConfig(StanceConfig):
    """Settings of the push-recovery task: the balance task's (``StanceConfig``) and the push schedule's.

    Raises:
        ValueError, ArgumentTypeError: as ``StanceConfig``, for every field (``leg_env.checks``).
    """

    unilateral_weight: float = 0.5  # per unit of flight time / dt: a recovery hop is allowed, not free
    drift_angle_weight: float = 10.0  # per rad^2 of torso tilt: upright between pushes
    ctrl_cost_weight: float = 0.05  # per unit of |action|^2: the actuator effort
    action_rate_weight: float = 0.2  # per unit of |action - last action|^2: no chatter
    observe_action: bool = True  # the last action as entries 19-20, what the action rate is charged from
    contact: str = "unilateral"
    push_force: tuple = (20.0, 150.0)  # range of the push magnitude [N]
    push_duration: float = 0.1  # [s], rounded to whole control steps
    first_push: tuple = (0.8, 1.2)  # range of the first push's start [s]
    push_interval: tuple = (2.0, 3.0)  # range of the time between push starts [s]
    com_weight: float = 1.0  # per m^2 of whole-body COM displacement along x
    quiet_share: float = 0.0  # share of the episodes with no push at all (drawn at each reset)
    quiet_flight_scale: float = 1.0  # in such an episode, the flight charge (reward_unilateral) times this
    quiet_change_scale: float = 1.0  # in such an episode, the action's change charge (reward_action_rate) times this

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("push_force", "first_push", "push_interval"):
            lo, hi, unit = PUSH_RANGES[name]
            value = checks.pair(f"PushConfig.{name}", getattr(self, name), lo, hi, lo_open=name == "push_interval", unit=unit)
            if not value[0] <= value[1]:
                raise ValueError(f"PushConfig.{name} must be (low, high) with low <= high, got {value!r}")
            object.__setattr__(self, name, value)
        for name in ("push_duration", "com_weight", "quiet_share", "quiet_flight_scale", "quiet_change_scale"):
            lo, hi, unit = PUSH_RANGES[name]
            value = checks.real(f"PushConfig.{name}", getattr(self, name), lo, hi, lo_open=name == "push_duration", unit=unit)
            object.__setattr__(self, name, value)
        if round(self.push_duration / self.dt) > MAX_STEPS:
            raise ValueError(f"PushConfig.push_duration must be at most {MAX_STEPS} control steps of dt = {self.dt} s, got {self.push_duration!r} s")
        if self.contact != "unilateral":
            raise ValueError(f"PushConfig.contact must be 'unilateral' (a pinned foot cannot step), got {self.contact!r}")

    @property
    def push_steps(self) -> int:
        """Control steps of one push: ``push_duration / dt`` rounded, at least one."""
        return max(1, int(round(self.push_duration / self.dt)))

    def task_settings(self, row: np.ndarray) -> None:
        """The push's length in control steps, the COM weight and the quiet episodes' scales, in its ``settings`` row."""
        row["push_steps"], row["w_com"] = self.push_steps, self.com_weight
        row["quiet_flight_scale"], row["quiet_change_scale"] = self.quiet_flight_scale, self.quiet_change_scale


def observation_space(params, config: PushConfig):
    """``PlanarLegStance``'s 18 entries on the unilateral ground, then the whole-body COM's x from its start [m],
    unbounded."""
    from gymnasium import spaces

    base = _stance_space(params, config)
    return spaces.Box(np.append(base.low, np.float32(-np.inf)), np.append(base.high, np.float32(np.inf)), dtype=np.float32)


def _draws(config: PushConfig) -> int:
    """3 uniforms a push, and with ``quiet_share`` > 0 one more, last, that decides whether the episode is quiet
    (so that a task without quiet episodes draws what it always drew)."""
    return _DRAWS_PER_PUSH * MAX_PUSHES + int(config.quiet_share > 0)


def _columns(draws: np.ndarray, config: PushConfig) -> dict:
    """The schedule of ``k`` robots from their ``(k, _draws(config))`` uniforms: each push's start and force, and
    whether the episode is quiet.

    Push ``j`` uses draws ``3 j`` (start time), ``3 j + 1`` (sign) and ``3 j + 2`` (magnitude); a quiet episode
    (draw ``3 MAX_PUSHES`` below ``quiet_share``) has no push at all. Row by row the same arithmetic whatever ``k``
    is, so a batch's schedules are the single env's bit for bit.
    """
    k = draws.shape[0]
    n = _DRAWS_PER_PUSH * MAX_PUSHES
    quiet = draws[:, n] < config.quiet_share if draws.shape[1] > n else np.zeros(k, dtype=bool)
    u = draws[:, :n].reshape(k, MAX_PUSHES, _DRAWS_PER_PUSH)
    (f0, f1), (i0, i1), (m0, m1) = config.first_push, config.push_interval, config.push_force
    gaps = np.empty((k, MAX_PUSHES))
    gaps[:, 0] = f0 + (f1 - f0) * u[:, 0, 0]
    gaps[:, 1:] = i0 + (i1 - i0) * u[:, 1:, 0]
    times = np.cumsum(gaps, axis=1)
    sign = np.where(u[:, :, 1] < 0.5, 1.0, -1.0)
    times[quiet] = np.inf
    # the start's control step (a push past 2^30 steps, 124 days at 100 Hz, never comes)
    return {
        "push_start": np.minimum(np.rint(times / config.dt), 2.0**30),
        "push_force": sign * (m0 + (m1 - m0) * u[:, :, 2]),
        "quiet": quiet,
    }


TASK = Task(
    name="push",
    config_cls=PushConfig,
    reward_terms=REWARD_TERMS,
    kernel=1,
    observation_space=observation_space,
    info_names=INFO_NAMES,
    draws=_draws,
    columns=_columns,
)
"""The push-recovery task as the shared environments see it (``leg_env.tasks.base.Task``)."""
