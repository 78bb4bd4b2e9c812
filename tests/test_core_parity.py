"""An environment's control step is the public physics step, bit for bit.

The environments step their packed rows (the compiled core's control step: the action clipped and scaled to
torques, the load, the mode and anchor carried over, the trigonometry kept); the public functions
(``leg_env.physics.hybrid.hybrid_step``, ``leg_env.physics.integrate.stance_step``) take a state as arrays. Both end in the
same compiled step, so every step of every task, pinned and unilateral, nominal and randomised, taken
again by the public function from the state before it, must agree to the last bit: a difference is a
wrong column, a lost load or a mode carried wrongly.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import leg_env  # noqa: F401  (registers the ids)
from leg_env.physics.hybrid import hybrid_step
from leg_env.physics.integrate import stance_step
from leg_env.envs.single import robot_of_row
CASES = [
    ("leg_env/PlanarLegStance-v0", False),
    ("leg_env/PlanarLegBalance-v1", False),
    ("leg_env/PlanarLegBalance-v1", True),
    ("leg_env/PlanarLegPush-v2", False),
    ("leg_env/PlanarLegHop-v4", False),
    ("leg_env/PlanarLegHop-v4", True),
]
STEPS = 150


def _core_step(env, action):
    """The control step of the env's robot 0 as the compiled core takes it from the env's current state."""
    state, robot, settings = env._state[0], env._robots[0], env._settings[0]
    params, mu = robot_of_row(robot)
    tau = np.clip(action, -1.0, 1.0) * robot["torque_limit"]
    dt, substeps, max_angle = float(settings["dt"]), int(settings["substeps"]), float(settings["max_angle"])
    q, qd, anchor = state["q"].copy(), state["qd"].copy(), state["anchor"].copy()
    if not env.unilateral:
        q1, qd1, lam = stance_step(q, qd, tau, params, dt=dt, substeps=substeps, anchor=anchor, max_angle=max_angle)
        return q1, qd1, None, None, lam
    r = hybrid_step(q, qd, tau, params, mu, mode=int(state["mode"]), anchor_x=anchor[0], dt=dt, substeps=substeps,
                    max_angle=max_angle, load_x=float(state["load"]))
    return r.q, r.qd, int(r.mode), float(r.anchor_x), r.lam_mean


@pytest.mark.parametrize("env_id, randomize", CASES)
def test_every_env_step_is_the_core_step_bit_for_bit(env_id, randomize):
    env = gym.make(env_id, randomize=True if randomize else None).unwrapped
    rng = np.random.default_rng(7)
    env.reset(seed=11)
    events = 0
    for k in range(STEPS):
        action = rng.uniform(-1.0, 1.0, 2) if k % 40 < 30 else np.sign(rng.uniform(-1.0, 1.0, 2))  # bursts of bang-bang
        action = action.astype(np.float32)
        q, qd, mode, anchor_x, lam = _core_step(env, action.astype(np.float64))
        _, _, terminated, _, info = env.step(action)
        state = env._state[0]
        if info["numerical_failure"]:  # the env undid the step; the core's state is not kept
            env.reset()
            continue
        np.testing.assert_array_equal(state["q"], q, err_msg=f"q at step {k}")
        np.testing.assert_array_equal(state["qd"], qd, err_msg=f"qd at step {k}")
        np.testing.assert_array_equal(info["contact_force"], lam, err_msg=f"lam at step {k}")
        if mode is not None:
            assert int(state["mode"]) == mode and state["anchor"][0] == anchor_x, k
            events += info["contact_events"]
        if terminated:
            env.reset()
    if env.unilateral and not randomize:
        assert events > 0  # lift-offs, touchdowns or slips were taken
