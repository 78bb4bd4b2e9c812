"""``info``: the one builder of every environment's ``info``, for one robot and for a batch.

Every key is listed once, in ``KEYS``, with the field of the compiled core's ``out`` (or ``state``) it comes
from; ``InfoBuilder`` reads them for one row (the single env's ``info`` dict) or for every row (the vector
env's ``info`` arrays, which the SB3 adapter splits into its per-env dicts). Keys, in order:

* every task: ``contact_force`` (the mean contact force over the step, ``[lam_x, lam_y]`` [N]),
  ``normal_force`` [N], ``unilateral_violation``, ``friction_violation``, ``numerical_failure`` (bools),
  ``base_drift``, ``foot_error`` [m], ``com_position`` and ``com_velocity`` (the whole-body centre of mass and
  its velocity, world frame [m, m/s]);
* on the unilateral ground (``UNILATERAL``): ``contact_mode`` (``"stick"``, ``"slip"`` or ``"flight"`` at the
  end of the step), ``foot_height`` [m], ``impulse`` (the sum of impact impulses on the foot in the step
  [N s]), ``stick_time``, ``slip_time``, ``flight_time`` [s] (they sum to ``dt``), ``slip_distance`` [m],
  ``work_actuators``, ``dissipation_slip``, ``dissipation_impacts`` [J] (``energy(t) - energy(0)`` is the sum
  over the steps of the first minus the other two), ``energy`` (kinetic + potential [J]),
  ``contact_events``, ``painleve_fallbacks``, ``zeno_settles`` (ints, what ``leg_env.hybrid`` counts);
* the task's own: its ``Task.info_names`` (push: ``push_force``, ``work_push``) and ``Task.state_info``
  (hop: ``command``);
* after a step, not a reset: the reward terms ``reward_<name>`` (they sum to the reward).
"""

from __future__ import annotations

from operator import itemgetter

import numpy as np

from .contact import MODE_NAMES

__all__ = ["KEYS", "UNILATERAL", "InfoBuilder"]

KEYS = (
    # key, out field
    ("contact_force", "lam"),
    ("normal_force", "normal_force"),
    ("unilateral_violation", "unilateral_violation"),
    ("friction_violation", "friction_violation"),
    ("numerical_failure", "numerical_failure"),
    ("base_drift", "base_drift"),
    ("foot_error", "foot_error"),
    ("com_position", "com"),
    ("com_velocity", "com_velocity"),
)
"""The keys of every task's ``info`` and the ``out`` field of each."""

UNILATERAL = (
    ("contact_mode", "mode"),
    ("foot_height", "foot_height"),
    ("impulse", "kick"),
    ("stick_time", "stick_time"),
    ("slip_time", "slip_time"),
    ("flight_time", "flight_time"),
    ("slip_distance", "slip_distance"),
    ("work_actuators", "work"),
    ("dissipation_slip", "slip_dissipation"),
    ("dissipation_impacts", "impact_dissipation"),
    ("energy", "energy"),
    ("contact_events", "events"),
    ("painleve_fallbacks", "painleve"),
    ("zeno_settles", "settles"),
)
"""The keys of the unilateral ground's ``info`` and the ``out`` field of each."""

_MODE_NAMES = np.array(MODE_NAMES)


class InfoBuilder:
    """The ``info`` keys of one env (its task and contact model), read from its ``out`` and ``state`` arrays.

    Args:
        task: the env's ``leg_env.tasks.base.Task``.
        unilateral: whether the env's ground is the unilateral one.
    """

    def __init__(self, task, unilateral: bool):
        self.unilateral = unilateral
        pairs = KEYS + (UNILATERAL if unilateral else ()) + tuple((name, name) for name in task.info_names)
        self.out_keys = tuple(key for key, _ in pairs)
        self.out_fields = tuple(field for _, field in pairs)
        self.state_keys = tuple(task.state_info)
        self.reward_keys = task.reward_keys
        self.keys = self.out_keys + self.state_keys
        """Every key of a reset's ``info``; a step's has ``reward_keys`` too."""
        self._task = task

    def reader(self, out: np.ndarray, state: np.ndarray) -> "RowReader":
        """A reader of the ``info`` of robot 0 of ``out`` and ``state`` (the single env's arrays, read at every step)."""
        return RowReader(self, out, state)

    def columns(self, out: np.ndarray, state: np.ndarray | None = None, rewards: bool = False) -> dict:
        """Every key as one fresh array over the rows of ``out`` (and ``state``); with ``rewards`` the reward terms."""
        cols = {}
        for key, field in zip(self.out_keys, self.out_fields):
            if key == "contact_mode":
                cols[key] = np.take(_MODE_NAMES, out[field])
            elif out.dtype.fields[field][0].kind == "i":  # counts: int64, as numpy stacks Python ints
                cols[key] = out[field].astype(np.int64)
            else:
                cols[key] = out[field].copy()
        for key in self.state_keys:
            cols[key] = state[key].copy()
        if rewards:
            terms = out["terms"].T.copy()  # one copy serves every term
            cols.update(zip(self.reward_keys, terms[: len(self.reward_keys)]))
        return cols


class RowReader:
    """The ``info`` dict of robot 0 of an ``out`` and a ``state`` array, read through views made once.

    Every value is read in one ``tolist`` per type (the doubles, the int32 counts and mode, the flags) and one
    copy of the array-valued keys' doubles, so that the single env's ``info`` costs about a microsecond.
    """

    def __init__(self, builder: InfoBuilder, out: np.ndarray, state: np.ndarray):
        dtype = out.dtype
        self._doubles = out[:1].view(np.float64)  # robot 0's row as doubles, int32s and bytes
        self._ints = out[:1].view(np.int32)
        self._bytes = out[:1].view(np.bool_)
        self._state_doubles = state[:1].view(np.float64)
        scalar_doubles, ints, flags, vectors = [], [], [], []
        for key, field in zip(builder.out_keys, builder.out_fields):
            base, offset = dtype.fields[field][0], dtype.fields[field][1]
            if base.shape:
                vectors.append((key, offset // 8))
            elif base.kind == "f":
                scalar_doubles.append((key, offset // 8))
            elif base.kind == "i":
                ints.append((key, offset // 4))
            else:
                flags.append((key, offset))
        # the int32 and the byte fields sit together: read only their span
        first_int = min((i for _, i in ints), default=0)
        first_flag = min((i for _, i in flags), default=0)
        self._ints = self._ints[first_int:max((i for _, i in ints), default=-1) + 1]
        self._bytes = self._bytes[first_flag:max((i for _, i in flags), default=-1) + 1]
        self._double_keys, self._get_doubles = _getter(scalar_doubles)
        self._int_keys, self._get_ints = _getter([(key, i - first_int) for key, i in ints])
        self._flag_keys, self._get_flags = _getter([(key, i - first_flag) for key, i in flags])
        self._vector_keys = tuple(key for key, _ in vectors)
        self._vector_index = np.array([k + j for _, k in vectors for j in (0, 1)], dtype=np.intp)
        terms = dtype.fields["terms"][1] // 8
        self._terms = slice(terms, terms + len(builder.reward_keys))
        self._reward_keys = builder.reward_keys
        self._state_keys = builder.state_keys
        self._state_index = [state.dtype.fields[key][1] // 8 for key in builder.state_keys]
        self._mode = "contact_mode" in self._int_keys

    def __call__(self, rewards: bool = True) -> dict:
        d = self._doubles.tolist()
        info = dict(zip(self._double_keys, self._get_doubles(d)))
        info.update(zip(self._flag_keys, self._get_flags(self._bytes.tolist())))
        if self._int_keys:
            info.update(zip(self._int_keys, self._get_ints(self._ints.tolist())))
            if self._mode:
                info["contact_mode"] = MODE_NAMES[info["contact_mode"]]
        vectors = self._doubles[self._vector_index]  # one copy serves every array-valued key
        for k, key in enumerate(self._vector_keys):
            info[key] = vectors[2 * k:2 * k + 2]
        if self._state_keys:
            s = self._state_doubles.tolist()
            info.update((key, s[i]) for key, i in zip(self._state_keys, self._state_index))
        if rewards:
            info.update(zip(self._reward_keys, d[self._terms]))
        return info


def _getter(pairs: list) -> tuple[tuple, object]:
    """The keys of ``(key, index)`` pairs and a function taking their values from a list (always a tuple)."""
    keys = tuple(key for key, _ in pairs)
    if not pairs:
        return keys, lambda values: ()
    get = itemgetter(*(index for _, index in pairs))
    return keys, (get if len(pairs) > 1 else (lambda values: (get(values),)))
