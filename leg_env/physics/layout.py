"""The numpy dtypes of the compiled core's structs, built from the structs themselves.

Each layout is declared once, in C (``leg_env/_core/robot.h`` and ``env.h``, one list of fields per struct): the
compiled module reports every struct's fields (name, byte offset, type, length, what it holds) and the item size,
and this module builds the numpy structured dtypes from that report. A batch of robots is then one structured array per struct,
and every field has its name: ``state["qd"]`` is ``(N, 5)``, ``out["terminated"]`` is ``(N,)`` bool.

* ``PARAMS`` (``leg_params``): a robot's masses, inertias, lengths and gravity (``LegParams``' fields).
* ``RECORD`` (``leg_record``): what one hybrid control step did (``leg_env.physics.hybrid.HybridStep``).
* ``ROBOT`` (``env_robot``): a robot of an env (its parameters ``p``, ``mu``, ``torque_limit`` and its
  nominal posture, holding torques and COM); a randomised batch has one per sub-env.
* ``state_dtype(task)``, ``settings_dtype(task)``, ``out_dtype(task)``: a robot's state, a task's settings
  and what a control step gives, each with the task's own fields (``env_state``, ``env_settings``,
  ``env_out`` and their unions).
* ``OBS``: the observation's columns by name (``obs_index``), and the width of each kind of observation.
"""

from __future__ import annotations

import numpy as np

from .._core import kernels

__all__ = ["PARAMS", "RECORD", "ROBOT", "OBS", "LOG_SIZE", "MAX_TERMS", "FLAG_NAMES", "FIELD_DOCS", "state_dtype", "settings_dtype", "out_dtype",
           "take_rows", "put_rows"]

LOG_SIZE = kernels.LOG_SIZE
"""Located events one control step can log (``2 * MAX_EVENTS``)."""
MAX_TERMS = kernels.MAX_TERMS
"""Reward terms a task has at most (the length of ``out["terms"]``)."""
FLAG_NAMES = ("terminated", "unilateral_violation", "friction_violation", "numerical_failure")
"""The flags of ``out`` (bool fields), in this order wherever they are listed."""

_LAYOUTS = kernels.layouts()
FIELD_DOCS: dict[str, dict[str, str]] = {struct: {name: doc for name, _, _, _, doc in fields} for struct, (_, fields) in _LAYOUTS.items()}
"""What each field of each struct holds, with its unit (``FIELD_DOCS["env_state"]["qd"]``, a task's own fields under
``"env_state.hop"`` and the like), written once in C beside the field (``leg_env/_core/robot.h``, ``env.h``)."""
_TASKS = ("stance", "push", "hop")


def _dtype(struct: str, task: str | None = None) -> np.dtype:
    """The dtype of C struct ``struct``, with the fields of ``task`` in its union where it has them."""
    itemsize, fields = _LAYOUTS[struct]
    extra = _LAYOUTS.get(f"{struct}.{task}", (itemsize, []))[1] if task else []
    names, formats, offsets = [], [], []
    for name, offset, kind, count, _ in list(fields) + list(extra):
        base = _DTYPES[kind] if kind in _DTYPES else np.dtype(kind)
        names.append(name)
        formats.append(base if count == 1 else (base, (count,)))
        offsets.append(offset)
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": itemsize})


_DTYPES: dict[str, np.dtype] = {}
PARAMS = _dtype("leg_params")
_DTYPES["leg_params"] = PARAMS
RECORD = _dtype("leg_record")
ROBOT = _dtype("env_robot")


def _check_task(task: str) -> str:
    if task not in _TASKS:
        raise ValueError(f"task must be one of {list(_TASKS)}, got {task!r}")
    return task


def state_dtype(task: str) -> np.dtype:
    """One robot's state (``env_state``) with ``task``'s own fields (push: its schedule; hop: its command)."""
    return _dtype("env_state", _check_task(task))


def settings_dtype(task: str) -> np.dtype:
    """A task's settings (``env_settings``) with ``task``'s own weights."""
    return _dtype("env_settings", _check_task(task))


def out_dtype(task: str) -> np.dtype:
    """What one control step of a robot gives (``env_out``) with ``task``'s own info (push: the force and its work)."""
    return _dtype("env_out", _check_task(task))


OBS = dict(kernels.observation())
"""The observation's columns by name (``base_x`` .. ``impulse_y``, the hop's ``command``, ``com_drift``,
``ground_time`` and ``last_apex``, the push task's ``push_com_drift``), and its widths (``pinned_dim``,
``unilateral_dim``, ``hop_dim``, ``push_dim``)."""


def _bytes(records: np.ndarray) -> np.ndarray:
    """A C-contiguous 1-d record array as a ``(len, itemsize)`` byte array (a view)."""
    return records.view(np.uint8).reshape(records.shape[0], records.dtype.itemsize)


def take_rows(records: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``records[rows]`` for a contiguous 1-d record array, gathered as bytes (numpy's structured fancy
    indexing copies field by field, several times slower)."""
    return _bytes(records)[rows].view(records.dtype).reshape(len(rows))


def put_rows(records: np.ndarray, rows: np.ndarray, values: np.ndarray) -> None:
    """``records[rows] = values`` for contiguous 1-d record arrays of one dtype, scattered as bytes."""
    if values.dtype != records.dtype:
        raise TypeError(f"put_rows: values of dtype {values.dtype} into records of dtype {records.dtype}")
    _bytes(records)[rows] = _bytes(np.ascontiguousarray(values))
