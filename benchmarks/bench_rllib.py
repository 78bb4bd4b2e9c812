"""RLlib throughput on this machine: sampling env-steps/s with 1 and 2 env runners, and one PPO iteration.

    python benchmarks/bench_rllib.py                  # needs the rllib extra (make test builds .venv-rllib)
    python benchmarks/bench_rllib.py --envs 64 --steps 20000 --iterations 3

Sampling: each remote env runner (one CPU, leg-env's native batch of ``--envs`` robots, the policy of
``train/hyperparams/ppo.yml``) runs ``sample(num_timesteps=--steps)`` after a warm-up; runners sample in
parallel, and the rate is all runners' steps over the wall time. This includes RLlib's per-step work
(connectors, the policy's forward pass, episode bookkeeping), which dominates: the bare batch steps
about 1.6M robots/s at N = 4096 (``bench_env.py``). Iteration: ``Algorithm.train()`` with the YAML's
PPO settings (2,048 env steps per iteration, 10 epochs of 1,024-step minibatches), median of
``--iterations`` after one warm-up iteration, with RLlib's own split into sampling and learning.
Ray gets ``--num-cpus`` CPUs (default: this machine's); the learner runs in this process.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # train/, next to leg_env


def build(runners: int, envs: int, total: int):
    from leg_env import ENV_ID
    from train.ppo import DEFAULT_HYPERPARAMS
    from train.rllib import RLlibArgs, resolve_config, rllib_config

    config = resolve_config(RLlibArgs(env_id=ENV_ID, hyperparams=DEFAULT_HYPERPARAMS, num_env_runners=runners, num_envs_per_env_runner=envs, total_timesteps=total))
    return rllib_config(config).build_algo(), config


def sampling_rate(runners: int, envs: int, steps: int) -> float:
    algo, _ = build(runners, envs, 1_000_000)
    try:
        group = algo.env_runner_group
        group.foreach_env_runner(lambda r: len(r.sample(num_timesteps=envs * 20)), local_env_runner=False)  # warm-up
        t0 = time.perf_counter()
        counts = group.foreach_env_runner(
            lambda r: sum(len(e) for e in r.sample(num_timesteps=steps, random_actions=False)), local_env_runner=False
        )
        elapsed = time.perf_counter() - t0
    finally:
        algo.stop()
    return sum(counts) / elapsed


def iteration_times(runners: int, iterations: int) -> tuple[float, float, float, int]:
    algo, config = build(runners, None, 1_000_000)
    try:
        algo.train()  # warm-up
        totals, samples, learns = [], [], []
        for _ in range(iterations):
            result = algo.train()
            totals.append(result["time_this_iter_s"])
            timers = result.get("timers", {})
            samples.append(timers.get("env_runner_sampling_timer", float("nan")))
            learns.append(timers.get("learner_update_timer", float("nan")))
    finally:
        algo.stop()
    return statistics.median(totals), statistics.median(samples), statistics.median(learns), config["ppo"]["train_batch_size"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", type=int, default=64, help="robots per env runner when measuring sampling")
    parser.add_argument("--steps", type=int, default=20_000, help="env steps each runner samples for the rate")
    parser.add_argument("--iterations", type=int, default=3, help="timed training iterations (after one warm-up)")
    parser.add_argument("--num-cpus", type=int, default=None, help="CPUs of the local Ray")
    args = parser.parse_args()

    import ray
    import torch

    torch.set_num_threads(1)
    ray.init(num_cpus=args.num_cpus, include_dashboard=False, log_to_driver=False)
    cpus = int(ray.cluster_resources()["CPU"])
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Ray CPUs {cpus}, Python {platform.python_version()}, "
        f"ray {ray.__version__}, torch {torch.__version__}"
    )
    print("| measurement | env runners | value |\n|---|---:|---:|")
    for runners in (1, 2):
        if runners > cpus:
            print(f"| sampling, {args.envs} robots per runner [env-steps/s] | {runners} | needs {runners} CPUs |")
            continue
        rate = sampling_rate(runners, args.envs, args.steps)
        print(f"| sampling, {args.envs} robots per runner [env-steps/s] | {runners} | {rate:,.0f} |", flush=True)
    total, sample, learn, batch = iteration_times(1, args.iterations)
    print(f"| one PPO iteration, {batch:,} env steps (ppo.yml) [s] | 1 | {total:.2f} |")
    print(f"| of which sampling / learner update [s] | 1 | {sample:.2f} / {learn:.2f} |")
    ray.shutdown()


if __name__ == "__main__":
    main()
