"""What a trained policy's episodes are paid just before they fall: a reward audit of the training conditions.

    python -m train.falls runs/hop --training-env
    python -m train.falls runs/hop --training-env --at-steps 45000000 --episodes 512
    python -m train.falls policies/ppo_hop_v4 --env-kwargs drift_com_weight:400.0 alive_bonus:2.0

A reward whose terms can turn the per-step reward negative (a charge that grows without bound, such as a quadratic
charge on the distance from the start) pays a policy for ending an episode: from a state where staying up costs more
than it earns, a fall is the better return. ``train.evaluate`` measures the task as registered with the mean action;
this runs the policy as it is trained, its actions drawn from its Gaussian (``--sample``, the default), on the
training env's settings (``--training-env``: the run's ``env_kwargs`` with every ``train.callbacks.ConfigSchedule``
field at its value after ``--at-steps``, default the run's last step) or on ``--env-kwargs``. For the episodes that
fall and for those that survive, it prints each reward term per step over their last ``--window`` steps, and the
share of them whose reward over that window is below 0, and how the falls ended (the torso's tilt, the base's height,
a joint past an end of its range), in flight or in contact. Episode ``i`` is seeded ``seed + i`` (default 30000 + i, the
fresh episodes, which neither training nor selection uses); the sampled actions come from torch's generator seeded
with ``seed``, so that a run prints the same figures again.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from leg_env import ENDINGS
from train.cli import parse_args

__all__ = ["FallsArgs", "FallsReport", "FallWatcher", "training_env_kwargs", "audit", "format_report", "main"]

FRESH_SEED = 30_000


@dataclass
class FallsArgs:
    """Run a trained policy as it is trained and print what its episodes are paid before they fall."""

    policy: Path = Path("policies/ppo_hop_v4")
    """Run or policy folder (model.zip, vecnormalize.pkl, config.yaml) of an SB3 policy, or a run's best/, last/ or
    checkpoints/<steps>/ folder (the run's config.yaml is read from above it)."""
    training_env: bool = False
    """The run's training env: its env_kwargs with each ConfigSchedule field at its value after --at-steps."""
    at_steps: int | None = None
    """With --training-env: the env steps at which the schedules are read (None: the run's total_timesteps)."""
    env_kwargs: list[str] = field(default_factory=list)
    """Further env arguments as key:value (after --training-env's, which they override)."""
    env_id: str | None = None
    """The task (None: the run's own, from its config.yaml)."""
    episodes: int = 256
    """Number of episodes, run as one batch."""
    seed: int = FRESH_SEED
    """Seed of the first episode; episode i uses seed + i; also torch's seed for the sampled actions."""
    window: int = 50
    """Steps before an episode's end over which its reward is averaged."""
    sample: bool = True
    """Draw the actions from the policy's Gaussian, as in training (--no-sample: its mean, as the evaluation)."""
    out: Path | None = None
    """Also write the report as JSON to this file."""

    def __post_init__(self):
        self.policy = Path(self.policy)
        if self.episodes < 1:
            raise ValueError(f"episodes must be >= 1, got {self.episodes}")
        if self.window < 1:
            raise ValueError(f"window must be >= 1, got {self.window}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0 (episode seeds are non-negative), got {self.seed}")
        if self.at_steps is not None and self.at_steps < 0:
            raise ValueError(f"at_steps must be >= 0, got {self.at_steps}")
        if self.at_steps is not None and not self.training_env:
            raise ValueError("at_steps reads the run's schedules: it needs --training-env")
        try:
            self.extra_env_kwargs()
        except ValueError as e:
            raise ValueError(f"env_kwargs: {e}") from None

    def extra_env_kwargs(self) -> dict:
        from train.hyperparameters import parse_override

        return dict(parse_override(item) for item in self.env_kwargs)


def training_env_kwargs(config: dict, at_steps: int | None = None) -> dict:
    """The training env's arguments of a run's ``config.yaml`` (``config``) after ``at_steps`` env steps (None: its
    ``total_timesteps``): its ``env_kwargs``, then each ``train.callbacks.ConfigSchedule`` field at its value then."""
    from train.callbacks import ConfigSchedule

    steps = int(config.get("total_timesteps", 0)) if at_steps is None else int(at_steps)
    kwargs = dict(config.get("env_kwargs") or {})
    for entry in config.get("callback") or []:
        if isinstance(entry, dict) and "train.callbacks.ConfigSchedule" in entry:
            kwargs.update(ConfigSchedule(**entry["train.callbacks.ConfigSchedule"]).values_at(steps))
    return kwargs


@dataclass
class FallsReport:
    """The audit's figures: per-episode ``survived``, ``lengths``, each reward term's sum per episode (``terms``)
    and its mean per step over each episode's last ``window`` steps (``last``), in the order of the seeds."""

    env_id: str
    env_kwargs: dict
    sample: bool
    window: int
    seeds: list[int]
    survived: np.ndarray
    lengths: np.ndarray
    terms: dict[str, np.ndarray]
    last: dict[str, np.ndarray]
    ends: list[str | None] = field(default_factory=list)
    in_flight: np.ndarray | None = None

    def ends_table(self) -> dict[str, dict[str, int]]:
        """For each way an episode ended early (``leg_env.ENDINGS``, the task's ``info["ending"]``), how many ended so
        in flight and in contact."""
        out: dict[str, dict[str, int]] = {}
        for end, flight in zip(self.ends, self.in_flight if self.in_flight is not None else []):
            if end is not None:
                row = out.setdefault(end, {"in flight": 0, "in contact": 0})
                row["in flight" if flight else "in contact"] += 1
        return out

    def groups(self) -> dict[str, dict]:
        """For the episodes that fell and those that survived: their number, each term's mean per step over the last
        ``window`` steps, the total's, and the share whose total over that window is below 0."""
        out = {}
        total = sum(self.last.values())
        for name, mask in (("fell", ~self.survived), ("survived", self.survived)):
            if mask.any():
                out[name] = {
                    "episodes": int(mask.sum()),
                    "reward": float(total[mask].mean()),
                    "negative_share": float((total[mask] < 0.0).mean()),
                    **{key: float(values[mask].mean()) for key, values in self.last.items()},
                }
        return out

    def to_json(self) -> dict:
        return {
            "env_id": self.env_id,
            "env_kwargs": self.env_kwargs,
            "sample": self.sample,
            "window": self.window,
            "seeds": [self.seeds[0], self.seeds[-1]],
            "survival_rate": float(self.survived.mean()),
            "mean_length": float(self.lengths.mean()),
            "mean_reward_terms": {key: float(values.mean()) for key, values in self.terms.items()},
            "last_steps": self.groups(),
            "ends": self.ends_table(),
        }


class FallWatcher:
    """What ``audit`` measures of each episode, a ``train.episodes.Watcher`` of the one episode runner: each reward
    term's sum, its mean per step over the episode's last ``window`` steps, and how the episode ended.

    Every episode of a batch starts at its reset, so an episode's step ``t`` is the batch's step ``t``: the last
    ``window`` steps are kept in a ring of ``window`` rows, row ``(t - 1) % window`` for step ``t``, written for the
    episodes still running; an episode that has ended keeps its own last steps there.
    """

    def __init__(self, window: int):
        self.window = window

    def start(self, envs, obs, info: dict) -> None:
        n = obs.shape[0]
        self.keys = list(envs.unwrapped.reward_keys)
        self.terms = {key: np.zeros(n) for key in self.keys}
        self.ring = {key: np.zeros((self.window, n)) for key in self.keys}
        self.steps = 0
        self.ends: list[str | None] = [None] * n
        self.in_flight = np.zeros(n, bool)

    def step(self, envs, obs, actions, info: dict, active: np.ndarray) -> None:
        row = self.steps % self.window
        self.steps += 1
        for key in self.keys:
            value = np.where(active, np.asarray(info[key], dtype=np.float64), 0.0)
            self.terms[key] += value
            self.ring[key][row, active] = value[active]
        fell = active & (info["ending"] != 0)  # terminated at this step (truncation is ending 0)
        for i in np.flatnonzero(fell):
            self.ends[i] = ENDINGS[info["ending"][i]]  # the first limit the step passed, as the task's kernel names it
            self.in_flight[i] = "contact_mode" in info and info["contact_mode"][i] == "flight"  # a pinned foot never flies

    def last(self, lengths: np.ndarray) -> dict[str, np.ndarray]:
        """Each term's mean per step over the last ``window`` steps of each episode (of ``lengths`` steps), summed
        from the oldest of those steps on."""
        n = len(lengths)
        oldest_first = (lengths[None, :] - self.window + np.arange(self.window)[:, None]) % self.window
        return {key: ring[oldest_first, np.arange(n)].sum(axis=0) / np.minimum(lengths, self.window)
                for key, ring in self.ring.items()}  # fmt: skip


def audit(args: FallsArgs) -> FallsReport:
    """Run ``args.episodes`` episodes of the policy as ``FallsArgs`` says, in one batch through
    ``train.episodes.run_batch``; returns their figures."""
    import torch

    from train.episodes import make_batch, policy_predict, run_batch

    policy, env_id, kwargs = _audited(args)
    torch.manual_seed(args.seed)
    envs = make_batch(env_id, args.episodes, kwargs)
    seeds = list(range(args.seed, args.seed + args.episodes))
    watcher = FallWatcher(args.window)
    try:
        batch = run_batch(policy_predict(policy, deterministic=not args.sample), envs, seeds, [watcher])
    finally:
        envs.close()
    return FallsReport(env_id, kwargs, args.sample, args.window, seeds, batch.survived, batch.lengths, watcher.terms,
                       watcher.last(batch.lengths), watcher.ends, watcher.in_flight)  # fmt: skip


def _audited(args: FallsArgs):
    """``(policy, env_id, env_kwargs)`` of the audit: the SB3 policy of ``args.policy``, its task and the env's
    arguments (``--training-env``'s, then ``--env-kwargs``)."""
    from train.policy_loading import TrainedPolicy, load_policy, read_run_config

    policy = load_policy(args.policy)
    if not isinstance(policy, TrainedPolicy):
        raise ValueError(f"{args.policy} is not an SB3 policy folder (train.falls samples an SB3 policy's Gaussian)")
    folder = args.policy.parent if args.policy.suffix == ".zip" else args.policy
    # a run's best/, last/ or checkpoints/<steps>/ folder: the run's config.yaml is above it
    config = next((c for c in map(read_run_config, (folder, folder.parent, folder.parent.parent)) if c), {})
    env_id = args.env_id or policy.env_id or config.get("env_id")
    if env_id is None:
        raise ValueError(f"{args.policy} has no config.yaml naming its task: pass --env-id")
    kwargs = training_env_kwargs(config, args.at_steps) if args.training_env else {}
    kwargs.update(args.extra_env_kwargs())
    return policy, env_id, kwargs


def format_report(report: FallsReport) -> str:
    """The report as Markdown: the episodes' survival and terms, then the last steps of those that fell and survived."""
    keys = list(report.terms)
    short = [key.removeprefix("reward_") for key in keys]
    lines = [
        f"{report.env_id}, {len(report.seeds)} episodes (seeds {report.seeds[0]}..{report.seeds[-1]}), actions "
        f"{'drawn from the policy' if report.sample else 'the policy mean'}; env arguments: {json.dumps(report.env_kwargs)}",
        "",
        f"survival {report.survived.mean():.1%}, mean length {report.lengths.mean():.1f} steps",
        "",
        "| per episode | " + " | ".join(short) + " |",
        "|---|" + "---:|" * len(keys),
        "| mean | " + " | ".join(f"{report.terms[key].mean():.1f}" for key in keys) + " |",
        "",
        f"| last {report.window} steps, per step | episodes | reward | below 0 | " + " | ".join(short) + " |",
        "|---|---:|---:|---:|" + "---:|" * len(keys),
    ]
    for name, group in report.groups().items():
        lines.append(
            f"| {name} | {group['episodes']} | {group['reward']:.2f} | {group['negative_share']:.0%} | "
            + " | ".join(f"{group[key]:.2f}" for key in keys) + " |"
        )
    table = report.ends_table()
    if table:
        lines += ["", "| how the falls ended | in flight | in contact |", "|---|---:|---:|"]
        lines += [f"| {end} | {table[end]['in flight']} | {table[end]['in contact']} |" for end in ENDINGS if end in table]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    import torch

    args = parse_args(FallsArgs, argv, positional=("policy",), prog="python -m train.falls")
    from train.policy_loading import PolicyLoadError, PolicyNotFoundError

    torch.set_num_threads(1)
    try:
        report = audit(args)
    except (PolicyNotFoundError, PolicyLoadError, ValueError) as e:
        raise SystemExit(f"python -m train.falls: error: {e}") from None
    print(format_report(report))
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report.to_json(), indent=2) + "\n")


if __name__ == "__main__":
    main()
