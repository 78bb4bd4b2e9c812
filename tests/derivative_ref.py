"""Independent reference for the Jacobians of the control step (``leg_env.physics.derivatives``): complex-step
differentiation of an RK4 control step written here on the SymPy Lagrangian's terms.

It shares no math with ``leg_env``: ``M``, ``h``, ``Jc``, ``Jcdot qd`` and the foot position come from
``test_dynamics_reference.sympy_reference`` (lambdified to numpy, which evaluates them at complex arguments too).
The step is the discrete map the compiled core computes, written from its documentation
(``leg_env.physics.integrate``): ``n`` classical RK4 steps of ``h = dt / n`` on ``(q, qd)`` with the accelerations of
the KKT solve ``[[M, -Jc^T], [Jc, 0]] [qdd; lam] = [S^T tau - h; -Jcdot qd]`` (pinned foot) or ``M qdd = S^T tau - h``
(flight), and after each pinned RK4 step the base moved so that the foot is on its anchor with ``Jc qd = 0``.

Complex step: for a real analytic map ``f``, ``f(x + i eps v) = f(x) + i eps f'(x) v + O(eps^2)``, so
``Im f(x + i eps v) / eps`` is the directional derivative with no cancellation: with ``eps = 1e-30`` it is exact to
round-off. The substep count (a whole number from the real rates) is held, as the core holds it.
"""

from __future__ import annotations

import math

import numpy as np

from test_dynamics_reference import sympy_reference

S_T = np.zeros((5, 2))
S_T[3, 0] = S_T[4, 1] = 1.0
EPS = 1e-30  # the complex step


def substeps_for(qd, dt: float, substeps: int, max_angle: float) -> int:
    """The step rule: at least ``substeps`` RK4 steps, and no link or joint turning by more than ``max_angle`` in one
    at the start's rates."""
    va, vb, vc = (float(np.real(v)) for v in qd[2:])
    w = max(abs(va), abs(vb), abs(vc), abs(va + vb), abs(va + vb + vc))
    return max(substeps, math.ceil(w * dt / max_angle))


def rk4(q, qd, h, f):
    """One classical RK4 step of ``(q, qd)' = (qd, f(q, qd))`` of length ``h``."""
    k1q, k1v = qd, f(q, qd)
    k2q = qd + h / 2 * k1v
    k2v = f(q + h / 2 * k1q, k2q)
    k3q = qd + h / 2 * k2v
    k3v = f(q + h / 2 * k2q, k3q)
    k4q = qd + h * k3v
    k4v = f(q + h * k3q, k4q)
    return q + h / 6 * (k1q + 2 * k2q + 2 * k3q + k4q), qd + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)


class ComplexStep:
    """The pinned (``stance=True``) or free control step of a parameter set, in complex arithmetic."""

    def __init__(self, p):
        self.p = p
        self.params = p.array.astype(complex)  # the parameters the terms are evaluated with (a complex step moves them)
        self.f = sympy_reference().raw

    def terms(self, q, qd):
        M, h, _, Jc, jd, p_f, *_ = self.f(q, qd, self.params)
        cast = lambda a: np.asarray(a, dtype=complex)  # noqa: E731
        return cast(M), cast(h).ravel(), cast(Jc), cast(jd).ravel(), cast(p_f).ravel()

    def accel(self, q, qd, tau, stance: bool):
        M, h, Jc, jd, _ = self.terms(q, qd)
        rhs = S_T @ tau - h
        if not stance:
            return np.linalg.solve(M, rhs)
        K = np.zeros((7, 7), dtype=complex)
        K[:5, :5], K[:5, 5:], K[5:, :5] = M, -Jc.T, Jc
        return np.linalg.solve(K, np.concatenate([rhs, -jd]))[:5]

    def project(self, q, qd, anchor):
        """The base moved so that the foot is on ``anchor`` and ``Jc qd = 0`` (the foot moves one for one with the
        base: ``Jc[:, :2]`` is the identity)."""
        _, _, Jc, _, p_f = self.terms(q, qd)
        q, qd = q.copy(), qd.copy()
        q[:2] += anchor - p_f
        qd[:2] = -Jc[:, 2:] @ qd[2:]
        return q, qd

    def step(self, q, qd, tau, anchor, dt, substeps, max_angle, stance: bool, n=None):
        q, qd, tau = (np.asarray(a, dtype=complex) for a in (q, qd, tau))
        n = substeps_for(qd, dt, substeps, max_angle) if n is None else n
        h = dt / n
        for _ in range(n):
            q, qd = rk4(q, qd, h, lambda q_, qd_: self.accel(q_, qd_, tau, stance))
            if stance:
                q, qd = self.project(q, qd, anchor)
        return np.concatenate([q, qd])

    def jacobians(self, q, qd, tau, dt, substeps, max_angle, stance: bool, anchor=None):
        """``(A, B)`` by complex steps; ``anchor=None``: the foot of ``q`` (its derivative follows ``q``)."""
        n = substeps_for(qd, dt, substeps, max_angle)
        x = np.concatenate([q, qd]).astype(complex)
        A = np.empty((10, 10))
        B = np.empty((10, 2))

        def run(x, tau):
            a = self.terms(x[:5], x[5:])[4] if anchor is None else np.asarray(anchor, dtype=complex)
            return self.step(x[:5], x[5:], tau, a, dt, substeps, max_angle, stance, n)

        tau = np.asarray(tau, dtype=complex)
        for j in range(10):
            e = np.zeros(10, dtype=complex)
            e[j] = 1j * EPS
            A[:, j] = run(x + e, tau).imag / EPS
        for j in range(2):
            e = np.zeros(2, dtype=complex)
            e[j] = 1j * EPS
            B[:, j] = run(x, tau + e).imag / EPS
        return A, B

    def param_jacobian(self, q, qd, tau, dt, substeps, max_angle, stance: bool, anchor=None):
        """``P`` (10, 12) by complex steps of the parameters (LegParams' fields in order; the last column, mu's, zero)."""
        n = substeps_for(qd, dt, substeps, max_angle)
        P = np.zeros((10, 12))
        for k in range(11):
            self.params[k] += 1j * EPS
            a = self.terms(np.asarray(q, complex), np.asarray(qd, complex))[4] if anchor is None else np.asarray(anchor, dtype=complex)
            P[:, k] = self.step(q, qd, tau, a, dt, substeps, max_angle, stance, n).imag / EPS
            self.params[k] = self.p.array[k]
        return P


STICK, SLIP_FORWARD, SLIP_BACKWARD, FLIGHT = 0, 1, 2, 3


class Refused(Exception):
    """A step this reference does not write (another event or mode choice than it knows)."""


class HybridComplexStep(ComplexStep):
    """The unilateral ground's control step through slip onset, lift-off and touchdown, in complex arithmetic:
    ``hybrid_step`` written from its documentation (``leg_env.physics.hybrid``) on the SymPy terms.

    Substeps of ``h = t_left / n_left`` in the current mode: stick (the KKT solve, then the base projected onto the
    anchor), slip in direction ``sigma`` (only ``y_f'' = 0``: ``[[M, -(J_y - sigma mu J_x)^T], [J_y, 0]] [qdd; lam_y] =
    [S^T tau - h; -gamma_y]``, then the foot put back on the ground line with ``y_f' = 0``) or flight. When a substep
    ends with a witness below zero (stick: ``lam_y`` and ``mu lam_y - |lam_x|``; slip: ``lam_y``; flight: ``y_f``), the
    event's time ``s`` inside it is the root of ``g(Phi(x, s)) = 0``, found in complex arithmetic (Newton's iteration
    from the real root: its fixed point is the complex root, so the root's derivative is carried). Then the reset:
    slip onset: slip against the friction the stick needed; lift-off: flight; touchdown: the base lowered so the foot
    is on the ground, the plastic sticking impulse ``qd+ = qd - M^-1 Jc^T (Jc M^-1 Jc^T)^-1 Jc qd``, stick with the
    anchor at the foot. The rest of the step runs with ``n_left`` raised to the step rule's count at the new rates if
    that is more. Only these events and choices: a step that meets another (a sliding stop, a slip onset after which the
    foot does not slide against the stick's friction) raises ``Refused``.
    """

    def __init__(self, p, mu: float):
        super().__init__(p)
        self.mu = mu

    def forces(self, q, qd, tau, mode):
        """``(qdd, lam)`` of the mode."""
        M, h, Jc, jd, _ = self.terms(q, qd)
        rhs = S_T @ tau - h
        if mode == FLIGHT:
            return np.linalg.solve(M, rhs), np.zeros(2, dtype=complex)
        if mode == STICK:
            K = np.zeros((7, 7), dtype=complex)
            K[:5, :5], K[:5, 5:], K[5:, :5] = M, -Jc.T, Jc
            x = np.linalg.solve(K, np.concatenate([rhs, -jd]))
            return x[:5], x[5:]
        sigma = 1.0 if mode == SLIP_FORWARD else -1.0
        K = np.zeros((6, 6), dtype=complex)
        K[:5, :5], K[:5, 5], K[5, :5] = M, -(Jc[1] - sigma * self.mu * Jc[0]), Jc[1]
        x = np.linalg.solve(K, np.concatenate([rhs, [-jd[1]]]))
        return x[:5], np.array([-sigma * self.mu * x[5], x[5]])

    def substep(self, q, qd, tau, h, mode, anchor):
        q, qd = rk4(q, qd, h, lambda q_, qd_: self.forces(q_, qd_, tau, mode)[0])
        if mode == STICK:
            q, qd = self.project(q, qd, anchor)
        elif mode != FLIGHT:  # the foot on the ground line, its normal velocity zero
            _, _, Jc, _, p_f = self.terms(q, qd)
            q, qd = q.copy(), qd.copy()
            q[1] += anchor[1] - p_f[1]
            qd[1] = -Jc[1, 2:] @ qd[2:]
        return q, qd

    def witnesses(self, q, qd, tau, mode) -> dict:
        if mode == FLIGHT:
            return {"touchdown": self.terms(q, qd)[4][1]}
        lam = self.forces(q, qd, tau, mode)[1]
        if mode == STICK:
            return {"liftoff": lam[1], "slip_onset": self.mu * lam[1] - np.sign(lam[0].real) * lam[0]}
        _, _, Jc, _, _ = self.terms(q, qd)
        return {"liftoff": lam[1], "sliding_stop": (1.0 if mode == SLIP_FORWARD else -1.0) * (Jc[0] @ qd)}

    def hybrid_step(self, q, qd, tau, mode, dt, substeps, max_angle, anchor_x=None):
        """``(x after the step, the events located)``; ``anchor_x=None``: the foot's x of ``q``."""
        q, qd, tau = (np.asarray(a, dtype=complex) for a in (q, qd, tau))
        anchor = np.array([self.terms(q, qd)[4][0] if anchor_x is None else anchor_x, 0.0], dtype=complex)
        n_left = substeps_for(qd, dt, substeps, max_angle)
        t_left = complex(dt)
        events = []
        while n_left > 0:
            h = t_left / n_left
            q1, qd1 = self.substep(q, qd, tau, h, mode, anchor)
            crossed = [k for k, w in self.witnesses(q1, qd1, tau, mode).items() if w.real < 0.0]
            if not crossed:
                q, qd, t_left, n_left = q1, qd1, t_left - h, n_left - 1
                continue

            def root(kind):
                """The real root of the witness by bisection, and g."""
                def g(s):
                    return self.witnesses(*self.substep(q, qd, tau, s, mode, anchor), tau, mode)[kind]

                lo, hi = 0.0, h.real
                for _ in range(60):
                    mid = 0.5 * (lo + hi)
                    lo, hi = (mid, hi) if g(mid).real >= 0.0 else (lo, mid)
                return 0.5 * (lo + hi), g

            roots = {kind: root(kind) for kind in crossed}
            kind = min(roots, key=lambda k: roots[k][0])
            if kind == "sliding_stop":
                raise Refused("a sliding stop (the sticking impulse is not written here)")
            if any(abs(roots[k][0] - roots[kind][0]) <= 1e-9 for k in roots if k != kind):
                raise Refused("two events at once")
            s0, g = roots[kind]
            s = complex(s0)
            slope = (g(s.real + 1e-9).real - g(s.real - 1e-9).real) / 2e-9
            for _ in range(6):
                s = s - g(s) / slope
            lam_before = self.forces(*self.substep(q, qd, tau, s.real - 1e-9, mode, anchor), tau, mode)[1]
            q, qd = self.substep(q, qd, tau, s, mode, anchor)
            t_left = t_left - s
            events.append(kind)
            if kind == "slip_onset":  # slip against the friction the stick needed, if the foot then moves that way
                mode = SLIP_BACKWARD if lam_before[0].real > 0.0 else SLIP_FORWARD
                qdd, lam = self.forces(q, qd, tau, mode)
                _, _, Jc, jd, _ = self.terms(q, qd)
                tie = -1e-6 * self.p.g  # at the onset the slide's foot acceleration is zero but for round-off
                if (1.0 if mode == SLIP_FORWARD else -1.0) * (Jc[0] @ qdd + jd[0]).real < tie or lam[1].real < 0.0:
                    raise Refused("the mode choice after the slip onset takes another mode")
            elif kind == "liftoff":
                mode = FLIGHT
            else:  # touchdown: on the ground, the sticking impulse, stick at the foot
                q = q.copy()
                q[1] -= self.terms(q, qd)[4][1]
                M, _, Jc, _, p_f = self.terms(q, qd)
                Minv_JT = np.linalg.solve(M, Jc.T)
                qd = qd - Minv_JT @ np.linalg.solve(Jc @ Minv_JT, Jc @ qd)
                anchor = np.array([p_f[0], 0.0], dtype=complex)
                mode = STICK
            n_left = max(n_left, substeps_for(qd, t_left.real, 1, max_angle))
        return np.concatenate([q, qd]), events

    def hybrid_param_jacobian(self, q, qd, tau, mode, dt, substeps, max_angle, anchor_x=None):
        """``(P, events)`` by complex steps of the parameters and of mu (the last column)."""
        P = np.empty((10, 12))
        _, events = self.hybrid_step(q, qd, tau, mode, dt, substeps, max_angle, anchor_x)
        for k in range(12):
            if k < 11:
                self.params[k] += 1j * EPS
            else:
                self.mu = self.mu + 1j * EPS
            y, ev = self.hybrid_step(q, qd, tau, mode, dt, substeps, max_angle, anchor_x)
            assert ev == events
            P[:, k] = y.imag / EPS
            self.params[:] = self.p.array
            self.mu = self.mu.real if isinstance(self.mu, complex) else self.mu
        return P, events

    def hybrid_jacobians(self, q, qd, tau, mode, dt, substeps, max_angle, anchor_x=None):
        """``(A, B, events)`` by complex steps (the anchor's x follows ``q`` if ``anchor_x`` is None)."""
        x = np.concatenate([q, qd]).astype(complex)
        A, B = np.empty((10, 10)), np.empty((10, 2))
        _, events = self.hybrid_step(q, qd, tau, mode, dt, substeps, max_angle, anchor_x)
        tau = np.asarray(tau, dtype=complex)
        for j in range(10):
            e = np.zeros(10, dtype=complex)
            e[j] = 1j * EPS
            y, ev = self.hybrid_step((x + e)[:5], (x + e)[5:], tau, mode, dt, substeps, max_angle, anchor_x)
            assert ev == events
            A[:, j] = y.imag / EPS
        for j in range(2):
            e = np.zeros(2, dtype=complex)
            e[j] = 1j * EPS
            y, _ = self.hybrid_step(x[:5], x[5:], tau + e, mode, dt, substeps, max_angle, anchor_x)
            B[:, j] = y.imag / EPS
        return A, B, events
