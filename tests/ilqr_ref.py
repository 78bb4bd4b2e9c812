"""The tests' reference of the iLQR backward pass (``policies.ilqr.PilotILQR._backward``, compiled in
``leg_env/_core/plan.c``): the same Gauss-Newton pass in numpy, batched over the robots, step by step from the plan's
end."""

from __future__ import annotations

import numpy as np


def backward(mpc, roll, ctx):
    """Gains ``k`` ``(n, H, 2)``, ``K`` ``(n, H, 2, 10)`` of one Gauss-Newton iLQR backward pass on the corrections of
    the controller ``mpc`` (a ``PilotILQR``): the numpy pass its compiled one (``kernels.ilqr_backward``) is held to."""
    r, Jr = mpc._state_residuals(roll, ctx, jacobian=True)
    lx = np.einsum("nhri,nhr->nhi", Jr, r)  # half the cost's derivatives, of the state after each step
    lxx = np.einsum("nhri,nhrj->nhij", Jr, Jr)
    return gains(mpc, roll, lx, lxx)


def gains(mpc, roll, lx, lxx):
    """``backward``'s pass from the state cost's half gradient ``lx`` ``(n, H, 10)`` and Hessian ``lxx``
    ``(n, H, 10, 10)`` (``PilotILQR._gains``'s reference)."""
    X, U, V = roll["X"], roll["U"], roll["V"]
    n, H = V.shape[:2]
    ws = mpc.smooth_weight
    D, Du = roll["D"], roll["Du"]  # u = clip(pi(x) + v): du/dv = D, du/dx = D dpi/dx
    Vx = np.zeros((n, 10))
    Vxx = np.zeros((n, 10, 10))
    k = np.zeros((n, H, 2))
    K = np.zeros((n, H, 2, 10))
    eye = np.eye(2)
    for t in range(H - 1, -1, -1):
        vx = lx[:, t] + Vx
        vxx = lxx[:, t] + Vxx
        At, Bt, Dt, Dxt, ut = roll["A"][:, t], roll["B"][:, t], D[:, t], Du[:, t], U[:, t]
        ra, Jau, Jax = mpc.action_residuals(X[:, t], ut)
        Jv = Jau * Dt[:, None, :]  # through u = clip(pi(x) + v)
        Jx = Jau @ Dxt + Jax
        JvT, JxT = np.swapaxes(Jv, 1, 2), np.swapaxes(Jx, 1, 2)
        Qx = np.einsum("nji,nj->ni", At, vx) + np.einsum("nij,nj->ni", JxT, ra)
        Qu = np.einsum("nji,nj->ni", Bt, vx) + np.einsum("nij,nj->ni", JvT, ra) + ws * V[:, t]
        VB = vxx @ Bt
        Qxx = np.swapaxes(At, 1, 2) @ vxx @ At + JxT @ Jx
        Quu = np.swapaxes(Bt, 1, 2) @ VB + JvT @ Jv + (ws + mpc.regularisation) * eye
        Qux = np.swapaxes(VB, 1, 2) @ At + JvT @ Jx
        kt = -np.linalg.solve(Quu, Qu[..., None])[..., 0]
        Kt = -np.linalg.solve(Quu, Qux)
        k[:, t], K[:, t] = kt, Kt
        KtT = np.swapaxes(Kt, 1, 2)
        Vx = Qx + np.einsum("nij,nj->ni", KtT, np.einsum("nij,nj->ni", Quu, kt) + Qu) + np.einsum("nji,nj->ni", Qux, kt)
        Vxx = Qxx + KtT @ Quu @ Kt + KtT @ Qux + np.swapaxes(Qux, 1, 2) @ Kt
        Vxx = 0.5 * (Vxx + np.swapaxes(Vxx, 1, 2))
    return k, K


def clocks(min_flight: float, dt: float, modes: np.ndarray, flight_time: np.ndarray, ground: np.ndarray):
    """``policies.mpc.HopMPC._track``'s clocks counted step by step: the time on the ground since the last hop (a
    flight of at least ``min_flight``, counted from the plan's start) and in the current stance, ``(n, H + 1)``
    each, from the plan's modes ``(n, H + 1)``, each step's time in flight ``(n, H)`` and the time on the ground at
    its start ``(n,)``."""
    n, H = flight_time.shape
    ground_time, stance_time = np.empty((n, H + 1)), np.empty((n, H + 1))
    ground_time[:, 0] = ground
    stance_time[:, 0] = np.where(modes[:, 0] == 3, 0.0, ground)
    run = np.zeros(n)
    for t in range(H):
        flying = modes[:, t + 1] == 3
        run = np.where(flying, run + flight_time[:, t], 0.0)
        hopped = flying & (run >= min_flight)
        ground_time[:, t + 1] = np.where(hopped, 0.0, ground_time[:, t] + dt)
        stance_time[:, t + 1] = np.where(flying, 0.0, stance_time[:, t] + dt)
    return ground_time, stance_time
