"""The balance task's names where they used to live (kept for imports): ``leg_env.tasks.stance`` and
``leg_env.step``."""

from . import step as _step
from .tasks import stance as _stance

for _module in (_step, _stance):
    globals().update({name: value for name, value in vars(_module).items() if not name.startswith("__")})
del _module
__all__ = _stance.__all__
