"""The tasks: one module per task (``leg_env.tasks.<name>``), and the table of registered ids.

Importing this package is cheap: a task module loads on first use
(``get``). ``REGISTRY`` maps each Gymnasium id to its task module and the keyword arguments the id
fixes; ``leg_env/__init__.py`` registers every entry. Adding a task is its module plus its line here.
"""

from __future__ import annotations

import importlib

__all__ = ["REGISTRY", "ALIASES", "get"]

REGISTRY = {
    # id: (task module, keyword arguments of the id)
    "leg_env/PlanarLegStance-v0": ("stance", {}),
    "leg_env/PlanarLegBalance-v0": ("stance", {"contact": "unilateral", "reset_noise_scale": 0.05}),
    "leg_env/PlanarLegPush-v0": ("push", {}),
    "leg_env/PlanarLegPush-v1": ("push", {"observe_com": True}),
    "leg_env/PlanarLegHop-v0": ("hop", {}),
    "leg_env/PlanarLegHop-v1": ("hop", {"flight_height": True, "max_ground_time": 1.0, "observe_progress": True, "height_scale_fine": 0.01,
                                 "pay_on_landing": True}),
    "leg_env/PlanarLegHop-v2": ("hop", {"flight_height": True, "max_ground_time": 1.0, "observe_progress": True, "height_scale_fine": 0.01,
                                 "pay_on_landing": True, "pay_hops_only": True, "pay_on_next_hop": True}),
    "leg_env/PlanarLegHop-v3": ("hop", {"max_ground_time": 1.0, "observe_progress": True, "height_scale_fine": 0.01, "hold_height": True,
                                 "observe_apex": True}),
}
"""Every current id: ``(task module, kwargs)``; the balance task's ids keep its own entry points."""

ALIASES = {
    # deprecated id: the current id it makes, with a DeprecationWarning (removed in the next release)
    "leg_env/PlanarLegStance-v1": "leg_env/PlanarLegBalance-v0",
}
"""Old ids that still work for one release. ``PlanarLegStance-v1`` was the unilateral balance: a different
contact model is a different task, so it has its own name (``PlanarLegBalance-v0``) rather than a version
of the pinned balance (``PlanarLegStance-v0``, the lesson's model)."""


def get(name: str):
    """The ``Task`` of the module ``leg_env.tasks.<name>``."""
    if not isinstance(name, str) or name not in {module for module, _ in REGISTRY.values()}:
        raise ValueError(f"task must be one of {sorted({module for module, _ in REGISTRY.values()})}, got {name!r}")
    return importlib.import_module(f"{__name__}.{name}").TASK
