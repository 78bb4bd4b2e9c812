"""Train PPO on a leg-env task with Ray RLlib's new API stack, on this machine or on a Ray cluster.

    python -m train.rllib --out runs/rllib_stance                          # a local Ray on every CPU
    python -m train.rllib --out runs/rllib_uni --params "env_kwargs:{contact: unilateral}"
    RAY_ADDRESS=10.0.0.1:6379 python -m train.rllib --out runs/rllib --num-env-runners 32
    python -m train.evaluate runs/rllib_stance --baseline lqr

Needs the ``rllib`` extra (``pip install -e '.[rllib]'`` after CPU torch). Each env runner steps
leg-env's native batch (``leg_env.rllib``: one kernel call for all its robots, seeds that no two
runners share). Hyperparameters come from the same Zoo-format file as ``train.ppo``
(``train/hyperparams/ppo.yml``, ``--params`` overrides). Where a key maps onto RLlib's PPO it is used:

    n_envs          the env runners' robots in total: num_envs_per_env_runner = ceil(n_envs / runners)
                    unless --num-envs-per-env-runner is given
    n_steps         train_batch_size = n_steps * n_envs env steps per iteration, as SB3 (split over
                    the learners)
    n_timesteps     the env steps to train for (--total-timesteps overrides)
    batch_size      minibatch_size          n_epochs       num_epochs
    learning_rate   lr; "lin_<x>" becomes the schedule [[0, x], [n_timesteps, 0]]
    gamma           gamma                   gae_lambda     lambda_
    clip_range      clip_param              clip_range_vf  vf_clip_param (SB3's None: no clipping, inf)
    ent_coef        entropy_coeff           vf_coef        vf_loss_coeff
    max_grad_norm   grad_clip (global norm)
    policy_kwargs.net_arch   fcnet_hiddens (separate policy and value MLPs with tanh, as SB3's MlpPolicy)
    env_kwargs      the training envs' arguments (evaluation uses the task as registered, as train.ppo)

and these do not map; the run prints which it ignored and keeps them in ``config.yaml`` under
``not_mapped``:

    normalize.norm_reward    SB3's VecNormalize reward scaling has no RLlib counterpart: the value
                             function learns the raw returns, unclipped (vf_clip_param inf)
    normalize.norm_obs       only false is accepted (the observations are O(1); true is an error)
    policy_kwargs.log_std_init   RLlib's Gaussian head starts from the network's output
    policy, stats_window_size    RLlib's default MLP; logging only

``target_kl``, ``use_sde``, ``bounds_loss_coef`` (``train.chunked_ppo``'s) and schedules of ``clip_range`` are
errors (RLlib's ``kl_target`` is an adaptive penalty, not SB3's early stop). RLlib's own KL penalty is off (``use_kl_loss=False``), as SB3's
PPO has none, and advantages are standardised per batch as in SB3.

The run folder::

    config.yaml         the resolved configuration (the RLlib settings and what did not map)
    command.txt         the command line of every invocation
    progress.json       one entry per training iteration (steps, return, sampling throughput, time)
    runners.json        the node (Ray's id and IP) of every env runner of the latest invocation
    checkpoints/<steps>/    RLlib checkpoints (``Algorithm.save_to_path``) with progress.json, the two newest
    train.lock          while a process trains into the folder (``train.runfolder.RunLock``)

A checkpoint is written every ``--checkpoint-freq`` env steps (at the end of the iteration that
crosses it), at the end, and on Ctrl-C or SIGTERM; it goes to a temporary folder first and is renamed
into place, so a killed run leaves only whole checkpoints. Rerunning the same command resumes from
the newest one (weights, optimiser, step count; ``restart`` in the envs' seeds draws new episodes);
a checkpoint that does not restore is set aside with a warning and the previous one is used. A folder
holding a different configuration is refused unless ``--overwrite``. ``train.evaluate`` loads the run
folder (its newest checkpoint) or any of its checkpoints as a policy with SB3's ``predict``.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from leg_env import ENV_ID
from train.checkpoints import write_json_atomic, write_text_atomic
from train.cli import interrupt, parse_args
from train.hyperparameters import DEFAULT_HYPERPARAMS, display_path, load_hyperparams, parse_override
from train.runfolder import RunFolderError, run_locked, runnable_command

__all__ = ["RLlibArgs", "train", "resolve_config", "rllib_config", "latest_checkpoint", "RLlibPolicy", "is_rllib_checkpoint", "is_rllib_run", "runner_nodes"]

TRAINER = "rllib-ppo"
"""``config.yaml``'s ``trainer`` entry: how ``train.evaluate`` tells an RLlib run from an SB3 one."""
CHECKPOINT_MARKER = "rllib_checkpoint.json"
"""The file RLlib writes at the top of an algorithm checkpoint."""
PROGRESS = "progress.json"
RUNNERS = "runners.json"  # where the env runners of the latest invocation ran
RESUME_KEYS = ("env_id", "env_kwargs", "seed", "learning_rate", "ppo", "model")
"""Entries of ``config.yaml`` a resume must match (the scaling knobs may change between invocations)."""


@dataclass
class RLlibArgs:
    """Train PPO on a leg-env task with Ray RLlib (new API stack) and write a run folder (see train/rllib.py)."""

    out: Path = Path("runs/rllib_stance")
    """Run folder: configuration, progress and checkpoints are written here."""
    env: str = ENV_ID
    """Gymnasium id of the leg-env task; its entry in the hyperparameter file is used."""
    hyperparams: Path = DEFAULT_HYPERPARAMS
    """Hyperparameter YAML in RL Zoo format (keyed by env id), the file train.ppo reads."""
    params: list[str] = field(default_factory=list)
    """Hyperparameter overrides as key:value pairs, values read as YAML literals (e.g. n_envs:256)."""
    total_timesteps: int | None = None
    """Environment steps in total, counting those before a resume (None: the file's n_timesteps)."""
    seed: int = 0
    """RLlib's config seed: network initialisation, sampling and (with the worker indices) the envs' seeds."""
    num_env_runners: int = 1
    """Env runner actors sampling in parallel (0: sample in this process)."""
    num_envs_per_env_runner: int | None = None
    """Robots in each runner's native batch (None: ceil(n_envs / num_env_runners))."""
    num_learners: int = 0
    """Learner actors (0: one learner in this process); the batch is split over them."""
    num_cpus_per_env_runner: float | None = None
    """CPUs Ray reserves for each env runner (None: env_threads)."""
    env_threads: int = 1
    """Threads each env runner's native batch is stepped with (the batch's ``num_threads``)."""
    numba_threads: int | None = None
    """Deprecated name of env_threads, from when the physics was numba code; removed in the next release."""
    checkpoint_freq: int = 200_000
    """Environment steps between checkpoints (0: only at the end and on Ctrl-C)."""
    address: str | None = None
    """Ray cluster to join (e.g. 10.0.0.1:6379). None: RAY_ADDRESS if set, else a local Ray."""
    num_cpus: int | None = None
    """CPUs of a local Ray (None: all of this machine's); not used when joining a cluster."""
    eval_env_kwargs: list[str] = field(default_factory=list)
    """Arguments of train.evaluate's env as key:value pairs (default: the registered task as is)."""
    overwrite: bool = False
    """Delete an existing run in the folder and start afresh."""
    verbose: int = 1
    """0: quiet; 1: a line per iteration."""

    def __post_init__(self):
        if self.numba_threads is not None:
            warnings.warn("--numba-threads is deprecated and will be removed in the next release: use --env-threads",
                          DeprecationWarning, stacklevel=2)  # fmt: skip
            self.env_threads, self.numba_threads = self.numba_threads, None
        if self.total_timesteps is not None and self.total_timesteps < 1:
            raise ValueError(f"total_timesteps must be >= 1, got {self.total_timesteps}")
        for name in ("num_env_runners", "num_learners", "checkpoint_freq", "seed"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        for name in ("num_envs_per_env_runner", "env_threads", "num_cpus"):
            value = getattr(self, name)
            if value is not None and value < 1:
                raise ValueError(f"{name} must be >= 1, got {value}")
        if self.num_cpus_per_env_runner is not None and self.num_cpus_per_env_runner <= 0:
            raise ValueError(f"num_cpus_per_env_runner must be > 0, got {self.num_cpus_per_env_runner}")


_MAPPED = {
    "batch_size": "minibatch_size",
    "n_epochs": "num_epochs",
    "gamma": "gamma",
    "gae_lambda": "lambda_",
    "clip_range": "clip_param",
    "ent_coef": "entropy_coeff",
    "vf_coef": "vf_loss_coeff",
    "max_grad_norm": "grad_clip",
}
_REFUSED = ("target_kl", "use_sde", "sde_sample_freq", "callback", "bounds_loss_coef")


def resolve_config(args: RLlibArgs) -> dict:
    """Everything that defines the run, as plain data (saved as ``config.yaml``)."""
    hp = load_hyperparams(args.hyperparams, args.env, args.params)
    refused = sorted(k for k in _REFUSED if k in hp and hp[k] not in (None, False))
    if refused:
        raise ValueError(f"{refused} have no counterpart in RLlib's PPO; remove them (see train/rllib.py)")
    for key in _REFUSED:  # what is left of them is off (None, false, 0): nothing to map
        hp.pop(key, None)
    not_mapped = {}
    normalize = hp.pop("normalize", False)
    if normalize is True:
        normalize = {}
    if isinstance(normalize, dict):
        if normalize.get("norm_obs", True):
            raise ValueError("normalize.norm_obs: true has no counterpart in train.rllib; set it to false")
        not_mapped["normalize"] = normalize
    elif normalize is not False:
        raise ValueError(f"normalize must be true, false or a mapping, got {normalize!r}")
    n_envs = int(hp.pop("n_envs", 1))
    total = args.total_timesteps if args.total_timesteps is not None else hp.get("n_timesteps")
    hp.pop("n_timesteps", None)
    if total is None or int(total) < 1:
        raise ValueError("total_timesteps must be given (or n_timesteps in the hyperparameter file) and be >= 1")
    total = int(total)
    n_steps = int(hp.pop("n_steps", 2048))

    ppo = {"train_batch_size": n_steps * n_envs, "use_kl_loss": False, "vf_clip_param": math.inf}
    for key, name in _MAPPED.items():
        if key in hp:
            ppo[name] = hp.pop(key)
    if "grad_clip" in ppo:
        ppo["grad_clip_by"] = "global_norm"
    if "clip_range" in ppo and not isinstance(ppo["clip_param"], (int, float)):
        raise ValueError(f"clip_range must be a number for train.rllib, got {ppo['clip_param']!r}")
    if hp.get("clip_range_vf") is not None:
        ppo["vf_clip_param"] = float(hp["clip_range_vf"])
    hp.pop("clip_range_vf", None)
    if hp.pop("normalize_advantage", True) is not True:
        raise ValueError("normalize_advantage: false has no counterpart in RLlib's PPO (it always standardises)")
    learning_rate = hp.pop("learning_rate", 3.0e-4)
    _lr(learning_rate, total)  # checked here, built by rllib_config over the run's total

    policy_kwargs = dict(hp.pop("policy_kwargs", None) or {})
    model = {"fcnet_hiddens": list(policy_kwargs.pop("net_arch", [64, 64])), "fcnet_activation": "tanh", "vf_share_layers": False}
    if policy_kwargs:
        not_mapped["policy_kwargs"] = policy_kwargs
    for key in ("policy", "stats_window_size"):
        if key in hp:
            not_mapped[key] = hp.pop(key)
    env_kwargs = hp.pop("env_kwargs", None) or {}
    assert not hp, f"unhandled hyperparameters {sorted(hp)}"  # load_hyperparams accepts only the keys above

    runners = args.num_env_runners
    return {
        "trainer": TRAINER,
        "env_id": args.env,
        "env_kwargs": env_kwargs,
        "eval_env_kwargs": dict(parse_override(item) for item in args.eval_env_kwargs),
        "seed": int(args.seed),
        "n_envs": n_envs,
        "total_timesteps": total,
        "learning_rate": learning_rate,
        "ppo": ppo,
        "model": model,
        "not_mapped": not_mapped,
        "scaling": {
            "num_env_runners": runners,
            "num_envs_per_env_runner": args.num_envs_per_env_runner or -(-n_envs // max(1, runners)),
            "num_learners": args.num_learners,
            "num_cpus_per_env_runner": args.num_cpus_per_env_runner or args.env_threads,
            "env_threads": args.env_threads,
        },
        "checkpoint_freq": int(args.checkpoint_freq),
        "hyperparams_file": display_path(args.hyperparams),
        "overrides": list(args.params),
    }


def _lr(learning_rate, total: int):
    """RLlib's ``lr``: a number, or for the Zoo's ``"lin_<x>"`` the schedule ``[[0, x], [total, 0]]``."""
    if isinstance(learning_rate, str):
        kind, _, initial = learning_rate.partition("_")
        if kind != "lin":
            raise ValueError(f"unknown schedule {learning_rate!r}; use a number or 'lin_<initial value>'")
        return [[0, float(initial)], [total, 0.0]]
    return float(learning_rate)


def rllib_config(config: dict, restart: int = 0):
    """RLlib's ``PPOConfig`` for a resolved configuration (``restart``: resumes so far, in the envs' seeds)."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    import leg_env.rllib

    scaling, ppo = config["scaling"], dict(config["ppo"])
    env_kwargs = dict(config["env_kwargs"])
    if scaling["env_threads"] > 1:
        env_kwargs["num_threads"] = scaling["env_threads"]
    learners = max(1, scaling["num_learners"])
    train_batch = ppo.pop("train_batch_size")
    return (
        PPOConfig()
        .environment(leg_env.rllib.register(), env_config={"env_id": config["env_id"], "env_kwargs": env_kwargs, "restart": restart})
        .env_runners(
            num_env_runners=scaling["num_env_runners"],
            num_envs_per_env_runner=scaling["num_envs_per_env_runner"],
            num_cpus_per_env_runner=scaling["num_cpus_per_env_runner"],
            gym_env_vectorize_mode="vector_entry_point",
            rollout_fragment_length="auto",
        )
        .callbacks(on_environment_created=leg_env.rllib.on_environment_created)
        .learners(num_learners=scaling["num_learners"])
        .training(
            train_batch_size_per_learner=-(-train_batch // learners), lr=_lr(config["learning_rate"], config["total_timesteps"]), **ppo
        )
        .rl_module(model_config=DefaultModelConfig(**config["model"]))
        .debugging(seed=config["seed"])
    )


def _checkpoints(folder: Path) -> list[Path]:
    """The complete checkpoints in ``folder``, oldest first (a complete one has its progress.json)."""
    if not folder.is_dir():
        return []
    found = [p for p in folder.iterdir() if p.is_dir() and p.name.isdigit() and (p / PROGRESS).is_file()]
    return sorted(found, key=lambda p: int(p.name))


def latest_checkpoint(run: Path) -> Path | None:
    """The newest complete checkpoint of an RLlib run folder (None: none yet)."""
    found = _checkpoints(Path(run) / "checkpoints")
    return found[-1] if found else None


def is_rllib_checkpoint(path: Path) -> bool:
    return (Path(path) / CHECKPOINT_MARKER).is_file()


def is_rllib_run(path: Path) -> bool:
    config = Path(path) / "config.yaml"
    if not config.is_file():
        return False
    try:
        return (yaml.safe_load(config.read_text()) or {}).get("trainer") == TRAINER
    except (yaml.YAMLError, AttributeError):
        return False


def _save(algo, folder: Path, progress: dict, keep: int = 2) -> Path:
    """Write a checkpoint to a temporary folder, rename it into place, keep the ``keep`` newest."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{progress['timesteps']:012d}"
    tmp = folder / f".tmp-{path.name}-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    algo.save_to_path(str(tmp.resolve()))
    write_json_atomic(tmp / PROGRESS, progress)
    if path.exists():
        shutil.rmtree(path)
    os.replace(tmp, path)
    for old in _checkpoints(folder)[:-keep]:
        shutil.rmtree(old, ignore_errors=True)
    return path


def _prepare(out: Path, config: dict, overwrite: bool) -> None:
    """Refuse a folder holding another run; tidy what a killed process left."""
    saved = out / "config.yaml"
    if overwrite:
        for name in ("config.yaml", "command.txt", PROGRESS, "checkpoints", "eval"):
            path = out / name
            shutil.rmtree(path) if path.is_dir() else path.unlink(missing_ok=True)
        return
    for tmp in (out / "checkpoints").glob(".tmp-*"):
        shutil.rmtree(tmp, ignore_errors=True)
    if saved.is_file():
        old = yaml.safe_load(saved.read_text()) or {}
        differs = [k for k in RESUME_KEYS if old.get(k) != config.get(k)] if old.get("trainer") == TRAINER else ["trainer"]
        if differs:
            raise RunFolderError(
                f"{out} holds a run with a different configuration ({', '.join(differs)} differ); "
                "choose another --out or pass --overwrite"
            )
    elif any(p.name != "train.lock" for p in out.iterdir()):
        raise RunFolderError(f"{out} is not empty and holds no train.rllib run; choose another --out or pass --overwrite")


def _ray_init(args: RLlibArgs, config: dict) -> None:
    import ray

    address = args.address or os.environ.get("RAY_ADDRESS")
    if address:
        ray.init(address=address)
    else:
        ray.init(num_cpus=args.num_cpus, include_dashboard=False)


def _notice(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def train(args: RLlibArgs) -> Path:
    """Train (or resume) a run as described by ``args``; returns the run folder.

    Ray is started here (or joined: ``address``, ``RAY_ADDRESS``) unless it already runs in this process.
    """
    import torch

    torch.set_num_threads(1)
    out = Path(args.out)
    config = resolve_config(args)

    def prepared_run() -> Path:
        _prepare(out, config, args.overwrite)
        return _train_locked(args, config, out)

    return run_locked(out, prepared_run)


def _restore(algo, out: Path) -> dict | None:
    """Restore the newest checkpoint that loads; set aside those that do not. Returns its progress."""
    while (path := latest_checkpoint(out)) is not None:
        try:
            progress = json.loads((path / PROGRESS).read_text())
            algo.restore_from_path(str(path.resolve()))
            return progress
        except Exception as e:  # RLlib raises pickle, torch, file and key errors on a damaged checkpoint
            aside = path.with_name(path.name + ".corrupt")
            shutil.rmtree(aside, ignore_errors=True)
            os.replace(path, aside)
            warnings.warn(f"checkpoint {path} does not restore ({type(e).__name__}: {e}); moved to {aside}", stacklevel=2)
    return None


def _train_locked(args: RLlibArgs, config: dict, out: Path) -> Path:
    import ray

    if not ray.is_initialized():
        _ray_init(args, config)
    for key, value in config["not_mapped"].items():
        _notice(f"train.rllib: {key}: {value} has no RLlib counterpart and is not used (see train/rllib.py)")

    previous = latest_checkpoint(out)
    restart = 0 if previous is None else json.loads((previous / PROGRESS).read_text()).get("restarts", 0) + 1
    algo = rllib_config(config, restart=restart).build_algo()
    progress = _restore(algo, out) if previous is not None else None
    if progress is None:
        progress = {"timesteps": 0, "iterations": 0, "wall_time": 0.0, "restarts": 0}
    else:
        progress["restarts"] = restart
        if args.verbose:
            print(f"resuming {out} from {progress['timesteps']:,} steps")
    write_text_atomic(out / "config.yaml", yaml.safe_dump(config, sort_keys=False))
    with open(out / "command.txt", "a") as f:
        f.write(runnable_command() + "\n")
    write_json_atomic(out / RUNNERS, {"runners": runner_nodes(algo)})
    history_file = out / PROGRESS
    history = json.loads(history_file.read_text())["iterations"] if history_file.is_file() else []
    history = [h for h in history if h["timesteps"] <= progress["timesteps"]]

    start_wall, t0 = progress["wall_time"], time.perf_counter()
    freq, next_checkpoint = config["checkpoint_freq"], None
    if freq:
        next_checkpoint = (progress["timesteps"] // freq + 1) * freq

    def save() -> Path:
        progress["wall_time"] = round(start_wall + time.perf_counter() - t0, 2)
        write_json_atomic(history_file, {"env_id": config["env_id"], "iterations": history})
        return _save(algo, out / "checkpoints", progress)

    try:
        while progress["timesteps"] < config["total_timesteps"]:
            result = algo.train()
            sampled = int(result["env_runners"]["num_env_steps_sampled"])
            progress["timesteps"] += sampled
            progress["iterations"] += 1
            runners = result["env_runners"]
            entry = {
                "timesteps": progress["timesteps"],
                "iteration_s": round(float(result["time_this_iter_s"]), 3),
                "episode_return_mean": _finite(runners.get("episode_return_mean")),
                "episode_len_mean": _finite(runners.get("episode_len_mean")),
                "time": round(start_wall + time.perf_counter() - t0, 2),
            }
            history.append(entry)
            if args.verbose:
                print(
                    f"[{entry['timesteps']:>9,} steps, {entry['time'] / 60:5.1f} min] iteration {entry['iteration_s']:.2f} s, "
                    f"return {entry['episode_return_mean']}, length {entry['episode_len_mean']}",
                    flush=True,
                )
            if next_checkpoint is not None and progress["timesteps"] >= next_checkpoint:
                save()
                next_checkpoint = (progress["timesteps"] // freq + 1) * freq
        save()
    except KeyboardInterrupt:
        path = save()
        print(f"\ninterrupted at {progress['timesteps']:,} steps; checkpoint saved in {path}. Run the same command again to resume.", file=sys.stderr)
        raise
    finally:
        algo.stop()
    return out


def runner_nodes(algo) -> list[dict]:
    """Where each remote env runner of ``algo`` runs: ``{"worker_index", "node_id", "node_ip"}`` (Ray's ids),
    by worker index; empty when the driver samples (``--num-env-runners 0``)."""

    def where(runner) -> dict:
        import ray

        return {"worker_index": int(runner.worker_index), "node_id": ray.get_runtime_context().get_node_id(), "node_ip": ray.util.get_node_ip_address()}

    found = algo.env_runner_group.foreach_env_runner(where, local_env_runner=False)
    return sorted(found, key=lambda r: r["worker_index"])


def _finite(value):
    return None if value is None or not math.isfinite(float(value)) else round(float(value), 3)


class RLlibPolicy:
    """The policy of an RLlib checkpoint, with SB3's ``predict``: raw observations ``(obs_dim,)`` or
    ``(N, obs_dim)`` in, the action (the Gaussian's mean when deterministic) clipped to ``[-1, 1]`` out."""

    def __init__(self, module, env_kwargs: dict | None = None, path: Path | None = None):
        self.module = module
        self.env_kwargs = dict(env_kwargs or {})
        self.path = path
        self.observation_space = module.observation_space
        self.action_space = module.action_space

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        import numpy as np
        import torch
        from ray.rllib.core.columns import Columns

        obs = np.asarray(observation, dtype=np.float32)
        single = obs.ndim == len(self.observation_space.shape)
        batch = torch.from_numpy(obs.reshape((-1, *self.observation_space.shape)))
        with torch.no_grad():
            out = self.module.forward_inference({Columns.OBS: batch})
            dist = self.module.get_inference_action_dist_cls().from_logits(out[Columns.ACTION_DIST_INPUTS])
            action = (dist.to_deterministic() if deterministic else dist).sample().numpy()
        action = np.clip(action, self.action_space.low, self.action_space.high)
        return (action[0] if single else action), state

    @classmethod
    def load(cls, path: Path) -> RLlibPolicy:
        """From an RLlib run folder (its newest checkpoint) or one of its checkpoints.

        Raises ``FileNotFoundError`` (no checkpoint, no module in it) or ``ValueError`` (a file RLlib cannot read).
        """
        import torch
        from ray.rllib.core import COMPONENT_LEARNER, COMPONENT_LEARNER_GROUP, COMPONENT_RL_MODULE, DEFAULT_MODULE_ID
        from ray.rllib.core.rl_module.rl_module import RLModule

        torch.set_num_threads(1)
        path = Path(path)
        run = path if is_rllib_run(path) else path.parent.parent
        if is_rllib_run(path):
            checkpoint = latest_checkpoint(path)
            if checkpoint is None:
                raise FileNotFoundError(f"the RLlib run {path} has no checkpoint yet in {path / 'checkpoints'}")
        else:
            checkpoint = path
        module_dir = checkpoint / COMPONENT_LEARNER_GROUP / COMPONENT_LEARNER / COMPONENT_RL_MODULE / DEFAULT_MODULE_ID
        if not module_dir.is_dir():
            raise FileNotFoundError(f"no RLlib policy module in {checkpoint} (expected {module_dir})")
        try:
            module = RLModule.from_checkpoint(str(module_dir.resolve()))
        except Exception as e:
            raise ValueError(f"cannot load the RLlib module {module_dir}: {type(e).__name__}: {e}") from e
        env_kwargs = {}
        if is_rllib_run(run):
            env_kwargs = (yaml.safe_load((run / "config.yaml").read_text()) or {}).get("eval_env_kwargs") or {}
        return cls(module, env_kwargs, run if is_rllib_run(run) else checkpoint)


def main(argv: list[str] | None = None) -> None:
    args = parse_args(RLlibArgs, argv, prog="python -m train.rllib")
    signal.signal(signal.SIGTERM, interrupt)  # `kill` saves a checkpoint like Ctrl-C
    try:
        train(args)
    except KeyboardInterrupt:
        raise SystemExit(130) from None
    except RunFolderError as e:
        raise SystemExit(f"python -m train.rllib: error: {e}") from None


if __name__ == "__main__":
    main()
