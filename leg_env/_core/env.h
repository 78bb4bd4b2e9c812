/* The environments' rows: what one robot of a Gymnasium env keeps between control steps.
 *
 * Every field is a double, so a row of each struct is a row of a float64 numpy array; the struct
 * names the columns once, and leg_env.step checks its column indices against env_layouts() (module.c)
 * at import. A task's own columns follow each struct (state: the task's per-robot state; robot: the
 * task's constants; out: the reward terms, then the task's info).
 */
#ifndef LEG_ENV_H
#define LEG_ENV_H

#include "robot.h"

/* One robot's state (leg_env.step's `state` row). */
typedef struct {
    double q[LEG_NQ], qd[LEG_NQ];
    double anchor[2];      /* the stick contact point (anchor[1]: the ground's height) */
    double action[2];      /* the last action, in [-1, 1] after clipping */
    double trig[4];        /* sin th1, cos th1, sin th2, cos th2 of q */
    double mode;           /* leg_mode */
    double load;           /* horizontal force on the torso's COM held over the next step [N] */
    /* the state before the last control step, to undo it */
    double prev_q[LEG_NQ], prev_qd[LEG_NQ];
    double prev_mode, prev_anchor_x;
    double prev_trig[4];
} env_state;

/* A task's settings that every task has (StanceConfig.array(), in its order). */
typedef struct {
    double dt, substeps, max_angle;
    double tau_hip, tau_knee;        /* torque limits [N m] */
    double alive_bonus, w_position, w_angle, w_velocity, w_unilateral, w_friction, w_ctrl;
    double mu;
    double min_base_height, max_torso_angle, hip_lo, hip_hi, knee_lo, knee_hi;
    double terminate_on_contact_loss, contact_loss_threshold;
    double max_rate;
    double unilateral;               /* 1: the unilateral ground, 0: the pinned foot */
} env_settings;

/* One robot's constants (leg_env.step's `consts` row): its parameters, the settings (a robot's own row
 * differs from row 0 only in mu and the torque limits), its nominal posture, holding torques and COM. */
typedef struct {
    leg_params p;
    env_settings c;
    double q_nom[LEG_NQ], tau_nom[LEG_NU], com_nom[2];
} env_robot;

/* What a control step of one robot gives (leg_env.step's `out` row), before the reward terms. */
typedef struct {
    double lam[2];                              /* mean contact force over the step [N] */
    double base_drift, foot_error, normal_force;
    /* the hybrid step's accumulators (leg_record's, as doubles) */
    double impulse[2], kick[2];
    double stick_time, slip_time, flight_time, slip_distance;
    double work, slip_dissipation, impact_dissipation;
    double events, painleve, settles;
    double work_load;
    double energy, foot_height;
    double mode;                                /* the contact mode at the end of the step */
} env_out;

/* The flags of a robot after a step (leg_env.step.FLAG_NAMES), one byte each. */
enum { FLAG_TERMINATED = 0, FLAG_UNILATERAL = 1, FLAG_FRICTION = 2, FLAG_FAILED = 3, N_FLAGS = 4 };

/* The tasks (leg_env.tasks) and their own columns. */
typedef enum { TASK_STANCE = 0, TASK_PUSH = 1, TASK_HOP = 2 } env_task;

#define PUSH_MAX 8
typedef struct {
    double steps, x_com0;
    double start[PUSH_MAX]; /* control step of each push's start */
    double force[PUSH_MAX]; /* its force [N] */
} push_state;
typedef struct {
    double push_steps, w_com;
} push_constants;

typedef struct {
    double command, x_com0;
} hop_state;
typedef struct {
    double w_height, height_scale, w_drift, w_tilt, w_impact, w_slip;
} hop_constants;

#define ENV_DOUBLES(type) ((Py_ssize_t)(sizeof(type) / sizeof(double)))

/* A batch of robots: the packed arrays of leg_env.step with their row lengths (doubles). */
typedef struct {
    double *state;
    Py_ssize_t n, state_cols;
    const double *consts;
    Py_ssize_t consts_rows, consts_cols;
    double *out;
    Py_ssize_t out_cols;
    float *obs;
    Py_ssize_t obs_cols;
    unsigned char *flags;
} env_batch;

#endif
