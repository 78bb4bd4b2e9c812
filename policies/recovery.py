"""What the recovery controllers (``policies.gated``, ``policies.stepping``) share: the COM from the balance tasks'
observation, and their two parts, the stance LQR and the hopper, built for one task."""

from __future__ import annotations

import numpy as np

from leg_env.physics.params import LegParams
from leg_env.tasks.base import Obs

__all__ = ["com_from_observation", "lqr_and_hopper"]


def com_from_observation(obs, params: LegParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The whole-body COM's ``(x, y, x')`` from observations ``(..., >=10)``: relative to the foot [m], and [m/s].

    Reads the base position (entries 0-1, relative to the contact point), the angles (2-4) and the rates (5-9),
    as ``leg_env.physics.dynamics.com_position`` computes the COM from ``q``:
    ``x_com = x_b + (a cos th1 + b cos th2) / m`` with ``a = m1 c1 + m2 l1``, ``b = m2 c2`` (first moments of the
    leg and the shank about the hip), ``th1 = th_b + q1``, ``th2 = th1 + q2``.
    """
    p = params
    obs = np.asarray(obs, dtype=np.float64)
    m = p.m_b + p.m1 + p.m2
    a, b = p.m1 * p.c1 + p.m2 * p.l1, p.m2 * p.c2
    th1 = obs[..., Obs.th_b] + obs[..., Obs.q1]
    th2 = th1 + obs[..., Obs.q2]
    w1 = obs[..., Obs.w_b] + obs[..., Obs.w_q1]
    w2 = w1 + obs[..., Obs.w_q2]
    x = obs[..., Obs.base_x] + (a * np.cos(th1) + b * np.cos(th2)) / m
    y = obs[..., Obs.base_y] + (a * np.sin(th1) + b * np.sin(th2)) / m
    vx = obs[..., Obs.vx_b] - (a * np.sin(th1) * w1 + b * np.sin(th2) * w2) / m
    return x, y, vx


def lqr_and_hopper(params, config, config_type, gains: dict):
    """``(params, config, lqr, hopper)`` of a recovery controller for one task.

    Args:
        params: the robot (``LegParams``, a dict, or None for the defaults).
        config: the task (a ``config_type`` instance, a dict of its fields, or None for its defaults).
        config_type: the task's config class (``StanceConfig``, ``PushConfig``).
        gains: the hopper's keyword arguments (``policies.gated.HOP_GAINS``, ``policies.stepping.STEP_GAINS``).

    Returns:
        The ``LegParams``, the config, the stance LQR (``policies.lqr``, the config's cost) and the hopper
        (``policies.hopper``) with the task's ``dt``, torque limits, ``mu`` and nominal knee.
    """
    from leg_env.tasks.hop import HopConfig
    from policies.hopper import HopperController
    from policies.lqr import LQRController

    params = LegParams.from_any(params)
    if config is None:
        config = config_type()
    elif isinstance(config, dict):
        config = config_type.from_kwargs(config)
    shared = {k: getattr(config, k) for k in ("dt", "torque_limit", "mu", "nominal_knee") if hasattr(config, k)}
    return params, config, LQRController(params, config), HopperController(params, HopConfig.from_kwargs(shared), **gains)
