"""The check both model-predictive controllers' tests make of the iLQR's backward pass (``policies.ilqr``): the chain
of the closed loop's ``A`` and ``B`` gives the plan cost's gradient by the corrections that centred differences of
the rolled-out cost give."""

from __future__ import annotations

import numpy as np


def checked_gradients(mpc, source, q, qd, mode, ctx, seed: int = 0) -> int:
    """Compare the adjoint gradient of half the plan's cost by the corrections at plan steps 0, 5, 15 and 30 with
    centred differences (steps 1e-5, then 1e-6 where the first straddles a change of the plan's events); returns how
    many robots' entries were compared with the same events on both sides. ``mpc`` needs ``clip_smoothing=0`` (the
    clip's own derivative: then the chain is the rolled-out cost's exact gradient) and a horizon above 30.

    Raises:
        AssertionError: an entry whose differences and adjoint disagree at both steps.
    """
    n = len(q)
    rng = np.random.default_rng(seed)
    V = 0.02 * rng.standard_normal((n, mpc.horizon, 2))
    roll = mpc._rollout(source, q, qd, mode, ctx, V, jacobians=True)

    def cost(V):
        r = mpc._rollout(source, q, qd, mode, ctx, V)
        return mpc._cost(r, ctx), r["modes"]

    # the adjoint: half the cost's gradient by the corrections, through A and B
    r, Jr = mpc._state_residuals(roll, ctx, jacobian=True)
    lx = np.einsum("nhri,nhr->nhi", Jr, r)
    ws = mpc.smooth_weight
    grad = np.zeros_like(V)
    lam = np.zeros((n, 10))
    for t in range(V.shape[1] - 1, -1, -1):
        lam = lam + lx[:, t]
        ra, Ju, Jx = mpc.action_residuals(roll["X"][:, t], roll["U"][:, t])
        Jv, Jx = Ju * roll["D"][:, t, None, :], Ju @ roll["Du"][:, t] + Jx  # through u = clip(pi(x) + v)
        grad[:, t] = np.einsum("nji,nj->ni", roll["B"][:, t], lam) + np.einsum("nji,nj->ni", Jv, ra) + ws * V[:, t]
        lam = np.einsum("nji,nj->ni", roll["A"][:, t], lam) + np.einsum("nji,nj->ni", Jx, ra)
    checked = 0
    for t in (0, 5, 15, 30):
        for j in range(2):
            for h in (1e-5, 1e-6):
                Vp, Vm = V.copy(), V.copy()
                Vp[:, t, j] += h
                Vm[:, t, j] -= h
                (cp, mp), (cm, mm) = cost(Vp), cost(Vm)
                fd = (cp - cm) / (4 * h)  # half the cost, as the backward pass
                same = (mp == roll["modes"]).all(axis=1) & (mm == roll["modes"]).all(axis=1)
                ok = np.abs(fd - grad[:, t, j]) <= 1e-4 * (1.0 + np.abs(grad[:, t, j]))
                if (ok | ~same).all():
                    checked += same.sum()
                    break
            else:
                raise AssertionError(f"step {t}, action {j}: differences {fd}, adjoint {grad[:, t, j]}")
    return checked


def checked_backward(mpc, source, q, qd, mode, ctx, seed: int = 0) -> float:
    """The compiled backward pass (``PilotILQR._backward``, ``kernels.ilqr_backward``) against the numpy pass of
    ``tests/ilqr_ref.py`` on a plan with random corrections: the largest difference of the gains ``k`` and ``K``,
    relative to each's largest entry."""
    from ilqr_ref import backward

    V = 0.05 * np.random.default_rng(seed).standard_normal((len(q), mpc.horizon, 2))
    roll = mpc._rollout(source, q, qd, mode, ctx, V, jacobians=True)
    k, K = mpc._backward(roll, ctx)
    k_ref, K_ref = backward(mpc, roll, ctx)
    assert np.isfinite(k_ref).all() and np.abs(k_ref).max() > 0.0
    return max(float(np.abs(k - k_ref).max() / np.abs(k_ref).max()), float(np.abs(K - K_ref).max() / np.abs(K_ref).max()))
