"""The machine a result was measured on, as results files and run folders record it."""

from __future__ import annotations

import os
import platform
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

__all__ = ["cpu_name", "describe"]


def cpu_name() -> str:
    """The CPU's model name (``/proc/cpuinfo`` on Linux), else what ``platform`` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def describe(packages: tuple[str, ...] = ("leg-env", "numpy", "gymnasium", "stable-baselines3", "torch")) -> str:
    """One line: the CPU, its cores, the OS, Python and the versions of ``packages`` (those installed)."""

    def installed(name: str) -> str | None:
        try:
            return f"{name} {version(name)}"
        except PackageNotFoundError:
            return None

    found = ", ".join(v for v in map(installed, packages) if v)
    return f"{cpu_name()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}; Python {platform.python_version()}; {found}"
