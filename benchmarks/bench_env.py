"""Environment speed of leg-env next to Gymnasium's MuJoCo environments, in one run, one table.

    .venv/bin/python benchmarks/bench_env.py          # the table (about a minute)
    .venv/bin/python benchmarks/bench_env.py --ppo    # and PPO fps, 50,000 steps each (a few minutes)

MuJoCo comes from the ``bench`` extra (``pip install -e '.[bench]'``). One thread for BLAS/OpenMP
and torch. Every rate is the median over ``REPEATS`` timed repeats (``time.perf_counter``), each
timing a loop of steps and dividing; the rows are timed round-robin, repeat by repeat, and every ratio
is the median over the repeats of the two rows' ratio within one repeat, so that a change in machine
load between repeats cancels; random actions are sampled before timing (uniform over the
action space, seeded) because sampling costs more than a leg-env step. Episodes end as they do in
training, and their resets are part of the time: the single envs are reset by the loop, the vector
envs autoreset themselves.

Rows:
(a) ``env.step`` of one environment made by ``gymnasium.make`` (with its ``TimeLimit`` and
    checkers): leg-env, ``Hopper-v5`` and ``InvertedDoublePendulum-v5``; the ratio is Hopper's time
    over the row's.
(b) env-steps per second of ``gymnasium.make_vec``: leg-env's native batch (its default
    ``vector_entry_point``, NEXT_STEP autoreset) at N = 1, 64, 1024, 4096, and Gymnasium's
    ``SyncVectorEnv`` of ``Hopper-v5`` with 8 envs; the ratio is the row's rate over that one's.
    One more row runs leg-env's N = 4096 batch on every core (``num_threads``); all other rows,
    leg-env's and MuJoCo's, use one thread.
(c) env-steps per second of Stable-Baselines3 ``VecEnv.step``: leg-env's adapter
    (``leg_env.sb3``, which builds the per-env ``infos`` dicts SB3 wants) and SB3's
    ``DummyVecEnv`` of ``Hopper-v5`` with 8 envs (the ratio's reference).
(d) the unilateral contact model (``contact="unilateral"``) next to the pinned one: ``env.step``
    (ratio to Hopper-v5), ``gym.make_vec`` at N = 4096 under the same random actions (lift-offs, slips and
    touchdowns included; ratio to the pinned batch), and both models balancing: the stance LQR's action
    plus uniform noise of +-``BALANCE_NOISE``, only ``step`` timed, after ``BALANCE_WARMUP`` steps (ratio of
    unilateral to pinned).
(e) every other registered task (``leg_env.tasks.REGISTRY``: ``PlanarLegBalance-v1``, ``PlanarLegPush-v2``,
    ``PlanarLegHop-v4``)
    through ``gym.make_vec`` at N = 4096, under random actions and balancing, each as a share of the
    unilateral stance batch's rate under the same actions (the target: at least 90%).
With ``--ppo``: SB3 PPO (``MlpPolicy``, SB3's default hyperparameters, 16,384-step rollouts) for
50,000 steps on the adapter with 64 envs and on ``InvertedDoublePendulum-v5`` with 8
``DummyVecEnv`` envs; fps = steps / wall time, and the rollout-collection rate alone.
"""

from __future__ import annotations

import os

# only the row marked "threads" uses more than one core
os.environ["OMP_NUM_THREADS"] = "1"
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from importlib.metadata import version  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "env_speed.md"
sys.path.insert(0, str(ROOT))

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import leg_env  # noqa: E402

REPEATS = 7
SEED = 0
LEG = leg_env.ENV_ID
HOPPER = "Hopper-v5"
PENDULUM = "InvertedDoublePendulum-v5"
SINGLE_STEPS = {LEG: 20_000, HOPPER: 2_000, PENDULUM: 4_000}  # env.step calls per repeat (about 0.3 s)
VECTOR_SIZES = (1, 64, 1024, 4096)
SB3_SIZES = (64, 1024, 4096)
REFERENCE_ENVS = 8  # SyncVectorEnv / DummyVecEnv of Hopper-v5
ENV_STEPS_PER_REPEAT = 100_000  # leg-env batches: calls per repeat = clip(this / N, MIN_CALLS, MAX_CALLS)
MIN_CALLS, MAX_CALLS = 25, 2_000
REFERENCE_CALLS = 200  # SyncVectorEnv / DummyVecEnv of Hopper-v5: calls per repeat
PPO_TIMESTEPS = 50_000
PPO_ROLLOUT = 16_384  # steps per PPO rollout for both runs (SB3's default 2048 steps x 8 envs)
PPO_LEG_ENVS = 64
PPO_PENDULUM_ENVS = 8
# the targets, as ratios measured in this one run
TARGET_SINGLE_RATIO = 25.0  # pinned
TARGET_SINGLE_UNILATERAL_RATIO = 20.0
TARGET_VECTOR_RATIO = 200.0
TARGET_VECTOR_RATE = 500_000.0
TARGET_UNILATERAL_RATE = 1_000_000.0  # make_vec N = 4096, unilateral, random actions
TARGET_UNILATERAL_RANDOM = 0.7  # ... as a share of the pinned batch's rate under the same actions
TARGET_TASK_SHARE = 0.9  # every other task's make_vec N = 4096 as a share of the unilateral balance's
TASK_IDS = tuple(i for i in leg_env.ENV_IDS if i != LEG)
TARGET_UNILATERAL_BALANCE = 0.8  # balancing: unilateral over pinned
BALANCE_NOISE = 0.02  # half-width of the noise on the LQR's action in the balancing rows
BALANCE_WARMUP = 400  # untimed steps of every balancing row first (4 s: two pushes of a push episode, its falls and restarts)
UNILATERAL = {"contact": "unilateral"}
RANDOMISED = {"pinned": {}, "unilateral": UNILATERAL}  # randomize=True rows, against the same rows without it
_RANDOMISED_REFERENCE = {
    "pinned": (("randomised", ("vector", max(VECTOR_SIZES))), ("randomised balance", ("balance", "pinned"))),
    "unilateral": (("randomised", ("vector", "unilateral")), ("randomised balance", ("balance", "unilateral"))),
}
TARGET_RANDOMISED_SHARE = 0.9  # randomised over nominal, resets included
LIMIT_ROBOTS = 65_536  # robots of the arithmetic-limit rows: one compiled call, Python's share negligible


def sampled_actions(space: gym.spaces.Box, calls: int, n: int | None, seed: int = SEED) -> np.ndarray:
    """``calls`` uniform random actions (of ``n`` envs each, if given), sampled before any timing."""
    shape = (calls,) + ((n,) if n is not None else ()) + space.shape
    return np.random.default_rng(seed).uniform(space.low, space.high, size=shape).astype(space.dtype)


class Runner:
    """One table row: ``run()`` steps an environment through a pre-sampled action block, returning env-steps."""

    def __init__(self, run, close):
        self.run, self.close, self.rates = run, close, []

    def time_once(self) -> None:
        start = time.perf_counter()
        units = self.run()
        if isinstance(units, tuple):  # (units, seconds): the run timed only its own part
            units, seconds = units
        else:
            seconds = time.perf_counter() - start
        self.rates.append(units / seconds)

    @property
    def rate(self) -> float:
        return statistics.median(self.rates)


class Rates(dict):
    """The rows' median rates by key, and ``ratio(a, b)``: the median over the repeats of row a's rate over row b's in
    the same repeat. The rows are timed round-robin, so both rates of a pair come from one round and a change in
    machine load between rounds cancels in their ratio, where a ratio of the two medians would take it in."""

    def __init__(self, runners: dict):
        super().__init__({key: runner.rate for key, runner in runners.items()})
        self.repeats = {key: runner.rates for key, runner in runners.items()}

    def ratio(self, a, b) -> float:
        return statistics.median(x / y for x, y in zip(self.repeats[a], self.repeats[b], strict=True))


def single_env_runner(env_id: str, **kwargs) -> Runner:
    """``env.step`` calls through ``gymnasium.make``, resetting when an episode ends."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=SEED)
    steps = SINGLE_STEPS[env_id]
    actions = sampled_actions(env.action_space, steps, None)

    def run() -> int:
        for a in actions:
            _, _, terminated, truncated, _ = env.step(a)
            if terminated or truncated:
                env.reset()
        return steps

    return Runner(run, env.close)


def calls_for(n: int) -> int:
    return int(np.clip(ENV_STEPS_PER_REPEAT // n, MIN_CALLS, MAX_CALLS))


def balancer(envs, calls: int):
    """The balancing rows' actions for ``envs``: ``action(obs, k)``, the stance LQR (``policies.lqr``) on the
    observation's stance entries plus the ``k``-th (mod ``calls``) of ``calls`` uniform noises of +-``BALANCE_NOISE``.
    The first observation is ``envs``' reset's, after ``BALANCE_WARMUP`` untimed steps under these actions."""
    from leg_env.physics.layout import OBS
    from policies.lqr import LQRController

    lqr = LQRController(envs.params, envs.config)
    noise = np.random.default_rng(SEED).uniform(-BALANCE_NOISE, BALANCE_NOISE, size=(calls, envs.num_envs, 2))
    width = OBS["unilateral_dim"] if envs.unilateral else OBS["pinned_dim"]  # the stance's entries (not a hop's command)

    def action(obs, k: int) -> np.ndarray:
        return (lqr.predict(obs[:, :width])[0] + noise[k % calls]).astype(np.float32)

    obs = envs.reset(seed=SEED)[0]
    for k in range(BALANCE_WARMUP):
        obs = envs.step(action(obs, k))[0]
    return action, obs


def vector_env_runner(envs, calls: int | None = None, balance: bool = False) -> Runner:
    """Env-steps of a ``gymnasium.vector.VectorEnv`` (it autoresets) under pre-sampled random actions, or with
    ``balance`` under the stance LQR (``policies.lqr``) plus uniform noise of +-``BALANCE_NOISE``: every robot
    balances near the nominal posture, timed after ``BALANCE_WARMUP`` untimed steps (a task whose episodes bring
    pushes is timed with them, not over its quiet first second). The LQR's own time is not counted: only
    ``envs.step`` is timed."""
    n = envs.num_envs
    calls = calls or calls_for(n)
    if balance:
        act, first = balancer(envs, calls)
        state = {"obs": first}

        def run_balanced() -> tuple[int, float]:
            obs, spent = state["obs"], 0.0
            for k in range(calls):
                action = act(obs, k)
                start = time.perf_counter()
                obs = envs.step(action)[0]
                spent += time.perf_counter() - start
            state["obs"] = obs
            return calls * n, spent

        return Runner(run_balanced, envs.close)
    actions = sampled_actions(envs.single_action_space, calls, n)
    envs.reset(seed=SEED)

    def run() -> int:
        for a in actions:
            envs.step(a)
        return calls * n

    return Runner(run, envs.close)


def sb3_runner(venv, calls: int | None = None) -> Runner:
    """Env-steps of a Stable-Baselines3 ``VecEnv`` (step_async + step_wait)."""
    n = venv.num_envs
    calls = calls or calls_for(n)
    actions = sampled_actions(venv.action_space, calls, n)
    venv.seed(SEED)
    venv.reset()

    def run() -> int:
        for a in actions:
            venv.step(a)
        return calls * n

    return Runner(run, venv.close)


def time_all(runners: dict) -> None:
    """Warm every runner up, then time them round-robin ``REPEATS`` times (load changes hit all rows alike)."""
    for runner in runners.values():
        runner.run()
    for _ in range(REPEATS):
        for runner in runners.values():
            runner.time_once()
    for runner in runners.values():
        runner.close()


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    packages = ", ".join(
        f"{name} {version(name)}" for name in ("numpy", "gymnasium", "mujoco", "stable-baselines3", "torch")
    )
    return (
        f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}; Python {platform.python_version()}; "
        f"{packages}; one thread unless a row says otherwise"
    )


def fmt_rate(x: float) -> str:
    return f"{x:,.0f}"


def arithmetic_limit() -> dict:
    """Seconds per robot-step of the compiled control step alone, the physical limit of an env step: one
    ``kernels.rk4_step`` (pinned) and one ``kernels.hybrid_step`` (unilateral, the foot sticking, no event)
    over ``LIMIT_ROBOTS`` robots near the nominal posture under their holding torques; median of ``REPEATS``."""
    from leg_env._core import kernels
    from leg_env.physics.dynamics import foot_position, static_equilibrium
    from leg_env.physics.layout import RECORD
    from leg_env.physics.params import LegParams

    p = LegParams()
    q0, tau0, _ = static_equilibrium(p)
    n = LIMIT_ROBOTS
    rng = np.random.default_rng(SEED)
    q = np.tile(q0, (n, 1))
    q[:, 2:] += rng.uniform(-0.01, 0.01, (n, 3))
    anchor = foot_position(q, p)
    anchor[:, 1] = 0.0
    qd, tau = np.zeros((n, 5)), np.tile(tau0, (n, 1))
    kernels.project(q, qd, p.array, anchor)
    load, mu, lam, record = np.zeros(n), np.full(n, 0.5), np.empty((n, 2)), np.empty(n, dtype=RECORD)
    out = {}
    for name in ("pinned", "unilateral"):
        times = []
        for _ in range(REPEATS):
            qa, qda, anchor_a, mode = q.copy(), qd.copy(), anchor.copy(), np.zeros(n, dtype=np.int64)
            t0 = time.perf_counter()
            if name == "pinned":
                kernels.rk4_step(qa, qda, tau, p.array, load, anchor_a, 0.01, 2, 0.02, True, lam)
            else:
                kernels.hybrid_step(qa, qda, tau, p.array, load, mu, mode, anchor_a, 0.01, 2, 0.02, record)
            times.append((time.perf_counter() - t0) / n)
        out[name] = statistics.median(times)
    return out


def work_per_step(steps: int = 200) -> dict:
    """What one control step computes under the random actions of the timed rows, pinned and unilateral
    (``make_vec`` of ``VECTOR_SIZES[-1]`` robots, ``steps`` steps): the RK4 steps the step rule asks for
    (``leg_env.physics.integrate``: at least 2, more when a link turns fast), the RK4 steps the compiled step integrated
    (``out["rk4_steps"]``: the re-integrations that locate events included), the located events, and the share
    of robots in flight. The physics of a step costs about its RK4 steps (4 dynamics evaluations each, the same
    for every contact mode): their ratio bounds the unilateral share of the pinned rate at equal cost per RK4
    step."""
    from leg_env.physics.integrate import MAX_ANGLE, SUBSTEPS

    n = max(VECTOR_SIZES)
    out = {}
    for name, kwargs in (("pinned", {}), ("unilateral", UNILATERAL)):
        envs = gym.make_vec(LEG, num_envs=n, **kwargs)
        envs.reset(seed=SEED)
        kernel = _KernelClock(envs.task)
        envs.task = kernel  # the task's compiled step, timed inside each envs.step
        actions = sampled_actions(envs.single_action_space, steps, n)
        rule, rk4, events, flight, total = [], [], [], [], []
        for a in actions:
            going = ~envs._ended  # the work counts leave out the rows that restart (they step from their new start)
            qd = envs._state["qd"][going]
            va, vb, vc = qd[:, 2], qd[:, 3], qd[:, 4]
            w = np.max(np.abs(np.stack([va, vb, vc, va + vb, va + vb + vc])), axis=0)
            rule.append(np.maximum(SUBSTEPS, np.ceil(w * envs.config.dt / MAX_ANGLE)).mean())
            flight.append((envs._state["mode"] == 3).mean())
            start = time.perf_counter()
            envs.step(a)
            total.append(time.perf_counter() - start)
            events.append(envs._out["events"][going].mean())
            rk4.append(envs._out["rk4_steps"][going].mean())
        envs.close()
        out[name] = {"rule": float(np.mean(rule)), "rk4": float(np.mean(rk4)), "events": float(np.mean(events)), "flight": float(np.mean(flight)),
                     "step_us": 1e6 * statistics.median(total), "kernel_us": 1e6 * statistics.median(kernel.seconds)}
    return out


def balancing_work(steps: int = 200) -> dict:
    """RK4 steps and located events per control step of the balancing rows (the stance LQR plus noise, as
    ``vector_env_runner(balance=True)`` drives them) on the unilateral stance and on every task, ``make_vec`` of
    ``VECTOR_SIZES[-1]`` robots, ``steps`` steps after the rows' ``BALANCE_WARMUP`` (``balancer``). A task whose
    episodes knock the robot off balance (a push) asks for more RK4 steps than the stance: their ratio bounds the task's share of the stance's rate at equal cost
    per RK4 step."""
    n = max(VECTOR_SIZES)
    out = {}
    for name, env_id, kwargs in (("unilateral", LEG, UNILATERAL), *((i, i, {}) for i in TASK_IDS)):
        envs = gym.make_vec(env_id, num_envs=n, **kwargs)
        act, obs = balancer(envs, steps)
        rk4, events = [], []
        for k in range(steps):
            going = ~envs._ended  # the rows that restart step from their new start: left out, as in work_per_step
            obs = envs.step(act(obs, k))[0]
            rk4.append(envs._out["rk4_steps"][going].mean())
            events.append(envs._out["events"][going].mean())
        envs.close()
        out[name] = {"rk4": float(np.mean(rk4)), "events": float(np.mean(events))}
    return out


class _KernelClock:
    """A task whose ``step`` (the one compiled call of a batched env step) is timed; everything else is the task's."""

    def __init__(self, task):
        self._task, self.seconds = task, []

    def step(self, *args):
        start = time.perf_counter()
        result = self._task.step(*args)
        self.seconds.append(time.perf_counter() - start)
        return result

    def __getattr__(self, name):
        return getattr(self._task, name)


def env_table() -> dict:
    """Time everything, print the table, return the numbers the targets need."""
    from stable_baselines3.common.env_util import make_vec_env

    from leg_env.sb3 import make_sb3_vec_env

    runners = {("single", env_id): single_env_runner(env_id) for env_id in (LEG, HOPPER, PENDULUM)}
    runners["single", "unilateral"] = single_env_runner(LEG, **UNILATERAL)
    # the pinned batches just before the unilateral batch compared with them, so that the two are timed close together in each round
    runners.update({("vector", n): vector_env_runner(gym.make_vec(LEG, num_envs=n)) for n in VECTOR_SIZES})
    n = max(VECTOR_SIZES)
    runners["vector", "unilateral"] = vector_env_runner(gym.make_vec(LEG, num_envs=n, **UNILATERAL))
    runners["balance", "pinned"] = vector_env_runner(gym.make_vec(LEG, num_envs=n), balance=True)
    runners["balance", "unilateral"] = vector_env_runner(gym.make_vec(LEG, num_envs=n, **UNILATERAL), balance=True)
    for env_id in TASK_IDS:
        runners["task", env_id] = vector_env_runner(gym.make_vec(env_id, num_envs=n))
        runners["task balance", env_id] = vector_env_runner(gym.make_vec(env_id, num_envs=n), balance=True)
    for name, kwargs in RANDOMISED.items():  # the same rows with a robot per sub-env, drawn at every reset
        runners["randomised", name] = vector_env_runner(gym.make_vec(LEG, num_envs=n, randomize=True, **kwargs))
        runners["randomised balance", name] = vector_env_runner(gym.make_vec(LEG, num_envs=n, randomize=True, **kwargs), balance=True)
    runners["sync", HOPPER] = vector_env_runner(
        gym.make_vec(HOPPER, num_envs=REFERENCE_ENVS, vectorization_mode="sync"), REFERENCE_CALLS
    )
    threads = os.cpu_count() or 1
    if threads > 1:
        n = max(VECTOR_SIZES)
        runners["threaded", n] = vector_env_runner(gym.make_vec(LEG, num_envs=n, num_threads=threads))
    runners["dummy", HOPPER] = sb3_runner(make_vec_env(HOPPER, n_envs=REFERENCE_ENVS), REFERENCE_CALLS)
    runners.update({("sb3", n): sb3_runner(make_sb3_vec_env(n)) for n in SB3_SIZES})
    time_all(runners)
    rate = Rates(runners)

    rows = []
    for env_id in (LEG, HOPPER, PENDULUM):
        r = rate["single", env_id]
        rows.append(("`gym.make` `env.step`", env_id, 1, r, rate.ratio(("single", env_id), ("single", HOPPER))))
    r = rate["single", "unilateral"]
    rows.append(("`gym.make` `env.step`, unilateral", LEG, 1, r, rate.ratio(("single", "unilateral"), ("single", HOPPER))))
    for n in VECTOR_SIZES:
        rows.append(("`gym.make_vec` (native)", LEG, n, rate["vector", n], rate.ratio(("vector", n), ("sync", HOPPER))))
    for (kind, n), r in rate.items():
        if kind == "threaded":
            rows.append((f"`gym.make_vec` (native, {threads} threads)", LEG, n, r, rate.ratio((kind, n), ("sync", HOPPER))))
    rows.append(("`gym.make_vec` (`SyncVectorEnv`)", HOPPER, REFERENCE_ENVS, rate["sync", HOPPER], 1.0))
    big = max(VECTOR_SIZES)
    rows.append(("`gym.make_vec`, unilateral, random (ratio: to pinned)", LEG, big, rate["vector", "unilateral"], rate.ratio(("vector", "unilateral"), ("vector", big))))
    rows.append(("`gym.make_vec`, pinned, balancing", LEG, big, rate["balance", "pinned"], 1.0))
    rows.append(("`gym.make_vec`, unilateral, balancing (ratio: to pinned)", LEG, big, rate["balance", "unilateral"], rate.ratio(("balance", "unilateral"), ("balance", "pinned"))))
    for env_id in TASK_IDS:
        r = rate["task", env_id]
        rows.append(("`gym.make_vec`, random (ratio: to unilateral stance)", env_id, big, r, rate.ratio(("task", env_id), ("vector", "unilateral"))))
        r = rate["task balance", env_id]
        rows.append(("`gym.make_vec`, balancing (ratio: to unilateral stance)", env_id, big, r, rate.ratio(("task balance", env_id), ("balance", "unilateral"))))
    for name in RANDOMISED:
        for kind, reference in _RANDOMISED_REFERENCE[name]:
            what = "random" if kind == "randomised" else "balancing"
            rows.append((f"`gym.make_vec`, {name}, {what}, `randomize=True` (ratio: to nominal)", LEG, big, rate[kind, name], rate.ratio((kind, name), reference)))
    for n in SB3_SIZES:
        rows.append(("SB3 `VecEnv` (`leg_env.sb3`)", LEG, n, rate["sb3", n], rate.ratio(("sb3", n), ("dummy", HOPPER))))
    rows.append(("SB3 `DummyVecEnv`", HOPPER, REFERENCE_ENVS, rate["dummy", HOPPER], 1.0))

    limit = arithmetic_limit()
    for name, seconds in limit.items():
        rows.append((f"physical limit: the compiled control step alone ({name}; ratio: to the native batch)", LEG, LIMIT_ROBOTS, 1.0 / seconds,
                     (1.0 / seconds) / rate["vector", big] if name == "pinned" else (1.0 / seconds) / rate["balance", "unilateral"]))
    lines = [
        f"Environment speed, median of {REPEATS} round-robin repeats (a ratio: the median of its ratio within each repeat), "
        "random actions, resets included.",
        "ratio: (a) vs Hopper-v5 `env.step`; (b) vs `SyncVectorEnv(Hopper-v5, 8)`; (c) vs `DummyVecEnv(Hopper-v5, 8)`; "
        "(d) as the row says. The physical-limit rows time the compiled control step of one robot (RK4, 2 substeps) over "
        f"{LIMIT_ROBOTS:,} robots in one call, near the nominal posture: the arithmetic an env step cannot go below.",
        "",
        "| interface | environment | N | us per call | env-steps/s | ratio |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for interface, env_id, n, r, ratio in rows:
        lines.append(f"| {interface} | {env_id} | {n} | {1e6 * n / r:,.1f} | {fmt_rate(r)} | {ratio:.1f}x |")
    work = work_per_step()
    p, u = work["pinned"], work["unilateral"]
    lines += [
        "",
        "Work per control step under the same random actions (RK4 steps integrated, located events, robots in flight):",
        f"pinned {p['rk4']:.2f} RK4 steps; unilateral {u['rk4']:.2f} RK4 steps ({u['rule']:.2f} by the step rule at the step's start, "
        f"the rest the work of {u['events']:.3f} located events: {(u['rk4'] - u['rule']) / max(u['events'], 1e-12):.1f} RK4 steps "
        "per event, its location included), "
        f"{100 * u['flight']:.0f}% in flight. "
        f"At equal cost per RK4 step the unilateral physics runs at most {p['rk4'] / u['rk4']:.0%} of the pinned rate. "
        "An RK4 step costs more in flight than pinned: a stance step's base comes from the contact projection (its RK4 "
        "sums are never formed), a flight's is integrated.",
        f"Median `envs.step` over those steps: pinned {p['step_us']:,.0f} us, of which the compiled step {p['kernel_us']:,.0f} us; "
        f"unilateral {u['step_us']:,.0f} us, of which {u['kernel_us']:,.0f} us. The compiled step takes {u['kernel_us'] / p['kernel_us']:.2f}x "
        f"as long unilateral as pinned, the rest of the step (actions, resets, info) {(u['step_us'] - u['kernel_us']) / (p['step_us'] - p['kernel_us']):.2f}x.",
    ]
    balancing = balancing_work()
    stance = balancing["unilateral"]
    lines += [
        "",
        f"Work per control step while balancing (RK4 steps integrated, located events): unilateral stance {stance['rk4']:.2f} "
        f"RK4 steps, {stance['events']:.4f} events; "
        + "; ".join(
            f"{env_id} {w['rk4']:.2f}, {w['events']:.4f} events (at equal cost per RK4 step at most {stance['rk4'] / w['rk4']:.0%} of the stance's rate)"
            for env_id, w in balancing.items()
            if env_id != "unilateral"
        )
        + ". A push knocks a balancing robot into slip and flight: located events and faster links ask for more RK4 steps.",
    ]
    print("\n" + "\n".join(lines))
    rate["lines"] = lines
    return rate


def check_targets(rate: dict) -> bool:
    n = max(VECTOR_SIZES)
    single_ratio = rate.ratio(("single", LEG), ("single", HOPPER))
    vector_ratio = rate.ratio(("vector", n), ("sync", HOPPER))
    checks = [
        (f"`gym.make` env.step vs Hopper-v5 >= {TARGET_SINGLE_RATIO:.0f}x", f"{single_ratio:.1f}x", single_ratio >= TARGET_SINGLE_RATIO),
        (
            f"`gym.make_vec` N={n} vs SyncVectorEnv(Hopper-v5, {REFERENCE_ENVS}) >= {TARGET_VECTOR_RATIO:.0f}x",
            f"{vector_ratio:.0f}x",
            vector_ratio >= TARGET_VECTOR_RATIO,
        ),
        (
            f"`gym.make_vec` N={n} >= {fmt_rate(TARGET_VECTOR_RATE)} env-steps/s",
            fmt_rate(rate["vector", n]),
            rate["vector", n] >= TARGET_VECTOR_RATE,
        ),
    ]
    uni_single = rate.ratio(("single", "unilateral"), ("single", HOPPER))
    uni_random = rate["vector", "unilateral"]
    uni_random_share = rate.ratio(("vector", "unilateral"), ("vector", n))
    uni_balance = rate.ratio(("balance", "unilateral"), ("balance", "pinned"))
    checks += [
        (f"unilateral `env.step` vs Hopper-v5 >= {TARGET_SINGLE_UNILATERAL_RATIO:.0f}x", f"{uni_single:.1f}x", uni_single >= TARGET_SINGLE_UNILATERAL_RATIO),
        (
            f"unilateral `gym.make_vec` N={n}, random actions >= {fmt_rate(TARGET_UNILATERAL_RATE)} env-steps/s",
            fmt_rate(uni_random),
            uni_random >= TARGET_UNILATERAL_RATE,
        ),
        (
            f"unilateral vs pinned `gym.make_vec` N={n}, random actions >= {TARGET_UNILATERAL_RANDOM:.0%}",
            f"{uni_random_share:.0%}",
            uni_random_share >= TARGET_UNILATERAL_RANDOM,
        ),
        (
            f"unilateral vs pinned `gym.make_vec` N={n}, balancing >= {TARGET_UNILATERAL_BALANCE:.0%}",
            f"{uni_balance:.0%}",
            uni_balance >= TARGET_UNILATERAL_BALANCE,
        ),
    ]
    for env_id in TASK_IDS:
        for kind, reference in (("task", ("vector", "unilateral")), ("task balance", ("balance", "unilateral"))):
            share = rate.ratio((kind, env_id), reference)
            checks.append(
                (
                    f"{env_id} `gym.make_vec` N={n}, {'random actions' if kind == 'task' else 'balancing'} vs unilateral stance >= {TARGET_TASK_SHARE:.0%}",
                    f"{share:.0%}",
                    share >= TARGET_TASK_SHARE,
                )
            )
    for name in RANDOMISED:
        for kind, reference in _RANDOMISED_REFERENCE[name]:
            share = rate.ratio((kind, name), reference)
            what = "random actions" if kind == "randomised" else "balancing"
            checks.append((f"{name} `gym.make_vec` N={n}, {what}, randomised vs nominal >= {TARGET_RANDOMISED_SHARE:.0%}", f"{share:.0%}", share >= TARGET_RANDOMISED_SHARE))
    if ("threaded", n) in rate:
        threaded_ratio = rate.ratio(("threaded", n), ("sync", HOPPER))
        checks.append(
            (
                f"`gym.make_vec` N={n} on {os.cpu_count()} threads vs SyncVectorEnv(Hopper-v5, {REFERENCE_ENVS}) >= {TARGET_VECTOR_RATIO:.0f}x",
                f"{threaded_ratio:.0f}x",
                threaded_ratio >= TARGET_VECTOR_RATIO,
            )
        )
    lines = ["", "Targets:"] + [f"  {'PASS' if ok else 'FAIL'}  {name}: {value}" for name, value, ok in checks]
    print("\n".join(lines))
    rate["lines"] += lines
    return all(ok for _, _, ok in checks)


def ppo_table() -> None:
    """PPO fps on the adapter (64 envs) and on InvertedDoublePendulum-v5 (8 DummyVecEnv envs)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecMonitor

    from leg_env.sb3 import make_sb3_vec_env

    torch.set_num_threads(1)

    class RolloutClock(BaseCallback):
        """Wall time spent collecting rollouts (env steps + policy inference)."""

        def __init__(self):
            super().__init__()
            self.seconds = 0.0
            self._start = 0.0

        def _on_rollout_start(self) -> None:
            self._start = time.perf_counter()

        def _on_rollout_end(self) -> None:
            self.seconds += time.perf_counter() - self._start

        def _on_step(self) -> bool:
            return True

    runs = [
        ("leg-env, `leg_env.sb3` adapter", LEG, PPO_LEG_ENVS, lambda: VecMonitor(make_sb3_vec_env(PPO_LEG_ENVS, seed=SEED))),
        ("MuJoCo, `DummyVecEnv`", PENDULUM, PPO_PENDULUM_ENVS, lambda: make_vec_env(PENDULUM, n_envs=PPO_PENDULUM_ENVS, seed=SEED)),
    ]
    print(
        f"\nPPO (SB3 `MlpPolicy`, default hyperparameters, n_steps x n_envs = {PPO_ROLLOUT:,}), "
        f"learn({PPO_TIMESTEPS:,}), torch on one thread; fps = timesteps / wall time.\n"
    )
    print("| environment | VecEnv | n_envs | timesteps | wall s | fps | rollout fps |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for label, env_id, n_envs, make in runs:
        venv = make()
        clock = RolloutClock()
        model = PPO("MlpPolicy", venv, n_steps=PPO_ROLLOUT // n_envs, seed=SEED, device="cpu", verbose=0)
        start = time.perf_counter()
        model.learn(PPO_TIMESTEPS, callback=clock)
        wall = time.perf_counter() - start
        steps = model.num_timesteps
        print(
            f"| {env_id} | {label} | {n_envs} | {steps:,} | {wall:.1f} | {fmt_rate(steps / wall)} | {fmt_rate(steps / clock.seconds)} |",
            flush=True,
        )
        venv.close()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--ppo", action="store_true", help=f"also time PPO for {PPO_TIMESTEPS:,} steps on leg-env and {PENDULUM}")
    args = parser.parse_args()
    header = f"Machine: {machine()}"
    print(header)
    rate = env_table()
    ok = check_targets(rate)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(f"# Environment speed\n\nWritten by `python benchmarks/bench_env.py` on {time.strftime('%Y-%m-%d')}.\n\n{header}\n\n"
                       + "\n".join(rate["lines"]) + "\n")
    print(f"\nwritten: {RESULTS.relative_to(ROOT)}")
    if args.ppo:
        ppo_table()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
