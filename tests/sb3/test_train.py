"""Training smoke tests: train() in-process, reload through the evaluation loader, resume, errors, the Zoo."""

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from stable_baselines3.common.callbacks import BaseCallback

from test_train_hardening import stop_with_a_checkpoint
from train.evaluate import EvalArgs, PolicyLoadError, evaluate, load_policy, run_episodes
from train.ppo import ENV_ID, TrainArgs, resolve_config, train

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "policies" / "ppo_stance"
TINY = ["n_envs:4", "n_steps:32", "batch_size:64", "n_epochs:1"]  # 128 env steps per PPO iteration
STEPS = 256
EVAL_SEEDS = (10_000, 10_001, 10_002)


def tiny_args(out: Path, **overrides) -> TrainArgs:
    kwargs = dict(
        out=out,
        params=list(TINY),
        total_timesteps=STEPS,
        eval_freq=128,
        eval_episodes=2,
        checkpoint_freq=128,
        progress_bar=False,
        verbose=0,
    )
    kwargs.update(overrides)
    return TrainArgs(**kwargs)


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    return train(tiny_args(tmp_path_factory.mktemp("train") / "run"))


def test_run_folder_has_everything(run):
    for name in ("model.zip", "vecnormalize.pkl", "config.yaml", "command.txt", "evaluations.json", "learning_curve.png"):
        assert (run / name).is_file(), name
    config = yaml.safe_load((run / "config.yaml").read_text())
    assert config["env_id"] == ENV_ID and config["n_envs"] == 4 and config["ppo"]["n_steps"] == 32
    assert config["eval_env_kwargs"] == {}  # evaluation on the registered task, whatever the training shaping
    evaluations = json.loads((run / "evaluations.json").read_text())
    assert evaluations["total_timesteps"] == STEPS
    assert [e["timesteps"] for e in evaluations["evaluations"]] == [128, 256]
    assert all(len(e["returns"]) == 2 for e in evaluations["evaluations"])
    assert all(e["motion"]["episodes"] == 2 and e["motion"]["tilt_rms"] > 0 for e in evaluations["evaluations"])  # how it moved
    assert list((run / "tb").iterdir()), "no TensorBoard log"
    # the shipped model is the best evaluated one; the last one is kept next to it
    selected = evaluations["selected"]
    best = max(evaluations["evaluations"], key=lambda e: (e["survival_rate"], e["mean_return"]))
    assert selected["from"] == "best" and selected["mean_return"] == best["mean_return"]
    assert (run / "model.zip").read_bytes() == (run / "best" / "model.zip").read_bytes()
    assert json.loads((run / "last" / "info.json").read_text())["timesteps"] == STEPS
    # the shipped model names no path of the machine that trained it (SB3 would store its TensorBoard folder)
    with zipfile.ZipFile(run / "model.zip") as archive:
        data = archive.read("data").decode()
    assert str(run.parent) not in data and "tensorboard_log" not in data


def test_reward_terms_and_violation_rates_reach_tensorboard(run):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    logs = [p for p in (run / "tb").rglob("events.out.tfevents.*")]
    tags = set()
    for log in logs:
        acc = EventAccumulator(str(log))
        acc.Reload()
        tags |= set(acc.Tags()["scalars"])
    for term in ("alive", "drift", "unilateral", "friction", "ctrl"):
        assert f"rollout/reward_{term}" in tags
    assert {"rollout/unilateral_violation_rate", "rollout/friction_violation_rate", "eval/mean_return"} <= tags


def test_result_reloads_through_the_evaluation_loader(run):
    policy = load_policy(run)
    obs = np.zeros(12, dtype=np.float32)
    action, _ = policy.predict(obs)
    assert action.shape == (2,) and np.all(np.abs(action) <= 1.0)
    assert policy.predict(np.zeros((5, 12), dtype=np.float32))[0].shape == (5, 2)
    summary, series = run_episodes(policy, EVAL_SEEDS[:1], record=0)
    assert summary["episodes"] == 1 and 1 <= summary["mean_length"] <= 1000
    assert series["torque"].shape == (summary["steps"], 2)


def test_evaluate_command_writes_the_comparison(run, tmp_path, capsys):
    out = evaluate(EvalArgs(policy=str(run), baseline="lqr", episodes=2, out=tmp_path / "eval", gif=True))
    for name in ("policy.json", "lqr.json", "table.md", "timeseries.png", "motion.png", "learning_curve.png", "episode.gif"):
        assert (out / name).is_file(), name
    lqr = json.loads((out / "lqr.json").read_text())
    assert lqr["seeds"] == [10_000, 10_001] and lqr["survival_rate"] == 1.0
    assert lqr["motion"]["episodes"] == 2 and set(lqr["both_survived"]) == {"run"}
    printed = capsys.readouterr().out
    assert "| survival rate |" in printed and "| torso tilt RMS [deg] |" in printed


def test_evaluate_takes_several_baselines(run, tmp_path):
    """--baseline takes several controllers, each evaluated on the same seeds and written to its own file: a
    model-based controller by its name, a folder as baseline.json (the policy itself here, so its scores must
    equal the policy's)."""
    from train.cli import parse_args

    args = parse_args(EvalArgs, [str(run), "--baseline", "lqr", str(run), "--episodes", "2", "--out", str(tmp_path / "eval")], positional=("policy",))
    assert args.baseline == ["lqr", str(run)]
    args.plot = False
    out = evaluate(args)
    policy, lqr, again = (json.loads((out / f"{name}.json").read_text()) for name in ("policy", "lqr", "baseline"))
    assert lqr["controller"] == "lqr" and again["controller"] == str(run)
    assert [e["return"] for e in again["per_episode"]] == [e["return"] for e in policy["per_episode"]]
    header = next(line for line in (out / "table.md").read_text().splitlines() if line.startswith("| metric"))
    assert header.count("|") == 5, header  # metric + three controllers
    assert EvalArgs(baseline="lqr").baseline == ["lqr"] and EvalArgs().baseline == []


def test_evaluate_env_kwargs_replace_the_runs_own(tmp_path):
    """--env-kwargs sets the evaluation env in place of the run's eval_env_kwargs (a push policy trained on
    randomised robots evaluated on the nominal one, say); a malformed item is a ValueError naming the field."""
    from train.cli import parse_args

    args = parse_args(EvalArgs, ["lqr", "--env-id", "leg_env/PlanarLegPush-v2", "--env-kwargs", "push_force:[34.0, 34.0]", "reset_noise_scale:0.0",
                                 "--episodes", "2", "--no-plot", "--out", str(tmp_path / "eval")], positional=("policy",))
    out = evaluate(args)
    lqr = json.loads((out / "lqr.json").read_text())
    assert lqr["env_kwargs"] == {"push_force": [34.0, 34.0], "reset_noise_scale": 0.0}
    with pytest.raises(ValueError, match="env_kwargs"):
        EvalArgs(env_kwargs=["push_force"])


def test_evaluate_on_held_out_robots_lists_every_robot(tmp_path):
    """--randomize: each episode's robot is drawn by its seed (the same robot for every controller), and
    robots.md lists them with each controller's survival and return."""
    out = evaluate(EvalArgs(policy="lqr", baseline="lqr", episodes=3, out=tmp_path / "eval", plot=False, randomize=True))
    lqr = json.loads((out / "lqr.json").read_text())
    robots = [e["robot"] for e in lqr["per_episode"]]
    assert len({r["m_b"] for r in robots}) == 3 and all(8.0 <= r["m_b"] <= 12.0 for r in robots)
    head, _, table = (out / "robots.md").read_text().partition("\n\n")
    table = table.splitlines()
    assert head.startswith("Measured ") and len(table) == 2 + 3 + 1
    assert table[2].startswith("| 10000 | ") and f"{robots[0]['m_b']:.3g}" in table[2]
    assert lqr["env_kwargs"] == {"randomize": True}


@pytest.mark.parametrize("module", ["train.ppo", "train.evaluate", "train.rllib", "train.falls"])
def test_every_command_prints_its_help(module):
    """Every field's docstring is a help text (a '%' in one once made argparse crash on --help)."""
    done = subprocess.run([sys.executable, "-m", module, "--help"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "usage:" in done.stdout


def test_resume_continues_the_step_counter(tmp_path):
    out = tmp_path / "run"
    train(tiny_args(out))
    first = json.loads((out / "evaluations.json").read_text())["evaluations"]
    train(tiny_args(out, total_timesteps=2 * STEPS))

    from stable_baselines3 import PPO

    assert PPO.load(out / "last" / "model.zip", device="cpu").num_timesteps == 2 * STEPS
    record = json.loads((out / "evaluations.json").read_text())
    assert record["resumes"] == 1
    history = record["evaluations"]
    assert [e["timesteps"] for e in history] == [128, 256, 384, 512]
    assert history[:2] == first  # the first invocation's evaluations are kept, not redone
    commands = (out / "command.txt").read_text().splitlines()
    assert len(commands) == 2
    # a command anyone can run: the interpreter is "python", not this machine's path to it
    assert all(c.split()[0] == "python" for c in commands) and sys.executable not in "".join(commands)
    assert yaml.safe_load((out / "config.yaml").read_text())["total_timesteps"] == 2 * STEPS


def test_existing_run_is_not_overwritten(tmp_path):
    out = tmp_path / "run"
    train(tiny_args(out))
    with pytest.raises(ValueError, match="different configuration"):
        train(tiny_args(out, seed=1))
    with pytest.raises(FileExistsError, match="--overwrite"):
        train(tiny_args(out, resume=False))
    train(tiny_args(out, seed=1, overwrite=True))
    assert yaml.safe_load((out / "config.yaml").read_text())["seed"] == 1


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_saves_a_checkpoint_and_the_run_resumes(tmp_path):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "train.ppo", "--out", str(out), "--total-timesteps", "1000000", "--eval-freq", "0",
           "--checkpoint-freq", "0", "--no-progress-bar", "--verbose", "0", "--params", *TINY]  # fmt: skip
    # a Ctrl-C at a terminal: SIGINT at its default action in the child, even when this suite runs as a
    # background job (a shell starts those with SIGINT ignored, and Python then installs no handler)
    proc = subprocess.Popen(cmd, cwd=ROOT, stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint)
    deadline = time.time() + 120
    while not list((out / "tb").rglob("events.out.tfevents.*")) and time.time() < deadline:
        time.sleep(0.2)
    time.sleep(3.0)  # let it train a few iterations
    stop_with_a_checkpoint(proc, signal.SIGINT)
    progress = json.loads(next((out / "checkpoints").glob("0*/progress.json")).read_text())
    assert progress["num_timesteps"] > 0
    target = progress["num_timesteps"] + 128
    train(tiny_args(out, total_timesteps=target, eval_freq=0, checkpoint_freq=0))
    from stable_baselines3 import PPO

    assert PPO.load(out / "last" / "model.zip", device="cpu").num_timesteps >= target


def test_missing_or_corrupt_files_name_the_file(run, tmp_path):
    broken = tmp_path / "broken"
    shutil.copytree(run, broken)
    (broken / "model.zip").unlink()
    with pytest.raises(FileNotFoundError, match=str(broken / "model.zip")):
        load_policy(broken)
    (broken / "model.zip").write_bytes(b"this is not a zip archive")
    with pytest.raises(PolicyLoadError, match=str(broken / "model.zip")):
        load_policy(broken)
    shutil.copy(run / "model.zip", broken / "model.zip")
    (broken / "vecnormalize.pkl").write_bytes(b"\x80\x04garbage")
    with pytest.raises(PolicyLoadError, match=str(broken / "vecnormalize.pkl")):
        load_policy(broken)
    (broken / "vecnormalize.pkl").unlink()
    with pytest.raises(FileNotFoundError, match=str(broken / "vecnormalize.pkl")):
        load_policy(broken)
    with pytest.raises(FileNotFoundError, match="nowhere"):
        load_policy(tmp_path / "nowhere")


def test_shipped_policy_survives():
    policy = load_policy(SHIPPED)
    summary, _ = run_episodes(policy, EVAL_SEEDS)
    assert summary["survival_rate"] == 1.0
    assert summary["unilateral_violation_frac"] == 0.0


def test_zoo_trains_the_env_from_the_same_file(tmp_path):
    cmd = [sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", ENV_ID, "--gym-packages", "leg_env",
           "--conf-file", "train/hyperparams/ppo.yml", "--n-timesteps", "2000", "--num-threads", "1",
           "--log-folder", str(tmp_path), "--seed", "0"]  # fmt: skip
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    result = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-4000:]
    assert list(tmp_path.rglob("*.zip")), "the Zoo saved no model"


RLLIB_FILES = ("leg_env/rllib.py", "train/rllib.py")
"""The RLlib path, whose imports come from the ``rllib`` extra (``ray`` is in no other)."""


@pytest.mark.parametrize("extra", ["train", "rllib"])
def test_extras_declare_every_package_that_training_and_evaluation_import(extra):
    """``make train`` installs only the core and the ``train`` extra: every third-party module that
    ``leg_env``, ``train/`` and ``policies/`` import must come from a distribution declared there;
    the files of the RLlib path likewise from the core and the ``rllib`` extra."""
    import ast
    import re
    import tomllib
    from importlib.metadata import packages_distributions

    def norm(name: str) -> str:
        return re.sub(r"[-_.]+", "-", name).lower()

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    todo = [extra]
    requirements = list(project["dependencies"])
    while todo:  # the extra and the extras it pulls in (leg-env[render], ...)
        for req in extras[todo.pop()]:
            self_ref = re.fullmatch(r"leg-env\[([\w,\s-]+)\]", req)
            if self_ref:
                todo += [e.strip() for e in self_ref.group(1).split(",")]
            else:
                requirements.append(req)
    declared = {norm(re.match(r"[A-Za-z0-9_.-]+", r).group(0)) for r in requirements}

    if extra == "rllib":
        paths = [ROOT / name for name in RLLIB_FILES]
    else:
        paths = [p for folder in ("leg_env", "train", "policies") for p in (ROOT / folder).rglob("*.py")]
        paths = [p for p in paths if str(p.relative_to(ROOT)) not in RLLIB_FILES]
    modules = set()
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                modules |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules.add(node.module.split(".")[0])
    third_party = modules - set(sys.stdlib_module_names) - {"leg_env", "train", "policies"}
    expected = {"ray", "torch", "yaml", "gymnasium"} if extra == "rllib" else {"numpy", "gymnasium", "stable_baselines3", "scipy", "yaml"}
    assert expected <= third_party  # the walk works
    providers = packages_distributions()
    missing = sorted(m for m in third_party if not {norm(d) for d in providers.get(m, [m])} & declared)
    assert not missing, f"imported but not declared in the core or {extra} dependencies: {missing}"


def test_torch_threads_apply_to_the_run_and_are_restored(tmp_path):
    import torch

    before = torch.get_num_threads()
    out = train(tiny_args(tmp_path / "run", torch_threads=2, eval_freq=0, checkpoint_freq=0, total_timesteps=128))
    assert json.loads((out / "evaluations.json").read_text())["machine"]["torch_threads"] == 2
    assert torch.get_num_threads() == before
    with pytest.raises(ValueError, match="torch_threads"):
        tiny_args(tmp_path / "bad", torch_threads=0)


@pytest.mark.parametrize("native", [True, False])
def test_update_precision_defaults_to_float32_auto_follows_the_cpu_and_it_is_recorded(tmp_path, monkeypatch, native):
    import train.ppo as ppo

    monkeypatch.setattr(ppo, "native_bfloat16", lambda: native)
    expected = "bfloat16" if native else "float32"
    assert resolve_config(tiny_args(tmp_path / "a"))["update_precision"] == "float32"  # the default, SB3's
    assert resolve_config(tiny_args(tmp_path / "d", update_precision="auto"))["update_precision"] == expected
    assert resolve_config(tiny_args(tmp_path / "b", update_precision="float32"))["update_precision"] == "float32"
    assert resolve_config(tiny_args(tmp_path / "c", update_precision="bfloat16"))["update_precision"] == "bfloat16"
    with pytest.raises(ValueError, match="update_precision"):
        tiny_args(tmp_path / "bad", update_precision="float16")


@pytest.mark.parametrize("native", [True, False])
def test_a_bfloat16_update_on_a_cpu_that_would_emulate_it_says_so(tmp_path, monkeypatch, capsys, native):
    import train.ppo as ppo

    monkeypatch.setattr(ppo, "native_bfloat16", lambda: native)
    train(tiny_args(tmp_path / "bf16", update_precision="bfloat16", eval_freq=0, checkpoint_freq=0, total_timesteps=128))
    assert (ppo.EMULATED_BFLOAT16 in capsys.readouterr().err) is not native
    train(tiny_args(tmp_path / "f32", update_precision="float32", eval_freq=0, checkpoint_freq=0, total_timesteps=128))
    assert ppo.EMULATED_BFLOAT16 not in capsys.readouterr().err


def test_update_precision_reaches_the_model_and_a_resume_takes_its_own(tmp_path):
    from train.checkpoints import load_checkpoint
    from train.chunked_ppo import ChunkedPPO

    out = train(tiny_args(tmp_path / "run", update_precision="bfloat16", eval_freq=0, total_timesteps=128))
    assert yaml.safe_load((out / "config.yaml").read_text())["update_precision"] == "bfloat16"
    assert load_checkpoint(out / "checkpoints", normalize=True, algo=ChunkedPPO).model.update_precision == "bfloat16"
    out = train(tiny_args(tmp_path / "run", update_precision="float32", eval_freq=0, total_timesteps=256))  # resumed
    assert yaml.safe_load((out / "config.yaml").read_text())["update_precision"] == "float32"
    assert load_checkpoint(out / "checkpoints", normalize=True, algo=ChunkedPPO).model.update_precision == "float32"


def test_tanh_choice_reaches_the_model_and_a_resume_takes_its_own(tmp_path):
    from train.chunked_ppo import ChunkedPPO, FastTanh
    from train.checkpoints import load_checkpoint

    assert resolve_config(tiny_args(tmp_path / "a"))["tanh"] == "fast"  # the default
    out = train(tiny_args(tmp_path / "run", tanh="torch", eval_freq=0, total_timesteps=128))
    assert yaml.safe_load((out / "config.yaml").read_text())["tanh"] == "torch"
    model = load_checkpoint(out / "checkpoints", normalize=True, algo=ChunkedPPO).model
    assert model.tanh == "torch" and not any(isinstance(m, FastTanh) for m in model.policy.modules())
    out = train(tiny_args(tmp_path / "run", tanh="fast", eval_freq=0, total_timesteps=256))  # resumed
    assert yaml.safe_load((out / "config.yaml").read_text())["tanh"] == "fast"
    model = load_checkpoint(out / "checkpoints", normalize=True, algo=ChunkedPPO).model
    assert model.tanh == "fast" and any(type(m) is FastTanh for m in model.policy.modules())
    with pytest.raises(ValueError, match="tanh"):
        tiny_args(tmp_path / "bad", tanh="sigmoid")


def test_select_after_leaves_the_earlier_evaluations_out_of_the_selection(tmp_path):
    out = train(tiny_args(tmp_path / "run", total_timesteps=384, select_after=256))
    assert yaml.safe_load((out / "config.yaml").read_text())["select_after"] == 256
    evaluations = json.loads((out / "evaluations.json").read_text())
    assert [e["timesteps"] for e in evaluations["evaluations"]] == [128, 256, 384]
    late = [e for e in evaluations["evaluations"] if e["timesteps"] >= 256]
    best = max(late, key=lambda e: (e["survival_rate"], e["mean_return"]))
    selected = evaluations["selected"]
    assert selected["from"] == "best" and selected["timesteps"] == best["timesteps"] >= 256
    assert (out / "model.zip").read_bytes() == (out / "best" / "model.zip").read_bytes()
    # nothing evaluated after select_after: the last policy is shipped
    out = train(tiny_args(tmp_path / "late", select_after=1000))
    assert json.loads((out / "evaluations.json").read_text())["selected"]["from"] == "last"
    assert (out / "model.zip").read_bytes() == (out / "last" / "model.zip").read_bytes()


@pytest.mark.parametrize("value", [-1, 1.5, "soon", True])
def test_a_bad_select_after_is_a_value_error_naming_it(tmp_path, value):
    with pytest.raises(ValueError, match="select_after"):
        tiny_args(tmp_path / "bad", select_after=value)


def test_each_evaluation_line_prints_the_training_rate(tmp_path, capsys):
    train(tiny_args(tmp_path / "run", verbose=1, checkpoint_freq=0))
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("[")]
    assert len(lines) == 2  # an evaluation at 128 steps and one at the end, 256
    for line in lines:
        rate = line.split(" min, ", 1)[1].split(" steps/s]", 1)[0]
        assert float(rate.replace(",", "")) > 0.0, line


CURRICULUM = "callback:[{train.callbacks.ConfigSchedule: {schedule: {command_range: [[64, [0.02, 0.03]], [192, [0.1, 0.15]]]}}}]"


def test_config_schedule_holds_its_ends_and_is_linear_between():
    from train.callbacks import ConfigSchedule

    schedule = ConfigSchedule({"command_range": [[100, [0.02, 0.06]], [300, [0.05, 0.15]]], "alive_bonus": [[0, 3.0], [1000, 1.0]]})
    assert schedule.values_at(0) == {"command_range": (0.02, 0.06), "alive_bonus": 3.0}
    assert schedule.values_at(200)["command_range"] == pytest.approx((0.035, 0.105))
    assert schedule.values_at(500) == {"command_range": (0.05, 0.15), "alive_bonus": 2.0}
    assert schedule.values_at(10**9) == {"command_range": (0.05, 0.15), "alive_bonus": 1.0}


@pytest.mark.parametrize(
    "schedule",
    [{}, None, {"alive_bonus": []}, {"alive_bonus": [[10, 1.0], [5, 2.0]]}, {"alive_bonus": [[0, float("nan")]]},
     {"alive_bonus": [[-1, 1.0]]}, {"command_range": [[0, [0.1, 0.2]], [5, 0.3]]}, {"alive_bonus": [3.0]}, {"alive_bonus": 3.0}],
)  # fmt: skip
def test_bad_schedules_are_value_errors(schedule):
    from train.callbacks import ConfigSchedule

    with pytest.raises(ValueError, match="ConfigSchedule"):
        ConfigSchedule(schedule)


def test_a_discount_schedule_sets_the_returns_discount_of_each_rollout():
    """DiscountSchedule under PPO: each rollout's returns and advantages are discounted by the schedule's value at its
    start (the rollout buffer's gamma, which computes them, and the model's), from the first rollout on; a bad
    schedule is a ValueError naming the discount."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback

    from leg_env.sb3 import make_sb3_vec_env
    from train.callbacks import DiscountSchedule

    schedule = DiscountSchedule([[512, 0.99], [1536, 0.95]])
    assert schedule.value_at(0) == 0.99 and schedule.value_at(1024) == pytest.approx(0.97) and schedule.value_at(10**9) == 0.95
    seen = []

    class Watch(BaseCallback):
        def _on_rollout_end(self) -> None:
            seen.append((self.num_timesteps, self.model.gamma, self.model.rollout_buffer.gamma))

        def _on_step(self) -> bool:
            return True

    model = PPO("MlpPolicy", make_sb3_vec_env(4, seed=0), n_steps=64, batch_size=256, n_epochs=1, gamma=0.5, device="cpu", seed=0)
    model.learn(2048, callback=[schedule, Watch()])
    assert len(seen) == 8
    for steps, gamma, buffer_gamma in seen:
        assert gamma == buffer_gamma == pytest.approx(schedule.value_at(steps - 256)), steps  # the rollout's start
    assert seen[0][1] == 0.99 and seen[-1][1] == 0.95
    for bad in ([], [[0, 1.5]], [[0, 0.0]], [[10, 0.99], [5, 0.9]], [[0, [0.9, 0.99]]], "0.99"):
        with pytest.raises(ValueError, match="gamma"):
            DiscountSchedule(bad)


def test_a_learning_rate_schedule_sets_the_rate_of_each_update_and_survives_a_save():
    """LearningRateSchedule under PPO: every update's optimiser runs at the schedule's value at its rollout's start,
    from the first rollout on (whatever ``learning_rate`` says); a saved model saves, and a loaded one (which SB3 gives
    the schedule of its ``learning_rate``) gets the schedule's value at its steps from ``start_on``, as a resumed run
    does; a bad schedule is a ValueError naming the learning rate."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback

    from leg_env.sb3 import make_sb3_vec_env
    from train.callbacks import LearningRateSchedule

    schedule = LearningRateSchedule([[512, 1e-3], [1536, 1e-4]])
    assert schedule.value_at(0) == 1e-3 and schedule.value_at(1024) == pytest.approx(5.5e-4) and schedule.value_at(10**9) == 1e-4
    seen = []

    class Watch(BaseCallback):
        def _on_rollout_end(self) -> None:
            seen.append(self.num_timesteps)

        def _on_step(self) -> bool:
            return True

    rates = []

    class Recording(PPO):
        def train(self) -> None:
            super().train()
            rates.append([group["lr"] for group in self.policy.optimizer.param_groups])

    model = Recording("MlpPolicy", make_sb3_vec_env(4, seed=0), n_steps=64, batch_size=256, n_epochs=1, learning_rate=0.5,
                      device="cpu", seed=0)
    model.learn(2048, callback=[schedule, Watch()])
    assert len(rates) == len(seen) == 8
    for steps, groups in zip(seen, rates):
        assert groups == [pytest.approx(schedule.value_at(steps - 256))] * len(groups), steps  # the rollout's start
    assert rates[0][0] == 1e-3 and rates[-1][0] == pytest.approx(1e-4)
    with tempfile.TemporaryDirectory() as tmp:
        model.save(Path(tmp) / "model")
        loaded = PPO.load(Path(tmp) / "model", device="cpu")
    schedule.start_on(None, loaded)
    assert loaded.num_timesteps == 2048 and loaded.lr_schedule(1.0) == pytest.approx(1e-4)
    for bad in ([], [[0, -1e-4]], [[0, 0.0]], [[10, 1e-4], [5, 1e-5]], [[0, [1e-4, 1e-5]]], "1e-4"):
        with pytest.raises(ValueError, match="learning rate"):
            LearningRateSchedule(bad)


def test_a_noise_floor_holds_up_the_policys_noise_at_every_rollout():
    """NoiseFloor under PPO: every rollout starts with each entry of the policy's log_std at least the log of the
    schedule's value at its start (the entries above it untouched), where without the floor the learnt noise falls
    below it; a policy without a log_std, or a bad schedule, is a ValueError naming the floor."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback

    from leg_env.sb3 import make_sb3_vec_env
    from train.callbacks import NoiseFloor

    floor = NoiseFloor([[512, 0.4], [1536, 0.3]])
    assert floor.value_at(0) == 0.4 and floor.value_at(1024) == pytest.approx(0.35) and floor.value_at(10**9) == 0.3

    def run(callbacks):
        starts = []

        class Watch(BaseCallback):
            def _on_rollout_start(self) -> None:
                starts.append((self.num_timesteps, self.model.policy.log_std.detach().clone()))

            def _on_step(self) -> bool:
                return True

        # ent_coef < 0 rewards a narrower policy: its log_std falls at every update, fast
        model = PPO("MlpPolicy", make_sb3_vec_env(4, seed=0), n_steps=64, batch_size=256, n_epochs=4, learning_rate=3e-2,
                    ent_coef=-1.0, policy_kwargs={"log_std_init": np.log(0.5)}, device="cpu", seed=0)
        with torch.no_grad():
            model.policy.log_std[0] = np.log(2.0)  # one entry far above the floor
        model.learn(2048, callback=[*callbacks, Watch()])
        return starts

    free, held = run([]), run([floor])
    assert len(held) == len(free) == 8
    assert float(free[-1][1][1:].exp().max()) < 0.3  # without the floor the noise falls below it
    for steps, log_std in held:
        assert float(log_std[1:].exp().min()) >= floor.value_at(steps) * (1 - 1e-6), steps
        assert float(log_std[0].exp()) > floor.value_at(steps), steps
    assert any(float(log_std[1:].exp().min()) == pytest.approx(floor.value_at(steps)) for steps, log_std in held)  # it binds

    model = PPO("MlpPolicy", make_sb3_vec_env(2, seed=0), n_steps=8, batch_size=16, device="cpu", seed=0)
    del model.policy.log_std
    with pytest.raises(ValueError, match="NoiseFloor"):
        NoiseFloor([[0, 0.1]]).start_on(None, model)
    for bad in ([], [[0, -0.1]], [[0, 0.0]], [[10, 0.1], [5, 0.2]], [[0, [0.1, 0.2]]], "0.1"):
        with pytest.raises(ValueError, match="noise floor"):
            NoiseFloor(bad)


def test_zoo_callback_entries():
    from train.callbacks import ConfigSchedule, FrozenActor, zoo_callbacks

    assert zoo_callbacks(None) == []
    (one,) = zoo_callbacks({"train.callbacks.ConfigSchedule": {"schedule": {"alive_bonus": [[0, 2.0]]}}})
    assert isinstance(one, ConfigSchedule) and one.values_at(5) == {"alive_bonus": 2.0}
    two = zoo_callbacks([{"train.callbacks.FrozenActor": {"until": 10}}, {"train.callbacks.ConfigSchedule": {"schedule": {"mu": [[0, 0.5]]}}}])
    assert [type(c) for c in two] == [FrozenActor, ConfigSchedule]
    for bad, match in [("no_such_module.Thing", "cannot import"), ("train.callbacks.zoo_callbacks", "not an SB3 callback"),
                       ("json.JSONDecoder", "not an SB3 callback"), ([{"a": 1, "b": 2}], "each entry"), (5, "each entry")]:  # fmt: skip
        with pytest.raises(ValueError, match=match):
            zoo_callbacks(bad)


def test_a_curriculum_moves_the_commands_of_the_training_episodes():
    """ConfigSchedule under SB3's PPO: every episode starts under the schedule's value of the moment, from the
    first reset on (train.ppo sets it before learn), and the evaluation env is left as built."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback

    from leg_env.sb3 import make_sb3_vec_env
    from leg_env.tasks.base import Obs
    from train.callbacks import ConfigSchedule

    venv = make_sb3_vec_env(16, seed=0, env_id="leg_env/PlanarLegHop-v4", per_env_info=False, command_range=[0.02, 0.15])
    other = make_sb3_vec_env(4, seed=0, env_id="leg_env/PlanarLegHop-v4", command_range=[0.02, 0.15])
    schedule = ConfigSchedule({"command_range": [[1000, [0.02, 0.03]], [3000, [0.10, 0.15]]]})
    seen = []

    class Watch(BaseCallback):
        def _on_step(self) -> bool:
            started = self.locals["dones"]
            seen.extend((self.num_timesteps, c) for c in self.locals["new_obs"][started, Obs.command])
            return True

    schedule.set_on(venv, 0)
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=256, n_epochs=1, device="cpu", seed=0)
    model.learn(5000, callback=[schedule, Watch()])
    first = model.env.reset()
    assert len(seen) > 20
    rollout = 64 * 16
    for steps, command in seen:  # the value set at the start of the rollout that holds the step
        lo, hi = schedule.values_at((steps - 1) // rollout * rollout)["command_range"]
        assert lo - 1e-7 <= command <= hi + 1e-7, (steps, command)
    assert any(c > 0.1 for s, c in seen) and any(c < 0.03 for s, c in seen)
    assert first[:, Obs.command].min() >= 0.1 - 1e-7  # a reset after training draws under the last value
    assert other.env.config.command_range == (0.02, 0.15)


def test_train_runs_a_curriculum_from_the_hyperparameters(tmp_path):
    out = train(tiny_args(tmp_path / "run", env_id="leg_env/PlanarLegHop-v4", eval_freq=0, checkpoint_freq=0,
                          params=TINY + ["env_kwargs:{command_range: [0.02, 0.15]}", CURRICULUM]))  # fmt: skip
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert config["callback"][0]["train.callbacks.ConfigSchedule"]["schedule"]["command_range"][1] == [192, [0.1, 0.15]]
    # a schedule the training env has no room for fails at the first set_config, naming the field
    with pytest.raises(ValueError, match="set_config\\(command_range\\)"):
        train(tiny_args(tmp_path / "narrow", env_id="leg_env/PlanarLegHop-v4", eval_freq=0, checkpoint_freq=0,
                        params=TINY + ["env_kwargs:{}", CURRICULUM]))  # fmt: skip
    # a bad entry is refused before the run folder is made
    with pytest.raises(ValueError, match="ConfigSchedule"):
        train(tiny_args(tmp_path / "bad", params=TINY + ["callback:[{train.callbacks.ConfigSchedule: {schedule: {}}}]"]))
    assert not (tmp_path / "bad").exists()


class FirstCommands(BaseCallback):
    """Records the commands of the episodes a training run starts with (``learn`` has reset the env by then)."""

    seen: list = []

    def _on_training_start(self) -> None:
        from leg_env.tasks.base import Obs

        env = self.training_env
        obs = env.get_original_obs() if hasattr(env, "get_original_obs") else self.model._last_obs
        FirstCommands.seen.append(np.array(obs[:, Obs.command]))

    def _on_step(self) -> bool:
        return True


def test_a_run_and_its_resume_start_their_episodes_under_the_curriculum(tmp_path):
    """train.ppo sets a curriculum's value before learn resets the env: the first episodes of a run draw their
    commands from the schedule's value at step 0, and those of a resumed run from its value at the saved step."""
    FirstCommands.seen = []
    recorded = CURRICULUM.replace("}}}]", "}}}, test_train.FirstCommands]")
    params = TINY + ["env_kwargs:{command_range: [0.02, 0.15]}", recorded]
    out = tmp_path / "run"
    train(tiny_args(out, env_id="leg_env/PlanarLegHop-v4", eval_freq=0, checkpoint_freq=0, params=params))
    train(tiny_args(out, env_id="leg_env/PlanarLegHop-v4", eval_freq=0, checkpoint_freq=0, total_timesteps=2 * STEPS, params=params))
    first, resumed = FirstCommands.seen
    assert first.min() >= 0.02 - 1e-7 and first.max() <= 0.03 + 1e-7  # the schedule's value at 0 steps
    assert resumed.min() >= 0.1 - 1e-7  # its value at 256 steps, past its last point


def _normalized_pair(**normalize):
    """SB3's VecNormalize and BatchVecNormalize over two identical batched envs whose episodes end often."""
    from stable_baselines3.common.vec_env import VecNormalize

    from leg_env.sb3 import make_sb3_vec_env
    from train.normalize import BatchVecNormalize

    def venv():
        return make_sb3_vec_env(16, seed=3, env_id="leg_env/PlanarLegBalance-v1", per_env_info=False, max_episode_steps=7)

    return VecNormalize(venv(), **normalize), BatchVecNormalize(venv(), **normalize)


def _step_both(plain, batched, steps: int, seed: int = 0) -> int:
    """Step both with the same random actions; assert the same bits out; return the terminal observations seen."""
    actions = np.random.default_rng(seed).uniform(-1.0, 1.0, size=(steps, plain.num_envs, 2)).astype(np.float32)
    ended = 0
    for a in actions:
        out_plain, out_batched = plain.step(a), batched.step(a)
        for x, y in zip(out_plain[:3], out_batched[:3]):
            assert x.dtype == y.dtype and np.array_equal(x, y)
        for info_x, info_y in zip(out_plain[3], out_batched[3]):
            assert info_x.keys() == info_y.keys()
            if "terminal_observation" in info_x:
                x, y = info_x["terminal_observation"], info_y["terminal_observation"]
                assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y)
                ended += 1
    for name in ("obs_rms", "ret_rms") if plain.norm_obs else ("ret_rms",):
        assert np.array_equal(getattr(plain, name).mean, getattr(batched, name).mean)
        assert np.array_equal(getattr(plain, name).var, getattr(batched, name).var)
    assert np.array_equal(plain.returns, batched.returns)
    return ended


@pytest.mark.parametrize("normalize", [dict(), dict(norm_obs=False), dict(clip_obs=0.5, gamma=0.9)])
def test_batch_vec_normalize_gives_sb3s_bits(normalize):
    plain, batched = _normalized_pair(**normalize)
    plain.reset()
    batched.reset()
    assert _step_both(plain, batched, 40) >= 50  # the comparison covers many ended episodes
    plain.training = batched.training = False  # evaluation: the statistics frozen
    _step_both(plain, batched, 10, seed=1)


def test_batch_vec_normalize_saves_as_sb3s_class_and_resumes(tmp_path):
    from stable_baselines3.common.vec_env import VecNormalize

    from train.normalize import BatchVecNormalize

    plain, batched = _normalized_pair()
    plain.reset()
    batched.reset()
    _step_both(plain, batched, 20)
    batched.save(tmp_path / "vecnormalize.pkl")
    loaded = VecNormalize.load(tmp_path / "vecnormalize.pkl", batched.venv)
    assert type(loaded) is VecNormalize  # loads without train.normalize
    assert np.array_equal(loaded.obs_rms.var, plain.obs_rms.var) and loaded.clip_obs == plain.clip_obs
    resumed = BatchVecNormalize.from_vec_normalize(loaded)
    assert type(resumed) is BatchVecNormalize and resumed.venv is batched.venv
    plain.save(tmp_path / "plain.pkl")  # a resume of SB3's own (loading zeroes the running returns)
    _step_both(VecNormalize.load(tmp_path / "plain.pkl", plain.venv), resumed, 20, seed=2)
    with pytest.raises(TypeError, match="VecNormalize"):
        BatchVecNormalize.from_vec_normalize(batched.venv)


class _Records:
    """A logger that keeps what is recorded."""

    def __init__(self):
        self.values = {}

    def record(self, key, value, exclude=None):
        self.values[key] = value


def _curriculum(**kwargs):
    """A CommandCurriculum driven by hand: a model that holds its level, raw observations through ``locals``."""
    from types import SimpleNamespace

    from train.callbacks import CommandCurriculum

    curriculum = CommandCurriculum([0.02, 0.06], [0.05, 0.15], **kwargs)
    calls = []
    env = SimpleNamespace(env_method=lambda name, **kw: calls.append((name, kw)))
    curriculum.model = SimpleNamespace(get_env=lambda: env, logger=_Records())
    return curriculum, calls


def _observe(curriculum, apex, command, dones):
    from leg_env.tasks.base import Obs

    obs = np.zeros((len(apex), 22), dtype=np.float32)
    obs[:, Obs.last_apex], obs[:, Obs.command] = apex, command
    curriculum.locals = {"new_obs": obs, "dones": np.array(dones)}
    curriculum._on_step()


def test_command_curriculum_rises_a_level_once_the_hops_meet_the_command():
    curriculum, calls = _curriculum(levels=4, max_error=0.01, min_hops=3)
    curriculum._on_training_start()
    assert curriculum.model.curriculum_level == 0 and calls == [("set_config", {"command_range": (0.02, 0.06)})]
    c = [np.float32(0.04)] * 3
    _observe(curriculum, [0, 0, 0], c, [False] * 3)
    _observe(curriculum, [0.035, 0, 0.04], c, [False] * 3)  # two hops, errors 0.005 and 0
    _observe(curriculum, [0.035, 0, 0], c, [False, False, True])  # row 2 restarted (its start shows no apex): not a hop
    curriculum._on_rollout_end()
    assert curriculum.level == 0  # three hops needed
    assert curriculum.logger.values["rollout/apex_error"] == pytest.approx(0.0025, abs=1e-7)
    _observe(curriculum, [0.035, 0, 0], c, [False] * 3)  # no apex moved: no hop
    _observe(curriculum, [0.035, 0.0615, 0], c, [False] * 3)  # error 0.0215: the three average 0.0088
    curriculum._on_rollout_end()
    assert curriculum.level == 1 and curriculum.logger.values["curriculum/command_level"] == 1
    curriculum._on_rollout_start()
    assert calls[-1] == ("set_config", {"command_range": pytest.approx((0.0275, 0.0825))})
    # the next level counts only its own hops, the last min_hops of them
    _observe(curriculum, [0.06, 0.0615, 0], c, [False] * 3)  # error 0.02
    _observe(curriculum, [0.04, 0.05, 0.04], c, [False] * 3)  # errors 0, 0.01, 0: the last three average 0.0033
    curriculum._on_rollout_end()
    assert curriculum.level == 2
    _observe(curriculum, [0.06, 0.06, 0.06], c, [False] * 3)  # errors 0.02
    curriculum._on_rollout_end()
    assert curriculum.level == 2


def test_command_curriculum_stops_at_its_last_level_and_refuses_bad_arguments():
    from train.callbacks import CommandCurriculum

    curriculum, calls = _curriculum(levels=1, max_error=0.5, min_hops=1)
    curriculum._on_training_start()
    for apex in (0.01, 0.02, 0.03):
        _observe(curriculum, [apex], [0.04], [False])
        curriculum._on_rollout_end()
    assert curriculum.level == 1 and curriculum.command_range(1) == (0.05, 0.15)
    for kwargs, field in [({"levels": 0}, "levels"), ({"levels": 2.5}, "levels"), ({"max_error": 0}, "max_error"),
                          ({"max_error": float("nan")}, "max_error"), ({"min_hops": 0}, "min_hops"), ({"min_hops": True}, "min_hops")]:  # fmt: skip
        with pytest.raises(ValueError, match=field):
            CommandCurriculum([0.02, 0.06], [0.05, 0.15], **kwargs)
    with pytest.raises(ValueError, match="start and end"):
        CommandCurriculum([0.02], [0.05, 0.15])


def test_train_keeps_the_command_level_in_the_model_and_resumes_from_it(tmp_path):
    """Any landed hop raises the level here (max_error of 10 m): the level reached is saved with the model, and a
    resumed run starts its episodes at that level's commands and goes on from it."""
    from stable_baselines3 import PPO

    curriculum = ("callback:[{train.callbacks.CommandCurriculum: {start: [0.02, 0.03], end: [0.14, 0.15], levels: 1000, "
                  "max_error: 10.0, min_hops: 1}}]")  # fmt: skip
    params = TINY + ["env_kwargs:{command_range: [0.02, 0.15]}", curriculum]
    out = tmp_path / "run"
    train(tiny_args(out, env_id="leg_env/PlanarLegHop-v4", eval_freq=0, checkpoint_freq=0, total_timesteps=2048, params=params))
    first = PPO.load(out / "last" / "model.zip", device="cpu").curriculum_level
    assert first > 0
    train(tiny_args(out, env_id="leg_env/PlanarLegHop-v4", eval_freq=0, checkpoint_freq=0, total_timesteps=4096, params=params))
    assert PPO.load(out / "last" / "model.zip", device="cpu").curriculum_level >= first
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    levels = []
    for events in sorted((out / "tb").rglob("events.out.tfevents.*")):
        accumulator = EventAccumulator(str(events))
        accumulator.Reload()
        levels += [(e.step, e.value) for e in accumulator.Scalars("curriculum/command_level")]
    resumed = [level for step, level in sorted(levels) if step > 2048]
    assert resumed and resumed[0] >= first  # the resumed run's first rollout was at the saved level, not back at 0


def test_command_gains_are_the_observation_and_its_products_with_the_command():
    import gymnasium as gym
    import torch

    from leg_env.tasks.base import Obs
    from train.features import CommandGains

    space = gym.spaces.Box(-np.inf, np.inf, (22,), np.float32)
    gains = CommandGains(space)
    assert gains.features_dim == 44 and not list(gains.parameters())
    x = torch.randn(5, 22)
    features = gains(x)
    assert torch.equal(features[:, :22], x) and torch.equal(features[:, 22:], x * x[:, Obs.command, None])
    assert torch.equal(CommandGains(space, command=3)(x)[:, 22:], x * x[:, 3, None])
    for bad, error in [({"command": 22}, ValueError), ({"command": -1}, ValueError), ({"command": 1.0}, TypeError)]:
        with pytest.raises(error, match="command"):
            CommandGains(space, **bad)
    with pytest.raises(TypeError, match="flat Box"):
        CommandGains(gym.spaces.Box(-1, 1, (2, 3), np.float32))


def test_train_takes_a_features_extractor_by_its_class_path(tmp_path):
    from stable_baselines3 import PPO

    from train.features import CommandGains

    params = TINY + ["policy_kwargs:{net_arch: [8], features_extractor_class: train.features.CommandGains}"]
    out = train(tiny_args(tmp_path / "run", env_id="leg_env/PlanarLegHop-v4", eval_freq=0, checkpoint_freq=0, params=params))
    model = PPO.load(out / "model.zip", device="cpu")
    assert isinstance(model.policy.features_extractor, CommandGains)
    assert model.policy.mlp_extractor.policy_net[0].in_features == 48  # the hop's 24 entries and their products with the command
    assert yaml.safe_load((out / "config.yaml").read_text())["ppo"]["policy_kwargs"]["features_extractor_class"] == "train.features.CommandGains"
    for path, match in [("train.features.Nothing", "cannot import|not an SB3"), ("no_such.Module", "cannot import"),
                        ("train.callbacks.ConfigSchedule", "not an SB3 features extractor")]:  # fmt: skip
        bad = TINY + [f"policy_kwargs:{{features_extractor_class: {path}}}"]
        with pytest.raises(ValueError, match=f"features_extractor_class.*({match})"):
            train(tiny_args(tmp_path / "bad", env_id="leg_env/PlanarLegHop-v4", params=bad))
        assert not (tmp_path / "bad").exists()
