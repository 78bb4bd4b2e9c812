"""Each sub-env's random number generator, drawn from in compiled code.

The vector environment keeps one numpy ``Generator`` per sub-env (sub-env ``i`` seeded ``seed + i``, as a single
env would be). Its resets draw from many of them at once: ``BitGeneratorRows`` hands the compiled core each row's
bit generator, so that one call draws every row's numbers, exactly those ``rng.random`` would give.
"""

from __future__ import annotations

import numpy as np

from .._core import kernels

__all__ = ["BitGeneratorRows"]


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
