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
from leg_env.identify import BASE_NAMES, base_parameters, fit
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
        modes.append(env._state["mode"].astype(np.int64))
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


def test_noisy_recordings_are_fitted_within_their_standard_errors():
    """With a robot's sensor noise (NOISE) every base parameter lands within four standard errors of the truth, and the
    standard errors are small: the total mass and the leg's moment and inertia to 1%, the shank's to 3%."""
    rng = np.random.default_rng(5)
    for truth, mu, q, qd, tau, modes in recordings(ROBOTS, seed=12):
        noise = np.asarray(NOISE)
        qn = q + rng.normal(0.0, 1.0, q.shape) * noise[:5]
        qdn = qd + rng.normal(0.0, 1.0, qd.shape) * noise[5:]
        result = fit(qn, qdn, tau, 0.01, prior(truth), 0.5, modes, noise=NOISE)
        true_base = base_parameters(truth, mu)
        err = np.abs(result.base - true_base)[:6]
        assert np.all(err <= 4.0 * result.base_std[:6]), (err / true_base[:6], result.base_std[:6] / true_base[:6])
        assert np.all(result.base_std[[0, 1, 3, 5]] <= 0.01 * true_base[[0, 1, 3, 5]])
        assert np.all(result.base_std[[2, 4]] <= 0.03 * true_base[[2, 4]])
        assert 0.7 < result.rms < 1.6


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
    with pytest.raises(TypeError):
        fit(q, qd, tau, 0.01, prior(truth), 0.5, modes, windw=10)
