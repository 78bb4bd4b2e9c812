"""Train PPO on any leg-env task (default ``leg_env/PlanarLegStance-v0``) with Stable-Baselines3.

    python -m train.ppo --out runs/ppo_stance              # the default configuration
    python -m train.ppo --env-id leg_env/PlanarLegPush-v0 --out runs/ppo_push
    python -m train.ppo --out runs/try --params learning_rate:1.0e-3 n_envs:64

The env is natively batched and reaches SB3 through ``leg_env.sb3``'s VecEnv adapter, wrapped in
``VecNormalize`` as the file's ``normalize`` says (the default normalises returns only). Hyperparameters come from ``train/hyperparams/ppo.yml``
(RL Baselines3 Zoo's format, so the Zoo can train the env with the same file). The trainer is SB3's PPO with each
minibatch's gradient summed over cache-sized chunks (``train.chunked_ppo.ChunkedPPO``): the same update, faster on
large minibatches; its models load with SB3's ``PPO.load``.

A run writes one folder::

    model.zip, vecnormalize.pkl   the selected policy and its normalisation statistics: the one with the
                                  best in-training evaluation (``--no-select-best``: the last one;
                                  ``--select-after N``: the best of those at N env steps or more)
    best/, last/                  model.zip, vecnormalize.pkl, info.json of the best and the last policy
    config.yaml                   the resolved configuration (everything needed to rerun)
    command.txt                   the command line of every invocation (first run and resumes)
    evaluations.json              periodic deterministic evaluations, wall time, fps
    learning_curve.png            evaluation return, survival rate and RMS base drift against steps
    tb/                           TensorBoard logs (SB3's plus reward terms and violation rates)
    checkpoints/                  the last checkpoints (see ``train.checkpoints``)
    train.lock                    present while a process trains into the folder (see ``train.runfolder``)

Resuming: rerunning the same command on a folder with a checkpoint continues from the newest intact
one (with the step counter, optimiser, normalisation statistics, evaluation history and random
generator states); a corrupt one is set aside with a warning that names the file, and the one
before it is used (``train.checkpoints``). Periodic checkpoints are taken between PPO iterations, so
a process killed outright loses at most one checkpoint interval and still ends at the same step
count. A Ctrl-C or a ``kill`` (SIGTERM) saves a checkpoint first; the steps of a rollout it cuts short
are not counted, as their samples are dropped. A run that ended before its first checkpoint is
started again by the same command. The envs restart from fresh episodes with new seeds, so a resumed
run is a valid continuation but not bit-identical to an uninterrupted one. A folder holding a
different configuration is never overwritten without ``--overwrite``, and a folder that another
process is training into is refused.
"""

from __future__ import annotations

import math
import os
import platform
import shutil
import signal
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from leg_env import ENV_ID  # importing leg_env registers the env
from train.checkpoints import (
    CheckpointError,
    file_mode,
    load_checkpoint,
    read_snapshot_info,
    restore_rng,
    save_checkpoint,
    save_snapshot,
    write_json_atomic,
    write_text_atomic,
)
from train.cli import interrupt, parse_args
from train.hyperparameters import DEFAULT_HYPERPARAMS, class_at, display_path, load_hyperparams, parse_override
from train.machine import TANHS, UPDATE_PRECISIONS, cpu_name, native_bfloat16
from train.runfolder import RunFolderError, prepare_run_folder, run_locked, runnable_command

__all__ = ["TrainArgs", "train", "resolve_config", "ppo_kwargs", "load_hyperparams", "ENV_ID", "DEFAULT_HYPERPARAMS"]

EVAL_SEED = 20_000
"""Seed of the in-training evaluation episodes (training envs use small seeds, ``train.evaluate`` 10_000+)."""

EMULATED_BFLOAT16 = (
    "note: --update-precision bfloat16 on a CPU without bfloat16 arithmetic (no avx512_bf16 or amx_bf16 flag): torch "
    "emulates it, and the update runs several times slower than in float32 (figures in docs/training.md). "
    "--update-precision auto picks float32 on this CPU."
)
"""What ``train.ppo`` prints (to stderr) when asked for a bfloat16 update on a CPU that would emulate it."""

@dataclass
class TrainArgs:
    """Train PPO on the planar leg's balance task and write a run folder (see train/ppo.py)."""

    out: Path = Path("runs/ppo_stance")
    """Run folder: model, normalisation statistics, config, logs and checkpoints are written here."""
    env_id: str = ENV_ID
    """Gymnasium id of the environment; its entry in the hyperparameter file is used."""
    hyperparams: Path = DEFAULT_HYPERPARAMS
    """Hyperparameter YAML in RL Zoo format (keyed by env id)."""
    params: list[str] = field(default_factory=list)
    """Hyperparameter overrides as key:value pairs, values read as YAML literals (e.g. learning_rate:1.0e-3)."""
    total_timesteps: int | None = None
    """Environment steps in total, counting those before a resume (None: the file's n_timesteps)."""
    eval_env_kwargs: list[str] = field(default_factory=list)
    """Arguments of the evaluation env as key:value pairs (YAML literals). Default: none, i.e. the
    registered task as is, whatever reward shaping the training env's env_kwargs add."""
    seed: int = 0
    """Seed of the training envs, the network initialisation and the sampling."""
    residual: str | None = None
    """Train a residual on a model-based controller ('lqr', 'hopper', 'gated', 'stepping': train.policy_loading.BASELINES): the
    robots get the controller's action plus residual_scale times the network's (train/residual.py); the
    shipped policy is that sum."""
    residual_scale: float = 0.3
    """With --residual: the largest correction, in action units."""
    critic_warmup: int = 500_000
    """With --init-from lqr or hopper, or with --residual: environment steps during which only the value
    network learns (the cloned actor, or the residual network, is kept fixed with its log_std:
    train.callbacks.FrozenActor); 0 to train both from the start."""
    init_from: str | None = None
    """Start from a trained policy folder's networks (e.g. policies/ppo_stance: every parameter copied, zero
    input weights for observation entries the source lacks), or from a model-based controller cloned into
    the actor ('lqr', 'hopper': behaviour cloning, train/warmstart.py) instead of random networks."""
    eval_freq: int = 100_000
    """Environment steps between evaluations (0 disables them; one is always run at the end)."""
    eval_episodes: int = 20
    """Deterministic episodes per evaluation, run in parallel (seeds 20000 + i)."""
    checkpoint_freq: int = 200_000
    """Environment steps between checkpoints (0: only on Ctrl-C and at the end)."""
    resume: bool = True
    """Continue from the folder's latest checkpoint when its configuration matches."""
    overwrite: bool = False
    """Delete an existing run in the folder and start afresh."""
    select_best: bool = True
    """Ship the policy with the best in-training evaluation (survival rate, then mean return on the
    task) as model.zip, as SB3's EvalCallback and the Zoo keep their best model; the last policy is
    in last/ either way. Guards against PPO's late regressions; evaluation seeds differ from the
    in-training ones, so the final numbers are not selected on."""
    select_after: int = 0
    """Environment steps before which no in-training evaluation is a candidate for the shipped policy (e.g. the
    steps of a training curriculum before its last stage); if none comes after, the last policy is shipped."""
    progress_bar: bool = True
    """Show SB3's progress bar."""
    verbose: int = 1
    """0: quiet; 1: a line per evaluation; 2: also SB3's training tables."""
    torch_threads: int = 1
    """Threads of torch (the policy's forward passes and the PPO update). The environments step on one thread
    and are idle during the update, so on an otherwise idle machine up to one thread per core speeds training;
    the results then depend on the thread count in their last digits."""
    update_precision: str = "float32"
    """Arithmetic of the hidden layers in PPO's update (train.chunked_ppo.ChunkedPPO): 'float32' (SB3's), 'bfloat16'
    (matrix products in bfloat16 with float32 accumulation; parameters, optimiser, output layers and losses
    float32: on a CPU with bfloat16 arithmetic the update runs about twice as fast), or 'auto': bfloat16 on a CPU
    with bfloat16 arithmetic (AVX512-BF16 or AMX), else float32. Over five seeds the hop task learnt as well in
    bfloat16 and the balance task to lower returns (docs/training.md)."""
    tanh: str = "fast"
    """How the networks compute tanh (train.chunked_ppo.ChunkedPPO): 'fast' (FastTanh, 2 sigmoid(2x) - 1: faster where
    torch's tanh kernel is slow, as on an AMD EPYC) or 'torch' (torch's own: faster on an Intel Xeon of the Sapphire
    Rapids class). The same function to float32's rounding, so a run's last digits differ; a resume takes its own."""

    def __post_init__(self):
        check_select_after(self.select_after)
        if self.total_timesteps is not None and self.total_timesteps < 1:
            raise ValueError(f"total_timesteps must be >= 1, got {self.total_timesteps}")
        if self.eval_episodes < 1:
            raise ValueError(f"eval_episodes must be >= 1 (one is always run at the end), got {self.eval_episodes}")
        if self.residual is not None and self.residual.lower() not in _controllers():
            raise ValueError(f"residual must be one of {sorted(_controllers())}, got {self.residual!r}")
        if not 0.0 < self.residual_scale <= 2.0:
            raise ValueError(f"residual_scale must be in (0, 2], got {self.residual_scale}")
        for name in ("eval_freq", "checkpoint_freq", "seed", "critic_warmup"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if not isinstance(self.torch_threads, int) or self.torch_threads < 1:
            raise ValueError(f"torch_threads must be an integer >= 1, got {self.torch_threads!r}")
        if self.update_precision not in ("auto", *UPDATE_PRECISIONS):
            raise ValueError(f"update_precision must be one of {('auto', *UPDATE_PRECISIONS)}, got {self.update_precision!r}")
        if self.tanh not in TANHS:
            raise ValueError(f"tanh must be one of {TANHS}, got {self.tanh!r}")


def _controllers() -> tuple:
    """The names of the model-based controllers (``train.policy_loading.BASELINES``)."""
    from train.policy_loading import BASELINES

    return tuple(BASELINES)


def resolve_config(args: TrainArgs) -> dict:
    """Everything that defines the run, as plain data (saved as ``config.yaml``)."""
    hp = load_hyperparams(args.hyperparams, args.env_id, args.params)
    normalize = hp.pop("normalize", False)
    if normalize is True:
        normalize = {}
    elif normalize is not False and not isinstance(normalize, dict):
        raise ValueError(f"normalize must be true, false or a mapping of VecNormalize arguments, got {normalize!r}")
    if isinstance(normalize, dict):
        normalize = {"gamma": hp.get("gamma", 0.99), **normalize}
    total = args.total_timesteps if args.total_timesteps is not None else hp.pop("n_timesteps", None)
    hp.pop("n_timesteps", None)
    if total is None or int(total) < 1:
        raise ValueError("total_timesteps must be given (or n_timesteps in the hyperparameter file) and be >= 1")
    from train.callbacks import zoo_callbacks

    zoo_callbacks(hp.get("callback"))  # checked before the run folder is touched
    _policy_kwargs(hp.get("policy_kwargs"))  # likewise
    return {
        "env_id": args.env_id,
        "env_kwargs": hp.pop("env_kwargs", None) or {},
        "callback": hp.pop("callback", None),
        "eval_env_kwargs": dict(parse_override(item) for item in args.eval_env_kwargs),
        "seed": int(args.seed),
        "residual": None if args.residual is None else {"controller": args.residual.lower(), "scale": float(args.residual_scale)},
        "critic_warmup": int(args.critic_warmup) if args.residual is not None or (args.init_from is not None and args.init_from.lower() in ("lqr", "hopper")) else 0,
        "init_from": None if args.init_from is None else (args.init_from if args.init_from.lower() in ("lqr", "hopper") else display_path(Path(args.init_from))),
        "n_envs": int(hp.pop("n_envs", 1)),
        "total_timesteps": int(total),
        "policy": hp.pop("policy", "MlpPolicy"),
        "normalize": normalize,
        "ppo": hp,
        "eval": {"freq": int(args.eval_freq), "episodes": int(args.eval_episodes), "seed": EVAL_SEED},
        "select_after": int(args.select_after),
        "checkpoint_freq": int(args.checkpoint_freq),
        "update_precision": update_precision(args.update_precision),
        "tanh": args.tanh,
        "hyperparams_file": display_path(args.hyperparams),
        "overrides": list(args.params),
    }


def check_select_after(value) -> None:
    """``ValueError`` naming ``select_after`` unless it is a whole number of environment steps >= 0."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"select_after must be a whole number of environment steps >= 0, got {value!r}")


def update_precision(name: str) -> str:
    """``TrainArgs.update_precision`` resolved: ``"auto"`` is ``"bfloat16"`` where the CPU has bfloat16 arithmetic."""
    if name == "auto":
        return "bfloat16" if native_bfloat16() else "float32"
    return name


def _schedule(value):
    """A Zoo schedule literal: a number, or ``"lin_<initial>"`` for a linear decay to 0."""
    if isinstance(value, str):
        kind, _, initial = value.partition("_")
        if kind != "lin":
            raise ValueError(f"unknown schedule {value!r}; use a number or 'lin_<initial value>'")
        initial = float(initial)
        return lambda progress_remaining: progress_remaining * initial
    return value


def _with_residual(venv, config: dict):
    """``venv`` as seen by a residual policy (``train.residual``) when the run trains one, else itself."""
    if not config.get("residual"):
        return venv
    from train.policy_loading import load_policy
    from train.residual import ResidualVecEnv

    residual = config["residual"]
    controller = load_policy(residual["controller"], env_kwargs=config["env_kwargs"], env_id=config["env_id"])
    return ResidualVecEnv(venv, controller, residual["scale"])


def _evaluated_policy(model, vec_normalize, config: dict):
    """What the periodic evaluation runs: ``model`` on observations normalised by the training statistics of the
    moment, plus its controller when the run trains a residual (``train.residual``)."""
    from train.policy_loading import TrainedPolicy, with_controller

    policy = TrainedPolicy(model, vec_normalize, config["env_kwargs"], env_id=config["env_id"])
    return with_controller(policy, config["residual"], config["env_kwargs"], config["env_id"]) if config.get("residual") else policy


def warm_start(model, init_from: str, config: dict) -> None:
    """Start ``model`` from ``init_from`` (``TrainArgs.init_from``, ``train.warmstart``)."""
    from train import warmstart

    if init_from.lower() in ("lqr", "hopper"):
        from train.policy_loading import load_policy

        controller = load_policy(init_from.lower(), env_kwargs=config["env_kwargs"], env_id=config["env_id"])
        rms = warmstart.clone_controller(model, controller, config["env_id"], config["env_kwargs"], config["seed"])
        print(f"init_from {init_from}: the actor fitted to its actions, RMS error {rms:.4f} (action units)")
    else:
        warmstart.copy_policy(model, Path(init_from))


def ppo_kwargs(config: dict) -> dict:
    """The keyword arguments of ``ChunkedPPO`` in a resolved ``config`` (``resolve_config``): its ``ppo`` entries (SB3
    PPO's, and ``bounds_loss_coef`` where set), a learning rate or clip range written as a schedule (``"lin_3e-4"``)
    made the callable SB3 takes."""
    kwargs = dict(config["ppo"])
    for key in ("learning_rate", "clip_range", "clip_range_vf"):
        if key in kwargs:
            kwargs[key] = _schedule(kwargs[key])
    if "policy_kwargs" in kwargs:
        kwargs["policy_kwargs"] = _policy_kwargs(kwargs["policy_kwargs"])
    return kwargs


def _policy_kwargs(policy_kwargs):
    """``policy_kwargs`` with a ``features_extractor_class`` given by its class path made the class (ValueError naming
    it if it is not an SB3 features extractor); anything else as it is."""
    if not (isinstance(policy_kwargs, dict) and isinstance(policy_kwargs.get("features_extractor_class"), str)):
        return policy_kwargs
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

    cls = class_at(policy_kwargs["features_extractor_class"], BaseFeaturesExtractor, "policy_kwargs.features_extractor_class",
                   "an SB3 features extractor class")  # fmt: skip
    return {**policy_kwargs, "features_extractor_class": cls}


def _save_atomic(save, path: Path) -> None:
    """Write through ``save(tmp_path)`` to a temporary file next to ``path``, then ``os.replace``."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    os.close(fd)
    try:
        save(tmp)
        os.chmod(tmp, file_mode())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _machine() -> dict:
    import stable_baselines3
    import torch

    return {
        "cpu_count": os.cpu_count(),
        "processor": cpu_name(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
        "stable_baselines3": stable_baselines3.__version__,
    }


def _notice(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _hop_line(result: dict) -> str:
    """The hop task's measures of an evaluation, for the training log (``-`` for one without a value)."""

    def cm(value: float) -> str:
        return f"{100 * value:.2f} cm" if math.isfinite(value) else "-"

    return (f", {result['hops_per_episode']:.1f} hops, apex error {cm(result['mean_abs_apex_error'])}, "
            f"drift after 10 s {cm(result['mean_drift_10s'])}")


def train(args: TrainArgs, command: str | None = None) -> Path:
    """Train (or resume) a run as described by ``args``; returns the run folder.

    ``command``: the line added to the folder's ``command.txt`` (None: this process's command line).

    Raises:
        RunLockedError: another process is training into ``args.out`` (a ``RunFolderError``).
        RunFolderError: the folder holds a run this call may not continue or replace.
        CheckpointError: the folder's checkpoints are all unusable.
    """
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(args.torch_threads)
    try:
        out = Path(args.out)
        config = resolve_config(args)
        return run_locked(out, lambda: _train_locked(args, config, out, command or runnable_command()))
    finally:
        torch.set_num_threads(threads)  # the caller's, as it was


def _train_locked(args: TrainArgs, config: dict, out: Path, command: str) -> Path:
    from stable_baselines3.common.utils import set_random_seed

    from leg_env.sb3 import make_sb3_vec_env
    from train.callbacks import (
        FrozenActor,
        PeriodicCheckpoint,
        PeriodicEvaluation,
        RewardTermsLogger,
        evaluate_now,
        zoo_callbacks,
    )
    from train.chunked_ppo import ChunkedPPO
    from train.episodes import make_batch
    from train.normalize import BatchVecNormalize
    from train.plots import plot_learning_curve

    checkpoint = None
    if prepare_run_folder(out, config, resume=args.resume, overwrite=args.overwrite, log=_notice):
        checkpoint = load_checkpoint(
            out / "checkpoints",
            normalize=config["normalize"] is not False,
            algo=ChunkedPPO,
            tensorboard_log=str(out / "tb"),
            verbose=max(0, args.verbose - 1),
        )
        progress = checkpoint.progress
        progress["resumes"] = progress.get("resumes", 0) + 1
    else:
        progress = {"resumes": 0, "wall_time": 0.0, "evaluations": []}
    write_text_atomic(out / "config.yaml", yaml.safe_dump(config, sort_keys=False))  # a resume may change the totals
    with open(out / "command.txt", "a") as f:
        f.write(command + "\n")

    if config["update_precision"] == "bfloat16" and not native_bfloat16():
        _notice(EMULATED_BFLOAT16)
    n_envs, seed = config["n_envs"], config["seed"]
    scheduled = zoo_callbacks(config.get("callback"))  # the Zoo entry's own callbacks (a curriculum)
    set_random_seed(seed)
    # each (re)start draws fresh episodes from its own block of small seeds
    # the training env's per-env info dicts hold only what SB3 reads; RewardTermsLogger logs from its step_info columns
    venv = make_sb3_vec_env(n_envs, seed=seed + progress["resumes"] * n_envs, env_id=config["env_id"], per_env_info=False, **config["env_kwargs"])
    venv = _with_residual(venv, config)
    if checkpoint is None:
        if config["normalize"] is not False:
            venv = BatchVecNormalize(venv, **config["normalize"])
        model = ChunkedPPO(
            config["policy"],
            venv,
            seed=seed,
            device="cpu",
            tensorboard_log=str(out / "tb"),
            verbose=max(0, args.verbose - 1),
            update_precision=config["update_precision"],
            tanh=config["tanh"],
            **ppo_kwargs(config),
        )
        if config.get("init_from"):
            warm_start(model, config["init_from"], config)
    else:
        if checkpoint.vec_normalize is not None:
            checkpoint.vec_normalize.set_venv(venv)
            venv = BatchVecNormalize.from_vec_normalize(checkpoint.vec_normalize)
        model = checkpoint.model
        model.update_precision = config["update_precision"]  # this invocation's (a resume may run on another CPU)
        model.use_tanh(config["tanh"])  # this invocation's too
        model.set_env(venv)
        restore_rng(checkpoint.rng)
        if args.verbose:
            print(f"resuming {out} from {model.num_timesteps:,} steps ({checkpoint.path})")
    vec_normalize = model.get_vec_normalize_env()

    history = progress["evaluations"]
    start_wall, t0 = progress["wall_time"], time.perf_counter()
    start_steps = model.num_timesteps

    def clock() -> float:
        return start_wall + time.perf_counter() - t0

    def save() -> None:
        progress["wall_time"] = clock()
        save_checkpoint(out / "checkpoints", model, vec_normalize, progress)

    def score(info: dict) -> tuple:
        return (info["survival_rate"], info["mean_return"])

    select_after = config.get("select_after", 0)

    def candidate_best() -> dict | None:
        """best/'s record, unless it predates ``select_after`` (then it is no candidate)."""
        best = read_snapshot_info(out / "best")
        return best if best is not None and best["timesteps"] >= select_after else None

    def report(result: dict) -> None:
        best = candidate_best()
        info = {k: result[k] for k in ("timesteps", "mean_return", "std_return", "survival_rate", "rms_base_drift")}
        if info["timesteps"] >= select_after and (best is None or score(info) >= score(best)):
            save_snapshot(out / "best", model, vec_normalize, info)
        if args.verbose:
            seconds = time.perf_counter() - t0
            rate = (result["timesteps"] - start_steps) / seconds if seconds > 0 else 0.0  # this invocation's, evaluations included
            print(
                f"[{result['timesteps']:>9,} steps, {result['time'] / 60:5.1f} min, {rate:,.0f} steps/s] return "
                f"{result['mean_return']:7.1f} +- {result['std_return']:5.1f}, length {result['mean_length']:6.1f}, "
                f"survival {100 * result['survival_rate']:5.1f}%, RMS drift {100 * result['rms_base_drift']:.2f} cm"
                + (_hop_line(result) if "hops_per_episode" in result else ""),
                flush=True,
            )

    eval_cfg = config["eval"]
    eval_policy = _evaluated_policy(model, vec_normalize, config)
    eval_envs = make_batch(config["env_id"], eval_cfg["episodes"], config["eval_env_kwargs"])
    checkpointer = PeriodicCheckpoint(config["checkpoint_freq"], save)
    callbacks = [
        *scheduled,
        RewardTermsLogger(eval_envs.reward_keys),
        PeriodicEvaluation(eval_envs, eval_policy, eval_cfg["freq"], eval_cfg["seed"], history, report, clock),
        checkpointer,
    ]
    if config.get("critic_warmup"):
        callbacks.append(FrozenActor(config["critic_warmup"]))
    for callback in scheduled:  # the first episodes start under a curriculum's settings (learn resets the env)
        if hasattr(callback, "start_on"):
            callback.start_on(venv, model)
    remaining = config["total_timesteps"] - model.num_timesteps
    try:
        if remaining > 0:
            model.learn(
                remaining,
                callback=callbacks,
                reset_num_timesteps=False,
                progress_bar=args.progress_bar,
                tb_log_name="PPO",
            )
        if not history or history[-1]["timesteps"] != model.num_timesteps:
            result = {"timesteps": int(model.num_timesteps)}
            result.update(evaluate_now(eval_policy, eval_envs, eval_cfg["seed"]))
            result["time"] = round(clock(), 2)
            history.append(result)
            report(result)
    except KeyboardInterrupt:
        if checkpointer.collecting:  # the cut-short rollout's samples are dropped: so are its steps
            model.num_timesteps = checkpointer.rollout_start
        save()
        plot_learning_curve(history, out / "learning_curve.png", config["env_id"]) if history else None
        print(
            f"\ninterrupted at {model.num_timesteps:,} steps; checkpoint saved in {out / 'checkpoints'}. "
            "Run the same command again to resume.",
            file=sys.stderr,
        )
        raise
    finally:
        eval_envs.close()
        venv.close()

    save()
    save_snapshot(out / "last", model, vec_normalize, {k: history[-1][k] for k in ("timesteps", "mean_return", "std_return", "survival_rate", "rms_base_drift")})
    selected = out / ("best" if args.select_best and candidate_best() else "last")
    for name in ("model.zip", "vecnormalize.pkl"):
        if (selected / name).is_file():
            _save_atomic(lambda tmp, src=selected / name: shutil.copyfile(src, tmp), out / name)
        elif (out / name).exists():
            (out / name).unlink()
    steps = model.num_timesteps - start_steps
    seconds = time.perf_counter() - t0
    write_json_atomic(
        out / "evaluations.json",
        {
            "env_id": config["env_id"],
            "total_timesteps": int(model.num_timesteps),
            "wall_time_s": round(progress["wall_time"], 1),
            "fps_this_invocation": round(steps / seconds, 1) if steps > 0 else None,
            "resumes": progress["resumes"],
            "selected": {"from": selected.name, **read_snapshot_info(selected)},
            "machine": _machine(),
            "evaluations": history,
        },
    )
    plot_learning_curve(history, out / "learning_curve.png", config["env_id"])
    return out


def main(argv: list[str] | None = None) -> None:
    args = parse_args(TrainArgs, argv, prog="python -m train.ppo")
    signal.signal(signal.SIGTERM, interrupt)  # `kill` saves a checkpoint like Ctrl-C
    try:
        train(args)
    except KeyboardInterrupt:
        raise SystemExit(130) from None
    except (RunFolderError, CheckpointError) as e:
        raise SystemExit(f"python -m train.ppo: error: {e}") from None


if __name__ == "__main__":
    main()
