/* The environments' structs: what one robot of a Gymnasium env keeps between control steps.
 *
 * A batch is a numpy structured array of each struct (leg_env.physics.layout builds the dtypes from the layouts
 * the compiled module reports, field for field, so each layout is declared here only): `state` and
 * `out` one row per robot, `robots` one row per robot or one shared by all, `settings` one row, and a
 * float32 observation matrix. A task's own fields live in the unions at the end of each struct.
 */
#ifndef LEG_ENV_H
#define LEG_ENV_H

#include <stdint.h>

#include "robot.h"

/* The tasks (leg_env.tasks). */
typedef enum { TASK_STANCE = 0, TASK_PUSH = 1, TASK_HOP = 2, N_TASKS = 3 } env_task;

#define PUSH_MAX 8     /* pushes scheduled per episode */
#define HOP_COMMANDS 4 /* hop commands drawn ahead at a reset, for a command schedule (command_steps) */
#define MAX_TERMS 8    /* reward terms of a task, at most */

/* The push-recovery task's state: its push schedule. */
#define PUSH_STATE_FIELDS(X, S, P)                                                                                     \
    X(S, P, I32, steps, , "control steps since the start (it stops at 2^31 - 1)")                                     \
    X(S, P, I32, push_start, [PUSH_MAX], "the control step at which each push starts")                               \
    X(S, P, F64, x_com0, , "the whole-body COM's x at the start [m]")                                                 \
    X(S, P, F64, push_force, [PUSH_MAX], "each push's force on the torso's COM [N]")
typedef struct {
    PUSH_STATE_FIELDS(FIELD_DECLARE, , )
} push_state;

/* The hopping task's state. */
#define HOP_STATE_FIELDS(X, S, P)                                                                                      \
    X(S, P, F64, command, , "the commanded rise of the COM at the apex above standing [m]")                           \
    X(S, P, F64, x_com0, , "the whole-body COM's x at the start [m]")                                                 \
    X(S, P, F64, flight_run, , "the current flight's time so far (0 on the ground) [s]")                              \
    X(S, P, F64, ground_time, , "time since the last flight of at least min_flight ended, or since the start [s]")    \
    X(S, P, F64, banked, , "the height term of the current flight, paid at its landing (pay_on_landing)")             \
    X(S, P, F64, pending, , "a landed hop's banked term, paid when the next hop lasts min_flight (pay_on_next_hop)")  \
    X(S, P, F64, arc_kernel, , "the height kernel of the current (or last) flight's apex (hold_height)")               \
    X(S, P, F64, held, , "the height kernel of the last landed hop's apex, paid at every step while hopping")         \
    X(S, P, F64, arc_apex, , "the current (or last) flight's apex rise above standing [m]")                           \
    X(S, P, F64, apex, , "the last landed hop's apex rise above standing [m] (0 before the first)")                   \
    X(S, P, F64, next_commands, [HOP_COMMANDS], "with command_steps: the commands to come, in turn [m]")               \
    X(S, P, I32, command_age, , "control steps since the command was set")                                            \
    X(S, P, I32, next_command, , "the index of the next of next_commands")
typedef struct {
    HOP_STATE_FIELDS(FIELD_DECLARE, , )
} hop_state;

/* One robot's state. */
#define ENV_STATE_FIELDS(X, S, P)                                                                                      \
    X(S, P, F64, q, [LEG_NQ], "q = (x_b, y_b, th_b, q1, q2) [m, rad]")                                                \
    X(S, P, F64, qd, [LEG_NQ], "its rates [m/s, rad/s]")                                                              \
    X(S, P, F64, anchor, [2], "the stick contact point; anchor[1] is the ground's height [m]")                         \
    X(S, P, F64, action, [2], "the last action, as given (clipped to [-1, 1] when used)")                             \
    X(S, P, F64, trig, [4], "sin th1, cos th1, sin th2, cos th2 of q")                                                \
    X(S, P, F64, load, , "horizontal force on the torso's COM held over the next step [N]")                           \
    X(S, P, F64, prev_q, [LEG_NQ], "q before the last control step, to undo it")                                      \
    X(S, P, F64, prev_qd, [LEG_NQ], "qd before the last control step")                                                \
    X(S, P, F64, prev_anchor_x, , "anchor[0] before the last control step [m]")                                       \
    X(S, P, F64, prev_trig, [4], "trig before the last control step")                                                 \
    X(S, P, I32, mode, , "the contact mode (leg_mode)")                                                               \
    X(S, P, I32, prev_mode, , "the contact mode before the last control step")
typedef struct {
    ENV_STATE_FIELDS(FIELD_DECLARE, , )
    union {
        push_state push;
        hop_state hop;
    } task;
} env_state;

/* One robot: its parameters and what follows from them (a randomised batch has a row per robot). */
#define ENV_ROBOT_FIELDS(X, S, P)                                                                                      \
    X(S, P, PARAMS, p, , "its masses, inertias, lengths and gravity")                                                 \
    X(S, P, F64, mu, , "friction coefficient of its ground")                                                          \
    X(S, P, F64, torque_limit, [LEG_NU], "|tau_hip|, |tau_knee| at action +-1 [N m]")                                 \
    X(S, P, F64, q_nom, [LEG_NQ], "its nominal posture, foot at the origin")                                          \
    X(S, P, F64, tau_nom, [LEG_NU], "the torques that hold it [N m]")                                                  \
    X(S, P, F64, com_nom, [2], "its whole-body COM there [m]")
typedef struct {
    ENV_ROBOT_FIELDS(FIELD_DECLARE, , )
} env_robot;

/* A task's settings, shared by every robot of an env (StanceConfig and the task's own). */
#define ENV_SETTINGS_FIELDS(X, S, P)                                                                                   \
    X(S, P, F64, dt, , "control period [s]")                                                                           \
    X(S, P, F64, max_angle, , "largest link rotation per RK4 step [rad]")                                              \
    X(S, P, F64, max_rate, , "a rate above this is a numerical failure [m/s, rad/s]")                                  \
    X(S, P, F64, alive_bonus, , "paid on each healthy step")                                                           \
    X(S, P, F64, w_position, , "per m^2 of the base's offset from nominal")                                            \
    X(S, P, F64, w_angle, , "per rad^2 of the torso's angle")                                                          \
    X(S, P, F64, w_velocity, , "per (m/s)^2 + (rad/s)^2 of the torso's velocity")                                      \
    X(S, P, F64, w_unilateral, , "per weight of pulling force (pinned) or share of the step in flight (unilateral)")   \
    X(S, P, F64, w_friction, , "per weight of force outside the cone (pinned) or m/s of sliding (unilateral)")         \
    X(S, P, F64, w_ctrl, , "per unit of |action|^2")                                                                   \
    X(S, P, F64, min_base_height, , "a fall: the torso this close above the contact point [m]")                        \
    X(S, P, F64, max_torso_angle, , "a fall: |th_b| above this [rad]")                                                 \
    X(S, P, F64, hip_range, [2], "allowed q1 [rad]")                                                                   \
    X(S, P, F64, knee_range, [2], "allowed q2 [rad]")                                                                  \
    X(S, P, F64, contact_loss_threshold, , "with terminate_on_contact_loss, lam_y below this ends the episode [N]")     \
    X(S, P, I32, substeps, , "least RK4 steps per control period")                                                     \
    X(S, P, FLAG, unilateral, , "the unilateral ground (else the pinned foot)")                                        \
    X(S, P, FLAG, terminate_on_contact_loss, , "losing the contact ends the episode")
#define PUSH_SETTINGS_FIELDS(X, S, P)                                                                                  \
    X(S, P, F64, w_com, , "per m^2 of the COM's displacement along x")                                                 \
    X(S, P, I32, push_steps, , "control steps of one push")                                                            \
    X(S, P, FLAG, observe_com, , "the COM's x from its start is the observation's last entry (v1)")
#define HOP_SETTINGS_FIELDS(X, S, P)                                                                                   \
    X(S, P, F64, w_height, , "weight of the apex height kernel")                                                       \
    X(S, P, F64, height_scale, , "width of the height kernel [m]")                                                     \
    X(S, P, F64, w_drift, , "per m^2 of the COM's drift from its start")                                               \
    X(S, P, F64, w_tilt, , "per rad^2 of the torso's angle")                                                           \
    X(S, P, F64, w_impact, , "per (N s / (m g))^2 of impact impulse")                                                  \
    X(S, P, F64, w_slip, , "per m/s of sliding")                                                                       \
    X(S, P, F64, height_scale_fine, , "> 0: the height kernel adds one of this width [m]")                             \
    X(S, P, F64, w_drift_near, , "a second drift charge, near the start")                                              \
    X(S, P, F64, drift_near_cap, , "finite: the near drift charge is capped at this a step")                          \
    X(S, P, F64, w_limit, , "per rad^2 of the hip and the knee inside the last limit_margin of their ranges")          \
    X(S, P, F64, limit_margin, , "[rad]")                                                                              \
    X(S, P, F64, min_flight, , "a flight at least this long is a hop [s]")                                             \
    X(S, P, F64, max_ground_time, , "the alive bonus stops after this long without a hop [s] (inf: never)")            \
    X(S, P, FLAG, flight_height, , "the height term is paid in flight only (else at every step)")                      \
    X(S, P, FLAG, observe_progress, , "the COM's x from its start and the ground time are observation entries")       \
    X(S, P, FLAG, pay_on_landing, , "a flight's height term is paid at its landing, if the robot stays up")           \
    X(S, P, FLAG, pay_hops_only, , "... and only if the flight was a hop (at least min_flight long)")                 \
    X(S, P, FLAG, pay_on_next_hop, , "... and not at its landing but when the next hop has lasted min_flight")        \
    X(S, P, FLAG, hold_height, , "the last landed hop's apex kernel is paid at every step while hopping")              \
    X(S, P, FLAG, observe_apex, , "the last landed hop's apex rise is an observation entry (after observe_progress's)") \
    X(S, P, I32, command_steps, , "> 0: the command changes every this many control steps (0: it holds)")
typedef struct {
    ENV_SETTINGS_FIELDS(FIELD_DECLARE, , )
    union {
        struct {
            PUSH_SETTINGS_FIELDS(FIELD_DECLARE, , )
        } push;
        struct {
            HOP_SETTINGS_FIELDS(FIELD_DECLARE, , )
        } hop;
    } task;
} env_settings;

/* Why an episode ended at a control step (env_out.ending): the first that holds, in this order; ENDING_NONE while
 * it goes on (a time limit is the TimeLimit wrapper's, not an ending). The names are reported to Python as
 * kernels.ENDINGS, in the same order. */
#define ENV_ENDINGS(X)                                                                                                 \
    X(NONE, none)                       /* the episode goes on */                                                      \
    X(TORSO_ANGLE, torso_angle)         /* |th_b| above max_torso_angle */                                             \
    X(BASE_HEIGHT, base_height)         /* the base below min_base_height above the foot's contact point */            \
    X(HIP_LOW, hip_low)                 /* q1 below hip_range */                                                       \
    X(HIP_HIGH, hip_high)               /* q1 above hip_range */                                                       \
    X(KNEE_LOW, knee_low)               /* q2 below knee_range */                                                      \
    X(KNEE_HIGH, knee_high)             /* q2 above knee_range */                                                      \
    X(BASE_BELOW_KNEE, base_below_knee) /* the base below the knee */                                                  \
    X(CONTACT_LOST, contact_lost)       /* terminate_on_contact_loss: the foot lifted or lam_y fell below the threshold */ \
    X(NUMERICAL_FAILURE, numerical_failure) /* the step failed and was undone (out.numerical_failure) */
#define ENDING_ENUM(NAME, name) ENDING_##NAME,
typedef enum { ENV_ENDINGS(ENDING_ENUM) N_ENDINGS } env_ending;

/* What a control step of one robot gives. */
#define ENV_OUT_FIELDS(X, S, P)                                                                                        \
    X(S, P, F64, lam, [2], "mean contact force over the step [N]")                                                    \
    X(S, P, F64, base_drift, , "the base's distance from its nominal place [m]")                                      \
    X(S, P, F64, foot_error, , "the foot's distance from its contact point [m]")                                      \
    X(S, P, F64, normal_force, , "lam_y [N]")                                                                          \
    X(S, P, TALLY, tally, , "what the hybrid step added up, written by it in place")                                  \
    X(S, P, F64, energy, , "kinetic plus potential energy [J]")                                                        \
    X(S, P, F64, foot_height, , "the foot's height above the ground [m]")                                             \
    X(S, P, F64, com, [2], "the whole-body COM, world frame [m]")                                                      \
    X(S, P, F64, com_velocity, [2], "its velocity [m/s]")                                                              \
    X(S, P, F64, terms, [MAX_TERMS], "the reward terms, in the task's order")                                         \
    X(S, P, I32, mode, , "the contact mode at the end of the step")                                                   \
    X(S, P, I32, ending, , "why the episode ended at this step (env_ending)")                                          \
    X(S, P, FLAG, terminated, , "the episode ended")                                                                   \
    X(S, P, FLAG, unilateral_violation, , "lam_y < 0")                                                                 \
    X(S, P, FLAG, friction_violation, , "|lam_x| > mu lam_y")                                                          \
    X(S, P, FLAG, numerical_failure, , "the step failed and was undone")
#define PUSH_OUT_FIELDS(X, S, P)                                                                                       \
    X(S, P, F64, push_force, , "the push's force over the step [N]")                                                   \
    X(S, P, F64, work_push, , "the push's work over the step [J]")
typedef struct {
    ENV_OUT_FIELDS(FIELD_DECLARE, , )
    union {
        struct {
            PUSH_OUT_FIELDS(FIELD_DECLARE, , )
        } push;
    } task;
} env_out;

/* Observation indices (float32 columns), the same for every task: the hop task's command last. */
typedef enum {
    OBS_BASE_X = 0, OBS_BASE_Y, OBS_TH_B, OBS_Q1, OBS_Q2,
    OBS_VX_B, OBS_VY_B, OBS_W_B, OBS_W_Q1, OBS_W_Q2,
    OBS_LAM_X, OBS_LAM_Y,
    OBS_PINNED_DIM, /* the pinned foot's observation ends here */
    OBS_FOOT_HEIGHT = OBS_PINNED_DIM, OBS_FOOT_VX, OBS_FOOT_VY, OBS_CONTACT, OBS_SLIP, OBS_IMPULSE_Y,
    OBS_UNILATERAL_DIM, /* the unilateral ground's */
    OBS_COMMAND = OBS_UNILATERAL_DIM,
    OBS_HOP_DIM,
    OBS_COM_DRIFT = OBS_HOP_DIM, /* with the hop's observe_progress */
    OBS_GROUND_TIME,
    OBS_PROGRESS_DIM,
    OBS_LAST_APEX = OBS_PROGRESS_DIM, /* with the hop's observe_apex */
    OBS_MAX_DIM
} obs_index;

/* The push task's entry (with its observe_com, on the unilateral ground): the COM's x from its start. */
#define OBS_PUSH_COM_DRIFT OBS_UNILATERAL_DIM
#define OBS_PUSH_DIM (OBS_UNILATERAL_DIM + 1)

/* A batch: the env arrays of one call, checked by the binder (module.c). */
typedef struct {
    env_state *state;
    Py_ssize_t n;
    const env_robot *robots;
    Py_ssize_t robot_rows;
    const env_settings *settings;
    env_out *out;
    float *obs;
    Py_ssize_t obs_cols;
} env_batch;

#endif
