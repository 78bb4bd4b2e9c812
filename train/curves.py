"""Learning curves over training seeds: a task's PPO configuration trained from scratch with several seeds,
summarised as RL results should be (Agarwal et al. 2021, the ``rliable`` package).

    python -m train.curves --env-id leg_env/PlanarLegHop-v4 --seeds 5
    python -m train.curves --env-id leg_env/PlanarLegBalance-v1 --seeds 5 --baseline gated --jobs 2

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
- every seed's final held-out scores, their IQM with its interval, and the controllers';
- the shipped seed, named by ``--shipped-seed`` before training (it is written on the page before any
  seed trains) and its rank among the seeds, so that a shipped policy is never picked after the fact;
- how each seed moves on the held-out episodes (``train.motion``: torso tilt, action rate, saturated share,
  actuator power, peak normal force, flights, COM excursion), the IQM across seeds with its interval and the
  controllers beside them (``motion.png`` draws them), and on the push task the same with no push at all;
- the task's acceptance bars (``train.bars``) for each seed, passed or failed with the number measured, and how
  many seeds meet every bar (``train.learning_page`` writes these two sections).

The controllers on the held-out episodes are ``--baseline`` and those the task's bars compare with (the gated
controller and the LQR on the balance task, the hopper on the hop task, the stepping controller on the push task),
each seed beside each of them also on the episodes both survive. ``scores.json`` holds every number of the page:
per seed in ``final.per_seed`` (the scores, ``motion``, ``both_survived``, ``no_push`` on the push task, ``bars``),
the motion measures' IQM in ``final.motion_iqm``, and each controller in ``controllers`` (``baseline`` repeats
``--baseline``'s).
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

__all__ = ["CurvesArgs", "iqm", "iqm_interval", "sweep", "main"]

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

    env_id: str = "leg_env/PlanarLegHop-v4"
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
    """A model-based controller evaluated on the same held-out episodes ('lqr', 'hopper', 'gated', 'stepping'); the
    controllers the task's bars compare with run there too."""
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


def iqm(scores: np.ndarray) -> float:
    """The interquartile mean of ``scores`` (the mean of every entry but the lowest and the highest quarter), as
    rliable's ``metrics.aggregate_iqm`` computes it (SciPy's ``trim_mean`` at 0.25 over every entry: the same
    partition, the same mean), without SciPy's handling of its arguments at each call, which took nine tenths of a
    page's time in the bootstrap's thousands of calls."""
    a = np.ravel(scores)
    low = int(0.25 * a.size)
    high = a.size - low
    return float(np.mean(np.partition(a, (low, high - 1))[low:high]))


def iqm_interval(scores: np.ndarray, reps: int = BOOTSTRAP_REPS, seed: int = 0) -> tuple[float, float, float]:
    """The IQM of ``scores`` (one per seed) and its 95% stratified-bootstrap confidence interval (rliable's
    ``get_interval_estimates`` on one task, of ``iqm``): ``(iqm, low, high)``."""
    from rliable import library as rly

    scores = np.asarray(scores, dtype=np.float64).reshape(-1, 1)
    np.random.seed(seed)  # rliable's bootstrap draws from numpy's global generator: seeded, the page is reproducible
    point, interval = rly.get_interval_estimates({"ppo": scores}, lambda x: np.array([iqm(x)]), reps=reps)
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


def _held_out(policy, args: CurvesArgs, env_kwargs: dict, push_curve: bool = True) -> dict:
    """A policy's evaluation on the held-out episodes, as ``train.evaluate`` makes it for one controller:
    ``train.evaluate.run_episodes``' summary (the motion measures among them) with the env's id and arguments and
    the control period ``dt``. On the push task also the same seeds with no push (``no_push``,
    ``train.evaluate.run_without_pushes``) and, with ``push_curve``, the push curve's 90% impulse
    (``train.episodes.push_survival``, every push of an episode at one magnitude)."""
    from train.evaluate import PUSH_FORCES, run_episodes, run_without_pushes
    from train.episodes import push_survival
    from train.task_metrics import is_push_task, largest_survived_impulse

    seeds = [TEST_SEED + i for i in range(args.episodes)]
    summary, series = run_episodes(policy, seeds, env_kwargs, record=0, env_id=args.env_id)
    result = {"env_id": args.env_id, "env_kwargs": env_kwargs, "dt": series["dt"], **summary}
    if is_push_task(args.env_id):
        result["no_push"] = run_without_pushes(policy, seeds, env_kwargs, args.env_id)
        if push_curve:
            curve = push_survival(policy, PUSH_FORCES, args.episodes, TEST_SEED, env_kwargs, args.env_id)
            result["push_impulse_90"] = largest_survived_impulse(curve)
    return result


def _kept(result: dict) -> dict:
    """What ``scores.json`` keeps of a held-out evaluation: the page's scores (``KEYS``), the motion measures and, on
    the push task, the episodes with no push."""
    kept = {**{k: result[k] for k in KEYS if k in result}, "motion": result["motion"]}
    if "no_push" in result:
        kept["no_push"] = result["no_push"]
    return kept


def _without_seeds(pooled: dict) -> dict:
    """A ``train.motion.both_survived`` entry without its list of seeds (its ``episodes`` count kept)."""
    return {k: v for k, v in pooled.items() if k != "seeds"}


def _controllers(args: CurvesArgs) -> list[str]:
    """The controllers run on the held-out episodes: ``--baseline``, then those the task's bars compare with
    (``train.bars``), each once."""
    from train.bars import bar_controllers
    from train.policy_loading import BASELINES

    named = [args.baseline.lower() if args.baseline.lower() in BASELINES else args.baseline] if args.baseline else []
    return list(dict.fromkeys(named + list(bar_controllers(args.env_id, eval_env_kwargs(args)))))


def _beside_controllers(seed: int, result: dict, controllers: dict[str, dict], kept: dict[str, dict], env_id: str) -> dict:
    """A seed's kept scores, with its motion measures on the episodes it and each controller both survive
    (``both_survived``, by controller) and its bars (``bars``, ``train.bars.check_bars``); each controller's measures
    on those episodes go into ``kept[name]["both_survived"][str(seed)]``."""
    from train.bars import check_bars
    from train.motion import both_survived

    label = f"PPO seed {seed}"
    results = {label: result, **{name: dict(r) for name, r in controllers.items()}}  # copies: both_survived adds to them
    both_survived(results, label, result["dt"])
    for name in controllers:
        kept[name].setdefault("both_survived", {})[str(seed)] = _without_seeds(results[name]["both_survived"][label])
    mine = {name: _without_seeds(pooled) for name, pooled in result.get("both_survived", {}).items()}
    scores = {**_kept(result), **({"both_survived": mine} if mine else {})}
    scores["bars"] = [check.as_dict() for check in check_bars(results, env_id)]
    return scores


def _motion_iqm(motions: list[dict]) -> dict:
    """Each motion measure's IQM across seeds with its interval, ``{measure: (iqm, low, high)}`` (nan where a seed's
    measure is nan)."""
    from train.motion import KEYS as MOTION_KEYS

    estimates = {}
    for key in MOTION_KEYS[1:]:  # not the episodes' count
        values = np.array([m[key] for m in motions], dtype=np.float64)
        estimates[key] = iqm_interval(values) if np.all(np.isfinite(values)) else (float("nan"),) * 3
    return estimates


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
    from train.plots import pyplot, save_figure

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
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path)


_COLUMNS = {  # a held-out score's column: its heading and how its value is written
    "push_impulse_90": ("90% survival up to [N s]", lambda v: f"{v:.2f}"),
    "survival_rate": ("survival", lambda v: f"{100 * v:.0f}%"),
    "mean_return": ("return", lambda v: f"{v:.1f}"),
    "mean_length": ("length", lambda v: f"{v:.0f}"),
    "hops_per_episode": ("hops of 50 ms+ per episode", lambda v: f"{v:.1f}"),
    "mean_abs_apex_error": ("mean abs apex error [cm]", lambda v: f"{100 * v:.2f}"),
    "mean_drift_10s": ("mean COM drift after 10 s [cm]", lambda v: "-" if v != v else f"{100 * v:.2f}"),
}


def _plot_motion(final: dict, controllers: dict[str, dict], path: Path) -> None:
    """How each seed moves beside the controllers (``train.plots.plot_motion``: a bar per seed and controller)."""
    from train.plots import plot_motion

    plot_motion({f"seed {seed}": scores for seed, scores in final["per_seed"].items()} | controllers, path)


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


def _controllers_sentence(controllers: dict[str, dict]) -> str:
    """The end of the page's sentence on the final scores: which controllers ran the same episodes."""
    if not controllers:
        return "."
    names = ", ".join(f"`{name}`" for name in controllers)
    return f"; {names} (model-based controller{'s' if len(controllers) > 1 else ''}) on the same episodes."


def _seed_label(args: CurvesArgs, seed: int) -> str:
    """A seed's name in the page's tables, the seed named before training marked."""
    return f"PPO seed {seed}" + ((" (shipped)" if args.shipped else " (named)") if seed == args.shipped_seed else "")


def _page(args: CurvesArgs, header: str, curves: dict, final: dict, controllers: dict[str, dict], command: str) -> str:
    """The results page from the sweep's numbers: ``controllers`` holds each controller's kept scores (the
    baseline first)."""
    from train.learning_page import bars_section, motion_section

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
        f"never used in training or selection){_on(args)}" + _controllers_sentence(controllers),
        "",
        "| policy | rank | " + " | ".join(_COLUMNS[k][0] for k in keys) + " |",
        "|---|---:|" + "---:|" * len(keys),
    ]
    for s in seeds:
        row = final["per_seed"][str(s)]
        lines.append(f"| {_seed_label(args, s)} | {final['rank'][str(s)]} | " + " | ".join(_fmt(row[k], k) for k in keys) + " |")
    for metric in final["iqm"]:
        iqm, low, high = final["iqm"][metric]
        cells = ["" if k != metric else f"{_fmt(iqm, metric)} [{_fmt(low, metric)}, {_fmt(high, metric)}]" for k in keys]  # under its own column
        lines.append(f"| PPO, IQM of {len(seeds)} seeds [95% CI]: {_COLUMNS[metric][0]} | | " + " | ".join(cells) + " |")
    for name, scores in controllers.items():
        lines.append(f"| {name} (controller) | | " + " | ".join(_fmt(scores[k], k) if k in scores else "-" for k in keys) + " |")
    by = "the push curve's 90% impulse, then held-out survival, then return" if "push_impulse_90" in keys else "held-out survival, then return"
    lines += ["", f"Rank: by {by}, among the {len(seeds)} seeds (1 = best). The drift is over the episodes "
              "that ran their 10 s (- if none did). Every number is in `scores.json`.", ""]
    labels = {str(s): _seed_label(args, s) for s in seeds}
    lines += motion_section(final, controllers, labels)
    lines += bars_section(final, labels, args.env_id, eval_env_kwargs(args))
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
    histories, evaluations, final = {}, {}, {"per_seed": {}}
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
        evaluations[seed] = _held_out(policy, args, policy.env_kwargs)
    kwargs = eval_env_kwargs(args)
    names = _controllers(args)
    baseline_name = names[0] if args.baseline else None  # the push curve is the baseline's only
    controllers = {name: _held_out(load_policy(name, kwargs, env_id=args.env_id), args, kwargs, push_curve=name == baseline_name)
                   for name in names}  # fmt: skip
    kept = {name: _kept(result) for name, result in controllers.items()}
    for seed in seeds:
        final["per_seed"][str(seed)] = _beside_controllers(seed, evaluations[seed], controllers, kept, args.env_id)
    order = sorted(seeds, key=lambda s: _rank_key(final["per_seed"][str(s)]))
    final["rank"] = {str(s): order.index(s) + 1 for s in seeds}
    summarised = (*METRICS, "push_impulse_90") if "push_impulse_90" in final["per_seed"][str(seeds[0])] else METRICS
    final["iqm"] = {m: iqm_interval([final["per_seed"][str(s)][m] for s in seeds]) for m in summarised}
    final["motion_iqm"] = {"all": _motion_iqm([final["per_seed"][str(s)]["motion"] for s in seeds])}
    if "no_push" in final["per_seed"][str(seeds[0])]:
        final["motion_iqm"]["no_push"] = _motion_iqm([final["per_seed"][str(s)]["no_push"]["motion"] for s in seeds])
    curves = _curves(histories)
    title = f"{_task(args)}: plain PPO, {len(seeds)} seeds{_precision_title(final)}"
    _plot(curves, args.out / "curves_steps.png", "timesteps", "environment steps", title)
    _plot(curves, args.out / "curves_time.png", "time_s", "wall-clock [min] (median over seeds)", title)
    _plot_motion(final, kept, args.out / "motion.png")
    baseline = kept[baseline_name] if baseline_name else None
    scores = {**plan, "machine": header, "date": time.strftime("%Y-%m-%d"), "curves": curves, "final": final, "baseline": baseline,
              "controllers": kept}  # fmt: skip
    (args.out / "scores.json").write_text(json.dumps(scores, indent=2) + "\n")
    (args.out / "README.md").write_text(_page(args, header, curves, final, kept, command))
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
