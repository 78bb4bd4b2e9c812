"""A model-based hopping controller for ``leg_env/PlanarLegHop-v0``: Raibert's three-part decomposition.

Raibert (1986) splits running into three decoupled servos; on this articulated leg (hip and knee, point
foot, no spring) each becomes a joint-torque law on the observation:

1. **Hopping height** (stance, knee). A virtual prismatic leg between the hip and the foot, of length
   ``L`` and extension force ``F``, acts through the knee alone: ``tau_knee = F dL/dq2`` (turning the
   whole leg at the hip does not change ``L``, so ``dL/dq1 = 0``). ``F`` is a virtual spring
   ``k (L0 - L)`` plus, while the leg extends (``L' >= 0``), a thrust ``F_th`` that supplies the
   vertical energy still missing over the remaining stroke:

       E_v = m y_com'^2 / 2 + m g y_com,     E* = m g (y_stand + dh*)   (the task's own definitions)
       F_th = max(0, E* - E_v - k (L0 - L)^2 / 2) / max(L0 - L, stroke_min)

   In flight ``E_v`` is ``m g`` times the apex height, so reaching ``E*`` at lift-off is hopping to the
   commanded apex (up to what the massless-leg picture misses: the leg's own mass, the impact loss at
   touchdown), and the next stance corrects what the last one missed.
2. **Forward speed** (flight, hip and knee). The foot is placed ahead of the whole-body COM by
   ``x_f - x_com = v T_s / 2 + k_v (v - v*)``, ``v* = -k_x (x_com - x_com,0)`` (Raibert's neutral point plus a
   speed correction towards the start; the task asks for hopping in place, ``v* = 0``), at leg length ``L0``,
   through the leg's inverse kinematics and a joint PD servo.
3. **Body attitude** (stance, hip). ``tau_hip = k_p th_b + k_d th_b'`` levels the torso: the hip torque
   turns the torso by ``-tau_hip`` while the foot holds the leg.

The start of an episode (at rest, standing) needs no special case: the thrust begins at once. The
controller reads only the observation (19 entries: ``PlanarLegHop-v0``'s table) and the model
(``LegParams``); the COM's displacement from the start is dead-reckoned from its velocity (per robot of
a batch; zeroed by ``reset()`` or where ``episode_start`` is true), since the foot's own ``x`` is not
observed. Torques are clipped to the joints' limits.
"""

from __future__ import annotations

import numpy as np

from leg_env.params import LegParams

__all__ = ["HopperController"]


class HopperController:
    """Raibert-style hopping controller with SB3's ``predict`` (module docstring).

    Args:
        params: the robot (``LegParams``, a dict, or None for the defaults).
        config: the task (``HopConfig`` or a dict of its fields; None: defaults): ``torque_limit``,
            ``dt`` and the nominal posture (for ``y_stand``).
        leg_length: ``L0``, the virtual spring's rest length and the flight leg length [m].
        stiffness: ``k`` [N/m]; stroke_min: the smallest stroke the thrust is spread over [m].
        stance_time: ``T_s`` of the neutral point [s]; speed_gain: ``k_v`` [s]; position_gain: ``k_x`` [1/s].
        attitude_gains: ``(k_p, k_d)`` of the torso servo [N m/rad, N m s/rad].
        joint_gains: ``(k_p, k_d)`` of the flight joint servo.
    """

    def __init__(
        self,
        params: LegParams | dict | None = None,
        config=None,
        leg_length: float = 0.95,
        stiffness: float = 2000.0,
        stroke_min: float = 0.03,
        stance_time: float = 0.2,
        speed_gain: float = 0.05,
        position_gain: float = 0.1,
        attitude_gains: tuple = (20.0, 4.0),
        balance_gains: tuple = (20.0, 4.0),
        friction_margin: float = 0.8,
        joint_gains: tuple = (150.0, 8.0),
    ):
        from leg_env.dynamics import com_position
        from leg_env.tasks.hop import HopConfig
        from leg_env.tasks.stance import nominal_state

        self.params = p = LegParams.from_any(params)
        self.config = c = config if isinstance(config, HopConfig) else HopConfig.from_kwargs(config)
        self.m = p.m_b + p.m1 + p.m2
        self.a, self.b = p.m1 * p.c1 + p.m2 * p.l1, p.m2 * p.c2  # COM moments of the thigh and shank about the hip
        self.y_stand = float(com_position(nominal_state(p, c).q, p)[1])
        self.torque_limit = np.asarray(c.torque_limit, dtype=np.float64)
        self.L0, self.k, self.stroke_min = leg_length, stiffness, stroke_min
        self.T_s, self.k_v, self.k_x = stance_time, speed_gain, position_gain
        self.attitude_gains, self.balance_gains, self.joint_gains = attitude_gains, balance_gains, joint_gains
        self.friction_margin = friction_margin
        self._x0 = None  # per-robot COM x at the episode's start

    def reset(self) -> None:
        """Forget the episodes' start positions (the next observation sets them)."""
        self._x0 = None

    def torque(self, obs: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """Joint torques [N m] for observations ``(N, 19)`` and COM displacements from the start ``x0`` ``(N,)`` [m]."""
        p, m, a, b = self.params, self.m, self.a, self.b
        l1, l2, g = p.l1, p.l2, p.g
        thb, q1, q2 = obs[:, 2], obs[:, 3], obs[:, 4]
        vxb, vyb, wb, wq1, wq2 = obs[:, 5], obs[:, 6], obs[:, 7], obs[:, 8], obs[:, 9]
        contact = obs[:, 15] > 0.5
        command = obs[:, 18]
        th1, th2 = thb + q1, thb + q1 + q2
        w1, w2 = wb + wq1, wb + wq1 + wq2
        s1, c1, s2, c2 = np.sin(th1), np.cos(th1), np.sin(th2), np.cos(th2)
        # COM relative to the hip (the base point) and its velocity, world axes
        x_com_rel = (a * c1 + b * c2) / m
        y_com = obs[:, 1] + (a * s1 + b * s2) / m  # above the ground
        vx_com = vxb - (a * s1 * w1 + b * s2 * w2) / m
        vy_com = vyb + (a * c1 * w1 + b * c2 * w2) / m
        # virtual leg from the hip to the foot
        rx, ry = l1 * c1 + l2 * c2, l1 * s1 + l2 * s2
        L = np.hypot(rx, ry)
        rdx, rdy = -l1 * s1 * w1 - l2 * s2 * w2, l1 * c1 * w1 + l2 * c2 * w2
        L_dot = (rx * rdx + ry * rdy) / L

        # 1. height: the leg's vertical push, spring + thrust over the remaining stroke (stance)
        E_v = 0.5 * m * vy_com**2 + m * g * y_com
        E_star = m * g * (self.y_stand + command)
        spring = self.k * (self.L0 - L)
        deficit = E_star - E_v - 0.5 * self.k * np.maximum(self.L0 - L, 0.0) ** 2
        thrust = np.where(L_dot >= 0.0, np.maximum(deficit, 0.0) / np.maximum(self.L0 - L, self.stroke_min), 0.0)
        lam_y = np.maximum(spring + thrust, 0.0)
        # 3. attitude and balance: the horizontal force brings the COM over the foot, stops it, and
        # levels the torso (its moment about the COM turns the whole body)
        kx, kvx = self.balance_gains
        kp, kd = self.attitude_gains
        com_over_foot = x_com_rel - rx  # COM x relative to the foot
        lam_x = m * (-kx * com_over_foot - kvx * vx_com) - kp * thb - kd * wb
        cap = self.friction_margin * self.config.mu * lam_y
        lam_x = np.clip(lam_x, -cap, cap)
        tau_stance = self._torques_for_force(obs, np.stack([lam_x, lam_y], axis=-1))

        # 2. foot placement (flight): foot ahead of the COM, leg at L0, joint PD
        v_des = np.clip(-self.k_x * x0, -0.3, 0.3)  # back towards the start
        dx_foot = vx_com * self.T_s / 2.0 + self.k_v * (vx_com - v_des)
        fx = np.clip(x_com_rel + dx_foot, -0.6 * self.L0, 0.6 * self.L0)  # foot relative to the hip
        fy = -np.sqrt(np.maximum(self.L0**2 - fx**2, 1e-6))
        cos_knee = np.clip((self.L0**2 - l1**2 - l2**2) / (2.0 * l1 * l2), -1.0, 1.0)
        knee = np.arccos(cos_knee)  # the knee bent forward (q2 > 0), as in the nominal posture
        th1_des = np.arctan2(fy, fx) - np.arctan2(l2 * np.sin(knee), l1 + l2 * np.cos(knee))
        q1_des = th1_des - thb
        jp, jd = self.joint_gains
        tau_hip_flight = jp * (_wrap(q1_des - q1)) - jd * wq1
        tau_knee_flight = jp * (knee - q2) - jd * wq2

        self._vx = vx_com
        tau = np.empty((obs.shape[0], 2))
        tau[:, 0] = np.where(contact, tau_stance[:, 0], tau_hip_flight)
        tau[:, 1] = np.where(contact, tau_stance[:, 1], tau_knee_flight)
        return tau

    def _torques_for_force(self, obs: np.ndarray, lam_des: np.ndarray) -> np.ndarray:
        """The joint torques under which the stance dynamics give the ground force ``lam_des`` ``(N, 2)`` now.

        The stance model's force is affine in the torques, ``lam = lam_0 + Lambda tau``: three solves of the
        exact dynamics (at zero and unit torques) give ``lam_0`` and ``Lambda``, and ``Lambda tau = lam_des
        - lam_0`` is solved (not inverted) per robot.
        """
        from leg_env.dynamics import stance_dynamics

        n = obs.shape[0]
        q = np.zeros((n, 5))
        q[:, 1:5] = obs[:, 1:5]
        q[:, 0] = obs[:, 0]
        qd = obs[:, 5:10].astype(np.float64)
        torques = np.zeros((3, n, 2))
        torques[1, :, 0] = 1.0
        torques[2, :, 1] = 1.0
        _, lam = stance_dynamics(np.broadcast_to(q, (3, n, 5)), np.broadcast_to(qd, (3, n, 5)), torques, self.params)
        Lam = np.stack([lam[1] - lam[0], lam[2] - lam[0]], axis=-1)  # (n, 2, 2): column j per unit torque j
        return np.linalg.solve(Lam, (lam_des - lam[0])[..., None])[..., 0]

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3-style ``predict``: actions in [-1, 1] for one observation (19,) or a batch (N, 19)."""
        obs = np.asarray(observation, dtype=np.float64)
        if obs.shape[-1:] != (19,) or obs.ndim not in (1, 2):
            raise ValueError(f"observation must have shape (19,) or (N, 19) (PlanarLegHop-v0), got {obs.shape}")
        batch = obs.reshape(-1, 19)
        if self._x0 is None or self._x0.shape[0] != batch.shape[0]:
            self._x0 = np.zeros(batch.shape[0])
        if episode_start is not None:
            self._x0[np.asarray(episode_start, dtype=bool).reshape(-1)] = 0.0
        tau = self.torque(batch, self._x0)
        self._x0 += self._vx * self.config.dt  # dead reckoning of the COM's x: the foot's x is not observed
        action = np.clip(tau / self.torque_limit, -1.0, 1.0).astype(np.float32)
        return (action[0] if obs.ndim == 1 else action), None


def _wrap(angle):
    return (angle + np.pi) % (2.0 * np.pi) - np.pi
