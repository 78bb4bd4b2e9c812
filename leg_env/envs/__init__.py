"""The Gymnasium environments: one robot (``stance``) and a native batch (``vector``)."""

from .stance import PlanarLegStanceEnv

__all__ = ["PlanarLegStanceEnv", "PlanarLegStanceVectorEnv"]


def __getattr__(name: str):
    if name == "PlanarLegStanceVectorEnv":
        from .vector import PlanarLegStanceVectorEnv

        return PlanarLegStanceVectorEnv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
