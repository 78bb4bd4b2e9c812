"""``train.falls``: a policy run as it is trained, and what its episodes are paid before they end."""

import json
from collections import deque

import numpy as np
import pytest
import torch

from leg_env import ENDINGS

from train.episodes import make_batch, policy_predict, run_batch
from train.falls import FallsArgs, audit, format_report, main, training_env_kwargs
from train.policy_loading import load_policy
from train.ppo import TrainArgs, train

SCHEDULE = "callback:[{train.callbacks.ConfigSchedule: {schedule: {drift_com_weight: [[128, 10.0], [256, 400.0]], alive_bonus: [[0, 1.0], [256, 3.0]]}}}]"


@pytest.fixture(scope="module")
def hop_run(tmp_path_factory):
    """A tiny hop run whose training env is scheduled (the drift charge and the alive bonus)."""
    out = tmp_path_factory.mktemp("falls") / "run"
    return train(TrainArgs(out=out, env_id="leg_env/PlanarLegHop-v4", total_timesteps=256, eval_freq=0, checkpoint_freq=0,
                           progress_bar=False, verbose=0,
                           params=["n_envs:4", "n_steps:32", "batch_size:64", "n_epochs:1", "env_kwargs:{height_weight: 4.0}", SCHEDULE]))  # fmt: skip


def test_the_training_env_is_the_runs_env_kwargs_with_each_schedule_at_the_step_asked():
    config = {
        "total_timesteps": 300,
        "env_kwargs": {"height_weight": 4.0, "alive_bonus": 5.0},
        "callback": [{"train.callbacks.DiscountSchedule": {"points": [[0, 0.99]]}},
                     {"train.callbacks.ConfigSchedule": {"schedule": {"drift_com_weight": [[100, 10.0], [200, 30.0]], "command_range": [[0, [0.02, 0.06]], [200, [0.06, 0.10]]]}}}],  # fmt: skip
    }
    assert training_env_kwargs(config) == {"height_weight": 4.0, "alive_bonus": 5.0, "drift_com_weight": 30.0, "command_range": (0.06, 0.10)}
    middle = training_env_kwargs(config, at_steps=150)
    assert middle["drift_com_weight"] == pytest.approx(20.0) and middle["command_range"] == pytest.approx((0.05, 0.09))
    assert training_env_kwargs({"env_kwargs": {"height_weight": 2.0}}, at_steps=10) == {"height_weight": 2.0}


def test_the_terms_sum_to_the_returns_of_the_evaluation_runner_and_the_window_averages_the_last_steps(hop_run):
    """With the policy's mean action the audit's episodes are ``train.episodes.run_batch``'s on the same env and
    seeds: each episode's terms sum to its return. A window longer than every episode averages the whole of it."""
    args = FallsArgs(policy=hop_run, training_env=True, episodes=6, seed=30_000, window=1000, sample=False)
    report = audit(args)
    assert report.env_kwargs == {"height_weight": 4.0, "drift_com_weight": 400.0, "alive_bonus": 3.0}
    batch = run_batch(policy_predict(load_policy(hop_run)), make_batch("leg_env/PlanarLegHop-v4", 6, report.env_kwargs), report.seeds)
    np.testing.assert_allclose(sum(report.terms.values()), batch.returns, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(report.lengths, batch.lengths)
    np.testing.assert_array_equal(report.survived, batch.survived)
    assert set(report.terms) == {f"reward_{k}" for k in ("alive", "height", "drift", "tilt", "impact", "slip", "ctrl", "limit", "action_rate", "power")}
    for key, values in report.terms.items():
        np.testing.assert_allclose(report.last[key], values / report.lengths, rtol=1e-12, atol=1e-15)
    assert report.last["reward_alive"][~report.survived].max() <= 3.0  # the scheduled bonus, 0 on the falling step
    groups = report.groups()
    assert sum(g["episodes"] for g in groups.values()) == 6 and "fell" in groups  # an untrained policy falls


def reference_audit(policy, env_id: str, env_kwargs: dict, seeds: list[int], window: int, sample: bool) -> dict:
    """The audit's figures from a loop of its own, stepping the batch and keeping each term's last ``window`` steps
    in a queue (the way ``train.falls`` computed them before it became a watcher of the episode runner)."""
    torch.manual_seed(seeds[0])
    n = len(seeds)
    envs = make_batch(env_id, n, env_kwargs)
    obs, _ = envs.reset(seed=seeds)
    keys = list(envs.unwrapped.reward_keys)
    done, starts = np.zeros(n, bool), np.ones(n, bool)
    lengths, survived, ends, in_flight = np.zeros(n, np.int64), np.zeros(n, bool), [None] * n, np.zeros(n, bool)
    terms, last = {key: np.zeros(n) for key in keys}, {key: np.zeros(n) for key in keys}
    recent = {key: deque(maxlen=window) for key in keys}
    while not done.all():
        actions, _ = policy.predict(obs, episode_start=starts, deterministic=not sample)
        obs, _, terminated, truncated, info = envs.step(np.asarray(actions, dtype=np.float64).reshape(n, -1))
        active = ~done
        for key in keys:
            value = np.where(active, np.asarray(info[key], dtype=np.float64), 0.0)
            terms[key] += value
            recent[key].append(value)
        lengths[active] += 1
        ended = (terminated | truncated) & active
        survived[ended] = truncated[ended] & ~terminated[ended]
        for key in keys:
            last[key][ended] = np.sum(recent[key], axis=0)[ended] / np.minimum(lengths[ended], window)
        for i in np.flatnonzero(ended & terminated):
            ends[i] = ENDINGS[info["ending"][i]]
            in_flight[i] = "contact_mode" in info and info["contact_mode"][i] == "flight"
        done |= ended
        starts = terminated | truncated
    envs.close()
    return {"survived": survived, "lengths": lengths, "terms": terms, "last": last, "ends": ends, "in_flight": in_flight}


@pytest.mark.parametrize("window, sample", [(5, True), (50, True), (20, False), (1000, True)])
def test_the_audit_gives_the_figures_of_a_loop_of_its_own_bit_for_bit(hop_run, window, sample):
    """``FallWatcher`` on the one episode runner gives, to the bit, each term's sum and last-window mean, survival,
    lengths and endings of a reference loop over the same episodes and drawn actions; windows shorter and longer
    than the episodes, which end at different steps when the actions are drawn (the untrained policy falls)."""
    args = FallsArgs(policy=hop_run, training_env=True, episodes=12, window=window, sample=sample)
    report = audit(args)
    ref = reference_audit(load_policy(hop_run), "leg_env/PlanarLegHop-v4", report.env_kwargs, report.seeds, window, sample)
    assert len(set(report.lengths.tolist())) > 3 or not sample, "the case needs episodes of different lengths"
    np.testing.assert_array_equal(report.survived, ref["survived"])
    np.testing.assert_array_equal(report.lengths, ref["lengths"])
    assert report.ends == ref["ends"]
    np.testing.assert_array_equal(report.in_flight, ref["in_flight"])
    for key in ref["terms"]:
        np.testing.assert_array_equal(report.terms[key], ref["terms"][key], err_msg=key)
        np.testing.assert_array_equal(report.last[key], ref["last"][key], err_msg=key)


def test_the_audit_runs_on_the_pinned_foot_where_nothing_flies(tmp_path):
    """A task without ``contact_mode`` in its info (the pinned foot): every fall is in contact."""
    out = train(TrainArgs(out=tmp_path / "run", total_timesteps=128, eval_freq=0, checkpoint_freq=0, progress_bar=False,
                          verbose=0, params=["n_envs:4", "n_steps:32", "batch_size:64", "n_epochs:1"]))  # fmt: skip
    report = audit(FallsArgs(policy=out, episodes=6, window=10))
    assert report.env_id == "leg_env/PlanarLegStance-v0" and not report.in_flight.any()
    assert all(row["in flight"] == 0 for row in report.ends_table().values())


def test_sampled_actions_repeat_with_the_seed_and_differ_from_the_mean(hop_run):
    first, again = (audit(FallsArgs(policy=hop_run, episodes=4, window=5)) for _ in range(2))
    mean = audit(FallsArgs(policy=hop_run, episodes=4, window=5, sample=False))
    for key in first.terms:
        np.testing.assert_array_equal(first.terms[key], again.terms[key])
    assert any(not np.array_equal(first.terms[k], mean.terms[k]) for k in first.terms)
    assert first.env_kwargs == {}  # without --training-env: the task as registered


def test_the_command_prints_the_table_and_writes_the_json(hop_run, tmp_path, capsys):
    main([str(hop_run / "last"), "--training-env", "--at-steps", "128", "--episodes", "3", "--window", "10",
          "--env-kwargs", "tilt_weight:2.0", "--out", str(tmp_path / "falls.json")])  # fmt: skip
    printed = capsys.readouterr().out
    assert "| last 10 steps, per step |" in printed and "| fell |" in printed
    saved = json.loads((tmp_path / "falls.json").read_text())
    assert saved["env_kwargs"] == {"height_weight": 4.0, "drift_com_weight": 10.0, "alive_bonus": 2.0, "tilt_weight": 2.0}
    assert saved["seeds"] == [30_000, 30_002] and saved["last_steps"]["fell"]["episodes"] + saved["last_steps"].get("survived", {}).get("episodes", 0) == 3
    assert format_report(audit(FallsArgs(policy=hop_run, episodes=2))).count("\n") > 5


@pytest.mark.parametrize("argv, message", [
    (["--at-steps", "5"], "needs --training-env"),
    (["--episodes", "0"], "episodes must be >= 1"),
    (["--window", "0"], "window must be >= 1"),
    (["--env-kwargs", "nonsense"], "env_kwargs"),
])  # fmt: skip
def test_bad_arguments_exit_with_the_field_named(hop_run, argv, message, capsys):
    with pytest.raises(SystemExit) as stop:
        main([str(hop_run), *argv])
    assert stop.value.code == 2 and message in capsys.readouterr().err


def test_a_missing_policy_names_the_folder(tmp_path):
    from train.policy_loading import PolicyNotFoundError

    with pytest.raises(PolicyNotFoundError, match="nowhere"):
        audit(FallsArgs(policy=tmp_path / "nowhere"))
    with pytest.raises(SystemExit, match="python -m train.falls: error: policy folder not found: .*nowhere"):
        main([str(tmp_path / "nowhere")])


def test_each_fall_is_named_by_the_tasks_ending_and_survivors_by_none(hop_run):
    """Each fall is named as the task's ``info["ending"]`` names it (tests/test_endings.py holds those names to the
    state), a survivor by None, and the table counts every fall once."""
    from leg_env import ENDINGS

    report = audit(FallsArgs(policy=hop_run, episodes=6, window=5))
    for end, survived in zip(report.ends, report.survived):
        assert (end is None) == bool(survived) and (end is None or end in ENDINGS[1:])
    table = report.ends_table()
    assert sum(sum(row.values()) for row in table.values()) == int((~report.survived).sum())
    assert "| how the falls ended |" in format_report(report)
