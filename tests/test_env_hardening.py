"""The env side of bad input: a rejected call changes nothing, every bad input names itself.

Each test turns one reproducer of the issue (items 5-9, 12-14, 16) into a check that failed on the
code before the fix.
"""

import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode

import leg_env
from leg_env import ENDINGS, ENV_ID, LegParams
from leg_env.checks import ArgumentTypeError
from leg_env.envs.single import LegEnv
from leg_env.envs.vector import LegVectorEnv
from leg_env.physics.integrate import stance_step
from leg_env.physics.params import PARAM_NAMES
from leg_env.physics.layout import FLAG_NAMES
from leg_env.tasks import stance
from leg_env.tasks.base import FIELD_RANGES, robot_row
from leg_env.tasks.stance import TASK

ROOT = Path(__file__).resolve().parents[1]
CONTACTS = ("pinned", "unilateral")
HUGE = 10**400  # an int too large for a float
NAN_QPOS = {"qpos": [np.nan] * 5}
# reset options that were accepted, or converted, before: each must now be refused with nothing changed
BAD_OPTIONS = [
    NAN_QPOS,
    {"qpos": [0.0, 0.0, 1e39, -2.0, 0.8]},  # th_b overflows the float32 observation
    {"qvel": [0.0, 0.0, 1e39, 0.0, 0.0]},
    {"qvel": [0.0, 0.0, 2e3, 0.0, 0.0]},  # faster than max_rate (1e3)
    {"qpos": ["0", "0", "0", "-2", "0.8"]},  # strings are not numbers
    {"qpos": [0.0, 0.0, 0.0, -2.0, True]},
    {"flying": True},
]
BAD_SEEDS = [-1, 1.5, "12", True]


def generator_state(env) -> dict:
    return env.unwrapped.np_random.bit_generator.state


def assert_same_state(a, b):
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


# ---------------------------------------------------------------- transactional reset


@pytest.mark.parametrize("options", BAD_OPTIONS, ids=repr)
def test_rejected_reset_changes_nothing_in_the_single_env(options):
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    for _ in range(5):
        env.step(np.array([0.0, -0.48], dtype=np.float32))
    state, rng = env.unwrapped.state, generator_state(env)
    with pytest.raises(ValueError, match="option"):
        env.reset(seed=99, options=options)
    assert generator_state(env) == rng, "the generator was re-seeded by a rejected reset"
    assert_same_state(env.unwrapped.state, state)
    # the next reset continues the generator as if the rejected one had never been made
    twin = gym.make(ENV_ID)
    twin.reset(seed=0)
    np.testing.assert_array_equal(env.reset()[0], twin.reset()[0])


@pytest.mark.parametrize("seed", BAD_SEEDS, ids=repr)
def test_rejected_seed_changes_nothing_in_the_single_env(seed):
    env = LegEnv()
    env.reset(seed=0)
    env.step(np.zeros(2))
    state, rng = env.state, generator_state(env)
    with pytest.raises((ValueError, TypeError, gym.error.Error), match="seed"):
        env.reset(seed=seed)
    assert generator_state(env) == rng
    assert_same_state(env.state, state)


@pytest.mark.parametrize("options", BAD_OPTIONS, ids=repr)
def test_rejected_reset_changes_nothing_in_the_vector_env(options):
    envs, twin = LegVectorEnv(3), LegVectorEnv(3)
    for e in (envs, twin):
        e.reset(seed=0)
        for _ in range(4):
            e.step(np.tile([0.0, -0.48], (3, 1)))
    with pytest.raises(ValueError, match="option"):
        envs.reset(seed=99, options=options)
    assert envs.elapsed_steps.tolist() == [4, 4, 4], "the time limit's counters were zeroed"
    assert_same_state(envs.state, twin.state)
    for a, b in zip(envs._rngs.generators, twin._rngs.generators):
        assert a.bit_generator.state == b.bit_generator.state
    np.testing.assert_array_equal(envs.reset()[0], twin.reset()[0])


@pytest.mark.sb3
@pytest.mark.parametrize("options", BAD_OPTIONS[:-1], ids=repr)
def test_rejected_reset_changes_nothing_in_the_sb3_adapter(options):
    from leg_env.sb3 import make_sb3_vec_env

    venv, twin = make_sb3_vec_env(2, seed=0), make_sb3_vec_env(2, seed=0)
    for v in (venv, twin):
        v.reset()
        v.step(np.tile([0.0, -0.48], (2, 1)))
    venv.seed(99)
    venv.set_options(options)
    with pytest.raises(ValueError, match="option"):
        venv.reset()
    assert venv.env.elapsed_steps.tolist() == [1, 1]
    assert_same_state(venv.env.state, twin.env.state)


# ---------------------------------------------------------------- step before reset


@pytest.mark.parametrize("mode", list(AutoresetMode), ids=str)
def test_vector_step_before_reset_raises_and_changes_nothing(mode):
    envs = LegVectorEnv(3, autoreset_mode=mode, max_episode_steps=1)
    state = envs.state
    with pytest.raises(ResetNeeded, match="reset"):
        envs.step(np.zeros((3, 2)))
    assert_same_state(envs.state, state)
    assert envs.elapsed_steps.tolist() == [0, 0, 0]
    # a partial reset leaves the other sub-envs without an episode: still refused, naming them
    envs.reset(seed=0, options={"reset_mask": np.array([True, False, True])})
    with pytest.raises(ResetNeeded, match=r"\[1\]"):
        envs.step(np.zeros((3, 2)))
    envs.reset(seed=0)
    for _ in range(3):  # every step ends an episode (max_episode_steps=1): autoresets draw from the generators
        if mode == AutoresetMode.DISABLED:
            envs.reset()
        envs.step(np.zeros((3, 2)))


@pytest.mark.sb3
def test_sb3_step_before_reset_raises_and_changes_nothing():
    from leg_env.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env(2, max_episode_steps=1)
    state = venv.env.state
    with pytest.raises(ResetNeeded, match="reset"):
        venv.step(np.zeros((2, 2)))
    assert_same_state(venv.env.state, state)
    venv.reset()
    venv.step(np.zeros((2, 2)))


# ---------------------------------------------------------------- one validation path, with bounds


@pytest.mark.parametrize("field", sorted(FIELD_RANGES), ids=str)
def test_every_config_field_refuses_a_number_too_large_for_a_float(field):
    value = (HUGE, HUGE) if field in ("hip_range", "knee_range") else HUGE
    with pytest.raises(ValueError, match=field):
        LegEnv(**{field: value})


@pytest.mark.parametrize("field", PARAM_NAMES, ids=str)
def test_every_param_refuses_a_number_too_large_for_a_float(field):
    with pytest.raises(ValueError, match=f"LegParams.{field} "):
        LegParams(**{field: HUGE})


@pytest.mark.parametrize("value", [2**63, 4097, np.nan, np.inf, 2.5, 0], ids=repr)
def test_substeps_has_a_documented_upper_bound(value):
    with pytest.raises(ValueError, match=r"substeps must be .*\[1, 4096\]"):
        LegEnv(substeps=value)
    with pytest.raises(ValueError, match="substeps"):
        stance_step(np.zeros(5), np.zeros(5), np.zeros(2), LegParams(), substeps=value)


def test_substeps_at_the_bound_and_unknown_keywords():
    assert LegEnv(substeps=4096).config.substeps == 4096
    with pytest.raises(TypeError, match="unexpected keyword argument 'substep'"):
        LegEnv(substep=2)


# ---------------------------------------------------------------- nothing overflows float32 silently


@pytest.mark.parametrize("g", [1e-300, 1e-7, -1.0, np.nan, 1e7])
def test_gravity_between_zero_and_its_bound_is_refused(g):
    with pytest.raises(ValueError, match=r"LegParams\.g must be"):
        LegParams(g=g)


@pytest.mark.parametrize("contact", CONTACTS)
@pytest.mark.parametrize("options", BAD_OPTIONS[1:4], ids=repr)
def test_reset_states_that_overflow_the_observation_are_refused(contact, options):
    with pytest.raises(ValueError, match="qpos|qvel"):
        LegEnv(contact=contact).reset(options=options)
    with pytest.raises(ValueError, match="qpos|qvel"):
        LegVectorEnv(2, contact=contact).reset(options=options)


def test_reset_noise_scale_is_bounded():
    with pytest.raises(ValueError, match=r"reset_noise_scale must be in \[0, 3.14159\]"):
        LegEnv(reset_noise_scale=1e300)
    LegEnv(reset_noise_scale=np.pi).reset(seed=0)


@pytest.mark.parametrize("contact", CONTACTS)
def test_an_observation_that_overflows_float32_is_a_flagged_numerical_failure(contact):
    """The kernel's last guard: a finite state whose observation overflows float32 (here through a
    gravity below the accepted range, put into the kernel's constants directly) is a numerical
    failure: flagged and terminated, the state and observation left at the last good ones."""
    env = LegEnv(contact=contact, reset_noise_scale=0.0)
    robots, settings = robot_row(env.params, env.config, env.nominal), env.config.settings()
    n = 2
    state, out = np.zeros(n, dtype=TASK.state_dtype), np.zeros(n, dtype=TASK.out_dtype)
    obs = np.zeros((n, env.observation_space.shape[0]), dtype=np.float32)
    state["q"] = env.nominal.q
    TASK.start(state, robots, settings, out, obs)
    assert np.isfinite(obs).all()
    before_state, before_obs = state.copy(), obs.copy()
    state["action"] = [[0.5, -0.2], [0.4, -0.25]]
    tiny_g = robots.copy()
    tiny_g["p"]["g"] = 1e-300  # the weight m g becomes 1.5e-299 N, and lam / (m g) overflows float32
    TASK.step(state, tiny_g, settings, out, obs)
    assert np.isfinite(obs).all(), obs
    assert out["numerical_failure"].all() and out["terminated"].all()
    assert [ENDINGS[k] for k in out["ending"]] == ["numerical_failure"] * n
    np.testing.assert_array_equal(obs, before_obs)
    for field in ("q", "qd", "anchor"):
        np.testing.assert_array_equal(state[field], before_state[field])


# ---------------------------------------------------------------- strict coercion


BAD_TYPED_ACTIONS = [["0.5", "0.5"], np.array([0.5 + 1j, 0.5]), [0.5 + 0j, 0.5], [True, False], np.array([True, False])]


@pytest.mark.parametrize("action", BAD_TYPED_ACTIONS, ids=repr)
def test_actions_that_are_not_real_numbers_are_refused(action):
    env = LegEnv()
    env.reset(seed=0)
    state = env.state
    with pytest.raises(ValueError, match="action"):
        env.step(action)
    assert_same_state(env.state, state)
    envs = LegVectorEnv(2)
    envs.reset(seed=0)
    with pytest.raises(ValueError, match="actions"):
        envs.step([action, action])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(torque_limit="99"), "torque_limit"),
        (dict(torque_limit=(True, 60)), r"torque_limit\[0\]"),
        (dict(torque_limit=(60, 1 + 2j)), r"torque_limit\[1\]"),
        (dict(hip_range="ab"), "hip_range"),
        (dict(alive_bonus="1"), "alive_bonus"),
        (dict(substeps=True), "substeps"),
        (dict(terminate_on_contact_loss=1), "terminate_on_contact_loss"),
        (dict(contact=1), "contact"),
        (dict(params={"m_b": "10"}), "m_b"),
        (dict(params={"g": True}), r"LegParams\.g"),
    ],
    ids=repr,
)
def test_arguments_of_the_wrong_type_are_refused_naming_them(kwargs, match):
    with pytest.raises(ArgumentTypeError, match=match) as error:
        LegEnv(**kwargs)
    assert isinstance(error.value, TypeError) and isinstance(error.value, ValueError)


@pytest.mark.parametrize("config", [5, "defaults", [("mu", 0.5)]], ids=repr)
def test_config_of_the_wrong_type_is_a_type_error_naming_config(config):
    for build in (LegEnv, lambda **kw: LegVectorEnv(2, **kw), lambda **kw: gym.make(ENV_ID, **kw)):
        with pytest.raises(TypeError, match="config must be"):
            build(config=config)


@pytest.mark.parametrize("seed", BAD_SEEDS + [[0, 1.5], [0, 1, 2], "ab"], ids=repr)
def test_vector_reset_refuses_bad_seeds_clearly_and_changes_nothing(seed):
    envs = LegVectorEnv(2)
    envs.reset(seed=0)
    state = envs.state
    with pytest.raises(ValueError, match="seed"):
        envs.reset(seed=seed)
    assert_same_state(envs.state, state)


# ---------------------------------------------------------------- human rendering without a display

_HUMAN = """
import warnings, numpy as np, gymnasium as gym, leg_env
env = gym.make("leg_env/PlanarLegStance-v0", render_mode="human", width=64, height=64)
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    try:
        env.reset(seed=5)
        print("RESET OK")
    except RuntimeError as e:
        print("RAISED", e)
        print("UNCHANGED", env.unwrapped._np_random is None and np.array_equal(env.unwrapped.state[0], env.unwrapped.nominal.q))
print("WARNED", *[str(w.message) for w in caught if "no window" in str(w.message)])
"""


def _run_headless(driver: str | None) -> str:
    environ = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER")}
    if driver:
        environ["SDL_VIDEODRIVER"] = driver
    done = subprocess.run([sys.executable, "-c", _HUMAN], capture_output=True, text=True, env=environ, cwd=ROOT, timeout=600)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_human_mode_without_a_display_warns_that_no_window_shows():
    out = _run_headless(None)
    assert "RESET OK" in out
    assert "fell back to its 'offscreen' video driver" in out, out


def test_human_mode_whose_window_cannot_open_raises_before_the_state_changes():
    out = _run_headless("x11")  # no X server: SDL cannot init the driver
    assert "RAISED render_mode=\"human\" could not open a window" in out, out
    assert "UNCHANGED True" in out, out


# ---------------------------------------------------------------- read-only install, no writable home


def test_a_read_only_package_without_a_writable_home_steps_every_task_at_once():
    """A read-only install (a container image, a system package) without a writable home: nothing is
    compiled or cached at run time, so every task steps at once, single and batched, writing nothing.

    The package (with its compiled core) is copied to a directory the child process cannot write, and
    HOME is not writable either: read-only modes, or for root (who writes anywhere) the immutable
    attribute (``chattr +i``).
    """
    top = Path(tempfile.mkdtemp(prefix="leg_env_ro_"))
    shutil.copytree(ROOT / "leg_env", top / "leg_env", ignore=shutil.ignore_patterns("__pycache__"))
    (top / "home").mkdir()
    locked = [path for path in (top / "leg_env").rglob("*") if path.is_dir()] + [top / "leg_env", top / "home"]
    root = os.geteuid() == 0
    try:
        for path in locked:
            if root:
                subprocess.run(["chattr", "+i", str(path)], capture_output=True)
            else:
                path.chmod(0o555)
        environ = {k: v for k, v in os.environ.items() if k not in ("XDG_CACHE_HOME",)}
        environ.update(HOME=str(top / "home"), PYTHONPATH=str(top), PYTHONDONTWRITEBYTECODE="1")
        code = textwrap.dedent(
            """
            import time, warnings
            warnings.simplefilter("error")
            import gymnasium as gym, numpy as np
            t0 = time.perf_counter()
            import leg_env
            for env_id in leg_env.ENV_IDS:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", DeprecationWarning)  # gymnasium's note on an older version
                    env = gym.make(env_id)
                    envs = gym.make_vec(env_id, num_envs=4, vectorization_mode="vector_entry_point")
                env.reset(seed=0)
                env.step(np.zeros(2, dtype=np.float32))
                envs.reset(seed=0)
                envs.step(np.zeros((4, 2), dtype=np.float32))
            print("stepped", len(leg_env.ENV_IDS), "seconds", round(time.perf_counter() - t0, 3))
            print(leg_env.__file__)
            """
        )
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=environ, cwd=top, timeout=600)
        assert done.returncode == 0, done.stderr
        assert str(top / "leg_env") in done.stdout and f"stepped {len(leg_env.ENV_IDS)}" in done.stdout, done.stdout
        assert not list((top / "home").iterdir())
        assert not [p for p in (top / "leg_env").rglob("*") if p.name == "__pycache__"]
    finally:
        for path in locked:
            if root:
                subprocess.run(["chattr", "-i", str(path)], capture_output=True)
            else:
                path.chmod(0o755)
        shutil.rmtree(top)


# ---------------------------------------------------------------- fork after threads (now safe)


def test_threads_work_in_a_child_forked_after_the_parent_ran_them():
    """Threads in a child forked after its parent stepped with ``num_threads=2`` give the parent's result.

    Under numba's GNU OpenMP threads the forked child was killed ("fork() called from a process already
    using GNU OpenMP"); the batch is now split over Python threads around a GIL-free kernel.
    """
    code = textwrap.dedent(
        """
        import multiprocessing as mp, numpy as np
        from leg_env.envs.vector import LegVectorEnv

        def step_once():
            envs = LegVectorEnv(8, num_threads=2)
            envs.reset(seed=0)
            out = float(envs.step(np.full((8, 2), 0.3))[1].sum())
            envs.close()
            return out

        def child(conn):
            conn.send(step_once())

        if __name__ == "__main__":
            envs = LegVectorEnv(8, num_threads=2)  # the parent's pool is alive at the fork
            envs.reset(seed=0)
            print("parent", float(envs.step(np.full((8, 2), 0.3))[1].sum()))
            for method in ("spawn", "fork"):
                ctx = mp.get_context(method)
                mine, theirs = ctx.Pipe()
                p = ctx.Process(target=child, args=(theirs,))
                p.start()
                p.join(300)
                print(method, mine.recv() if mine.poll() else f"died with exit code {p.exitcode}")
        """
    )
    script = Path(tempfile.mkdtemp()) / "fork_after_threads.py"
    script.write_text(code)
    environ = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=environ, cwd=ROOT, timeout=900)
    assert done.returncode == 0, done.stderr
    lines = dict(line.split(" ", 1) for line in done.stdout.strip().splitlines())
    assert lines["spawn"] == lines["parent"] == lines["fork"], done.stdout


# ---------------------------------------------------------------- g = 0


@pytest.mark.parametrize("contact", CONTACTS)
def test_zero_gravity_reports_the_contact_force_in_newtons(contact):
    """With ``g = 0`` there is no weight to divide by: obs[10:12] is the force in newtons (documented)."""
    env = LegEnv(params={"g": 0.0}, contact=contact, reset_noise_scale=0.0)
    env.reset(seed=0)
    obs, *_, info = env.step(np.array([0.3, -0.2]))
    np.testing.assert_allclose(obs[10:12], info["contact_force"].astype(np.float32), rtol=1e-6)
    assert np.abs(info["contact_force"]).max() > 0.1  # a force, not a rounding error
    weighted = LegEnv(contact=contact, reset_noise_scale=0.0)
    weighted.reset(seed=0)
    obs, *_, info = weighted.step(np.array([0.3, -0.2]))
    np.testing.assert_allclose(obs[10:12], (info["contact_force"] / weighted.params.weight).astype(np.float32), rtol=1e-6)
    doc = stance.__doc__
    assert "g = 0" in doc and "newtons" in doc
