"""Speed of leg-env's stance dynamics and integrator next to Pinocchio, in one run, one table.

    .venv/bin/python benchmarks/bench_dynamics.py

Every number is the median over ``REPEATS`` timed repeats (``time.perf_counter``). (a) times loops
of calls, alternating leg-env and Pinocchio repeats; (b) and (c) time trajectories of
``STEPS_PER_ROUND`` control steps from fixed start states (the reset between trajectories is not
timed). One thread (BLAS/OpenMP).

(a) One stance-dynamics evaluation on one robot, called from Python:
    ``leg_env.physics.dynamics.stance_dynamics`` vs Pinocchio's constrained forward dynamics
    (forward kinematics with zero acceleration, foot frame Jacobian, foot classical
    acceleration as the drift, ``pin.forwardDynamics``) on the same model (``tests/pin_model.py``).
(b) One control step (dt = 0.01 s, 2 RK4 steps = 8 dynamics evaluations at the defaults) on one robot:
    ``integrate.stance_step`` (checked public wrapper) and ``integrate.step_inplace`` on (1, 5)
    arrays (what the environments call), vs a Python RK4 loop over the same 8 Pinocchio
    evaluations (no contact projection: this favours Pinocchio).
(c) Robot-steps per second with ``step_inplace`` on batches of N robots, vs a Python loop over
    robots stepping Pinocchio as in (b) (its cost per robot-step does not depend on N, so it is
    timed on ``PIN_ROBOT_STEPS`` robot-steps of the first robots).

States: the nominal stance posture (``static_equilibrium``, knee 0.8) with N(0, 0.05 rad) on the
three angles and N(0, 0.3) on the velocities, projected onto the contact manifold. Torques: the
holding torques plus U(-5, 5) N m per joint, redrawn for every robot and step (pre-sampled).
The benchmark reports how many RK4 steps per control step the adaptive rule actually took.
"""

from __future__ import annotations

import math
import os

os.environ["NUMBA_NUM_THREADS"] = "1"
os.environ["OMP_NUM_THREADS"] = "1"

import platform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # leg_env, and the one Pinocchio model builder

import platform  # noqa: E402
import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

from leg_env import physics as dyn  # noqa: E402
from leg_env.physics.params import LegParams  # noqa: E402
from pin_model import build_model  # noqa: E402

REPEATS = 7
SEED = 0
ANGLE_NOISE = 0.05  # [rad]
RATE_NOISE = 0.3  # [m/s, rad/s]
TORQUE_NOISE = 5.0  # [N m] uniform half-width around the holding torques
BATCH_SIZES = (1, 64, 1024, 4096)
STEPS_PER_ROUND = 20  # each timed trajectory: 0.2 s from the start states, then reset (untimed)
ROBOT_STEPS_PER_REPEAT = 40_000  # leg-env: trajectories per repeat = max(1, this / (N * STEPS_PER_ROUND))
PIN_ROBOT_STEPS = 80  # Pinocchio (about 0.2 ms per robot-step): robot-steps per repeat
TARGET_EVAL_RATIO = 3.0
TARGET_STEP_US = 20.0
TARGET_RATE_4096 = 500_000.0


def paired_median_seconds(fn_a, number_a: int, fn_b, number_b: int) -> tuple[float, float]:
    """Medians over REPEATS of the mean time of one call of ``fn_a`` and of ``fn_b``, each timed
    in a loop of ``number_*`` calls; the repeats alternate, so both see the same machine load."""
    fn_a(), fn_b()  # warm up (JIT, caches)
    times_a, times_b = [], []
    for _ in range(REPEATS):
        for fn, number, times in ((fn_a, number_a, times_a), (fn_b, number_b, times_b)):
            t0 = time.perf_counter()
            for _ in range(number):
                fn()
            times.append((time.perf_counter() - t0) / number)
    return statistics.median(times_a), statistics.median(times_b)


def machine_info() -> str:
    cpu = platform.processor() or "?"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return (
        f"{platform.platform()} | {cpu} | {os.cpu_count()} CPUs | Python {platform.python_version()} | "
        f"numpy {np.__version__} | C core ({platform.python_compiler()}) | pin {pin.__version__} | "
        f"NUMBA_NUM_THREADS={os.environ['NUMBA_NUM_THREADS']} OMP_NUM_THREADS={os.environ['OMP_NUM_THREADS']}"
    )


class PinStance:
    """Pinocchio's stance dynamics and a Python RK4 control step for one robot."""

    def __init__(self, p: LegParams):
        self.model, self.foot = build_model(p)
        self.data = self.model.createData()
        self.zero = np.zeros(self.model.nv)
        self.tau = np.zeros(self.model.nv)

    def dynamics(self, q, v, tau2):
        model, data, foot, LWA = self.model, self.data, self.foot, pin.LOCAL_WORLD_ALIGNED
        self.tau[3:] = tau2
        pin.forwardKinematics(model, data, q, v, self.zero)
        J = pin.computeFrameJacobian(model, data, q, foot, LWA)[:2]
        drift = pin.getFrameClassicalAcceleration(model, data, foot, LWA).linear[:2]
        return pin.forwardDynamics(model, data, q, v, self.tau, J, drift)

    def step(self, q, v, tau2, dt=dyn.DT, n=dyn.SUBSTEPS):
        f, h = self.dynamics, dt / n
        for _ in range(n):
            a1 = f(q, v, tau2)
            q2, v2 = q + 0.5 * h * v, v + 0.5 * h * a1
            a2 = f(q2, v2, tau2)
            q3, v3 = q + 0.5 * h * v2, v + 0.5 * h * a2
            a3 = f(q3, v3, tau2)
            q4, v4 = q + h * v3, v + h * a3
            a4 = f(q4, v4, tau2)
            q = q + (h / 6.0) * (v + 2.0 * v2 + 2.0 * v3 + v4)
            v = v + (h / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        return q, v


def initial_states(p: LegParams, rng, n: int):
    q_eq, tau_eq, _ = dyn.static_equilibrium(p)
    q = q_eq + np.concatenate([np.zeros((n, 2)), rng.normal(0.0, ANGLE_NOISE, (n, 3))], axis=1)
    qd = rng.normal(0.0, RATE_NOISE, (n, 5))
    anchor = np.zeros((n, 2))
    q, qd = dyn.project_stance(q, qd, p, anchor)
    return q, qd, anchor, tau_eq


def main() -> None:
    p = LegParams()
    pa = p.array
    rng = np.random.default_rng(SEED)
    ref = PinStance(p)

    # ---- (a) one evaluation --------------------------------------------------------------
    q, qd, anchor, tau_eq = initial_states(p, rng, 1)
    q, qd, anchor = q[0].copy(), qd[0].copy(), anchor[0].copy()
    tau = tau_eq + rng.uniform(-TORQUE_NOISE, TORQUE_NOISE, 2)
    qdd_leg, _ = dyn.stance_dynamics(q, qd, tau, p)
    qdd_pin = ref.dynamics(q, qd, tau)
    agreement = np.abs(qdd_leg - qdd_pin).max()
    assert agreement < 1e-10, f"leg-env and Pinocchio disagree by {agreement}"
    t_eval_leg, t_eval_pin = paired_median_seconds(
        lambda: dyn.stance_dynamics(q, qd, tau, p), 20_000, lambda: ref.dynamics(q, qd, tau), 5_000
    )

    # ---- (b) one control step, (c) batches: 20-step trajectories from the start states ---------
    def seconds_per_step(step, reset, rounds):
        """Median over REPEATS of the time per control step over ``rounds`` trajectories of
        STEPS_PER_ROUND steps; ``reset()`` restores the start state outside the timing."""
        times = []
        for _ in range(REPEATS + 1):  # the first repeat warms up
            total = 0.0
            for _ in range(rounds):
                reset()
                t0 = time.perf_counter()
                for k in range(STEPS_PER_ROUND):
                    step(k)
                total += time.perf_counter() - t0
            times.append(total / (rounds * STEPS_PER_ROUND))
        return statistics.median(times[1:])

    def batch_case(n):
        q0, qd0, anc, tau_eq = initial_states(p, rng, n)
        taus = tau_eq + rng.uniform(-TORQUE_NOISE, TORQUE_NOISE, (STEPS_PER_ROUND, n, 2))
        state = {"q": q0.copy(), "qd": qd0.copy()}

        def reset():
            state["q"][:] = q0
            state["qd"][:] = qd0

        return q0, qd0, anc, taus, state, reset

    substep_counts = []

    def _rk4_steps(qd):
        """The RK4 steps the step rule takes for the rates qd (``leg_env.physics.integrate``'s docstring)."""
        va, vb, vc = qd[2], qd[3], qd[4]
        w = max(abs(va), abs(vb), abs(vc), abs(va + vb), abs(va + vb + vc))
        return max(dyn.SUBSTEPS, min(dyn.MAX_SUBSTEPS, math.ceil(w * dyn.DT / dyn.MAX_ANGLE)))

    def record_substeps(q0, qd0, anc, taus):
        qb, qdb, lam = q0.copy(), qd0.copy(), np.empty((len(q0), 2))
        for k in range(STEPS_PER_ROUND):
            substep_counts.extend(_rk4_steps(v) for v in qdb)
            dyn.step_inplace(qb, qdb, taus[k], pa, anc, dyn.DT, dyn.SUBSTEPS, dyn.MAX_ANGLE, True, lam)
        assert np.isfinite(qb).all()

    # (b): one robot
    q0, qd0, anc, taus, state, reset = batch_case(1)
    record_substeps(q0, qd0, anc, taus)
    lam1 = np.empty((1, 2))
    single = {"q": q0[0].copy(), "qd": qd0[0].copy()}

    def reset_single():
        single["q"], single["qd"] = q0[0].copy(), qd0[0].copy()

    def public_step(k):
        single["q"], single["qd"], _ = dyn.stance_step(single["q"], single["qd"], taus[k, 0], p, anchor=anc[0])

    def inplace_step(k):
        dyn.step_inplace(state["q"], state["qd"], taus[k], pa, anc, dyn.DT, dyn.SUBSTEPS, dyn.MAX_ANGLE, True, lam1)

    def pin_step(k):
        single["q"], single["qd"] = ref.step(single["q"], single["qd"], taus[k, 0])

    single_rounds = ROBOT_STEPS_PER_REPEAT // STEPS_PER_ROUND
    t_step_public = seconds_per_step(public_step, reset_single, single_rounds // 4)
    t_step_inplace = seconds_per_step(inplace_step, reset, single_rounds)
    t_step_pin = seconds_per_step(pin_step, reset_single, PIN_ROBOT_STEPS // STEPS_PER_ROUND)

    # (c): batches; Pinocchio loops over robots in Python, so its cost per robot-step is timed on
    # min(N, PIN_ROBOT_STEPS / STEPS_PER_ROUND) robots
    rows = []
    for n in BATCH_SIZES:
        q0, qd0, anc, taus, state, reset = batch_case(n)
        record_substeps(q0, qd0, anc, taus)
        lam = np.empty((n, 2))

        def batch_step(k):
            dyn.step_inplace(state["q"], state["qd"], taus[k], pa, anc, dyn.DT, dyn.SUBSTEPS, dyn.MAX_ANGLE, True, lam)

        rounds = max(1, ROBOT_STEPS_PER_REPEAT // (n * STEPS_PER_ROUND))
        rate_leg = n / seconds_per_step(batch_step, reset, rounds)

        m = min(n, max(1, PIN_ROBOT_STEPS // STEPS_PER_ROUND))
        robots = {"q": q0[:m].copy(), "qd": qd0[:m].copy()}

        def reset_pin():
            robots["q"], robots["qd"] = q0[:m].copy(), qd0[:m].copy()

        def pin_loop_step(k):
            for i in range(m):
                robots["q"][i], robots["qd"][i] = ref.step(robots["q"][i], robots["qd"][i], taus[k, i])

        rate_pin = m / seconds_per_step(pin_loop_step, reset_pin, 1)
        rows.append((n, rate_leg, rate_pin))

    # ---- the table ---------------------------------------------------------------------------
    def verdict(ok):
        return "PASS" if ok else "FAIL"

    eval_ratio = t_eval_pin / t_eval_leg
    rate_4096 = dict((n, r) for n, r, _ in rows)[4096]
    print("leg-env dynamics benchmark")
    print(f"machine: {machine_info()}")
    print(f"timing: median of {REPEATS} repeats, time.perf_counter; default LegParams; dt={dyn.DT}, "
          f"substeps={dyn.SUBSTEPS}, max_angle={dyn.MAX_ANGLE}")
    print(f"states: nominal posture + N(0, {ANGLE_NOISE}) rad angles, N(0, {RATE_NOISE}) velocities; "
          f"torques: holding torques {np.round(tau_eq, 2).tolist()} N m + U(-{TORQUE_NOISE}, {TORQUE_NOISE}) N m")
    print(f"RK4 steps per control step in (b), (c): mean {np.mean(substep_counts):.2f}, max {max(substep_counts)} "
          f"({4 * dyn.SUBSTEPS} dynamics evaluations at {dyn.SUBSTEPS}); leg-env vs Pinocchio qdd agreement {agreement:.1e}")
    print()
    w = 58
    print(f"{'measurement':<{w}} {'leg-env':>12} {'Pinocchio':>12} {'ratio':>8}  target")
    print("-" * (w + 56))
    print(f"{'(a) stance dynamics, 1 robot, from Python [us/eval]':<{w}} {t_eval_leg * 1e6:>12.2f} "
          f"{t_eval_pin * 1e6:>12.2f} {eval_ratio:>7.1f}x  >= {TARGET_EVAL_RATIO:.0f}x faster: "
          f"{verdict(eval_ratio >= TARGET_EVAL_RATIO)}")
    print(f"{'(b) control step, 1 robot, stance_step [us/step]':<{w}} {t_step_public * 1e6:>12.2f} "
          f"{t_step_pin * 1e6:>12.2f} {t_step_pin / t_step_public:>7.1f}x")
    print(f"{'(b) control step, 1 robot, step_inplace on (1,5) [us/step]':<{w}} {t_step_inplace * 1e6:>12.2f} "
          f"{t_step_pin * 1e6:>12.2f} {t_step_pin / t_step_inplace:>7.1f}x  < {TARGET_STEP_US:.0f} us: "
          f"{verdict(t_step_inplace * 1e6 < TARGET_STEP_US)}")
    for n, rate_leg, rate_pin in rows:
        target = f">= {TARGET_RATE_4096:,.0f}: {verdict(rate_4096 >= TARGET_RATE_4096)}" if n == 4096 else ""
        label = f"(c) step_inplace, N={n} [robot-steps/s]"
        print(f"{label:<{w}} {rate_leg:>12,.0f} {rate_pin:>12,.0f} {rate_leg / rate_pin:>7.0f}x  {target}")
    print()
    print("Pinocchio columns: (a) pin.forwardKinematics(q, v, 0) + computeFrameJacobian + "
          "getFrameClassicalAcceleration + pin.forwardDynamics per evaluation; (b), (c) a Python RK4 loop "
          f"over {4 * dyn.SUBSTEPS} such evaluations per control step, (c) looping over robots in Python.")


if __name__ == "__main__":
    main()
