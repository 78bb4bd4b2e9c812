/* The task-independent control step of the environments (leg_env.step documents it for users).
 *
 * physics_range: clip the actions, scale them to torques, take the control step of the contact model
 * (the pinned RK4 step or the hybrid step) under the step's load, check the result and keep the state
 * before the step. physics_start: put freshly reset robots on their contact without stepping. A task's
 * kernels (tasks.c) evaluate the robots after either.
 *
 * Part of the unity build of module.c.
 */
#include <math.h>

#include "env.h"

static inline env_state *state_row(const env_batch *b, Py_ssize_t i) { return b->state + i; }

/* Robot i: its own row with a row per robot, else the one row every robot shares. */
static inline const env_robot *robot_row(const env_batch *b, Py_ssize_t i) { return b->robots + (b->robot_rows > 1 ? i : 0); }

static inline env_out *out_row(const env_batch *b, Py_ssize_t i) { return b->out + i; }

static inline void write_trig(env_state *s) { leg_trig(s->q, &s->trig[0], &s->trig[1], &s->trig[2], &s->trig[3]); }

/* Restore the state to what it was before the last control step. */
static inline void undo_step(env_state *s)
{
    for (int j = 0; j < LEG_NQ; j++) {
        s->q[j] = s->prev_q[j];
        s->qd[j] = s->prev_qd[j];
    }
    s->mode = s->prev_mode;
    s->anchor[0] = s->prev_anchor_x;
    for (int j = 0; j < 4; j++)
        s->trig[j] = s->prev_trig[j];
}

/* What the hybrid step did, and the unilateral extras, zero. */
static inline void zero_record(env_out *o)
{
    memset(&o->tally, 0, sizeof o->tally);
    o->energy = o->foot_height = 0.0;
}

/* The whole-body COM and its velocity from the state's trigonometry. */
static inline void com_of(const leg_params *P, const env_state *s, double *com, double *vel)
{
    com_trig(P, s->q, s->qd, s->trig[0], s->trig[1], s->trig[2], s->trig[3], com, vel);
}

/* The torque a joint's motor gives for the commanded torque tau at the joint speed w [rad/s] at the step's start,
 * held over the step: an ideal torque source (w0 infinite), or a motor whose torque falls linearly with the speed
 * in the torque's direction, from the commanded one at rest to none at the no-load speed w0 (a torque braking the
 * joint, against its motion, is given whole). */
static inline double motor_torque(double tau, double w, double w0)
{
    if (isinf(w0) || tau == 0.0)
        return tau;
    const double along = tau > 0.0 ? w : -w; /* the speed in the torque's direction */
    return tau * leg_fmin(1.0, leg_fmax(0.0, 1.0 - along / w0));
}

/* One control step of robots lo .. hi - 1, in place. A numerical failure (a non-finite state or force, or
 * a rate above max_rate) restores the state before the step, zeroes lam and the record and sets the
 * robot's numerical_failure; otherwise it is cleared and trig follows the new q. Robots are
 * independent: the rows of a batch stepped in any split are bitwise those of one call. */
static void physics_range(const env_batch *b, Py_ssize_t lo, Py_ssize_t hi)
{
    const env_settings *c = b->settings;
    const int unilateral = c->unilateral;
    const double dt = c->dt, max_angle = c->max_angle, max_rate = c->max_rate;
    const int substeps = c->substeps;
    for (Py_ssize_t i = lo; i < hi; i++) {
        const env_robot *r = robot_row(b, i); /* this robot's parameters, friction and torque limits */
        env_state *s = state_row(b, i);
        env_out *o = out_row(b, i);
        for (int j = 0; j < LEG_NQ; j++) {
            s->prev_q[j] = s->q[j];
            s->prev_qd[j] = s->qd[j];
        }
        s->prev_mode = s->mode;
        s->prev_anchor_x = s->anchor[0];
        for (int j = 0; j < 4; j++)
            s->prev_trig[j] = s->trig[j];
        leg_drive u;
        u.tau_hip = motor_torque(leg_fmin(1.0, leg_fmax(-1.0, s->action[0])) * r->torque_limit[0], s->qd[3], c->motor_speed);
        u.tau_knee = motor_torque(leg_fmin(1.0, leg_fmax(-1.0, s->action[1])) * r->torque_limit[1], s->qd[4], c->motor_speed);
        o->torque[0] = u.tau_hip;
        o->torque[1] = u.tau_knee;
        u.load_x = s->load;
        u.mu = r->mu;
        if (unilateral) {
            s->mode = hybrid_control_step(&r->p, &u, s->q, s->qd, s->mode, s->anchor, dt, substeps, max_angle,
                                          s->trig[0], s->trig[1], s->trig[2], s->trig[3], &o->tally, NULL);
            o->energy = 0.0;
            o->foot_height = 0.0;
            o->lam[0] = o->tally.impulse[0] / dt;
            o->lam[1] = o->tally.impulse[1] / dt;
        } else {
            u.mu = 0.0;
            o->tally.rk4_steps = rk4_control_step(&r->p, &u, s->q, s->qd, s->anchor, dt, substeps, max_angle, 1, s->trig[0],
                                                  s->trig[1], s->trig[2], s->trig[3], o->lam);
        }
        int finite = isfinite(o->lam[0]) && isfinite(o->lam[1]);
        for (int j = 0; j < LEG_NQ; j++)
            if (!(isfinite(s->q[j]) && fabs(s->qd[j]) <= max_rate))
                finite = 0;
        if (finite) {
            o->numerical_failure = 0;
            write_trig(s);
        } else {
            undo_step(s);
            o->lam[0] = 0.0;
            o->lam[1] = 0.0;
            zero_record(o);
            o->numerical_failure = 1;
        }
        o->mode = s->mode;
    }
}

/* The nominal posture plus uniform(-scale, scale) noise on (th_b, q1, q2) and their rates, from 6 uniforms
 * in [0, 1) (numpy's uniform(low, high) is low + (high - low) u), projected onto the pin at the origin. */
static void perturbed_start(const double *noise, double scale, const double *q_nom, const leg_params *P, double *q,
                            double *qd, double *anchor)
{
    const double low = -scale, width = scale - (-scale);
    for (int j = 0; j < LEG_NQ; j++) {
        q[j] = q_nom[j];
        qd[j] = 0.0;
    }
    anchor[0] = 0.0;
    anchor[1] = 0.0;
    if (scale > 0.0) {
        for (int j = 0; j < 3; j++) {
            q[2 + j] += low + width * noise[j];
            qd[2 + j] += low + width * noise[3 + j];
        }
    }
    project_one(P, q, qd, anchor);
}

/* Mode, ground contact and instantaneous force of a unilateral start state: a foot within LEG_GROUND_TOL
 * of the ground is put on it, and the mode is chosen as at the start of a control step. */
static int start_unilateral(const leg_params *P, double *q, double *qd, double *anchor, const double *tau, double mu,
                            env_out *o)
{
    double s1, co1, s2, co2;
    leg_trig(q, &s1, &co1, &s2, &co2);
    const double height = q[1] + P->l1 * s1 + P->l2 * s2 - anchor[1];
    if (height <= LEG_GROUND_TOL)
        q[1] -= height;
    leg_x X = x_from(q, qd, s1, co1, s2, co2);
    const leg_drive u = {tau[0], tau[1], 0.0, mu};
    const leg_model M = model_of(P);
    leg_tally tally;
    memset(&tally, 0, sizeof tally);
    const int m = choose_mode(LEG_FLIGHT, &X, anchor, &M, &u, -1, 0, &tally, NULL);
    x_to(&X, q, qd);
    if (m != LEG_STICK)
        anchor[0] = q[0] + P->l1 * co1 + P->l2 * co2;
    const leg_accel k = derivative(m, &M, &u, &X);
    o->lam[0] = k.lam_x;
    o->lam[1] = k.lam_y;
    zero_record(o);
    return m;
}

/* Put row i on its contact without stepping: the pinned model projects the base so that the foot is on
 * its anchor with Jc qd = 0; the unilateral model chooses the mode (start_unilateral). lam is the
 * instantaneous force of that mode under the nominal holding torques, without load. */
static void start_row(const env_batch *b, Py_ssize_t i)
{
    const env_robot *r = robot_row(b, i);
    env_state *s = state_row(b, i);
    env_out *o = out_row(b, i);
    s->load = 0.0; /* a start has no load; the task's start kernel sets the first step's */
    o->torque[0] = r->tau_nom[0]; /* the torques its contact force is worked out under */
    o->torque[1] = r->tau_nom[1];
    if (b->settings->unilateral) {
        s->mode = start_unilateral(&r->p, s->q, s->qd, s->anchor, r->tau_nom, r->mu, o);
    } else {
        double s1, co1, s2, co2;
        s->mode = LEG_STICK;
        project_one(&r->p, s->q, s->qd, s->anchor);
        leg_trig(s->q, &s1, &co1, &s2, &co2);
        const double w1 = s->qd[2] + s->qd[3], w2 = w1 + s->qd[4];
        const leg_accel A = stance_core(&r->p, s1, co1, s2, co2, w1, w2, r->tau_nom[0], r->tau_nom[1], 0.0);
        o->lam[0] = A.lam_x;
        o->lam[1] = A.lam_y;
    }
    write_trig(s);
    o->mode = s->mode;
    o->numerical_failure = 0;
}

/* physics_start of every row; with noise ((N, 6) uniforms; NULL: none), each row first starts at its
 * nominal posture plus that noise (perturbed_start) with its foot at the origin. */
static void physics_start(const env_batch *b, const double *noise, double scale)
{
    static const double zeros[6] = {0.0};
    for (Py_ssize_t i = 0; i < b->n; i++) {
        if (noise) {
            const env_robot *r = robot_row(b, i);
            env_state *s = state_row(b, i);
            perturbed_start(scale > 0.0 ? noise + 6 * i : zeros, scale, r->q_nom, &r->p, s->q, s->qd, s->anchor);
        }
        start_row(b, i);
    }
}
