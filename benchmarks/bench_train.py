"""Training throughput of the shipped from-scratch PPO configurations, and where the time goes.

    .venv/bin/python benchmarks/bench_train.py            # every configuration (a few minutes)
    .venv/bin/python benchmarks/bench_train.py --env-id leg_env/PlanarLegBalance-v1 --rollouts 20

For each configuration of ``train/hyperparams/ppo.yml`` that trains a unilateral task from scratch (``CONFIGS``),
PPO is built exactly as ``python -m train.ppo`` builds it (``train.chunked_ppo.ChunkedPPO``, the same
``resolve_config``, the same ``leg_env.sb3`` adapter with ``per_env_info=False``, ``VecNormalize`` as configured)
and learns for ``--rollouts``
rollouts after one untimed warm-up rollout, without evaluations or checkpoints (``train.ppo`` adds one
evaluation of 32-64 episodes per 3M steps: under 1% of the time). A callback splits the wall-clock into:

* **rollout**: collecting ``n_envs x n_steps`` transitions (the policy's forward pass, the env step through the
  adapter, ``VecNormalize``, SB3's rollout buffer and its GAE);
* **env**: the part of the rollout spent in the adapter's ``step`` (the compiled physics and its Python);
* **update**: PPO's gradient steps (``n_epochs x n_envs x n_steps / batch_size`` of them per rollout).

Each configuration runs with torch on 1 thread and on every core, each measurement in a fresh process, ``--repeats`` times
interleaved (the table shows the median run). The references in the
same run: ``ChunkedPPO`` with ``--update-precision bfloat16`` (on a CPU with bfloat16 arithmetic), SB3's own ``PPO``
(its ``train`` without chunks, torch's ``tanh``) on the same threads, and the native batch
``gym.make_vec(env_id, n_envs)`` under pre-sampled random actions, the env alone. The env-steps/s end
to end is ``n_envs x n_steps x rollouts / wall time``. The table goes to stdout and to
``benchmarks/results/train_speed.md``, headed by the machine, the versions and the date.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "train_speed.md"
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

CONFIGS = ("leg_env/PlanarLegBalance-v1", "leg_env/PlanarLegHop-v4")
"""The from-scratch configurations of ``train/hyperparams/ppo.yml`` on the unilateral ground."""
TARGET = 100_000.0  # env-steps/s end to end, at least on the balance and hop configurations
SEED = 0


def env_rate(env_id: str, n_envs: int, env_kwargs: dict, calls: int = 200) -> float:
    """Env-steps/s of the native batch alone under pre-sampled random actions (resets included)."""
    import gymnasium as gym

    import leg_env  # noqa: F401

    env = gym.make_vec(env_id, num_envs=n_envs, **env_kwargs)
    env.reset(seed=SEED)
    actions = np.random.default_rng(SEED).uniform(-1.0, 1.0, size=(calls, n_envs, 2)).astype(np.float32)
    for a in actions[:10]:
        env.step(a)
    start = time.perf_counter()
    for a in actions[10:]:
        env.step(a)
    rate = n_envs * (calls - 10) / (time.perf_counter() - start)
    env.close()
    return rate


ALGOS = ("chunked", "bfloat16", "sb3")
"""The trainers timed: ``ChunkedPPO`` as ``train.ppo`` builds it (float32), ``ChunkedPPO`` with its update in bfloat16
(``--update-precision bfloat16``; timed only on a CPU with bfloat16 arithmetic), SB3's ``PPO`` (the reference)."""


SMOOTHING = {"temporal_smoothness_coef": 0.1, "spatial_smoothness_coef": 0.1}
"""The smoothness charges ``algo="smooth-<share>"`` adds (``benchmarks/bench_smoothness.py``)."""


def train_rate(env_id: str, rollouts: int, threads: int, algo: str = "chunked") -> dict:
    """PPO as ``train.ppo`` builds it for ``env_id`` (``algo="bfloat16"``: its update in bfloat16; ``"sb3"``: SB3's
    ``PPO`` instead of ``ChunkedPPO``, without the configuration's ``ChunkedPPO`` terms, which SB3's has not;
    ``"smooth-<share>"``: ``ChunkedPPO`` with ``SMOOTHING`` on that share of the samples, ``"smooth-0"`` with no
    smoothness charge, in place of the configuration's own smoothness settings), timed over ``rollouts`` rollouts after
    a warm-up one."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize

    from leg_env.sb3 import make_sb3_vec_env
    from train.chunked_ppo import ChunkedPPO
    from train.normalize import BatchVecNormalize
    from train.hyperparameters import CHUNKED_PPO_KEYS
    from train.ppo import TrainArgs, ppo_kwargs, resolve_config

    torch.set_num_threads(threads)
    config = resolve_config(TrainArgs(env_id=env_id, seed=SEED))
    n_envs = config["n_envs"]
    venv = make_sb3_vec_env(n_envs, seed=SEED, env_id=env_id, per_env_info=False, **config["env_kwargs"])
    inner = venv
    env_time = [0.0]
    step_wait = inner.step_wait

    def timed_step_wait():
        t = time.perf_counter()
        out = step_wait()
        env_time[0] += time.perf_counter() - t
        return out

    inner.step_wait = timed_step_wait
    if config["normalize"] is not False:  # as train.ppo wraps it; SB3's own class for SB3's PPO
        venv = (VecNormalize if algo == "sb3" else BatchVecNormalize)(venv, **config["normalize"])
    kwargs = ppo_kwargs(config)
    if algo.startswith("smooth-"):
        share = float(algo[len("smooth-"):])
        for key in (*SMOOTHING, "smoothness_share"):
            kwargs.pop(key, None)
        if share > 0.0:
            kwargs.update(SMOOTHING, smoothness_share=share)
    if algo == "sb3":
        kwargs = {key: value for key, value in kwargs.items() if key not in CHUNKED_PPO_KEYS}
    extra = sorted(key for key in CHUNKED_PPO_KEYS if kwargs.get(key))  # the ChunkedPPO terms of the trainer timed
    precision = {"bfloat16": "bfloat16", "sb3": "float32"}.get(algo, config["update_precision"])
    if algo == "sb3":
        model = PPO(config["policy"], venv, seed=SEED, device="cpu", verbose=0, **kwargs)
    else:
        model = ChunkedPPO(config["policy"], venv, seed=SEED, device="cpu", verbose=0, update_precision=precision, **kwargs)
    rollout_steps = n_envs * model.n_steps

    class Phases(BaseCallback):
        def __init__(self):
            super().__init__()
            self.marks: list[tuple[str, float, float]] = []  # (phase start, wall-clock, env time so far)

        def _on_rollout_start(self) -> None:
            self.marks.append(("rollout", time.perf_counter(), env_time[0]))

        def _on_rollout_end(self) -> None:
            self.marks.append(("update", time.perf_counter(), env_time[0]))

        def _on_step(self) -> bool:
            return True

        def _on_training_end(self) -> None:
            self.marks.append(("end", time.perf_counter(), env_time[0]))

    phases = Phases()
    model.learn(rollout_steps * (rollouts + 1), callback=phases)
    marks = phases.marks[2:]  # the warm-up rollout and its update untimed
    spent = {"rollout": 0.0, "update": 0.0}
    env_spent = 0.0
    for (kind, t, e), (_, t_next, e_next) in zip(marks, marks[1:]):
        spent[kind] += t_next - t
        if kind == "rollout":
            env_spent += e_next - e
    wall = marks[-1][1] - marks[0][1]
    ppo = config["ppo"]
    return {
        "n_envs": n_envs,
        "batch": ppo["batch_size"],
        "epochs": ppo["n_epochs"],
        "net": ppo.get("policy_kwargs", {}).get("net_arch"),
        "threads": threads,
        "algo": algo,
        "precision": precision,
        "rate": rollout_steps * rollouts / wall,
        "rollout": spent["rollout"] / wall,
        "env": env_spent / wall,
        "update": spent["update"] / wall,
        "gradient_steps": ppo["n_epochs"] * rollout_steps // ppo["batch_size"],
        "env_kwargs": config["env_kwargs"],
        "chunked_terms": extra,
    }


def _median(runs: list[dict]) -> dict:
    """The run of median rate among ``runs`` (its shares with it)."""
    return sorted(runs, key=lambda r: r["rate"])[len(runs) // 2]


def _in_fresh_process(env_id: str, rollouts: int, threads: int, algo: str = "chunked") -> dict:
    """``train_rate`` in a new interpreter: torch's thread pools and the previous run's memory do not carry over
    (timed in one process, a configuration timed after another ran up to a quarter slower)."""
    command = [sys.executable, str(Path(__file__).resolve()), "--one", env_id, str(threads), algo, "--rollouts", str(rollouts)]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    lines = [line for line in done.stdout.splitlines() if line.startswith("RESULT ")]
    if done.returncode != 0 or not lines:
        raise RuntimeError(f"{' '.join(command)} failed (exit {done.returncode}):\n{done.stderr[-2000:]}")
    return json.loads(lines[-1][len("RESULT "):])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env-id", action="append", help=f"a configuration to time (default: {', '.join(CONFIGS)})")
    parser.add_argument("--rollouts", type=int, default=30, help="timed rollouts per configuration and thread count")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each case (interleaved); the table shows their median")
    parser.add_argument("--no-write", action="store_true", help=f"print only, do not write {RESULTS.relative_to(ROOT)}")
    parser.add_argument("--one", nargs=3, metavar=("ENV_ID", "THREADS", "ALGO"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.rollouts < 2:
        parser.error("--rollouts must be at least 2")
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    from train.chunked_ppo import UPDATE_CHUNK
    from train.machine import describe, native_bfloat16

    if args.one:  # one measurement, in this fresh process: its result as a JSON line
        print("RESULT " + json.dumps(train_rate(args.one[0], args.rollouts, int(args.one[1]), args.one[2])))
        return
    env_ids = args.env_id or list(CONFIGS)
    threads = sorted({1, os.cpu_count() or 1})
    rows, checks, ratios = [], [], []
    for env_id in env_ids:
        algos = ALGOS if native_bfloat16() else ("chunked", "sb3")  # emulated bfloat16 is slower than float32
        cases = [(k, algo) for k in threads for algo in algos]
        runs = {case: [] for case in cases}
        for _ in range(args.repeats):  # interleaved, so that a noisy spell of the machine hits every case alike
            for case in cases:
                runs[case].append(_in_fresh_process(env_id, args.rollouts, *case))
        medians = {case: _median(runs[case]) for case in cases}
        results = [medians[(k, "chunked")] for k in threads]
        reference = env_rate(env_id, results[0]["n_envs"], results[0]["env_kwargs"])
        terms = results[0]["chunked_terms"]
        with_terms = f" (ChunkedPPO with the configuration's own terms {', '.join(terms)}, which SB3's PPO has not)" if terms else ""
        for k in threads:
            for algo in algos[:-1]:
                ratios.append(f"  {env_id}, torch on {k} thread{'s' * (k > 1)}: ChunkedPPO ({medians[(k, algo)]['precision']}) / SB3 PPO, "
                              f"medians of {args.repeats} runs: {medians[(k, algo)]['rate'] / medians[(k, 'sb3')]['rate']:.2f}x{with_terms}")
        for r in medians.values():
            trainer = {"chunked": "ChunkedPPO", "bfloat16": "ChunkedPPO, --update-precision bfloat16", "sb3": "SB3 PPO (reference)"}[r["algo"]]
            rows.append(
                f"| {env_id} | {trainer} | {r['precision']} | {r['n_envs']} | {r['batch']:,} | {r['epochs']} | {r['gradient_steps']} | {r['net']} | {r['threads']} "
                f"| {r['rate']:,.0f} | {r['rollout']:.0%} | {r['env']:.0%} | {r['update']:.0%} | {reference:,.0f} |"
            )
        for algo in algos[:-1]:
            best = max((medians[(k, algo)] for k in threads), key=lambda r: r["rate"])
            checks.append(
                f"  {'PASS' if best['rate'] >= TARGET else 'FAIL'}  {env_id} PPO end to end, update in {best['precision']}, >= {TARGET:,.0f} "
                f"env-steps/s: {best['rate']:,.0f} (torch on {best['threads']} thread{'s' * (best['threads'] > 1)})"
            )
    lines = [
        "# Training speed: SB3 PPO on the shipped from-scratch configurations",
        "",
        f"Written by `python benchmarks/bench_train.py --rollouts {args.rollouts} --repeats {args.repeats}` on {datetime.date.today().isoformat()}.",
        "",
        f"Machine: {describe()}",
        "",
        f"Each row: the median of {args.repeats} runs (interleaved, each in a fresh process) of {args.rollouts} rollouts of PPO as `python -m train.ppo` builds it (after one untimed), without evaluations: "
        f"`ChunkedPPO` (`train.chunked_ppo`: SB3's PPO with each minibatch's gradient summed over chunks of {UPDATE_CHUNK:,} samples per torch thread, "
        "its tanh computed as 2 sigmoid(2x) - 1), the same with its update's hidden layers in bfloat16 (`--update-precision bfloat16`, "
        "on a CPU with bfloat16 arithmetic), both over `train.normalize.BatchVecNormalize` as `train.ppo` wraps the env, "
        "and SB3's `PPO` over SB3's `VecNormalize` as the reference (without a configuration's `ChunkedPPO` terms, the "
        "smoothness and bounds charges, which SB3's PPO has not: `benchmarks/bench_smoothness.py` times what they cost). "
        "Shares of the wall-clock: the rollout (policy forward pass, env step, rollout buffer), of which the env step "
        "(the `leg_env.sb3` adapter), and the update (the gradient steps). The last column: the native batch alone "
        "under random actions, in the same run.",
        "",
        "| configuration | trainer | update precision | envs | batch | epochs | gradient steps per rollout | net | torch threads | env-steps/s | rollout | of which env | update | env alone, env-steps/s |",
        "|---|---|---|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|",
        *rows,
        "",
        "Targets:",
        *checks,
        "",
        "Speed-up of ChunkedPPO over SB3's PPO, end to end:",
        *ratios,
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    if not args.no_write:
        RESULTS.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
