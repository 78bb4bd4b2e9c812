"""ONNX export: the graph equals the SB3 policy's deterministic predict, with and without observation normalisation."""

import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import onnx
import onnxruntime
import pytest

from train.evaluate import load_policy
from train.export import ExportError, export_onnx, main
from train.ppo import TrainArgs, train

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "policies" / "ppo_stance"
HOP = ROOT / "policies" / "ppo_hop_v4"
NUM_OBS = 1000
TOLERANCE = 1e-5
# a tiny run that normalises observations (the shipped policy normalises returns only): both paths
TINY = ["n_envs:4", "n_steps:32", "batch_size:64", "n_epochs:1", "normalize:{norm_obs: true, norm_reward: true}"]


@pytest.fixture(scope="module")
def normalised_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("export") / "run"
    args = TrainArgs(out=out, params=list(TINY), total_timesteps=256, eval_freq=0, eval_episodes=1, checkpoint_freq=0, progress_bar=False, verbose=0)
    return train(args)


def observations(n: int = NUM_OBS, seed: int = 0, env_id: str = "leg_env/PlanarLegStance-v0") -> np.ndarray:
    """``n`` rows of the task ``env_id``: 90% states the env reaches (resets, balancing, falls under random torques)
    and 10% far outside them (a sensor glitch), which saturate the normalisation's clipping."""
    envs = gym.make_vec(env_id, num_envs=100)
    obs, _ = envs.reset(seed=seed)
    rows, rng = [obs], np.random.default_rng(seed)
    while len(rows) * 100 < n:
        obs, *_ = envs.step(rng.uniform(-1.0, 1.0, size=(100, 2)) + (0.5, -0.5))
        rows.append(obs)
    obs = np.concatenate(rows)[:n]
    obs[::10] = rng.uniform(-50.0, 50.0, size=obs[::10].shape)
    return obs


def run_onnx(path: Path, obs: np.ndarray) -> np.ndarray:
    session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    (action,) = session.run(None, {"observation": obs})
    return action


@pytest.mark.parametrize("which", ["shipped", "normalised"])
def test_onnx_graph_equals_predict(which, normalised_run, tmp_path):
    folder = SHIPPED if which == "shipped" else normalised_run
    policy = load_policy(folder)
    assert (policy.vec_normalize is not None) == (which == "normalised")  # the two paths of the graph
    path = export_onnx(folder, tmp_path / "policy.onnx")
    obs = observations()
    expected, _ = policy.predict(obs, deterministic=True)
    action = run_onnx(path, obs)
    assert action.dtype == np.float32 and action.shape == (NUM_OBS, 2)
    np.testing.assert_allclose(action, expected, rtol=0.0, atol=TOLERANCE)
    np.testing.assert_allclose(run_onnx(path, obs[:1]), expected[:1], rtol=0.0, atol=TOLERANCE)  # any batch size
    if policy.vec_normalize is None:  # the trained policy saturates on falls: the action clipping is exercised
        assert (np.abs(expected) == 1.0).any() and (np.abs(expected) < 1.0).any()
    else:  # the far rows exercise the observation clipping
        rms, vec_normalize = policy.vec_normalize.obs_rms, policy.vec_normalize
        assert (np.abs((obs - rms.mean) / np.sqrt(rms.var + vec_normalize.epsilon)) > vec_normalize.clip_obs).any()
    model = onnx.load(path)
    props = {p.key: p.value for p in model.metadata_props}
    assert props["observation_normalization"] == ("VecNormalize" if which == "normalised" else "none")
    assert props["env_id"] == "leg_env/PlanarLegStance-v0" and props["env_id"] in model.doc_string


def test_the_graph_names_the_policys_own_task(tmp_path):
    """A policy of another task: the graph takes that task's observations and its metadata names that task."""
    policy = load_policy(HOP)
    assert policy.env_id == "leg_env/PlanarLegHop-v4"
    path = export_onnx(HOP, tmp_path / "hop.onnx")
    model = onnx.load(path)
    props = {p.key: p.value for p in model.metadata_props}
    assert props["env_id"] == "leg_env/PlanarLegHop-v4" and "PlanarLegHop-v4" in model.doc_string and "Stance" not in model.doc_string
    obs = observations(env_id="leg_env/PlanarLegHop-v4")
    assert obs.shape == (NUM_OBS, 24)
    expected, _ = policy.predict(obs, deterministic=True)
    np.testing.assert_allclose(run_onnx(path, obs), expected, rtol=0.0, atol=TOLERANCE)


def test_command_line_writes_the_graph(normalised_run, tmp_path, capsys):
    out = tmp_path / "out" / "policy.onnx"
    main([str(normalised_run), "--onnx", str(out)])
    assert out.is_file() and str(out) in capsys.readouterr().out
    main([str(normalised_run / "model.zip")])  # default: next to the model
    assert (normalised_run / "policy.onnx").is_file()


def test_missing_or_corrupt_files_are_errors_naming_the_file(normalised_run, tmp_path):
    with pytest.raises(SystemExit, match=str(tmp_path / "nowhere")):
        main([str(tmp_path / "nowhere"), "--onnx", str(tmp_path / "x.onnx")])
    broken = tmp_path / "broken"
    shutil.copytree(normalised_run, broken)
    (broken / "model.zip").write_bytes(b"this is not a zip archive")
    with pytest.raises(SystemExit, match=str(broken / "model.zip")):
        main([str(broken), "--onnx", str(tmp_path / "x.onnx")])
    shutil.copy(normalised_run / "model.zip", broken / "model.zip")
    (broken / "vecnormalize.pkl").unlink()
    with pytest.raises(SystemExit, match=str(broken / "vecnormalize.pkl")):
        main([str(broken), "--onnx", str(tmp_path / "x.onnx")])
    assert not (tmp_path / "x.onnx").exists()
    with pytest.raises(ExportError, match="not a network"):
        export_onnx("lqr", tmp_path / "x.onnx")


def test_a_policy_with_command_gains_exports_with_its_products(tmp_path):
    """``train.features.CommandGains`` in the graph: Slice, Mul and Concat before the actor, equal to predict."""
    from train.features import CommandGains

    params = TINY + ["policy_kwargs:{net_arch: [16, 16], features_extractor_class: train.features.CommandGains}"]
    args = TrainArgs(out=tmp_path / "run", env_id="leg_env/PlanarLegHop-v4", params=params, total_timesteps=256, eval_freq=0,
                     eval_episodes=1, checkpoint_freq=0, progress_bar=False, verbose=0)  # fmt: skip
    folder = train(args)
    policy = load_policy(folder)
    assert isinstance(policy.model.policy.pi_features_extractor, CommandGains)
    path = export_onnx(folder, tmp_path / "gains.onnx")
    assert {"Slice", "Mul", "Concat"} <= {n.op_type for n in onnx.load(path).graph.node}
    obs = observations(env_id="leg_env/PlanarLegHop-v4")
    expected, _ = policy.predict(obs, deterministic=True)
    np.testing.assert_allclose(run_onnx(path, obs), expected, rtol=0.0, atol=TOLERANCE)
