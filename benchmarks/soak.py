"""Soak: millions of env-steps of abuse through ``gymnasium.make_vec``, counting what went wrong.

For each case of ``CASES`` (both contact models of ``leg_env/PlanarLegStance-v0``, the push task (with and without quiet
episodes) and every hop version, and
each of them again with a robot per sub-env drawn at every reset, ``randomize=True``) and
each action kind (``random``: uniform in [-1, 1]; ``bang_bang``: every joint at -1 or +1, each flipping
with probability 0.1 per step), at ten times the default torque limit (``torque_limit=500``), this steps
``num_envs`` robots with autoreset and counts, over every env-step:

* ``non_finite``: non-finite values in the observation, the reward or any numeric ``info`` value;
* ``exceptions``: exceptions raised by ``step`` (a run stops at its first);
* ``unflagged``: env-steps whose state after the step is non-finite or faster than ``max_rate``, or whose
  observation leaves the observation space's bounds, without ``info["numerical_failure"]``; and terminations
  whose ``info["ending"]`` names no limit, or numerical failures it does not name as such;
* ``failures``: flagged numerical failures (each ends its episode; they are allowed), and the
  terminations and truncations.

Not a CI test (``tests/test_soak.py`` runs the same ``soak`` for 10^5 env-steps). Usage::

    python benchmarks/soak.py                 # 10^7 env-steps per case and action kind, N = 4096
    python benchmarks/soak.py --steps 1e6 --num-envs 1024 --json soak.json
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import leg_env

CONTACTS = ("pinned", "unilateral")
CASES = {  # name: (env id, keyword arguments)
    "stance pinned": (leg_env.ENV_ID, {"contact": "pinned"}),
    "stance unilateral": (leg_env.ENV_ID, {"contact": "unilateral"}),
    "push": ("leg_env/PlanarLegPush-v2", {}),
    "hop": ("leg_env/PlanarLegHop-v4", {}),
    "stance pinned randomised": (leg_env.ENV_ID, {"contact": "pinned", "randomize": True}),
    "stance unilateral randomised": (leg_env.ENV_ID, {"contact": "unilateral", "randomize": True}),
    "push randomised": ("leg_env/PlanarLegPush-v2", {"randomize": True}),
    # quiet episodes (no push, flight and the action's change charged more): a training option
    "push quiet": ("leg_env/PlanarLegPush-v2", {"quiet_share": 0.5, "quiet_flight_scale": 24.0, "quiet_change_scale": 5.0, "action_change_weight": 0.2}),
    "hop randomised": ("leg_env/PlanarLegHop-v4", {"randomize": True}),
    "hop command schedule": ("leg_env/PlanarLegHop-v4", {"command_period": 0.5}),  # the training setting
    "hop training charges": ("leg_env/PlanarLegHop-v4", {"drift_near_weight": 390.0, "drift_near_cap": 1.0, "limit_weight": 400.0}),
    # the effort settings: the motor model, heavier power and squared action-rate charges (the last action is observed)
    "hop effort": ("leg_env/PlanarLegHop-v4", {"motor_speed": 8.0, "power_weight": 0.01, "action_rate_weight": 0.5}),
    "stance unilateral effort": (leg_env.ENV_ID, {"contact": "unilateral", "motor_speed": 8.0, "power_weight": 0.01, "action_change_weight": 0.2,
                                                  "observe_action": True}),
}
ACTIONS = ("random", "bang_bang")
TORQUE_LIMIT = 500.0  # ten times the default 50 N m
FLIP = 0.1  # bang-bang: probability that a joint's sign flips in a step
NUMERICAL_FAILURE = leg_env.ENDINGS.index("numerical_failure")


def soak(case: str, actions: str, steps: int, num_envs: int = 4096, seed: int = 0) -> dict:
    """Step ``gym.make_vec(..., num_envs)`` of ``CASES[case]`` for at least ``steps`` env-steps; return the counts
    (module docstring). ``case`` may also be a contact model, for the balance task."""
    env_id, kwargs = CASES[case] if case in CASES else (leg_env.ENV_ID, {"contact": case})
    envs = gym.make_vec(env_id, num_envs=num_envs, torque_limit=TORQUE_LIMIT, **kwargs)
    space = envs.single_observation_space
    max_rate = envs.config.max_rate
    rng = np.random.default_rng(seed)
    counts = dict(case=case, actions=actions, num_envs=num_envs, steps=0, seconds=0.0, non_finite=0, exceptions=0,
                  unflagged=0, failures=0, terminated=0, truncated=0)  # fmt: skip
    envs.reset(seed=seed)
    signs = np.where(rng.random((num_envs, 2)) < 0.5, -1.0, 1.0)
    start = time.perf_counter()
    while counts["steps"] < steps:
        if actions == "random":
            a = rng.uniform(-1.0, 1.0, (num_envs, 2))
        else:
            signs[rng.random((num_envs, 2)) < FLIP] *= -1.0
            a = signs
        try:
            obs, reward, terminated, truncated, info = envs.step(a)
        except Exception as e:  # noqa: BLE001 - counting them is the point
            counts["exceptions"] += 1
            counts["exception"] = repr(e)
            break
        counts["steps"] += num_envs
        failed = info["numerical_failure"]
        bad = ~np.isfinite(obs).all(axis=1) | ~np.isfinite(reward)
        counts["non_finite"] += int((~np.isfinite(obs)).sum() + (~np.isfinite(reward)).sum())
        for key, value in info.items():
            if not key.startswith("_") and isinstance(value, np.ndarray) and value.dtype.kind == "f":
                finite = np.isfinite(value)
                counts["non_finite"] += int((~finite).sum())
                bad |= ~finite.reshape(num_envs, -1).all(axis=1)
        q, qd, anchor = envs.unwrapped.state
        bad |= ~np.isfinite(q).all(axis=1) | ~np.isfinite(qd).all(axis=1) | (np.abs(qd) > max_rate).any(axis=1)
        bad |= ((obs < space.low) | (obs > space.high)).any(axis=1)
        ending = info["ending"]
        counts["unflagged"] += int((bad & ~failed).sum() + (terminated & (ending == 0)).sum()
                                   + (failed & (ending != NUMERICAL_FAILURE)).sum())
        counts["failures"] += int(failed.sum())
        counts["terminated"] += int(terminated.sum())
        counts["truncated"] += int(truncated.sum())
    counts["seconds"] = round(time.perf_counter() - start, 2)
    counts["steps_per_second"] = round(counts["steps"] / max(counts["seconds"], 1e-9))
    envs.close()
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=float, default=1e7, help="env-steps per contact model and action kind")
    parser.add_argument("--num-envs", type=int, default=4096)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", help="also write the results to this file")
    args = parser.parse_args()
    results = []
    for case in CASES:
        for actions in ACTIONS:
            r = soak(case, actions, int(args.steps), args.num_envs, args.seed)
            results.append(r)
            print(json.dumps(r), flush=True)
    ok = all(r["non_finite"] == 0 and r["exceptions"] == 0 and r["unflagged"] == 0 for r in results)
    print(f"total env-steps {sum(r['steps'] for r in results):,}, {sum(r['seconds'] for r in results):.1f} s: "
          f"{'0 non-finite, 0 exceptions, 0 unflagged failures' if ok else 'PROBLEMS, see above'}")  # fmt: skip
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)
    write_results(results, args)
    raise SystemExit(0 if ok else 1)


RESULTS = Path(__file__).resolve().parent / "results" / "soak.md"


def write_results(results: list[dict], args) -> None:
    """The table of ``results`` in ``benchmarks/results/soak.md``, headed by the machine, the versions and the date."""
    import platform
    import time
    from importlib.metadata import version

    cpu = platform.machine()
    try:
        cpu = next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines() if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    lines = [
        "# Soak",
        "",
        f"Written by `python benchmarks/soak.py --steps {args.steps:g} --num-envs {args.num_envs}` on {time.strftime('%Y-%m-%d')}: "
        f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}; Python {platform.python_version()}, "
        f"numpy {version('numpy')}, gymnasium {version('gymnasium')}, leg-env {version('leg-env')}.",
        "",
        "Each row: `num_envs` robots through `gymnasium.make_vec` with autoreset, at ten times the default torque limit. "
        "`failures` are flagged numerical failures (each ends its episode; they are allowed); `non_finite`, `exceptions` and "
        "`unflagged` must be 0.",
        "",
        "| case | actions | env-steps | non_finite | exceptions | unflagged | failures | terminated | env-steps/s |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        lines.append(f"| {r['case']} | {r['actions']} | {r['steps']:,} | {r['non_finite']} | {r['exceptions']} | {r['unflagged']} | "
                     f"{r['failures']} | {r['terminated']:,} | {r['steps_per_second']:,} |")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text("\n".join(lines) + "\n")
    print(f"written: {RESULTS}")


if __name__ == "__main__":
    main()
