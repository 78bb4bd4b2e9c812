"""Probe: ``train.ppo`` with a capture-point charge added to the training env's reward of the push task
(``push_probes.md``, probe BC). Each step pays ``-w (x_cp - x_foot)^2``, ``x_cp = x_com + v_com,x / omega`` with
``omega = sqrt(g / y_com)``: where the foot would have to stand for the robot to come to rest over it (the linear
inverted pendulum's instantaneous capture point). Standing still it is the COM over the foot; after a push it jumps
ahead by ``v / omega`` at once, long before the drift shows, and a step that lands the foot there removes it.
The evaluations and the selection are the task as registered (the charge is added to the training env only).

    CP_WEIGHT=20 .venv/bin/python research/push_capture_probe.py <train.ppo arguments>
"""
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import numpy as np

import leg_env.sb3 as sb3
from leg_env.physics.dynamics import com_state, foot_position

WEIGHT = float(os.environ["CP_WEIGHT"])
_step_wait = sb3.LegStanceVecEnv.step_wait


def step_wait(self):
    obs, rewards, dones, infos = _step_wait(self)
    q, qd, _ = self.env.state
    p = self.env.params
    com, com_velocity = com_state(q, qd, p)
    omega = np.sqrt(p.g / np.maximum(com[:, 1], 0.1))
    charge = WEIGHT * (com[:, 0] + com_velocity[:, 0] / omega - foot_position(q, p)[:, 0]) ** 2
    charge[dones] = 0.0  # these rows already hold the next episode's start
    return obs, (rewards - charge).astype(np.float32), dones, infos


if __name__ == "__main__":
    sb3.LegStanceVecEnv.step_wait = step_wait
    from train.ppo import main

    main(sys.argv[1:])
