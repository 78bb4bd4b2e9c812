"""Kill ``train.ppo`` at random moments, rerun the same command each time, and check the run ends intact.

    .venv/bin/python benchmarks/kill_resume.py                 # 10 kills, about 3 minutes
    .venv/bin/python benchmarks/kill_resume.py --kills 20 --seed 1 --out runs/kill_resume

Not a CI test: it takes minutes and its kill moments are random (seeded by ``--seed``). Three parts:

1. An uninterrupted reference run of the command below, for the step count to compare with.
2. The same command into another folder, SIGKILLed after a random delay (uniform in
   ``[0.5, --max-delay]`` s, so kills land in the imports, the set-up, training, checkpoint writes and
   the final evaluation) and started again, until ``--kills`` kills have hit a running process;
   then once more to the end. Checked: every rerun continues from at least the newest checkpoint
   the previous kill left (or starts again if there was none), no checkpoint is ever found corrupt
   (writes are atomic), and the run ends with exit status 0, the reference's step count, and a
   ``model.zip`` that the evaluation loader loads and runs.
3. The newest checkpoint's ``vecnormalize.pkl`` is overwritten with garbage and the run is continued
   for one more checkpoint interval. Checked: a warning naming that file, the resume from the
   previous checkpoint, and the new step count.

One line per kill and per check; exit status 1 if any check fails.
"""

from __future__ import annotations

import argparse
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PARAMS = ["n_envs:4", "n_steps:32", "batch_size:64", "n_epochs:1"]  # 128 env steps per PPO iteration
TOTAL = 65_536
CHECKPOINT_FREQ = 1_024
EVAL_FREQ = 4_096
RESUMED = re.compile(r"resuming .* from ([\d,]+) steps")


def command(out: Path, total: int = TOTAL) -> list[str]:
    return [sys.executable, "-m", "train.ppo", "--out", str(out), "--total-timesteps", str(total),
            "--checkpoint-freq", str(CHECKPOINT_FREQ), "--eval-freq", str(EVAL_FREQ), "--eval-episodes", "2",
            "--no-progress-bar", "--verbose", "1", "--params", *PARAMS]  # fmt: skip


def run(cmd: list[str], kill_after: float | None = None) -> tuple[int | None, str, str, bool]:
    """Run ``cmd``; SIGKILL it after ``kill_after`` s if it still runs. Returns (exit status, stdout,
    stderr, whether the kill hit a running process)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}  # a kill loses no output
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        out, err = proc.communicate(timeout=kill_after)
        return proc.returncode, out, err, False
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        return proc.returncode, out, err, True


def checkpoint_steps(out: Path) -> list[int]:
    folder = out / "checkpoints"
    if not folder.is_dir():
        return []
    return sorted(int(p.name) for p in folder.iterdir() if p.is_dir() and re.fullmatch(r"\d{12}", p.name))


def resumed_from(stdout: str) -> int | None:
    match = RESUMED.search(stdout)
    return int(match.group(1).replace(",", "")) if match else None


def final_steps(out: Path) -> int:
    from stable_baselines3 import PPO

    return PPO.load(out / "last" / "model.zip", device="cpu").num_timesteps


class Checks:
    def __init__(self):
        self.failed = 0

    def __call__(self, ok: bool, what: str) -> None:
        print(f"  [{'ok' if ok else 'FAIL'}] {what}", flush=True)
        self.failed += not ok


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--kills", type=int, default=10, help="SIGKILLs that must hit a running process")
    parser.add_argument("--max-delay", type=float, default=12.0, help="longest delay before a kill [s]")
    parser.add_argument("--seed", type=int, default=0, help="seed of the kill delays")
    parser.add_argument("--out", type=Path, default=None, help="folder for the two runs (default: a temporary one)")
    args = parser.parse_args()
    if args.kills < 1 or args.max_delay <= 0.5:
        parser.error("--kills must be >= 1 and --max-delay > 0.5")
    base = args.out or Path(tempfile.mkdtemp(prefix="kill_resume."))
    reference, killed = base / "reference", base / "killed"
    for folder in (reference, killed):
        if folder.exists():
            shutil.rmtree(folder)
    rng = random.Random(args.seed)
    check = Checks()
    print(f"runs in {base}; command: {' '.join(command(killed)[1:])}", flush=True)

    t0 = time.perf_counter()
    status, _, err, _ = run(command(reference))
    print(f"reference run: exit {status}, {time.perf_counter() - t0:.1f} s", flush=True)
    check(status == 0, f"the uninterrupted run succeeds{'' if status == 0 else ': ' + err[-2000:]}")
    reference_steps = final_steps(reference) if status == 0 else None

    kills = attempts = 0
    newest_before = None  # the newest checkpoint the previous kill left
    while kills < args.kills and attempts < 4 * args.kills:
        attempts += 1
        delay = rng.uniform(0.5, args.max_delay)
        status, out, err, hit = run(command(killed), kill_after=delay)
        start = resumed_from(out)
        left = checkpoint_steps(killed)
        if hit:
            kills += 1
            if start is not None:
                when = f"resumed from {start:,} steps"
            elif left and left != newest_before:
                when = "started afresh, past its first checkpoint"
            else:
                when = "before it loaded or wrote a checkpoint"
            print(f"kill {kills:2d} after {delay:5.2f} s ({when}); checkpoints left: {left or 'none'}", flush=True)
        else:
            print(f"(attempt {attempts}: finished with exit {status} before the kill at {delay:.2f} s)", flush=True)
            check(status == 0, f"an unkilled invocation succeeds{'' if status == 0 else ': ' + err[-2000:]}")
        # where this invocation started against what the previous kill left (unknown if killed before it said)
        if newest_before is not None and (start is not None or not hit):
            expected = max(newest_before) if newest_before else None
            check(start == expected, f"started from {start if start is not None else 'scratch'} steps, "
                  f"the newest checkpoint left was {expected if expected is not None else 'none'}")  # fmt: skip
        check("CheckpointWarning" not in err, "no checkpoint found corrupt")
        newest_before = left

    status, out, err, _ = run(command(killed))
    start = resumed_from(out)
    print(f"final run: exit {status}, resumed from {start} steps", flush=True)
    check(status == 0, f"the killed run completes{'' if status == 0 else ': ' + err[-2000:]}")
    check(start == (max(newest_before) if newest_before else None), "it resumed from the newest checkpoint left")
    if status == 0:
        steps = final_steps(killed)
        check(steps == reference_steps == TOTAL, f"same step count: killed {steps:,}, reference {reference_steps}, target {TOTAL:,}")
        check(checkpoint_steps(killed)[-1] == TOTAL, f"the newest checkpoint holds {TOTAL:,} steps")
        sys.path.insert(0, str(ROOT))
        import numpy as np

        from train.evaluate import load_policy

        action, _ = load_policy(killed).predict(np.zeros(12, dtype=np.float32))
        check(action.shape == (2,), f"model.zip loads through the evaluation loader and acts ({killed / 'model.zip'})")

    print("corrupt latest checkpoint:", flush=True)
    steps = checkpoint_steps(killed)
    if len(steps) >= 2:
        corrupt = killed / "checkpoints" / f"{steps[-1]:012d}" / "vecnormalize.pkl"
        corrupt.write_bytes(b"\x80\x04garbage")
        status, out, err, _ = run(command(killed, total=TOTAL + CHECKPOINT_FREQ))
        warning = next((line for line in err.splitlines() if "CheckpointWarning" in line), "")
        print(f"  warning: {warning.strip()}", flush=True)
        check(str(corrupt) in warning, "a warning names the corrupt file")
        check(resumed_from(out) == steps[-2], f"resumed from the previous checkpoint ({resumed_from(out)} steps)")
        check(status == 0 and final_steps(killed) == TOTAL + CHECKPOINT_FREQ, f"ends at {TOTAL + CHECKPOINT_FREQ:,} steps")
    else:
        check(False, f"two checkpoints to fall back between (found {steps})")

    print(f"{kills} kills in {attempts} attempts, {time.perf_counter() - t0:.0f} s; "
          f"{'all checks passed' if not check.failed else f'{check.failed} check(s) FAILED'}")  # fmt: skip
    return 1 if check.failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
