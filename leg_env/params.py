"""Physical parameters of the planar floating-base leg (lesson section 1).

Units are SI throughout. ``LegParams`` is frozen: derived quantities are
properties, never defaults computed from other defaults.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from functools import cached_property

import numpy as np

__all__ = ["LegParams", "PARAM_NAMES"]


@dataclass(frozen=True)
class LegParams:
    """Masses, inertias, lengths and gravity of the torso + thigh + shank model.

    The hip sits at the torso's centre of mass; ``c1`` and ``c2`` are the
    distances from the hip to the thigh's COM and from the knee to the shank's COM.

    Raises:
        ValueError: a field is not a finite number, a mass, inertia or length is
            not positive, or ``g`` is negative. The message names the field.
    """

    m_b: float = 10.0  # torso mass [kg]
    m1: float = 3.0  # thigh mass [kg]
    m2: float = 2.0  # shank mass [kg]
    I_b: float = 1.0  # torso rotational inertia about its COM [kg m^2]
    I1: float = 0.2  # thigh rotational inertia about its COM [kg m^2]
    I2: float = 0.1  # shank rotational inertia about its COM [kg m^2]
    l1: float = 0.5  # thigh length, hip to knee [m]
    l2: float = 0.5  # shank length, knee to foot [m]
    c1: float = 0.25  # hip to thigh COM [m]
    c2: float = 0.25  # knee to shank COM [m]
    g: float = 9.81  # gravitational acceleration, acting along -y [m/s^2]

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
                raise ValueError(f"LegParams.{f.name} must be a real number, got {value!r}")
            value = float(value)
            if not math.isfinite(value):
                raise ValueError(f"LegParams.{f.name} must be finite, got {value!r}")
            if f.name == "g":
                if value < 0.0:
                    raise ValueError(f"LegParams.g must be >= 0 (gravity acts along -y), got {value!r}")
            elif value <= 0.0:
                raise ValueError(f"LegParams.{f.name} must be > 0, got {value!r}")
            object.__setattr__(self, f.name, value)

    @classmethod
    def from_any(cls, params: "LegParams | dict | None") -> "LegParams":
        """Return ``params`` as ``LegParams``: an instance, a dict of fields, or None for defaults."""
        if params is None:
            return cls()
        if isinstance(params, cls):
            return params
        if isinstance(params, dict):
            unknown = set(params) - set(PARAM_NAMES)
            if unknown:
                raise ValueError(f"unknown LegParams field(s): {sorted(unknown)}; valid: {list(PARAM_NAMES)}")
            return cls(**params)
        raise ValueError(f"params must be LegParams, a dict or None, got {type(params).__name__}")

    @property
    def total_mass(self) -> float:
        """m_b + m1 + m2 [kg]."""
        return self.m_b + self.m1 + self.m2

    @property
    def weight(self) -> float:
        """Total weight (m_b + m1 + m2) g [N]."""
        return self.total_mass * self.g

    @cached_property
    def array(self) -> np.ndarray:
        """The fields as a read-only float64 array, in ``PARAM_NAMES`` order (for the JIT kernels)."""
        a = np.array([getattr(self, n) for n in PARAM_NAMES], dtype=np.float64)
        a.setflags(write=False)
        return a

    def __getstate__(self) -> dict:
        return {n: getattr(self, n) for n in PARAM_NAMES}

    def __setstate__(self, state: dict) -> None:
        for n in PARAM_NAMES:
            object.__setattr__(self, n, state[n])


PARAM_NAMES: tuple[str, ...] = tuple(f.name for f in fields(LegParams))
