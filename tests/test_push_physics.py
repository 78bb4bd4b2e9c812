"""A horizontal force on the torso's COM (the push of ``leg_env/PlanarLegPush-v2``) in the dynamics.

``M qdd + h = S^T tau + Jc^T lam + Q`` with ``Q = J_b^T (F, 0) = (F, 0, 0, 0, 0)`` (the base point is the
torso's COM). Checked against:

* the KKT systems of the SymPy Lagrangian with ``Q`` added, independently of the closed forms
  (``stance_dynamics`` and the flight and slip solves at ``p[LOAD_X] = F``);
* the event-driven SciPy reference of ``tests/hybrid_ref.py`` (DOP853, 1e-12) with ``Q`` added to every
  mode's right-hand side, over pushes that make the standing robot slip, and in flight;
* the balance laws over a push: the whole robot's momentum change equals the push's impulse plus the
  ground's (continuous and impulsive, the hybrid step's accumulators) plus gravity's, and its energy
  change equals the actuators' and the push's work minus the dissipation.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import hybrid_ref as H
from contact_ref import terms
from leg_env._core import kernels
from leg_env import physics as dyn
from leg_env.physics.hybrid import hybrid_step
from leg_env.physics.params import LegParams

DT = 0.01
LOADS = (-120.0, -35.0, 60.0, 150.0)  # [N]
KKT_TOL = 1e-9  # closed forms vs the SymPy KKT, relative to the accelerations' scale
STATE_TOL = 1e-6  # one hybrid step vs the SciPy reference [m, rad; m/s, rad/s]
EVENT_TIME_TOL = 1e-7  # [s]
MOMENTUM_TOL = 1e-6  # [N s]: RK4's own error per step (v_com is not linear in q), about 2e-7 of the step's impulse
ENERGY_TOL = 2e-5  # [J]


def Q(F: float) -> np.ndarray:
    return np.array([F, 0.0, 0.0, 0.0, 0.0])


def _random_states(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    p = LegParams()
    q_nom, _, _ = dyn.static_equilibrium(p)
    out = []
    for _ in range(n):
        q = q_nom + np.r_[rng.uniform(-0.5, 0.5, 2), rng.uniform(-0.3, 0.3, 3)]
        qd = rng.uniform(-2.0, 2.0, 5)
        tau = rng.uniform(-50.0, 50.0, 2)
        out.append((q, qd, tau, float(rng.choice(LOADS))))
    return p, out


def test_stance_and_flight_closed_forms_match_the_kkt_with_the_push():
    p, cases = _random_states(40)
    for q, qd, tau, F in cases:
        r = terms(q, qd, p)
        M, J, h = r["M"], r["Jc"], r["h"]
        rhs = np.r_[0.0, 0.0, 0.0, tau] - h + Q(F)
        A = np.block([[M, -J.T], [J, np.zeros((2, 2))]])
        x = np.linalg.solve(A, np.r_[rhs, -r["Jcdot_qd"]])
        pl = dyn.params_array(p, F)
        qdd, lam = _stance(q, qd, tau, pl)
        scale = 1.0 + np.abs(x).max()
        assert np.abs(qdd - x[:5]).max() < KKT_TOL * scale and np.abs(lam - x[5:]).max() < KKT_TOL * scale, (F, qdd, x)
        qdd_f = np.linalg.solve(M, rhs)
        got = _flight(q, qd, tau, pl)
        assert np.abs(got - qdd_f).max() < KKT_TOL * (1.0 + np.abs(qdd_f).max()), (F, got, qdd_f)


def test_slip_solve_matches_the_kkt_with_the_push():
    p, cases = _random_states(40, seed=1)
    mu = 0.5
    for q, qd, tau, F in cases:
        r = terms(q, qd, p)
        M, J, h = r["M"], r["Jc"], r["h"]
        for sigma in (1.0, -1.0):
            A = np.zeros((6, 6))
            A[:5, :5] = M
            A[:5, 5] = -(J[1] - sigma * mu * J[0])
            A[5, :5] = J[1]
            x = np.linalg.solve(A, np.r_[np.r_[0.0, 0.0, 0.0, tau] - h + Q(F), -r["Jcdot_qd"][1]])
            qdd, lam = np.empty((1, 5)), np.empty((1, 2))
            kernels.slip(q[None], qd[None], tau[None], np.array([mu]), np.array([sigma]), p.array, np.array([F]), qdd, lam)
            scale = 1.0 + np.abs(x).max()
            assert np.abs(qdd[0] - x[:5]).max() < KKT_TOL * scale, (F, sigma, qdd, x)
            assert abs(lam[0, 1] - x[5]) < KKT_TOL * scale and abs(lam[0, 0] + sigma * mu * x[5]) < KKT_TOL * scale


def _stance(q, qd, tau, pl):
    qdd, lam = np.empty((1, 5)), np.empty((1, 2))
    kernels.stance(q[None], qd[None], tau[None], pl[:11], pl[11:], qdd, lam)
    return qdd[0], lam[0]


def _flight(q, qd, tau, pl):
    qdd = np.empty((1, 5))
    kernels.flight(q[None], qd[None], tau[None], pl[:11], pl[11:], qdd)
    return qdd[0]


def _scenario(name):
    p = LegParams()
    q_nom, tau_hold, _ = dyn.static_equilibrium(p)
    if name == "push_slip":  # 100 N forward: the leg pivots, lam_x grows past mu lam_y at mu = 0.03, the foot slides
        return p, 0.03, 100.0, H.State(q_nom.copy(), np.zeros(5), H.STICK, 0.0), [tau_hold] * 8
    if name == "push_stick":  # 30 N backward: stays stuck
        return p, 0.5, -30.0, H.State(q_nom.copy(), np.zeros(5), H.STICK, 0.0), [tau_hold] * 6
    if name == "push_flight":  # in the air, then landing while pushed
        q = q_nom.copy()
        q[1] += 0.03
        qd = np.zeros(5)
        qd[1] = -0.2
        return p, 0.5, 80.0, H.State(q, qd, H.FLIGHT), [tau_hold] * 6
    raise KeyError(name)


SCENARIOS = ("push_slip", "push_stick", "push_flight")


@functools.lru_cache(maxsize=None)
def _runs(name):
    p, mu, F, st, taus = _scenario(name)
    ref = H.Reference(p, mu, load=F)
    recs = ref.run(st, taus, DT)
    steps = []
    for r in recs:
        s = r.start
        anchor = s.anchor_x if s.mode == H.STICK else None
        steps.append(hybrid_step(s.q.copy(), s.qd.copy(), r.tau.copy(), p, mu, mode=s.mode, anchor_x=anchor, dt=DT, load_x=F))
    return p, F, recs, steps


@pytest.mark.parametrize("name", SCENARIOS)
def test_pushed_hybrid_step_matches_the_scipy_reference(name):
    p, F, recs, steps = _runs(name)
    kinds = [(i, e.kind) for i, r in enumerate(recs) for e in r.events]
    if name == "push_slip":
        assert any(k == H.SLIP_ONSET for _, k in kinds), H.describe(recs)
    if name == "push_flight":
        assert any(k == H.TOUCHDOWN for _, k in kinds), H.describe(recs)
    for i, (r, s) in enumerate(zip(recs, steps)):
        assert np.abs(s.q - r.end.q).max() < STATE_TOL and np.abs(s.qd - r.end.qd).max() < STATE_TOL, (name, i, H.describe(recs))
        assert int(s.mode) == r.end.mode, (name, i, int(s.mode), H.describe(recs))
        n = int(s.events)
        assert [int(k) for k in s.event_kind[:n]] == r.event_kinds, (name, i, s.event_kind[:n], H.describe(recs))
        assert np.abs(np.asarray(s.event_time[:n]) - np.asarray(r.event_times)).max(initial=0.0) < EVENT_TIME_TOL
        assert np.abs(s.impulse - r.impulse).max() < 1e-6, (name, i, s.impulse, r.impulse)


@pytest.mark.parametrize("name", SCENARIOS)
def test_momentum_over_a_push_is_the_push_the_ground_and_gravity(name):
    """``m (v_com(end) - v_com(start)) = F dt e_x + ground impulse (continuous + impacts) - m g dt e_y``, per step."""
    p, F, recs, steps = _runs(name)
    m = p.total_mass
    J_com = _com_jacobian(p)
    for r, s in zip(recs, steps):
        dP = m * (J_com(s.q) @ s.qd - J_com(r.start.q) @ r.start.qd)
        ground = s.lam_mean * DT + s.impulse
        expected = ground + np.array([F * DT, -m * p.g * DT])
        assert np.abs(dP - expected).max() < MOMENTUM_TOL, (name, dP, expected)
    # and over the whole push: the sums
    total = sum(s.lam_mean * DT + s.impulse for s in steps) + len(steps) * np.array([F * DT, -m * p.g * DT])
    dP = m * (J_com(steps[-1].q) @ steps[-1].qd - J_com(recs[0].start.q) @ recs[0].start.qd)
    assert np.abs(dP - total).max() < len(steps) * MOMENTUM_TOL


def _com_jacobian(p):
    """``v_com = J_com(q) qd``: ``m p_com = m p_b + a (cos th1, sin th1) + b (cos th2, sin th2)``, ``a = m1 c1 + m2 l1``, ``b = m2 c2``."""
    m = p.total_mass
    a, b = p.m1 * p.c1 + p.m2 * p.l1, p.m2 * p.c2

    def J(q):
        th1 = q[2] + q[3]
        th2 = th1 + q[4]
        d1 = np.array([-np.sin(th1), np.cos(th1)]) * a / m  # d p_com / d th1
        d2 = np.array([-np.sin(th2), np.cos(th2)]) * b / m
        # th1 = th_b + q1, th2 = th_b + q1 + q2
        return np.column_stack([[1.0, 0.0], [0.0, 1.0], d1 + d2, d1 + d2, d2])

    return J


@pytest.mark.parametrize("name", SCENARIOS)
def test_energy_balance_includes_the_work_of_the_push(name):
    p, F, recs, steps = _runs(name)
    E = lambda q, qd: float(dyn.kinetic_energy(q, qd, p) + dyn.potential_energy(q, p))  # noqa: E731
    for r, s in zip(recs, steps):
        assert abs(float(s.work_load) - F * (s.q[0] - r.start.q[0])) < 1e-12 * (1.0 + abs(F))
        dE = E(s.q, s.qd) - E(r.start.q, r.start.qd)
        booked = float(s.work + s.work_load - s.slip_dissipation - s.impact_dissipation)
        assert abs(dE - booked) < ENERGY_TOL, (name, dE, booked)
    assert any(abs(float(s.work_load)) > 1e-3 for s in steps)  # the push did work
