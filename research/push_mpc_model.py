"""The push MPC planning on each randomised robot's own model: how much of its falls on randomised robots is the model.

    .venv/bin/python research/push_mpc_model.py 10000 50 own        # seeds 10000..10049, planning on the drawn robot
    .venv/bin/python research/push_mpc_model.py 10050 50 own        # and 10050..10099, beside it
    .venv/bin/python research/push_mpc_model.py 10000 50 nominal    # planning on the nominal robot, as shipped
    .venv/bin/python research/push_mpc_model.py 10000 50 body       # its own masses, inertias and COMs only
    .venv/bin/python research/push_mpc_model.py 10000 50 contact    # its own mu and torque limits only

Each episode is ``PlanarLegPush-v2`` with ``randomize=True`` and every push at 34 N (3.4 N s), the same robots and
pushes as ``policies/baselines/mpc_push/robots`` (seeds 10000..10099); the MPC is made for that episode with the
robot drawn at its reset (``info["params"]``: masses, inertias, link COMs, ``mu`` and the torque limits). Findings in
``push_mpc_probes.md``.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import leg_env  # noqa: E402, F401
from leg_env.physics.params import LegParams  # noqa: E402
from leg_env.tasks.push import PushConfig  # noqa: E402
from policies.push_mpc import PushMPC  # noqa: E402

first, n, model = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
survived = []
t0 = time.time()
for seed in range(first, first + n):
    env = gym.make("leg_env/PlanarLegPush-v2", push_force=(34.0, 34.0), randomize=True)
    obs, info = env.reset(seed=seed)
    p = dict(info["params"])
    own_config = dataclasses.replace(env.unwrapped.config, mu=p.pop("mu"),
                                     torque_limit=(p.pop("hip_torque_limit"), p.pop("knee_torque_limit")))
    nominal_config = PushConfig(push_force=(34.0, 34.0))
    body = LegParams(**p) if model in ("own", "body") else LegParams()
    mpc = PushMPC(body, own_config if model in ("own", "contact") else nominal_config)
    ok = True
    for _ in range(1000):
        action, _ = mpc.predict(obs)
        obs, _, terminated, _, _ = env.step(action)
        if terminated:
            ok = False
            break
    survived.append(ok)
    print(seed, ok, flush=True)
print(f"survival {np.mean(survived):.2f} over seeds {first}..{first + n - 1}, {time.time() - t0:.0f} s")
