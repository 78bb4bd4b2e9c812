"""A model-based hopping controller for ``leg_env/PlanarLegHop-v4`` (and v0-v3): Raibert's three-part decomposition.

Raibert (1986) splits running into three decoupled servos. On this articulated leg (hip and knee, point
foot, no spring, 50 N m per joint) each becomes a law on the observation, with the stance torques solved
exactly from the stance model and the flight torques from the flight model:

1. **Hopping height** (stance). Each stance has three phases per robot:

   * *crouch* (from touchdown, and from the start of an episode): the COM sinks at most at ``v_sink`` and
     stops when the virtual leg (hip to foot) reaches ``L_low = L_lo - c_0 - c_1 dh*``, along the profile
     ``v_des = -min(v_sink, sqrt(2 a_c (L - L_low)))``; ``lam_y = m (g + k_c (v_des - y_com'))``, and when the
     COM comes down faster than the profile (a landing) at least the deceleration that stops it within
     the remaining stroke, ``y_com'^2 / (2 (L - L_low))``;
   * *push* (once the crouch has stopped): the vertical energy still missing, spread over the COM's
     remaining rise to its lift-off height ``y_lo`` (the leg along its present direction at length
     ``L_lo``), with at least one step's travel:

         E_v = m y_com'^2 / 2 + m g y_com,     E* = m g (y_stand + dh* + b)   (the task's own definitions)
         lam_y = max(0, E* - E_v) / max(y_lo - y_com, y_com' dt, stroke_min)

   * *release* (once ``E_v >= E*``, or the knee would pass its lift-off angle within a step): the flight
     servo takes over, which stops the knee and lifts the foot.

   In flight ``E_v / (m g)`` is the apex height; at each touchdown the per-robot bias ``b`` integrates the
   last apex error, ``b -= k_a (apex - y_stand - dh*)`` (what the model misses: the leg's own motion,
   the release step, the impact).
2. **Forward speed** (flight). The foot is placed ahead of the whole-body COM by
   ``x_f - x_com = v T_s / 2 + k_v (v - v*)``, ``v* = -k_x (x_com - x_com,0)`` (Raibert's neutral point plus a
   speed correction towards the start; the task asks for hopping in place), at leg length ``L_td``:
   inverse kinematics give the absolute leg angles ``(th1*, th2*)`` (knee bent forward), and a
   computed-torque servo of the flight model, ``K(th) th'' + c(th, th') = (tau_hip - tau_knee, tau_knee)``
   (the leg's inertia about the free-falling COM), tracks ``th'' = k_p (th* - th) - k_d th'``. Servoing the
   absolute angles places the foot whatever the torso does; the torso takes the reaction.
3. **Body attitude** (stance). The whole-body angular momentum about the COM, ``H``, is conserved in
   flight, so the torso's rate after the leg has stopped is ``H / I``: the stance steers ``H`` to zero and
   the torso level through the moment of the ground force about the COM,

       (x_f - x_com) lam_y + y_com lam_x = -k_H H - k_th I_b th_b,

   which sets ``lam_x`` (clipped to ``friction_margin`` of the friction cone). Balance of the COM over the
   foot is left to the foot placement, as in Raibert's hopper.

The stance model's ground force is affine in the torques, ``lam = lam_0 + Lambda tau``: the torques for
``lam_des`` come from three exact solves and one 2x2 solve per robot, and where they would pass the torque
limit ``lam_des`` is scaled down along its direction to the largest feasible force (the knee limit
mostly). The controller reads only the observation (the first 19 entries of ``PlanarLegHop``'s table) and the
model (``LegParams``, ``HopConfig``); its per-robot state (phase, apex bias, last apex, and the COM's
displacement from the start, dead-reckoned from its velocity since the foot's own ``x`` is not observed)
is reset by ``reset()`` or where ``episode_start`` is true. Torques are clipped to the joints' limits.

**Tuning** (measured on 100 episodes, seeds 10000..10099, and on seeds 30000..30099 as a check).
The first gains (``position_gain`` 0.3, ``liftoff_knee`` 0.6) survived 95% / 85%, drifted 12.6 cm (mean after
10 s) and missed the apex by 1.62 cm. The drift is the slow position loop, not the dead reckoning: its
estimate of the COM's displacement is within 0.16 cm of the truth at 10 s (mean over the surviving
episodes), while the loop's time constant ``1 / k_x`` was about 3 s of a 10 s episode. ``position_gain`` 0.6
halves the drift (6.2 cm) but alone costs survival (92% / 83%): the falls are the push's end, where the knee
overshoots its lower limit (0.05 rad) after release, with the torso pitched back, or the flight servo
starts while the foot is still on the ground. Ending the push a little earlier, ``liftoff_knee`` 0.62,
restores survival (95% / 89%) for a slightly larger apex error (1.78 cm / 1.61 cm): the push's stroke is
shorter, and the highest commands are undershot more. Larger gains or an earlier release (0.65-0.75) each
cost either survival or apex accuracy. The falls come at the lowest commands: on 20 fresh episodes per range of
commands (seeds 30000..30019), the controller survives none at 5-5.5 cm, 15% at 5.5-6 cm, 95% at 6-7 cm and every one
at 7-8 cm.
"""

from __future__ import annotations

import numpy as np

from leg_env.physics.params import LegParams
from leg_env.tasks.base import OBS_DIM_UNILATERAL, Obs
from policies.base import BatchedController

__all__ = ["HopperController"]

_CROUCH, _PUSH, _RELEASE = 0, 1, 2  # stance phases


class HopperController(BatchedController):
    """Raibert-style hopping controller with SB3's ``predict`` (module docstring).

    Args:
        params: the robot (``LegParams``, a dict, or None for the defaults).
        config: the task (``HopConfig`` or a dict of its fields; None: defaults): ``torque_limit``, ``dt``,
            ``mu`` and the nominal posture (for ``y_stand``).
        touchdown_length: ``L_td``, the leg length held in flight [m].
        liftoff_knee: the knee angle at which the push ends, which sets ``L_lo`` [rad].
        crouch: ``(c_0, c_1)`` of the crouch depth ``L_lo - L_low = c_0 + c_1 dh*`` [m, -].
        sink_speed: ``v_sink`` [m/s]; crouch_decel: ``a_c`` [m/s^2]; crouch_gain: ``k_c`` [1/s].
        stroke_min: the shortest rise the push is spread over [m].
        apex_gain: ``k_a``, the per-hop integral gain of the apex bias.
        stance_time: ``T_s`` of the neutral point [s]; speed_gain: ``k_v`` [s]; position_gain: ``k_x`` [1/s].
        attitude_gains: ``(k_H, k_th)`` of the stance angular-momentum servo [1/s, 1/s^2].
        friction_margin: the fraction of the friction cone ``lam_x`` may use.
        swing_gains: ``(k_p, k_d)`` of the flight computed-torque servo [1/s^2, 1/s].
    """

    def __init__(
        self,
        params: LegParams | dict | None = None,
        config=None,
        touchdown_length: float = 0.95,
        liftoff_knee: float = 0.62,
        crouch: tuple = (0.05, 0.3),
        sink_speed: float = 1.0,
        crouch_decel: float = 4.0,
        crouch_gain: float = 10.0,
        stroke_min: float = 0.01,
        apex_gain: float = 0.5,
        stance_time: float = 0.25,
        speed_gain: float = 0.15,
        position_gain: float = 0.6,
        attitude_gains: tuple = (40.0, 20.0),
        friction_margin: float = 0.8,
        swing_gains: tuple = (400.0, 40.0),
    ):
        from leg_env.physics.dynamics import com_position
        from leg_env.tasks.hop import HopConfig
        from leg_env.tasks.base import nominal_state

        self.params = p = LegParams.from_any(params)
        self.config = c = config if isinstance(config, HopConfig) else HopConfig.from_kwargs(config)
        self.m = m = p.m_b + p.m1 + p.m2
        self.a, self.b = a, b = p.m1 * p.c1 + p.m2 * p.l1, p.m2 * p.c2  # leg's and shank's first moments
        # flight inertia of the absolute leg angles about the free-falling COM (leg_env.physics.dynamics._flight_core)
        self.kf = p.m2 * p.l1 * p.c2 - a * b / m
        self.K11 = p.I1 + p.m1 * p.c1**2 + p.m2 * p.l1**2 - a * a / m
        self.K22 = p.I2 + p.m2 * p.c2**2 - b * b / m
        self.y_stand = float(com_position(nominal_state(p, c).q, p)[1])
        self.torque_limit = np.asarray(c.torque_limit, dtype=np.float64)
        self.L_td = touchdown_length
        self.q2_lo = liftoff_knee
        self.L_lo = float(np.sqrt(p.l1**2 + p.l2**2 + 2.0 * p.l1 * p.l2 * np.cos(liftoff_knee)))
        self.alpha_lo = float(np.arctan2(p.l2 * np.sin(liftoff_knee), p.l1 + p.l2 * np.cos(liftoff_knee)))
        self.crouch = crouch
        self.v_sink, self.a_c, self.k_c, self.stroke_min = sink_speed, crouch_decel, crouch_gain, stroke_min
        self.apex_gain = apex_gain
        self.T_s, self.k_v, self.k_x = stance_time, speed_gain, position_gain
        self.attitude_gains, self.friction_margin, self.swing_gains = attitude_gains, friction_margin, swing_gains

    # PlanarLegHop's 22 entries (then the last action, with observe_action), whose entries after the command (the
    # COM's drift, the ground time, the last hop's apex, the last action) the controller does not read: it keeps its
    # own dead reckoning and apex estimate and hops all the time
    widths, task, dtype = (22, 24), "PlanarLegHop-v4: 24 entries, 22 without observe_action", np.float64

    continuous_state = ("_bias", "_apex", "_x0")
    """The per-robot state that moves with the robot: the apex bias, the last flight's apex, the dead-reckoned drift."""
    discrete_state = ("_phase", "_was_flight")
    """The per-robot state that changes only at thresholds: the stance phase, whether the last step was in flight."""

    def _allocate(self, n: int) -> None:
        self._x0, self._bias, self._apex = np.zeros(n), np.zeros(n), np.zeros(n)
        self._phase, self._was_flight = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool)

    def _start(self, rows: np.ndarray, batch: np.ndarray | None = None) -> None:
        self._x0[rows] = 0.0
        self._phase[rows] = _CROUCH
        self._bias[rows] = 0.0
        self._apex[rows] = np.nan
        self._was_flight[rows] = False

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
        self._apex[~contact] = E_v[~contact] / (m * g)
        self._was_flight = ~contact
        E_star = m * g * (target + self._bias)
        L_low = self.L_lo - self.crouch[0] - self.crouch[1] * command
        crouch = contact & (self._phase == _CROUCH)
        self._phase[crouch & (vy_com >= -0.05) & (L < L_low + 0.03)] = _PUSH
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

    def act_on(self, observation: np.ndarray, command: float, starts: np.ndarray, rows: np.ndarray, action: np.ndarray) -> None:
        """Write the hopper's actions into ``action[rows]``, for balance-task observations ``(N, 18)`` (or more: a
        task's own entries after the 18 are not read) and an apex command.

        The recovery hop of another controller (``policies.gated``, ``policies.stepping``): the hopper runs on the
        whole batch, its state being per robot, with ``command`` [m] as the hop task's command entry; the robots
        in ``starts`` start afresh (a hop's first step).
        """
        n = observation.shape[0]
        hop_obs = np.full((n, self.widths[0]), np.nan, dtype=np.float32)  # the hop's entries after the command: not read
        hop_obs[:, :OBS_DIM_UNILATERAL] = observation[:, :OBS_DIM_UNILATERAL]  # the unilateral ground's 18 entries
        hop_obs[:, Obs.command] = command
        hop_action, _ = self.predict(hop_obs, episode_start=starts)
        action[rows] = hop_action[rows]

    def act(self, batch: np.ndarray) -> np.ndarray:
        return self.exact_actions(batch).astype(np.float32)

    def exact_actions(self, batch: np.ndarray) -> np.ndarray:
        """``act``'s actions in float64, before their rounding to float32 (for the closed loop's derivatives)."""
        tau = self.torque(batch)
        self._x0 += self._vx * self.config.dt  # dead reckoning of the COM's x: the foot's x is not observed
        return np.clip(tau / self.torque_limit, -1.0, 1.0)


def _wrap(angle):
    return (angle + np.pi) % (2.0 * np.pi) - np.pi

