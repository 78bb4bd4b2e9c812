"""One validation path for every argument that crosses into leg-env.

Parameters (``LegParams``), task settings (``StanceConfig``), constructor keywords, reset seeds and
options, and actions all go through these functions, so a bad value is refused the same way
wherever it enters, with a message that names it and says what is accepted:

* a value of the wrong type (a string, a complex number, ``True`` for a number, ``config=5``) raises
  ``ArgumentTypeError``, which is both a ``TypeError`` and a ``ValueError``;
* a number out of its documented range, NaN, or too large for a float (``10**400``) raises ``ValueError``.

``bool`` is never a number here, and nothing is coerced from a string.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence

import numpy as np

__all__ = ["ArgumentTypeError", "is_real", "real", "integer", "pair", "boolean", "seed", "real_array", "number_array", "shown"]


class ArgumentTypeError(TypeError, ValueError):
    """An argument of the wrong type.

    A ``TypeError``, and also a ``ValueError`` so that code catching the ``ValueError`` of a bad value
    (leg-env's documented error for a bad argument) catches this one too; numpy's ``AxisError`` is
    built the same way.
    """


def shown(value, limit: int = 60) -> str:
    """``repr(value)``, shortened to about ``limit`` characters (``10**400`` has 401 digits)."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit // 2]}...{text[-10:]} ({len(text)} characters)"


def _interval(lo: float, hi: float, lo_open: bool, hi_open: bool) -> str:
    return f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def is_real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def real(name: str, value, lo: float = -math.inf, hi: float = math.inf, *, lo_open: bool = False, hi_open: bool = False,
         unit: str = "") -> float:  # fmt: skip
    """``value`` as a float in the interval from ``lo`` to ``hi`` (closed unless ``lo_open`` / ``hi_open``).

    Raises:
        ArgumentTypeError: ``value`` is not a real number (a bool, a string, a complex number...).
        ValueError: NaN, too large for a float, or outside the interval. The message names ``name``.
    """
    where = _interval(lo, hi, lo_open, hi_open) + (f" {unit}" if unit else "")
    if not is_real(value):
        raise ArgumentTypeError(f"{name} must be a real number in {where}, got {shown(value)} of type {type(value).__name__}")
    try:
        x = float(value)
    except OverflowError:
        raise ValueError(f"{name} must be a real number in {where}, got {shown(value)}: too large for a float") from None
    if math.isnan(x) or x < lo or x > hi or (lo_open and x == lo) or (hi_open and x == hi):
        raise ValueError(f"{name} must be in {where}, got {shown(value)}")
    return x


def integer(name: str, value, lo: int, hi: int, *, floats: bool = False) -> int:
    """``value`` as an int in ``[lo, hi]``; with ``floats``, an integral float (``2.0``) is accepted too.

    Raises:
        ArgumentTypeError: not an integer (not a real number, or a float without ``floats``).
        ValueError: NaN, not integral, or outside ``[lo, hi]``; the message names ``name`` and the bounds.
    """
    if not floats and not (isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))):
        raise ArgumentTypeError(f"{name} must be an integer in [{lo}, {hi}], got {shown(value)} of type {type(value).__name__}")
    x = real(name, value, lo, hi)
    if x != int(x):
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {shown(value)}")
    return int(value) if isinstance(value, (int, np.integer)) else int(x)


def pair(name: str, value, lo: float = -math.inf, hi: float = math.inf, *, lo_open: bool = False, unit: str = "") -> tuple[float, float]:
    """``value`` as a pair of floats, each checked by ``real`` as ``name[0]`` / ``name[1]``."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)):
        raise ArgumentTypeError(f"{name} must be a pair of real numbers, got {shown(value)} of type {type(value).__name__}")
    if len(value) != 2:
        raise ValueError(f"{name} must be a pair of real numbers, got {len(value)} of them: {shown(value)}")
    return tuple(real(f"{name}[{k}]", v, lo, hi, lo_open=lo_open, unit=unit) for k, v in enumerate(value))


def boolean(name: str, value) -> bool:
    """``value`` as a bool; only ``True``, ``False`` and numpy bools are accepted."""
    if not isinstance(value, (bool, np.bool_)):
        raise ArgumentTypeError(f"{name} must be True or False, got {shown(value)} of type {type(value).__name__}")
    return bool(value)


def seed(name: str, value) -> int | None:
    """A random seed: ``None`` or a non-negative integer (a Python or numpy int, not a bool or a float)."""
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ArgumentTypeError(f"{name} must be a non-negative integer or None, got {shown(value)} of type {type(value).__name__}")
    if value < 0:
        raise ValueError(f"{name} must be a non-negative integer or None, got {value!r}")
    return int(value)


def real_array(name: str, value, what: str) -> np.ndarray:
    """``value`` as a float64 array, refusing what is not real numbers (``what`` describes the expected value).

    numpy would convert strings (``"0.5"``), drop imaginary parts and take bools as 0 and 1: these,
    and ragged nestings, raise ``ArgumentTypeError`` (also a ``ValueError``) naming ``name``.
    """
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError) as e:  # ragged nesting
        raise ArgumentTypeError(f"{name} must be {what}, got {shown(value)}") from e
    if raw.dtype.kind == "O" and all(is_real(v) for v in raw.flat):  # an object array of numbers
        raw = raw.astype(np.float64)
    if raw.dtype.kind not in "fiu" or (isinstance(value, (list, tuple)) and _holds_a_bool(value)):
        raise ArgumentTypeError(f"{name} must be {what}, got {shown(value)} (dtype {raw.dtype})")
    return raw.astype(np.float64)


def _holds_a_bool(value) -> bool:
    """Whether nested lists / tuples hold a bool, which numpy turns into 0 or 1 next to numbers."""
    if isinstance(value, (list, tuple)):
        return any(_holds_a_bool(v) for v in value)
    return isinstance(value, (bool, np.bool_))


def number_array(name: str, value, bound: float, shapes: tuple[tuple[int, ...], ...], unit: str = "",
                 entries: tuple[str, ...] = ()) -> np.ndarray:  # fmt: skip
    """``value`` as a float64 array of one of ``shapes`` with every entry finite and in ``[-bound, bound]``.

    Only real numbers are accepted (``real_array``). ``entries`` names the entries of a 1-D array in
    messages about non-finite values.

    Raises:
        ArgumentTypeError: entries that are not real numbers.
        ValueError: a shape not in ``shapes``, NaN or infinite entries, or entries beyond ``bound``.
    """
    wanted = " or ".join(str(s) for s in shapes)
    a = real_array(name, value, f"real numbers of shape {wanted}")
    if a.shape not in shapes:
        raise ValueError(f"{name} must have shape {wanted}, got shape {a.shape}")
    finite = np.isfinite(a)
    if not finite.all():
        if entries and a.ndim == 1:
            bad = [entry for entry, ok in zip(entries, finite.tolist()) if not ok]
            raise ValueError(f"{name} must be finite; non-finite entries: {bad} in {a.tolist()}")
        raise ValueError(f"{name} must be finite, got {a.tolist()}")
    if np.any(np.abs(a) > bound):
        raise ValueError(f"{name} entries must be in [-{bound:g}, {bound:g}]{f' {unit}' if unit else ''}, got {a.tolist()}")
    return a
