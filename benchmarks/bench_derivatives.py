"""Cost of the step's Jacobians (``leg_env.physics.derivatives``) beside the step and beside finite differences, in
one run.

    .venv/bin/python benchmarks/bench_derivatives.py

For each model (the pinned foot, flight, and the unilateral ground standing and hopping) and a batch of ``N`` robots,
one thread, the compiled kernels called directly:

* the step: ``kernels.rk4_step`` (what ``stance_step`` and the pinned task run) or ``kernels.hybrid_step`` (what
  ``hybrid_step`` and the unilateral tasks run);
* the step with ``A`` and ``B``: ``kernels.rk4_jacobians`` or ``kernels.hybrid_jacobians``; and with ``P`` too (the
  derivative by the robot's eleven parameters and the friction coefficient);
* forward differences of ``A`` and ``B``: the step on the 13 N states of the batch and its 12 one-sided perturbations
  (10 state entries, 2 torques) in one call, then the differences;
* centred differences: the step on 25 N states (each direction perturbed both ways) in one call, then the differences.

The pinned foot and flight start near the nominal posture (angles N(0, 0.05 rad), rates N(0, 0.3), holding torques
plus U(-5, 5) N m). The unilateral ground's batches are states of rollouts of ``PlanarLegBalance-v1`` under the gated
controller ("standing": few events) and of ``PlanarLegHop-v4`` under the hopper ("hopping": a touchdown or a lift-off
in some of the steps), each robot with the torques the controller gave it there.

Every figure is the median over ``REPEATS`` round-robin repeats of the time per robot; each ratio is the median of its
ratio within a repeat. The bar: ``A`` and ``B`` together at most 8 times the step. The table is printed and written
to ``benchmarks/results/derivatives.md``.
"""

from __future__ import annotations

import datetime
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import platform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # train.machine and the controllers (policies)

import numpy as np  # noqa: E402

from leg_env import __version__  # noqa: E402
from leg_env._core import kernels  # noqa: E402
from leg_env.physics import foot_position, project_stance, static_equilibrium  # noqa: E402
from leg_env.physics.params import LegParams  # noqa: E402
from train.machine import cpu_name  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "derivatives.md"
N = 4096
REPEATS = 9
CALLS = 5  # timed calls per repeat and case
DT, SUBSTEPS, MAX_ANGLE = 0.01, 2, 0.02
EPS = 1e-6
BAR = 8.0


def states(p: LegParams, stance: bool, rng):
    q_eq, tau_eq, _ = static_equilibrium(p)
    q = q_eq + np.concatenate([np.zeros((N, 2)), rng.normal(0.0, 0.05, (N, 3))], axis=1)
    qd = rng.normal(0.0, 0.3, (N, 5))
    if stance:
        q, qd = project_stance(q, qd, p, np.zeros(2))
    tau = tau_eq + rng.uniform(-5.0, 5.0, (N, 2))
    return np.ascontiguousarray(q), np.ascontiguousarray(qd), tau


def perturbed(q, qd, tau, sides: int):
    """The batch and its perturbations, for one call of the step: rows [base, +e_0 .. +e_11 (, -e_0 .. -e_11)] of
    (q, qd, tau); returns their q, qd, tau and the number of copies."""
    k = 1 + 12 * sides
    x = np.tile(np.concatenate([q, qd, tau], axis=1), (k, 1)).reshape(k, N, 12)
    for j in range(12):
        x[1 + j, :, j] += EPS
        if sides == 2:
            x[13 + j, :, j] -= EPS
    x = x.reshape(k * N, 12)
    return np.ascontiguousarray(x[:, :5]), np.ascontiguousarray(x[:, 5:10]), np.ascontiguousarray(x[:, 10:]), k


def differenced(qq, vv, k: int, sides: int):
    """Forward (sides 1) or centred (2) differences of the stepped copies."""
    y = np.concatenate([qq, vv], axis=1).reshape(k, N, 10)
    if sides == 1:
        return (y[1:] - y[0]) / EPS
    return (y[1:13] - y[13:]) / (2 * EPS)


def cases(p: LegParams, stance: bool, q, qd, tau):
    P = p.array
    anchor = foot_position(q, p)

    def step():
        qq, vv, lam = q.copy(), qd.copy(), np.empty((N, 2))
        kernels.rk4_step(qq, vv, tau, P, np.zeros(N), anchor, DT, SUBSTEPS, MAX_ANGLE, stance, lam)

    def jacobians():
        qq, vv, lam, A, B = q.copy(), qd.copy(), np.empty((N, 2)), np.empty((N, 100)), np.empty((N, 20))
        kernels.rk4_jacobians(qq, vv, tau, P, np.zeros(N), anchor, DT, SUBSTEPS, MAX_ANGLE, stance, stance, lam, A, B, None)

    def with_params():
        qq, vv, lam, A, B = q.copy(), qd.copy(), np.empty((N, 2)), np.empty((N, 100)), np.empty((N, 20))
        kernels.rk4_jacobians(qq, vv, tau, P, np.zeros(N), anchor, DT, SUBSTEPS, MAX_ANGLE, stance, stance, lam, A, B,
                              np.empty((N, 120)))

    def differences(sides: int):
        qq, vv, tt, k = perturbed(q, qd, tau, sides)
        lam = np.empty((k * N, 2))
        kernels.rk4_step(qq, vv, tt, P, np.zeros(k * N), np.tile(anchor, (k, 1)), DT, SUBSTEPS, MAX_ANGLE, stance, lam)
        return differenced(qq, vv, k, sides)

    return {"step": step, "A, B": jacobians, "A, B, P": with_params, "forward differences (13 steps)": lambda: differences(1),
            "centred differences (25 steps)": lambda: differences(2)}


def rollout_states(env_id: str, controller):
    """N (q, qd, tau, mode, load) of one rollout step after another of ``env_id`` under ``controller``."""
    import gymnasium as gym

    envs = gym.make_vec(env_id, num_envs=256, vectorization_mode="vector_entry_point")
    obs, _ = envs.reset(seed=0)
    env, out = envs.unwrapped, []
    while sum(len(o[0]) for o in out) < N:
        q, qd, _ = env.state
        mode = env._state["mode"].astype(np.int64)
        obs, _, _, _, info = envs.step(controller.predict(obs, deterministic=True)[0])
        out.append((q, qd, info["torque"].copy(), mode))
    params, mu = env.params, env.config.mu
    envs.close()
    q, qd, tau, mode = (np.ascontiguousarray(np.concatenate([o[k] for o in out])[:N]) for k in range(4))
    return q, qd, tau, mode, params, mu


def hybrid_cases(q, qd, tau, mode, p: LegParams, mu: float):
    from leg_env.physics.layout import RECORD

    P, mus, load = p.array, np.full(N, mu), np.zeros(N)
    anchor = np.zeros((N, 2))
    anchor[:, 0] = foot_position(q, p)[:, 0]

    def step():
        qq, vv, mm, aa, rec = q.copy(), qd.copy(), mode.copy(), anchor.copy(), np.empty(N, RECORD)
        kernels.hybrid_step(qq, vv, tau, P, load, mus, mm, aa, DT, SUBSTEPS, MAX_ANGLE, rec)

    def jacobians():
        qq, vv, mm, aa, rec = q.copy(), qd.copy(), mode.copy(), anchor.copy(), np.empty(N, RECORD)
        A, B, undefined = np.empty((N, 100)), np.empty((N, 20)), np.empty(N, np.int64)
        kernels.hybrid_jacobians(qq, vv, tau, P, load, mus, mm, aa, DT, SUBSTEPS, MAX_ANGLE, rec, True, A, B, undefined, None)

    def with_params():
        qq, vv, mm, aa, rec = q.copy(), qd.copy(), mode.copy(), anchor.copy(), np.empty(N, RECORD)
        A, B, undefined = np.empty((N, 100)), np.empty((N, 20)), np.empty(N, np.int64)
        kernels.hybrid_jacobians(qq, vv, tau, P, load, mus, mm, aa, DT, SUBSTEPS, MAX_ANGLE, rec, True, A, B, undefined,
                                 np.empty((N, 120)))

    def differences(sides: int):
        qq, vv, tt, k = perturbed(q, qd, tau, sides)
        rec = np.empty(k * N, RECORD)
        kernels.hybrid_step(qq, vv, tt, P, np.zeros(k * N), np.full(k * N, mu), np.tile(mode, k), np.tile(anchor, (k, 1)), DT,
                            SUBSTEPS, MAX_ANGLE, rec)
        return differenced(qq, vv, k, sides)

    return {"step": step, "A, B": jacobians, "A, B, P": with_params, "forward differences (13 steps)": lambda: differences(1),
            "centred differences (25 steps)": lambda: differences(2)}


def measure(fns: dict) -> dict:
    for fn in fns.values():
        fn()
    times = {name: [] for name in fns}
    for _ in range(REPEATS):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            for _ in range(CALLS):
                fn()
            times[name].append((time.perf_counter() - t0) / CALLS / N)
    return times


def main() -> None:
    rng = np.random.default_rng(0)
    p = LegParams()
    from policies.gated import GatedController
    from policies.hopper import HopperController

    batches = {}
    for stance in (True, False):
        batches["pinned foot" if stance else "flight"] = cases(p, stance, *states(p, stance, rng))
    batches["unilateral, standing (gated controller)"] = hybrid_cases(*rollout_states("leg_env/PlanarLegBalance-v1", GatedController()))
    batches["unilateral, hopping (hopper)"] = hybrid_cases(*rollout_states("leg_env/PlanarLegHop-v4", HopperController()))
    rows = []
    for model, fns in batches.items():
        times = measure(fns)
        step = times["step"]
        for name, t in times.items():
            ratio = statistics.median(a / b for a, b in zip(t, step))
            vs_ab = statistics.median(a / b for a, b in zip(t, times["A, B"]))
            rows.append((model, name, statistics.median(t) * 1e6, ratio, vs_ab))
    machine = (f"{cpu_name()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}; Python "
               f"{platform.python_version()}; leg-env {__version__}, numpy {np.__version__}; one thread")
    lines = [
        "# Cost of the step's Jacobians",
        "",
        f"Written by `python benchmarks/bench_derivatives.py` on {datetime.date.today().isoformat()}.",
        "",
        f"Machine: {machine}",
        "",
        f"{N} robots in one call of the compiled kernel, dt = {DT} s, at least {SUBSTEPS} RK4 substeps; the "
        f"median over {REPEATS} round-robin repeats of the time per robot, each ratio the median of the ratios within a "
        "repeat. The differences run the step on the batch and its perturbations in one call.",
        "",
        "| model | what | us per robot | x the step | x A, B |",
        "|---|---|---:|---:|---:|",
    ]
    for model, name, us, ratio, vs_ab in rows:
        lines.append(f"| {model} | {name} | {us:.3f} | {ratio:.2f} | {vs_ab:.2f} |")
    worst = max(r[3] for r in rows if r[1] == "A, B")
    lines += ["", f"Bar: A and B together at most {BAR:.0f} times the step: {'met' if worst <= BAR else 'missed'} "
              f"(at most {worst:.2f} times)."]
    text = "\n".join(lines) + "\n"
    print(text)
    RESULTS.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
