"""The speed of this checkout beside another version of leg-env, in one run, one table.

    .venv/bin/python benchmarks/bench_compare.py --before 53e8861      # a git ref: checked out and built in a temporary worktree
    .venv/bin/python benchmarks/bench_compare.py --before-tree ../old  # a source tree whose compiled core is built in place

Each row is measured in a fresh process per repeat, on the rows of ``benchmarks/bench_env.py`` that a change of the
compiled boundary can move: a single ``env.step`` (``gym.make``, pinned and unilateral) and ``gym.make_vec`` of 4096
robots (pinned, pinned with ``randomize=True``, and the hop task), all under seeded uniform random actions sampled
before timing, with the resets of ended episodes timed as training takes them; and, as the references the bars are
stated against, ``Hopper-v5``'s ``env.step`` and ``SyncVectorEnv(Hopper-v5, 8)``. The two versions and the references
are timed round-robin, repeat by repeat, each process on one thread, so that a change of machine load falls on
every row alike; every rate is the median over the repeats, and every ratio the median of the per-repeat ratios.
The table is printed and written to ``benchmarks/results/compare.md``, headed by the machine, the versions and the date.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from importlib.metadata import version
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "compare.md"
SINGLE_STEPS = 60_000  # env.step calls of one leg-env timing (about 0.25 s)
VECTOR_CALLS = 300  # make_vec(4096).step calls of one timing (0.5 to 1.5 s)
HOPPER_STEPS, SYNC_CALLS = 3_000, 400
N = 4096

ROWS = {
    # row: (kind, id, make_vec keyword arguments)
    "single, pinned": ("single", "leg_env/PlanarLegStance-v0", {}),
    "single, unilateral": ("single", "leg_env/PlanarLegBalance-v1", {}),
    "make_vec 4096, pinned": ("vector", "leg_env/PlanarLegStance-v0", {}),
    "make_vec 4096, pinned, randomize=True": ("vector", "leg_env/PlanarLegStance-v0", {"randomize": True}),
    "make_vec 4096, hop": ("vector", "leg_env/PlanarLegHop-v4", {}),
}
REFERENCES = {"Hopper-v5 env.step": ("single", "Hopper-v5", {}), "SyncVectorEnv(Hopper-v5, 8)": ("sync", "Hopper-v5", {})}

CHILD = r"""
import json, os, sys, time
import numpy as np, gymnasium as gym
kind, env_id, kwargs = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
if env_id.startswith("leg_env"):
    import leg_env
rng = np.random.default_rng(0)
if kind == "single":
    env = gym.make(env_id)
    steps = {steps_single}
    acts = rng.uniform(-1, 1, (steps,) + env.action_space.shape).astype(env.action_space.dtype)
    env.reset(seed=0)
    def run():
        for a in acts:
            if env.step(a)[2:4] != (False, False):
                env.reset()
        return steps
else:
    n = {n} if kind == "vector" else 8
    calls = {calls} if kind == "vector" else {sync_calls}
    env = gym.make_vec(env_id, num_envs=n, **kwargs) if kind == "vector" else gym.make_vec(env_id, num_envs=n, vectorization_mode="sync")
    acts = rng.uniform(-1, 1, (calls, n) + env.single_action_space.shape).astype(env.single_action_space.dtype)
    env.reset(seed=0)
    def run():
        for a in acts:
            env.step(a)
        return calls * n
run()  # warm up
t = time.perf_counter()
done = run()
print(json.dumps({{"rate": done / (time.perf_counter() - t)}}))
"""


def _child(tree: Path | None, kind: str, env_id: str, kwargs: dict) -> float:
    code = CHILD.format(steps_single=SINGLE_STEPS if tree is not None else HOPPER_STEPS, n=N, calls=VECTOR_CALLS, sync_calls=SYNC_CALLS)
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    env["PYTHONPATH"] = str(tree) if tree is not None else ""
    out = subprocess.run([sys.executable, "-c", code, kind, env_id, json.dumps(kwargs)], env=env, cwd=tempfile.gettempdir(),
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])["rate"]


def _cpu() -> str:
    """The CPU's model name, with its family and model numbers (AMD's family 25 model 17 is a Zen 4)."""
    if not os.path.exists("/proc/cpuinfo"):
        return platform.processor()
    info = {}
    for line in open("/proc/cpuinfo"):
        key, _, value = line.partition(":")
        info.setdefault(key.strip(), value.strip())
    return f"{info.get('model name', '?')} (cpu family {info.get('cpu family', '?')}, model {info.get('model', '?')})"


def _before_tree(ref: str) -> tuple[Path, str]:
    sha = subprocess.run(["git", "rev-parse", "--short", ref], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    tree = Path(tempfile.gettempdir()) / f"leg-env-before-{sha}"
    if not tree.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(tree), sha], cwd=ROOT, capture_output=True, check=True)
    subprocess.run([sys.executable, "setup.py", "build_ext", "--inplace"], cwd=tree, capture_output=True, check=True)
    return tree, sha


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default=None, help="a git ref of the version to compare with (built in a temporary worktree)")
    parser.add_argument("--before-tree", type=Path, default=None, help="a source tree of it, its compiled core built in place")
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    if (args.before is None) == (args.before_tree is None):
        parser.error("give one of --before or --before-tree")
    if args.before_tree is not None:
        before, label = args.before_tree.resolve(), str(args.before_tree)
        subprocess.run([sys.executable, "setup.py", "build_ext", "--inplace"], cwd=before, capture_output=True, check=True)
    else:
        before, label = _before_tree(args.before)
    subprocess.run([sys.executable, "setup.py", "build_ext", "--inplace"], cwd=ROOT, capture_output=True, check=True)
    now = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    rates: dict[tuple[str, str], list[float]] = {}
    for r in range(args.repeats):
        for name, (kind, env_id, kwargs) in REFERENCES.items():
            rates.setdefault(("ref", name), []).append(_child(None, kind, env_id, kwargs))
        for name, (kind, env_id, kwargs) in ROWS.items():
            for which, tree in (("before", before), ("now", ROOT)):
                rates.setdefault((which, name), []).append(_child(tree, kind, env_id, kwargs))
        print(f"repeat {r + 1} of {args.repeats} done", file=sys.stderr)

    def ratio(a, b):
        return statistics.median(x / y for x, y in zip(rates[a], rates[b]))

    cpu = _cpu()
    lines = [
        "# leg-env beside an earlier version: the rows a change of the compiled boundary can move",
        "",
        f"Machine: {cpu}, {os.cpu_count()} CPUs; Python {platform.python_version()}, numpy {version('numpy')}, gymnasium "
        f"{version('gymnasium')}, mujoco {version('mujoco')}; {time.strftime('%Y-%m-%d')}. Written by `benchmarks/bench_compare.py "
        f"--repeats {args.repeats}`: each rate the median of {args.repeats} fresh processes, one thread each, round-robin; each ratio "
        "the median of the per-repeat ratios.",
        "",
        f"| row | before ({label}) | now ({now}) | now / before | now / reference |",
        "|---|---:|---:|---:|---:|",
    ]
    for name, (kind, _, _) in ROWS.items():
        ref = ("ref", "Hopper-v5 env.step") if kind == "single" else ("ref", "SyncVectorEnv(Hopper-v5, 8)")
        b, n = statistics.median(rates["before", name]), statistics.median(rates["now", name])
        lines.append(f"| {name} | {b:,.0f}/s | {n:,.0f}/s | {ratio(('now', name), ('before', name)):.3f} | "
                     f"{ratio(('now', name), ref):.1f}x {ref[1]} |")
    for which, tree_label in (("before", label), ("now", now)):
        share = ratio((which, "make_vec 4096, pinned, randomize=True"), (which, "make_vec 4096, pinned"))
        lines.append(f"| randomised pinned batch / nominal, {tree_label} | | | | {share:.1%} |")
    for name in REFERENCES:
        lines.append(f"| {name} (reference) | | {statistics.median(rates['ref', name]):,.0f}/s | | |")
    text = "\n".join(lines) + "\n"
    print(text)
    RESULTS.write_text(text)


if __name__ == "__main__":
    main()
