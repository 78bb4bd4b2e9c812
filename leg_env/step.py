"""The task-independent control step: the physics every task shares.

A task (``leg_env.tasks``) is evaluated in two calls of the compiled core (``leg_env/_core``, C) per
control step, one after the other on the same arrays:

1. ``physics_range`` (``env.c``, the same for every task): clip the actions, scale them to torques, take
   the control step of the contact model (the pinned RK4 step of ``leg_env.integrate`` or the hybrid step
   of ``leg_env.hybrid``) under the step's horizontal load on the torso's COM, check the result, and keep
   the state before the step for the task's own last check;
2. the task's kernel (``Task.assess``, ``tasks.c``): observation, reward terms, termination, extras, and
   whatever the task keeps per robot (a push schedule, a command).

Starting robots is one call (``Task.start``: on their contact, then evaluated). The envs make both calls
of a step in one: ``Task.step`` (the vector env: block by block over rows, so that each block stays in
cache between the two) and ``kernels.Batch.step_one`` (the single env); the results are bitwise those of
the two calls.

The arrays (``leg_env.layout``; row ``i`` is robot ``i``): ``state`` (``state_dtype(task)``: ``q``, ``qd``,
the contact ``anchor``, the last ``action``, the ``trig`` of ``q``, the ``load`` held over the next step, the
contact ``mode`` and the state before the last step, then the task's own fields), ``robots``
(``layout.ROBOT``: one row for every robot, or a row per robot of a randomised batch), ``settings`` (one row of
``settings_dtype(task)``), ``out`` (``out_dtype(task)``: the mean contact force ``lam``, the extras, what the
hybrid step did, the COM, the reward ``terms``, the flags, the task's own info) and ``obs`` (float32,
``(N, obs_dim)``).
"""

from __future__ import annotations

import numpy as np

from ._core import kernels

__all__ = ["FLAG_NAMES", "physics_range", "BitGeneratorRows"]

FLAG_NAMES = ("terminated", "unilateral_violation", "friction_violation", "numerical_failure")
"""The flags of ``out`` (bool fields), in this order wherever they are listed."""

physics_range = kernels.physics_range
"""``physics_range(lo, hi, state, robots, settings, out)``: one control step of robots ``lo .. hi - 1``, in place.

Per robot: keep the state before the step; clip the action to [-1, 1] and scale it to torques; step the contact
model under the load ``state["load"]``; write ``lam`` (mean contact force over the step) and, on the unilateral
ground, what the hybrid step did. A numerical failure (a non-finite state or force, or a rate above
``max_rate``) restores the state before the step, zeroes ``lam`` and the record and sets
``out["numerical_failure"]``; otherwise it is cleared and ``trig`` follows the new ``q``. Releases the GIL, so
that threads can share a batch: robots are independent, so the rows of a batch stepped in any split are
bitwise those of one call.

Starting robots (``Task.start``, ``kernels.start``) puts them on their contact without stepping. Pinned model:
each robot's base is projected so that its foot is on its anchor with ``Jc qd = 0``. Unilateral model: a foot
within ``GROUND_TOL`` of the ground (``y = anchor[1]``) is put on it by moving the base and the mode is chosen
as at the start of a control step (a foot moving into the ground gets the impact map); a foot above it flies.
``lam`` is the instantaneous force of that mode under the nominal holding torques without load; the record
and the load are zeroed (the task sets the first step's load)."""


class BitGeneratorRows:
    """The generators of many sub-envs, drawn from in one compiled call.

    ``draw(rows, out)`` fills ``out[k]`` with ``out.shape[1]`` draws from generator ``rows[k]``: exactly the
    numbers (and the state advance) of ``rng.random(out=out[k])``, through the C interface numpy gives every
    bit generator (its ``capsule``, read when a generator is set, held with the generator by a
    ``kernels.Generators``).
    """

    def __init__(self, n: int):
        self.generators: list[np.random.Generator | None] = [None] * n
        # what the compiled draws read: each row's bit generator, held with the pointer to its C interface (no
        # attribute look-ups through Python objects per row and draw)
        self.bit_generators = kernels.Generators(n)

    def __setitem__(self, i: int, rng: np.random.Generator) -> None:
        self.generators[i] = rng
        self.bit_generators.set(i, rng.bit_generator)

    def __getitem__(self, i: int) -> np.random.Generator | None:
        return self.generators[i]

    def draw(self, rows: np.ndarray, out: np.ndarray) -> None:
        """``out[k] = generators[rows[k]].random(out.shape[1])`` for every k."""
        kernels.draw_uniform(self.bit_generators, np.ascontiguousarray(rows, dtype=np.int64), out)

    def __getstate__(self) -> dict:
        return {"generators": self.generators}

    def __setstate__(self, state: dict) -> None:
        self.__init__(len(state["generators"]))
        for i, rng in enumerate(state["generators"]):
            if rng is not None:
                self[i] = rng
