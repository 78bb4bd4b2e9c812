"""The arrays of the physics API: the parameter array, leading batch axes broadcast, arguments checked.

Every public function of ``leg_env.physics`` takes one robot (``q`` of shape ``(5,)``) or a batch with leading
axes (``(..., 5)``); these helpers broadcast the leading axes, refuse what is not real numbers (naming the
argument), and hand the compiled core C-contiguous ``(N, n)`` float64 rows.
"""

from __future__ import annotations

import numpy as np

from .. import checks
from .params import PARAM_RANGE, LegParams

__all__ = ["NQ", "NU", "NP", "LOAD_X", "params_array", "as_params", "core_params", "single_robot", "vec", "batched",
           "finite_rows"]

_LOAD_MAX = 1.0e12  # bound of a horizontal load [N]: far beyond any use, far below overflow
NQ = 5  # generalized coordinates
NU = 2  # actuated joints
NP = 11  # LegParams fields in the kernels' parameter array
LOAD_X = NP  # the kernels' parameter array ends with the horizontal force on the torso's COM [N] (``params_array``)


def params_array(p: LegParams | np.ndarray, load_x: float = 0.0) -> np.ndarray:
    """``LegParams`` as the float64 array the kernels read: its 11 fields, then the load ``p[LOAD_X]``.

    ``load_x`` is the horizontal force on the torso's COM [N] held over a step (0: no load). An array of
    11 values gets the load appended; one of 12 passes through.
    """
    load_x = 0.0 if load_x == 0.0 and type(load_x) in (float, int) else checks.real("load_x", load_x, -_LOAD_MAX, _LOAD_MAX, unit="N")
    if isinstance(p, LegParams):
        return _loaded(p.array, load_x)
    if type(p) is np.ndarray and p.dtype == np.float64 and p.shape == (NP,) and _valid_fields(p):  # the common case
        return _loaded(p, load_x)
    a = checks.real_array("p", p, f"LegParams or {NP} real numbers (or {NP + 1} with the load)")
    if a.shape not in ((NP,), (NP + 1,)):
        raise ValueError(f"p must be LegParams or an array of {NP} values (or {NP + 1} with the load), got shape {a.shape}")
    if not _valid_fields(a[:NP]):
        try:
            LegParams(*a[:NP].tolist())  # the field that is not a valid LegParams one, by name
        except ValueError as e:
            raise ValueError(f"p: {e}") from None  # names p and the field
    if a.shape == (NP,):
        return _loaded(a, load_x)
    checks.real("p's load (entry 11)", float(a[NP]), -_LOAD_MAX, _LOAD_MAX, unit="N")
    return a


_LOW = np.full(NP, PARAM_RANGE[0])
_LOW[NP - 1] = 0.0  # g may be 0, or at least G_MIN


def _valid_fields(a: np.ndarray) -> bool:
    """Whether 11 values are the fields of a ``LegParams`` (its own checks, at numpy's speed: ``LegParams(*a)``
    costs about 20 us, a parameter array's check at every step of ``step_inplace`` should not)."""
    g = a[NP - 1]
    return bool(np.all((a >= _LOW) & (a <= PARAM_RANGE[1]))) and (g == 0.0 or g >= PARAM_RANGE[0])


def as_params(p) -> LegParams:
    """``p`` as ``LegParams``: an instance as it is, an array of its 11 fields (or 12 with a load) checked."""
    return p if isinstance(p, LegParams) else LegParams(*params_array(p)[:NP].tolist())  # params_array names p


def core_params(p: LegParams | np.ndarray) -> np.ndarray:
    """The compiled core's ``leg_params`` of ``p``: a ``LegParams``' array as it is, else the first 11 values of
    ``params_array(p)`` (a load, where one is given, is an argument of its own in the core)."""
    return p.array if isinstance(p, LegParams) else params_array(p)[:NP]


def _loaded(a: np.ndarray, load_x: float) -> np.ndarray:
    out = np.empty(NP + 1)
    out[:NP] = a
    out[LOAD_X] = load_x
    return out


F64 = np.dtype(np.float64)
NO_LOAD = np.zeros(1)  # the load of one robot: none (the core only reads it)
NO_LOAD.setflags(write=False)
_SHAPE_Q = (NQ,)
_SHAPE_TAU = (NU,)


def single_robot(q, qd, tau) -> bool:
    """Fast-path test: ``q``, ``qd`` of shape (5,) and ``tau`` of shape (2,), all contiguous, aligned float64.

    One expression, no calls (this sits on the per-evaluation path). ``dtype is`` compares with
    numpy's float64 singleton; an equal but distinct dtype object only takes the general path.
    """
    return (
        type(q) is np.ndarray
        and type(qd) is np.ndarray
        and type(tau) is np.ndarray
        and q.shape == _SHAPE_Q
        and qd.shape == _SHAPE_Q
        and tau.shape == _SHAPE_TAU
        and q.dtype is F64
        and qd.dtype is F64
        and tau.dtype is F64
        and q.flags.c_contiguous
        and qd.flags.c_contiguous
        and tau.flags.c_contiguous
        and q.flags.aligned
        and qd.flags.aligned
        and tau.flags.aligned
    )


def vec(x, n: int, name: str) -> np.ndarray:
    """``x`` as a float64 array of shape ``(..., n)``. Only real numbers are taken (``leg_env.checks.real_array``:
    no strings, bools, complex numbers or None, which numpy would convert); a wrong shape is a ``ValueError``.
    Both name ``name``."""
    a = x if type(x) is np.ndarray and x.dtype is F64 else checks.real_array(name, x, f"real numbers of shape (..., {n})")
    if a.ndim == 0 or a.shape[-1] != n:
        raise ValueError(f"{name} must have shape (..., {n}), got {a.shape}")
    return a


def batched(*named):
    """Broadcast the leading axes of ``(name, array)`` pairs; return the lead shape and contiguous (N, n) views."""
    try:
        lead = np.broadcast_shapes(*(a.shape[:-1] for _, a in named))
    except ValueError:
        shapes = ", ".join(f"{name} {a.shape}" for name, a in named)
        raise ValueError(f"the leading axes of {shapes} do not broadcast together") from None
    flat = []
    for _, a in named:
        if a.shape[:-1] != lead:
            a = np.broadcast_to(a, lead + a.shape[-1:])
        flat.append(np.require(a.reshape(-1, a.shape[-1]), requirements=("C", "A")))  # C order, aligned: what the core reads
    return lead, flat


def finite_rows(*named: tuple[str, np.ndarray]) -> None:
    """``ValueError`` naming the first of the ``(name, rows (N, n))`` arrays that holds NaN or inf, with its first such
    rows: a state or torque the step cannot integrate (nothing is changed)."""
    for name, a in named:
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite, got {checks.shown(a[~np.isfinite(a).all(axis=-1)][:3])}")
