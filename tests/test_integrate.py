"""The RK4 stepper with contact projection (leg_env.physics.integrate): constraint drift, energy, order,
the mean contact force, batching, the projections and argument checks.

Tolerances are norm-relative, ``|a - b| <= tol * (1 + |b|)``, unless stated.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import simpson

from conftest import random_params
from leg_env import physics as dyn
from leg_env.physics.params import LegParams

PARAM_SEEDS = [None, 0, 1]  # None: the lesson's defaults; ints: conftest.random_params(seed)
DRIFT_STEPS = 1000  # control steps of the drift test
DRIFT_ROBOTS = 8
DRIFT_TORQUE = 50.0  # |tau| <= [N m], uniform, redrawn every control step
DRIFT_TOL = 1e-9  # [m] foot distance from its anchor; also |Jc qd| [m/s]
ENERGY_STEPS = 100  # 1 s at the default dt = 0.01
ENERGY_RTOL = 1e-6  # |E(t) - E(0)| <= ENERGY_RTOL |E(0)|, P measured from the ground y = 0
ANGLE_NOISE = 0.05  # std of the perturbation of the nominal posture [rad]
RATE_NOISE = 0.3  # std of the initial velocities [m/s, rad/s]
ORDER_STEPS = 100  # 1 s
ORDER_TORQUE_OFFSET = np.array([2.0, -2.0])  # [N m] added to the holding torques (stance) or applied alone (flight)
ORDER_REFERENCE_SUBSTEPS = 128
ORDER_MIN_RATIO = 10.0  # RK4 gives ~16 when the step halves
LAM_FINE_STEPS = 400  # fine re-integration of one control step for the mean contact force
LAM_RTOL = 1e-7
# (std of the initial rates, least substeps): slow, moderate, odd substep count, fast (adaptive rule takes ~8)
LAM_CASES = [(0.3, 4), (3.0, 4), (3.0, 7), (10.0, 4)]
PROJECTION_TOL = 1e-12


def make_params(seed):
    return LegParams() if seed is None else random_params(np.random.default_rng(seed))


def near_nominal(p, rng, angle_noise=ANGLE_NOISE, rate_noise=RATE_NOISE, anchor=(0.0, 0.0)):
    """Nominal posture + noise, projected onto the contact manifold with the foot at ``anchor``."""
    q_eq, tau_eq, _ = dyn.static_equilibrium(p)
    q = q_eq + np.concatenate([[0.0, 0.0], rng.normal(0.0, angle_noise, 3)])
    qd = rng.normal(0.0, rate_noise, 5)
    q, qd = dyn.project_stance(q, qd, p, np.asarray(anchor, dtype=float))
    return q, qd, tau_eq


def energy(q, qd, p):
    return dyn.kinetic_energy(q, qd, p) + dyn.potential_energy(q, p)


# ----------------------------------------------------------------------------
# Contact drift and energy
# ----------------------------------------------------------------------------


@pytest.mark.parametrize("seed", PARAM_SEEDS, ids=str)
def test_foot_drift_under_random_torques(seed):
    p = make_params(seed)
    rng = np.random.default_rng(10)
    anchor = rng.uniform(-1.0, 1.0, (DRIFT_ROBOTS, 2))
    states = [near_nominal(p, rng, anchor=a) for a in anchor]
    q = np.array([s[0] for s in states])
    qd = np.array([s[1] for s in states])
    worst_drift = worst_velocity = 0.0
    for _ in range(DRIFT_STEPS):
        tau = rng.uniform(-DRIFT_TORQUE, DRIFT_TORQUE, (DRIFT_ROBOTS, 2))
        q, qd, lam = dyn.stance_step(q, qd, tau, p, anchor=anchor)
        worst_drift = max(worst_drift, np.abs(dyn.foot_position(q, p) - anchor).max())
        Jc = dyn.contact_jacobian(q, p)
        worst_velocity = max(worst_velocity, np.abs((Jc @ qd[..., None])[..., 0]).max())
    assert np.isfinite(q).all() and np.isfinite(qd).all()
    assert worst_drift < DRIFT_TOL
    assert worst_velocity < DRIFT_TOL
    # the test exercised real motion: the robots moved far from the start
    assert np.abs(qd[:, 2:]).max() > 1.0


@pytest.mark.parametrize("seed", PARAM_SEEDS, ids=str)
def test_energy_conserved_in_stance(seed):
    p = make_params(seed)
    q, qd, _ = near_nominal(p, np.random.default_rng(11))
    E0 = energy(q, qd, p)
    K0 = dyn.kinetic_energy(q, qd, p)
    K_max = K0
    anchor = np.zeros(2)
    for _ in range(ENERGY_STEPS):
        q, qd, _ = dyn.stance_step(q, qd, np.zeros(2), p, anchor=anchor)
        assert abs(energy(q, qd, p) - E0) <= ENERGY_RTOL * abs(E0)
        K_max = max(K_max, dyn.kinetic_energy(q, qd, p))
    assert K_max > K0 + 1e-3 * abs(E0)  # potential energy really turned into kinetic energy


@pytest.mark.parametrize("seed", PARAM_SEEDS, ids=str)
def test_energy_conserved_in_flight(seed):
    p = make_params(seed)
    rng = np.random.default_rng(12)
    q, qd, _ = near_nominal(p, rng)
    qd = rng.normal(0.0, 1.0, 5)  # free flight: any velocity
    E0 = energy(q, qd, p)
    for _ in range(ENERGY_STEPS):
        q, qd = dyn.flight_step(q, qd, np.zeros(2), p)
        assert abs(energy(q, qd, p) - E0) <= ENERGY_RTOL * abs(E0)
    assert q[1] < -1.0  # it fell under gravity


# ----------------------------------------------------------------------------
# In-step trigonometry
# ----------------------------------------------------------------------------


def test_turn_matches_library_trigonometry():
    """The integrator's ``turn`` (angle addition with Taylor series for small increments, in the compiled
    core) is sin/cos to a few ulp, on both sides of its series threshold and for NaN."""
    from leg_env._core import kernels

    rng = np.random.default_rng(21)
    th = rng.uniform(-np.pi, np.pi, 20_000)
    d = np.concatenate([
        rng.uniform(-kernels.TURN_MAX, kernels.TURN_MAX, 10_000),
        rng.uniform(-1e-6, 1e-6, 5_000),
        rng.uniform(-3.0, 3.0, 5_000),  # mostly the library fallback
    ])
    out = np.empty((th.size, 2))
    kernels.turn(th, d, out)
    assert np.abs(out[:, 0] - np.sin(th + d)).max() < 1e-15
    assert np.abs(out[:, 1] - np.cos(th + d)).max() < 1e-15
    nan = np.empty((1, 2))
    kernels.turn(np.zeros(1), np.array([np.nan]), nan)
    assert np.isnan(nan).all()


# ----------------------------------------------------------------------------
# Order of accuracy
# ----------------------------------------------------------------------------


def simulate(p, q, qd, tau, stance, substeps, max_angle, steps=ORDER_STEPS):
    for _ in range(steps):
        if stance:
            q, qd, _ = dyn.stance_step(q, qd, tau, p, substeps=substeps, max_angle=max_angle, anchor=np.zeros(2))
        else:
            q, qd = dyn.flight_step(q, qd, tau, p, substeps=substeps, max_angle=max_angle)
    return np.concatenate([q, qd])


# (substeps, max_angle) -> halved step (2 substeps, 2x finer angle rule)
ORDER_SETTINGS = {
    "fixed": ((2, np.inf), (4, np.inf)),
    "adaptive_default": ((dyn.SUBSTEPS, dyn.MAX_ANGLE), (2 * dyn.SUBSTEPS, dyn.MAX_ANGLE / 2)),
}


@pytest.mark.parametrize("stance", [True, False], ids=["stance", "flight"])
@pytest.mark.parametrize("setting", list(ORDER_SETTINGS))
@pytest.mark.parametrize("seed", PARAM_SEEDS, ids=str)
def test_halving_the_step_cuts_the_error_tenfold(seed, setting, stance):
    p = make_params(seed)
    q, qd, tau_eq = near_nominal(p, np.random.default_rng(13))
    tau = tau_eq + ORDER_TORQUE_OFFSET if stance else ORDER_TORQUE_OFFSET
    reference = simulate(p, q, qd, tau, stance, ORDER_REFERENCE_SUBSTEPS, np.inf)
    (n_coarse, a_coarse), (n_fine, a_fine) = ORDER_SETTINGS[setting]
    err_coarse = np.linalg.norm(simulate(p, q, qd, tau, stance, n_coarse, a_coarse) - reference)
    err_fine = np.linalg.norm(simulate(p, q, qd, tau, stance, n_fine, a_fine) - reference)
    assert err_fine > 0.0
    assert err_coarse / err_fine >= ORDER_MIN_RATIO, f"errors {err_coarse:.3e} -> {err_fine:.3e}"


def test_fast_motion_takes_more_substeps():
    """At 40 rad/s the max_angle rule keeps a default control step accurate; fixed 4 substeps are not."""
    p = LegParams()
    rng = np.random.default_rng(14)
    q, qd, tau_eq = near_nominal(p, rng)
    qd[2:] = [0.0, 40.0, -40.0]
    q, qd = dyn.project_stance(q, qd, p, np.zeros(2))
    ref = np.concatenate(dyn.stance_step(q, qd, tau_eq, p, substeps=512, max_angle=np.inf)[:2])
    adaptive = np.concatenate(dyn.stance_step(q, qd, tau_eq, p)[:2])
    fixed = np.concatenate(dyn.stance_step(q, qd, tau_eq, p, max_angle=np.inf)[:2])
    err_adaptive = np.linalg.norm(adaptive - ref)
    err_fixed = np.linalg.norm(fixed - ref)
    assert err_adaptive < 1e-6 * np.linalg.norm(ref)
    assert err_fixed > 10.0 * err_adaptive


# ----------------------------------------------------------------------------
# Mean contact force
# ----------------------------------------------------------------------------


@pytest.mark.parametrize("seed", PARAM_SEEDS, ids=str)
@pytest.mark.parametrize("rate_scale, substeps", LAM_CASES)
def test_lam_mean_is_time_average_of_contact_force(seed, rate_scale, substeps):
    p = make_params(seed)
    rng = np.random.default_rng(15)
    q, qd, tau_eq = near_nominal(p, rng, rate_noise=rate_scale)
    tau = tau_eq + rng.uniform(-20.0, 20.0, 2)
    anchor = np.zeros(2)
    _, _, lam_mean = dyn.stance_step(q, qd, tau, p, substeps=substeps, anchor=anchor)
    # fine re-integration of the same control step; Simpson's rule over the instantaneous forces
    h = dyn.DT / LAM_FINE_STEPS
    qf, qdf = q, qd
    lam_t = [dyn.stance_dynamics(qf, qdf, tau, p)[1]]
    for _ in range(LAM_FINE_STEPS):
        qf, qdf, _ = dyn.stance_step(qf, qdf, tau, p, dt=h, substeps=1, max_angle=np.inf, anchor=anchor)
        lam_t.append(dyn.stance_dynamics(qf, qdf, tau, p)[1])
    lam_t = np.array(lam_t)
    lam_avg = simpson(lam_t, dx=h, axis=0) / dyn.DT
    err = np.linalg.norm(lam_mean - lam_avg)
    assert err <= LAM_RTOL * (1.0 + np.linalg.norm(lam_avg))
    # the average differs from the force at either end of the step by far more than the tolerance
    assert np.linalg.norm(lam_t[0] - lam_avg) > 100.0 * err
    assert np.linalg.norm(lam_t[-1] - lam_avg) > 100.0 * err


def test_lam_mean_at_rest_is_the_weight():
    p = LegParams()
    q, tau, lam = dyn.static_equilibrium(p)
    q1, qd1, lam_mean = dyn.stance_step(q, np.zeros(5), tau, p)
    np.testing.assert_allclose(lam_mean, [0.0, p.weight], rtol=0, atol=1e-10 * p.weight)
    np.testing.assert_allclose(q1, q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(qd1, 0.0, rtol=0, atol=1e-12)


def test_flight_step_has_no_contact_force():
    p = LegParams()
    q, qd, tau = near_nominal(p, np.random.default_rng(16))
    lam = np.full((1, 2), np.nan)
    dyn.step_inplace(q[None].copy(), qd[None].copy(), tau[None], p.array, np.zeros((1, 2)), dyn.DT, dyn.SUBSTEPS,
                    dyn.MAX_ANGLE, False, lam)
    np.testing.assert_array_equal(lam, 0.0)


# ----------------------------------------------------------------------------
# Batching
# ----------------------------------------------------------------------------

LEAD_SHAPES = [(1,), (7,), (2, 3)]


def random_batch(p, rng, lead):
    n = int(np.prod(lead))
    states = [near_nominal(p, rng, angle_noise=0.3, rate_noise=2.0) for _ in range(n)]
    q = np.array([s[0] for s in states])
    qd = np.array([s[1] for s in states])
    qd[: n // 2, 3:] *= 20.0  # some robots fast enough for the adaptive substep rule
    tau = rng.uniform(-50.0, 50.0, (n, 2))
    anchor = rng.uniform(-1.0, 1.0, (n, 2))
    return q, qd, tau, anchor


@pytest.mark.parametrize("lead", LEAD_SHAPES, ids=str)
def test_stance_step_batched_equals_stacked_singles(lead):
    p = random_params(np.random.default_rng(17))
    q, qd, tau, anchor = random_batch(p, np.random.default_rng(18), lead)
    q, qd = dyn.project_stance(q, qd, p, anchor)
    batched = dyn.stance_step(q.reshape(lead + (5,)), qd.reshape(lead + (5,)), tau.reshape(lead + (2,)), p,
                             anchor=anchor.reshape(lead + (2,)))
    singles = [dyn.stance_step(q[i], qd[i], tau[i], p, anchor=anchor[i]) for i in range(len(q))]
    for k, b in enumerate(batched):
        assert b.shape == lead + singles[0][k].shape
        np.testing.assert_array_equal(b.reshape(len(q), -1), np.array([s[k] for s in singles]))


@pytest.mark.parametrize("lead", LEAD_SHAPES, ids=str)
def test_flight_step_batched_equals_stacked_singles(lead):
    p = random_params(np.random.default_rng(19))
    q, qd, tau, _ = random_batch(p, np.random.default_rng(20), lead)
    batched = dyn.flight_step(q.reshape(lead + (5,)), qd.reshape(lead + (5,)), tau.reshape(lead + (2,)), p)
    singles = [dyn.flight_step(q[i], qd[i], tau[i], p) for i in range(len(q))]
    for k, b in enumerate(batched):
        assert b.shape == lead + (5,)
        np.testing.assert_array_equal(b.reshape(len(q), -1), np.array([s[k] for s in singles]))


def test_single_torque_and_default_anchor_broadcast():
    p = LegParams()
    q, qd, _, anchor = random_batch(p, np.random.default_rng(21), (5,))
    tau = np.array([3.0, -4.0])
    batched = dyn.stance_step(q, qd, tau, p)  # anchor: each foot where it is
    singles = [dyn.stance_step(q[i], qd[i], tau, p) for i in range(len(q))]
    for k, b in enumerate(batched):
        np.testing.assert_array_equal(b, np.array([s[k] for s in singles]))
    flight_singles = np.array([dyn.flight_step(x, v, tau, p)[0] for x, v in zip(q, qd)])
    np.testing.assert_array_equal(dyn.flight_step(q, qd, tau, p)[0], flight_singles)


def test_step_inplace_equals_stance_step():
    """The env's low-level entry point is the same computation as the checked wrapper."""
    p = random_params(np.random.default_rng(22))
    q, qd, tau, anchor = random_batch(p, np.random.default_rng(23), (6,))
    q, qd = dyn.project_stance(q, qd, p, anchor)
    expected = dyn.stance_step(q, qd, tau, p, anchor=anchor)
    q_io, qd_io, lam = q.copy(), qd.copy(), np.empty((6, 2))
    dyn.step_inplace(q_io, qd_io, tau, p.array, anchor, dyn.DT, dyn.SUBSTEPS, dyn.MAX_ANGLE, True, lam)
    for a, b in zip((q_io, qd_io, lam), expected):
        np.testing.assert_array_equal(a, b)


def test_step_inplace_reads_no_load_past_an_11_entry_parameter_array():
    """``p`` of 11 entries (``LegParams.array``) means no load: the kernels read the load at ``p[11]``, so an
    11-entry view whose memory goes on with a large number must give the unloaded step, as 12 entries with a
    zero load do; another length is a ValueError."""
    p = random_params(np.random.default_rng(24))
    q, qd, tau, anchor = random_batch(p, np.random.default_rng(25), (4,))
    q, qd = dyn.project_stance(q, qd, p, anchor)
    expected = dyn.stance_step(q, qd, tau, p, anchor=anchor)
    buffer = np.append(p.array, 1e4)  # a 10 kN "load" right after the 11 parameters
    for params in (buffer[:11], dyn.params_array(p)):
        q_io, qd_io, lam = q.copy(), qd.copy(), np.empty((4, 2))
        dyn.step_inplace(q_io, qd_io, tau, params, anchor, dyn.DT, dyn.SUBSTEPS, dyn.MAX_ANGLE, True, lam)
        for a, b in zip((q_io, qd_io, lam), expected):
            np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="11 values"):
        dyn.step_inplace(q.copy(), qd.copy(), tau, p.array[:10], anchor, dyn.DT, dyn.SUBSTEPS, dyn.MAX_ANGLE, True, np.empty((4, 2)))


# ----------------------------------------------------------------------------
# Projections
# ----------------------------------------------------------------------------


def test_project_stance_puts_foot_on_anchor_with_zero_contact_velocity():
    rng = np.random.default_rng(24)
    for _ in range(50):
        p = random_params(rng)
        q = np.concatenate([rng.uniform(-2.0, 2.0, 2), rng.uniform(-np.pi, np.pi, 3)])
        qd = rng.normal(0.0, 3.0, 5)
        anchor = rng.uniform(-1.0, 1.0, 2)
        qp, qdp = dyn.project_stance(q, qd, p, anchor)
        np.testing.assert_allclose(dyn.foot_position(qp, p), anchor, rtol=0, atol=PROJECTION_TOL)
        np.testing.assert_allclose(dyn.contact_jacobian(qp, p) @ qdp, 0.0, rtol=0, atol=PROJECTION_TOL * 10)
        np.testing.assert_array_equal(qp[2:], q[2:])  # only the base moves
        np.testing.assert_array_equal(qdp[2:], qd[2:])


def test_project_velocity_is_the_euclidean_projection_onto_the_nullspace():
    rng = np.random.default_rng(25)
    for _ in range(50):
        p = random_params(rng)
        q = np.concatenate([rng.uniform(-2.0, 2.0, 2), rng.uniform(-np.pi, np.pi, 3)])
        qd = rng.normal(0.0, 3.0, 5)
        qdp = dyn.project_velocity(q, qd, p)
        Jc = dyn.contact_jacobian(q, p)
        np.testing.assert_allclose(Jc @ qdp, 0.0, rtol=0, atol=PROJECTION_TOL * 10)
        np.testing.assert_allclose(dyn.project_velocity(q, qdp, p), qdp, rtol=0, atol=PROJECTION_TOL * 10)
        # the removed part lies in the range of Jc^T, i.e. orthogonal to the nullspace
        removed = qd - qdp
        assert abs(removed @ qdp) <= PROJECTION_TOL * 10 * (1.0 + qd @ qd)


def test_project_velocity_batched():
    rng = np.random.default_rng(26)
    p = random_params(rng)
    q = rng.uniform(-np.pi, np.pi, (3, 4, 5))
    qd = rng.normal(0.0, 3.0, (3, 4, 5))
    batched = dyn.project_velocity(q, qd, p)
    singles = np.array([dyn.project_velocity(a, b, p) for a, b in zip(q.reshape(-1, 5), qd.reshape(-1, 5))])
    np.testing.assert_allclose(batched.reshape(-1, 5), singles, rtol=1e-14, atol=1e-14)


# ----------------------------------------------------------------------------
# Argument checks
# ----------------------------------------------------------------------------

BAD_STEP_ARGS = [
    {"dt": 0.0},
    {"dt": -0.01},
    {"dt": float("nan")},
    {"dt": float("inf")},
    {"substeps": 0},
    {"substeps": -1},
    {"substeps": 2.5},
    {"substeps": "4"},
    {"max_angle": 0.0},
    {"max_angle": -0.02},
    {"max_angle": float("nan")},
]


@pytest.mark.parametrize("kwargs", BAD_STEP_ARGS, ids=str)
@pytest.mark.parametrize("stepper", ["stance_step", "flight_step"])
def test_bad_step_arguments_raise(stepper, kwargs):
    p = LegParams()
    q, tau, _ = dyn.static_equilibrium(p)
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        getattr(dyn, stepper)(q, np.zeros(5), tau, p, **kwargs)


@pytest.mark.parametrize("stepper", ["stance_step", "flight_step"])
def test_wrong_shapes_raise(stepper):
    p = LegParams()
    q, tau, _ = dyn.static_equilibrium(p)
    for args in ((q[:4], np.zeros(5), tau), (q, np.zeros(6), tau), (q, np.zeros(5), np.zeros(3))):
        with pytest.raises(ValueError):
            getattr(dyn, stepper)(*args, p)
    if stepper == "stance_step":
        with pytest.raises(ValueError):
            dyn.stance_step(q, np.zeros(5), tau, p, anchor=np.zeros(3))


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("lead", [(), (3,)], ids=["one robot", "batch"])
@pytest.mark.parametrize("stepper", ["stance_step", "flight_step"])
def test_non_finite_input_is_named_and_nothing_changes(stepper, lead, value):
    """A NaN or inf in the state, the torques or the anchor: a ValueError naming the argument, the inputs as they
    were (the one robot's fast path and the batched path alike); a step that only sums past the largest float (finite
    entries) is taken."""
    p = LegParams()
    q0, tau0, _ = dyn.static_equilibrium(p)
    names = ["q", "qd", "tau"] + (["anchor"] if stepper == "stance_step" else [])
    clean = {"q": q0, "qd": np.zeros(5), "tau": tau0, "anchor": dyn.foot_position(q0, p)}
    for bad in names:
        args = {k: np.array(np.broadcast_to(v, lead + v.shape)) for k, v in clean.items()}
        args[bad][..., -1] = value
        kept = {k: v.copy() for k, v in args.items()}
        extra = {"anchor": args["anchor"]} if stepper == "stance_step" else {}
        with pytest.raises(ValueError, match=f"^{bad} must be finite"):
            getattr(dyn, stepper)(args["q"], args["qd"], args["tau"], p, **extra)
        for k in args:
            assert np.array_equal(args[k], kept[k], equal_nan=True)
    far = q0.copy()
    far[0] = 1e308  # the base's x, which nothing depends on: with the anchor's the sum overflows, every entry finite
    q_next, *_ = dyn.stance_step(far, np.zeros(5), tau0, p)
    assert q_next[0] == 1e308


def test_single_robot_inputs_of_any_layout_agree():
    """Lists, strided views and contiguous arrays take different entry paths; results agree."""
    p = LegParams()
    q, qd, tau = near_nominal(p, np.random.default_rng(27))
    anchor = dyn.foot_position(q, p)
    expected = dyn.stance_step(q, qd, tau, p, anchor=anchor)
    strided = np.zeros((5, 2))
    strided[:, 0] = q
    for args in ((list(q), list(qd), list(tau), list(anchor)), (strided[:, 0], qd, tau, anchor)):
        got = dyn.stance_step(*args[:3], p, anchor=args[3])
        for a, b in zip(got, expected):
            np.testing.assert_array_equal(a, b)
