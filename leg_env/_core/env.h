/* The environments' structs: what one robot of a Gymnasium env keeps between control steps.
 *
 * A batch is a numpy structured array of each struct (leg_env.layout builds the dtypes from
 * env_layouts() of module_env.c, field for field, so each layout is declared here only): `state` and
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
typedef struct {
    int32_t steps;            /* control steps since the start */
    int32_t start[PUSH_MAX];  /* the control step at which each push starts */
    double x_com0;            /* the whole-body COM's x at the start [m] */
    double force[PUSH_MAX];   /* each push's force on the torso's COM [N] */
} push_state;

/* The hopping task's state. */
typedef struct {
    double command;     /* the commanded rise of the COM at the apex above standing [m] */
    double x_com0;      /* the whole-body COM's x at the start [m] */
    double flight_run;  /* the current flight's time so far (0 on the ground) [s] */
    double ground_time; /* time since the last flight of at least min_flight ended, or since the start [s] */
    double banked;      /* the height term of the current flight, paid at its landing (pay_on_landing) */
    double pending;     /* a landed hop's banked term, paid when the next hop lasts min_flight (pay_on_next_hop) */
    double arc_kernel;  /* the height kernel of the current (or last) flight's apex (hold_height) */
    double held;        /* the height kernel of the last landed hop's apex, paid at every step while hopping (hold_height) */
    double arc_apex;    /* the current (or last) flight's apex rise above standing [m] */
    double apex;        /* the last landed hop's apex rise above standing [m] (0 before the first) */
    double next_commands[HOP_COMMANDS]; /* with command_steps: the commands to come, in turn [m] */
    int32_t command_age;  /* control steps since the command was set */
    int32_t next_command; /* the index of the next of next_commands */
} hop_state;

/* One robot's state. */
typedef struct {
    double q[LEG_NQ], qd[LEG_NQ];
    double anchor[2];      /* the stick contact point (anchor[1]: the ground's height) */
    double action[2];      /* the last action, as given (clipped to [-1, 1] when used) */
    double trig[4];        /* sin th1, cos th1, sin th2, cos th2 of q */
    double load;           /* horizontal force on the torso's COM held over the next step [N] */
    /* the state before the last control step, to undo it */
    double prev_q[LEG_NQ], prev_qd[LEG_NQ];
    double prev_anchor_x;
    double prev_trig[4];
    int32_t mode;          /* leg_mode */
    int32_t prev_mode;
    union {
        push_state push;
        hop_state hop;
    } task;
} env_state;

/* One robot: its parameters and what follows from them (a randomised batch has a row per robot). */
typedef struct {
    leg_params p;
    double mu;                   /* friction coefficient of its ground */
    double torque_limit[LEG_NU]; /* |tau_hip|, |tau_knee| at action +-1 [N m] */
    double q_nom[LEG_NQ];        /* its nominal posture, foot at the origin */
    double tau_nom[LEG_NU];      /* the torques that hold it */
    double com_nom[2];           /* its whole-body COM there [m] */
} env_robot;

/* A task's settings, shared by every robot of an env (StanceConfig and the task's own). */
typedef struct {
    double dt;                 /* control period [s] */
    double max_angle;          /* largest link rotation per RK4 step [rad] */
    double max_rate;           /* a rate above this is a numerical failure [m/s, rad/s] */
    double alive_bonus, w_position, w_angle, w_velocity, w_unilateral, w_friction, w_ctrl;
    double min_base_height, max_torso_angle;
    double hip_range[2], knee_range[2];
    double contact_loss_threshold;
    int32_t substeps;          /* least RK4 steps per control period */
    uint8_t unilateral;        /* the unilateral ground (else the pinned foot) */
    uint8_t terminate_on_contact_loss;
    union {
        struct {
            double w_com;        /* per m^2 of the COM's displacement along x */
            int32_t push_steps;  /* control steps of one push */
            uint8_t observe_com; /* the COM's x from its start is the observation's last entry (v1) */
        } push;
        struct {
            double w_height, height_scale, w_drift, w_tilt, w_impact, w_slip;
            double height_scale_fine; /* > 0: the height kernel is the sum of the height_scale one and this one [m] */
            double w_drift_near;      /* a second drift charge, near the start: w_drift_near dx^2, or with a finite */
            double drift_near_cap;    /* drift_near_cap, cap (1 - exp(-w_drift_near dx^2 / cap)), at most cap a step */
            double w_limit;           /* per rad^2 of the hip and the knee inside the last limit_margin of their ranges */
            double limit_margin;      /* [rad] */
            double min_flight;        /* a flight at least this long is a hop [s] */
            double max_ground_time;   /* the alive bonus stops after this long without a hop [s] (inf: never) */
            uint8_t flight_height;    /* the height term is paid in flight only (else at every step) */
            uint8_t observe_progress; /* the COM's x from its start and the ground time are observation entries */
            uint8_t pay_on_landing;   /* a flight's height term is paid at its landing, if the robot stays up */
            uint8_t pay_hops_only;    /* ... and only if the flight was a hop (at least min_flight long) */
            uint8_t pay_on_next_hop;  /* ... and not at its landing but when the next hop has lasted min_flight */
            uint8_t hold_height;      /* the last landed hop's apex kernel is paid at every step while hopping */
            uint8_t observe_apex;     /* the last landed hop's apex rise is an observation entry (after observe_progress's) */
            int32_t command_steps;    /* > 0: the command changes every this many control steps, to each of
                                       * next_commands in turn (0: it holds for the episode) */
        } hop;
    } task;
} env_settings;

/* Why an episode ended at a control step (env_out.ending): the first that holds, in this order; ENDING_NONE while
 * it goes on (a time limit is the TimeLimit wrapper's, not an ending). Their names, in the same order: ENDING_NAMES
 * (tasks.c), reported to Python as kernels.ENDINGS. */
typedef enum {
    ENDING_NONE = 0,
    ENDING_TORSO_ANGLE,       /* |th_b| above max_torso_angle */
    ENDING_BASE_HEIGHT,       /* the base below min_base_height above the foot's contact point */
    ENDING_HIP_LOW,           /* q1 below hip_range */
    ENDING_HIP_HIGH,          /* q1 above hip_range */
    ENDING_KNEE_LOW,          /* q2 below knee_range */
    ENDING_KNEE_HIGH,         /* q2 above knee_range */
    ENDING_BASE_BELOW_KNEE,   /* the base below the knee */
    ENDING_CONTACT_LOST,      /* terminate_on_contact_loss: the foot lifted or its normal force fell below the threshold */
    ENDING_NUMERICAL_FAILURE, /* the step failed and was undone (out.numerical_failure) */
    N_ENDINGS
} env_ending;

/* What a control step of one robot gives. */
typedef struct {
    double lam[2];                              /* mean contact force over the step [N] */
    double base_drift, foot_error, normal_force;
    leg_tally tally;                            /* what the hybrid step added up, written by it in place */
    double energy, foot_height;
    double com[2], com_velocity[2];             /* the whole-body COM and its velocity, world frame */
    double terms[MAX_TERMS];                    /* the reward terms, in the task's order */
    union {
        struct {
            double push_force, work_push;
        } push;
    } task;
    int32_t mode;                               /* the contact mode at the end of the step */
    int32_t ending;                             /* why the episode ended at this step (env_ending) */
    uint8_t terminated, unilateral_violation, friction_violation, numerical_failure;
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

/* A batch: the arrays of one call, checked (module_env.c). */
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
