"""The Gymnasium environments, generic over the task: one robot (``single``) and a native batch (``vector``)."""

__all__ = ["LegEnv", "LegVectorEnv"]


def __getattr__(name: str):
    if name == "LegEnv":
        from .single import LegEnv

        return LegEnv
    if name == "LegVectorEnv":
        from .vector import LegVectorEnv

        return LegVectorEnv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
