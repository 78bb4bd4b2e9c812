"""The balance task's names where they used to live: ``leg_env.tasks.stance`` (kept for imports)."""

from .tasks import stance as _stance

globals().update({name: value for name, value in vars(_stance).items() if not name.startswith("__")})
__all__ = _stance.__all__
