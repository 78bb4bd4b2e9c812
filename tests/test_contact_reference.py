"""The unilateral-contact functions of leg_env.physics.dynamics against independent references.

References (``tests/contact_ref.py``; none of them calls ``leg_env``):

* the SymPy Lagrangian of ``tests/test_dynamics_reference.py`` (``M``, ``h``, ``Jc``, ``Jcdot qd``), with
  the non-symmetric slip KKT, the sticking impulse and ``Lambda = J M^-1 J^T`` solved by numpy;
* Pinocchio's ``impulseDynamics`` (restitution 0) for the sticking impact;
* the three momenta a foot impulse cannot change (whole robot about the foot, torso + thigh about the
  knee, ``th_b'``), written from link COM velocities and inertias;
* a brute-force integration of Routh's incremental impact process for the frictional impact;
* a brute-force enumeration of all 16 complementary index sets of the planar Coulomb contact LCP.

Tolerance: ``|a - b| <= RTOL (1 + |b|)`` (Euclidean norms, ``b`` the reference) unless a test states
another one with its reason. Every random case has its own random parameter set.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pinocchio as pin
import pytest

import contact_ref as cr
from conftest import random_params
from pin_model import build_model, foot_terms
from leg_env import physics as dyn
from leg_env.physics.params import LegParams

N_CASES = 200  # random (state, parameter set) pairs per test family
N_REST_CASES = 240  # foot at rest on the ground, for the mode test
N_PAINLEVE = 400  # (tau, mu) samples past the Painleve bound at the worst posture
SEED = 20240917
RTOL = 1e-10
POSITION_RANGE = 2.0  # |x_b|, |y_b| <= [m]
RATE_SCALE = 3.0  # std of the generalized velocities [m/s, rad/s]
REST_RATE_SCALE = 1.0  # std of the (projected) velocities of a foot at rest
TORQUE_RANGE = 50.0  # |tau| <= [N m] (slip test)
REST_TORQUE_FACTOR = 0.5  # |tau| <= this * m g (l1 + l2) in the mode test (all four modes occur)
MU_RANGE = (0.05, 1.5)  # friction coefficients of the slip test (both sides of mu_critical)
MU_BELOW_CRIT = (0.05, 0.9)  # mu = U(...) * min(mu_critical, MU_CAP) where mu < mu_critical is needed
MU_CAP = 1.5
MIN_K_REL = 1e-3  # slip test: redraw mu when |k_sigma| < MIN_K_REL * Lambda_yy (a singular KKT)
ROUTH_STEPS = 5_000  # increments of the brute-force Routh integration
MIN_MODE_COUNT = 10  # each mode / impact kind must occur at least this often in its sample


def assert_close(actual, reference, what: str, rtol: float = RTOL, atol_scale: float = 1.0) -> None:
    actual, reference = np.asarray(actual, dtype=float), np.asarray(reference, dtype=float)
    assert actual.shape == reference.shape, f"{what}: shape {actual.shape} != {reference.shape}"
    err = np.linalg.norm(actual - reference)
    assert err <= rtol * (atol_scale + np.linalg.norm(reference)), (
        f"{what}: |a - b| = {err:.3e}, |b| = {np.linalg.norm(reference):.3e}\na = {actual}\nb = {reference}"
    )


def _random_q(rng) -> np.ndarray:
    return np.concatenate([rng.uniform(-POSITION_RANGE, POSITION_RANGE, 2), rng.uniform(-np.pi, np.pi, 3)])


def _on_ground(q, p) -> np.ndarray:
    """``q`` with the base shifted so the foot is at ``y = 0``."""
    q = np.array(q, dtype=float)
    q[1] -= cr.terms(q, np.zeros(5), p)["p_f"][1]
    return q


def _with_foot_velocity(q, qd0, p, v_f) -> np.ndarray:
    """The velocity nearest to ``qd0`` (least squares) with foot velocity ``v_f``."""
    J = cr.terms(q, np.zeros(5), p)["Jc"]
    return qd0 + J.T @ np.linalg.solve(J @ J.T, np.asarray(v_f, float) - J @ qd0)


def _nominal():
    p = LegParams()
    q = dyn.static_equilibrium(p)[0]
    return p, q


# ----------------------------------------------------------------------------
# The API's constants
# ----------------------------------------------------------------------------


def test_mode_constants():
    assert (dyn.STICK, dyn.SLIP_FORWARD, dyn.SLIP_BACKWARD, dyn.FLIGHT) == (
        cr.STICK,
        cr.SLIP_FORWARD,
        cr.SLIP_BACKWARD,
        cr.FLIGHT,
    )
    assert dyn.REST_SPEED == 1e-9


# ----------------------------------------------------------------------------
# slip_dynamics: the non-symmetric KKT of the SymPy Lagrangian
# ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def slip_cases():
    rng = np.random.default_rng(SEED)
    out = []
    for i in range(N_CASES):
        p = random_params(rng)
        q = _random_q(rng)
        qd = RATE_SCALE * rng.standard_normal(5)
        tau = rng.uniform(-TORQUE_RANGE, TORQUE_RANGE, 2)
        r = cr.terms(q, qd, p)
        sigma = 1.0 if i % 2 == 0 else -1.0
        while True:
            mu = rng.uniform(*MU_RANGE)
            if abs(cr.k_sigma(r["Lambda"], mu, sigma)) > MIN_K_REL * r["Lambda"][1, 1]:
                break
        out.append((q, qd, tau, p, mu, sigma, r))
    return out


def test_slip_sample_covers_both_sides_of_the_bound(slip_cases):
    """Both sigmas, and k_sigma of both signs (the formula is tested past the Painleve bound too)."""
    ks = np.array([cr.k_sigma(r["Lambda"], mu, s) for _, _, _, _, mu, s, r in slip_cases])
    sigmas = np.array([c[5] for c in slip_cases])
    assert (sigmas > 0).sum() >= MIN_MODE_COUNT and (sigmas < 0).sum() >= MIN_MODE_COUNT
    assert (ks < 0).sum() >= 3 and (ks > 0).sum() >= MIN_MODE_COUNT


def test_slip_dynamics_sympy_kkt(slip_cases):
    for i, (q, qd, tau, p, mu, sigma, r) in enumerate(slip_cases):
        qdd_ref, lam_ref = cr.slip_kkt(r, tau, mu, sigma)
        qdd, lam = dyn.slip_dynamics(q, qd, tau, p, mu, sigma)
        assert_close(qdd, qdd_ref, f"slip qdd, case {i} (mu {mu}, sigma {sigma})")
        assert_close(lam, lam_ref, f"slip lam, case {i} (mu {mu}, sigma {sigma})")


def test_slip_dynamics_constraints(slip_cases):
    """``y_f'' = J_y qdd + gamma_y = 0`` and ``lam_x = -sigma mu lam_y``; the equations of motion hold."""
    for i, (q, qd, tau, p, mu, sigma, r) in enumerate(slip_cases):
        qdd, lam = dyn.slip_dynamics(q, qd, tau, p, mu, sigma)
        J, gam = r["Jc"], r["Jcdot_qd"]
        y_acc = J[1] @ qdd + gam[1]
        scale = np.linalg.norm(J[1]) * np.linalg.norm(qdd) + abs(gam[1])
        assert abs(y_acc) <= RTOL * (1.0 + scale), f"y_f'' = {y_acc:.3e}, case {i}"
        assert abs(lam[0] + sigma * mu * lam[1]) <= RTOL * (1.0 + abs(lam[1])), f"friction law, case {i}"
        residual = r["M"] @ qdd + r["h"] - cr.generalized_torque(tau) - J.T @ lam
        assert_close(residual, np.zeros(5), f"M qdd + h - S^T tau - J^T lam, case {i}",
                     atol_scale=1.0 + np.linalg.norm(r["M"] @ qdd) + np.linalg.norm(r["h"]))


def test_slip_reference_against_pinocchio(slip_cases):
    """The reference itself: Pinocchio's ABA with the reference contact force gives the reference qdd."""
    for i, (q, qd, tau, p, mu, sigma, r) in enumerate(slip_cases[:50]):
        qdd_ref, lam_ref = cr.slip_kkt(r, tau, mu, sigma)
        model, foot_id = build_model(p)
        data = model.createData()
        J, _ = foot_terms(model, data, foot_id, q, qd)
        qdd_pin = pin.aba(model, data, q, qd, cr.generalized_torque(tau) + J.T @ lam_ref)
        assert_close(qdd_ref, qdd_pin, f"reference slip qdd vs pin.aba, case {i}")


def test_slip_dynamics_batch(slip_cases):
    """One batched call (per-robot mu and sigma, leading shape (2, n/2)) equals the single calls."""
    p = slip_cases[0][3]
    q, qd, tau, mu, sigma = (np.array([c[k] for c in slip_cases]) for k in (0, 1, 2, 4, 5))
    n = len(slip_cases) // 2 * 2
    shape = (2, n // 2)
    qdd_b, lam_b = dyn.slip_dynamics(
        q[:n].reshape(shape + (5,)), qd[:n].reshape(shape + (5,)), tau[:n].reshape(shape + (2,)), p,
        mu[:n].reshape(shape), sigma[:n].reshape(shape),
    )
    assert qdd_b.shape == shape + (5,) and lam_b.shape == shape + (2,)
    for i in range(n):
        qdd, lam = dyn.slip_dynamics(q[i], qd[i], tau[i], p, mu[i], sigma[i])
        assert_close(qdd_b.reshape(n, 5)[i], qdd, f"batched slip qdd, row {i}")
        assert_close(lam_b.reshape(n, 2)[i], lam, f"batched slip lam, row {i}")
    # scalar mu and sigma broadcast over the batch
    qdd_s, lam_s = dyn.slip_dynamics(q[:n], qd[:n], tau[:n], p, 0.4, -1.0)
    for i in range(0, n, 17):
        qdd, lam = dyn.slip_dynamics(q[i], qd[i], tau[i], p, 0.4, -1.0)
        assert_close(qdd_s[i], qdd, f"broadcast slip qdd, row {i}")
        assert_close(lam_s[i], lam, f"broadcast slip lam, row {i}")


def test_free_foot_acceleration_sympy(slip_cases):
    """``(Lambda, a0)`` of the public helper against the SymPy terms."""
    for i, (q, qd, tau, p, mu, sigma, r) in enumerate(slip_cases):
        Lam, a0 = dyn.free_foot_acceleration(q, qd, tau, p)
        assert_close(Lam, r["Lambda"], f"Lambda, case {i}")
        assert_close(a0, cr.free_foot_acceleration(r, tau), f"a0, case {i}")


# ----------------------------------------------------------------------------
# mu_critical
# ----------------------------------------------------------------------------


def test_mu_critical_sympy(slip_cases):
    for i, (q, qd, tau, p, mu, sigma, r) in enumerate(slip_cases):
        L = r["Lambda"]
        mc = float(dyn.mu_critical(q, p))
        assert_close(mc, L[1, 1] / abs(L[0, 1]), f"mu_critical, case {i}")
        # its meaning: both slip directions well posed just below it, one ill posed just above it
        below = [cr.k_sigma(L, mc * (1.0 - 1e-6), s) for s in (1.0, -1.0)]
        above = [cr.k_sigma(L, mc * (1.0 + 1e-6), s) for s in (1.0, -1.0)]
        assert min(below) > 0.0, f"k_sigma below mu_critical: {below}, case {i}"
        assert min(above) < 0.0, f"k_sigma above mu_critical: {above}, case {i}"
    q_all = np.array([c[0] for c in slip_cases])
    p0 = slip_cases[0][3]
    batch = dyn.mu_critical(q_all, p0)
    assert batch.shape == (len(slip_cases),)
    for i in range(0, len(slip_cases), 7):
        assert_close(batch[i], dyn.mu_critical(q_all[i], p0), f"batched mu_critical, row {i}")


def test_mu_critical_notes_figures():
    """Nominal posture 1.008 and the notes' worst posture about 0.52 (notes give 3 and 2 digits)."""
    p, q = _nominal()
    assert abs(float(dyn.mu_critical(q, p)) - 1.008) <= 0.0005
    q_worst = np.array([0.0, 0.0, -0.45, -0.925, 0.05])
    assert abs(float(dyn.mu_critical(q_worst, p)) - 0.52) <= 0.005


# ----------------------------------------------------------------------------
# impact_map, mu = inf: sticking map
# ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def impact_cases():
    rng = np.random.default_rng(SEED + 1)
    out = []
    for _ in range(N_CASES):
        p = random_params(rng)
        q = _random_q(rng)
        qd = RATE_SCALE * rng.standard_normal(5)
        out.append((q, qd, p, cr.terms(q, qd, p)))
    return out


def test_impact_map_sticking_pinocchio(impact_cases):
    for i, (q, qd, p, r) in enumerate(impact_cases):
        model, foot_id = build_model(p)
        data = model.createData()
        J, _ = foot_terms(model, data, foot_id, q, qd)
        v_after = pin.impulseDynamics(model, data, q, qd, J, 0.0).copy()
        impulse = data.impulse_c.copy()
        qd_plus, P = dyn.impact_map(q, qd, p)
        assert_close(qd_plus, v_after, f"qd+ vs pin.impulseDynamics, case {i}")
        assert_close(P, impulse, f"impulse vs pin impulse_c, case {i}")
        qd_plus_inf, P_inf = dyn.impact_map(q, qd, p, math.inf)
        assert_close(qd_plus_inf, qd_plus, f"mu=inf explicit, case {i}")
        assert_close(P_inf, P, f"mu=inf explicit, case {i}")


def test_impact_map_sticking_momenta(impact_cases):
    """The three conserved momenta and ``v_f+ = 0`` pin ``qd+`` down (a 5x5 linear system, solved here)."""
    for i, (q, qd, p, r) in enumerate(impact_cases):
        qd_plus, P = dyn.impact_map(q, qd, p)
        m_minus, m_plus = cr.momenta(q, qd, p), cr.momenta(q, qd_plus, p)
        assert_close(m_plus, m_minus, f"momenta (H_foot, H_knee, th_b'), case {i}")
        assert_close(r["Jc"] @ qd_plus, np.zeros(2), f"v_f+ = J qd+, case {i}", atol_scale=1.0 + np.linalg.norm(qd))
        # closed-form reference qd+ from the 5 conditions
        C = np.vstack([np.array([cr.momenta(q, e, p) for e in np.eye(5)]).T, r["Jc"]])
        assert np.linalg.cond(C) < 1e8
        qd_ref = np.linalg.solve(C, np.concatenate([m_minus, [0.0, 0.0]]))
        assert_close(qd_plus, qd_ref, f"qd+ vs momenta oracle, case {i}")
        _, P_ref = cr.sticking_impulse(r)
        assert_close(P, P_ref, f"impulse vs SymPy Lambda P = -v_f-, case {i}")


def test_impact_map_sticking_energy(impact_cases):
    """Carnot: ``T- - T+ = 1/2 v_f-^T Lambda^-1 v_f-`` (Lambda from the SymPy M and J, solved)."""
    for i, (q, qd, p, r) in enumerate(impact_cases):
        qd_plus, _ = dyn.impact_map(q, qd, p)
        T_minus = cr.kinetic_energy(r)
        T_plus = 0.5 * qd_plus @ r["M"] @ qd_plus
        v = r["v_f"]
        loss_ref = 0.5 * v @ np.linalg.solve(r["Lambda"], v)
        assert loss_ref >= 0.0
        assert_close(T_minus - T_plus, loss_ref, f"kinetic energy lost, case {i}", atol_scale=1.0 + T_minus)


def test_impact_map_nominal_drop():
    """Vertical drop at 1 m/s in the nominal posture loses 30.7 % (2.305 J of 7.50 J) [notes: 3-4 digits]."""
    p, q = _nominal()
    qd = np.array([0.0, -1.0, 0.0, 0.0, 0.0])
    r = cr.terms(q, qd, p)
    qd_plus, P = dyn.impact_map(q, qd, p)
    T_minus, T_plus = cr.kinetic_energy(r), 0.5 * qd_plus @ r["M"] @ qd_plus
    assert abs(T_minus - 7.5) <= 1e-12
    assert abs((T_minus - T_plus) - 2.305) <= 0.0005
    assert abs((T_minus - T_plus) / T_minus - 0.307) <= 0.0005
    assert_close(qd_plus, cr.sticking_impulse(r)[0], "nominal drop qd+")
    # the same with the notes' friction: |P_x|/P_y = 0.317 < 0.8, so it sticks
    qd_f, P_f = dyn.impact_map(q, qd, p, 0.8)
    assert abs(abs(P_f[0]) / P_f[1] - 0.317) <= 0.0005
    assert_close(P_f, P, "nominal drop, mu = 0.8 sticks")


def test_impact_map_batch(impact_cases):
    p = impact_cases[0][2]
    q = np.array([c[0] for c in impact_cases])
    qd = np.array([c[1] for c in impact_cases])
    mu = np.where(np.arange(len(q)) % 3 == 0, np.inf, np.linspace(0.1, 1.2, len(q)))
    qd_b, P_b = dyn.impact_map(q, qd, p, mu)
    assert qd_b.shape == q.shape and P_b.shape == (len(q), 2)
    for i in range(len(q)):
        qd1, P1 = dyn.impact_map(q[i], qd[i], p, mu[i])
        assert_close(qd_b[i], qd1, f"batched impact qd+, row {i}")
        assert_close(P_b[i], P1, f"batched impact impulse, row {i}")


# ----------------------------------------------------------------------------
# impact_map, finite mu: unilateral frictional impact vs brute-force Routh
# ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def friction_cases():
    """Approaching feet (``v_fy- < 0``) with ``mu < 0.9 mu_critical``: a quarter pure vertical base drops
    (``v_fx- = 0`` exactly); a quarter prone to reversal (``mu < |Lambda_xy / Lambda_xx|`` and a small
    ``v_fx-`` against the direction friction accelerates it, so sliding stops early and reverses); the
    rest with the tangential foot speed 0-2x the normal one."""
    rng = np.random.default_rng(SEED + 2)
    out = []
    for i in range(N_CASES):
        p = random_params(rng)
        q = _random_q(rng)
        L = cr.terms(q, np.zeros(5), p)["Lambda"]
        mc = cr.mu_critical(L)
        mu = rng.uniform(*MU_BELOW_CRIT) * min(mc, MU_CAP)
        vy = -rng.uniform(0.2, 3.0)
        if i % 4 == 0:
            qd = np.array([0.0, vy, 0.0, 0.0, 0.0])
        else:
            if i % 4 == 1:
                mu = rng.uniform(*MU_BELOW_CRIT) * min(mc, MU_CAP, abs(L[0, 1] / L[0, 0]))
                vx = -np.sign(L[0, 1]) * rng.uniform(0.02, 0.5) * abs(vy)
            else:
                vx = rng.uniform(-1.0, 1.0) * abs(vy) * (0.2, 1.0, 2.0)[i % 3]
            qd = _with_foot_velocity(q, RATE_SCALE * rng.standard_normal(5), p, [vx, vy])
        out.append((q, qd, p, mu, cr.terms(q, qd, p)))
    return out


@pytest.fixture(scope="module")
def routh(friction_cases):
    """Brute-force Routh result per case, with its tolerance and the kind of impact."""
    Lam = np.array([c[4]["Lambda"] for c in friction_cases])
    v = np.array([c[4]["v_f"] for c in friction_cases])
    mu = np.array([c[3] for c in friction_cases])
    P, v_plus, dPy, flips = cr.routh_impact(Lam, v, mu, ROUTH_STEPS)
    # "stick": the sticking impulse is in the cone, so the API law takes it. Note that this is the
    # velocity-level (stick-first) choice, not pure Routh: in some of these cases (about 1 in 6 here) the
    # brute-force Routh process slides, stops and slides back (|L_xy/L_xx| > mu), ending with v_fx+ != 0
    # and a different impulse. Where the sticking impulse is outside the cone the two laws coincide
    # (Routh ending stuck would give exactly the sticking impulse, accumulated inside the cone), and
    # only there is the brute force the reference.
    kinds = []
    for (q, qd, p, m, r), f in zip(friction_cases, flips):
        P_stick = cr.sticking_impulse(r)[1]
        feasible = P_stick[1] >= 0.0 and abs(P_stick[0]) <= m * P_stick[1]
        kinds.append("stick" if feasible else ("reverse" if f > 0 else "slide"))
    # Tolerance of the brute force: one increment dP_y of P_y, the friction share mu dP_y of P_x, and the
    # chattering of v_x about 0 after sliding stops (amplitude R dP_y, R = |L_xy| + mu L_xx, the largest
    # |dv_x / dP_y|), which maps to an impulse error |Lambda^-1| R dP_y; x2 margin.
    R = np.abs(Lam[:, 0, 1]) + mu * Lam[:, 0, 0]
    Linv = np.array([np.linalg.norm(np.linalg.inv(L), 2) for L in Lam])
    tol_P = 2.0 * (1.0 + mu + Linv * R) * dPy
    return P, v_plus, tol_P, kinds


def test_friction_sample_covers_all_impact_kinds(routh):
    counts = Counter(routh[3])
    assert all(counts[k] >= MIN_MODE_COUNT for k in ("stick", "slide", "reverse")), counts


def test_routh_brute_force_is_converged(friction_cases, routh):
    """The reference: halving the increments keeps it within its own tolerance, and where sliding never
    stops (piecewise linear, no chattering) it is exact; it ends at ``v_fy = 0``."""
    n = 60
    Lam = np.array([c[4]["Lambda"] for c in friction_cases[:n]])
    v = np.array([c[4]["v_f"] for c in friction_cases[:n]])
    mu = np.array([c[3] for c in friction_cases[:n]])
    P2, _, _, _ = cr.routh_impact(Lam, v, mu, 2 * ROUTH_STEPS)
    P, v_plus, tol_P, kinds = routh
    for i in range(n):
        assert np.linalg.norm(P2[i] - P[i]) <= tol_P[i], f"Routh not converged, case {i}"
    assert np.all(v_plus[:, 1] == 0.0)
    Lam_all = np.array([c[4]["Lambda"] for c in friction_cases])
    for i, k in enumerate(kinds):
        if k != "slide":
            continue
        m, v_i, L = friction_cases[i][3], friction_cases[i][4]["v_f"], Lam_all[i]
        sigma = np.sign(v_i[0]) if v_i[0] != 0.0 else np.sign(L[0, 1])
        Py = -v_i[1] / cr.k_sigma(L, m, sigma)
        assert_close(P[i], [-sigma * m * Py, Py], f"Routh slide vs its closed form, case {i}", rtol=1e-9)


def test_impact_map_friction_vs_routh(friction_cases, routh):
    """Where the sticking impulse is outside the cone: equal to the brute-force Routh process within
    its stated tolerance (O(dP_y): about 1e-3 relative with ROUTH_STEPS increments; the observed error
    is below a tenth of it)."""
    P_ref, v_ref, tol_P, kinds = routh
    for i, ((q, qd, p, mu, r), kind) in enumerate(zip(friction_cases, kinds)):
        if kind == "stick":
            continue
        qd_plus, P = dyn.impact_map(q, qd, p, mu)
        err = np.linalg.norm(P - P_ref[i])
        assert err <= tol_P[i] + RTOL * (1.0 + np.linalg.norm(P_ref[i])), (
            f"{kind} impact, case {i}: impulse {P} vs Routh {P_ref[i]} (tol {tol_P[i]:.2e}); mu {mu}, "
            f"v_f- {r['v_f']}, Lambda {r['Lambda'].ravel()}"
        )
        G = np.linalg.solve(r["M"], r["Jc"].T)  # qd+ - qd- = G P
        assert np.linalg.norm(qd_plus - cr.apply_impulse(r, P_ref[i])) <= (
            np.linalg.norm(G, 2) * tol_P[i] + RTOL * (1.0 + np.linalg.norm(qd_plus))
        ), f"{kind} impact qd+, case {i}"


def test_impact_map_friction_identities(friction_cases, routh):
    """Exact identities: ``v_fy+ = 0``; ``P_y >= 0``; ``|P_x| <= mu P_y``; ``qd+ = qd- + M^-1 J^T P``;
    ``Delta T = 1/2 P.(v_f- + v_f+) <= 0``; the sticking impulse (to 1e-10) wherever it is in the cone."""
    kinds = routh[3]
    for i, ((q, qd, p, mu, r), kind) in enumerate(zip(friction_cases, kinds)):
        qd_plus, P = dyn.impact_map(q, qd, p, mu)
        scale = 1.0 + np.linalg.norm(P)
        v_minus, v_plus = r["v_f"], r["Jc"] @ qd_plus
        assert abs(v_plus[1]) <= RTOL * (1.0 + np.linalg.norm(v_minus)), f"v_fy+ = {v_plus[1]}, case {i}"
        assert P[1] >= -RTOL * scale, f"P_y = {P[1]}, case {i}"
        assert abs(P[0]) <= mu * P[1] + RTOL * scale, f"impulse outside the cone: {P}, mu {mu}, case {i}"
        assert_close(qd_plus, cr.apply_impulse(r, P), f"qd+ = qd- + M^-1 J^T P, case {i}")
        T_minus, T_plus = cr.kinetic_energy(r), 0.5 * qd_plus @ r["M"] @ qd_plus
        assert_close(T_plus - T_minus, 0.5 * P @ (v_minus + v_plus), f"Delta T, case {i}", atol_scale=1.0 + T_minus)
        assert T_plus <= T_minus + RTOL * (1.0 + T_minus), f"energy gained, case {i}"
        if kind == "stick":
            qd_s, P_s = cr.sticking_impulse(r)
            assert_close(P, P_s, f"sticking impulse (feasible), case {i}")
            assert_close(qd_plus, qd_s, f"sticking qd+ (feasible), case {i}")


def test_impact_map_friction_not_approaching():
    """No impulse when the foot is not approaching the ground (``v_fy- >= 0``), whatever mu."""
    rng = np.random.default_rng(SEED + 3)
    for i in range(50):
        p = random_params(rng)
        q = _random_q(rng)
        if i % 5 == 0:  # a tangential base motion: v_fy = 0 exactly however it is computed
            qd = np.array([rng.uniform(-2.0, 2.0), 0.0, 0.0, 0.0, 0.0])
        else:
            v = [rng.uniform(-2.0, 2.0), rng.uniform(0.05, 2.0)]
            qd = _with_foot_velocity(q, RATE_SCALE * rng.standard_normal(5), p, v)
        assert cr.terms(q, qd, p)["v_f"][1] >= 0.0
        mu = rng.uniform(0.05, 3.0)
        qd_plus, P = dyn.impact_map(q, qd, p, mu)
        assert np.all(P == 0.0), f"impulse {P} for qd- {qd}, case {i}"
        assert np.array_equal(qd_plus, qd), f"qd changed for qd- {qd}, case {i}"


def test_impact_map_friction_above_bound_identities():
    """Past the Painleve bound (``mu`` up to 3 mu_critical) only the law-independent identities hold:
    ``v_fy+ = 0`` for an approaching foot and no energy gain."""
    rng = np.random.default_rng(SEED + 4)
    for i in range(N_CASES // 2):
        p = random_params(rng)
        q = _random_q(rng)
        vy = -rng.uniform(0.2, 3.0)
        qd = _with_foot_velocity(q, RATE_SCALE * rng.standard_normal(5), p, [rng.uniform(-2, 2) * abs(vy), vy])
        r = cr.terms(q, qd, p)
        mu = rng.uniform(1.0, 3.0) * cr.mu_critical(r["Lambda"])
        if not np.isfinite(mu):
            continue
        qd_plus, P = dyn.impact_map(q, qd, p, mu)
        v_plus = r["Jc"] @ qd_plus
        assert abs(v_plus[1]) <= RTOL * (1.0 + np.linalg.norm(r["v_f"])), f"v_fy+ = {v_plus[1]}, case {i}"
        T_minus, T_plus = cr.kinetic_energy(r), 0.5 * qd_plus @ r["M"] @ qd_plus
        assert T_plus <= T_minus + RTOL * (1.0 + T_minus), f"energy gained, case {i}"
        assert_close(qd_plus, cr.apply_impulse(r, P), f"qd+ = qd- + M^-1 J^T P, case {i}")


def test_impact_map_swinging_leg():
    """The notes' swinging-leg case: nominal posture, base dropping at 1 m/s, hip swinging back at
    q1' = -2 rad/s, mu = 0.8. The sticking impulse would need |P_x|/P_y = 0.865 > 0.8, so the impact
    slides backward (sigma = -1) all the way: P = (1.303, 1.629) N s, v_fx+ = -0.039 m/s, 21.3 % of the
    kinetic energy lost (notes' figures, 3-4 digits: tolerance 5e-4)."""
    p, q = _nominal()
    qd = np.array([0.0, -1.0, 0.0, -2.0, 0.0])
    mu = 0.8
    r = cr.terms(q, qd, p)
    P_stick = cr.sticking_impulse(r)[1]
    assert abs(P_stick[0]) / P_stick[1] > mu
    qd_plus, P = dyn.impact_map(q, qd, p, mu)
    v_plus = r["Jc"] @ qd_plus
    assert np.abs(P - [1.303, 1.629]).max() <= 0.0005, P
    assert abs(v_plus[0] - (-0.039)) <= 0.0005, v_plus
    assert abs(v_plus[1]) <= RTOL
    T_minus, T_plus = cr.kinetic_energy(r), 0.5 * qd_plus @ r["M"] @ qd_plus
    assert abs((T_minus - T_plus) / T_minus - 0.213) <= 0.0005
    assert abs(P[0] - mu * P[1]) <= RTOL * (1.0 + np.linalg.norm(P))  # on the cone edge, sigma = -1
    P_ref, _, dPy, _ = cr.routh_impact(r["Lambda"][None], r["v_f"][None], np.array([mu]), ROUTH_STEPS)
    assert np.linalg.norm(P - P_ref[0]) <= 1e-9 * (1.0 + np.linalg.norm(P))  # no stop: the brute force is exact


# ----------------------------------------------------------------------------
# contact_mode vs brute-force LCP enumeration
# ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def rest_cases():
    """Foot at rest on the ground (base shifted to y_f = 0, qd projected to v_f = 0), random torques,
    mu drawn below mu_critical at that state; the LCP solutions by enumeration."""
    rng = np.random.default_rng(SEED + 5)
    out = []
    for _ in range(N_REST_CASES):
        p = random_params(rng)
        q = _on_ground(_random_q(rng), p)
        qd = _with_foot_velocity(q, REST_RATE_SCALE * rng.standard_normal(5), p, [0.0, 0.0])
        r = cr.terms(q, qd, p)
        tau = rng.uniform(-1.0, 1.0, 2) * REST_TORQUE_FACTOR * p.weight * (p.l1 + p.l2)
        mc = cr.mu_critical(r["Lambda"])
        mu = rng.uniform(*MU_BELOW_CRIT) * min(mc, MU_CAP)
        a0 = cr.free_foot_acceleration(r, tau)
        sols, continuum = cr.lcp_solutions(r["Lambda"], a0, mu)
        out.append((q, qd, tau, p, mu, r, a0, sols, continuum))
    return out


def test_rest_cases_are_at_rest(rest_cases):
    for i, (q, qd, tau, p, mu, r, a0, sols, cont) in enumerate(rest_cases):
        assert abs(r["p_f"][1]) <= 1e-12 and np.abs(r["v_f"]).max() <= 1e-3 * dyn.REST_SPEED, f"case {i}"


def test_lcp_has_exactly_one_solution_below_bound(rest_cases):
    for i, (q, qd, tau, p, mu, r, a0, sols, cont) in enumerate(rest_cases):
        assert len(sols) == 1 and not cont, f"case {i}: {len(sols)} LCP solutions (continuum {cont}), mu {mu}"


def test_lcp_sample_covers_all_modes(rest_cases):
    counts = Counter(cr.lcp_mode(*c[7][0], c[6]) for c in rest_cases)
    assert all(counts[m] >= MIN_MODE_COUNT for m in cr.MODE_NAMES), counts


def test_contact_mode_vs_lcp(rest_cases):
    for i, (q, qd, tau, p, mu, r, a0, sols, cont) in enumerate(rest_cases):
        expected = cr.lcp_mode(*sols[0], a0)
        got = dyn.contact_mode(q, qd, tau, p, mu)
        assert np.ndim(got) == 0
        assert int(got) == expected, (
            f"case {i}: contact_mode {int(got)} != LCP {cr.MODE_NAMES[expected]} (lam {sols[0][0]}, "
            f"a_f {sols[0][1]}); q {q}, qd {qd}, tau {tau}, mu {mu}, params {p}"
        )


def test_contact_mode_batch(rest_cases):
    p = rest_cases[0][3]
    q, qd, tau, mu = (np.array([c[k] for c in rest_cases]) for k in (0, 1, 2, 4))
    # the states are at rest for their own parameters; under p they are still valid inputs
    modes = dyn.contact_mode(q, qd, tau, p, mu)
    assert modes.shape == (len(q),)
    for i in range(len(q)):
        assert modes[i] == int(dyn.contact_mode(q[i], qd[i], tau[i], p, mu[i])), f"row {i}"


def test_contact_mode_sliding_foot():
    """A foot sliding on the ground (|v_fx| >> REST_SPEED, v_fy = 0), mu below the bound: SLIP in the
    direction of v_fx if that slip's lam_y (SymPy KKT) is >= 0, else FLIGHT."""
    rng = np.random.default_rng(SEED + 6)
    counts = Counter()
    for i in range(N_CASES):
        p = random_params(rng)
        q = _on_ground(_random_q(rng), p)
        vx = rng.choice([-1.0, 1.0]) * rng.uniform(1e-3, 2.0)
        qd = _with_foot_velocity(q, REST_RATE_SCALE * rng.standard_normal(5), p, [vx, 0.0])
        r = cr.terms(q, qd, p)
        tau = rng.uniform(-1.0, 1.0, 2) * REST_TORQUE_FACTOR * p.weight * (p.l1 + p.l2)
        mu = rng.uniform(*MU_BELOW_CRIT) * min(cr.mu_critical(r["Lambda"]), MU_CAP)
        sigma = np.sign(r["v_f"][0])
        _, lam = cr.slip_kkt(r, tau, mu, sigma)
        expected = (cr.SLIP_FORWARD if sigma > 0 else cr.SLIP_BACKWARD) if lam[1] >= 0.0 else cr.FLIGHT
        counts[expected] += 1
        got = int(dyn.contact_mode(q, qd, tau, p, mu))
        assert got == expected, f"case {i}: {got} != {expected}, lam {lam}, v_f {r['v_f']}"
    assert all(counts[m] >= MIN_MODE_COUNT for m in (cr.SLIP_FORWARD, cr.SLIP_BACKWARD, cr.FLIGHT)), counts


# ----------------------------------------------------------------------------
# Past the Painleve bound: the notes' worst posture
# ----------------------------------------------------------------------------


def test_painleve_worst_posture():
    """At rest past the bound the LCP can have several solutions (STICK + SLIP_FORWARD with k_+ < 0 +
    FLIGHT here) but never none: for ``a0_y >= 0`` FLIGHT is a solution, and for ``a0_y < 0`` along the
    slip line ``y_f'' = 0`` parametrised by ``rho = lam_x / lam_y`` the foot's ``x_f''`` runs to -inf/+inf
    at the pole ``k(rho) = 0``, so if the end of the cone with ``k > 0`` is not a consistent slip, ``x_f''``
    changes sign inside the cone: a consistent STICK. So the documented "none consistent -> STICK" rule
    cannot be reached by a foot at rest (asserted over the sample); where several modes are consistent,
    ``contact_mode`` must return one of them, and STICK (the jam rule) is what the issue asks for."""
    p = LegParams()
    q = _on_ground(np.array([0.0, 0.0, -0.45, -0.925, 0.05]), p)
    rng = np.random.default_rng(SEED + 7)
    r0 = cr.terms(q, np.zeros(5), p)
    mc = cr.mu_critical(r0["Lambda"])
    assert abs(mc - 0.52) <= 0.005
    assert_close(dyn.mu_critical(q, p), mc, "mu_critical at the worst posture")
    counts = Counter()
    for i in range(N_PAINLEVE):
        qd = np.zeros(5)
        if i % 2:
            qd = _with_foot_velocity(q, REST_RATE_SCALE * rng.standard_normal(5), p, [0.0, 0.0])
        r = cr.terms(q, qd, p)
        tau = rng.uniform(-TORQUE_RANGE, TORQUE_RANGE, 2)
        mu = rng.uniform(1.0, 3.0) * mc
        a0 = cr.free_foot_acceleration(r, tau)
        sols, cont = cr.lcp_solutions(r["Lambda"], a0, mu)
        modes = sorted(cr.lcp_mode(lam, a_f, a0) for lam, a_f in sols)
        counts[len(sols)] += 1
        assert len(sols) >= 1 and not cont, f"{len(sols)} LCP solutions (continuum {cont}): tau {tau}, mu {mu}"
        got = int(dyn.contact_mode(q, qd, tau, p, mu))
        assert got in modes, f"contact_mode {got} not an LCP solution {modes}: tau {tau}, mu {mu}"
        if len(sols) == 1:
            assert got == modes[0]
        else:
            assert got == cr.STICK, f"several solutions {modes}, contact_mode {got}: tau {tau}, mu {mu}"
    assert counts[3] >= MIN_MODE_COUNT, counts  # the indeterminate case really is exercised
