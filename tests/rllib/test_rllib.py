"""RLlib smoke test: ``python -m train.rllib``'s training, checkpoints, resume, in-training evaluation, the policy it
keeps, and evaluation by ``train.evaluate``.

Needs the ``rllib`` extra, so plain ``pytest`` does not collect this folder (pyproject's
``norecursedirs``); ``make test`` runs it in its second venv, ``.venv-rllib``. A tiny network and a
128-step batch keep it to about a minute on 2 cores, on a local ``ray.init(num_cpus=2)``.
"""

import json

import numpy as np
import pytest
import ray
import yaml

import leg_env
import leg_env.rllib
from leg_env.rllib import sub_env_seed
from train.evaluate import EvalArgs, evaluate, load_policy
from train.rllib import RLlibArgs, RLlibPolicy, latest_checkpoint, main, resolve_config, rllib_config, train

BATCH = 128  # env steps per iteration: n_steps * n_envs (RLlib samples a few more when episodes end)
PARAMS = ["n_envs:4", "n_steps:32", "batch_size:64", "n_epochs:2", "policy_kwargs:{net_arch: [16, 16]}"]


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def args(out, **kwargs) -> RLlibArgs:
    return RLlibArgs(out=out, params=PARAMS, num_env_runners=1, checkpoint_freq=BATCH, eval_freq=2 * BATCH, eval_episodes=2,
                     verbose=0, **kwargs)  # fmt: skip


@pytest.fixture(scope="module")
def run(local_ray, tmp_path_factory):
    """Two training iterations into a run folder, then one more by rerunning with a larger total."""
    out = tmp_path_factory.mktemp("rllib") / "run"
    train(args(out, total_timesteps=2 * BATCH))
    first = json.loads((out / "progress.json").read_text())["iterations"]
    checkpoints = sorted(p.name for p in (out / "checkpoints").iterdir())
    train(args(out, total_timesteps=3 * BATCH))  # the same command with a larger total resumes
    return out, first, checkpoints


def test_two_iterations_write_checkpoints(run):
    out, first, checkpoints = run
    steps = [it["timesteps"] for it in first]
    assert len(steps) == 2 and all(BATCH <= n < BATCH + 16 for n in np.diff([0, *steps]))
    assert all(np.isfinite(it["iteration_s"]) and np.isfinite(it["episode_return_mean"]) for it in first)
    assert checkpoints == [f"{n:012d}" for n in steps]  # one per checkpoint_freq steps, the two newest
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert config["ppo"]["train_batch_size"] == BATCH and config["ppo"]["minibatch_size"] == 64
    assert config["scaling"]["num_envs_per_env_runner"] == 4 and config["model"]["fcnet_hiddens"] == [16, 16]
    assert config["not_mapped"]["normalize"] == {"norm_obs": False, "norm_reward": True}  # from ppo.yml


def test_rerun_resumes_from_the_newest_checkpoint(run):
    out, first, _ = run
    progress = json.loads((out / "progress.json").read_text())["iterations"]
    assert len(progress) == 3 and progress[:2] == first
    assert BATCH <= progress[2]["timesteps"] - first[1]["timesteps"] < BATCH + 16  # one iteration more, not three
    newest = latest_checkpoint(out)
    assert newest.name == f"{progress[2]['timesteps']:012d}"
    state = json.loads((newest / "progress.json").read_text())
    assert state["resumes"] == 1 and state["iterations"] == 3
    assert len(list((out / "checkpoints").iterdir())) == 2
    assert len((out / "command.txt").read_text().splitlines()) == 2


def test_the_run_evaluates_keeps_the_best_and_the_last_policy_and_selects_one(run):
    """As train.ppo's runs: an evaluation at the first multiple of eval_freq and at the end of each invocation (the
    resume's history kept), best/ and last/ with their records, and the selected one's module at the top."""
    out, first, _ = run
    record = json.loads((out / "evaluations.json").read_text())
    steps = [e["timesteps"] for e in record["evaluations"]]
    assert steps == [first[1]["timesteps"], json.loads((out / "progress.json").read_text())["iterations"][-1]["timesteps"]]
    assert all(len(e["returns"]) == 2 for e in record["evaluations"]) and record["resumes"] == 1
    assert record["total_timesteps"] == steps[-1] and "ray" in record["machine"]
    best = max(record["evaluations"], key=lambda e: (e["survival_rate"], e["mean_return"]))
    assert record["selected"]["from"] == "best" and record["selected"]["mean_return"] == best["mean_return"]
    assert json.loads((out / "last" / "info.json").read_text())["timesteps"] == steps[-1]
    assert (out / "learning_curve.png").is_file()
    top, chosen = RLlibPolicy.load(out).module.state_dict(), RLlibPolicy.load(out / "best").module.state_dict()
    for name, value in top.items():
        np.testing.assert_array_equal(value.numpy(), chosen[name].numpy(), err_msg=name)
    assert isinstance(load_policy(str(out / "last")), RLlibPolicy)


def test_the_environment_flag_is_env_id_as_in_train_ppo(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--env", leg_env.ENV_ID, "--total-timesteps", str(BATCH)])
    assert stop.value.code == 2 and "--env was renamed --env-id" in capsys.readouterr().err
    with pytest.raises(TypeError, match="env"):
        RLlibArgs(env=leg_env.ENV_ID)


def test_checkpoint_restores_into_a_new_algorithm(run, local_ray):
    out, _, _ = run
    config = yaml.safe_load((out / "config.yaml").read_text())
    algo = rllib_config(config).build_algo()
    try:
        saved = RLlibPolicy.load(latest_checkpoint(out)).module.state_dict()
        fresh = algo.get_module().state_dict()  # the local runner's inference module: the actor's weights
        assert any(not np.array_equal(fresh[name], saved[name]) for name in fresh)  # training moved them
        algo.restore_from_path(str(latest_checkpoint(out).resolve()))
        restored = algo.get_module().state_dict()
        assert any(name.startswith("pi.") for name in restored)
        for name, value in restored.items():
            np.testing.assert_array_equal(np.asarray(value), saved[name].numpy(), err_msg=name)
        # the remote runner was named by the callback and seeded its sub-envs with its own seeds
        found = algo.env_runner_group.foreach_env_runner(
            lambda runner: (runner.worker_index, leg_env.rllib.find_runner_seeds(runner.env).seeds()), local_env_runner=False
        )
        assert found == [(1, [sub_env_seed(0, 0, False, 1, i) for i in range(4)])]
    finally:
        algo.stop()


def test_evaluate_loads_the_run_as_a_policy(run, tmp_path):
    out, _, _ = run
    policy = load_policy(str(out))
    assert isinstance(policy, RLlibPolicy) and policy.env_kwargs == {}
    obs = np.random.default_rng(0).normal(size=(5, 12)).astype(np.float32)
    action, state = policy.predict(obs)
    assert action.shape == (5, 2) and state is None and np.all(np.abs(action) <= 1.0)
    single, _ = policy.predict(obs[0])
    np.testing.assert_allclose(single, action[0], rtol=0, atol=1e-6)
    import torch  # the deterministic action is the Gaussian's mean, clipped

    with torch.no_grad():
        inputs = policy.module.forward_inference({"obs": torch.from_numpy(obs)})["action_dist_inputs"].numpy()
    np.testing.assert_allclose(action, np.clip(inputs[:, :2], -1, 1), rtol=0, atol=1e-6)
    stochastic = policy.predict(obs, deterministic=False)[0]
    assert not np.allclose(stochastic, action)

    result = evaluate(EvalArgs(policy=str(out), baseline="lqr", episodes=1, out=tmp_path / "eval", plot=False))
    summary = json.loads((result / "policy.json").read_text())
    assert summary["episodes"] == 1 and summary["steps"] >= 1 and summary["env_kwargs"] == {}
    assert (result / "lqr.json").is_file()


def test_another_configuration_is_refused(run, capsys):
    out, _, _ = run
    with pytest.raises(SystemExit, match="different configuration"):
        main(["--out", str(out), "--params", "gamma:0.9", "--total-timesteps", str(BATCH)])


def test_unmapped_keys_are_errors_or_recorded(tmp_path):
    with pytest.raises(ValueError, match="target_kl"):
        resolve_config(RLlibArgs(out=tmp_path, params=["target_kl:0.01"]))
    with pytest.raises(ValueError, match="callback"):  # SB3 callbacks (a curriculum) have no counterpart either
        resolve_config(RLlibArgs(out=tmp_path, params=["callback:train.callbacks.ConfigSchedule"]))
    with pytest.raises(ValueError, match="bounds_loss_coef"):  # ChunkedPPO's charge on the mean action
        resolve_config(RLlibArgs(out=tmp_path, params=["bounds_loss_coef:0.05"]))
    with pytest.raises(ValueError, match="temporal_smoothness_coef"):  # ChunkedPPO's smoothness charge
        resolve_config(RLlibArgs(out=tmp_path, params=["temporal_smoothness_coef:0.1"]))
    resolve_config(RLlibArgs(out=tmp_path, params=["bounds_loss_coef:0.0", "target_kl:null", "use_sde:false",
                                                   "temporal_smoothness_coef:0", "spatial_smoothness_coef:0"]))  # off: nothing to refuse
    with pytest.raises(ValueError, match="norm_obs"):
        resolve_config(RLlibArgs(out=tmp_path, params=["normalize:{norm_obs: true}"]))
    with pytest.raises(ValueError, match="clip_range must be a number"):  # a Zoo schedule of it has no counterpart
        resolve_config(RLlibArgs(out=tmp_path, params=["clip_range:lin_0.2"]))
    config = resolve_config(RLlibArgs(out=tmp_path, num_env_runners=3))
    assert config["scaling"]["num_envs_per_env_runner"] == 11  # ceil(32 / 3)
    assert config["learning_rate"] == "lin_3.0e-4" and config["total_timesteps"] == 4_000_000
    assert rllib_config(config).lr == [[0, 3.0e-4], [4_000_000, 0.0]]  # linear to 0 over the run
    assert config["not_mapped"]["policy_kwargs"] == {"log_std_init": -1.0}
    assert config["env_id"] == leg_env.ENV_ID
