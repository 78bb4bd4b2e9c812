"""The cluster commands of the training page (docs/training.md), run on this machine: a token made with
``ray get-auth-token --generate`` (``~/.ray/auth_token``), a head node and a worker node started with
``ray start`` on the loopback address, each with ``RAY_AUTH_MODE=token``, then ``python -m train.rllib
--address`` with one env runner per node, also with the token. Each node has one CPU and each runner needs one,
so the runners can only run on both nodes; ``runners.json`` says where they ran.

``HOME`` is a temporary folder, so the token is written there and nothing of the user's is touched; the
nodes are stopped at the end (``ray stop``), whatever happens.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RAY = str(Path(sys.executable).with_name("ray"))
PARAMS = ["n_envs:4", "n_steps:32", "batch_size:64", "n_epochs:1", "policy_kwargs:{net_arch: [16, 16]}"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run(cmd: list[str], env: dict, timeout: float = 300) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"{' '.join(cmd)} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc


@pytest.fixture
def cluster(tmp_path):
    """A head and a worker node on 127.0.0.1, one CPU each; yields (address, env of a node that has the token)."""
    import ray

    if ray.is_initialized():  # a Ray of this process would be a third node, and ray stop would take it down
        ray.shutdown()
    home = tmp_path / "home"
    home.mkdir()
    env = dict(os.environ, HOME=str(home), RAY_USAGE_STATS_ENABLED="0", PYTHONPATH=str(ROOT))
    env.pop("RAY_ADDRESS", None)
    port = free_port()
    address = f"127.0.0.1:{port}"
    token = dict(env, RAY_AUTH_MODE="token")
    try:
        run([RAY, "get-auth-token", "--generate"], env)
        assert (home / ".ray" / "auth_token").is_file(), "ray get-auth-token --generate wrote no token"
        run([RAY, "start", "--head", f"--port={port}", "--node-ip-address=127.0.0.1", "--num-cpus=1", "--include-dashboard=false",
             "--disable-usage-stats"], token)
        run([RAY, "start", f"--address={address}", "--node-ip-address=127.0.0.1", "--num-cpus=1", "--disable-usage-stats"], token)
        yield address, token
    finally:
        subprocess.run([RAY, "stop", "--force"], env=env, capture_output=True, timeout=120)


def test_train_rllib_runs_an_env_runner_on_each_node(cluster, tmp_path):
    address, env = cluster
    out = tmp_path / "run"
    run([sys.executable, "-m", "train.rllib", "--address", address, "--num-env-runners", "2", "--num-cpus-per-env-runner", "1",
         "--total-timesteps", "128", "--checkpoint-freq", "0", "--verbose", "0", "--out", str(out), "--params", *PARAMS], env, timeout=600)
    runners = json.loads((out / "runners.json").read_text())["runners"]
    assert [r["worker_index"] for r in runners] == [1, 2]
    assert len({r["node_id"] for r in runners}) == 2, runners  # one runner on each node
    progress = json.loads((out / "progress.json").read_text())["iterations"]
    assert progress and progress[-1]["timesteps"] >= 128
