"""The unilateral contact model: hybrid-step identities, the Painleve and Zeno rules, and the env contract.

The physics against independent references is in ``test_contact_reference.py`` (closed forms) and
``test_hybrid_reference.py`` (event-driven SciPy); here: energy balance over long hybrid runs, the
ground and cone invariants, bounded events, the Painleve rule, and the env option ``contact="unilateral"``
(resets in world coordinates, vector/single parity, determinism, pickling, checkers, SB3, soak).
"""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env

import leg_env
from leg_env import physics as dyn
from leg_env.physics.contact import STICK
from leg_env.physics.hybrid import LOG_SIZE, MAX_EVENTS, hybrid_step
from leg_env.physics.params import LegParams

UNI = {"contact": "unilateral"}
ENERGY_RTOL = 1e-6  # energy balance over 10 s, relative to the initial energy
SOAK_STEPS = 100_000


def energy(q, qd, p):
    return float(dyn.kinetic_energy(q, qd, p) + dyn.potential_energy(q, p))


@pytest.fixture(scope="module")
def hopping_run():
    """10 s of random torques (holding torques +- 40 N m, a new draw every step) from the nominal posture:
    the robot lifts off, flies, lands, slips and falls, stepped by hybrid_step; every step's record.

    The step is halved (``max_angle = 0.01``, 4 substeps): the balance then isolates the hybrid
    bookkeeping from RK4's own error, which at the default step reaches a few 1e-6 of E0 in this flailing
    run and falls at RK4's order as the step shrinks (README, "Unilateral contact")."""
    p = LegParams()
    q, tau_hold, _ = dyn.static_equilibrium(p)
    qd = np.zeros(5)
    mode, anchor = STICK, 0.0
    rng = np.random.default_rng(0)
    records = []
    for _ in range(1000):
        tau = tau_hold + rng.uniform(-40.0, 40.0, 2)
        r = hybrid_step(q, qd, tau, p, 0.5, mode, anchor, max_angle=0.01, substeps=4)
        records.append((q, qd, r))
        q, qd, mode, anchor = r.q, r.qd, r.mode, r.anchor_x
    return p, records


def test_energy_balance_over_ten_seconds_with_liftoffs_and_touchdowns(hopping_run):
    p, records = hopping_run
    kinds = np.concatenate([r.event_kind for _, _, r in records])
    assert np.sum(kinds == 0) >= 5 and np.sum(kinds == 3) >= 5, "the run must lift off and land several times"
    q0, qd0, _ = records[0]
    last = records[-1][2]
    e0 = energy(q0, qd0, p)
    work = sum(float(r.work) for _, _, r in records)
    losses = sum(float(r.slip_dissipation + r.impact_dissipation) for _, _, r in records)
    residual = energy(last.q, last.qd, p) - e0 - (work - losses)
    assert abs(residual) <= ENERGY_RTOL * abs(e0), f"energy balance residual {residual:.3e} J of E0 = {e0:.3f} J"
    assert sum(float(r.impact_dissipation) for _, _, r in records) > 0.0


def test_ground_and_force_invariants(hopping_run):
    p, records = hopping_run
    dt = 0.01
    for k, (_, _, r) in enumerate(records):
        y_f = dyn.foot_position(r.q, p)[1]
        assert y_f >= -1e-9, f"step {k}: foot below the ground by {y_f:.3e} m"
        lam = r.lam_mean
        # the mean of forces that are each in the cone is in the cone; flight contributes zero
        assert lam[1] >= -1e-9 * p.weight, f"step {k}: the ground pulled, lam = {lam}"
        assert abs(lam[0]) <= 0.5 * lam[1] + 1e-9 * p.weight, f"step {k}: force outside the cone, lam = {lam}"
        if r.flight_time == pytest.approx(dt, abs=1e-15):
            assert np.all(lam == 0.0), f"step {k}: force in flight {lam}"
        assert r.stick_time + r.slip_time + r.flight_time == pytest.approx(dt, abs=1e-12)
        impulse = r.impulse
        # impacts are in the cone; a sliding stop adds a sticking impulse of round-off size (< 1e-9 N s)
        assert impulse[1] >= -1e-9 and abs(impulse[0]) <= 0.5 * impulse[1] + 1e-9
        if r.mode == STICK:
            assert abs(dyn.foot_position(r.q, p)[0] - r.anchor_x) <= 1e-12


def test_zero_torque_drop_ends_with_bounded_events():
    """A drop with zero torques: the robot collapses; every step finishes within the event cap."""
    p = LegParams()
    q, _, _ = dyn.static_equilibrium(p)
    q = q + np.array([0.0, 0.2, 0.1, 0.0, 0.0])
    qd = np.array([0.5, -1.0, 0.0, 2.0, -3.0])
    mode, anchor = None, None
    for k in range(300):
        r = hybrid_step(q, qd, np.zeros(2), p, 0.5, mode, anchor)
        assert r.events <= 2 * MAX_EVENTS <= LOG_SIZE
        assert np.all(np.isfinite(r.q)) and np.all(np.isfinite(r.qd))
        assert dyn.foot_position(r.q, p)[1] >= -1e-9
        q, qd, mode, anchor = r.q, r.qd, r.mode, r.anchor_x


def test_painleve_rule_fires_past_the_bound_and_is_counted():
    """A foot sliding where k_sigma < 0 (mu above mu_critical) and pushed into the ground: no consistent force."""
    p = LegParams()
    q = np.array([0.0, 0.0, -0.45, -0.925, 0.05])  # the notes' worst posture, mu_critical about 0.52
    q[1] -= dyn.foot_position(q, p)[1]
    mu = 0.9
    assert dyn.mu_critical(q, p) < mu
    lam_c, _ = dyn.free_foot_acceleration(q, np.zeros(5), np.zeros(2), p)
    sigma = np.sign(lam_c[0, 1])  # k_sigma = Lyy - sigma mu Lxy < 0 for this direction
    assert lam_c[1, 1] - sigma * mu * lam_c[0, 1] < 0.0
    J = dyn.contact_jacobian(q, p)
    qd = np.linalg.lstsq(J, np.array([0.3 * sigma, 0.0]), rcond=None)[0]  # the foot slides along the ground
    tau = np.array([0.0, -20.0])
    _, a0 = dyn.free_foot_acceleration(q, qd, tau, p)
    assert a0[1] < 0.0, "the torques must push the foot into the ground"
    r = hybrid_step(q, qd, tau, p, mu, None, None)
    assert r.painleve >= 1
    assert dyn.foot_position(r.q, p)[1] >= -1e-9
    # below the bound the same slide is well posed and never counted
    r_ok = hybrid_step(q, qd, tau, p, 0.3, None, None)
    assert r_ok.painleve == 0


def test_a_foot_leaving_the_ground_from_a_round_off_below_it_lands_again_at_a_located_touchdown():
    """A sliding foot at y_f = -5.6e-16 (the round-off of its contact projection) that leaves the ground and comes
    back down within the step: its touchdown is located (the foot ends on the ground, not 2e-5 m below it, which
    the next step would refuse). The state was found by the reference recording (tests/reference/record.py)."""
    p = LegParams()
    q = np.array([-0.2071468465217468, -0.6926806097296976, -3.1489865732354807, 11.936113891382774, -20.442604387229775])
    qd = np.array([1.3505218683398479, 1.4283855011302726, -5.418527068977169, 12.021300818954591, -2.608687132438418])
    tau = np.array([-19.164609248729857, 2.4460877515398494])
    assert -1e-15 < dyn.foot_position(q, p)[1] < 0.0
    r = hybrid_step(q, qd, tau, p, 0.43948274465913995, mode=2, anchor_x=-0.3023751071739096)
    assert abs(dyn.foot_position(r.q, p)[1]) < 1e-12
    assert r.events >= 1 and 3 in r.event_kind.tolist()  # a touchdown
    hybrid_step(r.q, r.qd, tau, p, 0.43948274465913995, mode=r.mode, anchor_x=r.anchor_x)  # the next step takes the state


def test_batched_hybrid_step_equals_stacked_singles_bitwise():
    p = LegParams()
    rng = np.random.default_rng(3)
    q0, tau0, _ = dyn.static_equilibrium(p)
    q = q0 + rng.uniform(-0.2, 0.2, (12, 5)) * np.array([0, 0, 1, 1, 1])
    q[:, 1] -= dyn.foot_position(q, p)[:, 1] - rng.uniform(0.0, 0.05, 12) * (np.arange(12) % 2)
    qd = rng.normal(0, 0.5, (12, 5))
    tau = tau0 + rng.uniform(-30, 30, (12, 2))
    batch = hybrid_step(q, qd, tau, p, 0.5)
    for i in range(12):
        single = hybrid_step(q[i], qd[i], tau[i], p, 0.5)
        for name, a, b in zip(batch._fields, batch, single):
            np.testing.assert_array_equal(a[i], b, err_msg=f"robot {i}, {name}")


# ---------------------------------------------------------------- the env option


def test_the_controllers_calls_take_the_same_step_through_fewer_checks():
    """The calls a controller's loop makes (float64 ``(N, 5)`` states and ``(N, 2)`` torques, int64 modes, a number
    ``mu``, a number or ``(N,)`` load) skip the argument conversions but not their outcome: the step and its Jacobians
    equal those of the same arguments given as lists (the full checks) bit for bit, over rollout states through every
    mode; and such arrays holding what the checks refuse get the checks' errors, nothing changed."""
    from leg_env.physics.derivatives import hybrid_step_jacobians
    from leg_env.physics.hybrid import _fast_call

    p, mu = LegParams(), 0.5
    envs = gym.make_vec("leg_env/PlanarLegHop-v4", num_envs=32, vectorization_mode="vector_entry_point")
    envs.reset(seed=3)
    rng = np.random.default_rng(0)
    seen = set()
    for _ in range(40):
        e = envs.unwrapped
        (q, qd, _), mode = e.state, e.contact_mode
        seen.update(mode.tolist())
        tau = rng.uniform(-50.0, 50.0, (32, 2))
        for load in (0.0, rng.uniform(-60.0, 60.0, 32)):
            assert _fast_call(q, qd, tau, p, mu, mode, None, 0.01, 2, 0.02, load) is not None
            listed = dict(load_x=load if np.isscalar(load) else load.tolist())
            a, b = hybrid_step(q, qd, tau, p, mu, mode, load_x=load), hybrid_step(q, qd, tau, p, mu, mode.tolist(), **listed)
            assert all(np.array_equal(x, y, equal_nan=True) for x, y in zip(a, b))
            ja = hybrid_step_jacobians(q, qd, tau, p, mu, mode, load_x=load)
            jb = hybrid_step_jacobians(q, qd, tau, p, mu, mode.tolist(), **listed)
            assert np.array_equal(ja.A, jb.A, equal_nan=True) and np.array_equal(ja.B, jb.B, equal_nan=True)
        envs.step(rng.uniform(-1.0, 1.0, (32, 2)))
    assert seen == {0, 1, 2, 3}  # stick, slip either way, flight
    q0, qd0, tau0, mode0 = q.copy(), qd.copy(), tau.copy(), mode.copy()
    bad_q, bad_tau, bad_mode = q.copy(), tau.copy(), mode.copy()
    bad_q[1, 2], bad_tau[0, 1], bad_mode[2] = np.nan, np.inf, 7
    low = q.copy()
    low[0, 1] -= 2.0  # the foot a metre and more below the ground
    for args, message in (((bad_q, qd, tau, p, mu, mode), "q must be finite"),
                          ((q, qd, bad_tau, p, mu, mode), "tau must be finite"),
                          ((q, qd, tau, p, mu, bad_mode), "mode must be one of"),
                          ((q, qd, tau, p, float("nan"), mode), "mu must be"),
                          ((low, qd, tau, p, mu, mode), "below the ground")):
        with pytest.raises(ValueError, match=message):
            hybrid_step(*args)
        with pytest.raises(ValueError, match="load_x must be finite"):
            hybrid_step(q, qd, tau, p, mu, mode, load_x=np.full(32, np.inf))
    for before, now in ((q0, q), (qd0, qd), (tau0, tau), (mode0, mode)):
        np.testing.assert_array_equal(now, before)


def test_default_is_pinned_and_unilateral_changes_spaces_and_mu():
    pinned = gym.make(leg_env.ENV_ID).unwrapped
    uni = gym.make(leg_env.ENV_ID, **UNI).unwrapped
    assert pinned.config.contact == "pinned" and pinned.config.mu == 0.8
    assert pinned.observation_space.shape == (12,)
    assert uni.config.mu == 0.5 and uni.observation_space.shape == (18,)
    assert gym.make(leg_env.ENV_ID, contact="unilateral", mu=0.3).unwrapped.config.mu == 0.3
    with pytest.raises(ValueError, match="contact"):
        gym.make(leg_env.ENV_ID, contact="soft")


def test_reset_in_world_coordinates():
    env = gym.make(leg_env.ENV_ID, **UNI)
    p = env.unwrapped.params
    q_nom = env.unwrapped.nominal.q
    up = q_nom + np.array([0.3, 0.1, 0.0, 0.0, 0.0])
    obs, info = env.reset(options={"qpos": up})
    assert info["contact_mode"] == "flight" and obs[15] == 0.0
    assert obs[12] == pytest.approx(0.1) and info["foot_height"] == pytest.approx(0.1)
    q, qd, anchor = env.unwrapped.state
    np.testing.assert_allclose(q, up)  # world coordinates: nothing is moved
    assert anchor[1] == 0.0
    on = q_nom + np.array([0.3, 5e-10, 0.0, 0.0, 0.0])
    obs, info = env.reset(options={"qpos": on})
    assert info["contact_mode"] == "stick" and obs[15] == 1.0
    assert dyn.foot_position(env.unwrapped.state[0], p)[1] == pytest.approx(0.0, abs=1e-15)
    assert env.unwrapped.state[2][0] == pytest.approx(0.3)
    with pytest.raises(ValueError, match="below the ground"):
        env.reset(options={"qpos": q_nom - np.array([0.0, 1e-6, 0.0, 0.0, 0.0])})


def test_observation_and_info_describe_the_contact():
    env = gym.make(leg_env.ENV_ID, **UNI)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    seen = set()
    for _ in range(400):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 2))
        mode = info["contact_mode"]
        seen.add(mode)
        assert obs[15] == (0.0 if mode == "flight" else 1.0)
        assert (obs[16] != 0.0) == (mode == "slip")
        assert obs[12] == pytest.approx(info["foot_height"], abs=1e-6)
        assert info["stick_time"] + info["slip_time"] + info["flight_time"] == pytest.approx(0.01, abs=1e-12)
        assert info["reward_unilateral"] == pytest.approx(-10.0 * info["flight_time"] / 0.01)
        assert info["reward_friction"] == pytest.approx(-10.0 * info["slip_distance"] / 0.01)
        terms = ("reward_alive", "reward_drift", "reward_unilateral", "reward_friction", "reward_ctrl")
        assert reward == sum(info[k] for k in terms)
        assert not info["unilateral_violation"] and info["painleve_fallbacks"] == 0
        if terminated or truncated:
            env.reset()
    assert seen == {"stick", "slip", "flight"}


def test_unilateral_vector_equals_singles_bitwise():
    n, steps = 8, 150
    rng = np.random.default_rng(1)
    actions = rng.uniform(-1, 1, (steps, n, 2))
    venv = gym.make_vec(leg_env.ENV_ID, num_envs=n, **UNI)
    obs, info = venv.reset(seed=7)
    singles = [gym.make(leg_env.ENV_ID, **UNI) for _ in range(n)]
    for i, env in enumerate(singles):
        o, inf = env.reset(seed=7 + i)
        np.testing.assert_array_equal(obs[i], o)
        assert info["contact_mode"][i] == inf["contact_mode"]
    ended = [False] * n
    for t in range(steps):
        obs, reward, term, trunc, info = venv.step(actions[t])
        for i, env in enumerate(singles):
            if ended[i]:
                o, inf = env.reset()
                r, ended[i] = 0.0, False
            else:
                o, r, te, tr, inf = env.step(actions[t, i])
                ended[i] = te or tr
                for key in ("contact_mode", "energy", "flight_time", "slip_distance", "contact_events"):
                    assert info[key][i] == inf[key], (t, i, key)
                np.testing.assert_array_equal(info["impulse"][i], inf["impulse"])
            np.testing.assert_array_equal(obs[i], o)
            assert reward[i] == r


def test_determinism_and_pickling():
    def rollout(env, seed):
        obs = [env.reset(seed=seed)[0]]
        rng = np.random.default_rng(seed)
        for _ in range(200):
            o, _, te, tr, _ = env.step(rng.uniform(-1, 1, 2))
            obs.append(o)
            if te or tr:
                obs.append(env.reset()[0])
        return np.array(obs)

    env = gym.make(leg_env.ENV_ID, **UNI)
    np.testing.assert_array_equal(rollout(env, 3), rollout(env, 3))
    env.reset(seed=4)
    for a in np.random.default_rng(0).uniform(-1, 1, (30, 2)):
        env.step(a)
    copy = pickle.loads(pickle.dumps(env))
    assert copy.unwrapped.config.contact == "unilateral"
    for a in np.random.default_rng(1).uniform(-1, 1, (50, 2)):
        a1, a2 = env.step(a), copy.step(a)
        np.testing.assert_array_equal(a1[0], a2[0])
        assert a1[4]["contact_mode"] == a2[4]["contact_mode"]


def test_gymnasium_checker_passes():
    gym_check_env(gym.make(leg_env.ENV_ID, **UNI).unwrapped, skip_render_check=True)


@pytest.mark.sb3
def test_sb3_checker_passes():
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    sb3_check_env(gym.make(leg_env.ENV_ID, **UNI).unwrapped, warn=False)


@pytest.mark.sb3
def test_sb3_adapter_carries_the_contact_keys():
    from leg_env.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env(4, seed=0, **UNI)
    venv.reset()
    assert venv.reset_infos[0]["contact_mode"] == "stick"
    rng = np.random.default_rng(0)
    for _ in range(60):
        obs, rewards, dones, infos = venv.step(rng.uniform(-1, 1, (4, 2)))
        assert obs.shape == (4, 18)
        for info in infos:
            assert info["contact_mode"] in ("stick", "slip", "flight")
            assert isinstance(info["contact_events"], int) and info["impulse"].shape == (2,)


def test_frames_show_the_contact_mode():
    env = gym.make(leg_env.ENV_ID, render_mode="rgb_array", **UNI)
    q_nom = env.unwrapped.nominal.q
    env.reset(options={"qpos": q_nom})
    stick = env.render()
    env.reset(options={"qpos": q_nom + np.array([0.0, 0.05, 0.0, 0.0, 0.0])})
    flight = env.render()
    assert stick.shape == flight.shape and stick.std() > 0 and flight.std() > 0
    # the flight marker is blue, the stick marker green
    blue = np.all(flight == (40, 120, 220), axis=-1).sum()
    assert blue > 20 and np.all(stick == (40, 120, 220), axis=-1).sum() == 0


@pytest.mark.parametrize("kind", ["uniform", "bang_bang"])
def test_soak_finite_and_flagged(kind):
    """10^5 env-steps at ten times the torque limit: every observation finite, every failure flagged."""
    n = 100
    venv = gym.make_vec(leg_env.ENV_ID, num_envs=n, torque_limit=500.0, **UNI)
    venv.reset(seed=11)
    rng = np.random.default_rng(11)
    failures = 0
    for _ in range(SOAK_STEPS // n):
        a = rng.uniform(-1, 1, (n, 2))
        if kind == "bang_bang":
            a = np.sign(a)
        obs, reward, term, trunc, info = venv.step(a)
        assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))
        failures += int(info["numerical_failure"].sum())
        assert np.all(term[info["numerical_failure"]])
    assert failures < SOAK_STEPS // 100  # blow-ups are rare and each one ends its episode
