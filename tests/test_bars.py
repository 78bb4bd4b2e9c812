"""The acceptance bars (train.bars): each task's bars found by the env id's name in any version, every bar passed by
a policy that meets it and failed just past its threshold (and only that bar), the bars that cannot be measured
said so, and train.evaluate's table ending with them."""

from __future__ import annotations

import copy
import json
import math

import pytest

from train import bars as b
from train.bars import BOTH_SURVIVED, NO_PUSH, bar_controllers, bars_for, bars_table, check_bars, meets_every_bar, task_name

BALANCE, HOP, PUSH = "leg_env/PlanarLegBalance-v1", "leg_env/PlanarLegHop-v4", "leg_env/PlanarLegPush-v2"


def motion(**values) -> dict:
    """A motion summary (train.motion.pool's keys) of calm numbers, some replaced."""
    calm = {"episodes": 100, "tilt_rms": 2.0, "action_rate": 0.005, "saturated_share": 0.01, "actuator_power": 1.0,
            "peak_normal_force": 1.2, "peak_normal_force_max": 1.5, "flights_per_episode": 0.0, "flights_per_10s": 0.0,
            "com_excursion": 0.02, "normal_force_unit": "m g"}  # fmt: skip
    return {**calm, **values}


def evaluation(env_id: str, env_kwargs: dict | None = None) -> dict[str, dict]:
    """train.evaluate's results for a policy (first) that meets every bar of its task, and the task's controllers."""
    policy = {"env_id": env_id, "env_kwargs": env_kwargs or {}, "survival_rate": 1.0, "mean_return": 950.0, "motion": motion()}
    controller = {"env_id": env_id, "env_kwargs": env_kwargs or {}, "survival_rate": 0.9, "mean_return": 900.0,
                  "motion": motion(tilt_rms=3.0, action_rate=0.2, saturated_share=0.2, actuator_power=4.0, peak_normal_force=2.5,
                                   com_excursion=0.1)}  # fmt: skip
    if task_name(env_id) == "PlanarLegHop":
        policy.update(hops_per_episode=30.0, mean_abs_apex_error=0.005, mean_drift_10s=0.03)
        policy["motion"] = motion(flights_per_episode=30.0)
    if task_name(env_id) == "PlanarLegPush":
        policy.update(push_impulse_90=7.0, no_push={"survival_rate": 1.0, "mean_return": 990.0, "motion": motion()})
        controller["no_push"] = {"survival_rate": 1.0, "mean_return": 980.0, "motion": motion()}
    results = {"ppo": policy}
    for k, name in enumerate(bar_controllers(env_id, env_kwargs)):
        theirs = copy.deepcopy(controller)
        theirs["mean_return"] -= 50.0 * k  # each controller its own numbers
        policy.setdefault("both_survived", {})[name] = {k: v for k, v in policy["motion"].items()}
        theirs["both_survived"] = {"ppo": dict(theirs["motion"])}
        results[name] = theirs
    return results


def where(results: dict, bar, name: str = "ppo", other: str | None = None) -> dict:
    """The summary that holds a bar's number for ``name`` (read as train.bars documents it)."""
    result = results[name]
    if bar.episodes == NO_PUSH:
        result = result["no_push"]
    elif bar.episodes == BOTH_SURVIVED:
        return result["both_survived"][other or bar.controller]
    return result if bar.measure in result else result["motion"]


CASES = [(BALANCE, {}), ("leg_env/PlanarLegBalance-v1", {}), (HOP, {}), ("leg_env/PlanarLegHop-v4", {}),
         (PUSH, {"push_force": [50.0, 50.0]}), ("leg_env/PlanarLegPush-v2", {"push_force": (50, 50)}),
         (PUSH, {"push_force": [34.0, 34.0], "randomize": True})]  # fmt: skip
EVERY_BAR = [(env_id, kwargs, k) for env_id, kwargs in CASES for k in range(len(bars_for(env_id, kwargs)))]


def test_a_task_is_found_by_its_name_in_any_version():
    assert task_name("leg_env/PlanarLegPush-v22") == "PlanarLegPush" and task_name("PlanarLegHop-v4") == "PlanarLegHop"
    assert bars_for("leg_env/PlanarLegBalance-v1") == bars_for(BALANCE) == b.BALANCE_BARS
    assert bars_for("leg_env/PlanarLegHop-v4") == b.HOP_BARS and bars_for("leg_env/PlanarLegPush-v2") == b.PUSH_BARS
    assert bars_for(PUSH, {"randomize": True}) == b.RANDOMIZED_PUSH_BARS and bars_for(HOP, {"randomize": True}) == b.HOP_BARS
    assert bars_for("leg_env/PlanarLegStance-v0") == () and check_bars({"lqr": {"env_id": "leg_env/PlanarLegStance-v0"}}) == []
    assert bar_controllers(BALANCE) == ("gated", "lqr") and bar_controllers(HOP) == ("hopper",) and bar_controllers(PUSH) == ("stepping",)


def test_the_thresholds_are_the_tasks_bars():
    described = {env_id: [bar.description for bar in bars_for(env_id, kwargs)] for env_id, kwargs in ((BALANCE, {}), (HOP, {}), (PUSH, {}))}
    assert described[BALANCE][:3] == ["survival >= 98%", "mean return >= gated's", "mean return >= lqr's"]
    assert "torso tilt RMS <= gated's (episodes both survive)" in described[BALANCE]
    assert {"survival >= 98%", "hops of 50 ms+ per episode >= 10.0", "mean abs apex error <= 1.50 cm", "mean COM drift at the end <= 5.00 cm",
            "torso tilt RMS <= 8.0 deg", "peak normal force <= hopper's (episodes both survive)"} <= set(described[HOP])  # fmt: skip
    assert {"push impulse survived 90% of the time >= 6.00 N s", "with no push: survival >= 100%", "with no push: flights per episode <= 0.0",
            "with no push: action rate <= 0.01", "with no push: actuator power <= 2.00 W", "pushed at 5 N s: action rate <= 0.1",
            "pushed at 5 N s: saturated share <= 10.0%", "pushed at 5 N s: actuator power <= 2x stepping's (episodes both survive)"} == set(described[PUSH])  # fmt: skip
    assert [bar.description for bar in b.RANDOMIZED_PUSH_BARS] == ["randomised robots pushed at 3.4 N s: survival >= 90%"]


@pytest.mark.parametrize("env_id, env_kwargs", CASES)
def test_a_policy_within_every_bar_meets_every_bar(env_id, env_kwargs):
    checks = check_bars(evaluation(env_id, env_kwargs))
    assert len(checks) == len(bars_for(env_id, env_kwargs)) > 0
    assert all(check.passed for check in checks), [c for c in checks if not c.passed]
    assert meets_every_bar(checks)
    for check, bar in zip(checks, bars_for(env_id, env_kwargs)):
        assert check.description == bar.description and check.measured is not None


@pytest.mark.parametrize("env_id, env_kwargs, k", EVERY_BAR)
def test_each_bar_holds_at_its_threshold_and_fails_just_past_it(env_id, env_kwargs, k):
    """The policy's number set to the threshold passes; set just past it, this bar fails and every bar on another
    number passes (the balance task's return has two bars)."""
    results = evaluation(env_id, env_kwargs)
    bars = bars_for(env_id, env_kwargs)
    bar = bars[k]
    threshold = check_bars(results)[k].threshold
    if bar.controller is not None:  # the threshold is the controller's number on the same episodes, times the factor
        assert threshold == pytest.approx(bar.bound * where(results, bar, bar.controller, "ppo")[bar.measure])
    else:
        assert threshold == bar.bound
    where(results, bar)[bar.measure] = threshold
    assert check_bars(results)[k].passed is True
    past = threshold - 1e-3 if bar.at_least else threshold + 1e-3
    where(results, bar)[bar.measure] = past
    checks = check_bars(results)
    assert checks[k].passed is False and checks[k].measured == past and checks[k].threshold == threshold
    others = [c.passed for j, c in enumerate(checks) if (bars[j].measure, bars[j].episodes) != (bar.measure, bar.episodes)]
    assert others == [True] * len(others) and len(others) >= len(checks) - 2
    assert not meets_every_bar(checks)


def test_numbers_against_the_hop_bars():
    results = evaluation(HOP)
    results["ppo"].update(mean_abs_apex_error=0.016, mean_drift_10s=0.049)
    results["ppo"]["both_survived"]["hopper"]["actuator_power"] = 4.5  # the hopper's 4.0 on the same episodes
    results["ppo"]["motion"]["tilt_rms"] = 37.0
    checks = {c.description: c for c in check_bars(results)}
    assert checks["mean abs apex error <= 1.50 cm"].passed is False
    assert checks["mean COM drift at the end <= 5.00 cm"].passed is True
    power = checks["actuator power <= hopper's (episodes both survive)"]
    assert (power.measured, power.threshold, power.passed) == (4.5, 4.0, False)
    assert checks["torso tilt RMS <= 8.0 deg"].passed is False
    assert "**fail**: 4.50 W (bar 4.00 W)" == power.cell()


def test_a_nan_fails_and_no_episode_both_survive_is_said():
    results = evaluation(PUSH, {"push_force": [50.0, 50.0]})
    results["ppo"]["both_survived"]["stepping"].update(episodes=0, actuator_power=math.nan)
    results["stepping"]["both_survived"]["ppo"].update(episodes=0, actuator_power=math.nan)
    power = check_bars(results)[-1]
    assert power.passed is False and power.note == "no episode both survive"
    assert power.cell() == "**fail**: nan (bar nan; no episode both survive)"


def test_bars_without_their_numbers_are_not_measured_and_not_met():
    """Without the controller's run, the push curve or the evaluation env a bar needs, the bar is not measured (never
    passed), and the policy does not meet every bar."""
    results = evaluation(PUSH, {"push_force": [45.0, 45.0]})  # not the 5 N s pushes
    del results["ppo"]["push_impulse_90"], results["stepping"]
    checks = check_bars(results)
    unmeasured = {c.description: c.note for c in checks if c.passed is None}
    assert unmeasured["push impulse survived 90% of the time >= 6.00 N s"] == "no push_impulse_90 in the results"
    assert unmeasured["pushed at 5 N s: action rate <= 0.1"] == "needs an evaluation env with push_force (50.0, 50.0)"
    assert unmeasured["pushed at 5 N s: actuator power <= 2x stepping's (episodes both survive)"].startswith("needs an evaluation env")
    assert [c.passed for c in checks if c.passed is not None] == [True] * 4  # the no-push bars
    assert not meets_every_bar(checks) and not meets_every_bar([])
    results = evaluation(BALANCE)
    del results["lqr"]
    assert check_bars(results)[2].note == "no lqr run"
    results = {"gated": evaluation(BALANCE)["ppo"], "lqr": evaluation(BALANCE)["lqr"]}  # a controller as the policy
    assert check_bars(results)[1].note == "the policy is gated itself"


def test_the_bars_table_has_a_row_per_bar_and_one_on_every_bar():
    meets, misses = evaluation(BALANCE), evaluation(BALANCE)
    misses["ppo"]["survival_rate"] = 0.97
    table = bars_table({"seed 0": check_bars(meets), "seed 1": check_bars(misses)})
    lines = table.splitlines()
    assert lines[0] == "| bar | seed 0 | seed 1 |" and len(lines) == 2 + len(b.BALANCE_BARS) + 1
    assert lines[2] == "| survival >= 98% | pass: 100% | **fail**: 97% |"
    assert lines[-1] == "| **every bar** | **yes** | no |"


def test_the_evaluation_table_ends_with_the_bars(tmp_path):
    """train.evaluate writes the policy's bars under its tables, with the numbers of its JSON."""
    from train.evaluate import EvalArgs, evaluate

    out = evaluate(EvalArgs(policy="gated", baseline=["lqr"], env_id=BALANCE, episodes=3, plot=False, out=tmp_path / "eval"))
    table = (out / "table.md").read_text()
    assert "Bars (`train.bars`): gated on these episodes" in table
    gated = json.loads((out / "gated.json").read_text())
    survival = "pass" if gated["survival_rate"] >= 0.98 else "**fail**"
    assert f"| survival >= 98% | {survival}: {100 * gated['survival_rate']:.0f}% |" in table
    assert "| mean return >= gated's | not measured (the policy is gated itself) |" in table
    stance = evaluate(EvalArgs(policy="lqr", episodes=2, plot=False, out=tmp_path / "stance"))
    assert "Bars" not in (stance / "table.md").read_text()  # the pinned foot has no bars
