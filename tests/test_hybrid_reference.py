"""``leg_env.physics.hybrid.hybrid_step`` against an independent event-driven reference (``tests/hybrid_ref.py``).

The reference integrates the mode dynamics (KKT solves on the SymPy Lagrangian's ``M, h, J, Jdot qd``)
with DOP853 at ``rtol = atol = 1e-12`` and locates the events with ``solve_ivp``'s terminal events,
choosing modes at rest by brute-force enumeration of the contact LCP. First the reference is checked
against itself and against Pinocchio; then four scenarios, designed with the reference alone, are
compared control step by control step: each step of ``hybrid_step`` (``dt = 0.01``, ``substeps = 2``,
``max_angle = 0.02``) starts from the reference's state (and mode, anchor) at that step's start, so the
instability of the stance (errors grow about ``e^(7 t)``) does not accumulate.

Scenarios (default ``LegParams``; ``q_nom, tau_hold = static_equilibrium(p)[:2]``, foot at the origin):

* DROP (``mu = 0.5``): ``q_nom`` lifted 5 cm, falling at 0.3 m/s, holding torques: TOUCHDOWN in
  step 4 (sticking impact), then stick.
* HOP (``mu = 0.5``): at rest in stick, ``tau = tau_hold + 0.336 ((-50, 50) - tau_hold)`` unloads the
  foot slowly while the robot tips: SLIP_ONSET (step 3), LIFTOFF from the slip (step 4), two steps
  of flight, then ``tau = (20, -40)``: TOUCHDOWN with a sticking impact (step 7).
* HOP_SLIDE (``mu = 0.5``): the same, one more flight step, then ``tau = (-20, -40)``: TOUCHDOWN with a
  *sliding* impact (step 8), then slip and SLIDING_STOP into stick in the same step.
* SLIP (``mu = 0.2``): at rest in stick, a torque whose stick force lies just inside the cone
  (``|lam_x| / lam_y = 0.1985`` at the start): SLIP_ONSET (step 3), the foot slides forward; then a
  torque at ratio 0.19: SLIDING_STOP (step 5) and stick again.

Tolerances (stated, not tuned): event times 1e-7 s; the state after one control step 1e-6 (max-abs
over q and over qd separately); work and dissipations 1e-6 J per step; impulses 1e-6 N s; the
reference's own energy balance 1e-9 J per step.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pinocchio as pin
import pytest

import hybrid_ref as H
from conftest import random_params
from pin_model import build_model, constrained_forward_dynamics, foot_terms
from leg_env.physics.dynamics import static_equilibrium
from leg_env.physics.integrate import flight_step, stance_step
from leg_env.physics.params import LegParams

DT = 0.01
EVENT_TIME_TOL = 1e-7  # [s]
STATE_TOL = 1e-6  # max-abs over q [m, rad] and over qd [m/s, rad/s]
ENERGY_TOL = 1e-6  # [J] per step
IMPULSE_TOL = 1e-6  # [N s]
REF_ENERGY_TOL = 1e-9  # [J] per step, the reference's own balance
TIME_SPLIT_TOL = 1e-7  # [s] stick/slip/flight time
SLIP_DISTANCE_TOL = 1e-9  # [m]
LAM_MEAN_TOL = 1e-6  # relative to the weight (RK4 quadrature of the force vs the exact integral)


# ----------------------------------------------------------------------------------------------
# Scenarios
# ----------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def nominal():
    p = LegParams()
    q, tau, _ = static_equilibrium(p)
    return p, q, tau


def _scenario(name):
    p, q_nom, tau_hold = nominal()
    rest = H.State(q_nom.copy(), np.zeros(5), H.STICK, 0.0)
    if name == "drop":
        q = q_nom.copy()
        q[1] += 0.05
        qd = np.zeros(5)
        qd[1] = -0.3
        return 0.5, H.State(q, qd, H.FLIGHT), [tau_hold] * 7
    unload = tau_hold + 0.336 * (np.array([-50.0, 50.0]) - tau_hold)
    if name == "hop":
        return 0.5, rest, [unload] * 7 + [np.array([20.0, -40.0])] * 2
    if name == "hop_slide":
        return 0.5, rest, [unload] * 8 + [np.array([-20.0, -40.0])] * 2
    if name == "slip":
        w = p.weight / 4.78  # ~ N m of the lam_x-only torque direction per unit ratio (see d below)
        d = np.array([4.23, 2.23])  # torque direction that changes lam_x but hardly lam_y at q_nom
        return 0.2, rest, [tau_hold + 0.1985 * w * d] * 5 + [tau_hold + 0.19 * w * d] * 2
    raise KeyError(name)


SCENARIOS = ("drop", "hop", "hop_slide", "slip")

# what the reference sees (global step index, event kind), the design of each scenario
EXPECTED_EVENTS = {
    "drop": [(4, H.TOUCHDOWN)],
    "hop": [(3, H.SLIP_ONSET), (4, H.LIFTOFF), (7, H.TOUCHDOWN)],
    "hop_slide": [(3, H.SLIP_ONSET), (4, H.LIFTOFF), (8, H.TOUCHDOWN), (8, H.SLIDING_STOP)],
    "slip": [(3, H.SLIP_ONSET), (5, H.SLIDING_STOP)],
}


@functools.lru_cache(maxsize=None)
def reference_run(name):
    mu, st, taus = _scenario(name)
    p = nominal()[0]
    ref = H.Reference(p, mu)
    return ref, ref.run(st, taus, DT)


def _all_events(recs):
    return [(i, e) for i, r in enumerate(recs) for e in r.events]


# ----------------------------------------------------------------------------------------------
# The implementation, one control step per reference step (cached per scenario)
# ----------------------------------------------------------------------------------------------


def _hybrid():
    from leg_env.physics import hybrid  # fails (not skips) when the module is missing

    return hybrid


def _call(rec, mu, p, **kw):
    hyb = _hybrid()
    s = rec.start
    anchor = s.anchor_x if s.mode == H.STICK else None
    return hyb.hybrid_step(s.q.copy(), s.qd.copy(), rec.tau.copy(), p, mu, mode=s.mode, anchor_x=anchor, dt=rec.dt,
                           **kw)


@functools.lru_cache(maxsize=None)
def implementation_steps(name):
    ref, recs = reference_run(name)
    return [_call(r, ref.mu, ref.p) for r in recs]


def _events_of(res):
    n = int(np.asarray(res.events))
    kinds = [int(k) for k in np.asarray(res.event_kind)[:n]]
    times = [float(t) for t in np.asarray(res.event_time)[:n]]
    return kinds, times


def _inputs(name, i, rec):
    s = rec.start
    return (f"scenario {name}, step {i}: q={s.q.tolist()}, qd={s.qd.tolist()}, mode={H.MODE_NAMES[s.mode]}, "
            f"anchor_x={s.anchor_x}, tau={rec.tau.tolist()}, mu={reference_run(name)[0].mu}")


# ----------------------------------------------------------------------------------------------
# 0. The reference itself
# ----------------------------------------------------------------------------------------------


def _random_state(rng, p):
    q = np.concatenate([rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi, 3)])
    return q, 2.0 * rng.standard_normal(5), rng.uniform(-50, 50, 2)


def test_reference_stick_and_flight_against_pinocchio():
    """The reference's stick KKT (qdd, lam) = Pinocchio's constrained forward dynamics; flight = ABA."""
    rng = np.random.default_rng(11)
    for i in range(30):
        p = random_params(rng)
        ref = H.Reference(p, 0.5)
        q, qd, tau = _random_state(rng, p)
        model, foot = build_model(p)
        data = model.createData()
        qdd_pin, lam_pin = constrained_forward_dynamics(model, data, foot, q, qd, tau)
        qdd, lam = ref.dynamics(q, qd, tau, H.STICK)
        np.testing.assert_allclose(lam, lam_pin, rtol=1e-9, atol=1e-9 * (1 + np.abs(lam_pin).max()), err_msg=f"{i}")
        np.testing.assert_allclose(qdd, qdd_pin, rtol=1e-9, atol=1e-9 * (1 + np.abs(qdd_pin).max()), err_msg=f"{i}")
        qdd_f, _ = ref.dynamics(q, qd, tau, H.FLIGHT)
        aba = pin.aba(model, model.createData(), q, qd, H.S_T @ tau)
        np.testing.assert_allclose(qdd_f, aba, rtol=1e-9, atol=1e-9 * (1 + np.abs(aba).max()))


def test_reference_slip_against_pinocchio_terms():
    """The slip KKT: y_f'' = 0, lam on the cone edge opposing sigma, and the equations of motion hold with
    Pinocchio's M, h, J, Jdot qd (so the non-symmetric KKT is right, not just self-consistent)."""
    rng = np.random.default_rng(12)
    for i in range(30):
        p = random_params(rng)
        mu = rng.uniform(0.05, 0.9)
        ref = H.Reference(p, mu)
        q, qd, tau = _random_state(rng, p)
        model, foot = build_model(p)
        data = model.createData()
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        h = pin.rnea(model, data, q, qd, np.zeros(5))
        J, drift = foot_terms(model, data, foot, q, qd)
        for mode in (H.SLIP_FORWARD, H.SLIP_BACKWARD):
            sigma = H.sigma_of(mode)
            qdd, lam = ref.dynamics(q, qd, tau, mode)
            scale = 1 + np.abs(M @ qdd).max() + np.abs(h).max()
            assert np.abs(M @ qdd + h - H.S_T @ tau - J.T @ lam).max() < 1e-9 * scale, f"case {i}"
            assert abs(J[1] @ qdd + drift[1]) < 1e-9 * (1 + np.abs(qdd).max()), f"case {i}"
            assert lam[0] == pytest.approx(-sigma * mu * lam[1], rel=1e-12, abs=1e-12)


def test_reference_impact_against_pinocchio_and_invariants():
    """mu = inf: the reference impact = Pinocchio's impulseDynamics (r = 0). Finite mu: plastic
    (v_fy+ = 0), impulse inside the cone, kinetic energy never increases, sticking inside the cone."""
    rng = np.random.default_rng(13)
    p = LegParams()
    q_nom = nominal()[1]
    branches = set()
    for i in range(200):
        q = q_nom + np.r_[0, 0, rng.uniform(-0.3, 0.3), rng.uniform(-0.4, 0.4, 2)]
        qd = 2.0 * rng.standard_normal(5)
        ref = H.Reference(p, rng.choice([0.1, 0.2, 0.5, 0.8]))
        r = ref.terms(q, qd)
        vf = r["Jc"] @ qd
        if vf[1] >= 0:
            qd[1] -= vf[1] + rng.uniform(0.05, 1.0)  # make the foot approach
            r = ref.terms(q, qd)
            vf = r["Jc"] @ qd
        if i < 20:
            model, foot = build_model(p)
            data = model.createData()
            J, _ = foot_terms(model, data, foot, q, qd)
            qd_pin = pin.impulseDynamics(model, data, q, qd, J, 0.0)
            qd_inf, P_inf = ref.impact(q, qd, mu=math.inf)
            np.testing.assert_allclose(qd_inf, qd_pin, atol=1e-10 * (1 + np.abs(qd).max()))
            np.testing.assert_allclose(P_inf, data.impulse_c, atol=1e-10 * (1 + np.abs(P_inf).max()))
        qd_p, P = ref.impact(q, qd)
        vf_p = r["Jc"] @ qd_p
        assert abs(vf_p[1]) < 1e-12 * (1 + np.abs(qd).max())
        assert P[1] > 0 and abs(P[0]) <= ref.mu * P[1] * (1 + 1e-12)
        K0, K1 = r["K"], ref.terms(q, qd_p)["K"]
        assert K1 <= K0 + 1e-12
        assert K1 - K0 == pytest.approx(0.5 * P @ (vf + vf_p), rel=1e-9, abs=1e-12)
        stuck = abs(vf_p[0]) < 1e-12 * (1 + np.abs(qd).max())
        edge = abs(abs(P[0]) - ref.mu * P[1]) < 1e-9 * P[1]
        Lam = r["Jc"] @ np.linalg.solve(r["M"], r["Jc"].T)
        if stuck:  # v_f+ = 0 makes P the sticking impulse, which must then lie in the cone
            outcome = "stick"
            assert abs(P[0]) <= ref.mu * P[1] * (1 + 1e-12)
        elif edge:
            outcome = "slide"
        else:  # slid, stopped, slid back (only possible when |Lxy / Lxx| > mu): ends moving along sign(Lxy)
            outcome = "reverse"
            assert abs(Lam[0, 1] / Lam[0, 0]) > ref.mu and np.sign(vf_p[0]) == np.sign(Lam[0, 1])
        branches.add(outcome)
    assert branches == {"stick", "slide", "reverse"}, branches  # all three outcomes occur


def test_lcp_enumeration_matches_closed_form_candidates():
    """Below mu_crit the brute-force LCP has exactly one solution, the one consistent closed-form candidate."""
    rng = np.random.default_rng(14)
    p = LegParams()
    ref = H.Reference(p, 0.5)
    q_nom, tau_hold = nominal()[1:]
    Lam = ref.contact_terms(q_nom, np.zeros(5), tau_hold)[0]
    mu_crit = Lam[1, 1] / abs(Lam[0, 1])
    modes = set()
    for frac in (0.2, 0.5, 0.9):
        for _ in range(300):
            a0 = rng.normal(0, 20, 2)
            sols = H.lcp_solutions(Lam, a0, frac * mu_crit)
            cands = H.closed_form_candidates(Lam, a0, frac * mu_crit)
            assert len(sols) == 1 and len(cands) == 1, (a0, sols, cands)
            assert sols[0][0] == cands[0][0]
            np.testing.assert_allclose(sols[0][1], cands[0][1], atol=1e-9 * (1 + np.abs(a0).max()))
            modes.add(sols[0][0])
    assert modes == {H.STICK, H.SLIP_FORWARD, H.SLIP_BACKWARD, H.FLIGHT}


def test_reference_matches_fine_rk4_on_event_free_steps():
    """Event-free stick and flight steps of the reference = leg_env's stance_step / flight_step with 400 RK4
    substeps (two independent models and integrators agree to round-off level)."""
    checked = 0
    for name in SCENARIOS:
        ref, recs = reference_run(name)
        for r in recs:
            if r.events or not r.start.mode == r.mode_start == r.end.mode or r.end.mode not in (H.STICK, H.FLIGHT):
                continue
            s = r.start
            if r.end.mode == H.STICK:
                qn, qdn, lam = stance_step(s.q, s.qd, r.tau, ref.p, substeps=400, anchor=np.array([s.anchor_x, 0.0]))
                np.testing.assert_allclose(lam, r.lam_mean, atol=1e-9 * ref.p.weight)
            else:
                qn, qdn = flight_step(s.q, s.qd, r.tau, ref.p, substeps=400)
            assert np.abs(qn - r.end.q).max() < 1e-11 and np.abs(qdn - r.end.qd).max() < 1e-11, name
            checked += 1
    assert checked >= 15


@pytest.mark.parametrize("name", SCENARIOS)
def test_reference_scenario_design(name):
    """The reference sees the designed events, at the designed steps, well inside the steps, with the
    witnesses at zero, and its energy balance closes: dE = W - D_slip - D_impact."""
    ref, recs = reference_run(name)
    got = [(i, e.kind) for i, e in _all_events(recs)]
    assert got == EXPECTED_EVENTS[name], H.describe(recs)
    for i, e in _all_events(recs):
        assert 2e-4 < e.time < DT - 2e-4, f"{name}: event too close to a step boundary: {e}"
        tau = recs[i].tau
        r = ref.terms(e.q, e.qd_minus)
        if e.kind == H.TOUCHDOWN:
            assert abs(r["p_f"][1]) < 1e-12 and (r["Jc"] @ e.qd_minus)[1] < -1e-3
        elif e.kind == H.LIFTOFF:
            lam = ref.dynamics(e.q, e.qd_minus, tau, e.mode_before)[1]
            assert abs(lam[1]) < 1e-8
        elif e.kind == H.SLIP_ONSET:
            lam = ref.dynamics(e.q, e.qd_minus, tau, H.STICK)[1]
            assert abs(ref.mu * lam[1] - abs(lam[0])) < 1e-8 and lam[1] > 0.1
        else:
            assert abs((r["Jc"] @ e.qd_minus)[0]) < 1e-12
    for i, r in enumerate(recs):
        dE = r.energy_end - r.energy_start
        assert abs(dE - (r.work - r.slip_dissipation - r.impact_dissipation)) < REF_ENERGY_TOL, f"{name} step {i}"
        assert abs(r.work - r.power_int) < REF_ENERGY_TOL
        assert r.stick_time + r.slip_time + r.flight_time == pytest.approx(DT, abs=1e-15)
    if name == "hop_slide":  # the landing is a sliding impact: the impulse lies on the cone's edge
        e = [e for _, e in _all_events(recs) if e.kind == H.TOUCHDOWN][0]
        assert e.mode_after == H.SLIP_BACKWARD
        assert abs(e.impulse[0]) == pytest.approx(ref.mu * e.impulse[1], rel=1e-12)
    if name in ("drop", "hop"):
        e = [e for _, e in _all_events(recs) if e.kind == H.TOUCHDOWN][0]
        assert e.mode_after == H.STICK and abs(e.impulse[0]) < 0.9 * ref.mu * e.impulse[1]


# ----------------------------------------------------------------------------------------------
# The contact building blocks of leg_env against the reference (for diagnosis of the step)
# ----------------------------------------------------------------------------------------------


def test_impact_map_matches_reference():
    """leg_env.physics.dynamics.impact_map = the reference's impact (sticking, sliding, stop-then-stick,
    stop-then-reverse) on approaching feet near the nominal posture."""
    from leg_env import physics as dyn

    rng = np.random.default_rng(21)
    p = LegParams()
    q_nom = nominal()[1]
    for i in range(200):
        mu = [0.1, 0.2, 0.5, 0.8, math.inf][i % 5]
        ref = H.Reference(p, 0.5)
        q = q_nom + np.r_[0, 0, rng.uniform(-0.3, 0.3), rng.uniform(-0.4, 0.4, 2)]
        qd = 2.0 * rng.standard_normal(5)
        vf = ref.terms(q, qd)["Jc"] @ qd
        if vf[1] >= 0:
            qd[1] -= vf[1] + rng.uniform(0.05, 1.0)
        qd_ref, P_ref = ref.impact(q, qd, mu=mu)
        qd_p, P = dyn.impact_map(q, qd, p, mu)
        tol = 1e-9 * (1 + np.abs(qd).max())
        assert np.abs(np.asarray(P) - P_ref).max() < tol and np.abs(np.asarray(qd_p) - qd_ref).max() < tol, (
            f"case {i}: q={q.tolist()}, qd={qd.tolist()}, mu={mu}: impulse {P} vs {P_ref}, qd+ {qd_p} vs {qd_ref}"
        )


def test_contact_mode_and_slip_dynamics_match_reference():
    from leg_env import physics as dyn

    rng = np.random.default_rng(22)
    p = LegParams()
    q_nom = nominal()[1]
    seen = set()
    for i in range(300):
        mu = rng.uniform(0.05, 0.5)  # below min mu_crit at default parameters: unique modes
        ref = H.Reference(p, mu)
        q = q_nom + np.r_[0, 0, rng.uniform(-0.3, 0.3), rng.uniform(-0.4, 0.4, 2)]
        q[:2] -= ref.terms(q, np.zeros(5))["p_f"]  # foot at the origin
        w = rng.normal(0, 1.0, 3)
        J = ref.terms(q, np.zeros(5))["Jc"]
        qd = np.r_[-(J[:, 2:] @ w), w]  # foot at rest
        tau = rng.uniform(-50, 50, 2)
        m_ref = ref.mode_at_rest(q, qd, tau)
        seen.add(m_ref)
        assert int(dyn.contact_mode(q, qd, tau, p, mu)) == m_ref, f"case {i}: q={q.tolist()} qd={qd.tolist()} tau={tau}"
        for mode in (H.SLIP_FORWARD, H.SLIP_BACKWARD):
            qdd_ref, lam_ref = ref.dynamics(q, qd, tau, mode)
            qdd, lam = dyn.slip_dynamics(q, qd, tau, p, mu, H.sigma_of(mode))
            np.testing.assert_allclose(lam, lam_ref, atol=1e-9 * (1 + np.abs(lam_ref).max()))
            np.testing.assert_allclose(qdd, qdd_ref, atol=1e-9 * (1 + np.abs(qdd_ref).max()))
    assert seen == {H.STICK, H.SLIP_FORWARD, H.SLIP_BACKWARD, H.FLIGHT}


# ----------------------------------------------------------------------------------------------
# 1-3. Events of hybrid_step, step by step from the reference's states
# ----------------------------------------------------------------------------------------------


def _compare_events(name):
    ref, recs = reference_run(name)
    res = implementation_steps(name)
    worst = 0.0
    for i, (r, s) in enumerate(zip(recs, res)):
        kinds, times = _events_of(s)
        msg = (f"{_inputs(name, i, r)}\nreference events {[H.EVENT_NAMES[k] for k in r.event_kinds]} at "
               f"{r.event_times}, hybrid_step {kinds} at {times}")
        assert kinds == r.event_kinds, msg
        for t, tr in zip(times, r.event_times):
            worst = max(worst, abs(t - tr))
            assert abs(t - tr) < EVENT_TIME_TOL, msg
        assert int(np.asarray(s.mode)) == r.end.mode, msg + f"\nend mode {int(np.asarray(s.mode))} vs {r.end.mode}"
    return worst


def test_api_constants():
    hyb = _hybrid()
    from leg_env import physics as dyn

    assert (hyb.LIFTOFF, hyb.SLIP_ONSET, hyb.SLIDING_STOP, hyb.TOUCHDOWN) == (
        H.LIFTOFF, H.SLIP_ONSET, H.SLIDING_STOP, H.TOUCHDOWN)
    assert (dyn.STICK, dyn.SLIP_FORWARD, dyn.SLIP_BACKWARD, dyn.FLIGHT) == (
        H.STICK, H.SLIP_FORWARD, H.SLIP_BACKWARD, H.FLIGHT)


def test_drop_touchdown_sticks():
    """1. The drop: touchdown time (step index * dt + event time) within 1e-7 s, step by step and in a
    free replay of hybrid_step from the initial state; then STICK; impulse and post-impact velocity."""
    from leg_env import physics as dyn

    hyb = _hybrid()
    ref, recs = reference_run("drop")
    _compare_events("drop")
    (i_td, ev), = _all_events(recs)
    t_ref = i_td * DT + ev.time
    # free replay (flight is not unstable; one step of stick after the touchdown)
    mu, st, taus = _scenario("drop")
    q, qd, mode, anchor = st.q.copy(), st.qd.copy(), st.mode, None
    t_impl = None
    for i, tau in enumerate(taus[: i_td + 2]):
        res = hyb.hybrid_step(q, qd, tau, ref.p, mu, mode=mode, anchor_x=anchor)
        kinds, times = _events_of(res)
        if kinds:
            assert kinds == [H.TOUCHDOWN] and i == i_td, (i, kinds, times)
            t_impl = i * DT + times[0]
            assert int(np.asarray(res.mode)) == H.STICK
            assert np.abs(np.asarray(res.impulse) - ev.impulse).max() < IMPULSE_TOL, (res.impulse, ev.impulse)
        q, qd, mode, anchor = np.asarray(res.q), np.asarray(res.qd), int(np.asarray(res.mode)), res.anchor_x
        if mode != H.STICK:
            anchor = None
    assert t_impl is not None and abs(t_impl - t_ref) < EVENT_TIME_TOL, (t_impl, t_ref)
    # the impulse reported by the step from the reference state, and the impact map at the reference's
    # pre-impact state
    s = implementation_steps("drop")[i_td]
    assert np.abs(np.asarray(s.impulse) - ev.impulse).max() < IMPULSE_TOL, (s.impulse, ev.impulse)
    qd_p, P = dyn.impact_map(ev.q, ev.qd_minus, ref.p, mu)
    assert np.abs(np.asarray(qd_p) - ev.qd_plus).max() < 1e-9 and np.abs(np.asarray(P) - ev.impulse).max() < 1e-9


@pytest.mark.parametrize("name", ["hop", "hop_slide"])
def test_liftoff_flight_touchdown(name):
    """2. Stance unloads, slips, lifts off, flies and lands (sticking, resp. sliding impact): every
    event's kind, order and time (1e-7 s), the end modes and the landing impulse."""
    ref, recs = reference_run(name)
    _compare_events(name)
    res = implementation_steps(name)
    for i, (r, s) in enumerate(zip(recs, res)):
        assert np.abs(np.asarray(s.impulse) - r.impulse).max() < IMPULSE_TOL, (
            f"{_inputs(name, i, r)}\nimpulse {s.impulse} vs {r.impulse}")


def test_slip_then_stick():
    """3. Stick -> SLIP_ONSET -> slide -> SLIDING_STOP -> stick at mu = 0.2, event times within 1e-7 s."""
    _compare_events("slip")


# ----------------------------------------------------------------------------------------------
# 4. One control step from the reference's state lands on the reference's next state
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", SCENARIOS)
def test_one_step_state(name):
    ref, recs = reference_run(name)
    res = implementation_steps(name)
    for i, (r, s) in enumerate(zip(recs, res)):
        eq = np.abs(np.asarray(s.q) - r.end.q).max()
        eqd = np.abs(np.asarray(s.qd) - r.end.qd).max()
        assert eq < STATE_TOL and eqd < STATE_TOL, (
            f"{_inputs(name, i, r)}\n|q - q_ref| = {eq:.3e}, |qd - qd_ref| = {eqd:.3e}\n"
            f"q = {np.asarray(s.q).tolist()}\nq_ref = {r.end.q.tolist()}\nqd = {np.asarray(s.qd).tolist()}\n"
            f"qd_ref = {r.end.qd.tolist()}")
        if r.end.mode == H.STICK:
            assert abs(float(np.asarray(s.anchor_x)) - r.end.anchor_x) < STATE_TOL, (i, s.anchor_x, r.end.anchor_x)


# ----------------------------------------------------------------------------------------------
# 5. Energy terms and the rest of the step's bookkeeping
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", SCENARIOS)
def test_energy_terms(name):
    ref, recs = reference_run(name)
    res = implementation_steps(name)
    for i, (r, s) in enumerate(zip(recs, res)):
        for field, want in (("work", r.work), ("slip_dissipation", r.slip_dissipation),
                            ("impact_dissipation", r.impact_dissipation)):
            got = float(np.asarray(getattr(s, field)))
            assert abs(got - want) < ENERGY_TOL, f"{_inputs(name, i, r)}\n{field}: {got!r} vs reference {want!r}"
    # over the whole scenario the reference's energy change is its work minus its dissipation
    dE = recs[-1].energy_end - recs[0].energy_start
    W = sum(r.work for r in recs)
    D = sum(r.slip_dissipation + r.impact_dissipation for r in recs)
    assert abs(dE - (W - D)) < len(recs) * REF_ENERGY_TOL


@pytest.mark.parametrize("name", SCENARIOS)
def test_step_bookkeeping(name):
    """Mode times, slip distance and the mean contact force of each step against the reference."""
    ref, recs = reference_run(name)
    res = implementation_steps(name)
    for i, (r, s) in enumerate(zip(recs, res)):
        msg = _inputs(name, i, r)
        for field, want in (("stick_time", r.stick_time), ("slip_time", r.slip_time), ("flight_time", r.flight_time)):
            got = float(np.asarray(getattr(s, field)))
            assert abs(got - want) < TIME_SPLIT_TOL, f"{msg}\n{field}: {got!r} vs {want!r}"
        got = float(np.asarray(s.slip_distance))
        assert abs(got - r.slip_distance) < SLIP_DISTANCE_TOL, f"{msg}\nslip_distance {got!r} vs {r.slip_distance!r}"
        err = np.abs(np.asarray(s.lam_mean) - r.lam_mean).max()
        assert err < LAM_MEAN_TOL * ref.p.weight, f"{msg}\nlam_mean {s.lam_mean} vs {r.lam_mean}"


def _step_rule(qd, dt, substeps=2, max_angle=0.02):
    """leg_env.physics.integrate's step rule: at least ``substeps`` RK4 steps, and no link or joint turning by more than
    ``max_angle`` per step at the rates of ``qd``."""
    va, vb, vc = qd[2], qd[3], qd[4]
    w = max(abs(va), abs(vb), abs(vc), abs(va + vb), abs(va + vb + vc))
    return max(substeps, int(np.ceil(w * dt / max_angle)))


@pytest.mark.parametrize("name", SCENARIOS)
def test_rk4_steps_count_the_integration_work(name):
    """A step without events or impulses integrates exactly the step rule's RK4 steps; a step with events more:
    per located event, the substep that crossed it and at least one re-integration that located it."""
    ref, recs = reference_run(name)
    res = implementation_steps(name)
    with_events = 0
    for i, (r, s) in enumerate(zip(recs, res)):
        n_rule, steps, events = _step_rule(r.start.qd, DT), int(np.asarray(s.rk4_steps)), int(np.asarray(s.events))
        if events == 0 and not np.any(np.asarray(s.impulse)):
            assert steps == n_rule, (_inputs(name, i, r), steps, n_rule)
        elif events > 0:
            with_events += 1
            assert steps >= n_rule + 2 * events, (_inputs(name, i, r), steps, n_rule, events)
    assert with_events > 0  # every scenario locates events


def test_env_out_counts_the_rk4_steps_of_both_contact_models():
    """The batched env's ``out["rk4_steps"]``: the pinned step takes the step rule's count, the unilateral one that
    many without events, and per located event at least two more (the substep that crossed it, its location)."""
    import gymnasium as gym

    import leg_env

    rng = np.random.default_rng(0)
    for contact in ("pinned", "unilateral"):
        envs = gym.make_vec(leg_env.ENV_ID, num_envs=256, contact=contact)
        envs.reset(seed=0)
        extra = 0
        for _ in range(30):
            qd, restarting = envs.unwrapped._state["qd"].copy(), envs.unwrapped._ended.copy()
            envs.step(rng.uniform(-1, 1, (256, 2)).astype(np.float32))
            out = envs.unwrapped._out
            rule = np.array([_step_rule(row, envs.unwrapped.config.dt) for row in qd])
            stepped = ~out["numerical_failure"] & ~restarting  # an autoreset row steps from its new start
            steps = out["rk4_steps"][stepped]
            if contact == "pinned":
                assert np.array_equal(steps, rule[stepped])
            else:
                plain = stepped & (out["events"] == 0) & ~np.any(out["kick"] != 0, axis=1)
                assert np.array_equal(out["rk4_steps"][plain], rule[plain])
                eventful = stepped & (out["events"] > 0)
                assert np.all(out["rk4_steps"][eventful] >= rule[eventful] + 2 * out["events"][eventful])
                extra += int((out["rk4_steps"][eventful] - rule[eventful]).sum())
        if contact == "unilateral":
            assert extra > 0
        envs.close()
