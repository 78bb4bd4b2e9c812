"""The hopping controller's compiled law (``leg_env._core.kernels.hopper_torque``, ``policies.hopper``) against the law
as it was written in numpy (``tests/hopper_ref.py``): the same torques and the same per-robot state (phase, apex bias,
last apex, whether the last step flew), step by step along hopping episodes and at perturbed states."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import leg_env  # noqa: F401  (registers the ids)
from hopper_ref import ReferenceLaw
from leg_env.tasks.base import Obs
from policies.hopper import HopperController
from policies.stepping import STEP_GAINS

STATE = ("_bias", "_apex", "_phase", "_was_flight")


def _compare(h: HopperController, obs: np.ndarray, gains: dict | None = None):
    """One call of the compiled law and of the reference from the same state; the state after both must be the same.
    Returns the compiled torques and their largest difference from the reference's, relative to the torques' size."""
    ref = ReferenceLaw(h, gains)
    expected = ref.torque(obs)
    got = h.torque(obs)
    for name in STATE:
        a, b = getattr(ref, name), getattr(h, name)
        assert a.dtype == b.dtype, name
        np.testing.assert_array_equal(a, b, err_msg=name)  # NaN where NaN (no apex yet)
    np.testing.assert_array_equal(ref._vx, h._vx)
    return got, float(np.abs(got - expected).max() / (1.0 + np.abs(expected).max()))


def _hopper(envs, n, gains):
    e = envs.unwrapped
    h = HopperController(e.params, e.config, **gains)
    h._n = n
    h._allocate(n)
    h._start(np.ones(n, dtype=bool))
    return h


@pytest.mark.parametrize("gains", [{}, {"crouch": (0.05, 0.5)}, STEP_GAINS], ids=["default", "mpc_pilot", "stepping_hop"])
def test_compiled_law_is_the_reference_along_hopping_episodes(gains):
    n, steps = 32, 400
    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=n, vectorization_mode="vector_entry_point")
    h = _hopper(envs, n, gains)
    obs, _ = envs.reset(seed=2024)
    worst, phases, touchdowns = 0.0, set(), 0
    for _ in range(steps):
        o = np.asarray(obs, dtype=np.float64)
        was = h._was_flight.copy()
        tau, diff = _compare(h, o, gains)
        worst = max(worst, diff)
        touchdowns += int((was & (o[:, Obs.contact] > 0.5)).sum())
        phases.update(h._phase.tolist())
        h._x0 += h._vx * envs.unwrapped.config.dt
        obs, *_ = envs.step(np.clip(tau / h.torque_limit, -1.0, 1.0).astype(np.float32))
    envs.close()
    assert worst < 1e-12, worst
    assert phases == {0, 1, 2} and touchdowns > n  # every phase, and the apex bias updated at touchdowns


def test_compiled_law_is_the_reference_at_perturbed_states_in_every_phase():
    """Random states about the hop's (the MPC's centred differences move each coordinate), each phase and flag."""
    rng = np.random.default_rng(7)
    n = 600
    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=n, vectorization_mode="vector_entry_point")
    obs, _ = envs.reset(seed=11)
    envs.close()
    o = np.asarray(obs, dtype=np.float64).copy()
    cols = [Obs.th_b, Obs.q1, Obs.q2, Obs.vx_b, Obs.vy_b, Obs.w_b, Obs.w_q1, Obs.w_q2, Obs.base_y]
    o[:, cols] += rng.normal(0.0, [0.1, 0.2, 0.3, 0.5, 1.0, 1.0, 3.0, 5.0, 0.05], (n, len(cols)))
    o[:, Obs.contact] = rng.integers(0, 2, n)
    h = _hopper(envs, n, {})
    h._phase[:] = rng.integers(0, 3, n)
    h._was_flight[:] = rng.integers(0, 2, n).astype(bool)
    h._apex[:] = np.where(rng.random(n) < 0.5, np.nan, 0.8 + 0.1 * rng.random(n))
    h._bias[:] = rng.normal(0.0, 0.02, n)
    h._x0[:] = rng.normal(0.0, 0.3, n)
    _, diff = _compare(h, o)
    assert diff < 1e-12, diff


def test_a_non_finite_reading_is_refused_and_nothing_advances():
    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=3, vectorization_mode="vector_entry_point")
    h = _hopper(envs, 3, {})
    obs, _ = envs.reset(seed=3)
    envs.close()
    o = np.asarray(obs, dtype=np.float64).copy()
    o[1, Obs.w_q2] = np.nan
    before = {name: getattr(h, name).copy() for name in STATE}
    with pytest.raises(ValueError, match=r"observation must be finite .* rows \[1\]"):
        h.torque(o)
    for name in STATE:
        np.testing.assert_array_equal(getattr(h, name), before[name], err_msg=name)
    o[1, Obs.w_q2] = 0.0
    o[2, Obs.com_drift] = np.nan  # an entry the law does not read
    assert np.isfinite(h.torque(o)).all()
