"""Domain randomisation (``leg_env.randomize``): a robot per sub-env, drawn at reset, in every task."""

import json
import pickle
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import leg_env
from leg_env.physics.contact import mu_critical
from leg_env.physics.dynamics import static_equilibrium, stance_dynamics
from leg_env.physics.hybrid import hybrid_step
from leg_env.physics.integrate import stance_step
from leg_env.physics.params import PARAM_NAMES, LegParams
from leg_env.randomize import DEFAULT_RANGES, FIELDS, MAX_DRAWS
from test_tasks import _as_sync_info, _strings_as_objects
from test_vector import SEED, STEPS, assert_same, random_actions

ROOT = Path(__file__).resolve().parents[1]
TASK_IDS = leg_env.ENV_IDS
BALANCE = "leg_env/PlanarLegBalance-v1"
N = 6


def robot(info_params: dict, i: int | None = None) -> tuple[LegParams, float, np.ndarray]:
    """``(LegParams, mu, torque limits)`` of one robot from ``info["params"]`` (row ``i`` of a vector's)."""
    value = (lambda k: info_params[k]) if i is None else (lambda k: float(info_params[k][i]))
    p = LegParams(**{name: value(name) for name in PARAM_NAMES})
    return p, value("mu"), np.array([value("hip_torque_limit"), value("knee_torque_limit")])


# ------------------------------------------------------------------ off by default: nothing changes


def test_without_randomize_the_shipped_lqr_evaluation_reproduces_bit_for_bit():
    """randomize=None draws nothing and changes nothing: the shipped balance LQR episodes, exactly."""
    from policies.lqr import LQRController

    shipped = json.loads((ROOT / "policies/baselines/lqr_balance/lqr.json").read_text())
    env = gym.make(BALANCE)
    policy = LQRController(env.unwrapped.params, env.unwrapped.config)
    for episode in shipped["per_episode"][:8]:
        obs, info = env.reset(seed=episode["seed"])
        assert "params" not in info
        total, length, done = 0.0, 0, False
        while not done:
            obs, reward, terminated, truncated, info = env.step(policy.predict(obs)[0])
            total += reward
            length += 1
            done = terminated or truncated
        assert length == episode["length"]
        assert round(total, 4) == episode["return"]


def test_without_randomize_there_is_one_robot_row_and_no_params_key():
    envs = gym.make_vec(BALANCE, num_envs=3)
    _, info = envs.reset(seed=0)
    assert "params" not in info and envs.unwrapped._robots.shape[0] == 1


# ------------------------------------------------------------------ parity


@pytest.mark.parametrize("env_id", TASK_IDS)
@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_randomised_vector_env_equals_sync_vector_env_of_single_envs(env_id, mode):
    """Sub-env i with randomisation is a single env with the same seed and settings, bit for bit: the
    observations, rewards, flags and the whole info, ``params`` included, across autoresets."""
    kwargs = dict(randomize=True, max_episode_steps=25)
    ours = gym.make_vec(env_id, num_envs=4, autoreset_mode=mode, **kwargs)
    sync = gym.make_vec(env_id, num_envs=4, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, **kwargs)
    reset_ours, reset_sync = ours.reset(seed=SEED), sync.reset(seed=SEED)
    assert_same((reset_ours[0], _strings_as_objects(reset_ours[1])), reset_sync, "reset")
    assert len(set(reset_ours[1]["params"]["m_b"].tolist())) == 4  # four different robots
    resets = 0
    for t, actions in enumerate(random_actions(STEPS, 4, seed=3)):
        step_ours, step_sync = ours.step(actions), sync.step(actions)
        assert_same((*step_ours[:4], _as_sync_info(step_ours[4], ours.unwrapped.reward_keys)), step_sync, f"step {t}")
        resets += int("params" in step_ours[4])
    assert resets >= 3


@pytest.mark.parametrize("contact", ["pinned", "unilateral"])
def test_each_sub_env_runs_leg_env_dynamics_with_its_drawn_parameters(contact):
    """A batch of different robots against stacked single calls of ``leg_env.physics.dynamics`` / the integrators:
    the start at each robot's own equilibrium and holding force, then one control step."""
    envs = gym.make_vec("leg_env/PlanarLegStance-v0", num_envs=N, randomize=True, contact=contact, reset_noise_scale=0.0)
    env = envs.unwrapped
    obs, info = envs.reset(seed=5)
    q0, qd0, anchor0 = env.state
    mode0 = env.contact_mode
    actions = np.random.default_rng(0).uniform(-1, 1, (N, 2))
    envs.step(actions)
    q1, qd1, _ = env.state
    for i in range(N):
        p, mu, limits = robot(info["params"], i)
        q_nom, tau_nom, lam_nom = static_equilibrium(p, env.config.nominal_knee)
        np.testing.assert_array_equal(q0[i] - np.r_[anchor0[i], 0, 0, 0], q_nom)
        _, lam = stance_dynamics(q0[i], qd0[i], tau_nom, p)
        np.testing.assert_allclose(info["contact_force"][i], lam, rtol=0, atol=1e-9 * p.weight)
        np.testing.assert_allclose(lam, lam_nom, rtol=0, atol=1e-9 * p.weight)
        tau = actions[i] * limits
        if contact == "pinned":
            q, qd, _ = stance_step(q0[i], qd0[i], tau, p, dt=env.config.dt, anchor=anchor0[i])
        else:
            r = hybrid_step(q0[i], qd0[i], tau, p, mu, mode=int(mode0[i]), anchor_x=anchor0[i, 0], dt=env.config.dt)
            q, qd = r.q, r.qd
        np.testing.assert_allclose(q1[i], q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(qd1[i], qd, rtol=0, atol=1e-10)
    # the robots differ, so the same step from the same kind of start gives different states
    assert np.ptp(q1[:, 3]) > 1e-6


# ------------------------------------------------------------------ the draw


def test_defaults_stay_in_their_ranges_and_never_compound():
    env = gym.make(BALANCE, randomize=True)
    nominal = {**{n: getattr(LegParams(), n) for n in PARAM_NAMES}, "mu": 0.5, "hip_torque_limit": 40.0, "knee_torque_limit": 40.0}
    nominal["hip_torque_limit"], nominal["knee_torque_limit"] = env.unwrapped.config.torque_limit
    seen = {name: [] for name in FIELDS}
    env.reset(seed=0)
    for _ in range(300):
        _, info = env.reset()
        for name in FIELDS:
            seen[name].append(info["params"][name])
    for name in FIELDS:
        values = np.array(seen[name])
        if name not in DEFAULT_RANGES:
            assert (values == nominal[name]).all(), name
            continue
        kind, lo, hi = DEFAULT_RANGES[name]
        ends = (nominal[name] * lo, nominal[name] * hi) if kind == "scale" else (nominal[name] + lo, nominal[name] + hi)
        assert ends[0] <= values.min() and values.max() <= ends[1], name
        assert values.max() - values.min() > 0.8 * (ends[1] - ends[0]), name  # the range is covered: no drift
    assert np.corrcoef(seen["m_b"][:-1], seen["m_b"][1:])[0, 1] < 0.2  # fresh draws, not a walk


def test_infeasible_robots_are_redrawn_and_counted():
    """Knee limits down to 30% of nominal cannot hold the nominal posture (it needs ~48%): those robots are
    refused and drawn again; every robot that runs holds its posture, and the refusals are counted."""
    env = gym.make("leg_env/PlanarLegStance-v0", randomize={"knee_torque_limit": ("scale", 0.3, 1.0), "m_b": ("scale", 0.8, 1.2)})
    env.reset(seed=1)
    rejected = 0
    for _ in range(200):
        _, info = env.reset()
        p, _, limits = robot(info["params"])
        _, tau, _ = static_equilibrium(p, env.unwrapped.config.nominal_knee)
        assert np.all(np.abs(tau) <= limits)
        rejected += info["params_rejected"]
        assert 0 <= info["params_rejected"] < MAX_DRAWS
    assert rejected > 20


def test_painleve_prone_friction_is_refused_on_the_unilateral_ground():
    """mu from 0.7 to 1.2 straddles the Painleve bound at the nominal posture (about 1.0): robots at or past it are
    redrawn, so every robot that runs has mu below its own bound there; on the pinned ground mu is kept."""
    ranges = {"mu": ("range", 0.7, 1.2), "m1": ("scale", 0.8, 1.2)}
    env = gym.make(BALANCE, randomize=ranges)
    env.reset(seed=2)
    rejected = 0
    for _ in range(100):
        _, info = env.reset()
        p, mu, _ = robot(info["params"])
        q_nom = static_equilibrium(p, env.unwrapped.config.nominal_knee)[0]
        assert mu < mu_critical(q_nom, p)
        rejected += info["params_rejected"]
    assert rejected > 10
    pinned = gym.make("leg_env/PlanarLegStance-v0", randomize=ranges)
    pinned.reset(seed=2)
    assert max(pinned.reset()[1]["params"]["mu"] for _ in range(100)) > 1.05


@pytest.mark.parametrize(
    "randomize, error, match",
    [
        ({"mass": ("scale", 0.8, 1.2)}, ValueError, "unknown field"),
        ({"m_b": ("stretch", 0.8, 1.2)}, ValueError, "unknown kind"),
        ({"m_b": ("scale", 1.2, 0.8)}, ValueError, "above high"),
        ({"m_b": ("scale", float("nan"), 1.2)}, ValueError, "m_b"),
        ({"m_b": ("scale", -1.0, 1.2)}, ValueError, "m_b"),
        ({"c1": ("offset", -0.3, 0.0)}, ValueError, "c1"),
        ({"mu": ("range", -0.1, 0.5)}, ValueError, "mu"),
        ({"knee_torque_limit": ("range", 1.0, 5.0)}, ValueError, "hold their nominal posture"),
        ({"m_b": "0.8-1.2"}, TypeError, "m_b"),
        ("yes", TypeError, "randomize"),
    ],
)
def test_bad_ranges_raise_naming_the_field(randomize, error, match):
    with pytest.raises(error, match=match):
        gym.make(BALANCE, randomize=randomize)
    with pytest.raises(error, match=match):
        gym.make_vec(BALANCE, num_envs=2, randomize=randomize)


# ------------------------------------------------------------------ explicit robots


def test_reset_option_params_sets_a_robot_for_one_episode():
    env = gym.make(BALANCE)
    _, info = env.reset(seed=0, options={"params": {"m_b": 12.0, "mu": 0.3}})
    assert info["params"]["m_b"] == 12.0 and info["params"]["mu"] == 0.3 and info["params"]["m1"] == 3.0
    assert "params_rejected" not in info
    q = env.unwrapped.state[0]
    assert env.unwrapped.robot_params.m_b == 12.0
    heavier = static_equilibrium(LegParams(m_b=12.0), 0.8)[0]
    np.testing.assert_allclose(q[3:], heavier[3:], atol=0.06)  # the heavier robot's own posture (plus the noise)
    _, info = env.reset(seed=0)
    assert "params" not in info and env.unwrapped.robot_params == LegParams()
    obs_a = env.reset(seed=4)[0]
    obs_b = gym.make(BALANCE).reset(seed=4)[0]
    np.testing.assert_array_equal(obs_a, obs_b)  # back to the nominal robot exactly


def test_vector_reset_option_params_per_sub_env_and_masked_info():
    envs = gym.make_vec(BALANCE, num_envs=3, autoreset_mode=AutoresetMode.DISABLED)
    _, info = envs.reset(seed=0, options={"params": {"m_b": np.array([9.0, 10.0, 11.0])}})
    np.testing.assert_array_equal(info["params"]["m_b"], [9.0, 10.0, 11.0])
    assert info["_params"].all()
    mask = np.array([False, True, False])
    _, info = envs.reset(options={"reset_mask": mask, "params": {"g": 9.0}})
    np.testing.assert_array_equal(info["_params"], mask)
    assert info["params"]["g"][1] == 9.0
    _, info = envs.reset(options={"reset_mask": mask})  # the nominal robot again: no params key
    assert "params" not in info
    assert envs.unwrapped._robots[1] == envs.unwrapped.robots.base[0]


@pytest.mark.parametrize(
    "params, match",
    [
        ({"mass": 1.0}, "unknown field"),
        ({"m_b": -1.0}, "'m_b'"),
        ({"m_b": float("inf")}, "'m_b'"),
        ({"knee_torque_limit": 5.0}, "cannot run its nominal posture"),
        ({"mu": 1.5}, "Painleve"),
    ],
)
def test_bad_reset_params_raise_and_change_nothing(params, match):
    env = gym.make(BALANCE)
    env.reset(seed=0)
    env.step(np.array([0.1, -0.1], dtype=np.float32))
    before = env.unwrapped.state
    with pytest.raises(ValueError, match=match):
        env.reset(options={"params": params})
    for a, b in zip(before, env.unwrapped.state):
        np.testing.assert_array_equal(a, b)
    env.step(np.array([0.1, -0.1], dtype=np.float32))  # still running


# ------------------------------------------------------------------ the rest of the contract


def test_pickled_randomised_env_continues_identically():
    env = gym.make("leg_env/PlanarLegPush-v2", randomize=True).unwrapped
    env.reset(seed=3)
    clone = pickle.loads(pickle.dumps(env))
    for a in random_actions(60, 1, seed=4)[:, 0]:
        out_a, out_b = env.step(a), clone.step(a)
        assert_same(out_a, out_b, "step")
        if out_a[2]:
            assert_same(env.reset(), clone.reset(), "reset")


@pytest.mark.sb3
def test_sb3_adapter_takes_randomize_and_reports_the_robots():
    from leg_env.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env(3, seed=0, env_id=BALANCE, randomize=True)
    venv.reset()
    masses = [info["params"]["m_b"] for info in venv.reset_infos]
    assert len(set(masses)) == 3
    for actions in random_actions(40, 3, seed=5):
        _, _, dones, _ = venv.step(actions)
        for i in np.flatnonzero(dones):
            assert "params" in venv.reset_infos[i]


def test_gymnasium_env_checker_passes_with_randomisation():
    from gymnasium.utils.env_checker import check_env

    for env_id in TASK_IDS:
        check_env(gym.make(env_id, randomize=True).unwrapped, skip_render_check=True)
