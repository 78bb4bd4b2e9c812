"""The planar floating-base leg's physics: its model and its time stepping (lesson sections 1-5).

Everything a user of the dynamics needs is importable from here::

    from leg_env.physics import LegParams, stance_dynamics, hybrid_step, stance_step_jacobians

=================== ================================================================================
module              what it holds
=================== ================================================================================
``params``          ``LegParams``: masses, inertias, lengths and gravity (a frozen dataclass)
``dynamics``        ``M``, ``h``, ``Jc``, ``Jcdot qd``, the stance (pinned) and flight solves, COM, energy,
                    the static equilibrium
``contact``         the unilateral ground: contact modes, the slip solve, the impact map, the Painleve bound
``integrate``       the pinned foot's (and free flight's) RK4 control step with exact contact projection
``hybrid``          the control step on the unilateral ground: every contact event located inside the step
``derivatives``     the Jacobians of the control step as computed, ``d(q, qd)`` after it by ``(q, qd)`` and ``tau``
``layout``          the numpy dtypes of the compiled core's structs (a robot, its state, what a step gives)
``arrays``          the broadcasting and checks every function above applies to its arrays
=================== ================================================================================

Conventions (stated once, in ``leg_env.physics.dynamics``): ``q = [x_b, y_b, th_b, q1, q2]``,
``M(q) qdd + h(q, qd) = S^T tau + Jc^T lam`` with ``h`` holding Coriolis, centrifugal **and** gravity terms,
``lam = [lam_x, lam_y]`` the ground's force on the foot. Every function takes one robot or a batch with leading
axes and runs in the compiled core (``leg_env/_core``, C); nothing here imports Gymnasium.
"""

import importlib

_HOMES = {
    "arrays": ("NQ", "NU", "NP", "LOAD_X", "params_array"),
    "params": ("LegParams", "PARAM_NAMES", "PARAM_RANGE", "G_MIN"),
    "dynamics": ("S", "mass_matrix", "bias_forces", "gravity_forces", "contact_jacobian", "contact_jdot_qd", "foot_position",
                 "contact_inertia", "stance_dynamics", "flight_dynamics", "kinetic_energy", "potential_energy", "com_position", "com_state",
                 "static_equilibrium"),
    "contact": ("STICK", "SLIP_FORWARD", "SLIP_BACKWARD", "FLIGHT", "MODE_NAMES", "REST_SPEED", "slip_dynamics", "impact_map",
                "contact_mode", "mu_critical", "free_foot_acceleration"),
    "integrate": ("DT", "SUBSTEPS", "MAX_ANGLE", "MAX_SUBSTEPS", "stance_step", "flight_step", "project_stance", "project_velocity",
                  "step_inplace"),
    "hybrid": ("hybrid_step", "HybridStep", "LIFTOFF", "SLIP_ONSET", "SLIDING_STOP", "TOUCHDOWN", "EVENT_NAMES", "MAX_EVENTS",
               "LOG_SIZE", "GROUND_TOL", "SETTLE_SPEED", "ROOT_TIME"),
    "derivatives": ("StepJacobians", "HybridJacobians", "stance_step_jacobians", "flight_step_jacobians", "hybrid_step_jacobians"),
}
_HOME = {name: module for module, names in _HOMES.items() for name in names}
__all__ = list(_HOME)


def __getattr__(name: str):
    # each module loads on first use, so that ``import leg_env`` (which needs only ``LegParams``) stays cheap
    if name in _HOME:
        value = getattr(importlib.import_module(f"{__name__}.{_HOME[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
