"""The framework every task is written in: ``Task`` (what the shared environments need from a task, one per task
module: its ``TASK``), ``StanceConfig`` (the settings every task shares, which a task's config extends), the
observation's shared columns (``Obs``), the nominal posture and the robot row the compiled core reads.

A task module (``leg_env/tasks/<name>.py``) holds everything about its task and nothing else: its
frozen config dataclass (a ``StanceConfig`` subclass: the physics settings, limits and weights every
task shares, and its own), its observation, reward terms and termination, written once in the compiled
core (``leg_env/_core/tasks.c``: ``assess`` after a control step, ``start`` after a reset, on the
structured arrays of ``leg_env.physics.layout``), its reset distribution (what it draws from the robot's generator
beyond the posture noise), its documentation (the module docstring, in Gymnasium's order) and, in
``leg_env.tasks.REGISTRY``, its ids. The physics (``leg_env.physics``), the single and vector environments
(``leg_env.envs``), the ``info`` builder (``leg_env.info``), the SB3 adapter, rendering and training are
written once for every task.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from enum import IntEnum
from functools import cached_property
from typing import Callable

import numpy as np

from .. import checks
from .._core import kernels
from ..physics import layout
from ..physics.dynamics import com_position, static_equilibrium
from ..physics.integrate import DT, MAX_ANGLE, MAX_SUBSTEPS, SUBSTEPS
from ..physics.params import LegParams

__all__ = [
    "Task",
    "StanceConfig",
    "FIELD_RANGES",
    "CONTACT_MODELS",
    "DEFAULT_MU",
    "OBS_DIM",
    "OBS_DIM_UNILATERAL",
    "Obs",
    "Nominal",
    "nominal_state",
    "robot_row",
    "observation_space",
]


def _no_draws(config) -> int:
    return 0


@dataclass(frozen=True, eq=False)
class Task:
    """A task as the shared environments see it (every field is read by ``leg_env.envs``).

    Attributes:
        name: the module name under ``leg_env.tasks``; also the name of its fields in ``leg_env.physics.layout``.
        config_cls: the config dataclass (``StanceConfig`` or a subclass; ``from_kwargs``, ``settings``).
        reward_terms: names of the reward terms, in the order they are summed (``info["reward_<name>"]``):
            ``out["terms"][:, :len(reward_terms)]``.
        kernel: the task's number in the compiled core (``env_task`` of ``leg_env/_core/env.h``).
        observation_space: ``(params, config) -> gymnasium.spaces.Box`` of one robot.
        info_names: the task's own ``out`` fields that ``info`` carries (push: ``push_force``, ``work_push``).
        state_info: the task's own ``state`` fields that ``info`` carries (hop: ``command``).
        draws: ``config -> int``: uniforms the task draws at every reset, after the posture noise.
        needs_gravity: the task has no meaning without gravity (the hop's apex is where gravity stops the rise): a
            robot with ``g = 0``, nominal, drawn or given at a reset, is refused.
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
    needs_gravity: bool = False

    def space(self, params: LegParams, config) -> "spaces.Box":
        """One robot's observation space: the task's entries (``observation_space``), then with ``config.observe_action``
        the last action's two, in [-1, 1]."""
        space = self.observation_space(params, config)
        if not config.observe_action:
            return space
        from gymnasium import spaces

        ones = np.ones(ACTION_DIM, dtype=np.float32)
        return spaces.Box(np.append(space.low, -ones), np.append(space.high, ones), dtype=np.float32)

    def assess(self, state, robots, settings, out, obs) -> None:
        """The task after a control step of every robot (the compiled core's control step, ``env.c``), in place: the
        observation, the reward terms (they sum to the reward), the extras and the flags."""
        kernels.assess(self.kernel, state, robots, settings, out, obs)

    def step(self, state, robots, settings, out, obs, lo: int = 0, hi: int | None = None) -> None:
        """One control step of robots ``lo .. hi - 1`` and the task after it, in place: bitwise
        the control step then ``assess`` of those rows, in one compiled call that releases the
        GIL (so that chunks of rows can run in threads) and keeps each block of rows in cache between the two."""
        kernels.step(self.kernel, lo, state.shape[0] if hi is None else hi, state, robots, settings, out, obs)

    def start(self, state, robots, settings, out, obs, noise=None, scale: float = 0.0) -> None:
        """Freshly reset robots put on their contact and evaluated without stepping (reward terms zero): at
        ``state["q"], ["qd"], ["anchor"]`` if ``noise`` is None, else at each robot's nominal posture plus
        ``uniform(-scale, scale)`` noise from the ``(N, 6)`` uniforms ``noise``."""
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


ACTION_DIM = 2  # the action's entries (hip, knee); with observe_action the observation ends with the last action's
OBS_DIM = layout.OBS["pinned_dim"]  # 12
OBS_DIM_UNILATERAL = layout.OBS["unilateral_dim"]  # 18: the foot's height, velocity, contact, slip and impulse after them
Obs = IntEnum("Obs", {name: i for name, i in layout.OBS.items() if not name.endswith("_dim") and not name.startswith("push_")})
"""The observation's columns by name (``obs[:, Obs.contact]``), as the compiled core writes them: the 12 of the
pinned foot, the 6 of the unilateral ground, and the hop task's own after them (the push task's own entry, in the
column of the hop's ``command``, is ``leg_env.tasks.push.OBS_COM_DRIFT``)."""
CONTACT_MODELS = ("pinned", "unilateral")
DEFAULT_MU = {"pinned": 0.8, "unilateral": 0.5}
"""The default friction coefficient of each contact model. On the pinned foot it is the cone of the violation check (as in v0).
Unilateral: 0.5, below the Painleve bound ``mu_critical`` everywhere in the joint box at the default
parameters (its minimum there is about 0.52; 0.8 would leave about 8% of postures past it), so
sliding is always well posed and the Painleve rule stays a fallback."""

_INF = math.inf
_BIG = 1.0e6  # bound of lengths, angles, torques, rates and reward weights: far beyond any use, far below overflow
FIELD_RANGES = {
    # name: (low, high, low open, high open, unit)
    "dt": (0.0, 1.0, True, False, "s"),
    "substeps": (1, MAX_SUBSTEPS, False, False, ""),
    "max_angle": (0.0, _INF, True, False, "rad"),
    "torque_limit": (0.0, _BIG, True, False, "N m"),
    "nominal_knee": (0.0, math.pi, True, True, "rad"),
    "alive_bonus": (0.0, _BIG, False, False, ""),
    "drift_position_weight": (0.0, _BIG, False, False, ""),
    "drift_angle_weight": (0.0, _BIG, False, False, ""),
    "drift_velocity_weight": (0.0, _BIG, False, False, ""),
    "unilateral_weight": (0.0, _BIG, False, False, ""),
    "friction_weight": (0.0, _BIG, False, False, ""),
    "ctrl_cost_weight": (0.0, _BIG, False, False, ""),
    "action_rate_weight": (0.0, _BIG, False, False, ""),
    "action_change_weight": (0.0, _BIG, False, False, ""),
    "power_weight": (0.0, _BIG, False, False, "per W"),
    "motor_speed": (0.0, _INF, True, False, "rad/s"),
    "mu": (0.0, _BIG, False, False, ""),
    "min_base_height": (0.0, _BIG, True, False, "m"),
    "max_torso_angle": (0.0, _BIG, True, False, "rad"),
    "hip_range": (-_BIG, _BIG, False, False, "rad"),
    "knee_range": (-_BIG, _BIG, False, False, "rad"),
    "contact_loss_threshold": (-1.0e12, 1.0e12, False, False, "N"),
    "max_rate": (0.0, _BIG, True, False, "m/s, rad/s"),
    "reset_noise_scale": (0.0, math.pi, False, False, "rad, rad/s"),
}
"""The accepted range of every numeric ``StanceConfig`` field: ``(low, high, low_open, high_open, unit)``.

``substeps`` is at most ``MAX_SUBSTEPS`` (4096, the most RK4 steps the step rule ever takes);
``reset_noise_scale`` at most pi (a wider noise wraps the angles); ``max_angle`` may be ``inf`` (fixed
steps). The other bounds only keep products and the float32 observation from overflowing."""


@dataclass(frozen=True)
class StanceConfig:
    """Settings every task shares (everything that is not the robot's physics); a task's config extends it.

    Every numeric field has the range in ``FIELD_RANGES`` (``(low, high, low_open, high_open, unit)``),
    checked by ``leg_env.checks`` like every other argument.

    Raises:
        ValueError: a value is NaN, too large for a float or out of its range; the message names the
            field and the range.
        ArgumentTypeError: a value of the wrong type (a string, a bool for a number, a complex number);
            it is also a ``ValueError``.
    """

    dt: float = DT  # control period [s]
    substeps: int = SUBSTEPS  # least RK4 steps per control period
    max_angle: float = MAX_ANGLE  # largest link/joint rotation per RK4 step [rad]
    torque_limit: tuple = (50.0, 50.0)  # |tau_hip|, |tau_knee| at action +-1 [N m]; a number sets both
    nominal_knee: float = 0.8  # knee angle of the nominal equilibrium [rad]
    # reward weights
    alive_bonus: float = 1.0  # paid on each healthy step
    drift_position_weight: float = 10.0  # per m^2 of base offset from nominal
    drift_angle_weight: float = 1.0  # per rad^2 of torso angle
    drift_velocity_weight: float = 0.1  # per (m/s)^2 + (rad/s)^2 of torso velocity
    unilateral_weight: float = 10.0  # per unit of max(0, -lam_y) / weight
    friction_weight: float = 10.0  # per unit of max(0, |lam_x| - mu lam_y) / weight
    ctrl_cost_weight: float = 0.01  # per unit of |action|^2
    action_rate_weight: float = 0.0  # per unit of |action - last action|^2 (both clipped to [-1, 1])
    action_change_weight: float = 0.0  # per unit of |action - last action|_1: the entries' absolute changes, summed
    power_weight: float = 0.0  # per W of the hip's and the knee's positive mechanical power
    mu: float | None = None  # friction coefficient; None: DEFAULT_MU of the contact model (0.8 pinned, 0.5 unilateral)
    # termination
    min_base_height: float = 0.5  # torso above the contact point [m]
    max_torso_angle: float = 1.0  # |th_b| [rad]
    hip_range: tuple = (-3.0, -0.9)  # allowed q1 [rad]
    knee_range: tuple = (0.05, 2.5)  # allowed q2 [rad]
    terminate_on_contact_loss: bool = False
    contact_loss_threshold: float = 0.0  # lam_y below this ends the episode, if enabled [N]
    max_rate: float = 1.0e3  # any |qd| above this is a numerical failure [m/s, rad/s]
    # reset
    reset_noise_scale: float = 0.01  # uniform noise half-width on (th_b, q1, q2) [rad] and their rates [rad/s]
    # physics
    contact: str = "pinned"  # "pinned": the foot is a bilateral pin (v0); "unilateral": exact unilateral contact
    motor_speed: float = _INF  # no-load speed of the joints' motors [rad/s]: torque falls linearly to 0 there; inf: ideal
    # observation
    observe_action: bool = False  # the last action (clipped) as the observation's last two entries

    def __post_init__(self) -> None:
        if not isinstance(self.contact, str):
            raise checks.ArgumentTypeError(f"StanceConfig.contact must be one of {list(CONTACT_MODELS)}, got {checks.shown(self.contact)}")
        if self.contact not in CONTACT_MODELS:
            raise ValueError(f"StanceConfig.contact must be one of {list(CONTACT_MODELS)}, got {self.contact!r}")
        if self.mu is None:
            object.__setattr__(self, "mu", DEFAULT_MU[self.contact])
        for name, (lo, hi, lo_open, hi_open, unit) in FIELD_RANGES.items():
            value = getattr(self, name)
            if name == "substeps":
                value = checks.integer(f"StanceConfig.{name}", value, int(lo), int(hi), floats=True)
            elif name in ("torque_limit", "hip_range", "knee_range"):
                if name == "torque_limit" and checks.is_real(value):
                    value = (value, value)  # one limit for both joints
                value = checks.pair(f"StanceConfig.{name}", value, lo, hi, lo_open=lo_open, unit=unit)
            else:
                value = checks.real(f"StanceConfig.{name}", value, lo, hi, lo_open=lo_open, hi_open=hi_open, unit=unit)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "terminate_on_contact_loss", checks.boolean("StanceConfig.terminate_on_contact_loss", self.terminate_on_contact_loss))
        object.__setattr__(self, "observe_action", checks.boolean("StanceConfig.observe_action", self.observe_action))
        for name in ("hip_range", "knee_range"):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise ValueError(f"StanceConfig.{name} must be (low, high) with low < high, got {getattr(self, name)!r}")

    @classmethod
    def from_kwargs(cls, config: "StanceConfig | dict | None" = None, **overrides) -> "StanceConfig":
        """A config from an instance or dict, with keyword overrides.

        An unknown keyword raises ``TypeError`` worded as Python's own ("got an unexpected keyword
        argument 'name'"; wrappers such as TorchRL's ``GymEnv`` read that to drop an optional
        argument); an unknown key of a ``config`` dict is a bad value, ``ValueError``.
        """
        names = {f.name for f in fields(cls)}
        unknown = [name for name in overrides if name not in names]
        if unknown:
            listed = ", ".join(repr(name) for name in unknown)
            what = f"an unexpected keyword argument {listed}" if len(unknown) == 1 else f"unexpected keyword arguments {listed}"
            raise TypeError(f"got {what}: not an argument of the env nor a {cls.__name__} field")
        if config is not None and not isinstance(config, (StanceConfig, dict)):
            raise checks.ArgumentTypeError(
                f"config must be a StanceConfig, a dict of its fields or None, got {checks.shown(config)} of type {type(config).__name__}"
            )
        base = {} if config is None else (asdict(config) if isinstance(config, StanceConfig) else dict(config))
        unknown = sorted(set(base) - names)
        if unknown:
            raise ValueError(f"config has unknown {cls.__name__} field(s): {unknown}")
        base.update(overrides)
        return cls(**base)

    def replace(self, **changes) -> "StanceConfig":
        """A copy with ``changes`` (checked as at construction)."""
        return replace(self, **changes)

    def task_settings(self, row: np.ndarray) -> None:
        """Write a task's own settings into its ``settings_row`` (none for the balance task)."""

    def settings(self, task: str = "stance") -> np.ndarray:
        """The settings the compiled core reads, as a 1-row array of ``leg_env.physics.layout.settings_dtype(task)``."""
        row = np.zeros(1, dtype=layout.settings_dtype(task))
        row["dt"], row["max_angle"], row["max_rate"], row["substeps"] = self.dt, self.max_angle, self.max_rate, self.substeps
        row["alive_bonus"] = self.alive_bonus
        row["w_position"], row["w_angle"], row["w_velocity"] = self.drift_position_weight, self.drift_angle_weight, self.drift_velocity_weight
        row["w_unilateral"], row["w_friction"], row["w_ctrl"] = self.unilateral_weight, self.friction_weight, self.ctrl_cost_weight
        row["w_action_rate"], row["w_power"], row["motor_speed"] = self.action_rate_weight, self.power_weight, self.motor_speed
        row["w_action_change"] = self.action_change_weight
        row["observe_action"] = self.observe_action
        row["min_base_height"], row["max_torso_angle"] = self.min_base_height, self.max_torso_angle
        row["hip_range"], row["knee_range"] = self.hip_range, self.knee_range
        row["terminate_on_contact_loss"], row["contact_loss_threshold"] = self.terminate_on_contact_loss, self.contact_loss_threshold
        row["unilateral"] = self.contact == "unilateral"
        self.task_settings(row)
        return row


if set(FIELD_RANGES) | {"terminate_on_contact_loss", "contact", "observe_action"} != {f.name for f in fields(StanceConfig)}:
    raise RuntimeError("FIELD_RANGES must list every numeric StanceConfig field")  # a developer error


@dataclass(frozen=True)
class Nominal:
    """The nominal equilibrium of a task: state with the foot at the origin, holding torques, contact force."""

    q: np.ndarray
    tau: np.ndarray
    lam: np.ndarray

    @property
    def base(self) -> np.ndarray:
        """Nominal base position relative to the contact point [m]."""
        return self.q[:2]


def nominal_state(p: LegParams, config: StanceConfig) -> Nominal:
    """The task's nominal posture: a static equilibrium with the torso level and the COM above the foot."""
    q, tau, lam = static_equilibrium(p, config.nominal_knee)
    if np.any(np.abs(tau) > np.asarray(config.torque_limit)):
        raise ValueError(
            f"torque_limit {config.torque_limit} cannot hold the nominal posture, which needs {tau.round(2).tolist()} N m"
        )
    return Nominal(q=q, tau=tau, lam=lam)


def robot_row(p: LegParams, config: StanceConfig, nominal: Nominal) -> np.ndarray:
    """A robot as the compiled core reads it, a 1-row array of ``leg_env.physics.layout.ROBOT``: its parameters, the task's
    friction and torque limits, its nominal posture, holding torques and COM (writable: a reset may put another
    robot in it)."""
    row = np.zeros(1, dtype=layout.ROBOT)
    row["p"] = tuple(p.array)
    row["mu"], row["torque_limit"] = config.mu, config.torque_limit
    row["q_nom"], row["tau_nom"], row["com_nom"] = nominal.q, nominal.tau, com_position(nominal.q, p)
    return row


def observation_space(params: LegParams, config: StanceConfig):
    """One robot's observation space: 12 entries (pinned) or 18 (unilateral); see the balance task's table (``leg_env.tasks.stance``)."""
    from gymnasium import spaces

    reach = 1.01 * (params.l1 + params.l2)
    unilateral = config.contact == "unilateral"
    high = np.full(OBS_DIM_UNILATERAL if unilateral else OBS_DIM, np.inf, dtype=np.float32)
    high[Obs.base_x] = reach
    if not unilateral:  # on the unilateral ground the base may fly: its height has no bound
        high[Obs.base_y] = reach
    else:
        high[Obs.contact] = 1.0
        high[Obs.slip] = 1.0  # the slip direction
    low = -high
    if unilateral:
        low[Obs.contact] = 0.0
    return spaces.Box(low, high, dtype=np.float32)
