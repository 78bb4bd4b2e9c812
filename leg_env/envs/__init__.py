"""The Gymnasium environments, generic over the task: one robot (``single``) and a native batch (``vector``)."""

from .stance import PlanarLegStanceEnv

__all__ = ["LegEnv", "LegVectorEnv", "PlanarLegStanceEnv", "PlanarLegStanceVectorEnv"]


def __getattr__(name: str):
    if name == "LegEnv":
        from .single import LegEnv

        return LegEnv
    if name in ("LegVectorEnv", "PlanarLegStanceVectorEnv"):
        from . import vector

        return getattr(vector, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
