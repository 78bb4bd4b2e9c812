/* The tasks' kernels: observation, reward terms and termination of each task after a control step
 * (assess) and after a reset (start). Each task's module in leg_env/tasks/ documents it for users.
 *
 * Part of the unity build of module.c.
 */
#include <math.h>

#include "env.h"

#define STANCE_TERMS 7 /* alive, drift, unilateral, friction, ctrl, action_rate, power */
#define PUSH_TERMS 8   /* the balance task's and com */
#define HOP_TERMS 10   /* alive, height, drift, tilt, impact, slip, ctrl, limit, action_rate, power */

/* m g of the robot, or 1 without gravity (the observed force is then in newtons). */
static inline double weight_of(const leg_params *P)
{
    const double w = (P->m_b + P->m1 + P->m2) * P->g;
    return w > 0.0 ? w : 1.0;
}

/* The balance task's reward terms (alive, drift, unilateral, friction, ctrl), flags, extras and
 * observation of robot i at its (finite) state and force. The one place where its predicates (health,
 * feasibility) are written; the other tasks call it and add their own terms. shared: the flight inertia
 * of the robot every row shares (task_assess), or NULL to work out robot i's. */
static void stance_assess(const env_batch *b, Py_ssize_t i, const leg_flight_inertia *shared, double a0, double a1,
                          double *terms)
{
    const env_robot *r = robot_row(b, i);
    const env_settings *c = b->settings;
    const leg_params *P = &r->p;
    const double mu = r->mu, weight = weight_of(P);
    env_state *s = state_row(b, i);
    env_out *o = out_row(b, i);
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
    const int unilateral_model = c->unilateral;

    const double unilateral = leg_fmax(0.0, -lam_y);
    const double friction = leg_fmax(0.0, fabs(lam_x) - mu * lam_y);
    int lost;
    double flight_time = 0.0;
    if (unilateral_model) { /* the ground cannot pull: what is charged is time off it and sliding on it */
        flight_time = o->tally.flight_time;
        lost = c->terminate_on_contact_loss && (flight_time > 0.0 || lam_y < c->contact_loss_threshold);
    } else {
        lost = c->terminate_on_contact_loss && lam_y < c->contact_loss_threshold;
    }
    /* the health predicate: the first limit passed names the ending */
    env_ending ending = ENDING_NONE;
    if (fabs(th_b) > c->max_torso_angle)
        ending = ENDING_TORSO_ANGLE;
    else if (height < c->min_base_height)
        ending = ENDING_BASE_HEIGHT;
    else if (s->q[3] < c->hip_range[0])
        ending = ENDING_HIP_LOW;
    else if (s->q[3] > c->hip_range[1])
        ending = ENDING_HIP_HIGH;
    else if (s->q[4] < c->knee_range[0])
        ending = ENDING_KNEE_LOW;
    else if (s->q[4] > c->knee_range[1])
        ending = ENDING_KNEE_HIGH;
    else if (s->q[1] < knee_y)
        ending = ENDING_BASE_BELOW_KNEE;
    else if (lost)
        ending = ENDING_CONTACT_LOST;
    const int terminated = ending != ENDING_NONE;

    terms[0] = terminated ? 0.0 : c->alive_bonus;
    terms[1] = -(c->w_position * (dx * dx + dy * dy) + c->w_angle * th_b * th_b
                 + c->w_velocity * (s->qd[0] * s->qd[0] + s->qd[1] * s->qd[1] + s->qd[2] * s->qd[2]));
    if (unilateral_model) {
        terms[2] = -c->w_unilateral * flight_time / c->dt;
        terms[3] = -c->w_friction * o->tally.slip_distance / c->dt;
        o->friction_violation = friction > 1e-9 * weight; /* a stick force outside the cone: only by the Painleve rule */
    } else {
        terms[2] = -c->w_unilateral * unilateral / weight;
        terms[3] = -c->w_friction * friction / weight;
        o->friction_violation = friction > 0.0;
    }
    terms[4] = -c->w_ctrl * (a0 * a0 + a1 * a1);
    o->terminated = terminated;
    o->ending = ending;
    o->unilateral_violation = lam_y < 0.0;
    o->numerical_failure = 0;
    o->base_drift = sqrt(dx * dx + dy * dy);
    o->foot_error = sqrt(fx * fx + fy * fy);
    o->normal_force = lam_y;
    com_of(P, s, o->com, o->com_velocity);
    /* observation */
    obs[OBS_BASE_X] = (float)(s->q[0] - s->anchor[0]);
    obs[OBS_BASE_Y] = (float)height;
    obs[OBS_TH_B] = (float)s->q[2];
    obs[OBS_Q1] = (float)s->q[3];
    obs[OBS_Q2] = (float)s->q[4];
    obs[OBS_VX_B] = (float)s->qd[0];
    obs[OBS_VY_B] = (float)s->qd[1];
    obs[OBS_W_B] = (float)s->qd[2];
    obs[OBS_W_Q1] = (float)s->qd[3];
    obs[OBS_W_Q2] = (float)s->qd[4];
    obs[OBS_LAM_X] = (float)(lam_x / weight);
    obs[OBS_LAM_Y] = (float)(lam_y / weight);
    if (unilateral_model) {
        const double w1 = s->qd[2] + s->qd[3], w2 = w1 + s->qd[4];
        double vfx, vfy;
        foot_velocity(P, s1, co1, s2, co2, s->qd[0], s->qd[1], w1, w2, &vfx, &vfy);
        const int m = s->mode;
        obs[OBS_FOOT_HEIGHT] = (float)fy;
        obs[OBS_FOOT_VX] = (float)vfx;
        obs[OBS_FOOT_VY] = (float)vfy;
        obs[OBS_CONTACT] = m == LEG_FLIGHT ? 0.0f : 1.0f;
        obs[OBS_SLIP] = m == LEG_SLIP_FORWARD ? 1.0f : (m == LEG_SLIP_BACKWARD ? -1.0f : 0.0f);
        obs[OBS_IMPULSE_Y] = (float)(o->tally.kick[1] / (weight * c->dt));
        leg_flight_inertia own;
        if (shared == NULL)
            own = flight_inertia(P);
        o->energy = energy_flight(shared ? shared : &own, P->I_b, P->g, s1, co1, s2, co2, s->q[1] - s->anchor[1],
                                  o->com_velocity[0], o->com_velocity[1], s->qd[2], w1, w2);
        o->foot_height = fy;
    }
}

/* The outputs of a numerical failure of robot i: the episode ends and pays nothing; the physics has
 * restored the last good state and the observation is left at the last good one. */
static void fail_row(const env_batch *b, Py_ssize_t i, double *terms, int n_terms)
{
    const env_robot *r = robot_row(b, i);
    env_state *s = state_row(b, i);
    env_out *o = out_row(b, i);
    for (int k = 0; k < n_terms; k++)
        terms[k] = 0.0;
    o->terminated = 1;
    o->ending = ENDING_NUMERICAL_FAILURE;
    o->unilateral_violation = 0;
    o->friction_violation = 0;
    o->numerical_failure = 1;
    const double dx = s->q[0] - s->anchor[0] - r->q_nom[0], dy = s->q[1] - s->anchor[1] - r->q_nom[1];
    o->base_drift = sqrt(dx * dx + dy * dy);
    o->foot_error = 0.0;
    o->normal_force = 0.0;
    com_of(&r->p, s, o->com, o->com_velocity);
}

/* The action a (clipped) becomes robot i's last action, and with observe_action the observation's last two entries. */
static void set_last_action(const env_batch *b, Py_ssize_t i, double a0, double a1)
{
    env_state *s = state_row(b, i);
    s->last_action[0] = a0;
    s->last_action[1] = a1;
    if (b->settings->observe_action) {
        float *obs = b->obs + (i + 1) * b->obs_cols - OBS_ACTION_DIM;
        obs[0] = (float)a0;
        obs[1] = (float)a1;
    }
}

/* The effort terms of robot i's step under the clipped action a, after the balance task's five: the action's change
 * from the last one, -(w_action_rate |a - a_last|^2 + w_action_change |a - a_last|_1), and the positive mechanical power of the hip and the knee,
 * -w_power sum_j max(0, tau_j (q_j - q_j,before)) / dt (each torque held over the step, so tau_j dq_j is the joint's
 * work exactly); then a is the last action. */
static void effort_terms(const env_batch *b, Py_ssize_t i, double a0, double a1, double *terms)
{
    const env_settings *c = b->settings;
    const env_state *s = state_row(b, i);
    const env_out *o = out_row(b, i);
    const double d0 = a0 - s->last_action[0], d1 = a1 - s->last_action[1];
    const double work_hip = o->torque[0] * (s->q[3] - s->prev_q[3]), work_knee = o->torque[1] * (s->q[4] - s->prev_q[4]);
    terms[5] = -(c->w_action_rate * (d0 * d0 + d1 * d1) + c->w_action_change * (fabs(d0) + fabs(d1)));
    terms[6] = -c->w_power * (leg_fmax(0.0, work_hip) + leg_fmax(0.0, work_knee)) / c->dt;
    set_last_action(b, i, a0, a1);
}

/* A freshly started robot's last action: the one that holds its nominal posture (its torques over its limits). */
static void start_action(const env_batch *b, Py_ssize_t i)
{
    const env_robot *r = robot_row(b, i);
    const double a0 = leg_fmin(1.0, leg_fmax(-1.0, r->tau_nom[0] / r->torque_limit[0]));
    const double a1 = leg_fmin(1.0, leg_fmax(-1.0, r->tau_nom[1] / r->torque_limit[1]));
    set_last_action(b, i, a0, a1);
}

/* Evaluate robot i after physics_range stepped it: its balance terms into `terms` (n_terms zeroed on a
 * failure). A numerical failure of the physics pays nothing and ends the episode. Returns whether the robot was
 * evaluated (no numerical failure); a task then writes its own terms and columns. */
static int evaluate(const env_batch *b, Py_ssize_t i, const leg_flight_inertia *shared, double *terms, int n_terms)
{
    env_out *o = out_row(b, i);
    if (o->numerical_failure) {
        fail_row(b, i, terms, n_terms);
        return 0;
    }
    const env_state *s = state_row(b, i);
    const double a0 = leg_fmin(1.0, leg_fmax(-1.0, s->action[0])), a1 = leg_fmin(1.0, leg_fmax(-1.0, s->action[1]));
    stance_assess(b, i, shared, a0, a1, terms);
    effort_terms(b, i, a0, a1, terms);
    return 1;
}

/* After a task wrote robot i's observation: if an entry is not finite (the state is, but a column overflowed
 * float32), it is a numerical failure: the step is undone, the observation left at the one kept before the task
 * wrote it, and the episode ends paying nothing. */
static void guard_observation(const env_batch *b, Py_ssize_t i, const float *kept, int n_terms)
{
    env_out *o = out_row(b, i);
    const Py_ssize_t cols = b->obs_cols;
    float *obs = b->obs + i * cols;
    uint32_t non_finite = 0; /* an all-ones exponent: inf or NaN (a test of the bits, with no chain of additions) */
    for (Py_ssize_t j = 0; j < cols; j++) {
        uint32_t bits;
        memcpy(&bits, obs + j, sizeof bits);
        non_finite |= (bits & 0x7f800000u) == 0x7f800000u;
    }
    if (!non_finite || o->numerical_failure)
        return;
    env_state *s = state_row(b, i);
    memcpy(obs, kept, b->obs_cols * sizeof(float));
    undo_step(s);
    o->lam[0] = 0.0;
    o->lam[1] = 0.0;
    zero_record(o);
    o->mode = s->mode;
    fail_row(b, i, o->terms, n_terms);
}

/* ---------------------------------------------------------------- push recovery (leg_env.tasks.push) */

/* The push force held over control step number n (0 at the first). */
static inline double push_load_at(const push_state *t, int32_t n, int32_t push_steps)
{
    for (int j = 0; j < PUSH_MAX; j++) {
        const int32_t start = t->push_start[j];
        if (start <= n && (int64_t)n < (int64_t)start + push_steps)
            return t->push_force[j];
    }
    return 0.0;
}

static void push_assess(const env_batch *b, Py_ssize_t i, const leg_flight_inertia *shared, const float *kept)
{
    env_state *s = state_row(b, i);
    env_out *o = out_row(b, i);
    push_state *t = &s->task.push;
    const double force = s->load;
    if (evaluate(b, i, shared, o->terms, PUSH_TERMS)) {
        const double dx = o->com[0] - t->x_com0;
        o->terms[PUSH_TERMS - 1] = -b->settings->task.push.w_com * dx * dx;
        if (t->quiet) { /* an episode no push comes in: its flight (term 2) and action's change (term 5) scaled */
            o->terms[2] *= b->settings->task.push.quiet_flight_scale;
            o->terms[5] *= b->settings->task.push.quiet_change_scale;
        }
        b->obs[i * b->obs_cols + OBS_PUSH_COM_DRIFT] = (float)dx;
    }
    guard_observation(b, i, kept, PUSH_TERMS);
    o->task.push.push_force = force;
    o->task.push.work_push = force * (s->q[0] - s->prev_q[0]); /* exact: F constant over the step (0 if undone) */
    if (t->steps < INT32_MAX) /* a counter that stops, not one that wraps: no push after 2^31 - 1 steps */
        t->steps += 1;
    s->load = push_load_at(t, t->steps, b->settings->task.push.push_steps);
}

static void push_start(const env_batch *b, Py_ssize_t i)
{
    env_state *s = state_row(b, i);
    env_out *o = out_row(b, i);
    push_state *t = &s->task.push;
    stance_assess(b, i, NULL, 0.0, 0.0, o->terms);
    for (int j = 0; j < PUSH_TERMS; j++)
        o->terms[j] = 0.0;
    o->task.push.push_force = 0.0;
    o->task.push.work_push = 0.0;
    t->steps = 0;
    t->x_com0 = o->com[0];
    b->obs[i * b->obs_cols + OBS_PUSH_COM_DRIFT] = 0.0f;
    s->load = push_load_at(t, 0, b->settings->task.push.push_steps);
}

/* ---------------------------------------------------------------- hopping (leg_env.tasks.hop) */

/* The hop's height kernel of an apex energy error de = E_v - E*: a Gaussian of scale `scale` [m], plus one of scale
 * `fine` if it is positive (a coarse kernel to find the apex, a fine one to hit it). */
static double height_kernel(double de, double weight, double scale, double fine)
{
    const double err = de / (weight * scale);
    if (fine > 0.0) {
        const double err_fine = de / (weight * fine);
        return exp(-err * err) + exp(-err_fine * err_fine);
    }
    return exp(-err * err);
}

/* The hop's near-start drift charge of the COM's x from its start dx [m], its weight w per m^2: w dx^2, or with a
 * finite cap cap (1 - exp(-w dx^2 / cap)), which is w dx^2 near the start and never more than cap a step (a strong
 * charge that could outgrow the alive bonus would make a fall worth more than staying up). */
static double near_drift_charge(double dx, double w, double cap)
{
    const double quadratic = w * dx * dx;
    if (isinf(cap))
        return quadratic;
    return -cap * expm1(-quadratic / cap);
}

/* The squared distances [rad^2] of the hip and the knee inside the last `margin` of their ranges (an episode ends
 * past a range's end), summed: 0 while both are at least `margin` from their ends. */
static double limit_excess(const double *q, const env_settings *c, double margin)
{
    double sum = 0.0;
    const double *ranges[2] = {c->hip_range, c->knee_range};
    for (int j = 0; j < 2; j++) {
        const double below = ranges[j][0] + margin - q[3 + j], above = q[3 + j] - (ranges[j][1] - margin);
        if (below > 0.0)
            sum += below * below;
        if (above > 0.0)
            sum += above * above;
    }
    return sum;
}

/* A command schedule (command_steps > 0): once the command has held for command_steps control steps, the
 * next of next_commands takes over from the next step on, and the observation shows it (after the last of
 * them, the command holds). A step is judged by the command it was taken under. */
static void next_hop_command(const env_batch *b, Py_ssize_t i, hop_state *t)
{
    const int32_t steps = b->settings->task.hop.command_steps;
    if (steps <= 0 || t->next_command < 0 || t->next_command >= HOP_COMMANDS)
        return;
    if (t->command_age < steps - 1) {
        t->command_age += 1;
        return;
    }
    t->command = t->next_commands[t->next_command];
    t->next_command += 1;
    t->command_age = 0;
    b->obs[i * b->obs_cols + OBS_COMMAND] = (float)t->command;
}

static void hop_assess(const env_batch *b, Py_ssize_t i, const leg_flight_inertia *shared, const float *kept)
{
    const env_robot *r = robot_row(b, i);
    const leg_params *P = &r->p;
    env_state *s = state_row(b, i);
    env_out *o = out_row(b, i);
    hop_state *t = &s->task.hop;
    double *terms = o->terms;
    double stance_terms[STANCE_TERMS];
    const double m = P->m_b + P->m1 + P->m2, g = P->g, weight = weight_of(P);
    const double y_stand = r->com_nom[1]; /* the standing COM height above the foot */
    const double w_height = b->settings->task.hop.w_height, height_scale = b->settings->task.hop.height_scale;
    if (!evaluate(b, i, shared, stance_terms, STANCE_TERMS)) {
        for (int j = 0; j < HOP_TERMS; j++)
            terms[j] = 0.0;
        return;
    }
    const double x_com = o->com[0], y_com = o->com[1], vy_com = o->com_velocity[1];
    const double e_v = 0.5 * m * vy_com * vy_com + m * g * (y_com - s->anchor[1]);
    const double e_star = m * g * (y_stand + t->command);
    const double dx = x_com - t->x_com0;
    const double px = o->tally.kick[0], py = o->tally.kick[1];
    const env_settings *c = b->settings;
    /* hops: a flight of at least min_flight; the ground time runs from the end of the last one */
    const int landed = s->mode != LEG_FLIGHT && t->flight_run > 0.0; /* a flight ended in this step */
    const double flight_length = t->flight_run + o->tally.flight_time; /* with this step's share */
    t->flight_run = s->mode == LEG_FLIGHT ? t->flight_run + o->tally.flight_time : 0.0;
    t->ground_time = t->flight_run >= c->task.hop.min_flight ? 0.0 : t->ground_time + c->dt;
    terms[0] = stance_terms[0]; /* alive: the balance task's health predicate */
    if (t->ground_time > c->task.hop.max_ground_time) /* and hopping */
        terms[0] = 0.0;
    if (s->mode == LEG_FLIGHT) { /* in flight E_v / (m g) is the arc's apex height above the ground (none without gravity) */
        t->arc_apex = g > 0.0 ? e_v / (m * g) - y_stand : 0.0;
        t->arc_kernel = height_kernel(e_v - e_star, weight, height_scale, c->task.hop.height_scale_fine);
    }
    if (landed && flight_length >= c->task.hop.min_flight) { /* a hop landed: its apex is the one paid from now on */
        t->apex = t->arc_apex;
        t->held = t->arc_kernel;
    }
    /* the height term: the kernel of the last landed hop's apex, paid at every step while hopping */
    terms[1] = t->ground_time <= c->task.hop.max_ground_time ? w_height * t->held : 0.0;
    b->obs[i * b->obs_cols + OBS_COM_DRIFT] = (float)dx;
    b->obs[i * b->obs_cols + OBS_GROUND_TIME] = (float)t->ground_time;
    b->obs[i * b->obs_cols + OBS_LAST_APEX] = (float)t->apex;
    terms[2] = -b->settings->task.hop.w_drift * dx * dx
               - near_drift_charge(dx, b->settings->task.hop.w_drift_near, b->settings->task.hop.drift_near_cap);
    terms[3] = -b->settings->task.hop.w_tilt * s->q[2] * s->q[2];
    terms[4] = -b->settings->task.hop.w_impact * (px * px + py * py) / (m * m);
    terms[5] = -b->settings->task.hop.w_slip * o->tally.slip_distance / b->settings->dt;
    terms[6] = stance_terms[4]; /* ctrl */
    terms[7] = -b->settings->task.hop.w_limit * limit_excess(s->q, b->settings, b->settings->task.hop.limit_margin);
    terms[8] = stance_terms[5]; /* action_rate */
    terms[9] = stance_terms[6]; /* power */
    if (o->terminated) /* terminated: nothing but the penalties */
        terms[1] = 0.0;
    next_hop_command(b, i, t);
    guard_observation(b, i, kept, HOP_TERMS); /* after every column is written */
}

static void hop_start(const env_batch *b, Py_ssize_t i)
{
    env_state *s = state_row(b, i);
    env_out *o = out_row(b, i);
    double stance_terms[STANCE_TERMS];
    stance_assess(b, i, NULL, 0.0, 0.0, stance_terms);
    for (int j = 0; j < HOP_TERMS; j++)
        o->terms[j] = 0.0;
    b->obs[i * b->obs_cols + OBS_COMMAND] = (float)s->task.hop.command;
    s->task.hop.flight_run = 0.0;
    s->task.hop.ground_time = 0.0;
    s->task.hop.arc_kernel = 0.0;
    s->task.hop.held = 0.0;
    s->task.hop.arc_apex = 0.0;
    s->task.hop.apex = 0.0;
    s->task.hop.command_age = 0;
    s->task.hop.next_command = 0;
    b->obs[i * b->obs_cols + OBS_COM_DRIFT] = 0.0f;
    b->obs[i * b->obs_cols + OBS_GROUND_TIME] = 0.0f;
    b->obs[i * b->obs_cols + OBS_LAST_APEX] = 0.0f;
    s->task.hop.x_com0 = o->com[0];
}

/* ---------------------------------------------------------------- dispatch */

/* The number of reward terms of each task. */
static int task_terms(int task) { return task == TASK_STANCE ? STANCE_TERMS : (task == TASK_PUSH ? PUSH_TERMS : HOP_TERMS); }

/* The observation's width of a task with its settings. */
static Py_ssize_t task_obs_dim(int task, const env_settings *c)
{
    const Py_ssize_t action = c->observe_action ? OBS_ACTION_DIM : 0;
    if (task == TASK_HOP)
        return OBS_HOP_DIM + action;
    if (task == TASK_PUSH)
        return OBS_PUSH_DIM + action;
    return (c->unilateral ? OBS_UNILATERAL_DIM : OBS_PINNED_DIM) + action;
}

/* The task after a control step of robots lo .. hi - 1. When every row shares one robot, its flight inertia
 * (which the energy of the unilateral ground needs) is worked out once, not per row. */
static void task_assess(int task, const env_batch *b, Py_ssize_t lo, Py_ssize_t hi)
{
    leg_flight_inertia one;
    const leg_flight_inertia *shared = NULL;
    if (b->robot_rows == 1 && b->settings->unilateral) {
        one = flight_inertia(&b->robots[0].p);
        shared = &one;
    }
    float kept[OBS_MAX_DIM];
    const Py_ssize_t cols = b->obs_cols;
    for (Py_ssize_t i = lo; i < hi; i++) {
        memcpy(kept, b->obs + i * cols, cols * sizeof(float));
        if (task == TASK_PUSH) {
            push_assess(b, i, shared, kept);
        } else if (task == TASK_HOP) {
            hop_assess(b, i, shared, kept);
        } else {
            evaluate(b, i, shared, out_row(b, i)->terms, STANCE_TERMS);
            guard_observation(b, i, kept, STANCE_TERMS);
        }
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
            double *terms = out_row(b, i)->terms;
            stance_assess(b, i, NULL, 0.0, 0.0, terms);
            for (int k = 0; k < STANCE_TERMS; k++)
                terms[k] = 0.0;
        }
        start_action(b, i);
    }
}

/* Robot 0's reward: its reward terms summed in order. */
static double summed_terms(int task, const env_batch *b)
{
    const double *terms = out_row(b, 0)->terms;
    double reward = terms[0];
    for (int k = 1; k < task_terms(task); k++)
        reward += terms[k];
    return reward;
}

/* Every robot's reward: its terms summed in order (the single env's sum, row by row). */
static void summed_rewards(int task, const env_batch *b, double *reward)
{
    for (Py_ssize_t i = 0; i < b->n; i++) {
        const double *terms = out_row(b, i)->terms;
        double sum = terms[0];
        for (int k = 1; k < task_terms(task); k++)
            sum += terms[k];
        reward[i] = sum;
    }
}
