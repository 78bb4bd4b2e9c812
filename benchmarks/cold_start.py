"""Cold start of the installed wheel: from ``import leg_env`` to the first ``step``, per id, single and batched.

    .venv/bin/python benchmarks/cold_start.py                         # the wheel, every id, 3 processes per case
    .venv/bin/python benchmarks/cold_start.py --reference e4e99ff     # and an older commit, for comparison

The wheel is built as a user's installer builds it (an sdist from a copy of the sources, the wheel from the
sdist) and installed in a fresh venv without system site-packages and without byte-compiled files; the
venv, HOME and the working directory are then read-only (``benchmarks/wheel_venv.py``, shared with
``tests/test_wheel.py``). So there is no cache anywhere: no bytecode, nothing compiled or written at run
time.

Each measurement is a fresh process of that venv, outside the repository: it imports numpy and
gymnasium, then times ``import leg_env``, the make (``gym.make(id)`` or ``gym.make_vec(id, num_envs=64,
vectorization_mode="vector_entry_point")``), ``reset(seed=0)`` and the first ``step`` (zero actions).
Every case runs ``--repeat`` times (interleaved); the table gives the slowest, which must be within the
bar (1.0 s). The table is printed and written to ``benchmarks/results/cold_start.md``.

``--reference COMMIT`` times the same for one id (``--reference-id``) of an older commit's source tree,
checked out in a temporary git worktree and imported from there (``PYTHONPATH``) by this environment's
Python, with ``NUMBA_CACHE_DIR`` a fresh empty directory: for the numba implementation, which compiles
its kernels at first use. A case still running after ``--reference-budget`` seconds is stopped and
reported as such; the worktree is removed afterwards.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import wheel_venv  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "cold_start.md"
BAR = 1.0  # seconds
NUM_ENVS = 64
CASES = {"make": "gym.make(ENV_ID)", "make_vec": f'gym.make_vec(ENV_ID, num_envs={NUM_ENVS}, vectorization_mode="vector_entry_point")'}


def child_code(env_id: str, case: str) -> str:
    """The measured process: numpy and gymnasium first, then import -> make -> reset -> first step."""
    return textwrap.dedent(
        f"""
        import json, time, warnings
        import numpy as np
        import gymnasium as gym
        warnings.simplefilter("ignore", DeprecationWarning)  # gymnasium's note on an older version of an id
        ENV_ID = {env_id!r}
        t0 = time.perf_counter()
        import leg_env
        t1 = time.perf_counter()
        env = {CASES[case]}
        env.reset(seed=0)
        env.step(np.zeros(env.action_space.shape, dtype=env.action_space.dtype))
        t2 = time.perf_counter()
        print(json.dumps({{"import": t1 - t0, "seconds": t2 - t0, "file": leg_env.__file__}}))
        """
    )


def parse(done: subprocess.CompletedProcess, inside: Path) -> dict:
    if done.returncode != 0:
        raise RuntimeError(f"the measured process failed:\n{done.stderr[-3000:]}")
    out = json.loads(done.stdout.strip().splitlines()[-1])
    if not Path(out["file"]).is_relative_to(inside):
        raise RuntimeError(f"leg_env was imported from {out['file']}, not from {inside}")
    return out


def measure_wheel(repeat: int) -> tuple[list[dict], str]:
    """Every id and case in the read-only venv of the built wheel, ``repeat`` fresh processes each."""
    work = Path(tempfile.mkdtemp(prefix="leg_env_cold_"))
    try:
        built = wheel_venv.build(work)
        venv = wheel_venv.make_venv(work, built.wheel)
        before = wheel_venv.snapshot(venv.root, venv.home, venv.cwd)
        with wheel_venv.read_only(venv) as locked:
            listed = locked.run("import json, leg_env; print(json.dumps(leg_env.ENV_IDS))")
            ids = json.loads(listed.stdout.strip().splitlines()[-1]) if listed.returncode == 0 else None
            if ids is None:
                raise RuntimeError(listed.stderr)
            times: dict[tuple[str, str], list[dict]] = {(i, c): [] for i in ids for c in CASES}
            for _ in range(repeat):
                for env_id in ids:
                    for case in CASES:
                        out = parse(locked.run(child_code(env_id, case), timeout=300), venv.site_packages)
                        times[env_id, case].append(out)
                        print(f"  {env_id:32s} {case:9s} {out['seconds']:.3f} s", file=sys.stderr)
        if wheel_venv.snapshot(venv.root, venv.home, venv.cwd) != before:
            raise RuntimeError("the measured processes wrote to the read-only venv, HOME or working directory")
        setup = f"{built.wheel.name}, read-only: {locked.how}; dependencies {venv.wheels}"
    finally:
        wheel_venv.cleanup(work)
    rows = []
    for (env_id, case), outs in times.items():
        seconds = [o["seconds"] for o in outs]
        rows.append({"id": env_id, "case": case, "worst": max(seconds), "median": statistics.median(seconds), "import": max(o["import"] for o in outs), "n": len(outs)})
    return rows, setup


def measure_reference(commit: str, env_id: str, budget: float) -> tuple[list[dict], str]:
    """One id, single and batched, from ``commit``'s source tree with an empty numba cache: one process each."""
    tmp = Path(tempfile.mkdtemp(prefix="leg_env_cold_ref_"))
    tree = tmp / "tree"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), commit], check=True, capture_output=True)
    rows = []
    try:
        for case in CASES:
            cache, home, cwd = (Path(tempfile.mkdtemp(dir=tmp)) for _ in range(3))
            env = {k: v for k, v in os.environ.items() if not wheel_venv.UNSAFE_ENV.match(k)}
            env.update(PYTHONPATH=str(tree), NUMBA_CACHE_DIR=str(cache), HOME=str(home))
            row = {"id": env_id, "case": case, "worst": None, "median": None, "import": None, "n": 1}
            try:
                done = subprocess.run([sys.executable, "-c", child_code(env_id, case)], capture_output=True, text=True, env=env, cwd=cwd, timeout=budget)
                out = parse(done, tree)
                row.update(worst=out["seconds"], median=out["seconds"], **{"import": out["import"]})
                print(f"  reference {env_id:32s} {case:9s} {out['seconds']:.1f} s", file=sys.stderr)
            except subprocess.TimeoutExpired:
                row["note"] = f"stopped: not done within {budget:.0f} s"
            rows.append(row)
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], capture_output=True)
        subprocess.run(["git", "-C", str(ROOT), "worktree", "prune"], capture_output=True)
        wheel_venv.cleanup(tmp)
    short = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", commit], capture_output=True, text=True).stdout.strip() or commit
    return rows, f"commit {short}: its source tree on PYTHONPATH, this environment's Python, numba {_version('numba')}, an empty NUMBA_CACHE_DIR"


def _version(name: str) -> str:
    import importlib.metadata

    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def table(rows: list[dict], with_bar: bool = True) -> list[str]:
    def s(x):
        return "-" if x is None else f"{x:.3f}"

    lines = ["| id | case | seconds (slowest) | median | of which `import leg_env` | processes | bar | result |", "|---|---|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        result = r.get("note") or ("pass" if r["worst"] is not None and r["worst"] <= BAR else "FAIL")
        bar = f"{BAR:.1f} s" if with_bar else "-"
        if not with_bar and "note" not in r:
            result = "reference"
        lines.append(f"| `{r['id']}` | {r['case']} | {s(r['worst'])} | {s(r['median'])} | {s(r['import'])} | {r['n']} | {bar} | {result} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--repeat", type=int, default=3, help="fresh processes per id and case (the slowest is compared to the bar)")
    parser.add_argument("--reference", metavar="COMMIT", help="also time one id of this commit's source tree (with an empty numba cache)")
    parser.add_argument("--reference-id", default="leg_env/PlanarLegStance-v0")
    parser.add_argument("--reference-budget", type=float, default=600.0, help="seconds allowed for each reference case")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)

    info = wheel_venv.machine()
    today = datetime.date.today().isoformat()
    header = f"Machine: {info['platform']}, {info['cpu']}, {info['cores']} cores; Python {info['python']}, numpy {info['numpy']}, gymnasium {info['gymnasium']}; {today}"
    print(header, file=sys.stderr)
    rows, setup = measure_wheel(args.repeat)
    lines = [
        "# Cold start: from `import leg_env` to the first step returned",
        "",
        header,
        "",
        f"Built wheel in a fresh venv ({setup}); no bytecode or other cache anywhere; a fresh process per run,"
        f" cwd outside the repository; numpy and gymnasium imported before the clock starts; `make_vec` is"
        f" `gym.make_vec(id, num_envs={NUM_ENVS}, vectorization_mode=\"vector_entry_point\")`. Bar: {BAR:.1f} s for the slowest of"
        f" {args.repeat} processes. Written by `python benchmarks/cold_start.py`.",
        "",
        *table(rows),
    ]
    if args.reference:
        ref_rows, ref_setup = measure_reference(args.reference, args.reference_id, args.reference_budget)
        lines += ["", f"Reference, the numba implementation ({ref_setup}), one process per case:", "", *table(ref_rows, with_bar=False)]
    failed = [r for r in rows if r["worst"] > BAR]
    lines += ["", f"{len(rows) - len(failed)} of {len(rows)} cases within the bar."]
    text = "\n".join(lines) + "\n"
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
