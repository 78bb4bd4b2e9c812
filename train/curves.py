"""Learning curves over training seeds: a task's PPO configuration trained from scratch with several seeds,
summarised as RL results should be (Agarwal et al. 2021, the ``rliable`` package).

    python -m train.curves --env-id leg_env/PlanarLegHop-v3 --seeds 5
    python -m train.curves --env-id leg_env/PlanarLegBalance-v0 --seeds 5 --baseline gated --jobs 2

Seed ``s`` trains ``python -m train.ppo --seed s`` (the task's entry in ``train/hyperparams/ppo.yml``, or in the
file of ``--hyperparams``, the same for every seed) into ``<runs>/seed_<s>``, evaluated during training on the same fixed episodes
(seeds 20000+) for every seed. A finished seed is not trained again and an interrupted one resumes from its
checkpoint, so rerunning the command after a stop finishes the sweep. With ``--jobs k`` the seeds train k at a
time in worker processes; a Ctrl-C or a ``kill`` of the command stops every worker at a checkpoint (as
``train.ppo`` stops), and a worker whose command was killed outright stops the same way by itself. Each
seed's selected policy is then
evaluated on ``--episodes`` held-out episodes (seeds 10000+, never used in training or selection), and so is
``--baseline``, a model-based controller, on the same episodes. ``--eval-env-kwargs`` sets the evaluation env
of the in-training and held-out episodes alike (the push task's fixed push magnitude, say); on the push task
the final scores also hold the push curve's headline, the largest impulse survived in 90% of the held-out
episodes with every push of an episode at that impulse (``train.evaluate --push-curve``).

The results page, ``<out>/README.md`` (headed by the machine, the versions and the date), gives:

- the interquartile mean (IQM) across seeds of the in-training survival rate and return, with 95%
  stratified-bootstrap confidence intervals, against environment steps (``curves_steps.png``) and
  against wall-clock time (``curves_time.png``; the seeds' median time at each evaluation), every seed's
  curve drawn faintly beside it;
- every seed's final held-out scores, their IQM with its interval, and the baseline's;
- the shipped seed, named by ``--shipped-seed`` before training (it is written on the page before any
  seed trains) and its rank among the seeds, so that a shipped policy is never picked after the fact.

``scores.json`` holds every number of the page.
"""

from __future__ import annotations

import json
import os
import shlex
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from train.cli import interrupt, parse_args
from train.hyperparameters import DEFAULT_HYPERPARAMS, display_path
from train.machine import TANHS, UPDATE_PRECISIONS, describe

__all__ = ["CurvesArgs", "iqm_interval", "sweep", "main"]

ROOT = Path(__file__).resolve().parents[1]
METRICS = ("survival_rate", "mean_return")
"""The in-training evaluation metrics whose curves are drawn (``train.callbacks.PeriodicEvaluation``)."""
BOOTSTRAP_REPS = 5000
TEST_SEED = 10_000  # the held-out episodes: train.evaluate's default
KEYS = ("push_impulse_90", "survival_rate", "mean_return", "mean_length", "hops_per_episode", "mean_abs_apex_error", "mean_drift_10s")
"""The held-out scores on the page (the push curve's headline for the push task; the hop metrics for the hop
task: ``train.task_metrics.HopTracker``)."""


@dataclass
class CurvesArgs:
    """Train a task's PPO configuration with several seeds and write its learning curves and scores."""

    env_id: str = "leg_env/PlanarLegHop-v3"
    """The task: its entry in the hyperparameter file is trained, the same for every seed."""
    seeds: int = 5
    """Number of training seeds (first_seed, first_seed + 1, ...)."""
    first_seed: int = 0
    """The first training seed."""
    shipped_seed: int | None = None
    """The seed whose policy is (or will be) shipped, chosen before training: the page says where it ranks
    (None: first_seed)."""
    shipped: bool = True
    """Whether the shipped seed's policy is the one shipped in policies/ (--no-shipped: a sweep beside the shipped
    configuration, whose page names that seed as chosen before training, not as shipped)."""
    total_timesteps: int | None = None
    """Environment steps per seed (None: the file's n_timesteps)."""
    hyperparams: Path = DEFAULT_HYPERPARAMS
    """Hyperparameter YAML in RL Zoo format whose env_id entry every seed trains (train.ppo's --hyperparams)."""
    params: list[str] = field(default_factory=list)
    """Hyperparameter overrides for every seed, as train.ppo's --params."""
    eval_freq: int = 2_000_000
    """Environment steps between in-training evaluations (the points of the curves)."""
    eval_episodes: int = 32
    """Episodes per in-training evaluation (seeds 20000 + i, the same for every seed)."""
    eval_env_kwargs: list[str] = field(default_factory=list)
    """Arguments of the evaluation env, in training and on the held-out episodes, for every seed and the
    baseline (train.ppo's --eval-env-kwargs; none: the task as registered)."""
    episodes: int = 100
    """Held-out episodes per seed for the final scores (seeds 10000 + i)."""
    baseline: str | None = None
    """A model-based controller evaluated on the same held-out episodes ('lqr', 'hopper', 'gated', 'stepping')."""
    runs: Path | None = None
    """Folder of the seeds' run folders (None: runs/curves/<task name>, with -randomized when the evaluation
    draws randomised robots)."""
    out: Path | None = None
    """Folder of the results page (None: benchmarks/results/learning/<task name>, with -randomized as for runs)."""
    torch_threads: int = 1
    """Threads of torch in each seed's training (train.ppo's --torch-threads)."""
    update_precision: str = "float32"
    """The arithmetic of the hidden layers in each seed's PPO update (train.ppo's --update-precision)."""
    tanh: str = "fast"
    """How each seed's networks compute tanh (train.ppo's --tanh: 'fast' or 'torch'; the faster depends on the CPU)."""
    select_after: int = 0
    """Environment steps before which no in-training evaluation is a candidate for a seed's selected policy
    (train.ppo's --select-after)."""
    jobs: int = 1
    """Seeds trained at once, each in a process of its own with torch_threads threads (the wall-clock
    curves then show each seed's own time, on its share of the cores)."""
    progress_bar: bool = False
    """Show SB3's progress bar while a seed trains."""

    def __post_init__(self):
        if self.seeds < 1:
            raise ValueError(f"seeds must be >= 1, got {self.seeds}")
        if self.first_seed < 0:
            raise ValueError(f"first_seed must be >= 0, got {self.first_seed}")
        if self.update_precision not in ("auto", *UPDATE_PRECISIONS):  # before any seed trains
            raise ValueError(f"update_precision must be one of {('auto', *UPDATE_PRECISIONS)}, got {self.update_precision!r}")
        if self.tanh not in TANHS:
            raise ValueError(f"tanh must be one of {TANHS}, got {self.tanh!r}")
        if self.shipped_seed is None:
            self.shipped_seed = self.first_seed
        if not self.first_seed <= self.shipped_seed < self.first_seed + self.seeds:
            raise ValueError(f"shipped_seed must be one of the trained seeds {self.first_seed}..{self.first_seed + self.seeds - 1}, got {self.shipped_seed}")
        if self.jobs < 1:
            raise ValueError(f"jobs must be >= 1, got {self.jobs}")
        from train.run import check_select_after

        check_select_after(self.select_after)  # before any seed trains
        if self.episodes < 1 or self.eval_episodes < 1:
            raise ValueError(f"episodes and eval_episodes must be >= 1, got {self.episodes} and {self.eval_episodes}")
        if self.eval_freq < 1:
            raise ValueError(f"eval_freq must be >= 1 (the curves are made of the evaluations), got {self.eval_freq}")
        try:
            eval_env_kwargs(self)
        except ValueError as e:
            raise ValueError(f"eval_env_kwargs: {e}") from None
        name = self.env_id.split("/")[-1] + ("-randomized" if self.randomized else "")
        if self.runs is None:
            self.runs = Path("runs/curves") / name
        if self.out is None:
            self.out = ROOT / "benchmarks" / "results" / "learning" / name

    @property
    def randomized(self) -> bool:
        """Whether the evaluation draws randomised robots (``randomize`` in ``eval_env_kwargs``)."""
        return bool(eval_env_kwargs(self).get("randomize"))


def iqm_interval(scores: np.ndarray, reps: int = BOOTSTRAP_REPS, seed: int = 0) -> tuple[float, float, float]:
    """The IQM of ``scores`` (one per seed) and its 95% stratified-bootstrap confidence interval (rliable's
    ``get_interval_estimates`` on one task): ``(iqm, low, high)``."""
    from rliable import library as rly
    from rliable import metrics

    scores = np.asarray(scores, dtype=np.float64).reshape(-1, 1)
    np.random.seed(seed)  # rliable's bootstrap draws from numpy's global generator: seeded, the page is reproducible
    point, interval = rly.get_interval_estimates({"ppo": scores}, lambda x: np.array([metrics.aggregate_iqm(x)]), reps=reps)
    return float(point["ppo"][0]), float(interval["ppo"][0, 0]), float(interval["ppo"][1, 0])


def _train_seed(args: CurvesArgs, seed: int) -> Path:
    """Train (or finish) one seed's run folder; returns it."""
    from train.ppo import TrainArgs, train

    folder = args.runs / f"seed_{seed}"
    log = folder / "evaluations.json"
    if log.is_file() and (args.total_timesteps is None or json.loads(log.read_text())["total_timesteps"] >= args.total_timesteps):
        return folder  # finished
    train(
        TrainArgs(
            out=folder,
            env_id=args.env_id,
            hyperparams=args.hyperparams,
            params=list(args.params),
            total_timesteps=args.total_timesteps,
            seed=seed,
            eval_freq=args.eval_freq,
            eval_episodes=args.eval_episodes,
            eval_env_kwargs=list(args.eval_env_kwargs),
            progress_bar=args.progress_bar,
            verbose=1,
            torch_threads=args.torch_threads,
            update_precision=args.update_precision,
            tanh=args.tanh,
            select_after=args.select_after,
        ),
        command=seed_command(args, seed),
    )
    return folder


PARENT_POLL_S = 1.0  # how often a worker checks that the command that started it is still there


def _train_in_processes(args: CurvesArgs, seeds: list[int]) -> None:
    """Train ``seeds``, ``args.jobs`` at a time, each in a spawned process of its own (``_train_seed_in_worker``).

    Raises ``RuntimeError`` naming the seed if a worker fails. On any way out before every seed is done (a
    failure, a Ctrl-C, a SIGTERM turned into ``KeyboardInterrupt`` by ``main``), every running worker gets one
    SIGTERM, saves a checkpoint and stops, and is waited for: no worker outlives the command.
    """
    import multiprocessing
    from multiprocessing.connection import wait

    context = multiprocessing.get_context("spawn")
    pending, running = list(seeds), {}
    try:
        while pending or running:
            while pending and len(running) < args.jobs:
                seed = pending.pop(0)
                running[seed] = context.Process(target=_train_seed_in_worker, args=(args, seed), name=f"train.curves seed {seed}")
                running[seed].start()
            wait([worker.sentinel for worker in running.values()])
            for seed, worker in list(running.items()):
                if worker.exitcode is None:
                    continue
                del running[seed]
                if worker.exitcode != 0:
                    raise RuntimeError(f"seed {seed} failed in its worker process (exit code {worker.exitcode}); its traceback is above")
    finally:
        for worker in running.values():
            if worker.is_alive():
                worker.terminate()  # SIGTERM: train.ppo saves a checkpoint and stops
        for worker in running.values():
            worker.join()


def _train_seed_in_worker(args: CurvesArgs, seed: int) -> None:
    """A worker process's seed (``_train_seed``). Ctrl-C reaches the command only, which passes it on as one
    SIGTERM; SIGTERM saves a checkpoint and stops the worker (exit code 130); so does the command's death."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, interrupt)
    parent = os.getppid()

    def watch_parent() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_POLL_S)
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=watch_parent, name="watch the command", daemon=True).start()
    try:
        _train_seed(args, seed)
    except KeyboardInterrupt:
        raise SystemExit(130) from None


def seed_command(args: CurvesArgs, seed: int) -> str:
    """The ``python -m train.ppo`` command that trains seed ``seed`` of the sweep alone (its ``command.txt``)."""
    import shlex

    argv = ["python", "-m", "train.ppo", "--env-id", args.env_id, "--seed", str(seed), "--out", str(args.runs / f"seed_{seed}"),
            "--eval-freq", str(args.eval_freq), "--eval-episodes", str(args.eval_episodes), "--torch-threads", str(args.torch_threads)]
    if Path(args.hyperparams).resolve() != Path(DEFAULT_HYPERPARAMS).resolve():
        argv += ["--hyperparams", str(args.hyperparams)]
    if args.update_precision != "float32":
        argv += ["--update-precision", args.update_precision]
    if args.tanh != "fast":
        argv += ["--tanh", args.tanh]
    if args.total_timesteps is not None:
        argv += ["--total-timesteps", str(args.total_timesteps)]
    if args.select_after:
        argv += ["--select-after", str(args.select_after)]
    if args.eval_env_kwargs:
        argv += ["--eval-env-kwargs", *args.eval_env_kwargs]
    if args.params:
        argv += ["--params", *args.params]
    return shlex.join(argv)


def eval_env_kwargs(args: CurvesArgs) -> dict:
    """The evaluation env's arguments, parsed as train.ppo parses its --eval-env-kwargs."""
    from train.hyperparameters import parse_override

    return dict(parse_override(item) for item in args.eval_env_kwargs)


def _held_out(policy, args: CurvesArgs, env_kwargs: dict) -> dict:
    """A policy's scores on the held-out episodes (``train.evaluate.run_episodes``); on the push task also the
    push curve's 90% impulse (``train.episodes.push_survival``, every push of an episode at one magnitude)."""
    from train.evaluate import PUSH_FORCES, run_episodes
    from train.episodes import push_survival
    from train.task_metrics import is_push_task, largest_survived_impulse

    seeds = [TEST_SEED + i for i in range(args.episodes)]
    summary, _ = run_episodes(policy, seeds, env_kwargs, env_id=args.env_id)
    if is_push_task(args.env_id):
        curve = push_survival(policy, PUSH_FORCES, args.episodes, TEST_SEED, env_kwargs, args.env_id)
        summary["push_impulse_90"] = largest_survived_impulse(curve)
    return {k: summary[k] for k in KEYS if k in summary}


def _curves(histories: dict[int, list[dict]]) -> dict:
    """Per metric, at each evaluation every seed reached: the steps, the seeds' median wall-clock, the IQM and
    its interval, and every seed's value."""
    n = min(len(h) for h in histories.values())
    seeds = sorted(histories)
    steps = [histories[seeds[0]][j]["timesteps"] for j in range(n)]
    out = {"timesteps": steps, "time_s": [float(np.median([histories[s][j]["time"] for s in seeds])) for j in range(n)], "seeds": seeds}
    for metric in METRICS:
        values = np.array([[histories[s][j][metric] for j in range(n)] for s in seeds])  # (seeds, evaluations)
        estimates = [iqm_interval(values[:, j]) for j in range(n)]
        out[metric] = {"per_seed": values.tolist(), "iqm": [e[0] for e in estimates], "low": [e[1] for e in estimates], "high": [e[2] for e in estimates]}
    return out


def _plot(curves: dict, path: Path, x_key: str, x_label: str, title: str) -> None:
    from train.plots import pyplot

    plt = pyplot()
    fig, axes = plt.subplots(1, len(METRICS), figsize=(10.0, 3.6), dpi=100)
    labels = {"survival_rate": "survival rate [%]", "mean_return": "episode return"}
    x = np.asarray(curves[x_key], dtype=float) / (60.0 if x_key == "time_s" else 1.0)
    for ax, metric in zip(axes, METRICS):
        scale = 100.0 if metric == "survival_rate" else 1.0
        c = curves[metric]
        for row in c["per_seed"]:
            ax.plot(x, scale * np.asarray(row), color="C0", alpha=0.25, lw=0.8)
        ax.plot(x, scale * np.asarray(c["iqm"]), "o-", color="C0", ms=3, label=f"IQM of {len(c['per_seed'])} seeds")
        ax.fill_between(x, scale * np.asarray(c["low"]), scale * np.asarray(c["high"]), color="C0", alpha=0.2, label="95% CI")
        ax.set_xlabel(x_label)
        ax.set_ylabel(labels[metric])
        ax.grid(alpha=0.3)
    axes[0].legend(loc="lower right", fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


_COLUMNS = {  # a held-out score's column: its heading and how its value is written
    "push_impulse_90": ("90% survival up to [N s]", lambda v: f"{v:.2f}"),
    "survival_rate": ("survival", lambda v: f"{100 * v:.0f}%"),
    "mean_return": ("return", lambda v: f"{v:.1f}"),
    "mean_length": ("length", lambda v: f"{v:.0f}"),
    "hops_per_episode": ("hops of 50 ms+ per episode", lambda v: f"{v:.1f}"),
    "mean_abs_apex_error": ("mean abs apex error [cm]", lambda v: f"{100 * v:.2f}"),
    "mean_drift_10s": ("mean COM drift after 10 s [cm]", lambda v: "-" if v != v else f"{100 * v:.2f}"),
}


def _fmt(v: float, metric: str) -> str:
    return _COLUMNS[metric][1](v) if metric in _COLUMNS else f"{v:.3g}"


def _resumed(resumes: dict) -> list[str]:
    """The page's line on the seeds whose training was resumed from a checkpoint (none: no line)."""
    resumed = {seed: n for seed, n in resumes.items() if n > 0}
    if not resumed:
        return []
    each = ", ".join(f"seed {seed} {'once' if n == 1 else f'{n} times'}" for seed, n in resumed.items())
    return [f"Resumed from a checkpoint (`train.ppo`'s resume: the same run continued with fresh episodes, not bit-identical "
            f"to an uninterrupted one): {each}.", ""]


def _on(args: CurvesArgs) -> str:
    """How the page names the evaluation env: nothing for the task as registered."""
    kwargs = eval_env_kwargs(args)
    return f" of the task with {', '.join(f'{k}={v!r}' for k, v in kwargs.items())}" if kwargs else ""


def _task(args: CurvesArgs) -> str:
    """The task as the page's title and plots name it: the id, and randomised robots when the evaluation draws them."""
    return args.env_id + (", randomised robots" if args.randomized else "")


def _precisions(by_seed: dict) -> str:
    """The update precision of the seeds' runs, as the page says it (runs from before the option: float32)."""
    kinds = sorted(set(by_seed.values()))
    if len(kinds) == 1:
        return f"the hidden layers in {kinds[0]}" + (" (matrix products in bfloat16, parameters and losses float32)" if kinds[0] == "bfloat16" else "")
    return "; ".join(f"seed {seed} in {kind}" for seed, kind in by_seed.items())


def _named(args: CurvesArgs) -> str:
    """The page's sentence on the seed named before training."""
    if args.shipped:
        return f"The shipped seed, named before training: {args.shipped_seed}"
    return f"The seed to ship, named before training: {args.shipped_seed} (not shipped: \"named\" in the table)"


def _precision_title(final: dict) -> str:
    """What a page's title adds when its seeds' updates ran in bfloat16 (float32, SB3's own, adds nothing)."""
    return ", bfloat16 update" if set(final.get("precision", {}).values()) == {"bfloat16"} else ""


def _page(args: CurvesArgs, header: str, curves: dict, final: dict, baseline: dict | None, command: str) -> str:
    name = args.env_id.split("/")[-1]
    seeds = curves["seeds"]
    lines = [
        f"# Learning curves: {_task(args)}{_precision_title(final)}",
        "",
        f"Written by `{command}` on {time.strftime('%Y-%m-%d')}.",
        "",
        f"Machine: {header}",
        "",
        f"Plain PPO from scratch (SB3 `MlpPolicy`, random initialisation, no controller, no demonstrations), the "
        f"`{args.env_id}` entry of `{display_path(args.hyperparams)}`{' with ' + ' '.join(args.params) if args.params else ''}, "
        f"{len(seeds)} training seeds ({seeds[0]}..{seeds[-1]}). {_named(args)}. "
        f"PPO's update: {_precisions(final.get('precision', {}))} (`train.ppo --update-precision`).",
        "",
        f"Curves: every {args.eval_freq:,} steps each seed's policy runs the same {args.eval_episodes} deterministic "
        f"episodes (seeds 20000+){_on(args)}; the line is the interquartile mean (IQM) across seeds, the band its 95% "
        "stratified-bootstrap confidence interval (rliable), the faint lines the seeds.",
        "",
        *_resumed(final.get("resumes", {})),
        f"![against steps](curves_steps.png)",
        "",
        f"![against wall-clock](curves_time.png)",
        "",
        "| env steps | wall-clock (median) | survival IQM [95% CI] | return IQM [95% CI] |",
        "|---:|---:|---|---|",
    ]
    for j, steps in enumerate(curves["timesteps"]):
        s, r = curves["survival_rate"], curves["mean_return"]
        lines.append(
            f"| {steps:,} | {curves['time_s'][j] / 60:.1f} min | {_fmt(s['iqm'][j], 'survival_rate')} "
            f"[{_fmt(s['low'][j], 'survival_rate')}, {_fmt(s['high'][j], 'survival_rate')}] | {r['iqm'][j]:.1f} [{r['low'][j]:.1f}, {r['high'][j]:.1f}] |"
        )
    keys = [k for k in KEYS if k in final["per_seed"][str(seeds[0])]]
    lines += [
        "",
        f"Final scores: each seed's selected policy"
        + (f" (its best in-training evaluation at {args.select_after:,} steps or more)" if args.select_after else "")
        + f" on {args.episodes} held-out episodes (seeds {TEST_SEED}..{TEST_SEED + args.episodes - 1}, "
        f"never used in training or selection){_on(args)}" + (f"; `{args.baseline}` (model-based controller) on the same episodes." if baseline else "."),
        "",
        "| policy | rank | " + " | ".join(_COLUMNS[k][0] for k in keys) + " |",
        "|---|---:|" + "---:|" * len(keys),
    ]
    for s in seeds:
        row = final["per_seed"][str(s)]
        label = f"PPO seed {s}" + ((" (shipped)" if args.shipped else " (named)") if s == args.shipped_seed else "")
        lines.append(f"| {label} | {final['rank'][str(s)]} | " + " | ".join(_fmt(row[k], k) for k in keys) + " |")
    for metric in final["iqm"]:
        iqm, low, high = final["iqm"][metric]
        cells = ["" if k != metric else f"{_fmt(iqm, metric)} [{_fmt(low, metric)}, {_fmt(high, metric)}]" for k in keys]  # under its own column
        lines.append(f"| PPO, IQM of {len(seeds)} seeds [95% CI]: {_COLUMNS[metric][0]} | | " + " | ".join(cells) + " |")
    if baseline:
        lines.append(f"| {args.baseline} (controller) | | " + " | ".join(_fmt(baseline.get(k, float("nan")), k) for k in keys) + " |")
    by = "the push curve's 90% impulse, then held-out survival, then return" if "push_impulse_90" in keys else "held-out survival, then return"
    lines += ["", f"Rank: by {by}, among the {len(seeds)} seeds (1 = best). The drift is over the episodes "
              "that ran their 10 s (- if none did). Every number is in `scores.json`.", ""]
    return "\n".join(lines)


def _rank_key(scores: dict) -> tuple:
    """The order of the seeds on the page: by the push curve's 90% impulse where there is one, then held-out
    survival, then return (best first)."""
    return (-scores.get("push_impulse_90", 0.0), -scores["survival_rate"], -scores["mean_return"])


def sweep(args: CurvesArgs, command: str | None = None) -> Path:
    """Train every seed, evaluate them and write the results page; returns its folder."""
    from train.policy_loading import load_policy

    command = command or shlex.join(["python", "-m", "train.curves", *sys.argv[1:]])  # quoted: the page's command can be pasted
    header = describe()
    args.out.mkdir(parents=True, exist_ok=True)
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    plan = {"env_id": args.env_id, "seeds": seeds, "shipped_seed": args.shipped_seed, "hyperparams": display_path(args.hyperparams),
            "params": list(args.params), "command": command}
    (args.out / "plan.json").write_text(json.dumps(plan, indent=2) + "\n")  # the shipped seed, on record before training
    histories, final = {}, {"per_seed": {}}
    if args.jobs > 1 and len(seeds) > 1:  # train in parallel processes; the loop below then finds every seed finished
        _train_in_processes(args, seeds)
    for seed in seeds:
        folder = _train_seed(args, seed)
        log = json.loads((folder / "evaluations.json").read_text())
        histories[seed] = log["evaluations"]
        final.setdefault("resumes", {})[str(seed)] = int(log.get("resumes", 0))
        config = yaml.safe_load((folder / "config.yaml").read_text())
        final.setdefault("precision", {})[str(seed)] = config.get("update_precision", "float32")
        policy = load_policy(folder)
        final["per_seed"][str(seed)] = _held_out(policy, args, policy.env_kwargs)
    order = sorted(seeds, key=lambda s: _rank_key(final["per_seed"][str(s)]))
    final["rank"] = {str(s): order.index(s) + 1 for s in seeds}
    summarised = (*METRICS, "push_impulse_90") if "push_impulse_90" in final["per_seed"][str(seeds[0])] else METRICS
    final["iqm"] = {m: iqm_interval([final["per_seed"][str(s)][m] for s in seeds]) for m in summarised}
    kwargs = eval_env_kwargs(args)
    baseline = _held_out(load_policy(args.baseline, kwargs, env_id=args.env_id), args, kwargs) if args.baseline else None
    curves = _curves(histories)
    title = f"{_task(args)}: plain PPO, {len(seeds)} seeds{_precision_title(final)}"
    _plot(curves, args.out / "curves_steps.png", "timesteps", "environment steps", title)
    _plot(curves, args.out / "curves_time.png", "time_s", "wall-clock [min] (median over seeds)", title)
    scores = {**plan, "machine": header, "date": time.strftime("%Y-%m-%d"), "curves": curves, "final": final, "baseline": baseline}
    (args.out / "scores.json").write_text(json.dumps(scores, indent=2) + "\n")
    (args.out / "README.md").write_text(_page(args, header, curves, final, baseline, command))
    print(f"results written to {args.out}/ (the shipped seed {args.shipped_seed} ranks {final['rank'][str(args.shipped_seed)]} of {len(seeds)})")
    return args.out


def main(argv: list[str] | None = None) -> None:
    args = parse_args(CurvesArgs, argv, prog="python -m train.curves")
    previous = signal.signal(signal.SIGTERM, interrupt)  # `kill` stops the sweep at checkpoints, like Ctrl-C
    try:
        sweep(args)
    except KeyboardInterrupt:
        raise SystemExit(130) from None
    finally:
        signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    main()
