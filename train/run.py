"""The life of a training run in its folder, the same for ``train.ppo`` (Stable-Baselines3) and ``train.rllib``
(Ray RLlib): the arguments they share, the folder, resuming, the in-training evaluation and the policy kept.

A run writes one folder::

    config.yaml            the resolved configuration (everything needed to rerun)
    command.txt            the command line of every invocation (first run and resumes)
    checkpoints/<steps>/   the trainer's checkpoints (the two newest), each written to a temporary folder first
    best/, last/           the policy of the best in-training evaluation and the last one, with info.json
    <the policy>           the selected policy: ``train.ppo``'s model.zip and vecnormalize.pkl, ``train.rllib``'s
                           module/ (RLlib's RLModule); the one with the best in-training evaluation
                           (``--no-select-best``: the last one; ``--select-after N``: the best of those at N env
                           steps or more)
    evaluations.json       the in-training evaluations, the selection, wall time, fps, the machine
    learning_curve.png     evaluation return, survival rate and RMS base drift against steps
    train.lock             present while a process trains into the folder (``train.runfolder``)

and each trainer its own files besides (``train.ppo``: ``tb/``; ``train.rllib``: ``progress.json``,
``runners.json``). An invocation goes through the same steps with either trainer:

1. ``open_run``: torch's threads set, the folder locked, and a fresh start, a resume or a refusal decided
   (``train.runfolder.prepare_run_folder``: a folder holding another configuration is never overwritten without
   ``--overwrite``);
2. ``Run.start``: the trainer has built its learner (from the newest intact checkpoint when resuming: step
   counter, optimiser, statistics, evaluation history) and the run records the invocation in ``config.yaml``
   and ``command.txt``;
3. ``Run.begin``, then while the trainer trains, ``Run.evaluate`` every ``--eval-freq`` env steps: deterministic
   episodes of the policy as it is (seeds ``EVAL_SEED + i``, ``train.episodes.evaluate_now``), each result a
   candidate for ``best/`` (survival rate, then mean return); checkpoints every ``--checkpoint-freq``, with
   ``Run.stamp``'s progress;
4. ``Run.evaluate_last``: an evaluation at the last step; the trainer's last checkpoint; ``Run.finish``:
   ``last/``, the selected policy copied to the top of the folder, ``evaluations.json`` and the learning curve. A Ctrl-C or a ``kill`` (SIGTERM) saves a checkpoint
   instead (``Run.interrupted``); running the same command again resumes.
"""

from __future__ import annotations

import math
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from leg_env import ENV_ID  # importing leg_env registers the ids
from train.checkpoints import (
    CheckpointError,
    copy_policy,
    read_snapshot_info,
    save_snapshot,
    write_json_atomic,
    write_text_atomic,
)
from train.cli import interrupt, parse_args
from train.hyperparameters import DEFAULT_HYPERPARAMS, display_path, parse_override
from train.runfolder import RunFolderError, RunKind, prepare_run_folder, run_locked, runnable_command

__all__ = ["RunArgs", "Run", "open_run", "main", "machine", "check_select_after", "Every", "EVAL_SEED", "notice"]

EVAL_SEED = 20_000
"""Seed of the in-training evaluation episodes (training envs use small seeds, ``train.evaluate`` 10_000+)."""
SUMMARY_KEYS = ("timesteps", "mean_return", "std_return", "survival_rate", "rms_base_drift")
"""What ``best/``'s and ``last/``'s ``info.json`` keep of their evaluation."""


@dataclass
class RunArgs:
    """The arguments every trainer takes, with the same meaning (``train.ppo.TrainArgs``, ``train.rllib.RLlibArgs``)."""

    out: Path = Path("runs/ppo_stance")
    """Run folder: the policy, config, logs and checkpoints are written here."""
    env_id: str = ENV_ID
    """Gymnasium id of the leg-env task; its entry in the hyperparameter file is used."""
    hyperparams: Path = DEFAULT_HYPERPARAMS
    """Hyperparameter YAML in RL Zoo format (keyed by env id)."""
    params: list[str] = field(default_factory=list)
    """Hyperparameter overrides as key:value pairs, values read as YAML literals (e.g. learning_rate:1.0e-3)."""
    total_timesteps: int | None = None
    """Environment steps in total, counting those before a resume (None: the file's n_timesteps)."""
    seed: int = 0
    """Seed of the training: network initialisation, sampling and the training envs' seeds."""
    eval_env_kwargs: list[str] = field(default_factory=list)
    """Arguments of the evaluation env as key:value pairs (YAML literals). Default: none, i.e. the
    registered task as is, whatever reward shaping the training env's env_kwargs add."""
    eval_freq: int = 100_000
    """Environment steps between evaluations (0 disables them; one is always run at the end)."""
    eval_episodes: int = 20
    """Deterministic episodes per evaluation, run in parallel (seeds 20000 + i)."""
    select_best: bool = True
    """Ship the policy with the best in-training evaluation (survival rate, then mean return on the
    task), as SB3's EvalCallback and the Zoo keep their best model; the last policy is in last/ either
    way. Guards against PPO's late regressions; evaluation seeds differ from the in-training ones, so
    the final numbers are not selected on."""
    select_after: int = 0
    """Environment steps before which no in-training evaluation is a candidate for the shipped policy (e.g. the
    steps of a training curriculum before its last stage); if none comes after, the last policy is shipped."""
    checkpoint_freq: int = 200_000
    """Environment steps between checkpoints (0: only on Ctrl-C and at the end)."""
    resume: bool = True
    """Continue from the folder's latest checkpoint when its configuration matches."""
    overwrite: bool = False
    """Delete an existing run in the folder and start afresh."""
    torch_threads: int = 1
    """Threads of torch in this process (the policy's forward passes and, unless RLlib runs it elsewhere, the PPO
    update). The environments step on one thread and are idle during the update, so on an otherwise idle machine up
    to one thread per core speeds training; the results then depend on the thread count in their last digits."""
    verbose: int = 1
    """0: quiet; 1: a line per evaluation (and per RLlib iteration); 2: also SB3's training tables."""

    def __post_init__(self):
        check_select_after(self.select_after)
        if self.total_timesteps is not None and self.total_timesteps < 1:
            raise ValueError(f"total_timesteps must be >= 1, got {self.total_timesteps}")
        if self.eval_episodes < 1:
            raise ValueError(f"eval_episodes must be >= 1 (one is always run at the end), got {self.eval_episodes}")
        for name in ("eval_freq", "checkpoint_freq", "seed"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if isinstance(self.torch_threads, bool) or not isinstance(self.torch_threads, int) or self.torch_threads < 1:
            raise ValueError(f"torch_threads must be an integer >= 1, got {self.torch_threads!r}")

    def total(self, hp: dict) -> int:
        """The run's env steps: ``total_timesteps``, else the hyperparameter entry ``hp``'s ``n_timesteps`` (popped)."""
        total = self.total_timesteps if self.total_timesteps is not None else hp.get("n_timesteps")
        hp.pop("n_timesteps", None)
        if total is None or int(total) < 1:
            raise ValueError("total_timesteps must be given (or n_timesteps in the hyperparameter file) and be >= 1")
        return int(total)

    def evaluation_config(self) -> dict:
        """``config.yaml``'s ``eval``, ``select_after`` and ``checkpoint_freq`` entries."""
        return {
            "eval": {"freq": int(self.eval_freq), "episodes": int(self.eval_episodes), "seed": EVAL_SEED},
            "select_after": int(self.select_after),
            "checkpoint_freq": int(self.checkpoint_freq),
        }

    def eval_env_config(self) -> dict:
        """``eval_env_kwargs`` as a mapping."""
        return dict(parse_override(item) for item in self.eval_env_kwargs)

    def source_config(self) -> dict:
        """``config.yaml``'s ``hyperparams_file`` and ``overrides`` entries: where the hyperparameters came from."""
        return {"hyperparams_file": display_path(self.hyperparams), "overrides": list(self.params)}


def check_select_after(value) -> None:
    """``ValueError`` naming ``select_after`` unless it is a whole number of environment steps >= 0."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"select_after must be a whole number of environment steps >= 0, got {value!r}")


class Every:
    """Due each time a step counter passes a multiple of ``freq`` (never if ``freq <= 0``)."""

    def __init__(self, freq: int, done: int = 0):
        self.freq = int(freq)
        self.start_after(done)

    def start_after(self, done: int) -> None:
        """The first time due comes at the first multiple of ``freq`` after ``done`` steps."""
        self.next = (done // self.freq + 1) * self.freq if self.freq > 0 else None

    def due(self, steps: int) -> bool:
        """Whether ``steps`` has passed the next multiple of ``freq`` (which then moves on)."""
        if self.next is None or steps < self.next:
            return False
        while self.next <= steps:
            self.next += self.freq
        return True


def notice(message: str) -> None:
    """A line for the user on stderr."""
    print(message, file=sys.stderr, flush=True)


def _hop_line(result: dict) -> str:
    """The hop task's measures of an evaluation, for the training log (``-`` for one without a value)."""

    def cm(value: float) -> str:
        return f"{100 * value:.2f} cm" if math.isfinite(value) else "-"

    return (f", {result['hops_per_episode']:.1f} hops, apex error {cm(result['mean_abs_apex_error'])}, "
            f"drift after 10 s {cm(result['mean_drift_10s'])}")


def _motion_line(motion: dict) -> str:
    """How the robot moved in an evaluation (``train.motion``), for the training log."""
    return (f"; tilt {motion['tilt_rms']:.1f} deg, action rate {motion['action_rate']:.3g}, saturated "
            f"{100 * motion['saturated_share']:.1f}%, power {motion['actuator_power']:.1f} W, {motion['flights_per_episode']:.1f} flights")


def _score(info: dict) -> tuple:
    """What the selection of the best policy compares: survival rate, then mean return."""
    return (info["survival_rate"], info["mean_return"])


class Run:
    """One invocation of a trainer on its run folder (the module docstring's steps), made by ``open_run``.

    ``resuming`` says whether the trainer is to restore the newest intact checkpoint; ``progress`` is what its
    checkpoints keep of the run (this class keeps ``wall_time`` and the ``evaluations`` in it, the trainer its
    own entries), ``history`` the evaluations.
    """

    def __init__(self, args: RunArgs, config: dict, kind: RunKind, command: str):
        self.args, self.config, self.kind, self.command = args, config, kind, command
        self.out = Path(args.out)
        self.resuming = prepare_run_folder(self.out, config, kind, resume=args.resume, overwrite=args.overwrite, log=notice)
        self.progress: dict = {}
        self.history: list[dict] = []
        self._envs = None

    def start(self, progress: dict) -> None:
        """Record this invocation: ``config.yaml`` (a resume may change the totals) and a line of ``command.txt``.
        ``progress``: the restored checkpoint's, or a new run's."""
        self.progress = progress
        self.history = progress.setdefault("evaluations", [])
        progress.setdefault("wall_time", 0.0)
        write_text_atomic(self.out / "config.yaml", yaml.safe_dump(self.config, sort_keys=False))
        with open(self.out / "command.txt", "a") as f:
            f.write(self.command + "\n")

    def begin(self, steps: int, policy: Callable[[], object], save_policy: Callable[[Path], None]):
        """Start the clock at ``steps`` env steps and open the evaluation episodes; returns their batch.

        ``policy()``: the policy as it is now, with SB3's ``predict`` on raw observations. ``save_policy(folder)``
        writes it (``kind.policy_files``) into ``folder``.
        """
        from train.episodes import make_batch

        self.policy, self.save_policy = policy, save_policy
        self.start_steps, self.start_wall, self.t0 = steps, self.progress["wall_time"], time.perf_counter()
        self.evaluations = Every(self.config["eval"]["freq"], self.history[-1]["timesteps"] if self.history else 0)
        self._envs = make_batch(self.config["env_id"], self.config["eval"]["episodes"], self.config["eval_env_kwargs"])
        return self._envs

    def clock(self) -> float:
        """Seconds of training of the run so far, over every invocation."""
        return self.start_wall + time.perf_counter() - self.t0

    def stamp(self) -> dict:
        """``progress`` with its wall time brought up to now, for a checkpoint."""
        self.progress["wall_time"] = self.clock()
        return self.progress

    def evaluate(self, steps: int) -> dict:
        """Evaluate the policy now, record the result in ``history``, keep the policy in ``best/`` if it is the best
        candidate so far, print a line (``verbose``); returns the result."""
        from train.episodes import evaluate_now

        result = {"timesteps": int(steps)}
        result.update(evaluate_now(self.policy(), self._envs, self.config["eval"]["seed"]))
        result["time"] = round(self.clock(), 2)
        self.history.append(result)
        best = self._best()
        if result["timesteps"] >= self.config["select_after"] and (best is None or _score(result) >= _score(best)):
            save_snapshot(self.out / "best", self.save_policy, {k: result[k] for k in SUMMARY_KEYS})
        if self.args.verbose:
            seconds = time.perf_counter() - self.t0
            rate = (steps - self.start_steps) / seconds if seconds > 0 else 0.0  # this invocation's, evaluations included
            print(
                f"[{steps:>9,} steps, {result['time'] / 60:5.1f} min, {rate:,.0f} steps/s] return "
                f"{result['mean_return']:7.1f} +- {result['std_return']:5.1f}, length {result['mean_length']:6.1f}, "
                f"survival {100 * result['survival_rate']:5.1f}%, RMS drift {100 * result['rms_base_drift']:.2f} cm"
                + (_hop_line(result) if "hops_per_episode" in result else "")
                + _motion_line(result["motion"]),
                flush=True,
            )
        return result

    def evaluate_if_due(self, steps: int) -> dict | None:
        """``evaluate`` when ``steps`` has passed the next multiple of ``--eval-freq``."""
        return self.evaluate(steps) if self.evaluations.due(steps) else None

    def evaluate_last(self, steps: int) -> None:
        """The evaluation at the last step, unless the last one was there already."""
        if not self.history or self.history[-1]["timesteps"] != steps:
            self.evaluate(steps)

    def _best(self) -> dict | None:
        """best/'s record, unless it predates ``select_after`` (then it is no candidate)."""
        best = read_snapshot_info(self.out / "best")
        return best if best is not None and best["timesteps"] >= self.config["select_after"] else None

    def close(self) -> None:
        """Close the evaluation episodes."""
        if self._envs is not None:
            self._envs.close()
            self._envs = None

    def interrupted(self, steps: int) -> None:
        """After a Ctrl-C or SIGTERM, once the trainer has saved its checkpoint: the learning curve so far, and what
        to do."""
        from train.plots import plot_learning_curve

        if self.history:
            plot_learning_curve(self.history, self.out / "learning_curve.png", self.config["env_id"])
        notice(f"\ninterrupted at {steps:,} steps; checkpoint saved in {self.out / 'checkpoints'}. "
               "Run the same command again to resume.")  # fmt: skip

    def finish(self, steps: int, machine: dict) -> Path:
        """After the last checkpoint: ``last/``, the selected policy at the top of the folder, ``evaluations.json``
        and the learning curve; returns the run folder."""
        from train.plots import plot_learning_curve

        save_snapshot(self.out / "last", self.save_policy, {k: self.history[-1][k] for k in SUMMARY_KEYS})
        selected = self.out / ("best" if self.args.select_best and self._best() else "last")
        copy_policy(selected, self.out, self.kind.policy_files)
        done, seconds = steps - self.start_steps, time.perf_counter() - self.t0
        write_json_atomic(
            self.out / "evaluations.json",
            {
                "env_id": self.config["env_id"],
                "total_timesteps": int(steps),
                "wall_time_s": round(self.progress["wall_time"], 1),
                "fps_this_invocation": round(done / seconds, 1) if done > 0 else None,
                "resumes": self.progress.get("resumes", 0),
                "selected": {"from": selected.name, **read_snapshot_info(selected)},
                "machine": machine,
                "evaluations": self.history,
            },
        )
        plot_learning_curve(self.history, self.out / "learning_curve.png", self.config["env_id"])
        return self.out


def open_run(args: RunArgs, config: dict, kind: RunKind, body: Callable[[Run], Path], command: str | None = None) -> Path:
    """Run ``body(run)`` on the run folder ``args.out``, locked and prepared (``Run``), with torch on
    ``args.torch_threads`` threads (the caller's count restored after); returns what ``body`` returns.

    ``command``: the line added to the folder's ``command.txt`` (None: this process's command line).
    """
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(args.torch_threads)
    try:
        out = Path(args.out)
        return run_locked(out, lambda: body(Run(args, config, kind, command or runnable_command())))
    finally:
        torch.set_num_threads(threads)


def machine(**packages: str) -> dict:
    """The machine a run trained on, for ``evaluations.json``: CPUs, processor, Python, torch (and its threads),
    and the versions of ``packages`` (name: version)."""
    import os
    import platform

    import torch

    from train.machine import cpu_name

    return {
        "cpu_count": os.cpu_count(),
        "processor": cpu_name(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
        **packages,
    }


def main(args_class: type, train: Callable, prog: str, argv: list[str] | None = None) -> None:
    """A trainer's command: parse ``argv`` into ``args_class``, ``train`` it; a ``kill`` (SIGTERM) stops it as a
    Ctrl-C does (a checkpoint is saved, exit status 130); a run folder it may not use is an error message."""
    args = parse_args(args_class, argv, prog=prog)
    signal.signal(signal.SIGTERM, interrupt)
    try:
        train(args)
    except KeyboardInterrupt:
        raise SystemExit(130) from None
    except (RunFolderError, CheckpointError) as e:
        raise SystemExit(f"{prog}: error: {e}") from None
