"""System identification (leg_env.identify) on recorded hopping of randomised robots.

The recording is the hop task's own (``PlanarLegHop-v4`` with ``randomize=True`` under the hopper controller): the
state at every control step, the torques held over each step and the contact modes. The fit starts from the nominal
robot (its lengths and gravity replaced by the true ones, which ``fit`` takes as known).
"""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

from leg_env import physics as dyn
from leg_env import identify
from leg_env.identify import BASE_NAMES, base_parameters, cramer_rao, fit
from leg_env.physics.params import PARAM_NAMES, LegParams

STEPS = 500  # 5 s
ROBOTS = 3
NOISE = (1e-3, 1e-3, 0.01, 0.01, 0.01, 0.01, 0.01, 0.1, 0.1, 0.1)  # a robot's sensors: 1 mm, 0.01 rad, 0.01 m/s, 0.1 rad/s


def recordings(n_robots: int, seed: int = 11):
    """(truth, mu, q, qd, tau, modes) of the first robots that hop STEPS steps without falling."""
    from policies.hopper import HopperController

    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=4 * n_robots, vectorization_mode="vector_entry_point", randomize=True)
    obs, _ = envs.reset(seed=seed)
    env, controller = envs.unwrapped, HopperController()
    robots = env._robots.copy()  # drawn at the reset; a robot that falls is redrawn, so only the survivors count
    q, qd, tau, modes, ended = [], [], [], [], []
    for _ in range(STEPS + 1):
        state = env.state
        q.append(state[0])
        qd.append(state[1])
        modes.append(env.contact_mode)
        obs, _, terminated, truncated, info = envs.step(controller.predict(obs, deterministic=True)[0])
        tau.append(info["torque"].copy())
        ended.append(terminated | truncated)
    envs.close()
    q, qd, tau, modes, ended = map(np.array, (q, qd, tau, modes, ended))
    out = []
    for i in np.flatnonzero(~ended[:-1].any(axis=0))[:n_robots]:
        truth = LegParams(**{k: float(robots[i]["p"][k]) for k in PARAM_NAMES})
        out.append((truth, float(robots[i]["mu"]), q[:, i], qd[:, i], tau[:-1, i], modes[:, i]))
    assert len(out) == n_robots
    return out


def prior(truth: LegParams) -> LegParams:
    return LegParams(l1=truth.l1, l2=truth.l2, g=truth.g)


def test_base_parameters_leave_the_motion_unchanged():
    """The fact the fit rests on: two robots with the same base parameters (m, a, b, J1, J2, I_b) move alike under
    the same torques, though their masses, COMs and inertias differ."""
    rng = np.random.default_rng(0)
    p = LegParams()
    # move m1 and c1 keeping a = m1 c1 + m2 l1, m = m_b + m1 + m2 and J1 = I1 + m1 c1^2 + m2 l1^2
    m1 = p.m1 * 1.2
    c1 = p.m1 * p.c1 / m1
    other = dataclasses.replace(p, m1=m1, c1=c1, m_b=p.m_b - (m1 - p.m1), I1=p.I1 + p.m1 * p.c1**2 - m1 * c1**2)
    np.testing.assert_allclose(base_parameters(other, 0.5), base_parameters(p, 0.5), rtol=1e-14)
    q_eq, tau_eq, _ = dyn.static_equilibrium(p)
    q = np.tile(q_eq, (64, 1)) + np.concatenate([np.zeros((64, 2)), rng.normal(0, 0.1, (64, 3))], axis=1)
    q[:, 1] += rng.uniform(0.0, 0.05, 64) - dyn.foot_position(q, p)[:, 1]  # the feet up to 5 cm above the ground
    qd = rng.normal(0.0, 1.0, (64, 5))
    tau = tau_eq + rng.normal(0.0, 10.0, (64, 2))
    a = dyn.hybrid_step(q, qd, tau, p, 0.5, mode=dyn.FLIGHT)
    b = dyn.hybrid_step(q, qd, tau, other, 0.5, mode=dyn.FLIGHT)
    assert (a.events > 0).any()  # some land within the step: the contact too
    np.testing.assert_allclose(np.concatenate([b.q, b.qd], axis=1), np.concatenate([a.q, a.qd], axis=1), atol=1e-10)


def test_clean_recordings_give_the_base_parameters_exactly():
    for truth, mu, q, qd, tau, modes in recordings(ROBOTS):
        result = fit(q, qd, tau, 0.01, prior(truth), 0.5, modes, noise=NOISE)
        true_base = base_parameters(truth, mu)
        assert result.identifiable[:6].all()
        np.testing.assert_allclose(result.base[:6], true_base[:6], rtol=1e-6, err_msg=str(BASE_NAMES))
        # the raw masses, COMs and inertias are not all determined: the regressor has a null space among them
        assert result.rank <= len(result.fitted) - 2


def noisy(q, qd, rng):
    noise = np.asarray(NOISE)
    return q + rng.normal(0.0, 1.0, q.shape) * noise[:5], qd + rng.normal(0.0, 1.0, qd.shape) * noise[5:]


def test_noisy_recordings_are_fitted_within_their_standard_errors():
    """With a robot's sensor noise (NOISE) every base parameter lands within four standard errors of the truth and within
    2% of it, the standard errors are small (the total mass and the leg's moment and inertia to 0.3%, the shank's and
    the torso's to 1%), equal to the Cramer-Rao bound of the recording, and the residual is the noise."""
    rng = np.random.default_rng(5)
    for truth, mu, q, qd, tau, modes in recordings(ROBOTS, seed=12):
        qn, qdn = noisy(q, qd, rng)
        result = fit(qn, qdn, tau, 0.01, prior(truth), 0.5, modes, noise=NOISE)
        true_base = base_parameters(truth, mu)
        err = np.abs(result.base - true_base)[:6]
        assert result.identifiable[:6].all()
        assert np.all(err <= 4.0 * result.base_std[:6]), (err / true_base[:6], result.base_std[:6] / true_base[:6])
        assert np.all(err <= 0.02 * true_base[:6]), err / true_base[:6]
        assert np.all(result.base_std[[0, 1, 3]] <= 0.003 * true_base[[0, 1, 3]])
        assert np.all(result.base_std[[2, 4, 5]] <= 0.01 * true_base[[2, 4, 5]])
        bound = cramer_rao(q, qd, tau, 0.01, truth, mu, modes, noise=NOISE)
        np.testing.assert_allclose(result.base_std[:6], bound[:6], rtol=0.35)
        assert 0.9 < result.rms < 1.1
        if result.identifiable[6]:  # mu: only where it is known to 2%
            assert abs(result.mu - mu) <= 4.0 * result.base_std[6]


def test_joined_windows_beat_independent_ones():
    """The noisy first state of every window taken as unknown and fitted on its own (junction=None) costs the shank's
    parameters most of their precision: joined into one motion, their standard errors fall by a factor of three or
    more, and so does the Cramer-Rao bound."""
    rng = np.random.default_rng(6)
    truth, mu, q, qd, tau, modes = recordings(1, seed=12)[0]
    qn, qdn = noisy(q, qd, rng)
    joined = fit(qn, qdn, tau, 0.01, prior(truth), 0.5, modes, noise=NOISE)
    independent = fit(qn, qdn, tau, 0.01, prior(truth), 0.5, modes, noise=NOISE, junction=None)
    assert np.all(independent.base_std[[2, 4]] >= 3.0 * joined.base_std[[2, 4]])
    free_bound = cramer_rao(q, qd, tau, 0.01, truth, mu, modes, noise=NOISE, junction=None)
    bound = cramer_rao(q, qd, tau, 0.01, truth, mu, modes, noise=NOISE)
    assert np.all(free_bound[[2, 4]] >= 3.0 * bound[[2, 4]])


def test_friction_only_where_the_recording_slides():
    """A recording that never slides determines no mu: it is not fitted, and reported not identifiable; one that slides
    fits it exactly without noise."""
    rng = np.random.default_rng(7)
    for truth, mu, q, qd, tau, modes in recordings(ROBOTS):
        slides = np.isin(modes, (dyn.SLIP_FORWARD, dyn.SLIP_BACKWARD)).any()
        result = fit(*noisy(q, qd, rng), tau, 0.01, prior(truth), 0.5, modes, noise=NOISE)
        if not slides:
            assert "mu" not in result.fitted and not result.identifiable[6] and np.isinf(result.base_std[6])
            assert result.mu == 0.5
            assert np.isinf(cramer_rao(q, qd, tau, 0.01, truth, mu, modes, noise=NOISE)[6])
            with pytest.raises(ValueError, match="fitted"):
                fit(q, qd, tau, 0.01, prior(truth), 0.5, modes, fitted=("mu",))
        else:
            clean = fit(q, qd, tau, 0.01, prior(truth), 0.5, modes, noise=NOISE)
            assert clean.identifiable[6]
            assert abs(clean.mu - mu) <= 1e-6 * mu


def _problem(junction):
    """A joined problem on the first 60 steps of a recording (a flight, a touchdown and a stance) at parameters off the
    truth: its residual and Jacobians."""
    truth, mu, q, qd, tau, modes = recordings(1)[0]
    rec = identify._recording(q[:61], qd[:61], tau[:60], 0.01, truth, modes[:61], NOISE, 20, identify.FITTED, junction)
    columns = [identify._COLUMN[name] for name in identify.FITTED]
    theta = np.concatenate([truth.array, [mu]])
    theta[columns] *= 1.0 + 0.02 * np.sin(np.arange(len(columns)))
    scale = np.abs(theta[columns])
    problem = rec.problem(columns, scale, truth, 20, junction, dyn.SUBSTEPS, dyn.MAX_ANGLE)
    return problem, theta, problem.frames.z0 + 1e-4 * np.cos(np.arange(problem.frames.z0.size))


def test_joined_jacobians_match_finite_differences():
    """The residual's Jacobians by the windows' start states and by the parameters, the junctions' among them, against
    centred differences of the residual itself."""
    problem, theta, z = _problem(1e-3)
    r, Jz, Jp, (rc, a, b, c) = problem.system(theta, z)
    assert len(problem.starts) >= 3 and (problem.frames.modes == dyn.FLIGHT).any() and (problem.frames.modes != dyn.FLIGHT).any()
    W, sizes, offset = len(problem.starts), problem.frames.size, problem.frames.offset

    def residual(theta_, z_):
        r_, _, _, (rc_, _, _, _) = problem.system(theta_, z_)
        return r_, rc_

    for j, column in enumerate(problem.columns):  # the parameters, in scaled units
        h = 1e-6
        up, down = theta.copy(), theta.copy()
        up[column] += h * problem.scale[j]
        down[column] -= h * problem.scale[j]
        (ru, rcu), (rd, rcd) = residual(up, z), residual(down, z)
        # the residual is measured minus simulated: its derivative is minus the Jacobian
        np.testing.assert_allclose(-(ru - rd) / (2 * h), Jp[..., j], rtol=1e-4, atol=1e-4 * np.abs(Jp[..., j]).max())
        np.testing.assert_allclose(-(rcu - rcd) / (2 * h), c[..., j], rtol=1e-4, atol=1e-4 * np.abs(c[..., j]).max())
    for w in range(W):  # every start state's entries
        for i in range(sizes[w]):
            h = 1e-7
            up, down = z.copy(), z.copy()
            up[offset[w] + i] += h
            down[offset[w] + i] -= h
            (ru, rcu), (rd, rcd) = residual(theta, up), residual(theta, down)
            np.testing.assert_allclose(-(ru[w] - rd[w]) / (2 * h), Jz[w, :, i], rtol=1e-4, atol=1e-4 * max(np.abs(Jz[w, :, i]).max(), 1.0))
            d_rc = -(rcu - rcd) / (2 * h)
            expect = np.zeros_like(rc)
            if w < W - 1:
                expect[w] += a[w][:, i]
            if w > 0:
                expect[w - 1] += b[w - 1][:, i]
            np.testing.assert_allclose(d_rc, expect, rtol=1e-4, atol=1e-4 * max(np.abs(expect).max(), 1.0))


def test_the_eliminations_agree_with_the_dense_normal_equations():
    """The block-tridiagonal elimination of the start states and the orthogonal factor of the information equal the
    dense normal equations' Schur complement."""
    problem, theta, z = _problem(1e-2)
    system = problem.system(theta, z)
    r, Jz, Jp, (rc, a, b, c) = system
    W, sizes, offset, n_p = len(problem.starts), problem.frames.size, problem.frames.offset, len(problem.columns)
    n_z = int(offset[-1])
    rows, rhs = [], []
    for w in range(W):
        block = np.zeros((Jz.shape[1], n_z + n_p))
        block[:, offset[w]:offset[w + 1]] = Jz[w][:, :sizes[w]]
        block[:, n_z:] = Jp[w]
        rows.append(block)
        rhs.append(r[w])
    for w in range(W - 1):
        block = np.zeros((10, n_z + n_p))
        block[:, offset[w]:offset[w + 1]] = a[w][:, :sizes[w]]
        block[:, offset[w + 1]:offset[w + 2]] = b[w][:, :sizes[w + 1]]
        block[:, n_z:] = c[w]
        rows.append(block)
        rhs.append(rc[w])
    J, res = np.concatenate(rows), np.concatenate(rhs)
    N, g = J.T @ J, J.T @ res
    S_dense = N[n_z:, n_z:] - N[n_z:, :n_z] @ np.linalg.solve(N[:n_z, :n_z], N[:n_z, n_z:])
    s_dense = g[n_z:] - N[n_z:, :n_z] @ np.linalg.solve(N[:n_z, :n_z], g[:n_z])
    S, s, back = problem.reduced(system, 0.0)
    np.testing.assert_allclose(S, S_dense, rtol=1e-6, atol=1e-8 * np.abs(S_dense).max())
    np.testing.assert_allclose(s, s_dense, rtol=1e-6, atol=1e-8 * np.abs(s_dense).max())
    dp = np.linalg.lstsq(S, s, rcond=1e-9)[0]  # the states' step that goes with a parameters' step
    dz = np.linalg.solve(N[:n_z, :n_z], g[:n_z] - N[:n_z, n_z:] @ dp)
    np.testing.assert_allclose(back(dp), dz, rtol=1e-5, atol=1e-8 * np.abs(dz).max())
    root = problem.root(system)
    np.testing.assert_allclose(root.T @ root, S_dense, rtol=1e-6, atol=1e-8 * np.abs(S_dense).max())


def test_bad_input_is_named():
    truth, mu, q, qd, tau, modes = recordings(1)[0]
    with pytest.raises(ValueError, match="tau"):
        fit(q, qd, tau[:-1], 0.01, prior(truth), 0.5, modes)
    bad = q.copy()
    bad[3, 2] = np.nan
    with pytest.raises(ValueError, match="q must be finite"):
        fit(bad, qd, tau, 0.01, prior(truth), 0.5, modes)
    with pytest.raises(ValueError, match="fitted"):
        fit(q, qd, tau, 0.01, prior(truth), 0.5, modes, fitted=("l1",))
    with pytest.raises(ValueError, match="window"):
        fit(q[:5], qd[:5], tau[:4], 0.01, prior(truth), 0.5, modes[:5])
    with pytest.raises(ValueError, match="dt"):
        fit(q, qd, tau, 0.0, prior(truth), 0.5, modes)
    with pytest.raises(ValueError, match="junction"):
        fit(q, qd, tau, 0.01, prior(truth), 0.5, modes, junction=0.0)
    with pytest.raises(ValueError, match="noise"):
        fit(q, qd, tau, 0.01, prior(truth), 0.5, modes, noise=(1e-3,) * 9)
    with pytest.raises(ValueError, match="modes"):
        fit(q, qd, tau, 0.01, prior(truth), 0.5, modes[:-1])
    with pytest.raises(ValueError, match="mu"):
        cramer_rao(q, qd, tau, 0.01, truth, -1.0, modes)
    with pytest.raises(TypeError):
        fit(q, qd, tau, 0.01, prior(truth), 0.5, modes, windw=10)
    with pytest.raises(TypeError):
        cramer_rao(q, qd, tau, 0.01, truth, mu, modes, windw=10)
