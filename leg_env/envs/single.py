"""The Gymnasium environment of one robot, generic over the task (``leg_env.tasks``)."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .. import checks
from ..dynamics import foot_position
from ..params import PARAM_NAMES, LegParams
from ..hybrid import GROUND_TOL
from .. import tasks
from .._core import kernels
from ..step import FLAG_NAMES, OUT_EXTRA, OUT_LAM, STATE_ACTION, STATE_ANCHOR, STATE_MODE, STATE_Q, STATE_QD
from ..step import C_MU, OUT_BASE
from ..randomize import Robots, params_of_row
from ..tasks.stance import OUT_KICK, StanceConfig, info_template, nominal_state, row_info, task_constants

__all__ = ["LegEnv"]

_RESET_OPTIONS = ("qpos", "qvel", "params")
QPOS_BOUND = 1.0e6
"""Largest magnitude of a reset ``qpos`` entry [m, rad]; ``qvel`` entries are bounded by ``max_rate``."""
MAX_PIXELS = 16384  # largest frame width or height
# attributes that are views of the buffers (rebuilt by _bind, never pickled)
_NO_NOISE = np.zeros((1, 6))  # the posture noise of a start without noise (not read)
_VIEWS = ("_q", "_qd", "_anchor", "_action", "_lam", "_terms", "_extra", "_action_row", "_out_row", "_flag_row", "_obs_row", "_kernel_args", "_force_row", "_kick_row",
          "_core", "_step_kernel", "_task_columns", "task", "_physics_args",
          "_tail_keys", "_template", "_reset_keys", "_reset_template", "_reset_columns", "_task_draws", "_out_info",
          "_human")  # fmt: skip


class LegEnv(gym.Env):
    """One robot of any leg-env task (``leg_env.tasks``): the Gymnasium env, generic over the task.

    ``task`` names the task module (``"stance"``, ``"push"``); its docstring documents spaces, rewards,
    termination and arguments. Everything here (argument checks, reset, step, info, rendering,
    pickling) is shared by every task: the task enters only through its ``leg_env.tasks.base.Task``.
    ``PlanarLegStanceEnv`` is this class for the balance task, with that task's documentation.
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
        self.config = self.task.config_cls.from_kwargs(config, **config_overrides)
        self.nominal = nominal_state(self.params, self.config)

        fps = 1.0 / self.config.dt
        fps = int(round(fps)) if abs(fps - round(fps)) < 1e-9 * fps else fps
        if fps != self.metadata["render_fps"]:
            self.metadata = {**type(self).metadata, "render_fps": fps}

        self.unilateral = self.config.contact == "unilateral"
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        # the kernel's packed arrays (leg_env.task), one row, shared with nothing; _bind() makes the views
        self._consts = task_constants(self.params, self.config, self.nominal)
        self.robots = Robots(randomize, self._consts[0], self.config)  # leg_env.randomize
        self.observation_space = self.task.observation_space(self.robots.longest(self.params), self.config)
        self._custom_robot = False  # whether the robot is not the nominal one
        self._state = np.zeros((1, self.task.state_dim))  # leg_env.step's layout, then the task's columns
        self._out = np.zeros((1, self.task.out_dim))  # leg_env.step's layout, then reward terms and task info
        self._obs = np.zeros((1, self.observation_space.shape[0]), dtype=np.float32)
        self._flags = np.zeros((1, len(FLAG_NAMES)), dtype=np.bool_)
        self._bind()
        self._viewer = None

        # start at the nominal posture, so that it can be checked against the termination limits
        self._start(self.nominal.q, np.zeros(5), np.zeros(2), self.task.task_columns(np.full((1, self.task.draws(self.config)), 0.5), self.config)[0])
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
        robot = None if not options or "params" not in options else self.robots.explicit_rows(options["params"])[0]
        if self.render_mode == "human":
            self._open_window()
        super().reset(seed=seed)
        rejected = None
        if robot is not None:  # the robot first: the nominal posture is the robot's
            self._consts[0] = robot
        elif self.robots.active:
            rejected = self.robots.draw_one(self.np_random, self._consts[0])
        elif self._custom_robot:
            self._consts[0] = self.robots.base
        self._custom_robot = robot is not None or self.robots.active
        posture = 6 if start is None and self.config.reset_noise_scale > 0.0 else 0  # uniforms of the posture noise
        k = posture + self._task_draws
        draws = self.np_random.random((1, k)) if k else np.empty((1, 0))  # rng.random(out=...)'s numbers
        columns = self.task.task_columns(draws[:, posture:], self.config)[0] if self._reset_columns else None
        if start is None:  # the posture noise, the contact and the task's evaluation in two compiled calls
            if columns is not None:
                self._task_columns[:] = columns
            self._core.start(draws[:, :posture] if posture else _NO_NOISE, self.config.reset_noise_scale)
        else:
            q, qd = start
            self._start(q, qd, start_anchor(q, self.robot_params, self.unilateral), columns)
        info = self._info(self._out_row.tolist(), self._flag_row.tolist())
        if self._custom_robot:
            info["params"] = params_of_row(self._consts[0])
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
        out, flags = self._out_row.tolist(), self._flag_row.tolist()  # one conversion each serves every key
        if self.unilateral:
            info = row_info(out, flags, self._force_row, self._template, self._kick_row)
        else:
            info = row_info(out, flags, self._force_row, self._template)
        info.update(zip(self._tail_keys, out[OUT_BASE:]))  # the reward terms, then the task's own info
        if self._human:
            self.render()
        return self._obs_row.copy(), reward, flags[0], False, info

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
        push = push_mark(self.task, self._out, 0)
        if self.render_mode == "rgb_array":
            return render.draw(
                self._q[0], self._anchor[0], self._lam[0], self.robot_params, violated, self.width, self.height, self._robot_mu(), mode, impulse,
                push,
            )  # fmt: skip
        self._open_window()
        self._viewer.show(self._q[0], self._anchor[0], self._lam[0], self.robot_params, violated, self._robot_mu(), mode, impulse, push)
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

    def _robot_mu(self) -> float:
        return robot_of_row(self._consts[0])[1]

    @property
    def robot_params(self) -> LegParams:
        """The ``LegParams`` of the robot being simulated: ``params`` unless randomised or set by a reset."""
        if not self._custom_robot:
            return self.params
        return robot_of_row(self._consts[0])[0]

    # ------------------------------------------------------------ helpers

    def _bind(self) -> None:
        """Named views of the packed buffers and the kernel's argument tuple (rebuilt after unpickling)."""
        state, out = self._state, self._out
        self.task = tasks.get(self.task_name)
        self._q, self._qd, self._anchor, self._action = state[:, STATE_Q], state[:, STATE_QD], state[:, STATE_ANCHOR], state[:, STATE_ACTION]
        self._lam, self._terms, self._extra = out[:, OUT_LAM], out[:, self.task.out_terms], out[:, OUT_EXTRA]
        self._action_row, self._out_row, self._flag_row, self._obs_row = self._action[0], out[0], self._flags[0], self._obs[0]
        self._force_row, self._kick_row = out[0, OUT_LAM], out[0, OUT_KICK]
        self._kernel_args = (state, self._consts, out, self._obs, self._flags)
        self._physics_args = (state, self._consts, out, self._flags)
        self._core = kernels.Batch(self.task.kernel, state, self._consts, out, self._obs, self._flags)  # the arrays, held by C
        self._step_kernel = self._core.step_one
        self._tail_keys = self.task.reward_keys + self.task.info_names  # the columns out[OUT_BASE:]
        self._template = info_template(self.unilateral, self._tail_keys)
        self._reset_keys = self.task.info_names  # a reset's info has no reward terms: the columns after them
        self._out_info = self.task.out_info
        self._reset_template = info_template(self.unilateral, self._reset_keys)
        self._reset_columns = bool(self.task.state_names)
        self._task_draws = self.task.draws(self.config)
        self._human = self.render_mode == "human"
        self._task_columns = state[0, len(state[0]) - len(self.task.state_names):] if self.task.state_names else None

    def _start(self, q, qd, anchor, columns) -> None:
        """Put the robot at ``(q, qd)`` with its foot on ``anchor`` and the task's state ``columns``, and
        evaluate it without stepping."""
        self._q[0] = q
        self._qd[0] = qd
        self._anchor[0] = anchor
        if self._task_columns is not None:
            self._task_columns[:] = columns
        self._core.start(None, 0.0)

    def _info(self, out: list, flags: list) -> dict:
        """``info`` of a reset (no reward terms) from the output row and the flags, as lists."""
        if self.unilateral:
            info = row_info(out, flags, self._force_row, self._reset_template, self._kick_row)
        else:
            info = row_info(out, flags, self._force_row, self._reset_template)
        info.update(zip(self._reset_keys, out[self._out_info]))
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


def robot_of_row(row: np.ndarray) -> tuple[LegParams, float]:
    """The ``LegParams`` and friction coefficient of the robot whose ``consts`` row is ``row``."""
    return LegParams(**{name: float(v) for name, v in zip(PARAM_NAMES, row[:len(PARAM_NAMES)])}), float(row[len(PARAM_NAMES) + C_MU])


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


def contact_marks(state: np.ndarray, out: np.ndarray, i: int, unilateral: bool):
    """``(mode, impulse)`` of row ``i`` for the renderer: ``(None, None)`` in the pinned model."""
    if not unilateral:
        return None, None
    return int(state[i, STATE_MODE]), out[i, OUT_KICK]


def push_mark(task, out: np.ndarray, i: int) -> float:
    """The push on robot ``i``'s torso over its last step [N] for the renderer (the task's ``push_force``
    info column), 0 for a task without pushes."""
    if "push_force" not in task.info_names:
        return 0.0
    return float(out[i, task.out_info.start + task.info_names.index("push_force")])


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
