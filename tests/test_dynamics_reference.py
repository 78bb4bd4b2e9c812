"""leg_env.physics.dynamics against two independent references, over random states and random parameters.

1. A SymPy Lagrangian derivation written here from the link COM positions and angular
   velocities (lesson sections 1-4): ``M = d^2 K / d qd^2``, ``h`` = the Euler-Lagrange terms
   without ``qdd``, gravity ``= dP/dq``, ``Jc = d p_f / dq``, ``Jcdot qd = d(Jc qd)/dq qd``.
   The stance and flight references solve the KKT system with numpy on the SymPy terms.
2. Pinocchio (``tests/pin_model.py``): CRBA, RNEA, generalized gravity, the foot frame Jacobian,
   the foot's classical acceleration at ``qdd = 0`` and Pinocchio's constrained forward dynamics.

Tolerance: ``|a - b| <= RTOL * (1 + |b|)`` with ``|.|`` the Euclidean (Frobenius) norm of the
whole quantity and ``b`` the reference.
"""

from __future__ import annotations

import functools

import numpy as np
import pinocchio as pin
import pytest
import sympy as sp

from conftest import random_params
from pin_model import build_model, constrained_forward_dynamics, foot_terms
from leg_env import physics as dyn
from leg_env.physics.params import PARAM_NAMES

N_CASES = 200  # random (state, parameter set) pairs, each with its own parameters
SEED = 20240611
RTOL = 1e-10
POSITION_RANGE = 2.0  # |x_b|, |y_b| <= [m]
RATE_SCALE = 3.0  # std of the generalized velocities [m/s, rad/s]
TORQUE_RANGE = 50.0  # |tau| <= [N m]


def assert_close(actual, reference, what: str) -> None:
    actual, reference = np.asarray(actual, dtype=float), np.asarray(reference, dtype=float)
    assert actual.shape == reference.shape, f"{what}: shape {actual.shape} != {reference.shape}"
    err = np.linalg.norm(actual - reference)
    assert err <= RTOL * (1.0 + np.linalg.norm(reference)), (
        f"{what}: |a - b| = {err:.3e}, |b| = {np.linalg.norm(reference):.3e}\na = {actual}\nb = {reference}"
    )


# ----------------------------------------------------------------------------
# The SymPy derivation (once per session; parameters are symbols, so one derivation serves all)
# ----------------------------------------------------------------------------


@functools.lru_cache(maxsize=1)
def sympy_reference():
    """Return ``f(q, qd, p) -> (M, h, G, Jc, Jcdot_qd, p_f, K, P, p_com)`` from a Lagrangian derivation."""
    q = sp.symbols("x_b y_b th_b q1 q2", real=True)
    qd = sp.symbols("xd_b yd_b thd_b qd1 qd2", real=True)
    params = sp.symbols(PARAM_NAMES, positive=True)
    m_b, m1, m2, I_b, I1, I2, l1, l2, c1, c2, g = params
    x_b, y_b, th_b, q1, q2 = q
    q_vec, qd_vec = sp.Matrix(q), sp.Matrix(qd)

    def u(th):  # unit vector of a link at absolute angle th
        return sp.Matrix([sp.cos(th), sp.sin(th)])

    th1 = th_b + q1
    th2 = th1 + q2
    p_b = sp.Matrix([x_b, y_b])  # torso COM = hip
    p_c1 = p_b + c1 * u(th1)
    p_knee = p_b + l1 * u(th1)
    p_c2 = p_knee + c2 * u(th2)
    p_f = p_knee + l2 * u(th2)

    def v(r):  # velocity of a point by the chain rule
        return r.jacobian(q_vec) * qd_vec

    w_b = qd[2]
    w_1 = qd[2] + qd[3]
    w_2 = w_1 + qd[4]
    K = sp.Rational(1, 2) * (
        m_b * v(p_b).dot(v(p_b))
        + m1 * v(p_c1).dot(v(p_c1))
        + m2 * v(p_c2).dot(v(p_c2))
        + I_b * w_b**2
        + I1 * w_1**2
        + I2 * w_2**2
    )
    P = g * (m_b * y_b + m1 * p_c1[1] + m2 * p_c2[1])
    L = K - P

    M = sp.hessian(K, qd)
    dL_dqd = sp.Matrix([sp.diff(L, s) for s in qd])
    dL_dq = sp.Matrix([sp.diff(L, s) for s in q])
    # d/dt dL/dqd = (d^2 L / dqd dq) qd + M qdd; h is everything but M qdd
    h = dL_dqd.jacobian(q_vec) * qd_vec - dL_dq
    G = sp.Matrix([sp.diff(P, s) for s in q])
    Jc = p_f.jacobian(q_vec)
    Jcdot_qd = (Jc * qd_vec).jacobian(q_vec) * qd_vec
    p_com = (m_b * p_b + m1 * p_c1 + m2 * p_c2) / (m_b + m1 + m2)

    f = sp.lambdify([q, qd, params], [M, h, G, Jc, Jcdot_qd, p_f, K, P, p_com], "numpy", cse=True)

    def evaluate(q_val, qd_val, p):
        out = f(q_val, qd_val, p.array)
        M_, h_, G_, Jc_, jd_, pf_, K_, P_, com_ = (np.asarray(o, dtype=float) for o in out)
        return {
            "M": M_,
            "h": h_.ravel(),
            "G": G_.ravel(),
            "Jc": Jc_,
            "Jcdot_qd": jd_.ravel(),
            "p_f": pf_.ravel(),
            "K": float(K_),
            "P": float(P_),
            "p_com": com_.ravel(),
        }

    evaluate.raw = f  # f(q, qd, params) -> [M, h, G, Jc, Jcdot_qd, p_f, K, P, p_com], complex arguments too
    return evaluate


def kkt_reference(M, h, Jc, Jcdot_qd, tau):
    """Solve [M -Jc^T; Jc 0] [qdd; lam] = [S^T tau - h; -Jcdot qd] with numpy."""
    A = np.zeros((7, 7))
    A[:5, :5] = M
    A[:5, 5:] = -Jc.T
    A[5:, :5] = Jc
    rhs = np.concatenate([dyn.S.T @ tau - h, -Jcdot_qd])
    x = np.linalg.solve(A, rhs)
    return x[:5], x[5:]


@pytest.fixture(scope="module")
def cases():
    """Random states, torques and parameter sets with their SymPy reference terms."""
    rng = np.random.default_rng(SEED)
    ref = sympy_reference()
    out = []
    for _ in range(N_CASES):
        p = random_params(rng)
        q = np.concatenate([rng.uniform(-POSITION_RANGE, POSITION_RANGE, 2), rng.uniform(-np.pi, np.pi, 3)])
        qd = RATE_SCALE * rng.standard_normal(5)
        tau = rng.uniform(-TORQUE_RANGE, TORQUE_RANGE, 2)
        out.append((q, qd, tau, p, ref(q, qd, p)))
    return out


# ----------------------------------------------------------------------------
# SymPy
# ----------------------------------------------------------------------------


def test_parameter_sets_vary(cases):
    """The random parameter sets really vary (not silently the defaults)."""
    masses = np.array([c[3].m_b for c in cases])
    assert masses.std() > 1.0


def test_mass_matrix_sympy(cases):
    for i, (q, qd, tau, p, r) in enumerate(cases):
        assert_close(dyn.mass_matrix(q, p), r["M"], f"M, case {i}")


def test_bias_forces_sympy(cases):
    for i, (q, qd, tau, p, r) in enumerate(cases):
        assert_close(dyn.bias_forces(q, qd, p), r["h"], f"h, case {i}")


def test_gravity_forces_sympy(cases):
    for i, (q, qd, tau, p, r) in enumerate(cases):
        assert_close(dyn.gravity_forces(q, p), r["G"], f"gravity, case {i}")


def test_contact_jacobian_sympy(cases):
    for i, (q, qd, tau, p, r) in enumerate(cases):
        assert_close(dyn.contact_jacobian(q, p), r["Jc"], f"Jc, case {i}")


def test_contact_jdot_qd_sympy(cases):
    for i, (q, qd, tau, p, r) in enumerate(cases):
        assert_close(dyn.contact_jdot_qd(q, qd, p), r["Jcdot_qd"], f"Jcdot qd, case {i}")


def test_foot_position_sympy(cases):
    for i, (q, qd, tau, p, r) in enumerate(cases):
        assert_close(dyn.foot_position(q, p), r["p_f"], f"foot, case {i}")


def test_com_position_sympy(cases):
    for i, (q, qd, tau, p, r) in enumerate(cases):
        assert_close(dyn.com_position(q, p), r["p_com"], f"COM, case {i}")


def test_contact_inertia_sympy(cases):
    for i, (q, qd, tau, p, r) in enumerate(cases):
        Lambda_c = r["Jc"] @ np.linalg.solve(r["M"], r["Jc"].T)
        assert_close(dyn.contact_inertia(q, p), Lambda_c, f"Lambda_c, case {i}")


def test_stance_dynamics_sympy(cases):
    for i, (q, qd, tau, p, r) in enumerate(cases):
        qdd_ref, lam_ref = kkt_reference(r["M"], r["h"], r["Jc"], r["Jcdot_qd"], tau)
        qdd, lam = dyn.stance_dynamics(q, qd, tau, p)
        assert_close(qdd, qdd_ref, f"stance qdd, case {i}")
        assert_close(lam, lam_ref, f"stance lam, case {i}")


def test_flight_dynamics_sympy(cases):
    for i, (q, qd, tau, p, r) in enumerate(cases):
        qdd_ref = np.linalg.solve(r["M"], dyn.S.T @ tau - r["h"])
        assert_close(dyn.flight_dynamics(q, qd, tau, p), qdd_ref, f"flight qdd, case {i}")


def test_kinetic_energy_sympy(cases):
    for i, (q, qd, tau, p, r) in enumerate(cases):
        assert_close(dyn.kinetic_energy(q, qd, p), r["K"], f"K, case {i}")


def test_potential_energy_sympy(cases):
    for i, (q, qd, tau, p, r) in enumerate(cases):
        assert_close(dyn.potential_energy(q, p), r["P"], f"P, case {i}")


def test_sympy_reference_is_not_degenerate(cases):
    """The reference itself must see velocity terms: h differs from gravity, Jcdot qd is nonzero."""
    q, qd, tau, p, r = cases[0]
    assert np.linalg.norm(r["h"] - r["G"]) > 1e-3 * (1.0 + np.linalg.norm(r["G"]))
    assert np.linalg.norm(r["Jcdot_qd"]) > 1e-3


# ----------------------------------------------------------------------------
# Pinocchio
# ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def pin_results(cases):
    """Pinocchio's terms for every case (one model per parameter set)."""
    out = []
    for q, qd, tau, p, _ in cases:
        model, foot_id = build_model(p)
        data = model.createData()
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T  # crba fills the upper triangle
        h = pin.rnea(model, data, q, qd, np.zeros(5)).copy()
        G = pin.computeGeneralizedGravity(model, data, q).copy()
        Jc, drift = foot_terms(model, data, foot_id, q, qd)
        pin.forwardKinematics(model, data, q)
        pin.updateFramePlacements(model, data)
        p_f = data.oMf[foot_id].translation[:2].copy()
        qdd, lam = constrained_forward_dynamics(model, data, foot_id, q, qd, tau)
        pin.computeAllTerms(model, data, q, qd)
        K = pin.computeKineticEnergy(model, data, q, qd)
        com = pin.centerOfMass(model, data, q)[:2].copy()
        out.append({"M": M, "h": h, "G": G, "Jc": Jc.copy(), "Jcdot_qd": drift.copy(), "p_f": p_f,
                    "qdd": qdd.copy(), "lam": lam, "K": K, "p_com": com})
    return out


def test_mass_matrix_pinocchio(cases, pin_results):
    for i, ((q, qd, tau, p, _), r) in enumerate(zip(cases, pin_results)):
        assert_close(dyn.mass_matrix(q, p), r["M"], f"M vs crba, case {i}")


def test_bias_forces_pinocchio(cases, pin_results):
    for i, ((q, qd, tau, p, _), r) in enumerate(zip(cases, pin_results)):
        assert_close(dyn.bias_forces(q, qd, p), r["h"], f"h vs rnea(q, v, 0), case {i}")


def test_gravity_forces_pinocchio(cases, pin_results):
    for i, ((q, qd, tau, p, _), r) in enumerate(zip(cases, pin_results)):
        assert_close(dyn.gravity_forces(q, p), r["G"], f"gravity, case {i}")


def test_contact_terms_pinocchio(cases, pin_results):
    for i, ((q, qd, tau, p, _), r) in enumerate(zip(cases, pin_results)):
        assert_close(dyn.foot_position(q, p), r["p_f"], f"foot, case {i}")
        assert_close(dyn.contact_jacobian(q, p), r["Jc"], f"Jc vs frame Jacobian, case {i}")
        assert_close(dyn.contact_jdot_qd(q, qd, p), r["Jcdot_qd"], f"Jcdot qd vs classical acc., case {i}")


def test_stance_dynamics_pinocchio(cases, pin_results):
    for i, ((q, qd, tau, p, _), r) in enumerate(zip(cases, pin_results)):
        qdd, lam = dyn.stance_dynamics(q, qd, tau, p)
        assert_close(qdd, r["qdd"], f"stance qdd vs pin.forwardDynamics, case {i}")
        assert_close(lam, r["lam"], f"stance lam vs pin lambda_c, case {i}")


def test_flight_dynamics_pinocchio(cases):
    for i, (q, qd, tau, p, _) in enumerate(cases):
        model, _ = build_model(p)
        qdd_ref = pin.aba(model, model.createData(), q, qd, dyn.S.T @ tau)
        assert_close(dyn.flight_dynamics(q, qd, tau, p), qdd_ref, f"flight vs aba, case {i}")


def test_energies_and_com_pinocchio(cases, pin_results):
    for i, ((q, qd, tau, p, _), r) in enumerate(zip(cases, pin_results)):
        assert_close(dyn.kinetic_energy(q, qd, p), r["K"], f"K, case {i}")
        assert_close(dyn.com_position(q, p), r["p_com"], f"COM, case {i}")
        assert_close(dyn.potential_energy(q, p), p.g * p.total_mass * r["p_com"][1], f"P, case {i}")
