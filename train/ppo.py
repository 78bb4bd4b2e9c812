"""Train PPO on any leg-env task (default ``leg_env/PlanarLegStance-v0``) with Stable-Baselines3.

    python -m train.ppo --out runs/ppo_stance              # the default configuration
    python -m train.ppo --env-id leg_env/PlanarLegPush-v2 --out runs/push
    python -m train.ppo --out runs/try --params learning_rate:1.0e-3 n_envs:64

The env is natively batched and reaches SB3 through ``leg_env.sb3``'s VecEnv adapter, wrapped in
``VecNormalize`` as the file's ``normalize`` says (the default normalises returns only). Hyperparameters come from ``train/hyperparams/ppo.yml``
(RL Baselines3 Zoo's format, so the Zoo can train the env with the same file). The trainer is SB3's PPO with each
minibatch's gradient summed over cache-sized chunks (``train.chunked_ppo.ChunkedPPO``): the same update, faster on
large minibatches; its models load with SB3's ``PPO.load``.

A run writes one folder, as ``train.run`` describes it (the arguments, the evaluation and the selection are that
module's, the same as ``train.rllib``'s). The policy is::

    model.zip, vecnormalize.pkl   the selected policy and its normalisation statistics (also in best/ and last/)
    tb/                           TensorBoard logs (SB3's plus reward terms and violation rates)
    checkpoints/<steps>/          model, statistics, progress and random generator states (``train.checkpoints``)

Resuming: rerunning the same command on a folder with a checkpoint continues from the newest intact
one (with the step counter, optimiser, normalisation statistics, evaluation history and random
generator states); a corrupt one is set aside with a warning that names the file, and the one
before it is used (``train.checkpoints``). Periodic checkpoints are taken between PPO iterations, so
a process killed outright loses at most one checkpoint interval and still ends at the same step
count. A Ctrl-C or a ``kill`` (SIGTERM) saves a checkpoint first; the steps of a rollout it cuts short
are not counted, as their samples are dropped. A run that ended before its first checkpoint is
started again by the same command. The envs restart from fresh episodes with new seeds, so a resumed
run is a valid continuation but not bit-identical to an uninterrupted one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from leg_env import ENV_ID  # importing leg_env registers the env
from train.checkpoints import load_checkpoint, restore_rng, save_checkpoint
from train.hyperparameters import DEFAULT_HYPERPARAMS, class_at, display_path, linear_schedule_start, load_hyperparams
from train.machine import TANHS, UPDATE_PRECISIONS, native_bfloat16
from train.run import Run, RunArgs, machine, main as run_main, notice, open_run
from train.runfolder import RunKind

__all__ = ["TrainArgs", "train", "resolve_config", "ppo_kwargs", "load_hyperparams", "ENV_ID", "DEFAULT_HYPERPARAMS", "SB3_RUN"]

SB3_RUN = RunKind(
    command="train.ppo",
    trainer=None,
    resume_keys=("env_id", "env_kwargs", "eval_env_kwargs", "seed", "n_envs", "policy", "normalize", "ppo", "residual", "init_from"),
    policy_files=("model.zip", "vecnormalize.pkl"),
)
"""What a ``train.ppo`` run folder holds (``train.runfolder.RunKind``)."""

EMULATED_BFLOAT16 = (
    "note: --update-precision bfloat16 on a CPU without bfloat16 arithmetic (no avx512_bf16 or amx_bf16 flag): torch "
    "emulates it, and the update runs several times slower than in float32 (figures in docs/training.md). "
    "--update-precision auto picks float32 on this CPU."
)
"""What ``train.ppo`` prints (to stderr) when asked for a bfloat16 update on a CPU that would emulate it."""


@dataclass
class TrainArgs(RunArgs):
    """Train PPO on the planar leg's balance task and write a run folder (see train/ppo.py)."""

    out: Path = Path("runs/ppo_stance")
    """Run folder: model, normalisation statistics, config, logs and checkpoints are written here."""
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
    progress_bar: bool = True
    """Show SB3's progress bar."""
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
        super().__post_init__()
        if self.residual is not None and self.residual.lower() not in _controllers():
            raise ValueError(f"residual must be one of {sorted(_controllers())}, got {self.residual!r}")
        if not 0.0 < self.residual_scale <= 2.0:
            raise ValueError(f"residual_scale must be in (0, 2], got {self.residual_scale}")
        if self.critic_warmup < 0:
            raise ValueError(f"critic_warmup must be >= 0, got {self.critic_warmup}")
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
    total = args.total(hp)
    from train.callbacks import zoo_callbacks

    zoo_callbacks(hp.get("callback"))  # checked before the run folder is touched
    _policy_kwargs(hp.get("policy_kwargs"))  # likewise
    return {
        "env_id": args.env_id,
        "env_kwargs": hp.pop("env_kwargs", None) or {},
        "callback": hp.pop("callback", None),
        "eval_env_kwargs": args.eval_env_config(),
        "seed": int(args.seed),
        "residual": None if args.residual is None else {"controller": args.residual.lower(), "scale": float(args.residual_scale)},
        "critic_warmup": int(args.critic_warmup) if args.residual is not None or (args.init_from is not None and args.init_from.lower() in ("lqr", "hopper")) else 0,
        "init_from": None if args.init_from is None else (args.init_from if args.init_from.lower() in ("lqr", "hopper") else display_path(Path(args.init_from))),
        "n_envs": int(hp.pop("n_envs", 1)),
        "total_timesteps": total,
        "policy": hp.pop("policy", "MlpPolicy"),
        "normalize": normalize,
        "ppo": hp,
        **args.evaluation_config(),
        "update_precision": update_precision(args.update_precision),
        "tanh": args.tanh,
        **args.source_config(),
    }


def update_precision(name: str) -> str:
    """``TrainArgs.update_precision`` resolved: ``"auto"`` is ``"bfloat16"`` where the CPU has bfloat16 arithmetic."""
    if name == "auto":
        return "bfloat16" if native_bfloat16() else "float32"
    return name


def _schedule(value):
    """A Zoo schedule literal: a number, or ``"lin_<initial>"`` for a linear decay to 0."""
    initial = linear_schedule_start(value)
    if initial is None:
        return value
    return lambda progress_remaining: progress_remaining * initial


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


def train(args: TrainArgs, command: str | None = None) -> Path:
    """Train (or resume) a run as described by ``args``; returns the run folder.

    ``command``: the line added to the folder's ``command.txt`` (None: this process's command line).

    Raises:
        RunLockedError: another process is training into ``args.out`` (a ``RunFolderError``).
        RunFolderError: the folder holds a run this call may not continue or replace.
        CheckpointError: the folder's checkpoints are all unusable.
    """
    return open_run(args, resolve_config(args), SB3_RUN, lambda run: _train_locked(run, args), command)


def _train_locked(run: Run, args: TrainArgs) -> Path:
    """The run's life once its folder is locked and prepared (``train.run``): build, learn, finish."""
    import stable_baselines3

    from train.callbacks import PeriodicCheckpoint

    model, venv, scheduled = _model(run, args)
    vec_normalize = model.get_vec_normalize_env()

    def save() -> None:
        save_checkpoint(run.out / "checkpoints", model, vec_normalize, run.stamp())

    evaluated = _evaluated_policy(model, vec_normalize, run.config)
    eval_envs = run.begin(model.num_timesteps, lambda: evaluated, lambda folder: _save_policy(folder, model, vec_normalize))
    checkpointer = PeriodicCheckpoint(run.config["checkpoint_freq"], save)
    callbacks = _callbacks(run, scheduled, eval_envs, checkpointer)
    for callback in scheduled:  # the first episodes start under a curriculum's settings (learn resets the env)
        if hasattr(callback, "start_on"):
            callback.start_on(venv, model)
    try:
        remaining = run.config["total_timesteps"] - model.num_timesteps
        if remaining > 0:
            model.learn(remaining, callback=callbacks, reset_num_timesteps=False, progress_bar=args.progress_bar, tb_log_name="PPO")
        run.evaluate_last(model.num_timesteps)
    except KeyboardInterrupt:
        if checkpointer.collecting:  # the cut-short rollout's samples are dropped: so are its steps
            model.num_timesteps = checkpointer.rollout_start
        save()
        run.interrupted(model.num_timesteps)
        raise
    finally:
        run.close()
        venv.close()
    save()
    return run.finish(model.num_timesteps, machine(stable_baselines3=stable_baselines3.__version__))


def _model(run: Run, args: TrainArgs):
    """``(model, venv, scheduled)``: the model on its training envs, new or from the run's newest intact checkpoint,
    and the Zoo entry's own callbacks (a curriculum). The invocation is recorded (``Run.start``) before the envs
    are made, so that a start that fails on their arguments leaves its configuration in the folder."""
    from stable_baselines3.common.utils import set_random_seed

    from leg_env.sb3 import make_sb3_vec_env
    from train.callbacks import zoo_callbacks
    from train.chunked_ppo import ChunkedPPO

    config = run.config
    checkpoint = None
    if run.resuming:
        checkpoint = load_checkpoint(run.out / "checkpoints", normalize=config["normalize"] is not False, algo=ChunkedPPO,
                                     tensorboard_log=str(run.out / "tb"), verbose=max(0, args.verbose - 1))  # fmt: skip
        progress = checkpoint.progress
        progress["resumes"] = progress.get("resumes", 0) + 1
    else:
        progress = {"resumes": 0, "wall_time": 0.0, "evaluations": []}
    run.start(progress)
    if config["update_precision"] == "bfloat16" and not native_bfloat16():
        notice(EMULATED_BFLOAT16)
    n_envs, seed = config["n_envs"], config["seed"]
    scheduled = zoo_callbacks(config.get("callback"))
    set_random_seed(seed)
    # each (re)start draws fresh episodes from its own block of small seeds
    # the training env's per-env info dicts hold only what SB3 reads; RewardTermsLogger logs from its step_info columns
    venv = make_sb3_vec_env(n_envs, seed=seed + progress["resumes"] * n_envs, env_id=config["env_id"], per_env_info=False, **config["env_kwargs"])
    venv = _with_residual(venv, config)
    if checkpoint is None:
        model, venv = _new_model(run, args, venv)
    else:
        model, venv = _resumed_model(run, args, checkpoint, venv)
    return model, venv, scheduled


def _new_model(run: Run, args: TrainArgs, venv):
    """A new ``ChunkedPPO`` on ``venv`` (normalised as the configuration says), warm-started if it asks."""
    from train.chunked_ppo import ChunkedPPO
    from train.normalize import BatchVecNormalize

    config = run.config
    if config["normalize"] is not False:
        venv = BatchVecNormalize(venv, **config["normalize"])
    model = ChunkedPPO(
        config["policy"],
        venv,
        seed=config["seed"],
        device="cpu",
        tensorboard_log=str(run.out / "tb"),
        verbose=max(0, args.verbose - 1),
        update_precision=config["update_precision"],
        tanh=config["tanh"],
        **ppo_kwargs(config),
    )
    if config.get("init_from"):
        warm_start(model, config["init_from"], config)
    return model, venv


def _resumed_model(run: Run, args: TrainArgs, checkpoint, venv):
    """The checkpoint's model and statistics on ``venv``, with its random generator states restored."""
    from train.normalize import BatchVecNormalize

    if checkpoint.vec_normalize is not None:
        checkpoint.vec_normalize.set_venv(venv)
        venv = BatchVecNormalize.from_vec_normalize(checkpoint.vec_normalize)
    model = checkpoint.model
    model.update_precision = run.config["update_precision"]  # this invocation's (a resume may run on another CPU)
    model.use_tanh(run.config["tanh"])  # this invocation's too
    model.set_env(venv)
    restore_rng(checkpoint.rng)
    if args.verbose:
        print(f"resuming {run.out} from {model.num_timesteps:,} steps ({checkpoint.path})")
    return model, venv


def _callbacks(run: Run, scheduled: list, eval_envs, checkpointer) -> list:
    """SB3's callbacks of the run: the Zoo entry's, the reward terms' log, the periodic evaluation, the checkpoints
    and, during a critic warm-up, the frozen actor."""
    from train.callbacks import FrozenActor, PeriodicEvaluation, RewardTermsLogger

    callbacks = [*scheduled, RewardTermsLogger(eval_envs.reward_keys), PeriodicEvaluation(run.evaluate_if_due), checkpointer]
    if run.config.get("critic_warmup"):
        callbacks.append(FrozenActor(run.config["critic_warmup"]))
    return callbacks


def _save_policy(folder: Path, model, vec_normalize) -> None:
    """The policy's files in ``folder``: ``model.zip`` and, when the run normalises, ``vecnormalize.pkl``."""
    model.save(folder / "model.zip", exclude=["tensorboard_log"])  # a machine's path; a policy needs none
    if vec_normalize is not None:
        vec_normalize.save(folder / "vecnormalize.pkl")


def main(argv: list[str] | None = None) -> None:
    run_main(TrainArgs, train, "python -m train.ppo", argv)


if __name__ == "__main__":
    main()
