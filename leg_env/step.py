"""The task-independent control step on packed arrays: the physics kernel every task shares.

A task (``leg_env.tasks``) is evaluated in two calls of the compiled core (``leg_env/_core``, C) per
control step, one after the other on the same packed arrays:

1. ``physics_range`` (``env.c``, the same for every task): clip the actions, scale them to torques, take
   the control step of the contact model (the pinned RK4 step of ``leg_env.integrate`` or the hybrid step
   of ``leg_env.hybrid``) under the step's horizontal load on the torso's COM, check the result, and keep
   the state before the step for the task's own last check;
2. the task's kernel (``Task.assess``, ``tasks.c``): observation, reward terms, termination, extras, and
   whatever the task keeps per robot (a push schedule, a command).

Starting robots is split the same way (``physics_start`` puts them on their contact, ``Task.start``
evaluates them). The single env makes both calls of a step in one (``kernels.Batch.step_one``).

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

import numpy as np

from ._core import kernels

__all__ = [
    "FLAG_NAMES",
    "STATE_DIM",
    "OUT_BASE",
    "OUT_MODE",
    "physics_range",
    "physics_start",
    "physics_start_noisy",
    "BitGeneratorRows",
]

FLAG_NAMES = ("terminated", "unilateral_violation", "friction_violation", "numerical_failure")
FAILED = 3  # flags column of a numerical failure (written by the physics, read by the task)

# state columns (the C struct env_state of leg_env/_core/env.h, checked below)
_QD0, _ANCHOR0, _ACTION0, _TRIG0, STATE_MODE, STATE_LOAD, _PREV0 = 5, 10, 12, 14, 18, 19, 20
STATE_Q, STATE_QD, STATE_ANCHOR, STATE_ACTION, STATE_TRIG = (
    slice(0, _QD0), slice(_QD0, _ANCHOR0), slice(_ANCHOR0, _ACTION0), slice(_ACTION0, _TRIG0), slice(_TRIG0, STATE_MODE)
)
_PREV_MODE, _PREV_ANCHOR, _PREV_TRIG = _PREV0 + 10, _PREV0 + 11, _PREV0 + 12
STATE_DIM = _PREV0 + 16  # the first task column

# out columns (env_out)
OUT_LAM, OUT_EXTRA = slice(0, 2), slice(2, 5)
ACC0 = 5  # first accumulator column
HYB0 = ACC0 + 15  # energy, foot height
OUT_ACC, OUT_HYBRID = slice(ACC0, HYB0), slice(HYB0, HYB0 + 2)
OUT_MODE = HYB0 + 2  # the contact mode at the end of the step (a copy of the state's, for a cheap info)
OUT_BASE = OUT_MODE + 1  # the first reward-term column

# consts: LegParams | config.array() | q_nom | tau_nom | com_nom | task constants (env_robot). With a row per robot
# the rows differ only in LegParams, mu, the torque limits and what follows from them (q_nom, tau_nom, com_nom):
# the kernels read every other setting from row 0
NP = 11  # LegParams fields
NC = 23  # entries of StanceConfig.array(), the settings every task has
NOM0 = NP + NC
TAU0 = NOM0 + 5
COM0 = TAU0 + 2  # the nominal COM (x, y)
CONSTS_BASE = COM0 + 2
# indices into config.array() of the settings read here (the order of StanceConfig.array())
C_DT, C_SUBSTEPS, C_MAX_ANGLE, C_TAU_HIP, C_TAU_KNEE = 0, 1, 2, 3, 4
C_MU, C_MAX_RATE, C_UNILATERAL = 12, 21, 22


def _check_columns() -> None:
    """Raise ``ImportError`` unless the columns above are those of the compiled core's structs (``env.h``)."""
    layouts = kernels.env_layouts()
    expected = {
        "state": (STATE_DIM, {"q": (0, 5), "qd": (_QD0, 5), "anchor": (_ANCHOR0, 2), "action": (_ACTION0, 2), "trig": (_TRIG0, 4),
                              "mode": (STATE_MODE, 1), "load": (STATE_LOAD, 1), "prev_q": (_PREV0, 5), "prev_qd": (_PREV0 + 5, 5),
                              "prev_mode": (_PREV_MODE, 1), "prev_anchor_x": (_PREV_ANCHOR, 1), "prev_trig": (_PREV_TRIG, 4)}),
        "robot": (CONSTS_BASE, {"p": (0, NP), "c": (NP, NC), "c.dt": (NP + C_DT, 1), "c.substeps": (NP + C_SUBSTEPS, 1),
                                "c.max_angle": (NP + C_MAX_ANGLE, 1), "c.tau_hip": (NP + C_TAU_HIP, 1), "c.tau_knee": (NP + C_TAU_KNEE, 1),
                                "c.mu": (NP + C_MU, 1), "c.max_rate": (NP + C_MAX_RATE, 1), "c.unilateral": (NP + C_UNILATERAL, 1),
                                "q_nom": (NOM0, 5), "tau_nom": (TAU0, 2), "com_nom": (COM0, 2)}),
        "out": (OUT_BASE, {"lam": (0, 2), "base_drift": (OUT_EXTRA.start, 1), "impulse": (ACC0, 2), "kick": (ACC0 + 2, 2),
                           "stick_time": (ACC0 + 4, 1), "events": (ACC0 + 11, 1), "work_load": (ACC0 + 14, 1), "energy": (HYB0, 1),
                           "mode": (OUT_MODE, 1)}),
    }
    for row, (width, columns) in expected.items():
        size, fields = layouts[row]
        got = {name: (first, count) for name, first, count in fields}
        if size != width or got != columns:
            raise ImportError(f"leg_env.step: the {row} columns do not match the compiled core ({size}, {got}); rebuild the package")


_check_columns()

physics_range = kernels.physics_range
"""``physics_range(lo, hi, state, consts, out, flags)``: one control step of robots ``lo .. hi - 1``, in place.

Per robot: keep ``prev``; clip the action to [-1, 1] and scale it to torques; step the contact model under
the load ``state[i, STATE_LOAD]``; write ``lam`` (mean contact force over the step) and, in the unilateral
model, the step's accumulators. A numerical failure (a non-finite state or force, or a rate above
``max_rate``) restores the state before the step, zeroes ``lam`` and the accumulators and sets
``flags[i, FAILED]``; otherwise ``flags[i, FAILED]`` is cleared and ``trig`` follows the new ``q``. Releases
the GIL, so that threads can share a batch: robots are independent, so the rows of a batch stepped in any
split are bitwise those of one call."""

physics_start = kernels.physics_start
"""``physics_start(state, consts, out, flags)``: put freshly reset robots on their contact, without stepping.

Pinned model: each robot's base is projected so that its foot is on its anchor with ``Jc qd = 0``. Unilateral
model: a foot within ``GROUND_TOL`` of the ground (``y = anchor[1]``) is put on it by moving the base and the
mode is chosen as at the start of a control step (a foot moving into the ground gets the impact map); a foot
above it flies. ``lam`` is the instantaneous force of that mode under the nominal holding torques without
load, the accumulators and the load are zeroed (the task's ``start`` sets the first step's load)."""

physics_start_noisy = kernels.physics_start_noisy
"""``physics_start_noisy(noise, scale, state, consts, out, flags)``: ``physics_start`` of robots started at the
nominal posture plus ``uniform(-scale, scale)`` noise on ``(th_b, q1, q2)`` and their rates, ``noise`` being
``(N, 6)`` uniforms in [0, 1) (``low + (high - low) u`` as numpy's ``uniform``; not read at ``scale == 0``),
projected onto the pin at the origin, each robot from its own row of ``consts``."""


class BitGeneratorRows:
    """The generators of many sub-envs, drawn from in one compiled call.

    ``draw(rows, out)`` fills ``out[k]`` with ``out.shape[1]`` draws from generator ``rows[k]``: exactly the
    numbers (and the state advance) of ``rng.random(out=out[k])``, through the C interface numpy gives every
    bit generator (its ``capsule``).
    """

    def __init__(self, n: int):
        self.generators: list[np.random.Generator | None] = [None] * n
        self.capsules: list = [None] * n

    def __setitem__(self, i: int, rng: np.random.Generator) -> None:
        self.generators[i] = rng
        self.capsules[i] = rng.bit_generator.capsule

    def __getitem__(self, i: int) -> np.random.Generator | None:
        return self.generators[i]

    def draw(self, rows: np.ndarray, out: np.ndarray) -> None:
        """``out[k] = generators[rows[k]].random(out.shape[1])`` for every k."""
        kernels.draw_uniform(self.capsules, np.ascontiguousarray(rows, dtype=np.int64), out)

    def __getstate__(self) -> dict:
        return {"generators": self.generators}

    def __setstate__(self, state: dict) -> None:
        self.__init__(len(state["generators"]))
        for i, rng in enumerate(state["generators"]):
            if rng is not None:
                self[i] = rng
