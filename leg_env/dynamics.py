r"""Analytic floating-base dynamics of the planar leg (lesson sections 1-5).

Conventions, stated once:

* ``q = [x_b, y_b, th_b, q1, q2]``: torso COM position (the hip sits there),
  torso angle, hip angle (thigh relative to torso), knee angle (shank relative
  to thigh). ``qd``, ``qdd`` are its first and second time derivatives.
  Absolute link angles are ``th1 = th_b + q1`` and ``th2 = th1 + q2``; a link at
  absolute angle ``th`` points along ``(cos th, sin th)`` from its proximal joint.
* ``tau = [tau_hip, tau_knee]``; ``S = [0_{2x3} I_2]`` so ``S^T tau = [0, 0, 0, tau_hip, tau_knee]``
  (section 2, Problem 2).
* Equations of motion (section 4)::

      M(q) qdd + h(q, qd) = S^T tau + Jc(q)^T lam
      Jc(q) qdd + Jcdot(q, qd) qd = 0

  ``h`` holds Coriolis, centrifugal **and** gravity terms. ``lam = [lam_x, lam_y]``
  is the ground's force on the foot, world frame; ``lam_y > 0`` pushes up.
  As the KKT system::

      [ M   -Jc^T ] [qdd]   [S^T tau - h ]
      [ Jc    0   ] [lam] = [-Jcdot qd   ]

* Gravity acts along ``-y``; ``P = g (m_b y_b + m1 y_c1 + m2 y_c2)``.
* An external horizontal force ``F`` on the torso's COM (a push; ``p[LOAD_X]`` of the kernels' parameter
  array, 0 unless a task sets it) adds the generalised force ``Q = J_b^T (F, 0)`` to the right-hand side,
  ``J_b = d(x_b, y_b)/dq``. The torso's COM is the base point, so ``J_b = [I_2 0]`` and
  ``Q = (F, 0, 0, 0, 0)``: it moves the base, and exerts no torque on the torso about its COM.

Every public function takes one robot (``q`` of shape ``(5,)``) or a batch with
leading axes (``(..., 5)``); ``q``, ``qd`` and ``tau`` broadcast over the leading
axes, and outputs carry the broadcast leading shape.

How it is computed: in absolute coordinates ``z = (x_b, y_b, th_b, th1, th2) = T q``
the mass matrix ``A`` is sparse, ``M = T^T A T`` and ``h = T^T h_z``. The hip is at
the torso's COM, so the torso row decouples: ``th_b'' = -tau_hip / I_b`` in
flight and in stance. In stance the contact fixes ``(x_b, y_b)'' = -Jcdot qd - J_leg
(th1'', th2'')``, which leaves a 2x2 symmetric positive definite system in the leg
angles: the inverted double pendulum of shank and thigh about the foot, carrying the
torso's mass at the hip (``_stance_core`` writes it out). Flight leaves another 2x2
system. Nothing is inverted: each 2x2 system is solved by Cramer's rule.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._jit import CACHE
from .params import LegParams

__all__ = [
    "NQ",
    "NU",
    "S",
    "mass_matrix",
    "bias_forces",
    "gravity_forces",
    "contact_jacobian",
    "contact_jdot_qd",
    "foot_position",
    "contact_inertia",
    "stance_dynamics",
    "flight_dynamics",
    "kinetic_energy",
    "potential_energy",
    "com_position",
    "params_array",
    "static_equilibrium",
]

NQ = 5  # generalized coordinates
NU = 2  # actuated joints
NP = 11  # LegParams fields in the kernels' parameter array
LOAD_X = NP  # the kernels' parameter array ends with the horizontal force on the torso's COM [N] (``params_array``)
S = np.array([[0.0, 0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0]])
S.setflags(write=False)

# z = T q with z = (x_b, y_b, th_b, th1, th2)
_T = np.array(
    [
        [1.0, 0.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 1.0, 0.0],
        [0.0, 0.0, 1.0, 1.0, 1.0],
    ]
)


# ----------------------------------------------------------------------------
# Single-robot kernels (one implementation of the math; batch loops call these)
# ----------------------------------------------------------------------------


@njit(cache=CACHE, fastmath=False, inline="always")
def _leg_terms(q, qd, p):
    """Shared trigonometry, angular rates and inertial constants of one robot."""
    m_b, m1, m2 = p[0], p[1], p[2]
    l1, c1, c2 = p[6], p[8], p[9]
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    w1 = qd[2] + qd[3]
    w2 = w1 + qd[4]
    m = m_b + m1 + m2
    a = m1 * c1 + m2 * l1  # first moment of the leg about the hip along the thigh
    b = m2 * c2  # first moment of the shank about the knee
    return np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2), th1, th2, w1, w2, m, a, b


@njit(cache=CACHE, inline="always")
def _stance_core(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, p):
    """Stance KKT solve from the link angles' sines/cosines and rates ``w1 = th1'``, ``w2 = th2'``.

    With the foot pinned, the leg seen from the foot is an inverted double pendulum: the shank
    turns about the foot, the thigh about the knee, and the torso is a point mass ``m_b`` at the
    hip (its rotation decouples). Eliminating ``(x_b, y_b)`` from the KKT system with
    ``s1^2 + c1^2 = 1`` (and ``k = m2 l1 c2 = l1 b``) leaves, in the absolute leg angles::

        [K11      kap c12] [th1'']   [tau_hip - tau_knee + g e1 cos th1 - kap s12 th2'^2]
        [kap c12  K22    ] [th2''] = [tau_knee           + g e2 cos th2 + kap s12 th1'^2]

        K11 = I1 + m1 (l1 - c1)^2 + m_b l1^2            e1 = m_b l1 + m1 (l1 - c1)
        K22 = I2 + m2 (l2 - c2)^2 + (m_b + m1) l2^2     e2 = (m_b + m1) l2 + m2 (l2 - c2)
        kap = l2 e1,  c12 = cos(th1 - th2),  s12 = sin(th1 - th2)

    ``K`` is SPD (the leg's inertia about the foot). The base follows from the contact
    (``(x_b, y_b)'' = -Jcdot qd - J_leg (th1'', th2'')``) and ``lam = m a_com + m g``, which
    reduces to the ``e1``, ``e2`` lines below. The stance dynamics depend on nothing else
    (translation invariance), so the integrator can reuse the trigonometry of its projection.
    Returns ``(qdd[0..4], lam_x, lam_y)`` as scalars.
    """
    m_b, m1, m2, I_b, I1, I2 = p[0], p[1], p[2], p[3], p[4], p[5]
    l1, l2, c1, c2, g = p[6], p[7], p[8], p[9], p[10]
    m = m_b + m1 + m2
    e1 = m_b * l1 + m1 * (l1 - c1)  # first moment about the knee of what the thigh carries
    e2 = (m_b + m1) * l2 + m2 * (l2 - c2)  # first moment about the foot, thigh and torso lumped at the knee
    kap = l2 * e1
    K11 = I1 + m1 * (l1 - c1) ** 2 + m_b * l1 * l1
    K22 = I2 + m2 * (l2 - c2) ** 2 + (m_b + m1) * l2 * l2
    c12 = co1 * co2 + s1 * s2  # cos(th1 - th2)
    s12 = s1 * co2 - co1 * s2  # sin(th1 - th2)
    K12 = kap * c12
    v1 = w1 * w1
    v2 = w2 * w2
    F = p[LOAD_X]  # horizontal force on the torso's COM [N]; virtual work F d x_b = F (l1 s1 d th1 + l2 s2 d th2)
    r1 = (tau_hip - tau_knee) + g * e1 * co1 - kap * s12 * v2 + F * l1 * s1
    r2 = tau_knee + g * e2 * co2 + kap * s12 * v1 + F * l2 * s2
    # the 2x2 SPD system by Cramer's rule (one division on the critical path)
    inv_det = 1.0 / (K11 * K22 - K12 * K12)
    dd1 = (K22 * r1 - K12 * r2) * inv_det
    dd2 = (K11 * r2 - K12 * r1) * inv_det
    # accelerations of the knee relative to the foot (ux, uy) and of the hip relative to the knee (vx, vy), per length
    ux, uy = co2 * v2 + s2 * dd2, s2 * v2 - co2 * dd2
    vx, vy = co1 * v1 + s1 * dd1, s1 * v1 - co1 * dd1
    xdd = l1 * vx + l2 * ux
    ydd = l1 * vy + l2 * uy
    lam_x = e1 * vx + e2 * ux - F  # m a_com = lam + F e_x - m g e_y
    lam_y = e1 * vy + e2 * uy + m * g
    thbdd = -tau_hip / I_b
    return xdd, ydd, thbdd, dd1 - thbdd, dd2 - dd1, lam_x, lam_y


@njit(cache=CACHE, inline="always")
def _flight_inertia(p):
    """Constants of the leg's motion about the whole-body COM: ``(m, a, b, kf, K11, K22)``.

    ``m`` total mass, ``a = m1 c1 + m2 l1`` and ``b = m2 c2`` the first moments of the leg about the hip
    and of the shank about the knee, and the flight inertia ``K = [[K11, kf c12], [kf c12, K22]]`` of the
    absolute leg angles (``_flight_core``).
    """
    m_b, m1, m2, I1, I2 = p[0], p[1], p[2], p[4], p[5]
    l1, c1, c2 = p[6], p[8], p[9]
    m = m_b + m1 + m2
    a = m1 * c1 + m2 * l1
    b = m2 * c2
    kf = m2 * l1 * c2 - a * b / m
    K11 = I1 + m1 * c1 * c1 + m2 * l1 * l1 - a * a / m
    K22 = I2 + m2 * c2 * c2 - b * b / m
    return m, a, b, kf, K11, K22


@njit(cache=CACHE, inline="always")
def _flight_core(s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, p):
    """Unconstrained (flight) forward dynamics from the same inputs as ``_stance_core``; returns ``qdd[0..4]``.

    The COM falls freely, ``m (x, y)_com'' = (0, -m g)``, and eliminating it leaves the leg
    angles' 2x2 SPD system, without gravity (relative motion in free fall)::

        [D11 - a^2/m  kf c12     ] [th1'']   [tau_hip - tau_knee - kf s12 th2'^2]
        [kf c12       D22 - b^2/m] [th2''] = [tau_knee           + kf s12 th1'^2]

    with ``a = m1 c1 + m2 l1``, ``b = m2 c2``, ``kf = m2 l1 c2 - a b / m``,
    ``D11 = I1 + m1 c1^2 + m2 l1^2`` and ``D22 = I2 + m2 c2^2``.
    """
    I_b, g = p[3], p[10]
    m, a, b, kf, K11, K22 = _flight_inertia(p)
    c12 = co1 * co2 + s1 * s2  # cos(th1 - th2)
    s12 = s1 * co2 - co1 * s2  # sin(th1 - th2)
    K12 = kf * c12
    v1 = w1 * w1
    v2 = w2 * w2
    F = p[LOAD_X]  # horizontal force on the torso's COM [N]: d(p_b - p_com)/d th_i . e_x = (a s1, b s2) / m
    r1 = (tau_hip - tau_knee) - kf * s12 * v2 + F * a * s1 / m
    r2 = tau_knee + kf * s12 * v1 + F * b * s2 / m
    inv_det = 1.0 / (K11 * K22 - K12 * K12)
    dd1 = (K22 * r1 - K12 * r2) * inv_det
    dd2 = (K11 * r2 - K12 * r1) * inv_det
    thbdd = -tau_hip / I_b
    # x_b = x_com - (a cos th1 + b cos th2) / m, and likewise y_b; the COM falls freely (m x_com'' = F)
    xdd = (a * (co1 * v1 + s1 * dd1) + b * (co2 * v2 + s2 * dd2) + F) / m
    ydd = (a * (s1 * v1 - co1 * dd1) + b * (s2 * v2 - co2 * dd2)) / m - g
    return xdd, ydd, thbdd, dd1 - thbdd, dd2 - dd1


@njit(cache=CACHE, inline="always")
def _energy_core(s1, co1, s2, co2, y_b, vx, vy, w_b, w1, w2, p):
    """Mechanical energy ``T + V`` [J] from the link trigonometry, base height and velocity, and rates.

    By Koenig's theorem ``T = m |v_com|^2 / 2 + I_b th_b'^2 / 2 + theta'^T K theta' / 2``, ``K`` the flight
    inertia of the leg angles ``theta = (th1, th2)`` about the COM (``_flight_core``); ``V = m g y_com``.
    """
    I_b, g = p[3], p[10]
    m, a, b, kf, K11, K22 = _flight_inertia(p)
    K12 = kf * (co1 * co2 + s1 * s2)
    vcx = vx - (a * s1 * w1 + b * s2 * w2) / m
    vcy = vy + (a * co1 * w1 + b * co2 * w2) / m
    T = 0.5 * (m * (vcx * vcx + vcy * vcy) + I_b * w_b * w_b + K11 * w1 * w1 + 2.0 * K12 * w1 * w2 + K22 * w2 * w2)
    return T + g * (m * y_b + a * s1 + b * s2)


@njit(cache=CACHE, inline="always")
def _stance_one(q, qd, tau, p, qdd, lam):
    """Stance KKT solve for one robot; writes ``qdd`` (5,) and ``lam`` (2,)."""
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    w1 = qd[2] + qd[3]
    w2 = w1 + qd[4]
    qdd[0], qdd[1], qdd[2], qdd[3], qdd[4], lam[0], lam[1] = _stance_core(
        np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2), w1, w2, tau[0], tau[1], p
    )


@njit(cache=CACHE, inline="always")
def _flight_one(q, qd, tau, p, qdd):
    """Unconstrained (flight) forward dynamics for one robot; writes ``qdd`` (5,)."""
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    w1 = qd[2] + qd[3]
    w2 = w1 + qd[4]
    qdd[0], qdd[1], qdd[2], qdd[3], qdd[4] = _flight_core(
        np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2), w1, w2, tau[0], tau[1], p
    )


@njit(cache=CACHE, inline="always")
def _mass_matrix_one(q, p, M):
    m_b, m1, m2, I_b, I1, I2 = p[0], p[1], p[2], p[3], p[4], p[5]
    l1, c1, c2 = p[6], p[8], p[9]
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    m = m_b + m1 + m2
    a = m1 * c1 + m2 * l1
    b = m2 * c2
    s1, co1, s2, co2 = np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2)
    D11 = I1 + m1 * c1 * c1 + m2 * l1 * l1
    D22 = I2 + m2 * c2 * c2
    D12 = m2 * l1 * c2 * np.cos(th1 - th2)
    # M = T^T A T written out: columns 2, 3 of M see th1 and th2; column 4 sees th2 only
    Mx1 = -a * s1 - b * s2  # d(p_com * m)/d th_b along x, = x-row coupling of q1 and th_b
    My1 = a * co1 + b * co2
    Mx2 = -b * s2
    My2 = b * co2
    M[0, 0] = m
    M[0, 1] = 0.0
    M[1, 1] = m
    M[0, 2] = Mx1
    M[0, 3] = Mx1
    M[0, 4] = Mx2
    M[1, 2] = My1
    M[1, 3] = My1
    M[1, 4] = My2
    M[2, 2] = I_b + D11 + D22 + 2.0 * D12
    M[2, 3] = D11 + D22 + 2.0 * D12
    M[3, 3] = D11 + D22 + 2.0 * D12
    M[2, 4] = D22 + D12
    M[3, 4] = D22 + D12
    M[4, 4] = D22
    for i in range(5):
        for j in range(i):
            M[i, j] = M[j, i]


@njit(cache=CACHE, inline="always")
def _bias_one(q, qd, p, h, gravity_only):
    m2, l1, c2, g = p[2], p[6], p[9], p[10]
    s1, co1, s2, co2, th1, th2, w1, w2, m, a, b = _leg_terms(q, qd, p)
    if gravity_only:
        w1 = 0.0
        w2 = 0.0
    k = m2 * l1 * c2
    s12 = np.sin(th1 - th2)
    hx = -a * co1 * w1 * w1 - b * co2 * w2 * w2
    hy = -a * s1 * w1 * w1 - b * s2 * w2 * w2 + m * g
    h1 = k * s12 * w2 * w2 + a * g * co1
    h2 = -k * s12 * w1 * w1 + b * g * co2
    h[0] = hx
    h[1] = hy
    h[2] = h1 + h2
    h[3] = h1 + h2
    h[4] = h2


@njit(cache=CACHE, inline="always")
def _foot_one(q, p, out):
    l1, l2 = p[6], p[7]
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    out[0] = q[0] + l1 * np.cos(th1) + l2 * np.cos(th2)
    out[1] = q[1] + l1 * np.sin(th1) + l2 * np.sin(th2)


@njit(cache=CACHE, inline="always")
def _jacobian_one(q, p, Jc):
    l1, l2 = p[6], p[7]
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    J1x, J1y = -l1 * np.sin(th1), l1 * np.cos(th1)
    J2x, J2y = -l2 * np.sin(th2), l2 * np.cos(th2)
    Jc[0, 0] = 1.0
    Jc[0, 1] = 0.0
    Jc[1, 0] = 0.0
    Jc[1, 1] = 1.0
    Jc[0, 2] = J1x + J2x
    Jc[1, 2] = J1y + J2y
    Jc[0, 3] = J1x + J2x
    Jc[1, 3] = J1y + J2y
    Jc[0, 4] = J2x
    Jc[1, 4] = J2y


@njit(cache=CACHE, inline="always")
def _jdot_qd_one(q, qd, p, out):
    l1, l2 = p[6], p[7]
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    w1 = qd[2] + qd[3]
    w2 = w1 + qd[4]
    out[0] = -l1 * np.cos(th1) * w1 * w1 - l2 * np.cos(th2) * w2 * w2
    out[1] = -l1 * np.sin(th1) * w1 * w1 - l2 * np.sin(th2) * w2 * w2


@njit(cache=CACHE, inline="always")
def _com_one(q, p, out):
    m_b, m1, m2, l1, c1, c2 = p[0], p[1], p[2], p[6], p[8], p[9]
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    m = m_b + m1 + m2
    a = m1 * c1 + m2 * l1
    b = m2 * c2
    out[0] = q[0] + (a * np.cos(th1) + b * np.cos(th2)) / m
    out[1] = q[1] + (a * np.sin(th1) + b * np.sin(th2)) / m


@njit(cache=CACHE)
def _equilibrium_one(p, knee, q, tau, work):
    """``static_equilibrium``'s posture ``q`` (5,) and holding torques ``tau`` (2,), written in place; ``work`` is
    ``(4, 5)`` scratch (the foot, ``G``, ``Jc``), so that a randomised reset solving this per robot allocates nothing."""
    m = p[0] + p[1] + p[2]
    A = (p[1] * p[8] + p[2] * p[6]) / m - p[6]
    B = p[2] * p[9] / m - p[7]
    th1 = np.arctan2(A + B * np.cos(knee), B * np.sin(knee))
    while th1 > 0.0:
        th1 -= np.pi
    while th1 <= -np.pi:
        th1 += np.pi
    q[0], q[1], q[2], q[3], q[4] = 0.0, 0.0, 0.0, th1, knee
    foot, G, Jc = work[0, :2], work[1], work[2:4]
    _foot_one(q, p, foot)
    q[0] -= foot[0]
    q[1] -= foot[1]
    _bias_one(q, q, p, G, True)
    _jacobian_one(q, p, Jc)
    mg = m * p[10]
    # M qdd + G = S^T tau + Jc^T lam with qdd = 0 and lam = (0, m g), read on the actuated rows
    tau[0] = G[3] - (Jc[0, 3] * 0.0 + Jc[1, 3] * mg)
    tau[1] = G[4] - (Jc[0, 4] * 0.0 + Jc[1, 4] * mg)


# ----------------------------------------------------------------------------
# Batch kernels: loop the single-robot kernels over the leading axis
# ----------------------------------------------------------------------------


@njit(cache=CACHE)
def _stance_batch(q, qd, tau, p, qdd, lam):
    for i in range(q.shape[0]):
        _stance_one(q[i], qd[i], tau[i], p, qdd[i], lam[i])


@njit(cache=CACHE)
def _flight_batch(q, qd, tau, p, qdd):
    for i in range(q.shape[0]):
        _flight_one(q[i], qd[i], tau[i], p, qdd[i])


@njit(cache=CACHE)
def _stance_single(q, qd, tau, p, qdd, lam):
    _stance_one(q, qd, tau, p, qdd, lam)


@njit(cache=CACHE)
def _mass_matrix_batch(q, p, M):
    for i in range(q.shape[0]):
        _mass_matrix_one(q[i], p, M[i])


@njit(cache=CACHE)
def _bias_batch(q, qd, p, h, gravity_only):
    for i in range(q.shape[0]):
        _bias_one(q[i], qd[i], p, h[i], gravity_only)


@njit(cache=CACHE)
def _foot_batch(q, p, out):
    for i in range(q.shape[0]):
        _foot_one(q[i], p, out[i])


@njit(cache=CACHE)
def _jacobian_batch(q, p, Jc):
    for i in range(q.shape[0]):
        _jacobian_one(q[i], p, Jc[i])


@njit(cache=CACHE)
def _jdot_qd_batch(q, qd, p, out):
    for i in range(q.shape[0]):
        _jdot_qd_one(q[i], qd[i], p, out[i])


@njit(cache=CACHE)
def _com_batch(q, p, out):
    for i in range(q.shape[0]):
        _com_one(q[i], p, out[i])


# ----------------------------------------------------------------------------
# Public API: shape handling around the kernels
# ----------------------------------------------------------------------------


def params_array(p: LegParams | np.ndarray, load_x: float = 0.0) -> np.ndarray:
    """``LegParams`` as the float64 array the kernels read: its 11 fields, then the load ``p[LOAD_X]``.

    ``load_x`` is the horizontal force on the torso's COM [N] held over a step (0: no load). An array of
    11 values gets the load appended; one of 12 passes through.
    """
    if isinstance(p, LegParams):
        return _loaded(p.array, load_x)
    a = np.asarray(p, dtype=np.float64)
    if a.shape == (NP,):
        return _loaded(a, load_x)
    if a.shape != (NP + 1,):
        raise ValueError(f"params must be LegParams or an array of {NP} values (or {NP + 1} with the load), got shape {a.shape}")
    return a


def _kernel_params(p: LegParams | np.ndarray) -> np.ndarray:
    """``params_array(p)`` for the public wrappers' kernel calls: a ``LegParams``' array is made once and shared
    (``LegParams._unloaded``; no kernel writes its parameter array), so a call on one robot pays no allocation."""
    return p._unloaded if isinstance(p, LegParams) else params_array(p)


def _loaded(a: np.ndarray, load_x: float) -> np.ndarray:
    out = np.empty(NP + 1)
    out[:NP] = a
    out[LOAD_X] = load_x
    return out


_F64 = np.dtype(np.float64)
_SHAPE_Q = (NQ,)
_SHAPE_TAU = (NU,)


def _single_robot(q, qd, tau) -> bool:
    """Fast-path test: ``q``, ``qd`` of shape (5,) and ``tau`` of shape (2,), all contiguous float64.

    One expression, no calls (this sits on the per-evaluation path). ``dtype is`` compares with
    numpy's float64 singleton; an equal but distinct dtype object only takes the general path.
    """
    return (
        type(q) is np.ndarray
        and type(qd) is np.ndarray
        and type(tau) is np.ndarray
        and q.shape == _SHAPE_Q
        and qd.shape == _SHAPE_Q
        and tau.shape == _SHAPE_TAU
        and q.dtype is _F64
        and qd.dtype is _F64
        and tau.dtype is _F64
        and q.flags.c_contiguous
        and qd.flags.c_contiguous
        and tau.flags.c_contiguous
    )


def _vec(x, n: int, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 0 or a.shape[-1] != n:
        raise ValueError(f"{name} must have shape (..., {n}), got {a.shape}")
    return a


def _batched(*arrays):
    """Broadcast leading axes; return the lead shape and contiguous (N, n) views."""
    lead = np.broadcast_shapes(*(a.shape[:-1] for a in arrays))
    flat = []
    for a in arrays:
        if a.shape[:-1] != lead:
            a = np.broadcast_to(a, lead + a.shape[-1:])
        flat.append(np.ascontiguousarray(a.reshape(-1, a.shape[-1])))
    return lead, flat


def mass_matrix(q, p: LegParams) -> np.ndarray:
    """Joint-space mass matrix ``M(q)`` (section 2), shape ``(..., 5, 5)``, symmetric positive definite."""
    lead, (qf,) = _batched(_vec(q, NQ, "q"))
    M = np.empty((qf.shape[0], NQ, NQ))
    _mass_matrix_batch(qf, _kernel_params(p), M)
    return M.reshape(lead + (NQ, NQ))


def bias_forces(q, qd, p: LegParams) -> np.ndarray:
    """``h(q, qd)``: Coriolis, centrifugal and gravity generalized forces, shape ``(..., 5)``."""
    lead, (qf, qdf) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"))
    h = np.empty((qf.shape[0], NQ))
    _bias_batch(qf, qdf, _kernel_params(p), h, False)
    return h.reshape(lead + (NQ,))


def gravity_forces(q, p: LegParams) -> np.ndarray:
    """Gravity generalized forces ``dP/dq``, shape ``(..., 5)``."""
    lead, (qf,) = _batched(_vec(q, NQ, "q"))
    h = np.empty((qf.shape[0], NQ))
    _bias_batch(qf, qf, _kernel_params(p), h, True)
    return h.reshape(lead + (NQ,))


def foot_position(q, p: LegParams) -> np.ndarray:
    """Foot position ``p_f(q)`` in the world frame (section 3), shape ``(..., 2)``."""
    lead, (qf,) = _batched(_vec(q, NQ, "q"))
    out = np.empty((qf.shape[0], 2))
    _foot_batch(qf, _kernel_params(p), out)
    return out.reshape(lead + (2,))


def com_position(q, p: LegParams) -> np.ndarray:
    """Whole-body centre of mass in the world frame, shape ``(..., 2)``."""
    lead, (qf,) = _batched(_vec(q, NQ, "q"))
    out = np.empty((qf.shape[0], 2))
    _com_batch(qf, _kernel_params(p), out)
    return out.reshape(lead + (2,))


def contact_jacobian(q, p: LegParams) -> np.ndarray:
    """Contact Jacobian ``Jc = d p_f / d q`` (section 3, Problem 3), rows ``x, y``, shape ``(..., 2, 5)``."""
    lead, (qf,) = _batched(_vec(q, NQ, "q"))
    Jc = np.empty((qf.shape[0], 2, NQ))
    _jacobian_batch(qf, _kernel_params(p), Jc)
    return Jc.reshape(lead + (2, NQ))


def contact_jdot_qd(q, qd, p: LegParams) -> np.ndarray:
    """``Jcdot(q, qd) qd``, the foot's velocity-product acceleration, shape ``(..., 2)``."""
    lead, (qf, qdf) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"))
    out = np.empty((qf.shape[0], 2))
    _jdot_qd_batch(qf, qdf, _kernel_params(p), out)
    return out.reshape(lead + (2,))


def contact_inertia(q, p: LegParams) -> np.ndarray:
    """Contact inertia ``Lambda_c = Jc M^-1 Jc^T`` (section 4, Problem 4), shape ``(..., 2, 2)``.

    Computed by a Cholesky-based solve of ``M X = Jc^T``, never by inverting ``M``.
    """
    M = mass_matrix(q, p)
    Jc = contact_jacobian(q, p)
    L = np.linalg.cholesky(M)
    Y = np.linalg.solve(L, np.swapaxes(Jc, -1, -2))  # L Y = Jc^T, so Lambda_c = Y^T Y
    return np.swapaxes(Y, -1, -2) @ Y


def stance_dynamics(q, qd, tau, p: LegParams) -> tuple[np.ndarray, np.ndarray]:
    """Solve the stance KKT system (section 4) for ``qdd`` and the contact force ``lam``.

    Args:
        q: ``(..., 5)`` configuration.
        qd: ``(..., 5)`` velocity.
        tau: ``(..., 2)`` hip and knee torques [N m].
        p: physical parameters.

    Returns:
        ``(qdd, lam)`` of shapes ``(..., 5)`` and ``(..., 2)``; ``lam = [lam_x, lam_y]`` is the
        ground's force on the foot [N].
    """
    if _single_robot(q, qd, tau):
        qdd, lam = np.empty(NQ), np.empty(2)
        _stance_single(q, qd, tau, _kernel_params(p), qdd, lam)
        return qdd, lam
    lead, (qf, qdf, tf) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"), _vec(tau, NU, "tau"))
    n = qf.shape[0]
    qdd = np.empty((n, NQ))
    lam = np.empty((n, 2))
    _stance_batch(qf, qdf, tf, _kernel_params(p), qdd, lam)
    return qdd.reshape(lead + (NQ,)), lam.reshape(lead + (2,))


def flight_dynamics(q, qd, tau, p: LegParams) -> np.ndarray:
    """Unconstrained forward dynamics ``M qdd + h = S^T tau`` (section 2), shape ``(..., 5)``."""
    lead, (qf, qdf, tf) = _batched(_vec(q, NQ, "q"), _vec(qd, NQ, "qd"), _vec(tau, NU, "tau"))
    qdd = np.empty((qf.shape[0], NQ))
    _flight_batch(qf, qdf, tf, _kernel_params(p), qdd)
    return qdd.reshape(lead + (NQ,))


def kinetic_energy(q, qd, p: LegParams) -> np.ndarray:
    """Kinetic energy ``qd^T M qd / 2`` [J], shape ``(...)``."""
    qd = _vec(qd, NQ, "qd")
    M = mass_matrix(q, p)
    return 0.5 * np.einsum("...i,...ij,...j->...", qd, M, qd)


def potential_energy(q, p: LegParams) -> np.ndarray:
    """Potential energy ``g (m_b y_b + m1 y_c1 + m2 y_c2)`` [J], shape ``(...)``."""
    q = _vec(q, NQ, "q")
    com = com_position(q, p)
    return p.g * p.total_mass * com[..., 1]


def static_equilibrium(p: LegParams, knee: float = 0.8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The stance equilibrium with the torso level, knee at ``knee`` and the COM above the foot.

    With ``th_b = 0`` and ``th2 = th1 + knee``, the COM is above the foot when
    ``(a/m - l1) cos th1 + (b/m - l2) cos th2 = 0`` (``a = m1 c1 + m2 l1``, ``b = m2 c2``),
    i.e. ``tan th1 = (A + B cos knee) / (B sin knee)``; the root with the knee below the hip
    is taken. The hip torque is then zero and the knee torque balances gravity.

    Returns:
        ``(q, tau, lam)``: configuration with the foot at the origin, holding torques and the
        contact force ``[0, m g]``.
    """
    q, tau = np.empty(NQ), np.empty(NU)
    _equilibrium_one(p.array, float(knee), q, tau, np.empty((4, NQ)))
    lam = np.array([0.0, p.total_mass * p.g])
    return q, tau, lam



# The unilateral contact (modes, slip, impact map, Painleve bound) lives in leg_env.contact and is
# re-exported here, the one place users look for the dynamics (lazily: leg_env.contact imports this module).
_CONTACT_NAMES = (  # leg_env.contact.__all__
    "STICK",
    "SLIP_FORWARD",
    "SLIP_BACKWARD",
    "FLIGHT",
    "MODE_NAMES",
    "REST_SPEED",
    "slip_dynamics",
    "impact_map",
    "contact_mode",
    "mu_critical",
    "free_foot_acceleration",
)
__all__ += list(_CONTACT_NAMES)


def __getattr__(name: str):
    if name in _CONTACT_NAMES:
        from . import contact

        return getattr(contact, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
