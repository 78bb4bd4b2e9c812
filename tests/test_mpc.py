"""``policies.mpc.HopMPC``: its model is the env's step, its backward pass differentiates the closed loop it rolls
out, and without iterations it is the hopper it starts from."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import leg_env  # noqa: F401  (registers the tasks)
from ilqr_checks import checked_backward, checked_gradients
from ilqr_ref import clocks, gains
from policies.ilqr import PilotILQR
from policies.hopper import HopperController
from policies.mpc import HopMPC
from train.policy_loading import load_policy

HOP = "leg_env/PlanarLegHop-v4"


def _envs(n, seed=60000):
    envs = gym.make_vec(HOP, num_envs=n, vectorization_mode="vector_entry_point")
    obs, _ = envs.reset(seed=seed)
    return envs, obs


def test_the_plan_predicts_the_env():
    """The plan's first state after the step is the env's next state (the observation's float32 aside): the
    controller's model is the env's own step, through touchdowns and lift-offs."""
    envs, obs = _envs(3)
    e = envs.unwrapped
    mpc = HopMPC(e.params, e.config, horizon=12)
    modes = set()
    for _ in range(100):
        action, _ = mpc.predict(obs)
        predicted = mpc.planned[:, 1].copy()
        obs, _, terminated, _, info = envs.step(action)
        assert not terminated.any()
        q, qd, mode = mpc.state(obs)
        modes.update(info["contact_mode"])
        # the observation's frame: the base relative to its contact point (translation along the ground is free)
        got = np.concatenate([q, qd], axis=1)
        np.testing.assert_allclose(got[:, 1:], predicted[:, 1:], atol=2e-5)
    assert {"stick", "flight"} <= modes  # the check went through lift-offs and touchdowns


def test_backward_pass_differentiates_the_closed_loop():
    """The chain of the closed loop's ``A`` and ``B`` (the step's Jacobians with the hopper's feedback) gives the
    plan cost's gradient by the corrections that centred differences of the rolled-out cost give."""
    envs, obs = _envs(4)
    e = envs.unwrapped
    mpc = HopMPC(e.params, e.config, horizon=40, steps=(), stance_cost=0.0, fall_cost=0.0, power_weight=1e-4,
                 clip_smoothing=0.0)  # the clip's own derivative: the chain is the rolled-out cost's exact gradient
    for _ in range(25):  # into the first stance's push
        action, _ = mpc.predict(obs)
        obs, *_ = envs.step(action)
    q, qd, mode = mpc.state(obs)
    batch = np.asarray(obs, dtype=np.float64)
    like = batch[:, :22]
    target = mpc.y_stand + batch[:, 18]
    x_ref = mpc.com(np.concatenate([q, qd], axis=1))[0] - batch[:, 19]
    ground = batch[:, 20]
    ctx = dict(like=like, target=target, x_ref=x_ref, ground=ground)
    assert checked_backward(mpc, mpc._pilot, q, qd, mode, ctx) < 1e-10  # the compiled pass is the numpy one
    checked = checked_gradients(mpc, mpc._pilot, q, qd, mode, ctx)
    assert checked >= 24  # most robots, every step checked with the same events at both sides


def test_the_compiled_backward_pass_on_random_plans():
    """``kernels.ilqr_backward`` (``PilotILQR._gains``) is the numpy pass (``tests/ilqr_ref.py``) on random plans with
    every residual of the action active (the power charged, the clip's derivative between 0 and 1) and joints whose
    authority differs by a factor of 30, so that either row of ``Q_vv`` pivots its solve."""
    mpc = HopMPC(power_weight=1e-3, effort_weight=0.05, regularisation=1e-3, smooth_weight=0.01)
    rng = np.random.default_rng(3)
    n, H = 64, 12
    roll = dict(A=np.eye(10) + 0.3 * rng.standard_normal((n, H, 10, 10)),
                B=rng.standard_normal((n, H, 10, 2)) * np.where(rng.random((n, 1, 1, 2)) < 0.5, [1.0, 30.0], [30.0, 1.0]),
                D=rng.uniform(0.0, 1.0, (n, H, 2)), Du=rng.standard_normal((n, H, 2, 10)),
                X=rng.standard_normal((n, H + 1, 10)), U=rng.uniform(-1.0, 1.0, (n, H, 2)), V=0.1 * rng.standard_normal((n, H, 2)))
    Jr, r = rng.standard_normal((n, H, 7, 10)), rng.standard_normal((n, H, 7))
    lx, lxx = np.einsum("nhri,nhr->nhi", Jr, r), np.einsum("nhri,nhrj->nhij", Jr, Jr)
    # at the last step Q_vv = B^T l_xx B + J_v^T J_v + (w_s + regularisation) I: either row's pivot is the larger
    Quu = np.swapaxes(roll["B"][:, -1], 1, 2) @ lxx[:, -1] @ roll["B"][:, -1]
    swapped = np.abs(Quu[:, 1, 0]) > np.abs(Quu[:, 0, 0])
    assert 0 < swapped.sum() < n
    k, K = mpc._gains(roll, lx, lxx)
    k_ref, K_ref = gains(mpc, roll, lx, lxx)
    np.testing.assert_allclose(k, k_ref, rtol=1e-9, atol=1e-9 * np.abs(k_ref).max())
    np.testing.assert_allclose(K, K_ref, rtol=1e-9, atol=1e-9 * np.abs(K_ref).max())


def _context(mpc, obs):
    """The plan's start and context at observations ``obs``, as ``HopMPC.exact_actions`` makes them."""
    q, qd, mode = mpc.state(obs)
    batch = np.asarray(obs, dtype=np.float64)
    x_ref = mpc.com(np.concatenate([q, qd], axis=1))[0] - batch[:, 19]
    return q, qd, mode, dict(like=batch[:, :22], target=mpc.y_stand + batch[:, 18], x_ref=x_ref, ground=batch[:, 20])


def test_the_compiled_plan_is_the_numpy_rollout():
    """``HopMPC._rollout`` (``kernels.hop_rollout``: the hopper's law, its derivative and the step in one call) makes
    the plans ``PilotILQR._rollout`` makes in numpy around the same hopper: the same states, modes, actions and clocks
    to the bit, the closed loop's Jacobians to rounding; with the line search's feedback, to rounding. At states along
    hopping episodes in every phase, with the plans of several robots in one call and tiled as the line search tiles
    them; the clocks are those counted step by step."""
    n = 4
    envs, obs = _envs(n, seed=2025)
    e = envs.unwrapped
    mpc = HopMPC(e.params, e.config, horizon=40)
    rng = np.random.default_rng(0)
    phases, modes = set(), set()
    for step in range(90):
        action, _ = mpc.predict(obs)
        obs, *_ = envs.step(action)
        if step % 6:
            continue
        q, qd, mode, ctx = _context(mpc, obs)
        phases.update(mpc._pilot._phase.tolist())
        V = 0.1 * rng.standard_normal((n, mpc.horizon, 2))
        for jacobians in (True, False):
            got = mpc._rollout(mpc._pilot, q, qd, mode, ctx, V, jacobians=jacobians)
            want = PilotILQR._rollout(mpc, mpc._pilot, q, qd, mode, ctx, V, jacobians=jacobians)
            assert set(got) == set(want)
            for name in ("X", "modes", "U", "V", "flight_time", "ground", "stance"):
                np.testing.assert_array_equal(got[name], want[name], err_msg=name)
            for name in ("A", "B", "Du", "D") if jacobians else ():
                np.testing.assert_allclose(got[name], want[name], rtol=1e-12, atol=1e-12 * np.abs(want[name]).max(), err_msg=name)
            modes.update(got["modes"].ravel().tolist())
            counted = clocks(e.config.min_flight, e.config.dt, got["modes"], got["flight_time"], ctx["ground"])
            np.testing.assert_array_equal(got["ground"], counted[0])
            np.testing.assert_array_equal(got["stance"], counted[1])
        # the line search's plans: two step lengths' copies, feedback about a nominal plan
        k, K = 0.05 * rng.standard_normal((2 * n, mpc.horizon, 2)), 0.5 * rng.standard_normal((2 * n, mpc.horizon, 2, 10))
        nominal = np.tile(want["X"], (2, 1, 1)) + 1e-3 * rng.standard_normal((2 * n, mpc.horizon + 1, 10))
        tiled = {name: np.tile(value, (2,) + (1,) * (value.ndim - 1)) for name, value in ctx.items()}
        args = (np.tile(q, (2, 1)), np.tile(qd, (2, 1)), np.tile(mode, 2), tiled, np.tile(V, (2, 1, 1)))
        got = mpc._rollout(mpc._pilot, *args, nominal=nominal, k=k, K=K, copies=2)
        want = PilotILQR._rollout(mpc, mpc._pilot, *args, nominal=nominal, k=k, K=K, copies=2)
        np.testing.assert_array_equal(got["modes"], want["modes"])
        np.testing.assert_allclose(got["X"], want["X"], rtol=0.0, atol=1e-9)
        np.testing.assert_allclose(got["U"], want["U"], rtol=0.0, atol=1e-9)
    envs.close()
    assert phases == {0, 1, 2} and {0, 3} <= modes  # crouch, push, release; stick and flight


def test_the_plans_clocks_are_counted_step_by_step():
    """``HopMPC._track``'s clocks (time on the ground since the last hop, time in the current stance), vectorised over
    the plan, are the clocks counted step by step (``tests/ilqr_ref.py``), to the bit, on random sequences of stance
    and flight with partial flights (and on hopping robots' plans: ``test_the_compiled_plan_is_the_numpy_rollout``)."""
    mpc = HopMPC()
    c = mpc.config
    rng = np.random.default_rng(1)
    for _ in range(300):
        n, H = 3, 50
        modes = np.repeat(np.where(rng.random((n, H // 5 + 1)) < 0.5, 3, rng.integers(0, 3, (n, H // 5 + 1))), 5, axis=1)[:, :H + 1]
        flight_time = np.where(modes[:, 1:] == 3, np.where(rng.random((n, H)) < 0.7, c.dt, c.dt * rng.random((n, H))),
                               c.dt * rng.random((n, H)) * (rng.random((n, H)) < 0.2))
        ground = rng.uniform(0.0, 0.5, n)
        roll = dict(modes=modes, flight_time=flight_time)
        mpc._track(roll, dict(ground=ground))
        want = clocks(c.min_flight, c.dt, modes, flight_time, ground)
        np.testing.assert_array_equal(roll["ground"], want[0])
        np.testing.assert_array_equal(roll["stance"], want[1])


def test_the_clip_derivative_fades_to_zero_at_the_limit():
    """The backward pass's clip derivative: 1 inside ``1 - w``, 0 at the limit and beyond, a continuously
    differentiable smoothstep between; the clip's own 0 or 1 with ``clip_smoothing=0``."""
    mpc, hard = HopMPC(clip_smoothing=0.05), HopMPC(clip_smoothing=0.0)
    z = np.linspace(-1.2, 1.2, 24001)
    D = mpc.clip_derivative(z)
    assert np.all(D[np.abs(z) <= 0.95] == 1.0) and np.all(D[np.abs(z) >= 1.0] == 0.0)
    assert np.all((D >= 0.0) & (D <= 1.0)) and np.max(np.abs(np.diff(D))) < 1e-2  # continuous
    slope = np.diff(D) / np.diff(z)
    assert np.max(np.abs(np.diff(slope))) < 1.0  # and its derivative too (its largest slope 30, steps of 1e-4)
    assert np.array_equal(hard.clip_derivative(z), (np.abs(z) < 1.0).astype(float))


@pytest.mark.parametrize("smooth", [True, False])
def test_the_law_is_continuous_where_the_push_saturates(smooth):
    """The hopper's push scales its torques onto the limit, so the clip's derivative at those plan steps is 0 or 1 by
    a rounding: with the clip's own derivative and differences of the hopper at 1e-6 the MPC's law jumps under
    perturbations of the state of 1e-6 at nearly every step of the push (its one-sided difference quotients
    disagree: the gains change with the perturbation); with the defaults at most at the steps where a phase switch
    of the hopper inside the plan moves by a plan step (one of these ten)."""
    from train.stability import HopLoop

    settings = None if smooth else dict(clip_smoothing=0.0, law_step=1e-6)
    loop = HopLoop("mpc", 0.12, None, settings)
    z, d = loop.start(0)
    jumps = 0
    for k in range(65):
        if k >= 46 and k % 2 == 0:  # the first push (after the dwell), ten steps (a knee at its limit in every plan)
            held = loop.jumps
            loop.jacobian(z, d)
            jumps += loop.jumps > held
        z, d, _, _ = loop.step(z, d)
    assert (jumps <= 2) if smooth else (jumps >= 8)


def test_without_iterations_it_is_the_hopper():
    """No line-search step: the plan is its hopper's own closed loop, so the actions are that hopper's (the MPC reads
    the COM's drift from the model where the hopper dead-reckons it)."""
    envs, obs = _envs(4)
    e = envs.unwrapped
    mpc = HopMPC(e.params, e.config, horizon=4, steps=())
    hopper = HopperController(e.params, e.config, **mpc.hopper_settings)
    for _ in range(80):
        a, _ = mpc.predict(obs)
        b, _ = hopper.predict(obs)
        np.testing.assert_allclose(a, b, atol=2e-3)
        obs, *_ = envs.step(b)


def test_replans_every_few_steps_and_follows_the_plan_between():
    """With ``replan_every=8`` each robot plans at every eighth control step and in between follows the held plan:
    its state stays on the plan's states (the observation's float32 aside); a contact mode other than the plan's
    makes that robot plan at once."""
    envs, obs = _envs(3)
    e = envs.unwrapped
    mpc = HopMPC(e.params, e.config, replan_every=8)
    for t in range(40):
        action, _ = mpc.predict(obs)
        assert np.all(mpc._since == t % 8)
        if t % 8:
            q, qd, _ = mpc.state(obs)
            held = mpc._held["X"][:, t % 8]
            np.testing.assert_allclose(np.concatenate([q, qd], axis=1)[:, 1:], held[:, 1:], atol=2e-4)
        obs, *_ = envs.step(action)
    assert mpc._since[0] == 7  # the next call plans
    obs = obs.copy()
    mpc._since[:] = 2  # mid-plan; robot 0's contact flag (the plan's stance) flipped
    planned_mode = mpc._held["modes"][:, 3].copy()
    obs[0, 15] = 1.0 - obs[0, 15]
    mpc.predict(obs)
    assert mpc._since[0] == 0 and np.all(mpc._since[1:] == 3), (mpc._since, planned_mode)
    with pytest.raises(ValueError, match="replan_every"):
        HopMPC(horizon=10, replan_every=11)


def test_loads_by_name_and_checks_its_input():
    policy = load_policy("mpc", env_id=HOP)
    assert isinstance(policy, HopMPC)
    envs, obs = _envs(2)
    policy.horizon = 5
    policy.reset()
    action, _ = policy.predict(obs)
    assert action.shape == (2, 2) and action.dtype == np.float32 and np.all(np.abs(action) <= 1.0)
    with pytest.raises(ValueError, match="observation must have shape"):
        policy.predict(obs[:, :20])
    with pytest.raises(ValueError, match="horizon"):
        HopMPC(horizon=1)
    with pytest.raises(ValueError, match="apex_scale"):
        HopMPC(apex_scale=0.0)
    with pytest.raises(ValueError, match="charge_apex"):
        HopMPC(charge_apex="apex")
    with pytest.raises(ValueError, match="clip_smoothing"):
        HopMPC(clip_smoothing=-0.1)
    with pytest.raises(ValueError, match="law_step"):
        HopMPC(law_step=float("nan"))
    with pytest.raises(TypeError):
        HopMPC(horizon_steps=10)
    bad = obs.copy()
    bad[0, 3] = np.nan
    plan = policy._plan.copy()
    with pytest.raises(ValueError, match="observation must be finite: rows \\[0\\]"):
        policy.predict(bad)
    np.testing.assert_array_equal(policy._plan, plan)  # nothing changed


def test_wild_states_give_bounded_actions():
    """Far from any gait (tilted, fast, in the air or not), the plans stay finite and the actions within their bounds."""
    envs, obs = _envs(4, seed=1)
    e = envs.unwrapped
    mpc = HopMPC(e.params, e.config)
    rng = np.random.default_rng(0)
    for _ in range(8):
        wild = obs.copy()
        wild[:, 1] = rng.uniform(0.2, 1.2, 4)  # the base's height
        wild[:, 2] += rng.uniform(-1.5, 1.5, 4)  # the torso's tilt
        wild[:, 5:10] += rng.normal(0.0, 30.0, (4, 5))  # the rates
        wild[:, 15] = rng.integers(0, 2, 4)  # the contact flag
        action, _ = mpc.predict(wild)
        assert np.isfinite(action).all() and np.abs(action).max() <= 1.0
        assert np.isfinite(mpc.planned).all()
