r"""The balance task: ``leg_env/PlanarLegStance-v0`` (the pinned foot, the lesson's model) and ``leg_env/PlanarLegBalance-v1`` (the unilateral ground).

Balance a planar torso on one leg whose point foot is pinned to the ground.

## Description
The robot of the lesson "Simple Legged Robot Dynamics": a floating torso (the base), a thigh
hinged at the torso's centre of mass (hip) and a shank hinged to the thigh (knee), ending in a
point foot in single support on level ground. Generalised coordinates
``q = [x_b, y_b, th_b, q1, q2]``: torso position and angle, hip angle (thigh relative to torso),
knee angle (shank relative to thigh); angles are counter-clockwise, ``th_b = 0`` is a level torso.

The physics is the exact stance model: the foot is a bilateral pin joint at its contact point
and ``M qdd + h = S^T tau + Jc^T lam`` with ``Jc qdd + Jcdot qd = 0`` is solved analytically at
every RK4 stage (``leg_env.physics.dynamics``). The stance integrator (``leg_env.physics.integrate``) integrates
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
plastic impact, each transition located inside the control step (``leg_env.physics.hybrid``; the modes,
impact map and the Painleve and Zeno rules are documented there and in ``leg_env.physics.contact``). The
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

With ``observe_action=True`` (any task, any ground) two more entries end the observation, after the task's own:
the last action, clipped to ``[-1, 1]`` (hip, knee), the one the action rate below is measured from; after a
reset, the action that holds the nominal posture (its torques over the torque limits).

## Rewards
``reward = reward_alive + reward_drift + reward_unilateral + reward_friction + reward_ctrl + reward_action_rate
+ reward_power``, each term in ``info`` under that name (they sum to the reward exactly, in this order):

- ``reward_alive = alive_bonus`` on a healthy step (not terminated), else 0.
- ``reward_drift = -(drift_position_weight |p_b - p_nom|^2 + drift_angle_weight th_b^2
  + drift_velocity_weight (x_b'^2 + y_b'^2 + th_b'^2))``, with ``p_b`` the base position relative to
  the contact point and ``p_nom`` its nominal value.
- ``reward_unilateral = -unilateral_weight max(0, -lam_y) / (m g)``: the ground cannot pull.
- ``reward_friction = -friction_weight max(0, |lam_x| - mu lam_y) / (m g)``: the force must lie in
  the friction cone.
- ``reward_ctrl = -ctrl_cost_weight |a|^2`` with ``a`` the clipped action.
- ``reward_action_rate = -(action_rate_weight |a - a_last|^2 + action_change_weight |a - a_last|_1)``: the
  action's change from the last step's (both clipped; after a reset ``a_last`` is the action that holds the nominal
  posture), squared, and in absolute value summed over the two entries. The squared charge stops swings across the
  range and hardly notices a jitter of a few hundredths; the absolute one charges a jitter in proportion to what
  ``train.motion`` measures as the action rate (the mean absolute change per step). Both 0 by default.
- ``reward_power = -power_weight (max(0, tau_hip dq1) + max(0, tau_knee dq2)) / dt`` [per W]: the hip's and the
  knee's positive mechanical power over the step, ``tau`` the torques held over it (``info["torque"]``) and ``dq``
  the joint angles' change, so that each product is the joint's work exactly; negative work (braking) is not paid
  back. 0 by default.

**Motor model** (``motor_speed``, the joints' no-load speed [rad/s]; ``inf`` by default, ideal torque sources). The
torque a joint gets is the commanded one ``a torque_limit`` scaled by ``clip(1 - w / motor_speed, 0, 1)``, ``w`` the
joint's speed in the torque's direction at the step's start (a torque that brakes the joint gets its full value),
held over the step like every torque here: a DC motor's torque-speed line, sampled at the control rate.

With ``contact="unilateral"`` the ground cannot pull or leave the cone, so the two contact terms
charge what asking for it does instead: ``reward_unilateral = -unilateral_weight flight_time / dt``
(the share of the step spent off the ground) and ``reward_friction = -friction_weight
slip_distance / dt`` (the mean slip speed over the step, m/s). ``info`` then also has
the unilateral keys of ``leg_env.info`` (which documents every key): ``contact_mode``
(``"stick"``, ``"slip"``, ``"flight"`` at the end of the step), ``foot_height``, ``impulse``, the time in
each mode, ``slip_distance``, ``work_actuators``, ``dissipation_slip``, ``dissipation_impacts``,
``energy`` and the counts ``contact_events``, ``painleve_fallbacks``, ``zeno_settles``;
``unilateral_violation`` / ``friction_violation`` can then only come from a Zeno settle or a
Painleve jam.

``info`` also has ``contact_force`` (``lam`` [N], shape (2,)), ``normal_force`` (``lam_y`` [N]),
``unilateral_violation`` (``lam_y < 0``), ``friction_violation`` (``|lam_x| > mu lam_y``),
``numerical_failure``, ``ending`` (why the episode ended, below), ``base_drift`` (``|p_b - p_nom|`` [m]), ``foot_error`` (the foot's distance from
its contact point [m]) and ``com_position``, ``com_velocity`` (the whole-body centre of mass and its
velocity, world frame [m, m/s], shape (2,) each). ``reset`` returns the same keys except the reward terms.

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

``info["ending"]`` says which: an index into ``leg_env.ENDINGS`` (``"torso_angle"``, ``"base_height"``,
``"hip_low"``, ``"hip_high"``, ``"knee_low"``, ``"knee_high"``, ``"base_below_knee"``, ``"contact_lost"``,
``"numerical_failure"``: the first that holds, in that order), 0 (``"none"``) while the episode goes on.
``leg_env.ENDINGS[info["ending"]]`` is its name. A ``reset`` reports it too: a start state already past a
limit (large ``reset_noise_scale``) is named there, and its first step ends the episode.

### Truncation
Only through the time limit: 1000 steps (10 s) when made with ``gymnasium.make``.

## Arguments
``gymnasium.make("leg_env/PlanarLegStance-v0", **kwargs)`` or ``leg_env.envs.LegEnv(task="stance", **kwargs)``.
Every ``StanceConfig`` field is a keyword argument (it overrides ``config``). An unknown keyword
raises ``TypeError`` ("got an unexpected keyword argument ...", as Python does); out-of-range values
(NaN, ``10**400``, beyond the bounds of ``leg_env.tasks.base.FIELD_RANGES`` and ``leg_env.physics.PARAM_RANGE``)
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
| `action_rate_weight`        | float             | 0.0            | per unit of `|a - a_last|^2`                             |
| `action_change_weight`      | float             | 0.0            | per unit of `|a - a_last|_1`                             |
| `power_weight`              | float             | 0.0            | per W of the joints' positive mechanical power           |
| `motor_speed`               | float             | inf            | no-load joint speed of the motor model [rad/s]           |
| `observe_action`            | bool              | False          | the last action as the observation's last two entries    |
| `mu`                        | float or None     | None           | friction coefficient; None: 0.8 pinned (the cone check), 0.5 unilateral |
| `contact`                   | str               | "pinned"       | `"pinned"` (bilateral pin) or `"unilateral"` (exact unilateral ground) |
| `min_base_height`           | float             | 0.5            | fall: torso height above the contact point [m]           |
| `max_torso_angle`           | float             | 1.0            | fall: torso tilt [rad]                                   |
| `hip_range`, `knee_range`   | pair              | (-3, -0.9), (0.05, 2.5) | allowed joint angles [rad]                      |
| `terminate_on_contact_loss` | bool              | False          | end the episode when `lam_y < contact_loss_threshold`    |
| `contact_loss_threshold`    | float             | 0.0            | [N]                                                      |
| `max_rate`                  | float             | 1000           | a faster state is a numerical failure [m/s, rad/s]       |
| `reset_noise_scale`         | float             | 0.01           | half-width of the reset noise [rad, rad/s], at most pi   |
| `randomize`                 | None, True, dict  | None           | a robot per episode (domain randomisation), below        |

**Domain randomisation** (``randomize``, ``leg_env.randomize``). None (the default) runs the nominal
robot and draws no random number, so every seed gives what it gave before the argument existed.
True draws, at every reset and from the env's own generator before the posture noise, a robot from
``leg_env.randomize.DEFAULT_RANGES`` (masses and inertias x U(0.8, 1.2), ``c1``, ``c2`` +- 2 cm, ``mu``
x U(0.6, 1), torque limits x U(0.9, 1.1)); a dict ``{field: ("scale" | "offset" | "range", low, high)}``
gives explicit ranges over ``LegParams``' fields, ``mu``, ``hip_torque_limit`` and ``knee_torque_limit``.
Values are drawn around the nominal ones every time (nothing compounds), the nominal posture and
holding torques follow the drawn robot, and a robot that could not run its nominal posture (torques
above its limits, a posture outside the termination limits, friction past the Painleve bound) is
drawn again (``info["params_rejected"]`` counts them). ``reset`` then returns ``info["params"]``
(field to value), and ``reset(options={"params": {field: value}})`` runs the given robot for one
episode (the fields left out nominal). ``env.unwrapped.robot_params`` is the robot being run.

``render_mode="human"`` opens its window at the first ``reset`` or ``step``, before the state
changes: a window that cannot open raises ``RuntimeError`` naming SDL's video driver, and the env
is untouched. Without a display SDL falls back to an off-screen driver that shows nothing; a
``UserWarning`` says so (unless ``SDL_VIDEODRIVER`` asked for that driver).

Pickling (and ``copy.deepcopy``) keeps every argument and the full state, random generator
included, so a copy continues the same trajectory; an open window is not copied.

## Solved
``PlanarLegStance-v0``: survival in every episode and a mean return of at least 980 over 100 evaluation episodes
(the LQR of ``policies/lqr.py`` scores 996.45, the shipped PPO policy 994.42).

``PlanarLegBalance-v1``: over 100 evaluation episodes on seeds not used in training or selection, beside the gated
controller (``policies/gated.py``: a backward hop from the starts whose capture point is behind the foot, then the
LQR) and the LQR on the same starts (``train.bars``): survival of at least 98%; a mean return of at least the gated
controller's and the LQR's; and, on the starts the policy and the gated controller both survive, a torso tilt (RMS),
an action rate (the mean absolute change of the action per step) and a positive actuator power no more than the
gated controller's. At a reset noise of 0.05 some starts need a step back: the LQR alone survives 89% of them.

## The balance on the unilateral ground: ``PlanarLegBalance-v1``
``gymnasium.make("leg_env/PlanarLegBalance-v1")`` is ``PlanarLegStance-v0`` with ``contact="unilateral"``, a reset
noise of 0.05 (so that the start is not already inside the LQR's comfort zone) and these weights, each for a reason:

- ``unilateral_weight = 2``, per step of flight (``-2 flight_time / dt``): the step back that a hard start needs, a
  flight of 0.12-0.17 s, costs 24-34, far less than the fall it saves, while a needless hop costs its flight too.
  At 10 (v0) the discounted objective preferred the fall to the step, and PPO needed the charge scheduled from 0
  to learn it; at 0.5 PPO found the step and went on hopping about once a second where it could have stood.
- ``drift_angle_weight = 10`` per rad^2 of torso tilt (as the push task): with 1, PPO balanced with its torso
  leaning 10-24 degrees.
- ``ctrl_cost_weight = 0.05`` per unit of ``|a|^2``, the actuator effort: about 0.012 a step to hold the posture.
- ``action_change_weight = 0.2`` per unit of ``|a - a_last|_1``: the action's change in absolute value, so that a
  jitter costs in proportion to the action rate. v0's PPO policy changed its action by 0.030 a step where the gated
  controller changes its own by 0.004; at that rate the charge is 0.012 a step, 12 an episode, where the squared
  charge at the same weight would cost 0.4.
- ``observe_action = True``: the last action is the observation's entries 18-19, the one the charge is measured
  from.

### PPO from scratch
The configuration of ``train/hyperparams/ppo.yml`` is plain PPO with no schedule: 1024 envs, rollouts of 32 steps,
2 epochs of minibatches of 8192, a discount of 0.998, an initial action noise of std 0.61 and no entropy bonus, 48M
steps. Without an entropy bonus the action noise falls to std 0.07, so that the charge on the action's change
charges the policy's own moves rather than the exploration's. The training env charges more than the task for the
base offset (100 per m^2; the task's 10 lets the policy creep a few cm off its posture), the action's change (0.4)
and flight (3 a step): without the last two, two seeds of five took up a hop in training and kept some of it; and it
charges positive actuator power, 0.0005 per W. PPO's update (``train.chunked_ppo.ChunkedPPO``) charges the mean
action's change between consecutive observations and under a noise of 0.05 on the normalised observation (0.1 each,
on a quarter of each minibatch, as CAPS does), which smooths the policy without charging its exploration, and the
mean beyond the action box (0.05). The evaluations and the selection are the task as registered. Over five seeds
(``benchmarks/results/learning/PlanarLegBalance-v1``; seeds 0-4, seed 2 named as the shipped one before any
trained, 8.8-10.0 minutes each alone on a 2-core AMD EPYC) every seed survives every one of the 100 held-out starts
with a return of 967-971 (IQM 969 [968, 971]), above the gated controller's 822 (96% survival) and the LQR's 758
(89%), and every seed meets every bar of Solved with a margin: on the starts a seed and the gated controller both
survive its torso stays within 1.2-1.7 degrees of level (RMS; the controller 6.0), its action changes by
0.0024-0.0029 a step (0.0041) and it spends 0.55-0.73 W (0.90 W). The policies step on more starts than they must
(0.7-0.8 flights per episode against 0.6). v0's policy, trained with its schedules for 60M steps, changed its action
by 0.030 a step.

What was tried on the way, and what each probe found, is kept with the research records
(``research/balance_probes.md``).

## Version History
* PlanarLegBalance-v1: effort and smoothness charged and the last action observed: the action's change charged 0.2
  in absolute value, the torque squared 0.05 (was 0.01) and the torso's tilt 10 (was 1); flight charged 2 per step
  (was 10). v0's PPO policy, trained with a curriculum of the flight charge and of the reset noise over 60M steps,
  stood with an action rate of 0.030 against the gated controller's 0.004, and needed that curriculum to find the
  step at all.
* PlanarLegBalance-v0 (removed): the unilateral ground with a reset noise of 0.05; registered as
  ``PlanarLegStance-v1`` before it had a name of its own (a different contact model is a different task, not a
  version of the pinned one).
* PlanarLegStance-v0: Initial release. The ``contact`` argument (default ``"pinned"``: the release's behaviour, bit
  for bit) adds the unilateral ground as an opt-in model; the ``randomize`` argument (default None:
  the same, bit for bit) adds domain randomisation in every version and task.
"""

from __future__ import annotations

from .base import StanceConfig, Task, observation_space

__all__ = ["TASK", "REWARD_TERMS"]

REWARD_TERMS = ("alive", "drift", "unilateral", "friction", "ctrl", "action_rate", "power")
"""The balance task's reward terms, in the order they are summed (``info["reward_<name>"]``)."""

TASK = Task(
    name="stance",
    config_cls=StanceConfig,
    reward_terms=REWARD_TERMS,
    kernel=0,
    observation_space=observation_space,
)
"""The balance task as the shared environments see it (``leg_env.tasks.base.Task``)."""
