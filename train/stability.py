"""Gait stability on ``leg_env/PlanarLegHop-v4``: the apex-to-apex return map of a closed loop (the robot, the
task's observation and a controller or policy), its derivative composed from the hybrid step's exact Jacobians around
the hop cycle and checked against centred differences of the map; the Lyapunov exponents of any gait and the Floquet
multipliers of a periodic one (``docs/stability.md``).

    python -m train.stability hopper hopper:apex_gain=0 policies/ppo_hop_v4 mpc   # benchmarks/results/stability.md, .png

**The closed loop** (``HopLoop``) is the task's step in float64 (the env rounds its observation and the action to
float32; the map analysed is the smooth one that rounding samples). Its continuous state ``z`` is the robot's
``(q, qd)`` and every continuous quantity the next observation or action depends on (``LOOP_STATE``): the step's mean
contact force and impact impulse and the last action (observed), the task's apex memory (the arc's apex in flight,
the last landed hop's apex), then the controller's own state (the hopper's apex bias, apex estimate and dead-reckoned
drift; the MPC's inner hopper's). Its discrete state (the contact mode, the flight's and the ground's time, the COM's
start, the controller's phases) is held by a derivative: it changes only at thresholds.

**Its step's derivative** ``G = dz'/dz`` (``HopLoop.jacobian``) is composed from

* the step's exact ``A``, ``B`` (``leg_env.physics.derivatives.hybrid_step_jacobians``, with the saltation of every
  touchdown, impact and lift-off located inside the step),
* the controller's derivative by its observation and state: a PPO policy's own, from torch (its observation
  normalisation and network in float64); the model-based controllers' by differences of their law (their discrete
  state held, the MPC's line-search choice held; where the two one-sided differences disagree the law jumps, and the
  side without the jump is taken),
* the observation's by the state (its geometry: the foot, the COM) and the step's mean force and impulse by
  ``(q, qd, tau)`` by centred differences (the core's tangents do not carry them).

**The return map** is taken at the first control step after the COM's apex in flight (``hop_maps``). A sampled
controller (a torque held over each 10 ms step) has a periodic gait only where the hop locks to a whole number of
control steps: ``analyse`` reports the Lyapunov exponents per hop of any gait (``lyapunov_exponents``; and the same
growth by simulation alone, ``perturbation_growth``), and where the gait locks, Newton's method closes its orbit
(``periodic_orbit``) and the eigenvalues of the period map's derivative there are its Floquet multipliers. A gait is
orbitally stable when they lie inside the unit circle; the largest sets how fast a perturbation decays (by that
factor per period). Every composed map is checked against centred differences of the loop (``map_error``).
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import sys
from pathlib import Path

import numpy as np

from leg_env.physics import contact as _contact
from leg_env.physics.derivatives import hybrid_step_jacobians
from leg_env.physics.dynamics import com_state, contact_jacobian, foot_position
from leg_env.physics.hybrid import GROUND_TOL, hybrid_step
from leg_env.tasks.base import Obs

__all__ = ["LOOP_STATE", "HopLoop", "Hop", "Stability", "hop_maps", "return_map_fd", "lyapunov_exponents", "analyse", "main"]

LOOP_STATE = ("x_b", "y_b", "th_b", "q1", "q2", "vx_b", "vy_b", "w_b", "w_q1", "w_q2",
              "lam_x", "lam_y", "impulse_y", "last_a_hip", "last_a_knee", "arc_apex", "last_apex")
"""The loop's continuous state before the controller's own (``HopLoop.names`` has all of it)."""
_X, _LAM, _IMP, _LAST, _ARC, _APEX = slice(0, 10), slice(10, 12), 12, slice(13, 15), 15, 16
_NL = len(LOOP_STATE)
_EPS_LAW = 1e-6  # centred differences of a controller's law and of the step's mean force
_EPS_GEOMETRY = 1e-6  # centred differences of the observation's geometry
_JUMP = 1e-3  # one-sided differences of a law this far apart (relative) straddle a jump
MPC_HOPS = 8  # the hops the command line analyses of the MPC (a control step of its derivative takes about 0.3 s)
_MAP_TOL = 1e-3  # composed maps further than this from their differences (relative) are not the map's derivative


class _Model:
    """A model-based controller of ``policies`` (its float64 ``exact_actions``) with its state as arrays."""

    def __init__(self, controller, continuous: tuple[str, ...], discrete: tuple[str, ...], state_of):
        self.controller, self.continuous, self.discrete, self._state_of = controller, continuous, discrete, state_of
        self.choice = None

    def load(self, s: np.ndarray, d: dict) -> None:
        """Set the controller's state for a batch: continuous ``s`` ``(n, k)``, discrete ``d`` (name -> ``(n,)``)."""
        c = self.controller
        n = s.shape[0]
        if c._n != n:
            c._n = n
            c._allocate(n)
        holder = self._state_of(c)
        for j, name in enumerate(self.continuous):
            setattr(holder, name, s[:, j].copy())
        for name in self.discrete:
            setattr(holder, name, d[name].copy())

    def save(self) -> tuple[np.ndarray, dict]:
        holder = self._state_of(self.controller)
        s = np.stack([np.asarray(getattr(holder, name), dtype=np.float64) for name in self.continuous], axis=1)
        return s, {name: getattr(holder, name).copy() for name in self.discrete}

    def __call__(self, obs: np.ndarray, s: np.ndarray, d: dict, hold=None):
        """Actions, state and discrete state after them; ``hold``: the MPC's line-search choice to take (None: its own)."""
        self.load(s, d)
        c = self.controller
        if hasattr(c, "hold_pick"):
            c.hold_pick = None if hold is None else np.broadcast_to(hold, obs.shape[:1]).copy()
        u = c.exact_actions(obs)
        self.choice = int(c.pick[0]) if hasattr(c, "pick") and len(c.pick) else None
        s_new, d_new = self.save()
        return u, s_new, d_new


class _Network:
    """A trained SB3 policy as a float64 torch function of the raw observation (its normalisation included)."""

    continuous: tuple[str, ...] = ()
    discrete: tuple[str, ...] = ()

    def __init__(self, trained):
        import torch

        self.torch = torch
        self.policy = copy.deepcopy(trained.model.policy).double().eval()
        vn = trained.vec_normalize
        self.mean = self.scale = None
        if vn is not None:
            self.mean = torch.as_tensor(vn.obs_rms.mean, dtype=torch.float64)
            self.scale = torch.as_tensor(np.sqrt(vn.obs_rms.var + vn.epsilon), dtype=torch.float64)
            self.clip = float(vn.clip_obs)

    def mean_action(self, obs):
        """The policy's deterministic action before the clip, a torch function of raw observations ``(n, 24)``."""
        if self.mean is not None:
            obs = self.torch.clamp((obs - self.mean) / self.scale, -self.clip, self.clip)
        policy = self.policy  # SB3's forward casts to float32: its parts in float64, as its deterministic predict composes them
        features = policy.pi_features_extractor(obs)
        return policy.action_net(policy.mlp_extractor.forward_actor(features))

    choice = None

    def __call__(self, obs: np.ndarray, s: np.ndarray, d: dict, hold=None):
        with self.torch.no_grad():
            a = self.mean_action(self.torch.as_tensor(obs, dtype=self.torch.float64)).numpy()
        return np.clip(a, -1.0, 1.0), s, {}

    def jacobian(self, obs: np.ndarray) -> np.ndarray:
        """``d mean_action / d obs`` ``(2, 24)`` at one observation ``(24,)``, by torch's autograd."""
        from torch.autograd.functional import jacobian

        x = self.torch.as_tensor(obs[None], dtype=self.torch.float64)
        return jacobian(lambda o: self.mean_action(o)[0], x)[:, 0].numpy()


def controller_for(name_or_path, params, config, settings: dict | None = None):
    """The loop's controller: ``"hopper"``, ``"mpc"`` (``settings``: their keyword arguments) or a trained policy's
    folder (``train.policy_loading``)."""
    from policies.hopper import HopperController
    from policies.mpc import HopMPC

    if settings and name_or_path not in ("hopper", "mpc"):
        raise TypeError(f"settings are for the controllers 'hopper' and 'mpc', not a trained policy: got {settings}")
    state = HopperController.continuous_state, HopperController.discrete_state  # the MPC's: its inner hopper's
    if name_or_path == "hopper":
        return _Model(HopperController(params, config, **(settings or {})), *state, lambda c: c)
    if name_or_path == "mpc":
        return _Model(HopMPC(params, config, **(settings or {})), *state, lambda c: c._pilot)
    from train.policy_loading import TrainedPolicy, load_policy

    trained = load_policy(Path(name_or_path))
    if not isinstance(trained, TrainedPolicy):
        raise ValueError(f"{name_or_path}: the stability analysis takes a plain SB3 policy (no residual on a controller)")
    return _Network(trained)


class HopLoop:
    """The hop task's closed loop in float64 (module docstring), for a batch of robots.

    Args:
        controller: ``"hopper"``, ``"mpc"`` or a trained policy's folder.
        command: the commanded apex rise ``dh*`` [m], held.
        env_kwargs: the task's settings (``HopConfig`` fields), as ``gym.make`` takes them.
        settings: the controller's keyword arguments (``"hopper"`` and ``"mpc"`` only).
    """

    def __init__(self, controller, command: float, env_kwargs: dict | None = None, settings: dict | None = None):
        import gymnasium as gym

        import leg_env  # noqa: F401  (registers the ids)

        kwargs = dict(env_kwargs or {}, command_range=(float(command), float(command)))
        self.env = gym.make("leg_env/PlanarLegHop-v4", disable_env_checker=True, **kwargs).unwrapped
        self.params, self.config = self.env.params, self.env.config
        p, c = self.params, self.config
        self.command = float(command)
        self.ctrl = controller_for(controller, p, c, settings)
        self.names = LOOP_STATE + tuple(name.strip("_") for name in self.ctrl.continuous)
        self.nz = len(self.names)
        self.limit = np.array(c.torque_limit, dtype=np.float64) * np.ones(2)
        self.mass = p.m_b + p.m1 + p.m2
        self.weight = self.mass * p.g
        self.y_stand = float(com_state(self.env.nominal.q, np.zeros(5), p)[0][1])
        self.step_args = dict(dt=c.dt, substeps=c.substeps, max_angle=c.max_angle)
        self.jumps = 0  # the steps whose law derivative straddled a jump of the law (``_law_derivative``)

    # ---- state

    def start(self, seed: int = 0):
        """``(z, d)`` of one robot at the env's reset of ``seed`` (the controller started at its first observation)."""
        obs, _ = self.env.reset(seed=seed)
        st = self.env._state[0]
        z = np.zeros((1, self.nz))
        z[0, :5], z[0, 5:10] = st["q"], st["qd"]
        z[0, _LAM], z[0, _IMP] = obs[Obs.lam_x:Obs.lam_y + 1], obs[Obs.impulse_y]  # the reset's force at rest
        z[0, _LAST] = st["last_action"]
        d = {"mode": np.array([st["mode"]], dtype=np.int64), "flight_run": np.zeros(1), "ground_time": np.zeros(1),
             "x_com0": np.array([st["x_com0"]], dtype=np.float64)}
        ctrl = self.ctrl
        if ctrl.continuous or ctrl.discrete:
            ctrl.controller.reset()
            ctrl.controller._n = 1
            ctrl.controller._allocate(1)
            ctrl.controller._start(np.ones(1, dtype=bool), self.observe(z, d))
            s, cd = ctrl.save()
            z[0, _NL:] = s[0]
            d.update(cd)
        return z, d

    def observe(self, z: np.ndarray, d: dict) -> np.ndarray:
        """The task's observation ``(n, 24)`` in float64 of states ``z`` ``(n, nz)``."""
        p = self.params
        q, qd = z[:, 0:5], z[:, 5:10]
        foot = foot_position(q, p)
        vfoot = np.einsum("nij,nj->ni", contact_jacobian(q, p), qd)
        mode = d["mode"]
        obs = np.zeros((z.shape[0], 24))
        obs[:, Obs.base_x] = q[:, 0] - foot[:, 0]  # the base from the ground point under the foot
        obs[:, Obs.base_y:Obs.q2 + 1] = q[:, 1:5]
        obs[:, Obs.vx_b:Obs.w_q2 + 1] = qd
        obs[:, Obs.lam_x:Obs.lam_y + 1] = z[:, _LAM]
        obs[:, Obs.foot_height] = foot[:, 1]
        obs[:, Obs.foot_vx:Obs.foot_vy + 1] = vfoot
        obs[:, Obs.contact] = mode != _contact.FLIGHT
        obs[:, Obs.slip] = np.where(mode == _contact.SLIP_FORWARD, 1.0, np.where(mode == _contact.SLIP_BACKWARD, -1.0, 0.0))
        obs[:, Obs.impulse_y] = z[:, _IMP]
        obs[:, Obs.command] = self.command
        obs[:, Obs.com_drift] = com_state(q, qd, p)[0][:, 0] - d["x_com0"]
        obs[:, Obs.ground_time] = d["ground_time"]
        obs[:, Obs.last_apex] = z[:, _APEX]
        obs[:, 22:24] = z[:, _LAST]
        return obs

    def arc_apex(self, x: np.ndarray) -> np.ndarray:
        """The ballistic apex's rise above ``y_stand`` of states ``x`` ``(n, 10)`` in flight (the task's)."""
        pos, vel = com_state(x[:, :5], x[:, 5:], self.params)
        return pos[:, 1] + vel[:, 1] ** 2 / (2.0 * self.params.g) - self.y_stand

    def _memory(self, z, d, u, r):
        """The task's memory after a step ``r`` (``hybrid_step``'s result) taken at ``(z, d)`` under action ``u``."""
        c = self.config
        n = z.shape[0]
        x_new = np.concatenate([r.q, r.qd], axis=1)
        m = np.empty((n, _NL - 10))
        m[:, 0:2] = r.lam_mean / self.weight
        m[:, 2] = r.impulse[:, 1] / (self.weight * c.dt)
        m[:, 3:5] = u
        flight = r.mode == _contact.FLIGHT
        landed = ~flight & (d["flight_run"] > 0.0)
        hop = landed & (d["flight_run"] + r.flight_time >= c.min_flight)
        m[:, 5] = np.where(flight, self.arc_apex(x_new), z[:, _ARC])
        m[:, 6] = np.where(hop, z[:, _ARC], z[:, _APEX])
        flight_run = np.where(flight, d["flight_run"] + r.flight_time, 0.0)
        ground_time = np.where(flight_run >= c.min_flight, 0.0, d["ground_time"] + c.dt)
        return x_new, m, {"mode": r.mode.astype(np.int64), "flight_run": flight_run, "ground_time": ground_time,
                          "x_com0": d["x_com0"]}

    def step(self, z: np.ndarray, d: dict, hold=None):
        """One control step of the loop: ``(z', d', u, r)``; ``hold``: the controller's choice to take (the MPC's line
        search), None: its own (``choice`` is then the first robot's)."""
        obs = self.observe(z, d)
        u, s_new, cd = self.ctrl(obs, z[:, _NL:], d, hold)
        self.choice = self.ctrl.choice
        r = hybrid_step(z[:, :5], z[:, 5:10], u * self.limit, self.params, self.config.mu, d["mode"], None, **self.step_args)
        x_new, m, d_new = self._memory(z, d, u, r)
        d_new.update(cd)
        return np.concatenate([x_new, m, s_new], axis=1), d_new, u, r

    # ---- derivative

    def _repeat(self, d: dict, k: int) -> dict:
        return {name: np.repeat(v, k, axis=0) for name, v in d.items()}

    def _law_derivative(self, z, d, hold):
        """``du/dz`` ``(2, nz)`` (before the clip) and ``ds'/dz`` of the controller's state at one robot ``z`` ``(1, nz)``."""
        nz, e = self.nz, _EPS_LAW
        if isinstance(self.ctrl, _Network):
            Z = np.repeat(z, 2 * nz, axis=0) + np.concatenate([np.eye(nz), -np.eye(nz)]) * e
            D = self._repeat(d, 2 * nz)
            J_obs = self.ctrl.jacobian(self.observe(z, d)[0])  # (2, 24): the network's own derivative
            O = self.observe(Z, D)
            dobs = (O[:nz] - O[nz:]).T / (2 * e)  # (24, nz): the observation's geometry
            return J_obs @ dobs, np.zeros((0, nz))
        # a model-based law by centred differences along what it reads: the robot's state and its own (the
        # controllers of policies do not read the task's memory: the step's force, the last action, the apexes)
        # A law can jump (the MPC's plan runs the hopper, whose phase switches move by whole plan steps under a
        # perturbation): where the two one-sided differences disagree, the side without the jump (the smaller) is
        # the derivative of the law's branch at the state, and the step is counted in ``jumps``.
        cols = np.r_[0:10, _NL:nz]
        k = len(cols)
        Z = np.repeat(z, 2 * k + 1, axis=0)
        Z[np.arange(k), cols] += e
        Z[k + np.arange(k), cols] -= e
        U, S, _ = self.ctrl(self.observe(Z, self._repeat(d, 2 * k + 1)), Z[:, _NL:], self._repeat(d, 2 * k + 1), hold)
        V = np.concatenate([U, S], axis=1)
        ahead, behind = (V[:k] - V[-1]) / e, (V[-1] - V[k:2 * k]) / e
        jump = np.abs(ahead - behind) > _JUMP * (1.0 + np.abs(ahead) + np.abs(behind))
        dv = np.where(jump, np.where(np.abs(ahead) < np.abs(behind), ahead, behind), (ahead + behind) / 2)
        self.jumps += bool(jump.any())
        du, ds = np.zeros((2, nz)), np.zeros((nz - _NL, nz))
        du[:, cols], ds[:, cols] = dv[:, :2].T, dv[:, 2:].T
        return du, ds

    def _onto_contact(self, X: np.ndarray, mode: int) -> None:
        """Put states ``X`` ``(n, >= 10)`` on their contact (in place): the foot on the ground and, sticking, at rest.

        In contact a state lives on the contact's manifold, and every map of the loop lands on it: a derivative is
        only ever applied along it. Differences taken through this projection are exact along the manifold (where
        the projection is the identity to first order) and defined off it.
        """
        if mode == _contact.FLIGHT:
            return
        q, qd = X[:, :5], X[:, 5:10]
        q[:, 1] -= foot_position(q, self.params)[:, 1]
        v = np.einsum("nij,nj->ni", contact_jacobian(q, self.params), qd)
        qd[:, 1] -= v[:, 1]
        if mode == _contact.STICK:
            qd[:, 0] -= v[:, 0]

    def jacobian(self, z: np.ndarray, d: dict, hold=None):
        """One step at one robot ``z`` ``(1, nz)``: ``(z', d', G, defined)``, ``G = dz'/dz`` ``(nz, nz)`` (module
        docstring); the controller's choice (``choice``) is held in its derivative."""
        nz = self.nz
        z_new, d_new, u, r = self.step(z, d, hold)
        du, ds = self._law_derivative(z, d, self.choice)  # the law's differences call the controller, not step
        inside = (np.abs(u[0]) < 1.0).astype(float)
        du = du * inside[:, None]  # the clip's derivative
        tau = u * self.limit
        J = hybrid_step_jacobians(z[:, :5], z[:, 5:10], tau, self.params, self.config.mu, d["mode"], None, **self.step_args)
        A, B = J.A[0], J.B[0]
        dtau = self.limit[:, None] * du  # (2, nz)
        G = np.zeros((nz, nz))
        G[_X] = A @ np.eye(10, nz) + B @ dtau
        # the step's mean force and impulse by (x, tau): centred differences of the step, its modes held
        e = _EPS_LAW
        X = np.repeat(np.concatenate([z[:, :10], tau], axis=1), 24, axis=0) + np.concatenate([np.eye(12), -np.eye(12)]) * e
        self._onto_contact(X, d["mode"][0])
        below = foot_position(X[:, :5], self.params)[:, 1] < -0.5 * GROUND_TOL  # a foot in flight at the ground moved below it:
        X[below] = np.concatenate([z[:, :10], tau], axis=1)  # a one-sided difference on that side
        R = hybrid_step(X[:, :5], X[:, 5:10], X[:, 10:], self.params, self.config.mu, np.repeat(d["mode"], 24), None, **self.step_args)
        F = np.concatenate([R.lam_mean / self.weight, R.impulse[:, 1:] / (self.weight * self.config.dt)], axis=1)
        sides = 2.0 - below[:12] - below[12:]
        dF = (F[:12] - F[12:]).T / (sides * e)  # (3, 12)
        G[10:13] = dF[:, :10] @ np.eye(10, nz) + dF[:, 10:] @ dtau
        G[_LAST] = du
        flight = r.mode[0] == _contact.FLIGHT
        if flight:  # the arc's apex of the new state
            e_g = _EPS_GEOMETRY
            Xn = np.repeat(z_new[:, :10], 20, axis=0) + np.concatenate([np.eye(10), -np.eye(10)]) * e_g
            a = self.arc_apex(Xn)
            G[_ARC] = ((a[:10] - a[10:]) / (2 * e_g)) @ G[_X]
        else:
            G[_ARC, _ARC] = 1.0
        hop = (not flight) and d["flight_run"][0] > 0.0 and d["flight_run"][0] + r.flight_time[0] >= self.config.min_flight
        G[_APEX, _ARC if hop else _APEX] = 1.0
        G[_NL:] = ds
        defined = bool(J.defined[0])
        return z_new, d_new, G, defined


@dataclasses.dataclass(frozen=True)
class Hop:
    """One hop of the loop, from a section to the next: where it starts and its return map's derivative."""

    step: int  # the control step of the section it starts from
    z: np.ndarray  # (1, nz) the loop's state there
    d: dict  # its discrete state there
    steps: int  # control steps to the next section
    H: np.ndarray  # (nz, nz) the derivative of the state at the next section by this one's, composed
    defined: bool  # every step's Jacobian exists
    choices: tuple  # the controller's choice at each step (the MPC's line search; None for the others)


def _copy(d: dict) -> dict:
    return {name: a.copy() for name, a in d.items()}


def hop_maps(loop: HopLoop, seed: int = 0, settle: float = 5.0, hops: int = 12):
    """Run the loop from the env's reset of ``seed``: ``settle`` seconds, then ``hops`` hops with their return maps'
    derivatives composed step by step. Returns ``(hops, fell)``: the list of ``Hop`` and whether the robot fell."""
    z, d = loop.start(seed)
    vy_prev = com_state(z[:, :5], z[:, 5:10], loop.params)[1][:, 1]
    settle_steps = int(round(settle / loop.config.dt))
    found, start, product, defined, choices = [], None, None, True, []
    k = 0
    while len(found) < hops:
        if k < settle_steps or start is None:
            z_new, d_new, _, _ = loop.step(z, d)
            G, ok = None, True
        else:
            z_new, d_new, G, ok = loop.jacobian(z, d)
        k += 1
        if G is not None:
            product, defined = G @ product, defined and ok
            choices.append(loop.choice)
        vy = com_state(z_new[:, :5], z_new[:, 5:10], loop.params)[1][:, 1]
        section = d_new["mode"][0] == _contact.FLIGHT and vy_prev[0] >= 0.0 > vy[0]
        if section and k >= settle_steps:
            if start is not None:
                found.append(Hop(start[0], start[1], start[2], k - start[0], product, defined, tuple(choices)))
            start, product, defined, choices = (k, z_new.copy(), _copy(d_new)), np.eye(loop.nz), True, []
        z, d, vy_prev = z_new, d_new, vy
        if abs(z[0, 2]) > 1.0 or not np.all(np.isfinite(z[:, :10])) or k > settle_steps + 400 * hops:
            return found, True  # fell, or stopped hopping
    return found, False


def return_map_fd(loop: HopLoop, z: np.ndarray, d: dict, steps: int, eps: float = 1e-6, choices=None) -> np.ndarray:
    """The derivative of the state ``steps`` control steps after ``(z, d)`` by ``z``, by centred differences: each
    coordinate moved by ``+-eps`` and the loop run (its discrete state at the start held, and the controller's
    ``choices`` at each step, if given: the branch the composed map differentiates). A state in contact is moved
    along the contact's manifold (``HopLoop._onto_contact``): with ``steps=0`` this gives that projection's
    derivative."""
    nz = loop.nz
    Z = np.repeat(z, 2 * nz, axis=0) + np.concatenate([np.eye(nz), -np.eye(nz)]) * eps
    loop._onto_contact(Z, int(d["mode"][0]))  # a state in contact moved along its manifold
    D = loop._repeat(d, 2 * nz)
    for i in range(steps):
        Z, D, _, _ = loop.step(Z, D, None if choices is None else choices[i])
    return (Z[:nz] - Z[nz:]).T / (2 * eps)


def map_error(loop: HopLoop, H: np.ndarray, z: np.ndarray, d: dict, steps: int, eps=(1e-6, 1e-7), choices=None):
    """``(error, H_fd)``: the largest difference between a composed map ``H`` and its centred differences, relative
    to ``H``'s largest entry (in contact: along the contact's manifold), at the best of the steps ``eps`` (a step that moves an event across a control step's
    end, or changes a discrete state, differences another branch), over the coordinates the map depends on (a column
    of zeros is a memory the map overwrites)."""
    finite = np.isfinite(z[0])  # a memory not yet set (the hopper's apex before its first hop) is NaN: left out
    H = np.where(np.outer(finite, finite), H, 0.0)
    live = np.flatnonzero(np.abs(H).sum(axis=0) > 0.0)
    best = (np.inf, None)
    for e in np.atleast_1d(eps):
        H_fd = return_map_fd(loop, z, d, steps, float(e), choices)
        onto = np.nan_to_num(return_map_fd(loop, z, d, 0, float(e)))  # in flight the identity; in contact, the projection onto it
        error = float(np.abs(H @ onto - H_fd)[np.ix_(live, live)].max() / np.abs(H).max())
        best = min(best, (error, H_fd), key=lambda b: b[0])
    return best


def perturbation_growth(loop: HopLoop, found: list, delta: float = 1e-6, count: int = 8, skip: int | None = None,
                        seed: int = 0) -> float:
    """The largest growth per hop of small perturbations by simulation alone, no derivative (Benettin's method with
    finite differences): the robot's state at the first of the hops ``found`` moved by ``delta`` in ``count`` random
    directions, the loop run along the hops, and at each of the unperturbed gait's sections each perturbation's size
    (the loop's state but the position along the ground) measured and scaled back to ``delta``. Returns the geometric
    mean growth per hop after the first ``skip`` hops (by default a third, as ``lyapunov_exponents``), the median over
    the directions. Where the law is smooth it
    approaches the largest Lyapunov exponent's factor; where the law jumps, it measures what the jumps do."""
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(count, 9))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    Z = np.repeat(found[0].z, count + 1, axis=0)
    Z[1:, 1:10] += delta * directions
    D = loop._repeat(found[0].d, count + 1)
    measured = np.isfinite(Z[0])
    measured[0] = False
    skip = len(found) // 3 if skip is None else skip
    logs = np.zeros(count)
    for i, h in enumerate(found):
        for _ in range(h.steps):
            Z, D, _, _ = loop.step(Z, D)
        gap = Z[1:] - Z[0]
        size = np.linalg.norm(np.where(measured, gap, 0.0), axis=1)
        if i >= skip:
            logs += np.log(size / delta)
        Z[1:] = Z[0] + np.where(measured, gap * (delta / size)[:, None], gap)
    return float(np.exp(np.median(logs) / (len(found) - skip)))


def lyapunov_exponents(maps: list, warmup: int | None = None) -> np.ndarray:
    """The Lyapunov exponents per hop of a sequence of hop maps, largest first: the mean logarithm of the growth of
    ``k``-dimensional volumes, by QR of the running product (Benettin's method), counted after the first ``warmup``
    maps (by default a third: the basis turns into the directions that grow, and a hop map's transient gain on a
    direction it then leaves is not counted). ``-inf`` for a direction every map annihilates (a memory the next hop
    overwrites)."""
    n = maps[0].shape[0]
    warmup = len(maps) // 3 if warmup is None else warmup
    basis, logs = np.eye(n), np.zeros(n)
    for i, H in enumerate(maps):
        basis, R = np.linalg.qr(H @ basis)
        if i >= warmup:
            with np.errstate(divide="ignore"):
                logs += np.log(np.abs(np.diag(R)))
    return np.sort(logs / (len(maps) - warmup))[::-1]


def period_map(loop: HopLoop, z: np.ndarray, d: dict, steps: int):
    """``(z', DP, defined, choices)``: the loop's state ``steps`` control steps after ``(z, d)``, its derivative
    composed, and the controller's choices on the way."""
    DP, defined, choices = np.eye(loop.nz), True, []
    d = _copy(d)
    for _ in range(steps):
        z, d, G, ok = loop.jacobian(z, d)
        DP, defined = G @ DP, defined and ok
        choices.append(loop.choice)
    return z, DP, defined, tuple(choices)


def periodic_orbit(loop: HopLoop, z: np.ndarray, d: dict, steps: int, iterations: int = 6, tol: float = 1e-10,
                   max_move: float = 0.05):
    """Newton's method on the period map: the state ``z*`` near ``z`` whose loop returns to it after ``steps`` control
    steps, moved along the ground at most (``x_b`` is free), the discrete state ``d`` held.

    Each iteration solves ``(DP - I) dz = -(P(z) - z)`` (least squares: a direction the map keeps, such as a held
    integrator, is left where it is) on the composed ``DP``; it stops where the closure stops falling or a step would
    move the state by more than ``max_move``. Returns ``(z*, closure, DP, defined, choices)`` at the best state it
    found, ``closure`` the largest entry of ``P(z*) - z*`` but for ``x_b``.
    """
    finite = np.isfinite(z[0])
    finite[0] = False  # the position along the ground: a gait that walks is periodic in the rest
    best = None
    for _ in range(iterations):
        try:
            end, DP, defined, choices = period_map(loop, z, d, steps)
        except ValueError:  # the step refused the state (the foot below the ground): no orbit here
            break
        r = (end - z)[0][finite]
        closure = float(np.abs(r).max())
        if best is not None and closure >= best[1]:
            break  # Newton does not converge: no periodic orbit near the gait
        best = (z, closure, DP, defined, choices)
        if closure <= tol or not defined or not np.all(np.isfinite(DP)):
            break
        dz = np.linalg.lstsq((DP - np.eye(loop.nz))[np.ix_(finite, np.isfinite(z[0]))], -r, rcond=1e-10)[0]
        if np.abs(dz).max() > max_move:
            break
        z = z.copy()
        z[0, np.isfinite(z[0])] += dz
    return best if best is not None else (z, np.inf, np.full((loop.nz, loop.nz), np.nan), False, ())


def _hop_pattern(steps: tuple, k: int, repeats: int = 3) -> bool:
    """Whether the last ``repeats`` periods of ``k`` hops took the same control steps."""
    if len(steps) < k * repeats:
        return False
    last = steps[len(steps) - k:]
    return all(tuple(steps[len(steps) - (j + 1) * k:len(steps) - j * k]) == tuple(last) for j in range(repeats))
@dataclasses.dataclass(frozen=True)
class Stability:
    """The stability of a closed loop's gait at one command (``analyse``)."""

    controller: str
    command: float
    hop_steps: tuple  # control steps of each analysed hop
    exponents: np.ndarray  # Lyapunov exponents per hop, largest first (composed maps)
    locked: int  # hops per period where the gait is periodic, 0 where it is not
    closure: float  # the return error (but x_b) Newton's method reached; NaN where the sections did not repeat
    multipliers: np.ndarray  # Floquet multipliers of a locked gait, largest first (composed); empty if not locked
    multipliers_fd: np.ndarray  # the same of the return map by centred differences
    fd_error: float  # largest |H - H_fd| over the checked maps, relative to their largest entry
    defined: bool  # every Jacobian along the analysed hops exists
    fell: bool  # the robot fell (or stopped hopping) before the hops were analysed
    neutral: tuple  # the coordinates every hop map keeps (left out of the exponents and multipliers)
    jump_share: float  # the share of the analysed control steps at which the controller's law jumps (its derivative
    # there is its branch's: the one-sided difference without the jump)
    perturbation_growth: float  # the growth per hop of perturbations of 1e-6, by simulation alone
    coarse_growth: float  # the same of perturbations of 1e-3


def analyse(controller, command: float, seed: int = 0, settle: float = 10.0, hops: int = 30, checked: int = 2,
            tol: float = 1e-9, near: float = 1e-2, eps: tuple = (1e-6, 1e-7), env_kwargs: dict | None = None,
            settings: dict | None = None, name: str | None = None) -> Stability:
    """The stability of ``controller``'s gait at ``command`` from the env's reset of ``seed`` (module docstring).

    After ``settle`` seconds the loop runs ``hops`` hops with their maps composed from the Jacobians. The gait is
    locked where the hop's control steps repeat with a period of ``k`` hops (``k`` = 1..4), the section state (but
    ``x_b``) repeats within ``near`` after ``k`` hops, and Newton's method closes the orbit within ``tol``; a locked
    gait's Floquet multipliers are the eigenvalues of its period map's composed derivative at the closed orbit,
    checked against centred differences of the period map. Every gait's Lyapunov exponents per hop come from all
    the analysed maps; the last ``checked`` of them are compared with centred differences (``fd_error``, at the best
    of the steps ``eps``).
    """
    loop = controller if isinstance(controller, HopLoop) else HopLoop(controller, command, env_kwargs, settings)
    name = name or str(controller)
    jumps = loop.jumps
    found, fell = hop_maps(loop, seed, settle, hops)
    jump_share = (loop.jumps - jumps) / max(1, sum(h.steps for h in found))
    empty = np.zeros(0)
    if fell or len(found) < 2:
        return Stability(name, command, tuple(h.steps for h in found), empty, 0, np.nan, empty, empty, np.nan, False, True,
                         (), jump_share, np.nan, np.nan)
    # a coordinate every hop map keeps as it is is neutral by construction: the position along the ground of a
    # controller that does not observe it (nothing depends on it: its column is the identity's), a held integrator
    # (it depends on nothing: its row is). Either way its multiplier is 1 and the others are those of the map with its
    # row and column left out: the exponents and multipliers reported.
    eye = np.eye(loop.nz)
    fixed = lambda H, c: np.abs(H[:, c] - eye[c]).max() < 1e-9 or np.abs(H[c] - eye[c]).max() < 1e-9  # noqa: E731
    keep = np.array([not all(fixed(h.H, c) for h in found) for c in range(loop.nz)])
    neutral = tuple(name for name, k in zip(loop.names, keep) if not k)
    exponents = lyapunov_exponents([h.H[np.ix_(keep, keep)] for h in found])
    growth = perturbation_growth(loop, found), perturbation_growth(loop, found, delta=1e-3)
    errors = [map_error(loop, h.H, h.z, h.d, h.steps, eps, h.choices)[0] for h in found[-checked:]]
    steps = tuple(h.steps for h in found)
    locked, closure = 0, np.nan
    multipliers = multipliers_fd = empty
    for k in (1, 2, 3, 4):
        if not _hop_pattern(steps, k):
            continue
        start = found[-k]
        change = found[-1].z[0] - found[-1 - k].z[0] if len(found) > k else np.full(loop.nz, np.inf)
        change = np.abs(change[1:][np.isfinite(change[1:])])
        if change.size == 0 or change.max() > near:
            continue  # the sections do not repeat yet: no orbit for Newton's method to close
        z, closure, DP, defined, choices = periodic_orbit(loop, start.z, start.d, sum(steps[-k:]))
        if closure > tol or not defined:
            continue
        locked = k
        error, DP_fd = map_error(loop, DP, z, start.d, sum(steps[-k:]), eps, choices)
        errors.append(error)
        multipliers, multipliers_fd = (np.array(sorted(np.linalg.eigvals(M[np.ix_(keep, keep)]), key=abs, reverse=True))
                                       for M in (DP, DP_fd))
        break
    return Stability(name, command, steps, exponents, locked, closure, multipliers, multipliers_fd,
                     float(max(errors)), all(h.defined for h in found), False, neutral, jump_share, *growth)


# ---- the results file and its plot

def _controller_spec(text: str):
    """``NAME[:key=value,...]`` (``hopper:apex_gain=0``) as ``(name, settings or None)``."""
    name, _, rest = text.partition(":")
    settings = {}
    for item in filter(None, rest.split(",")):
        key, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"controller settings must be key=value pairs, got {item!r} in {text!r}")
        settings[key.strip()] = float(value)
    return name, settings or None


def _multipliers_text(w: np.ndarray, count: int = 3) -> str:
    """The ``count`` largest multipliers, a complex pair once (``a +- bi``); ``w`` sorted by modulus."""
    shown, i = [], 0
    while i < len(w) and len(shown) < count:
        if abs(w[i].imag) < 5e-4:
            shown.append(f"{w[i].real:.3f}")
            i += 1
        else:
            shown.append(f"{w[i].real:.3f} +- {abs(w[i].imag):.3f}i")
            i += 2
    return ", ".join(shown)


def _to_json(r: Stability) -> dict:
    row = dataclasses.asdict(r)
    for name in ("multipliers", "multipliers_fd"):
        row[name] = [[float(w.real), float(w.imag)] for w in np.asarray(row[name], dtype=complex)]
    row["exponents"] = [float(x) for x in r.exponents]  # -inf: a direction every map annihilates
    row["hop_steps"] = [int(k) for k in r.hop_steps]
    return row


def _from_json(row: dict) -> Stability:
    row = dict(row)
    for name in ("multipliers", "multipliers_fd"):
        row[name] = np.array([complex(re, im) for re, im in row[name]])
    row["exponents"] = np.array(row["exponents"], dtype=float)
    row["hop_steps"], row["neutral"] = tuple(row["hop_steps"]), tuple(row["neutral"])
    return Stability(**row)


def write_results(results: list, out: Path, run: dict) -> None:
    """``out``.json (every result and the run's settings), ``out``.md (the table, headed by machine, versions and
    date) and ``out``.png (the plot). ``run``: ``seconds``, ``seed``, ``settle``, ``hops``, ``machine``, ``date``."""
    import json

    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(dict(run, results=[_to_json(r) for r in results]), indent=1) + "\n")
    seed, settle, hops = run["seed"], run["settle"], run["hops"]
    lines = [
        "# Gait stability on PlanarLegHop-v4",
        "",
        f"Written by `python -m train.stability` on {run['date']} in {run['seconds']:.0f} s.",
        "",
        f"Machine: {run['machine']}.",
        "",
        f"Each row: a controller hopping to one command, from the env's reset of seed {seed}, its gait analysed after "
        f"{settle:g} s over {hops} hops ({min(hops, MPC_HOPS)} for the MPC) between sections at the first control step after "
        "the COM's apex "
        "(`train.stability`). *Hop*: control steps per hop (range). *Growth*: the two largest Lyapunov exponents per "
        "hop of the composed hop maps, as the factors a perturbation grows by per hop (below 1: neighbouring gaits "
        "converge; above: they diverge). *By simulation*: the growth per hop of perturbations of 1e-6 and "
        "of 1e-3 by simulation alone (`perturbation_growth`, no derivative). *Locked*: hops per period of a periodic gait (Newton's method on the period "
        "map closes it to 1e-9), else no; its Floquet multipliers (of the whole period), largest first, composed from "
        "the Jacobians (a complex pair once), and their largest difference from the multipliers of the period map by "
        "centred differences. "
        "*Maps*: the largest difference between a composed hop (or period) map and its centred differences, relative "
        "to its largest entry (beyond 1e-3 the composition is not the map's derivative: *no derivative*; where the "
        "controller's law jumps, the share of the steps it jumps at). *Neutral*: coordinates every map keeps "
        "(multiplier 1 by construction), left out.",
        "",
        "| controller | command | hop [steps] | growth per hop | by simulation | locked | Floquet multipliers | vs differences | maps | neutral |",
        "|---|---:|---|---:|---:|---:|---|---:|---:|---|",
    ]
    for r in results:
        if r.fell:
            lines.append(f"| {r.controller} | {100 * r.command:.0f} cm | fell | | | | | | | |")
            continue
        hop = f"{min(r.hop_steps)}" if min(r.hop_steps) == max(r.hop_steps) else f"{min(r.hop_steps)}-{max(r.hop_steps)}"
        lock = str(r.locked) if r.locked else "no"
        mult = _multipliers_text(r.multipliers) if r.locked else ""
        diff = f"{np.abs(r.multipliers - r.multipliers_fd).max():.1e}" if r.locked else ""
        undefined = "" if r.defined else " (a Jacobian undefined)"
        growth = ", ".join(f"{g:.3f}" for g in np.exp(r.exponents[:2])) if r.fd_error <= _MAP_TOL else "no derivative"
        jumps = f" (the law jumps at {100 * r.jump_share:.0f}% of the steps)" if r.jump_share else ""
        lines.append(f"| {r.controller} | {100 * r.command:.0f} cm | {hop} | {growth} | {r.perturbation_growth:.3g}, "
                     f"{r.coarse_growth:.3g} | {lock} | {mult} | "
                     f"{diff} | {r.fd_error:.1e}{undefined}{jumps} | {', '.join(r.neutral)} |")
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    _plot(results, out.with_suffix(".png"))


def _plot(results: list, path: Path) -> None:
    from train.plots import pyplot, save_figure

    plt = pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.6))
    names = list(dict.fromkeys(r.controller for r in results))
    colours = dict(zip(names, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    for name in names:
        rows = [r for r in results if r.controller == name and not r.fell]
        composed = [r for r in rows if r.fd_error <= _MAP_TOL]
        ax.plot([100 * r.command for r in composed], [np.exp(r.exponents[0]) for r in composed], "o-", color=colours[name],
                label=f"{name}: composed maps")
        ax.plot([100 * r.command for r in rows], [r.coarse_growth for r in rows], "x--", color=colours[name], alpha=0.7,
                label=f"{name}: simulated, 1e-3")
    markers = dict(zip(sorted({r.command for r in results}), "osD^vP*"))
    for r in results:
        if r.locked:
            bx.plot(r.multipliers.real, r.multipliers.imag, markers[r.command], color=colours[r.controller], alpha=0.8,
                    label=f"{r.controller}, {100 * r.command:.0f} cm ({r.locked} hop{'s' if r.locked > 1 else ''})")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("command [cm]")
    ax.set_ylabel("largest growth of a perturbation per hop")
    ax.set_title("Neighbouring gaits converge (< 1) or diverge (> 1)")
    ax.legend(fontsize=7)
    t = np.linspace(0, 2 * np.pi, 200)
    bx.plot(np.cos(t), np.sin(t), "k", lw=0.8)
    bx.set_aspect("equal")
    bx.set_xlabel("Re")
    bx.set_ylabel("Im")
    bx.set_title("Floquet multipliers of the locked gaits (per period)")
    handles, labels = bx.get_legend_handles_labels()
    unique = dict(zip(labels, handles))
    if unique:
        bx.legend(unique.values(), unique.keys(), fontsize=7, loc="lower left")
    save_figure(fig, path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m train.stability", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("controllers", nargs="+", help="hopper, mpc, or a trained policy's folder; settings of the "
                        "controllers as NAME:key=value,... (hopper:apex_gain=0 holds the hopper's apex bias)")
    parser.add_argument("--commands", type=float, nargs="+", default=[0.06, 0.08, 0.10, 0.12, 0.14], help="commands [m]")
    parser.add_argument("--seed", type=int, default=0, help="the env reset the gait starts from")
    parser.add_argument("--settle", type=float, default=10.0, help="seconds run before the analysis")
    parser.add_argument("--hops", type=int, default=30, help=f"hops analysed (the MPC: at most {MPC_HOPS})")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/stability"),
                        help="the results' path without suffix: OUT.md, OUT.png")
    parser.add_argument("--merge", type=Path, nargs="+", metavar="JSON",
                        help="write OUT from the results files of earlier runs (their rows in the order given; "
                        "CONTROLLERS are then ignored, give any)")
    args = parser.parse_args(argv)
    import datetime
    import json
    import time

    from train.machine import describe

    if args.merge:
        runs = [json.loads(Path(f).read_text()) for f in args.merge]
        settings = {(r["seed"], r["settle"], r["hops"]) for r in runs}
        if len(settings) != 1:
            raise ValueError(f"--merge needs runs of the same seed, settle and hops, got {sorted(settings)}")
        run = dict(runs[0], seconds=sum(r["seconds"] for r in runs))
        run.pop("results")
        write_results([_from_json(row) for r in runs for row in r["results"]], args.out, run)
        print(args.out.with_suffix(".md").read_text())
        return 0
    start = time.perf_counter()
    results = []
    for spec in args.controllers:
        name, settings = _controller_spec(spec)
        for command in args.commands:
            hops = min(args.hops, MPC_HOPS) if name == "mpc" else args.hops
            r = analyse(name, command, args.seed, args.settle, hops, settings=settings, name=spec)
            results.append(r)
            print(f"{spec} {100 * command:.0f} cm: " + ("fell" if r.fell else
                  f"growth {np.exp(r.exponents[0]):.3f} per hop, locked {r.locked}, maps {r.fd_error:.1e}"), flush=True)
    run = dict(seconds=time.perf_counter() - start, seed=args.seed, settle=args.settle, hops=args.hops,
               machine=describe(), date=datetime.date.today().isoformat())
    write_results(results, args.out, run)
    print(args.out.with_suffix(".md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
