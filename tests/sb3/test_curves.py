"""``python -m train.curves`` on a tiny budget: every seed trained, the curves and the held-out scores summarised
by the IQM with bootstrap intervals, the shipped seed named before training and ranked, a rerun that trains
nothing again."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from train.bars import BALANCE_BARS
from train.curves import CurvesArgs, iqm, iqm_interval, main

TINY = ["n_envs:8", "n_steps:32", "batch_size:128", "n_epochs:1"]


def test_iqm_is_the_mean_of_the_middle_half_and_its_interval_contains_it():
    scores = np.arange(1.0, 9.0)  # IQM: mean of 3, 4, 5, 6
    iqm, low, high = iqm_interval(scores, reps=500)
    assert iqm == pytest.approx(4.5)
    assert low <= iqm <= high and low >= 1.0 and high <= 8.0 and high - low > 0.5
    assert iqm_interval(np.full(5, 0.7), reps=200) == pytest.approx((0.7, 0.7, 0.7))
    assert iqm_interval(scores, reps=500) == iqm_interval(scores, reps=500)  # seeded: the page is reproducible


def test_iqm_is_rliables_to_the_bit():
    """``train.curves.iqm`` is rliable's ``aggregate_iqm`` (SciPy's 25% trimmed mean over every entry), to the bit,
    on matrices of any shape (the bootstrap's resamples are (seeds, 1)), ties and sizes where the quarter rounds down;
    and the interval is rliable's own bootstrap of it."""
    from rliable import library as rly
    from rliable import metrics

    rng = np.random.default_rng(4)
    for n in (1, 2, 3, 4, 5, 7, 8, 11, 16):
        for x in (rng.standard_normal((n, 1)), rng.integers(0, 3, (n, 1)).astype(float), 1e3 * rng.random((n, 3))):
            assert iqm(x) == metrics.aggregate_iqm(x)
    scores = rng.standard_normal(7)
    np.random.seed(0)
    point, interval = rly.get_interval_estimates({"ppo": scores.reshape(-1, 1)}, lambda x: np.array([metrics.aggregate_iqm(x)]),
                                                 reps=300)
    assert iqm_interval(scores, reps=300) == (point["ppo"][0], interval["ppo"][0, 0], interval["ppo"][1, 0])


@pytest.mark.parametrize(
    "kwargs, field",
    [({"seeds": 0}, "seeds"), ({"seeds": 3, "shipped_seed": 3}, "shipped_seed"), ({"eval_freq": 0}, "eval_freq"), ({"episodes": 0}, "episodes"),
     ({"jobs": 0}, "jobs"), ({"eval_env_kwargs": ["push_force"]}, "eval_env_kwargs"), ({"update_precision": "float16"}, "update_precision"), ({"tanh": "sigmoid"}, "tanh"),
     ({"select_after": -1}, "select_after")],
)
def test_bad_arguments_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        CurvesArgs(**kwargs)


def test_a_sweep_on_randomised_robots_has_its_own_folders_and_title():
    """Evaluated on randomised robots, a sweep is not the task's nominal one: its default folders and its title say so."""
    from train.curves import _task

    args = CurvesArgs(env_id="leg_env/PlanarLegPush-v2", eval_env_kwargs=["push_force:[34.0, 34.0]", "randomize:true"])
    assert args.out.name == "PlanarLegPush-v2-randomized" and args.runs.name == "PlanarLegPush-v2-randomized"
    assert _task(args) == "leg_env/PlanarLegPush-v2, randomised robots"
    nominal = CurvesArgs(env_id="leg_env/PlanarLegPush-v2", eval_env_kwargs=["push_force:[34.0, 34.0]"])
    assert nominal.out.name == "PlanarLegPush-v2" and _task(nominal) == "leg_env/PlanarLegPush-v2"


def test_a_sweep_of_five_seeds_on_a_tiny_budget(tmp_path):
    runs, out = tmp_path / "runs", tmp_path / "page"
    argv = ["--env-id", "leg_env/PlanarLegBalance-v1", "--seeds", "5", "--shipped-seed", "2", "--total-timesteps", "512",
            "--eval-freq", "256", "--eval-episodes", "2", "--episodes", "3", "--baseline", "lqr",
            "--runs", str(runs), "--out", str(out), "--params", *TINY]
    main(argv)
    plan = json.loads((out / "plan.json").read_text())
    assert plan["seeds"] == [0, 1, 2, 3, 4] and plan["shipped_seed"] == 2
    scores = json.loads((out / "scores.json").read_text())
    curves, final = scores["curves"], scores["final"]
    assert curves["timesteps"] == [256, 512] and len(curves["time_s"]) == 2
    for metric in ("survival_rate", "mean_return"):
        per_seed = np.array(curves[metric]["per_seed"])
        assert per_seed.shape == (5, 2)
        for j in range(2):  # the IQM and its interval lie within the seeds' values
            assert per_seed[:, j].min() - 1e-9 <= curves[metric]["low"][j] <= curves[metric]["iqm"][j] <= curves[metric]["high"][j] <= per_seed[:, j].max() + 1e-9
        values = [final["per_seed"][str(s)][metric] for s in range(5)]
        iqm, low, high = final["iqm"][metric]
        assert min(values) - 1e-9 <= low <= iqm <= high <= max(values) + 1e-9
    # every seed trained with its own seed: the in-training returns are not all the same
    assert len({tuple(r) for r in curves["mean_return"]["per_seed"]}) > 1
    ranks = sorted(final["rank"].values())
    assert ranks == [1, 2, 3, 4, 5]
    assert scores["baseline"]["survival_rate"] >= 0.0 and "mean_return" in scores["baseline"]
    # the balance task's bars compare with the gated controller too: it ran the same episodes beside the baseline
    assert list(scores["controllers"]) == ["lqr", "gated"] and scores["baseline"] == scores["controllers"]["lqr"]
    for s in range(5):
        seed = final["per_seed"][str(s)]
        assert seed["motion"]["episodes"] == 3 and set(seed["both_survived"]) == {"lqr", "gated"}
        assert [check["description"] for check in seed["bars"]] == [bar.description for bar in BALANCE_BARS]
        assert scores["controllers"]["gated"]["both_survived"][str(s)]["episodes"] == seed["both_survived"]["gated"]["episodes"]
    assert set(final["motion_iqm"]["all"]) >= {"tilt_rms", "action_rate", "actuator_power"}
    page = (out / "README.md").read_text()
    assert "PPO seed 2 (shipped)" in page and "IQM" in page and "lqr (controller)" in page and "Machine:" in page
    assert "How each seed's selected policy moves" in page and "| survival >= 98% |" in page and " of 5 seeds meet every bar.**" in page
    assert (out / "motion.png").stat().st_size > 1000
    assert "Resumed" not in page  # every seed trained in one go
    assert sum(line.startswith("| PPO seed ") for line in page.splitlines()) == 5  # the final scores' rows
    for png in ("curves_steps.png", "curves_time.png"):
        assert (out / png).stat().st_size > 1000
    # a rerun finds every seed finished and trains none again
    stamps = {p: p.stat().st_mtime_ns for p in runs.glob("seed_*/model.zip")}
    assert len(stamps) == 5
    main(argv)
    assert {p: p.stat().st_mtime_ns for p in runs.glob("seed_*/model.zip")} == stamps


def test_a_push_sweep_scores_the_push_curve_on_its_evaluation_env(tmp_path):
    """On the push task the page ranks the seeds by the push curve's 90% impulse, each computed as
    ``train.evaluate --push-curve`` computes it, and the in-training, held-out and baseline episodes all run
    the evaluation env of ``--eval-env-kwargs``."""
    from train.evaluate import PUSH_FORCES, load_policy
    from train.episodes import push_survival
    from train.task_metrics import largest_survived_impulse

    runs, out = tmp_path / "runs", tmp_path / "page"
    env_id = "leg_env/PlanarLegPush-v2"
    argv = ["--env-id", env_id, "--seeds", "2", "--shipped-seed", "1", "--total-timesteps", "256",
            "--eval-freq", "256", "--eval-episodes", "2", "--episodes", "2", "--baseline", "stepping",
            "--eval-env-kwargs", "push_force:[45.0, 45.0]", "--runs", str(runs), "--out", str(out), "--params", *TINY]
    main(argv)
    scores = json.loads((out / "scores.json").read_text())
    final = scores["final"]
    for seed in (0, 1):
        folder = runs / f"seed_{seed}"
        assert "--eval-env-kwargs 'push_force:[45.0, 45.0]'" in (folder / "command.txt").read_text()
        policy = load_policy(folder)
        assert policy.env_kwargs == {"push_force": [45.0, 45.0]}
        assert policy.env_id == env_id
        expected = largest_survived_impulse(push_survival(policy, PUSH_FORCES, 2, 10_000, policy.env_kwargs, env_id))
        assert final["per_seed"][str(seed)]["push_impulse_90"] == expected
    impulses = {s: final["per_seed"][str(s)]["push_impulse_90"] for s in (0, 1)}
    best = max(impulses, key=lambda s: impulses[s])
    if impulses[0] != impulses[1]:
        assert final["rank"][str(best)] == 1
    # the baseline's push curve on the same held-out episodes (on 100 of them the stepping controller reaches 4.5 N s)
    stepping = load_policy("stepping", {"push_force": [45.0, 45.0]}, env_id=env_id)
    curve = push_survival(stepping, PUSH_FORCES, 2, 10_000, {"push_force": [45.0, 45.0]}, env_id)
    assert scores["baseline"]["push_impulse_90"] == largest_survived_impulse(curve)
    assert scores["baseline"]["push_impulse_90"] >= 2.0
    page = (out / "README.md").read_text()
    assert "90% survival up to [N s]" in page and "push_force=[45.0, 45.0]" in page and "stepping (controller)" in page
    assert "Rank: by the push curve's 90% impulse" in page
    # each seed also ran the same episodes with no push; the bars pushed at 5 N s need an evaluation env at 50 N
    for seed in (0, 1):
        scores_of_seed = final["per_seed"][str(seed)]
        assert scores_of_seed["no_push"]["env_kwargs"] == {"push_force": [0.0, 0.0]} and "motion" in scores_of_seed["no_push"]
        checks = {check["description"]: check for check in scores_of_seed["bars"]}
        assert checks["push impulse survived 90% of the time >= 6.00 N s"]["measured"] == scores_of_seed["push_impulse_90"]
        assert checks["pushed at 5 N s: action rate <= 0.1"]["passed"] is None
    assert "With no push at all" in page and "**0 of 2 seeds meet every bar.**" in page


def test_seeds_trained_in_parallel_processes_learn_what_one_process_learns(tmp_path):
    base = ["--env-id", "leg_env/PlanarLegBalance-v1", "--total-timesteps", "512", "--eval-freq", "256", "--eval-episodes", "2",
            "--episodes", "2", "--params", *TINY]
    main(base + ["--seeds", "2", "--jobs", "2", "--runs", str(tmp_path / "parallel"), "--out", str(tmp_path / "page_parallel")])
    main(base + ["--seeds", "1", "--first-seed", "1", "--runs", str(tmp_path / "serial"), "--out", str(tmp_path / "page_serial")])

    def evaluations(folder):
        return [(e["timesteps"], e["mean_return"], e["survival_rate"]) for e in json.loads((folder / "evaluations.json").read_text())["evaluations"]]

    assert len(evaluations(tmp_path / "parallel" / "seed_1")) == 2
    assert evaluations(tmp_path / "parallel" / "seed_1") == evaluations(tmp_path / "serial" / "seed_1")
    assert evaluations(tmp_path / "parallel" / "seed_0") != evaluations(tmp_path / "parallel" / "seed_1")
    # each seed's folder says how to train it alone, whichever process trained it
    for folder in ("parallel", "serial"):
        line = (tmp_path / folder / "seed_1" / "command.txt").read_text().splitlines()[0]
        assert line.startswith("python -m train.ppo --env-id leg_env/PlanarLegBalance-v1 --seed 1 --out ") and "--params n_envs:8" in line


def test_a_sweep_passes_its_update_precision_and_selection_to_each_seed_and_can_be_one_not_shipped(tmp_path):
    import yaml

    main(["--env-id", "leg_env/PlanarLegBalance-v1", "--total-timesteps", "256", "--eval-freq", "128", "--eval-episodes", "2",
          "--episodes", "2", "--seeds", "1", "--update-precision", "bfloat16", "--tanh", "torch", "--no-shipped", "--select-after", "200",
          "--params", *TINY, "--runs", str(tmp_path / "runs"), "--out", str(tmp_path / "page")])  # fmt: skip
    folder = tmp_path / "runs" / "seed_0"
    config = yaml.safe_load((folder / "config.yaml").read_text())
    assert config["update_precision"] == "bfloat16" and config["select_after"] == 200 and config["tanh"] == "torch"
    assert "--update-precision bfloat16" in (folder / "command.txt").read_text()
    assert "--tanh torch" in (folder / "command.txt").read_text()
    assert "--select-after 200" in (folder / "command.txt").read_text()
    assert json.loads((folder / "evaluations.json").read_text())["selected"]["timesteps"] == 256  # not the one at 128
    page = (tmp_path / "page" / "README.md").read_text()
    assert "selected policy (its best in-training evaluation at 200 steps or more) on 2 held-out episodes" in page
    assert page.startswith("# Learning curves: leg_env/PlanarLegBalance-v1, bfloat16 update\n")
    assert "PPO's update: the hidden layers in bfloat16 (matrix products in bfloat16, parameters and losses float32)" in page
    assert "The seed to ship, named before training: 0 (not shipped" in page and "| PPO seed 0 (named) |" in page and "(shipped)" not in page


def test_a_sweep_trains_every_seed_on_the_entry_of_its_hyperparameter_file(tmp_path):
    import yaml

    from train.hyperparameters import DEFAULT_HYPERPARAMS

    entry = yaml.safe_load(DEFAULT_HYPERPARAMS.read_text())["leg_env/PlanarLegBalance-v1"]
    entry["gamma"] = 0.97  # the file's own value, which no override sets
    hyperparams = tmp_path / "probe.yml"
    hyperparams.write_text(yaml.safe_dump({"leg_env/PlanarLegBalance-v1": entry}))
    main(["--env-id", "leg_env/PlanarLegBalance-v1", "--total-timesteps", "256", "--eval-freq", "128", "--eval-episodes", "2",
          "--episodes", "2", "--seeds", "1", "--hyperparams", str(hyperparams), "--params", *TINY,
          "--runs", str(tmp_path / "runs"), "--out", str(tmp_path / "page")])  # fmt: skip
    folder = tmp_path / "runs" / "seed_0"
    config = yaml.safe_load((folder / "config.yaml").read_text())
    assert config["ppo"]["gamma"] == 0.97 and Path(config["hyperparams_file"]).name == "probe.yml"
    assert f"--hyperparams {hyperparams}" in (folder / "command.txt").read_text()
    assert "probe.yml" in json.loads((tmp_path / "page" / "plan.json").read_text())["hyperparams"]
    assert f"entry of `{hyperparams}`" in (tmp_path / "page" / "README.md").read_text()


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, dead but not yet reaped by its new parent, does not)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")


def _wait_for(condition, seconds: float, what: str) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {seconds:.0f} s: {what}")
        time.sleep(0.2)


def _worker_pids(runs: Path, seeds) -> dict:
    """The process training each seed's folder, from its lock file, once every seed has one."""
    pids = {}
    for seed in seeds:
        try:
            pids[seed] = int((runs / f"seed_{seed}" / "train.lock").read_text())
        except (FileNotFoundError, ValueError):
            return {}
    return pids


def _checkpoints(runs: Path, seed: int) -> dict:
    """Each checkpoint of a seed's run and when it was written (a save at the same step count replaces one)."""
    return {p.name: p.stat().st_mtime_ns for p in (runs / f"seed_{seed}" / "checkpoints").glob("0*")}


def _logged(runs: Path, seed: int) -> int:
    """Bytes of a seed's TensorBoard log: it grows as PPO iterations end."""
    return sum(p.stat().st_size for p in (runs / f"seed_{seed}" / "tb").rglob("events.*"))


def test_stopping_a_parallel_sweep_stops_every_worker_at_a_checkpoint(tmp_path):
    """``--jobs 2``: a SIGTERM to the command stops both workers at a checkpoint before it exits (130); when the
    command is killed outright (SIGKILL), each worker notices and stops the same way by itself. Nothing keeps
    training after the command is gone, and the same command resumes."""
    runs = tmp_path / "runs"
    command = [sys.executable, "-m", "train.curves", "--env-id", "leg_env/PlanarLegBalance-v1", "--seeds", "2", "--jobs", "2",
               "--total-timesteps", "100000000", "--eval-freq", "100000000", "--episodes", "2", "--runs", str(runs),
               "--out", str(tmp_path / "page"), "--params", *TINY]
    root = Path(__file__).resolve().parents[2]
    for how in (signal.SIGTERM, signal.SIGKILL):
        before = {seed: _checkpoints(runs, seed) for seed in (0, 1)}
        sweep = subprocess.Popen(command, cwd=root, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        try:
            _wait_for(lambda: len(_worker_pids(runs, (0, 1))) == 2, 180, "both seeds training")
            pids = _worker_pids(runs, (0, 1))
            assert sweep.pid not in pids.values() and all(_alive(pid) for pid in pids.values())
            logged = {seed: _logged(runs, seed) for seed in (0, 1)}
            _wait_for(lambda: all(_logged(runs, seed) > logged[seed] + 20_000 for seed in (0, 1)), 180, "both seeds in PPO iterations")
            sweep.send_signal(how)
            code = sweep.wait(timeout=120)
            if how == signal.SIGTERM:
                assert code == 130, sweep.stderr.read().decode()[-2000:]
                assert not any(_alive(pid) for pid in pids.values())  # waited for: none outlives the command
            else:
                _wait_for(lambda: not any(_alive(pid) for pid in pids.values()), 60, "the orphaned workers stopping")
            for seed in (0, 1):  # each stopped at a checkpoint of its own, a new one
                assert _checkpoints(runs, seed).items() - before[seed].items(), f"seed {seed} saved no checkpoint on stopping ({how!r})"
        finally:
            if sweep.poll() is None:
                sweep.kill()
                sweep.wait()


def test_the_page_says_which_seeds_were_resumed():
    from train.curves import _resumed

    assert _resumed({"0": 0, "1": 0}) == []
    line = _resumed({"0": 1, "1": 0, "2": 3})[0]
    assert "seed 0 once, seed 2 3 times." in line and "seed 1" not in line


def _motion(**values) -> dict:
    """A motion summary (train.motion.pool's keys), some numbers given."""
    from train.motion import KEYS as MOTION_KEYS

    return {**{key: 1.0 for key in MOTION_KEYS}, "episodes": 100, "normal_force_unit": "m g", **values}


def _synthetic_push_scores() -> tuple[CurvesArgs, dict, dict, dict]:
    """The page's numbers for two push seeds and the stepping controller, made up: seed 0 meets every bar, seed 1
    chatters when nothing pushes it."""
    from train.bars import PUSH_BARS

    args = CurvesArgs(env_id="leg_env/PlanarLegPush-v2", seeds=2, baseline="stepping", episodes=100, eval_freq=100,
                      eval_env_kwargs=["push_force:[50.0, 50.0]"], runs=Path("runs"), out=Path("page"))  # fmt: skip
    curves = {"timesteps": [100], "time_s": [60.0], "seeds": [0, 1],
              **{m: {"per_seed": [[1.0], [1.0]], "iqm": [1.0], "low": [1.0], "high": [1.0]} for m in ("survival_rate", "mean_return")}}  # fmt: skip
    calm = {"survival_rate": 1.0, "mean_return": 990.0, "motion": _motion(tilt_rms=0.5, action_rate=0.004)}
    chatter = {"survival_rate": 1.0, "mean_return": 900.0, "motion": _motion(tilt_rms=4.0, action_rate=0.3, flights_per_episode=12.0)}
    passed = [{"description": bar.description, "measured": bar.bound if bar.at_least else 0.5 * bar.bound, "threshold": bar.bound, "passed": True}
              for bar in PUSH_BARS]  # fmt: skip
    passed[0] = {**passed[0], "measured": 7.0, "threshold": 6.0}
    failed = [dict(check) for check in passed]
    failed[3] = {**failed[3], "measured": 0.3, "passed": False}  # with no push: action rate
    per_seed = {
        "0": {"push_impulse_90": 7.0, "survival_rate": 1.0, "mean_return": 600.0, "mean_length": 1000.0,
              "motion": _motion(tilt_rms=2.0), "no_push": calm, "bars": passed},
        "1": {"push_impulse_90": 6.5, "survival_rate": 0.97, "mean_return": 580.0, "mean_length": 990.0,
              "motion": _motion(tilt_rms=3.0), "no_push": chatter, "bars": failed},
    }  # fmt: skip
    final = {"per_seed": per_seed, "rank": {"0": 1, "1": 2}, "iqm": {"survival_rate": (0.985, 0.97, 1.0)},
             "motion_iqm": {case: {key: (2.5, 2.0, 3.0) for key in _motion() if key not in ("episodes", "normal_force_unit")}
                            for case in ("all", "no_push")}}  # fmt: skip
    controllers = {"stepping": {"push_impulse_90": 4.5, "survival_rate": 0.84, "mean_return": 651.0, "mean_length": 861.0,
                                "motion": _motion(tilt_rms=5.0), "no_push": calm}}  # fmt: skip
    return args, curves, final, controllers


def test_the_page_shows_how_each_seed_moves_and_which_bars_it_meets():
    """From the numbers of scores.json alone: the motion table (a column per seed, the IQM with its interval, the
    controller), the one with no push, and the bars per seed with how many seeds meet every one."""
    from train.curves import _page

    args, curves, final, controllers = _synthetic_push_scores()
    page = _page(args, "a machine", curves, final, controllers, "python -m train.curves")
    motion = page.split("How each seed's selected policy moves")[1].split("With no push at all")[0]
    assert "| measure | PPO seed 0 (shipped) | PPO seed 1 | PPO, IQM of 2 seeds [95% CI] | stepping (controller) |" in motion
    assert "| torso tilt RMS [deg] | 2.00 | 3.00 | 2.50 [2.00, 3.00] | 5.00 |" in motion
    assert "![how each seed moves](motion.png)" in motion
    calm = page.split("With no push at all")[1].split("Bars (`train.bars`)")[0]
    assert "| survival rate | 100% | 100% |  | 100% |" in calm
    assert "| action rate (mean abs change per step) | 0.004 | 0.3 | 2.5 [2, 3] | 0.004 |" in calm
    bars = page.split("Bars (`train.bars`)")[1]
    assert "| bar | PPO seed 0 (shipped) | PPO seed 1 |" in bars
    assert "| push impulse survived 90% of the time >= 6.00 N s | pass: 7.00 N s | pass: 7.00 N s |" in bars
    assert "| with no push: survival >= 100% | pass: 100% | pass: 100% |" in bars
    assert "| with no push: action rate <= 0.01 | pass: 0.005 | **fail**: 0.3 |" in bars
    assert "| pushed at 5 N s: actuator power <= 2x stepping's (episodes both survive) | pass: 1.00 W (bar 2.00 W) |" in bars
    assert "| **every bar** | **yes** | no |" in bars and "**1 of 2 seeds meet every bar.**" in bars
    assert "| stepping (controller) | | 4.50 | 84% | 651.0 | 861 |" in page


def test_a_page_without_motion_measures_or_bars_has_neither_section():
    """A task without bars (the pinned foot) has no bars section; scores from before the motion measures no motion one."""
    from train.curves import _page

    args, curves, final, controllers = _synthetic_push_scores()
    for scores in final["per_seed"].values():
        del scores["motion"], scores["no_push"], scores["bars"]
    del final["motion_iqm"]
    page = _page(args, "a machine", curves, final, {}, "python -m train.curves")
    assert "How each seed" not in page and "Bars" not in page and "(controller)" not in page
