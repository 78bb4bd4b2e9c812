"""``info``: the one builder of every environment's ``info``, for one robot and for a batch.

Every key is listed once, in ``KEYS``, with the field of the compiled core's ``out`` (or ``state``) it comes
from; ``InfoBuilder`` reads them for one row (the single env's ``info`` dict) or for every row (the vector
env's ``info`` arrays, which the SB3 adapter splits into its per-env dicts). Keys, in order:

* every task: ``contact_force`` (the mean contact force over the step, ``[lam_x, lam_y]`` [N]),
  ``normal_force`` [N], ``unilateral_violation``, ``friction_violation``, ``numerical_failure`` (bools),
  ``ending`` (why the episode ended at this step, an index into ``ENDINGS``: 0, ``"none"``, while it goes on),
  ``base_drift``, ``foot_error`` [m], ``com_position`` and ``com_velocity`` (the whole-body centre of mass and
  its velocity, world frame [m, m/s]), ``torque`` (the hip and knee torques held over the step [N m]: the clipped
  action times the torque limits, or with the motor model what the motors give at the joints' speeds; after a
  reset, the holding torques the reset's contact force is worked out under);
* on the unilateral ground (``UNILATERAL``): ``contact_mode`` (``"stick"``, ``"slip"`` or ``"flight"`` at the
  end of the step), ``foot_height`` [m], ``impulse`` (the sum of impact impulses on the foot in the step
  [N s]), ``stick_time``, ``slip_time``, ``flight_time`` [s] (they sum to ``dt``), ``slip_distance`` [m],
  ``work_actuators``, ``dissipation_slip``, ``dissipation_impacts`` [J] (``energy(t) - energy(0)`` is the sum
  over the steps of the first minus the other two), ``energy`` (kinetic + potential [J]),
  ``contact_events``, ``painleve_fallbacks``, ``zeno_settles`` (ints, what ``leg_env.physics.hybrid`` counts);
* the task's own: its ``Task.info_names`` (push: ``push_force``, ``work_push``) and ``Task.state_info``
  (hop: ``command``);
* after a step, not a reset: the reward terms ``reward_<name>`` (they sum to the reward).
"""

from __future__ import annotations

import numpy as np

from ._core import kernels
from .physics.contact import MODE_NAMES

__all__ = ["KEYS", "UNILATERAL", "ENDINGS", "InfoBuilder", "RowReader"]

ENDINGS: tuple[str, ...] = kernels.ENDINGS
"""Why an episode ends, by ``info["ending"]``: ``"none"`` (0: it goes on, or it was truncated), then, the first
that holds at the step: ``"torso_angle"`` (the torso tilted past ``max_torso_angle``), ``"base_height"`` (the base
came within ``min_base_height`` of the foot's contact point), ``"hip_low"``, ``"hip_high"``, ``"knee_low"``,
``"knee_high"`` (the hip or the knee left ``hip_range`` or ``knee_range``, below or above; the knee above is bent
past it), ``"base_below_knee"``, ``"contact_lost"`` (``terminate_on_contact_loss``: the foot lifted, or its normal
force fell below ``contact_loss_threshold``) and ``"numerical_failure"`` (the step failed and was undone). An episode
is terminated exactly when its ``ending`` is not 0."""

KEYS = (
    # key, out field
    ("contact_force", "lam"),
    ("normal_force", "normal_force"),
    ("unilateral_violation", "unilateral_violation"),
    ("friction_violation", "friction_violation"),
    ("numerical_failure", "numerical_failure"),
    ("ending", "ending"),
    ("base_drift", "base_drift"),
    ("foot_error", "foot_error"),
    ("com_position", "com"),
    ("com_velocity", "com_velocity"),
    ("torque", "torque"),
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
_KIND = {"d": kernels.INFO_DOUBLE, "i": kernels.INFO_INT, "?": kernels.INFO_FLAG, "v": kernels.INFO_VECTOR, "m": kernels.INFO_MODE}
"""The compiled passes' code of each kind of value: a double, an int32 (given as int64), a byte flag (bool), two
doubles, a contact mode (an int32 given as its name)."""


def _kind(key: str, base: np.dtype) -> str:
    return "m" if key == "contact_mode" else ("v" if base.shape else {"f": "d", "i": "i", "b": "?"}[base.kind])


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
        self._mode_keys = tuple(key for key in self.out_keys if key == "contact_mode")

    def entries(self, out_dtype: np.dtype, state_dtype: np.dtype, rewards: bool) -> list:
        """``(key, source, byte offset, kind)`` of every key: source 0 ``out``, 1 ``state``; kind ``d``, ``i``, ``?``, ``v``
        or ``m`` (``_KIND``)."""
        entries = [(key, 0, out_dtype.fields[field][1], _kind(key, out_dtype.fields[field][0]))
                   for key, field in zip(self.out_keys, self.out_fields)]  # fmt: skip
        entries += [(key, 1, state_dtype.fields[key][1], "d") for key in self.state_keys]
        if rewards:
            terms = out_dtype.fields["terms"][1]
            entries += [(key, 0, terms + 8 * k, "d") for k, key in enumerate(self.reward_keys)]
        return entries

    def reader(self, batch, out: np.ndarray, state: np.ndarray) -> "RowReader":
        """A reader of the ``info`` of robot 0 of the arrays ``out`` and ``state`` that ``batch`` (their
        ``kernels.Batch``) holds: the single env's, read at every step."""
        return RowReader(self, batch, out, state)

    def columns(self, out: np.ndarray, state: np.ndarray, rewards: bool = False) -> dict:
        """Every key as one fresh array over the rows of ``out`` and ``state``; with ``rewards`` the reward terms.

        One compiled pass (``kernels.info_columns``) fills a block per type (doubles, int64 counts, bools, ``(N, 2)``
        vectors); each key's array is its row of a block (fresh, and no two share memory); a contact mode is its
        name."""
        spec, counts, keys = self._column_spec(out.dtype, state.dtype, rewards)
        n = out.shape[0]
        doubles, ints = np.empty((counts["d"], n)), np.empty((counts["i"], n), dtype=np.int64)
        flags, vectors = np.empty((counts["?"], n), dtype=np.bool_), np.empty((counts["v"], n, 2))
        named = kernels.info_columns(spec, out, state, doubles, ints, flags, vectors)
        blocks = {"d": doubles, "i": ints, "m": ints, "?": flags, "v": vectors}
        columns = {key: blocks[kind][row] for key, kind, row in keys}
        for key in self._mode_keys:
            modes = columns[key]
            if not named:
                raise ValueError(f"info: a contact mode outside 0 .. {len(MODE_NAMES) - 1} in out: {modes[(modes < 0) | (modes >= len(MODE_NAMES))][:3]}")
            columns[key] = _MODE_NAMES[modes]
        return columns

    def _column_spec(self, out_dtype: np.dtype, state_dtype: np.dtype, rewards: bool):
        """``info_columns``' spec, the blocks' sizes and the keys' places, for arrays of these dtypes (made once)."""
        cache = self.__dict__.setdefault("_specs", {})
        if rewards not in cache:
            counts, spec, keys = {"d": 0, "i": 0, "?": 0, "v": 0}, [], []
            for key, source, offset, kind in self.entries(out_dtype, state_dtype, rewards):
                block = "i" if kind == "m" else kind
                spec.append((source, offset, _KIND[kind], counts[block]))
                keys.append((key, kind, counts[block]))
                counts[block] += 1
            cache[rewards] = (np.array(spec, dtype=np.int64).reshape(-1, 4), counts, keys)
        return cache[rewards]


class RowReader:
    """The ``info`` dict of robot 0 of an env's arrays, read by its ``kernels.Batch`` in one call.

    The keys and where each comes from (``out`` or ``state``, its byte offset and kind) are worked out once,
    from the dtypes; every call makes the values, the array-valued ones as slices of one fresh array.
    """

    def __init__(self, builder: InfoBuilder, batch, out: np.ndarray, state: np.ndarray):
        self._batch = batch
        entries = builder.entries(out.dtype, state.dtype, rewards=True)
        spec = np.array([(source, offset, _KIND[kind], 0) for _, source, offset, kind in entries], dtype=np.int64).reshape(-1, 4)
        plain = len(entries) - len(builder.reward_keys)
        batch.bind_info(tuple(key for key, *_ in entries), spec, plain, MODE_NAMES)  # parsed once, read at every call
        self._vectors = 2 * sum(kind == "v" for *_, kind in entries[:plain])

    def __call__(self, rewards: bool = True) -> dict:
        return self._batch.info(rewards, np.empty(self._vectors))
