"""The control step as a differentiable torch operation: rollouts whose gradients are the exact Jacobians.

``hybrid_step`` and ``stance_step`` here take the state ``x = (q, qd)`` as a float64 torch tensor ``(N, 10)`` and the
torques ``(N, 2)``, step them in the compiled core and return the next state as a tensor whose backward pass applies
the step's Jacobians (``leg_env.physics.derivatives``): ``dL/dx = dL/dx+ A`` and ``dL/dtau = dL/dx+ B``. A rollout
that feeds a policy's torques through several steps is then differentiable end to end, through touchdowns and
lift-offs, for first-order policy gradients or trajectory optimisation::

    x, mode = x0, None
    for t in range(T):
        x, step = hybrid_step(x, policy(x), p, mu, mode=mode)
        mode = step.mode
        loss = loss + cost(x)
    loss.backward()

The contact mode and the anchor are carried from step to step as plain arrays (they are discrete, or follow the
foot); a robot whose step has no derivative (``HybridJacobians.undefined``) passes NaN gradients back. torch is
imported when this module is.
"""

from __future__ import annotations

import numpy as np
import torch

from .physics import derivatives
from .physics.params import LegParams

__all__ = ["hybrid_step", "stance_step"]


class _Step(torch.autograd.Function):
    """x+ = step(x, tau); the backward pass is the step's Jacobians, saved by the forward pass."""

    @staticmethod
    def forward(ctx, x, tau, run):
        x_next, A, B = run(x.detach().cpu().numpy(), tau.detach().cpu().numpy())
        ctx.save_for_backward(torch.from_numpy(A), torch.from_numpy(B))
        return torch.from_numpy(x_next).to(x.device)

    @staticmethod
    def backward(ctx, grad):
        A, B = ctx.saved_tensors
        g = grad.to(torch.float64).cpu().unsqueeze(-2)  # (N, 1, 10)
        return (g @ A).squeeze(-2).to(grad.device), (g @ B).squeeze(-2).to(grad.device), None


def _checked(x: torch.Tensor, tau: torch.Tensor) -> None:
    if not (isinstance(x, torch.Tensor) and isinstance(tau, torch.Tensor)):
        raise TypeError(f"x and tau must be torch tensors, got {type(x).__name__} and {type(tau).__name__}")
    if x.dtype != torch.float64 or tau.dtype != torch.float64:
        raise ValueError(f"x and tau must be float64 (the step's arithmetic), got {x.dtype} and {tau.dtype}")
    if x.ndim != 2 or x.shape[1] != derivatives.NX or tau.shape != (x.shape[0], 2):
        raise ValueError(f"x must be (N, 10) and tau (N, 2), got {tuple(x.shape)} and {tuple(tau.shape)}")


def hybrid_step(x: torch.Tensor, tau: torch.Tensor, p: LegParams, mu, mode=None, anchor_x=None, **step_rule):
    """``leg_env.physics.hybrid.hybrid_step`` on ``x = (q, qd)``, differentiable in ``x`` and ``tau``.

    Args:
        x: ``(N, 10)`` float64 states; tau: ``(N, 2)`` float64 torques [N m].
        p, mu, mode, anchor_x, step_rule (``dt``, ``substeps``, ``max_angle``, ``load_x``): as ``hybrid_step``.

    Returns:
        ``(x_next, step)``: the next states ``(N, 10)`` (in the autograd graph) and the ``HybridStep`` (its mode and
        anchor_x to carry into the next step).
    """
    _checked(x, tau)
    out = {}

    def run(x_np, tau_np):
        J = derivatives.hybrid_step_jacobians(x_np[:, :5], x_np[:, 5:], tau_np, p, mu, mode=mode, anchor_x=anchor_x, **step_rule)
        out["step"] = J.step
        return np.concatenate([J.step.q, J.step.qd], axis=1), J.A, J.B

    x_next = _Step.apply(x, tau, run)
    return x_next, out["step"]


def stance_step(x: torch.Tensor, tau: torch.Tensor, p: LegParams, anchor=None, **step_rule):
    """``leg_env.physics.integrate.stance_step`` (the foot pinned) on ``x = (q, qd)``, differentiable in ``x`` and
    ``tau``; ``anchor=None``: the foot of ``x``, following it. Returns ``(x_next, lam_mean)``."""
    _checked(x, tau)
    out = {}

    def run(x_np, tau_np):
        J = derivatives.stance_step_jacobians(x_np[:, :5], x_np[:, 5:], tau_np, p, anchor=anchor, **step_rule)
        out["lam"] = J.lam_mean
        return np.concatenate([J.q, J.qd], axis=1), J.A, J.B

    x_next = _Step.apply(x, tau, run)
    return x_next, out["lam"]
