r"""System identification: the robot's masses, inertias, link COMs and friction from a recorded trajectory.

``fit`` takes what a robot's sensors and drives record at every control step (``q``, ``qd``, the torques held over
each step, the contact modes if known) and fits the parameters of ``LegParams`` that the motion can tell apart, by
Gauss-Newton on the exact Jacobians of the hybrid step (``leg_env.physics.derivatives``):

* **Output error over short windows.** The trajectory is cut into windows of ``window`` steps. Each window is
  simulated from a start state of its own, fitted with the parameters, under the recorded torques, and every
  measured state is compared with the simulated one, weighted by its noise. A start state in stick is the leg's
  angles and rates and the contact point (the base follows from the contact), in slip the same with the base's
  x and its rate, in flight the whole state. The sensitivities of the simulated states come from the step's
  ``A`` (to the start state) and ``P`` (to the parameters), chained along each window: no finite differences.
  Unlike the one-step prediction error, this does not regress on noisy states: the noise of every measurement
  enters only as a residual.
* **What the motion can tell apart.** The dynamics depend on the masses, the inertias and the COMs only through
  six combinations, the base parameters of this robot: the total mass ``m``, the first moments of the leg about
  the hip ``a = m1 c1 + m2 l1`` and of the shank about the knee ``b = m2 c2``, the inertias of the leg about the
  hip ``J1 = I1 + m1 c1^2 + m2 l1^2`` and of the shank about the knee ``J2 = I2 + m2 c2^2``, and the torso's
  ``I_b``; and ``mu`` only where the foot slides. Any change of the eight raw parameters that keeps these leaves
  every trajectory unchanged, so the raw parameters are not identifiable from motion and ``fit`` does not pretend
  otherwise: it reports the base parameters with standard errors, the rank and the singular values of the
  regressor (with the window states eliminated), and moves the raw parameters only along the identifiable
  directions from the prior ``p0`` (the minimum-norm change). The lengths ``l1``, ``l2`` and gravity are taken
  from ``p0`` as known (a drawing or a tape measure gives them).

The standard errors assume independent Gaussian measurement noise of the given standard deviations; they are the
square roots of the diagonal of the inverse of the Gauss-Newton information at the solution, scaled by the
residual's variance per degree of freedom.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from . import checks
from .physics import derivatives
from .physics.contact import FLIGHT, SLIP_BACKWARD, SLIP_FORWARD, STICK
from .physics.dynamics import foot_position
from .physics.integrate import MAX_ANGLE, SUBSTEPS
from .physics.params import PARAM_NAMES, LegParams

__all__ = ["fit", "Identification", "BASE_NAMES", "base_parameters", "FITTED", "DEFAULT_NOISE"]

FITTED = ("m_b", "m1", "m2", "I_b", "I1", "I2", "c1", "c2", "mu")
"""The parameters ``fit`` estimates by default (the lengths and gravity are known)."""
BASE_NAMES = ("m", "a", "b", "J1", "J2", "I_b", "mu")
"""The names of the identifiable combinations, in order (the total mass, the leg's first moment about the hip and the
shank's about the knee, the leg's inertia about the hip and the shank's about the knee, the torso's inertia, the
friction coefficient)."""
DEFAULT_NOISE = (1e-3, 1e-3, 1e-2, 1e-2, 1e-2, 1e-2, 1e-2, 1e-1, 1e-1, 1e-1)
"""The measurement noise ``fit`` assumes without one given (std of x_b, y_b [m], th_b, q1, q2 [rad], their rates)."""
_DEBUG = False  # print each Levenberg-Marquardt iteration (for maintainers)
_COLUMN = {name: k for k, name in enumerate(PARAM_NAMES + ("mu",))}


def base_parameters(p: LegParams, mu: float) -> np.ndarray:
    """``(m, a, b, J1, J2, I_b, mu)`` of a parameter set (``BASE_NAMES``)."""
    m = p.m_b + p.m1 + p.m2
    return np.array([m, p.m1 * p.c1 + p.m2 * p.l1, p.m2 * p.c2, p.I1 + p.m1 * p.c1**2 + p.m2 * p.l1**2,
                     p.I2 + p.m2 * p.c2**2, p.I_b, mu])


def _base_gradient(theta: np.ndarray) -> np.ndarray:
    """d(base parameters) / d(the 12 parameters: LegParams' fields, mu), (7, 12)."""
    m_b, m1, m2, I_b, I1, I2, l1, l2, c1, c2, g, mu = theta
    G = np.zeros((7, 12))
    G[0, [0, 1, 2]] = 1.0
    G[1, [1, 2, 6, 8]] = [c1, l1, m2, m1]
    G[2, [2, 9]] = [c2, m2]
    G[3, [4, 1, 8, 2, 6]] = [1.0, c1**2, 2 * m1 * c1, l1**2, 2 * m2 * l1]
    G[4, [5, 2, 9]] = [1.0, c2**2, 2 * m2 * c2]
    G[5, 3] = 1.0
    G[6, 11] = 1.0
    return G


@dataclass(frozen=True)
class Identification:
    """What ``fit`` found."""

    params: LegParams  # the fitted parameters: the prior moved along the identifiable directions only
    mu: float  # the fitted friction coefficient (the prior's if the foot never slides)
    base: np.ndarray  # (7,) BASE_NAMES' values at the fit
    base_std: np.ndarray  # (7,) their standard errors (inf where not identifiable: mu without sliding)
    identifiable: np.ndarray  # (7,) bool: whether the trajectory determines each base parameter
    rank: int  # the rank of the fitted parameters' regressor, the window states eliminated
    singular_values: np.ndarray  # its singular values, largest first (scaled parameters: relative changes)
    fitted: tuple  # the names of the fitted parameters, in the regressor's order
    rms: float  # the weighted residual's RMS at the fit (about 1 if the noise is as given)
    iterations: int
    seconds: float


def _modes_from(q, qd, p: LegParams, noise) -> np.ndarray:
    """The contact modes of recorded states when none are given: flight where the foot is more than five position
    noises above the ground, else stick."""
    height = foot_position(q, p)[:, 1]
    return np.where(height > 5.0 * max(noise[0], noise[1]), FLIGHT, STICK).astype(np.int64)


class _Windows:
    """The windows' start states in their modes' coordinates: z -> (q, qd) and d(q, qd)/dz."""

    def __init__(self, q, qd, modes, p: LegParams):
        self.modes = modes
        self.size = np.where(modes == FLIGHT, 10, np.where(modes == STICK, 7, 8))
        self.offset = np.concatenate([[0], np.cumsum(self.size)])
        self.p = p
        z = np.zeros(self.offset[-1])
        foot = foot_position(q, p)
        for w, mode in enumerate(modes):
            o = self.offset[w]
            if mode == FLIGHT:
                z[o:o + 10] = np.concatenate([q[w], qd[w]])
            elif mode == STICK:
                z[o:o + 7] = np.concatenate([q[w, 2:], qd[w, 2:], [foot[w, 0]]])
            else:
                z[o:o + 8] = np.concatenate([q[w, [0, 2, 3, 4]], qd[w, [0, 2, 3, 4]]])
        self.z0 = z

    def states(self, z):
        """``(q, qd, S)``: the windows' start states and d(q, qd)/dz, (W, 10, 10) (the
        columns after a window's size zero)."""
        p, n = self.p, len(self.modes)
        q, qd, S = np.zeros((n, 5)), np.zeros((n, 5)), np.zeros((n, 10, 10))
        for w, mode in enumerate(self.modes):
            zw = z[self.offset[w]:self.offset[w + 1]]
            if mode == FLIGHT:
                q[w], qd[w] = zw[:5], zw[5:]
                S[w] = np.eye(10)
                continue
            if mode == STICK:
                ang, rates, x_or_anchor, vx = zw[:3], zw[3:6], zw[6], None
            else:
                ang, rates, x_or_anchor, vx = zw[1:4], zw[5:8], zw[0], zw[4]
            th1, w1 = ang[0] + ang[1], rates[0] + rates[1]
            th2, w2 = th1 + ang[2], w1 + rates[2]
            s1, c1, s2, c2 = math.sin(th1), math.cos(th1), math.sin(th2), math.cos(th2)
            l1, l2 = p.l1, p.l2
            q[w, 2:], qd[w, 2:] = ang, rates
            q[w, 1] = -(l1 * s1 + l2 * s2)  # the foot on the ground y = 0
            qd[w, 1] = -(l1 * c1 * w1 + l2 * c2 * w2)  # and not moving across it
            # d/d(th_b, q1, q2) and d/d(rates) of y_b, y_b': th1 moves with all three angles, th2 too
            dy_dth1, dy_dth2 = -l1 * c1, -l2 * c2
            dvy_dth1, dvy_dth2 = l1 * s1 * w1, l2 * s2 * w2
            dvy_dw1, dvy_dw2 = -l1 * c1, -l2 * c2
            a_cols = (0, 1, 2) if mode == STICK else (1, 2, 3)
            r_cols = (3, 4, 5) if mode == STICK else (5, 6, 7)
            S[w, 2, a_cols[0]] = S[w, 3, a_cols[1]] = S[w, 4, a_cols[2]] = 1.0
            S[w, 7, r_cols[0]] = S[w, 8, r_cols[1]] = S[w, 9, r_cols[2]] = 1.0
            for i, c in enumerate(a_cols):  # th1 = th_b + q1 (i = 0, 1), th2 = th1 + q2 (every i)
                S[w, 1, c] = (dy_dth1 if i < 2 else 0.0) + dy_dth2
                S[w, 6, c] = (dvy_dth1 if i < 2 else 0.0) + dvy_dth2
            for i, c in enumerate(r_cols):
                S[w, 6, c] = (dvy_dw1 if i < 2 else 0.0) + dvy_dw2
            if mode == STICK:  # the base from the contact point, at rest: x_b = anchor - l1 c1 - l2 c2
                q[w, 0] = x_or_anchor - l1 * c1 - l2 * c2
                qd[w, 0] = l1 * s1 * w1 + l2 * s2 * w2
                S[w, 0, 6] = 1.0
                for i, c in enumerate(a_cols):
                    S[w, 0, c] = (l1 * s1 if i < 2 else 0.0) + l2 * s2
                    S[w, 5, c] = (l1 * c1 * w1 if i < 2 else 0.0) + l2 * c2 * w2
                for i, c in enumerate(r_cols):
                    S[w, 5, c] = (l1 * s1 if i < 2 else 0.0) + l2 * s2
            else:  # slip: the base's x and its rate are free
                q[w, 0], qd[w, 0] = x_or_anchor, vx
                S[w, 0, 0] = S[w, 5, 4] = 1.0
        return q, qd, S


def _window_starts(low: np.ndarray, length: int) -> np.ndarray:
    """Window starts every ``length`` steps, each moved on past the steps it cannot start from (``low``: a flight too
    near the ground, whose measured foot may lie below it)."""
    T = low.shape[0]
    starts, s = [], 0
    while s < T - 1:
        while s < T - 1 and low[s]:
            s += 1
        if s >= T - 1:
            break
        starts.append(s)
        s += length
    return np.array(starts if starts else [0])


class _Problem:
    """The output error of one set of windows: the residual, its Jacobians and Levenberg-Marquardt on them."""

    def __init__(self, recorded, tau, modes, starts, ends, columns, scale, weights, p0, dt, substeps, max_angle):
        self.tau, self.starts, self.ends, self.columns, self.scale, self.weights = tau, starts, ends, columns, scale, weights
        self.dt, self.substeps, self.max_angle = dt, substeps, max_angle
        self.K = K = int((ends - starts).max())
        self.frames = _Windows(recorded[starts, :5], recorded[starts, 5:], modes[starts], p0)
        pad = max(starts[-1] + K + 1 - recorded.shape[0], 0)  # the recording padded with its last state
        padded = np.concatenate([recorded, np.repeat(recorded[-1:], pad, axis=0)])
        self.measured = np.stack([padded[s:s + K + 1] for s in starts])
        self.valid = np.arange(K + 1)[None, :] <= (ends - starts)[:, None]  # (W, K + 1): each window's own measurements
        self.row_window = np.repeat(np.arange(len(starts)), self.valid.sum(axis=1))

    def simulate(self, theta, z):
        """The windows' simulated states (W, K + 1, 10), d/dz (W, K + 1, 10, 10), d/dparams (W, K + 1, 10, n_p)."""
        p = LegParams(**dict(zip(PARAM_NAMES, theta[:11])))
        q0, qd0, S = self.frames.states(z)
        W, K, columns = len(self.starts), self.K, self.columns
        X = np.zeros((W, K + 1, 10))
        DZ = np.zeros((W, K + 1, 10, 10))
        DP = np.zeros((W, K + 1, 10, len(columns)))
        X[:, 0] = np.concatenate([q0, qd0], axis=1)
        DZ[:, 0] = S
        qk, qdk, mode = q0, qd0, self.frames.modes.copy()
        for k in range(K):  # the contact point follows the foot: on the contact it is the foot's, and A carries it
            active = self.starts + k < self.ends
            tau = self.tau[np.minimum(self.starts + k, self.tau.shape[0] - 1)]
            J = derivatives.hybrid_step_jacobians(qk, qdk, tau, p, theta[11], mode=mode, dt=self.dt, substeps=self.substeps,
                                                  max_angle=self.max_angle, params=True)
            A = np.where(J.defined[:, None, None], J.A, 0.0)
            P = np.where(J.defined[:, None, None], J.P, 0.0)[:, :, columns]
            X[:, k + 1] = np.where(active[:, None], np.concatenate([J.step.q, J.step.qd], axis=1), X[:, k])
            DZ[:, k + 1] = A @ DZ[:, k]
            DP[:, k + 1] = A @ DP[:, k] + P
            qk, qdk, mode = J.step.q, J.step.qd, J.step.mode
        return X, DZ, DP

    def system(self, theta, z):
        """The weighted residual and its Jacobians, window by window: r (W, R), d/dz (W, R, 10) (a window's columns
        beyond its size zero) and d/d(the scaled parameters) (W, R, n_p), R = 10 (K + 1), a row past a window's end zero."""
        X, DZ, DP = self.simulate(theta, z)
        w, W, K = self.weights, len(self.starts), self.K
        mask = self.valid[:, :, None] * w[None, None, :]  # (W, K + 1, 10)
        r = ((self.measured - X) * mask).reshape(W, -1)
        Jz = (DZ * mask[..., None]).reshape(W, 10 * (K + 1), 10)
        Jp = (DP * mask[..., None] * self.scale[None, None, None, :]).reshape(W, 10 * (K + 1), len(self.columns))
        return r, Jz, Jp

    def blocks(self, r, Jz, Jp, lam: float):
        """The normal equations with the window states eliminated (each window's block solved on its own):
        ``(S, s, H, C, g)``: S dp = s for the parameters, then dz_w = H_w^-1 (g_w - C_w dp)."""
        H = np.einsum("wri,wrj->wij", Jz, Jz)
        pad = np.arange(10)[None, :] >= self.frames.size[:, None]  # a window's unused columns: held
        H = H + lam * (H * np.eye(10)) + np.eye(10) * (pad[:, :, None] + 1e-12)
        C = np.einsum("wri,wrj->wij", Jz, Jp)
        g = np.einsum("wri,wr->wi", Jz, r)
        Hinv_C = np.linalg.solve(H, C)
        Hinv_g = np.linalg.solve(H, g[..., None])[..., 0]
        Fp = np.einsum("wri,wrj->ij", Jp, Jp)
        S = Fp - np.einsum("wki,wkj->ij", C, Hinv_C)
        s = np.einsum("wri,wr->i", Jp, r) - np.einsum("wki,wk->i", C, Hinv_g)
        return S, s, Hinv_C, Hinv_g, Fp

    def solve(self, theta, iterations: int, tol: float):
        """Levenberg-Marquardt from the parameters ``theta`` and the measured window starts."""
        columns, scale, n_p = self.columns, self.scale, len(self.columns)
        z = self.frames.z0.copy()
        r, Jz, Jp = self.system(theta, z)
        cost, lam, it = float((r * r).sum()), 1e-3, 0
        sizes = self.frames.size
        for it in range(1, iterations + 1):
            S, s, Hinv_C, Hinv_g, _ = self.blocks(r, Jz, Jp, lam)
            S = S + lam * np.diag(np.diag(S))
            dp = np.linalg.lstsq(S, s, rcond=1e-10)[0]
            dz_blocks = Hinv_g - Hinv_C @ dp
            dz = np.concatenate([dz_blocks[w, :sizes[w]] for w in range(len(sizes))])
            theta_new = theta.copy()
            theta_new[columns] += dp * scale
            z_new = z + dz
            cost_new = np.inf
            if np.all(theta_new[:11] > 0) and theta_new[11] >= 0:
                try:
                    r_new, Jz_new, Jp_new = self.system(theta_new, z_new)
                    cost_new = float((r_new * r_new).sum())
                except ValueError:  # a window start moved its foot below the ground: too long a step
                    pass
            if _DEBUG:
                print("window", self.K, "iteration", it, "cost", cost, "new", cost_new, "lam", lam)
            if cost_new < cost:
                done = (cost - cost_new) <= tol * cost
                theta, z, r, Jz, Jp, cost = theta_new, z_new, r_new, Jz_new, Jp_new, cost_new
                lam = max(lam / 10.0, 1e-12)
                if done:
                    break
            else:
                lam *= 10.0
                if lam > 1e4:
                    break
        return theta, z, r, Jz, Jp, cost, it


def fit(q, qd, tau, dt: float, p0: LegParams, mu0: float, modes=None, *, noise=DEFAULT_NOISE, window: int = 50,
        fitted: tuple = FITTED, iterations: int = 30, substeps: int = SUBSTEPS, max_angle: float = MAX_ANGLE,
        tol: float = 1e-9) -> Identification:
    """Fit the robot's parameters to a recorded trajectory (module docstring).

    Args:
        q, qd: ``(T, 5)`` the measured state at the start of every control step (and after the last).
        tau: ``(T - 1, 2)`` the torques held over each step [N m].
        dt: the control period [s] (the step rule's ``substeps`` and ``max_angle`` as recorded).
        p0, mu0: the prior: its lengths and gravity are kept; the fit starts from its other values.
        modes: ``(T,)`` the contact mode at the start of every step (``leg_env.physics.contact``), or None: flight
            where the foot is well above the ground, else stick.
        noise: the measurement noise's std of each of the ten state entries (the residuals' weights).
        window: control steps per window.
        fitted: the parameters to fit, among ``FITTED``.
        iterations: the most Gauss-Newton (Levenberg-Marquardt) iterations.
        tol: stop when the relative change of the weighted residual falls below this.

    Returns:
        ``Identification``.

    Raises:
        ValueError: arrays of the wrong shape or not finite, a non-positive ``dt``, a negative ``mu0``, a parameter not
            in ``FITTED``, a window shorter than 2 steps or a trajectory shorter than one window.
    """
    started = time.perf_counter()
    q = checks.real_array("q", q, "a (T, 5) array")
    qd = checks.real_array("qd", qd, "a (T, 5) array")
    tau = checks.real_array("tau", tau, "a (T - 1, 2) array")
    if q.ndim != 2 or q.shape[1] != 5 or qd.shape != q.shape or tau.shape != (q.shape[0] - 1, 2):
        raise ValueError(f"q and qd must be (T, 5) and tau (T - 1, 2), got {q.shape}, {qd.shape} and {tau.shape}")
    for name, a in (("q", q), ("qd", qd), ("tau", tau)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite")
    window = checks.integer("window", window, 2, 10_000)
    dt = checks.real("dt", dt, 0.0, math.inf, lo_open=True, hi_open=True, unit="s")
    mu0 = checks.real("mu0", mu0, 0.0, 1e6)
    if q.shape[0] <= window:
        raise ValueError(f"the trajectory must be longer than one window ({window} steps), got {q.shape[0]} states")
    unknown = [name for name in fitted if name not in FITTED]
    if unknown or not fitted:
        raise ValueError(f"fitted must name some of {FITTED}, got {fitted!r}")
    noise = np.asarray(noise, dtype=np.float64)
    if noise.shape != (10,) or not np.all(noise > 0):
        raise ValueError(f"noise must be 10 positive standard deviations, got {noise!r}")
    modes = _modes_from(q, qd, p0, noise) if modes is None else np.asarray(modes, dtype=np.int64)
    if modes.shape != (q.shape[0],) or not np.isin(modes, (STICK, SLIP_FORWARD, SLIP_BACKWARD, FLIGHT)).all():
        raise ValueError(f"modes must be ({q.shape[0]},) contact modes (0-3), got {modes!r}")

    columns = [_COLUMN[name] for name in fitted]
    theta = np.concatenate([p0.array, [mu0]])
    scale = np.maximum(np.abs(theta[columns]), 1e-3)  # the parameters in relative units
    weights = 1.0 / noise
    height = foot_position(q, p0)[:, 1]
    low = (modes == FLIGHT) & (height < 10.0 * max(noise[0], noise[1]))  # a flight too near the ground to start from
    recorded = np.concatenate([q, qd], axis=1)
    total = 0
    # continuation: short windows first (nearly the one-step error: the event sequences of the simulation stay those
    # of the recording while the parameters are far off), then the given length
    for length in sorted({min(n, window) for n in (2, 4, 10, 25)} | {window}):
        starts = _window_starts(low, length)
        ends = np.append(starts[1:], q.shape[0] - 1)
        problem = _Problem(recorded, tau, modes, starts, ends, columns, scale, weights, p0, dt, substeps, max_angle)
        theta, z, r, Jz, Jp, cost, it = problem.solve(theta, iterations, tol)
        total += it
    it = total
    n_z = z.size

    # the parameters' information with the window states eliminated (a Schur complement), and what it determines
    F, _, _, _, _ = problem.blocks(r, Jz, Jp, 0.0)
    F = 0.5 * (F + F.T)
    cost = float((r * r).sum())
    n_rows = int(problem.valid.sum()) * 10
    sv = np.sqrt(np.clip(np.linalg.eigvalsh(F)[::-1], 0.0, None))
    rank = int((sv > sv[0] * 1e-6).sum())
    dof = max(n_rows - rank - n_z, 1)
    sigma2 = cost / dof
    cov = sigma2 * np.linalg.pinv(F, rcond=1e-12)  # of the scaled parameters
    G = _base_gradient(theta)[:, columns] * scale[None, :]
    base_cov = G @ cov @ G.T
    base_std = np.sqrt(np.clip(np.diag(base_cov), 0.0, None))
    # a base parameter is identifiable if its gradient lies in the information's range
    evals, evecs = np.linalg.eigh(F)
    null = evecs[:, evals < evals.max() * 1e-12]
    identifiable = np.array([np.linalg.norm(gr @ null) <= 1e-6 * max(np.linalg.norm(gr), 1e-300) if gr.any() else False for gr in G])
    base_std = np.where(identifiable, base_std, np.inf)
    p = LegParams(**dict(zip(PARAM_NAMES, theta[:11])))
    return Identification(params=p, mu=float(theta[11]), base=base_parameters(p, float(theta[11])), base_std=base_std,
                          identifiable=identifiable, rank=rank, singular_values=sv, fitted=tuple(fitted),
                          rms=float(np.sqrt(cost / n_rows)), iterations=it, seconds=time.perf_counter() - started)
