/* The tasks' kernels: observation, reward terms and termination of each task after a control step
 * (assess) and after a reset (start). Each task's module in leg_env/tasks/ documents it for users.
 *
 * Part of the unity build of module.c.
 */
#include <math.h>

#include "env.h"

#define STANCE_TERMS 5 /* alive, drift, unilateral, friction, ctrl */

/* m g of the robot, or 1 without gravity (the observed force is then in newtons). */
static inline double weight_of(const leg_params *P)
{
    const double w = (P->m_b + P->m1 + P->m2) * P->g;
    return w > 0.0 ? w : 1.0;
}

/* The balance task's reward terms (alive, drift, unilateral, friction, ctrl), flags, extras and
 * observation of robot i at its (finite) state and force. The one place where its predicates (health,
 * feasibility) are written; the other tasks call it and add their own terms. */
static void stance_assess(const env_batch *b, Py_ssize_t i, double a0, double a1, double *terms)
{
    const env_robot *r = robot_row(b, i);
    const env_settings *c = &robot_row(b, 0)->c; /* the shared settings (a robot's own row differs in mu) */
    const leg_params *P = &r->p;
    const double mu = r->c.mu, weight = weight_of(P);
    env_state *s = state_row(b, i);
    env_out *o = out_row(b, i);
    unsigned char *flags = b->flags + i * N_FLAGS;
    float *obs = b->obs + i * b->obs_cols;
    const double lam_x = o->lam[0], lam_y = o->lam[1];
    const double dx = s->q[0] - s->anchor[0] - r->q_nom[0];
    const double dy = s->q[1] - s->anchor[1] - r->q_nom[1];
    const double th_b = s->q[2];
    /* foot error and knee height from the same kinematics as the integrator */
    const double s1 = s->trig[0], co1 = s->trig[1], s2 = s->trig[2], co2 = s->trig[3];
    const double knee_y = s->q[1] + P->l1 * s1;
    const double fx = s->q[0] + P->l1 * co1 + P->l2 * co2 - s->anchor[0];
    const double fy = knee_y + P->l2 * s2 - s->anchor[1];
    const double height = s->q[1] - s->anchor[1];
    const int unilateral_model = c->unilateral > 0.5;

    const double unilateral = fmax(0.0, -lam_y);
    const double friction = fmax(0.0, fabs(lam_x) - mu * lam_y);
    const int fell = height < c->min_base_height || s->q[1] < knee_y || fabs(th_b) > c->max_torso_angle
                     || s->q[3] < c->hip_lo || s->q[3] > c->hip_hi || s->q[4] < c->knee_lo || s->q[4] > c->knee_hi;
    int lost;
    double flight_time = 0.0;
    if (unilateral_model) { /* the ground cannot pull: what is charged is time off it and sliding on it */
        flight_time = o->flight_time;
        lost = c->terminate_on_contact_loss > 0.5 && (flight_time > 0.0 || lam_y < c->contact_loss_threshold);
    } else {
        lost = c->terminate_on_contact_loss > 0.5 && lam_y < c->contact_loss_threshold;
    }
    const int terminated = fell || lost;

    terms[0] = terminated ? 0.0 : c->alive_bonus;
    terms[1] = -(c->w_position * (dx * dx + dy * dy) + c->w_angle * th_b * th_b
                 + c->w_velocity * (s->qd[0] * s->qd[0] + s->qd[1] * s->qd[1] + s->qd[2] * s->qd[2]));
    if (unilateral_model) {
        terms[2] = -c->w_unilateral * flight_time / c->dt;
        terms[3] = -c->w_friction * o->slip_distance / c->dt;
        flags[FLAG_FRICTION] = friction > 1e-9 * weight; /* a stick force outside the cone: only by the Painleve rule */
    } else {
        terms[2] = -c->w_unilateral * unilateral / weight;
        terms[3] = -c->w_friction * friction / weight;
        flags[FLAG_FRICTION] = friction > 0.0;
    }
    terms[4] = -c->w_ctrl * (a0 * a0 + a1 * a1);
    flags[FLAG_TERMINATED] = terminated;
    flags[FLAG_UNILATERAL] = lam_y < 0.0;
    flags[FLAG_FAILED] = 0;
    o->base_drift = sqrt(dx * dx + dy * dy);
    o->foot_error = sqrt(fx * fx + fy * fy);
    o->normal_force = lam_y;
    /* observation */
    obs[0] = (float)(s->q[0] - s->anchor[0]);
    obs[1] = (float)height;
    for (int j = 2; j < 5; j++)
        obs[j] = (float)s->q[j];
    for (int j = 0; j < 5; j++)
        obs[5 + j] = (float)s->qd[j];
    obs[10] = (float)(lam_x / weight);
    obs[11] = (float)(lam_y / weight);
    if (unilateral_model) {
        const double w1 = s->qd[2] + s->qd[3], w2 = w1 + s->qd[4];
        double vfx, vfy;
        foot_velocity(P, s1, co1, s2, co2, s->qd[0], s->qd[1], w1, w2, &vfx, &vfy);
        const double m = s->mode;
        obs[12] = (float)fy;
        obs[13] = (float)vfx;
        obs[14] = (float)vfy;
        obs[15] = m == LEG_FLIGHT ? 0.0f : 1.0f;
        obs[16] = m == LEG_SLIP_FORWARD ? 1.0f : (m == LEG_SLIP_BACKWARD ? -1.0f : 0.0f);
        obs[17] = (float)(o->kick[1] / (weight * c->dt));
        o->energy = energy_core(P, s1, co1, s2, co2, s->q[1] - s->anchor[1], s->qd[0], s->qd[1], s->qd[2], w1, w2);
        o->foot_height = fy;
    }
}

/* The outputs of a numerical failure of robot i: the episode ends and pays nothing; the physics has
 * restored the last good state and the observation is left at the last good one. */
static void fail_row(const env_batch *b, Py_ssize_t i, double *terms, int n_terms)
{
    const env_robot *r = robot_row(b, i);
    const env_state *s = state_row(b, i);
    env_out *o = out_row(b, i);
    unsigned char *flags = b->flags + i * N_FLAGS;
    for (int k = 0; k < n_terms; k++)
        terms[k] = 0.0;
    flags[FLAG_TERMINATED] = 1;
    flags[FLAG_UNILATERAL] = 0;
    flags[FLAG_FRICTION] = 0;
    flags[FLAG_FAILED] = 1;
    const double dx = s->q[0] - s->anchor[0] - r->q_nom[0], dy = s->q[1] - s->anchor[1] - r->q_nom[1];
    o->base_drift = sqrt(dx * dx + dy * dy);
    o->foot_error = 0.0;
    o->normal_force = 0.0;
}

/* Evaluate robot i after physics_range stepped it: its balance terms into `terms` (n_terms zeroed on a
 * failure). A numerical failure of the physics pays nothing and ends the episode; so does an
 * observation that does not fit float32: the step is undone and the observation left at the last good
 * one. Returns whether the robot was evaluated (no numerical failure). */
static int evaluate(const env_batch *b, Py_ssize_t i, double *terms, int n_terms)
{
    if (b->flags[i * N_FLAGS + FLAG_FAILED]) {
        fail_row(b, i, terms, n_terms);
        return 0;
    }
    env_state *s = state_row(b, i);
    float *obs = b->obs + i * b->obs_cols;
    float kept[64];
    const Py_ssize_t n_obs = b->obs_cols < 64 ? b->obs_cols : 64;
    for (Py_ssize_t j = 0; j < n_obs; j++)
        kept[j] = obs[j];
    const double a0 = fmin(1.0, fmax(-1.0, s->action[0])), a1 = fmin(1.0, fmax(-1.0, s->action[1]));
    stance_assess(b, i, a0, a1, terms);
    double total = 0.0; /* finite for any finite float32 entries, inf or NaN if one of them is */
    for (Py_ssize_t j = 0; j < b->obs_cols; j++)
        total += obs[j];
    if (isfinite(total))
        return 1;
    /* the state is finite, but the observation overflowed float32 */
    for (Py_ssize_t j = 0; j < n_obs; j++)
        obs[j] = kept[j];
    undo_step(s);
    env_out *o = out_row(b, i);
    o->lam[0] = 0.0;
    o->lam[1] = 0.0;
    zero_accumulators(o);
    o->mode = s->mode;
    fail_row(b, i, terms, n_terms);
    return 0;
}

static inline double *terms_of(const env_batch *b, Py_ssize_t i) { return b->out + i * b->out_cols + ENV_DOUBLES(env_out); }

static inline void *task_state_of(const env_batch *b, Py_ssize_t i) { return b->state + i * b->state_cols + ENV_DOUBLES(env_state); }

static inline const void *task_constants_of(const env_batch *b) { return b->consts + ENV_DOUBLES(env_robot); }

/* ---------------------------------------------------------------- push recovery (leg_env.tasks.push) */

/* The whole-body COM's x from the state's trigonometry. */
static inline double com_x(const leg_params *P, const env_state *s)
{
    const double m = P->m_b + P->m1 + P->m2;
    return s->q[0] + ((P->m1 * P->c1 + P->m2 * P->l1) * s->trig[1] + P->m2 * P->c2 * s->trig[3]) / m;
}

/* The push force held over control step number n (0 at the first). */
static inline double push_load_at(const push_state *t, double n, double push_steps)
{
    for (int j = 0; j < PUSH_MAX; j++) {
        const double start = t->start[j];
        if (start <= n && n < start + push_steps)
            return t->force[j];
    }
    return 0.0;
}

static void push_assess(const env_batch *b, Py_ssize_t i)
{
    const int n_terms = STANCE_TERMS + 1;
    const push_constants *k = (const push_constants *)task_constants_of(b);
    const env_robot *r = robot_row(b, i);
    env_state *s = state_row(b, i);
    push_state *t = (push_state *)task_state_of(b, i);
    double *terms = terms_of(b, i), *info = terms + n_terms;
    const double force = s->load;
    if (evaluate(b, i, terms, n_terms)) {
        const double dx = com_x(&r->p, s) - t->x_com0;
        terms[n_terms - 1] = -k->w_com * dx * dx;
    }
    info[0] = force;
    info[1] = force * (s->q[0] - s->prev_q[0]); /* exact: F constant over the step, x_b continuous (0 if undone) */
    t->steps += 1.0;
    s->load = push_load_at(t, t->steps, k->push_steps);
}

static void push_start(const env_batch *b, Py_ssize_t i)
{
    const int n_terms = STANCE_TERMS + 1;
    const push_constants *k = (const push_constants *)task_constants_of(b);
    const env_robot *r = robot_row(b, i);
    env_state *s = state_row(b, i);
    push_state *t = (push_state *)task_state_of(b, i);
    double *terms = terms_of(b, i), *info = terms + n_terms;
    stance_assess(b, i, 0.0, 0.0, terms);
    for (int j = 0; j < n_terms; j++)
        terms[j] = 0.0;
    info[0] = 0.0;
    info[1] = 0.0;
    t->steps = 0.0;
    t->x_com0 = com_x(&r->p, s);
    s->load = push_load_at(t, 0.0, k->push_steps);
}

/* ---------------------------------------------------------------- hopping (leg_env.tasks.hop) */

/* The whole-body COM (x, y, y') from the state's trigonometry. */
static inline void com_state(const leg_params *P, const env_state *s, double *x, double *y, double *vy)
{
    const double m = P->m_b + P->m1 + P->m2, a = P->m1 * P->c1 + P->m2 * P->l1, b = P->m2 * P->c2;
    const double s1 = s->trig[0], co1 = s->trig[1], s2 = s->trig[2], co2 = s->trig[3];
    const double w1 = s->qd[2] + s->qd[3], w2 = w1 + s->qd[4];
    *x = s->q[0] + (a * co1 + b * co2) / m;
    *y = s->q[1] + (a * s1 + b * s2) / m;
    *vy = s->qd[1] + (a * co1 * w1 + b * co2 * w2) / m;
}

static void hop_assess(const env_batch *b, Py_ssize_t i)
{
    const int n_terms = 7; /* alive, height, drift, tilt, impact, slip, ctrl */
    const hop_constants *k = (const hop_constants *)task_constants_of(b);
    const env_robot *r = robot_row(b, i);
    const leg_params *P = &r->p;
    env_state *s = state_row(b, i);
    const env_out *o = out_row(b, i);
    const hop_state *t = (const hop_state *)task_state_of(b, i);
    double *terms = terms_of(b, i);
    double stance_terms[STANCE_TERMS];
    const double m = P->m_b + P->m1 + P->m2, g = P->g, weight = weight_of(P);
    const double y_stand = r->com_nom[1]; /* the standing COM height above the foot */
    if (!evaluate(b, i, stance_terms, STANCE_TERMS)) {
        for (int j = 0; j < n_terms; j++)
            terms[j] = 0.0;
        return;
    }
    double x_com, y_com, vy_com;
    com_state(P, s, &x_com, &y_com, &vy_com);
    const double e_v = 0.5 * m * vy_com * vy_com + m * g * (y_com - s->anchor[1]);
    const double e_star = m * g * (y_stand + t->command);
    const double err = (e_v - e_star) / (weight * k->height_scale);
    const double dx = x_com - t->x_com0;
    const double px = o->kick[0], py = o->kick[1];
    terms[0] = stance_terms[0]; /* alive: the balance task's health predicate */
    terms[1] = k->w_height * exp(-err * err);
    terms[2] = -k->w_drift * dx * dx;
    terms[3] = -k->w_tilt * s->q[2] * s->q[2];
    terms[4] = -k->w_impact * (px * px + py * py) / (m * m);
    terms[5] = -k->w_slip * o->slip_distance / robot_row(b, 0)->c.dt;
    terms[6] = stance_terms[4]; /* ctrl */
    if (b->flags[i * N_FLAGS + FLAG_TERMINATED]) /* terminated: nothing but the penalties */
        terms[1] = 0.0;
}

static void hop_start(const env_batch *b, Py_ssize_t i)
{
    const int n_terms = 7;
    const env_robot *r = robot_row(b, i);
    env_state *s = state_row(b, i);
    hop_state *t = (hop_state *)task_state_of(b, i);
    double *terms = terms_of(b, i);
    double stance_terms[STANCE_TERMS], y, vy;
    stance_assess(b, i, 0.0, 0.0, stance_terms);
    for (int j = 0; j < n_terms; j++)
        terms[j] = 0.0;
    b->obs[i * b->obs_cols + b->obs_cols - 1] = (float)t->command;
    com_state(&r->p, s, &t->x_com0, &y, &vy);
}

/* ---------------------------------------------------------------- dispatch */

/* The number of reward terms of each task. */
static int task_terms(int task) { return task == TASK_STANCE ? STANCE_TERMS : (task == TASK_PUSH ? STANCE_TERMS + 1 : 7); }

/* The task's own state columns, constants and info columns (doubles) after the shared ones. */
static void task_columns(int task, Py_ssize_t *state, Py_ssize_t *constants, Py_ssize_t *info)
{
    *state = task == TASK_PUSH ? ENV_DOUBLES(push_state) : (task == TASK_HOP ? ENV_DOUBLES(hop_state) : 0);
    *constants = task == TASK_PUSH ? ENV_DOUBLES(push_constants) : (task == TASK_HOP ? ENV_DOUBLES(hop_constants) : 0);
    *info = task == TASK_PUSH ? 2 : 0;
}

/* The task after a control step of robots lo .. hi - 1. */
static void task_assess(int task, const env_batch *b, Py_ssize_t lo, Py_ssize_t hi)
{
    for (Py_ssize_t i = lo; i < hi; i++) {
        if (task == TASK_PUSH)
            push_assess(b, i);
        else if (task == TASK_HOP)
            hop_assess(b, i);
        else
            evaluate(b, i, terms_of(b, i), STANCE_TERMS);
    }
}

/* The task at freshly started robots (after physics_start): reward terms zero. */
static void task_start(int task, const env_batch *b)
{
    for (Py_ssize_t i = 0; i < b->n; i++) {
        if (task == TASK_PUSH) {
            push_start(b, i);
        } else if (task == TASK_HOP) {
            hop_start(b, i);
        } else {
            double *terms = terms_of(b, i);
            stance_assess(b, i, 0.0, 0.0, terms);
            for (int k = 0; k < STANCE_TERMS; k++)
                terms[k] = 0.0;
        }
    }
}

/* Robot 0's reward: its reward terms summed in order. */
static double summed_terms(int task, const env_batch *b)
{
    const double *terms = terms_of(b, 0);
    double reward = terms[0];
    for (int k = 1; k < task_terms(task); k++)
        reward += terms[k];
    return reward;
}
