"""Physical parameters of the planar floating-base leg (lesson section 1).

Units are SI throughout. ``LegParams`` is frozen: derived quantities are
properties, never defaults computed from other defaults.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from functools import cached_property

import numpy as np

from .. import checks

__all__ = ["LegParams", "PARAM_NAMES", "PARAM_RANGE", "G_MIN"]

PARAM_RANGE = (1.0e-6, 1.0e6)
"""Accepted range of every mass [kg], inertia [kg m^2] and length [m], and of a non-zero ``g`` [m/s^2].

Wide enough for any robot, narrow enough that no product in the dynamics overflows or underflows
and that the contact force over the weight, ``lam / (m g)``, fits the float32 observation."""
G_MIN = PARAM_RANGE[0]
"""The least non-zero gravity [m/s^2]. ``g = 0`` is accepted (no gravity); a ``g`` between 0 and this
would make ``lam / (m g)`` overflow the float32 observation (``g = 1e-300``)."""


@dataclass(frozen=True)
class LegParams:
    """Masses, inertias, lengths and gravity of the torso + thigh + shank model.

    The hip sits at the torso's centre of mass; ``c1`` and ``c2`` are the
    distances from the hip to the thigh's COM and from the knee to the shank's COM. ``g = 0`` is
    allowed; the task's observation then gives the contact force in newtons instead of in units of
    the weight ``m g`` (there is no weight to divide by).

    Raises:
        ValueError: a field is NaN, too large for a float, or out of range: every mass, inertia
            and length must be in ``PARAM_RANGE`` = [1e-6, 1e6] (SI units), and ``g`` must be 0 or in
            that range. The message names the field and the range.
        ArgumentTypeError: a field is not a real number (a string, a bool, a complex number);
            it is also a ``ValueError``.
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
    g: float = 9.81  # gravitational acceleration, acting along -y [m/s^2]; 0: no gravity (observed forces in N)

    def __post_init__(self) -> None:
        lo, hi = PARAM_RANGE
        for f in fields(self):
            name, value = f"LegParams.{f.name}", getattr(self, f.name)
            if f.name == "g":
                value = checks.real(name, value, 0.0, hi, unit="m/s^2")
                if 0.0 < value < G_MIN:
                    raise ValueError(f"{name} must be 0 or in [{G_MIN:g}, {hi:g}] m/s^2, got {value!r}")
            else:
                value = checks.real(name, value, lo, hi)
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
        raise checks.ArgumentTypeError(f"params must be LegParams, a dict or None, got {checks.shown(params)} of type {type(params).__name__}")

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

    @cached_property
    def _unloaded(self) -> np.ndarray:
        """``array`` then a zero load: ``leg_env.physics.dynamics.params_array(self)``, made once (no kernel writes it)."""
        return np.append(self.array, 0.0)

    def __getstate__(self) -> dict:
        return {n: getattr(self, n) for n in PARAM_NAMES}

    def __setstate__(self, state: dict) -> None:
        for n in PARAM_NAMES:
            object.__setattr__(self, n, state[n])


PARAM_NAMES: tuple[str, ...] = tuple(f.name for f in fields(LegParams))
