"""The balance task's names where they used to live: ``leg_env.tasks.stance`` (kept for imports)."""

from .tasks.stance import *  # noqa: F401,F403
from .tasks.stance import __all__  # noqa: F401
