"""Independent references for the unilateral-contact functions of ``leg_env.physics.dynamics``.

Nothing here imports ``leg_env.physics.dynamics``: every quantity is built from the SymPy Lagrangian of
``tests/test_dynamics_reference.py`` (``M``, ``h``, ``Jc``, ``Jcdot qd``; derived once per session)
or, for the momenta, from link kinematics written out below, and solved with numpy.

* ``slip_kkt``: the non-symmetric slip KKT ``[[M, -(J_y - sigma mu J_x)^T], [J_y, 0]]``.
* ``sticking_impulse``: the plastic bilateral impact ``Lambda P = -v_f-``.
* ``routh_impact``: a brute-force integration of Routh's incremental impact process (normal impulse
  marched in small equal increments, Coulomb friction opposing the current tangential foot velocity).
* ``lcp_solutions``: every solution of the planar Coulomb contact LCP at acceleration level for a
  foot at rest, by enumerating all 16 complementary index sets.
* ``momenta``: the three momenta a sticking foot impact conserves.
"""

from __future__ import annotations

import itertools

import numpy as np

from test_dynamics_reference import sympy_reference

# the mode labels of the API (notes_tmp/contact_api.md); the tests check leg_env uses the same ints
STICK, SLIP_FORWARD, SLIP_BACKWARD, FLIGHT = 0, 1, 2, 3
MODE_NAMES = {STICK: "STICK", SLIP_FORWARD: "SLIP_FORWARD", SLIP_BACKWARD: "SLIP_BACKWARD", FLIGHT: "FLIGHT"}


def generalized_torque(tau) -> np.ndarray:
    """``S^T tau = [0, 0, 0, tau_hip, tau_knee]``."""
    return np.array([0.0, 0.0, 0.0, tau[0], tau[1]])


def terms(q, qd, p) -> dict:
    """SymPy terms at ``(q, qd, p)`` plus ``Lambda = J M^-1 J^T`` (solved, not inverted) and ``v_f``."""
    r = sympy_reference()(np.asarray(q, float), np.asarray(qd, float), p)
    J = r["Jc"]
    r["Lambda"] = J @ np.linalg.solve(r["M"], J.T)
    r["v_f"] = J @ np.asarray(qd, float)
    r["qd"] = np.asarray(qd, float)
    return r


def free_foot_acceleration(r: dict, tau) -> np.ndarray:
    """``a0 = J M^-1 (S^T tau - h) + Jcdot qd``: the foot's acceleration without a contact force."""
    return r["Jc"] @ np.linalg.solve(r["M"], generalized_torque(tau) - r["h"]) + r["Jcdot_qd"]


def mu_critical(Lam: np.ndarray) -> float:
    """``Lambda_yy / |Lambda_xy|``."""
    return Lam[1, 1] / abs(Lam[0, 1]) if Lam[0, 1] != 0.0 else np.inf


def k_sigma(Lam: np.ndarray, mu: float, sigma: float) -> float:
    """``J_y M^-1 (J_y - sigma mu J_x)^T = Lambda_yy - sigma mu Lambda_yx``."""
    return Lam[1, 1] - sigma * mu * Lam[1, 0]


# ----------------------------------------------------------------------------
# Slip: the non-symmetric KKT system
# ----------------------------------------------------------------------------


def slip_kkt(r: dict, tau, mu: float, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``[[M, -(J_y - sigma mu J_x)^T], [J_y, 0]] [qdd; lam_y] = [S^T tau - h; -gamma_y]``.

    Returns ``(qdd, lam)`` with ``lam = lam_y (-sigma mu, 1)``.
    """
    M, J = r["M"], r["Jc"]
    Jx, Jy = J[0], J[1]
    A = np.zeros((6, 6))
    A[:5, :5] = M
    A[:5, 5] = -(Jy - sigma * mu * Jx)
    A[5, :5] = Jy
    rhs = np.concatenate([generalized_torque(tau) - r["h"], [-r["Jcdot_qd"][1]]])
    x = np.linalg.solve(A, rhs)
    lam_y = x[5]
    return x[:5], np.array([-sigma * mu * lam_y, lam_y])


# ----------------------------------------------------------------------------
# Impacts
# ----------------------------------------------------------------------------


def sticking_impulse(r: dict) -> tuple[np.ndarray, np.ndarray]:
    """Plastic bilateral impact: ``Lambda P = -v_f-``, ``qd+ = qd- + M^-1 J^T P``. Returns ``(qd+, P)``."""
    P = -np.linalg.solve(r["Lambda"], r["v_f"])
    return r["qd"] + np.linalg.solve(r["M"], r["Jc"].T @ P), P


def apply_impulse(r: dict, P) -> np.ndarray:
    """``qd+ = qd- + M^-1 J^T P``."""
    return r["qd"] + np.linalg.solve(r["M"], r["Jc"].T @ np.asarray(P, float))


def routh_impact(Lam: np.ndarray, v_minus: np.ndarray, mu: np.ndarray, n_steps: int):
    """Brute-force Routh incremental impact process for a batch of impacts (vectorised over cases).

    Args:
        Lam: ``(n, 2, 2)`` contact inertias; v_minus: ``(n, 2)`` foot velocities before the impact
        (approaching, ``v_y < 0``); mu: ``(n,)`` friction coefficients, each below that case's
        ``mu_critical`` so the process terminates.
        n_steps: the normal impulse is marched in increments ``dP_y = P_y,max / n_steps`` where
        ``P_y,max = -v_y- / min(k_+, k_-, det Lambda / Lambda_xx)`` bounds the total normal impulse
        (``v_y`` rises at least at that rate in every phase).

    Per increment: if the tangential velocity is nonzero, friction opposes it,
    ``dP = dP_y (-sign(v_x) mu, 1)``. If it is exactly zero: stick (``dP_x = -Lambda_xy / Lambda_xx
    dP_y`` keeps ``v_x = 0``) when that ratio is inside the cone, else slide the one way that is
    self-consistent. When ``v_x`` crosses zero inside an increment it is *not* split: the next
    increments chatter around ``v_x = 0`` (that is the brute force; the error is O(dP_y)). The last
    increment is shortened so that the process ends exactly at ``v_y = 0``.

    Returns:
        ``(P (n, 2), v_plus (n, 2), dPy (n,), n_flips (n,))`` with ``n_flips`` the number of sign
        changes of ``v_x`` seen during the process.
    """
    Lam = np.asarray(Lam, float)
    v = np.array(v_minus, float)
    mu = np.asarray(mu, float)
    n = v.shape[0]
    Lxx, Lxy, Lyy = Lam[:, 0, 0], Lam[:, 0, 1], Lam[:, 1, 1]
    det = Lxx * Lyy - Lxy * Lxy
    k_min = np.minimum.reduce([Lyy - mu * Lxy, Lyy + mu * Lxy, det / Lxx])
    assert np.all(k_min > 0.0), "routh_impact needs mu < mu_critical"
    dPy = -v[:, 1] / k_min / n_steps
    P = np.zeros((n, 2))
    active = v[:, 1] < 0.0
    stick_ratio = -Lxy / Lxx
    stick_ok = np.abs(stick_ratio) <= mu
    zero_sigma = np.sign(Lxy)  # the only self-consistent slide direction out of v_x = 0 when sticking fails
    n_flips = np.zeros(n, dtype=int)
    last_sign = np.sign(v[:, 0])
    for _ in range(n_steps + 2):
        if not active.any():
            break
        sigma = np.sign(v[:, 0])
        ratio = -sigma * mu  # dP_x / dP_y
        at_zero = sigma == 0.0
        ratio = np.where(at_zero & stick_ok, stick_ratio, ratio)
        ratio = np.where(at_zero & ~stick_ok, -zero_sigma * mu, ratio)
        rate_y = Lam[:, 1, 0] * ratio + Lyy  # dv_y / dP_y
        step = np.where(active, dPy, 0.0)
        last = active & (v[:, 1] + rate_y * step >= 0.0)
        step = np.where(last, -v[:, 1] / rate_y, step)
        dP = np.stack([ratio * step, step], axis=1)
        P += dP
        v += np.einsum("nij,nj->ni", Lam, dP)
        v[last, 1] = 0.0
        active &= ~last
        s = np.sign(v[:, 0])
        n_flips += (s != 0) & (last_sign != 0) & (s != last_sign)
        last_sign = np.where(s != 0, s, last_sign)
    assert not active.any(), "routh_impact did not finish (P_y,max bound violated?)"
    return P, v, dPy, n_flips


# ----------------------------------------------------------------------------
# The contact LCP at acceleration level, for a foot at rest on the ground
# ----------------------------------------------------------------------------


def lcp_matrices(Lam: np.ndarray, a0: np.ndarray, mu: float) -> tuple[np.ndarray, np.ndarray]:
    """``w = b + A z`` with ``z = (lam_y, lam_plus, lam_minus, s)``, ``lam_x = lam_plus - lam_minus``:

    ``w = (y_f'', s + x_f'', s - x_f'', mu lam_y - lam_plus - lam_minus)``, where
    ``a_f = a0 + Lambda lam``. LCP: ``z >= 0``, ``w >= 0``, ``z . w = 0``.
    """
    Lxx, Lxy, Lyy = Lam[0, 0], Lam[0, 1], Lam[1, 1]
    Lyx = Lam[1, 0]
    A = np.array(
        [
            [Lyy, Lyx, -Lyx, 0.0],
            [Lxy, Lxx, -Lxx, 1.0],
            [-Lxy, -Lxx, Lxx, 1.0],
            [mu, -1.0, -1.0, 0.0],
        ]
    )
    b = np.array([a0[1], a0[0], -a0[0], 0.0])
    return A, b


def _physical(z: np.ndarray) -> np.ndarray:
    """``(lam_x, lam_y)`` of an LCP vector."""
    return np.array([z[1] - z[2], z[0]])


def lcp_solutions(Lam: np.ndarray, a0: np.ndarray, mu: float, rtol: float = 1e-9):
    """Every physically distinct solution of the contact LCP, by enumerating the 16 index sets.

    For an index set ``alpha``: ``w_i = 0`` for ``i`` in ``alpha``, ``z_i = 0`` otherwise (4 linear
    equations), then ``z >= 0``, ``w >= 0`` are checked. Singular systems (the slack ``s`` is free in
    flight; ``lam_plus + lam_minus`` is free when both are in ``alpha``) are solved by least squares
    plus a null-space search: with one null direction the feasible set is an interval (exact);
    more never occur here (asserted).

    Returns:
        ``(solutions, continuum)``: a list of distinct ``(lam (2,), a_f (2,))`` and a flag that is True
        when some index set admits a whole segment of physically different forces.
    """
    A, b = lcp_matrices(Lam, a0, mu)
    scale = 1.0 + np.abs(b).max()
    tol = rtol * scale
    found: list[np.ndarray] = []
    continuum = False
    for bits in itertools.product((False, True), repeat=4):
        alpha = np.array(bits)
        E = np.where(alpha[:, None], A, np.eye(4))  # rows: w_i = 0 (i in alpha) or z_i = 0
        f = np.where(alpha, -b, 0.0)
        U, sv, Vt = np.linalg.svd(E)
        rank = int(np.sum(sv > 1e-12 * sv[0]))
        z0 = Vt[:rank].T @ ((U[:, :rank].T @ f) / sv[:rank])
        if np.abs(E @ z0 - f).max() > tol:
            continue  # inconsistent equations
        N = Vt[rank:].T  # null directions, (4, k)
        # inequalities: z >= 0, w = b + A z >= 0, i.e. G (z0 + N t) + g0 >= 0
        G = np.vstack([np.eye(4), A])
        g0 = np.concatenate([np.zeros(4), b])
        c = G @ z0 + g0
        if N.shape[1] == 0:
            if c.min() >= -tol:
                found.append(z0)
            continue
        assert N.shape[1] == 1, f"null space of dimension {N.shape[1]} for index set {bits}"
        d = (G @ N)[:, 0]
        lo, hi = -np.inf, np.inf
        feasible = True
        for ci, di in zip(c, d):
            if abs(di) <= 1e-14:
                if ci < -tol:
                    feasible = False
            elif di > 0:
                lo = max(lo, (-tol - ci) / di)
            else:
                hi = min(hi, (-tol - ci) / di)
        if not feasible or lo > hi:
            continue
        t = lo if np.isfinite(lo) else (hi if np.isfinite(hi) else 0.0)
        if np.isfinite(lo) and np.isfinite(hi):
            t = 0.5 * (lo + hi)
        found.append(z0 + N[:, 0] * t)
        phys_dir = _physical(N[:, 0])
        if np.abs(phys_dir).max() > 1e-12 and (hi - lo) * np.abs(phys_dir).max() > tol:
            continuum = True
    solutions: list[tuple[np.ndarray, np.ndarray]] = []
    for z in found:
        lam = _physical(z)
        lam[np.abs(lam) <= tol] = 0.0
        if any(np.abs(lam - s[0]).max() <= 1e3 * tol for s in solutions):
            continue
        solutions.append((lam, a0 + Lam @ lam))
    return solutions, continuum


def lcp_mode(lam: np.ndarray, a_f: np.ndarray, a0: np.ndarray, rtol: float = 1e-9) -> int:
    """The contact mode of an LCP solution: no force -> FLIGHT, foot not accelerating along the
    ground -> STICK, else the direction of the foot's tangential acceleration."""
    tol = rtol * (1.0 + np.abs(a0).max())
    if lam[1] <= tol:
        return FLIGHT
    if abs(a_f[0]) <= 1e3 * tol:
        return STICK
    return SLIP_FORWARD if a_f[0] > 0.0 else SLIP_BACKWARD


# ----------------------------------------------------------------------------
# Momenta conserved by a sticking foot impact (own kinematics, not the SymPy module)
# ----------------------------------------------------------------------------


def _cross(r, v) -> float:
    return float(r[0] * v[1] - r[1] * v[0])


def momenta(q, qd, p) -> np.ndarray:
    """``(H_foot, H_knee, th_b')``.

    ``H_foot``: angular momentum of the whole robot about the (fixed, current) foot point;
    ``H_knee``: angular momentum of torso + thigh about the knee point; ``th_b'``.
    Each link: ``m (r_c - o) x v_c + I w``.
    """
    x_b, y_b, th_b, q1, q2 = q
    xd, yd, wb, qd1, qd2 = qd
    th1, th2 = th_b + q1, th_b + q1 + q2
    w1, w2 = wb + qd1, wb + qd1 + qd2
    u1, u2 = np.array([np.cos(th1), np.sin(th1)]), np.array([np.cos(th2), np.sin(th2)])
    n1, n2 = np.array([-np.sin(th1), np.cos(th1)]), np.array([-np.sin(th2), np.cos(th2)])
    r_b, v_b = np.array([x_b, y_b]), np.array([xd, yd])
    r_c1, v_c1 = r_b + p.c1 * u1, v_b + p.c1 * w1 * n1
    r_k, v_k = r_b + p.l1 * u1, v_b + p.l1 * w1 * n1
    r_c2, v_c2 = r_k + p.c2 * u2, v_k + p.c2 * w2 * n2
    r_f = r_k + p.l2 * u2
    torso = (p.m_b, p.I_b, r_b, v_b, wb)
    thigh = (p.m1, p.I1, r_c1, v_c1, w1)
    shank = (p.m2, p.I2, r_c2, v_c2, w2)

    def H(links, o):
        return sum(m * _cross(r - o, v) + I * w for m, I, r, v, w in links)

    return np.array([H((torso, thigh, shank), r_f), H((torso, thigh), r_k), wb])


def kinetic_energy(r: dict) -> float:
    return 0.5 * float(r["qd"] @ r["M"] @ r["qd"])
