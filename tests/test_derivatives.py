"""The Jacobians of the control step (leg_env.physics.derivatives) against two independent derivations and identities.

1. Complex-step differentiation of an RK4 step written on the SymPy Lagrangian's terms (``tests/derivative_ref.py``),
   over random states of random robots: agreement to round-off.
2. Centred finite differences of the step itself (``stance_step``, ``flight_step``) over states drawn from rollouts
   of the pinned task (random actions and the LQR controller) and random flights: the relative (Frobenius) error of
   ``A`` and ``B`` at most ``FD_RTOL``, with the substep count the same at both perturbations (the share where it is
   not is reported and bounded).
3. Identities: moving the whole robot (with the anchor following it) moves the next state by as much; a held anchor
   makes the base's position and velocity before the step irrelevant.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from conftest import random_params
from derivative_ref import ComplexStep, substeps_for
from leg_env import physics as dyn
from leg_env.physics.derivatives import NX, flight_step_jacobians, stance_step_jacobians
from leg_env.physics.params import LegParams

DT, SUBSTEPS, MAX_ANGLE = 0.01, 2, 0.02
REF_CASES = 40  # random (robot, state) pairs per model against the complex-step reference
REF_RTOL = 1e-12
FD_RTOL = 1e-6  # the bar on steps without an event
FD_EPS_X, FD_EPS_TAU = 1e-6, 1e-4  # [m, rad, m/s, rad/s], [N m]
ROLLOUT_ROBOTS, ROLLOUT_STEPS = 256, 40  # 2 policies x 256 x 40 = 20,480 states of the pinned task
FLIGHT_CASES = 4096


def rel(a, b) -> np.ndarray:
    """Relative Frobenius error of each matrix of a batch."""
    return np.linalg.norm(a - b, axis=(-2, -1)) / np.maximum(np.linalg.norm(b, axis=(-2, -1)), 1e-300)


def random_state(p, rng, stance: bool):
    q_eq, tau_eq, _ = dyn.static_equilibrium(p)
    q = q_eq + np.concatenate([rng.normal(0.0, 0.3, 2), rng.normal(0.0, 0.15, 3)])
    qd = rng.normal(0.0, 2.0, 5)
    tau = tau_eq + rng.normal(0.0, 10.0, 2)
    if stance:
        q, qd = dyn.project_stance(q, qd, p, dyn.foot_position(q, p))
    return q, qd, tau


# ------------------------------------------------------------------ the step itself


@pytest.mark.parametrize("stance", [True, False], ids=["pinned", "flight"])
def test_the_step_is_the_step(stance):
    """The Jacobians come with the step they differentiate, bit for bit, batched and one robot at a time."""
    rng = np.random.default_rng(0)
    p = random_params(rng)
    states = [random_state(p, rng, stance) for _ in range(16)]
    q, qd, tau = (np.array([s[k] for s in states]) for k in range(3))
    if stance:
        q1, qd1, lam = dyn.stance_step(q, qd, tau, p)
        J = stance_step_jacobians(q, qd, tau, p)
        np.testing.assert_array_equal(J.lam_mean, lam)
    else:
        q1, qd1 = dyn.flight_step(q, qd, tau, p)
        J = flight_step_jacobians(q, qd, tau, p)
        np.testing.assert_array_equal(J.lam_mean, 0.0)
    np.testing.assert_array_equal(J.q, q1)
    np.testing.assert_array_equal(J.qd, qd1)
    assert J.A.shape == (16, NX, NX) and J.B.shape == (16, NX, 2)
    one = (stance_step_jacobians if stance else flight_step_jacobians)(q[3], qd[3], tau[3], p)
    np.testing.assert_array_equal(one.A, J.A[3])
    np.testing.assert_array_equal(one.B, J.B[3])
    # leading axes are kept
    J2 = (stance_step_jacobians if stance else flight_step_jacobians)(q.reshape(4, 4, 5), qd.reshape(4, 4, 5), tau.reshape(4, 4, 2), p)
    np.testing.assert_array_equal(J2.A.reshape(16, NX, NX), J.A)


# ------------------------------------------------------------------ 1. the complex-step reference


@pytest.mark.parametrize("stance", [True, False], ids=["pinned", "flight"])
def test_against_complex_step_of_the_sympy_step(stance):
    rng = np.random.default_rng(20261206 + stance)
    worst = 0.0
    substeps_seen = set()
    for _ in range(REF_CASES):
        p = random_params(rng)
        q, qd, tau = random_state(p, rng, stance)
        A_ref, B_ref = ComplexStep(p).jacobians(q, qd, tau, DT, SUBSTEPS, MAX_ANGLE, stance)
        J = (stance_step_jacobians if stance else flight_step_jacobians)(q, qd, tau, p)
        worst = max(worst, rel(J.A, A_ref), rel(J.B, B_ref))
        substeps_seen.add(substeps_for(qd, DT, SUBSTEPS, MAX_ANGLE))
    assert worst <= REF_RTOL, worst
    assert len(substeps_seen) >= 3  # the step rule's substep count varied over the cases


def test_against_complex_step_with_a_held_anchor():
    rng = np.random.default_rng(7)
    for _ in range(10):
        p = random_params(rng)
        q, qd, tau = random_state(p, rng, True)
        anchor = dyn.foot_position(q, p)
        A_ref, B_ref = ComplexStep(p).jacobians(q, qd, tau, DT, SUBSTEPS, MAX_ANGLE, True, anchor=anchor)
        J = stance_step_jacobians(q, qd, tau, p, anchor=anchor)
        assert rel(J.A, A_ref) <= REF_RTOL and rel(J.B, B_ref) <= REF_RTOL


# ------------------------------------------------------------------ 2. finite differences on rollouts


def pinned_rollout_states():
    """(q, qd, tau) before each step of rollouts of the pinned task: random actions, then the LQR controller."""
    from policies.lqr import LQRController

    out = []
    for controller in ("random", "lqr"):
        envs = gym.make_vec("leg_env/PlanarLegStance-v0", num_envs=ROLLOUT_ROBOTS, vectorization_mode="vector_entry_point")
        obs, _ = envs.reset(seed=31)
        policy = None if controller == "random" else LQRController()
        rng = np.random.default_rng(5)
        for _ in range(ROLLOUT_STEPS):
            q, qd, _ = (a.copy() for a in envs.unwrapped.state)
            action = rng.uniform(-1.0, 1.0, (ROLLOUT_ROBOTS, 2)) if policy is None else policy.predict(obs, deterministic=True)[0]
            obs, _, _, _, info = envs.step(action)
            out.append((q, qd, info["torque"].copy()))
        envs.close()
    q, qd, tau = (np.concatenate([o[k] for o in out]) for k in range(3))
    return q, qd, tau, envs.unwrapped.params


def centred_fd(step, q, qd, tau):
    """Centred differences of a batched step ``step(q, qd, tau) -> (N, 10)``; also whether the step rule's substep
    count is the same at both perturbations of every direction."""
    n = q.shape[0]
    A, B = np.empty((n, NX, NX)), np.empty((n, NX, 2))
    same = np.ones(n, bool)
    x = np.concatenate([q, qd], axis=1)

    def count(qd_):
        return np.array([substeps_for(v, DT, SUBSTEPS, MAX_ANGLE) for v in qd_])

    base = count(qd)
    for j in range(NX):
        e = np.zeros(NX)
        e[j] = FD_EPS_X
        xp, xm = x + e, x - e
        A[:, :, j] = (step(xp[:, :5], xp[:, 5:], tau) - step(xm[:, :5], xm[:, 5:], tau)) / (2 * FD_EPS_X)
        if j >= 5:
            same &= (count(xp[:, 5:]) == base) & (count(xm[:, 5:]) == base)
    for j in range(2):
        e = np.zeros(2)
        e[j] = FD_EPS_TAU
        B[:, :, j] = (step(q, qd, tau + e) - step(q, qd, tau - e)) / (2 * FD_EPS_TAU)
    return A, B, same


def test_pinned_against_finite_differences_on_rollouts(capsys):
    q, qd, tau, p = pinned_rollout_states()
    assert q.shape[0] >= 10_000

    def step(q_, qd_, tau_):
        a, b, _ = dyn.stance_step(q_, qd_, tau_, p)
        return np.concatenate([a, b], axis=1)

    A_fd, B_fd, same = centred_fd(step, q, qd, tau)
    J = stance_step_jacobians(q, qd, tau, p)
    err_A, err_B = rel(J.A, A_fd)[same], rel(J.B, B_fd)[same]
    with capsys.disabled():
        print(f"\npinned: {q.shape[0]} states, substep count changed under a perturbation at {1 - same.mean():.2%}; "
              f"A median {np.median(err_A):.1e} max {err_A.max():.1e}; B median {np.median(err_B):.1e} max {err_B.max():.1e}")
    assert same.mean() > 0.99
    assert err_A.max() <= FD_RTOL and err_B.max() <= FD_RTOL


def test_flight_against_finite_differences():
    rng = np.random.default_rng(11)
    p = LegParams()
    states = [random_state(p, rng, False) for _ in range(FLIGHT_CASES)]
    q, qd, tau = (np.array([s[k] for s in states]) for k in range(3))

    def step(q_, qd_, tau_):
        return np.concatenate(dyn.flight_step(q_, qd_, tau_, p), axis=1)

    A_fd, B_fd, same = centred_fd(step, q, qd, tau)
    J = flight_step_jacobians(q, qd, tau, p)
    assert same.mean() > 0.99
    assert rel(J.A, A_fd)[same].max() <= FD_RTOL and rel(J.B, B_fd)[same].max() <= FD_RTOL


# ------------------------------------------------------------------ 3. identities


@pytest.mark.parametrize("stance", [True, False], ids=["pinned", "flight"])
def test_moving_the_whole_robot_moves_the_next_state(stance):
    """Translation invariance: with the anchor following q, d(next)/d(x_b) = e_x_b and d(next)/d(y_b) = e_y_b."""
    rng = np.random.default_rng(3)
    p = random_params(rng)
    states = [random_state(p, rng, stance) for _ in range(64)]
    q, qd, tau = (np.array([s[k] for s in states]) for k in range(3))
    J = (stance_step_jacobians if stance else flight_step_jacobians)(q, qd, tau, p)
    for j in (0, 1):
        np.testing.assert_allclose(J.A[:, :, j], np.broadcast_to(np.eye(NX)[j], (64, NX)), atol=1e-12)


def test_a_held_anchor_forgets_the_base():
    """With the anchor held, the projection sets the base from the leg: the base's position and velocity before the
    step have no effect (their columns of A are zero), and the foot after the step stays on the anchor to first order."""
    rng = np.random.default_rng(4)
    p = random_params(rng)
    states = [random_state(p, rng, True) for _ in range(64)]
    q, qd, tau = (np.array([s[k] for s in states]) for k in range(3))
    anchor = dyn.foot_position(q, p)
    J = stance_step_jacobians(q, qd, tau, p, anchor=anchor)
    np.testing.assert_array_equal(J.A[:, :, [0, 1, 5, 6]], 0.0)
    Jc = dyn.contact_jacobian(J.q, p)  # d p_f = Jc dq after the step: zero for every direction
    np.testing.assert_allclose(Jc @ J.A[:, :5, :], 0.0, atol=1e-12)
    np.testing.assert_allclose(Jc @ J.B[:, :5, :], 0.0, atol=1e-12)


def test_the_torques_drive_the_joints_the_right_way():
    """A hip torque turns the torso back (I_b th_b'' = -tau_hip): over one step, d th_b / d tau_hip = -dt^2 / (2 I_b)
    exactly in flight (the torso's equation is linear), and d th_b' / d tau_hip = -dt / I_b."""
    rng = np.random.default_rng(9)
    p = random_params(rng)
    q, qd, tau = random_state(p, rng, False)
    J = flight_step_jacobians(q, qd, tau, p)
    assert J.B[2, 0] == pytest.approx(-DT**2 / (2 * p.I_b), rel=1e-12)
    assert J.B[7, 0] == pytest.approx(-DT / p.I_b, rel=1e-12)
    assert J.B[2, 1] == 0.0 and J.B[7, 1] == 0.0


# ------------------------------------------------------------------ bad input


def test_bad_input_is_named():
    p = LegParams()
    q, qd, tau = random_state(p, np.random.default_rng(0), True)
    with pytest.raises(ValueError, match="qd"):
        stance_step_jacobians(q, qd[:4], tau, p)
    with pytest.raises(ValueError, match="tau"):
        stance_step_jacobians(q, qd, np.zeros(3), p)
    with pytest.raises(ValueError, match="substeps"):
        stance_step_jacobians(q, qd, tau, p, substeps=0)
    with pytest.raises(ValueError, match="anchor"):
        stance_step_jacobians(q, qd, tau, p, anchor=np.zeros(3))
    with pytest.raises(TypeError):
        stance_step_jacobians(q, qd, tau, p, anchr=None)
