"""Probe: the hopper's apex-to-apex return map on the hop task, its Jacobian composed from the step's exact ``A``,
``B`` and the hopper's derivative, against centred differences of the return map itself.

    .venv/bin/python research/stability_probe.py 0.10                        # the command [m]
    .venv/bin/python research/stability_probe.py 0.08 "dict(apex_gain=0.0)"  # and the hopper's settings

The closed loop's state at a section is ``z = (q, qd, bias, apex, x0)``: the robot's and the hopper's continuous state
(its apex bias, its apex memory, its dead-reckoned drift); its phase is held. The section is the first control step
after the COM's apex in flight; the return map runs the number of control steps the last hop took. What it found is
in ``stability_probe.md``.
"""
import sys, numpy as np, gymnasium as gym, leg_env
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
from leg_env.physics import contact as C
from leg_env.physics.derivatives import hybrid_step_jacobians
from leg_env.physics.hybrid import hybrid_step
from policies.hopper import HopperController
from policies.mpc import HopMPC

env = gym.make("leg_env/PlanarLegHop-v4").unwrapped
p, c = env.params, env.config
aux = HopMPC(p, c)  # for _observation and com
LIM = np.array(c.torque_limit, float) * np.ones(2)
SARGS = dict(dt=c.dt, substeps=c.substeps, max_angle=c.max_angle)
S = ("_bias", "_apex", "_x0")
GAINS = eval(sys.argv[2]) if len(sys.argv) > 2 else {}
NZ = 13

def ctl_step(z, phase, was_flight, mode, like):
    """(tau, s') of the hopper at batch of augmented states z (n, 13), its discrete state given."""
    n = z.shape[0]
    h = HopperController(p, c, **GAINS); h._n = n; h._allocate(n)
    h._bias, h._apex, h._x0 = z[:, 10].copy(), z[:, 11].copy(), z[:, 12].copy()
    h._phase, h._was_flight = phase.copy(), was_flight.copy()
    obs = aux._observation(z[:, :10], mode, np.broadcast_to(like, (n, like.shape[-1])))
    tau = h.torque(obs)
    u = np.clip(tau / LIM, -1, 1)
    x0 = h._x0 + h._vx * c.dt
    s_new = np.stack([h._bias, h._apex, x0], axis=1)
    return u, s_new, h._phase.copy(), h._was_flight.copy()

def step(z, phase, was, mode, like, jac=False):
    u, s_new, ph, wf = ctl_step(z, phase, was, mode, like)
    if jac:
        J = hybrid_step_jacobians(z[:, :5], z[:, 5:10], u * LIM, p, c.mu, mode, None, **SARGS)
        r = J.step
    else:
        r = hybrid_step(z[:, :5], z[:, 5:10], u * LIM, p, c.mu, mode, None, **SARGS)
    zn = np.concatenate([r.q, r.qd, s_new], axis=1)
    if not jac:
        return zn, ph, wf, r.mode
    # controller derivative by centred differences (its discrete state held)
    eps = 1e-6
    Z = np.repeat(z, 2 * NZ, axis=0) + np.concatenate([np.eye(NZ), -np.eye(NZ)]) * eps
    uu, ss, _, _ = ctl_step(Z, np.repeat(phase, 2 * NZ), np.repeat(was, 2 * NZ), np.repeat(mode, 2 * NZ), like)
    du = (uu[:NZ] - uu[NZ:]).T / (2 * eps)   # (2, 13)
    ds = (ss[:NZ] - ss[NZ:]).T / (2 * eps)   # (3, 13)
    Bt = J.B[0] * LIM * (np.abs(u[0]) < 1.0)
    G = np.zeros((NZ, NZ))
    G[:10, :10] = J.A[0]
    G[:10] += Bt @ du
    G[10:] = ds
    return zn, ph, wf, r.mode, G, J.undefined[0]

command = float(sys.argv[1]) if len(sys.argv) > 1 else 0.10
obs, _ = env.reset(seed=3)
like = np.array(obs[:22], float); like[18] = command
# start: the env's reset state rebuilt from the observation
q, qd, mode = aux.state(obs[None].astype(float))
z = np.concatenate([q, qd, np.zeros((1, 3))], axis=1); z[0, 11] = np.nan
phase = np.zeros(1, np.int64); was = np.zeros(1, bool)
def vyc(z): return aux.com(z[:, :10])[3]
sections = []
prev_vy = vyc(z)
for k in range(3000):
    z, phase, was, mode = step(z, phase, was, mode, like)
    vy = vyc(z)
    if mode[0] == C.FLIGHT and prev_vy[0] >= 0 and vy[0] < 0:
        sections.append((k + 1, z.copy(), phase.copy(), was.copy(), mode.copy()))
    prev_vy = vy
print("sections", len(sections), "periods", np.diff([s[0] for s in sections])[-8:])
# convergence: compare the last sections (translation-invariant coordinates)
for a, b in zip(sections[-4:-1], sections[-3:]):
    print("section change", np.round(np.abs(b[1][0, 1:] - a[1][0, 1:]).max(), 6))
k0, z0, ph0, wf0, m0 = sections[-2]
N = sections[-1][0] - k0
# Jacobian around the cycle
z, ph, wf, m = z0.copy(), ph0.copy(), wf0.copy(), m0.copy()
DP = np.eye(NZ); modes = []
for i in range(N):
    z, ph, wf, m, G, und = step(z, ph, wf, m, like, jac=True)
    DP = G @ DP; modes.append(int(m[0]))
print("steps", N, "undefined?", und, "return error", np.round(np.abs(z[0, 1:] - z0[0, 1:]).max(), 6))
# FD of the return map: N steps from the perturbed section state
def ret(zs):
    n = zs.shape[0]
    z, ph, wf, m = zs.copy(), np.repeat(ph0, n), np.repeat(wf0, n), np.repeat(m0, n)
    for i in range(N):
        z, ph, wf, m = step(z, ph, wf, m, like)
    return z
for eps in (1e-5, 1e-6):
    Zp = np.repeat(z0, NZ, 0) + eps * np.eye(NZ); Zm = np.repeat(z0, NZ, 0) - eps * np.eye(NZ)
    DPfd = ((ret(Zp) - ret(Zm)) / (2 * eps)).T
    live = [i for i in range(NZ) if i not in (11,)]
    print("eps", eps, "max |DP - DPfd|", np.abs(DP - DPfd)[np.ix_(live, live)].max(), "scale", np.abs(DP).max())
ev = np.linalg.eigvals(DP); evf = np.linalg.eigvals(DPfd)
print("multipliers (composed)", np.round(sorted(ev, key=abs, reverse=True), 4))
print("multipliers (FD)      ", np.round(sorted(evf, key=abs, reverse=True), 4))
names = ["x_b","y_b","th_b","q1","q2","vx","vy","wb","w1","w2","bias","apex","x0"]
print("per-coordinate change over the last hop:", {n: round(float(v), 5) for n, v in zip(names, sections[-1][1][0] - sections[-2][1][0])})
w, V = np.linalg.eig(DP)
for i in np.argsort(-np.abs(w))[:2]:
    print("mode", np.round(w[i], 4), {n: round(float(abs(v)), 3) for n, v in zip(names, V[:, i]) if abs(v) > 0.05})
