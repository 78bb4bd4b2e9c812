"""The model-based baseline: LQR on the stance dynamics linearised at the nominal equilibrium."""

import gymnasium as gym
import numpy as np
import pytest

import leg_env
from leg_env.physics.dynamics import stance_dynamics
from leg_env.physics.integrate import project_stance, stance_step
from leg_env.physics.params import LegParams
from leg_env.tasks.base import StanceConfig
from policies.lqr import STATE_INDEX, LQRController

EPISODE_SEEDS = (10_000, 10_001, 10_002)
FD_STEP = 1.0e-6


@pytest.fixture(scope="module")
def controller() -> LQRController:
    return LQRController()


def _discrete_map(x, tau, p, dt):
    """One control step of the env's integrator in minimal coordinates (foot pinned at the origin)."""
    q, qd = project_stance(np.r_[0.0, 0.0, x[:3]], np.r_[0.0, 0.0, x[3:]], p, np.zeros(2))
    q, qd, _ = stance_step(q, qd, tau, p, dt=dt, anchor=np.zeros(2))
    return np.r_[q[2:], qd[2:]]


def test_equilibrium_is_static(controller):
    q, qd = project_stance(np.r_[0.0, 0.0, controller.x_eq[:3]], np.zeros(5), controller.params, np.zeros(2))
    qdd, lam = stance_dynamics(q, qd, controller.tau_eq, controller.params)
    np.testing.assert_allclose(qdd, 0.0, atol=1e-9)
    np.testing.assert_allclose(lam, [0.0, controller.params.weight], atol=1e-9)
    np.testing.assert_allclose(controller.tau_eq, [0.0, -24.1], atol=0.05)


def test_open_loop_unstable_closed_loop_stable(controller):
    assert np.abs(np.linalg.eigvals(controller.Ad)).max() > 1.0  # the balance problem is real
    assert np.abs(controller.closed_loop_eigenvalues).max() < 0.999


def test_discrete_model_matches_the_integrator(controller):
    """Ad, Bd (ZOH of the finite-difference Jacobian of the dynamics) vs differences of the env's RK4 step."""
    p, dt = controller.params, controller.config.dt
    x0, u0 = controller.x_eq, controller.tau_eq
    Ad = np.empty((6, 6))
    Bd = np.empty((6, 2))
    for j in range(6):
        e = np.zeros(6)
        e[j] = FD_STEP
        Ad[:, j] = (_discrete_map(x0 + e, u0, p, dt) - _discrete_map(x0 - e, u0, p, dt)) / (2 * FD_STEP)
    for j in range(2):
        e = np.zeros(2)
        e[j] = FD_STEP
        Bd[:, j] = (_discrete_map(x0, u0 + e, p, dt) - _discrete_map(x0, u0 - e, p, dt)) / (2 * FD_STEP)
    np.testing.assert_allclose(controller.Ad, Ad, atol=1e-6 * np.abs(Ad).max())
    np.testing.assert_allclose(controller.Bd, Bd, atol=1e-6 * np.abs(Bd).max())


def test_linearisation_predicts_a_small_step(controller):
    """The continuous model's error on the nonlinear dynamics shrinks as the perturbation squared."""
    rng = np.random.default_rng(0)
    p = controller.params
    direction_x, direction_u = rng.standard_normal(6), 10 * rng.standard_normal(2)
    errors = []
    for scale in (1e-3, 1e-4):
        dx, du = scale * direction_x, scale * direction_u
        x = controller.x_eq + dx
        q, qd = project_stance(np.r_[0.0, 0.0, x[:3]], np.r_[0.0, 0.0, x[3:]], p, np.zeros(2))
        qdd, _ = stance_dynamics(q, qd, controller.tau_eq + du, p)
        f = np.r_[x[3:], qdd[2:]]
        errors.append(np.abs(f - (controller.A @ dx + controller.B @ du)).max())
    assert errors[1] < 1e-5
    assert 70 < errors[0] / errors[1] < 130  # second order: 10x smaller step, 100x smaller error


def test_predict_single_and_batch(controller):
    rng = np.random.default_rng(1)
    env = gym.make(leg_env.ENV_ID)
    obs0, _ = env.reset(seed=0)
    batch = obs0 + 0.05 * rng.standard_normal((7, 12)).astype(np.float32)
    a_batch, state = controller.predict(batch)
    assert state is None and a_batch.shape == (7, 2) and a_batch.dtype == np.float32
    assert np.all(np.abs(a_batch) <= 1.0)
    for i in range(7):
        a, _ = controller.predict(batch[i], deterministic=True)
        assert a.shape == (2,)
        np.testing.assert_array_equal(a, a_batch[i])
    with pytest.raises(ValueError, match="shape"):
        controller.predict(np.zeros(11))


@pytest.mark.parametrize("rows", [1, 2, 7, 64, 1000])
def test_a_rows_torque_does_not_depend_on_its_batch(controller, rows):
    """Each row's torque is the same, bit for bit, alone or in a batch of any size (so that a batched evaluation is
    the single env's episode, bit for bit, on any CPU), and is ``tau_eq - K x``."""
    rng = np.random.default_rng(rows)
    batch = rng.standard_normal((rows, 12))
    torques = controller.torque(batch)
    for i in range(rows):
        np.testing.assert_array_equal(controller.torque(batch[i]), torques[i])
        np.testing.assert_array_equal(controller.torque(batch[i : i + 1])[0], torques[i])
    x = batch[:, STATE_INDEX] - controller.x_eq
    np.testing.assert_allclose(torques, controller.tau_eq - x @ controller.K.T, rtol=0, atol=1e-9)


def test_nominal_observation_gives_holding_torque(controller):
    env = gym.make(leg_env.ENV_ID, reset_noise_scale=0.0)
    obs, _ = env.reset(seed=0)
    a, _ = controller.predict(obs)
    np.testing.assert_allclose(a * np.asarray(controller.config.torque_limit), controller.tau_eq, atol=1e-3)
    assert controller.x_eq.shape == (6,) and obs[list(STATE_INDEX)].shape == (6,)


@pytest.mark.parametrize("seed", EPISODE_SEEDS)
def test_survives_without_drifting_or_pulling(controller, seed):
    env = gym.make(leg_env.ENV_ID)
    obs, _ = env.reset(seed=seed)
    drift, pulled, steps = [], 0, 0
    terminated = truncated = False
    while not (terminated or truncated):
        action, _ = controller.predict(obs)
        obs, _, terminated, truncated, info = env.step(action)
        drift.append(info["base_drift"])
        pulled += info["unilateral_violation"] or info["friction_violation"]
        steps += 1
    assert steps == 1000 and not terminated
    assert np.sqrt(np.mean(np.square(drift))) < 0.02
    assert pulled == 0


def test_other_parameters_and_config():
    p = LegParams(m_b=12.0, l1=0.45)
    c = StanceConfig(nominal_knee=1.0, torque_limit=(60.0, 60.0))
    ctl = LQRController(p, c)
    assert np.abs(ctl.closed_loop_eigenvalues).max() < 1.0
    env = gym.make(leg_env.ENV_ID, params=p, config=c)
    obs, _ = env.reset(seed=3)
    for _ in range(300):
        obs, _, terminated, _, _ = env.step(ctl.predict(obs)[0])
        assert not terminated


def test_bad_weights_raise():
    with pytest.raises(ValueError, match="Q must be"):
        LQRController(Q=np.eye(5))
