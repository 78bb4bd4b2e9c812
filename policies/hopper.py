"""A model-based hopping controller for ``leg_env/PlanarLegHop-v4``: Raibert's three-part decomposition.

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

   With ``dwell`` > 0 (off by default) the push waits until ``dwell`` seconds after the touchdown: while the crouch
   has stopped at its bottom (``y_com' >= -0.05`` m/s within 3 cm of ``L_low``) before then, the ground force holds the
   COM over the foot instead of steering the attitude, ``lam_x = m (-k_p (x_com - x_f) - k_d x_com')``
   (``dwell_gains``): standing on the point foot, the COM falls away from it otherwise (with the attitude servo, 6 of
   24 episodes of a 0.38 s dwell fell; with this one 2, the hopper's own number). Without a spring, a hop's work is
   set by its height and the crouch's depth, not by how long it stands: a longer stance spends about the same work a
   hop over a longer period (the hopper with ``dwell=0.38``: 40.0 W against 45.0 W on 24 episodes, 31.6 J a hop
   against 30.9).

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

The law is compiled (``leg_env/_core/hopper.c``, ``leg_env._core.kernels.hopper_torque``, looped over the robots with
the GIL released): this class holds its settings (one float64 row, ``_gains``) and the per-robot state it advances in
place. A call for one robot costs microseconds, so that a model-predictive controller can run it thousands of times a
control step inside its plans (``policies.mpc``).

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

from leg_env import checks
from leg_env._core import kernels
from leg_env.physics.params import LegParams
from leg_env.tasks.base import OBS_DIM_UNILATERAL, Obs
from policies.base import BatchedController

__all__ = ["HopperController", "LAW_COLUMNS"]

LAW_COLUMNS = [Obs.th_b, Obs.q1, Obs.q2, Obs.vx_b, Obs.vy_b, Obs.w_b, Obs.w_q1, Obs.w_q2, Obs.base_y, Obs.contact, Obs.command]
"""The observation's entries the law reads, in the compiled law's order (``hopper.c``, ``HO_*``)."""

_CROUCH = 0  # the stance phase a touchdown or a start begins (hopper.c's HOP_CROUCH; then HOP_PUSH 1, HOP_RELEASE 2)


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
        dwell: the shortest time from a touchdown to the push [s] (0: none).
        dwell_gains: ``(k_p, k_d)`` of the COM's servo over the foot while the crouch waits out the dwell [1/s^2, 1/s].

    Raises:
        TypeError: an unknown keyword, or a setting that is not a number (a pair: not two). ValueError: a setting out
            of its range (the message names it: ``HopperController.dwell must be in [0, 10] s, got -1``).
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
        dwell: float = 0.0,
        dwell_gains: tuple = (20.0, 8.0),
    ):
        from leg_env.physics.dynamics import com_position
        from leg_env.tasks.hop import HopConfig
        from leg_env.tasks.base import nominal_state

        self.params = p = LegParams.from_any(params)
        self.config = c = config if isinstance(config, HopConfig) else HopConfig.from_kwargs(config)
        name = "HopperController."
        touchdown_length = checks.real(name + "touchdown_length", touchdown_length, 0.0, p.l1 + p.l2, lo_open=True, unit="m")
        liftoff_knee = checks.real(name + "liftoff_knee", liftoff_knee, 0.0, np.pi, lo_open=True, hi_open=True, unit="rad")
        crouch = checks.pair(name + "crouch", crouch, 0.0, 1.0)
        sink_speed = checks.real(name + "sink_speed", sink_speed, 0.0, 100.0, lo_open=True, unit="m/s")
        crouch_decel = checks.real(name + "crouch_decel", crouch_decel, 0.0, 1e3, lo_open=True, unit="m/s^2")
        crouch_gain = checks.real(name + "crouch_gain", crouch_gain, 0.0, 1e4, unit="1/s")
        stroke_min = checks.real(name + "stroke_min", stroke_min, 0.0, 1.0, lo_open=True, unit="m")
        apex_gain = checks.real(name + "apex_gain", apex_gain, 0.0, 10.0)
        stance_time = checks.real(name + "stance_time", stance_time, 0.0, 10.0, unit="s")
        speed_gain = checks.real(name + "speed_gain", speed_gain, 0.0, 10.0, unit="s")
        position_gain = checks.real(name + "position_gain", position_gain, 0.0, 100.0, unit="1/s")
        attitude_gains = checks.pair(name + "attitude_gains", attitude_gains, 0.0, 1e4)
        friction_margin = checks.real(name + "friction_margin", friction_margin, 0.0, 1.0)
        swing_gains = checks.pair(name + "swing_gains", swing_gains, 0.0, 1e5)
        dwell = checks.real(name + "dwell", dwell, 0.0, 10.0, unit="s")
        dwell_gains = checks.pair(name + "dwell_gains", dwell_gains, 0.0, 1e4)
        self.y_stand = float(com_position(nominal_state(p, c).q, p)[1])
        self.torque_limit = np.asarray(c.torque_limit, dtype=np.float64)
        # the virtual leg (hip to foot) at the push's end and in flight: its length and its angle from the thigh
        L_lo = float(np.sqrt(p.l1**2 + p.l2**2 + 2.0 * p.l1 * p.l2 * np.cos(liftoff_knee)))
        alpha_lo = float(np.arctan2(p.l2 * np.sin(liftoff_knee), p.l1 + p.l2 * np.cos(liftoff_knee)))
        knee = np.arccos(np.clip((touchdown_length**2 - p.l1**2 - p.l2**2) / (2.0 * p.l1 * p.l2), -1.0, 1.0))
        alpha = np.arctan2(p.l2 * np.sin(knee), p.l1 + p.l2 * np.cos(knee))
        limit = self.torque_limit * np.ones(2)
        self._gains = np.array([  # the compiled law's settings, in its order (leg_env/_core/hopper.c, HG_*)
            touchdown_length, liftoff_knee, L_lo, alpha_lo, crouch[0], crouch[1], sink_speed, crouch_decel,
            crouch_gain, stroke_min, apex_gain, stance_time, speed_gain, position_gain, attitude_gains[0],
            attitude_gains[1], friction_margin, swing_gains[0], swing_gains[1], self.y_stand, c.mu, c.dt, limit[0],
            limit[1], knee, alpha, dwell, dwell_gains[0], dwell_gains[1]], dtype=np.float64)

    # PlanarLegHop's 22 entries (then the last action, with observe_action), whose entries after the command (the
    # COM's drift, the ground time, the last hop's apex, the last action) the controller does not read: it keeps its
    # own dead reckoning and apex estimate and hops all the time
    widths, task, dtype = (22, 24), "PlanarLegHop-v4: 24 entries, 22 without observe_action", np.float64

    continuous_state = ("_bias", "_apex", "_x0")
    """The per-robot state that moves with the robot: the apex bias, the last flight's apex, the dead-reckoned drift."""
    discrete_state = ("_phase", "_was_flight", "_since_touchdown")
    """The per-robot state that changes only at thresholds or by the clock: the stance phase, whether the last step was in
    flight, the time on the ground since the last touchdown."""

    def _allocate(self, n: int) -> None:
        self._x0, self._bias, self._apex = np.zeros(n), np.zeros(n), np.zeros(n)
        self._phase, self._was_flight = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool)
        self._since_touchdown = np.zeros(n)

    def _start(self, rows: np.ndarray, batch: np.ndarray | None = None) -> None:
        self._x0[rows] = 0.0
        self._phase[rows] = _CROUCH
        self._bias[rows] = 0.0
        self._apex[rows] = np.nan
        self._was_flight[rows] = False
        self._since_touchdown[rows] = 0.0

    def torque(self, obs: np.ndarray) -> np.ndarray:
        """Joint torques [N m] for observations ``(N, 22)``; advances the per-robot phase and apex bias (the law of the
        module docstring, compiled: ``leg_env._core.kernels.hopper_torque``).

        Raises:
            ValueError: a NaN or inf in an entry the law reads (nothing is advanced).
        """
        reading = np.ascontiguousarray(obs[:, LAW_COLUMNS], dtype=np.float64)
        if not np.isfinite(reading).all():
            bad = np.flatnonzero(~np.isfinite(reading).all(axis=1))
            raise ValueError(f"observation must be finite in the entries the hopper reads: rows {bad[:5].tolist()} are not")
        n = reading.shape[0]
        tau, self._vx = np.empty((n, 2)), np.empty(n)
        kernels.hopper_torque(reading, self._x0, self.params.array, self._gains, self._bias, self._apex, self._phase,
                              self._was_flight, self._since_touchdown, tau, self._vx)
        return tau

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

