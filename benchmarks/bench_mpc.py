"""The MPCs' compute per control step per robot (``policies.mpc.HopMPC``, ``policies.push_mpc.PushMPC``), beside the
hopper's and the stepping controller's, in one run.

    .venv/bin/python benchmarks/bench_mpc.py

On ``PlanarLegHop-v4``, for batches of 1, 10 and 100 robots: the wall-clock time of ``predict`` (one iLQR iteration:
the rollout with the Jacobians, the backward pass, the line search's rollouts) over 60 control steps from the
episodes' starts (through the first hop), divided by the batch size; the median over the steps and the slowest step.
The hopper controller's ``predict`` on the same observations is the reference. One thread (numpy's BLAS and torch
are held to one). The bar: at most 10 ms per control step per robot on one core. One robot planning at every 8th
control step (``replan_every=8``) over 120 steps: its mean time a control step. Also, for one robot, the cost of
each call a control step makes in sequence (the step, the step with its Jacobians, the hopper's law on 21 and on 3
rows: 70 of each pair), the floor the plan's Python loop puts under it.

On ``PlanarLegPush-v2``, the push MPC plans only while a robot recovers from a push: every robot of a batch of 1, 10
and 100 is pushed at once (60 N, at 1 s), and the time of ``predict`` at the control steps where robots plan is
divided by the number planning; the stepping controller's ``predict`` on the same observations is the reference.
Written to ``benchmarks/results/mpc.md``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import datetime  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import leg_env  # noqa: E402
from leg_env import __version__  # noqa: E402
from policies.hopper import HopperController  # noqa: E402
from policies.mpc import HopMPC  # noqa: E402
from policies.push_mpc import PushMPC  # noqa: E402
from policies.stepping import SteppingController  # noqa: E402
from train.machine import cpu_name  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "mpc.md"
STEPS = 60


def measure(n: int, replan_every: int = 1, steps: int = STEPS) -> dict:
    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=n, vectorization_mode="vector_entry_point")
    e = envs.unwrapped
    mpc, hopper = HopMPC(e.params, e.config, replan_every=replan_every), HopperController(e.params, e.config)
    obs, _ = envs.reset(seed=10_000)
    t_mpc, t_hop = [], []
    for _ in range(steps):
        t0 = time.perf_counter()
        action, _ = mpc.predict(obs)
        t1 = time.perf_counter()
        hopper.predict(obs)
        t2 = time.perf_counter()
        t_mpc.append((t1 - t0) / n)
        t_hop.append((t2 - t1) / n)
        obs, *_ = envs.step(action)
    envs.close()
    return dict(n=n, horizon=mpc.horizon, replan_every=replan_every, mpc=np.median(t_mpc), mpc_max=np.max(t_mpc),
                mpc_mean=np.mean(t_mpc), hop=np.median(t_hop))


def measure_push(n: int) -> dict:
    envs = gym.make_vec("leg_env/PlanarLegPush-v2", num_envs=n, vectorization_mode="vector_entry_point",
                        push_force=(60.0, 60.0), first_push=(1.0, 1.0))
    e = envs.unwrapped
    mpc, stepping = PushMPC(e.params, e.config), SteppingController(e.params, e.config)
    obs, _ = envs.reset(seed=10_000)
    t_mpc, t_step, planning = [], [], 0
    for _ in range(200):  # the push at 1 s, the recovery within 1 s
        t0 = time.perf_counter()
        action, _ = mpc.predict(obs)
        t1 = time.perf_counter()
        stepping.predict(obs)
        t2 = time.perf_counter()
        if mpc.planning.any():
            planning += 1
            t_mpc.append((t1 - t0) / mpc.planning.sum())
            t_step.append((t2 - t1) / n)
        obs, *_ = envs.step(action)
    envs.close()
    return dict(n=n, horizon=mpc.horizon, steps=planning, mpc=np.median(t_mpc), mpc_max=np.max(t_mpc),
                stepping=np.median(t_step))


def per_call() -> dict:
    """Median microseconds of each call a control step makes for one robot (70 of the first two, 70 of the last two)."""
    from leg_env.physics.derivatives import hybrid_step_jacobians
    from leg_env.physics.hybrid import hybrid_step

    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=1, vectorization_mode="vector_entry_point")
    e = envs.unwrapped
    obs, _ = envs.reset(seed=10_000)
    mpc = HopMPC(e.params, e.config)
    q, qd, mode = mpc.state(np.asarray(obs, dtype=np.float64))
    tau, c = np.zeros((1, 2)), e.config
    step_args = (q, qd, tau, e.params, c.mu, mode, None)
    rule = dict(dt=c.dt, substeps=c.substeps, max_angle=c.max_angle)
    laws = {}
    for rows in (21, 3):
        law = HopperController(e.params, e.config)
        law._n = rows
        law._allocate(rows)
        law._start(np.ones(rows, dtype=bool))
        laws[rows] = (law, np.repeat(np.asarray(obs, dtype=np.float64), rows, axis=0))
    calls = {
        "the step with its Jacobians (`hybrid_step_jacobians`)": lambda: hybrid_step_jacobians(*step_args, **rule),
        "the hopper's law on 21 rows (the state and its differences)": lambda: laws[21][0].torque(laws[21][1]),
        "the step (`hybrid_step`)": lambda: hybrid_step(*step_args, **rule),
        "the hopper's law on 3 rows (the line search's plans)": lambda: laws[3][0].torque(laws[3][1]),
    }
    out = {}
    for name, call in calls.items():
        call()
        times = []
        for _ in range(15):
            t0 = time.perf_counter()
            for _ in range(100):
                call()
            times.append((time.perf_counter() - t0) / 100)
        out[name] = float(np.median(times))
    envs.close()
    return out


def main() -> None:
    rows = [measure(n) for n in (1, 10, 100)]
    replanning = measure(1, replan_every=8, steps=2 * STEPS)
    calls = per_call()
    pushes = [measure_push(n) for n in (1, 10, 100)]
    machine = (f"{cpu_name()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}; Python "
               f"{platform.python_version()}; leg-env {__version__}, numpy {np.__version__}")
    lines = [
        "# MPC: compute per control step",
        "",
        f"Written by `python benchmarks/bench_mpc.py` on {datetime.date.today().isoformat()}.",
        "",
        f"Machine: {machine}; one thread.",
        "",
        f"`policies.mpc.HopMPC` with its defaults (a horizon of {rows[0]['horizon']} control steps, one iLQR iteration and "
        f"its line search per control step), {STEPS} control steps from the episodes' starts of `PlanarLegHop-v4`; the "
        "time of `predict` divided by the batch size. The hopper's `predict` on the same observations is the reference. "
        "Bar: at most 10 ms per control step per robot on one core.",
        "",
        "| robots per call | MPC, median [ms per robot] | MPC, slowest step [ms per robot] | hopper [ms per robot] | MPC / hopper |",
        "|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(f"| {r['n']} | {1e3 * r['mpc']:.2f} | {1e3 * r['mpc_max']:.2f} | {1e3 * r['hop']:.3f} | "
                     f"{r['mpc'] / r['hop']:.0f}x |")
    lines += [
        "",
        f"Planning at every 8th control step (`replan_every=8`; between plans the hopper plus the held plan's correction "
        f"and feedback), one robot: {1e3 * replanning['mpc_mean']:.2f} ms a control step on average over "
        f"{2 * STEPS} steps, {1e3 * replanning['mpc_max']:.2f} ms at a planning step, {1e3 * replanning['mpc']:.2f} ms "
        "the median step.",
    ]
    lines += [
        "",
        "The calls a control step makes in sequence for one robot (70 of each: the rollout with the Jacobians, then the "
        "line search's), whatever else it does:",
        "",
        "| call | [us] |",
        "|---|---:|",
    ]
    lines += [f"| {name} | {1e6 * t:.1f} |" for name, t in calls.items()]
    lines.append(f"| 70 of each, a control step's floor | {70e3 * sum(calls.values()):.1f} ms |")
    lines += [
        "",
        f"`policies.push_mpc.PushMPC` with its defaults (a horizon of {pushes[0]['horizon']} control steps, one iLQR "
        "iteration), on `PlanarLegPush-v2` with every robot pushed at once (60 N at 1 s): the time of `predict` at the "
        "control steps where robots plan, divided by the number planning (elsewhere it is the stepping controller). The "
        "stepping controller's `predict` on the same observations is the reference.",
        "",
        "| robots per call | control steps planned | push MPC, median [ms per robot planning] | slowest step | "
        "stepping controller [ms per robot] | MPC / stepping |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for r in pushes:
        lines.append(f"| {r['n']} | {r['steps']} | {1e3 * r['mpc']:.2f} | {1e3 * r['mpc_max']:.2f} | "
                     f"{1e3 * r['stepping']:.3f} | {r['mpc'] / r['stepping']:.0f}x |")
    text = "\n".join(lines) + "\n"
    RESULTS.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
