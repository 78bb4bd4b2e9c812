"""Evaluate a trained policy, or a model-based controller, over deterministic episodes of any task.

    python -m train.evaluate runs/ppo_stance --baseline lqr --episodes 20 --gif
    python -m train.evaluate policies/ppo_stance
    python -m train.evaluate lqr --out runs/lqr_eval
    python -m train.evaluate policies/ppo_push_v2 --baseline stepping lqr --episodes 100 --push-curve
    python -m train.evaluate policies/ppo_hop_v4 --baseline hopper --episodes 100 --gif

``policy`` is a run or policy folder (``model.zip``, ``vecnormalize.pkl``, optionally ``config.yaml``
whose ``eval_env_kwargs`` the evaluation env uses: by default none, the registered task as is, even
when training shaped the reward through ``env_kwargs``), a ``python -m train.rllib`` run folder (its
newest checkpoint) or checkpoint, or a model-based controller: ``lqr`` (``policies.lqr``, the balance and
push tasks), ``hopper`` (``policies.hopper``, the hop task), ``stepping`` (``policies.stepping``: the LQR, and a quick hop when
the observed push is large; the push task) or ``gated`` (``policies.gated``: a backward hop
from a start whose capture point is behind the foot, then the LQR; the unilateral balance tasks). The task is the policy's own (its
``config.yaml``'s ``env_id``), else ``--env-id`` (default ``leg_env/PlanarLegStance-v0``). Episode ``i`` is seeded ``seed + i``
(default 10_000 + i: training uses small seeds, in-training evaluation 20_000 + i); the episodes run as one batch
(``train.episodes.run_batch``), each the episode of the single env from ``gymnasium.make`` with its 1000-step time
limit. Policies load through ``train.policy_loading.load_policy`` (re-exported here). Results go to ``<policy>/eval/``
(or ``--out``): one JSON per controller, ``table.md`` with the side-by-side tables that are also
printed (headed by the date, the machine and the versions, which the JSONs record too), ``timeseries.png`` (base
drift, torques and contact force of the first episode), ``motion.png`` (how each controller moves, below), for a run
folder ``learning_curve.png`` (the run's curve with the baseline's level drawn in) and with ``--gif``
an animation of the first episode.

Metrics (over all episodes; "steps" are all control steps of all episodes):

- ``survival_rate``: fraction of episodes that reach the time limit without terminating;
- ``mean_return``, ``std_return``, ``mean_length``;
- ``endings``: how many episodes ended early in each way (the task's ``info["ending"]``, named by
  ``leg_env.ENDINGS``: ``torso_angle``, ``knee_high``, ...); each episode's own is in ``per_episode``;
- ``rms_base_drift``, ``max_base_drift`` [m]: base distance from its nominal position;
- ``rms_torso_angle`` [rad]: the torso's tilt (0 in the nominal posture; ``motion``'s ``tilt_rms`` in radians);
- ``unilateral_violation_frac``: fraction of steps with ``lam_y < 0`` (the ground would have to pull);
- ``friction_violation_frac``: fraction of steps with ``|lam_x| > mu lam_y``;
- ``rms_torque`` [N m]: hip and knee; ``mean_reward_terms``: each reward term per episode (the task's terms).

How the robot moves, ``motion`` (``train.motion``, which defines each exactly; each episode's own in its
``per_episode`` entry), with actions as the env applies them, clipped to [-1, 1]:

- ``tilt_rms`` [deg]: the RMS of the torso angle ``th_b`` over all steps of all episodes;
- ``action_rate``: the mean of ``|a_t - a_{t-1}|`` over both entries and every step after an episode's first;
- ``saturated_share``: the share of action entries at the bound, ``|a| >= 1``;
- ``actuator_power`` [W]: positive actuator work per second, the sum over the steps of ``max(0, W)`` over the
  simulated time, ``W`` the step's ``info["work_actuators"]`` on the unilateral ground and, on the pinned foot (no
  such key), ``tau . (q_after - q_before)`` over the hip and knee (exact: the torques are held over the step);
- ``peak_normal_force``, ``peak_normal_force_max`` [body weights]: each episode's largest ``info["normal_force"] /
  (m g)`` (a step's mean normal force, without a landing's impact impulse), averaged over the episodes, and its
  largest over them (with ``g = 0``: in newtons, ``normal_force_unit``);
- ``flights_per_episode``, ``flights_per_10s``: flight phases (the contact mode going to ``"flight"``; 0 on the
  pinned foot) per episode, and per 10 s of simulated time;
- ``com_excursion`` [m]: each episode's largest horizontal distance of the whole-body COM
  (``info["com_position"][0]``) from where it started, averaged over the episodes.

The same measures restricted to the episodes that both the policy (the first controller) and each other controller
survive, for both, are ``both_survived`` (a falling robot's actions swing, so on all episodes a policy looks calmer
beside a controller that falls): in each controller's JSON under the other's name, with the ``seeds`` kept. On the
push task every controller also runs the same seeds with no push at all (``push_force=(0, 0)``): ``no_push`` has its
survival (and the seeds of the episodes it ``fell`` in), return and ``motion``, so that a policy that chatters or hops
while nothing pushes it shows it.

The hop task adds the metrics of ``train.task_metrics.HopTracker`` (apex error, hop period, drift after
10 s, landing impulses) and ``hops.png``, a few hops of the first episode (COM height against its target,
contact mode, contact force, impulses). ``--push-curve`` (push task) adds survival against the push
impulse for every controller on the same seeds (``train.episodes.push_survival``): ``push_curve.json``,
``push_curve.md`` and ``push_curve.png``, with the largest impulse each survives 90% of the time (also in each
controller's JSON, ``push_impulse_90``).

On the balance, hop and push tasks ``table.md`` ends with the policy's acceptance bars (``train.bars``): each bar's
number, its threshold and whether the policy meets it. A bar that compares with a controller is measured when that
controller is a ``--baseline`` (the gated controller and the LQR on the balance task, the hopper on the hop task, the
stepping controller on the push task); the push task's 90% impulse needs ``--push-curve``, and its bars pushed at
5 N s an evaluation env with ``push_force`` (50, 50).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from leg_env import ENDINGS, ENV_ID  # importing leg_env registers the env
from leg_env.tasks.base import Obs
from train.cli import parse_args
from train.policy_loading import BASELINES, PolicyLoadError, PolicyNotFoundError, TrainedPolicy, load_policy

__all__ = [
    "EvalArgs",
    "PolicyNotFoundError",
    "PolicyLoadError",
    "TrainedPolicy",
    "load_policy",
    "run_episodes",
    "run_without_pushes",
    "evaluate",
    "format_table",
]

EVAL_SEED = 10_000
GIF_FRAME_SKIP = 4  # one frame per 4 control steps: 25 frames per simulated second at dt = 0.01 s
GIF_SIZE = 320  # pixels


class EpisodeMetrics:
    """The common metrics of ``run_episodes``, a ``train.episodes.Watcher``: per episode the reward terms and the
    squared base drift; over every step the torques and violations; and the time series (and frames) of the
    episode of row ``record``. How the robot moves is ``train.motion.Motion``'s."""

    def __init__(self, record: int | None = None, frames: bool = False):
        self.record, self.frames = record, frames
        self.series: dict | None = None

    def start(self, envs, obs, info: dict) -> None:
        n = obs.shape[0]
        self.limit = np.asarray(envs.config.torque_limit)
        self.reward_terms = envs.task.reward_terms
        self.terms = np.zeros((n, len(self.reward_terms)))
        self.drift_sq = np.zeros(n)
        self.ending = np.zeros(n, dtype=np.int64)  # why each episode ended early (leg_env.ENDINGS; 0: it did not)
        self.drift_max, self.torque_sq, self.unilateral, self.friction = 0.0, np.zeros(2), 0, 0
        self.robots = None
        if "params" in info:  # a drawn robot per episode (randomize)
            params = info["params"]
            names = [k for k in params if not k.startswith("_")]
            self.robots = [{k: float(params[k][i]) for k in names} if params["_" + names[0]][i] else None for i in range(n)]
        if self.record is not None:
            self.series = {"base_drift": [], "torso_angle": [], "torque": [], "contact_force": [], "mode": [], "impulse": [], "frames": []}
            if self.frames:
                self.series["frames"].append(envs.render()[self.record])

    def step(self, envs, obs, actions, info: dict, active: np.ndarray) -> None:
        tau = np.asarray(info["torque"], dtype=np.float64)[active]  # what the joints got: each robot's own limits and motor model
        for k, name in enumerate(self.reward_terms):
            self.terms[active, k] += info[f"reward_{name}"][active]
        ended = active & (info["ending"] != 0)  # an episode that was running and ended at this step
        self.ending[ended] = info["ending"][ended]
        d = info["base_drift"]
        self.drift_sq[active] += d[active] * d[active]
        self.drift_max = max(self.drift_max, float(d[active].max()))
        self.torque_sq += (tau * tau).sum(axis=0)
        self.unilateral += int(np.count_nonzero(info["unilateral_violation"][active]))
        self.friction += int(np.count_nonzero(info["friction_violation"][active]))
        r = self.record
        if r is not None and active[r]:
            rec = self.series
            rec["base_drift"].append(float(d[r]))
            rec["torso_angle"].append(float(obs[r, Obs.th_b]))
            rec["torque"].append(np.asarray(info["torque"][r], dtype=np.float64))
            rec["contact_force"].append(np.asarray(info["contact_force"][r], dtype=np.float64))
            rec["mode"].append(str(info["contact_mode"][r]) if "contact_mode" in info else "stick")
            rec["impulse"].append(np.asarray(info["impulse"][r], dtype=np.float64) if "impulse" in info else np.zeros(2))
            if self.frames and len(rec["base_drift"]) % GIF_FRAME_SKIP == 0:
                rec["frames"].append(envs.render()[r])


def run_episodes(
    policy, seeds, env_kwargs: dict | None = None, record: int | None = None, frames: bool = False, env_id: str = ENV_ID
):
    """Run one deterministic episode per seed, all in one batch (``train.episodes.run_batch``); return the summary
    and the recorded episode.

    Args:
        policy: anything with SB3's ``predict`` (a batch of observations in, a batch of actions out).
        seeds: one seed per episode.
        env_kwargs: keyword arguments of ``gymnasium.make``.
        env_id: the task.
        record: index of the episode whose time series is returned (None: none).
        frames: also render that episode, one ``rgb_array`` frame per ``GIF_FRAME_SKIP`` steps.

    Returns:
        ``(summary, series)``: the metrics (module docstring) with per-episode lists, and for the
        recorded episode a dict of ``base_drift`` (T,), ``torso_angle`` (T,), ``torque`` (T, 2), ``contact_force`` (T, 2),
        ``weight`` and ``frames`` (or None); on the unilateral ground also ``mode`` (T,) and ``impulse``
        (T, 2), and on the hop task the ``HopTracker`` series.
    """
    from train.episodes import make_batch, policy_predict, run_batch
    from train.motion import Motion
    from train.task_metrics import HopTracker

    if len(seeds) == 0:
        raise ValueError("run_episodes needs at least one seed")
    if record is not None and not 0 <= record < len(seeds):
        raise ValueError(f"record must be the index of one of the {len(seeds)} episodes, got {record}")
    metrics, motion = EpisodeMetrics(record, frames), Motion()
    hop = HopTracker(record) if env_id.startswith("leg_env/PlanarLegHop-v") else None
    envs = make_batch(env_id, len(seeds), env_kwargs, record, frames, GIF_SIZE)
    try:
        batch = run_batch(policy_predict(policy), envs, seeds, [metrics, motion] + ([] if hop is None else [hop]))
        dt = envs.dt
    finally:
        envs.close()
    if hop is not None:
        hop.end(batch.survived)
    series = None if record is None else _series(metrics, hop, float(motion.weight[record]), dt, frames)  # its own robot's weight
    return _summary(batch, metrics, motion, hop), series


def _series(metrics: EpisodeMetrics, hop, weight: float, dt: float, frames: bool) -> dict:
    """The recorded episode's time series (``run_episodes``), as arrays."""
    rec = metrics.series
    return {
        "base_drift": np.asarray(rec["base_drift"]),
        "torso_angle": np.asarray(rec["torso_angle"]),
        "torque": np.asarray(rec["torque"]),
        "contact_force": np.asarray(rec["contact_force"]),
        "weight": weight,
        "dt": dt,
        "torque_limit": tuple(metrics.limit),
        "frames": rec["frames"] if frames else None,
        "mode": rec["mode"],
        "impulse": np.asarray(rec["impulse"]),
        "hop": dict(hop.series) if hop is not None else None,
    }


def _per_episode(batch, metrics: EpisodeMetrics, motion) -> list[dict]:
    """Each episode's seed, return, length, survival, ending, RMS drift, reward terms, how the robot moved
    (``train.motion.PER_EPISODE``) (and drawn robot)."""
    per_episode = []
    moved = motion.records()
    for i, seed in enumerate(batch.seeds):
        length = int(batch.lengths[i])
        per_episode.append(
            {
                "seed": seed,
                "return": round(float(batch.returns[i]), 4),
                "length": length,
                "survived": bool(batch.survived[i]),
                "ending": ENDINGS[metrics.ending[i]],
                "rms_base_drift": float(np.sqrt(metrics.drift_sq[i] / length)),
                "reward_terms": {k: round(float(metrics.terms[i, j]), 4) for j, k in enumerate(metrics.reward_terms)},
                "motion": moved[i],
                **({"robot": metrics.robots[i]} if metrics.robots is not None and metrics.robots[i] is not None else {}),
            }
        )
    return per_episode


def _summary(batch, metrics: EpisodeMetrics, motion, hop) -> dict:
    """The metrics of ``run_episodes`` (module docstring) over the episodes of ``batch``, with the per-episode list."""
    per_episode = _per_episode(batch, metrics, motion)
    moved = motion.summary()
    steps = int(batch.lengths.sum())
    returns = np.array([e["return"] for e in per_episode])
    return {
        "episodes": len(per_episode),
        "survival_rate": float(np.mean([e["survived"] for e in per_episode])),
        "mean_return": float(returns.mean()),
        "std_return": float(returns.std()),
        "mean_length": float(np.mean([e["length"] for e in per_episode])),
        "endings": {ENDINGS[k]: int(count) for k, count in enumerate(np.bincount(metrics.ending, minlength=len(ENDINGS))) if k and count},
        "rms_base_drift": float(np.sqrt(metrics.drift_sq.sum() / steps)),
        "max_base_drift": float(metrics.drift_max),
        "rms_torso_angle": float(np.radians(moved["tilt_rms"])),
        "unilateral_violation_frac": metrics.unilateral / steps,
        "friction_violation_frac": metrics.friction / steps,
        "rms_torque": np.sqrt(metrics.torque_sq / steps).round(4).tolist(),
        "mean_reward_terms": {k: float(np.mean([e["reward_terms"][k] for e in per_episode])) for k in metrics.reward_terms},
        "steps": steps,
        "motion": moved,
        **(hop.summary() if hop is not None else {}),
        "per_episode": per_episode,
    }


_ROWS = (
    ("survival rate", "survival_rate", lambda v: f"{100 * v:.0f}%"),
    ("mean return", "mean_return", lambda v: f"{v:.2f}"),
    ("std return", "std_return", lambda v: f"{v:.2f}"),
    ("mean episode length", "mean_length", lambda v: f"{v:.1f}"),
    ("episodes ended early, by ending", "endings", lambda v: ", ".join(f"{name} {count}" for name, count in v.items()) or "-"),
    ("RMS base drift [cm]", "rms_base_drift", lambda v: f"{100 * v:.3f}"),
    ("max base drift [cm]", "max_base_drift", lambda v: f"{100 * v:.3f}"),
    ("steps with lam_y < 0", "unilateral_violation_frac", lambda v: f"{100 * v:.2f}%"),
    ("steps outside friction cone", "friction_violation_frac", lambda v: f"{100 * v:.2f}%"),
    ("RMS torque hip / knee [N m]", "rms_torque", lambda v: f"{v[0]:.2f} / {v[1]:.2f}"),
    # the hop task's (train.task_metrics.HopTracker); rows whose key a result lacks are left out
    ("hops (all lift-offs)", "hops", lambda v: f"{v}"),
    ("hops of 50 ms or more per episode", "hops_per_episode", lambda v: f"{v:.1f}"),
    ("mean abs apex error [cm]", "mean_abs_apex_error", lambda v: f"{100 * v:.2f}"),
    ("RMS apex error [cm]", "rms_apex_error", lambda v: f"{100 * v:.2f}"),
    ("mean apex error, signed [cm]", "mean_apex_error", lambda v: f"{100 * v:+.2f}"),
    ("mean hop period [s]", "mean_hop_period", lambda v: f"{v:.3f}"),
    ("mean / max COM drift after 10 s [cm]", "mean_drift_10s", None),
    ("mean / max landing impulse [N s]", "mean_landing_impulse", None),
)
_PAIRS = {"mean_drift_10s": ("max_drift_10s", 100.0, "{:.2f} / {:.2f}"), "mean_landing_impulse": ("max_landing_impulse", 1.0, "{:.2f} / {:.2f}")}


def _band_rows(bands: list[list[dict]]) -> list[str]:
    """Rows of the hop task's signed apex error by command band (``HopTracker.by_command``), one per band; none if the
    results' bands differ (policies evaluated on different command ranges)."""
    edges = [[(b["low"], b["high"]) for b in result] for result in bands]
    if any(e != edges[0] for e in edges):
        return []
    rows = []
    for k, (low, high) in enumerate(edges[0]):
        cells = [f"{100 * r[k]['mean_apex_error']:+.2f} ({r[k]['hops']})" if r[k]["hops"] else "-" for r in bands]
        rows.append(f"| ... at commands {round(100 * low, 1):g}-{round(100 * high, 1):g} cm (hops) | " + " | ".join(cells) + " |")
    return rows


def format_table(results: dict[str, dict]) -> str:
    """Markdown tables with one column per controller: the metrics, then how the robot moves (``train.motion``) over
    all episodes, on the episodes that both the first controller (the policy) and each other one survive (when the
    results carry ``both_survived``) and without pushes (when they carry ``no_push``)."""
    from train.motion import motion_sections

    return "\n\n".join([_metrics_table(results)] + motion_sections(results))


def _metrics_table(results: dict[str, dict]) -> str:
    """The metrics' table, one column per controller."""
    names = list(results)
    lines = ["| metric | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]
    for label, key, fmt in _ROWS:
        if not all(key in results[n] for n in names):
            continue
        if fmt is None:
            other, scale, pattern = _PAIRS[key]
            cells = [pattern.format(scale * results[n][key], scale * results[n][other]) for n in names]
        else:
            cells = [fmt(results[n][key]) for n in names]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
        if key == "mean_apex_error" and all("apex_error_by_command" in results[n] for n in names):
            lines.extend(_band_rows([results[n]["apex_error_by_command"] for n in names]))
    for term in next(iter(results.values()))["mean_reward_terms"]:
        lines.append(
            f"| return from reward_{term} | " + " | ".join(f"{results[n]['mean_reward_terms'][term]:.3f}" for n in names) + " |"
        )
    return "\n".join(lines)


def _write_gif(frames, path: Path, fps: float) -> Path:
    import imageio.v2 as imageio

    imageio.mimsave(path, [np.asarray(f) for f in frames], duration=1.0 / fps, loop=0)
    return path


@dataclass
class EvalArgs:
    """Evaluate a trained policy or a model-based controller over deterministic episodes and write the results."""

    policy: str = "lqr"
    """Run or policy folder (with model.zip and vecnormalize.pkl), a train.rllib run folder or checkpoint, or
    a model-based controller: 'lqr' (balance, push), 'stepping' (push: the LQR, a hop for large pushes), 'hopper' (hop),
    'mpc' (hop: iLQR around the hopper; push: iLQR around the stepping controller while it recovers) or 'gated' (the
    backward hop then the LQR, PlanarLegBalance-v1)."""
    baseline: list[str] = field(default_factory=list)
    """Also evaluate these controllers ('lqr', 'hopper', 'mpc', 'gated', 'stepping' or a folder; one or several) on the
    same seeds and print them side by side with the policy."""
    env_id: str | None = None
    """The task (None: the policy's own from its config.yaml, else leg_env/PlanarLegStance-v0)."""
    env_kwargs: list[str] | None = None
    """The evaluation env's arguments as key:value, in place of the run's eval_env_kwargs (as train.ppo's
    --eval-env-kwargs: 'push_force:[34.0, 34.0]'; none given: the task as registered; None: the run's own,
    or the task as registered for a controller)."""
    push_curve: bool = False
    """Push task: also measure survival against the push impulse (PUSH_FORCES, --episodes per force) for
    every controller, and the largest impulse each survives 90% of the time."""
    episodes: int = 20
    """Number of episodes."""
    seed: int = EVAL_SEED
    """Seed of the first episode; episode i uses seed + i."""
    out: Path | None = None
    """Output folder (None: <policy>/eval, or runs/eval_lqr when evaluating 'lqr')."""
    gif: bool = False
    """Write an animated GIF of the first episode (every 4th step, 320 px)."""
    plot: bool = True
    """Write timeseries.png (base drift, torques, contact force of the first episode) and, for a run
    folder, learning_curve.png with the baseline's level."""
    randomize: bool = False
    """Held-out robots: each episode's robot drawn from the task's default randomisation ranges
    (leg_env.randomize, randomize=True) by the episode's seed; robots.md lists every robot with each
    controller's survival and return."""

    def __post_init__(self):
        if self.baseline is None:
            self.baseline = []
        elif isinstance(self.baseline, (str, Path)):
            self.baseline = [str(self.baseline)]
        else:
            self.baseline = [str(b) for b in self.baseline]
        if self.episodes < 1:
            raise ValueError(f"episodes must be >= 1, got {self.episodes}")
        if self.env_kwargs is not None:
            try:
                self.chosen_env_kwargs()
            except ValueError as e:
                raise ValueError(f"env_kwargs: {e}") from None
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0 (episode seeds are non-negative), got {self.seed}")

    def chosen_env_kwargs(self) -> dict | None:
        """``env_kwargs`` as a dict (None when not given)."""
        from train.hyperparameters import parse_override

        return None if self.env_kwargs is None else dict(parse_override(item) for item in self.env_kwargs)


_NO_PUSH_KEYS = ("survival_rate", "mean_return", "mean_length", "endings", "motion")
"""What ``train.evaluate`` keeps of each controller's episodes without pushes (push task), in its ``no_push``."""


def run_without_pushes(controller, seeds, env_kwargs: dict, env_id: str) -> dict:
    """A controller's episodes of the push task on ``seeds`` with no push at all (``push_force`` (0, 0), the rest of
    ``env_kwargs`` kept): its ``env_kwargs``, ``_NO_PUSH_KEYS`` of ``run_episodes``' summary and the seeds of the
    episodes it ``fell`` in. ``train.evaluate``'s ``no_push``."""
    calm = {**env_kwargs, "push_force": [0.0, 0.0]}
    summary, _ = run_episodes(controller, seeds, calm, env_id=env_id)
    fell = [e["seed"] for e in summary["per_episode"] if not e["survived"]]
    return {"env_kwargs": calm, **{key: summary[key] for key in _NO_PUSH_KEYS}, "fell": fell}


def _bars_section(results: dict[str, dict]) -> str:
    """The table of the policy's acceptance bars (``train.bars``), headed by a line; empty for a task without bars."""
    from train.bars import bars_table, check_bars

    checks = check_bars(results)
    if not checks:
        return ""
    policy = next(iter(results))
    return (f"\n\nBars (`train.bars`): {policy} on these episodes; a comparison with a controller on the episodes both survive, "
            "the return on all of them; a bar is not measured without its controller's run, the push curve (`--push-curve`) "
            "or its evaluation env:\n\n" + bars_table({policy: checks}))  # fmt: skip


def _write_results(results: dict[str, dict], out: Path) -> None:
    """One JSON per controller: ``policy.json``, a controller's by its name (``lqr.json``), a folder baseline's
    ``baseline.json`` (``baseline_2.json``, ... for more)."""
    written = set()
    for k, (label, summary) in enumerate(results.items()):
        base = label.split(" ")[0]
        name = base if base in BASELINES else ("policy" if k == 0 else "baseline")
        stem, n = name, 1
        while name in written:
            n += 1
            name = f"{stem}_{n}"
        written.add(name)
        (out / f"{name}.json").write_text(json.dumps(summary, indent=2) + "\n")


def _measured_line(measured: dict) -> str:
    """The line that heads a results file: when and on what it was measured."""
    return f"Measured {measured['date']} on {measured['machine']}"


def _label(spec: str) -> str:
    return spec.lower() if spec.lower() in BASELINES else (Path(spec).name or "policy")


def evaluate(args: EvalArgs) -> Path:
    """Evaluate ``args.policy`` (and ``args.baseline``) and write the results; returns the output folder."""
    is_model = args.policy.lower() in BASELINES
    seeds = [args.seed + i for i in range(args.episodes)]

    policy = load_policy(args.policy, env_id=args.env_id)
    env_id = args.env_id or (None if is_model else getattr(policy, "env_id", None)) or ENV_ID
    env_kwargs = {} if is_model else policy.env_kwargs
    if args.env_kwargs is not None:
        env_kwargs = args.chosen_env_kwargs()
    if args.randomize:
        env_kwargs = {**env_kwargs, "randomize": True}
    controllers = {_label(args.policy): policy}
    specs = {_label(args.policy): args.policy}
    for spec in args.baseline:
        label = _label(spec)
        while label in controllers:
            label = f"{label} (baseline)"
        controllers[label] = load_policy(spec, env_kwargs=env_kwargs, env_id=env_id)
        specs[label] = spec
    # only once every controller has loaded: a mistyped policy folder must not be created as <policy>/eval
    out = Path(args.out) if args.out is not None else (Path(f"runs/eval_{args.policy.lower()}") if is_model else policy.path / "eval")
    out.mkdir(parents=True, exist_ok=True)

    from train.machine import describe
    from train.motion import both_survived
    from train.task_metrics import is_push_task

    measured = {"machine": describe(), "date": time.strftime("%Y-%m-%d")}
    results, series = {}, {}
    for k, (label, controller) in enumerate(controllers.items()):
        summary, rec = run_episodes(controller, seeds, env_kwargs, record=0, frames=args.gif and k == 0, env_id=env_id)
        results[label] = {"controller": specs[label], "env_id": env_id, "env_kwargs": env_kwargs, "seeds": seeds, **measured, **summary}
        series[label] = rec
        if k == 0 and args.gif and rec["frames"]:
            _write_gif(rec["frames"], out / "episode.gif", 1.0 / (rec["dt"] * GIF_FRAME_SKIP))
    dt = series[next(iter(series))]["dt"]
    both_survived(results, next(iter(results)), dt)
    if is_push_task(env_id):  # the same seeds with no push at all: does the policy stand still when nothing happens?
        for label, controller in controllers.items():
            results[label]["no_push"] = run_without_pushes(controller, seeds, env_kwargs, env_id)
    if args.push_curve:
        for label, impulse in _push_curve(controllers, env_id, env_kwargs, args, out, measured).items():
            results[label]["push_impulse_90"] = impulse
    _write_results(results, out)

    table = format_table(results) + _bars_section(results)
    (out / "table.md").write_text(
        f"{env_id}: {args.episodes} deterministic episodes, seeds {seeds[0]}..{seeds[-1]}, env kwargs {env_kwargs or 'default'}\n"
        f"{_measured_line(measured)}\n\n" + table + "\n"
    )
    print(table)
    if args.plot:
        from train.plots import plot_learning_curve, plot_motion, plot_time_series

        first = next(iter(series.values()))
        plot_time_series(series, out / "timeseries.png", first["dt"], first["torque_limit"])
        plot_motion(results, out / "motion.png")
        if first.get("hop") is not None:
            from train.plots import plot_hops

            plot_hops(series, out / "hops.png", first["dt"])
        log = None if is_model else policy.path / "evaluations.json"
        if not is_model and log.is_file():
            reference = next((results[k] for k in results if k.split(" ")[0] in BASELINES), None)
            history = json.loads(log.read_text())["evaluations"]
            plot_learning_curve(history, out / "learning_curve.png", env_id, reference)
    if args.randomize:
        (out / "robots.md").write_text(f"{_measured_line(measured)}\n\n" + robots_table(results) + "\n")
    print(f"results written to {out}/")
    return out


_ROBOT_COLUMNS = ("m_b", "m1", "m2", "I_b", "I1", "I2", "c1", "c2", "mu", "hip_torque_limit", "knee_torque_limit")


def robots_table(results: dict[str, dict]) -> str:
    """Every held-out robot (one per episode) with each controller's survival and return, then the totals."""
    names = list(results)
    first = results[names[0]]["per_episode"]
    head = "| seed | " + " | ".join(_ROBOT_COLUMNS) + " | " + " | ".join(f"{n}: survived, return" for n in names) + " |"
    lines = [head, "|" + "---:|" * (1 + len(_ROBOT_COLUMNS) + len(names))]
    for k, episode in enumerate(first):
        robot = episode.get("robot", {})
        cells = [f"{robot.get(c, float('nan')):.3g}" for c in _ROBOT_COLUMNS]
        runs = [results[n]["per_episode"][k] for n in names]
        lines.append(f"| {episode['seed']} | " + " | ".join(cells) + " | " + " | ".join(f"{'yes' if r['survived'] else 'no'}, {r['return']:.1f}" for r in runs) + " |")
    lines.append("| **all** | " + " | " * (len(_ROBOT_COLUMNS) - 1) + " | " + " | ".join(
        f"**{100 * results[n]['survival_rate']:.0f}%, {results[n]['mean_return']:.2f}**" for n in names) + " |")  # fmt: skip
    return "\n".join(lines)


PUSH_FORCES = tuple(2.5 * k for k in range(1, 25)) + tuple(range(70, 201, 10))
"""Push magnitudes of ``--push-curve`` [N]: 2.5 to 60 N in steps of 2.5 N (0.25 N s over the task's 0.1 s push,
where the controllers' limits lie), then to 200 N (20 N s) in steps of 10 N."""


def _push_curve(controllers: dict, env_id: str, env_kwargs: dict, args: EvalArgs, out: Path, measured: dict) -> dict:
    """Survival against the push impulse for every controller (``train.episodes.push_survival``)."""
    from train.episodes import push_survival
    from train.task_metrics import is_push_task, largest_survived_impulse

    if not is_push_task(env_id):
        raise ValueError(f"--push-curve needs the push task (leg_env/PlanarLegPush-v2), not {env_id}")
    curves = {label: push_survival(c, PUSH_FORCES, args.episodes, args.seed, env_kwargs, env_id) for label, c in controllers.items()}
    best = {label: largest_survived_impulse(rows) for label, rows in curves.items()}
    (out / "push_curve.json").write_text(json.dumps({"seeds": [args.seed, args.seed + args.episodes - 1], "curves": curves, "impulse_90": best}, indent=2) + "\n")
    names = list(curves)
    lines = ["| push [N] | impulse [N s] | " + " | ".join(f"{n} survival" for n in names) + " |", "|---:|---:|" + "---:|" * len(names)]
    for k, force in enumerate(PUSH_FORCES):
        impulse = curves[names[0]][k]["impulse"]
        lines.append(f"| {force:g} | {impulse:.2f} | " + " | ".join(f"{100 * curves[n][k]['survival_rate']:.0f}%" for n in names) + " |")
    lines.append("| **90% survival up to** | | " + " | ".join(f"**{best[n]:.2f} N s**" for n in names) + " |")
    table = "\n".join(lines)
    (out / "push_curve.md").write_text(f"{args.episodes} episodes per push magnitude, seeds {args.seed}..{args.seed + args.episodes - 1}\n"
                                       f"{_measured_line(measured)}\n\n{table}\n")  # fmt: skip
    print(table)
    if args.plot:
        from train.plots import plot_push_curve

        plot_push_curve(curves, best, out / "push_curve.png")
    return best


def main(argv: list[str] | None = None) -> None:
    args = parse_args(EvalArgs, argv, positional=("policy",), prog="python -m train.evaluate")
    try:
        evaluate(args)
    except (PolicyNotFoundError, PolicyLoadError) as e:
        raise SystemExit(f"python -m train.evaluate: error: {e}") from None


if __name__ == "__main__":
    main()
