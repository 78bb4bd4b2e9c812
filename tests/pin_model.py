"""The planar leg as a Pinocchio model: the independent rigid-body reference for tests and benchmarks.

Pinocchio is 3-D; the robot moves in its x-y plane and every rotation is about z. The floating
base is a chain ``PX -> PY -> RZ`` (two massless bodies, then the torso), so Pinocchio's
configuration and velocity are exactly ``q = [x_b, y_b, th_b, q1, q2]`` and ``qd``. The hip (RZ)
sits at the torso's origin = its COM, the knee (RZ) at ``l1`` along the thigh's x axis, and the
frame ``"foot"`` at ``l2`` along the shank's x axis. Gravity is ``(0, -g, 0)``.

Used by ``tests/test_dynamics_reference.py`` and ``benchmarks/bench_dynamics.py`` (which puts this
folder on ``sys.path``), so there is one copy of the model.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from leg_env.physics.params import LegParams

__all__ = ["build_model", "foot_terms", "constrained_forward_dynamics"]


def _inertia(mass: float, com_x: float, I_zz: float) -> pin.Inertia:
    """Rigid-body inertia: ``mass`` with its COM at ``(com_x, 0, 0)``, ``I_zz`` about the COM."""
    # Ixx, Iyy never enter planar motion; give them the same value so the tensor is valid
    return pin.Inertia(mass, np.array([com_x, 0.0, 0.0]), np.diag([I_zz, I_zz, I_zz]))


def build_model(p: LegParams) -> tuple[pin.Model, int]:
    """Return ``(model, foot_frame_id)`` for parameters ``p``."""
    model = pin.Model()
    model.gravity = pin.Motion(np.array([0.0, -p.g, 0.0]), np.zeros(3))
    eye = pin.SE3.Identity()
    j_x = model.addJoint(0, pin.JointModelPX(), eye, "base_x")
    j_y = model.addJoint(j_x, pin.JointModelPY(), eye, "base_y")
    j_b = model.addJoint(j_y, pin.JointModelRZ(), eye, "base_rz")
    model.appendBodyToJoint(j_b, _inertia(p.m_b, 0.0, p.I_b), eye)
    j_1 = model.addJoint(j_b, pin.JointModelRZ(), eye, "hip")
    model.appendBodyToJoint(j_1, _inertia(p.m1, p.c1, p.I1), eye)
    knee = pin.SE3(np.eye(3), np.array([p.l1, 0.0, 0.0]))
    j_2 = model.addJoint(j_1, pin.JointModelRZ(), knee, "knee")
    model.appendBodyToJoint(j_2, _inertia(p.m2, p.c2, p.I2), eye)
    foot = pin.SE3(np.eye(3), np.array([p.l2, 0.0, 0.0]))
    foot_id = model.addFrame(pin.Frame("foot", j_2, foot, pin.FrameType.OP_FRAME))
    return model, foot_id


def foot_terms(model: pin.Model, data: pin.Data, foot_id: int, q, v) -> tuple[np.ndarray, np.ndarray]:
    """Foot Jacobian rows ``x, y`` (2, 5) and the drift ``Jcdot v`` (2,): the foot's classical
    acceleration at zero joint acceleration, both in world-aligned axes."""
    pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    J = pin.getFrameJacobian(model, data, foot_id, pin.LOCAL_WORLD_ALIGNED)[:2]
    drift = pin.getFrameClassicalAcceleration(model, data, foot_id, pin.LOCAL_WORLD_ALIGNED).linear[:2]
    return J, drift


def constrained_forward_dynamics(model, data, foot_id, q, v, tau2) -> tuple[np.ndarray, np.ndarray]:
    """Stance dynamics by Pinocchio: ``(qdd, lam)`` with ``lam`` the ground force on the foot."""
    J, drift = foot_terms(model, data, foot_id, q, v)
    tau = np.array([0.0, 0.0, 0.0, tau2[0], tau2[1]])
    qdd = pin.forwardDynamics(model, data, q, v, tau, J, drift)
    return qdd, data.lambda_c.copy()
