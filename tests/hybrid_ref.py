"""Independent event-driven reference simulator of the planar leg with a unilateral Coulomb foot contact.

The reference for ``leg_env.physics.hybrid.hybrid_step`` (``tests/test_hybrid_reference.py``). It shares no
math with ``leg_env``: every dynamic term (``M``, ``h``, ``J = Jc``, ``gamma = Jcdot qd``, the foot
position, ``K``, ``P``) comes from the SymPy Lagrangian of ``tests/test_dynamics_reference.py``
(``sympy_reference``), lambdified to numpy. On those terms:

* the mode dynamics are KKT solves:
  - stick (foot pinned):  ``[[M, -J^T], [J, 0]] [qdd; lam] = [S^T tau - h; -gamma]``;
  - slip in direction ``sigma`` (``+1`` = foot sliding towards +x): only ``y_f'' = 0`` is enforced and
    ``lam = lam_y (-sigma mu, 1)``:  ``[[M, -(J_y - sigma mu J_x)^T], [J_y, 0]] [qdd; lam_y] =
    [S^T tau - h; -gamma_y]`` (non-symmetric);
  - flight: ``M qdd + h = S^T tau``;
* the mode of a foot at rest on the ground is chosen by brute-force enumeration of the planar Coulomb
  contact LCP (all 16 complementary index sets, ``lcp_solutions``);
* the plastic impact map with friction follows ``notes_tmp/contact_api.md``: the sticking impulse
  when it lies in the friction cone, else Routh's incremental sliding impact (slide, possibly stop,
  then stick or slide back, until the foot's normal velocity is 0);
* time integration is ``scipy.integrate.solve_ivp(method="DOP853", rtol=atol=1e-12)`` with terminal
  events: stick: ``lam_y -> 0`` (LIFTOFF), ``mu lam_y - |lam_x| -> 0`` (SLIP_ONSET); slip:
  ``lam_y -> 0`` (LIFTOFF), ``sigma x_f' -> 0`` (SLIDING_STOP); flight: ``y_f -> 0`` downwards
  (TOUCHDOWN). After each event the reset (impact map, mode choice, re-anchoring) is applied and the
  integration restarts.

Coordinates: stick integrates the reduced state ``(th_b, q1, q2)`` and rates (the base follows from the
anchor, so the foot stays exactly on it); slip integrates ``(x_b, th_b, q1, q2)`` and rates (``y_b``
follows from ``y_f = 0``); flight the full state. Next to the state, every mode integrates the running
integrals ``(int lam_x, int lam_y, int mu lam_y |x_f'|, int |x_f'|, int tau . (q1', q2'))`` for the
bookkeeping that ``hybrid_step`` reports.

Torques are held constant over a control step; the mode is re-chosen at every step start (the torque
jump can change it, without a located event), as the API prescribes.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

from contact_ref import lcp_matrices as lcp_matrix  # the planar Coulomb LCP w = A z + b, z = (lam_y, lam+, lam-, beta)
from test_dynamics_reference import sympy_reference

STICK, SLIP_FORWARD, SLIP_BACKWARD, FLIGHT = 0, 1, 2, 3
LIFTOFF, SLIP_ONSET, SLIDING_STOP, TOUCHDOWN = 0, 1, 2, 3
MODE_NAMES = {STICK: "STICK", SLIP_FORWARD: "SLIP_FORWARD", SLIP_BACKWARD: "SLIP_BACKWARD", FLIGHT: "FLIGHT"}
EVENT_NAMES = {LIFTOFF: "LIFTOFF", SLIP_ONSET: "SLIP_ONSET", SLIDING_STOP: "SLIDING_STOP", TOUCHDOWN: "TOUCHDOWN"}
REST_SPEED = 1e-9  # [m/s] a foot slower than this is at rest (as in the API)
GROUND_TOL = 1e-9  # [m] a foot above this is in flight
RTOL = ATOL = 1e-12
MAX_STEP = 1e-3  # [s] largest DOP853 step (so that a witness cannot cross twice unseen)
MAX_EVENTS = 32

S_T = np.zeros((5, 2))
S_T[3, 0] = S_T[4, 1] = 1.0


def sigma_of(mode: int) -> float:
    return {SLIP_FORWARD: 1.0, SLIP_BACKWARD: -1.0}[mode]


def slip_mode(sigma: float) -> int:
    return SLIP_FORWARD if sigma > 0 else SLIP_BACKWARD


@dataclass
class State:
    """A hybrid state: ``q``, ``qd`` in world coordinates, the contact mode and the stick anchor."""

    q: np.ndarray
    qd: np.ndarray
    mode: int
    anchor_x: float = np.nan

    def copy(self) -> "State":
        return State(self.q.copy(), self.qd.copy(), int(self.mode), float(self.anchor_x))


@dataclass
class Event:
    kind: int
    time: float  # since the start of the control step [s]
    mode_before: int
    mode_after: int
    q: np.ndarray  # configuration at the event
    qd_minus: np.ndarray
    qd_plus: np.ndarray
    impulse: np.ndarray  # impact impulse (zero unless TOUCHDOWN)
    impact_dissipation: float = 0.0


@dataclass
class StepRecord:
    """One control step of the reference."""

    start: State  # as given (mode = the previous step's final mode)
    mode_start: int  # the mode chosen at the step start with this step's torques
    tau: np.ndarray
    dt: float
    end: State
    events: list = field(default_factory=list)
    lam_int: np.ndarray = field(default_factory=lambda: np.zeros(2))  # int lam dt (no impulses) [N s]
    impulse: np.ndarray = field(default_factory=lambda: np.zeros(2))
    work: float = 0.0  # tau . delta(q1, q2)
    power_int: float = 0.0  # int tau . (q1', q2') dt (the same, by quadrature)
    slip_dissipation: float = 0.0
    impact_dissipation: float = 0.0
    slip_distance: float = 0.0
    stick_time: float = 0.0
    slip_time: float = 0.0
    flight_time: float = 0.0
    energy_start: float = 0.0
    energy_end: float = 0.0

    @property
    def lam_mean(self) -> np.ndarray:
        return self.lam_int / self.dt

    @property
    def event_kinds(self) -> list:
        return [e.kind for e in self.events]

    @property
    def event_times(self) -> list:
        return [e.time for e in self.events]


# ----------------------------------------------------------------------------------------------
# Contact LCP at rest, by brute force
# ----------------------------------------------------------------------------------------------


def lcp_solutions(Lam, a0, mu, tol=1e-10):
    """Every solution of the contact LCP, by enumerating the 16 complementary index sets.

    Returns a list of ``(mode, lam (2,), foot acceleration (2,))``, duplicates removed. The index set
    ``{beta}`` alone is singular (with ``lam = 0`` the slack ``beta`` is free, any ``beta >= |x_f''|``):
    for it the particular solution ``beta = |a0_x|`` is taken, i.e. flight iff ``a0_y >= 0``.
    """
    A, b = lcp_matrix(Lam, a0, mu)
    scale = tol * (1.0 + np.abs(b).max() + np.abs(A).max())
    sols = []
    for act in itertools.product([False, True], repeat=4):
        act = np.array(act)
        z = np.zeros(4)
        idx = np.flatnonzero(act)
        if idx.size:
            sub = A[np.ix_(idx, idx)]
            if abs(np.linalg.det(sub)) < 1e-14:
                if list(idx) == [3]:
                    z[3] = abs(a0[0])
                else:
                    continue
            else:
                z[idx] = np.linalg.solve(sub, -b[idx])
        w = A @ z + b
        if (z < -scale).any() or (w < -scale).any():
            continue
        if (np.abs(w[act]) > scale).any():
            continue
        lam = np.array([z[1] - z[2], z[0]])
        acc = a0 + Lam @ lam
        if lam[1] <= scale:
            mode = FLIGHT
        elif abs(acc[0]) > scale:
            mode = slip_mode(np.sign(acc[0]))
        else:
            mode = STICK
        if not any(m == mode and np.allclose(l, lam, atol=1e3 * scale) for m, l, _ in sols):
            sols.append((mode, lam, acc))
    return sols


def closed_form_candidates(Lam, a0, mu):
    """The four closed-form candidates of ``contact_api.md`` that are consistent: list of ``(mode, lam)``."""
    out = []
    lam = -np.linalg.solve(Lam, a0)
    if lam[1] >= 0.0 and abs(lam[0]) <= mu * lam[1]:
        out.append((STICK, lam))
    for sigma in (-1.0, 1.0):
        k = Lam[1, 1] - sigma * mu * Lam[1, 0]
        if k > 0.0:
            ly = -a0[1] / k
            xdd = a0[0] + (Lam[0, 1] - sigma * mu * Lam[0, 0]) * ly
            if ly >= 0.0 and sigma * xdd >= 0.0:
                out.append((slip_mode(sigma), ly * np.array([-sigma * mu, 1.0])))
    if a0[1] >= 0.0:
        out.append((FLIGHT, np.zeros(2)))
    return out


# ----------------------------------------------------------------------------------------------
# The reference
# ----------------------------------------------------------------------------------------------


class Reference:
    """Event-driven reference for parameters ``p`` and friction coefficient ``mu``, with a constant horizontal force
    ``load`` [N] on the base (the push task's; the generalised force ``(load, 0, 0, 0, 0)``)."""

    def __init__(self, p, mu: float, load: float = 0.0):
        self.p = p
        self.mu = float(mu)
        self.load = float(load)
        self._f = sympy_reference()

    # ---- terms --------------------------------------------------------------------------------

    def terms(self, q, qd) -> dict:
        return self._f(np.asarray(q, float), np.asarray(qd, float), self.p)

    def energy(self, q, qd) -> float:
        r = self.terms(q, qd)
        return r["K"] + r["P"]

    def contact_terms(self, q, qd, tau):
        """``(Lambda, a0, r)``: contact inertia, free foot acceleration and the raw terms."""
        r = self.terms(q, qd)
        M, J = r["M"], r["Jc"]
        MinvJt = np.linalg.solve(M, J.T)
        Lam = J @ MinvJt
        a0 = J @ np.linalg.solve(M, self.forces(r, tau)) + r["Jcdot_qd"]
        return Lam, a0, r

    def forces(self, r, tau):
        """The right-hand side without the contact: ``S^T tau - h + (load, 0, 0, 0, 0)``."""
        return S_T @ tau - r["h"] + np.array([self.load, 0.0, 0.0, 0.0, 0.0])

    # ---- mode dynamics (KKT solves) -------------------------------------------------------------

    def stick_kkt(self, r, tau):
        A = np.zeros((7, 7))
        A[:5, :5] = r["M"]
        A[:5, 5:] = -r["Jc"].T
        A[5:, :5] = r["Jc"]
        rhs = np.concatenate([self.forces(r, tau), -r["Jcdot_qd"]])
        x = np.linalg.solve(A, rhs)
        return x[:5], x[5:]

    def slip_kkt(self, r, tau, sigma):
        J = r["Jc"]
        A = np.zeros((6, 6))
        A[:5, :5] = r["M"]
        A[:5, 5] = -(J[1] - sigma * self.mu * J[0])
        A[5, :5] = J[1]
        rhs = np.concatenate([self.forces(r, tau), [-r["Jcdot_qd"][1]]])
        x = np.linalg.solve(A, rhs)
        return x[:5], x[5] * np.array([-sigma * self.mu, 1.0])

    def flight_qdd(self, r, tau):
        return np.linalg.solve(r["M"], self.forces(r, tau))

    def dynamics(self, q, qd, tau, mode):
        """``(qdd, lam)`` of ``mode`` at a full state (no consistency checks)."""
        r = self.terms(q, qd)
        if mode == STICK:
            return self.stick_kkt(r, tau)
        if mode == FLIGHT:
            return self.flight_qdd(r, tau), np.zeros(2)
        return self.slip_kkt(r, tau, sigma_of(mode))

    # ---- reduced coordinates ------------------------------------------------------------------

    def _stick_full(self, z, anchor_x):
        a, w = z[0:3], z[3:6]
        r0 = self.terms(np.r_[0.0, 0.0, a], np.r_[0.0, 0.0, w])
        J0, pf0 = r0["Jc"], r0["p_f"]
        q = np.r_[anchor_x - pf0[0], -pf0[1], a]
        qd = np.r_[-(J0[0, 2:] @ w) / J0[0, 0], -(J0[1, 2:] @ w) / J0[1, 1], w]
        return q, qd

    def _slip_full(self, z):
        xb, a, vxb, w = z[0], z[1:4], z[4], z[5:8]
        r0 = self.terms(np.r_[xb, 0.0, a], np.r_[vxb, 0.0, w])
        J0, pf0 = r0["Jc"], r0["p_f"]
        q = np.r_[xb, -pf0[1], a]
        qd = np.r_[vxb, -(J0[1, 0] * vxb + J0[1, 2:] @ w) / J0[1, 1], w]
        return q, qd

    def to_full(self, z, mode, anchor_x):
        if mode == STICK:
            return self._stick_full(z, anchor_x)
        if mode == FLIGHT:
            return z[:5].copy(), z[5:10].copy()
        return self._slip_full(z)

    @staticmethod
    def to_reduced(q, qd, mode):
        if mode == STICK:
            return np.r_[q[2:], qd[2:]]
        if mode == FLIGHT:
            return np.r_[q, qd]
        return np.r_[q[0], q[2:], qd[0], qd[2:]]

    # ---- the ODE of each mode, with the running integrals ------------------------------------

    def _rhs(self, mode, tau, anchor_x):
        mu = self.mu

        def f(t, y):
            n = y.size - 5
            q, qd = self.to_full(y[:n], mode, anchor_x)
            r = self.terms(q, qd)
            if mode == STICK:
                qdd, lam = self.stick_kkt(r, tau)
                dz = np.r_[qd[2:], qdd[2:]]
                diss = dist = 0.0
            elif mode == FLIGHT:
                qdd, lam = self.flight_qdd(r, tau), np.zeros(2)
                dz = np.r_[qd, qdd]
                diss = dist = 0.0
            else:
                qdd, lam = self.slip_kkt(r, tau, sigma_of(mode))
                dz = np.r_[qd[0], qd[2:], qdd[0], qdd[2:]]
                vfx = r["Jc"][0] @ qd
                dist = abs(vfx)
                diss = mu * lam[1] * dist
            return np.r_[dz, lam[0], lam[1], diss, dist, tau @ qd[3:5]]

        return f

    def _events(self, mode, tau, anchor_x):
        mu = self.mu

        def full(y):
            n = y.size - 5
            return self.to_full(y[:n], mode, anchor_x)

        evs, kinds = [], []
        if mode == STICK:

            def lift(t, y):
                q, qd = full(y)
                return self.stick_kkt(self.terms(q, qd), tau)[1][1]

            def cone(t, y):
                q, qd = full(y)
                lam = self.stick_kkt(self.terms(q, qd), tau)[1]
                return mu * lam[1] - abs(lam[0])

            evs, kinds = [lift, cone], [LIFTOFF, SLIP_ONSET]
        elif mode == FLIGHT:

            def height(t, y):
                return self.terms(y[:5], y[5:10])["p_f"][1]

            evs, kinds = [height], [TOUCHDOWN]
        else:
            sigma = sigma_of(mode)

            def lift(t, y):
                q, qd = full(y)
                return self.slip_kkt(self.terms(q, qd), tau, sigma)[1][1]

            def slide(t, y):
                q, qd = full(y)
                return sigma * (self.terms(q, qd)["Jc"][0] @ qd)

            evs, kinds = [lift, slide], [LIFTOFF, SLIDING_STOP]
        for e in evs:
            e.terminal = True
            e.direction = -1.0
        return evs, kinds

    # ---- mode choice and the impact map --------------------------------------------------------

    def mode_at_rest(self, q, qd, tau) -> int:
        """The LCP's unique solution for a foot at rest on the ground (raises if not unique)."""
        Lam, a0, _ = self.contact_terms(q, qd, tau)
        sols = lcp_solutions(Lam, a0, self.mu)
        if len(sols) != 1:
            raise RuntimeError(f"contact LCP has {len(sols)} solutions: {sols}")
        return sols[0][0]

    def mode_on_ground(self, q, qd, tau) -> int:
        """The consistent mode of a foot on the ground (at rest: the LCP; sliding: slip or flight)."""
        r = self.terms(q, qd)
        vf = r["Jc"] @ qd
        if np.abs(vf).max() <= REST_SPEED:
            return self.mode_at_rest(q, qd, tau)
        sigma = float(np.sign(vf[0]))
        _, lam = self.slip_kkt(r, tau, sigma)
        return slip_mode(sigma) if lam[1] >= 0.0 else FLIGHT

    def impact(self, q, qd, mu=None):
        """Plastic impact with friction: ``(qd_plus, impulse)`` (see ``contact_api.md``)."""
        mu = self.mu if mu is None else mu
        r = self.terms(q, qd)
        M, J = r["M"], r["Jc"]
        Lam = J @ np.linalg.solve(M, J.T)
        v = J @ qd
        if v[1] >= 0.0:
            return qd.copy(), np.zeros(2)
        P_stick = -np.linalg.solve(Lam, v)
        if np.isinf(mu) or (P_stick[1] >= 0.0 and abs(P_stick[0]) <= mu * P_stick[1]):
            P = P_stick
        else:
            sigma = np.sign(v[0]) if v[0] != 0.0 else -np.sign(P_stick[0])
            k = Lam[1, 1] - sigma * mu * Lam[1, 0]
            c = Lam[0, 1] - sigma * mu * Lam[0, 0]
            if k <= 0.0:
                P = P_stick  # Painleve at impulse level: the documented fallback
            else:
                Py = -v[1] / k
                if sigma * (v[0] + c * Py) >= 0.0:
                    P = Py * np.array([-sigma * mu, 1.0])
                else:  # sliding stops at Py1, then stick or reversed sliding until v_y = 0
                    Py1 = -v[0] / c
                    P1 = Py1 * np.array([-sigma * mu, 1.0])
                    vy1 = v[1] + k * Py1
                    ratio = Lam[0, 1] / Lam[0, 0]
                    if abs(ratio) <= mu:
                        k2 = Lam[1, 1] - Lam[1, 0] * ratio
                        d2 = -vy1 / k2
                        P = P1 + d2 * np.array([-ratio, 1.0])
                    else:
                        s2 = np.sign(Lam[0, 1])
                        k2 = Lam[1, 1] - s2 * mu * Lam[1, 0]
                        if k2 <= 0.0:
                            P = P_stick
                        else:
                            P = P1 + (-vy1 / k2) * np.array([-s2 * mu, 1.0])
        qd_plus = qd + np.linalg.solve(M, J.T @ P)
        return qd_plus, P

    def choose_start_mode(self, st: State, tau) -> State:
        """The mode at a control-step start (torques just jumped)."""
        st = st.copy()
        if st.mode == FLIGHT:  # in the air every torque is consistent; touchdown is an event
            return st
        new = self.mode_on_ground(st.q, st.qd, tau)
        if new == STICK:
            if st.mode != STICK or not np.isfinite(st.anchor_x):
                st.anchor_x = float(self.terms(st.q, st.qd)["p_f"][0])
        else:
            st.anchor_x = np.nan
        st.mode = new
        return st

    # ---- one control step -----------------------------------------------------------------------

    def step(self, st: State, tau, dt: float = 0.01) -> StepRecord:
        tau = np.asarray(tau, float)
        rec = StepRecord(start=st.copy(), mode_start=-1, tau=tau.copy(), dt=dt, end=None)
        rec.energy_start = self.energy(st.q, st.qd)
        cur = self.choose_start_mode(st, tau)
        rec.mode_start = cur.mode
        t = 0.0
        while True:
            mode = cur.mode
            y0 = np.r_[self.to_reduced(cur.q, cur.qd, mode), np.zeros(5)]
            events, kinds = self._events(mode, tau, cur.anchor_x)
            sol = solve_ivp(
                self._rhs(mode, tau, cur.anchor_x),
                (t, dt),
                y0,
                method="DOP853",
                rtol=RTOL,
                atol=ATOL,
                events=events,
                max_step=MAX_STEP,
            )
            if sol.status < 0:
                raise RuntimeError(sol.message)
            if sol.status == 1:
                hits = [(te[0], i) for i, te in enumerate(sol.t_events) if te.size]
                t_e, i_e = min(hits)
                y_e = sol.y_events[i_e][0]
                kind = kinds[i_e]
            else:
                t_e, y_e, kind = dt, sol.y[:, -1], None
            n = y_e.size - 5
            aug = y_e[n:]
            seg = t_e - t
            rec.lam_int += aug[0:2]
            rec.slip_dissipation += aug[2]
            rec.slip_distance += aug[3]
            rec.power_int += aug[4]
            if mode == STICK:
                rec.stick_time += seg
            elif mode == FLIGHT:
                rec.flight_time += seg
            else:
                rec.slip_time += seg
            q, qd = self.to_full(y_e[:n], mode, cur.anchor_x)
            t = t_e
            if kind is None:
                cur = State(q, qd, mode, cur.anchor_x)
                break
            if len(rec.events) >= MAX_EVENTS:
                raise RuntimeError("too many events in one control step")
            cur, ev = self._reset(q, qd, tau, mode, cur.anchor_x, kind, t_e)
            rec.events.append(ev)
            rec.impulse += ev.impulse
            rec.impact_dissipation += ev.impact_dissipation
        rec.end = cur
        rec.energy_end = self.energy(cur.q, cur.qd)
        rec.work = float(tau @ (cur.q[3:5] - st.q[3:5]))
        return rec

    def _reset(self, q, qd, tau, mode, anchor_x, kind, t_e):
        qd_plus, P, D = qd.copy(), np.zeros(2), 0.0
        r = self.terms(q, qd)
        if kind == LIFTOFF:
            new, anchor = FLIGHT, np.nan
        elif kind == SLIP_ONSET:
            lam = self.stick_kkt(r, tau)[1]
            new, anchor = slip_mode(-np.sign(lam[0])), np.nan
        elif kind == SLIDING_STOP:
            new = self.mode_at_rest(q, qd, tau)
            anchor = float(r["p_f"][0]) if new == STICK else np.nan
        else:  # TOUCHDOWN
            qd_plus, P = self.impact(q, qd)
            D = r["K"] - self.terms(q, qd_plus)["K"]
            new = self.mode_on_ground(q, qd_plus, tau)
            anchor = float(r["p_f"][0]) if new == STICK else np.nan
        ev = Event(kind, float(t_e), mode, new, q.copy(), qd.copy(), qd_plus.copy(), P, D)
        return State(q.copy(), qd_plus.copy(), new, anchor), ev

    def run(self, st: State, taus, dt: float = 0.01) -> list:
        """Consecutive control steps with the torques ``taus`` (one row per step)."""
        recs = []
        for tau in taus:
            rec = self.step(st, tau, dt)
            recs.append(rec)
            st = rec.end
        return recs


def describe(recs) -> str:
    """A readable trace of a run: per step the mode chosen at the start, the events, the end mode."""
    lines = []
    for i, r in enumerate(recs):
        evs = ", ".join(f"{EVENT_NAMES[e.kind]}@{i * r.dt + e.time:.9f}" for e in r.events)
        lines.append(
            f"step {i}: tau={r.tau} start {MODE_NAMES[r.mode_start]} -> end {MODE_NAMES[r.end.mode]}"
            f" [{evs}] lam_mean={r.lam_mean} slip_diss={r.slip_dissipation:.3e} imp_diss={r.impact_dissipation:.3e}"
        )
    return "\n".join(lines)
