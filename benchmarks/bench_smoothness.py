"""What the smoothness charges of PPO's update cost in training speed (``train.chunked_ppo.ChunkedPPO``:
``temporal_smoothness_coef``, ``spatial_smoothness_coef``, ``smoothness_share``).

    .venv/bin/python benchmarks/bench_smoothness.py                 # the balance configuration, a few minutes
    .venv/bin/python benchmarks/bench_smoothness.py --env-id leg_env/PlanarLegHop-v4 --rollouts 10

Each case is the configuration of ``train/hyperparams/ppo.yml`` as ``python -m train.ppo`` builds it, its own
smoothness settings replaced, timed by ``benchmarks/bench_train.py`` (each run in a fresh process, the cases
interleaved, the median of ``--repeats``): without the charges (the reference, in the same run), and with both charges
at 0.1 on every sample and on a quarter of them (the balance configuration's own). Each charged sample costs one more forward and backward pass of the actor per charge in the update; the
rollouts are unchanged. The table goes to stdout and to ``benchmarks/results/smoothness_speed.md``, headed by the
machine, the versions and the date.
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "smoothness_speed.md"
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

CASES = ("smooth-0", "smooth-1", "smooth-0.25")
LABELS = {"smooth-0": "none (the reference)", "smooth-1": "both at 0.1, every sample", "smooth-0.25": "both at 0.1, a quarter of the samples"}


def main(argv: list[str] | None = None) -> None:
    from bench_train import _in_fresh_process, _median  # noqa: PLC0415 (the benchmark next to this one)

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env-id", default="leg_env/PlanarLegBalance-v1", help="the configuration to time")
    parser.add_argument("--rollouts", type=int, default=20, help="timed rollouts per case")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each case (interleaved); the table shows their median")
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1, help="torch threads")
    parser.add_argument("--no-write", action="store_true", help=f"print only, do not write {RESULTS.relative_to(ROOT)}")
    args = parser.parse_args(argv)
    if args.rollouts < 2 or args.repeats < 1 or args.threads < 1:
        parser.error("--rollouts must be at least 2, --repeats and --threads at least 1")
    from train.machine import describe

    runs = {case: [] for case in CASES}
    for _ in range(args.repeats):
        for case in CASES:
            runs[case].append(_in_fresh_process(args.env_id, args.rollouts, args.threads, case))
    medians = {case: _median(runs[case]) for case in CASES}
    reference = medians["smooth-0"]
    rows = [
        f"| {LABELS[case]} | {r['rate']:,.0f} | {r['rate'] / reference['rate']:.2f}x | {r['rollout']:.0%} | {r['update']:.0%} |"
        for case, r in medians.items()
    ]
    lines = [
        "# Training speed with the smoothness charges of PPO's update",
        "",
        f"Written by `python benchmarks/bench_smoothness.py --env-id {args.env_id} --rollouts {args.rollouts} --repeats {args.repeats} "
        f"--threads {args.threads}` on {datetime.date.today().isoformat()}.",
        "",
        f"Machine: {describe()}",
        "",
        f"`{args.env_id}`'s configuration of `train/hyperparams/ppo.yml` as `python -m train.ppo` builds it (`ChunkedPPO`, "
        f"{reference['n_envs']} envs, minibatches of {reference['batch']:,}, {reference['epochs']} epochs), torch on "
        f"{args.threads} thread{'s' * (args.threads > 1)}, its own smoothness settings replaced by each row's, without evaluations; "
        f"each row the median of {args.repeats} runs "
        f"of {args.rollouts} rollouts, interleaved, each in a fresh process (`benchmarks/bench_train.py`). The charges: "
        "`temporal_smoothness_coef` and `spatial_smoothness_coef` at 0.1, on the share `smoothness_share` of the samples.",
        "",
        "| smoothness charges | env-steps/s | of the reference | rollout | update |",
        "|---|---:|---:|---:|---:|",
        *rows,
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    if not args.no_write:
        RESULTS.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
