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
* An external horizontal force ``F`` on the torso's COM (a push: the ``load`` of the compiled core's
  steps, 0 unless a task sets it) adds the generalised force ``Q = J_b^T (F, 0)`` to the right-hand side,
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

Every public function here runs in the compiled core, ``leg_env/_core`` (C, built at install): the
arrays are broadcast and validated here and looped over in C, one robot per row, with the GIL released.
"""

from __future__ import annotations

import math

import numpy as np

from .. import checks
from .._core import kernels
from .arrays import NO_LOAD, NQ, NU, as_params, batched, core_params, single_robot, vec
from .params import LegParams

__all__ = ["S", "mass_matrix", "bias_forces", "gravity_forces", "contact_jacobian", "contact_jdot_qd",
           "foot_position", "contact_inertia", "stance_dynamics", "flight_dynamics", "kinetic_energy",
           "potential_energy", "com_position", "com_state", "static_equilibrium"]

S = np.array([[0.0, 0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0]])
S.setflags(write=False)


def mass_matrix(q, p: LegParams) -> np.ndarray:
    """Joint-space mass matrix ``M(q)`` (section 2), shape ``(..., 5, 5)``, symmetric positive definite."""
    lead, (qf,) = batched(("q", vec(q, NQ, "q")))
    M = np.empty((qf.shape[0], NQ, NQ))
    kernels.mass_matrix(qf, core_params(p), M)
    return M.reshape(lead + (NQ, NQ))


def bias_forces(q, qd, p: LegParams) -> np.ndarray:
    """``h(q, qd)``: Coriolis, centrifugal and gravity generalized forces, shape ``(..., 5)``."""
    lead, (qf, qdf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")))
    h = np.empty((qf.shape[0], NQ))
    kernels.bias(qf, qdf, core_params(p), h, False)
    return h.reshape(lead + (NQ,))


def gravity_forces(q, p: LegParams) -> np.ndarray:
    """Gravity generalized forces ``dP/dq``, shape ``(..., 5)``."""
    lead, (qf,) = batched(("q", vec(q, NQ, "q")))
    h = np.empty((qf.shape[0], NQ))
    kernels.bias(qf, qf, core_params(p), h, True)
    return h.reshape(lead + (NQ,))


def foot_position(q, p: LegParams) -> np.ndarray:
    """Foot position ``p_f(q)`` in the world frame (section 3), shape ``(..., 2)``."""
    lead, (qf,) = batched(("q", vec(q, NQ, "q")))
    out = np.empty((qf.shape[0], 2))
    kernels.foot(qf, core_params(p), out)
    return out.reshape(lead + (2,))


def com_position(q, p: LegParams) -> np.ndarray:
    """Whole-body centre of mass in the world frame, shape ``(..., 2)``."""
    lead, (qf,) = batched(("q", vec(q, NQ, "q")))
    out = np.empty((qf.shape[0], 2))
    kernels.com(qf, qf, core_params(p), out, np.empty((qf.shape[0], 2)))
    return out.reshape(lead + (2,))


def com_state(q, qd, p: LegParams) -> tuple[np.ndarray, np.ndarray]:
    """Whole-body centre of mass and its velocity in the world frame, each of shape ``(..., 2)``."""
    lead, (qf, qdf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")))
    pos, vel = np.empty((qf.shape[0], 2)), np.empty((qf.shape[0], 2))
    kernels.com(qf, qdf, core_params(p), pos, vel)
    return pos.reshape(lead + (2,)), vel.reshape(lead + (2,))


def contact_jacobian(q, p: LegParams) -> np.ndarray:
    """Contact Jacobian ``Jc = d p_f / d q`` (section 3, Problem 3), rows ``x, y``, shape ``(..., 2, 5)``."""
    lead, (qf,) = batched(("q", vec(q, NQ, "q")))
    Jc = np.empty((qf.shape[0], 2, NQ))
    kernels.jacobian(qf, core_params(p), Jc)
    return Jc.reshape(lead + (2, NQ))


def contact_jdot_qd(q, qd, p: LegParams) -> np.ndarray:
    """``Jcdot(q, qd) qd``, the foot's velocity-product acceleration, shape ``(..., 2)``."""
    lead, (qf, qdf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")))
    out = np.empty((qf.shape[0], 2))
    kernels.jdot_qd(qf, qdf, core_params(p), out)
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
    if single_robot(q, qd, tau):
        qdd, lam = np.empty(NQ), np.empty(2)
        kernels.stance(q, qd, tau, core_params(p), NO_LOAD, qdd, lam)
        return qdd, lam
    lead, (qf, qdf, tf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")), ("tau", vec(tau, NU, "tau")))
    n = qf.shape[0]
    qdd = np.empty((n, NQ))
    lam = np.empty((n, 2))
    kernels.stance(qf, qdf, tf, core_params(p), np.zeros(n), qdd, lam)
    return qdd.reshape(lead + (NQ,)), lam.reshape(lead + (2,))


def flight_dynamics(q, qd, tau, p: LegParams) -> np.ndarray:
    """Unconstrained forward dynamics ``M qdd + h = S^T tau`` (section 2), shape ``(..., 5)``."""
    lead, (qf, qdf, tf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")), ("tau", vec(tau, NU, "tau")))
    qdd = np.empty((qf.shape[0], NQ))
    kernels.flight(qf, qdf, tf, core_params(p), np.zeros(qf.shape[0]), qdd)
    return qdd.reshape(lead + (NQ,))


def kinetic_energy(q, qd, p: LegParams) -> np.ndarray:
    """Kinetic energy ``qd^T M qd / 2`` [J], shape ``(...)``."""
    lead, (qf, qdf) = batched(("q", vec(q, NQ, "q")), ("qd", vec(qd, NQ, "qd")))
    M = mass_matrix(qf, p)
    return (0.5 * np.einsum("ni,nij,nj->n", qdf, M, qdf)).reshape(lead)


def potential_energy(q, p: LegParams) -> np.ndarray:
    """Potential energy ``g (m_b y_b + m1 y_c1 + m2 y_c2)`` [J], shape ``(...)``."""
    q = vec(q, NQ, "q")
    p = as_params(p)
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
    p = as_params(p)
    knee = checks.real("knee", knee, -math.pi, math.pi, unit="rad")
    kernels.equilibrium(p.array, knee, q, tau)
    lam = np.array([0.0, p.total_mass * p.g])
    return q, tau, lam
