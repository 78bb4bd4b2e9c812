"""Training and evaluation under failure: normalize:false end to end, missing or corrupt checkpoints,
a start that failed or was killed, two processes on one run folder, bad evaluation arguments."""

import json
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from train import evaluate as evaluate_cli
from train import ppo as ppo_cli
from train.evaluate import EvalArgs, evaluate, load_policy
from train.ppo import TrainArgs, train

ROOT = Path(__file__).resolve().parents[2]
TINY = ["n_envs:4", "n_steps:32", "batch_size:64", "n_epochs:1"]  # 128 env steps per PPO iteration
ITERATION = 128
NO_NORMALIZE = [*TINY, "normalize:false"]
CORRUPTIONS = {  # file of the newest checkpoint -> how it is damaged
    "vecnormalize.pkl": lambda path: path.write_bytes(b"\x80\x04garbage"),
    "rng.pkl": lambda path: path.write_bytes(path.read_bytes()[:40]),
    "progress.json": lambda path: path.write_text(path.read_text()[:25]),
    "model.zip": lambda path: path.write_bytes(path.read_bytes()[:300]),
}


def tiny_args(out: Path, **overrides) -> TrainArgs:
    kwargs = dict(
        out=out,
        params=list(TINY),
        total_timesteps=2 * ITERATION,
        eval_freq=ITERATION,
        eval_episodes=2,
        checkpoint_freq=ITERATION,
        progress_bar=False,
        verbose=0,
    )
    kwargs.update(overrides)
    return TrainArgs(**kwargs)


def train_command(out: Path, *options: str, params=TINY) -> list[str]:
    """``python -m train.ppo`` for a long run of ``tiny_args``'s configuration, without periodic saves."""
    return [sys.executable, "-m", "train.ppo", "--out", str(out), "--total-timesteps", "1000000", "--eval-freq", "0",
            "--checkpoint-freq", "0", "--eval-episodes", "2", "--no-progress-bar", "--verbose", "0",
            *options, "--params", *params]  # fmt: skip


def start_training(out: Path, params=TINY) -> subprocess.Popen:
    """Start ``train_command`` and return once it trains (a new TensorBoard log has appeared)."""
    logs_before = len(list((out / "tb").rglob("events.out.tfevents.*")))
    proc = subprocess.Popen(train_command(out, params=params), cwd=ROOT, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while len(list((out / "tb").rglob("events.out.tfevents.*"))) == logs_before:
        if proc.poll() is not None or time.time() > deadline:
            proc.kill()
            pytest.fail(f"training did not start: {proc.communicate()[1][-3000:]}")
        time.sleep(0.2)
    time.sleep(1.0)  # a few iterations
    return proc


def stop_with_a_checkpoint(proc: subprocess.Popen, how: int = signal.SIGTERM) -> str:
    """Send ``how`` to a training process and return its stderr, once it has exited as a stopped run does: status
    130, a checkpoint saved."""
    try:
        proc.send_signal(how)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert "checkpoint saved" in err
    return err


def steps_of(folder: Path) -> int:
    from stable_baselines3 import PPO

    return PPO.load(folder / "model.zip", device="cpu").num_timesteps


@pytest.fixture(autouse=True)
def keep_sigterm_handler():
    """``train.ppo.main`` turns SIGTERM into KeyboardInterrupt; undo that for the test process."""
    handler = signal.getsignal(signal.SIGTERM)
    yield
    signal.signal(signal.SIGTERM, handler)


@pytest.fixture(scope="module")
def two_checkpoints(tmp_path_factory) -> Path:
    """A finished 256-step run (normalising returns, as the default configuration does) with
    checkpoints at 128 and 256 steps."""
    run = train(tiny_args(tmp_path_factory.mktemp("base") / "run"))
    assert [p.name for p in sorted((run / "checkpoints").iterdir()) if p.is_dir()] == ["000000000128", "000000000256"]
    return run


@pytest.fixture
def run_copy(two_checkpoints, tmp_path) -> Path:
    out = tmp_path / "run"
    shutil.copytree(two_checkpoints, out)
    return out


# ---------------------------------------------------------------- item 1: normalize: false


def test_normalize_false_trains_checkpoints_resumes_and_evaluates(tmp_path):
    out = train(tiny_args(tmp_path / "run", params=NO_NORMALIZE))
    assert yaml.safe_load((out / "config.yaml").read_text())["normalize"] is False
    for folder in (out, out / "best", out / "last", *(out / "checkpoints").glob("0*")):
        assert (folder / "model.zip").is_file() and not (folder / "vecnormalize.pkl").exists(), folder
    train(tiny_args(out, params=NO_NORMALIZE, total_timesteps=3 * ITERATION))
    assert steps_of(out / "last") == 3 * ITERATION
    assert load_policy(out).vec_normalize is None
    result = evaluate(EvalArgs(policy=str(out), episodes=1, plot=False))
    assert json.loads((result / "policy.json").read_text())["episodes"] == 1


def test_normalize_false_sigterm_saves_a_checkpoint_and_resumes(tmp_path):
    out = tmp_path / "run"
    stop_with_a_checkpoint(start_training(out, params=NO_NORMALIZE))
    (checkpoint,) = (out / "checkpoints").glob("0*")
    assert not (checkpoint / "vecnormalize.pkl").exists()
    steps = json.loads((checkpoint / "progress.json").read_text())["num_timesteps"]
    assert steps > 0 and steps % ITERATION == 0  # the cut-short rollout is not counted
    train(tiny_args(out, params=NO_NORMALIZE, total_timesteps=steps + ITERATION, eval_freq=0, checkpoint_freq=0))
    assert steps_of(out) == steps + ITERATION


# ---------------------------------------------------------------- items 2 and 3: missing or corrupt checkpoint files


def test_checkpoint_without_its_statistics_is_not_resumed_without_normalisation(run_copy, capsys):
    missing = run_copy / "checkpoints" / "000000000256" / "vecnormalize.pkl"
    missing.unlink()
    with pytest.warns(UserWarning, match=re.escape(str(missing))):
        train(tiny_args(run_copy, total_timesteps=3 * ITERATION, verbose=1))
    assert f"from {ITERATION} steps" in capsys.readouterr().out  # the previous checkpoint
    assert (run_copy / "checkpoints" / "000000000256.corrupt").is_dir()
    for checkpoint in (run_copy / "checkpoints").glob("0*[0-9]"):
        assert (checkpoint / "vecnormalize.pkl").is_file(), checkpoint
    assert (run_copy / "last" / "vecnormalize.pkl").is_file() and steps_of(run_copy / "last") == 3 * ITERATION


def test_no_intact_checkpoint_is_an_error_naming_the_files(run_copy, capsys):
    for checkpoint in (run_copy / "checkpoints").glob("0*"):
        (checkpoint / "vecnormalize.pkl").unlink()
    args = ["--out", str(run_copy), "--total-timesteps", str(3 * ITERATION), "--eval-episodes", "2",
            "--no-progress-bar", "--verbose", "0", "--params", *TINY]  # fmt: skip
    with pytest.raises(SystemExit, match="no intact checkpoint") as raised:
        ppo_cli.main(args)
    for step in ("000000000128", "000000000256"):
        assert str(run_copy / "checkpoints" / step / "vecnormalize.pkl") in str(raised.value)
        assert (run_copy / "checkpoints" / step).is_dir()  # left for the user to look at
    with pytest.raises(ValueError, match="no intact checkpoint"):
        train(tiny_args(run_copy, total_timesteps=3 * ITERATION))


@pytest.mark.parametrize("name", sorted(CORRUPTIONS))
def test_corrupt_latest_checkpoint_resumes_from_the_previous_one(run_copy, name, capsys):
    corrupt = run_copy / "checkpoints" / "000000000256" / name
    CORRUPTIONS[name](corrupt)
    with pytest.warns(UserWarning, match=re.escape(str(corrupt))):
        train(tiny_args(run_copy, total_timesteps=3 * ITERATION, verbose=1))
    assert f"from {ITERATION} steps" in capsys.readouterr().out
    assert steps_of(run_copy / "last") == 3 * ITERATION
    assert sorted(p.name for p in (run_copy / "checkpoints").iterdir()) == [
        "000000000256",  # written again by the resumed run
        "000000000256.corrupt",
        "000000000384",
    ]


def test_leftovers_of_an_interrupted_save_are_removed(run_copy):
    (run_copy / "checkpoints" / ".000000000384.k2j4").mkdir()  # a checkpoint being written when killed
    (run_copy / ".model.zip.x7f.zip").write_bytes(b"partial")
    shutil.copytree(run_copy / "best", run_copy / ".best.old")  # killed between the two renames of a snapshot swap
    shutil.rmtree(run_copy / "best")
    train(tiny_args(run_copy, total_timesteps=3 * ITERATION))
    assert not [p for p in (run_copy / "checkpoints").iterdir() if p.name.startswith(".")]
    assert not [p for p in run_copy.iterdir() if p.name.startswith(".")]
    assert (run_copy / "best" / "model.zip").is_file()


def test_periodic_checkpoints_fall_between_iterations(tmp_path):
    out = train(tiny_args(tmp_path / "run", total_timesteps=3 * ITERATION, checkpoint_freq=100, eval_freq=0))
    checkpoints = sorted((out / "checkpoints").glob("0*"))
    assert checkpoints and all(int(p.name) % ITERATION == 0 for p in checkpoints), checkpoints
    for checkpoint in checkpoints:  # the model has learnt from every step it counts
        progress = json.loads((checkpoint / "progress.json").read_text())
        assert steps_of(checkpoint) == progress["num_timesteps"] == int(checkpoint.name)


# ---------------------------------------------------------------- item 4: a start that failed or was killed


def test_bad_training_arguments_are_argument_errors_and_create_nothing(tmp_path, capsys):
    for option, value in (("--eval-episodes", "0"), ("--eval-episodes", "-1"), ("--checkpoint-freq", "-5")):
        out = tmp_path / f"run{option}{value}"
        with pytest.raises(SystemExit) as raised:
            ppo_cli.main(["--out", str(out), "--total-timesteps", "256", option, value, "--params", *TINY])
        assert raised.value.code == 2
        assert option.lstrip("-").replace("-", "_") in capsys.readouterr().err
        assert not out.exists()


def test_run_killed_before_its_first_checkpoint_is_started_again(tmp_path, capsys):
    out = tmp_path / "run"
    proc = start_training(out)
    proc.kill()
    proc.communicate(timeout=60)
    assert not list((out / "checkpoints").glob("0*"))

    train(tiny_args(out))  # the configuration of that command
    err = capsys.readouterr().err
    assert "before its first checkpoint" in err
    assert f"{out / 'train.lock'} left by process {proc.pid}" in err  # the killed process's stale lock
    assert not (out / "train.lock").exists()
    assert steps_of(out / "last") == 2 * ITERATION
    assert len((out / "command.txt").read_text().splitlines()) == 2
    assert json.loads((out / "evaluations.json").read_text())["resumes"] == 0  # a fresh start, not a resume


def test_failed_start_of_another_configuration_is_not_replaced_silently(tmp_path):
    out = tmp_path / "run"
    with pytest.raises((TypeError, ValueError), match="no_such_argument"):  # after config.yaml, before a checkpoint
        train(tiny_args(out, params=[*TINY, "env_kwargs:{no_such_argument: 1}"]))
    with pytest.raises(ValueError, match="different configuration.*--overwrite"):
        train(tiny_args(out))
    assert (out / "config.yaml").is_file() and (out / "command.txt").is_file()
    train(tiny_args(out, overwrite=True))
    assert steps_of(out / "last") == 2 * ITERATION


# ---------------------------------------------------------------- item 15: two processes, one run folder


def test_second_process_on_a_run_folder_is_refused(run_copy):
    proc = start_training(run_copy)  # resumes the run and keeps training
    try:
        lock = run_copy / "train.lock"
        refusal = rf"process {proc.pid} .*{re.escape(str(lock))}"
        with pytest.raises(Exception, match=refusal):
            train(tiny_args(run_copy, total_timesteps=3 * ITERATION))
        with pytest.raises(SystemExit, match=refusal):
            ppo_cli.main(["--out", str(run_copy), "--no-progress-bar", "--params", *TINY])
        assert proc.poll() is None, "the first process must keep training"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert not lock.exists()
    steps = json.loads((run_copy / "evaluations.json").read_text())["total_timesteps"]  # untouched by the refused ones
    assert steps == 2 * ITERATION


# ---------------------------------------------------------------- items 10 and 11: evaluation arguments


@pytest.mark.parametrize("episodes", [0, -3])
def test_evaluate_needs_a_positive_episode_count(episodes, tmp_path, capsys):
    with pytest.raises(SystemExit) as raised:
        evaluate_cli.main(["lqr", "--episodes", str(episodes), "--out", str(tmp_path / "eval")])
    assert raised.value.code == 2
    assert "episodes must be >= 1" in capsys.readouterr().err
    assert not (tmp_path / "eval").exists()


def test_evaluate_missing_policy_folder_creates_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit, match="policy folder not found: runs/nope"):
        evaluate_cli.main(["runs/nope"])
    with pytest.raises(FileNotFoundError, match="policy folder not found"):
        evaluate(EvalArgs(policy="runs/nope", baseline="lqr"))
    assert not (tmp_path / "runs").exists()


def test_evaluate_takes_a_model_file(run_copy):
    out = evaluate(EvalArgs(policy=str(run_copy / "model.zip"), episodes=1))
    assert out == run_copy / "eval" and (out / "policy.json").is_file() and (out / "learning_curve.png").is_file()


def test_rllib_env_threads_and_its_old_name():
    """``--env-threads`` sets the threads of each runner's batch; ``--numba-threads``, its old name, is an error that
    names it (nothing was released); a count below 1 is refused by name."""
    from train.cli import parse_args
    from train.rllib import RLlibArgs

    assert RLlibArgs(env_threads=2).env_threads == 2
    with pytest.raises(TypeError):
        RLlibArgs(numba_threads=3)
    with pytest.raises(SystemExit):
        parse_args(RLlibArgs, ["--numba-threads", "3"])
    with pytest.raises(ValueError, match="env_threads"):
        RLlibArgs(env_threads=0)
