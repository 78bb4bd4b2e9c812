"""First-order against zeroth-order policy gradients on exact rigid contact, as a function of the horizon.

    .venv/bin/python benchmarks/bench_policy_gradient.py

The question of Suh, Simchowitz, Zhang and Tedrake ("Do differentiable simulators give better policy gradients?",
ICML 2022), asked of the exact hybrid step. A linear feedback policy ``tau = tau_hold + limit tanh(K (x - x_eq) / limit)``
on the minimal state ``x = (th_b, q1, q2, th_b', q1', q2')``, its gain ``K`` the discrete LQR's of the stance
linearised by the step's own Jacobians, acts with Gaussian noise ``sigma`` on each torque, as PPO's policy explores.
The objective is the expected cost over ``H`` control steps, ``J(K) = E[sum_t c(x_t, tau_t)]``, ``c`` quadratic in the
deviation from the equilibrium and in the torque. Two estimators of ``dJ/dK`` from the same N rollouts:

* zeroth order (the likelihood ratio, PPO's): ``(C - mean C) sum_t d log pi(tau_t | x_t) / dK``, ``C`` the rollout's cost;
* first order (through the simulator): ``dC/dK`` along the sampled noise, by ``leg_env.autograd.hybrid_step`` (the
  exact Jacobians of every step, through touchdowns and lift-offs).

Two tasks: "stand", starts near the equilibrium on the unilateral ground (noise as the balance task's starts, the
foot sticking throughout); "land", the same robot dropped from 1-3 cm at 0.3-0.8 m/s, so that every rollout lands
(a touchdown, its impact, and a stance after it). For each horizon the table gives each estimator's variance (the
trace of its covariance over the N rollouts, relative to the squared norm of the zeroth-order mean) and the
difference of their means in units of its standard error: both estimate the same gradient where the dynamics are
smooth along the noise. Written to ``benchmarks/results/policy_gradient.md`` and ``policy_gradient.png``.
"""

from __future__ import annotations

import datetime
import os
import platform
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # train.machine

import numpy as np  # noqa: E402
import scipy.linalg  # noqa: E402
import torch  # noqa: E402

from leg_env import __version__  # noqa: E402
from leg_env import autograd  # noqa: E402
from leg_env import physics as dyn  # noqa: E402
from leg_env.physics.params import LegParams  # noqa: E402
from train.machine import cpu_name  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "policy_gradient.md"
FIGURE = ROOT / "benchmarks" / "results" / "policy_gradient.png"
N = 2048  # rollouts per horizon
HORIZONS = (1, 3, 10, 30, 100)
SIGMA = 5.0  # [N m] the exploration noise on each torque
LIMIT = 50.0  # [N m]
MU = 0.8
MINIMAL = [2, 3, 4, 7, 8, 9]  # (th_b, q1, q2) and their rates inside (q, qd)
WEIGHTS = torch.tensor([10.0, 1.0, 1.0, 0.1, 0.1, 0.1], dtype=torch.float64)  # the cost's weights on the minimal state
TORQUE_WEIGHT = 1e-3


def lqr_gain(p: LegParams, q_eq, tau_eq) -> np.ndarray:
    """The discrete LQR gain of the stance, linearised by the step's Jacobians, on the minimal state."""
    J = dyn.stance_step_jacobians(q_eq, np.zeros(5), tau_eq, p, anchor=dyn.foot_position(q_eq, p))
    A, B = J.A[np.ix_(MINIMAL, MINIMAL)], J.B[MINIMAL]
    Q, R = np.diag(WEIGHTS.numpy()), TORQUE_WEIGHT * np.eye(2)
    P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    return np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)


def starts(task: str, p: LegParams, q_eq, rng):
    q = np.tile(q_eq, (N, 1))
    q[:, 2:] += rng.uniform(-0.05, 0.05, (N, 3))
    qd = np.zeros((N, 5))
    qd[:, 2:] = rng.uniform(-0.1, 0.1, (N, 3))
    if task == "stand":
        q, qd = dyn.project_stance(q, qd, p, dyn.foot_position(q, p) * [1.0, 0.0])
        mode = np.full(N, dyn.STICK)
    else:
        q[:, 1] += rng.uniform(0.01, 0.03, N) - dyn.foot_position(q, p)[:, 1]
        qd[:, 1] = -rng.uniform(0.3, 0.8, N)
        mode = np.full(N, dyn.FLIGHT)
    return np.concatenate([q, qd], axis=1), mode


def estimates(task: str, H: int, K0: np.ndarray, p: LegParams, q_eq, tau_eq, rng):
    """Per-rollout first- and zeroth-order gradients (N, 12) of the cost over H steps by the gain, and the events."""
    x0, mode0 = starts(task, p, q_eq, rng)
    noise = torch.tensor(rng.normal(0.0, SIGMA, (H, N, 2)))
    K = torch.tensor(K0, requires_grad=True)
    x_eq = torch.tensor(np.r_[q_eq, np.zeros(5)][MINIMAL])
    x, mode, events = torch.tensor(x0), mode0, 0
    alive = torch.ones(N, dtype=torch.bool)  # a rollout that falls (or leaves the step's domain) is set aside
    rest = torch.tensor(np.r_[q_eq, np.zeros(5)])  # what a set-aside rollout steps from (its gradient is not read)
    cost = torch.zeros(N, dtype=torch.float64)
    score = torch.zeros((N, 2, 6), dtype=torch.float64)  # sum_t d log pi / dK, rollout by rollout
    means, local = [], []  # each step's mean torque, and its own derivative by K at the step's state
    for t in range(H):
        dev = x[:, MINIMAL] - x_eq
        inner = torch.tanh(-(dev @ K.T) / LIMIT)
        mean = torch.tensor(tau_eq) + LIMIT * inner
        mean.retain_grad()
        tau = mean + noise[t]
        # d mean_j / dK_jk at this state = -(1 - tanh_j^2) dev_k; d log pi / dK = noise / sigma^2 . d mean / dK
        d_mean = (-(1.0 - inner.detach() ** 2))[:, :, None] * dev.detach()[:, None, :]
        score = score + (noise[t] / SIGMA**2)[:, :, None] * d_mean
        means.append(mean)
        local.append(d_mean)
        x, step = autograd.hybrid_step(x, tau, p, MU, mode=mode)
        mode, events = step.mode, events + int(step.events[alive.numpy()].sum())
        ok = torch.isfinite(x).all(axis=1) & (x[:, 2].abs() < 1.0)
        alive = alive & ok
        x = torch.where(alive[:, None], x, rest)
        mode = np.where(alive.numpy(), mode, dyn.STICK)
        cost = cost + (WEIGHTS * (x[:, MINIMAL] - x_eq) ** 2).sum(axis=1) + TORQUE_WEIGHT * (tau**2).sum(axis=1)
    # first order, rollout by rollout: the rollouts are independent, so one backward pass of the summed cost gives
    # each rollout's dC/d(mean_t); through the states it carries every later step's dependence (backpropagation through
    # time), and dC/dK sums it against each step's own d mean_t / dK
    cost.sum().backward()
    first = sum(m.grad[:, :, None] * d for m, d in zip(means, local)).reshape(N, 12)
    keep = alive.numpy() & np.isfinite(first.detach().numpy()).all(axis=1)  # and a step with no derivative (flagged)
    C = cost.detach()[keep]
    zeroth = ((C - C.mean())[:, None, None] * score.detach()[keep]).reshape(-1, 12)
    return first.detach().numpy()[keep], zeroth.numpy(), events / N, C.mean().item(), keep.mean()


def main() -> None:
    torch.set_num_threads(1)
    p = LegParams()
    q_eq, tau_eq, _ = dyn.static_equilibrium(p)
    K0 = lqr_gain(p, q_eq, tau_eq)
    rng = np.random.default_rng(2026)
    rows, curves = [], {}
    for task in ("stand", "land"):
        for H in HORIZONS:
            print(task, H, flush=True)
            first, zeroth, events, mean_cost, kept = estimates(task, H, K0, p, q_eq, tau_eq, rng)
            scale = np.sum(zeroth.mean(axis=0) ** 2)
            var_first = np.trace(np.cov(first.T)) / scale
            var_zeroth = np.trace(np.cov(zeroth.T)) / scale
            diff = first.mean(axis=0) - zeroth.mean(axis=0)
            se = np.sqrt((first.var(axis=0) + zeroth.var(axis=0)) / len(first))
            gap = float(np.max(np.abs(diff) / se))
            curves.setdefault(task, []).append((H, var_first, var_zeroth))
            rows.append(f"| {task} | {H} | {kept:.1%} | {events:.2f} | {mean_cost:.3g} | {var_first:.3g} | {var_zeroth:.3g} | "
                        f"{var_zeroth / var_first:.3g} | {gap:.2f} |")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4), sharey=True)
    for ax, task in zip(axes, ("stand", "land")):
        H, vf, vz = np.array(curves[task]).T
        ax.loglog(H, vz, "o-", label="zeroth order (likelihood ratio)")
        ax.loglog(H, vf, "s-", label="first order (exact Jacobians)")
        ax.set_title(task)
        ax.set_xlabel("horizon [control steps]")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("variance / |mean gradient|^2")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(FIGURE, dpi=90)
    machine = (f"{cpu_name()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}; Python "
               f"{platform.python_version()}; leg-env {__version__}, numpy {np.__version__}, torch {torch.__version__}")
    lines = [
        "# First-order and zeroth-order policy gradients",
        "",
        f"Written by `python benchmarks/bench_policy_gradient.py` on {datetime.date.today().isoformat()}.",
        "",
        f"Machine: {machine}",
        "",
        f"{N} rollouts per row of a linear policy (the discrete LQR gain, torques squashed by tanh to 50 N m) with "
        f"Gaussian noise of {SIGMA:g} N m on each torque, on the unilateral ground (mu {MU}); the cost is quadratic in "
        "the minimal state's deviation and in the torque. Variance: the trace of each estimator's covariance over the "
        "rollouts, over the squared norm of the zeroth-order mean (smaller is better: the rollouts a gradient step needs "
        "scale with it). Ratio: zeroth-order variance over first-order. Gap: the largest difference of the two means "
        "over their standard error (about 3 or less where they agree, over 12 entries). A rollout that falls (the torso "
        "past 1 rad) is set aside from both estimators; kept: the share that is not.",
        "",
        "| task | horizon | rollouts kept | events per rollout | mean cost | first-order variance | zeroth-order variance | ratio | gap |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
        *rows,
        "",
        "![variance against the horizon](policy_gradient.png)",
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    RESULTS.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
