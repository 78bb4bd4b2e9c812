"""The numpy dtypes of the compiled core's structs (``leg_env/_core/robot.h``), each declared once.

``PARAMS`` mirrors ``leg_params`` (the fields of ``LegParams``, in order) and ``RECORD`` mirrors
``leg_record`` (what one hybrid control step did). At import every dtype is checked against the
layout the compiled module reports (field names, offsets, sizes and the item size), so that a change
on one side without the other fails at once, never as a silently wrong number.
"""

from __future__ import annotations

import numpy as np

from ._core import kernels

__all__ = ["PARAMS", "RECORD", "LOG_SIZE", "check"]

LOG_SIZE = kernels.LOG_SIZE
"""Located events one control step can log (``2 * MAX_EVENTS``)."""

PARAMS = np.dtype(
    [(name, np.float64) for name in ("m_b", "m1", "m2", "I_b", "I1", "I2", "l1", "l2", "c1", "c2", "g")], align=True
)
"""``leg_params``: masses [kg], inertias [kg m^2], lengths [m] and gravity [m/s^2] of one robot."""

RECORD = np.dtype(
    [
        ("impulse", np.float64, (2,)),  # integral of the contact force over the continuous modes [N s]
        ("kick", np.float64, (2,)),  # sum of impact (and tangential) impulses [N s]
        ("stick_time", np.float64),  # [s]
        ("slip_time", np.float64),  # [s]
        ("flight_time", np.float64),  # [s]
        ("slip_distance", np.float64),  # [m]
        ("work", np.float64),  # actuator work [J]
        ("work_load", np.float64),  # work of the horizontal force on the torso's COM [J]
        ("slip_dissipation", np.float64),  # [J]
        ("impact_dissipation", np.float64),  # [J]
        ("events", np.int32),  # located transitions
        ("painleve", np.int32),  # uses of the Painleve rule
        ("settles", np.int32),  # Zeno settles
        ("event_kind", np.int32, (LOG_SIZE,)),  # LIFTOFF, SLIP_ONSET, SLIDING_STOP, TOUCHDOWN; -1 after the last
        ("event_time", np.float64, (LOG_SIZE,)),  # since the step's start [s]; NaN after the last
    ],
    align=True,
)
"""``leg_record``: what one hybrid control step did (``leg_env.hybrid.HybridStep``)."""


def check(name: str, dtype: np.dtype) -> None:
    """Raise ``ImportError`` unless ``dtype`` has exactly the layout of the C struct ``name``."""
    itemsize, fields = kernels.layouts()[name]
    ours = [(field, dtype.fields[field][1], dtype.fields[field][0].itemsize) for field in dtype.names]
    if itemsize != dtype.itemsize or ours != [tuple(f) for f in fields]:
        raise ImportError(
            f"leg_env.layout: the numpy dtype of {name} does not match the compiled core "
            f"(C: {itemsize} bytes, {fields}; numpy: {dtype.itemsize} bytes, {ours}); rebuild the package"
        )


for _name, _dtype in (("leg_params", PARAMS), ("leg_record", RECORD)):
    check(_name, _dtype)
