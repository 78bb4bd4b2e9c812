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


class ComplexStep:
    """The pinned (``stance=True``) or free control step of a parameter set, in complex arithmetic."""

    def __init__(self, p):
        self.p = p
        self.f = sympy_reference().raw

    def terms(self, q, qd):
        M, h, _, Jc, jd, p_f, *_ = self.f(q, qd, self.p.array)
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
            k1q, k1v = qd, self.accel(q, qd, tau, stance)
            k2q, k2v = qd + h / 2 * k1v, None
            k2v = self.accel(q + h / 2 * k1q, k2q, tau, stance)
            k3q = qd + h / 2 * k2v
            k3v = self.accel(q + h / 2 * k2q, k3q, tau, stance)
            k4q = qd + h * k3v
            k4v = self.accel(q + h * k3q, k4q, tau, stance)
            q = q + h / 6 * (k1q + 2 * k2q + 2 * k3q + k4q)
            qd = qd + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
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
