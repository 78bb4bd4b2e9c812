"""The balance task on the stance model: configuration, observation, reward and termination.

One batched kernel (``step_batch``) advances the physics and computes the observation,
every reward term and every termination flag. The single environment calls it with a
batch of one and the vector environment with a batch of N, so the two cannot disagree.

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

import ctypes
import math
from dataclasses import asdict, dataclass, fields, replace

import numba
import numpy as np
from numba import njit

from ._jit import CACHE
from .contact import FLIGHT, MODE_NAMES, SLIP_BACKWARD, SLIP_FORWARD, STICK, _foot_velocity
from .dynamics import _energy_core, _stance_one, static_equilibrium
from .hybrid import (
    ACC_DIM, ACC_EVENTS, ACC_FLIGHT_TIME, ACC_IMPACT_DISSIPATION, ACC_IMPULSE_X, ACC_IMPULSE_Y, ACC_KICK_X, ACC_KICK_Y,
    ACC_PAINLEVE, ACC_SETTLES, ACC_SLIP_DISSIPATION, ACC_SLIP_DISTANCE, ACC_SLIP_TIME, ACC_STICK_TIME, ACC_WORK, GROUND_TOL,
    LOG_SIZE,
    _choose_mode, _derivative, _hybrid_from,
)  # fmt: skip
from . import checks
from .integrate import MAX_ANGLE, MAX_SUBSTEPS, SUBSTEPS, DT, _project_one, _rk4_from
from .params import LegParams

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
    "REWARD_INFO_KEYS",
    "compiled_entry",
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
FLAG_NAMES = ("terminated", "unilateral_violation", "friction_violation", "numerical_failure")
INFO_NAMES = ("base_drift", "foot_error", "normal_force")
HYBRID_NAMES = ("energy", "foot_height")  # unilateral extras after the step's accumulators (leg_env.hybrid.ACC_*)
UNILATERAL_KEYS = (
    "contact_mode", "foot_height", "impulse", "stick_time", "slip_time", "flight_time", "slip_distance",
    "work_actuators", "dissipation_slip", "dissipation_impacts", "energy", "contact_events", "painleve_fallbacks",
    "zeno_settles",
)  # fmt: skip
"""``info`` keys of the unilateral contact model, after ``reset`` and ``step`` (``unilateral_info``)."""

# The kernels take five arrays, so that a call from Python costs little to dispatch:
#   state (N, STATE_DIM) float64: q | qd | anchor | action | trig | mode  (columns STATE_Q, STATE_QD, ...);
#       trig = sin th1, cos th1, sin th2, cos th2 of q, written by the kernels that write q (start_batch,
#       step_batch) and read by the next step: callers change q only through start_batch
#   consts (CONSTS_DIM,) float64: LegParams.array | StanceConfig.array() | q_nom | tau_nom (task_constants)
#       mode: the contact mode (leg_env.contact constants; unilateral model only), as a float
#   out (N, OUT_DIM) float64: lam | reward terms (REWARD_TERMS order) | extras (INFO_NAMES order)
#       | the hybrid step's accumulators (leg_env.hybrid.ACC_*) | HYBRID_NAMES (unilateral model only)
#   obs (N, OBS_DIM or OBS_DIM_UNILATERAL) float32, flags (N, len(FLAG_NAMES)) bool
_QD0, _ANCHOR0, _ACTION0, _TRIG0, _MODE0, STATE_DIM = 5, 10, 12, 14, 18, 19  # first columns of qd ... mode; width
_TERMS0, _EXTRA0 = 2, 2 + len(REWARD_TERMS)  # first columns of the reward terms and the extras
_ACC0 = _EXTRA0 + len(INFO_NAMES)  # first column of the hybrid accumulators
_HYB0 = _ACC0 + ACC_DIM
OUT_DIM = _HYB0 + len(HYBRID_NAMES)
STATE_Q, STATE_QD, STATE_ANCHOR, STATE_ACTION = slice(0, _QD0), slice(_QD0, _ANCHOR0), slice(_ANCHOR0, _ACTION0), slice(_ACTION0, _TRIG0)
STATE_MODE = _MODE0
OUT_LAM, OUT_TERMS, OUT_EXTRA = slice(0, _TERMS0), slice(_TERMS0, _EXTRA0), slice(_EXTRA0, _ACC0)
OUT_ACC, OUT_HYBRID = slice(_ACC0, _HYB0), slice(_HYB0, OUT_DIM)
OUT_KICK = slice(_ACC0 + ACC_KICK_X, _ACC0 + ACC_KICK_Y + 1)  # the step's impact impulses (unilateral model)
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

_NP, _NC = 11, 23  # lengths of LegParams.array and StanceConfig.array()
_NOM0, _TAU0 = _NP + _NC, _NP + _NC + 5  # first entries of q_nom and tau_nom in consts
CONSTS_DIM = _TAU0 + 2
_KEPT = 4 + OBS_DIM_UNILATERAL  # scratch kept by a control step to undo itself: trig and the observation


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
            raise TypeError(f"got {what}: not an argument of the env nor a StanceConfig field")
        if config is not None and not isinstance(config, (StanceConfig, dict)):
            raise checks.ArgumentTypeError(
                f"config must be a StanceConfig, a dict of its fields or None, got {checks.shown(config)} of type {type(config).__name__}"
            )
        base = {} if config is None else (asdict(config) if isinstance(config, StanceConfig) else dict(config))
        unknown = sorted(set(base) - names)
        if unknown:
            raise ValueError(f"config has unknown StanceConfig field(s): {unknown}")
        base.update(overrides)
        return cls(**base)

    def replace(self, **changes) -> "StanceConfig":
        """A copy with ``changes`` (checked as at construction)."""
        return replace(self, **changes)

    def array(self) -> np.ndarray:
        """The numeric settings in the order ``step_batch`` reads them (``_C_*`` indices)."""
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

(
    _C_DT,
    _C_SUBSTEPS,
    _C_MAX_ANGLE,
    _C_TAU_HIP,
    _C_TAU_KNEE,
    _C_ALIVE,
    _C_W_POS,
    _C_W_ANG,
    _C_W_VEL,
    _C_W_UNI,
    _C_W_FRIC,
    _C_W_CTRL,
    _C_MU,
    _C_MIN_HEIGHT,
    _C_MAX_TORSO,
    _C_HIP_LO,
    _C_HIP_HI,
    _C_KNEE_LO,
    _C_KNEE_HI,
    _C_TERM_CONTACT,
    _C_CONTACT_THRESH,
    _C_MAX_RATE,
    _C_UNILATERAL,
) = range(23)


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
    """The kernels' read-only ``consts`` array: parameters, settings, nominal posture and torques."""
    parts = (p.array, config.array(), nominal.q, nominal.tau)
    if [len(x) for x in parts] != [_NP, _NC, 5, 2]:
        raise RuntimeError(f"task_constants: layout mismatch {[len(x) for x in parts]}")  # a developer error
    out = np.concatenate(parts).astype(np.float64)
    out.setflags(write=False)
    return out


@njit(cache=CACHE, inline="always")
def _unpack(state, consts, out):
    """Named views of the packed kernel arrays."""
    return (
        state[:, :_QD0], state[:, _QD0:_ANCHOR0], state[:, _ANCHOR0:_ACTION0], state[:, _ACTION0:_TRIG0], state[:, _TRIG0:_MODE0],
        consts[:_NP], consts[_NP:_NOM0], consts[_NOM0:_TAU0], consts[_TAU0:],
        out[:, :_TERMS0], out[:, _TERMS0:_EXTRA0], out[:, _EXTRA0:_ACC0],
    )  # fmt: skip


@njit(cache=CACHE, inline="always")
def _assess(i, q, qd, anchor, lam, a0, a1, p, c, q_nom, weight, obs, terms, flags, extra, trig, mode, hyb):
    """Reward terms, flags, extras and observation of robot ``i`` at its (finite) state and force.

    The one place where the task's predicates (health, feasibility) are written. ``mode`` and ``hyb``
    (the step's accumulators and the unilateral extras) are read and written in the unilateral model only.
    """
    lam_x, lam_y = lam[i, 0], lam[i, 1]
    dx = q[i, 0] - anchor[i, 0] - q_nom[0]
    dy = q[i, 1] - anchor[i, 1] - q_nom[1]
    th_b = q[i, 2]
    # foot error and knee height from the same kinematics as the integrator
    l1, l2 = p[6], p[7]
    th1 = q[i, 2] + q[i, 3]
    th2 = th1 + q[i, 4]
    s1, co1, s2, co2 = np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2)
    trig[i, 0], trig[i, 1], trig[i, 2], trig[i, 3] = s1, co1, s2, co2  # for the next step
    knee_y = q[i, 1] + l1 * s1
    fx = q[i, 0] + l1 * co1 + l2 * co2 - anchor[i, 0]
    fy = knee_y + l2 * s2 - anchor[i, 1]
    height = q[i, 1] - anchor[i, 1]
    unilateral_model = c[_C_UNILATERAL] > 0.5

    unilateral = max(0.0, -lam_y)
    friction = max(0.0, abs(lam_x) - c[_C_MU] * lam_y)
    fell = (
        height < c[_C_MIN_HEIGHT]
        or q[i, 1] < knee_y
        or abs(th_b) > c[_C_MAX_TORSO]
        or q[i, 3] < c[_C_HIP_LO]
        or q[i, 3] > c[_C_HIP_HI]
        or q[i, 4] < c[_C_KNEE_LO]
        or q[i, 4] > c[_C_KNEE_HI]
    )
    if unilateral_model:  # the ground cannot pull: what is charged is time off it and sliding on it
        dt = c[_C_DT]
        flight_time = hyb[i, ACC_FLIGHT_TIME]
        lost = c[_C_TERM_CONTACT] > 0.5 and (flight_time > 0.0 or lam_y < c[_C_CONTACT_THRESH])
    else:
        lost = c[_C_TERM_CONTACT] > 0.5 and lam_y < c[_C_CONTACT_THRESH]
    terminated = fell or lost

    terms[i, 0] = 0.0 if terminated else c[_C_ALIVE]
    terms[i, 1] = -(
        c[_C_W_POS] * (dx * dx + dy * dy)
        + c[_C_W_ANG] * th_b * th_b
        + c[_C_W_VEL] * (qd[i, 0] ** 2 + qd[i, 1] ** 2 + qd[i, 2] ** 2)
    )
    if unilateral_model:
        terms[i, 2] = -c[_C_W_UNI] * flight_time / dt
        terms[i, 3] = -c[_C_W_FRIC] * hyb[i, ACC_SLIP_DISTANCE] / dt
        flags[i, 2] = friction > 1e-9 * weight  # a stick force outside the cone: only by the Painleve rule
    else:
        terms[i, 2] = -c[_C_W_UNI] * unilateral / weight
        terms[i, 3] = -c[_C_W_FRIC] * friction / weight
        flags[i, 2] = friction > 0.0
    terms[i, 4] = -c[_C_W_CTRL] * (a0 * a0 + a1 * a1)
    flags[i, 0] = terminated
    flags[i, 1] = lam_y < 0.0
    flags[i, 3] = False
    extra[i, 0] = np.sqrt(dx * dx + dy * dy)
    extra[i, 1] = np.sqrt(fx * fx + fy * fy)
    extra[i, 2] = lam_y
    # observation
    obs[i, 0] = q[i, 0] - anchor[i, 0]
    obs[i, 1] = height
    for j in range(2, 5):
        obs[i, j] = q[i, j]
    for j in range(5):
        obs[i, 5 + j] = qd[i, j]
    obs[i, 10] = lam_x / weight
    obs[i, 11] = lam_y / weight
    if unilateral_model:
        w1 = qd[i, 2] + qd[i, 3]
        w2 = w1 + qd[i, 4]
        vfx, vfy = _foot_velocity(s1, co1, s2, co2, qd[i, 0], qd[i, 1], w1, w2, p)
        m = mode[i]
        obs[i, 12] = fy
        obs[i, 13] = vfx
        obs[i, 14] = vfy
        obs[i, 15] = 0.0 if m == FLIGHT else 1.0
        obs[i, 16] = 1.0 if m == SLIP_FORWARD else (-1.0 if m == SLIP_BACKWARD else 0.0)
        obs[i, 17] = hyb[i, ACC_KICK_Y] / (weight * c[_C_DT])
        hyb[i, ACC_DIM] = _energy_core(s1, co1, s2, co2, q[i, 1] - anchor[i, 1], qd[i, 0], qd[i, 1], qd[i, 2], w1, w2, p)
        hyb[i, ACC_DIM + 1] = fy


@njit(cache=CACHE, inline="always")
def _step_one(i, q, qd, anchor, action, trig, mode, p, c, q_nom, weight, lam, obs, terms, flags, extra, hyb, scratch, log_k):
    """One control step and task evaluation of robot ``i``; ``scratch`` and ``log_k`` are scratch space.

    A numerical failure (a non-finite state or force, a rate above ``max_rate``, or an observation
    that does not fit float32) restores the state before the step and is flagged (``_fail``).
    """
    q_prev, qd_prev, tau, a = scratch[0:5], scratch[5:10], scratch[10:12], scratch[12:14]
    kept, log_t = scratch[14:14 + _KEPT], scratch[14 + _KEPT:]
    for j in range(5):
        q_prev[j] = q[i, j]
        qd_prev[j] = qd[i, j]
    for j in range(4):
        kept[j] = trig[i, j]
    for j in range(obs.shape[1]):
        kept[4 + j] = obs[i, j]
    a[0] = min(1.0, max(-1.0, action[i, 0]))
    a[1] = min(1.0, max(-1.0, action[i, 1]))
    tau[0] = a[0] * c[_C_TAU_HIP]
    tau[1] = a[1] * c[_C_TAU_KNEE]
    mode_prev, anchor_prev = mode[i], anchor[i, 0]
    if c[_C_UNILATERAL] > 0.5:
        mode[i] = _hybrid_from(
            q[i], qd[i], tau, p, c[_C_MU], int(mode[i]), anchor[i], c[_C_DT], int(c[_C_SUBSTEPS]), c[_C_MAX_ANGLE],
            trig[i, 0], trig[i, 1], trig[i, 2], trig[i, 3], hyb[i], log_t, log_k,
        )  # fmt: skip
        lam[i, 0] = hyb[i, ACC_IMPULSE_X] / c[_C_DT]
        lam[i, 1] = hyb[i, ACC_IMPULSE_Y] / c[_C_DT]
    else:
        _rk4_from(
            q[i], qd[i], tau, p, anchor[i], c[_C_DT], int(c[_C_SUBSTEPS]), c[_C_MAX_ANGLE], True, lam[i],
            trig[i, 0], trig[i, 1], trig[i, 2], trig[i, 3],
        )  # fmt: skip

    finite = np.isfinite(lam[i, 0]) and np.isfinite(lam[i, 1])
    for j in range(5):
        if not (np.isfinite(q[i, j]) and abs(qd[i, j]) <= c[_C_MAX_RATE]):
            finite = False
    if not finite:
        _fail(i, q, qd, anchor, mode, lam, terms, flags, extra, hyb, q_nom, q_prev, qd_prev, mode_prev, anchor_prev)
        return
    _assess(i, q, qd, anchor, lam, a[0], a[1], p, c, q_nom, weight, obs, terms, flags, extra, trig, mode, hyb)
    total = 0.0  # float64: finite for any finite float32 entries, inf or NaN if one of them is
    for j in range(obs.shape[1]):
        total += obs[i, j]
    if not np.isfinite(total):  # the state is finite, but the observation overflowed float32
        for j in range(4):
            trig[i, j] = kept[j]
        for j in range(obs.shape[1]):
            obs[i, j] = kept[4 + j]
        _fail(i, q, qd, anchor, mode, lam, terms, flags, extra, hyb, q_nom, q_prev, qd_prev, mode_prev, anchor_prev)


@njit(cache=CACHE, inline="always")
def _fail(i, q, qd, anchor, mode, lam, terms, flags, extra, hyb, q_nom, q_prev, qd_prev, mode_prev, anchor_prev):
    """A numerical failure of robot ``i``: restore the last good state, end the episode, pay nothing.

    The observation is left at the last good one; ``flags`` say terminated and ``numerical_failure``.
    """
    for j in range(5):
        q[i, j] = q_prev[j]
        qd[i, j] = qd_prev[j]
    mode[i] = mode_prev
    anchor[i, 0] = anchor_prev
    lam[i, 0] = 0.0
    lam[i, 1] = 0.0
    for k in range(terms.shape[1]):
        terms[i, k] = 0.0
    for k in range(hyb.shape[1]):
        hyb[i, k] = 0.0
    flags[i, 0] = True
    flags[i, 1] = False
    flags[i, 2] = False
    flags[i, 3] = True
    extra[i, 0] = np.sqrt((q[i, 0] - anchor[i, 0] - q_nom[0]) ** 2 + (q[i, 1] - anchor[i, 1] - q_nom[1]) ** 2)
    extra[i, 1] = 0.0
    extra[i, 2] = 0.0


@njit(cache=CACHE, inline="always")
def _weight(p):
    weight = (p[0] + p[1] + p[2]) * p[10]
    return weight if weight > 0.0 else 1.0


@njit(cache=CACHE, nogil=True)
def step_range(lo, hi, state, consts, out, obs, flags):
    """``step_batch`` of the rows ``lo <= i < hi`` only; releases the GIL, so that threads can share a batch.

    Robots are independent: the rows of a batch stepped in any split are bitwise those of ``step_batch``.
    """
    q, qd, anchor, action, trig, p, c, q_nom, _, lam, terms, extra = _unpack(state, consts, out)
    mode, hyb = state[:, _MODE0], out[:, _ACC0:]
    weight = _weight(p)
    scratch = np.empty(14 + _KEPT + LOG_SIZE)
    log_k = np.empty(LOG_SIZE, dtype=np.int64)
    for i in range(lo, hi):
        _step_one(i, q, qd, anchor, action, trig, mode, p, c, q_nom, weight, lam, obs, terms, flags, extra, hyb, scratch, log_k)


@njit(cache=CACHE)
def step_batch(state, consts, out, obs, flags):
    """Advance every robot one control step and evaluate the task, in place (one thread).

    Args:
        state: ``(N, STATE_DIM)`` float64 ``q | qd | anchor | action`` (columns ``STATE_*``); ``q``
            and ``qd`` are overwritten (left unchanged on numerical failure); the actions must
            already be checked finite and are clipped here to [-1, 1].
        consts: ``task_constants(...)``.
        out: ``(N, OUT_DIM)`` float64 out: mean contact force over the step [N], the reward terms
            (they sum to the reward) and the extras (columns ``OUT_*``).
        obs: ``(N, 12)`` float32 out (left at the previous observation on numerical failure).
        flags: ``(N, 4)`` bool out, in ``FLAG_NAMES`` order.
    """
    step_range(0, state.shape[0], state, consts, out, obs, flags)


@njit(cache=CACHE)
def start_batch(state, consts, out, obs, flags):
    """Put freshly reset robots on their contact and evaluate them without stepping.

    Pinned model: each robot's base is first projected so that its foot is on its anchor with
    ``Jc qd = 0`` (``leg_env.integrate.project_stance``). Unilateral model: a foot within
    ``GROUND_TOL`` of the ground (``y = anchor[1]``) is put on it by moving the base, and the mode is
    chosen as at the start of a control step (``leg_env.hybrid``; a foot moving into the ground gets the
    impact map); a foot above it flies. No control step has been taken yet, so the contact force is
    the instantaneous force of that mode under the nominal holding torques: at the nominal posture it
    is exactly the nominal ``[0, m g]`` up to round-off. The reward terms and the step's accumulators
    are zeroed. Arguments as in ``step_batch`` (the actions are not read); ``flags[:, 0]`` tells whether
    the start state is already terminal.
    """
    q, qd, anchor, _, trig, p, c, q_nom, tau, lam, terms, extra = _unpack(state, consts, out)
    mode, hyb = state[:, _MODE0], out[:, _ACC0:]
    weight = _weight(p)
    qdd = np.empty(5)
    for i in range(state.shape[0]):
        if c[_C_UNILATERAL] > 0.5:
            _start_unilateral(q[i], qd[i], anchor[i], mode, i, tau, c[_C_MU], p, lam[i], hyb[i])
        else:
            _project_one(q[i], qd[i], p, anchor[i])
            _stance_one(q[i], qd[i], tau, p, qdd, lam[i])
        _assess(i, q, qd, anchor, lam, 0.0, 0.0, p, c, q_nom, weight, obs, terms, flags, extra, trig, mode, hyb)
        for k in range(terms.shape[1]):
            terms[i, k] = 0.0


def compiled_entry(kernel, args: tuple):
    """The machine code of ``kernel`` for the types of ``args``, callable as ``kernel`` is.

    A numba dispatcher types every argument at every call (about 0.25 us for the five arrays of a
    task kernel, a twentieth of a single env's ``step``). The arrays of an env never change type, so
    the env compiles its kernels once for exactly their types and calls the compiled entry point,
    which skips that typing. It must then only ever be called with arrays of those types. Where numba
    does not expose ``overloads[signature].entry_point`` the dispatcher itself is returned: the same
    machine code behind a little more overhead.
    """
    signature = tuple(numba.typeof(a) for a in args)
    try:
        kernel.compile(signature)
        return kernel.overloads[signature].entry_point
    except (AttributeError, KeyError, TypeError):
        return kernel


@njit(cache=CACHE)
def _start_unilateral(q, qd, anchor, mode, i, tau, mu, p, lam, hyb):
    """Mode, ground contact and instantaneous force of a unilateral start state (``start_batch``)."""
    l1, l2 = p[6], p[7]
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    s1, co1, s2, co2 = np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2)
    height = q[1] + l1 * s1 + l2 * s2 - anchor[1]
    if height <= GROUND_TOL:
        q[1] -= height
    X = (q[0], q[1], q[2], q[3], q[4], qd[0], qd[1], qd[2], qd[3], qd[4], s1, co1, s2, co2)
    m, X = _choose_mode(FLIGHT, X, anchor, tau[0], tau[1], mu, p, -1, False, hyb)
    for j in range(5):
        q[j] = X[j]
        qd[j] = X[5 + j]
    if m != STICK:
        anchor[0] = q[0] + l1 * co1 + l2 * co2
    mode[i] = m
    k = _derivative(m, mu, X, tau[0], tau[1], p)
    lam[0], lam[1] = k[5], k[6]
    for j in range(hyb.shape[0]):
        hyb[j] = 0.0


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
    return _perturbed_starts(noise, config.reset_noise_scale, nominal.q, p.array)


class BitGeneratorRows:
    """Draw ``rng.random()`` for many generators in one compiled call, through numpy's ctypes interface.

    Holds the generators (so their states stay alive) and the addresses of their bit generator
    states; ``draw(rows, out)`` fills ``out[k]`` with ``out.shape[1]`` draws from generator
    ``rows[k]``, exactly the numbers (and the state advance) of ``rng.random(out=out[k])``. This is
    numpy's documented route for numba (``BitGenerator.ctypes``). Generators whose bit generator
    has another ``next_double`` (not numpy's PCG64) are drawn in Python instead.
    """

    def __init__(self, n: int):
        self.generators: list[np.random.Generator | None] = [None] * n
        self._states = np.zeros(n, dtype=np.int64)
        self._next_double = None
        self._compiled = np.zeros(n, dtype=np.bool_)  # row drawn by the compiled path

    def __setitem__(self, i: int, rng: np.random.Generator) -> None:
        self.generators[i] = rng
        interface = rng.bit_generator.ctypes
        if self._next_double is None and isinstance(rng.bit_generator, np.random.PCG64):
            self._next_double = interface.next_double
        same = self._next_double is not None and _fn_address(interface.next_double) == _fn_address(self._next_double)
        self._compiled[i] = same
        self._states[i] = interface.state_address if same else 0

    def __getitem__(self, i: int) -> np.random.Generator | None:
        return self.generators[i]

    def draw(self, rows: np.ndarray, out: np.ndarray) -> None:
        """``out[k] = generators[rows[k]].random(out.shape[1])`` for every k."""
        if self._compiled[rows].all():
            _draw_rows(self._next_double, self._states, rows, out)
            return
        for k, i in enumerate(rows.tolist()):
            self.generators[i].random(out=out[k])

    def __getstate__(self) -> dict:
        return {"generators": self.generators}

    def __setstate__(self, state: dict) -> None:
        self.__init__(len(state["generators"]))
        for i, rng in enumerate(state["generators"]):
            if rng is not None:
                self[i] = rng


def _fn_address(fn) -> int:
    return ctypes.cast(fn, ctypes.c_void_p).value


@njit(cache=CACHE)
def _draw_rows(next_double, states, rows, out):
    for k in range(rows.shape[0]):
        state = states[rows[k]]
        for j in range(out.shape[1]):
            out[k, j] = next_double(state)


@njit(cache=CACHE)
def _perturbed_starts(noise, s, q_nom, p):
    """Nominal posture + ``uniform(-s, s)`` noise (from ``noise`` in [0, 1)) on (th_b, q1, q2) and their rates, projected."""
    k = noise.shape[0]
    q = np.empty((k, 5))
    qd = np.zeros((k, 5))
    anchor = np.zeros((k, 2))
    low, width = -s, s - (-s)  # numpy's uniform(low, high): low + (high - low) * random()
    for i in range(k):
        for j in range(5):
            q[i, j] = q_nom[j]
        if s > 0.0:
            for j in range(3):
                q[i, 2 + j] += low + width * noise[i, j]
                qd[i, 2 + j] += low + width * noise[i, 3 + j]
        _project_one(q[i], qd[i], p, anchor[i])
    return q, qd, anchor


# ``row_info`` unpacks a whole output row at once: it relies on this layout of ``out``
assert (_TERMS0, _EXTRA0, _ACC0, OUT_DIM) == (2, 7, 10, 26) and (ACC_KICK_X, ACC_STICK_TIME, ACC_EVENTS) == (2, 4, 11)


def row_info(out: list, flags: list, force: np.ndarray, impulse: np.ndarray | None = None, mode: float = 0.0) -> dict:
    """``info`` of one robot after a step, from its output row and flags (each as a list).

    ``force`` and ``impulse`` are the row's ``OUT_LAM`` and ``OUT_KICK`` columns (views, copied here:
    Gymnasium asks for new info data on every call). The keys are the reward terms
    (``reward_<term>`` of ``REWARD_TERMS``), ``contact_force`` (shape (2,)), ``normal_force``, the three
    violation / failure flags, ``base_drift`` and ``foot_error``; with an ``impulse`` (the unilateral
    model) also the ``UNILATERAL_KEYS`` of ``unilateral_info``, ``mode`` giving ``contact_mode``. After a
    reset the reward keys are left out (``REWARD_INFO_KEYS``). One dict display each, because this runs
    at every ``env.step``.
    """
    (
        _, _, alive, drift, unilateral, friction, ctrl, base_drift, foot_error, normal_force,
        _, _, _, _, stick_time, slip_time, flight_time, slip_distance, work, d_slip, d_impacts,
        events, painleve, settles, energy, foot_height,
    ) = out  # fmt: skip
    _, unilateral_violation, friction_violation, failure = flags
    if impulse is None:
        return {
            "contact_force": force.copy(),
            "normal_force": normal_force,
            "unilateral_violation": unilateral_violation,
            "friction_violation": friction_violation,
            "numerical_failure": failure,
            "base_drift": base_drift,
            "foot_error": foot_error,
            "reward_alive": alive,
            "reward_drift": drift,
            "reward_unilateral": unilateral,
            "reward_friction": friction,
            "reward_ctrl": ctrl,
        }
    # 26 keys: a dict display that large grows its table item by item, a copy of a template does not
    info = _UNILATERAL_TEMPLATE.copy()
    info["contact_force"] = force.copy()
    info["normal_force"] = normal_force
    info["unilateral_violation"] = unilateral_violation
    info["friction_violation"] = friction_violation
    info["numerical_failure"] = failure
    info["base_drift"] = base_drift
    info["foot_error"] = foot_error
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
    info["reward_alive"] = alive
    info["reward_drift"] = drift
    info["reward_unilateral"] = unilateral
    info["reward_friction"] = friction
    info["reward_ctrl"] = ctrl
    return info


REWARD_INFO_KEYS = tuple(f"reward_{name}" for name in REWARD_TERMS)
"""``info`` keys of the reward terms, after a step only (they sum to the reward)."""
assert REWARD_INFO_KEYS == ("reward_alive", "reward_drift", "reward_unilateral", "reward_friction", "reward_ctrl")
_UNILATERAL_TEMPLATE = dict.fromkeys(
    ("contact_force", "normal_force", "unilateral_violation", "friction_violation", "numerical_failure", "base_drift", "foot_error")
    + UNILATERAL_KEYS + REWARD_INFO_KEYS
)  # the keys of row_info's unilateral dict, in its order


def unilateral_info(out: list, mode: float) -> dict:
    """The ``UNILATERAL_KEYS`` of one robot from its output row (as a list) and its mode.

    ``contact_mode`` is ``"stick"``, ``"slip"`` or ``"flight"`` at the end of the step; ``foot_height`` [m];
    ``impulse`` the sum of impact impulses on the foot in the step [N s], shape (2,); ``stick_time``,
    ``slip_time``, ``flight_time`` [s] (they sum to ``dt``); ``slip_distance`` [m]; ``work_actuators``,
    ``dissipation_slip``, ``dissipation_impacts`` [J] (``energy(t) - energy(0)`` is the sum over the steps
    of the first minus the other two) and ``energy`` (kinetic + potential, [J]); ``contact_events``,
    ``painleve_fallbacks``, ``zeno_settles`` (ints) count what ``leg_env.hybrid`` describes.
    """
    row = np.asarray(out, dtype=np.float64)
    info = row_info(out, [False] * len(FLAG_NAMES), row[OUT_LAM], row[OUT_KICK], mode)
    return {key: info[key] for key in UNILATERAL_KEYS}


_MODE_NAME_OF = {float(mode): name for mode, name in enumerate(MODE_NAMES)}  # the mode column's value -> name


def unilateral_columns(out: np.ndarray, modes: np.ndarray) -> dict:
    """``unilateral_info`` of many robots at once: one fresh array per key over the rows of ``out``."""
    acc = out[:, _ACC0:].T.copy()  # one copy serves every key
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
