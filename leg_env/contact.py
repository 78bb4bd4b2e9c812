r"""Unilateral contact of the point foot with the ground ``y = 0``: modes, slip, impact, Painleve bound.

Notation (``leg_env.dynamics`` states the conventions): ``J = Jc`` with rows ``J_x, J_y``,
``gamma = Jcdot qd``, the contact inertia ``Lambda = J M^-1 J^T`` (2x2 SPD) and the free foot
acceleration ``a0 = J M^-1 (S^T tau - h) + gamma``. A contact force ``lam`` (the ground's force on the
foot) gives the foot acceleration ``a_f = a0 + Lambda lam`` (lesson section 5, and
``shared/notes/contact.md`` section 1).

Modes of a foot on the ground (acceleration-level complementarity ``0 <= y_f'' _|_ lam_y >= 0`` and
Coulomb friction with maximal dissipation); one planar contact needs no LCP solver, the four closed
forms are enumerated:

=================  ==================================================  ==========================================
mode               force                                               consistent iff
=================  ==================================================  ==========================================
``STICK``          ``lam = -Lambda^-1 a0`` (the pinned stance solution)   ``lam_y >= 0`` and ``|lam_x| <= mu lam_y``
``SLIP_FORWARD``   ``lam = lam_y (-sigma mu, 1)``, ``sigma = +1``,         ``k_sigma > 0``, ``lam_y >= 0`` and, from
``SLIP_BACKWARD``  ``sigma = -1``; ``lam_y = -a0_y / k_sigma``,          rest, ``sigma x_f'' >= 0``
                   ``k_sigma = Lambda_yy - sigma mu Lambda_yx``
``FLIGHT``         ``lam = 0``                                          ``a0_y >= 0``
=================  ==================================================  ==========================================

Below the Painleve bound, ``mu < mu_critical(q) = Lambda_yy / |Lambda_xy|``, both ``k_sigma > 0`` and
exactly one mode is consistent. Above it a mode may be missing (a sliding foot with ``k_sigma <= 0``
and ``a0_y < 0`` has no consistent force at all) or several may be consistent. The rule used here
("jam"): a foot at rest with no consistent mode sticks (the ground supplies the sticking force, even
outside the cone); a sliding foot with ``k_sigma <= 0`` leaves the ground if ``a0_y >= 0`` and is
otherwise stopped by a tangential impact (the sticking impulse), after which the at-rest rule
applies. ``leg_env.hybrid`` counts every use.

How it is computed. With the whole-body centre of mass eliminated (as in ``_flight_core``), the
leg's absolute angles ``theta = (th1, th2)`` obey ``K theta'' = r + G^T F`` for a foot force ``F``, with
``K`` the flight inertia, ``r`` the torques and velocity products, and ``G`` the Jacobian of the foot
relative to the COM, ``p_f - p_com = al1 (cos th1, sin th1) + al2 (cos th2, sin th2)``,
``al1 = l1 - a/m``, ``al2 = l2 - b/m``. The COM obeys ``m p_com'' = F - m g e_y`` and the torso turns
by ``th_b'' = -tau_hip / I_b`` whatever ``F`` is. Hence ``Lambda = I/m + G K^-1 G^T`` and
``a0 = -g e_y + G K^-1 r + Gdot theta'``: 2x2 solves by Cramer's rule, nothing is inverted. A horizontal
force ``F`` on the torso's COM (``p[LOAD_X]``) adds ``F e_x / m`` to the COM's acceleration and
``(a s1, b s2) F / m`` to ``r`` (the hip's position relative to the COM, differentiated).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._jit import CACHE
from .dynamics import _CONTACT_NAMES, LOAD_X, NQ, NU, _batched, _flight_inertia, _stance_core, _vec, _kernel_params
from .params import LegParams

__all__ = list(_CONTACT_NAMES)  # leg_env.dynamics re-exports these names

STICK, SLIP_FORWARD, SLIP_BACKWARD, FLIGHT = 0, 1, 2, 3
MODE_NAMES = ("stick", "slip", "slip", "flight")
"""``info["contact_mode"]`` of each mode constant (both slip directions are ``"slip"``)."""
REST_SPEED = 1e-9
"""A foot slower than this [m/s] counts as at rest."""
# Consistency margins within this relative tolerance (of m g, or of g for accelerations) are ties
# broken by the enumeration order, not Painleve cases: round-off at a located transition.
_TIE = 1e-9
# Impact status codes of ``_impact_core``
IMPACT_NONE, IMPACT_STICK, IMPACT_SLIDE, IMPACT_PAINLEVE = 0, 1, 2, 3


@njit(cache=CACHE, inline="always")
def _foot_response(s1, co1, s2, co2, p):
    """The foot's response to a foot force: ``Lambda`` and ``B = K^-1 G^T`` (rows th1, th2; columns x, y).

    Returns ``(Lxx, Lxy, Lyy, B1x, B1y, B2x, B2y, K11, K12, K22, inv_det)``; the last four let
    ``_free_terms`` solve ``K u = r`` with the same factorisation.
    """
    l1, l2 = p[6], p[7]
    m, a, b, kf, K11, K22 = _flight_inertia(p)
    K12 = kf * (co1 * co2 + s1 * s2)
    inv_det = 1.0 / (K11 * K22 - K12 * K12)
    al1 = l1 - a / m
    al2 = l2 - b / m
    g1x, g1y = -al1 * s1, al1 * co1  # d(p_f - p_com)/d th1
    g2x, g2y = -al2 * s2, al2 * co2  # d(p_f - p_com)/d th2
    B1x = (K22 * g1x - K12 * g2x) * inv_det
    B2x = (K11 * g2x - K12 * g1x) * inv_det
    B1y = (K22 * g1y - K12 * g2y) * inv_det
    B2y = (K11 * g2y - K12 * g1y) * inv_det
    Lxx = 1.0 / m + g1x * B1x + g2x * B2x
    Lxy = g1x * B1y + g2x * B2y
    Lyy = 1.0 / m + g1y * B1y + g2y * B2y
    return Lxx, Lxy, Lyy, B1x, B1y, B2x, B2y, K11, K12, K22, inv_det


@njit(cache=CACHE, inline="always")
def _free_terms(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, K11, K12, K22, inv_det, p):
    """Free leg accelerations ``u = K^-1 r`` and the free foot acceleration ``a0``; returns ``(u1, u2, a0x, a0y)``."""
    l1, l2, g = p[6], p[7], p[10]
    m, a, b, kf, _, _ = _flight_inertia(p)
    al1 = l1 - a / m
    al2 = l2 - b / m
    s12 = s1 * co2 - co1 * s2
    v1 = w1 * w1
    v2 = w2 * w2
    r1 = (tau_hip - tau_knee) - kf * s12 * v2
    r2 = tau_knee + kf * s12 * v1
    F = p[LOAD_X]  # horizontal force on the torso's COM: (a s1, b s2) F / m on the leg, F / m on the COM
    if F != 0.0:
        r1 += F * a * s1 / m
        r2 += F * b * s2 / m
    u1 = (K22 * r1 - K12 * r2) * inv_det
    u2 = (K11 * r2 - K12 * r1) * inv_det
    a0x = -al1 * (s1 * u1 + co1 * v1) - al2 * (s2 * u2 + co2 * v2) + F / m
    a0y = al1 * (co1 * u1 - s1 * v1) + al2 * (co2 * u2 - s2 * v2) - g
    return u1, u2, a0x, a0y


@njit(cache=CACHE, inline="always")
def _forced_accel(s1, co1, s2, co2, w1, w2, u1, u2, B1x, B1y, B2x, B2y, Fx, Fy, tau_hip, p):
    """``qdd[0..4]`` under the foot force ``F`` from the free leg accelerations ``u`` and ``B``."""
    m_b, m1, m2, I_b = p[0], p[1], p[2], p[3]
    l1, c1, c2, g = p[6], p[8], p[9], p[10]
    m = m_b + m1 + m2
    a = m1 * c1 + m2 * l1
    b = m2 * c2
    dd1 = u1 + B1x * Fx + B1y * Fy
    dd2 = u2 + B2x * Fx + B2y * Fy
    # x_b = x_com - (a cos th1 + b cos th2) / m, and likewise y_b; m p_com'' = F - m g e_y
    xdd = (Fx + a * (co1 * w1 * w1 + s1 * dd1) + b * (co2 * w2 * w2 + s2 * dd2) + p[LOAD_X]) / m
    ydd = (Fy + a * (s1 * w1 * w1 - co1 * dd1) + b * (s2 * w2 * w2 - co2 * dd2)) / m - g
    thbdd = -tau_hip / I_b
    return xdd, ydd, thbdd, dd1 - thbdd, dd2 - dd1


@njit(cache=CACHE, inline="always")
def _slip_core(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, mu, sigma, p):
    """Slip dynamics in direction ``sigma``: ``(qdd[0..4], lam_x, lam_y)``, the inputs of ``_stance_core``.

    Only ``y_f'' = 0`` is enforced; ``lam = lam_y (-sigma mu, 1)`` with ``lam_y = -a0_y / k_sigma``.
    """
    Lxx, Lxy, Lyy, B1x, B1y, B2x, B2y, K11, K12, K22, inv_det = _foot_response(s1, co1, s2, co2, p)
    u1, u2, a0x, a0y = _free_terms(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, K11, K12, K22, inv_det, p)
    k = Lyy - sigma * mu * Lxy
    lam_y = -a0y / k
    lam_x = -sigma * mu * lam_y
    xdd, ydd, thbdd, q1dd, q2dd = _forced_accel(s1, co1, s2, co2, w1, w2, u1, u2, B1x, B1y, B2x, B2y, lam_x, lam_y, tau_hip, p)
    return xdd, ydd, thbdd, q1dd, q2dd, lam_x, lam_y


@njit(cache=CACHE, inline="always")
def _foot_velocity(s1, co1, s2, co2, vx, vy, w1, w2, p):
    """``v_f = J qd`` from the base velocity and the link rates."""
    l1, l2 = p[6], p[7]
    return vx - l1 * s1 * w1 - l2 * s2 * w2, vy + l1 * co1 * w1 + l2 * co2 * w2


@njit(cache=CACHE, inline="always")
def _impulse_velocity(s1, co1, s2, co2, B1x, B1y, B2x, B2y, Px, Py, p):
    """Velocity jump ``M^-1 J^T P`` of a foot impulse ``P``: ``(d x_b', d y_b', d th_b', d q1', d q2')``."""
    m_b, m1, m2, l1, c1, c2 = p[0], p[1], p[2], p[6], p[8], p[9]
    m = m_b + m1 + m2
    a = m1 * c1 + m2 * l1
    b = m2 * c2
    dw1 = B1x * Px + B1y * Py
    dw2 = B2x * Px + B2y * Py
    # x_b' = x_com' + (a sin th1 th1' + b sin th2 th2') / m, y_b' = y_com' - (a cos th1 th1' + b cos th2 th2') / m
    return (Px + a * s1 * dw1 + b * s2 * dw2) / m, (Py - a * co1 * dw1 - b * co2 * dw2) / m, 0.0, dw1, dw2 - dw1


@njit(cache=CACHE)
def _impact_core(vfx, vfy, mu, Lxx, Lxy, Lyy):
    """Plastic (``e = 0``) foot impulse ``(Px, Py, status)`` for the foot velocity ``v_f-``.

    ``mu = inf``: the bilateral sticking impulse ``-Lambda^-1 v_f-`` for any velocity. Finite ``mu``: no
    impulse unless the foot approaches (``v_fy- < 0``); the sticking impulse when it lies in the cone;
    otherwise Routh's incremental sliding impact (see ``impact_map``). ``status`` is one of
    ``IMPACT_NONE, IMPACT_STICK, IMPACT_SLIDE, IMPACT_PAINLEVE``.
    """
    det = Lxx * Lyy - Lxy * Lxy
    Px = -(Lyy * vfx - Lxy * vfy) / det
    Py = -(Lxx * vfy - Lxy * vfx) / det
    if math.isinf(mu):
        return Px, Py, IMPACT_STICK
    if not vfy < 0.0:
        return 0.0, 0.0, IMPACT_NONE
    if Py >= 0.0 and abs(Px) <= mu * Py:
        return Px, Py, IMPACT_STICK
    sigma = 1.0 if vfx > 0.0 else (-1.0 if vfx < 0.0 else (1.0 if Px < 0.0 else -1.0))
    k = Lyy - sigma * mu * Lxy  # d v_fy / d P_y while sliding in direction sigma
    if k <= 0.0:
        return Px, Py, IMPACT_PAINLEVE
    r = Lxy - sigma * mu * Lxx  # d v_fx / d P_y while sliding
    p_end = -vfy / k
    if sigma * (vfx + r * p_end) >= 0.0:  # slides the whole impact
        return -sigma * mu * p_end, p_end, IMPACT_SLIDE
    p1 = -vfx / r  # sliding stops here, with the foot still approaching
    vfy1 = vfy + k * p1
    if abs(Lxy) <= mu * Lxx:  # then sticks: dPx = -(Lxy / Lxx) dPy keeps v_fx = 0
        p2 = -vfy1 * Lxx / det
        return -sigma * mu * p1 - (Lxy / Lxx) * p2, p1 + p2, IMPACT_SLIDE
    s2 = 1.0 if Lxy > 0.0 else -1.0  # else slides back, the way a normal impulse pushes the foot
    k2 = Lyy - s2 * mu * Lxy
    if k2 <= 0.0:
        return Px, Py, IMPACT_PAINLEVE
    p2 = -vfy1 / k2
    return -sigma * mu * p1 - s2 * mu * p2, p1 + p2, IMPACT_SLIDE


@njit(cache=CACHE)
def _mode_at_rest(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, mu, p, exclude):
    """The consistent mode of a foot at rest on the ground, by enumeration; returns ``(mode, painleve)``.

    Candidates in the order stick, slip, flight (``exclude``: a mode that a located transition has
    just made inconsistent, or -1). Margins within ``_TIE`` of zero count as consistent; with no
    consistent candidate (only above the Painleve bound) the foot sticks and ``painleve`` is True.
    """
    m = p[0] + p[1] + p[2]
    f_scale = m * max(p[10], 1.0)  # forces: weight (or mass x 1 m/s^2 without gravity)
    a_scale = max(p[10], 1.0)
    tie = -_TIE
    _, _, _, _, _, lam_x, lam_y = _stance_core(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, p)
    if exclude != STICK and lam_y / f_scale >= tie and (mu * lam_y - abs(lam_x)) / f_scale >= tie:
        return STICK, False
    Lxx, Lxy, Lyy, B1x, B1y, B2x, B2y, K11, K12, K22, inv_det = _foot_response(s1, co1, s2, co2, p)
    _, _, a0x, a0y = _free_terms(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, K11, K12, K22, inv_det, p)
    # the slip opposite to the friction force the stick needed first
    first = -1.0 if lam_x > 0.0 else 1.0
    for sigma in (first, -first):
        mode = SLIP_FORWARD if sigma > 0.0 else SLIP_BACKWARD
        k = Lyy - sigma * mu * Lxy
        if mode == exclude or k <= 0.0:
            continue
        ly = -a0y / k
        xdd = a0x + (Lxy - sigma * mu * Lxx) * ly
        if ly / f_scale >= tie and sigma * xdd / a_scale >= tie:
            return mode, False
    if exclude != FLIGHT and a0y / a_scale >= tie:
        return FLIGHT, False
    return STICK, True


@njit(cache=CACHE)
def _mode_sliding(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, mu, sigma, p):
    """Mode of a foot sliding on the ground in direction ``sigma``: ``(mode, painleve)``.

    ``SLIP`` if its normal force is compressive, else ``FLIGHT``. Past the Painleve bound
    (``k_sigma <= 0``): ``FLIGHT`` if ``a0_y >= 0``, else ``-1``: no consistent force, the caller stops the
    foot by a tangential impact.
    """
    Lxx, Lxy, Lyy, B1x, B1y, B2x, B2y, K11, K12, K22, inv_det = _foot_response(s1, co1, s2, co2, p)
    _, _, _, a0y = _free_terms(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, K11, K12, K22, inv_det, p)
    k = Lyy - sigma * mu * Lxy
    if k <= 0.0:
        return (FLIGHT, True) if a0y >= 0.0 else (-1, True)
    if a0y <= 0.0:  # lam_y = -a0y / k >= 0
        return (SLIP_FORWARD if sigma > 0.0 else SLIP_BACKWARD), False
    return FLIGHT, False


@njit(cache=CACHE, inline="always")
def _trig(q):
    """``sin th1, cos th1, sin th2, cos th2`` of one configuration."""
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    return np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2)


@njit(cache=CACHE)
def _slip_batch(q, qd, tau, mu, sigma, p, qdd, lam):
    for i in range(q.shape[0]):
        s1, co1, s2, co2 = _trig(q[i])
        w1 = qd[i, 2] + qd[i, 3]
        w2 = w1 + qd[i, 4]
        qdd[i, 0], qdd[i, 1], qdd[i, 2], qdd[i, 3], qdd[i, 4], lam[i, 0], lam[i, 1] = _slip_core(
            s1, co1, s2, co2, w1, w2, tau[i, 0], tau[i, 1], mu[i], sigma[i], p
        )


@njit(cache=CACHE)
def _impact_batch(q, qd, mu, p, qd_plus, impulse, status):
    for i in range(q.shape[0]):
        s1, co1, s2, co2 = _trig(q[i])
        w1 = qd[i, 2] + qd[i, 3]
        w2 = w1 + qd[i, 4]
        Lxx, Lxy, Lyy, B1x, B1y, B2x, B2y, _, _, _, _ = _foot_response(s1, co1, s2, co2, p)
        vfx, vfy = _foot_velocity(s1, co1, s2, co2, qd[i, 0], qd[i, 1], w1, w2, p)
        Px, Py, status[i] = _impact_core(vfx, vfy, mu[i], Lxx, Lxy, Lyy)
        d = _impulse_velocity(s1, co1, s2, co2, B1x, B1y, B2x, B2y, Px, Py, p)
        for j in range(5):
            qd_plus[i, j] = qd[i, j] + d[j]
        impulse[i, 0] = Px
        impulse[i, 1] = Py


@njit(cache=CACHE)
def _mode_batch(q, qd, tau, mu, p, out):
    for i in range(q.shape[0]):
        s1, co1, s2, co2 = _trig(q[i])
        w1 = qd[i, 2] + qd[i, 3]
        w2 = w1 + qd[i, 4]
        vfx, _ = _foot_velocity(s1, co1, s2, co2, qd[i, 0], qd[i, 1], w1, w2, p)
        if abs(vfx) <= REST_SPEED:
            out[i] = _mode_at_rest(s1, co1, s2, co2, w1, w2, tau[i, 0], tau[i, 1], mu[i], p, -1)[0]
        else:
            mode = _mode_sliding(s1, co1, s2, co2, w1, w2, tau[i, 0], tau[i, 1], mu[i], 1.0 if vfx > 0.0 else -1.0, p)[0]
            out[i] = FLIGHT if mode < 0 else mode


@njit(cache=CACHE)
def _response_batch(q, qd, tau, p, Lam, a0):
    for i in range(q.shape[0]):
        s1, co1, s2, co2 = _trig(q[i])
        w1 = qd[i, 2] + qd[i, 3]
        w2 = w1 + qd[i, 4]
        Lxx, Lxy, Lyy, _, _, _, _, K11, K12, K22, inv_det = _foot_response(s1, co1, s2, co2, p)
        _, _, a0[i, 0], a0[i, 1] = _free_terms(s1, co1, s2, co2, w1, w2, tau[i, 0], tau[i, 1], K11, K12, K22, inv_det, p)
        Lam[i, 0, 0], Lam[i, 0, 1], Lam[i, 1, 0], Lam[i, 1, 1] = Lxx, Lxy, Lxy, Lyy


def _scalar_field(x, lead, name: str) -> np.ndarray:
    """A per-robot scalar (``mu``, ``sigma``) broadcast to the batch, as a flat float64 array."""
    a = np.asarray(x, dtype=np.float64)
    try:
        return np.ascontiguousarray(np.broadcast_to(a, lead).reshape(-1))
    except ValueError as e:
        raise ValueError(f"{name} must broadcast to the batch shape {lead}, got shape {a.shape}") from e


def _checked_mu(mu, lead, allow_inf: bool = False) -> np.ndarray:
    m = _scalar_field(mu, lead, "mu")
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
    lead, (qf, qdf, tf) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"), _vec(tau, NU, "tau"))
    sg = _scalar_field(sigma, lead, "sigma")
    if not np.all(np.abs(sg) == 1.0):
        raise ValueError(f"sigma must be +1 or -1, got {sigma!r}")
    mu_f = _checked_mu(mu, lead)
    n = qf.shape[0]
    qdd, lam = np.empty((n, NQ)), np.empty((n, 2))
    _slip_batch(qf, qdf, tf, mu_f, sg, _kernel_params(p), qdd, lam)
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
    lead, (qf, qdf) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"))
    mu_f = _checked_mu(mu, lead, allow_inf=True)
    n = qf.shape[0]
    qd_plus, impulse, status = np.empty((n, NQ)), np.empty((n, 2)), np.empty(n, dtype=np.int64)
    _impact_batch(qf, qdf, mu_f, _kernel_params(p), qd_plus, impulse, status)
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
    lead, (qf, qdf, tf) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"), _vec(tau, NU, "tau"))
    mu_f = _checked_mu(mu, lead)
    out = np.empty(qf.shape[0], dtype=np.int64)
    _mode_batch(qf, qdf, tf, mu_f, _kernel_params(p), out)
    return out.reshape(lead)


def free_foot_acceleration(q, qd, tau, p: LegParams) -> tuple[np.ndarray, np.ndarray]:
    """``(Lambda, a0)``: the contact inertia ``J M^-1 J^T`` ``(..., 2, 2)`` and the free foot acceleration ``(..., 2)``."""
    lead, (qf, qdf, tf) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"), _vec(tau, NU, "tau"))
    n = qf.shape[0]
    Lam, a0 = np.empty((n, 2, 2)), np.empty((n, 2))
    _response_batch(qf, qdf, tf, _kernel_params(p), Lam, a0)
    return Lam.reshape(lead + (2, 2)), a0.reshape(lead + (2,))


def mu_critical(q, p: LegParams) -> np.ndarray:
    """Painleve bound ``Lambda_yy / |Lambda_xy|`` [1], shape ``(...)``: sliding is well posed iff ``mu < mu_critical``.

    ``inf`` where ``Lambda_xy = 0``. It depends only on the absolute leg angles.
    """
    q = _vec(q, NQ, "q")
    Lam, _ = free_foot_acceleration(q, np.zeros(q.shape), np.zeros(q.shape[:-1] + (NU,)), p)
    with np.errstate(divide="ignore"):
        return Lam[..., 1, 1] / np.abs(Lam[..., 0, 1])
