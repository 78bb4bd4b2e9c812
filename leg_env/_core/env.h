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
#define MAX_TERMS 10   /* reward terms of a task, at most */

/* The push-recovery task's state: its push schedule. */
typedef struct {
    PUSH_STATE_FIELDS(FIELD_DECLARE, , )
} push_state;

/* The hopping task's state. */
typedef struct {
    HOP_STATE_FIELDS(FIELD_DECLARE, , )
} hop_state;

/* One robot's state. */
typedef struct {
    ENV_STATE_FIELDS(FIELD_DECLARE, , )
    union {
        push_state push;
        hop_state hop;
    } task;
} env_state;

/* One robot: its parameters and what follows from them (a randomised batch has a row per robot). */
typedef struct {
    ENV_ROBOT_FIELDS(FIELD_DECLARE, , )
} env_robot;

/* A task's settings, shared by every robot of an env (StanceConfig and the task's own). */
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
typedef struct {
    ENV_OUT_FIELDS(FIELD_DECLARE, , )
    union {
        struct {
            PUSH_OUT_FIELDS(FIELD_DECLARE, , )
        } push;
    } task;
} env_out;

/* With observe_action, the last action (clipped) is the observation's last two entries, after the task's own. */
#define OBS_ACTION_DIM 2

/* Observation indices (float32 columns), the same for every task: the hop task's command last. */
typedef enum {
    OBS_BASE_X = 0, OBS_BASE_Y, OBS_TH_B, OBS_Q1, OBS_Q2,
    OBS_VX_B, OBS_VY_B, OBS_W_B, OBS_W_Q1, OBS_W_Q2,
    OBS_LAM_X, OBS_LAM_Y,
    OBS_PINNED_DIM, /* the pinned foot's observation ends here */
    OBS_FOOT_HEIGHT = OBS_PINNED_DIM, OBS_FOOT_VX, OBS_FOOT_VY, OBS_CONTACT, OBS_SLIP, OBS_IMPULSE_Y,
    OBS_UNILATERAL_DIM, /* the unilateral ground's */
    OBS_COMMAND = OBS_UNILATERAL_DIM, /* the hop's: its command, */
    OBS_COM_DRIFT,                    /* the COM's x from its start, */
    OBS_GROUND_TIME,                  /* the time since the last hop, */
    OBS_LAST_APEX,                    /* the last landed hop's apex rise */
    OBS_HOP_DIM,
    OBS_MAX_DIM = OBS_HOP_DIM + OBS_ACTION_DIM
} obs_index;

/* The push task's entry (on the unilateral ground): the COM's x from its start. */
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
