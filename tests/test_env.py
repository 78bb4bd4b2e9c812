"""The single-robot Gymnasium env ``leg_env/PlanarLegStance-v0``: API, checkers, task semantics, robustness."""

import copy
import math
import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest

import leg_env
from leg_env import ENV_ID, LegEnv
from leg_env.physics.dynamics import com_position, contact_jacobian, foot_position
from leg_env.physics.params import LegParams
from leg_env.tasks.base import StanceConfig

REWARD_KEYS = ("reward_alive", "reward_drift", "reward_unilateral", "reward_friction", "reward_ctrl")
INFO_KEYS = ("contact_force", "normal_force", "unilateral_violation", "friction_violation", "numerical_failure", "ending", "base_drift", "foot_error")
# gymnasium's check_space_limit warns about any infinite Box bound; angles, rates and the contact force
# have no bound that holds in every reachable state (documented in the class docstring, "Observation Space")
DOCUMENTED_GYM_WARNINGS = (
    "A Box observation space minimum value is -infinity",
    "A Box observation space maximum value is infinity",
)
NON_DEFAULT = dict(
    params={"m_b": 12.0, "l2": 0.55},
    dt=0.02,
    substeps=6,
    torque_limit=(40.0, 45.0),
    alive_bonus=2.0,
    drift_position_weight=3.0,
    ctrl_cost_weight=0.1,
    mu=0.6,
    max_torso_angle=0.9,
    terminate_on_contact_loss=True,
    contact_loss_threshold=-5.0,
    reset_noise_scale=0.03,
    width=200,
    height=150,
)
INVALID_ARGS = [
    dict(alive_bonus=-1.0),
    dict(ctrl_cost_weight=-0.1),
    dict(mu=-0.5),
    dict(reset_noise_scale=-0.01),
    dict(dt=0.0),
    dict(substeps=0),
    dict(hip_range=(-1.0, -2.0)),
    dict(params={"m_b": -1.0}),
    dict(params={"mass": 1.0}),
    dict(params="heavy"),
    dict(config={"no_such_field": 1}),  # a bad value of config; an unknown keyword is a TypeError
    dict(torque_limit=10.0),  # the knee needs 24.1 N m to hold the nominal posture
    dict(min_base_height=2.0),  # the nominal posture would be a fall
    dict(render_mode="ansi"),
    dict(width=0),
    dict(height=12.5),
]
BAD_ACTIONS = [
    [np.nan, 0.0],
    [0.0, np.inf],
    [-np.inf, np.nan],
    [0.1, 0.2, 0.3],
    [[0.1, 0.2]],
    0.5,
    [],
    ["a", "b"],
]


def make(**kwargs) -> LegEnv:
    return LegEnv(**kwargs)


def holding_action(env: LegEnv) -> np.ndarray:
    """The action that applies the nominal equilibrium torques."""
    return env.nominal.tau / np.asarray(env.config.torque_limit)


def rollout(env, seed: int, actions: np.ndarray, resets: int = 3):
    """Observations, rewards, flags and infos of ``resets`` episodes driven by ``actions`` (reset on episode end)."""
    out = []
    obs, info = env.reset(seed=seed)
    out.append((obs, info))
    done = 0
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        out.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            done += 1
            if done == resets:
                break
            out.append(env.reset())
    return out


# ------------------------------------------------------------------ registration


def test_registration():
    spec = gym.spec(ENV_ID)
    assert spec.max_episode_steps == 1000
    assert spec.entry_point == "leg_env.envs.single:LegEnv" and spec.kwargs == {"task": "stance"}
    assert spec.vector_entry_point == "leg_env.envs.vector:LegVectorEnv"
    env = gym.make(ENV_ID)
    assert isinstance(env.unwrapped, LegEnv)
    assert env.spec.max_episode_steps == 1000


def test_make_with_module_prefix_without_prior_import():
    code = (
        "import sys, gymnasium as gym\n"
        "assert 'leg_env' not in sys.modules\n"
        "env = gym.make('leg_env:leg_env/PlanarLegStance-v0')\n"
        "obs, info = env.reset(seed=0)\n"
        "print(type(env.unwrapped).__name__, env.spec.max_episode_steps, obs.shape)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["LegEnv", "1000", "(12,)"]


def test_import_is_cheap_and_reimport_safe():
    code = (
        "import sys, importlib, leg_env\n"
        "assert 'pygame' not in sys.modules\n"
        "importlib.reload(leg_env)\n"
        "import gymnasium as gym\n"
        "env = gym.make('leg_env/PlanarLegStance-v0'); env.reset(seed=0); env.step(env.action_space.sample())\n"
        "assert 'pygame' not in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


# ------------------------------------------------------------------- checkers


def test_gymnasium_check_env():
    from gymnasium.utils.env_checker import check_env

    env = gym.make(ENV_ID)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)  # unwrapped, with its spec: checks every render mode too
    messages = [str(w.message) for w in caught]
    unexpected = [m for m in messages if not any(d in m for d in DOCUMENTED_GYM_WARNINGS)]
    assert unexpected == []


@pytest.mark.sb3
@pytest.mark.parametrize("wrapped", [False, True])
def test_sb3_check_env(wrapped):
    from stable_baselines3.common.env_checker import check_env

    env = gym.make(ENV_ID) if wrapped else make()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env, warn=True)


# --------------------------------------------------------------------- spaces


def test_spaces():
    env = make()
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    space = env.observation_space
    assert space.shape == (12,) and space.dtype == np.float32
    reach = np.float32(1.01 * (env.params.l1 + env.params.l2))
    np.testing.assert_array_equal(space.high[:2], [reach, reach])
    np.testing.assert_array_equal(space.low, -space.high)
    assert np.all(np.isinf(space.high[2:]))


# ------------------------------------------------------------ nominal posture


def test_nominal_reset_is_exact_equilibrium(params):
    env = make(reset_noise_scale=0.0)
    obs, info = env.reset(seed=7)
    q, qd, anchor = env.state
    np.testing.assert_array_equal(q, env.nominal.q)
    np.testing.assert_array_equal(qd, np.zeros(5))
    np.testing.assert_array_equal(anchor, np.zeros(2))
    assert q[2] == 0.0 and q[4] == pytest.approx(0.8)  # torso level, knee bent 0.8 rad
    assert com_position(q, params)[0] == pytest.approx(0.0, abs=1e-12)  # COM above the foot
    tau = env.nominal.tau
    assert abs(tau[0]) < 1e-9 and tau[1] == pytest.approx(-24.1, abs=0.05)
    np.testing.assert_allclose(info["contact_force"], [0.0, 147.15], atol=1e-9)
    np.testing.assert_allclose(obs[10:], [0.0, 1.0], atol=1e-7)
    np.testing.assert_array_equal(obs[:5], q.astype(np.float32))
    assert info["base_drift"] == 0.0 and info["foot_error"] < 1e-15


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_equilibrium_torques_hold_for_100_steps(dtype):
    env = gym.make(ENV_ID, reset_noise_scale=0.0)
    env.reset(seed=0)
    action = holding_action(env.unwrapped).astype(dtype)
    for _ in range(100):
        _, reward, terminated, truncated, info = env.step(action)
        assert not terminated and not truncated
        assert info["base_drift"] < 1e-3
        assert reward > 0.99 * env.unwrapped.config.alive_bonus
    np.testing.assert_allclose(info["contact_force"], [0.0, 147.15], atol=1e-3)


def test_zero_torques_fall_and_terminate():
    env = gym.make(ENV_ID, reset_noise_scale=0.0)
    env.reset(seed=0)
    for step in range(1, 201):
        _, reward, terminated, truncated, info = env.step(np.zeros(2))
        if terminated:
            break
    assert terminated and not truncated and step < 200
    assert info["reward_alive"] == 0.0  # the alive bonus is paid only on healthy steps
    assert not info["numerical_failure"]


def test_default_control_step_is_converged():
    """The documented convergence check: 1 s under smooth torques, default vs 8x finer RK4 steps."""
    start = {"qpos": np.array([0.0, 0.0, 0.01, -2.0122, 0.8]), "qvel": np.array([0.0, 0.0, 0.0, 0.05, 0.0])}
    finals = []
    for kwargs in ({}, {"substeps": 16, "max_angle": 0.005}):
        env = make(**kwargs)
        env.reset(seed=0, options=start)
        limit = np.asarray(env.config.torque_limit)
        for k in range(100):
            t = k * env.dt
            tau = env.nominal.tau + np.array([3.0 * np.sin(2 * np.pi * t), 5.0 * np.sin(3 * np.pi * t)])
            env.step(tau / limit)
        finals.append(env.state)
    assert np.max(np.abs(finals[0][0] - finals[1][0])) < 1e-7
    assert np.max(np.abs(finals[0][1] - finals[1][1])) < 1e-6


# ----------------------------------------------------------- rollout invariants


def test_env_physics_is_the_integrators_control_step():
    """Each env step is exactly ``integrate.stance_step`` with the clipped, scaled torques, across
    resets and explicit states (the task kernel keeps the state's sines/cosines between steps; a
    stale copy would show here)."""
    from leg_env.physics.integrate import stance_step

    env = make(torque_limit=(40.0, 60.0))
    rng = np.random.default_rng(5)
    for episode, options in enumerate((None, {"qpos": env.nominal.q + [0.0, 0.0, 0.02, -0.03, 0.05]}, None)):
        env.reset(seed=episode, options=options)
        for _ in range(60):
            q, qd, anchor = env.state
            action = rng.uniform(-1.3, 1.3, 2).astype(np.float32)
            obs, _, terminated, _, info = env.step(action)
            if info["numerical_failure"]:
                break
            tau = np.clip(action.astype(np.float64), -1.0, 1.0) * [40.0, 60.0]
            q_ref, qd_ref, lam_ref = stance_step(q, qd, tau, env.params, anchor=anchor)
            q_env, qd_env, _ = env.state
            np.testing.assert_array_equal(q_env, q_ref)
            np.testing.assert_array_equal(qd_env, qd_ref)
            np.testing.assert_array_equal(info["contact_force"], lam_ref)
            if terminated:
                break


def test_foot_stays_on_contact_point_over_1000_random_steps():
    env = make()
    env.reset(seed=3)
    _, _, anchor = env.state
    actions = np.random.default_rng(3).uniform(-1.0, 1.0, size=(1000, 2))
    worst = 0.0
    for a in actions:  # keep stepping after a fall: the pin holds whatever happens
        _, _, _, _, info = env.step(a)
        q, _, _ = env.state
        worst = max(worst, info["foot_error"], float(np.linalg.norm(foot_position(q, env.params) - anchor)))
    assert worst < 1e-9


def test_same_seed_same_rollouts_across_resets():
    actions = np.random.default_rng(11).uniform(-1.2, 1.2, size=(3000, 2))
    runs = [rollout(gym.make(ENV_ID), seed=5, actions=actions, resets=4) for _ in range(2)]
    assert len(runs[0]) == len(runs[1]) > 20
    for a, b in zip(*runs):
        assert len(a) == len(b)
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:-1] == b[1:-1]  # reward, terminated, truncated (or nothing after a reset)
        info_a, info_b = a[-1], b[-1]
        assert info_a.keys() == info_b.keys()
        for key in info_a:
            np.testing.assert_array_equal(info_a[key], info_b[key])
    other = rollout(gym.make(ENV_ID), seed=6, actions=actions, resets=1)
    assert not np.array_equal(other[0][0], runs[0][0][0])


def test_step_outputs_reward_terms_and_space():
    env = gym.make(ENV_ID)
    space = env.observation_space
    actions = np.random.default_rng(2).uniform(-1.5, 1.5, size=(2000, 2)).astype(np.float32)
    obs, info = env.reset(seed=2)
    assert obs in space and set(INFO_KEYS) <= info.keys()
    c = env.unwrapped.config
    weight = env.unwrapped.params.weight
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        assert type(reward) is float and type(terminated) is bool and type(truncated) is bool
        assert obs.dtype == np.float32 and obs in space
        terms = [info[k] for k in REWARD_KEYS]
        assert reward == sum(terms)
        assert all(type(t) is float for t in terms)
        assert set(INFO_KEYS) <= info.keys()
        lam_x, lam_y = info["contact_force"]
        assert info["normal_force"] == lam_y
        assert info["unilateral_violation"] == (lam_y < 0.0)
        assert info["friction_violation"] == (abs(lam_x) > c.mu * lam_y)
        assert info["reward_unilateral"] == pytest.approx(-c.unilateral_weight * max(0.0, -lam_y) / weight)
        assert info["reward_friction"] == pytest.approx(-c.friction_weight * max(0.0, abs(lam_x) - c.mu * lam_y) / weight)
        clipped = np.clip(a.astype(np.float64), -1.0, 1.0)
        assert info["reward_ctrl"] == pytest.approx(-c.ctrl_cost_weight * float(clipped @ clipped))
        assert info["reward_alive"] == (0.0 if terminated else c.alive_bonus)
        np.testing.assert_allclose(obs[10:], np.asarray(info["contact_force"], np.float32) / np.float32(weight), rtol=1e-6)
        if terminated or truncated:
            obs, info = env.reset()


def test_contact_violations_are_flagged_and_charged():
    env = make(reset_noise_scale=0.0)
    env.reset(seed=0)
    _, reward, _, _, info = env.step(np.array([0.0, 1.0]))  # full knee extension torque yanks the foot up
    assert info["normal_force"] < 0.0 and info["unilateral_violation"]
    assert info["reward_unilateral"] < 0.0
    env = make(reset_noise_scale=0.0, mu=0.1)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([1.0, 0.0]))
    assert info["normal_force"] > 0.0 and info["friction_violation"] and not info["unilateral_violation"]
    assert info["reward_friction"] < 0.0


def test_terminate_on_contact_loss():
    results = {}
    for flag in (False, True):
        env = make(reset_noise_scale=0.0, terminate_on_contact_loss=flag, contact_loss_threshold=100.0)
        env.reset(seed=0)
        _, _, terminated, _, info = env.step(np.array([-1.0, 0.0]))  # lam_y drops below 100 N
        assert info["normal_force"] < 100.0
        results[flag] = terminated, leg_env.ENDINGS[info["ending"]]
    assert results == {False: (False, "none"), True: (True, "contact_lost")}


def test_joint_range_termination():
    env = make(reset_noise_scale=0.0, knee_range=(0.05, 0.85))
    env.reset(seed=0)
    for _ in range(100):
        _, _, terminated, _, info = env.step(np.array([0.0, 1.0]))  # extra knee torque: the knee opens
        if terminated:
            break
        assert info["ending"] == 0
    q, _, _ = env.state
    assert terminated and q[4] > 0.85 and leg_env.ENDINGS[info["ending"]] == "knee_high"


def test_numerical_failure_restores_state_and_terminates():
    env = make(reset_noise_scale=0.0, max_rate=0.5)  # any rate above 0.5 rad/s counts as a blow-up
    obs0, _ = env.reset(seed=0)
    state0 = env.state
    obs, reward, terminated, truncated, info = env.step(np.array([1.0, 1.0]))
    assert terminated and not truncated and info["numerical_failure"]
    assert leg_env.ENDINGS[info["ending"]] == "numerical_failure"
    assert reward == 0.0 and all(info[k] == 0.0 for k in REWARD_KEYS)
    assert np.all(np.isfinite(obs)) and obs in env.observation_space
    np.testing.assert_array_equal(obs, obs0)
    for before, after in zip(state0, env.state):
        np.testing.assert_array_equal(before, after)


def test_out_of_range_actions_are_clipped():
    results = []
    for action in ([1.0, -1.0], [5.0, -70.0]):
        env = make()
        env.reset(seed=4)
        results.append(env.step(np.array(action)))
    np.testing.assert_array_equal(results[0][0], results[1][0])
    assert results[0][1] == results[1][1]


@pytest.mark.parametrize("action", BAD_ACTIONS, ids=repr)
def test_bad_actions_raise_and_leave_state(action):
    env = make()
    env.reset(seed=1)
    env.step(np.array([0.1, -0.2]))
    before = env.state
    with pytest.raises(ValueError, match="action"):
        env.step(action)
    for a, b in zip(before, env.state):
        np.testing.assert_array_equal(a, b)
    env.step(np.array([0.1, -0.2]))  # and it still steps


def test_bad_action_messages():
    env = make()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"non-finite entries: \['knee'\]"):
        env.step([0.0, np.nan])
    with pytest.raises(ValueError, match=r"shape \(2,\).*got shape \(1, 2\)"):
        env.step(np.zeros((1, 2)))


# ---------------------------------------------------------------- constructor


@pytest.mark.parametrize("kwargs", INVALID_ARGS, ids=lambda k: ",".join(f"{a}={b!r}" for a, b in k.items()))
def test_invalid_constructor_arguments(kwargs):
    with pytest.raises(ValueError):
        make(**kwargs)
    with pytest.raises(ValueError), warnings.catch_warnings():
        warnings.filterwarnings("ignore", ".*The environment is being initialised with render_mode")  # gym.make's own
        gym.make(ENV_ID, **kwargs)


@pytest.mark.parametrize("unknown", [{"frameskip": 1}, {"no_such_argument": 1, "alive_bonus": 2.0, "other": 2}])
def test_unknown_keyword_argument_is_a_type_error_naming_it(unknown):
    """As Python's own: wrappers (TorchRL's GymEnv passes frameskip) catch exactly this TypeError."""
    names = [k for k in unknown if k != "alive_bonus"]
    for build in (make, lambda **kw: gym.make(ENV_ID, **kw), lambda **kw: gym.make_vec(ENV_ID, num_envs=2, **kw)):
        with pytest.raises(TypeError, match="unexpected keyword argument") as error:
            build(**unknown)
        assert all(repr(name) in str(error.value) for name in names), error.value
    with pytest.raises(TypeError, match=r"got an unexpected keyword argument 'frameskip'"):
        make(frameskip=1)
    with pytest.raises(ValueError, match="alive_bonus"):  # a bad value stays a ValueError naming the field
        make(alive_bonus=-1.0)


def test_constructor_accepts_params_and_config_objects():
    p = LegParams(m_b=12.0)
    c = StanceConfig(mu=0.6)
    env = make(params=p, config=c, alive_bonus=3.0, torque_limit=60.0)
    assert env.params == p
    assert env.config == c.replace(alive_bonus=3.0, torque_limit=(60.0, 60.0))
    env = make(params={"m_b": 12.0}, config={"mu": 0.6})
    assert env.params == p and env.config.mu == 0.6


def test_render_fps_follows_dt():
    assert make().metadata["render_fps"] == 100
    env = make(dt=0.02)
    assert env.metadata["render_fps"] == 50 and env.dt == 0.02
    assert LegEnv.metadata["render_fps"] == 100  # the class default is untouched
    assert make(dt=0.003).metadata["render_fps"] == pytest.approx(1.0 / 0.003)


# ---------------------------------------------------------------------- reset


def test_reset_seed_determinism_and_noise():
    env = make()
    a, _ = env.reset(seed=10)
    b, _ = env.reset(seed=10)
    c, _ = env.reset(seed=11)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    q, qd, anchor = env.state
    s = env.config.reset_noise_scale
    assert np.all(np.abs(q[2:] - env.nominal.q[2:]) <= s) and np.all(np.abs(qd[2:]) <= s)
    np.testing.assert_array_equal(anchor, np.zeros(2))
    assert np.linalg.norm(foot_position(q, env.params)) < 1e-15
    np.testing.assert_allclose(contact_jacobian(q, env.params) @ qd, 0.0, atol=1e-15)


def test_reset_draws_six_uniforms_from_the_env_generator():
    """The documented reset: 6 draws of ``np_random.uniform(-s, s)`` on (th_b, q1, q2) and their rates."""
    env = make()
    env.reset(seed=123)
    q, qd, _ = env.state
    s = env.config.reset_noise_scale
    noise = np.random.Generator(np.random.PCG64(123)).uniform(-s, s, size=6)
    np.testing.assert_array_equal(q[2:], env.nominal.q[2:] + noise[:3])
    np.testing.assert_array_equal(qd[2:], noise[3:])
    # the generator advanced by exactly those draws
    after = np.random.Generator(np.random.PCG64(123))
    after.uniform(size=6)
    assert env.np_random.random() == after.random()


def test_reset_info_has_the_contact_keys():
    _, info = make().reset(seed=0)
    assert set(INFO_KEYS) <= info.keys() and not set(REWARD_KEYS) & info.keys()
    assert info["contact_force"].shape == (2,) and info["normal_force"] > 0.0
    assert info["numerical_failure"] is False and info["unilateral_violation"] is False


def test_reset_with_explicit_state(params):
    env = make()
    qpos = np.array([0.3, 1.0, 0.05, -1.9, 0.7])
    qvel = np.array([1.0, 2.0, 0.1, -0.2, 0.3])
    obs, info = env.reset(seed=0, options={"qpos": qpos, "qvel": qvel})
    q, qd, anchor = env.state
    np.testing.assert_allclose(q, qpos, atol=1e-15)
    np.testing.assert_allclose(anchor, foot_position(qpos, params), atol=1e-15)
    np.testing.assert_array_equal(qd[2:], qvel[2:])  # torso and joint rates kept
    np.testing.assert_allclose(contact_jacobian(q, params) @ qd, 0.0, atol=1e-14)  # base rates projected
    np.testing.assert_allclose(obs[:2], (q[:2] - anchor).astype(np.float32))
    assert info["foot_error"] < 1e-15
    # only qvel: from the nominal posture
    env.reset(options={"qvel": qvel})
    np.testing.assert_allclose(env.state[0], env.nominal.q, atol=1e-15)
    # explicit starts draw no random numbers: the next noisy reset is as after a seeded reset
    env.reset(seed=3)
    expected, _ = env.reset()
    env.reset(seed=3)
    env.reset(options={"qpos": qpos})
    got, _ = env.reset()
    np.testing.assert_array_equal(expected, got)


@pytest.mark.parametrize(
    "options",
    [{"qpos": np.zeros(4)}, {"qvel": [0, 0, np.nan, 0, 0]}, {"qpos": "up"}, {"qpos": np.zeros(5), "start": 1}, {"state": 1}],
    ids=repr,
)
def test_reset_with_bad_options_raises(options):
    with pytest.raises(ValueError, match="option"):
        make().reset(seed=0, options=options)


# ------------------------------------------------------------------ truncation


def test_truncation_only_through_the_time_limit():
    env = gym.make(ENV_ID, max_episode_steps=5, reset_noise_scale=0.0)
    env.reset(seed=0)
    action = holding_action(env.unwrapped)
    flags = [env.step(action)[2:4] for _ in range(5)]
    assert flags == [(False, False)] * 4 + [(False, True)]


# -------------------------------------------------------------------- pickling


def test_pickle_round_trip_keeps_arguments_and_state():
    env = make(render_mode="rgb_array", **NON_DEFAULT)
    env.reset(seed=9)
    env.step(np.array([0.2, -0.3]))
    for clone in (pickle.loads(pickle.dumps(env)), copy.deepcopy(env)):
        assert clone.params == env.params and clone.params.m_b == 12.0 and clone.params.l2 == 0.55
        assert clone.config == env.config
        assert clone.config.mu == 0.6 and clone.config.dt == 0.02 and clone.config.torque_limit == (40.0, 45.0)
        assert clone.config.terminate_on_contact_loss is True and clone.config.reset_noise_scale == 0.03
        assert (clone.width, clone.height, clone.render_mode) == (200, 150, "rgb_array")
        assert clone.metadata["render_fps"] == 50
        assert clone.observation_space == env.observation_space
        for a, b in zip(clone.state, env.state):
            np.testing.assert_array_equal(a, b)
    # the copy continues the same trajectory, resets included
    clone = pickle.loads(pickle.dumps(env))
    actions = np.random.default_rng(0).uniform(-1, 1, size=(200, 2))
    for a in actions:
        ra, rb = env.step(a), clone.step(a)
        np.testing.assert_array_equal(ra[0], rb[0])
        assert ra[1:4] == rb[1:4]
        if ra[2]:
            np.testing.assert_array_equal(env.reset()[0], clone.reset()[0])


def test_pickle_through_make():
    env = gym.make(ENV_ID, mu=0.5, torque_limit=30.0)
    env.reset(seed=0)
    clone = pickle.loads(pickle.dumps(env))
    assert clone.unwrapped.config.mu == 0.5 and clone.unwrapped.config.torque_limit == (30.0, 30.0)
    assert clone.spec.max_episode_steps == 1000


# ------------------------------------------------------------------------ soak


def test_random_action_soak_100k_steps():
    env = gym.make(ENV_ID)
    space = env.observation_space
    actions = np.random.default_rng(123).uniform(-1.3, 1.3, size=(100_000, 2)).astype(np.float32)
    observations = np.empty((actions.shape[0], 12), dtype=np.float32)
    env.reset(seed=123)
    episodes = 0
    for i, a in enumerate(actions):
        observations[i], _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            episodes += 1
            env.reset()
    assert episodes > 100
    assert np.all(np.isfinite(observations))
    assert np.all(observations >= space.low) and np.all(observations <= space.high)


def test_public_names():
    assert leg_env.LegEnv is LegEnv and leg_env.LegVectorEnv is leg_env.envs.vector.LegVectorEnv
    assert leg_env.ENDINGS[0] == "none" and len(set(leg_env.ENDINGS)) == len(leg_env.ENDINGS) == 10
    assert leg_env.StanceConfig is StanceConfig
    assert math.isclose(make().dt, 0.01)
