"""What ``record.py`` recorded and ``tests/test_continuity.py`` replays: the runs, the comparison, the stop rule.

Both sides call these functions, so a recording and its replay run the same driver code; only the package
under test (``leg_env``, and the controllers of ``policies/``) may differ. Everything goes through the public
API: ``gymnasium.make`` / ``gymnasium.make_vec``, ``reset(seed=...)``, ``step``, ``leg_env.physics.hybrid.hybrid_step``,
``leg_env.physics.integrate.stance_step`` / ``flight_step``, ``leg_env.physics.dynamics.static_equilibrium`` and the
controllers' ``predict``.

Agreement (``mismatch``): a float64 quantity ``a`` agrees with its recorded value ``b`` when
``|a - b| <= 1e-9 (1 + |b|)``; a float32 observation when ``|a - b| <= 1e-6 (1 + |b|)`` (float32's resolution:
one unit in the last place is ``2^-23 |b| = 1.2e-7 |b|``, so an observation rounded from a float64 state that
moved by round-off can change by a whole float32 step; a tolerance at float64's 1e-9 would be met only by bit
equality); integers and booleans (modes, event counts, event kinds, terminations) exactly; NaN only where the
record has NaN (the event log's unused slots).

The stop rule (``horizon``): where a comparison of a free-running trajectory stops was measured when it was
recorded, by a *shadow* run: the same run with every torque (or action) multiplied by ``1 - 1e-14 u``, ``u``
uniform in [0, 1) drawn per step (``shadow_scale``; 1e-14 is some 45 units in the last place, about ten times the
few-ulp differences that a re-ordered but otherwise identical implementation makes in a step's quantities). A
trajectory is compared up to the step before the first step where the shadow run departs from it by more than
1/10 of the test's tolerance (``SHADOW_MARGIN``) on any float64 quantity (float32 observations: 1/5 of theirs,
above one float32 step) and still does at the next step, or differs in any discrete quantity. A departure for one
step alone (``jitter``) is a step quantity that is momentarily ill-conditioned while the trajectory is not: the time
of a located event, fixed only to the root finder's 1e-12 s bracket, moves that step's mean contact force by up to
~4e-10 of itself; a mean force passing near zero has the tightest tolerance, 1e-9 N, while its error scales with the
rates. On those steps only the discrete quantities are compared. So the comparison covers the steps over which the
motion has not amplified a per-step input change of 1e-14 beyond 1e-10: an implementation whose results differ by
a few ulps per step (ten times less) departs there by about 1e-11, a hundredth of the tolerance. Past that point (a fall,
chaotic flailing, an unstable balance replayed open loop: errors grow like ``e^(7 t)`` in stance, a factor 4 every
20 steps; a near-tie of an event), exact agreement cannot be asked of a different but correct implementation.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # the repository: policies/ and train/
F64_TOL = 1e-9  # |a - b| <= F64_TOL (1 + |b|) for float64 quantities
F32_TOL = 1e-6  # the same for float32 observations (see the module docstring)
SHADOW_EPS = 1e-14  # relative size of the shadow run's torque / action perturbation
SHADOW_MARGIN = 0.1  # the shadow run may depart by this fraction of F64_TOL
SHADOW_MARGIN_F32 = 0.2  # ... and of F32_TOL for float32 observations (one float32 step is below it)
MAX_STEPS = 300  # longest single-env episode
MODE_CODES = {"stick": 0, "slip": 1, "flight": 2}  # info["contact_mode"] as stored
SUCCESSORS = {
    # id at the recording: (the id that makes its task now, the recorded quantities its reward changed). A
    # successor's dynamics, starts and ends are the recorded id's, and its observation is the recorded one with
    # entries appended after it, so the recorded columns are compared.
    # renamed PlanarLegBalance-v0, then v1: the last action appended (entries 18-19); flight, the tilt and the torque
    # squared charged more, and the action's change charged
    "leg_env/PlanarLegStance-v1": ("leg_env/PlanarLegBalance-v1", ("reward", "info/reward_drift", "info/reward_unilateral",
                                                                   "info/reward_ctrl")),
    # the COM's x from its start and the last action appended (entries 18-20); the tilt, the torque squared and the
    # action's change charged more
    "leg_env/PlanarLegPush-v0": ("leg_env/PlanarLegPush-v2", ("reward", "info/reward_drift", "info/reward_ctrl")),
    # the height term and the alive bonus paid while hopping; the COM's x, the ground time, the last apex and the last
    # action appended (entries 19-23); the torque squared, the COM's drift and the tilt charged more, the action's change
    # and positive power charged
    "leg_env/PlanarLegHop-v0": ("leg_env/PlanarLegHop-v4", ("reward", "info/reward_height", "info/reward_alive", "info/reward_ctrl",
                                                            "info/reward_drift", "info/reward_tilt")),
}
"""The recorded ids that are no longer registered, and the id that replays each."""
RETIRED_POLICIES = {
    # recorded shipped policy: why it is no longer shipped
    "policies/ppo_hop": "its task's id, PlanarLegHop-v0, is removed",
    "policies/ppo_push": "its task's id, PlanarLegPush-v0, is removed",
    "policies/ppo_stance_v1": "no residual policy is shipped (residual training is an option of train.ppo)",
}
"""Recorded shipped policies no longer shipped: their episodes are still replayed open loop (their recorded actions,
on the id that makes their task now), their networks' actions no longer."""


def current_id(env_id: str) -> str:
    """The id to make a recorded task by: the recorded id (those of the numba implementation's commit) where it is
    still registered, else its successor (``SUCCESSORS``)."""
    import gymnasium as gym

    import leg_env  # noqa: F401  (registers the ids)

    if env_id in gym.registry:
        return env_id
    return SUCCESSORS[env_id][0]


def changed_keys(env_id: str) -> tuple:
    """The recorded quantities that the id replaying ``env_id`` computes differently (``SUCCESSORS``): not compared."""
    return SUCCESSORS[env_id][1] if current_id(env_id) != env_id else ()


# --------------------------------------------------------------------------------------------------
# comparison
# --------------------------------------------------------------------------------------------------


def mismatch(a, b, tol: float, lead: int = 1) -> np.ndarray:
    """Boolean array over the ``lead`` leading axes: where ``a`` does not agree with the recorded ``b``.

    Integers and booleans must be equal; floats ``|a - b| <= tol (1 + |b|)`` (in float64), with NaN agreeing
    only with NaN.
    """
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        raise AssertionError(f"shape {a.shape} against the recorded {b.shape}")
    if b.dtype.kind in "biu":
        bad = a != b
    else:
        a64, b64 = a.astype(np.float64), b.astype(np.float64)
        nan_a, nan_b = np.isnan(a64), np.isnan(b64)
        with np.errstate(invalid="ignore"):
            ok = np.abs(a64 - b64) <= tol * (1.0 + np.abs(b64))
        bad = np.where(nan_a | nan_b, nan_a != nan_b, ~ok)
    return bad.reshape(bad.shape[:lead] + (-1,)).any(axis=-1) if bad.ndim > lead else bad


def tolerance_of(key: str, value: np.ndarray, margin: float = 1.0) -> float:
    """The tolerance of a quantity: float32 arrays (observations) get ``F32_TOL``, the rest ``F64_TOL``."""
    if np.asarray(value).dtype == np.float32:
        return F32_TOL * (SHADOW_MARGIN_F32 if margin != 1.0 else 1.0)
    return F64_TOL * margin


def shadow_window(shadow: dict, record: dict, keys, lead: int = 1):
    """The stop rule (module docstring) from a shadow run: ``(horizon, jitter)``.

    ``horizon`` (one per trajectory: the axes 1 .. ``lead - 1``; a number for ``lead=1``) is the number of leading
    steps compared: the steps before the first one where the shadow run differs in a discrete quantity, or departs
    by more than ``SHADOW_MARGIN`` of the tolerance on a float quantity *and still does at the next step* (or that
    was the last step). ``jitter`` ``(T, ...)`` marks the steps before the horizon where the shadow run departed on
    a float quantity for that step alone (module docstring: an event time fixed to the root finder's 1e-12 s
    bracket, a mean force passing near zero). On those steps only the discrete quantities are compared."""
    fbad = dbad = None
    for k in keys:
        b = record[k]
        m = mismatch(shadow[k], b, tolerance_of(k, b, SHADOW_MARGIN), lead)
        if b.dtype.kind in "biu":
            dbad = m if dbad is None else dbad | m
        else:
            fbad = m if fbad is None else fbad | m
    fbad = np.zeros_like(dbad) if fbad is None else fbad
    dbad = np.zeros_like(fbad) if dbad is None else dbad
    T = fbad.shape[0]
    persists = np.concatenate([fbad[1:], np.ones_like(fbad[:1])])
    stop = dbad | (fbad & persists)
    horizon = np.where(stop.any(axis=0), stop.argmax(axis=0), T)
    jitter = fbad & (np.arange(T).reshape((T,) + (1,) * (fbad.ndim - 1)) < horizon)
    return horizon, jitter


def shadow_scale(rng: np.random.Generator, shape) -> np.ndarray:
    """Factors ``1 - SHADOW_EPS u`` of the shadow run (never pushes an action past its clip)."""
    return 1.0 - SHADOW_EPS * rng.random(shape)


def shadow_actions(actions: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The shadow run's actions: the clipped actions (what ``step`` applies) times ``shadow_scale``."""
    return np.clip(actions, -1.0, 1.0) * shadow_scale(rng, np.shape(actions))


# --------------------------------------------------------------------------------------------------
# single environments (gymnasium.make)
# --------------------------------------------------------------------------------------------------


def flat_info(info: dict) -> dict:
    """The numeric entries of a step's (or reset's) ``info``: ``contact_mode`` as ``MODE_CODES``, nested dicts
    (``params``) as ``params.<field>``, other strings left out."""
    out = {}
    for k, v in info.items():
        if k == "contact_mode":
            out[k] = np.int64(MODE_CODES[v])
        elif isinstance(v, str):
            continue
        elif isinstance(v, dict):
            for kk, vv in v.items():
                if not isinstance(vv, str):
                    out[f"{k}.{kk}"] = np.asarray(vv)
        else:
            out[k] = np.asarray(v)
    return out


def _stack(rows: list[dict], what: str) -> dict:
    keys = list(rows[0]) if rows else []
    for i, r in enumerate(rows):
        if list(r) != keys:
            raise AssertionError(f"{what}: the keys of step {i} {sorted(r)} are not those of step 0 {sorted(keys)}")
    return {k: np.stack([r[k] for r in rows]) for k in keys}


def run_single(env_id: str, kwargs: dict, seed: int, actions: np.ndarray | None = None, policy=None,
               max_steps: int = MAX_STEPS) -> dict:
    """One episode of ``gymnasium.make(env_id, **kwargs)`` reset with ``seed``, until it terminates or is
    truncated or after ``max_steps`` steps (or ``len(actions)``).

    The actions are ``actions[t]`` (float64, as given: ``step`` clips them), or ``policy.predict(obs)``'s
    (then recorded as float64 in ``"action"``). Returns ``obs`` ``(T + 1, d)`` float32 (the reset's first),
    ``action`` ``(T, 2)``, ``reward``, ``terminated``, ``truncated`` ``(T,)``, ``info/<key>`` ``(T, ...)`` and
    ``reset_info/<key>``.
    """
    import gymnasium as gym

    import leg_env  # noqa: F401  (registers the ids)

    env = gym.make(current_id(env_id), **kwargs)
    obs, info = env.reset(seed=int(seed))
    if policy is not None and hasattr(policy, "reset"):
        policy.reset()
    n = max_steps if actions is None else min(max_steps, len(actions))
    out_obs, out_act, rewards, terms, truncs, infos = [obs], [], [], [], [], []
    reset_info = flat_info(info)
    for t in range(n):
        if policy is not None:
            a, _ = policy.predict(obs, deterministic=True)
            a = np.asarray(a, dtype=np.float64).reshape(2)
        else:
            a = np.array(actions[t], dtype=np.float64)
        obs, reward, terminated, truncated, info = env.step(a)
        out_obs.append(obs)
        out_act.append(a)
        rewards.append(reward)
        terms.append(terminated)
        truncs.append(truncated)
        infos.append(flat_info(info))
        if terminated or truncated:
            break
    env.close()
    rec = {
        "obs": np.stack(out_obs).astype(np.float32),
        "action": np.array(out_act, dtype=np.float64).reshape(-1, 2),
        "reward": np.array(rewards, dtype=np.float64),
        "terminated": np.array(terms, dtype=bool),
        "truncated": np.array(truncs, dtype=bool),
    }
    rec.update({f"info/{k}": v for k, v in _stack(infos, f"{env_id} seed {seed}").items()})
    rec.update({f"reset_info/{k}": np.asarray(v) for k, v in reset_info.items()})
    return rec


def single_step_keys(rec: dict) -> list[str]:
    """The per-step quantities of a single-env record (those with the step axis): reward, flags, info.
    The observations are per step too, with the reset's first (``obs[1:]``)."""
    return ["reward", "terminated", "truncated"] + sorted(k for k in rec if k.startswith("info/"))


def single_window(rec: dict, shadow: dict):
    """``(n_compare, jitter)`` of a single-env episode (``shadow_window``): ``n_compare`` steps are compared, no
    further than the episode, which ends at its termination; ``jitter`` ``(T,)``."""
    T = len(rec["reward"])
    m = min(T, len(shadow["reward"]))  # a different end shows as a different `terminated` within these
    keys = single_step_keys(rec)
    if sorted(single_step_keys(shadow)) != sorted(keys):
        raise AssertionError("the shadow run's info keys differ")
    cut = {k: rec[k][:m] for k in keys}
    cut_s = {k: shadow[k][:m] for k in keys}
    cut["obs"], cut_s["obs"] = rec["obs"][1 : m + 1], shadow["obs"][1 : m + 1]
    horizon, jitter = shadow_window(cut_s, cut, keys + ["obs"])
    return int(horizon), np.concatenate([jitter, np.zeros(T - m, dtype=bool)])


# --------------------------------------------------------------------------------------------------
# vector environments (gymnasium.make_vec)
# --------------------------------------------------------------------------------------------------


def run_vector(env_id: str, kwargs: dict, num_envs: int, seed: int, actions: np.ndarray) -> dict:
    """``gymnasium.make_vec(env_id, num_envs, vectorization_mode="vector_entry_point", **kwargs)`` reset with
    ``seed`` and stepped by ``actions`` ``(T, num_envs, 2)`` (autoresets as they come: the default
    ``NEXT_STEP`` mode). Returns ``obs`` ``(T + 1, num_envs, d)``, ``reward``, ``terminated``, ``truncated``
    ``(T, num_envs)``."""
    import gymnasium as gym

    import leg_env  # noqa: F401

    envs = gym.make_vec(current_id(env_id), num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)
    obs, _ = envs.reset(seed=int(seed))
    out_obs, rewards, terms, truncs = [obs.copy()], [], [], []
    for a in actions:
        obs, reward, terminated, truncated, _ = envs.step(np.array(a, dtype=np.float64))
        out_obs.append(obs.copy())
        rewards.append(np.array(reward, dtype=np.float64))
        terms.append(np.array(terminated, dtype=bool))
        truncs.append(np.array(truncated, dtype=bool))
    envs.close()
    return {
        "obs": np.stack(out_obs).astype(np.float32),
        "reward": np.stack(rewards),
        "terminated": np.stack(terms),
        "truncated": np.stack(truncs),
    }


def vector_window(rec: dict, shadow: dict):
    """``(mask, jitter)`` ``(T, num_envs)`` of a vector run: per sub-env the steps before its horizon
    (``shadow_window``). The mask may run through an episode's end: the autoreset's episode starts from the
    sub-env's own generator, whatever round-off did to the last one, and is compared as long as everything before
    it was (its end, at the same step, included)."""
    T = rec["reward"].shape[0]
    keys = ["reward", "terminated", "truncated", "obs"]
    cut = {k: rec[k] for k in keys[:3]}
    cut_s = {k: shadow[k] for k in keys[:3]}
    cut["obs"], cut_s["obs"] = rec["obs"][1:], shadow["obs"][1:]
    horizon, jitter = shadow_window(cut_s, cut, keys, lead=2)
    return np.arange(T)[:, None] < horizon[None, :], jitter


# --------------------------------------------------------------------------------------------------
# low-level physics: hybrid_step, stance_step, flight_step
# --------------------------------------------------------------------------------------------------

HYBRID_FIELDS = (
    "q", "qd", "mode", "anchor_x", "lam_mean", "impulse", "stick_time", "slip_time", "flight_time", "slip_distance",
    "work", "work_load", "slip_dissipation", "impact_dissipation", "events", "painleve", "settles", "event_time",
    "event_kind",
)  # fmt: skip


def hybrid_one(q, qd, tau, mu, mode, anchor_x, params) -> dict:
    """One ``hybrid_step`` of a batch, as a dict of ``HYBRID_FIELDS``."""
    from leg_env.physics.hybrid import hybrid_step

    r = hybrid_step(q, qd, tau, params, mu, mode, anchor_x)
    return {k: np.asarray(getattr(r, k)) for k in HYBRID_FIELDS}


def hybrid_chain(q0, qd0, taus, mu, params, mode0=None, anchor0=None) -> dict:
    """``hybrid_step`` iterated from ``(q0, qd0)`` ``(N, 5)`` with the torques ``taus`` ``(T, N, 2)``, feeding
    back ``q, qd, mode, anchor_x``; the first step's mode and anchor are ``mode0`` / ``anchor0`` (None:
    hybrid_step's own choice). Returns each of ``HYBRID_FIELDS`` with the step axis first ``(T, N, ...)``, and
    the start of every step: ``start_q``, ``start_qd`` ``(T, N, 5)``, ``start_mode``, ``start_anchor_x``
    ``(T, N)`` (the first step's mode / anchor as hybrid_step chose them: recorded as -1 / NaN when None)."""
    q, qd, mode, anchor = np.array(q0, dtype=np.float64), np.array(qd0, dtype=np.float64), mode0, anchor0
    steps = []
    starts = []
    for t in range(len(taus)):
        starts.append((q, qd, np.full(len(q), -1) if mode is None else np.asarray(mode), np.full(len(q), np.nan) if anchor is None else np.asarray(anchor, dtype=np.float64)))
        r = hybrid_one(q, qd, taus[t], mu, mode, anchor, params)
        steps.append(r)
        q, qd, mode, anchor = r["q"], r["qd"], r["mode"], r["anchor_x"]
    out = {k: np.stack([s[k] for s in steps]) for k in HYBRID_FIELDS}
    out["start_q"] = np.stack([s[0] for s in starts])
    out["start_qd"] = np.stack([s[1] for s in starts])
    out["start_mode"] = np.stack([s[2] for s in starts]).astype(np.int64)
    out["start_anchor_x"] = np.stack([s[3] for s in starts])
    return out


def chain_starts(rec: dict, keys=("q", "qd", "mode", "anchor_x")) -> dict:
    """The start of every step of a recorded chain ``(T, N, ...)``: the initial state (``q0``, ``qd0``; mode -1 and
    anchor NaN: chosen by ``hybrid_step``), then each step's end. Not stored: rebuilt from the chain."""
    first = {"q": rec["q0"], "qd": rec["qd0"], "mode": np.full(rec["q0"].shape[0], -1, dtype=np.int64),
             "anchor_x": np.full(rec["q0"].shape[0], np.nan)}
    return {f"start_{k}": np.concatenate([first[k][None].astype(rec[k].dtype), rec[k][:-1]]) for k in keys if k in rec}


def hybrid_steps_from(starts_q, starts_qd, starts_mode, starts_anchor, taus, mu, params) -> dict:
    """One ``hybrid_step`` from each recorded step start (``(T, N, ...)`` arrays, all in one batch call):
    every control step checked on its own, without the error growth of a chained run. A start mode of -1
    (the chain's first step, given without one) is passed as None, in a call of its own."""
    T, N = starts_mode.shape
    mu_b = np.broadcast_to(np.asarray(mu, dtype=np.float64), (N,))
    out = {k: [None] * T for k in HYBRID_FIELDS}
    given = [t for t in range(T) if np.all(starts_mode[t] >= 0)]
    free = [t for t in range(T) if t not in given]
    for t in free:  # hybrid_step chooses the mode and anchor
        r = hybrid_one(starts_q[t], starts_qd[t], taus[t], mu_b, None, None, params)
        for k in HYBRID_FIELDS:
            out[k][t] = r[k]
    if given:
        g = np.array(given)
        shape = (len(g) * N,)
        r = hybrid_one(starts_q[g].reshape(shape + (5,)), starts_qd[g].reshape(shape + (5,)), taus[g].reshape(shape + (2,)),
                       np.tile(mu_b, len(g)), starts_mode[g].reshape(shape), starts_anchor[g].reshape(shape), params)
        for k in HYBRID_FIELDS:
            v = r[k].reshape((len(g), N) + r[k].shape[1:])
            for j, t in enumerate(given):
                out[k][t] = v[j]
    return {k: np.stack(v) for k, v in out.items()}


def pinned_chain(step: Callable, q0, qd0, taus, params, anchor=None) -> dict:
    """``stance_step`` (the feet pinned at ``anchor`` ``(N, 2)``) or ``flight_step`` iterated from ``(q0, qd0)``
    ``(N, 5)`` under ``taus`` ``(T, N, 2)``. Returns ``q``, ``qd`` (and ``lam_mean`` for ``stance_step``)
    ``(T, N, ...)`` at the step ends, and ``start_q``, ``start_qd``."""
    q, qd = np.array(q0, dtype=np.float64), np.array(qd0, dtype=np.float64)
    rows, starts = [], []
    for t in range(len(taus)):
        starts.append((q, qd))
        r = pinned_one(step, q, qd, taus[t], params, anchor)
        rows.append(r)
        q, qd = r["q"], r["qd"]
    out = {k: np.stack([r[k] for r in rows]) for k in rows[0]}
    out["start_q"] = np.stack([s[0] for s in starts])
    out["start_qd"] = np.stack([s[1] for s in starts])
    return out


def pinned_steps_from(step: Callable, starts_q, starts_qd, taus, params, anchor=None) -> dict:
    """One ``stance_step`` / ``flight_step`` from every recorded step start ``(T, N, 5)``, in one batch call."""
    T, N = starts_q.shape[:2]
    a = None if anchor is None else np.ascontiguousarray(np.broadcast_to(anchor, (T, N, 2)).reshape(T * N, 2))
    r = pinned_one(step, starts_q.reshape(T * N, 5), starts_qd.reshape(T * N, 5), taus.reshape(T * N, 2), params, a)
    return {k: v.reshape((T, N) + v.shape[1:]) for k, v in r.items()}


def pinned_one(step: Callable, q, qd, tau, params, anchor=None) -> dict:
    """One ``stance_step`` (pinned at ``anchor``) or ``flight_step`` (``anchor`` unused) of a batch."""
    from leg_env.physics.integrate import stance_step

    if step is stance_step:
        q1, qd1, lam = stance_step(q, qd, tau, params, anchor=anchor)
        return {"q": np.asarray(q1), "qd": np.asarray(qd1), "lam_mean": np.asarray(lam)}
    q1, qd1 = step(q, qd, tau, params)
    return {"q": np.asarray(q1), "qd": np.asarray(qd1)}


def chain_window(run: dict, shadow: dict, keys):
    """``(horizon (N,), jitter (T, N))`` of a chained run (``shadow_window``)."""
    return shadow_window(shadow, run, keys, lead=2)


# --------------------------------------------------------------------------------------------------
# controllers and shipped policies
# --------------------------------------------------------------------------------------------------


def make_policy(name: str, env_id: str):
    """A controller of ``policies/`` built for the task as registered, or a shipped SB3 policy folder."""
    if name.startswith("policies/"):
        from train.evaluate import load_policy

        return load_policy(ROOT / name)
    import gymnasium as gym

    import leg_env  # noqa: F401
    from policies.gated import GatedController
    from policies.hopper import HopperController
    from policies.lqr import LQRController
    from policies.stepping import SteppingController

    u = gym.make(current_id(env_id)).unwrapped
    return {"lqr": LQRController, "gated": GatedController, "hopper": HopperController, "stepping": SteppingController}[name](u.params, u.config)


def predicted_actions(policy, obs: np.ndarray) -> np.ndarray:
    """``policy.predict`` on each recorded observation in turn, from a reset (the stateful controllers' state
    follows the observations)."""
    if hasattr(policy, "reset"):
        policy.reset()
    return np.array([np.asarray(policy.predict(o, deterministic=True)[0], dtype=np.float64).reshape(2) for o in obs])


def to_json(obj) -> np.ndarray:
    """A JSON document as a 0-d unicode array (loads without pickle)."""
    return np.array(json.dumps(obj, sort_keys=True))


def from_json(a) -> object:
    return json.loads(str(np.asarray(a)[()]))
