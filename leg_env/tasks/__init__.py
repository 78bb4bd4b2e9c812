"""The tasks: one module per task (``leg_env.tasks.<name>``), and the table of registered ids.

Importing this package is cheap: a task module loads on first use
(``get``). ``REGISTRY`` maps each Gymnasium id to its task module and the keyword arguments the id
fixes; ``leg_env/__init__.py`` registers every entry. Adding a task is its module plus its line here.
"""

from __future__ import annotations

import importlib

__all__ = ["REGISTRY", "get"]

REGISTRY = {
    # id: (task module, keyword arguments of the id)
    "leg_env/PlanarLegStance-v0": ("stance", {}),
    "leg_env/PlanarLegBalance-v1": ("stance", {"contact": "unilateral", "reset_noise_scale": 0.05, "unilateral_weight": 2.0,
                                               "drift_angle_weight": 10.0, "ctrl_cost_weight": 0.05,
                                               "action_change_weight": 0.2, "observe_action": True}),
    "leg_env/PlanarLegPush-v2": ("push", {}),
    "leg_env/PlanarLegHop-v4": ("hop", {}),
}
"""Every id, one per task: ``(task module, kwargs)``. A change to a task's dynamics or reward takes a new version
and removes the old one (``CHANGELOG.md`` lists each); Gymnasium answers an older version of a name with an
error naming the current one."""


def get(name: str):
    """The ``Task`` of the module ``leg_env.tasks.<name>``."""
    if not isinstance(name, str) or name not in {module for module, _ in REGISTRY.values()}:
        raise ValueError(f"task must be one of {sorted({module for module, _ in REGISTRY.values()})}, got {name!r}")
    return importlib.import_module(f"{__name__}.{name}").TASK
