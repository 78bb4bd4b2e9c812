"""Domain randomisation: a robot of its own for every sub-environment, drawn at every reset.

Every task takes ``randomize``: None (the default: the nominal robot, and no random number is drawn,
so every seed reproduces what it did before randomisation existed), True (``DEFAULT_RANGES``), a dict
``{field: range}`` or a ``Randomization``. The fields (``FIELDS``) are those of ``LegParams``, the
friction coefficient ``mu`` and the torque limits ``hip_torque_limit`` and ``knee_torque_limit``. A
range is one of

* ``("scale", low, high)``: the nominal value times ``U(low, high)``;
* ``("offset", low, high)``: the nominal value plus ``U(low, high)`` (in the field's unit);
* ``("range", low, high)`` or ``(low, high)``: ``U(low, high)``, whatever the nominal value.

Each value is drawn from the nominal one at every reset, never from the last drawn one, so nothing
compounds across resets. "Nominal" is the env's own robot (its ``params``, ``mu`` and
``torque_limit``). The nominal posture, holding torques, COM height and every other derived constant
follow each drawn robot (the env's ``robots`` array has a row per robot).

Draws, in the sub-env's own generator, before the posture noise: one uniform per randomised field in
``FIELDS`` order (whatever the order of the dict). **Rejection rule.** A drawn robot is refused, and
all its fields drawn again, when its nominal posture could not be run:

* a holding torque of the nominal posture exceeds the drawn torque limit;
* the nominal posture is outside the task's termination limits (``hip_range``, ``knee_range``,
  ``min_base_height``);
* on the unilateral ground, the friction is at or past the Painleve bound at the nominal posture,
  ``mu >= mu_critical(q_nom)`` (sliding there would not be well posed; ``leg_env.physics.contact``).

A reset tries at most ``MAX_DRAWS`` robots. Ranges under which fewer than ``MIN_ACCEPTANCE`` of
``CHECK_DRAWS`` robots (drawn from a fixed seed at construction) are accepted are refused at
construction with a ``ValueError``, so a reset that exhausts its ``MAX_DRAWS`` is a rare event
(probability below ``(1 - MIN_ACCEPTANCE) ** MAX_DRAWS``, about 1e-5): it runs the nominal robot,
and ``info["params_rejected"]`` (the robots refused at that reset) says ``MAX_DRAWS``.

``DEFAULT_RANGES`` (``randomize=True``): masses and inertias times U(0.8, 1.2); the links' COM
distances ``c1``, ``c2`` plus U(-2, 2) cm; the torque limits times U(0.9, 1.1); ``mu`` times U(0.6, 1):
on the unilateral ground 0.3 to 0.5, at most the nominal 0.5, which is below the nominal robot's
Painleve bound at every posture of the joint box (its minimum there is 0.523); the drawn masses move
the bound (over 200 default robots its minimum ranged from 0.44 to 0.60, and 3.5% of them had a ``mu``
past it on 0.01% of the box's postures, where the contact model's Painleve rule applies and is
counted); on the pinned ground, where ``mu`` is only the cone of the violation check, 0.48 to 0.8.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import checks
from ._core import kernels
from .physics import layout
from .physics.params import G_MIN, PARAM_NAMES, PARAM_RANGE

__all__ = [
    "FIELDS",
    "KINDS",
    "DEFAULT_RANGES",
    "MAX_DRAWS",
    "CHECK_DRAWS",
    "MIN_ACCEPTANCE",
    "Randomization",
    "robot_params",
]

FIELDS: tuple[str, ...] = PARAM_NAMES + ("mu", "hip_torque_limit", "knee_torque_limit")
"""The fields that can be randomised, in the order they are drawn."""
KINDS = ("scale", "offset", "range")
DEFAULT_RANGES = {
    **{name: ("scale", 0.8, 1.2) for name in ("m_b", "m1", "m2", "I_b", "I1", "I2")},
    "c1": ("offset", -0.02, 0.02),
    "c2": ("offset", -0.02, 0.02),
    "mu": ("scale", 0.6, 1.0),
    "hip_torque_limit": ("scale", 0.9, 1.1),
    "knee_torque_limit": ("scale", 0.9, 1.1),
}
"""``randomize=True``: the usual ranges of legged-robot suites (legged_gym, Isaac Lab)."""
MAX_DRAWS = 100
CHECK_DRAWS = 1000
MIN_ACCEPTANCE = 0.1

def _double_index(field: str, k: int = 0) -> int:
    """The index of ``ROBOT`` field ``field`` (entry ``k`` of an array field) among the doubles of a robot."""
    if field in layout.PARAMS.names:
        return (layout.ROBOT.fields["p"][1] + layout.PARAMS.fields[field][1]) // 8
    return layout.ROBOT.fields[field][1] // 8 + k


# where each field lives among the doubles of a robot (leg_env.physics.layout.ROBOT: its LegParams, mu, torque limits)
_COLUMN = {**{name: _double_index(name) for name in PARAM_NAMES}, "mu": _double_index("mu"),
           "hip_torque_limit": _double_index("torque_limit", 0), "knee_torque_limit": _double_index("torque_limit", 1)}  # fmt: skip
FIELD_COLUMNS = np.array([_COLUMN[name] for name in FIELDS])
"""The index of each of ``FIELDS`` among the doubles of a ``leg_env.physics.layout.ROBOT`` row (``row.view(np.float64)``)."""
_BIG = 1.0e6
# accepted values of a drawn field: (low, high, low open)
_VALID = {
    **{name: (PARAM_RANGE[0], PARAM_RANGE[1], False) for name in PARAM_NAMES},
    "g": (0.0, PARAM_RANGE[1], False),
    "mu": (0.0, _BIG, False),
    "hip_torque_limit": (0.0, _BIG, True),
    "knee_torque_limit": (0.0, _BIG, True),
}


@dataclass(frozen=True)
class Randomization:
    """Checked ranges of the randomised fields, in ``FIELDS`` order: ``(field, kind, low, high)`` each.

    Build it with ``Randomization.from_any``; the kinds are those of the module docstring.
    """

    ranges: tuple[tuple[str, str, float, float], ...]

    @classmethod
    def from_any(cls, value) -> "Randomization | None":
        """None / False: no randomisation; True: ``DEFAULT_RANGES``; a dict ``{field: range}``; an instance.

        Raises:
            ValueError: an unknown field, an unknown kind, ``low > high``, or a bound that is NaN or
                infinite (the message names the field).
            ArgumentTypeError: a value of the wrong type (also a ``ValueError``).
        """
        if value is None or value is False:
            return None
        if isinstance(value, cls):
            return value
        if value is True:
            value = DEFAULT_RANGES
        if not isinstance(value, dict):
            raise checks.ArgumentTypeError(
                f"randomize must be None, True, a dict {{field: range}} or a Randomization, got {checks.shown(value)} of type {type(value).__name__}"
            )
        unknown = sorted(set(value) - set(FIELDS), key=str)
        if unknown:
            raise ValueError(f"randomize: unknown field(s) {unknown}; valid: {list(FIELDS)}")
        ranges = []
        for name in FIELDS:
            if name in value:
                ranges.append((name, *_checked_range(name, value[name])))
        return cls(tuple(ranges))

    def spec(self) -> np.ndarray:
        """``(k, 4)`` float64 rows ``(the field's index among a robot's doubles, kind index, low, high)`` for the compiled draw."""
        return np.array([[_COLUMN[n], KINDS.index(k), lo, hi] for n, k, lo, hi in self.ranges], dtype=np.float64).reshape(-1, 4)

    def check_against(self, base: np.ndarray, gravity: bool = False) -> None:
        """``ValueError`` naming the field if a value the ranges can draw around the nominal robot ``base`` (a
        1-row ``ROBOT`` array) is not a valid value of the field (a mass at or below 0, a negative ``mu``, a ``g``
        between 0 and ``G_MIN`` that ``LegParams`` refuses, or with ``gravity`` (a task that needs it) a ``g`` of 0)."""
        doubles = base.view(np.float64)
        for name, kind, lo, hi in self.ranges:
            nominal = float(doubles[_COLUMN[name]])
            ends = (_drawn(kind, nominal, lo), _drawn(kind, nominal, hi))
            v_lo, v_hi, lo_open = _VALID[name]
            for v in ends:
                if not (v > v_lo if lo_open else v >= v_lo) or v > v_hi:
                    raise ValueError(
                        f"randomize[{name!r}] = {(kind, lo, hi)} draws {name} = {v:g} around the nominal {nominal:g}; "
                        f"{name} must be in {'(' if lo_open else '['}{v_lo:g}, {v_hi:g}]"
                    )
            if name == "g" and (min(ends) < G_MIN and (max(ends) > 0.0 or gravity)):
                raise ValueError(
                    f"randomize['g'] = {(kind, lo, hi)} draws g in [{min(ends):g}, {max(ends):g}] around the nominal {nominal:g}; "
                    f"g must be {'' if gravity else '0 or '}at least {G_MIN:g} m/s^2{' (this task needs gravity)' if gravity else ''}"
                )


def _drawn(kind: str, nominal: float, x: float) -> float:
    """The value a range of ``kind`` gives for the uniform number ``x`` (an end of the range)."""
    return nominal * x if kind == "scale" else (nominal + x if kind == "offset" else x)


def _checked_range(name: str, value) -> tuple[str, float, float]:
    where = f"randomize[{name!r}]"
    if isinstance(value, (tuple, list)) and len(value) == 2:
        value = ("range", *value)
    if not (isinstance(value, (tuple, list)) and len(value) == 3 and isinstance(value[0], str)):
        raise checks.ArgumentTypeError(
            f"{where} must be (kind, low, high) with kind one of {list(KINDS)}, or (low, high), got {checks.shown(value)}"
        )
    kind = value[0]
    if kind not in KINDS:
        raise ValueError(f"{where}: unknown kind {kind!r}; valid: {list(KINDS)}")
    lo = checks.real(f"{where} low", value[1], -_BIG, _BIG)
    hi = checks.real(f"{where} high", value[2], -_BIG, _BIG)
    if lo > hi:
        raise ValueError(f"{where}: low {lo:g} is above high {hi:g}")
    return kind, lo, hi


def robot_params(u: np.ndarray, spec: np.ndarray, base: np.ndarray, limits: np.ndarray, row: np.ndarray) -> bool:
    """Build a drawn robot in ``row`` from the ``(k,)`` uniforms ``u``; return whether it is accepted.

    ``spec`` is ``Randomization.spec()``; ``base`` the nominal robot and ``row`` the drawn one, 1-row arrays of
    ``leg_env.physics.layout.ROBOT``; ``limits`` ``(hip_lo, hip_hi, knee_lo, knee_hi, min_base_height, nominal_knee,
    unilateral)`` (``posture_limits``). The drawn fields are written, then the nominal posture, holding
    torques and COM of the drawn parameters (``leg_env.physics.dynamics.static_equilibrium``), then the
    rejection rule of the module docstring is applied (in the compiled core, ``leg_env/_core/draws.c``).
    """
    return kernels.robot_params(u, spec, base, limits, row)


def draw_robot(rng: np.random.Generator, spec: np.ndarray, base: np.ndarray, limits: np.ndarray, row: np.ndarray) -> int:
    """One sub-env's robot into ``row`` from ``rng`` (``draw_robots`` in Python, for one generator);
    returns the number of refused tries."""
    u = np.empty(spec.shape[0])
    for t in range(MAX_DRAWS):
        rng.random(out=u)
        if robot_params(u, spec, base, limits, row):
            return t
    row[0] = base[0]
    return MAX_DRAWS


def posture_limits(config) -> np.ndarray:
    """The ``limits`` argument of ``robot_params`` for a task ``config``."""
    return np.array([*config.hip_range, *config.knee_range, config.min_base_height, config.nominal_knee,
                     float(config.contact == "unilateral")], dtype=np.float64)  # fmt: skip


def acceptance(randomization: Randomization, base: np.ndarray, limits: np.ndarray, draws: int = CHECK_DRAWS, seed: int = 0) -> float:
    """The fraction of ``draws`` robots (from ``seed``) that the rejection rule accepts."""
    rng = np.random.default_rng(seed)
    spec, row = randomization.spec(), np.empty_like(base)
    u = rng.random((draws, spec.shape[0]))
    return float(np.mean([robot_params(u[k], spec, base, limits, row) for k in range(draws)]))


class Robots:
    """The robots of an env's sub-envs: the nominal one, the ranges, and how a reset sets each robot's row.

    Shared by the single and the vector env, so that a sub-env and a single env draw the same robot from
    the same generator. ``base`` is the nominal robot, a 1-row array of ``leg_env.physics.layout.ROBOT``.
    """

    def __init__(self, randomize, base: np.ndarray, config, gravity: bool = False):
        self.randomization = Randomization.from_any(randomize)
        self.gravity = gravity  # the task refuses g = 0
        self.base = np.array(base, dtype=layout.ROBOT).reshape(1)
        self.base.setflags(write=False)
        self.limits = posture_limits(config)
        self.spec = np.zeros((0, 4)) if self.randomization is None else self.randomization.spec()
        if self.randomization is not None:
            self.randomization.check_against(self.base, gravity)
            rate = acceptance(self.randomization, self.base, self.limits)
            if rate < MIN_ACCEPTANCE:
                raise ValueError(
                    f"randomize: only {rate:.1%} of {CHECK_DRAWS} drawn robots can hold their nominal posture "
                    f"(at least {MIN_ACCEPTANCE:.0%} needed; see leg_env.randomize's rejection rule); narrow the ranges "
                    f"{dict((n, (k, lo, hi)) for n, k, lo, hi in self.randomization.ranges)}"
                )

    def longest(self, params):
        """``params`` with each link length at the longest the ranges can draw (for the observation bounds)."""
        from dataclasses import replace

        longer = {}
        for name, kind, lo, hi in () if self.randomization is None else self.randomization.ranges:
            if name in ("l1", "l2"):
                longer[name] = max(getattr(params, name), _drawn(kind, getattr(params, name), hi))
        return replace(params, **longer) if longer else params

    @property
    def active(self) -> bool:
        """Whether resets draw robots."""
        return self.randomization is not None

    def draw_one(self, rng: np.random.Generator, row: np.ndarray) -> int:
        """Draw one sub-env's robot into ``row`` (a 1-row ``ROBOT`` array); the number of refused tries."""
        return draw_robot(rng, self.spec, self.base, self.limits, row)

    def draw_rows(self, rngs, rows: np.ndarray, robots: np.ndarray) -> np.ndarray:
        """Draw the robots of sub-envs ``rows`` into their rows of ``robots`` (``(num_envs,)`` ``ROBOT``) from ``rngs``
        (``leg_env.envs.generators.BitGeneratorRows``); the refused tries of each."""
        rejected = np.zeros(rows.size, dtype=np.int64)
        kernels.draw_robots(rngs.bit_generators, np.ascontiguousarray(rows, dtype=np.int64), self.spec, self.base, self.limits, MAX_DRAWS,
                            robots, rejected)
        return rejected

    def explicit_rows(self, params, k: int | None = None) -> np.ndarray:
        """The robots of the ``reset(options={"params": ...})``: a ``(1 or k,)`` ``ROBOT`` array.

        ``params`` maps fields of ``FIELDS`` to values (with ``k``: a number for every sub-env, or one
        per sub-env, shape ``(k,)``); fields left out keep their nominal values. Raises ``ValueError``
        naming the field for an unknown field or a bad value, and for a robot the rejection rule
        refuses (explicit robots are never redrawn).
        """
        if not isinstance(params, dict):
            raise checks.ArgumentTypeError(f"reset option 'params' must be a dict {{field: value}}, got {checks.shown(params)}")
        unknown = sorted(set(params) - set(FIELDS), key=str)
        if unknown:
            raise ValueError(f"reset option 'params': unknown field(s) {unknown}; valid: {list(FIELDS)}")
        n = 1 if k is None else k
        shapes = ((),) if k is None else ((), (k,))
        names = [name for name in FIELDS if name in params]
        values = np.empty((n, len(names)))
        for j, name in enumerate(names):
            lo, hi, lo_open = _VALID[name]
            v = checks.number_array(f"reset option 'params'[{name!r}]", params[name], _BIG * 10, shapes)
            v = np.broadcast_to(v, (n,))
            bad = ~((v > lo) if lo_open else (v >= lo)) | (v > hi)
            if name == "g":
                bad |= ((v > 0.0) | self.gravity) & (v < PARAM_RANGE[0])
            if bad.any():
                where = f"[{PARAM_RANGE[0]:g}, {hi:g}]" if name == "g" and self.gravity else (
                    f"0 or [{PARAM_RANGE[0]:g}, {hi:g}]" if name == "g" else f"{'(' if lo_open else '['}{lo:g}, {hi:g}]")
                raise ValueError(f"reset option 'params'[{name!r}] must be in {where}, got {float(v[bad][0])!r}")
            values[:, j] = v
        spec = np.array([[_COLUMN[name], KINDS.index("range"), 0.0, 0.0] for name in names], dtype=np.float64).reshape(-1, 4)
        out = np.empty(n, dtype=layout.ROBOT)
        u = np.zeros(len(names))
        for r in range(n):
            spec[:, 2] = values[r]
            spec[:, 3] = values[r]
            if not robot_params(u, spec, self.base, self.limits, out[r:r + 1]):
                where = "" if k is None else f" (sub-env {r})"
                raise ValueError(
                    f"reset option 'params' gives a robot{where} that cannot run its nominal posture: a holding torque "
                    f"{out['tau_nom'][r].round(3).tolist()} N m above its limit, the posture outside the task's limits, "
                    "or (unilateral ground) mu at or past the Painleve bound there (leg_env.randomize)"
                )
        return out


def params_of_row(row) -> dict:
    """``info["params"]`` of one robot (a row of ``leg_env.physics.layout.ROBOT``): field name to float."""
    return dict(zip(FIELDS, np.asarray(row).reshape(1).view(np.float64)[FIELD_COLUMNS].tolist()))
