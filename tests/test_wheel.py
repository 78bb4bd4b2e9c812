"""The built wheel as a user gets it: installed in a fresh venv that nothing can write, it steps every task.

The sdist is built from a copy of the sources and the wheel from the sdist alone (so the sdist must carry
every file of the build); the wheel and its runtime dependencies go into a fresh venv without system
site-packages and without byte-compiled files; the venv, HOME and the working directory are then made
read-only (as root: ``chattr +i``, or the process runs as ``nobody``). A fresh process of that venv, outside
the repository, makes, resets and steps every registered id, single (``gym.make``) and batched
(``gym.make_vec(id, num_envs=64, vectorization_mode="vector_entry_point")``), and writes nothing.

The set-up is ``benchmarks/wheel_venv.py``, shared with the cold-start benchmark
(``benchmarks/cold_start.py``). The build and the install take seconds and need no network once pip's
cache holds the dependencies' wheels (without one, the wheels are packed from the installed distributions).
"""

import importlib.util
import json
import sys
import tarfile
import tempfile
import textwrap
import zipfile
from pathlib import Path

import pytest

import leg_env

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("wheel_venv", ROOT / "benchmarks" / "wheel_venv.py")
wheel_venv = importlib.util.module_from_spec(_spec)
sys.modules["wheel_venv"] = wheel_venv  # its dataclasses look their module up
_spec.loader.exec_module(wheel_venv)

NUM_ENVS = 64

STEP_EVERY_ID = textwrap.dedent(
    f"""
    import json, sys, warnings
    warnings.simplefilter("error")
    import gymnasium as gym, numpy as np
    import leg_env
    from leg_env._core import kernels

    stepped = []
    for env_id in leg_env.ENV_IDS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)  # gymnasium's note on an older version of an id
            env = gym.make(env_id)
            envs = gym.make_vec(env_id, num_envs={NUM_ENVS}, vectorization_mode="vector_entry_point")
        env.reset(seed=0)
        obs, reward, terminated, truncated, info = env.step(np.zeros(env.action_space.shape, dtype=env.action_space.dtype))
        assert obs.shape == env.observation_space.shape and np.isfinite(obs).all() and np.isfinite(reward), env_id
        envs.reset(seed=0)
        obs, reward, terminated, truncated, info = envs.step(np.zeros(envs.action_space.shape, dtype=envs.action_space.dtype))
        assert obs.shape[0] == reward.shape[0] == {NUM_ENVS} and np.isfinite(obs).all() and np.isfinite(reward).all(), env_id
        env.close()
        envs.close()
        stepped.append(env_id)
    print(json.dumps({{"file": leg_env.__file__, "kernels": kernels.__file__, "prefix": sys.prefix, "stepped": stepped}}))
    """
)


@pytest.fixture(scope="module")
def installed():
    """The sdist, the wheel built from it, and the fresh venv it is installed in (removed afterwards)."""
    work = Path(tempfile.mkdtemp(prefix="leg_env_wheel_"))
    try:
        built = wheel_venv.build(work)
        venv = wheel_venv.make_venv(work, built.wheel)
        yield built, venv
    finally:
        wheel_venv.cleanup(work)


def test_the_sdist_carries_every_file_of_the_build(installed):
    built, _ = installed
    names = set(wheel_venv.sdist_names(built.sdist))
    needed = {"setup.py", "MANIFEST.in", "pyproject.toml", "README.md", "LICENSE", "leg_env/py.typed"}
    needed |= {p.relative_to(built.source).as_posix() for p in (built.source / "leg_env").rglob("*") if p.suffix in (".py", ".c", ".h")}
    assert {n for n in needed if n.startswith("leg_env/_core/") and n.endswith((".c", ".h"))}  # the core's sources were found
    assert not needed - names, sorted(needed - names)
    with tarfile.open(built.sdist) as tar:
        assert not [n for n in tar.getnames() if n.endswith((".so", ".pyd", ".pyc", ".nbi", ".nbc"))]


def test_the_wheel_carries_the_compiled_core_and_not_its_sources(installed):
    built, _ = installed
    assert "-py3-none-any" not in built.wheel.name  # a platform wheel
    with zipfile.ZipFile(built.wheel) as z:
        names = z.namelist()
    assert [n for n in names if n.startswith("leg_env/_core/kernels.") and n.endswith((".so", ".pyd"))], names
    assert not [n for n in names if n.endswith((".c", ".h", ".pyc"))], names


def test_the_installed_wheel_steps_every_id_in_a_read_only_venv_and_writes_nothing(installed):
    _, venv = installed
    before = wheel_venv.snapshot(venv.root, venv.home, venv.cwd)
    with wheel_venv.read_only(venv) as locked:
        done = locked.run(STEP_EVERY_ID)
    assert done.returncode == 0, f"{locked.how}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    out = json.loads(done.stdout.strip().splitlines()[-1])
    # the wheel's package, from the fresh venv, not the repository
    assert Path(out["prefix"]) == venv.root
    assert Path(out["file"]) == venv.site_packages / "leg_env" / "__init__.py", out
    assert Path(out["kernels"]).parent == venv.site_packages / "leg_env" / "_core", out
    assert out["stepped"] == list(leg_env.ENV_IDS)
    # nothing was written: no bytecode, nothing in HOME or the working directory, no file changed
    assert not [p for p in wheel_venv.walk(venv.root) if p.name == "__pycache__"]
    assert not list(venv.home.iterdir()) and not list(venv.cwd.iterdir())
    assert wheel_venv.snapshot(venv.root, venv.home, venv.cwd) == before
