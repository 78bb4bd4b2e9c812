"""The task-independent control step on packed arrays: the physics kernel every task shares.

A task (``leg_env.tasks``) is evaluated in two compiled calls per control step, one after the other on
the same packed arrays:

1. ``physics_range`` (this module, compiled once for every task): clip the actions, scale them to
   torques, take the control step of the contact model (the pinned RK4 step of ``leg_env.integrate`` or
   the hybrid step of ``leg_env.hybrid``) under the step's horizontal load on the torso's COM, check the
   result, and keep the state before the step for the task's own last check;
2. the task's kernel (``Task.assess``, compiled per task, small): observation, reward terms,
   termination, extras, and whatever the task keeps per robot (a push schedule, a command).

So adding a task compiles only its own small kernel: the hybrid step (minutes of cold compilation) is
compiled once, in ``physics_range``, whatever the number of tasks. Starting robots is split the same way
(``physics_start`` puts them on their contact, ``Task.start`` evaluates them).

Packed arrays (row ``i`` is robot ``i``):

* ``state (N, STATE_DIM + task columns)`` float64: ``q | qd | anchor | action | trig | mode | load | prev
  | task columns``. ``trig = sin th1, cos th1, sin th2, cos th2`` of ``q`` (written by the kernels that
  write ``q``, read by the next step: callers change ``q`` only through a start). ``load`` is the
  horizontal force on the torso's COM [N] held over the next step (written by the task's kernel, 0 for
  tasks without one). ``prev`` is the state before the last step (``q, qd, mode, anchor_x, trig``), for
  a task that finds its observation overflowing float32 and must undo the step.
* ``consts (R, CONSTS_BASE + task constants)`` float64, read only by the kernels: ``LegParams.array |
  config.array() | q_nom | tau_nom | com_nom | task constants``. ``config.array()`` starts with the settings
  this module reads (``C_*`` indices); ``q_nom, tau_nom`` are the robot's nominal posture and holding
  torques, ``com_nom`` its whole-body COM there (foot at the origin). ``R = 1``: every robot is the same
  robot (row 0); ``R = N``: row ``i`` is robot ``i``'s own (domain randomisation, ``leg_env.randomize``),
  the parameters, friction, torque limits and everything derived from them. The settings that are not
  the robot's (``dt``, weights, limits of the task) are the same in every row.
* ``out (N, OUT_BASE + task columns)`` float64: ``lam | extras | accumulators | energy, foot height | mode |
  reward terms | task info``; ``lam`` is the mean contact force over the step [N], the accumulators are
  the hybrid step's (``leg_env.hybrid.ACC_*``, unilateral model only).
* ``obs (N, obs_dim)`` float32 and ``flags (N, len(FLAG_NAMES))`` bool.
"""

from __future__ import annotations

import ctypes

import numba
import numpy as np
from numba import njit

from ._jit import CACHE
from .dynamics import LOAD_X, NP, _stance_one
from .contact import FLIGHT, STICK
from .hybrid import ACC_DIM, ACC_IMPULSE_X, ACC_IMPULSE_Y, GROUND_TOL, LOG_SIZE, _choose_mode, _derivative, _hybrid_from
from .integrate import _project_one, _rk4_from

__all__ = [
    "FLAG_NAMES",
    "STATE_DIM",
    "OUT_BASE",
    "OUT_MODE",
    "robot_row",
    "physics_range",
    "physics_start",
    "physics_start_noisy",
    "perturbed_start",
    "physics_one",
    "summed_terms",
    "compiled_entry",
    "BitGeneratorRows",
]

FLAG_NAMES = ("terminated", "unilateral_violation", "friction_violation", "numerical_failure")
FAILED = 3  # flags column of a numerical failure (written by the physics, read by the task)

# state columns
_QD0, _ANCHOR0, _ACTION0, _TRIG0, STATE_MODE, STATE_LOAD, _PREV0 = 5, 10, 12, 14, 18, 19, 20
STATE_Q, STATE_QD, STATE_ANCHOR, STATE_ACTION, STATE_TRIG = (
    slice(0, _QD0), slice(_QD0, _ANCHOR0), slice(_ANCHOR0, _ACTION0), slice(_ACTION0, _TRIG0), slice(_TRIG0, STATE_MODE)
)
_PREV_MODE, _PREV_ANCHOR, _PREV_TRIG = _PREV0 + 10, _PREV0 + 11, _PREV0 + 12
STATE_DIM = _PREV0 + 16  # the first task column

# out columns
OUT_LAM, OUT_EXTRA = slice(0, 2), slice(2, 5)
ACC0 = 5  # first accumulator column
HYB0 = ACC0 + ACC_DIM  # energy, foot height
OUT_ACC, OUT_HYBRID = slice(ACC0, HYB0), slice(HYB0, HYB0 + 2)
OUT_MODE = HYB0 + 2  # the contact mode at the end of the step (a copy of the state's, for a cheap info)
OUT_BASE = OUT_MODE + 1  # the first reward-term column

# consts: LegParams | config.array() | q_nom | tau_nom | com_nom | task constants. With a row per robot the
# rows differ only in LegParams, mu, the torque limits and what follows from them (q_nom, tau_nom, com_nom):
# the kernels read every other setting from row 0
NC = 23  # entries of StanceConfig.array(), the settings every task has
NOM0 = NP + NC
TAU0 = NOM0 + 5
COM0 = TAU0 + 2  # the nominal COM (x, y)
CONSTS_BASE = COM0 + 2
# indices into config.array() of the settings read here (the order of StanceConfig.array())
C_DT, C_SUBSTEPS, C_MAX_ANGLE, C_TAU_HIP, C_TAU_KNEE = 0, 1, 2, 3, 4
C_MU, C_MAX_RATE, C_UNILATERAL = 12, 21, 22


@njit(cache=CACHE, nogil=True)
def physics_range(lo, hi, state, consts, out, flags):
    """One control step of robots ``lo .. hi - 1``, in place; the task's kernel evaluates them next.

    Per robot: keep ``prev``; clip the action to [-1, 1] and scale it to torques; step the contact model
    under the load ``state[i, STATE_LOAD]``; write ``lam`` (mean contact force over the step) and, in the
    unilateral model, the step's accumulators. A numerical failure (a non-finite state or force, or a
    rate above ``max_rate``) restores the state before the step, zeroes ``lam`` and the accumulators and
    sets ``flags[i, FAILED]``; otherwise ``flags[i, FAILED]`` is cleared and ``trig`` follows the new ``q``.
    Releases the GIL, so that threads can share a batch: robots are independent, so the rows of a batch
    stepped in any split are bitwise those of one call.
    """
    c = consts[0, NP:NOM0]  # the settings every robot shares (a robot's own row differs in mu and torque limits)
    per_robot = consts.shape[0] > 1
    # one allocation for the scratch (a single robot's step pays for each): the parameter array (LegParams,
    # then this robot's load), the torques, and the hybrid step's event log (not read here)
    scratch = np.empty(NP + 3 + 2 * LOG_SIZE)
    p, tau = scratch[:NP + 1], scratch[NP + 1:NP + 3]
    log_t = scratch[NP + 3:NP + 3 + LOG_SIZE]
    log_k = scratch[NP + 3 + LOG_SIZE:].view(np.int64)
    _robot_params(consts, 0, p)
    unilateral = c[C_UNILATERAL] > 0.5
    dt, substeps, max_angle, max_rate = c[C_DT], int(c[C_SUBSTEPS]), c[C_MAX_ANGLE], c[C_MAX_RATE]
    mu, tau_hip, tau_knee = c[C_MU], c[C_TAU_HIP], c[C_TAU_KNEE]
    for i in range(lo, hi):
        if per_robot:  # this robot's parameters, friction and torque limits
            r = _robot_params(consts, i, p)
            mu, tau_hip, tau_knee = r[NP + C_MU], r[NP + C_TAU_HIP], r[NP + C_TAU_KNEE]
        s = state[i]
        q, qd, anchor = s[0:_QD0], s[_QD0:_ANCHOR0], s[_ANCHOR0:_ACTION0]
        lam, hyb = out[i, 0:2], out[i, ACC0:OUT_MODE]
        for j in range(10):
            s[_PREV0 + j] = s[j]
        s[_PREV_MODE] = s[STATE_MODE]
        s[_PREV_ANCHOR] = s[_ANCHOR0]
        for j in range(4):
            s[_PREV_TRIG + j] = s[_TRIG0 + j]
        tau[0] = min(1.0, max(-1.0, s[_ACTION0])) * tau_hip
        tau[1] = min(1.0, max(-1.0, s[_ACTION0 + 1])) * tau_knee
        p[LOAD_X] = s[STATE_LOAD]
        if unilateral:
            s[STATE_MODE] = _hybrid_from(
                q, qd, tau, p, mu, int(s[STATE_MODE]), anchor, dt, substeps, max_angle,
                s[_TRIG0], s[_TRIG0 + 1], s[_TRIG0 + 2], s[_TRIG0 + 3], hyb, log_t, log_k,
            )  # fmt: skip
            lam[0] = hyb[ACC_IMPULSE_X] / dt
            lam[1] = hyb[ACC_IMPULSE_Y] / dt
        else:
            _rk4_from(q, qd, tau, p, anchor, dt, substeps, max_angle, True, lam, s[_TRIG0], s[_TRIG0 + 1], s[_TRIG0 + 2], s[_TRIG0 + 3])
        finite = np.isfinite(lam[0]) and np.isfinite(lam[1])
        for j in range(5):
            if not (np.isfinite(q[j]) and abs(qd[j]) <= max_rate):
                finite = False
        if finite:
            flags[i, FAILED] = False
            _write_trig(s)
        else:
            undo_step(s)
            lam[0] = 0.0
            lam[1] = 0.0
            for j in range(hyb.shape[0]):
                hyb[j] = 0.0
            flags[i, FAILED] = True
        out[i, OUT_MODE] = s[STATE_MODE]


@njit(cache=CACHE, inline="always")
def robot_row(consts, i):
    """Robot ``i``'s row of ``consts``: its own with a row per robot, else the one row every robot shares."""
    return consts[i if consts.shape[0] > 1 else 0]


@njit(cache=CACHE, inline="always")
def _robot_params(consts, i, p):
    """Copy robot ``i``'s ``LegParams`` into ``p``; return its row of ``consts`` (``robot_row``)."""
    r = robot_row(consts, i)
    for j in range(NP):
        p[j] = r[j]
    return r


@njit(cache=CACHE, inline="always")
def _write_trig(s):
    th1 = s[2] + s[3]
    th2 = th1 + s[4]
    s[_TRIG0], s[_TRIG0 + 1], s[_TRIG0 + 2], s[_TRIG0 + 3] = np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2)


@njit(cache=CACHE, inline="always")
def undo_step(s):
    """Restore the state row ``s`` to what it was before the last control step (``prev``)."""
    for j in range(10):
        s[j] = s[_PREV0 + j]
    s[STATE_MODE] = s[_PREV_MODE]
    s[_ANCHOR0] = s[_PREV_ANCHOR]
    for j in range(4):
        s[_TRIG0 + j] = s[_PREV_TRIG + j]


@njit(cache=CACHE)
def physics_start(state, consts, out, flags):
    """Put freshly reset robots on their contact, without stepping; the task's ``start`` evaluates them.

    Pinned model: each robot's base is projected so that its foot is on its anchor with ``Jc qd = 0``
    (``leg_env.integrate.project_stance``). Unilateral model: a foot within ``GROUND_TOL`` of the ground
    (``y = anchor[1]``) is put on it by moving the base and the mode is chosen as at the start of a control
    step (``leg_env.hybrid``; a foot moving into the ground gets the impact map); a foot above it flies. No
    control step has been taken yet, so ``lam`` is the instantaneous force of that mode under the nominal
    holding torques without load (at the nominal posture exactly ``[0, m g]`` up to round-off), the
    accumulators are zeroed and so is the load (the task's ``start`` sets the first step's).
    """
    p = np.empty(NP + 1)
    qdd = np.empty(5)
    for i in range(state.shape[0]):
        r = _robot_params(consts, i, p)
        _start_row(i, state, r, out, flags, p, qdd)


@njit(cache=CACHE)
def physics_start_noisy(noise, scale, state, consts, out, flags):
    """``physics_start`` of robots started at the nominal posture plus noise, in one compiled call.

    Row ``i`` starts at ``perturbed_start(noise[i], scale, ...)`` (``q_nom`` and the parameters from
    ``consts``) with its foot at the origin, then is put on its contact as by ``physics_start``: bit for bit
    what ``perturbed_start`` followed by ``physics_start`` gives. ``noise`` is ``(N, 6)`` uniforms in
    [0, 1), not read at ``scale == 0``.
    """
    p = np.empty(NP + 1)
    qdd = np.empty(5)
    for i in range(state.shape[0]):
        r = _robot_params(consts, i, p)
        s = state[i]
        perturbed_start(noise[i], scale, r[NOM0:TAU0], p, s[0:_QD0], s[_QD0:_ANCHOR0], s[_ANCHOR0:_ACTION0])
        _start_row(i, state, r, out, flags, p, qdd)


@njit(cache=CACHE, inline="always")
def perturbed_start(noise, scale, q_nom, p, q, qd, anchor):
    """Write into ``q, qd, anchor`` the nominal posture plus ``uniform(-scale, scale)`` noise (from ``noise``,
    6 uniforms in [0, 1)) on ``(th_b, q1, q2)`` and their rates, projected onto the pin at the origin.

    ``low + (high - low) * u`` is numpy's ``uniform(low, high)`` from the same draw ``u``, so the state is
    the same bit for bit whether the draws were made by numpy or in compiled code.
    """
    low, width = -scale, scale - (-scale)
    for j in range(5):
        q[j] = q_nom[j]
        qd[j] = 0.0
    anchor[0] = 0.0
    anchor[1] = 0.0
    if scale > 0.0:
        for j in range(3):
            q[2 + j] += low + width * noise[j]
            qd[2 + j] += low + width * noise[3 + j]
    _project_one(q, qd, p, anchor)


@njit(cache=CACHE, inline="always")
def _start_row(i, state, r, out, flags, p, qdd):
    """``physics_start`` of row ``i``, robot ``r`` (its ``consts`` row) whose parameters the caller has put in
    ``p`` (``qdd``: scratch)."""
    c = r[NP:NOM0]
    tau = r[TAU0:COM0]
    s = state[i]
    q, qd, anchor = s[0:_QD0], s[_QD0:_ANCHOR0], s[_ANCHOR0:_ACTION0]
    s[STATE_LOAD] = 0.0  # a start has no load; the task's start kernel sets the first step's
    p[LOAD_X] = 0.0
    if c[C_UNILATERAL] > 0.5:
        s[STATE_MODE] = _start_unilateral(q, qd, anchor, tau, c[C_MU], p, out[i, 0:2], out[i, ACC0:OUT_MODE])
    else:
        _project_one(q, qd, p, anchor)
        _stance_one(q, qd, tau, p, qdd, out[i, 0:2])
    _write_trig(s)
    out[i, OUT_MODE] = s[STATE_MODE]
    flags[i, FAILED] = False


@njit(cache=CACHE, nogil=True)
def physics_one(a0, a1, state, consts, out, flags):
    """The single env's ``physics_range``: set robot 0's action to ``(a0, a1)`` and step it."""
    state[0, _ACTION0] = a0
    state[0, _ACTION0 + 1] = a1
    physics_range(0, 1, state, consts, out, flags)


@njit(cache=CACHE, inline="always")
def summed_terms(out, n_terms):
    """Robot 0's reward: its ``n_terms`` reward terms (from ``OUT_BASE``) summed in order."""
    reward = out[0, OUT_BASE]
    for k in range(1, n_terms):
        reward += out[0, OUT_BASE + k]
    return reward


@njit(cache=CACHE)
def _start_unilateral(q, qd, anchor, tau, mu, p, lam, hyb):
    """Mode, ground contact and instantaneous force of a unilateral start state (``physics_start``)."""
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
    k = _derivative(m, mu, X, tau[0], tau[1], p)
    lam[0], lam[1] = k[5], k[6]
    for j in range(hyb.shape[0]):
        hyb[j] = 0.0
    return m


def compiled_entry(kernel, args: tuple):
    """The machine code of ``kernel`` for the types of ``args``, callable as ``kernel`` is.

    A numba dispatcher types every argument at every call (about 0.25 us for the arrays of a kernel,
    a twentieth of a single env's ``step``). The arrays of an env never change type, so the env
    compiles its kernels once for exactly their types and calls the compiled entry point, which skips
    that typing. It must then only ever be called with arrays of those types. Where numba does not
    expose ``overloads[signature].entry_point`` the dispatcher itself is returned: the same machine
    code behind a little more overhead.
    """
    signature = tuple(numba.typeof(a) for a in args)
    try:
        kernel.compile(signature)
        return kernel.overloads[signature].entry_point
    except (AttributeError, KeyError, TypeError):
        return kernel


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

    @property
    def next_double(self):
        """numpy's ``next_double`` of PCG64 (a ctypes function), for compiled draws; None before one is held."""
        return self._next_double

    @property
    def states(self) -> np.ndarray:
        """The addresses of the bit generators' states, ``(n,)`` int64 (0 for a generator drawn in Python)."""
        return self._states

    def all_compiled(self, rows: np.ndarray) -> bool:
        """Whether every generator of ``rows`` can be drawn from in compiled code."""
        return bool(self._compiled[rows].all())

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
