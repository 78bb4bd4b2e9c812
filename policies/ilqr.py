"""iLQR on the corrections of a model-based controller's law, on the exact Jacobians of the hybrid step: what the
model-predictive controllers (``policies.mpc.HopMPC``, ``policies.push_mpc.PushMPC``) share.

**The plan.** At every control step the controller rebuilds the robot's state from the observation and rolls a plan
out over ``horizon`` control steps on the simulator's own step (``leg_env.physics.derivatives.hybrid_step_jacobians``:
the map the env steps, its touchdowns, impacts, lift-offs and stick/slip changes located inside the step). The plan is
a controller (the *pilot*: the hopper, the stepping controller) in closed loop, plus a correction ``v_t`` of its action
at every step, ``a_t = clip(pi(x_t) + v_t, -1, 1)``. One iteration of iLQR improves the corrections:

* the backward pass is Gauss-Newton on the closed loop's Jacobians ``A_cl = A + B D dpi/dx`` and ``B_cl = B D``:
  ``A``, ``B`` the step's, each with the saltation of the events it located (so the pass sees how a torque in a push
  moves the lift-off, and with it the flight), ``dpi/dx`` the pilot's derivative (centred differences of its law at
  ``law_step``, its discrete state held), ``D`` the clip's, faded to 0 over the last ``clip_smoothing`` before the
  limit (``clip_derivative``);
* the line search rolls the corrected plans out on the simulator, with the feedback ``K dx`` of the backward pass,
  at step lengths ``steps``, and every robot keeps the plan of least cost (the uncorrected one among them).

The controller applies the plan's first action. The cost is the sum over the plan's steps of ``|r(x)|^2`` (a task's
state residuals, ``residuals``), the action's ``effort_weight |a|^2`` and joints' positive power
``power_weight max(0, tau_j q_j')^2`` [W^2], ``smooth_weight |v|^2`` of the corrections and a penalty without
derivative (``_penalty``: a fall; the line search sees it, the backward pass does not). A subclass names its pilot
(``_new_pilot``, ``pilot_state``, ``_law``), its residuals (``residuals``, ``_charged``) and penalty, what the plan
tracks or pushes (``_track``, ``_load``), and in ``exact_actions`` the per-robot context ``ctx`` (a dict of ``(n, ...)``
arrays) its law and residuals read. ``replan_every > 1`` holds a plan between replans (``_due``, ``_hold``,
``_follow_held``).

**Compiled.** The backward pass is the compiled core's (``leg_env._core.kernels.ilqr_backward``, ``plan.c``), for
every pilot. The rollout here (``_rollout``) steps the plans of a batch of robots together, one numpy call of the
pilot's law and one of the step per plan step, for any pilot; a subclass whose pilot is compiled replaces it with a
compiled one (``HopMPC``: ``kernels.hop_rollout``, the whole plan in one call), to which this one is the reference.
"""

from __future__ import annotations

import numpy as np

from leg_env._core import kernels
from leg_env.physics import contact as _contact
from leg_env.physics.derivatives import hybrid_step_jacobians
from leg_env.physics.dynamics import com_state, foot_position
from leg_env.physics.hybrid import hybrid_step
from leg_env.physics.params import LegParams
from leg_env.tasks.base import Obs
from policies.base import BatchedController

__all__ = ["PilotILQR", "check_settings"]

NX, NU = 10, 2


def check_settings(positive: dict, nonnegative: dict) -> None:
    """``ValueError`` naming the first setting that is not positive and finite (``positive``) or not finite and at
    least 0 (``nonnegative``)."""
    for name, value in positive.items():
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be positive and finite, got {value}")
    for name, value in nonnegative.items():
        if not (np.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be finite and at least 0, got {value}")


def _get(obj, path: str):
    for name in path.split("."):
        obj = getattr(obj, name)
    return obj


def _set(obj, path: str, value) -> None:
    *parents, name = path.split(".")
    for parent in parents:
        obj = getattr(obj, parent)
    setattr(obj, name, value)


class PilotILQR(BatchedController):
    """The iLQR machinery around a pilot controller (module docstring); a subclass makes it a controller.

    Args (the subclass's keywords):
        params: the robot (``LegParams``). config: the task's config (``dt``, ``substeps``, ``max_angle``, ``mu``,
            ``torque_limit``).
        horizon: the plan's length in control steps. steps: the line search's step lengths. iterations: iLQR
            iterations per control step. warm_start: start each control step from the last plan's corrections.
        regularisation: added to the backward pass's ``Q_vv`` [cost per action^2].
        effort_weight: per action^2; power_weight: per W^2 of a joint's positive power; smooth_weight: per
            correction^2.
        clip_smoothing: the band inside the action's bounds over which the clip's derivative fades to 0.
        law_step: the step of the centred differences of the pilot's law [m, rad, m/s, rad/s].

    After each ``predict``, ``planned`` ``(N, horizon + 1, 10)`` holds the planned robots' chosen plans (the first
    state the robot's now), ``cost`` ``(N,)`` their cost and ``pick`` ``(N,)`` the line search's choice of the last
    iteration (the index of its step length in ``steps``, -1: the plan it started from). Setting ``hold_pick`` (an
    ``(N,)`` int array, or None) makes the line search take those choices whatever the costs. With ``replan_every``
    (``HopMPC``), ``plans`` counts the plans made, a robot each.
    """

    dtype = np.float64
    pilot_state: tuple[str, ...] = ()
    """The pilot's per-robot state (attribute paths, ``"hopper._phase"`` for a part's), copied into each plan."""
    n_residuals = 0

    def _setup(self, params: LegParams, config, horizon, steps, iterations, warm_start, regularisation, effort_weight,
               power_weight, smooth_weight, clip_smoothing, law_step, positive: dict, nonnegative: dict,
               replan_every: int = 1) -> None:
        if int(horizon) < 2:
            raise ValueError(f"horizon must be at least 2, got {horizon}")
        if not 1 <= int(replan_every) <= int(horizon):
            raise ValueError(f"replan_every must be from 1 to the horizon ({horizon}), got {replan_every}")
        if int(iterations) < 1:
            raise ValueError(f"iterations must be at least 1, got {iterations}")
        check_settings(dict(law_step=law_step, **positive),
                       dict(regularisation=regularisation, effort_weight=effort_weight, power_weight=power_weight,
                            smooth_weight=smooth_weight, clip_smoothing=clip_smoothing, **nonnegative))
        self.params, self.config = params, config
        self.horizon, self.iterations, self.warm_start = int(horizon), int(iterations), bool(warm_start)
        self.replan_every = int(replan_every)
        self.steps = tuple(float(s) for s in steps)
        self.regularisation = float(regularisation)
        self.torque_limit = np.asarray(config.torque_limit, dtype=np.float64) * np.ones(2)
        self.effort_weight, self.power_weight = float(effort_weight), float(power_weight)
        self.smooth_weight = float(smooth_weight)
        self.clip_smoothing, self.law_step = float(clip_smoothing), float(law_step)
        self._step_args = dict(dt=config.dt, substeps=config.substeps, max_angle=config.max_angle)
        self.hold_pick: np.ndarray | None = None
        self.pick = np.full(0, -1)

    # ---- what a subclass names

    def _new_pilot(self, n: int):
        """A pilot controller for ``n`` robots, cheap to make (its per-robot ``pilot_state`` is set by the caller)."""
        raise NotImplementedError

    def _law(self, pilot, x: np.ndarray, mode: np.ndarray, ctx: dict) -> np.ndarray:
        """The pilot's torques [N m] ``(n, 2)`` at model states ``x`` ``(n, 10)``, advancing its state."""
        raise NotImplementedError

    def residuals(self, x: np.ndarray, charged: np.ndarray, ctx: dict) -> np.ndarray:
        """The state's residuals ``(n, H, n_residuals)`` at the plan's states ``x`` ``(n, H, 10)``; ``charged`` ``(n, H)``:
        the subclass's mask of ``_charged``; ``ctx``: per-robot context, each ``(n, 1)``."""
        raise NotImplementedError

    def _charged(self, modes: np.ndarray) -> np.ndarray:
        """A per-step mask ``(n, H)`` from the plan's modes ``(n, H + 1)`` that ``residuals`` reads."""
        return modes[:, 1:] == _contact.FLIGHT

    def _penalty(self, roll: dict, ctx: dict) -> np.ndarray:
        """The penalty ``(n, H)`` of the plan's steps (no derivative)."""
        raise NotImplementedError

    def _track(self, roll: dict, ctx: dict) -> None:
        """Bookkeeping of a rolled-out plan (its ``modes`` and each step's ``flight_time``) that the cost reads;
        nothing by default."""

    def _load(self, t: int, ctx: dict):
        """The horizontal force on the torso over the plan's step ``t`` (``hybrid_step``'s ``load_x``): none."""
        return 0.0

    terminal_weight = 1.0

    # ---- the state from the observation

    def state(self, obs: np.ndarray):
        """``(q, qd, mode)`` of the robots of observations ``(N, >=18)``, the contact point at ``x = 0``.

        The state is projected on its contact (float32 rounding puts a foot a little off the ground): a foot in
        contact is put on the ground, and a sticking foot at rest.
        """
        p = self.params
        n = obs.shape[0]
        q = np.array(obs[:, Obs.base_x:Obs.q2 + 1], dtype=np.float64)
        qd = np.array(obs[:, Obs.vx_b:Obs.w_q2 + 1], dtype=np.float64)
        contact = obs[:, Obs.contact] > 0.5
        slip = obs[:, Obs.slip]
        mode = np.full(n, _contact.FLIGHT, dtype=np.int64)
        mode[contact & (slip > 0.5)] = _contact.SLIP_FORWARD
        mode[contact & (slip < -0.5)] = _contact.SLIP_BACKWARD
        mode[contact & (np.abs(slip) <= 0.5)] = _contact.STICK
        th1, th2 = q[:, 2] + q[:, 3], q[:, 2] + q[:, 3] + q[:, 4]
        w1, w2 = qd[:, 2] + qd[:, 3], qd[:, 2] + qd[:, 3] + qd[:, 4]
        foot_y = foot_position(q, p)[:, 1]
        q[:, 1] -= np.where(contact, foot_y, np.minimum(foot_y, 0.0))  # on the ground, or not below it
        vfx = qd[:, 0] - p.l1 * np.sin(th1) * w1 - p.l2 * np.sin(th2) * w2
        vfy = qd[:, 1] + p.l1 * np.cos(th1) * w1 + p.l2 * np.cos(th2) * w2
        qd[:, 0] -= np.where(mode == _contact.STICK, vfx, 0.0)
        qd[:, 1] -= np.where(contact, vfy, 0.0)
        return q, qd, mode

    def com(self, x: np.ndarray):
        """The whole-body COM ``(x, y)`` and its velocity ``(x', y')`` of states ``x`` ``(..., 10)``."""
        pos, vel = com_state(x[..., :5], x[..., 5:], self.params)
        return pos[..., 0], pos[..., 1], vel[..., 0], vel[..., 1]

    def _observation(self, x, mode, like):
        """The pilot's observation of model states ``x`` (the entries the state does not set as in ``like``)."""
        p = self.params
        obs = np.array(like, dtype=np.float64)
        obs[..., Obs.base_x:Obs.q2 + 1] = x[..., :5]
        obs[..., Obs.vx_b:Obs.w_q2 + 1] = x[..., 5:]
        obs[..., Obs.foot_height] = foot_position(x[..., :5], p)[..., 1]
        obs[..., Obs.contact] = mode != _contact.FLIGHT
        obs[..., Obs.slip] = np.where(mode == _contact.SLIP_FORWARD, 1.0, np.where(mode == _contact.SLIP_BACKWARD, -1.0, 0.0))
        return obs

    # ---- cost

    def _residual_jacobian(self, X, charged, ctx, eps=1e-6):
        """``dr/dx`` ``(n, H, n_residuals, 10)`` by centred differences of the residuals (closed forms, cheap), every
        coordinate's two moved states in one call of ``residuals`` (on a leading axis of 20)."""
        d = eps * np.eye(NX)[:, None, None, :]
        r = self.residuals(np.concatenate([X[None] + d, X[None] - d]), charged, ctx)
        return np.moveaxis((r[:NX] - r[NX:]) / (2 * eps), 0, -1)

    def action_residuals(self, x: np.ndarray, u: np.ndarray):
        """The action's residuals ``(..., 4)`` at states ``x`` ``(..., 10)`` and actions ``u`` ``(..., 2)``: the effort
        ``sqrt(effort_weight) u`` and the joints' positive power ``sqrt(power_weight) max(0, tau_j q_j')`` [W]; and
        their derivatives by ``u`` ``(..., 4, 2)`` and by ``x`` ``(..., 4, 10)``."""
        se, sp = np.sqrt(self.effort_weight), np.sqrt(self.power_weight)
        lim = self.torque_limit
        w = x[..., 8:10]  # the hip's and the knee's rates
        power = lim * u * w
        on = (power > 0.0).astype(np.float64)
        r = np.concatenate([se * u, sp * on * power], axis=-1)
        Ju = np.zeros(u.shape[:-1] + (4, 2))
        Jx = np.zeros(u.shape[:-1] + (4, NX))
        Ju[..., 0, 0] = Ju[..., 1, 1] = se
        Ju[..., 2, 0] = sp * on[..., 0] * lim[0] * w[..., 0]
        Ju[..., 3, 1] = sp * on[..., 1] * lim[1] * w[..., 1]
        Jx[..., 2, 8] = sp * on[..., 0] * lim[0] * u[..., 0]
        Jx[..., 3, 9] = sp * on[..., 1] * lim[1] * u[..., 1]
        return r, Ju, Jx

    def _state_residuals(self, roll, ctx, jacobian: bool = False):
        """The plan's state residuals ``(n, H, k)`` (the last step's weighted by ``terminal_weight``), and with
        ``jacobian`` their derivatives."""
        X = roll["X"][:, 1:]
        charged = self._charged(roll["modes"])
        context = {name: value[:, None] for name, value in ctx.items()}
        r = self.residuals(X, charged, context)
        r[:, -1] *= np.sqrt(self.terminal_weight)
        if not jacobian:
            return r
        Jr = self._residual_jacobian(X, charged, context)
        Jr[:, -1] *= np.sqrt(self.terminal_weight)
        return r, Jr

    def _cost(self, roll, ctx):
        r = self._state_residuals(roll, ctx)
        ra = self.action_residuals(roll["X"][:, :-1], roll["U"])[0]
        return (np.sum(r**2, axis=(1, 2)) + np.sum(ra**2, axis=(1, 2))
                + self.smooth_weight * np.sum(roll["V"] ** 2, axis=(1, 2)) + np.sum(self._penalty(roll, ctx), axis=1))

    # ---- the pilot inside the plan

    def _pilot_copy(self, source, copies: int = 1):
        """A pilot in ``source``'s state, its robots repeated ``copies`` times (a batch of plans per robot)."""
        pilot = self._new_pilot(source._n * copies)
        for name in self.pilot_state:
            _set(pilot, name, np.tile(_get(source, name), copies))
        return pilot

    def _law_and_derivative(self, pilot, x, mode, ctx, derivative: bool):
        """The pilot's action (unclipped, in action units) at states ``x`` ``(n, 10)``, advancing ``pilot``; with
        ``derivative`` also its derivative by the state ``(n, 2, 10)`` (centred differences, its discrete state
        held), from the same call of the law (the state itself, then each coordinate moved by +-eps)."""
        n, eps = x.shape[0], self.law_step
        copies = 2 * NX + 1 if derivative else 1
        if copies == 1:
            return self._law(pilot, x, mode, ctx) / self.torque_limit, None
        dx = np.zeros((copies, 1, NX))
        dx[1 + np.arange(NX), 0, np.arange(NX)] = eps
        dx[1 + NX + np.arange(NX), 0, np.arange(NX)] = -eps
        xs = (x[None] + dx).reshape(-1, NX)
        law = self._probe
        for name in self.pilot_state:
            _set(law, name, np.tile(_get(pilot, name), copies))
        tiled = {name: np.tile(value, (copies,) + (1,) * (value.ndim - 1)) for name, value in ctx.items()}
        tau = self._law(law, xs, np.tile(mode, copies), tiled)
        tau = tau.reshape(copies, n, NU) / self.torque_limit
        for name in self.pilot_state:  # the pilot advanced by the state's own row
            _set(pilot, name, _get(law, name)[:n].copy())
        dpi = np.moveaxis((tau[1:1 + NX] - tau[1 + NX:]) / (2 * eps), 0, -1)  # (n, 2, 10)
        return tau[0], dpi

    def clip_derivative(self, z: np.ndarray) -> np.ndarray:
        """The backward pass's derivative of ``clip(z, -1, 1)``: 1 where ``|z| <= 1 - w``, 0 where ``|z| >= 1``, a
        smoothstep between (``w = clip_smoothing``; 0: the clip's own 0 or 1).

        A pilot that scales its torques exactly onto the limit (the hopper's push) sits where the clip's derivative
        is 1 on one side and 0 on the other: a rounding decided which, and with it the plan's gains, so that the law
        jumped under any perturbation of the state. The band gives a step at the limit no authority (a correction
        cannot raise a saturated torque) and fades it in continuously inside.
        """
        w = self.clip_smoothing
        if w == 0.0:
            return (np.abs(z) < 1.0).astype(np.float64)
        s = np.clip((1.0 - np.abs(z)) / w, 0.0, 1.0)
        return s * s * (3.0 - 2.0 * s)

    # ---- the model

    def _rollout(self, source, q, qd, mode, ctx, V, nominal=None, k=None, K=None, jacobians=False, copies=1):
        """Roll the pilot (from ``source``'s state) plus the corrections ``V`` ``(n, H, 2)`` (or the nominal's plus
        ``k + K dx``) out on the simulator; with ``jacobians`` also the closed loop's ``A``, ``B`` and the action's
        derivatives."""
        n, H = V.shape[0], self.horizon
        p, mu = self.params, self.config.mu
        pilot = self._pilot_copy(source, copies)
        X = np.empty((n, H + 1, NX))
        X[:, 0, :5], X[:, 0, 5:] = q, qd
        modes = np.empty((n, H + 1), dtype=np.int64)
        modes[:, 0] = mode
        U, Vt = np.empty_like(V), np.empty_like(V)
        out = dict(X=X, modes=modes, U=U, V=Vt, flight_time=np.empty((n, H)))
        if jacobians:
            out.update(A=np.empty((n, H, NX, NX)), B=np.empty((n, H, NX, NU)), Du=np.empty((n, H, NU, NX)),
                       D=np.empty((n, H, NU)))
        for t in range(H):
            v = V[:, t]
            if k is not None:
                v = v + k[:, t] + np.einsum("nij,nj->ni", K[:, t], X[:, t] - nominal[:, t])
            pi, dpi = self._law_and_derivative(pilot, X[:, t], mode, ctx, jacobians)
            u = np.clip(pi + v, -1.0, 1.0)
            Vt[:, t], U[:, t] = v, u
            tau = u * self.torque_limit
            load = self._load(t, ctx)
            if jacobians:
                J = hybrid_step_jacobians(X[:, t, :5], X[:, t, 5:], tau, p, mu, mode, None, load_x=load, **self._step_args)
                r = J.step
                bad = (J.undefined != 0)[:, None, None]
                D = self.clip_derivative(pi + v)
                Bt = np.where(bad, 0.0, J.B * self.torque_limit) * D[:, None, :]
                out["A"][:, t] = np.where(bad, np.eye(NX), J.A) + Bt @ dpi
                out["B"][:, t] = Bt
                out["Du"][:, t] = D[:, :, None] * dpi
                out["D"][:, t] = D
            else:
                r = hybrid_step(X[:, t, :5], X[:, t, 5:], tau, p, mu, mode, None, load_x=load, **self._step_args)
            X[:, t + 1, :5], X[:, t + 1, 5:] = r.q, r.qd
            mode = modes[:, t + 1] = r.mode
            out["flight_time"][:, t] = r.flight_time
        self._track(out, ctx)
        return out

    # ---- iLQR

    def _backward(self, roll, ctx):
        """Gains ``k`` ``(n, H, 2)``, ``K`` ``(n, H, 2, 10)`` of one Gauss-Newton iLQR backward pass on the
        corrections (the pilot's feedback inside ``A``; compiled: ``leg_env._core.kernels.ilqr_backward``).

        At each step from the last, with ``V_x``, ``V_xx`` the cost-to-go's expansion after it and ``l_x``,
        ``l_xx`` the state residuals' (``J_r^T r``, ``J_r^T J_r``) at the state it reaches, the action's residuals
        ``r_a`` with their derivatives through ``u = clip(pi(x) + v)`` (``J_v = J_u D``, ``J_x = J_u D dpi/dx + J_ax``):
        ``Q_x = A^T v_x + J_x^T r_a``, ``Q_v = B^T v_x + J_v^T r_a + w_s v``, ``Q_xx = A^T v_xx A + J_x^T J_x``,
        ``Q_vv = B^T v_xx B + J_v^T J_v + (w_s + regularisation) I``, ``Q_vx = B^T v_xx A + J_v^T J_x``
        (``v_x = l_x + V_x``, ``v_xx = l_xx + V_xx``); ``k = -Q_vv^-1 Q_v``, ``K = -Q_vv^-1 Q_vx`` (solved); then
        ``V_x = Q_x + K^T (Q_vv k + Q_v) + Q_vx^T k``, ``V_xx = Q_xx + K^T Q_vv K + K^T Q_vx + Q_vx^T K``, symmetrised.
        """
        r, Jr = self._state_residuals(roll, ctx, jacobian=True)
        lx = np.einsum("nhri,nhr->nhi", Jr, r)  # half the cost's derivatives, of the state after each step
        lxx = np.einsum("nhri,nhrj->nhij", Jr, Jr)
        return self._gains(roll, lx, lxx)

    def _gains(self, roll, lx, lxx):
        """``_backward``'s pass from the state cost's half gradient ``lx`` ``(n, H, 10)`` and Gauss-Newton Hessian
        ``lxx`` ``(n, H, 10, 10)`` at the state after each step."""
        V = roll["V"]
        n, H = V.shape[:2]
        k, K = np.empty((n, H, NU)), np.empty((n, H, NU, NX))
        flat = lambda a: np.ascontiguousarray(a, dtype=np.float64).reshape(n, -1)  # noqa: E731
        kernels.ilqr_backward(flat(lx), flat(lxx), flat(roll["A"]), flat(roll["B"]), flat(roll["D"]), flat(roll["Du"]),
                              flat(roll["X"]), flat(roll["U"]), flat(V), self.effort_weight, self.power_weight,
                              self.smooth_weight, self.regularisation, self.torque_limit[None], k.reshape(n, -1),
                              K.reshape(n, -1))
        return k, K

    def _plan_actions(self, source, q, qd, mode, ctx, V):
        """The first actions ``(n, 2)`` of the plans of ``iterations`` of iLQR from the pilot ``source``'s state and
        the corrections ``V`` (updated with the plan's shifted by a step); sets ``cost``, ``planned`` and ``pick``."""
        if not self.warm_start:
            V[:] = 0.0
        plan = V
        n = len(q)
        for _ in range(self.iterations):
            pick = np.full(n, -1)  # the line search's choice (-1: the plan it started from)
            roll = self._rollout(source, q, qd, mode, ctx, plan, jacobians=True)
            best_cost = self._cost(roll, ctx)
            best_V, best_U, best_X, best_M = roll["V"], roll["U"], roll["X"], roll["modes"]
            k, K = self._backward(roll, ctx)
            if self.steps:  # every step length's plan in one batch, robot-major within each length
                S = len(self.steps)
                tile = lambda a: np.tile(a, (S,) + (1,) * (a.ndim - 1))  # noqa: E731
                scale = np.repeat(np.asarray(self.steps), n)[:, None, None]
                tiled = {name: tile(value) for name, value in ctx.items()}
                trial = self._rollout(source, tile(q), tile(qd), tile(mode), tiled, tile(roll["V"]),
                                      nominal=tile(roll["X"]), k=scale * tile(k), K=tile(K), copies=S)
                costs = self._cost(trial, tiled).reshape(S, n)
                for i in range(S):
                    cost = costs[i]
                    rows = slice(i * n, (i + 1) * n)
                    better = cost < best_cost if self.hold_pick is None else self.hold_pick == i
                    pick[better] = i
                    best_cost = np.where(better, cost, best_cost)
                    best_V = np.where(better[:, None, None], trial["V"][rows], best_V)
                    best_U = np.where(better[:, None, None], trial["U"][rows], best_U)
                    best_X = np.where(better[:, None, None], trial["X"][rows], best_X)
                    best_M = np.where(better[:, None], trial["modes"][rows], best_M)
            plan = best_V
            self.pick = pick
        V[:, :-1] = best_V[:, 1:]
        V[:, -1] = 0.0
        self.cost, self.planned = best_cost, best_X
        self._chosen = dict(V=best_V, X=best_X, K=K, modes=best_M)
        return best_U[:, 0].copy()

    # ---- replanning every few control steps

    def _allocate_held(self, n: int) -> None:
        """The plans held between replans (``replan_every``): the corrections, states and feedback gains."""
        H = self.horizon
        self._since = np.full(n, self.replan_every)  # control steps since each robot's plan (at least replan_every: plan now)
        self.plans = 0  # plans made (a robot each)
        self._held = dict(V=np.zeros((n, H, NU)), X=np.zeros((n, H + 1, NX)), K=np.zeros((n, H, NU, NX)),
                          modes=np.zeros((n, H + 1), dtype=np.int64))

    def _due(self, mode: np.ndarray) -> np.ndarray:
        """The robots that plan at this control step: ``replan_every`` steps after their last plan, or sooner where
        the contact mode is not the plan's (an event came at another step than planned)."""
        due = self._since + 1 >= self.replan_every
        if self.replan_every > 1:
            j = np.minimum(self._since + 1, self.horizon)
            due |= mode != self._held["modes"][np.arange(len(mode)), j]
        self.plans += int(due.sum())
        return due

    def _hold(self, rows: np.ndarray) -> None:
        """Keep the plans just made for ``rows`` (``_plan_actions``' chosen ones)."""
        if self.replan_every > 1 and rows.any():
            for name, value in self._chosen.items():
                self._held[name][rows] = value
        self._since[rows] = 0

    def _follow_held(self, rows: np.ndarray, x: np.ndarray, pi: np.ndarray) -> np.ndarray:
        """Actions of the robots ``rows`` between their plans, at states ``x`` ``(n, 10)`` with the pilot's actions
        ``pi`` there: the held plan's correction at this step plus its feedback on the state's departure from it,
        ``clip(pi + v_j + K_j (x - x_j), -1, 1)`` (the base's ``x`` left out: its frame moves with the contact point)."""
        r = np.flatnonzero(rows)
        j = self._since[r] + 1
        dx = x - self._held["X"][r, j]
        dx[:, 0] = 0.0
        v = self._held["V"][r, j] + np.einsum("nij,nj->ni", self._held["K"][r, j], dx)
        self._since[r] = j
        return np.clip(pi + v, -1.0, 1.0)

    def _pilot_rows(self, source, rows: np.ndarray):
        """A pilot in ``source``'s state at ``rows`` only."""
        pilot = self._new_pilot(int(rows.sum()))
        for name in self.pilot_state:
            _set(pilot, name, np.array(_get(source, name)[rows]))
        return pilot

    def act(self, batch: np.ndarray) -> np.ndarray:
        return self.exact_actions(batch).astype(np.float32)

    def exact_actions(self, batch: np.ndarray) -> np.ndarray:
        """``act``'s actions in float64, before their rounding to float32 (for the closed loop's derivatives)."""
        raise NotImplementedError

    @staticmethod
    def _check_finite(batch: np.ndarray) -> None:
        bad = ~np.isfinite(batch).all(axis=1)
        if bad.any():
            raise ValueError(f"observation must be finite: rows {np.flatnonzero(bad)[:5].tolist()} are not")
