"""The machine a result was measured on, as results files and run folders record it."""

from __future__ import annotations

import os
import platform
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

__all__ = ["cpu_name", "describe", "native_bfloat16", "UPDATE_PRECISIONS", "TANHS"]

UPDATE_PRECISIONS = ("float32", "bfloat16")
"""The arithmetic of the hidden layers in PPO's update (``train.chunked_ppo.ChunkedPPO(update_precision=...)``)."""
TANHS = ("fast", "torch")
"""``train.chunked_ppo.ChunkedPPO``'s ways of computing ``tanh``: ``FastTanh``, or torch's own (which is faster
depends on the CPU)."""


def cpu_name() -> str:
    """The CPU's model name (``/proc/cpuinfo`` on Linux), else what ``platform`` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def native_bfloat16() -> bool:
    """Whether this CPU has bfloat16 arithmetic (the ``avx512_bf16`` or ``amx_bf16`` flag of Linux's
    ``/proc/cpuinfo``; False where that file is absent). Elsewhere torch emulates bfloat16, more slowly than float32."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                flags = line.split(":", 1)[1].split()
                return "avx512_bf16" in flags or "amx_bf16" in flags
    except OSError:
        pass
    return False


def describe(packages: tuple[str, ...] = ("leg-env", "numpy", "gymnasium", "stable-baselines3", "torch")) -> str:
    """One line: the CPU, its cores, the OS, Python and the versions of ``packages`` (those installed)."""

    def installed(name: str) -> str | None:
        try:
            return f"{name} {version(name)}"
        except PackageNotFoundError:
            return None

    found = ", ".join(v for v in map(installed, packages) if v)
    return f"{cpu_name()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}; Python {platform.python_version()}; {found}"
