"""``python -m train.curves`` on a tiny budget: every seed trained, the curves and the held-out scores summarised
by the IQM with bootstrap intervals, the shipped seed named before training and ranked, a rerun that trains
nothing again."""

from __future__ import annotations

import json

import numpy as np
import pytest

from train.curves import CurvesArgs, iqm_interval, main

TINY = ["n_envs:8", "n_steps:32", "batch_size:128", "n_epochs:1"]


def test_iqm_is_the_mean_of_the_middle_half_and_its_interval_contains_it():
    scores = np.arange(1.0, 9.0)  # IQM: mean of 3, 4, 5, 6
    iqm, low, high = iqm_interval(scores, reps=500)
    assert iqm == pytest.approx(4.5)
    assert low <= iqm <= high and low >= 1.0 and high <= 8.0 and high - low > 0.5
    assert iqm_interval(np.full(5, 0.7), reps=200) == pytest.approx((0.7, 0.7, 0.7))
    assert iqm_interval(scores, reps=500) == iqm_interval(scores, reps=500)  # seeded: the page is reproducible


@pytest.mark.parametrize(
    "kwargs, field",
    [({"seeds": 0}, "seeds"), ({"seeds": 3, "shipped_seed": 3}, "shipped_seed"), ({"eval_freq": 0}, "eval_freq"), ({"episodes": 0}, "episodes"),
     ({"jobs": 0}, "jobs")],
)
def test_bad_arguments_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        CurvesArgs(**kwargs)


def test_a_sweep_of_five_seeds_on_a_tiny_budget(tmp_path):
    runs, out = tmp_path / "runs", tmp_path / "page"
    argv = ["--env-id", "leg_env/PlanarLegBalance-v0", "--seeds", "5", "--shipped-seed", "2", "--total-timesteps", "512",
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
    page = (out / "README.md").read_text()
    assert "PPO seed 2 (shipped)" in page and "IQM" in page and "lqr (controller)" in page and "Machine:" in page
    assert page.count("| PPO seed ") == 5
    for png in ("curves_steps.png", "curves_time.png"):
        assert (out / png).stat().st_size > 1000
    # a rerun finds every seed finished and trains none again
    stamps = {p: p.stat().st_mtime_ns for p in runs.glob("seed_*/model.zip")}
    assert len(stamps) == 5
    main(argv)
    assert {p: p.stat().st_mtime_ns for p in runs.glob("seed_*/model.zip")} == stamps


def test_seeds_trained_in_parallel_processes_learn_what_one_process_learns(tmp_path):
    base = ["--env-id", "leg_env/PlanarLegBalance-v0", "--total-timesteps", "512", "--eval-freq", "256", "--eval-episodes", "2",
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
        assert line.startswith("python -m train.ppo --env-id leg_env/PlanarLegBalance-v0 --seed 1 --out ") and "--params n_envs:8" in line
