"""Whether numba can cache the compiled kernels, decided once before any kernel is defined.

numba looks for a writable place for its cache (``NUMBA_CACHE_DIR``, the package's ``__pycache__``,
the user's cache directory). With none, ``@njit(cache=True)`` raises ``RuntimeError: cannot cache
function ...: no locator available`` as the kernel is defined: a read-only install (a container
image, a system package) without a writable home. ``CACHE`` is then False, the kernels compile
without a cache (every process compiles them again, which takes minutes), and a warning says to set
``NUMBA_CACHE_DIR`` to a writable directory.
"""

from __future__ import annotations

import warnings

from numba import njit

__all__ = ["CACHE"]


def _probe():  # pragma: no cover - never called, only given to numba's cache locators
    return 0


def _can_cache() -> bool:
    """True when numba finds a cache location for a function in this package (nothing is compiled)."""
    try:
        njit(cache=True)(_probe)
    except RuntimeError:
        return False
    return True


CACHE = _can_cache()
"""The ``cache`` argument of every ``njit`` and ``guvectorize`` kernel of the package."""

if not CACHE:
    warnings.warn(
        "leg_env: numba has nowhere to cache the compiled kernels (the package directory is read-only and there is "
        "no writable user cache directory), so they are compiled without a cache, in every process (minutes). "
        "Set NUMBA_CACHE_DIR to a writable directory to keep them.",
        RuntimeWarning,
        stacklevel=2,
    )
