"""Cold compile time of the kernels, per task: what adding a task costs CI.

    .venv/bin/python benchmarks/compile_time.py

Each measurement runs in a fresh process with an empty numba cache (``NUMBA_CACHE_DIR`` a new temporary
directory, so the package's own caches are not read): the shared physics kernel
(``leg_env.step.physics_range`` and ``physics_start``) first, then each task's kernels (``assess``,
``start``) for the unilateral and the pinned model, timed one by one. Then the same in a process that
finds the cache just written (warm start).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

def child(order: list[str]) -> dict:
    import time

    import numpy as np

    t0 = time.perf_counter()
    from leg_env import tasks
    from leg_env.params import LegParams
    from leg_env.step import FLAG_NAMES, physics_range, physics_start
    from leg_env.tasks.stance import nominal_state, task_constants

    out = {"import": time.perf_counter() - t0}
    p = LegParams()
    for item in order:
        name, contact = item.split(":")
        task = tasks.get(name)
        config = task.config_cls(contact=contact)
        nominal = nominal_state(p, config)
        consts = task_constants(p, config, nominal)
        state = np.zeros((2, task.state_dim))
        o = np.zeros((2, task.out_dim))
        obs = np.zeros((2, task.observation_space(p, config).shape[0]), dtype=np.float32)
        flags = np.zeros((2, len(FLAG_NAMES)), dtype=np.bool_)
        state[:, :5] = nominal.q
        t = time.perf_counter()
        physics_start(state, consts, o, flags)
        physics_range(0, 2, state, consts, o, flags)
        out[f"physics ({item})"] = time.perf_counter() - t
        t = time.perf_counter()
        task.start(state, consts, o, obs, flags)
        task.assess(state, consts, o, obs, flags)
        out[f"task kernels ({item})"] = time.perf_counter() - t
    return out


def run(cache_dir: str, order: list[str]) -> dict:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache_dir, "PYTHONPATH": str(ROOT)}
    code = f"import sys, json; sys.path.insert(0, {str(ROOT / 'benchmarks')!r}); import compile_time as c; print(json.dumps(c.child({order!r})))"
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True, cwd=ROOT)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    order = ["stance:unilateral", "push:unilateral", "hop:unilateral", "stance:pinned", "push:pinned"]
    with tempfile.TemporaryDirectory() as d:
        cold = run(d, order)
        warm = run(d, order)
    print("| kernel | cold compile [s] | from the cache [s] |")
    print("|---|---:|---:|")
    for key in cold:
        print(f"| {key} | {cold[key]:.1f} | {warm[key]:.2f} |")
    print(f"| total | {sum(cold.values()):.1f} | {sum(warm.values()):.2f} |")


if __name__ == "__main__":
    main()
