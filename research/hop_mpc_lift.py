"""Probe: the hopper's and the hop MPC's positive actuator work per second beside the work of lifting the COM, on 12
episodes of the hop task (seeds 60000..60011), on the robots that survive: each hop's lift is the COM's rise from its
stance's lowest point to the next flight's highest (flights of 15 control steps or more), times ``m g`` (the
default robot's 15 kg). What it found is in ``hop_mpc_probes.md``.

    .venv/bin/python research/hop_mpc_lift.py
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import numpy as np, gymnasium as gym
import leg_env
from policies.mpc import HopMPC
from policies.hopper import HopperController
n = 12
out = {}
for name, make in (("hopper", lambda e: HopperController(e.params, e.config)), ("mpc", lambda e: HopMPC(e.params, e.config))):
    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=n, vectorization_mode="vector_entry_point")
    e = envs.unwrapped
    pol = make(e)
    obs, _ = envs.reset(seed=60000)
    ys, contact, work, alive = [], [], [], np.ones(n, bool)
    for t in range(1000):
        a, _ = pol.predict(obs)
        obs, r, term, trunc, info = envs.step(a)
        alive &= ~term
        ys.append(info["com_position"][:, 1].copy()); contact.append(info["contact_mode"] != "flight")
        w = info["work_actuators"]; work.append(np.where(w > 0, w, 0.0))
    Y, C, W = np.array(ys), np.array(contact), np.array(work)
    lifts, pos, secs = [], [], 0.0
    for i in np.flatnonzero(alive):
        y, c = Y[:, i], C[:, i]
        # each stance: lowest COM; the next flight: highest COM
        t = 0; T = len(y)
        while t < T:
            if c[t]:
                s = t
                while t < T and c[t]: t += 1
                low = y[s:t].min()
                f = t
                while t < T and not c[t]: t += 1
                if t - f >= 15: lifts.append(y[f:t].max() - low)
            else:
                t += 1
        pos.append(W[:, i].sum()); secs += 10.0
    m_g = 15 * 9.81
    print(name, "survived", alive.sum(), "hops", len(lifts), "mean lift [m]", np.mean(lifts), "lift power [W]", m_g * np.sum(lifts) / secs, "positive work power [W]", np.sum(pos) / secs)
    envs.close()
