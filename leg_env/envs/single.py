"""The Gymnasium environment of one robot, generic over the task (``leg_env.tasks``)."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .. import checks
from ..physics.dynamics import foot_position
from ..physics.hybrid import GROUND_TOL
from ..physics.params import PARAM_NAMES, LegParams
from .. import tasks
from .._core import kernels
from ..info import InfoBuilder
from ..randomize import Robots, params_of_row, posture_limits
from ..tasks.base import StanceConfig, nominal_state, robot_row

__all__ = ["LegEnv"]

_RESET_OPTIONS = ("qpos", "qvel", "params")
QPOS_BOUND = 1.0e6
"""Largest magnitude of a reset ``qpos`` entry [m, rad]; ``qvel`` entries are bounded by ``max_rate``."""
MAX_PIXELS = 16384  # largest frame width or height
# attributes that are views of the buffers (rebuilt by _bind, never pickled)
_NO_NOISE = np.zeros((1, 6))  # the posture noise of a start without noise (not read)
_VIEWS = ("_q", "_qd", "_anchor", "_out_row", "_state_row", "_obs_row", "_core", "_step_kernel", "task", "_info",
          "_task_draws", "_human")  # fmt: skip


class LegEnv(gym.Env):
    """One robot of any leg-env task (``leg_env.tasks``): the Gymnasium env, generic over the task.

    ``task`` names the task module (``"stance"``, ``"push"``); its docstring documents spaces, rewards,
    termination and arguments. Everything here (argument checks, reset, step, info, rendering,
    pickling) is shared by every task: the task enters only through its ``leg_env.tasks.base.Task``.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 100}

    def __init__(
        self,
        render_mode: str | None = None,
        params: LegParams | dict | None = None,
        config: StanceConfig | dict | None = None,
        width: int = 480,
        height: int = 480,
        task: str = "stance",
        randomize: Any = None,
        **config_overrides: Any,
    ):
        self.task_name = task
        self.task = tasks.get(task)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.width, self.height = checks.integer("width", width, 1, MAX_PIXELS), checks.integer("height", height, 1, MAX_PIXELS)
        self.params = LegParams.from_any(params)
        if self.task.needs_gravity and self.params.g == 0.0:
            raise ValueError(f"params.g must be positive for the {task} task (its apex is where gravity stops the rise), got 0.0")
        self.config = self.task.config_cls.from_kwargs(config, **config_overrides)
        self.nominal = nominal_state(self.params, self.config)

        fps = 1.0 / self.config.dt
        fps = int(round(fps)) if abs(fps - round(fps)) < 1e-9 * fps else fps
        if fps != self.metadata["render_fps"]:
            self.metadata = {**type(self).metadata, "render_fps": fps}

        self.unilateral = self.config.contact == "unilateral"
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        # the compiled core's arrays (leg_env.physics.layout), one row, shared with nothing; _bind() hands them to C
        self._robots = robot_row(self.params, self.config, self.nominal)
        self.robots = Robots(randomize, self._robots, self.config, gravity=self.task.needs_gravity)  # leg_env.randomize
        self.observation_space = self.task.space(self.robots.longest(self.params), self.config)
        self._custom_robot = False  # whether the robot is not the nominal one
        self._settings = self.config.settings(self.task.name)
        self._state = np.zeros(1, dtype=self.task.state_dtype)
        self._out = np.zeros(1, dtype=self.task.out_dtype)
        self._obs = np.zeros((1, self.observation_space.shape[0]), dtype=np.float32)
        self._bind()
        self._viewer = None

        # start at the nominal posture, so that it can be checked against the termination limits
        self._start(self.nominal.q, np.zeros(5), np.zeros(2), self.task.task_columns(np.full((1, self.task.draws(self.config)), 0.5), self.config))
        if self._out["terminated"][0]:
            raise ValueError(
                "the nominal posture is already terminal under these limits "
                f"(q = {np.round(self.nominal.q, 3).tolist()}; check min_base_height, max_torso_angle, hip_range, knee_range, contact_loss_threshold)"
            )

    # ---------------------------------------------------------------- API

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        # every check first (seed, options, the window): a rejected reset changes nothing
        seed = checks.seed("seed", seed)
        start = self._explicit_state(options)
        robot = None if not options or "params" not in options else self.robots.explicit_rows(options["params"])[0]
        if self.render_mode == "human":
            self._open_window()
        super().reset(seed=seed)
        rejected = None
        if robot is not None:  # the robot first: the nominal posture is the robot's
            self._robots[0] = robot
        elif self.robots.active:
            rejected = self.robots.draw_one(self.np_random, self._robots)
        elif self._custom_robot:
            self._robots[0] = self.robots.base[0]
        self._custom_robot = robot is not None or self.robots.active
        posture = 6 if start is None and self.config.reset_noise_scale > 0.0 else 0  # uniforms of the posture noise
        k = posture + self._task_draws
        draws = self.np_random.random((1, k)) if k else np.empty((1, 0))  # rng.random(out=...)'s numbers
        for field, values in self.task.task_columns(draws[:, posture:], self.config).items():
            self._state[field] = values
        if start is None:  # the posture noise, the contact and the task's evaluation in one compiled call
            self._core.start(draws[:, :posture] if posture else _NO_NOISE, self.config.reset_noise_scale)
        else:
            q, qd = start
            self._start(q, qd, start_anchor(q, self.robot_params, self.unilateral), {})
        info = self._info(rewards=False)
        if self._custom_robot:
            info["params"] = params_of_row(self._robots[0])
            if rejected is not None:
                info["params_rejected"] = rejected
        if self.render_mode == "human":
            self.render()
        return self._obs[0].copy(), info

    def step(self, action):
        if type(action) is np.ndarray and action.shape == (2,) and action.dtype.kind == "f":
            a0, a1 = action.tolist()  # the common case, checked here without a call
            if not (math.isfinite(a0) and math.isfinite(a1)):
                a0, a1 = _checked_action(action)  # raises, naming the entry
        else:
            a0, a1 = _checked_action(action)
        if self._human and self._viewer is None:
            self._open_window()  # before the state changes
        reward = self._step_kernel(a0, a1)  # the action, physics, the task in one call; the terms summed
        info = self._info()
        if self._human:
            self.render()
        return self._obs_row.copy(), reward, info["ending"] != 0, False, info  # terminated is exactly an ending

    def render(self):
        if self.render_mode is None:
            gym.logger.warn(
                "You are calling render method without specifying any render mode. You can specify the render_mode "
                f'at initialization, e.g. gym.make("{self.spec.id if self.spec else "leg_env/PlanarLegStance-v0"}", render_mode="rgb_array")'
            )
            return None
        from .. import render

        violated, mode, impulse, push = render_marks(self._out, 0, self.unilateral)
        lam = self._out["lam"][0]
        if self.render_mode == "rgb_array":
            return render.draw(
                self._q[0], self._anchor[0], lam, self.robot_params, violated, self.width, self.height, self._robot_mu(), mode, impulse, push,
            )  # fmt: skip
        self._open_window()
        self._viewer.show(self._q[0], self._anchor[0], lam, self.robot_params, violated, self._robot_mu(), mode, impulse, push)
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

    def set_config(self, **changes: Any) -> None:
        """Change task settings of the running env: a curriculum's handle.

        ``changes`` are config fields (``alive_bonus=3.0``, ``command_range=(0.02, 0.06)``), checked as at
        construction. Reward weights, termination limits and the step rule hold from the next ``step``; what a
        start draws (the reset noise, a command, pushes) from the next ``reset``. The robot, its nominal posture
        and the posture limits it is drawn under, the contact model, the control period and the observation
        space stay as built: a change that would move any of them raises ``ValueError`` naming the fields and
        changes nothing (an observation space may narrow, e.g. a command range within the built one, and
        stays the built one). An unknown field raises ``TypeError``.
        """
        self.config, settings = checked_config_change(self, self.observation_space, changes)
        self._settings[...] = settings  # in place: the compiled core holds this array
        self._task_draws = self.task.draws(self.config)

    # ---------------------------------------------------------- accessors

    @property
    def dt(self) -> float:
        """Control period [s]: the simulated time of one ``step``."""
        return self.config.dt

    @property
    def state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Copies of ``(q, qd, anchor)``: configuration, velocity and the foot's contact point."""
        return self._q[0].copy(), self._qd[0].copy(), self._anchor[0].copy()

    @property
    def contact_mode(self) -> int:
        """The contact mode now, as ``leg_env.physics.hybrid.hybrid_step`` takes it: ``leg_env.physics.contact``'s
        ``STICK``, ``SLIP_FORWARD``, ``SLIP_BACKWARD`` or ``FLIGHT`` (the pinned foot: ``STICK``)."""
        return int(self._state["mode"][0])

    def _robot_mu(self) -> float:
        return float(self._robots["mu"][0])

    @property
    def robot_params(self) -> LegParams:
        """The ``LegParams`` of the robot being simulated: ``params`` unless randomised or set by a reset."""
        if not self._custom_robot:
            return self.params
        return robot_of_row(self._robots[0])[0]

    # ------------------------------------------------------------ helpers

    def _bind(self) -> None:
        """The arrays handed to C (``kernels.Batch``) and named views of them (rebuilt after unpickling)."""
        state = self._state
        self.task = tasks.get(self.task_name)
        self._q, self._qd, self._anchor = state["q"], state["qd"], state["anchor"]
        self._out_row, self._state_row, self._obs_row = self._out[0], state[0], self._obs[0]
        self._core = kernels.Batch(self.task.kernel, state, self._robots, self._settings, self._out, self._obs)  # held by C
        self._step_kernel = self._core.step_one
        self._info = InfoBuilder(self.task, self.unilateral).reader(self._core, self._out, state)
        self._task_draws = self.task.draws(self.config)
        self._human = self.render_mode == "human"

    def _start(self, q, qd, anchor, columns: dict) -> None:
        """Put the robot at ``(q, qd)`` with its foot on ``anchor`` and the task's state ``columns``, and
        evaluate it without stepping."""
        self._q[0] = q
        self._qd[0] = qd
        self._anchor[0] = anchor
        for field, values in columns.items():
            self._state[field] = values
        self._core.start(None, 0.0)

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
        if not set(options) & {"qpos", "qvel"}:
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


def checked_config_change(env, observation_space: spaces.Box, changes: dict):
    """``env``'s config with ``changes`` and its settings row, for ``set_config`` of the single and the vector env.

    Every check of a new env runs on the changed config (a scratch ``LegEnv`` is built from it); then what must
    stay as built is compared: the robot row, the posture limits of drawn robots, the contact model, the control
    period, and the observation space (which may narrow). Raises ``TypeError`` for an unknown field and
    ``ValueError`` naming the changed fields otherwise; nothing is changed by this function.
    """
    config = env.config
    new = type(config).from_kwargs(config, **changes)
    changed = [name for name in changes if getattr(new, name) != getattr(config, name)]
    named = ", ".join(changed) or "nothing"
    scratch = LegEnv(params=env.params, config=new, task=env.task_name)  # the checks of a new env
    moved = []
    if new.contact != config.contact:
        moved.append("the contact model")
    if new.dt != config.dt:
        moved.append("the control period")
    if robot_row(env.params, new, scratch.nominal).tobytes() != robot_row(env.params, config, env.nominal).tobytes():
        moved.append("the robot (its friction, torque limits or nominal posture)")
    if not np.array_equal(posture_limits(new), posture_limits(config)):
        moved.append("the posture limits robots are drawn under")
    space = env.task.space(env.robots.longest(env.params), new)
    if space.shape != observation_space.shape:
        moved.append(f"the observation's shape ({observation_space.shape} to {space.shape})")
    else:
        wider = np.flatnonzero((space.low < observation_space.low) | (space.high > observation_space.high))
        if wider.size:
            moved.append(f"the observation space: entries {wider.tolist()} would widen beyond the built bounds (they may only narrow)")
    if moved:
        raise ValueError(f"set_config({named}) would change {'; '.join(moved)}: make a new env for that")
    return new, scratch._settings


def robot_of_row(row) -> tuple[LegParams, float]:
    """The ``LegParams`` and friction coefficient of a robot (a row of ``leg_env.physics.layout.ROBOT``)."""
    return LegParams(**dict(zip(PARAM_NAMES, row["p"].item()))), float(row["mu"])


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


def render_marks(out: np.ndarray, i: int, unilateral: bool):
    """What the renderer marks for robot ``i`` from its ``out`` row: ``(violated, mode, impulse, push)``: whether
    its force broke the ground's limits, its contact mode and impact impulse (None on the pinned foot) and the
    push on its torso over the last step [N] (0 for a task without pushes)."""
    o = out[i]
    violated = bool(o["unilateral_violation"] or o["friction_violation"])
    push = float(o["push_force"]) if "push_force" in out.dtype.names else 0.0
    if not unilateral:
        return violated, None, None, push
    return violated, int(o["mode"]), o["kick"].copy(), push


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
