"""Cost of the step's Jacobians (``leg_env.physics.derivatives``) beside the step and beside finite differences, in
one run.

    .venv/bin/python benchmarks/bench_derivatives.py

For each model (the pinned foot, flight) and a batch of ``N`` robots near the nominal posture (angles N(0, 0.05 rad),
rates N(0, 0.3), holding torques plus U(-5, 5) N m), one thread, the compiled kernels called directly:

* the step: ``kernels.rk4_step`` (what ``stance_step`` and the environments run);
* the step with ``A`` and ``B``: ``kernels.rk4_jacobians``;
* forward differences of ``A`` and ``B``: the step on the 13 N states of the batch and its 12 one-sided perturbations
  (10 state entries, 2 torques) in one call, then the differences;
* centred differences: the step on 25 N states (each direction perturbed both ways) in one call, then the differences.

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
sys.path.insert(0, str(ROOT))

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


def cases(p: LegParams, stance: bool, q, qd, tau):
    P = p.array
    anchor = foot_position(q, p)

    def step():
        qq, vv, lam = q.copy(), qd.copy(), np.empty((N, 2))
        kernels.rk4_step(qq, vv, tau, P, np.zeros(N), anchor, DT, SUBSTEPS, MAX_ANGLE, stance, lam)

    def jacobians():
        qq, vv, lam, A, B = q.copy(), qd.copy(), np.empty((N, 2)), np.empty((N, 100)), np.empty((N, 20))
        kernels.rk4_jacobians(qq, vv, tau, P, np.zeros(N), anchor, DT, SUBSTEPS, MAX_ANGLE, stance, stance, lam, A, B)

    def differences(sides: int):
        """The step on the batch and its perturbations in one call: rows [base, +e_0 .. +e_11 (, -e_0 .. -e_11)]."""
        k = 1 + 12 * sides
        x = np.tile(np.concatenate([q, qd, tau], axis=1), (k, 1)).reshape(k, N, 12)
        for j in range(12):
            x[1 + j, :, j] += EPS
            if sides == 2:
                x[13 + j, :, j] -= EPS
        x = x.reshape(k * N, 12)
        qq, vv, tt = np.ascontiguousarray(x[:, :5]), np.ascontiguousarray(x[:, 5:10]), np.ascontiguousarray(x[:, 10:])
        lam = np.empty((k * N, 2))
        kernels.rk4_step(qq, vv, tt, P, np.zeros(k * N), np.tile(anchor, (k, 1)), DT, SUBSTEPS, MAX_ANGLE, stance, lam)
        y = np.concatenate([qq, vv], axis=1).reshape(k, N, 10)
        if sides == 1:
            return (y[1:] - y[0]) / EPS
        return (y[1:13] - y[13:]) / (2 * EPS)

    return {"step": step, "A, B": jacobians, "forward differences (13 steps)": lambda: differences(1),
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
    rows = []
    for stance in (True, False):
        q, qd, tau = states(p, stance, rng)
        times = measure(cases(p, stance, q, qd, tau))
        step = times["step"]
        for name, t in times.items():
            ratio = statistics.median(a / b for a, b in zip(t, step))
            vs_ab = statistics.median(a / b for a, b in zip(t, times["A, B"]))
            rows.append(("pinned foot" if stance else "flight", name, statistics.median(t) * 1e6, ratio, vs_ab))
    machine = (f"{cpu_name()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}; Python "
               f"{platform.python_version()}; leg-env {__version__}, numpy {np.__version__}; one thread")
    lines = [
        "# Cost of the step's Jacobians",
        "",
        f"Written by `python benchmarks/bench_derivatives.py` on {datetime.date.today().isoformat()}.",
        "",
        f"Machine: {machine}",
        "",
        f"{N} robots in one call of the compiled kernel, near the nominal posture, dt = {DT} s, {SUBSTEPS} RK4 substeps; the "
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
