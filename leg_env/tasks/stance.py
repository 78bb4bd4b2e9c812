"""The balance task (``leg_env/PlanarLegStance-v0``, ``leg_env/PlanarLegBalance-v0``): configuration,
observation, reward, termination.

A control step runs, in one call of the compiled core on the structured arrays of ``leg_env.layout``, the
shared physics (``leg_env.step.physics_range``) and then this task's kernel ``assess``
(``leg_env/_core/tasks.c``: observation, every reward term, every termination flag). The single environment
runs them with a batch of one and the vector environment with a batch of N, so the two cannot disagree. ``StanceConfig`` holds every
setting; tasks built on this one (``leg_env.tasks.push``, ``hop``) extend it, and their kernels call this
one's.

Observation (float32, ``OBS_DIM = 12``; ``Obs`` names the columns):

===== ========================================== ======
index meaning                                    unit
===== ========================================== ======
0     base x relative to the foot contact point  m
1     base y relative to the foot contact point  m
2     torso angle th_b                           rad
3     hip angle q1                               rad
4     knee angle q2                              rad
5-9   qd = [x_b', y_b', th_b', q1', q2']         m/s, rad/s
10    lam_x / (m_total g)                        1 (N if g = 0)
11    lam_y / (m_total g)                        1 (N if g = 0)
===== ========================================== ======

The contact force is the mean over the last control step (the contact impulse / dt). With ``g = 0``
there is no weight to divide by: the kernels divide by 1, so entries 10-11 are in newtons.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from enum import IntEnum

import numpy as np

from .._core import kernels
from .. import checks, layout
from ..dynamics import com_position, static_equilibrium
from ..integrate import MAX_ANGLE, MAX_SUBSTEPS, SUBSTEPS, DT
from ..params import LegParams
from ..step import FLAG_NAMES, BitGeneratorRows

__all__ = [
    "StanceConfig",
    "FIELD_RANGES",
    "OBS_DIM",
    "OBS_DIM_UNILATERAL",
    "Obs",
    "REWARD_TERMS",
    "FLAG_NAMES",
    "Nominal",
    "nominal_state",
    "robot_row",
    "settings_row",
    "step_batch",
    "step_range",
    "start_batch",
    "reset_state",
    "reset_states",
    "starts_from_noise",
    "BitGeneratorRows",
    "CONTACT_MODELS",
    "DEFAULT_MU",
    "UNILATERAL_KEYS",
    "observation_space",
]

OBS_DIM = layout.OBS["pinned_dim"]  # 12
OBS_DIM_UNILATERAL = layout.OBS["unilateral_dim"]  # 18: the foot's height, velocity, contact, slip and impulse after them
Obs = IntEnum("Obs", {name: i for name, i in layout.OBS.items() if not name.endswith("_dim") and not name.startswith("push_")})
"""The observation's columns by name (``obs[:, Obs.contact]``), as the compiled core writes them: the 12 of the
pinned foot, the 6 of the unilateral ground, and the hop task's own after them (the push task's own entry, in the
column of the hop's ``command``, is ``leg_env.tasks.push.OBS_COM_DRIFT``)."""
CONTACT_MODELS = ("pinned", "unilateral")
DEFAULT_MU = {"pinned": 0.8, "unilateral": 0.5}
"""Default friction coefficient per contact model. Pinned: the cone of the violation check (as in v0).
Unilateral: 0.5, below the Painleve bound ``mu_critical`` everywhere in the joint box at the default
parameters (its minimum there is about 0.52; 0.8 would leave about 8% of postures past it), so
sliding is always well posed and the Painleve rule stays a fallback."""
REWARD_TERMS = ("alive", "drift", "unilateral", "friction", "ctrl")
UNILATERAL_KEYS = (
    "contact_mode", "foot_height", "impulse", "stick_time", "slip_time", "flight_time", "slip_distance",
    "work_actuators", "dissipation_slip", "dissipation_impacts", "energy", "contact_events", "painleve_fallbacks",
    "zeno_settles",
)  # fmt: skip
"""``info`` keys of the unilateral contact model, after ``reset`` and ``step`` (``leg_env.info``)."""

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
    """Settings of the balance task (everything that is not physics).

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
        """The settings the compiled core reads, as a 1-row array of ``leg_env.layout.settings_dtype(task)``."""
        row = np.zeros(1, dtype=layout.settings_dtype(task))
        row["dt"], row["max_angle"], row["max_rate"], row["substeps"] = self.dt, self.max_angle, self.max_rate, self.substeps
        row["alive_bonus"] = self.alive_bonus
        row["w_position"], row["w_angle"], row["w_velocity"] = self.drift_position_weight, self.drift_angle_weight, self.drift_velocity_weight
        row["w_unilateral"], row["w_friction"], row["w_ctrl"] = self.unilateral_weight, self.friction_weight, self.ctrl_cost_weight
        row["min_base_height"], row["max_torso_angle"] = self.min_base_height, self.max_torso_angle
        row["hip_range"], row["knee_range"] = self.hip_range, self.knee_range
        row["terminate_on_contact_loss"], row["contact_loss_threshold"] = self.terminate_on_contact_loss, self.contact_loss_threshold
        row["unilateral"] = self.contact == "unilateral"
        self.task_settings(row)
        return row


if set(FIELD_RANGES) | {"terminate_on_contact_loss", "contact"} != {f.name for f in fields(StanceConfig)}:
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
    """A robot as the compiled core reads it, a 1-row array of ``leg_env.layout.ROBOT``: its parameters, the task's
    friction and torque limits, its nominal posture, holding torques and COM (writable: a reset may put another
    robot in it)."""
    row = np.zeros(1, dtype=layout.ROBOT)
    row["p"] = tuple(p.array)
    row["mu"], row["torque_limit"] = config.mu, config.torque_limit
    row["q_nom"], row["tau_nom"], row["com_nom"] = nominal.q, nominal.tau, com_position(nominal.q, p)
    return row


def settings_row(config: StanceConfig, task: str = "stance") -> np.ndarray:
    """``config.settings(task)``: the task's settings as the compiled core reads them."""
    return config.settings(task)


def step_batch(state, robots, settings, out, obs):
    """Advance every robot one control step and evaluate the task, in place (one thread).

    Args:
        state: ``(N,)`` array of ``leg_env.layout.state_dtype("stance")``; ``q`` and ``qd`` are overwritten (left
            unchanged on numerical failure); the actions (``state["action"]``) must already be checked finite and
            are clipped here to [-1, 1].
        robots: ``robot_row(...)`` (one robot for all), or a row per robot.
        settings: ``settings_row(config)``.
        out: ``(N,)`` array of ``leg_env.layout.out_dtype("stance")``: the mean contact force over the step [N],
            the extras, what the hybrid step did, the flags and the reward terms.
        obs: ``(N, 12 or 18)`` float32 out (left at the previous observation on numerical failure).
    """
    _check_obs(state, settings, obs)  # before the physics changes anything
    n = state.shape[0] if isinstance(state, np.ndarray) and state.ndim >= 1 else 0  # the core refuses what is not a state
    TASK.step(state, robots, settings, out, obs, 0, n)  # the physics, then the task's kernel, in one call


def step_range(lo, hi, state, robots, settings, out, obs):
    """``step_batch`` of the rows ``lo <= i < hi`` only (the physics releases the GIL).

    Robots are independent: the rows of a batch stepped in any split are bitwise those of ``step_batch``.
    """
    _check_obs(state, settings, obs)  # before the physics changes anything
    TASK.step(state, robots, settings, out, obs, lo, hi)


def _check_obs(state, settings, obs) -> None:
    """``obs`` must be the C-contiguous, writable float32 ``(N, 12 or 18)`` observation of ``state``'s ``N`` robots on
    ``settings``' ground: checked before the physics steps them, so that a refused ``obs`` changes nothing. (A
    ``state`` or ``settings`` that is not one of their dtype's arrays is left for the core to refuse, which it does
    before it steps.)"""
    dtype = layout.settings_dtype("stance")
    if not (isinstance(state, np.ndarray) and state.ndim == 1 and state.dtype.itemsize == TASK.state_dtype.itemsize
            and isinstance(settings, np.ndarray) and settings.nbytes == dtype.itemsize):  # fmt: skip
        return
    unilateral = np.frombuffer(settings.tobytes(), dtype=dtype)["unilateral"][0]
    width = OBS_DIM_UNILATERAL if unilateral else OBS_DIM
    if not (isinstance(obs, np.ndarray) and obs.dtype == np.float32 and obs.shape == (state.shape[0], width)
            and obs.flags.c_contiguous and obs.flags.writeable):  # fmt: skip
        got = f"{obs.dtype} {obs.shape}" if isinstance(obs, np.ndarray) else checks.shown(obs)
        raise ValueError(f"obs must be a C-contiguous, writable float32 array of shape ({state.shape[0]}, {width}), got {got}")


def start_batch(state, robots, settings, out, obs):
    """Put freshly reset robots on their contact and evaluate them without stepping.

    ``state["q"], state["qd"], state["anchor"]`` hold the start states; ``leg_env.step`` says how each contact
    model starts. The reward terms are zero and ``out["terminated"]`` tells whether the start state is already
    terminal. Arguments as in ``step_batch`` (the actions are not read).
    """
    TASK.start(state, robots, settings, out, obs)


def reset_state(rng: np.random.Generator, p: LegParams, config: StanceConfig, nominal: Nominal):
    """Sample one initial state: nominal posture + uniform noise, projected onto the contact.

    Noise of half-width ``reset_noise_scale`` is added to ``(th_b, q1, q2)`` and their rates;
    the base position and velocity then follow from the contact (foot at the origin, ``Jc qd = 0``).
    Draws exactly 6 uniforms from ``rng`` (none when the scale is 0), so resets are reproducible.

    Returns:
        ``(q, qd, anchor)`` as float64 arrays of shapes (5,), (5,), (2,).
    """
    q, qd, anchor = reset_states([rng], p, config, nominal)
    return q[0], qd[0], anchor[0]


def reset_states(rngs, p: LegParams, config: StanceConfig, nominal: Nominal):
    """``reset_state`` for several robots at once, robot ``j`` drawing from ``rngs[j]``.

    Row ``j`` is exactly ``reset_state(rngs[j], ...)``; one compiled call builds and projects the batch.

    Returns:
        ``(q, qd, anchor)`` as float64 arrays of shapes (k, 5), (k, 5), (k, 2), ``k = len(rngs)``.
    """
    noise = np.empty((len(rngs), 6))
    if config.reset_noise_scale > 0.0:
        for j, rng in enumerate(rngs):
            rng.random(out=noise[j])
    return starts_from_noise(noise, p, config, nominal)


def starts_from_noise(noise: np.ndarray, p: LegParams, config: StanceConfig, nominal: Nominal):
    """The start states of ``reset_states`` from its ``(k, 6)`` draws of ``rng.random()`` (ignored at zero noise).

    ``rng.uniform(-s, s, 6)`` is ``-s + 2 s rng.random(6)``, computed here exactly as numpy does, so
    the states are the same bit for bit whether the draws were made in Python or in compiled code
    (``BitGeneratorRows``).
    """
    k = noise.shape[0]
    q, qd, anchor = np.empty((k, 5)), np.empty((k, 5)), np.empty((k, 2))
    kernels.perturbed_starts(np.ascontiguousarray(noise, dtype=np.float64), config.reset_noise_scale, nominal.q, p.array, q, qd, anchor)
    return q, qd, anchor


def observation_space(params: LegParams, config: StanceConfig):
    """One robot's observation space: 12 entries (pinned) or 18 (unilateral); see ``PlanarLegStanceEnv``'s table."""
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


from .base import Task  # noqa: E402  (after the kernels it names)

TASK = Task(
    name="stance",
    config_cls=StanceConfig,
    reward_terms=REWARD_TERMS,
    kernel=0,
    observation_space=observation_space,
)
"""The balance task as the shared environments see it (``leg_env.tasks.base.Task``)."""
