"""The balance task (``leg_env/PlanarLegStance-v0`` and ``-v1``): configuration, observation, reward, termination.

A control step is two calls of the compiled core on the packed arrays of ``leg_env.step``: the shared
physics (``leg_env.step.physics_range``) and this task's kernel ``assess`` (``leg_env/_core/tasks.c``:
observation, every reward term, every termination flag). The single environment calls them with a batch of one and the vector
environment with a batch of N, so the two cannot disagree. ``StanceConfig`` holds every setting; tasks
built on this one (``leg_env.tasks.push``) extend it and call ``_assess``.

Observation (float32, ``OBS_DIM = 12``):

===== ======================================== ======
index meaning                                  unit
===== ======================================== ======
0     base x relative to the foot contact point m
1     base y relative to the foot contact point m
2     torso angle th_b                          rad
3     hip angle q1                              rad
4     knee angle q2                             rad
5-9   qd = [x_b', y_b', th_b', q1', q2']        m/s, rad/s
10    lam_x / (m_total g)                       1 (N if g = 0)
11    lam_y / (m_total g)                       1 (N if g = 0)
===== ======================================== ======

The contact force is the mean over the last control step (the contact impulse / dt). With ``g = 0``
there is no weight to divide by: the kernels divide by 1, so entries 10-11 are in newtons.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from .._core import kernels
from ..contact import MODE_NAMES
from ..dynamics import NP, com_position, static_equilibrium
from ..hybrid import (
    ACC_DIM, ACC_EVENTS, ACC_FLIGHT_TIME, ACC_IMPACT_DISSIPATION, ACC_KICK_X, ACC_KICK_Y,
    ACC_PAINLEVE, ACC_SETTLES, ACC_SLIP_DISSIPATION, ACC_SLIP_DISTANCE, ACC_SLIP_TIME, ACC_STICK_TIME, ACC_WORK,
    ACC_WORK_LOAD,
)  # fmt: skip
from .. import checks
from ..integrate import MAX_ANGLE, MAX_SUBSTEPS, SUBSTEPS, DT
from ..params import LegParams
from ..step import (
    ACC0, CONSTS_BASE, FLAG_NAMES, NC, NOM0, OUT_BASE, OUT_MODE, OUT_EXTRA, OUT_LAM, STATE_DIM, TAU0,
    BitGeneratorRows, physics_range, physics_start,
)  # fmt: skip

__all__ = [
    "StanceConfig",
    "FIELD_RANGES",
    "OBS_DIM",
    "REWARD_TERMS",
    "FLAG_NAMES",
    "INFO_NAMES",
    "Nominal",
    "nominal_state",
    "STATE_DIM",
    "OUT_DIM",
    "CONSTS_DIM",
    "task_constants",
    "step_batch",
    "step_range",
    "start_batch",
    "reset_state",
    "reset_states",
    "starts_from_noise",
    "BitGeneratorRows",
    "OBS_DIM_UNILATERAL",
    "CONTACT_MODELS",
    "DEFAULT_MU",
    "UNILATERAL_KEYS",
    "unilateral_info",
    "row_info",
    "info_template",
    "REWARD_INFO_KEYS",
    "unilateral_columns",
]

OBS_DIM = 12
OBS_DIM_UNILATERAL = 18  # the pinned observation and the foot's height, velocity, contact, slip and impulse
CONTACT_MODELS = ("pinned", "unilateral")
DEFAULT_MU = {"pinned": 0.8, "unilateral": 0.5}
"""Default friction coefficient per contact model. Pinned: the cone of the violation check (as in v0).
Unilateral: 0.5, below the Painleve bound ``mu_critical`` everywhere in the joint box at the default
parameters (its minimum there is about 0.52; 0.8 would leave about 8% of postures past it), so
sliding is always well posed and the Painleve rule stays a fallback."""
REWARD_TERMS = ("alive", "drift", "unilateral", "friction", "ctrl")
INFO_NAMES = ("base_drift", "foot_error", "normal_force")
HYBRID_NAMES = ("energy", "foot_height")  # unilateral extras after the step's accumulators (leg_env.hybrid.ACC_*)
UNILATERAL_KEYS = (
    "contact_mode", "foot_height", "impulse", "stick_time", "slip_time", "flight_time", "slip_distance",
    "work_actuators", "dissipation_slip", "dissipation_impacts", "energy", "contact_events", "painleve_fallbacks",
    "zeno_settles",
)  # fmt: skip
"""``info`` keys of the unilateral contact model, after ``reset`` and ``step`` (``unilateral_info``)."""

# The packed arrays are those of ``leg_env.step`` (state, consts, out, obs, flags). This task's columns:
#   out: ... | reward terms (REWARD_TERMS order, from OUT_BASE) ; no state columns, no task constants.
#   obs (N, OBS_DIM or OBS_DIM_UNILATERAL) float32
_TERMS0 = OUT_BASE
OUT_DIM = OUT_BASE + len(REWARD_TERMS)
N_TERMS = len(REWARD_TERMS)
OUT_TERMS = slice(_TERMS0, OUT_DIM)
OUT_KICK = slice(ACC0 + ACC_KICK_X, ACC0 + ACC_KICK_Y + 1)
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

_NP, _NC, _NOM0, _TAU0 = NP, NC, NOM0, TAU0
CONSTS_DIM = CONSTS_BASE


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

    def task_array(self, p: LegParams, nominal: "Nominal") -> np.ndarray:
        """Constants of a task built on this one, after the nominal torques in ``consts`` (none here)."""
        return np.zeros(0)

    def array(self) -> np.ndarray:
        """The numeric settings in the order the kernels read them (``_C_*`` indices; ``leg_env.step.C_*``)."""
        return np.array(
            [
                self.dt,
                self.substeps,
                self.max_angle,
                self.torque_limit[0],
                self.torque_limit[1],
                self.alive_bonus,
                self.drift_position_weight,
                self.drift_angle_weight,
                self.drift_velocity_weight,
                self.unilateral_weight,
                self.friction_weight,
                self.ctrl_cost_weight,
                self.mu,
                self.min_base_height,
                self.max_torso_angle,
                self.hip_range[0],
                self.hip_range[1],
                self.knee_range[0],
                self.knee_range[1],
                float(self.terminate_on_contact_loss),
                self.contact_loss_threshold,
                self.max_rate,
                float(self.contact == "unilateral"),
            ],
            dtype=np.float64,
        )


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


def task_constants(p: LegParams, config: StanceConfig, nominal: Nominal) -> np.ndarray:
    """The kernels' ``consts`` of one robot (they only read it), shape ``(1, CONSTS_DIM + task constants)``: parameters,
    settings, nominal posture, holding torques and COM, task constants (``leg_env.step``)."""
    parts = (p.array, config.array(), nominal.q, nominal.tau, com_position(nominal.q, p), config.task_array(p, nominal))
    if [len(x) for x in parts[:5]] != [_NP, _NC, 5, 2, 2]:
        raise RuntimeError(f"task_constants: layout mismatch {[len(x) for x in parts]}")  # a developer error
    return np.concatenate(parts).astype(np.float64)[None, :]  # writable: a reset may put another robot in a row


def step_batch(state, consts, out, obs, flags):
    """Advance every robot one control step and evaluate the task, in place (one thread).

    Args:
        state: ``(N, STATE_DIM)`` float64 packed state (``leg_env.step``); ``q`` and ``qd`` are
            overwritten (left unchanged on numerical failure); the actions must already be checked
            finite and are clipped here to [-1, 1].
        consts: ``task_constants(...)``.
        out: ``(N, OUT_DIM)`` float64 out: mean contact force over the step [N], the extras, the
            hybrid step's accumulators and the reward terms (columns ``OUT_*``).
        obs: ``(N, 12 or 18)`` float32 out (left at the previous observation on numerical failure).
        flags: ``(N, 4)`` bool out, in ``FLAG_NAMES`` order.
    """
    physics_range(0, state.shape[0], state, consts, out, flags)
    TASK.assess(state, consts, out, obs, flags)


def step_range(lo, hi, state, consts, out, obs, flags):
    """``step_batch`` of the rows ``lo <= i < hi`` only (the physics releases the GIL).

    Robots are independent: the rows of a batch stepped in any split are bitwise those of ``step_batch``.
    """
    physics_range(lo, hi, state, consts, out, flags)
    TASK.assess(state[lo:hi], consts if consts.shape[0] == 1 else consts[lo:hi], out[lo:hi], obs[lo:hi], flags[lo:hi])


def start_batch(state, consts, out, obs, flags):
    """Put freshly reset robots on their contact and evaluate them without stepping.

    ``leg_env.step.physics_start`` (its docstring says how each contact model starts), then ``start``:
    the reward terms are zero and ``flags[:, 0]`` tells whether the start state is already terminal.
    Arguments as in ``step_batch`` (the actions are not read).
    """
    physics_start(state, consts, out, flags)
    TASK.start(state, consts, out, obs, flags)


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


# ``row_info`` unpacks a whole output row at once: it relies on this layout of ``out``
assert (OUT_EXTRA.start, ACC0, OUT_MODE, OUT_BASE) == (2, 5, 22, 23) and (ACC_KICK_X, ACC_STICK_TIME, ACC_EVENTS, ACC_WORK_LOAD, ACC_DIM) == (2, 4, 11, 14, 15)


def info_template(unilateral: bool, tail_keys: tuple = ()) -> dict:
    """The keys of ``row_info``'s dict, in its order, each None: ``row_info`` copies it and fills it.

    ``tail_keys`` are the names of the output columns from ``OUT_BASE`` on (a task's reward keys, then its
    own info names), as ``row_info`` writes them.
    """
    keys = ("contact_force", "normal_force", "unilateral_violation", "friction_violation", "numerical_failure", "base_drift", "foot_error")
    return dict.fromkeys(keys + (UNILATERAL_KEYS if unilateral else ()) + tuple(tail_keys))


def row_info(out: list, flags: list, force: np.ndarray, template: dict, impulse: np.ndarray | None = None) -> dict:
    """``info`` of one robot after a step, from its output row and flags (each as a list).

    ``force`` and ``impulse`` are the row's ``OUT_LAM`` and ``OUT_KICK`` columns (views, copied here:
    Gymnasium asks for new info data on every call); ``template`` is ``info_template(...)`` of the env.
    The keys are ``contact_force`` (shape (2,)), ``normal_force``, the three violation / failure flags,
    ``base_drift`` and ``foot_error``; with an ``impulse`` (the unilateral model) also the
    ``UNILATERAL_KEYS`` of ``unilateral_info`` (``contact_mode`` from the ``OUT_MODE`` column); the template's tail keys
    are left for the caller to fill (from the columns ``out[OUT_BASE:]``). This runs at every ``env.step``: a copy of a template does not grow its table item by item as a large dict
    display would.
    """
    (
        base_drift, foot_error, normal_force,
        _, _, _, _, stick_time, slip_time, flight_time, slip_distance, work, d_slip, d_impacts,
        events, painleve, settles, _, energy, foot_height,
        mode,
    ) = out[2:OUT_BASE]  # fmt: skip
    _, unilateral_violation, friction_violation, failure = flags
    info = template.copy()
    info["contact_force"] = force.copy()
    info["normal_force"] = normal_force
    info["unilateral_violation"] = unilateral_violation
    info["friction_violation"] = friction_violation
    info["numerical_failure"] = failure
    info["base_drift"] = base_drift
    info["foot_error"] = foot_error
    if impulse is not None:
        info["contact_mode"] = _MODE_NAME_OF[mode]
        info["foot_height"] = foot_height
        info["impulse"] = impulse.copy()
        info["stick_time"] = stick_time
        info["slip_time"] = slip_time
        info["flight_time"] = flight_time
        info["slip_distance"] = slip_distance
        info["work_actuators"] = work
        info["dissipation_slip"] = d_slip
        info["dissipation_impacts"] = d_impacts
        info["energy"] = energy
        info["contact_events"] = int(events) if events else 0
        info["painleve_fallbacks"] = int(painleve) if painleve else 0
        info["zeno_settles"] = int(settles) if settles else 0
    return info


_MODE_NAME_OF = {float(mode): name for mode, name in enumerate(MODE_NAMES)}  # the mode column's value -> name
_UNILATERAL_TEMPLATE = info_template(True)
REWARD_INFO_KEYS = tuple(f"reward_{name}" for name in REWARD_TERMS)
"""``info`` keys of the balance task's reward terms, after a step only (they sum to the reward)."""


def unilateral_info(out: list, mode: float) -> dict:
    """The ``UNILATERAL_KEYS`` of one robot from its output row (as a list) and its mode.

    ``contact_mode`` is ``"stick"``, ``"slip"`` or ``"flight"`` at the end of the step; ``foot_height`` [m];
    ``impulse`` the sum of impact impulses on the foot in the step [N s], shape (2,); ``stick_time``,
    ``slip_time``, ``flight_time`` [s] (they sum to ``dt``); ``slip_distance`` [m]; ``work_actuators``,
    ``dissipation_slip``, ``dissipation_impacts`` [J] (``energy(t) - energy(0)`` is the sum over the steps
    of the first minus the other two) and ``energy`` (kinetic + potential, [J]); ``contact_events``,
    ``painleve_fallbacks``, ``zeno_settles`` (ints) count what ``leg_env.hybrid`` describes.
    """
    out = list(out[:OUT_BASE])
    out[OUT_MODE] = float(mode)
    row = np.asarray(out, dtype=np.float64)
    info = row_info(out, [False] * len(FLAG_NAMES), row[OUT_LAM], _UNILATERAL_TEMPLATE, row[OUT_KICK])
    return {key: info[key] for key in UNILATERAL_KEYS}


def unilateral_columns(out: np.ndarray, modes: np.ndarray) -> dict:
    """``unilateral_info`` of many robots at once: one fresh array per key over the rows of ``out``."""
    acc = out[:, ACC0:OUT_MODE].T.copy()  # one copy serves every key
    counts = acc[[ACC_EVENTS, ACC_PAINLEVE, ACC_SETTLES]].astype(np.int64)
    return {
        "contact_mode": np.take(_MODE_NAME_ARRAY, modes.astype(np.intp)),
        "foot_height": acc[ACC_DIM + 1],
        "impulse": acc[ACC_KICK_X:ACC_KICK_Y + 1].T,
        "stick_time": acc[ACC_STICK_TIME],
        "slip_time": acc[ACC_SLIP_TIME],
        "flight_time": acc[ACC_FLIGHT_TIME],
        "slip_distance": acc[ACC_SLIP_DISTANCE],
        "work_actuators": acc[ACC_WORK],
        "dissipation_slip": acc[ACC_SLIP_DISSIPATION],
        "dissipation_impacts": acc[ACC_IMPACT_DISSIPATION],
        "energy": acc[ACC_DIM],
        "contact_events": counts[0],
        "painleve_fallbacks": counts[1],
        "zeno_settles": counts[2],
    }


_MODE_NAME_ARRAY = np.array(MODE_NAMES)


def observation_space(params: LegParams, config: StanceConfig):
    """One robot's observation space: 12 entries (pinned) or 18 (unilateral); see ``PlanarLegStanceEnv``'s table."""
    from gymnasium import spaces

    reach = 1.01 * (params.l1 + params.l2)
    unilateral = config.contact == "unilateral"
    high = np.full(OBS_DIM_UNILATERAL if unilateral else OBS_DIM, np.inf, dtype=np.float32)
    high[0] = reach
    if not unilateral:  # on the unilateral ground the base may fly: its height has no bound
        high[1] = reach
    else:
        high[15] = 1.0  # contact flag
        high[16] = 1.0  # slip direction
    low = -high
    if unilateral:
        low[15] = 0.0
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
