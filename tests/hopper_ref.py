"""The hopping controller's law as it was written in numpy (``policies.hopper`` before the law moved into the compiled
core), kept as the test's reference: the compiled law must give the same torques and advance the same state."""

from __future__ import annotations

import inspect

import numpy as np

from leg_env.tasks.base import Obs
from policies.hopper import HopperController

_CROUCH, _PUSH, _RELEASE = 0, 1, 2


class ReferenceLaw:
    """The numpy law with the settings ``gains`` (``HopperController``'s keywords, its defaults for the rest: read
    from its signature, not from the compiled law's row) and a copy of the per-robot state of the controller ``h``."""

    def __init__(self, h, gains: dict | None = None):
        kw = {name: arg.default for name, arg in inspect.signature(HopperController).parameters.items()
              if arg.default is not inspect.Parameter.empty and name not in ("params", "config")}
        kw.update(gains or {})
        p = self.params = h.params
        self.config, self.y_stand, self.torque_limit = h.config, h.y_stand, h.torque_limit
        self.m = m = p.m_b + p.m1 + p.m2
        self.a, self.b = a, b = p.m1 * p.c1 + p.m2 * p.l1, p.m2 * p.c2  # leg's and shank's first moments
        # flight inertia of the absolute leg angles about the free-falling COM (leg_env.physics.dynamics._flight_core)
        self.kf = p.m2 * p.l1 * p.c2 - a * b / m
        self.K11 = p.I1 + p.m1 * p.c1**2 + p.m2 * p.l1**2 - a * a / m
        self.K22 = p.I2 + p.m2 * p.c2**2 - b * b / m
        self.L_td = kw["touchdown_length"]
        self.q2_lo = kw["liftoff_knee"]
        self.L_lo = float(np.sqrt(p.l1**2 + p.l2**2 + 2.0 * p.l1 * p.l2 * np.cos(self.q2_lo)))
        self.alpha_lo = float(np.arctan2(p.l2 * np.sin(self.q2_lo), p.l1 + p.l2 * np.cos(self.q2_lo)))
        self.crouch = kw["crouch"]
        self.v_sink, self.a_c, self.k_c, self.stroke_min = kw["sink_speed"], kw["crouch_decel"], kw["crouch_gain"], kw["stroke_min"]
        self.apex_gain = kw["apex_gain"]
        self.T_s, self.k_v, self.k_x = kw["stance_time"], kw["speed_gain"], kw["position_gain"]
        self.attitude_gains, self.friction_margin, self.swing_gains = kw["attitude_gains"], kw["friction_margin"], kw["swing_gains"]
        self.dwell, self.dwell_gains = kw["dwell"], kw["dwell_gains"]
        self._x0, self._bias, self._apex = h._x0.copy(), h._bias.copy(), h._apex.copy()
        self._phase, self._was_flight = h._phase.copy(), h._was_flight.copy()
        self._since_touchdown = h._since_touchdown.copy()

    def torque(self, obs: np.ndarray) -> np.ndarray:
        """Joint torques [N m] for observations ``(N, 22)``; advances the per-robot phase and apex bias."""
        p, m, a, b = self.params, self.m, self.a, self.b
        l1, l2, g, dt = p.l1, p.l2, p.g, self.config.dt
        thb, q1, q2 = obs[:, Obs.th_b], obs[:, Obs.q1], obs[:, Obs.q2]
        vxb, vyb, wb, wq1, wq2 = obs[:, Obs.vx_b], obs[:, Obs.vy_b], obs[:, Obs.w_b], obs[:, Obs.w_q1], obs[:, Obs.w_q2]
        contact = obs[:, Obs.contact] > 0.5
        command = obs[:, Obs.command]
        th1, th2 = thb + q1, thb + q1 + q2
        w1, w2 = wb + wq1, wb + wq1 + wq2
        s1, c1, s2, c2 = np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2)
        # COM relative to the hip (the base point) and its velocity, world axes
        x_com_rel = (a * c1 + b * c2) / m
        y_com = obs[:, Obs.base_y] + (a * s1 + b * s2) / m  # above the ground
        vx_com = vxb - (a * s1 * w1 + b * s2 * w2) / m
        vy_com = vyb + (a * c1 * w1 + b * c2 * w2) / m
        rx, ry = l1 * c1 + l2 * c2, l1 * s1 + l2 * s2  # foot relative to the hip
        L = np.hypot(rx, ry)
        E_v = 0.5 * m * vy_com**2 + m * g * y_com

        # phases: touchdown starts a crouch and updates the apex bias with the last flight's apex
        target = self.y_stand + command
        touchdown = contact & self._was_flight
        seen = touchdown & np.isfinite(self._apex)
        self._bias[seen] -= self.apex_gain * (self._apex[seen] - target[seen])
        self._phase[touchdown] = _CROUCH
        self._since_touchdown[touchdown] = 0.0
        self._apex[~contact] = E_v[~contact] / (m * g)
        self._was_flight = ~contact
        E_star = m * g * (target + self._bias)
        L_low = self.L_lo - self.crouch[0] - self.crouch[1] * command
        crouch = contact & (self._phase == _CROUCH)
        stopped = crouch & (vy_com >= -0.05) & (L < L_low + 0.03)  # at the crouch's bottom
        self._phase[stopped & (self._since_touchdown >= self.dwell - 1e-9)] = _PUSH
        self.dwelling = dwelling = stopped & (self._phase == _CROUCH)
        self._since_touchdown[contact] += dt
        push = contact & (self._phase == _PUSH)
        self._phase[push & ((E_v >= E_star) | (q2 + wq2 * dt <= self.q2_lo))] = _RELEASE
        phase = self._phase

        # 1. height: crouch (sink, then stop at L_low) or push (the energy deficit over the remaining rise)
        d = np.maximum(L - L_low, 0.0)
        v_des = -np.minimum(self.v_sink, np.sqrt(2.0 * self.a_c * d))
        a_crouch = self.k_c * (v_des - vy_com)
        a_stop = np.minimum(vy_com**2 / (2.0 * np.maximum(d, 0.01)), 3.0 * g)
        a_crouch = np.where(vy_com < v_des, np.maximum(a_crouch, a_stop), a_crouch)
        lam_crouch = np.maximum(m * (g + a_crouch), 0.2 * m * g)
        phi = np.arctan2(ry, rx)  # the leg's direction; at L_lo the thigh is at phi - alpha_lo
        t1_lo = phi - self.alpha_lo
        y_lo = -self.L_lo * np.sin(phi) + (a * np.sin(t1_lo) + b * np.sin(t1_lo + self.q2_lo)) / m
        rise = np.maximum(np.maximum(y_lo - y_com, vy_com * dt), self.stroke_min)
        lam_push = np.maximum(E_star - E_v, 0.0) / rise
        lam_y = np.where(phase == _CROUCH, lam_crouch, lam_push)
        # 3. attitude: the ground force's moment about the COM steers H and the torso angle to zero
        kH, kth = self.attitude_gains
        H = self._angular_momentum(wb, w1, w2, s1, c1, s2, c2)
        lam_x = (-kH * H - kth * p.I_b * thb - (rx - x_com_rel) * lam_y) / y_com
        kp, kd = self.dwell_gains
        lam_x = np.where(dwelling, m * (-kp * (x_com_rel - rx) - kd * vx_com), lam_x)  # the COM held over the foot
        cap = self.friction_margin * self.config.mu * lam_y
        lam_x = np.clip(lam_x, -cap, cap)
        tau_stance = self._stance_torques(obs, np.stack([lam_x, lam_y], axis=-1))

        # 2. foot placement (flight, and the release): IK at L_td, computed-torque servo of the leg angles
        v_star = np.clip(-self.k_x * self._x0, -0.3, 0.3)  # back towards the start
        dx_foot = vx_com * self.T_s / 2.0 + self.k_v * (vx_com - v_star)
        knee = np.arccos(np.clip((self.L_td**2 - l1**2 - l2**2) / (2.0 * l1 * l2), -1.0, 1.0))
        alpha = np.arctan2(l2 * np.sin(knee), l1 + l2 * np.cos(knee))
        com_des = x_com_rel
        for _ in range(2):  # the COM's offset from the hip at the target posture
            fx = np.clip(com_des + dx_foot, -0.6 * self.L_td, 0.6 * self.L_td)
            th1_d = np.arctan2(-np.sqrt(np.maximum(self.L_td**2 - fx**2, 1e-6)), fx) - alpha
            th2_d = th1_d + knee
            com_des = (a * np.cos(th1_d) + b * np.cos(th2_d)) / m
        kp, kd = self.swing_gains
        dd1 = kp * _wrap(th1_d - th1) - kd * w1
        dd2 = kp * _wrap(th2_d - th2) - kd * w2
        K12 = self.kf * (c1 * c2 + s1 * s2)
        s12 = s1 * c2 - c1 * s2
        tau_knee_f = K12 * dd1 + self.K22 * dd2 - self.kf * s12 * w1**2
        tau_hip_f = self.K11 * dd1 + K12 * dd2 + tau_knee_f + self.kf * s12 * w2**2

        self._vx = vx_com
        stance = contact & (phase != _RELEASE)
        tau = np.empty((obs.shape[0], 2))
        tau[:, 0] = np.where(stance, tau_stance[:, 0], tau_hip_f)
        tau[:, 1] = np.where(stance, tau_stance[:, 1], tau_knee_f)
        return tau

    def _angular_momentum(self, wb, w1, w2, s1, c1, s2, c2) -> np.ndarray:
        """Whole-body angular momentum about the COM [kg m^2/s], from positions and velocities relative to the hip."""
        p, m = self.params, self.m
        t_x, t_y, t_vx, t_vy = p.c1 * c1, p.c1 * s1, -p.c1 * s1 * w1, p.c1 * c1 * w1  # thigh's COM
        s_x, s_y = p.l1 * c1 + p.c2 * c2, p.l1 * s1 + p.c2 * s2  # shank's COM
        s_vx, s_vy = -p.l1 * s1 * w1 - p.c2 * s2 * w2, p.l1 * c1 * w1 + p.c2 * c2 * w2
        g_x, g_y = (p.m1 * t_x + p.m2 * s_x) / m, (p.m1 * t_y + p.m2 * s_y) / m  # whole-body COM
        g_vx, g_vy = (p.m1 * t_vx + p.m2 * s_vx) / m, (p.m1 * t_vy + p.m2 * s_vy) / m
        H = p.I_b * wb + p.I1 * w1 + p.I2 * w2
        for mass, x, y, vx, vy in ((p.m_b, 0.0, 0.0, 0.0, 0.0), (p.m1, t_x, t_y, t_vx, t_vy), (p.m2, s_x, s_y, s_vx, s_vy)):
            H = H + mass * ((x - g_x) * (vy - g_vy) - (y - g_y) * (vx - g_vx))
        return H

    def _stance_torques(self, obs: np.ndarray, lam_des: np.ndarray) -> np.ndarray:
        """The torques under which the stance dynamics give the ground force ``s lam_des`` ``(N, 2)`` now.

        The stance model's force is affine in the torques, ``lam = lam_0 + Lambda tau``: three solves of the
        exact dynamics (at zero and unit torques) give ``lam_0`` and ``Lambda``, and ``tau = s t_1 - t_0``
        with ``Lambda t_1 = lam_des``, ``Lambda t_0 = lam_0``; ``s`` is the largest scale in [0, 1] within
        the torque limits.
        """
        from leg_env.physics.dynamics import stance_dynamics

        n = obs.shape[0]
        q = np.zeros((n, 5))
        q[:, 1:5] = obs[:, Obs.base_y:Obs.q2 + 1]  # the stance dynamics do not depend on x_b
        qd = obs[:, Obs.vx_b:Obs.w_q2 + 1].astype(np.float64)
        torques = np.zeros((3, n, 2))
        torques[1, :, 0] = 1.0
        torques[2, :, 1] = 1.0
        _, lam = stance_dynamics(np.broadcast_to(q, (3, n, 5)), np.broadcast_to(qd, (3, n, 5)), torques, self.params)
        Lam = np.stack([lam[1] - lam[0], lam[2] - lam[0]], axis=-1)  # (n, 2, 2): column j per unit torque j
        t1 = np.linalg.solve(Lam, lam_des[..., None])[..., 0]
        t0 = np.linalg.solve(Lam, lam[0][..., None])[..., 0]
        lim = self.torque_limit
        with np.errstate(divide="ignore", invalid="ignore"):
            hi = np.where(t1 > 0, (lim + t0) / t1, np.where(t1 < 0, (t0 - lim) / t1, np.inf))
        s = np.clip(np.min(hi, axis=-1), 0.0, 1.0)[:, None]
        return s * t1 - t0



def _wrap(angle):
    return (angle + np.pi) % (2.0 * np.pi) - np.pi
