"""Identities the dynamics must satisfy, the lesson's Problems 1-4, batching and input validation.

Derivatives are taken by central finite differences of the public functions, so these checks
are independent of how ``leg_env.physics.dynamics`` computes its terms. Tolerances are norm-relative:
``|a - b| <= tol * (1 + |b|)``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from conftest import random_params
from leg_env import physics as dyn
from leg_env.physics.params import PARAM_NAMES, LegParams

N_STATES = 200  # random (state, parameter set) pairs per identity
SEED = 7
RATE_SCALE = 2.0  # std of the random generalized velocities [m/s, rad/s]
TORQUE_RANGE = 50.0  # |tau| <= [N m]
FD_STEP = 1e-5  # central-difference step for first derivatives
FD_TOL = 1e-7  # relative tolerance of first-derivative checks
COM_FD_STEP = 1e-3  # step of the 5-point second-derivative stencil along the trajectory
COM_FD_TOL = 1e-6
EXACT_TOL = 1e-10  # identities that hold to round-off
LEAD_SHAPES = [(1,), (7,), (3, 4, 5), (2, 1, 3)]  # leading batch axes for batched == stacked singles
DEFAULT_KNEE = 0.8
DEFAULT_KNEE_TORQUE = -24.1  # [N m], lesson defaults, knee 0.8 (statics re-derived in the test below)
BAD_VALUES = [float("nan"), float("inf"), -float("inf"), 0.0, -1.0, "1.0", None, True, [1.0]]
BAD_G_VALUES = [float("nan"), float("inf"), -9.81, "9.81", None]


def assert_close(actual, reference, tol, what=""):
    actual, reference = np.asarray(actual, dtype=float), np.asarray(reference, dtype=float)
    err = np.linalg.norm(actual - reference)
    assert err <= tol * (1.0 + np.linalg.norm(reference)), f"{what}: |a-b| = {err:.3e}\na = {actual}\nb = {reference}"


def random_state(rng, rate_scale=RATE_SCALE):
    q = np.concatenate([rng.uniform(-2.0, 2.0, 2), rng.uniform(-np.pi, np.pi, 3)])
    qd = rate_scale * rng.standard_normal(5)
    tau = rng.uniform(-TORQUE_RANGE, TORQUE_RANGE, 2)
    return q, qd, tau


@pytest.fixture(scope="module")
def cases():
    rng = np.random.default_rng(SEED)
    return [(*random_state(rng), random_params(rng)) for _ in range(N_STATES)]


def central_difference(f, q, step=FD_STEP):
    """d f / d q by central differences, stacked along the last axis: shape f(q).shape + (5,)."""
    E = step * np.eye(5)
    return np.stack([(f(q + E[k]) - f(q - E[k])) / (2.0 * step) for k in range(5)], axis=-1)


# ----------------------------------------------------------------------------
# Mass matrix, Coriolis and gravity
# ----------------------------------------------------------------------------


def test_mass_matrix_symmetric_positive_definite(cases):
    for q, qd, tau, p in cases:
        M = dyn.mass_matrix(q, p)
        np.testing.assert_array_equal(M, M.T)
        assert np.linalg.eigvalsh(M).min() > 0.0


def christoffel_terms(q, qd, p):
    """Mdot and C (Christoffel symbols of the first kind) from finite differences of M."""
    dM = central_difference(lambda x: dyn.mass_matrix(x, p), q)  # dM[i, j, k] = dM_ij / dq_k
    Mdot = dM @ qd
    # C_ij = sum_k 1/2 (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i) qd_k
    Gamma = 0.5 * (dM + np.transpose(dM, (0, 2, 1)) - np.transpose(dM, (2, 0, 1)))
    C = Gamma @ qd
    return Mdot, C


def test_mdot_minus_2c_is_skew_symmetric(cases):
    rng = np.random.default_rng(1)
    for q, qd, tau, p in cases:
        Mdot, C = christoffel_terms(q, qd, p)
        N = Mdot - 2.0 * C
        scale = 1.0 + np.linalg.norm(Mdot)
        assert np.linalg.norm(N + N.T) <= FD_TOL * scale
        x = rng.standard_normal(5)
        assert abs(x @ N @ x) <= FD_TOL * scale * (x @ x)


def test_bias_minus_gravity_is_coriolis_times_velocity(cases):
    for i, (q, qd, tau, p) in enumerate(cases):
        _, C = christoffel_terms(q, qd, p)
        h_minus_G = dyn.bias_forces(q, qd, p) - dyn.gravity_forces(q, p)
        assert_close(h_minus_G, C @ qd, FD_TOL, f"h - G vs C qd, case {i}")


def test_bias_at_zero_velocity_is_gravity(cases):
    for q, qd, tau, p in cases:
        np.testing.assert_array_equal(dyn.bias_forces(q, np.zeros(5), p), dyn.gravity_forces(q, p))


def test_gravity_is_gradient_of_potential_energy(cases):
    for i, (q, qd, tau, p) in enumerate(cases):
        grad = central_difference(lambda x: dyn.potential_energy(x, p), q)
        assert_close(dyn.gravity_forces(q, p), grad, FD_TOL, f"gravity vs dP/dq, case {i}")


def test_kinetic_energy_is_quadratic_form(cases):
    for q, qd, tau, p in cases:
        assert_close(dyn.kinetic_energy(q, qd, p), 0.5 * qd @ dyn.mass_matrix(q, p) @ qd, EXACT_TOL)


# ----------------------------------------------------------------------------
# Contact kinematics and the constrained solve
# ----------------------------------------------------------------------------


def test_contact_jacobian_is_derivative_of_foot_position(cases):
    for i, (q, qd, tau, p) in enumerate(cases):
        J_fd = central_difference(lambda x: dyn.foot_position(x, p), q)
        assert_close(dyn.contact_jacobian(q, p), J_fd, FD_TOL, f"Jc vs dp_f/dq, case {i}")


def test_jdot_qd_is_derivative_of_jc_qd(cases):
    for i, (q, qd, tau, p) in enumerate(cases):
        d_Jqd = central_difference(lambda x: dyn.contact_jacobian(x, p) @ qd, q)
        assert_close(dyn.contact_jdot_qd(q, qd, p), d_Jqd @ qd, FD_TOL, f"Jcdot qd, case {i}")


def test_stance_solution_satisfies_both_kkt_rows(cases):
    for i, (q, qd, tau, p) in enumerate(cases):
        qdd, lam = dyn.stance_dynamics(q, qd, tau, p)
        M, h, Jc = dyn.mass_matrix(q, p), dyn.bias_forces(q, qd, p), dyn.contact_jacobian(q, p)
        jd = dyn.contact_jdot_qd(q, qd, p)
        lhs = M @ qdd + h
        assert_close(lhs, dyn.S.T @ tau + Jc.T @ lam, EXACT_TOL, f"M qdd + h = S^T tau + Jc^T lam, case {i}")
        assert np.linalg.norm(Jc @ qdd + jd) <= EXACT_TOL * (1.0 + np.linalg.norm(jd) + np.linalg.norm(qdd))


def test_flight_solution_satisfies_equations_of_motion(cases):
    for i, (q, qd, tau, p) in enumerate(cases):
        qdd = dyn.flight_dynamics(q, qd, tau, p)
        M, h = dyn.mass_matrix(q, p), dyn.bias_forces(q, qd, p)
        assert_close(M @ qdd + h, dyn.S.T @ tau, EXACT_TOL, f"flight EoM, case {i}")


def com_acceleration(q, qd, qdd, p, e=COM_FD_STEP):
    """d^2/dt^2 of the COM along q(t) = q + t qd + t^2/2 qdd at t = 0 (5-point stencil)."""
    c = {k: dyn.com_position(q + k * e * qd + 0.5 * (k * e) ** 2 * qdd, p) for k in (-2, -1, 0, 1, 2)}
    return (-c[2] + 16.0 * c[1] - 30.0 * c[0] + 16.0 * c[-1] - c[-2]) / (12.0 * e * e)


def test_total_mass_times_com_acceleration_is_external_force(cases):
    for i, (q, qd, tau, p) in enumerate(cases):
        qdd, lam = dyn.stance_dynamics(q, qd, tau, p)
        force = p.total_mass * com_acceleration(q, qd, qdd, p)
        assert_close(force, lam + np.array([0.0, -p.weight]), COM_FD_TOL, f"stance m a_com, case {i}")
        qdd = dyn.flight_dynamics(q, qd, tau, p)
        force = p.total_mass * com_acceleration(q, qd, qdd, p)
        assert_close(force, [0.0, -p.weight], COM_FD_TOL, f"flight m a_com, case {i}")


def test_torso_angular_acceleration_is_minus_hip_torque_over_inertia(cases):
    for q, qd, tau, p in cases:
        expected = -tau[0] / p.I_b
        assert_close(dyn.stance_dynamics(q, qd, tau, p)[0][2], expected, EXACT_TOL)
        assert_close(dyn.flight_dynamics(q, qd, tau, p)[2], expected, EXACT_TOL)


# ----------------------------------------------------------------------------
# Static equilibrium
# ----------------------------------------------------------------------------


def cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def statics_torques(q, lam, p):
    """Hip and knee torques from free-body moment balance (not from the generalized forces).

    Shank about the knee: tau_knee + (p_f - p_k) x lam + (p_c2 - p_k) x (0, -m2 g) = 0.
    Thigh + shank about the hip: tau_hip + (p_f - p_h) x lam + sum (p_ci - p_h) x (0, -mi g) = 0.
    """
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    u1, u2 = np.array([math.cos(th1), math.sin(th1)]), np.array([math.cos(th2), math.sin(th2)])
    W1, W2 = np.array([0.0, -p.m1 * p.g]), np.array([0.0, -p.m2 * p.g])
    tau_knee = -(cross(p.l2 * u2, lam) + cross(p.c2 * u2, W2))
    tau_hip = -(cross(p.l1 * u1 + p.l2 * u2, lam) + cross(p.c1 * u1, W1) + cross(p.l1 * u1 + p.c2 * u2, W2))
    return np.array([tau_hip, tau_knee])


@pytest.mark.parametrize("seed", [None, 0, 1, 2, 3, 4])
def test_static_equilibrium_is_at_rest(seed):
    p = LegParams() if seed is None else random_params(np.random.default_rng(seed))
    q, tau, lam = dyn.static_equilibrium(p, knee=DEFAULT_KNEE)
    assert q[2] == 0.0 and q[4] == DEFAULT_KNEE
    assert_close(dyn.foot_position(q, p), [0.0, 0.0], EXACT_TOL)
    assert abs(dyn.com_position(q, p)[0]) <= EXACT_TOL  # COM above the foot
    knee_y = q[1] + p.l1 * math.sin(q[2] + q[3])
    assert knee_y < q[1]  # knee below the hip
    assert_close(lam, [0.0, p.weight], EXACT_TOL)
    assert_close(tau, statics_torques(q, lam, p), EXACT_TOL, "holding torques vs moment balance")
    qdd, lam_solved = dyn.stance_dynamics(q, np.zeros(5), tau, p)
    assert np.abs(qdd).max() <= EXACT_TOL * 100.0
    assert_close(lam_solved, [0.0, p.weight], EXACT_TOL)


def test_static_equilibrium_at_lesson_defaults():
    p = LegParams()
    q, tau, lam = dyn.static_equilibrium(p, knee=DEFAULT_KNEE)
    np.testing.assert_allclose(tau, [0.0, DEFAULT_KNEE_TORQUE], atol=0.05)
    np.testing.assert_allclose(lam, [0.0, 147.15], atol=1e-9)


# ----------------------------------------------------------------------------
# The lesson's Problems 1-4
# ----------------------------------------------------------------------------


def test_problem1_stance_has_three_dof(cases):
    for q, qd, tau, p in cases:
        Jc = dyn.contact_jacobian(q, p)
        assert np.linalg.matrix_rank(Jc) == 2
        N = scipy.linalg.null_space(Jc)
        assert N.shape == (5, 3)
        assert np.abs(Jc @ N).max() <= EXACT_TOL


def test_problem2_selection_matrix():
    tau = np.array([1.5, -2.5])
    np.testing.assert_array_equal(dyn.S.T @ tau, [0.0, 0.0, 0.0, 1.5, -2.5])
    np.testing.assert_array_equal(dyn.S, np.hstack([np.zeros((2, 3)), np.eye(2)]))


def test_problem2_torques_enter_actuated_rows_only(cases):
    """The generalized force the solvers apply, M qdd + h - Jc^T lam, is tau in entries 4, 5 and zero elsewhere."""
    for q, qd, tau, p in cases:
        M, h, Jc = dyn.mass_matrix(q, p), dyn.bias_forces(q, qd, p), dyn.contact_jacobian(q, p)
        qdd, lam = dyn.stance_dynamics(q, qd, tau, p)
        Q = M @ qdd + h - Jc.T @ lam
        assert_close(Q, [0.0, 0.0, 0.0, tau[0], tau[1]], EXACT_TOL)


def analytic_contact_jacobian(q, p):
    """Problem 3: dp_f/dq column by column."""
    th1 = q[2] + q[3]
    th2 = th1 + q[4]
    dp_dth1 = p.l1 * np.array([-math.sin(th1), math.cos(th1)])
    dp_dth2 = p.l2 * np.array([-math.sin(th2), math.cos(th2)])
    return np.column_stack([[1.0, 0.0], [0.0, 1.0], dp_dth1 + dp_dth2, dp_dth1 + dp_dth2, dp_dth2])


def test_problem3_analytic_contact_jacobian(cases):
    for q, qd, tau, p in cases:
        assert_close(dyn.contact_jacobian(q, p), analytic_contact_jacobian(q, p), EXACT_TOL)


def test_problem4_contact_inertia_spd(cases):
    for q, qd, tau, p in cases:
        Lambda_c = dyn.contact_inertia(q, p)
        assert_close(Lambda_c, Lambda_c.T, EXACT_TOL)
        assert np.linalg.eigvalsh(Lambda_c).min() > 0.0
        M, Jc = dyn.mass_matrix(q, p), dyn.contact_jacobian(q, p)
        assert_close(Lambda_c, Jc @ np.linalg.solve(M, Jc.T), EXACT_TOL)


# ----------------------------------------------------------------------------
# Batched calls equal stacked single calls
# ----------------------------------------------------------------------------

PUBLIC_FUNCTIONS = {
    "mass_matrix": ("q",),
    "bias_forces": ("q", "qd"),
    "gravity_forces": ("q",),
    "contact_jacobian": ("q",),
    "contact_jdot_qd": ("q", "qd"),
    "foot_position": ("q",),
    "com_position": ("q",),
    "contact_inertia": ("q",),
    "stance_dynamics": ("q", "qd", "tau"),
    "flight_dynamics": ("q", "qd", "tau"),
    "kinetic_energy": ("q", "qd"),
    "potential_energy": ("q",),
}


def as_tuple(out):
    return out if isinstance(out, tuple) else (out,)


# built from numpy linear algebra on stacks rather than one compiled kernel: equal to round-off
NUMPY_COMPOSED = {"contact_inertia", "kinetic_energy"}


def assert_stacked_equal(batched, singles, lead, exact):
    for k, b in enumerate(batched):
        s = np.array([one[k] for one in singles]).reshape(lead + np.shape(singles[0][k]))
        assert b.shape == s.shape
        if exact:
            np.testing.assert_array_equal(b, s)
        else:
            np.testing.assert_allclose(b, s, rtol=1e-14, atol=1e-14 * (1.0 + np.abs(s).max()))


@pytest.mark.parametrize("name", list(PUBLIC_FUNCTIONS))
@pytest.mark.parametrize("lead", LEAD_SHAPES, ids=str)
def test_batched_equals_stacked_singles(name, lead):
    rng = np.random.default_rng([list(PUBLIC_FUNCTIONS).index(name), *lead])
    p = random_params(rng)
    n = int(np.prod(lead))
    states = [random_state(rng) for _ in range(n)]
    arrays = {k: np.array([s[j] for s in states]).reshape(lead + (len(states[0][j]),))
              for j, k in enumerate(("q", "qd", "tau"))}
    f = getattr(dyn, name)
    args = PUBLIC_FUNCTIONS[name]
    batched = as_tuple(f(*(arrays[a] for a in args), p))
    singles = [as_tuple(f(*(s[("q", "qd", "tau").index(a)] for a in args), p)) for s in states]
    assert_stacked_equal(batched, singles, lead, exact=name not in NUMPY_COMPOSED)


@pytest.mark.parametrize("name", ["stance_dynamics", "flight_dynamics"])
def test_single_torque_broadcasts_against_batch(name):
    rng = np.random.default_rng(3)
    p = random_params(rng)
    states = [random_state(rng) for _ in range(6)]
    q = np.array([s[0] for s in states])
    qd = np.array([s[1] for s in states])
    tau = np.array([12.0, -7.0])
    f = getattr(dyn, name)
    batched = as_tuple(f(q, qd, tau, p))
    singles = [as_tuple(f(s[0], s[1], tau, p)) for s in states]
    assert_stacked_equal(batched, singles, (6,), exact=True)
    # one velocity against many configurations too
    batched = as_tuple(f(q, qd[0], tau, p))
    singles = [as_tuple(f(s[0], qd[0], tau, p)) for s in states]
    assert_stacked_equal(batched, singles, (6,), exact=True)


def test_inputs_accept_lists():
    p = LegParams()
    q, tau, _ = dyn.static_equilibrium(p)
    a = dyn.stance_dynamics(list(q), [0] * 5, list(tau), p)
    b = dyn.stance_dynamics(q, np.zeros(5), tau, p)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


# ----------------------------------------------------------------------------
# Validation
# ----------------------------------------------------------------------------


@pytest.mark.parametrize("field", [n for n in PARAM_NAMES if n != "g"])
@pytest.mark.parametrize("value", BAD_VALUES, ids=repr)
def test_invalid_params_raise_naming_the_field(field, value):
    with pytest.raises(ValueError, match=rf"\b{field}\b"):
        LegParams(**{field: value})


@pytest.mark.parametrize("value", BAD_G_VALUES, ids=repr)
def test_invalid_gravity_raises(value):
    with pytest.raises(ValueError, match=r"\bg\b"):
        LegParams(g=value)


def test_zero_gravity_is_valid():
    assert LegParams(g=0.0).weight == 0.0


def test_unknown_param_name_raises():
    with pytest.raises(ValueError, match="mass"):
        LegParams.from_any({"mass": 1.0})


BAD_Q_SHAPES = [(), (4,), (6,), (3, 4), (5, 2)]


@pytest.mark.parametrize("shape", BAD_Q_SHAPES, ids=str)
@pytest.mark.parametrize("name", list(PUBLIC_FUNCTIONS))
def test_wrong_shaped_q_raises(name, shape):
    p = LegParams()
    args = {"q": np.zeros(shape), "qd": np.zeros(5), "tau": np.zeros(2)}
    with pytest.raises(ValueError):
        getattr(dyn, name)(*(args[a] for a in PUBLIC_FUNCTIONS[name]), p)


@pytest.mark.parametrize("name", [n for n, a in PUBLIC_FUNCTIONS.items() if "qd" in a])
def test_wrong_shaped_qd_and_tau_raise(name):
    p = LegParams()
    args = PUBLIC_FUNCTIONS[name]
    good = {"q": np.zeros(5), "qd": np.zeros(5), "tau": np.zeros(2)}
    for bad in ({"qd": np.zeros(4)}, {"tau": np.zeros(3)}, {"q": np.zeros((3, 5)), "qd": np.zeros((4, 5))}):
        if not set(bad) <= set(args):
            continue
        with pytest.raises(ValueError):
            getattr(dyn, name)(*({**good, **bad}[a] for a in args), p)


def test_com_state_is_the_com_and_its_derivative():
    """``com_state``: the position is ``com_position``'s, the velocity the centred difference of it along ``qd``."""
    rng = np.random.default_rng(7)
    for _ in range(20):
        p = random_params(rng)
        q, qd = rng.normal(size=(4, 5)), rng.normal(size=(4, 5))
        pos, vel = dyn.com_state(q, qd, p)
        np.testing.assert_array_equal(pos, dyn.com_position(q, p))
        h = 1e-6
        fd = (dyn.com_position(q + h * qd, p) - dyn.com_position(q - h * qd, p)) / (2 * h)
        np.testing.assert_allclose(vel, fd, rtol=1e-7, atol=1e-8)
