"""Continuity: the present code replays the trajectories recorded from the numba implementation, step by step.

``tests/data/reference_trajectories.npz`` was written by ``tests/reference/record.py`` from the numba kernels
(the commit and the versions are in its ``meta``), before their port to a compiled C core. Each test here
re-runs a recorded trajectory with the code present (same seeds, same stored actions or torques, same start
states; the drivers are ``tests/reference/runners.py``, shared with the recorder) and asserts agreement on every
recorded quantity, step by step:

* float64 quantities (rewards, every numeric ``info`` value, the physics functions' outputs):
  ``|a - b| <= 1e-9 (1 + |b|)``, ``b`` the recorded value;
* float32 observations: ``|a - b| <= 1e-6 (1 + |b|)``. An observation is a float64 state rounded to float32,
  whose step is 2^-23 = 1.2e-7 of the value: a state that moved by round-off (a re-ordered sum in C) can round to
  the neighbouring float32, so a float64-sized tolerance would demand bit equality; 1e-6 allows a few float32
  steps and no more (the float64 quantities next to them are held to 1e-9);
* discrete quantities (terminated, truncated, contact mode, event counts and kinds, Painleve and Zeno counts,
  violation flags): exactly.

Where each comparison stops, and why, is stated per test below. In short: a fall (a termination) amplifies
round-off, so an episode is compared to its termination at most; and a trajectory of an unstable or chaotic
motion (random actions, a fall, flailing, hopping) is compared only while it is well conditioned, which the
recorder measured by a shadow run with every action / torque changed by a relative 1e-14 per step (about ten
times the few-ulp differences of a re-ordered implementation): the comparison stops at the step before the
shadow run departed by 1/10 of the tolerance and stayed departed (``runners.py``'s docstring). An isolated step
where the shadow run departed for that step alone (``jitter``: a located event's time is fixed only to the root
finder's 1e-12 s bracket, which moves that step's mean contact force by up to ~4e-10 of itself, and not the state;
or a mean force passing near zero, where the tolerance is tightest) has only its discrete quantities compared. The stored windows (``n_compare``, ``mask``, ``horizon``, ``jitter``,
``step_ok``) are that measurement; ``test_recording_covers_the_contact_events`` checks that what
is compared still contains stick, slip, flight, impacts and every event kind.

Do not re-record the data to make a failure go away (``record.py``'s docstring).

The tests that need Stable-Baselines3 (and torch): ``test_shipped_policy_sb3_actions``. The shipped policies'
episodes themselves are replayed (open loop, with their recorded actions) by ``test_policy_episode_replay``,
which needs no SB3.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

# tests/reference/runners.py, the drivers shared with the recorder, loaded by its path (sys.path stays as it is)
_spec = importlib.util.spec_from_file_location("continuity_runners", Path(__file__).resolve().parent / "reference" / "runners.py")
R = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = R
_spec.loader.exec_module(R)

DATA = Path(__file__).resolve().parent / "data" / "reference_trajectories.npz"
ROOT = Path(__file__).resolve().parents[1]


def _load() -> tuple[dict, dict]:
    with np.load(DATA, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    return data, R.from_json(data.pop("meta"))


DATA_ARRAYS, META = _load()


def group(prefix: str) -> dict:
    """The arrays stored under ``prefix/``, keys without it."""
    return {k[len(prefix) + 1 :]: v for k, v in DATA_ARRAYS.items() if k.startswith(prefix + "/")}


def assert_agree(actual: dict, expected: dict, keys, compared: np.ndarray, what: str, tol_scale: float = 1.0,
                 jitter: np.ndarray | None = None) -> None:
    """Every key agrees (``R.mismatch``) wherever ``compared`` (over the leading axes) is True, float keys only where
    ``jitter`` is not (``runners.shadow_window``); the message names the first step (and robot) that does not, the
    key, both values and the tolerance."""
    for k in keys:
        b = expected[k]
        a = np.asarray(actual[k])
        if a.shape != b.shape:
            raise AssertionError(f"{what}: {k} has shape {a.shape}, recorded {b.shape}")
        where_compared = compared if jitter is None or b.dtype.kind in "biu" else compared & ~jitter
        tol = R.tolerance_of(k, b) * tol_scale
        bad = R.mismatch(a, b, tol, lead=compared.ndim) & where_compared
        if bad.any():
            where = tuple(int(i) for i in np.argwhere(bad)[0])
            rule = "must be equal" if b.dtype.kind in "biu" else f"tolerance {tol:g} (1 + |recorded|)"
            raise AssertionError(
                f"{what}: {k} differs at (step, ...) {where} ({int(bad.sum())} of {int(where_compared.sum())} compared entries): "
                f"got {a[where]!r}, recorded {b[where]!r}, {rule}"
            )


# --------------------------------------------------------------------------------------------------
# 0. the recording
# --------------------------------------------------------------------------------------------------


def test_recording_provenance_and_versions():
    prov = META["provenance"]
    assert prov["recorded_from"].startswith("the numba implementation")
    assert len(prov["git_commit"] or "") == 40
    assert not prov["git_uncommitted_changes_in_leg_env_policies_train"]
    assert prov["numpy"] and prov["gymnasium"] and prov["numba"]
    assert prov["tolerances"]["F64_TOL"] == R.F64_TOL and prov["tolerances"]["F32_TOL"] == R.F32_TOL
    assert str(DATA_ARRAYS["provenance/git_commit"]) == prov["git_commit"]


def test_recording_covers_the_contact_events():
    """The compared windows (not only the recording) contain stick, slip, flight, impacts, every event kind and
    terminations; the single-env episodes cover every task id of the recorded commit."""
    hybrid = META["hybrid"]
    for stats in (hybrid["chained_compared"], hybrid["all_steps"]):
        assert stats["steps_flight"] > 0 and stats["steps_slip"] > 0 and stats["steps_impact"] > 0
        assert all(v > 0 for v in stats["events"].values()), stats["events"]
    assert hybrid["one_step_compared"] >= 0.99 * hybrid["n"] * hybrid["steps"]
    single = META["single"]
    assert {s["env_id"] for s in single} == set(META["provenance"]["env_ids"])
    assert len(META["provenance"]["env_ids"]) == 4
    compared = [s["events_compared"] for s in single if "events_compared" in s]
    for key in ("steps_flight", "steps_slip", "steps_impact", "steps_events"):
        assert sum(c[key] for c in compared) > 0, key
    assert sum(c["end_modes"]["stick"] for c in compared) > 0
    assert any(s["terminated"] and s["n_compare"] == s["steps"] for s in single), "no termination is compared"
    assert any(s["kwargs"].get("randomize") for s in single) and any(v["kwargs"].get("randomize") for v in META["vector"])


# --------------------------------------------------------------------------------------------------
# 3. low-level physics: hybrid_step, stance_step, flight_step
# --------------------------------------------------------------------------------------------------


def _params():
    from leg_env.physics.params import LegParams

    return LegParams()


def test_hybrid_step_from_every_recorded_state():
    """One ``hybrid_step`` from the start of every recorded step (64 robots x 200 steps, one batch call), against
    that step's recorded outcome: every ``HybridStep`` field. Each step starts from the recorded state, so errors
    do not accumulate and nearly every step of the 200 is compared, falls and flailing included. Left out
    (``step_ok`` False, counted in ``meta["hybrid"]["one_step_left_out"]``): the steps whose outcome a relative
    1e-14 torque change moved by more than 1e-10 (1 + |b|) when recorded, i.e. near-ties of an event or a mode
    choice, where a different round-off may take the other branch."""
    h = group("hybrid")
    s = R.chain_starts(h)
    got = R.hybrid_steps_from(s["start_q"], s["start_qd"], s["start_mode"], s["start_anchor_x"], h["tau"], h["mu"], _params())
    assert_agree(got, h, R.HYBRID_FIELDS, h["step_ok"], "hybrid_step, one step from the recorded state")


def test_hybrid_step_chained_runs():
    """``hybrid_step`` iterated from the 64 recorded initial states with the recorded torques, feeding back
    ``q, qd, mode, anchor_x`` (as recorded). Stops, per robot, at ``horizon[i]``: the step before the shadow run
    (torques x (1 - 1e-14 u)) departed for good when recorded; these robots flail under random torques, lift off,
    land and fall (chaotic), so exact agreement cannot survive a different summation order for long. On the
    isolated ``jitter`` steps before it (an event time fixed only to the root finder's bracket) only the discrete
    fields are compared."""
    h = group("hybrid")
    steps = int(h["horizon"].max())
    got = R.hybrid_chain(h["q0"], h["qd0"], h["tau"][:steps], h["mu"], _params())
    compared = np.arange(steps)[:, None] < h["horizon"][None, :]
    expected = {k: h[k][:steps] for k in R.HYBRID_FIELDS}
    assert_agree(got, expected, R.HYBRID_FIELDS, compared, "hybrid_step, chained", jitter=h["jitter"][:steps])


@pytest.mark.parametrize("name", ["stance", "flight"])
def test_stance_and_flight_step(name):
    """``stance_step`` (foot pinned at ``anchor``) / ``flight_step`` from 16 perturbed equilibria under torques
    about the holding torques, 200 steps: (1) one step from every recorded step start, all compared but the
    ill-conditioned ones (``step_ok``, as for ``hybrid_step``); (2) the chained run, per robot to ``horizon[i]``,
    the step before the shadow run departed for good (the pinned leg falls over: an unstable motion; flight: a
    tumbling double pendulum, up to 200 rad/s; on the isolated ``jitter`` steps, where a mean force passes near zero
    or the rates peak, nothing is compared: these have no discrete quantities)."""
    from leg_env.physics.integrate import flight_step, stance_step

    step = {"stance": stance_step, "flight": flight_step}[name]
    g = group(name)
    keys = [k for k in ("q", "qd", "lam_mean") if k in g]
    anchor = g.get("anchor")
    s = R.chain_starts(g, keys=("q", "qd"))
    one = R.pinned_steps_from(step, s["start_q"], s["start_qd"], g["tau"], _params(), anchor)
    assert_agree(one, g, keys, g["step_ok"], f"{name}_step, one step from the recorded state")
    steps = int(g["horizon"].max())
    run = R.pinned_chain(step, g["q0"], g["qd0"], g["tau"][:steps], _params(), anchor)
    compared = np.arange(steps)[:, None] < g["horizon"][None, :]
    assert_agree(run, {k: g[k][:steps] for k in keys}, keys, compared, f"{name}_step, chained", jitter=g["jitter"][:steps])


# --------------------------------------------------------------------------------------------------
# 1. single environments
# --------------------------------------------------------------------------------------------------


def _single_id(spec) -> str:
    kw = "-randomize" if spec["kwargs"].get("randomize") else ""
    return f"{spec['env_id'].split('/')[-1]}{kw}-{spec['actions']}-seed{spec['seed']}"


def recorded_width(env_id: str, recorded: np.ndarray, got: np.ndarray) -> int:
    """The observation entries to compare: all of them, or for an id replayed by its successor
    (``runners.SUCCESSORS``), which appends entries, the recorded ones."""
    width = recorded.shape[-1]
    if R.current_id(env_id) == env_id or got.shape[-1] < width:
        assert got.shape[-1] == width, f"{env_id}: observations of {got.shape[-1]} entries, recorded {width}"
    return width


def replay_single(prefix: str, spec: dict) -> None:
    """Replay a recorded single-env episode with its stored actions and compare the reset's obs and info, then
    steps ``0 .. n_compare - 1``: obs, reward, terminated, truncated and every numeric info value."""
    rec = group(prefix)
    n = spec["n_compare"]
    got = R.run_single(spec["env_id"], spec["kwargs"], spec["seed"], rec["action"][:n])
    what = f"{prefix} ({spec['env_id']} {spec['kwargs']} seed {spec['seed']})"
    reset_keys = sorted(k for k in rec if k.startswith("reset_info/"))
    # every recorded key is still there (keys added since, such as com_position, are not in the recording)
    assert set(reset_keys) <= {k for k in got if k.startswith("reset_info/")}, f"{what}: reset info keys"
    assert_agree({k: got[k][None] for k in reset_keys}, {k: rec[k][None] for k in reset_keys}, reset_keys, np.ones(1, bool), what + ", reset")
    width = recorded_width(spec["env_id"], rec["obs"], got["obs"])
    assert_agree({"obs": got["obs"][:1, :width]}, {"obs": rec["obs"][:1]}, ["obs"], np.ones(1, bool), what + ", reset")
    assert len(got["reward"]) == n, f"{what}: the replay ended after {len(got['reward'])} steps, the record ran {spec['steps']} (compared {n})"
    keys = R.single_step_keys(rec)
    assert set(keys) <= set(R.single_step_keys(got)), f"{what}: recorded info keys missing"
    keys = [k for k in keys if k not in R.changed_keys(spec["env_id"])]
    expected = {k: rec[k][:n] for k in keys}
    expected["obs"] = rec["obs"][1 : n + 1]
    actual = {k: got[k] for k in keys}
    actual["obs"] = got["obs"][1:, : recorded_width(spec["env_id"], rec["obs"], got["obs"])]
    assert_agree(actual, expected, keys + ["obs"], np.ones(n, bool), what, jitter=rec["jitter"][:n])


@pytest.mark.parametrize("index", range(len(META["single"])), ids=[_single_id(s) for s in META["single"]])
def test_single_env_episode(index):
    """``gymnasium.make(id)`` episodes (uniform random, bang-bang and oversized actions; ``randomize=True``).
    Compared from the reset to the episode's end (its termination, or 300 steps), or to ``n_compare``, the step
    before the shadow run departed, if that comes first: random actions make the robot fall, a fall amplifies
    round-off, and the unilateral episodes' hops and slips are chaotic."""
    replay_single(f"single/{index:02d}", META["single"][index])


# --------------------------------------------------------------------------------------------------
# 2. vector environments
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("index", range(len(META["vector"])),
                         ids=[f"{v['env_id'].split('/')[-1]}{'-randomize' if v['kwargs'].get('randomize') else ''}" for v in META["vector"]])
def test_vector_env(index):
    """``gymnasium.make_vec(id, num_envs=8, vectorization_mode="vector_entry_point")``, 150 steps of the stored
    random actions, autoresets as they come. The reset observations are compared for every sub-env; then step
    ``t`` of sub-env ``i`` where ``mask[t, i]``: every step before the shadow run departed in that sub-env
    (random actions: the robots fall, which amplifies round-off). The mask may run through a termination into the
    autoreset's next episode, which starts from the sub-env's own generator, not from the fallen state."""
    spec = META["vector"][index]
    rec = group(f"vector/{index:02d}")
    got = R.run_vector(spec["env_id"], spec["kwargs"], spec["num_envs"], spec["seed"], rec["action"])
    what = f"vector {index} ({spec['env_id']} {spec['kwargs']} seed {spec['seed']})"
    width = recorded_width(spec["env_id"], rec["obs"], got["obs"])
    assert_agree({"obs": got["obs"][:1, :, :width]}, {"obs": rec["obs"][:1]}, ["obs"], np.ones(1, bool), what + ", reset")
    keys = [k for k in ("reward", "terminated", "truncated") if k not in R.changed_keys(spec["env_id"])]
    actual = {k: got[k] for k in keys}
    actual["obs"] = got["obs"][1:, :, :width]
    expected = {k: rec[k] for k in keys}
    expected["obs"] = rec["obs"][1:]
    assert_agree(actual, expected, keys + ["obs"], rec["mask"], what, jitter=rec["jitter"])


# --------------------------------------------------------------------------------------------------
# 4. the controllers' and the shipped policies' evaluation episodes
# --------------------------------------------------------------------------------------------------


def _policy_id(spec) -> str:
    return f"{spec['name'].split('/')[-1]}-{spec['env_id'].split('/')[-1]}-seed{spec['seed']}"


@pytest.mark.parametrize("index", range(len(META["policy"])), ids=[_policy_id(s) for s in META["policy"]])
def test_policy_episode_replay(index):
    """The environment under a controller's / shipped policy's recorded actions, open loop (no SB3 needed).
    Compared from the reset to the end (termination or 300 steps) or to ``n_compare``, the step before the shadow
    run departed. Replayed open loop, the balancing robot is an unstable system that the closed loop held up: a
    difference grows about 4-fold every 20 steps (``e^(7 t)``), and the float32 observations would hide it from
    a closed-loop replay too until it reached their resolution. So these episodes are compared over their first
    100 to 200 steps (``n_compare``, measured by the shadow run), not all 300."""
    replay_single(f"policy/{index:02d}", META["policy"][index])


def _predict_check(index: int) -> None:
    """``predict`` on the recorded observations, in order from a reset (the stateful controllers' phases follow
    them), against the recorded actions, at float32 resolution (the controllers return float32 actions; their
    gains come from the dynamics, e.g. the LQR's finite-difference linearisation, where round-off changes the
    last float32 digit at most). Every step of the episode is compared: fed the recorded observations, nothing
    accumulates."""
    spec = META["policy"][index]
    rec = group(f"policy/{index:02d}")
    policy = R.make_policy(spec["name"], spec["env_id"])
    obs = rec["obs"][:-1]
    width = gym.make(R.current_id(spec["env_id"])).observation_space.shape[0]
    if width > obs.shape[1]:  # a successor's appended entries, which no controller reads: NaN would show if one did
        assert R.current_id(spec["env_id"]) != spec["env_id"]
        obs = np.concatenate([obs, np.full((len(obs), width - obs.shape[1]), np.nan, np.float32)], axis=1)
    got = R.predicted_actions(policy, obs)
    T = len(rec["action"])
    assert_agree({"action": got}, {"action": rec["action"]}, ["action"], np.ones(T, bool),
                 f"{spec['name']} on {spec['env_id']} seed {spec['seed']}, predict", tol_scale=R.F32_TOL / R.F64_TOL)


@pytest.mark.parametrize("index", [i for i, s in enumerate(META["policy"]) if not s.get("sb3")],
                         ids=[_policy_id(s) for s in META["policy"] if not s.get("sb3")])
def test_controller_actions(index):
    _predict_check(index)


SHIPPED = [i for i, s in enumerate(META["policy"]) if s.get("sb3") and s["name"] not in R.RETIRED_POLICIES]


def test_every_recorded_policy_is_shipped_or_retired():
    """A recorded shipped policy is still shipped, or is retired (``runners.RETIRED_POLICIES``: its folder is gone,
    its episodes are still replayed open loop)."""
    for spec in META["policy"]:
        if spec.get("sb3"):
            name = spec["name"]
            assert (name in R.RETIRED_POLICIES) != (ROOT / name / "model.zip").is_file(), name


@pytest.mark.sb3
@pytest.mark.parametrize("index", SHIPPED, ids=[_policy_id(META["policy"][i]) for i in SHIPPED])
def test_shipped_policy_sb3_actions(index):
    """The shipped SB3 policies (``train.evaluate.load_policy``: PPO, VecNormalize, residual controllers): needs
    Stable-Baselines3 and torch."""
    import torch

    torch.set_num_threads(1)
    _predict_check(index)
