"""The entry points of old ids (``leg_env.tasks.ALIASES``): the current id's environment, with a warning.

Each builds exactly what its current id builds (same classes, same arguments); only the warning differs.
"""

from __future__ import annotations

import warnings

__all__ = ["single_stance", "vector_stance"]


def _warn(alias: tuple[str, str]) -> None:
    old, new = alias
    warnings.warn(
        f"{old} is deprecated and will be removed in the next release: it is now {new} (the same task, the same "
        "dynamics and reward; a different contact model is a different task, so it has a name of its own).",
        DeprecationWarning,
        stacklevel=3,
    )


def single_stance(_alias: tuple[str, str], **kwargs):
    """The balance task's single env, made by a deprecated id."""
    from .stance import PlanarLegStanceEnv

    _warn(_alias)
    return PlanarLegStanceEnv(**kwargs)


def vector_stance(_alias: tuple[str, str], **kwargs):
    """The balance task's vector env, made by a deprecated id."""
    from .vector import PlanarLegStanceVectorEnv

    _warn(_alias)
    return PlanarLegStanceVectorEnv(**kwargs)
