"""The MPCs' compute per control step per robot (``policies.mpc.HopMPC``, ``policies.push_mpc.PushMPC``), beside the
hopper's and the stepping controller's, in one run.

    .venv/bin/python benchmarks/bench_mpc.py

On ``PlanarLegHop-v4``, for batches of 1, 10 and 100 robots: the wall-clock time of ``predict`` (one iLQR iteration:
the rollout with the Jacobians, the backward pass, the line search's rollouts) over 60 control steps from the
episodes' starts (through the first hop), divided by the batch size; the median over the steps and the slowest step.
The hopper controller's ``predict`` on the same observations is the reference. One thread (numpy's BLAS and torch
are held to one). The bar: at most 10 ms per control step per robot on one core. One robot planning at every 8th
control step (``replan_every=8``) over 120 steps: its mean time a control step. Also, for one robot, the time of
each part of a control step: the plan with its Jacobians and the line search's plans (compiled), the backward pass,
the cost.

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
    """Median microseconds of each part of one robot's control step, at the 30th control step of an episode (its
    first stance): the plan with its Jacobians, the line search's plans, the backward pass, the cost of a plan."""
    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=1, vectorization_mode="vector_entry_point")
    e = envs.unwrapped
    mpc = HopMPC(e.params, e.config)
    obs, _ = envs.reset(seed=10_000)
    for _ in range(30):
        action, _ = mpc.predict(obs)
        obs, *_ = envs.step(action)
    batch = np.asarray(obs, dtype=np.float64)
    q, qd, mode = mpc.state(batch)
    x_ref = mpc.com(np.concatenate([q, qd], axis=1))[0] - batch[:, 19]
    ctx = dict(like=batch[:, :22], target=mpc.y_stand + batch[:, 18], x_ref=x_ref, ground=batch[:, 20])
    V = np.zeros((1, mpc.horizon, 2))
    roll = mpc._rollout(mpc._pilot, q, qd, mode, ctx, V, jacobians=True)
    k, K = mpc._backward(roll, ctx)
    S = len(mpc.steps)
    tiled = {name: np.tile(value, (S,) + (1,) * (value.ndim - 1)) for name, value in ctx.items()}
    trial = (np.tile(q, (S, 1)), np.tile(qd, (S, 1)), np.tile(mode, S), tiled, np.tile(V, (S, 1, 1)))
    calls = {
        f"the plan with its Jacobians (`kernels.hop_rollout`, {mpc.horizon} steps)":
            lambda: mpc._rollout(mpc._pilot, q, qd, mode, ctx, V, jacobians=True),
        f"the line search's {S} plans (`kernels.hop_rollout`)":
            lambda: mpc._rollout(mpc._pilot, *trial, nominal=np.tile(roll["X"], (S, 1, 1)), k=np.tile(k, (S, 1, 1)),
                                 K=np.tile(K, (S, 1, 1, 1)), copies=S),
        "the backward pass (the residuals' derivatives in numpy, `kernels.ilqr_backward`)": lambda: mpc._backward(roll, ctx),
        "the cost of a plan (numpy)": lambda: mpc._cost(roll, ctx),
    }
    out = {}
    for name, call in calls.items():
        call()
        times = []
        for _ in range(15):
            t0 = time.perf_counter()
            for _ in range(20):
                call()
            times.append((time.perf_counter() - t0) / 20)
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
        "The parts of one robot's control step (at its first stance; the cost is computed for each of the four plans):",
        "",
        "| part | [ms] |",
        "|---|---:|",
    ]
    lines += [f"| {name} | {1e3 * t:.2f} |" for name, t in calls.items()]
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
