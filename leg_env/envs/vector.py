"""Every task as a natively batched ``gymnasium.vector.VectorEnv``.

``gymnasium.make_vec(id, num_envs=N)`` builds this class (it is every id's ``vector_entry_point``). One call
of the compiled core advances all N robots (``Task.step``: the control step and the task's ``assess``, block by
block), the same kernels the single
environment calls with N = 1, and resets build their
start states with the same task ``start`` kernel (the noise, and with ``randomize`` the robot, drawn in
compiled code from each sub-env's own generator, ``BitGeneratorRows``, the same numbers as ``rng.random``):
sub-env ``i`` of a batch reset with
``seed=s`` is exactly a ``LegEnv`` reset with ``seed=s + i`` under ``TimeLimit``, step for
step and across autoresets. Observations, rewards, terminations, truncations and ``info`` (keys,
values and ``_key`` masks) equal, bit for bit, those of ``gymnasium.vector.SyncVectorEnv`` over N
single environments in the same autoreset mode, with one deliberate difference: on a step where
every sub-env resets, the reward-term keys are still there (masks all False) where SyncVectorEnv
drops them, so ``info["reward_alive"]`` never raises ``KeyError``.
"""

from __future__ import annotations

import numbers
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any, NamedTuple

import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .. import checks
from .._core import kernels
from ..physics.params import LegParams
from .. import tasks
from ..info import InfoBuilder
from ..physics.layout import put_rows, take_rows
from ..randomize import FIELD_COLUMNS, FIELDS
from .generators import BitGeneratorRows
from ..tasks.base import StanceConfig
from .single import LegEnv, checked_config_change, explicit_start, render_marks, robot_of_row, start_anchor

__all__ = ["LegVectorEnv"]

_RESET_OPTIONS = ("qpos", "qvel", "reset_mask", "params")
MAX_ENVS = kernels.MAX_ROWS  # bound of num_envs and render_envs: the most rows of the compiled core's tables, 2^26
MAX_THREADS = 256  # bound of num_threads
_VIEWS = ("_q", "_qd", "_anchor", "_action", "task", "_info_builder")  # rebuilt by _bind, never pickled
_UNPICKLED = _VIEWS + ("_pool", "_busy")  # the thread pool is made anew where it is used, the lock at unpickling


class LegVectorEnv(VectorEnv):
    r"""N independent copies of ``LegEnv`` (any task; ``task`` names it), stepped by batched kernel calls.

    Everything about a sub-environment (dynamics, observation, reward terms, termination, ``info``,
    constructor arguments, spaces) is documented in its task's module (``leg_env.tasks.<task>``) and
    is computed by the same code; this class adds batching, the time limit and autoreset.

    ## Spaces
    ``single_observation_space`` and ``single_action_space`` are the single environment's
    (``Box(-1, 1, (2,))`` actions, 12 observations); ``observation_space`` and ``action_space`` are
    those batched to ``(num_envs, 12)`` and ``(num_envs, 2)``.

    ## Step
    ``step(actions)`` takes ``(num_envs, 2)`` actions (clipped to ``[-1, 1]``) and returns
    ``(obs, reward, terminated, truncated, info)`` with shapes ``(num_envs, 12)`` float32,
    ``(num_envs,)`` float64, bool and bool. A NaN or infinite action, a wrong shape, or actions that are
    not real numbers raise ``ValueError`` naming the sub-envs, and leave every sub-env untouched.
    Stepping before the first ``reset`` (or while a ``reset_mask`` reset has left some sub-env never
    reset) raises ``gymnasium.error.ResetNeeded`` before anything changes.

    ``info`` is Gymnasium's vector form: one array per key over the sub-envs, and a boolean mask
    ``info["_key"]`` telling which sub-envs report it. The keys are the single env's:
    ``reward_alive, reward_drift, reward_unilateral, reward_friction, reward_ctrl`` (summing to the
    reward), ``contact_force`` ``(num_envs, 2)``, ``normal_force``, ``unilateral_violation``,
    ``friction_violation``, ``numerical_failure``, ``ending`` (int), ``base_drift``, ``foot_error``.

    ## Episode end and autoreset
    ``terminated`` is the single env's termination. ``truncated`` is the time limit: a sub-env's
    ``max_episode_steps``-th step since its reset (``gymnasium.make_vec`` passes the registered 1000;
    ``None`` disables it). A sub-env that ended restarts with fresh noise from its own random
    generator, by ``autoreset_mode`` (also in ``metadata["autoreset_mode"]``):

    - ``NEXT_STEP`` (default, Gymnasium's): the step after the end resets it instead of stepping it
      (its action is ignored); that step returns its reset observation, reward 0, ``terminated`` and
      ``truncated`` False, and the reset ``info`` (no reward terms, whose masks are False).
    - ``SAME_STEP``: the ending step resets it at once and returns the reset observation;
      ``info["final_obs"]`` (object array, ``None`` elsewhere) and ``info["final_info"]`` hold the
      last observation and the step ``info`` of the sub-envs that ended (masks ``_final_obs``,
      ``_final_info``); the top-level ``info`` of those sub-envs is their reset ``info``.
      The Stable-Baselines3 adapter ``leg_env.sb3`` uses this mode.
    - ``DISABLED``: no autoreset; reset ended sub-envs with
      ``reset(options={"reset_mask": mask})`` before stepping them again (else ``ValueError``).

    ## Reset
    ``reset(seed=s)`` seeds sub-env ``i`` with ``s + i`` (``seed`` may also be a list of ``num_envs``
    ints or ``None``); ``seed=None`` continues each sub-env's generator (fresh entropy the first
    time), as ``SyncVectorEnv`` does. ``options``: ``reset_mask`` (``(num_envs,)`` bool) resets only
    those sub-envs; ``qpos`` / ``qvel`` give explicit states, ``(5,)`` for all reset sub-envs or one
    row per reset sub-env (semantics and bounds of the single env's options); ``params`` (``{field:
    value}``, each a number or one per reset sub-env) runs the given robots for their next episode. A
    rejected reset (a bad seed such as ``1.5``, a bad option, an infeasible robot) raises before anything
    changes: generators, states and the time limit's counters stay as they were.

    ## Domain randomisation
    ``randomize`` (None, True or a dict of ranges; ``leg_env.randomize`` and the single env's docstring):
    every reset, including autoresets, draws each reset sub-env's robot from its own generator before its
    posture noise, exactly as a single env does, and the kernels read a row of parameters per sub-env. The
    reset ``info`` (and a step's ``info`` for the sub-envs it autoreset) has ``params``, a dict of ``(num_envs,)``
    arrays with masks, as ``SyncVectorEnv`` gathers the single envs' dicts, and ``params_rejected``.

    ## Rendering
    ``render_mode="rgb_array"``: ``render()`` returns a tuple of ``(height, width, 3)`` uint8 frames,
    one per sub-env, as Gymnasium's vector wrappers (``RecordVideo``, ``HumanRendering``) expect;
    ``render_envs=k`` draws only the first ``k`` (cheaper for a large batch, but those wrappers then
    refuse the frames). ``metadata["render_fps"]`` is the real rate, ``1 / dt``.

    ## Arguments
    ``num_envs`` (int >= 1), ``max_episode_steps`` (int >= 1 or None, default 1000),
    ``autoreset_mode`` (``AutoresetMode`` or its value string, default ``NEXT_STEP``),
    ``render_envs`` (frames per ``render()``, default None: every sub-env), ``num_threads`` (default 1: one thread, the
    right choice next to a training process; ``1 <= k <= 256`` splits the batch into ``k`` contiguous
    chunks whose physics is stepped by ``k`` Python threads, the compiled kernel releasing the GIL: bitwise the same
    results; fork-safe, since no OpenMP runtime is involved) and every argument of the single env:
    ``render_mode`` (None or ``"rgb_array"``), ``params``, ``config``, ``width``, ``height``, ``randomize`` and the
    ``StanceConfig`` fields as keywords. Pickling keeps every argument and the full state.

    ## Version History
    * v0: Initial release.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 100, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        render_mode: str | None = None,
        params: LegParams | dict | None = None,
        config: StanceConfig | dict | None = None,
        max_episode_steps: int | None = 1000,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        width: int = 480,
        height: int = 480,
        render_envs: int | None = None,
        num_threads: int = 1,
        task: str = "stance",
        randomize: Any = None,
        **config_overrides: Any,
    ):
        num_envs = checks.integer("num_envs", num_envs, 1, MAX_ENVS)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        if max_episode_steps is not None:
            max_episode_steps = checks.integer("max_episode_steps", max_episode_steps, 1, np.iinfo(np.int64).max)
        try:
            autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError as e:
            raise ValueError(f"autoreset_mode must be one of {[m.value for m in AutoresetMode]}, got {autoreset_mode!r}") from e
        if render_envs is not None:
            render_envs = checks.integer("render_envs", render_envs, 1, MAX_ENVS)
        num_threads = checks.integer("num_threads", num_threads, 1, MAX_THREADS)

        # The single env checks the arguments and defines the spaces; the batch reuses both.
        single = LegEnv(params=params, config=config, width=width, height=height, task=task, randomize=randomize, **config_overrides)
        self.robots = single.robots  # leg_env.randomize: the nominal robot, and the ranges of drawn ones
        self.task_name = single.task_name
        self.task = single.task
        self.reward_keys = self.task.reward_keys
        self.num_envs = n = int(num_envs)
        self.render_mode = render_mode
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        self.autoreset_mode = autoreset_mode
        self.render_envs = None if render_envs is None else int(render_envs)
        self.num_threads = int(num_threads)
        self._pool: tuple[int, ThreadPoolExecutor] | None = None  # (pid, pool), made at the first threaded step
        self.width, self.height = single.width, single.height
        self.unilateral = single.unilateral
        self._info_builder = InfoBuilder(self.task, self.unilateral)
        self.state_keys = self._info_builder.keys
        self.params, self.config, self.nominal = single.params, single.config, single.nominal
        self.metadata = {**type(self).metadata, "render_fps": single.metadata["render_fps"], "autoreset_mode": autoreset_mode}
        self.single_observation_space = single.observation_space
        self.single_action_space = single.action_space
        self.observation_space = batch_space(self.single_observation_space, n)
        self.action_space = batch_space(self.single_action_space, n)

        # the compiled core's arrays (leg_env.physics.layout), row i is sub-env i; _bind() makes the views
        # one robot for every row, or a row per robot when robots are drawn or set by a reset
        self._robots = np.repeat(self.robots.base, n if self.robots.active else 1)
        self._custom = np.zeros(n, dtype=np.bool_)  # rows whose robot is not the nominal one
        self._settings = single._settings
        self._state = np.zeros(n, dtype=self.task.state_dtype)
        self._out = np.zeros(n, dtype=self.task.out_dtype)
        self._obs = np.zeros((n, self.single_observation_space.shape[0]), dtype=np.float32)
        self._bind()
        nominal_columns = self.task.task_columns(np.full((n, self.task.draws(self.config)), 0.5), self.config)
        self._start(None, (self.nominal.q, np.zeros(5), np.zeros(2)), None, nominal_columns)  # every row at the nominal posture
        self._elapsed = np.zeros(n, dtype=np.int64)
        self._ended = np.zeros(n, dtype=np.bool_)  # ended on the last step and not reset since
        self._rngs = BitGeneratorRows(n)  # sub-env i's generator, drawn from in compiled code
        self._rng_seeds: list[int | None] = [None] * n  # the seed each generator was made from
        self._never_reset = np.ones(n, dtype=np.bool_)  # step() refuses to run while a sub-env was never reset
        self._busy = threading.Lock()  # held by the step or reset under way: one caller at a time

    # ---------------------------------------------------------------- API

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        """Reset all sub-envs (or those in ``options["reset_mask"]``); see the class docstring."""
        if not self._busy.acquire(blocking=False):
            raise self._concurrent("reset")
        try:
            return self._reset(seed, options)
        finally:
            self._busy.release()

    def _concurrent(self, what: str) -> RuntimeError:
        """A second thread's step or reset while one is under way (they would interleave their rows)."""
        return RuntimeError(f"{type(self).__name__}.{what}: another thread is stepping or resetting this env; step a vector env from "
                            "one thread at a time (num_threads splits each step over threads)")

    def _reset(self, seed, options):
        n = self.num_envs
        if options is not None and not isinstance(options, dict):
            raise checks.ArgumentTypeError(f"reset options must be a dict or None, got {checks.shown(options)}")
        options = dict(options or {})
        unknown = set(options) - set(_RESET_OPTIONS)
        if unknown:
            raise ValueError(f"unknown reset option(s) {sorted(unknown)}; valid: {list(_RESET_OPTIONS)}")
        rows = self._reset_rows(options.pop("reset_mask", None))
        seeds = self._seeds(seed)
        robots = self.robots.explicit_rows(options.pop("params"), len(rows)) if "params" in options else None
        explicit = self._explicit_states(options, len(rows)) if options else None
        # every check is done: from here on nothing raises
        if isinstance(seed, (int, np.integer)):
            super().reset(seed=int(seed))
        for i in rows.tolist():
            if seeds[i] is not None or self._rngs[i] is None:
                self._rngs[i], self._rng_seeds[i] = seeding.np_random(seeds[i])
        rejected = self._set_robots(rows, robots)
        starts = self._draw_starts(rows, explicit)
        self._start(None if rows.size == n else rows, *starts)
        self._elapsed[rows] = 0
        self._ended[rows] = False
        self._never_reset[rows] = False  # a reset_mask may leave some never reset
        info = {}
        if rows.size == n:
            self._add_state_info(info, self._out, self._state)
        else:
            self._add_state_info(info, self._out[rows], self._state[rows], rows)
        self._add_params_info(info, rows, rejected)
        return self._obs.copy(), info

    def step(self, actions):
        """Step every sub-env (autoresetting those that ended); see the class docstring."""
        if not self._busy.acquire(blocking=False):
            raise self._concurrent("step")
        try:
            t = self._step(actions)
        finally:
            self._busy.release()
        stepped = None
        if t.restarted is not None:
            stepped = np.ones(self.num_envs, dtype=np.bool_)
            stepped[t.restarted] = False
        info = {}
        self._add_reward_info(info, stepped, t.terms)
        self._add_state_info(info, self._out, self._state)
        if t.restarted is not None:  # their reset's robot, as SyncVectorEnv passes a reset's info on
            self._add_params_info(info, t.restarted, t.rejected)
        if t.final is not None:  # SAME_STEP: the ended rows report their reset, their last step goes to final_*
            ended = np.logical_not(stepped)
            final_obs = np.full(self.num_envs, None, dtype=object)
            for k, i in enumerate(t.restarted.tolist()):
                final_obs[i] = t.final.obs[k]
            final_info = {}
            self._add_reward_info(final_info, ended, t.terms)
            self._add_state_info(final_info, t.final.out, t.final.state, t.restarted)
            info["final_obs"] = final_obs
            info["_final_obs"] = ended
            info["final_info"] = final_info
            info["_final_info"] = ended.copy()
        return t.obs, t.reward, t.terminated, t.truncated, info

    def close_extras(self, **kwargs: Any) -> None:
        """Stop the threads of ``num_threads > 1`` (a later step makes new ones)."""
        pool = getattr(self, "_pool", None)  # None too when __init__ refused its arguments
        if pool is not None and pool[0] == os.getpid():
            pool[1].shutdown(wait=True)
        self._pool = None

    def render(self):
        """One frame per sub-env, or of the first ``render_envs`` (``rgb_array`` mode); else None with a warning."""
        if self.render_mode is None:
            from gymnasium import logger

            logger.warn('You are calling render method without specifying any render mode, e.g. render_mode="rgb_array".')
            return None
        from .. import render

        frames = []
        for i in range(self.num_envs if self.render_envs is None else min(self.render_envs, self.num_envs)):
            violated, mode, impulse, push = render_marks(self._out, i, self.unilateral)
            params, mu = robot_of_row(self._robots[i if self._robots.shape[0] > 1 else 0])  # each robot drawn as it is
            frames.append(
                render.draw(self._q[i], self._anchor[i], self._out["lam"][i], params, violated, self.width, self.height, mu, mode, impulse, push)
            )  # fmt: skip
        return tuple(frames)

    def set_config(self, **changes: Any) -> None:
        """Change task settings of every sub-env: a curriculum's handle (``LegEnv.set_config`` says what may
        change and when it takes effect). Episodes under way keep their starts; later resets, autoresets
        included, draw under the new settings. The SB3 adapter reaches it by ``env_method("set_config", ...)``."""
        self.config, settings = checked_config_change(self, self.single_observation_space, changes)
        self._settings[...] = settings

    # ---------------------------------------------------------- accessors

    @property
    def dt(self) -> float:
        """Control period [s]: the simulated time of one ``step``."""
        return self.config.dt

    @property
    def state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Copies of ``(q, qd, anchor)``, shapes ``(num_envs, 5), (num_envs, 5), (num_envs, 2)``."""
        return self._q.copy(), self._qd.copy(), self._anchor.copy()

    @property
    def contact_mode(self) -> np.ndarray:
        """Each robot's contact mode now, as ``leg_env.physics.hybrid.hybrid_step`` takes it: int64 ``(num_envs,)`` of
        ``leg_env.physics.contact``'s ``STICK``, ``SLIP_FORWARD``, ``SLIP_BACKWARD``, ``FLIGHT`` (the pinned foot:
        ``STICK``). ``info["contact_mode"]`` names it without the slip's direction."""
        return self._state["mode"].astype(np.int64)

    @property
    def np_random_seed(self) -> tuple[int | None, ...]:
        """Each sub-env's seed, as ``SyncVectorEnv`` gives them: the seed its generator was made from at its last
        seeded reset (an entropy-drawn one after ``reset(seed=None)``). Before a sub-env's first reset, as a single
        env does, asking draws its generator from fresh entropy, and a later ``reset(seed=None)`` goes on from it."""
        for i in np.flatnonzero(np.array([rng is None for rng in self._rngs.generators], dtype=np.bool_)).tolist():
            self._rngs[i], self._rng_seeds[i] = seeding.np_random(None)
        return tuple(self._rng_seeds)

    @property
    def elapsed_steps(self) -> np.ndarray:
        """Steps of each sub-env since its last reset (a copy)."""
        return self._elapsed.copy()

    # ------------------------------------------------------------ helpers

    def _step(self, actions) -> "_Transition":
        """Check the actions, autoreset, make one kernel call; shared by ``step`` and the SB3 adapter.

        NEXT_STEP resets the rows that ended on the previous step (they are stepped from their
        start, then put back there: the kernel call stays one call over all rows); SAME_STEP resets
        the rows that end in this step, after keeping their last observation, flags, extras and
        force in ``final``. The returned ``terms`` are the step's; the buffers hold the reset rows' start.
        """
        if self._never_reset.any():
            raise ResetNeeded(
                f"call reset() before step(): sub-env(s) {_some(np.flatnonzero(self._never_reset))} were never reset (no episode)"
            )
        self._action[:] = self._checked_actions(actions)
        mode = self.autoreset_mode
        restarted = rejected = None
        if mode == AutoresetMode.NEXT_STEP and self._ended.any():
            restarted = np.flatnonzero(self._ended)
            rejected = self._set_robots(restarted)
            # step the restarting rows from their start (cheap, near nominal), then put them back there
            starts = self._start(restarted, *self._draw_starts(restarted))
        elif mode == AutoresetMode.DISABLED and self._ended.any():
            raise ValueError(
                f"sub-env(s) {_some(np.flatnonzero(self._ended))} ended; with autoreset_mode DISABLED reset them "
                'with reset(options={"reset_mask": mask}) before stepping them again'
            )
        if self.num_threads == 1:
            self.task.step(self._state, self._robots, self._settings, self._out, self._obs)
        else:
            self._step_threaded()
        self._elapsed += 1
        if restarted is not None:
            self._put_rows(restarted, starts)  # zeroes their reward terms too
            self._elapsed[restarted] = 0
        terms = self._out["terms"][:, :len(self.reward_keys)].copy()  # the step's, before a SAME_STEP reset zeroes the reset rows'
        reward = terms[:, 0].copy()
        for k in range(1, terms.shape[1]):  # summed in order, as the single env does
            reward += terms[:, k]
        terminated = self._out["terminated"].copy()
        if self.max_episode_steps is None:
            truncated = np.zeros(self.num_envs, dtype=np.bool_)
        else:
            truncated = self._elapsed >= self.max_episode_steps
        if restarted is not None:
            terminated[restarted] = False  # a start state is not an episode end
        ended = terminated | truncated
        final = None
        if mode == AutoresetMode.SAME_STEP and ended.any():
            restarted = np.flatnonzero(ended)
            final = _Final(self._obs[restarted], take_rows(self._out, restarted), take_rows(self._state, restarted))
            rejected = self._set_robots(restarted)
            self._start(restarted, *self._draw_starts(restarted))
            self._elapsed[restarted] = 0
            self._ended[:] = False
        else:
            self._ended = ended
        return _Transition(self._obs.copy(), reward, terminated, truncated, restarted, final, terms, rejected)

    def _step_threaded(self) -> None:
        """``Task.step`` split into ``num_threads`` contiguous chunks, each stepped in a thread.

        The kernel releases the GIL, so the chunks run in parallel; robots are independent, so the result is
        bitwise that of one thread. The pool is made in the process that uses it (a forked child, whose copy
        of its parent's pool has no threads, makes its own).
        """
        pid = os.getpid()
        if self._pool is None or self._pool[0] != pid:
            self._pool = (pid, ThreadPoolExecutor(self.num_threads, thread_name_prefix="leg_env"))
        n, k, args = self.num_envs, self.num_threads, (self._state, self._robots, self._settings, self._out, self._obs)
        chunks = [self._pool[1].submit(self.task.step, *args, j * n // k, (j + 1) * n // k) for j in range(k)]
        for chunk in chunks:
            chunk.result()

    def jacobians(self, actions) -> tuple[np.ndarray, np.ndarray]:
        """The exact Jacobians of the next ``step(actions)`` from the batch's current states; the env is not stepped.

        Args:
            actions: ``(num_envs, 2)``, as ``step`` takes them (in [-1, 1]; beyond, clipped).

        Returns:
            ``(A, B)``: ``A`` ``(num_envs, 10, 10)``, d(q, qd) after the step / d(q, qd) now, and ``B``
            ``(num_envs, 10, 2)``, d(q, qd) after the step / d action, in the action's units (the torque limit
            times the torque's derivative; 0 for an entry beyond its bound). ``q = (x_b, y_b, th_b, q1, q2)`` as in
            ``state``. On the unilateral ground a robot whose step has no derivative (a grazing event, two at once,
            the Painleve rule, a Zeno settle; ``leg_env.physics.derivatives``) gets NaN. The anchor is the state's,
            held.

        Raises:
            ValueError: ``actions`` of the wrong shape, or not finite.
        """
        from ..physics.derivatives import action_jacobians

        a = self._checked_actions(actions)
        c = self.config
        A, B, _ = action_jacobians(self._state, self._robots, a, dt=c.dt, substeps=c.substeps, max_angle=c.max_angle,
                                   motor_speed=c.motor_speed, unilateral=self.unilateral)
        return A, B

    def _checked_actions(self, actions) -> np.ndarray:
        """``actions`` as a C-contiguous float64 ``(num_envs, 2)`` array; ``ValueError`` if malformed or non-finite.

        Strings, complex numbers and bools are refused (``leg_env.checks.real_array``), not converted.
        """
        if type(actions) is np.ndarray and actions.dtype.kind == "f" and actions.ndim:
            a = np.ascontiguousarray(actions, dtype=np.float64)  # the common case
        elif isinstance(actions, (numbers.Number, np.generic)) or (type(actions) is np.ndarray and actions.ndim == 0):  # one number (Sync: a TypeError)
            raise checks.ArgumentTypeError(f"actions must be a ({self.num_envs}, 2) array [hip, knee], not one number: {checks.shown(actions)}")
        else:
            a = checks.real_array("actions", actions, f"a ({self.num_envs}, 2) array of numbers [hip, knee]")
        if a.shape != (self.num_envs, 2):
            raise ValueError(f"actions must have shape ({self.num_envs}, 2) [hip, knee], got shape {a.shape}")
        finite = np.isfinite(a)
        if not finite.all():
            bad = np.flatnonzero(~finite.all(axis=1))
            raise ValueError(f"actions must be finite; sub-env(s) {_some(bad)} got {a[bad[:3]].tolist()}")
        return a

    def _set_robots(self, rows: np.ndarray, robots: np.ndarray | None = None) -> np.ndarray | None:
        """Give ``rows`` their robots for the new episode: ``robots`` (a ``reset`` option's, ``(len(rows), D)``),
        else drawn from each row's own generator (``randomize``), else the nominal one. The robots are drawn
        before the start state, as the single env draws them; returns the refused draws (None if none drawn)."""
        rejected = None
        if robots is not None or self.robots.active or self._custom[rows].any():
            if self._robots.shape[0] == 1:  # from now on a row per robot
                self._robots = np.repeat(self._robots, self.num_envs)
            if robots is not None:
                self._robots[rows] = robots
            elif self.robots.active:
                rejected = self.robots.draw_rows(self._rngs, rows, self._robots)
            else:
                self._robots[rows] = self.robots.base[0]
            self._custom[rows] = robots is not None or self.robots.active
        return rejected

    def _add_params_info(self, info: dict, rows: np.ndarray, rejected: np.ndarray | None) -> None:
        """``info["params"]`` (and ``params_rejected`` when drawn) of the robots of ``rows`` that are not the
        nominal one, as ``SyncVectorEnv`` gathers the single envs' (masked arrays, a nested dict)."""
        custom = rows[self._custom[rows]]
        if custom.size == 0:
            return
        n = self.num_envs
        columns = np.zeros((len(FIELDS), n))  # one block for every field's column, one for every mask
        values = self._robots.view(np.float64).reshape(n, -1)  # a ROBOT row is doubles only
        columns[:, custom] = values[custom][:, FIELD_COLUMNS].T
        mask = np.zeros(n, dtype=np.bool_)
        mask[custom] = True
        masks = np.empty((len(FIELDS) + 1, n), dtype=np.bool_)
        masks[:] = mask  # a broadcast copy: cheaper than scattering into every row
        params = {}
        for j, name in enumerate(FIELDS):
            params[name] = columns[j]
            params["_" + name] = masks[j]
        info["params"] = params
        info["_params"] = masks[-1]
        if rejected is not None:
            column = np.zeros(n, dtype=np.int64)
            column[rows] = rejected
            info["params_rejected"] = column
            info["_params_rejected"] = mask

    def _draw_starts(self, rows: np.ndarray, explicit=None):
        """The draws of fresh starts of ``rows``, each from its own generator as the single env draws them:
        ``(explicit, noise, task columns)`` for ``_start``. ``explicit``: ``(q, qd, anchor)`` given (then
        only the task draws, and ``noise`` is None); else ``noise`` holds the posture noise's uniforms."""
        posture = 6 if explicit is None and self.config.reset_noise_scale > 0.0 else 0
        draws = np.empty((rows.size, posture + self.task.draws(self.config)))
        if draws.shape[1]:
            self._rngs.draw(rows, draws)
        columns = self.task.task_columns(draws[:, posture:], self.config)
        noise = None if explicit is not None else np.ascontiguousarray(draws[:, :posture])
        return explicit, noise, columns

    def _start(self, rows: np.ndarray | None, explicit, noise, columns: dict):
        """Start ``rows`` (all if None) with the task's state ``columns`` and evaluate them without stepping.

        ``explicit``: ``(q, qd, anchor)`` (each broadcast to ``(len(rows), .)``), put on their contact as they
        are; else the nominal posture plus the posture ``noise`` (``(len(rows), 6 or 0)`` uniforms), each robot
        from its own row of ``robots``. Their reward terms become zero. Returns the rows' ``(state, out, obs)``
        (None when ``rows`` is None), for ``_put_rows``.
        """
        if rows is None:
            state, robots, out, obs = self._state, self._robots, self._out, self._obs
        else:
            k = rows.size
            state, out = np.zeros(k, dtype=self._state.dtype), np.zeros(k, dtype=self._out.dtype)
            obs = np.empty((k, self._obs.shape[1]), dtype=np.float32)
            robots = self._robots if self._robots.shape[0] == 1 else take_rows(self._robots, rows)
        for field, values in columns.items():
            state[field] = values
        if explicit is not None:
            state["q"], state["qd"], state["anchor"] = explicit
            noise = None
        elif noise.shape[1] == 0:
            noise = np.zeros((state.shape[0], 6))  # no posture noise: not read
        self.task.start(state, robots, self._settings, out, obs, noise, self.config.reset_noise_scale)
        if rows is None:
            return None
        started = (state, out, obs)
        self._put_rows(rows, started)
        return started

    def _put_rows(self, rows: np.ndarray, started) -> None:
        """Write ``_start``'s ``(state, out, obs)`` of ``rows`` back into the buffers."""
        state, out, obs = started
        put_rows(self._state, rows, state)
        put_rows(self._out, rows, out)
        self._obs[rows] = obs

    def _bind(self) -> None:
        """Named views of the arrays (rebuilt after unpickling)."""
        state = self._state
        self.task = tasks.get(self.task_name)
        self._q, self._qd, self._anchor, self._action = state["q"], state["qd"], state["anchor"], state["action"]
        self._info_builder = InfoBuilder(self.task, self.unilateral)

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k not in _UNPICKLED}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._pool = None
        self._busy = threading.Lock()
        self._bind()

    def _reset_rows(self, reset_mask) -> np.ndarray:
        if reset_mask is None:
            return np.arange(self.num_envs)
        if not isinstance(reset_mask, np.ndarray) or reset_mask.dtype != np.bool_:  # SyncVectorEnv: a TypeError
            raise checks.ArgumentTypeError(f"options['reset_mask'] must be a bool numpy array of shape ({self.num_envs},), got {checks.shown(reset_mask)}")
        if reset_mask.shape != (self.num_envs,):
            raise ValueError(f"options['reset_mask'] must be a bool numpy array of shape ({self.num_envs},), got shape {reset_mask.shape}")
        if not reset_mask.any():
            raise ValueError("options['reset_mask'] must select at least one sub-env")
        return np.flatnonzero(reset_mask)

    def _seeds(self, seed) -> list[int | None]:
        """Each sub-env's seed: ``seed + i`` for an int, the entries of a list, all None for None."""
        n = self.num_envs
        if seed is None or isinstance(seed, (int, np.integer, bool, np.bool_)):
            seed = checks.seed("seed", seed)
            return [None] * n if seed is None else [seed + i for i in range(n)]
        if not isinstance(seed, (list, tuple, np.ndarray)):
            raise checks.ArgumentTypeError(
                f"seed must be a non-negative integer, a list of {n} such integers or None, got {checks.shown(seed)} of type {type(seed).__name__}"
            )
        if len(seed) != n:
            raise ValueError(f"a list of seeds must have num_envs={n} entries, got {len(seed)}")
        return [checks.seed(f"seed[{i}]", s) for i, s in enumerate(seed)]

    def _explicit_states(self, options: dict, k: int):
        """``(q, qd, anchor)`` for ``k`` rows from the ``qpos`` / ``qvel`` options (single env semantics)."""
        q, qd = explicit_start(options, self.nominal.q, self.config.max_rate, rows=k)
        return q, qd, start_anchor(q, self.params, self.unilateral)

    def _add_reward_info(self, info: dict, mask: np.ndarray | None, terms: np.ndarray) -> None:
        """The reward terms of the rows in ``mask`` (all if None), zeros elsewhere.

        The keys are there even when no row stepped (SyncVectorEnv omits them then).
        """
        columns = terms.T.copy()  # one copy: row k is term k over the sub-envs
        if mask is None:
            masks = np.ones(columns.shape, dtype=np.bool_)
        else:
            columns[:, ~mask] = 0.0
            masks = np.empty(columns.shape, dtype=np.bool_)
            masks[:] = mask
        for k, key in enumerate(self.reward_keys):
            info[key] = columns[k]
            info["_" + key] = masks[k]

    def _add_state_info(self, info: dict, out, state, rows: np.ndarray | None = None) -> None:
        """The state keys (``leg_env.info``) from row-aligned ``out`` and ``state`` of ``rows`` (all if None);
        zeros elsewhere."""
        n = self.num_envs
        if rows is None:
            masks = np.ones((len(self.state_keys), n), dtype=np.bool_)
        else:
            masks = np.zeros((len(self.state_keys), n), dtype=np.bool_)
            masks[:, rows] = True
        for k, (key, values) in enumerate(self._info_builder.columns(out, state).items()):
            if rows is not None:
                column = np.zeros((n, *values.shape[1:]), dtype=values.dtype)
                column[rows] = values
                values = column
            info[key] = values
            info["_" + key] = masks[k]


class _Final(NamedTuple):
    """The last step of the rows that SAME_STEP reset, before the reset (row-aligned with ``restarted``)."""

    obs: np.ndarray
    out: np.ndarray
    state: np.ndarray


class _Transition(NamedTuple):
    """What one batched step produced; ``restarted`` are the rows reset during it (or None)."""

    obs: np.ndarray
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    restarted: np.ndarray | None
    final: _Final | None
    terms: np.ndarray
    rejected: np.ndarray | None = None  # the refused robot draws of the restarted rows (randomize)


def _some(rows: np.ndarray, limit: int = 10) -> str:
    """Up to ``limit`` sub-env indices, for error messages."""
    shown = rows[:limit].tolist()
    return f"{shown}{' ...' if rows.size > limit else ''}"

