"""Train PPO on a leg-env task with Ray RLlib's new API stack, on this machine or on a Ray cluster.

    python -m train.rllib --out runs/rllib_stance                          # a local Ray on every CPU
    python -m train.rllib --out runs/rllib_uni --params "env_kwargs:{contact: unilateral}"
    RAY_ADDRESS=10.0.0.1:6379 python -m train.rllib --out runs/rllib --num-env-runners 32
    python -m train.evaluate runs/rllib_stance --baseline lqr

Needs the ``rllib`` extra (``pip install -e '.[rllib]'`` after CPU torch). Each env runner steps
leg-env's native batch (``leg_env.rllib``: one kernel call for all its robots, seeds that no two
runners share). The arguments shared with ``train.ppo`` (``--env-id``, ``--seed``, ``--out``, the evaluation,
the selection, checkpoints, resuming, ``--torch-threads``) are ``train.run.RunArgs``, with the same meaning.
Hyperparameters come from the same Zoo-format file as ``train.ppo`` (``train/hyperparams/ppo.yml``, ``--params``
overrides). Where a key maps onto RLlib's PPO it is used:

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

A run writes one folder, as ``train.run`` describes it; the policy and this trainer's own files::

    module/             the selected policy (RLlib's RLModule; also in best/ and last/)
    progress.json       one entry per training iteration (steps, return, sampling throughput, time)
    runners.json        the node (Ray's id and IP) of every env runner of the latest invocation
    checkpoints/<steps>/    RLlib checkpoints (``Algorithm.save_to_path``) with progress.json, the two newest

Evaluations and checkpoints come at the end of the iteration that crosses a multiple of ``--eval-freq`` or
``--checkpoint-freq``. Rerunning the same command resumes from the newest checkpoint (weights, optimiser, step
count, evaluations; ``restart`` in the envs' seeds draws new episodes); a checkpoint that does not restore is set
aside with a warning and the previous one is used. ``train.evaluate`` loads the run folder (its selected policy),
``best/``, ``last/`` or any of its checkpoints as a policy with SB3's ``predict``.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import yaml

from train.checkpoints import checkpoint_dirs, set_aside, write_checkpoint, write_json_atomic
from train.hyperparameters import CHUNKED_PPO_KEYS, linear_schedule_start, load_hyperparams
from train.run import Every, Run, RunArgs, machine, main as run_main, notice, open_run
from train.runfolder import RunKind

__all__ = ["RLlibArgs", "train", "resolve_config", "rllib_config", "latest_checkpoint", "RLlibPolicy", "is_rllib_checkpoint",
           "is_rllib_run", "is_rllib_policy", "runner_nodes", "RLLIB_RUN"]

TRAINER = "rllib-ppo"
"""``config.yaml``'s ``trainer`` entry: how ``train.evaluate`` tells an RLlib run from an SB3 one."""
CHECKPOINT_MARKER = "rllib_checkpoint.json"
"""The file RLlib writes at the top of an algorithm checkpoint."""
MODULE = "module"
"""A policy of an RLlib run: the RLModule's folder (``RLModule.save_to_path``)."""
PROGRESS = "progress.json"
RUNNERS = "runners.json"  # where the env runners of the latest invocation ran
RLLIB_RUN = RunKind(
    command="train.rllib",
    trainer=TRAINER,
    resume_keys=("env_id", "env_kwargs", "eval_env_kwargs", "seed", "learning_rate", "ppo", "model"),
    policy_files=(MODULE,),
)
"""What a ``train.rllib`` run folder holds (``train.runfolder.RunKind``; the scaling knobs may change between
invocations)."""


@dataclass
class RLlibArgs(RunArgs):
    """Train PPO on a leg-env task with Ray RLlib (new API stack) and write a run folder (see train/rllib.py)."""

    RENAMED: ClassVar[dict[str, str]] = {"env": "env_id", "numba_threads": "env_threads"}

    out: Path = Path("runs/rllib_stance")
    """Run folder: the policy, configuration, progress and checkpoints are written here."""
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
    address: str | None = None
    """Ray cluster to join (e.g. 10.0.0.1:6379). None: RAY_ADDRESS if set, else a local Ray."""
    num_cpus: int | None = None
    """CPUs of a local Ray (None: all of this machine's); not used when joining a cluster."""

    def __post_init__(self):
        super().__post_init__()
        for name in ("num_env_runners", "num_learners"):
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
_REFUSED = ("target_kl", "use_sde", "sde_sample_freq", "callback", *CHUNKED_PPO_KEYS)


def resolve_config(args: RLlibArgs) -> dict:
    """Everything that defines the run, as plain data (saved as ``config.yaml``)."""
    hp = load_hyperparams(args.hyperparams, args.env_id, args.params)
    refused = sorted(k for k in _REFUSED if k in hp and hp[k] not in (None, False))
    if refused:
        raise ValueError(f"{refused} have no counterpart in RLlib's PPO; remove them (see train/rllib.py)")
    for key in _REFUSED:  # what is left of them is off (None, false, 0): nothing to map
        hp.pop(key, None)
    not_mapped = _normalize_not_mapped(hp.pop("normalize", False))
    n_envs = int(hp.pop("n_envs", 1))
    total = args.total(hp)
    ppo = _ppo_settings(hp, n_envs)
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
        "env_id": args.env_id,
        "env_kwargs": env_kwargs,
        "eval_env_kwargs": args.eval_env_config(),
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
        **args.evaluation_config(),
        **args.source_config(),
    }


def _normalize_not_mapped(normalize) -> dict:
    """``not_mapped``'s ``normalize`` entry for the Zoo entry's ``normalize`` (its reward scaling); ``norm_obs:
    true`` is an error."""
    if normalize is True:
        normalize = {}
    if isinstance(normalize, dict):
        if normalize.get("norm_obs", True):
            raise ValueError("normalize.norm_obs: true has no counterpart in train.rllib; set it to false")
        return {"normalize": normalize}
    if normalize is not False:
        raise ValueError(f"normalize must be true, false or a mapping, got {normalize!r}")
    return {}


def _ppo_settings(hp: dict, n_envs: int) -> dict:
    """RLlib's PPO training settings from the Zoo entry ``hp`` (the keys used are popped from it)."""
    n_steps = int(hp.pop("n_steps", 2048))
    ppo = {"train_batch_size": n_steps * n_envs, "use_kl_loss": False, "vf_clip_param": math.inf}
    for key, name in _MAPPED.items():
        if key in hp:
            ppo[name] = hp.pop(key)
    if "grad_clip" in ppo:
        ppo["grad_clip_by"] = "global_norm"
    if "clip_param" in ppo and not isinstance(ppo["clip_param"], (int, float)):
        raise ValueError(f"clip_range must be a number for train.rllib, got {ppo['clip_param']!r}")
    if hp.get("clip_range_vf") is not None:
        ppo["vf_clip_param"] = float(hp["clip_range_vf"])
    hp.pop("clip_range_vf", None)
    if hp.pop("normalize_advantage", True) is not True:
        raise ValueError("normalize_advantage: false has no counterpart in RLlib's PPO (it always standardises)")
    return ppo


def _lr(learning_rate, total: int):
    """RLlib's ``lr``: a number, or for the Zoo's ``"lin_<x>"`` the schedule ``[[0, x], [total, 0]]``."""
    initial = linear_schedule_start(learning_rate)
    return float(learning_rate) if initial is None else [[0, initial], [total, 0.0]]


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


def latest_checkpoint(run: Path) -> Path | None:
    """The newest complete checkpoint of an RLlib run folder (None: none yet)."""
    found = checkpoint_dirs(Path(run) / "checkpoints")
    return found[0] if found else None


def is_rllib_checkpoint(path: Path) -> bool:
    return (Path(path) / CHECKPOINT_MARKER).is_file()


def is_rllib_policy(path: Path) -> bool:
    """Whether ``path`` is a policy folder of an RLlib run (``best/``, ``last/``): one holding ``module/``."""
    return (Path(path) / MODULE / "class_and_ctor_args.pkl").is_file()


def is_rllib_run(path: Path) -> bool:
    config = Path(path) / "config.yaml"
    if not config.is_file():
        return False
    try:
        return (yaml.safe_load(config.read_text()) or {}).get("trainer") == TRAINER
    except (yaml.YAMLError, AttributeError):
        return False


def _save(algo, folder: Path, progress: dict) -> Path:
    """Write a checkpoint of ``algo`` with its ``progress`` (``train.checkpoints.write_checkpoint``)."""

    def write(tmp: Path) -> None:
        algo.save_to_path(str(tmp.resolve()))
        write_json_atomic(tmp / PROGRESS, progress)

    return write_checkpoint(folder, progress["timesteps"], write)


def _ray_init(args: RLlibArgs) -> None:
    import ray

    address = args.address or os.environ.get("RAY_ADDRESS")
    if address:
        ray.init(address=address)
    else:
        ray.init(num_cpus=args.num_cpus, include_dashboard=False)


def train(args: RLlibArgs, command: str | None = None) -> Path:
    """Train (or resume) a run as described by ``args``; returns the run folder.

    Ray is started here (or joined: ``address``, ``RAY_ADDRESS``) unless it already runs in this process.
    ``command``: the line added to the folder's ``command.txt`` (None: this process's command line).
    """
    return open_run(args, resolve_config(args), RLLIB_RUN, lambda run: _train_locked(run, args), command)


def _restore(algo, out: Path) -> dict | None:
    """Restore the newest checkpoint that loads; set aside those that do not. Returns its progress."""
    while (path := latest_checkpoint(out)) is not None:
        try:
            progress = json.loads((path / PROGRESS).read_text())
            algo.restore_from_path(str(path.resolve()))
            return progress
        except Exception as e:  # RLlib raises pickle, torch, file and key errors on a damaged checkpoint
            aside = set_aside(path)
            warnings.warn(f"checkpoint {path} does not restore ({type(e).__name__}: {e}); moved to {aside}", stacklevel=2)
    return None


def _resumes(progress: dict) -> int:
    """The resumes so far of a checkpoint's ``progress`` (named ``restarts`` in the checkpoints of earlier versions)."""
    return progress.get("resumes", progress.get("restarts", 0))


def _algorithm(run: Run, verbose: int):
    """``(algo, progress)``: RLlib's algorithm, restored from the run's newest checkpoint that loads when resuming."""
    previous = latest_checkpoint(run.out) if run.resuming else None
    resumes = 0 if previous is None else _resumes(json.loads((previous / PROGRESS).read_text())) + 1
    algo = rllib_config(run.config, restart=resumes).build_algo()
    progress = _restore(algo, run.out) if previous is not None else None
    if progress is None:
        return algo, {"timesteps": 0, "iterations": 0, "wall_time": 0.0, "resumes": 0, "evaluations": []}
    progress.pop("restarts", None)
    progress["resumes"] = resumes
    if verbose:
        print(f"resuming {run.out} from {progress['timesteps']:,} steps")
    return algo, progress


def _train_locked(run: Run, args: RLlibArgs) -> Path:
    """The run's life once its folder is locked and prepared (``train.run``): build, train, finish."""
    import ray

    if not ray.is_initialized():
        _ray_init(args)
    for key, value in run.config["not_mapped"].items():
        notice(f"train.rllib: {key}: {value} has no RLlib counterpart and is not used (see train/rllib.py)")
    algo, progress = _algorithm(run, args.verbose)
    try:
        run.start(progress)
        write_json_atomic(run.out / RUNNERS, {"runners": runner_nodes(algo)})
        _train(run, algo, progress, args.verbose)
        return run.finish(progress["timesteps"], machine(ray=ray.__version__))
    finally:
        algo.stop()


def _train(run: Run, algo, progress: dict, verbose: int) -> None:
    """Train ``algo`` to the run's total, evaluating and checkpointing as the run asks; a checkpoint at the end
    and on Ctrl-C or SIGTERM."""
    iterations = _iterations(run.out, progress["timesteps"])

    def save() -> Path:
        write_json_atomic(run.out / PROGRESS, {"env_id": run.config["env_id"], "iterations": iterations})
        return _save(algo, run.out / "checkpoints", run.stamp())

    env_kwargs = run.config["eval_env_kwargs"]
    run.begin(progress["timesteps"], lambda: RLlibPolicy(algo.get_module(), env_kwargs), lambda folder: _save_module(algo, folder))
    checkpoints = Every(run.config["checkpoint_freq"], progress["timesteps"])
    try:
        while progress["timesteps"] < run.config["total_timesteps"]:
            iterations.append(_iterate(algo, progress, run, verbose))
            run.evaluate_if_due(progress["timesteps"])
            if checkpoints.due(progress["timesteps"]):
                save()
        run.evaluate_last(progress["timesteps"])
        save()
    except KeyboardInterrupt:
        save()
        run.interrupted(progress["timesteps"])
        raise
    finally:
        run.close()


def _iterations(out: Path, steps: int) -> list[dict]:
    """The run's ``progress.json`` entries up to ``steps`` env steps (a resume drops those after its checkpoint)."""
    path = out / PROGRESS
    history = json.loads(path.read_text())["iterations"] if path.is_file() else []
    return [h for h in history if h["timesteps"] <= steps]


def _iterate(algo, progress: dict, run: Run, verbose: int) -> dict:
    """One training iteration of ``algo``, counted in ``progress``; returns its ``progress.json`` entry."""
    result = algo.train()
    runners = result["env_runners"]
    progress["timesteps"] += int(runners["num_env_steps_sampled"])
    progress["iterations"] += 1
    entry = {
        "timesteps": progress["timesteps"],
        "iteration_s": round(float(result["time_this_iter_s"]), 3),
        "episode_return_mean": _finite(runners.get("episode_return_mean")),
        "episode_len_mean": _finite(runners.get("episode_len_mean")),
        "time": round(run.clock(), 2),
    }
    if verbose:
        print(
            f"[{entry['timesteps']:>9,} steps, {entry['time'] / 60:5.1f} min] iteration {entry['iteration_s']:.2f} s, "
            f"return {entry['episode_return_mean']}, length {entry['episode_len_mean']}",
            flush=True,
        )
    return entry


def _save_module(algo, folder: Path) -> None:
    """The policy's files in ``folder``: the RLModule of ``algo``'s env runners, as they act (``module/``)."""
    algo.get_module().save_to_path(str((folder / MODULE).resolve()))


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
        """From an RLlib run folder (its selected policy, ``module/``; before its first finish, its newest
        checkpoint), its ``best/`` or ``last/``, or one of its checkpoints.

        Raises ``FileNotFoundError`` (no checkpoint, no module in it) or ``ValueError`` (a file RLlib cannot read).
        """
        import torch
        from ray.rllib.core.rl_module.rl_module import RLModule

        torch.set_num_threads(1)
        module_dir, run = _module_folder(Path(path))
        if not module_dir.is_dir():
            raise FileNotFoundError(f"no RLlib policy module in {path} (expected {module_dir})")
        try:
            module = RLModule.from_checkpoint(str(module_dir.resolve()))
        except Exception as e:
            raise ValueError(f"cannot load the RLlib module {module_dir}: {type(e).__name__}: {e}") from e
        env_kwargs = {}
        if run is not None:
            env_kwargs = (yaml.safe_load((run / "config.yaml").read_text()) or {}).get("eval_env_kwargs") or {}
        return cls(module, env_kwargs, run if run is not None else Path(path))


def _module_folder(path: Path) -> tuple[Path, Path | None]:
    """The RLModule folder of an RLlib run folder, policy folder (``best/``, ``last/``) or checkpoint, and the run
    folder it belongs to (None: not known)."""
    from ray.rllib.core import COMPONENT_LEARNER, COMPONENT_LEARNER_GROUP, COMPONENT_RL_MODULE, DEFAULT_MODULE_ID

    if is_rllib_run(path) and (path / MODULE).is_dir():
        return path / MODULE, path
    if is_rllib_run(path):
        checkpoint = latest_checkpoint(path)
        if checkpoint is None:
            raise FileNotFoundError(f"the RLlib run {path} has no policy and no checkpoint yet in {path / 'checkpoints'}")
        run = path
    elif is_rllib_policy(path):
        return path / MODULE, path.parent if is_rllib_run(path.parent) else None
    else:
        checkpoint, run = path, path.parent.parent if is_rllib_run(path.parent.parent) else None
    return checkpoint / COMPONENT_LEARNER_GROUP / COMPONENT_LEARNER / COMPONENT_RL_MODULE / DEFAULT_MODULE_ID, run
def main(argv: list[str] | None = None) -> None:
    run_main(RLlibArgs, train, "python -m train.rllib", argv)


if __name__ == "__main__":
    main()
