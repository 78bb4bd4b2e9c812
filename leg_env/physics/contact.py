r"""Unilateral contact of the point foot with the ground ``y = 0``: modes, slip, impact, Painleve bound.

Notation (``leg_env.physics.dynamics`` states the conventions): ``J = Jc`` with rows ``J_x, J_y``,
``gamma = Jcdot qd``, the contact inertia ``Lambda = J M^-1 J^T`` (2x2 SPD) and the free foot
acceleration ``a0 = J M^-1 (S^T tau - h) + gamma``. A contact force ``lam`` (the ground's force on the
foot) gives the foot acceleration ``a_f = a0 + Lambda lam`` (lesson section 5).

Modes of a foot on the ground (acceleration-level complementarity ``0 <= y_f'' _|_ lam_y >= 0`` and
Coulomb friction with maximal dissipation); one planar contact needs no LCP solver, the four closed
forms are enumerated:

=================  ======================================================  ==========================================
mode               force                                                   consistent iff
=================  ======================================================  ==========================================
``STICK``          ``lam = -Lambda^-1 a0`` (the pinned stance solution)    ``lam_y >= 0`` and ``|lam_x| <= mu lam_y``
``SLIP_FORWARD``   ``lam = lam_y (-sigma mu, 1)``, ``sigma = +1``,         ``k_sigma > 0``, ``lam_y >= 0`` and, from
``SLIP_BACKWARD``  ``sigma = -1``; ``lam_y = -a0_y / k_sigma``,            rest, ``sigma x_f'' >= 0``
                   ``k_sigma = Lambda_yy - sigma mu Lambda_yx``
``FLIGHT``         ``lam = 0``                                             ``a0_y >= 0``
=================  ======================================================  ==========================================

Below the Painleve bound, ``mu < mu_critical(q) = Lambda_yy / |Lambda_xy|``, both ``k_sigma > 0`` and
exactly one mode is consistent. Above it a mode may be missing (a sliding foot with ``k_sigma <= 0``
and ``a0_y < 0`` has no consistent force at all) or several may be consistent. The rule used here
("jam"): a foot at rest with no consistent mode sticks (the ground supplies the sticking force, even
outside the cone); a sliding foot with ``k_sigma <= 0`` leaves the ground if ``a0_y >= 0`` and is
otherwise stopped by a tangential impact (the sticking impulse), after which the at-rest rule
applies. ``leg_env.physics.hybrid`` counts every use.

How it is computed. With the whole-body centre of mass eliminated (as in ``_flight_core``), the
leg's absolute angles ``theta = (th1, th2)`` obey ``K theta'' = r + G^T F`` for a foot force ``F``, with
``K`` the flight inertia, ``r`` the torques and velocity products, and ``G`` the Jacobian of the foot
relative to the COM, ``p_f - p_com = al1 (cos th1, sin th1) + al2 (cos th2, sin th2)``,
``al1 = l1 - a/m``, ``al2 = l2 - b/m``. The COM obeys ``m p_com'' = F - m g e_y`` and the torso turns
by ``th_b'' = -tau_hip / I_b`` whatever ``F`` is. Hence ``Lambda = I/m + G K^-1 G^T`` and
``a0 = -g e_y + G K^-1 r + Gdot theta'``: 2x2 solves by Cramer's rule, nothing is inverted. A horizontal
force ``F`` on the torso's COM (``p[LOAD_X]``) adds ``F e_x / m`` to the COM's acceleration and
``(a s1, b s2) F / m`` to ``r`` (the hip's position relative to the COM, differentiated).

Every function here runs in the compiled core (``leg_env/_core``, C, built at install); this module
broadcasts and validates the arrays around it.
"""

from __future__ import annotations

import math

import numpy as np

from .. import checks
from .._core import kernels
from .arrays import NQ, NU, batched, core_params, vec
from .params import LegParams

__all__ = ["STICK", "SLIP_FORWARD", "SLIP_BACKWARD", "FLIGHT", "MODE_NAMES", "REST_SPEED", "slip_dynamics",
           "impact_map", "contact_mode", "mu_critical", "free_foot_acceleration"]

STICK, SLIP_FORWARD, SLIP_BACKWARD, FLIGHT = kernels.STICK, kernels.SLIP_FORWARD, kernels.SLIP_BACKWARD, kernels.FLIGHT
MODE_NAMES = ("stick", "slip", "slip", "flight")
"""``info["contact_mode"]`` of each mode constant (both slip directions are ``"slip"``)."""
REST_SPEED = kernels.REST_SPEED
"""A foot slower than this [m/s] counts as at rest."""


def scalar_field(x, lead, name: str) -> np.ndarray:
    """A per-robot scalar (``mu``, ``sigma``) broadcast to the batch, as a flat float64 array (real numbers only,
    ``leg_env.checks.real_array``)."""
    a = checks.real_array(name, x, f"a real number or one per robot of the batch {lead}")
    try:
        return np.ascontiguousarray(np.broadcast_to(a, lead).reshape(-1))
    except ValueError as e:
        raise ValueError(f"{name} must broadcast to the batch shape {lead}, got shape {a.shape}") from e


def checked_mu(mu, lead, allow_inf: bool = False) -> np.ndarray:
    m = scalar_field(mu, lead, "mu")
    if np.any(np.isnan(m)) or np.any(m < 0.0) or (not allow_inf and np.any(np.isinf(m))):
        raise ValueError(f"mu must be >= 0 and {'not NaN' if allow_inf else 'finite'}, got {mu!r}")
    return m


def slip_dynamics(q, qd, tau, p: LegParams, mu, sigma):
    """Dynamics of a foot sliding on the ground in direction ``sigma`` (``+1``: +x, ``-1``: -x).

    Only the normal constraint ``y_f'' = 0`` holds; Coulomb friction opposes the sliding:
    ``lam = lam_y (-sigma mu, 1)`` with ``lam_y = -a0_y / k_sigma``, ``k_sigma = Lambda_yy - sigma mu Lambda_yx``
    (the non-symmetric KKT system ``[[M, -(J_y - sigma mu J_x)^T], [J_y, 0]] [qdd; lam_y] = [S^T tau - h; -gamma_y]``).
    Consistency (``lam_y >= 0``, ``k_sigma > 0``) is not checked: see ``contact_mode``.

    Args:
        q, qd: ``(..., 5)`` state with the foot on the ground. tau: ``(..., 2)`` torques [N m].
        p: physical parameters. mu: friction coefficient (>= 0), sigma: sliding direction, ``+-1``;
            both scalars or arrays broadcasting over the leading axes.

    Returns:
        ``(qdd, lam)`` of shapes ``(..., 5)`` and ``(..., 2)``; ``lam`` is the ground's force on the foot [N].
    """
    lead, (qf, qdf, tf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")), ("tau", vec(tau, NU, "tau")))
    sg = scalar_field(sigma, lead, "sigma")
    if not np.all(np.abs(sg) == 1.0):
        raise ValueError(f"sigma must be +1 or -1, got {sigma!r}")
    mu_f = checked_mu(mu, lead)
    n = qf.shape[0]
    qdd, lam = np.empty((n, NQ)), np.empty((n, 2))
    kernels.slip(qf, qdf, tf, mu_f, sg, core_params(p), np.zeros(n), qdd, lam)
    return qdd.reshape(lead + (NQ,)), lam.reshape(lead + (2,))


def impact_map(q, qd, p: LegParams, mu=math.inf):
    """Plastic (``e = 0``) impact of the foot with the ground at configuration ``q``.

    ``mu = inf`` is the sticking map for any velocity: ``P = -Lambda^-1 v_f-``,
    ``qd+ = qd- + M^-1 J^T P``, so ``J qd+ = 0`` (Pinocchio's ``impulseDynamics`` with restitution 0).
    With a finite ``mu`` the impact is unilateral and frictional: no impulse unless the foot
    approaches (``v_fy- < 0``); the sticking impulse when ``P_y >= 0`` and ``|P_x| <= mu P_y``; otherwise a
    sliding impact by Routh's incremental method: sliding in ``sigma = sign(v_fx-)`` the impulse grows
    along ``(-sigma mu, 1)``; if the tangential velocity reaches zero before the normal one, the rest is
    a sticking phase (``dP_x = -(Lambda_xy / Lambda_xx) dP_y``) when ``|Lambda_xy / Lambda_xx| <= mu``, else
    reversed sliding; the impact ends when ``v_fy = 0``. It never adds energy; the kinetic energy lost
    is ``-1/2 P^T (v_f- + v_f+)`` (``1/2 v_f-^T Lambda^-1 v_f-`` when sticking). Past the Painleve bound
    (a sliding phase with ``k_sigma <= 0``) the sticking impulse is used.

    Args:
        q, qd: ``(..., 5)`` state just before the impact (the foot on the ground). p: parameters.
        mu: friction coefficient (``>= 0``, may be ``inf``), scalar or per robot.

    Returns:
        ``(qd_plus, impulse)``: ``(..., 5)`` velocity after the impact and ``(..., 2)`` the ground's
        impulse on the foot [N s].
    """
    lead, (qf, qdf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")))
    mu_f = checked_mu(mu, lead, allow_inf=True)
    n = qf.shape[0]
    qd_plus, impulse, status = np.empty((n, NQ)), np.empty((n, 2)), np.empty(n, dtype=np.int64)
    kernels.impact(qf, qdf, mu_f, core_params(p), qd_plus, impulse, status)
    return qd_plus.reshape(lead + (NQ,)), impulse.reshape(lead + (2,))


def contact_mode(q, qd, tau, p: LegParams, mu) -> np.ndarray:
    """The consistent contact mode of a foot on the ground under the torques ``tau``.

    A foot at rest (``|v_fx| <= REST_SPEED``) gets the one mode of ``STICK``, ``SLIP_BACKWARD``,
    ``SLIP_FORWARD``, ``FLIGHT`` that satisfies its consistency conditions (module docstring; exactly one
    does when ``mu < mu_critical(q)``); if none does (past the Painleve bound) ``STICK`` (the "jam"
    rule). A sliding foot keeps sliding in ``sign(v_fx)`` if its normal force is compressive, else
    ``FLIGHT`` (also past the bound). The foot's height and normal velocity are not read.

    Returns:
        int64 array of shape ``(...)`` (0-d for one robot): the mode constants of this module.
    """
    lead, (qf, qdf, tf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")), ("tau", vec(tau, NU, "tau")))
    mu_f = checked_mu(mu, lead)
    out = np.empty(qf.shape[0], dtype=np.int64)
    kernels.contact_mode(qf, qdf, tf, mu_f, core_params(p), out)
    return out.reshape(lead)


def free_foot_acceleration(q, qd, tau, p: LegParams) -> tuple[np.ndarray, np.ndarray]:
    """``(Lambda, a0)``: the contact inertia ``J M^-1 J^T`` ``(..., 2, 2)`` and the free foot acceleration ``(..., 2)``."""
    lead, (qf, qdf, tf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")), ("tau", vec(tau, NU, "tau")))
    n = qf.shape[0]
    Lam, a0 = np.empty((n, 2, 2)), np.empty((n, 2))
    kernels.response(qf, qdf, tf, core_params(p), Lam, a0)
    return Lam.reshape(lead + (2, 2)), a0.reshape(lead + (2,))


def mu_critical(q, p: LegParams) -> np.ndarray:
    """Painleve bound ``Lambda_yy / |Lambda_xy|`` [1], shape ``(...)``: sliding is well posed iff ``mu < mu_critical``.

    ``inf`` where ``Lambda_xy = 0``. It depends only on the absolute leg angles.
    """
    q = vec(q, NQ, "q")
    Lam, _ = free_foot_acceleration(q, np.zeros(q.shape), np.zeros(q.shape[:-1] + (NU,)), p)
    with np.errstate(divide="ignore"):
        return Lam[..., 1, 1] / np.abs(Lam[..., 0, 1])
