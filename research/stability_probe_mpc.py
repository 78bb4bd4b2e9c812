"""Probe: the hop MPC's apex-to-apex return map by centred differences (on the model, its inner hopper's apex bias
held), beside ``stability_probe.py``'s hopper.

    .venv/bin/python research/stability_probe_mpc.py 0.08     # the command [m]

The MPC's state at the section is the robot's (its inner hopper's apex memory and drift are overwritten in flight,
its bias is held); the return map runs the control steps of the last hop. Findings in ``stability_probe.md``.
"""
import sys, numpy as np, gymnasium as gym, leg_env
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
from leg_env.physics import contact as C
from leg_env.physics.hybrid import hybrid_step
from policies.mpc import HopMPC
env = gym.make("leg_env/PlanarLegHop-v4").unwrapped
p, c = env.params, env.config
LIM = np.array(c.torque_limit, float) * np.ones(2)
SARGS = dict(dt=c.dt, substeps=c.substeps, max_angle=c.max_angle)
command = float(sys.argv[1])
mpc = HopMPC(p, c, hopper=dict(crouch=(0.05, 0.5), apex_gain=0.0))
obs0, _ = env.reset(seed=3)
q, qd, mode = mpc.state(obs0[None].astype(float))
x = np.concatenate([q, qd], 1)
xc0 = mpc.com(x)[0].copy()
def observe(x, mode, ground, n):
    like = np.repeat(obs0[None].astype(float), n, 0)
    o = mpc._observation(x, mode, like)
    o[:, 18] = command; o[:, 19] = mpc.com(x)[0] - np.repeat(xc0, n) ; o[:, 20] = ground
    return o
def run(x, mode, ground, pilot, steps, n):
    mpc.reset(); mpc.predict(observe(x, mode, ground, n))  # allocate
    mpc.reset()
    # first call allocates and starts; then overwrite the pilot state
    mpc._n = n; mpc._allocate(n)
    for name in mpc.pilot_state: setattr(mpc._pilot, name, np.repeat(pilot[name], n) if pilot[name].shape[0] == 1 else pilot[name].copy())
    vys = []
    for k in range(steps):
        o = observe(x, mode, ground, n)
        a, _ = mpc.predict(o)
        r = hybrid_step(x[:, :5], x[:, 5:], a.astype(float) * LIM, p, c.mu, mode, None, **SARGS)
        x = np.concatenate([r.q, r.qd], 1); mode = r.mode
        ground = np.where(mode == C.FLIGHT, 0.0, ground + c.dt)
        vys.append(mpc.com(x)[3].copy())
    return x, mode, ground, vys
# settle
mpc.reset(); n = 1
o = observe(x, mode, np.zeros(1), 1); mpc.predict(o); mpc.reset()
mpc._n = 1; mpc._allocate(1)
ground = np.zeros(1); sections = []; prev = mpc.com(x)[3]
for k in range(1500):
    o = observe(x, mode, ground, 1)
    a, _ = mpc.predict(o)
    r = hybrid_step(x[:, :5], x[:, 5:], a.astype(float) * LIM, p, c.mu, mode, None, **SARGS)
    x = np.concatenate([r.q, r.qd], 1); mode = r.mode
    ground = np.where(mode == C.FLIGHT, 0.0, ground + c.dt)
    vy = mpc.com(x)[3]
    if mode[0] == C.FLIGHT and prev[0] >= 0 and vy[0] < 0:
        sections.append((k + 1, x.copy(), mode.copy(), ground.copy(), {nm: getattr(mpc._pilot, nm).copy() for nm in mpc.pilot_state}))
    prev = vy
ks = [s_[0] for s_ in sections]
print("hops", len(sections), "periods", np.diff(ks)[-8:])
for a_, b_ in zip(sections[-4:-1], sections[-3:]):
    print("section change", np.round(np.abs(b_[1][0, 1:] - a_[1][0, 1:]).max(), 6))
k0, xs0, m0, g0, pil = sections[-2]
N = sections[-1][0] - k0
def ret(X):
    n = X.shape[0]
    pilot = {nm: np.repeat(v, n) for nm, v in pil.items()}
    xr, _, _, _ = run(X, np.repeat(m0, n), np.repeat(g0, n), pilot, N, n)
    return xr
xr = ret(xs0)
print("steps", N, "return error", np.abs(xr[0, 1:] - xs0[0, 1:]).max())
for eps in (1e-5, 1e-6):
    P = np.repeat(xs0, 10, 0) + eps * np.eye(10); M = np.repeat(xs0, 10, 0) - eps * np.eye(10)
    DP = ((ret(P) - ret(M)) / (2 * eps)).T
    ev = np.linalg.eigvals(DP)
    print("eps", eps, "multipliers", np.round(sorted(ev, key=abs, reverse=True), 4))
