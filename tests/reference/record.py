"""Record the reference trajectories replayed by ``tests/test_continuity.py``: ``tests/data/reference_trajectories.npz``.

**Recorded from the numba implementation** of the physics kernels (``leg_env/dynamics.py``, ``contact.py``,
``integrate.py``, ``hybrid.py``, ``step.py``, ``tasks/*.py`` as numba ``@njit`` code), before their port to a
compiled C core, so that the port can be checked against it step by step. The file's ``meta`` entry holds the
git commit recorded from (and whether ``leg_env/``, ``policies/`` or ``train/`` had uncommitted changes), the
versions of Python, numpy, numba, gymnasium (and SB3 / torch for the shipped policies) and the machine.

**Do not re-run this script to "fix" a failing comparison.** A failing ``test_continuity.py`` means the code
under test no longer reproduces the numba implementation's trajectories: find out why. Re-recording would
replace the reference with the code under test and so test nothing. Re-record only on purpose, for a change
of the physics or of a task that is meant to change the trajectories, and say so in the commit.

Usage (from the repository root, in the package's venv; minutes on a cold numba cache)::

    python tests/reference/record.py [--out tests/data/reference_trajectories.npz]

It records whatever ``leg_env`` it imports (the ``leg_env/`` next to it). The committed file was recorded from a
clean checkout of commit e4e99ffd (the last commit with the numba kernels, the parent of the C port d1d7942), with
numpy 2.4.6, numba 0.68.1, gymnasium 1.4.0, Python 3.11 (``meta["provenance"]``), in about 10 s on warm kernels.
Task ids are the recorded commit's. Those no longer registered are replayed by the id that makes their task now
(``runners.SUCCESSORS``: ``PlanarLegStance-v1`` renamed ``PlanarLegBalance-v0``, now ``-v1``; ``PlanarLegPush-v0`` and
``PlanarLegHop-v0`` by ``-v1`` and ``-v3``, which append observation entries and, for the hop, change its reward:
the recorded columns and quantities that did not change are compared).

Everything goes through the public API (``tests/reference/runners.py``), so the recording survives a rewrite of
the internals. What is recorded (``meta`` has one entry per group, with every trajectory's spec, its compared
window and its counts of flight, slip, impact and event steps):

1. ``single``: ``gymnasium.make(id)`` for every id of ``leg_env.ENV_IDS``, seeds 0, 1, 2, actions drawn up front
   from ``np.random.default_rng(seed)`` uniform in [-1, 1]; on the unilateral tasks (Stance-v1, Push-v0, Hop-v0)
   also "bang-bang" episodes (each action entry -1 or +1, held for 2 to 14 steps, seeds 100..) and episodes of
   actions uniform in [-3, 3] (clipped to the limits by ``step``; seeds 200..), which lift off, fly, land with
   impacts and slip, and "knee pumping" (hip 0, knee -1 or 0 held for 3 to 11 steps; seeds 300..), with long
   stick phases and slips; and ``randomize=True`` on Stance-v1 and Hop-v0 (seeds 0, 1, uniform actions, and one
   bang-bang). Per step: obs (float32), reward, terminated, truncated and every numeric ``info`` value
   (``contact_mode`` as 0 stick / 1 slip / 2 flight; ``params`` flattened as ``params.<field>``), the reset's
   obs and info. Each episode runs until it terminates or for 300 steps.
2. ``vector``: ``gymnasium.make_vec(id, num_envs=8, vectorization_mode="vector_entry_point")`` for every id, and
   Stance-v1 with ``randomize=True``; reset with a seed, 150 steps of pre-drawn uniform actions; obs, rewards,
   terminations, truncations (autoresets included).
3. ``hybrid``: ``leg_env.physics.hybrid.hybrid_step`` on 64 random robots' states (default ``LegParams``; the nominal
   posture with the joints perturbed, the foot on the ground or up to 5 cm above it, random velocities; ``mu``
   uniform in [0.3, 0.9]) for 200 control steps under piecewise-constant random torques around the holding
   torques, feeding back ``q, qd, mode, anchor_x``; every ``HybridStep`` field of every step (each step's start is
   the previous step's end: ``runners.chain_starts``). Robots whose chain leaves the foot below the ground, which
   the numba implementation does in a corner case (``below_ground``), are redrawn (one was).
   ``stance``, ``flight``: ``leg_env.physics.integrate.stance_step`` (foot pinned at its start) and ``flight_step`` on 16
   perturbed equilibria (``leg_env.physics.dynamics.static_equilibrium``) for 200 steps of torques around the holding
   torques.
4. ``policy``: the controllers of ``policies/`` on their tasks (``lqr`` on Stance-v0 and Stance-v1, ``gated`` on
   Stance-v1, ``hopper`` on Hop-v0, ``stepping`` on Push-v0) and the shipped SB3 policies (``policies/ppo_stance``,
   ``ppo_stance_v1``, ``ppo_hop``, ``ppo_push``, loaded by ``train.evaluate.load_policy``), seeds 10000 and 10001
   (and 10003 for ``gated``: a start from which it hops), deterministic actions, up to 300 steps: the actions
   (float64, as given to ``step``), obs, rewards, terminations and info.

Where each comparison stops (the number of compared steps is stored: ``n_compare``, ``mask``, ``horizon``; and
the isolated ill-conditioned steps whose float quantities are not compared: ``jitter``) was measured here by
the shadow runs of ``runners.py`` (module docstring); the one-step checks of group 3 leave out
the steps whose outcome a 1e-14 torque perturbation moves by more than 1e-10 (``step_ok``).
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # policies/, train/
sys.path.insert(0, str(Path(__file__).resolve().parent))  # runners

import numpy as np  # noqa: E402

import runners as R  # noqa: E402

DEFAULT_OUT = ROOT / "tests" / "data" / "reference_trajectories.npz"
STANCE_V0, STANCE_V1 = "leg_env/PlanarLegStance-v0", "leg_env/PlanarLegStance-v1"
PUSH, HOP = "leg_env/PlanarLegPush-v0", "leg_env/PlanarLegHop-v0"
UNILATERAL_IDS = (STANCE_V1, PUSH, HOP)
VECTOR_ENVS, VECTOR_STEPS = 8, 150
N_HYBRID, T_HYBRID = 64, 200
N_PINNED, T_PINNED = 16, 200
POLICY_SEEDS = (10000, 10001)


def log(*a):
    print(f"[{time.strftime('%H:%M:%S')}]", *a, flush=True)


# --------------------------------------------------------------------------------------------------
# actions
# --------------------------------------------------------------------------------------------------


def uniform_actions(seed: int, n: int = R.MAX_STEPS, scale: float = 1.0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-scale, scale, (n, 2))


def bangbang_actions(seed: int, n: int = R.MAX_STEPS) -> np.ndarray:
    """Each entry -1 or +1, switched after 2 to 14 steps (drawn per switch and per entry)."""
    rng = np.random.default_rng(seed)
    out = np.empty((n, 2))
    for j in range(2):
        t = 0
        while t < n:
            hold = int(rng.integers(2, 15))
            out[t : t + hold, j] = rng.choice((-1.0, 1.0))
            t += hold
    return out


def pump_actions(seed: int, n: int = R.MAX_STEPS) -> np.ndarray:
    """Knee pumping: no hip torque, the knee action -1 (full extension torque) or 0, switched after 3 to 11 steps:
    long stick phases, slips and lift-offs before the fall."""
    rng = np.random.default_rng(seed)
    out = np.zeros((n, 2))
    t = 0
    while t < n:
        hold = int(rng.integers(3, 12))
        out[t : t + hold, 1] = rng.choice((-1.0, 0.0))
        t += hold
    return out


# --------------------------------------------------------------------------------------------------
# groups
# --------------------------------------------------------------------------------------------------


def single_cases() -> list[dict]:
    import leg_env

    cases = []
    for env_id in leg_env.ENV_IDS:
        for seed in (0, 1, 2):
            cases.append(dict(env_id=env_id, kwargs={}, seed=seed, actions="uniform"))
    for env_id in UNILATERAL_IDS:
        for seed in (100, 101, 102):
            cases.append(dict(env_id=env_id, kwargs={}, seed=seed, actions="bangbang"))
        for seed in (200, 201):
            cases.append(dict(env_id=env_id, kwargs={}, seed=seed, actions="uniform3"))
        for seed in (300, 301):
            cases.append(dict(env_id=env_id, kwargs={}, seed=seed, actions="pump"))
    for env_id in (STANCE_V1, HOP):
        for seed in (0, 1):
            cases.append(dict(env_id=env_id, kwargs={"randomize": True}, seed=seed, actions="uniform"))
        cases.append(dict(env_id=env_id, kwargs={"randomize": True}, seed=100, actions="bangbang"))
    return cases


def case_actions(case: dict) -> np.ndarray:
    kind, seed = case["actions"], case["seed"]
    if kind == "uniform":
        return uniform_actions(seed)
    if kind == "uniform3":
        return uniform_actions(seed, scale=3.0)
    if kind == "bangbang":
        return bangbang_actions(seed)
    if kind == "pump":
        return pump_actions(seed)
    raise KeyError(kind)


def event_counts(info_mode, info_events, info_impulse, info_slip, info_flight) -> dict:
    """Steps with flight, slip, an impact, any located event (for the report)."""
    return {
        "steps_flight": int(np.sum(info_flight > 0)),
        "steps_slip": int(np.sum(info_slip > 0)),
        "steps_impact": int(np.sum(np.abs(info_impulse).sum(axis=-1) > 1e-9)),
        "steps_events": int(np.sum(info_events > 0)),
        "end_modes": {name: int(np.sum(info_mode == code)) for name, code in R.MODE_CODES.items()},
    }


def record_single(data: dict, meta: dict) -> None:
    specs = []
    for i, case in enumerate(single_cases()):
        actions = case_actions(case)
        rec = R.run_single(case["env_id"], case["kwargs"], case["seed"], actions)
        shadow = R.run_single(case["env_id"], case["kwargs"], case["seed"], R.shadow_actions(actions, np.random.default_rng(10_000 + i)))
        again = R.run_single(case["env_id"], case["kwargs"], case["seed"], actions)
        assert all(np.array_equal(again[k], rec[k], equal_nan=True) for k in rec), "a replay is not bitwise the recording"
        T = len(rec["reward"])
        n_compare, jitter = R.single_window(rec, shadow)
        rec["jitter"] = jitter
        spec = dict(case, steps=T, n_compare=n_compare, jitter_steps=int(jitter.sum()), terminated=bool(rec["terminated"][-1]))
        if "info/contact_mode" in rec:
            c = {k: v for k, v in event_counts(rec["info/contact_mode"], rec["info/contact_events"], rec["info/impulse"],
                                            rec["info/slip_time"], rec["info/flight_time"]).items()}
            cc = event_counts(rec["info/contact_mode"][:n_compare], rec["info/contact_events"][:n_compare],
                              rec["info/impulse"][:n_compare], rec["info/slip_time"][:n_compare], rec["info/flight_time"][:n_compare])
            spec["events"], spec["events_compared"] = c, cc
        specs.append(spec)
        for k, v in rec.items():
            data[f"single/{i:02d}/{k}"] = v
        log(f"single {i:2d} {case['env_id']} {case['kwargs']} seed {case['seed']} {case['actions']}: {T} steps, "
            f"compared {n_compare} ({int(jitter.sum())} jitter), terminated {spec['terminated']}, {spec.get('events_compared', '')}")
    meta["single"] = specs


def record_vector(data: dict, meta: dict) -> None:
    import leg_env

    cases = [dict(env_id=e, kwargs={}, seed=1000 + k) for k, e in enumerate(leg_env.ENV_IDS)]
    cases.append(dict(env_id=STANCE_V1, kwargs={"randomize": True}, seed=1100))
    specs = []
    for i, case in enumerate(cases):
        actions = np.random.default_rng(case["seed"]).uniform(-1.0, 1.0, (VECTOR_STEPS, VECTOR_ENVS, 2))
        rec = R.run_vector(case["env_id"], case["kwargs"], VECTOR_ENVS, case["seed"], actions)
        shadow = R.run_vector(case["env_id"], case["kwargs"], VECTOR_ENVS, case["seed"],
                              R.shadow_actions(actions, np.random.default_rng(20_000 + i)))
        mask, jitter = R.vector_window(rec, shadow)
        rec["action"], rec["mask"], rec["jitter"] = actions, mask, jitter
        spec = dict(case, num_envs=VECTOR_ENVS, steps=VECTOR_STEPS, compared=int(mask.sum()), jitter_steps=int(jitter.sum()),
                    terminations=int(rec["terminated"].sum()), terminations_compared=int((rec["terminated"] & mask).sum()))
        specs.append(spec)
        for k, v in rec.items():
            data[f"vector/{i:02d}/{k}"] = v
        log(f"vector {i} {case}: {mask.sum()} of {mask.size} sub-env steps compared, per sub-env {mask.sum(axis=0).tolist()}, "
            f"terminations {spec['terminations']} ({spec['terminations_compared']} compared), {int(jitter.sum())} jitter")
    meta["vector"] = specs


def hybrid_robot(rng: np.random.Generator, p, q_nom, tau_hold, lifted: bool):
    """One robot of the ``hybrid`` group: joints perturbed about the nominal posture, the foot on the ground or up
    to 5 cm above it, random velocities, ``mu`` in [0.3, 0.9], and piecewise-constant torques: the holding torques
    plus uniform +-40 N m, each entry redrawn after 1 to 12 steps."""
    from leg_env.physics.dynamics import foot_position

    q = q_nom.copy()
    q[2] += rng.uniform(-0.2, 0.2)
    q[3] += rng.uniform(-0.3, 0.3)
    q[4] = np.clip(q[4] + rng.uniform(-0.4, 0.4), 0.15, 2.3)
    lift = rng.uniform(0.0, 0.05) if lifted else 0.0
    foot = foot_position(q, p)
    q[0] += rng.uniform(-0.1, 0.1) - foot[0]
    q[1] += lift - foot[1]
    qd = np.concatenate([rng.normal(0.0, 0.4, 2), rng.normal(0.0, 1.0, 3)])
    mu = rng.uniform(0.3, 0.9)
    tau = np.empty((T_HYBRID, 2))
    for j in range(2):
        t = 0
        while t < T_HYBRID:
            hold = int(rng.integers(1, 13))
            tau[t : t + hold, j] = tau_hold[j] + rng.uniform(-40.0, 40.0)
            t += hold
    return q, qd, mu, tau


def below_ground(q0, qd0, taus, mu, p) -> np.ndarray:
    """The robots whose chain of ``hybrid_step`` (or that of its shadow run) leaves the foot below the ground by
    more than ``GROUND_TOL`` (so that the next ``hybrid_step`` refuses the state).

    This happens in the numba implementation this was recorded from: a foot at rest on the ground at
    ``y_f = -5.6e-17`` (round-off of the stick projection) whose free acceleration is barely upward gets FLIGHT at
    the step's start; if the foot comes back down within the step, the touchdown witness (``y_f`` going from
    ``>= 0`` to ``< 0``) never fires, since it started below zero, and the step ends with the foot 1e-5 m below
    the ground and no event. Such robots are redrawn: the reference holds well-defined steps only."""
    from leg_env.physics.dynamics import foot_position
    from leg_env.physics.hybrid import GROUND_TOL, hybrid_step

    bad = np.zeros(len(q0), dtype=bool)
    for factor in (None, 34):
        q, qd, mode, anchor = q0.copy(), qd0.copy(), None, None
        tt = taus if factor is None else taus * R.shadow_scale(np.random.default_rng(factor), taus.shape)
        for t in range(len(tt)):
            r = hybrid_step(q, qd, tt[t], p, mu, mode, anchor)
            low = foot_position(r.q, p)[:, 1] < -GROUND_TOL
            if low.any():  # reseat those robots (their record is dropped anyway) so the batch can go on
                bad |= low
                rq = r.q.copy()
                rq[low] = q[low]
                q, qd, mode, anchor = rq, np.where(low[:, None], qd, r.qd), np.where(low, mode if mode is not None else r.mode, r.mode), np.where(low, anchor if anchor is not None else r.anchor_x, r.anchor_x)
            else:
                q, qd, mode, anchor = r.q, r.qd, r.mode, r.anchor_x
    return bad


def hybrid_inputs(rng: np.random.Generator):
    """64 robots (``hybrid_robot``), half with the foot on the ground, half lifted; robots whose chain ends with
    the foot below the ground (``below_ground``) are redrawn. Returns ``p, q0, qd0, mu, taus, redrawn``."""
    from leg_env.physics.dynamics import static_equilibrium
    from leg_env.physics.params import LegParams

    p = LegParams()
    q_nom, tau_hold, _ = static_equilibrium(p)
    robots = [hybrid_robot(rng, p, q_nom, tau_hold, lifted=i % 2 == 1) for i in range(N_HYBRID)]
    redrawn = 0
    while True:
        q0 = np.array([r[0] for r in robots])
        qd0 = np.array([r[1] for r in robots])
        mu = np.array([r[2] for r in robots])
        taus = np.stack([r[3] for r in robots], axis=1)
        bad = below_ground(q0, qd0, taus, mu, p)
        if not bad.any():
            return p, q0, qd0, mu, taus, redrawn
        log(f"hybrid: redrawing robots {np.flatnonzero(bad).tolist()} (foot left below the ground)")
        redrawn += int(bad.sum())
        for i in np.flatnonzero(bad):
            robots[i] = hybrid_robot(rng, p, q_nom, tau_hold, lifted=i % 2 == 1)


def one_step_ok(recorded: dict, again: dict, shadow: dict, keys) -> np.ndarray:
    """``(T, N)``: the steps whose one-step replay is bitwise the chained recording, and whose outcome the shadow
    perturbation of the torques (``runners.shadow_scale``) moves by less than ``SHADOW_MARGIN`` of the tolerance
    (well-conditioned steps)."""
    same = np.ones(recorded[keys[0]].shape[:2], dtype=bool)
    for k in keys:
        eq = (recorded[k] == again[k]) | (np.isnan(recorded[k]) & np.isnan(again[k]) if recorded[k].dtype.kind == "f" else False)
        same &= eq.reshape(eq.shape[:2] + (-1,)).all(axis=-1)
    assert same.all(), f"one-step replays differ from the chain at {np.argwhere(~same)[:5].tolist()}"
    ok = np.ones_like(same)
    for k in keys:
        ok &= ~R.mismatch(shadow[k], recorded[k], R.tolerance_of(k, recorded[k], R.SHADOW_MARGIN), lead=2)
    return ok


def hybrid_stats(run: dict, upto=None) -> dict:
    T, N = run["mode"].shape
    m = np.ones((T, N), dtype=bool) if upto is None else (np.arange(T)[:, None] < np.asarray(upto)[None, :])
    kinds = run["event_kind"]
    return {
        "robot_steps": int(m.sum()),
        "steps_flight": int((m & (run["flight_time"] > 0)).sum()),
        "steps_slip": int((m & (run["slip_time"] > 0)).sum()),
        "steps_impact": int((m & (np.abs(run["impulse"]).sum(axis=-1) > 1e-9)).sum()),
        "steps_painleve": int((m & (run["painleve"] > 0)).sum()),
        "steps_settles": int((m & (run["settles"] > 0)).sum()),
        "events": {name: int((m[..., None] & (kinds == code)).sum()) for code, name in enumerate(("liftoff", "slip_onset", "sliding_stop", "touchdown"))},
    }


def record_hybrid(data: dict, meta: dict) -> None:
    p, q0, qd0, mu, taus, redrawn = hybrid_inputs(np.random.default_rng(31))
    t0 = time.time()
    run = R.hybrid_chain(q0, qd0, taus, mu, p)
    log(f"hybrid chain {time.time() - t0:.1f} s")
    shadow = R.hybrid_chain(q0, qd0, taus * R.shadow_scale(np.random.default_rng(34), taus.shape), mu, p)
    keys = list(R.HYBRID_FIELDS)
    horizon, jitter = R.chain_window(run, shadow, keys)
    again = R.hybrid_steps_from(run["start_q"], run["start_qd"], run["start_mode"], run["start_anchor_x"], taus, mu, p)
    shadow1 = R.hybrid_steps_from(run["start_q"], run["start_qd"], run["start_mode"], run["start_anchor_x"],
                                  taus * R.shadow_scale(np.random.default_rng(33), taus.shape), mu, p)
    step_ok = one_step_ok(run, again, shadow1, keys)
    starts = R.chain_starts(dict(run, q0=q0, qd0=qd0))
    assert all(np.array_equal(starts[k], run[k], equal_nan=True) for k in starts), "chain_starts does not rebuild the chain's starts"
    for k, v in run.items():
        if not k.startswith("start_"):  # rebuilt by R.chain_starts
            data[f"hybrid/{k}"] = v
    data.update({"hybrid/q0": q0, "hybrid/qd0": qd0, "hybrid/mu": mu, "hybrid/tau": taus, "hybrid/horizon": horizon,
                 "hybrid/jitter": jitter, "hybrid/step_ok": step_ok})
    meta["hybrid"] = dict(n=N_HYBRID, steps=T_HYBRID, params="LegParams()", redrawn_below_ground=redrawn, all_steps=hybrid_stats(run),
                          chained_compared=hybrid_stats(run, horizon), horizon=horizon.tolist(), chained_jitter_steps=int(jitter.sum()),
                          one_step_compared=int(step_ok.sum()), one_step_left_out=int((~step_ok).sum()))
    log(f"hybrid: all {meta['hybrid']['all_steps']}")
    log(f"hybrid: chained compared {meta['hybrid']['chained_compared']}; horizons {sorted(horizon.tolist())}; {int(jitter.sum())} jitter")
    log(f"hybrid: one-step checks {step_ok.sum()} of {step_ok.size}")


def pinned_inputs(rng: np.random.Generator, n: int):
    from leg_env.physics.dynamics import static_equilibrium
    from leg_env.physics.params import LegParams

    p = LegParams()
    q_nom, tau_hold, _ = static_equilibrium(p)
    q = np.tile(q_nom, (n, 1))
    q[:, 2:] += rng.uniform(-0.05, 0.05, (n, 3))
    qd = np.zeros((n, 5))
    qd[:, 2:] = rng.normal(0.0, 0.1, (n, 3))
    taus = tau_hold + rng.uniform(-5.0, 5.0, (T_PINNED, n, 2))
    return p, q, qd, taus


def record_pinned(data: dict, meta: dict) -> None:
    from leg_env.physics.dynamics import foot_position
    from leg_env.physics.integrate import flight_step, project_stance, stance_step

    for name, step, seed in (("stance", stance_step, 41), ("flight", flight_step, 42)):
        p, q0, qd0, taus = pinned_inputs(np.random.default_rng(seed), N_PINNED)
        anchor = None
        if name == "stance":  # on the contact manifold: base placed by the foot (at the origin), Jc qd = 0
            q0, qd0 = project_stance(q0, qd0, p, np.zeros((N_PINNED, 2)))
            anchor = foot_position(q0, p)
        else:  # a flying leg: the base moves too
            qd0[:, :2] = np.random.default_rng(seed + 100).normal(0.0, 0.5, (N_PINNED, 2))
        run = R.pinned_chain(step, q0, qd0, taus, p, anchor)
        shadow = R.pinned_chain(step, q0, qd0, taus * R.shadow_scale(np.random.default_rng(seed + 1), taus.shape), p, anchor)
        keys = [k for k in ("q", "qd", "lam_mean") if k in run]
        horizon, jitter = R.chain_window(run, shadow, keys)
        again = R.pinned_steps_from(step, run["start_q"], run["start_qd"], taus, p, anchor)
        shadow1 = R.pinned_steps_from(step, run["start_q"], run["start_qd"],
                                      taus * R.shadow_scale(np.random.default_rng(seed + 2), taus.shape), p, anchor)
        step_ok = one_step_ok(run, again, shadow1, keys)
        starts = R.chain_starts(dict(run, q0=q0, qd0=qd0), keys=("q", "qd"))
        assert all(np.array_equal(starts[k], run[k]) for k in starts), "chain_starts does not rebuild the chain's starts"
        for k, v in run.items():
            if not k.startswith("start_"):  # rebuilt by R.chain_starts
                data[f"{name}/{k}"] = v
        data.update({f"{name}/q0": q0, f"{name}/qd0": qd0, f"{name}/tau": taus, f"{name}/horizon": horizon, f"{name}/jitter": jitter,
                     f"{name}/step_ok": step_ok})
        if anchor is not None:
            data[f"{name}/anchor"] = anchor
        meta[name] = dict(n=N_PINNED, steps=T_PINNED, horizon=horizon.tolist(), chained_jitter_steps=int(jitter.sum()),
                          one_step_compared=int(step_ok.sum()),
                          one_step_left_out=int((~step_ok).sum()))
        log(f"{name}: horizons {sorted(horizon.tolist())}, {int(jitter.sum())} jitter; one-step checks {step_ok.sum()} of {step_ok.size}")


def policy_cases(with_sb3: bool) -> list[dict]:
    cases = [
        dict(name="lqr", env_id=STANCE_V0, seeds=POLICY_SEEDS),
        dict(name="lqr", env_id=STANCE_V1, seeds=POLICY_SEEDS),
        dict(name="gated", env_id=STANCE_V1, seeds=POLICY_SEEDS + (10003,)),
        dict(name="hopper", env_id=HOP, seeds=POLICY_SEEDS),
        dict(name="stepping", env_id=PUSH, seeds=POLICY_SEEDS),
    ]
    if with_sb3:
        for folder, env_id in (("ppo_stance", STANCE_V0), ("ppo_stance_v1", STANCE_V1), ("ppo_hop", HOP), ("ppo_push", PUSH)):
            cases.append(dict(name=f"policies/{folder}", env_id=env_id, seeds=POLICY_SEEDS, sb3=True))
    return [dict(c, kwargs={}, seed=s) for c in cases for s in c.pop("seeds")]


def record_policies(data: dict, meta: dict, with_sb3: bool) -> None:
    specs = []
    for i, case in enumerate(policy_cases(with_sb3)):
        policy = R.make_policy(case["name"], case["env_id"])
        rec = R.run_single(case["env_id"], case["kwargs"], case["seed"], policy=policy)
        replay = R.run_single(case["env_id"], case["kwargs"], case["seed"], rec["action"])
        assert all(np.array_equal(replay[k], rec[k], equal_nan=True) for k in rec), "open-loop replay is not bitwise the closed loop"
        again = R.predicted_actions(policy, rec["obs"][:-1])
        assert np.array_equal(again, rec["action"]), "predict on the recorded observations is not bitwise the closed loop"
        shadow = R.run_single(case["env_id"], case["kwargs"], case["seed"], R.shadow_actions(rec["action"], np.random.default_rng(30_000 + i)))
        T = len(rec["reward"])
        n_compare, jitter = R.single_window(rec, shadow)
        rec["jitter"] = jitter
        spec = dict(case, steps=T, n_compare=n_compare, jitter_steps=int(jitter.sum()), terminated=bool(rec["terminated"][-1]))
        if "info/contact_mode" in rec:
            spec["events"] = event_counts(rec["info/contact_mode"], rec["info/contact_events"], rec["info/impulse"], rec["info/slip_time"], rec["info/flight_time"])
            spec["events_compared"] = event_counts(rec["info/contact_mode"][:n_compare], rec["info/contact_events"][:n_compare], rec["info/impulse"][:n_compare],
                                                   rec["info/slip_time"][:n_compare], rec["info/flight_time"][:n_compare])
        specs.append(spec)
        for k, v in rec.items():
            data[f"policy/{i:02d}/{k}"] = v
        log(f"policy {i:2d} {case['name']} on {case['env_id']} seed {case['seed']}: {T} steps, open loop compared {n_compare} ({int(jitter.sum())} jitter), "
            f"terminated {spec['terminated']} {spec.get('events_compared', '')}")
    meta["policy"] = specs


# --------------------------------------------------------------------------------------------------


def provenance() -> dict:
    import gymnasium
    import numba

    def git(*args):
        try:
            return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return None

    import leg_env

    info = {
        "recorded_from": "the numba implementation of the leg_env physics kernels",
        "git_commit": git("rev-parse", "HEAD"),
        "git_uncommitted_changes_in_leg_env_policies_train": git("status", "--porcelain", "--", "leg_env", "policies", "train"),
        "leg_env_file": leg_env.__file__,
        "leg_env_version": leg_env.__version__,
        "env_ids": list(leg_env.ENV_IDS),
        "python": sys.version,
        "numpy": np.__version__,
        "numba": numba.__version__,
        "gymnasium": gymnasium.__version__,
        "machine": platform.platform() + " " + platform.machine(),
        "recorded_at": time.strftime("%Y-%m-%d %H:%M:%S %z"),
        "tolerances": {"F64_TOL": R.F64_TOL, "F32_TOL": R.F32_TOL, "SHADOW_EPS": R.SHADOW_EPS, "SHADOW_MARGIN": R.SHADOW_MARGIN,
                       "SHADOW_MARGIN_F32": R.SHADOW_MARGIN_F32},
    }
    try:
        import stable_baselines3
        import torch

        info["stable_baselines3"], info["torch"] = stable_baselines3.__version__, torch.__version__
    except ImportError:
        pass
    return info


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    ap.add_argument("--no-sb3", action="store_true", help="leave out the shipped SB3 policies")
    args = ap.parse_args(argv)
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass
    meta = {"provenance": provenance()}
    log("recording from", meta["provenance"]["leg_env_file"], "commit", meta["provenance"]["git_commit"])
    if meta["provenance"]["git_uncommitted_changes_in_leg_env_policies_train"]:
        log("WARNING: uncommitted changes:", meta["provenance"]["git_uncommitted_changes_in_leg_env_policies_train"])
    data: dict = {}
    record_hybrid(data, meta)
    record_pinned(data, meta)
    record_single(data, meta)
    record_vector(data, meta)
    record_policies(data, meta, with_sb3=not args.no_sb3)
    data["meta"] = R.to_json(meta)
    for k in ("git_commit", "numpy", "gymnasium", "numba", "python"):  # also as plain strings, for a quick look
        data[f"provenance/{k}"] = np.array(str(meta["provenance"][k]))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(args.out, **data)
    log(f"wrote {args.out}: {args.out.stat().st_size / 1e6:.2f} MB, {len(data)} arrays")


if __name__ == "__main__":
    main()
