r"""System identification: the robot's masses, inertias, link COMs and friction from a recorded trajectory.

``fit`` takes what a robot's sensors and drives record at every control step (``q``, ``qd``, the torques held over
each step, the contact modes if known) and fits the parameters of ``LegParams`` that the motion can tell apart, by
Gauss-Newton on the exact Jacobians of the hybrid step (``leg_env.physics.derivatives``):

* **Output error, by multiple shooting.** The trajectory is cut into windows of ``window`` steps. Each window is
  simulated from a start state of its own under the recorded torques, and every measured state is compared with the
  simulated one, weighted by its noise. A start state in stick is the leg's angles and rates and the contact point
  (the base follows from the contact), in slip the same with the base's x and its rate, in flight the whole state.
  The windows are joined: where one ends, its simulated state must equal the next one's start to within
  ``junction`` (a thousandth) of the measurement noise, so that the whole recording is one motion, determined by the
  parameters and its first state, and the fit is its maximum-likelihood estimate under independent Gaussian noise of
  the measurements (no regression on noisy states, no noisy start state taken as known). The windows keep the
  simulation well posed although the open-loop hop is unstable (a state error grows about fivefold every quarter
  second). The sensitivities come from the step's ``A`` (to the state) and ``P`` (to the parameters), chained along
  each window; the start states are eliminated from the normal equations (block tridiagonal: the junctions couple
  neighbours only).
  The fit gets there by continuation: short independent windows first (while the parameters are far off), then the
  given length, then the junctions tightened from one noise to ``junction``. The measurements beside a touchdown (the
  last in flight, the first on the ground) are left out and no window starts there: where the simulated touchdown falls
  on the other side of a step from the recorded one, the state there jumps by the impact.
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
* **Friction.** ``mu`` is fitted only if the recorded modes slide somewhere (a recording that never slides bounds it
  from below, and determines no value), and reported as identifiable only if the fitted motion slides exactly where
  the recording does and its standard error is below ``MAX_STD``: a few steps of sliding determine it to a few
  percent at best (``cramer_rao``).

The standard errors assume independent Gaussian measurement noise of the given standard deviations; they are the
square roots of the diagonal of the inverse of the Gauss-Newton information at the solution (from an orthogonal
factorisation of the weighted Jacobian, window by window), scaled by the residual's variance per degree of freedom.
A base parameter is identifiable if the information determines it and its standard error is at most ``MAX_STD`` of
its value. ``cramer_rao`` gives the same standard errors at given parameters along a noise-free recording: the bound
below which no unbiased estimate from such a recording can go.
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

__all__ = ["fit", "cramer_rao", "Identification", "BASE_NAMES", "base_parameters", "FITTED", "DEFAULT_NOISE", "JUNCTION",
           "MAX_STD"]

FITTED = ("m_b", "m1", "m2", "I_b", "I1", "I2", "c1", "c2", "mu")
"""The parameters ``fit`` estimates by default (the lengths and gravity are known)."""
BASE_NAMES = ("m", "a", "b", "J1", "J2", "I_b", "mu")
"""The names of the identifiable combinations, in order (the total mass, the leg's first moment about the hip and the
shank's about the knee, the leg's inertia about the hip and the shank's about the knee, the torso's inertia, the
friction coefficient)."""
DEFAULT_NOISE = (1e-3, 1e-3, 1e-2, 1e-2, 1e-2, 1e-2, 1e-2, 1e-1, 1e-1, 1e-1)
"""The measurement noise ``fit`` assumes without one given (std of x_b, y_b [m], th_b, q1, q2 [rad], their rates)."""
JUNCTION = 1e-3
"""The tolerance ``fit`` joins its windows with by default: a window's simulated end state and the next window's start
may differ by this fraction of the measurement noise (``junction``)."""
MAX_STD = 0.02
"""The largest standard error, relative to its value, at which ``fit`` counts a base parameter as identifiable."""
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
    mu: float  # the fitted friction coefficient (the prior's if the recording never slides)
    base: np.ndarray  # (7,) BASE_NAMES' values at the fit
    base_std: np.ndarray  # (7,) their standard errors (inf where the motion does not determine one: mu without sliding)
    identifiable: np.ndarray  # (7,) bool: determined, to a standard error of at most MAX_STD of its value (and mu
    # only where the fitted motion slides where the recording does)
    rank: int  # the rank of the fitted parameters' regressor, the window states eliminated
    singular_values: np.ndarray  # its singular values, largest first (scaled parameters: relative changes)
    fitted: tuple  # the names of the fitted parameters, in the regressor's order (no mu if the recording never slides)
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


def _window_starts(avoid: np.ndarray, length: int, onsets: np.ndarray | None = None) -> np.ndarray:
    """Window starts every ``length`` steps, each moved on past the steps it cannot start from (``avoid``), and a
    window started at every step of ``onsets`` (where the foot begins to slide) that is not avoided."""
    T = avoid.shape[0]
    onsets = np.array([], np.int64) if onsets is None else np.asarray(onsets, np.int64)
    onsets = onsets[(onsets < T - 1) & ~avoid[np.minimum(onsets, T - 1)]]
    starts, s = [], 0
    while s < T - 1:
        while s < T - 1 and avoid[s]:
            s += 1
        if s >= T - 1:
            break
        starts.append(s)
        later = onsets[onsets > s]
        s = min(s + length, int(later[0])) if later.size else s + length
    return np.array(starts if starts else [0])


def _block_tridiagonal_solve(D: np.ndarray, E: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve the symmetric positive definite block tridiagonal system with diagonal blocks ``D`` (W, n, n) and upper
    blocks ``E`` (W - 1, n, n) (the lower ones their transposes) for ``rhs`` (W, n, m): block elimination along the
    windows and back substitution."""
    W = D.shape[0]
    Dp, rp = D.copy(), rhs.copy()
    for w in range(1, W):
        L = np.linalg.solve(Dp[w - 1], E[w - 1]).T  # E[w-1]^T Dp[w-1]^-1 (Dp symmetric)
        Dp[w] -= L @ E[w - 1]
        rp[w] -= L @ rp[w - 1]
    x = np.empty_like(rhs)
    x[W - 1] = np.linalg.solve(Dp[W - 1], rp[W - 1])
    for w in range(W - 2, -1, -1):
        x[w] = np.linalg.solve(Dp[w], rp[w] - E[w] @ x[w + 1])
    return x


class _Problem:
    """The output error of one set of windows: the residual, its Jacobians and Levenberg-Marquardt on them."""

    def __init__(self, recorded, tau, modes, starts, ends, columns, scale, weights, p0, dt, substeps, max_angle,
                 junction=None, usable=None):
        self.tau, self.starts, self.ends, self.columns, self.scale, self.weights = tau, starts, ends, columns, scale, weights
        self.dt, self.substeps, self.max_angle = dt, substeps, max_angle
        self.junction = junction  # None: independent windows; else the junctions' tolerance in noise units
        self.K = K = int((ends - starts).max())
        self.frames = _Windows(recorded[starts, :5], recorded[starts, 5:], modes[starts], p0)
        pad = max(starts[-1] + K + 1 - recorded.shape[0], 0)  # the recording padded with its last state
        padded = np.concatenate([recorded, np.repeat(recorded[-1:], pad, axis=0)])
        self.measured = np.stack([padded[s:s + K + 1] for s in starts])
        self.valid = np.arange(K + 1)[None, :] <= (ends - starts)[:, None]  # (W, K + 1): each window's own measurements
        if junction is not None:  # joined windows: a window's last state is the next one's first, measured once
            self.valid[np.arange(len(starts) - 1), (ends - starts)[:-1]] = False
        if usable is not None:  # the measurements the fit compares (not those beside a touchdown)
            self.valid &= np.concatenate([usable, np.zeros(K + 1, bool)])[starts[:, None] + np.arange(K + 1)[None, :]]

    def simulate(self, theta, z):
        """The windows' simulated states (W, K + 1, 10), d/dz (W, K + 1, 10, 10), d/dparams (W, K + 1, 10, n_p)."""
        p = LegParams(**dict(zip(PARAM_NAMES, theta[:11])))
        q0, qd0, S = self.frames.states(z)
        self.q0_qd0 = (q0, qd0, S)
        W, K, columns = len(self.starts), self.K, self.columns
        X = np.zeros((W, K + 1, 10))
        DZ = np.zeros((W, K + 1, 10, 10))
        DP = np.zeros((W, K + 1, 10, len(columns)))
        X[:, 0] = np.concatenate([q0, qd0], axis=1)
        DZ[:, 0] = S
        qk, qdk, mode = q0, qd0, self.frames.modes.copy()
        self.simulated_modes = np.zeros((W, K + 1), np.int64)  # the contact mode at the start of every simulated step
        self.simulated_modes[:, 0] = mode
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
            self.simulated_modes[:, k + 1] = mode
        return X, DZ, DP

    def system(self, theta, z):
        """The weighted residual (measured minus simulated) and the simulation's Jacobians, window by window: r (W, R),
        d/dz (W, R, 10) (a window's columns beyond its size zero) and d/d(the scaled parameters) (W, R, n_p),
        R = 10 (K + 1), a row not measured zero; and with joined windows the junctions ``(rc, a, b, c)``: the next start
        minus the simulated end (W - 1, 10), weighted by the noise over the tolerance, and the mismatch's Jacobians by
        this window's start, the next one's and the scaled parameters; else None."""
        X, DZ, DP = self.simulate(theta, z)
        w, W, K = self.weights, len(self.starts), self.K
        mask = self.valid[:, :, None] * w[None, None, :]  # (W, K + 1, 10)
        r = ((self.measured - X) * mask).reshape(W, -1)
        Jz = (DZ * mask[..., None]).reshape(W, 10 * (K + 1), 10)
        Jp = (DP * mask[..., None] * self.scale[None, None, None, :]).reshape(W, 10 * (K + 1), len(self.columns))
        if self.junction is None:
            return r, Jz, Jp, None
        # the junctions: window w's simulated end against window w + 1's start, (W - 1, 10), weighted by the noise over
        # the tolerance; their Jacobians by z_w, by z_(w + 1) and by the scaled parameters
        n = self.ends - self.starts
        last = np.arange(W - 1)
        wc = (w / self.junction)[None, :]
        start_next = np.concatenate([self.q0_qd0[0][1:], self.q0_qd0[1][1:]], axis=1)
        rc = (start_next - X[last, n[:-1]]) * wc
        Jc_own = DZ[last, n[:-1]] * wc[..., None]
        Jc_next = -self.q0_qd0[2][1:] * wc[..., None]
        Jc_p = DP[last, n[:-1]] * wc[..., None] * self.scale[None, None, :]
        return r, Jz, Jp, (rc, Jc_own, Jc_next, Jc_p)

    def reduced(self, system, lam: float):
        """The normal equations with the window states eliminated (a Schur complement), Levenberg-Marquardt damped by
        ``lam``: ``(S, s, back)``, S dp = s for the scaled parameters, then ``back(dp)`` the states' step (compact).
        Independent windows: each window's block solved on its own. Joined windows: the junctions couple neighbours
        only, and the states' block, block tridiagonal, is solved by block elimination along the windows."""
        r, Jz, Jp, junctions = system
        W, n_p = len(self.starts), len(self.columns)
        sizes = self.frames.size
        JzT = np.swapaxes(Jz, 1, 2)
        H = JzT @ Jz
        C = JzT @ Jp
        g = (JzT @ r[..., None])[..., 0]
        Jp_all = Jp.reshape(-1, n_p)
        Fp = Jp_all.T @ Jp_all
        gp = Jp_all.T @ r.reshape(-1)
        held = np.eye(10) * ((np.arange(10)[None, :] >= sizes[:, None])[:, :, None] + 1e-12)  # unused columns
        if junctions is None:
            H = H + lam * (H * np.eye(10)) + held
            rhs = np.concatenate([C, g[..., None]], axis=2)
            X = np.linalg.solve(H, rhs)
        else:
            rc, a, b, c = junctions
            aT, bT = np.swapaxes(a, 1, 2), np.swapaxes(b, 1, 2)
            D = H.copy()  # the diagonal blocks, then E[w] = N[w, w + 1]
            D[:-1] += aT @ a
            D[1:] += bT @ b
            E = aT @ b
            C = C.copy()
            C[:-1] += aT @ c
            C[1:] += bT @ c
            g = g.copy()
            g[:-1] += (aT @ rc[..., None])[..., 0]
            g[1:] += (bT @ rc[..., None])[..., 0]
            Fp = Fp + np.einsum("wki,wkj->ij", c, c)
            gp = gp + np.einsum("wki,wk->i", c, rc)
            D = D + lam * (D * np.eye(10)) + held
            rhs = np.concatenate([C, g[..., None]], axis=2)
            X = _block_tridiagonal_solve(D, E, rhs)
        Ninv_C, Ninv_g = X[..., :n_p], X[..., n_p]
        S = Fp - np.einsum("wki,wkj->ij", C, Ninv_C)
        s = gp - np.einsum("wki,wk->i", C, Ninv_g)

        def back(dp):
            dz = Ninv_g - Ninv_C @ dp
            return np.concatenate([dz[w, :sizes[w]] for w in range(W)])
        return 0.5 * (S + S.T), s, back

    def root(self, system) -> np.ndarray:
        """A square root of the parameters' information with the window states eliminated, ``(n_p, n_p)``: the
        parameters' block of the triangular factor of the whole weighted Jacobian (states first), by orthogonal
        elimination window by window (a square-root information smoother), so that the directions the motion cannot
        determine come out at round-off of the Jacobian itself, not of its square (a junction weighs a thousand times
        a measurement)."""
        r, Jz, Jp, junctions = system
        W, n_p = len(self.starts), len(self.columns)
        sizes = self.frames.size
        keep = np.repeat(self.valid, 10, axis=1)  # (W, R): the measured rows
        carry = np.zeros((0, sizes[0] + n_p))  # rows in (this window's state, the parameters) from the windows before
        acc = np.zeros((0, n_p))  # rows in the parameters alone
        for w in range(W):
            sw = sizes[w]
            rows = [carry, np.concatenate([Jz[w][keep[w], :sw], Jp[w][keep[w]]], axis=1)]
            if junctions is not None and w < W - 1:
                _, a, b, c = junctions
                sn = sizes[w + 1]
                widen = lambda m: np.concatenate([m[:, :sw], np.zeros((m.shape[0], sn)), m[:, sw:]], axis=1)  # noqa: E731
                rows = [widen(m) for m in rows] + [np.concatenate([a[w][:, :sw], b[w][:, :sn], c[w]], axis=1)]
                R = np.linalg.qr(np.concatenate(rows), mode="r")
                carry = R[sw:sw + sn + n_p, sw:]
            else:
                R = np.linalg.qr(np.concatenate(rows), mode="r")
                acc = np.linalg.qr(np.concatenate([acc, R[sw:sw + n_p, sw:]]), mode="r")
                carry = np.zeros((0, (sizes[w + 1] if w < W - 1 else 0) + n_p))
        return acc[:n_p]

    @staticmethod
    def cost(system) -> float:
        r, _, _, junctions = system
        return float((r * r).sum()) + (0.0 if junctions is None else float((junctions[0] ** 2).sum()))

    def solve(self, theta, z, iterations: int, tol: float):
        """Levenberg-Marquardt from the parameters ``theta`` and the window states ``z``."""
        columns, scale = self.columns, self.scale
        system = self.system(theta, z)
        cost, lam, it = self.cost(system), 1e-3, 0
        for it in range(1, iterations + 1):
            S, s, back = self.reduced(system, lam)
            S = S + lam * np.diag(np.diag(S))
            dp = np.linalg.lstsq(S, s, rcond=1e-9)[0]
            theta_new = theta.copy()
            theta_new[columns] += dp * scale
            z_new = z + back(dp)
            cost_new = np.inf
            if np.all(theta_new[:11] > 0) and theta_new[11] >= 0:
                try:
                    system_new = self.system(theta_new, z_new)
                    cost_new = self.cost(system_new)
                except ValueError:  # a window start moved its foot below the ground: too long a step
                    pass
            if _DEBUG:
                print("window", self.K, "junction", self.junction, "iteration", it, "cost", cost, "new", cost_new, "lam", lam)
            if cost_new < cost:
                done = (cost - cost_new) <= tol * (cost + self.valid.sum() * 10)  # also at round-off of a clean fit
                theta, z, system, cost = theta_new, z_new, system_new, cost_new
                lam = max(lam / 10.0, 1e-12)
                if done:
                    break
            else:
                lam *= 10.0
                if lam > 1e4:
                    break
        return theta, z, system, cost, it


def _recording(q, qd, tau, dt, p0: LegParams, modes, noise, window, fitted, junction):
    """Checked arrays and what the fit needs of the recording's structure (``fit``'s errors)."""
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

    if junction is not None:
        junction = checks.real("junction", junction, 0.0, math.inf, lo_open=True, hi_open=True)
    sliding = (modes == SLIP_FORWARD) | (modes == SLIP_BACKWARD)
    if not sliding.any():  # the recording never slides: it bounds mu from below, and determines no value of it
        fitted = tuple(name for name in fitted if name != "mu")
        if not fitted:
            raise ValueError("fitted names only mu, and the recording never slides (modes): nothing to fit")
    height = foot_position(q, p0)[:, 1]
    # the steps no window starts from: a flight too near the ground (its measured foot may lie below it) and the two
    # steps after a touchdown (where the simulated touchdown may fall on the other side of the step, and with it the
    # impact: the state there is not a smooth function of the parameters, nor is a junction's mismatch)
    low = (modes == FLIGHT) & (height < 10.0 * max(noise[0], noise[1]))
    touchdown = np.flatnonzero((modes[:-1] == FLIGHT) & (modes[1:] != FLIGHT)) + 1
    near_touchdown = low.copy()
    for lag in (0, 1):
        near_touchdown[np.minimum(touchdown + lag, q.shape[0] - 1)] = True
    # the short windows also start where the foot begins to slide: there the friction coefficient enters at once,
    # though a simulation from an earlier start would stick while it is far off (and not depend on it at all)
    onsets = np.flatnonzero(sliding[1:] & ~sliding[:-1]) + 1
    # the measurements beside a touchdown (the last in flight, the first on the ground) are left out: where the
    # simulated touchdown falls on the other side of a step from the recorded one, the simulated state jumps by the
    # impact, and the error is not smooth in the parameters
    usable = np.ones(q.shape[0], bool)
    usable[np.concatenate([touchdown - 1, touchdown])] = False
    return _Recording(q, qd, tau, dt, modes, noise, window, tuple(fitted), junction, low, near_touchdown, onsets,
                      usable)


@dataclass(frozen=True)
class _Recording:
    q: np.ndarray
    qd: np.ndarray
    tau: np.ndarray
    dt: float
    modes: np.ndarray
    noise: np.ndarray
    window: int
    fitted: tuple  # without mu where the recording never slides
    junction: float | None
    low: np.ndarray  # flights too near the ground to start a window from
    near_touchdown: np.ndarray  # those and the two steps after each touchdown: no junction there
    onsets: np.ndarray  # the steps where the foot begins to slide
    usable: np.ndarray  # the measurements the residual compares (not those beside a touchdown)

    def problem(self, columns, scale, p0, length, tolerance, substeps, max_angle, starts=None):
        if starts is None:
            starts = (_window_starts(self.low, length, self.onsets) if length < self.window
                      else _window_starts(self.near_touchdown, length))
        ends = np.append(starts[1:], self.q.shape[0] - 1)
        recorded = np.concatenate([self.q, self.qd], axis=1)
        return _Problem(recorded, self.tau, self.modes, starts, ends, columns, scale, 1.0 / self.noise, p0, self.dt,
                        substeps, max_angle, junction=tolerance, usable=self.usable)


def _extra_slides(problem, modes, missed: bool = False) -> np.ndarray:
    """(W, K + 1) where the last simulation of ``problem`` slides and the recording's ``modes`` do not (``missed``: the
    other way round)."""
    K = problem.K
    span = np.arange(K + 1)[None, :] <= (problem.ends - problem.starts)[:, None]
    recorded = np.isin(modes[np.minimum(problem.starts[:, None] + np.arange(K + 1)[None, :], modes.shape[0] - 1)],
                       (SLIP_FORWARD, SLIP_BACKWARD))
    simulated = np.isin(problem.simulated_modes, (SLIP_FORWARD, SLIP_BACKWARD))
    return span & (recorded & ~simulated if missed else simulated & ~recorded)


def _base_errors(root, theta, columns, scale):
    """The base parameters' standard errors for unit noise from a square root of the information of the scaled
    parameters, and which of them the information determines (inf where it does not): a base parameter is
    determined if its gradient lies in the information's range."""
    sv, vt = np.linalg.svd(root)[1:]
    rank = int((sv > sv[0] * 1e-6).sum())
    root_inv = np.linalg.pinv(root, rcond=1e-6)
    G = _base_gradient(theta)[:, columns] * scale[None, :]
    base_std = np.sqrt(np.clip(np.einsum("ij,ij->i", G @ root_inv, G @ root_inv), 0.0, None))
    null = vt[rank:].T
    structural = np.array([np.linalg.norm(gr @ null) <= 1e-6 * max(np.linalg.norm(gr), 1e-300) if gr.any() else False
                           for gr in G])
    return np.where(structural, base_std, np.inf), structural


def fit(q, qd, tau, dt: float, p0: LegParams, mu0: float, modes=None, *, noise=DEFAULT_NOISE, window: int = 25,
        fitted: tuple = FITTED, iterations: int = 30, substeps: int = SUBSTEPS, max_angle: float = MAX_ANGLE,
        tol: float = 1e-9, junction: float | None = JUNCTION) -> Identification:
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
        iterations: the most Gauss-Newton (Levenberg-Marquardt) iterations of each stage of the continuation.
        tol: stop a stage when the relative change of the weighted residual falls below this.
        junction: the tolerance of the windows' junctions, a fraction of the measurement noise (``JUNCTION``; the
            smaller, the nearer one continuous motion), or None: independent windows, each from a start state of its
            own (more robust to a model that is not exact, such as unmodelled disturbances, less precise).

    Returns:
        ``Identification``.

    Raises:
        ValueError: arrays of the wrong shape or not finite, a non-positive ``dt``, a negative ``mu0``, a parameter not
            in ``FITTED`` (or only mu, where the recording never slides), a window shorter than 2 steps, a trajectory
            shorter than one window, a junction not positive.
    """
    started = time.perf_counter()
    mu0 = checks.real("mu0", mu0, 0.0, 1e6)
    rec = _recording(q, qd, tau, dt, p0, modes, noise, window, fitted, junction)
    fitted, window, junction = rec.fitted, rec.window, rec.junction
    columns = [_COLUMN[name] for name in fitted]
    theta = np.concatenate([p0.array, [mu0]])
    scale = np.maximum(np.abs(theta[columns]), 1e-3)  # the parameters in relative units
    total = 0
    # continuation: short independent windows first (nearly the one-step error: the event sequences of the simulation
    # stay those of the recording while the parameters are far off), then the given length; then the windows joined,
    # their junctions' tolerance tightened step by step to the given one
    lengths = sorted({min(n, window) for n in (2, 4, 10, 25)} | {window})
    stages = [(length, None) for length in lengths]
    if junction is not None:
        stages += [(window, t) for t in (1.0, 0.1, 0.01) if t > junction] + [(window, junction)]
    problem = z = None
    for length, tolerance in stages:
        joined = tolerance is not None and problem is not None
        problem = rec.problem(columns, scale, p0, length, tolerance, substeps, max_angle,
                              starts=problem.starts if joined else None)
        if not joined:
            z = problem.frames.z0.copy()  # the windows' measured starts
        between = tolerance is not None and (length, tolerance) != stages[-1]  # a junction on its way: not converged
        theta, z, system, cost, it = problem.solve(theta, z, min(iterations, 10) if between else iterations, tol)
        total += it
        if length == stages[0][0] and "mu" in fitted:
            # the error is flat in mu wherever the simulated foot does not slide (mu too large), so its gradient cannot
            # find a smaller one: search below it on a grid, and refine from there if that is clearly better
            trials = theta[11] * 1.04 ** -np.arange(1, 31)
            costs = []
            for trial in trials:
                moved = theta.copy()
                moved[11] = trial
                try:
                    costs.append(problem.cost(problem.system(moved, z)))
                except ValueError:
                    costs.append(np.inf)
            if min(costs) < cost * (1.0 - 1e-3):
                theta[11] = trials[int(np.argmin(costs))]
                theta, z, system, cost, it = problem.solve(theta, z, min(iterations, 10), tol)
                total += it
    if "mu" in fitted and _extra_slides(problem, rec.modes).any():
        # the fitted motion slides where the recording does not: mu has gone too low and the extra slides bias the
        # rest. Hold it instead where the motion slides nowhere the recording does not (a missed slide of a step or
        # two costs the other parameters little, one too many much more), and fit the rest again: mu is then not
        # identified
        theta[11] = max(mu0, theta[11])
        for _ in range(20):
            problem.system(theta, z)
            if not _extra_slides(problem, rec.modes).any():
                break
            theta[11] *= 1.25
        fitted = tuple(name for name in fitted if name != "mu")
        columns = [_COLUMN[name] for name in fitted]
        scale = np.maximum(np.abs(np.concatenate([p0.array, [mu0]])[columns]), 1e-3)
        problem = rec.problem(columns, scale, p0, window, junction, substeps, max_angle, starts=problem.starts)
        theta, z, system, cost, it = problem.solve(theta, z, iterations, tol)
        total += it
    it = total

    # the parameters' information with the window states eliminated (a Schur complement), and what it determines
    r = system[0]
    n_rows = int(problem.valid.sum()) * 10
    root = problem.root(system)
    # the states the measurements must pay for: every window's start, or with joined windows the first one's only
    n_z = z.size if junction is None else int(problem.frames.size[0])
    sv, vt = np.linalg.svd(root)[1:]
    rank = int((sv > sv[0] * 1e-6).sum())
    sigma2 = cost / max(n_rows - rank - n_z, 1)
    base_std, structural = _base_errors(root, theta, columns, scale)
    base_std = base_std * math.sqrt(sigma2)
    p = LegParams(**dict(zip(PARAM_NAMES, theta[:11])))
    base = base_parameters(p, float(theta[11]))
    # and the trajectory determines it if its standard error is small besides: a friction coefficient seen in a few
    # steps of sliding may lie in the range and still be known to no better than several percent
    identifiable = structural & (base_std <= MAX_STD * np.abs(base))
    # and mu only if the fitted motion slides where the recording does and nowhere else: a slide the recording does not
    # have, or one it misses, shows a fit that does not reproduce the contact, whose mu (and its standard error,
    # which near the onset of a slide can be arbitrarily small) means nothing
    identifiable[6] &= not (_extra_slides(problem, rec.modes).any()
                            or _extra_slides(problem, rec.modes, missed=True).any())
    return Identification(params=p, mu=float(theta[11]), base=base, base_std=base_std,
                          identifiable=identifiable, rank=rank, singular_values=sv, fitted=tuple(fitted),
                          rms=float(np.sqrt(float((r * r).sum()) / n_rows)), iterations=it, seconds=time.perf_counter() - started)


def cramer_rao(q, qd, tau, dt: float, p: LegParams, mu: float, modes=None, *, noise=DEFAULT_NOISE, window: int = 25,
               fitted: tuple = FITTED, substeps: int = SUBSTEPS, max_angle: float = MAX_ANGLE,
               junction: float | None = JUNCTION) -> np.ndarray:
    """The Cramer-Rao bound of the base parameters (``BASE_NAMES``): the smallest standard errors an unbiased estimate
    from such a recording can have, for measurement noise of the std ``noise``, at the parameters ``p``, ``mu``.

    The inverse of the Fisher information of ``fit``'s model (with joined windows and ``junction`` small, the whole
    motion determined by the parameters and its first state), with the states eliminated, from the exact Jacobians along
    the motion simulated from the recorded states: pass the noise-free recording of the robot ``p`` (a simulation), to
    learn what a recording of this motion can determine before any fit; ``inf`` where it cannot (``mu`` without
    sliding). The arguments are ``fit``'s (``p``, ``mu`` the parameters it is evaluated at); the same errors.
    """
    mu = checks.real("mu", mu, 0.0, 1e6)
    rec = _recording(q, qd, tau, dt, p, modes, noise, window, fitted, junction)
    columns = [_COLUMN[name] for name in rec.fitted]
    theta = np.concatenate([p.array, [mu]])
    scale = np.maximum(np.abs(theta[columns]), 1e-3)
    problem = rec.problem(columns, scale, p, rec.window, rec.junction, substeps, max_angle)
    std = _base_errors(problem.root(problem.system(theta, problem.frames.z0)), theta, columns, scale)[0]
    if "mu" not in rec.fitted:
        std[6] = np.inf
    return std
