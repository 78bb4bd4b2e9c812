r"""``leg_env/PlanarLegHop-v4``: hop in place to a commanded apex height, on the unilateral ground, with effort and
smoothness charged.

## Description
The robot and the exact unilateral ground of ``PlanarLegStance`` (``contact="unilateral"``, the only
model here: a pinned foot cannot hop). Each episode draws a command ``dh*``, uniform in
``command_range`` (5 to 15 cm): the rise of the whole-body centre of mass at the apex of each hop above
its standing height ``y_stand`` (the COM height of the nominal posture, 0.784 m at the default
parameters). The command is in the observation. There is no equilibrium to linearise about: the task is
a periodic hybrid orbit (stance, lift-off, flight, touchdown). The reward pays the hops' apex and charges, beside
the outcome, how the robot gets there: the actuators' effort, the action's change from step to step, the torso's
tilt and the COM's excursion at every step, so that a smooth, upright, economical gait earns more than chatter that
reaches the same apex.

## Observation Space
``Box((24,), float32)``: the 18 entries of ``PlanarLegStance`` on the unilateral ground (base relative to the
ground point under the foot, angles, velocities, mean contact force, foot height and velocity, contact flag, slip
direction, impact impulse), then what the reward depends on and nothing else observes: ``dh*`` [m] (entry 18,
``Obs.command``); the COM's horizontal distance from where it started, ``x_com - x_com,0`` [m] (entry 19,
``Obs.com_drift``); the ground time [s] (entry 20, ``Obs.ground_time``): the time since the last hop (a flight of
at least ``min_flight`` = 150 ms) ended, or since the start (a touchdown that lifts off again within the same
control step does not end a flight); the apex rise of the last hop the robot landed, the COM's apex above
``y_stand`` [m] (entry 21, ``Obs.last_apex``; 0 before the first hop); and the last action (entries 22-23, clipped;
after a reset the action that holds the nominal posture), the one the action's change is charged from
(``observe_action``).

## Rewards
``reward = reward_alive + reward_height + reward_drift + reward_tilt + reward_impact + reward_slip
+ reward_ctrl + reward_limit + reward_action_rate + reward_power``, each in ``info``:

- ``reward_alive = alive_bonus`` (1) on a healthy step while the ground time is at most ``max_ground_time``
  (1 s): the robot must keep hopping.
- ``reward_height = height_weight (k(e, height_scale) + k(e, height_scale_fine))`` (2; 0.05 m and 0.01 m),
  ``k(e, s) = exp(-(e / s)^2)``, at every step while the ground time is at most ``max_ground_time`` (the rule of
  the alive bonus), where ``e`` is the apex error of the last hop the robot has landed (nothing before the first):
  its COM apex above ``y_stand`` minus the command (entry 21 minus entry 18). A coarse kernel to find the apex, a
  fine one to hit it: up to twice the weight. A hop's apex is paid from its landing until the next hop lands, so
  the term depends not on how much of the time the robot spends in the air or how often it hops, only on how
  close its hops come to the command. The apex is the ballistic one of the flight's vertical energy
  ``E_v = m y_com'^2 / 2 + m g y_com``, constant in flight: ``y_com + y_com'^2 / 2g`` at lift-off, with no apex
  event to locate. A hop is a flight of at least ``min_flight`` = 150 ms: shorter flights (the lift-offs of a
  bounce in place, a stumble) are paid nothing. A flight of 150 ms rises 2.8 cm from lift-off to apex, so a hop to
  the lowest commands (5 cm) lifts off with the COM at most 2.2 cm above standing, its leg not yet straight.
- ``reward_drift = -drift_com_weight (x_com - x_com,0)^2`` (30 per m^2) at every step: the COM stays over its
  start during the episode, not only at its end (5 cm off costs 0.075 a step). A second charge for training,
  ``-c (1 - exp(-drift_near_weight (x_com - x_com,0)^2 / c))`` with ``c = drift_near_cap``, adds a strong pull near
  the start that never takes more than ``c`` a step; ``drift_near_weight`` is 0 in the registered task (with ``c``
  infinite the second charge is quadratic too).
- ``reward_tilt = -tilt_weight th_b^2`` (10 per rad^2): the torso upright. A lean of 8 degrees costs 0.19 a step,
  one of 36 degrees (v3's PPO gait) 4, as much as a hop on the command earns.
- ``reward_impact = -impact_weight (|P| / m)^2`` (0.5 per (m/s)^2): ``P`` the step's impact impulses on
  the foot, so hard landings cost the velocity change they impose on the robot.
- ``reward_slip = -slip_weight slip_distance / dt`` (1 per m/s of mean slip speed).
- ``reward_ctrl = -ctrl_cost_weight |a|^2`` (0.5): the actuator effort; both joints at their limits cost 1 a step.
- ``reward_limit = -limit_weight (e_hip^2 + e_knee^2)``, ``e`` how far a joint is inside the last ``limit_margin``
  (0.05 rad) of its range (``hip_range``, ``knee_range``; an episode ends past either end), 0 elsewhere: a
  training setting, ``limit_weight`` 0 in the registered task, which warns of the range's end before the episode
  ends there.
- ``reward_action_rate = -(action_rate_weight |a - a_last|^2 + action_change_weight |a - a_last|_1)`` (0 and 1, as
  in ``PlanarLegStance``): the action's change in absolute value, summed over the two entries, so that a jitter
  costs in proportion to the action rate ``train.motion`` measures (the hopper's 0.063 per entry costs 0.13 a
  step; v3's PPO policy's 0.170, 0.34).
- ``reward_power = -power_weight (max(0, tau_hip dq1) + max(0, tau_knee dq2)) / dt`` (0.006 per W, as in
  ``PlanarLegStance``): the joints' positive mechanical power; the hopper's 43 W costs 0.26 a step, v3's PPO
  policy's 100 W 0.6. Twice this weight (0.012) or more, PPO never finds the hop (``research/hop_probes.md``).

The options ``motor_speed`` (the motor model) and the squared charge on the action's change
(``action_rate_weight``) are the balance task's too (``inf`` and 0 here).

Flight is the task, so it is not charged. **Unilateral violation** here means what it means on the
unilateral ground of ``PlanarLegStance``: ``info["unilateral_violation"]`` (``lam_y < 0``) and
``friction_violation`` can only come from a Zeno settle or a Painleve jam (``leg_env.physics.hybrid``); the ground
never pulls. ``info["flight_time"]``, ``impulse`` and the event counts describe the hops.

## Starting State, Episode End
The nominal posture plus noise ``reset_noise_scale = 0.01`` (as ``PlanarLegStance``); the command is drawn
after the posture noise (one uniform). With ``command_period`` finite (a setting for training; the registered
task has ``inf``, one command per episode) the reset also draws ``COMMANDS_AHEAD`` (4) more commands, each
held for ``command_period`` seconds in turn after the first; after the last the command holds. A step's height
term is judged by the command in force during it, and the observation shows the next one from the step that ends
a period. Terminates on a fall (torso below 0.5 m above the ground or below
the knee, ``|th_b| > 1`` rad) or a joint out of range, ``info["ending"]`` naming which (``leg_env.ENDINGS``);
truncated at 1000 steps (10 s).

## Solved
Over 100 evaluation episodes on seeds not used in training or selection, beside the model-based hopper
(``policies.hopper``) on the same episodes (``train.evaluate``, whose hop metrics are
``train.task_metrics.HopTracker``'s; the bars are ``train.bars``): survival of at least 98%; at least 10 hops
(flights of 50 ms or more) per 10 s episode on average; a mean absolute apex error (COM apex minus
``y_stand + dh*``, over all hops) of at most 1.5 cm; a mean horizontal COM drift after 10 s of at most 5 cm; a torso
tilt of at most 8 degrees RMS; and, on the episodes the policy and the hopper both survive, a COM excursion (its
largest distance from the start), an action rate (the mean absolute change of the action per step), a share of
saturated action entries, a positive actuator power and a peak normal force no more than the hopper's. On the
held-out episodes (``policies/baselines/hopper``) the hopper survives 95% with 14.2 hops an episode, an apex error of
1.78 cm, a drift of 6.24 cm and a tilt of 4.6 degrees, changing its action by 0.063 a step with 14.2% of the entries
saturated, on 43.8 W and a peak force of 2.12 body weights (over all its episodes). The model-predictive controller
(``policies.mpc``: iLQR through the contact events around the hopper, ``policies/baselines/mpc_hop``) survives every
episode with an apex error of 0.74 cm and a drift of 1.53 cm, on 39.3 W, and meets every bar: 11.2 hops an episode,
from a dwell of 0.45 s at each crouch's bottom.

## PPO from scratch
The configuration of ``train/hyperparams/ppo.yml`` is plain PPO with one curriculum, of the commands: 1024 envs,
rollouts of 32 steps, 4 epochs of minibatches of 16384, a discount of 0.998, an entropy bonus of 0.005, an initial
action noise of std 0.37, 32M steps; the networks' first layer also sees the observation's products with the command
(``train.features.CommandGains``). The training env draws the commands from 2-6 cm for the first 6M steps and widens
the range linearly to the task's 5-15 cm by 20M; no reward weight, discount or action noise changes during training,
and the evaluations and the selection are the task as registered. Over five seeds
(``benchmarks/results/learning/PlanarLegHop-v4``; seeds 0-4, seed 2 named as the shipped one before any trained,
14.5-15.0 minutes each on one core beside another) four survive every held-out episode and every seed hops to the
command, with apex errors of 0.53-1.27 cm (the hopper 1.78 cm), its torso within 5.1-8.2 degrees of upright (RMS;
v3's policy leaned 36); the survival IQM is 100% [81%, 100%], the return IQM 2,806 [2,113, 3,109] (the hopper
2,308). Seed 0 finds the hop last, after 24M steps, and survives 71%; seed 3 drifts 8.9 cm. The shipped
``policies/ppo_hop_v4`` (seed 2) survives every episode with 31.1 hops, an apex error of 0.87 cm, a drift of 4.07 cm
and a tilt of 6.4 degrees: six bars of ten. No seed meets the four the hopper's gait sets. The policies hop twice as
often as the hopper (27-31 hops an episode for the four seeds that survive every episode, against 14), for about the
work per hop the hopper spends (27 J against 30 J for the shipped seed), so on the episodes both survive they spend
70-84 W against 44 W, with an action rate of 0.11-0.15 (0.063), 14.5-33% of the entries saturated (14.5%) and a peak
normal force of 2.6-2.7 body weights (2.1). At their work per hop the power bar asks for at most about 16 hops an
episode.

What was tried on the way, and what each probe found, is kept with the research records
(``research/hop_probes.md``).

## Version History
* v4: effort, smoothness and posture charged, and the last action observed (entries 22-23; the observation has
  24 entries): the action's change costs ``1.0 |a - a_last|_1`` a step (was 0), the torque squared ``0.5 |a|^2``
  (was 0.01), positive power 0.006 per W (was 0), the torso's tilt ``10 th_b^2`` (was 1) and the COM's drift
  ``30 dx^2`` (was 10); a hop is a flight of at least 150 ms (was 50 ms). v3's PPO policy, trained with schedules of
  four reward weights, the discount and the action noise, leaned its torso 36 degrees, saturated 38% of its action
  entries, changed its action by 0.170 a step and spent 100 W, 2.3 times the hopper's.
* v3 (removed): the height term pays the last landed hop's apex at every step while the robot keeps hopping, and
  that apex is observation entry 21. v1 and v2 paid a hop's kernels for each step it spent in the air, so a gait airborne most of
  the time earned the term over and over: plain PPO on v2 bounced at 2.5-3 cm, in the air about 80% of the time.
  Now a precise hop once a second pays as much per second as a precise hop every 0.3 s.
* v2 (removed): a flight's height term paid only for a hop (a flight of at least ``min_flight``), once the robot had
  hopped again: v1 paid the chattering lift-offs of a few milliseconds between hops, and a jump that fell a few
  steps after its landing.
* v1 (removed): the height term paid for flight only, at the flight's landing, with the fine kernel beside the
  coarse one; the alive bonus stops after a second on the ground; the COM's drift and the ground time observed.
  v0's vertical-energy term paid in stance as well, so standing tall and bobbing scored more than hopping.
* v0 (removed): initial version.

The probes behind each version, with their figures, are kept with the research records
(``research/hop_versions.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import checks
from ..physics import layout
from ..physics.layout import state_dtype
from .base import OBS_DIM_UNILATERAL, StanceConfig, Task, observation_space as _stance_space

__all__ = ["HopConfig", "TASK", "REWARD_TERMS", "OBS_DIM"]

MAX_STEPS = 2**31 - 1  # control steps a setting can count (an int32 of the compiled core)

REWARD_TERMS = ("alive", "height", "drift", "tilt", "impact", "slip", "ctrl", "limit", "action_rate", "power")
N_TERMS = len(REWARD_TERMS)
OBS_DIM = layout.OBS["hop_dim"]  # 22: the unilateral ground's 18, the command, the COM's drift, the ground time, the last apex
_BIG = 1.0e6


@dataclass(frozen=True)
class HopConfig(StanceConfig):
    """Settings of the hopping task: the balance task's (``StanceConfig``; the unilateral ground only) and the hop's.

    Raises:
        ValueError, ArgumentTypeError: as ``StanceConfig``, for every field (``leg_env.checks``).
    """

    contact: str = "unilateral"
    ctrl_cost_weight: float = 0.5  # per unit of |action|^2
    action_change_weight: float = 1.0  # per unit of |action - last action|_1
    power_weight: float = 0.006  # per W of the hip's and the knee's positive mechanical power
    observe_action: bool = True  # the last action (clipped) as the observation's last two entries
    command_range: tuple = (0.05, 0.15)  # commanded COM rise at the apex above standing [m]
    height_weight: float = 2.0
    height_scale: float = 0.05  # [m] of apex height error at which the height term is 1/e of its peak
    height_scale_fine: float = 0.01  # [m] > 0: the height kernel is the sum of the height_scale one and this one
    drift_com_weight: float = 30.0  # per m^2 of COM x from the start
    drift_near_weight: float = 0.0  # per m^2 of COM x from the start: a second drift charge, capped by drift_near_cap
    drift_near_cap: float = float("inf")  # the most drift_near_weight's charge takes a step (inf: no cap, quadratic)
    limit_weight: float = 0.0  # per rad^2 of the hip and the knee inside the last limit_margin of their ranges
    limit_margin: float = 0.05  # [rad] from each end of hip_range and knee_range
    tilt_weight: float = 10.0  # per rad^2
    impact_weight: float = 0.5  # per (m/s)^2 of |P| / m
    slip_weight: float = 1.0  # per m/s of mean slip speed
    min_flight: float = 0.15  # [s] a flight at least this long is a hop
    max_ground_time: float = 1.0  # [s] the alive bonus and the height term stop after this long without a hop
    command_period: float = float("inf")  # [s] a new command from command_range every this long, up to COMMANDS_AHEAD times an episode (inf: one per episode)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.contact != "unilateral":
            raise ValueError(f"HopConfig.contact must be 'unilateral' (a pinned foot cannot hop), got {self.contact!r}")
        value = checks.pair("HopConfig.command_range", self.command_range, 0.0, 10.0, unit="m")
        if not value[0] <= value[1]:
            raise ValueError(f"HopConfig.command_range must be (low, high) with low <= high, got {value!r}")
        object.__setattr__(self, "command_range", value)
        for name in ("height_weight", "drift_com_weight", "tilt_weight", "impact_weight", "slip_weight"):
            object.__setattr__(self, name, checks.real(f"HopConfig.{name}", getattr(self, name), 0.0, _BIG))
        object.__setattr__(self, "height_scale", checks.real("HopConfig.height_scale", self.height_scale, 0.0, _BIG, lo_open=True, unit="m"))
        object.__setattr__(self, "min_flight", checks.real("HopConfig.min_flight", self.min_flight, 0.0, _BIG, unit="s"))
        object.__setattr__(self, "height_scale_fine", checks.real("HopConfig.height_scale_fine", self.height_scale_fine, 0.0, _BIG, unit="m"))
        object.__setattr__(self, "drift_near_weight", checks.real("HopConfig.drift_near_weight", self.drift_near_weight, 0.0, _BIG))
        object.__setattr__(self, "limit_weight", checks.real("HopConfig.limit_weight", self.limit_weight, 0.0, _BIG))
        object.__setattr__(self, "limit_margin", checks.real("HopConfig.limit_margin", self.limit_margin, 0.0, _BIG, unit="rad"))
        object.__setattr__(self, "drift_near_cap", checks.real("HopConfig.drift_near_cap", self.drift_near_cap, 0.0, float("inf"), lo_open=True))
        object.__setattr__(self, "max_ground_time", checks.real("HopConfig.max_ground_time", self.max_ground_time, 0.0, float("inf"), lo_open=True, unit="s"))
        object.__setattr__(self, "command_period", checks.real("HopConfig.command_period", self.command_period, 0.0, float("inf"), lo_open=True, unit="s"))
        if self.command_period < self.dt:
            raise ValueError(f"HopConfig.command_period must be at least dt ({self.dt} s), got {self.command_period!r}")
        if self.command_period != float("inf") and round(self.command_period / self.dt) > MAX_STEPS:
            raise ValueError(f"HopConfig.command_period must be at most {MAX_STEPS} control steps of dt = {self.dt} s (or inf), got "
                             f"{self.command_period!r} s")
        if self.max_ground_time == float("inf"):
            raise ValueError("HopConfig.max_ground_time must be finite (else one hop would pay the height term for the rest of the episode)")

    def task_settings(self, row: np.ndarray) -> None:
        """The hop's weights in its ``settings`` row (the standing height is each robot's nominal COM)."""
        row["w_height"], row["height_scale"], row["w_drift"] = self.height_weight, self.height_scale, self.drift_com_weight
        row["w_tilt"], row["w_impact"], row["w_slip"] = self.tilt_weight, self.impact_weight, self.slip_weight
        row["min_flight"], row["max_ground_time"] = self.min_flight, self.max_ground_time
        row["height_scale_fine"] = self.height_scale_fine
        row["w_drift_near"], row["drift_near_cap"] = self.drift_near_weight, self.drift_near_cap
        row["w_limit"], row["limit_margin"] = self.limit_weight, self.limit_margin
        row["command_steps"] = command_steps(self)


def observation_space(params, config: HopConfig):
    """``PlanarLegStance``'s 18 entries on the unilateral ground, then the command within ``command_range``, the COM's
    x from its start (unbounded), the ground time (at least 0) and the last landed hop's apex rise (unbounded)."""
    from gymnasium import spaces

    base = _stance_space(params, config)
    low = np.append(base.low, np.float32([config.command_range[0], -np.inf, 0.0, -np.inf]))
    high = np.append(base.high, np.float32([config.command_range[1], np.inf, np.inf, np.inf]))
    return spaces.Box(low, high, dtype=np.float32)


COMMANDS_AHEAD = state_dtype("hop")["next_commands"].shape[0]
"""The commands a reset draws ahead for a command schedule (``command_period``): the episode's first and this many more."""


def command_steps(config: HopConfig) -> int:
    """Control steps each command of a schedule holds (``command_period / dt``, rounded, at least 1), 0 for one
    command per episode."""
    if config.command_period == float("inf"):
        return 0
    return max(1, round(config.command_period / config.dt))


def _draws(config: HopConfig) -> int:
    return 1 if command_steps(config) == 0 else 1 + COMMANDS_AHEAD


def _columns(draws: np.ndarray, config: HopConfig) -> dict:
    """The command of ``k`` robots from their ``(k, 1)`` uniforms; with a command schedule, also the
    ``COMMANDS_AHEAD`` commands to come, from the uniforms after it."""
    lo, hi = config.command_range
    columns = {"command": lo + (hi - lo) * draws[:, 0]}
    if draws.shape[1] > 1:
        columns["next_commands"] = lo + (hi - lo) * draws[:, 1:]
    return columns


TASK = Task(
    name="hop",
    config_cls=HopConfig,
    reward_terms=REWARD_TERMS,
    kernel=2,
    observation_space=observation_space,
    state_info=("command", "ground_time"),
    draws=_draws,
    columns=_columns,
    needs_gravity=True,
)
"""The hopping task as the shared environments see it (``leg_env.tasks.base.Task``)."""
