"""The hopping controller's compiled law (``leg_env._core.kernels.hopper_torque``, ``policies.hopper``) against the law
as it was written in numpy (``tests/hopper_ref.py``): the same torques and the same per-robot state (phase, apex bias,
last apex, whether the last step flew, the time since the touchdown), step by step along hopping episodes and at
perturbed states."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import leg_env  # noqa: F401  (registers the ids)
from hopper_ref import ReferenceLaw
from leg_env.tasks.base import Obs
from policies.hopper import HopperController
from policies.mpc import HopMPC
from policies.stepping import STEP_GAINS

STATE = ("_bias", "_apex", "_phase", "_was_flight", "_since_touchdown")
MPC_PILOT = HopMPC().hopper_settings  # the hopper inside the MPC's plans: a deeper crouch and a dwell


def _compare(h: HopperController, obs: np.ndarray, gains: dict | None = None):
    """One call of the compiled law and of the reference from the same state; the state after both must be the same.
    Returns the compiled torques, their largest difference from the reference's, relative to the torques' size, and
    the robots that waited out a dwell at the step (the reference's)."""
    ref = ReferenceLaw(h, gains)
    expected = ref.torque(obs)
    got = h.torque(obs)
    for name in STATE:
        a, b = getattr(ref, name), getattr(h, name)
        assert a.dtype == b.dtype, name
        np.testing.assert_array_equal(a, b, err_msg=name)  # NaN where NaN (no apex yet)
    np.testing.assert_array_equal(ref._vx, h._vx)
    return got, float(np.abs(got - expected).max() / (1.0 + np.abs(expected).max())), ref.dwelling


def _hopper(envs, n, gains):
    e = envs.unwrapped
    h = HopperController(e.params, e.config, **gains)
    h._n = n
    h._allocate(n)
    h._start(np.ones(n, dtype=bool))
    return h


@pytest.mark.parametrize("gains", [{}, MPC_PILOT, STEP_GAINS], ids=["default", "mpc_pilot", "stepping_hop"])
def test_compiled_law_is_the_reference_along_hopping_episodes(gains):
    n, steps = 32, 400
    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=n, vectorization_mode="vector_entry_point")
    h = _hopper(envs, n, gains)
    obs, _ = envs.reset(seed=2024)
    worst, phases, touchdowns, dwelt, pushes = 0.0, set(), 0, 0, []
    for _ in range(steps):
        o = np.asarray(obs, dtype=np.float64)
        was, phase_was = h._was_flight.copy(), h._phase.copy()
        tau, diff, dwelling = _compare(h, o, gains)
        worst = max(worst, diff)
        touchdowns += int((was & (o[:, Obs.contact] > 0.5)).sum())
        phases.update(h._phase.tolist())
        dwelt += int(dwelling.sum())
        pushes += h._since_touchdown[(phase_was == 0) & (h._phase == 1) & ~was].tolist()  # the clock at each push's start
        h._x0 += h._vx * envs.unwrapped.config.dt
        obs, *_ = envs.step(np.clip(tau / h.torque_limit, -1.0, 1.0).astype(np.float32))
    envs.close()
    assert worst < 1e-12, worst
    assert phases == {0, 1, 2} and touchdowns > n  # every phase, and the apex bias updated at touchdowns
    dwell = gains.get("dwell", 0.0)
    assert (dwelt > n) == (dwell > 0), dwelt  # the dwell's servo ran where a dwell is set, and only there
    assert len(pushes) > n and min(pushes) >= dwell + 0.005, min(pushes)  # no push before the dwell is out


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
    for gains in ({}, MPC_PILOT):
        h = _hopper(envs, n, gains)
        h._phase[:] = rng.integers(0, 3, n)
        h._was_flight[:] = rng.integers(0, 2, n).astype(bool)
        h._apex[:] = np.where(rng.random(n) < 0.5, np.nan, 0.8 + 0.1 * rng.random(n))
        h._bias[:] = rng.normal(0.0, 0.02, n)
        h._x0[:] = rng.normal(0.0, 0.3, n)
        h._since_touchdown[:] = rng.uniform(0.0, 1.0, n)
        _, diff, _ = _compare(h, o, gains)
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


@pytest.mark.parametrize("setting, value, error, words", [
    ("dwell", -0.1, ValueError, r"HopperController\.dwell must be in \[0, 10\] s, got -0\.1"),
    ("liftoff_knee", float("nan"), ValueError, r"HopperController\.liftoff_knee must be in \(0, 3\.14159\) rad, got nan"),
    ("touchdown_length", 2.0, ValueError, r"HopperController\.touchdown_length must be in \(0, 1\] m"),
    ("crouch", (0.05,), ValueError, r"HopperController\.crouch must be a pair of real numbers, got 1 of them"),
    ("swing_gains", (400.0, -1.0), ValueError, r"HopperController\.swing_gains\[1\] must be in \[0, 100000\]"),
    ("friction_margin", 1.5, ValueError, r"HopperController\.friction_margin must be in \[0, 1\]"),
    ("attitude_gains", "ab", TypeError, r"HopperController\.attitude_gains must be a pair of real numbers, got 'ab'"),
    ("apex_gain", True, TypeError, r"HopperController\.apex_gain must be a real number"),
    ("dwel", 0.3, TypeError, r"unexpected keyword argument 'dwel'"),
])
def test_a_setting_out_of_its_range_is_refused_by_name(setting, value, error, words):
    """The hopper's settings, and the hopper inside the MPC's plan, are checked where they are given."""
    with pytest.raises(error, match=words):
        HopperController(**{setting: value})
    with pytest.raises(error, match=words):
        HopMPC(hopper={setting: value})
