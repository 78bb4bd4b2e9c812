"""The entry points of old ids (``leg_env.tasks.ALIASES``): the current id's environment, with a warning.

Each builds exactly what its current id builds (same classes, same arguments); only the warning differs.
"""

from __future__ import annotations

import warnings

__all__ = ["single", "vector"]


def _warn(alias: tuple[str, str]) -> None:
    old, new = alias
    warnings.warn(
        f"{old} is deprecated and will be removed in the next release: it is now {new} (the same task, the same "
        "dynamics and reward; a different contact model is a different task, so it has a name of its own).",
        DeprecationWarning,
        stacklevel=3,
    )


def single(_alias: tuple[str, str], **kwargs):
    """The current id's single env, made by a deprecated id."""
    from .single import LegEnv

    _warn(_alias)
    return LegEnv(**kwargs)


def vector(_alias: tuple[str, str], **kwargs):
    """The current id's vector env, made by a deprecated id."""
    from .vector import LegVectorEnv

    _warn(_alias)
    return LegVectorEnv(**kwargs)
