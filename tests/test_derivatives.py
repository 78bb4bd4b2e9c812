"""The Jacobians of the control step (leg_env.physics.derivatives) against two independent derivations and identities.

1. Complex-step differentiation of an RK4 step written on the SymPy Lagrangian's terms (``tests/derivative_ref.py``),
   over random states of random robots: agreement to round-off.
2. Centred finite differences of the step itself (``stance_step``, ``flight_step``) over states drawn from rollouts
   of the pinned task (random actions and the LQR controller) and random flights: the relative (Frobenius) error of
   ``A`` and ``B`` at most ``FD_RTOL``, with the substep count the same at both perturbations (the share where it is
   not is reported and bounded). The same for ``hybrid_step`` over rollouts of every task on the unilateral ground
   (random actions and each task's controller), reported per kind of event: at most ``FD_RTOL`` on steps without an
   event, ``FD_RTOL_EVENT`` on steps with one, wherever the events are the same at both perturbations. A robot in
   contact is perturbed only along its contact's manifold (the foot on the ground, and at rest in stick), where the
   step is smooth; a foot in the air, along every direction.
3. Identities: moving the whole robot (with the anchor following it) moves the next state by as much; a held anchor
   makes the base's position and velocity before the step irrelevant.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from conftest import random_params
from derivative_ref import ComplexStep, HybridComplexStep, Refused, substeps_for
from leg_env import physics as dyn
from leg_env.physics.derivatives import NX, flight_step_jacobians, stance_step_jacobians
from leg_env.physics.params import LegParams

DT, SUBSTEPS, MAX_ANGLE = 0.01, 2, 0.02
REF_CASES = 40  # random (robot, state) pairs per model against the complex-step reference
REF_RTOL = 1e-12
REF_RTOL_EVENT = 1e-9  # through an event located to ROOT_TIME (1e-12 s) rather than to the exact root
FD_RTOL = 1e-6  # the bar on steps without an event (relative, Frobenius)
FD_EPS_X, FD_EPS_TAU = 1e-6, 1e-4  # [m, rad, m/s, rad/s], [N m]
ROLLOUT_ROBOTS, ROLLOUT_STEPS = 256, 40  # 2 policies x 256 x 40 = 20,480 states of the pinned task
FLIGHT_CASES = 4096
FD_RTOL_EVENT = 1e-4  # the bar on steps with an event
HYBRID_ROBOTS, HYBRID_STEPS = 64, 200  # per task and controller: 3 tasks x 2 x 64 x 200 = 76,800 states


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


def random_batch(p, rng, stance: bool, n: int):
    """(q, qd, tau) of n random states (random_state's)."""
    states = [random_state(p, rng, stance) for _ in range(n)]
    return tuple(np.array([s[k] for s in states]) for k in range(3))


# ------------------------------------------------------------------ the step itself


@pytest.mark.parametrize("stance", [True, False], ids=["pinned", "flight"])
def test_the_step_is_the_step(stance):
    """The Jacobians come with the step they differentiate, bit for bit, batched and one robot at a time."""
    rng = np.random.default_rng(0)
    p = random_params(rng)
    q, qd, tau = random_batch(p, rng, stance, 16)
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
        ref = ComplexStep(p)
        A_ref, B_ref = ref.jacobians(q, qd, tau, DT, SUBSTEPS, MAX_ANGLE, stance)
        P_ref = ref.param_jacobian(q, qd, tau, DT, SUBSTEPS, MAX_ANGLE, stance)
        J = (stance_step_jacobians if stance else flight_step_jacobians)(q, qd, tau, p, params=True)
        worst = max(worst, rel(J.A, A_ref), rel(J.B, B_ref), rel(J.P, P_ref))
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


def pinned_rollout_states(controllers_=None):
    """(q, qd, tau) before each step of rollouts of the pinned task: random actions, then the LQR controller (or the
    given controllers, None standing for random actions)."""
    from policies.lqr import LQRController

    out = []
    for controller in (controllers_ if controllers_ is not None else (None, LQRController())):
        envs = gym.make_vec("leg_env/PlanarLegStance-v0", num_envs=ROLLOUT_ROBOTS, vectorization_mode="vector_entry_point")
        obs, _ = envs.reset(seed=31)
        rng = np.random.default_rng(5)
        for _ in range(ROLLOUT_STEPS):
            q, qd, _ = (a.copy() for a in envs.unwrapped.state)
            action = rng.uniform(-1.0, 1.0, (ROLLOUT_ROBOTS, 2)) if controller is None else controller.predict(obs, deterministic=True)[0]
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


def pinned_fd_check(controllers_=None):
    """Centred differences of ``stance_step`` against its Jacobians on pinned rollout states: (states, share with the
    substep count changed, errors of A and B where it is not)."""
    q, qd, tau, p = pinned_rollout_states(controllers_)

    def step(q_, qd_, tau_):
        a, b, _ = dyn.stance_step(q_, qd_, tau_, p)
        return np.concatenate([a, b], axis=1)

    A_fd, B_fd, same = centred_fd(step, q, qd, tau)
    J = stance_step_jacobians(q, qd, tau, p)
    return q.shape[0], same, rel(J.A, A_fd)[same], rel(J.B, B_fd)[same]


def test_pinned_against_finite_differences_on_rollouts(capsys):
    n, same, err_A, err_B = pinned_fd_check()
    assert n >= 10_000
    with capsys.disabled():
        print(f"\npinned: {n} states, substep count changed under a perturbation at {1 - same.mean():.2%}; "
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


# ------------------------------------------------------------------ the unilateral ground


def unilateral_rollout_states(env_id: str, controller):
    """(q, qd, tau, mode, anchor_x, load) before each step of a rollout of ``env_id`` under ``controller`` (None:
    random actions), and the robot's parameters and friction."""
    envs = gym.make_vec(env_id, num_envs=HYBRID_ROBOTS, vectorization_mode="vector_entry_point")
    obs, _ = envs.reset(seed=17)
    env = envs.unwrapped
    rng = np.random.default_rng(23)
    out = []
    for _ in range(HYBRID_STEPS):
        q, qd, anchor = env.state
        mode = env.contact_mode
        action = rng.uniform(-1.0, 1.0, (HYBRID_ROBOTS, 2)) if controller is None else controller.predict(obs, deterministic=True)[0]
        obs, _, _, _, info = envs.step(action)
        load = info.get("push_force", np.zeros(HYBRID_ROBOTS))
        out.append((q, qd, info["torque"].copy(), mode, anchor[:, 0].copy(), np.asarray(load, float).copy()))
    params, mu = env.params, env.config.mu
    envs.close()
    return (*(np.concatenate([o[k] for o in out]) for k in range(6)), params, mu)


def manifold_basis(q, qd, mode, p) -> np.ndarray:
    """(N, 10, 10): the first columns an orthonormal basis of the directions along which the step is smooth, the rest
    zero: in stick the foot stays on the ground (y_f) and at rest (x_f', y_f'), in slip on the ground (y_f, y_f'); a
    foot in the air moves freely, one within 10 um of the ground (a flight just begun) not towards it."""
    n = q.shape[0]
    Jc = dyn.contact_jacobian(q, p)
    # d(Jc qd)/dq by centred differences: only to lay the directions on the manifold (their error is second order)
    G = np.empty((n, 2, 5))
    for j in range(5):
        e = np.zeros(5)
        e[j] = 1e-6
        G[:, :, j] = ((dyn.contact_jacobian(q + e, p) - dyn.contact_jacobian(q - e, p)) @ qd[:, :, None])[:, :, 0] / 2e-6
    zeros = np.zeros((n, 5))
    height = dyn.foot_position(q, p)[:, 1]
    basis = np.zeros((n, NX, NX))
    for i in range(n):
        rows = []
        if mode[i] != dyn.FLIGHT or height[i] < 1e-5:
            rows.append(np.concatenate([Jc[i, 1], zeros[i]]))
        if mode[i] in (dyn.STICK, dyn.SLIP_FORWARD, dyn.SLIP_BACKWARD):
            rows.append(np.concatenate([G[i, 1], Jc[i, 1]]))
        if mode[i] == dyn.STICK:
            rows.append(np.concatenate([G[i, 0], Jc[i, 0]]))
        if rows:
            _, _, vt = np.linalg.svd(np.array(rows))
            basis[i, :, : NX - len(rows)] = vt[len(rows):].T
        else:
            basis[i] = np.eye(NX)
    return basis


def controllers():
    from policies.gated import GatedController
    from policies.hopper import HopperController
    from policies.stepping import SteppingController

    return {"leg_env/PlanarLegBalance-v1": GatedController, "leg_env/PlanarLegPush-v2": SteppingController,
            "leg_env/PlanarLegHop-v4": HopperController}


def test_hybrid_step_is_the_step():
    rng = np.random.default_rng(2)
    p = random_params(rng)
    q, qd, tau = random_batch(p, rng, True, 32)
    q, qd = dyn.project_stance(q, qd, p, dyn.foot_position(q, p) * [1.0, 0.0])  # the feet on the ground
    q[::2, 1] += rng.uniform(0.0, 0.05, 16)  # half of them in the air
    qd[::2, 1] -= 1.0
    load = rng.normal(0.0, 20.0, 32)
    ref = dyn.hybrid_step(q, qd, tau, p, 0.6, load_x=load)
    J = dyn.hybrid_step_jacobians(q, qd, tau, p, 0.6, load_x=load)
    for name, value in ref._asdict().items():
        np.testing.assert_array_equal(getattr(J.step, name), value, err_msg=name)
    assert (J.step.events > 0).any() and J.defined.all()
    one = dyn.hybrid_step_jacobians(q[5], qd[5], tau[5], p, 0.6, load_x=load[5])
    np.testing.assert_array_equal(one.A, J.A[5])
    assert one.A.shape == (NX, NX) and one.undefined.shape == ()


def hybrid_fd_check(env_id: str, controller, worst: dict, rows: list) -> None:
    """Five-point differences of ``hybrid_step`` against its Jacobians on rollout states of ``env_id`` under
    ``controller`` (None: random actions): each kind of event's largest relative error into ``worst``, a line of
    counts into ``rows``; at most 1% of the states may change their events under a perturbation or be undefined."""
    q, qd, tau, mode, anchor_x, load, p, mu = unilateral_rollout_states(env_id, controller)
    J = dyn.hybrid_step_jacobians(q, qd, tau, p, mu, mode=mode, load_x=load)
    basis = manifold_basis(q, qd, mode, p)
    x = np.concatenate([q, qd], axis=1)
    kinds = J.step.event_kind
    same = np.ones(q.shape[0], bool)

    def differences(run, n_dirs, eps):
        """Five-point centred differences (fourth order): an event is located to ROOT_TIME (1e-12 s), which a
        difference with a small step amplifies, so the step must stay large and its truncation error small."""
        nonlocal same
        out = np.empty((q.shape[0], NX, n_dirs))
        for k in range(n_dirs):
            ends = {}
            for m in (-2, -1, 1, 2):
                r = run(k, m * eps)
                same &= (r.event_kind == kinds).all(axis=1) & (r.mode == J.step.mode)
                ends[m] = np.concatenate([r.q, r.qd], axis=1)
            out[:, :, k] = (8.0 * (ends[1] - ends[-1]) - (ends[2] - ends[-2])) / (12.0 * eps)
        return out

    def along_basis(k, d):
        xs = x + d * basis[:, :, k]
        return dyn.hybrid_step(xs[:, :5], xs[:, 5:], tau, p, mu, mode=mode, load_x=load)

    def along_torque(j, d):
        e = np.zeros(2)
        e[j] = d
        return dyn.hybrid_step(q, qd, tau + e, p, mu, mode=mode, load_x=load)

    # the better of two step sizes: near a grazing re-contact the larger step's truncation error dominates, at the
    # smaller the round-off of an event's location
    err = np.full(q.shape[0], np.inf)
    for scale in (1.0, 0.1):
        AN = differences(along_basis, NX, FD_EPS_X * scale)
        B = differences(along_torque, 2, FD_EPS_TAU * scale)
        err = np.minimum(err, np.maximum(rel(J.A @ basis, AN), rel(J.B, B)))
    checked = same & J.defined
    first = np.where(kinds[:, 0] < 0, -1, kinds[:, 0])
    for kind, name in [(-1, "no event"), *enumerate(dyn.EVENT_NAMES)]:
        m = checked & (first == kind)
        if m.any():
            worst[name] = max(worst.get(name, 0.0), err[m].max())
            rows.append(f"{name}: {m.sum()} (median {np.median(err[m]):.1e}, max {err[m].max():.1e})")
    rows.append(f"{'random' if controller is None else type(controller).__name__}: {q.shape[0]} states, events changed "
                f"under a perturbation at {1 - same.mean():.2%}, undefined at {1 - J.defined.mean():.2%}")
    assert same.mean() > 0.99 and J.defined.mean() > 0.99


@pytest.mark.parametrize("env_id", ["leg_env/PlanarLegBalance-v1", "leg_env/PlanarLegPush-v2", "leg_env/PlanarLegHop-v4"])
def test_hybrid_against_finite_differences_on_rollouts(env_id, capsys):
    rows, worst = [], {}
    for controller in (None, controllers()[env_id]()):
        hybrid_fd_check(env_id, controller, worst, rows)
    with capsys.disabled():
        print(f"\n{env_id}: " + "; ".join(rows))
    assert worst["no event"] <= FD_RTOL
    assert max(v for k, v in worst.items() if k != "no event") <= FD_RTOL_EVENT
    if env_id == "leg_env/PlanarLegHop-v4":  # the hop's cycle: touchdowns with their impacts, and lift-offs
        assert "touchdown" in worst and "liftoff" in worst


def test_hybrid_against_complex_step_through_events():
    """Through slip onset, lift-off (from a slip) and touchdown with its impact, against complex-step
    differentiation of the independent hybrid step of ``derivative_ref.HybridComplexStep``, by the state, the torques,
    the parameters and mu: the touchdowns of a hopper's rollout, and stick starts that break away (and some of them
    then lift off)."""
    from policies.hopper import HopperController

    seen = {}
    q, qd, tau, mode, _, load, p, mu = unilateral_rollout_states("leg_env/PlanarLegHop-v4", HopperController())
    J = dyn.hybrid_step_jacobians(q, qd, tau, p, mu, mode=mode)
    touchdowns = np.flatnonzero((mode == dyn.FLIGHT) & (J.step.event_kind[:, 0] == dyn.TOUCHDOWN) & (J.step.event_kind[:, 1] < 0))
    cases = [(p, mu, q[i], qd[i], tau[i], dyn.FLIGHT) for i in touchdowns[:4]]
    # stick starts under random torques, consistent at the start, that leave the stick within the step
    rng = np.random.default_rng(1)
    p, mu, n = LegParams(), 0.8, 20000
    q_eq, tau_eq, _ = dyn.static_equilibrium(p)
    q = q_eq + np.concatenate([np.zeros((n, 2)), rng.normal(0.0, 0.1, (n, 3))], axis=1)
    q, qd = dyn.project_stance(q, rng.normal(0.0, 4.0, (n, 5)), p, np.zeros(2))
    tau = tau_eq + rng.normal(0.0, 40.0, (n, 2))
    _, lam = dyn.stance_dynamics(q, qd, tau, p)
    consistent = (lam[:, 1] > 0.0) & (np.abs(lam[:, 0]) <= mu * lam[:, 1])
    kinds = dyn.hybrid_step(q, qd, tau, p, mu, mode=np.zeros(n, np.int64)).event_kind
    for seq in ([dyn.SLIP_ONSET], [dyn.SLIP_ONSET, dyn.LIFTOFF]):
        want = np.full(kinds.shape[1], -1)
        want[: len(seq)] = seq
        rows = np.flatnonzero(consistent & (kinds == want).all(axis=1))
        cases += [(p, mu, q[i], qd[i], tau[i], dyn.STICK) for i in rows[:4]]
    refused = 0
    for p_, mu_, q_, qd_, tau_, mode_ in cases:
        ref = HybridComplexStep(p_, mu_)
        try:
            A, B, events = ref.hybrid_jacobians(q_, qd_, tau_, mode_, DT, SUBSTEPS, MAX_ANGLE)
            P, _ = ref.hybrid_param_jacobian(q_, qd_, tau_, mode_, DT, SUBSTEPS, MAX_ANGLE)
        except Refused:  # a step the reference does not write
            refused += 1
            continue
        Jc = dyn.hybrid_step_jacobians(q_, qd_, tau_, p_, mu_, mode=mode_, params=True)
        assert [dyn.EVENT_NAMES[k] for k in Jc.step.event_kind if k >= 0] == events
        err = max(rel(Jc.A, A), rel(Jc.B, B), rel(Jc.P, P))
        assert err <= REF_RTOL_EVENT, (events, err)
        seen[tuple(events)] = seen.get(tuple(events), 0) + 1
    assert refused <= 2
    assert seen.get(("touchdown",), 0) >= 3 and seen.get(("slip_onset",), 0) >= 3 and seen.get(("slip_onset", "liftoff"), 0) >= 2, seen


@pytest.mark.parametrize("env_id", ["leg_env/PlanarLegBalance-v1", "leg_env/PlanarLegPush-v2", "leg_env/PlanarLegHop-v4"])
def test_param_jacobian_against_finite_differences_on_rollouts(env_id, capsys):
    """``P`` (the parameters and mu) against five-point differences of the step in each parameter, over rollout
    states (random actions; the hop: its controller, so that it lands), per kind of event. Changing a length moves the
    foot: for a robot in contact the base follows (y_b, and its velocity) so that the foot stays on the ground and, in
    stick, at rest; that direction is ``P``'s column plus ``A`` times the base's change."""
    import dataclasses

    from leg_env.physics.params import PARAM_NAMES
    from policies.hopper import HopperController

    controller = HopperController() if env_id.endswith("Hop-v4") else None
    q, qd, tau, mode, _, load, p, mu = unilateral_rollout_states(env_id, controller)
    q, qd, tau, mode, load = (a[: HYBRID_ROBOTS * 100] for a in (q, qd, tau, mode, load))
    n = q.shape[0]
    J = dyn.hybrid_step_jacobians(q, qd, tau, p, mu, mode=mode, load_x=load, params=True)
    kinds = J.step.event_kind
    th1 = q[:, 2] + q[:, 3]
    w1 = qd[:, 2] + qd[:, 3]
    angles, rates = (th1, th1 + q[:, 4]), (w1, w1 + qd[:, 4])
    contact = (mode != dyn.FLIGHT) | (dyn.foot_position(q, p)[:, 1] < 1e-5)
    follow = np.zeros((n, NX, 2))  # the base's change per unit of l1, l2
    for c in range(2):
        follow[:, 1, c] = np.where(contact, -np.sin(angles[c]), 0.0)
        follow[:, 6, c] = np.where(contact, -np.cos(angles[c]) * rates[c], 0.0)
        follow[:, 5, c] = np.where(mode == dyn.STICK, np.sin(angles[c]) * rates[c], 0.0)
    predicted = J.P.copy()
    predicted[:, :, 6:8] += J.A @ follow
    same = np.ones(n, bool)
    err = np.full(n, np.inf)
    for scale in (1e-6, 1e-7):
        P = np.empty((n, NX, 12))
        for k in range(12):
            value = getattr(p, PARAM_NAMES[k]) if k < 11 else mu
            eps = scale * max(1.0, abs(value))
            ends = {}
            for m in (-2, -1, 1, 2):
                q_, qd_ = q, qd
                if k in (6, 7):
                    q_, qd_ = q + m * eps * follow[:, :5, k - 6], qd + m * eps * follow[:, 5:, k - 6]
                p_ = dataclasses.replace(p, **{PARAM_NAMES[k]: value + m * eps}) if k < 11 else p
                r = dyn.hybrid_step(q_, qd_, tau, p_, mu + m * eps if k == 11 else mu, mode=mode, load_x=load)
                same &= (r.event_kind == kinds).all(axis=1) & (r.mode == J.step.mode)
                ends[m] = np.concatenate([r.q, r.qd], axis=1)
            P[:, :, k] = (8.0 * (ends[1] - ends[-1]) - (ends[2] - ends[-2])) / (12.0 * eps)
        err = np.minimum(err, rel(predicted, P))
    checked = same & J.defined
    first = np.where(kinds[:, 0] < 0, -1, kinds[:, 0])
    rows, worst = [], {}
    for kind, name in [(-1, "no event"), *enumerate(dyn.EVENT_NAMES)]:
        m = checked & (first == kind)
        if m.any():
            worst[name] = err[m].max()
            rows.append(f"{name}: {m.sum()} (median {np.median(err[m]):.1e}, max {err[m].max():.1e})")
    with capsys.disabled():
        print(f"\n{env_id}, P: " + "; ".join(rows) + f"; events changed under a perturbation at {1 - same.mean():.2%}")
    assert same.mean() > 0.99
    assert worst["no event"] <= FD_RTOL
    assert max(v for k, v in worst.items() if k != "no event") <= FD_RTOL_EVENT
    assert "touchdown" in worst


def test_no_derivative_is_flagged_not_given():
    """Past the Painleve bound (a foot sliding where no contact force is consistent, the worst posture of
    ``tests/test_unilateral.py``) the step is not a smooth map: flagged, A and B NaN. Below the bound (mu 0.3) the same
    slide gets its derivative."""
    from leg_env.physics.derivatives import PAINLEVE

    p = LegParams()
    q = np.array([0.0, 0.0, -0.45, -0.925, 0.05])
    q[1] -= dyn.foot_position(q, p)[1]
    lam_c, _ = dyn.free_foot_acceleration(q, np.zeros(5), np.zeros(2), p)
    sigma = np.sign(lam_c[0, 1])
    qd = np.linalg.lstsq(dyn.contact_jacobian(q, p), np.array([0.3 * sigma, 0.0]), rcond=None)[0]
    tau = np.array([0.0, -20.0])
    J = dyn.hybrid_step_jacobians(np.stack([q, q]), np.stack([qd, qd]), np.stack([tau, tau]), p, np.array([0.9, 0.3]))
    assert J.step.painleve[0] >= 1 and J.step.painleve[1] == 0
    assert J.undefined[0] & PAINLEVE and not J.defined[0] and np.isnan(J.A[0]).all() and np.isnan(J.B[0]).all()
    assert J.defined[1] and np.isfinite(J.A[1]).all() and np.isfinite(J.B[1]).all()


# ------------------------------------------------------------------ 3. identities


@pytest.mark.parametrize("stance", [True, False], ids=["pinned", "flight"])
def test_moving_the_whole_robot_moves_the_next_state(stance):
    """Translation invariance: with the anchor following q, d(next)/d(x_b) = e_x_b and d(next)/d(y_b) = e_y_b."""
    rng = np.random.default_rng(3)
    p = random_params(rng)
    q, qd, tau = random_batch(p, rng, stance, 64)
    J = (stance_step_jacobians if stance else flight_step_jacobians)(q, qd, tau, p)
    for j in (0, 1):
        np.testing.assert_allclose(J.A[:, :, j], np.broadcast_to(np.eye(NX)[j], (64, NX)), atol=1e-12)


def test_a_held_anchor_forgets_the_base():
    """With the anchor held, the projection sets the base from the leg: the base's position and velocity before the
    step have no effect (their columns of A are zero), and the foot after the step stays on the anchor to first order."""
    rng = np.random.default_rng(4)
    p = random_params(rng)
    q, qd, tau = random_batch(p, rng, True, 64)
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
    for bad in ("q", "qd", "tau"):
        args = {"q": q.copy(), "qd": qd.copy(), "tau": tau.copy()}
        args[bad][0] = np.nan
        with pytest.raises(ValueError, match=f"{bad} must be finite"):
            stance_step_jacobians(args["q"], args["qd"], args["tau"], p)
        with pytest.raises(ValueError, match=f"{bad} must be finite"):
            dyn.hybrid_step_jacobians(args["q"], args["qd"], args["tau"], p, 0.8)
    with pytest.raises(ValueError, match="mu"):
        dyn.hybrid_step_jacobians(q, qd, tau, p, -1.0)


# ------------------------------------------------------------------ the vector env's Jacobians


@pytest.mark.parametrize("env_id, kwargs", [
    ("leg_env/PlanarLegStance-v0", {}),
    ("leg_env/PlanarLegHop-v4", {}),
    ("leg_env/PlanarLegBalance-v1", {"motor_speed": 20.0}),
    ("leg_env/PlanarLegPush-v2", {"randomize": True}),
], ids=["pinned", "hop", "balance-motor", "push-randomized"])
def test_env_jacobians_against_differences_of_its_steps(env_id, kwargs):
    """``envs.unwrapped.jacobians(actions)`` against centred differences of the env's own steps (copies of it):
    ``B`` in action units (the torque limit, the motor model, a robot of its own per row), and ``A``'s columns of the
    joint rates, through which the motor model's torque falls with speed. An action beyond its bound has no effect."""
    import copy

    n, eps = 32, 1e-6
    envs = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
    envs.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(30):
        envs.step(rng.uniform(-1.0, 1.0, (n, 2)))
    actions = rng.uniform(-0.9, 0.9, (n, 2))
    actions[0, 0] = 1.5
    before = envs.unwrapped.state
    A, B = envs.unwrapped.jacobians(actions)
    np.testing.assert_array_equal(envs.unwrapped.state[0], before[0])  # nothing stepped

    def stepped(change):
        e = copy.deepcopy(envs)
        a = change(e, actions.copy())
        e.step(a)
        q, qd, _ = e.unwrapped.state
        return np.concatenate([q, qd], axis=1), e.unwrapped.elapsed_steps > 0

    def column(change_plus, change_minus):
        (yp, ok_p), (ym, ok_m) = stepped(change_plus), stepped(change_minus)
        return (yp - ym) / (2 * eps), ok_p & ok_m

    B_fd, A_fd, ok = np.empty_like(B), np.empty((n, NX, 2)), np.ones(n, bool)
    q, _, _ = envs.unwrapped.state
    Jc = dyn.contact_jacobian(q, envs.unwrapped.params)
    direction = np.zeros((n, NX, 2))  # along q1' (q2'), the base's velocity taking up the foot's change
    for j in range(2):
        direction[:, 8 + j, j] = 1.0
        direction[:, 5:7, j] = -Jc[:, :, 3 + j]
    for j in range(2):
        def shift(d, j=j):
            def change(e, a):
                a[:, j] += d
                return a
            return change

        def rate(d, j=j):
            def change(e, a):  # the joint's rate, the base's velocity keeping the foot's (on the contact's manifold)
                e.unwrapped._state["qd"] += d * direction[:, 5:, j]
                return a
            return change

        B_fd[:, :, j], ok_b = column(shift(eps), shift(-eps))
        A_fd[:, :, j], ok_a = column(rate(eps), rate(-eps))
        ok &= ok_a & ok_b
    ok &= np.isfinite(B).all(axis=(1, 2))
    assert ok.sum() >= n - 8
    assert rel(B, B_fd)[ok].max() <= 1e-5
    assert rel(A @ direction, A_fd)[ok].max() <= 1e-5
    np.testing.assert_array_equal(B[0, :, 0], 0.0)


# ------------------------------------------------------------------ torch


def test_torch_rollout_gradients_are_the_jacobians():
    """A differentiable rollout of hops (leg_env.autograd): its gradient is the product of the steps'
    Jacobians, checked by torch's own gradcheck on one step and by the chain of A, B over a rollout through events."""
    import torch

    from leg_env import autograd

    p, mu = LegParams(), 0.8
    q_eq, tau_eq, _ = dyn.static_equilibrium(p)
    n, T = 8, 40
    rng = np.random.default_rng(0)
    q = np.tile(q_eq, (n, 1))
    q[:, 1] += rng.uniform(0.005, 0.02, n)  # dropped from a little height: each rollout lands
    x0 = torch.tensor(np.concatenate([q, np.zeros((n, 5))], axis=1), requires_grad=True)
    taus = torch.tensor(np.tile(tau_eq, (T, n, 1)) + rng.normal(0.0, 3.0, (T, n, 2)), requires_grad=True)
    x, mode, anchor, events = x0, None, None, 0
    chain = np.tile(np.eye(NX), (n, 1, 1))
    for t in range(T):
        J = dyn.hybrid_step_jacobians(x.detach().numpy()[:, :5], x.detach().numpy()[:, 5:], taus[t].detach().numpy(), p, mu,
                                      mode=mode, anchor_x=anchor)
        chain = J.A @ chain
        x, step = autograd.hybrid_step(x, taus[t], p, mu, mode=mode, anchor_x=anchor)
        mode, anchor, events = step.mode, step.anchor_x, events + int(step.events.sum())
    assert events >= n  # every robot landed
    weights = torch.tensor(rng.normal(size=(n, NX)))
    (x * weights).sum().backward()
    expected = np.einsum("ni,nij->nj", weights.numpy(), chain)
    np.testing.assert_allclose(x0.grad.numpy(), expected, rtol=1e-10, atol=1e-12)
    assert taus.grad.abs().sum() > 0
    # torch's gradcheck of one pinned step (its own finite differences)
    q1, qd1 = dyn.project_stance(q_eq + np.r_[0, 0, rng.normal(0, 0.05, 3)], rng.normal(0, 0.3, 5), p, np.zeros(2))
    x1 = torch.tensor(np.concatenate([q1, qd1])[None], requires_grad=True)
    tau1 = torch.tensor(tau_eq[None], requires_grad=True)
    assert torch.autograd.gradcheck(lambda a, b: autograd.stance_step(a, b, p)[0], (x1, tau1), eps=1e-6, atol=1e-5)
    with pytest.raises(ValueError, match="float64"):
        autograd.hybrid_step(x0.float(), taus[0].float(), p, mu)
