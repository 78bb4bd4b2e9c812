"""``leg_env/PlanarLegStance-v0``: balance the planar leg on its pinned foot (one robot)."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .. import checks
from ..dynamics import foot_position
from ..params import LegParams
from ..hybrid import GROUND_TOL
from ..task import (
    FLAG_NAMES, OBS_DIM, OBS_DIM_UNILATERAL, OUT_DIM, OUT_EXTRA, OUT_KICK, OUT_LAM, OUT_TERMS, STATE_ACTION,
    STATE_ANCHOR, STATE_DIM, STATE_MODE, STATE_Q, STATE_QD, StanceConfig, compiled_entry, nominal_state, reset_state,
    REWARD_INFO_KEYS, row_info, start_batch, step_batch, task_constants,
)  # fmt: skip

__all__ = ["PlanarLegStanceEnv"]

_RESET_OPTIONS = ("qpos", "qvel")
QPOS_BOUND = 1.0e6
"""Largest magnitude of a reset ``qpos`` entry [m, rad]; ``qvel`` entries are bounded by ``max_rate``."""
MAX_PIXELS = 16384  # largest frame width or height
# attributes that are views of the buffers (rebuilt by _bind, never pickled)
_VIEWS = ("_q", "_qd", "_anchor", "_action", "_lam", "_terms", "_extra", "_action_row", "_out_row", "_flag_row", "_obs_row", "_kernel_args", "_force_row", "_kick_row",
          "_step_kernel", "_start_kernel")  # fmt: skip


class PlanarLegStanceEnv(gym.Env):
    r"""Balance a planar torso on one leg whose point foot is pinned to the ground.

    ## Description
    The robot of the lesson "Simple Legged Robot Dynamics": a floating torso (the base), a thigh
    hinged at the torso's centre of mass (hip) and a shank hinged to the thigh (knee), ending in a
    point foot in single support on level ground. Generalised coordinates
    ``q = [x_b, y_b, th_b, q1, q2]``: torso position and angle, hip angle (thigh relative to torso),
    knee angle (shank relative to thigh); angles are counter-clockwise, ``th_b = 0`` is a level torso.

    The physics is the exact stance model: the foot is a bilateral pin joint at its contact point
    and ``M qdd + h = S^T tau + Jc^T lam`` with ``Jc qdd + Jcdot qd = 0`` is solved analytically at
    every RK4 stage (``leg_env.dynamics``). The stance integrator (``leg_env.integrate``) integrates
    the independent coordinates ``(th_b, q1, q2)`` and places the base exactly on the contact, so the
    foot stays on its contact point to round-off (about 1e-15 m). Because the pin is bilateral the
    ground can pull as well as push: the contact force ``lam = [lam_x, lam_y]`` (the ground's force on
    the foot) is part of the observation, and the reward charges the agent for asking the ground for
    a force it could not give (``lam_y < 0``, or ``|lam_x| > mu lam_y``).

    The task is to stay near the nominal posture: a static equilibrium with the torso level, the knee
    bent by ``nominal_knee`` (0.8 rad) and the whole-body centre of mass above the foot, held by
    constant torques (about 0 N m at the hip and -24.1 N m at the knee with the default parameters;
    ``lam = [0, m g] = [0, 147.15] N``). The equilibrium is unstable: with zero torques the robot falls.

    **Unilateral contact** (``contact="unilateral"``). The ground is instead the line ``y = 0`` of
    the world, which can only push, with Coulomb friction (``mu`` = 0.5 by default, below the Painleve
    bound everywhere in the joint box): the foot sticks, slips, lifts off, flies and lands with a
    plastic impact, each transition located inside the control step (``leg_env.hybrid``; the modes,
    impact map and the Painleve and Zeno rules are documented there and in ``leg_env.contact``). The
    contact mode is part of the state; the observation and ``info`` describe it (below).

    **Time stepping.** One ``step`` is a control period ``dt`` = 0.01 s (100 Hz) with the torques held
    constant, integrated by at least ``substeps`` = 2 RK4 steps, more when the motion is fast so that no
    link or joint turns by more than ``max_angle`` = 0.02 rad per RK4 step (balancing never triggers
    this; a fall does). Convergence check (1 s from a slightly perturbed nominal state, default
    parameters, compared with 256 fixed RK4 steps per period): under smooth torques (nominal +
    sinusoids of 3 and 5 N m) the default state error is 7.3e-8 in ``q`` and 4.6e-7 in ``qd``, the
    contact force 3e-7 of the weight (4x finer steps: 3.2e-10 in ``q``, the 4th-order ratio ~256);
    under zero torques (a fall) 4.7e-8 in ``q``, 1.5e-7 in ``qd`` and 1e-5 of the weight. The
    discretisation error is far
    below anything a policy can notice.

    ## Action Space
    ``Box(-1, 1, (2,), float32)``, scaled by ``torque_limit`` (default 50 N m for both joints, twice the
    24.1 N m the knee needs to hold the nominal posture). Out-of-range actions are clipped to ``[-1, 1]``.
    A NaN or infinite action, one whose shape is not ``(2,)``, or one that is not real numbers (strings,
    complex numbers, bools: nothing is converted) raises ``ValueError`` and leaves the environment untouched.

    | Num | Action              | Min | Max | Unit                   |
    |-----|---------------------|-----|-----|------------------------|
    | 0   | hip torque `tau_hip`   | -1  | 1   | `torque_limit[0]` N m |
    | 1   | knee torque `tau_knee` | -1  | 1   | `torque_limit[1]` N m |

    ## Observation Space
    ``Box(low, high, (12,), float32)``. The base position is relative to the contact point and is
    bounded by the leg length ``L = l1 + l2`` (padded by 1%); the other entries have no finite bound
    that holds for every state the environment can reach (the torso and joints turn freely once the
    robot has fallen, if stepping goes on), so their bounds are infinite. Velocities never exceed
    ``max_rate``: a faster state is treated as a numerical failure. The contact force is the mean over
    the last control step (the contact impulse over ``dt``), divided by the weight ``m g``; after
    ``reset`` it is the instantaneous force under the nominal holding torques (exactly ``[0, 1]`` at the
    nominal posture). With ``g = 0`` there is no weight: entries 10-11 are then the force in newtons
    (divided by 1), and entry 17 is ``P_y / dt`` in newtons.

    | Num | Observation                                      | Min  | Max  | Unit  |
    |-----|--------------------------------------------------|------|------|-------|
    | 0   | base `x_b` relative to the contact point         | -1.01 L | 1.01 L | m  |
    | 1   | base `y_b` relative to the contact point         | -1.01 L | 1.01 L | m  |
    | 2   | torso angle `th_b`                               | -Inf | Inf  | rad   |
    | 3   | hip angle `q1`                                   | -Inf | Inf  | rad   |
    | 4   | knee angle `q2`                                  | -Inf | Inf  | rad   |
    | 5   | base velocity `x_b'`                             | -Inf | Inf  | m/s   |
    | 6   | base velocity `y_b'`                             | -Inf | Inf  | m/s   |
    | 7   | torso angular velocity `th_b'`                   | -Inf | Inf  | rad/s |
    | 8   | hip angular velocity `q1'`                       | -Inf | Inf  | rad/s |
    | 9   | knee angular velocity `q2'`                      | -Inf | Inf  | rad/s |
    | 10  | tangential contact force `lam_x / (m g)`         | -Inf | Inf  | 1 (N if g = 0) |
    | 11  | normal contact force `lam_y / (m g)`             | -Inf | Inf  | 1 (N if g = 0) |

    With ``contact="unilateral"`` the observation has 18 entries: entries 0-1 are the base position
    relative to the ground point below the foot (the stick contact point in stick), entry 1 (the base
    height) is unbounded, the force in 10-11 is the mean over the step without impact impulses, and:

    | Num | Observation (unilateral only)                    | Min  | Max  | Unit  |
    |-----|--------------------------------------------------|------|------|-------|
    | 12  | foot height `y_f`                                | -Inf | Inf  | m     |
    | 13  | foot velocity `x_f'`                             | -Inf | Inf  | m/s   |
    | 14  | foot velocity `y_f'`                             | -Inf | Inf  | m/s   |
    | 15  | in contact (1: stick or slip, 0: flight)         | 0    | 1    | 1     |
    | 16  | slip direction (+1, -1; 0 unless slipping)       | -1   | 1    | 1     |
    | 17  | impact impulse of the step `P_y / (m g dt)`      | -Inf | Inf  | 1     |

    ## Rewards
    ``reward = reward_alive + reward_drift + reward_unilateral + reward_friction + reward_ctrl``, each
    term in ``info`` under that name (they sum to the reward exactly, in this order):

    - ``reward_alive = alive_bonus`` on a healthy step (not terminated), else 0.
    - ``reward_drift = -(drift_position_weight |p_b - p_nom|^2 + drift_angle_weight th_b^2
      + drift_velocity_weight (x_b'^2 + y_b'^2 + th_b'^2))``, with ``p_b`` the base position relative to
      the contact point and ``p_nom`` its nominal value.
    - ``reward_unilateral = -unilateral_weight max(0, -lam_y) / (m g)``: the ground cannot pull.
    - ``reward_friction = -friction_weight max(0, |lam_x| - mu lam_y) / (m g)``: the force must lie in
      the friction cone.
    - ``reward_ctrl = -ctrl_cost_weight |a|^2`` with ``a`` the clipped action.

    With ``contact="unilateral"`` the ground cannot pull or leave the cone, so the two contact terms
    charge what asking for it does instead: ``reward_unilateral = -unilateral_weight flight_time / dt``
    (the share of the step spent off the ground) and ``reward_friction = -friction_weight
    slip_distance / dt`` (the mean slip speed over the step, m/s). ``info`` then also has
    ``leg_env.task.UNILATERAL_KEYS`` (``leg_env.task.unilateral_info`` documents them): ``contact_mode``
    (``"stick"``, ``"slip"``, ``"flight"`` at the end of the step), ``foot_height``, ``impulse``, the time in
    each mode, ``slip_distance``, ``work_actuators``, ``dissipation_slip``, ``dissipation_impacts``,
    ``energy`` and the counts ``contact_events``, ``painleve_fallbacks``, ``zeno_settles``;
    ``unilateral_violation`` / ``friction_violation`` can then only come from a Zeno settle or a
    Painleve jam.

    ``info`` also has ``contact_force`` (``lam`` [N], shape (2,)), ``normal_force`` (``lam_y`` [N]),
    ``unilateral_violation`` (``lam_y < 0``), ``friction_violation`` (``|lam_x| > mu lam_y``),
    ``numerical_failure``, ``base_drift`` (``|p_b - p_nom|`` [m]) and ``foot_error`` (the foot's
    distance from its contact point [m]). ``reset`` returns the same keys except the reward terms.

    ## Starting State
    The nominal posture plus uniform noise in ``[-reset_noise_scale, reset_noise_scale]`` on the torso,
    hip and knee angles [rad] and on their rates [rad/s]; ``reset_noise_scale = 0`` gives exactly the
    nominal state. The base position and velocity then follow from the contact: the foot is on the
    contact point, which is the world origin, and ``Jc qd = 0`` (the base velocity is replaced, the
    torso and joint rates are kept: a projection onto the nullspace of ``Jc``).

    ``reset(options={"qpos": q, "qvel": qd})`` starts from an explicit state instead (either key may be
    left out: ``qpos`` defaults to the nominal posture, ``qvel`` to zero; no noise is added). The contact
    point is where that foot is, and the base velocity is projected onto the contact as above. Shapes
    must be ``(5,)``, values real and finite, ``qpos`` entries within ``QPOS_BOUND`` (1e6 m or rad) and
    ``qvel`` entries within ``max_rate``, else ``ValueError`` naming the option.

    A rejected ``reset`` changes nothing: the seed, the options and (in ``human`` mode) the window are
    checked before the generator is seeded or the state is touched. Through ``gymnasium.make`` one thing
    is outside the env's reach: Gymnasium's ``TimeLimit`` wrapper zeroes its step counter before it
    calls the env's ``reset``, so a rejected reset still restarts that count (the vector env and the
    SB3 adapter keep their own counters and leave them untouched). With ``contact="unilateral"`` the state is
    taken in world coordinates and is not projected: a foot above the ground starts in flight, a foot
    within 1e-9 m of it is put on it in the consistent contact mode (one moving into it gets the impact
    map first), and a foot below it raises ``ValueError``; ``env.unwrapped.state`` is the world
    ``(q, qd, anchor)`` with ``anchor = (x, 0)`` the contact point (the foot's ``x`` when not sticking).

    ## Episode End
    ### Termination
    The episode terminates when the robot is unhealthy:

    1. it falls: the torso is less than ``min_base_height`` (0.5 m) above the contact point, or below
       the knee, or ``|th_b| > max_torso_angle`` (1 rad);
    2. a joint leaves its range: ``q1`` outside ``hip_range`` (-3, -0.9) rad or ``q2`` outside
       ``knee_range`` (0.05, 2.5) rad;
    3. if ``terminate_on_contact_loss``: ``lam_y < contact_loss_threshold`` (0 N), and with
       ``contact="unilateral"`` also any time in flight;
    4. a numerical failure: a non-finite state or force, a rate above ``max_rate``, or an observation
       that would overflow float32. The state is restored to the last good one, the observation is the
       last (finite) one, every reward term is 0 and ``info["numerical_failure"]`` is True.

    ### Truncation
    Only through the time limit: 1000 steps (10 s) when made with ``gymnasium.make``.

    ## Arguments
    ``gymnasium.make("leg_env/PlanarLegStance-v0", **kwargs)`` or ``PlanarLegStanceEnv(**kwargs)``.
    Every ``StanceConfig`` field is a keyword argument (it overrides ``config``). An unknown keyword
    raises ``TypeError`` ("got an unexpected keyword argument ...", as Python does); out-of-range values
    (NaN, ``10**400``, beyond the bounds of ``leg_env.task.FIELD_RANGES`` and ``leg_env.params.PARAM_RANGE``)
    raise ``ValueError`` naming the field and its range, as does a ``torque_limit`` that cannot hold the
    nominal posture or termination limits that the nominal posture itself violates. A value of the wrong
    type (``torque_limit="99"``, ``(True, 60)``, ``config=5``) raises ``leg_env.checks.ArgumentTypeError``,
    both a ``TypeError`` and a ``ValueError``. Every argument goes through ``leg_env.checks``.

    | Parameter                   | Type              | Default        | Description                                              |
    |-----------------------------|-------------------|----------------|----------------------------------------------------------|
    | `render_mode`               | str or None       | None           | `"rgb_array"` (headless frames) or `"human"` (a window, see below) |
    | `params`                    | LegParams or dict | lesson's       | masses, inertias, lengths, gravity                       |
    | `config`                    | StanceConfig or dict | defaults    | all task settings below at once                          |
    | `width`, `height`           | int               | 480, 480       | frame size in pixels                                     |
    | `dt`                        | float             | 0.01           | control period [s], at most 1; `metadata["render_fps"] = 1 / dt` |
    | `substeps`                  | int               | 2              | least RK4 steps per control period, 1 to 4096            |
    | `max_angle`                 | float             | 0.02           | largest link rotation per RK4 step [rad] (`inf`: fixed)  |
    | `torque_limit`              | float or pair     | (50, 50)       | torque at action 1 for hip, knee [N m]                   |
    | `nominal_knee`              | float             | 0.8            | knee angle of the nominal posture [rad]                  |
    | `alive_bonus`               | float             | 1.0            | reward per healthy step                                  |
    | `drift_position_weight`     | float             | 10.0           | per m^2 of base offset                                   |
    | `drift_angle_weight`        | float             | 1.0            | per rad^2 of torso angle                                 |
    | `drift_velocity_weight`     | float             | 0.1            | per (m/s)^2 + (rad/s)^2 of torso velocity                |
    | `unilateral_weight`         | float             | 10.0           | per weight of pulling force                              |
    | `friction_weight`           | float             | 10.0           | per weight of force outside the friction cone            |
    | `ctrl_cost_weight`          | float             | 0.01           | per unit of squared action                               |
    | `mu`                        | float or None     | None           | friction coefficient; None: 0.8 pinned (the cone check), 0.5 unilateral |
    | `contact`                   | str               | "pinned"       | `"pinned"` (bilateral pin) or `"unilateral"` (exact unilateral ground) |
    | `min_base_height`           | float             | 0.5            | fall: torso height above the contact point [m]           |
    | `max_torso_angle`           | float             | 1.0            | fall: torso tilt [rad]                                   |
    | `hip_range`, `knee_range`   | pair              | (-3, -0.9), (0.05, 2.5) | allowed joint angles [rad]                      |
    | `terminate_on_contact_loss` | bool              | False          | end the episode when `lam_y < contact_loss_threshold`    |
    | `contact_loss_threshold`    | float             | 0.0            | [N]                                                      |
    | `max_rate`                  | float             | 1000           | a faster state is a numerical failure [m/s, rad/s]       |
    | `reset_noise_scale`         | float             | 0.01           | half-width of the reset noise [rad, rad/s], at most pi   |

    ``render_mode="human"`` opens its window at the first ``reset`` or ``step``, before the state
    changes: a window that cannot open raises ``RuntimeError`` naming SDL's video driver, and the env
    is untouched. Without a display SDL falls back to an off-screen driver that shows nothing; a
    ``UserWarning`` says so (unless ``SDL_VIDEODRIVER`` asked for that driver).

    Pickling (and ``copy.deepcopy``) keeps every argument and the full state, random generator
    included, so a copy continues the same trajectory; an open window is not copied.

    ## Version History
    * v0: Initial release. The ``contact`` argument (default ``"pinned"``: the release's behaviour, bit
      for bit) adds the unilateral ground as an opt-in model.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 100}

    def __init__(
        self,
        render_mode: str | None = None,
        params: LegParams | dict | None = None,
        config: StanceConfig | dict | None = None,
        width: int = 480,
        height: int = 480,
        **config_overrides: Any,
    ):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.width, self.height = checks.integer("width", width, 1, MAX_PIXELS), checks.integer("height", height, 1, MAX_PIXELS)
        self.params = LegParams.from_any(params)
        self.config = StanceConfig.from_kwargs(config, **config_overrides)
        self.nominal = nominal_state(self.params, self.config)

        fps = 1.0 / self.config.dt
        fps = int(round(fps)) if abs(fps - round(fps)) < 1e-9 * fps else fps
        if fps != self.metadata["render_fps"]:
            self.metadata = {**type(self).metadata, "render_fps": fps}

        self.unilateral = self.config.contact == "unilateral"
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = observation_space(self.params, self.config)

        # the kernel's packed arrays (leg_env.task), one row, shared with nothing; _bind() makes the views
        self._consts = task_constants(self.params, self.config, self.nominal)
        self._state = np.zeros((1, STATE_DIM))  # q | qd | anchor | action | trig
        self._out = np.zeros((1, OUT_DIM))  # lam | reward terms | extras
        self._obs = np.zeros((1, self.observation_space.shape[0]), dtype=np.float32)
        self._flags = np.zeros((1, len(FLAG_NAMES)), dtype=np.bool_)
        self._bind()
        self._viewer = None

        # start at the nominal posture, so that it can be checked against the termination limits
        self._start(self.nominal.q, np.zeros(5), np.zeros(2))
        if self._flags[0, 0]:
            raise ValueError(
                "the nominal posture is already terminal under these limits "
                f"(q = {np.round(self.nominal.q, 3).tolist()}; check min_base_height, max_torso_angle, hip_range, knee_range, contact_loss_threshold)"
            )

    # ---------------------------------------------------------------- API

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        # every check first (seed, options, the window): a rejected reset changes nothing
        seed = checks.seed("seed", seed)
        start = self._explicit_state(options)
        if self.render_mode == "human":
            self._open_window()
        super().reset(seed=seed)
        if start is None:
            q, qd, anchor = reset_state(self.np_random, self.params, self.config, self.nominal)
        else:
            q, qd = start
            anchor = start_anchor(q, self.params, self.unilateral)
        self._start(q, qd, anchor)
        info = self._info(self._out_row.tolist(), self._flag_row.tolist())
        if self.render_mode == "human":
            self.render()
        return self._obs[0].copy(), info

    def step(self, action):
        a0, a1 = _checked_action(action)
        if self.render_mode == "human" and self._viewer is None:
            self._open_window()  # before the state changes
        self._action_row[0] = a0
        self._action_row[1] = a1
        self._step_kernel(*self._kernel_args)
        out, flags = self._out_row.tolist(), self._flag_row.tolist()  # one conversion each serves every key
        if self.unilateral:
            info = row_info(out, flags, self._force_row, self._kick_row, self._state[0, STATE_MODE])
        else:
            info = row_info(out, flags, self._force_row)
        if self.render_mode == "human":
            self.render()
        _, _, alive, drift, unilateral, friction, ctrl = out[:7]  # OUT_TERMS
        return self._obs_row.copy(), alive + drift + unilateral + friction + ctrl, flags[0], False, info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn(
                "You are calling render method without specifying any render mode. You can specify the render_mode "
                f'at initialization, e.g. gym.make("{self.spec.id if self.spec else "leg_env/PlanarLegStance-v0"}", render_mode="rgb_array")'
            )
            return None
        from .. import render

        violated = bool(self._flags[0, 1] or self._flags[0, 2])
        mode, impulse = contact_marks(self._state, self._out, 0, self.unilateral)
        if self.render_mode == "rgb_array":
            return render.draw(
                self._q[0], self._anchor[0], self._lam[0], self.params, violated, self.width, self.height, self.config.mu, mode, impulse
            )
        self._open_window()
        self._viewer.show(self._q[0], self._anchor[0], self._lam[0], self.params, violated, self.config.mu, mode, impulse)
        return None

    def _open_window(self) -> None:
        """Open the ``human`` window unless it is open (``leg_env.render.Viewer`` raises or warns)."""
        if self._viewer is None:
            from .. import render

            self._viewer = render.Viewer(self.width, self.height, self.metadata["render_fps"])

    def close(self):
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None

    # ---------------------------------------------------------- accessors

    @property
    def dt(self) -> float:
        """Control period [s]: the simulated time of one ``step``."""
        return self.config.dt

    @property
    def state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Copies of ``(q, qd, anchor)``: configuration, velocity and the foot's contact point."""
        return self._q[0].copy(), self._qd[0].copy(), self._anchor[0].copy()

    # ------------------------------------------------------------ helpers

    def _bind(self) -> None:
        """Named views of the packed buffers and the kernel's argument tuple (rebuilt after unpickling)."""
        state, out = self._state, self._out
        self._q, self._qd, self._anchor, self._action = state[:, STATE_Q], state[:, STATE_QD], state[:, STATE_ANCHOR], state[:, STATE_ACTION]
        self._lam, self._terms, self._extra = out[:, OUT_LAM], out[:, OUT_TERMS], out[:, OUT_EXTRA]
        self._action_row, self._out_row, self._flag_row, self._obs_row = self._action[0], out[0], self._flags[0], self._obs[0]
        self._force_row, self._kick_row = out[0, OUT_LAM], out[0, OUT_KICK]
        self._kernel_args = (state, self._consts, out, self._obs, self._flags)
        self._step_kernel = compiled_entry(step_batch, self._kernel_args)
        self._start_kernel = compiled_entry(start_batch, self._kernel_args)

    def _start(self, q, qd, anchor) -> None:
        """Put the robot at ``(q, qd)`` with its foot on ``anchor`` and evaluate it without stepping."""
        self._q[0] = q
        self._qd[0] = qd
        self._anchor[0] = anchor
        self._start_kernel(*self._kernel_args)

    def _info(self, out: list, flags: list) -> dict:
        """The state keys of ``info`` (no reward terms: a reset's) from the output row and the flags, as lists."""
        if self.unilateral:
            info = row_info(out, flags, self._force_row, self._kick_row, self._state[0, STATE_MODE])
        else:
            info = row_info(out, flags, self._force_row)
        for key in REWARD_INFO_KEYS:
            del info[key]
        return info

    def _explicit_state(self, options: dict | None) -> tuple[np.ndarray, np.ndarray] | None:
        """The checked ``(q, qd)`` of the ``qpos`` / ``qvel`` reset options, or None without them."""
        if options is None:
            return None
        if not isinstance(options, dict):
            raise checks.ArgumentTypeError(f"reset options must be a dict or None, got {checks.shown(options)}")
        unknown = set(options) - set(_RESET_OPTIONS)
        if unknown:
            raise ValueError(f"unknown reset option(s) {sorted(unknown)}; valid: {list(_RESET_OPTIONS)}")
        if not options:
            return None
        q, qd = explicit_start(options, self.nominal.q, self.config.max_rate)
        start_anchor(q, self.params, self.unilateral)  # raises for a foot below the unilateral ground
        return q, qd

    def __getstate__(self) -> dict:
        state = {k: v for k, v in self.__dict__.items() if k not in _VIEWS}
        state["_viewer"] = None  # a window does not travel
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._bind()


def explicit_start(options: dict, q_nominal: np.ndarray, max_rate: float, rows: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(q, qd)`` from the reset options ``qpos`` / ``qvel`` (defaults: the nominal posture, rest).

    With ``rows=None`` each must have shape ``(5,)``; with ``rows=k`` shape ``(5,)`` (for every row)
    or ``(k, 5)``, and the result has ``k`` rows. Entries must be real numbers, ``qpos`` within
    ``QPOS_BOUND`` (1e6 m or rad) and ``qvel`` within ``max_rate`` (a faster state is a numerical
    failure), else ``ValueError`` naming the option.
    """
    shapes = ((5,),) if rows is None else ((5,), (rows, 5))
    out = []
    for key, default, bound, unit in (("qpos", q_nominal, QPOS_BOUND, "m, rad"), ("qvel", np.zeros(5), max_rate, "m/s, rad/s (max_rate)")):
        value = checks.number_array(f"reset option {key!r}", options.get(key, default), bound, shapes, unit)
        out.append(value if rows is None else np.array(np.broadcast_to(value, (rows, 5))))
    return out[0], out[1]


def observation_space(params: LegParams, config: StanceConfig) -> spaces.Box:
    """The single env's observation space: 12 entries (pinned) or 18 (unilateral); see the docstring's table."""
    reach = 1.01 * (params.l1 + params.l2)
    unilateral = config.contact == "unilateral"
    high = np.full(OBS_DIM_UNILATERAL if unilateral else OBS_DIM, np.inf, dtype=np.float32)
    high[0] = reach
    if not unilateral:  # on the unilateral ground the base may fly: its height has no bound
        high[1] = reach
    else:
        high[15] = 1.0  # contact flag
        high[16] = 1.0  # slip direction
    low = -high
    if unilateral:
        low[15] = 0.0
    return spaces.Box(low, high, dtype=np.float32)


def contact_marks(state: np.ndarray, out: np.ndarray, i: int, unilateral: bool):
    """``(mode, impulse)`` of row ``i`` for the renderer: ``(None, None)`` in the pinned model."""
    if not unilateral:
        return None, None
    return int(state[i, STATE_MODE]), out[i, OUT_KICK]


def start_anchor(q: np.ndarray, params: LegParams, unilateral: bool) -> np.ndarray:
    """The contact point(s) of explicit start states ``q`` ``(..., 5)``.

    Pinned: wherever the foot is. Unilateral: the point of the ground ``y = 0`` below the foot; a foot
    below the ground by more than ``GROUND_TOL`` raises ``ValueError``.
    """
    foot = foot_position(q, params)
    if not unilateral:
        return foot
    low = foot[..., 1] < -GROUND_TOL
    if np.any(low):
        raise ValueError(
            f"reset option 'qpos' puts the foot below the ground (y_f = {float(foot[..., 1].min()):.3e} m); "
            f"on the unilateral ground the foot must be at y_f >= -{GROUND_TOL} m (on it within that) or above it"
        )
    anchor = foot.copy()
    anchor[..., 1] = 0.0
    return anchor


def _checked_action(action) -> tuple[float, float]:
    """The action as two Python floats; ``ValueError`` unless it is 2 finite real numbers of shape (2,).

    Strings, complex numbers and bools are refused (``ArgumentTypeError``, also a ``ValueError``),
    not converted.
    """
    if type(action) is np.ndarray and action.shape == (2,) and action.dtype.kind == "f":
        a0, a1 = action.tolist()  # the common case, without a conversion
        if math.isfinite(a0) and math.isfinite(a1):
            return a0, a1
    a = checks.number_array("action [hip, knee]", action, math.inf, ((2,),), entries=("hip", "knee"))
    return tuple(a.tolist())
