/* The entry points' work: each takes one call of the compiled module, its arguments fetched and checked by the
 * binder (module.c) from the entry's row of the table, and loops one robot's function over the call's rows.
 * Nothing here touches a Python object; the physics kernels run with the GIL released.
 *
 * Part of the unity build of module.c.
 */
#include <math.h>
#include <string.h>

#include "env.h"

#define MAX_ARGS 32 /* arguments of an entry point, at most */

/* One call's arguments, in its entry's order: an array's data, rows, values per row and row stride (0 for one
 * row shared by every robot); a scalar's value; an integer or flag; an object. */
typedef struct {
    Py_ssize_t n; /* the robots of the call */
    void *a[MAX_ARGS];
    Py_ssize_t rows[MAX_ARGS], cols[MAX_ARGS], step[MAX_ARGS];
    double x[MAX_ARGS];
    Py_ssize_t k[MAX_ARGS];
    void *o[MAX_ARGS];
    int result; /* what a kernel that answers yes or no answered */
} call;

#define EACH for (Py_ssize_t i = 0; i < c->n; i++)
#define ROW(j) ((double *)c->a[j] + i * c->step[j] * c->cols[j]) /* robot i's row of array argument j */
#define PAR(j) ((const leg_params *)c->a[j] + i * c->step[j])
#define INT(j) ((int64_t *)c->a[j] + i * c->step[j])
#define INT_ROW(j) ((int64_t *)c->a[j] + i * c->step[j] * c->cols[j]) /* robot i's row of int64 array argument j */
#define OPTIONAL_ROW(j) (c->a[j] != NULL ? ROW(j) : NULL) /* ROW(j), or NULL where argument j is None */

/* ------------------------------------------------------------------------- the dynamics (leg_env.physics) */

static void k_mass_matrix(call *c) { EACH mass_matrix_one(PAR(1), ROW(0), ROW(2)); }
static void k_bias(call *c) { EACH bias_one(PAR(2), ROW(0), ROW(1), (int)c->k[4], ROW(3)); }
static void k_foot(call *c) { EACH foot_one(PAR(1), ROW(0), ROW(2)); }
static void k_jacobian(call *c) { EACH jacobian_one(PAR(1), ROW(0), ROW(2)); }
static void k_jdot_qd(call *c) { EACH jdot_qd_one(PAR(2), ROW(0), ROW(1), ROW(3)); }
static void k_com(call *c) { EACH com_one(PAR(2), ROW(0), ROW(1), ROW(3), ROW(4)); }
static void k_equilibrium(call *c) { equilibrium_one((const leg_params *)c->a[0], c->x[1], (double *)c->a[2], (double *)c->a[3], NULL); }

/* qdd (and lam) of one contact mode: stance, flight, or slip in direction sigma */
static void mode_dynamics(const leg_params *P, const double *q, const double *qd, const double *tau, double load, int mode,
                          double mu, double sigma, double *qdd, double *lam)
{
    double s1, co1, s2, co2;
    leg_trig(q, &s1, &co1, &s2, &co2);
    const double w1 = qd[2] + qd[3], w2 = w1 + qd[4];
    const leg_accel A = mode == LEG_STICK    ? stance_core(P, s1, co1, s2, co2, w1, w2, tau[0], tau[1], load)
                        : mode == LEG_FLIGHT ? flight_core(P, s1, co1, s2, co2, w1, w2, tau[0], tau[1], load)
                                             : slip_core(P, s1, co1, s2, co2, w1, w2, tau[0], tau[1], load, mu, sigma);
    const double out[LEG_NQ] = {A.xdd, A.ydd, A.thbdd, A.q1dd, A.q2dd};
    memcpy(qdd, out, sizeof out);
    if (lam != NULL) {
        lam[0] = A.lam_x;
        lam[1] = A.lam_y;
    }
}

static void k_stance(call *c) { EACH mode_dynamics(PAR(3), ROW(0), ROW(1), ROW(2), *ROW(4), LEG_STICK, 0.0, 0.0, ROW(5), ROW(6)); }
static void k_flight(call *c) { EACH mode_dynamics(PAR(3), ROW(0), ROW(1), ROW(2), *ROW(4), LEG_FLIGHT, 0.0, 0.0, ROW(5), NULL); }
static void k_slip(call *c) { EACH mode_dynamics(PAR(5), ROW(0), ROW(1), ROW(2), *ROW(6), LEG_SLIP_FORWARD, *ROW(3), *ROW(4), ROW(7), ROW(8)); }

static void k_impact(call *c)
{
    EACH {
        double s1, co1, s2, co2, vfx, vfy, d[LEG_NQ];
        const double *v = ROW(1);
        leg_trig(ROW(0), &s1, &co1, &s2, &co2);
        const double w1 = v[2] + v[3], w2 = w1 + v[4];
        const leg_response R = foot_response(PAR(3), s1, co1, s2, co2);
        foot_velocity(PAR(3), s1, co1, s2, co2, v[0], v[1], w1, w2, &vfx, &vfy);
        double *P = ROW(5);
        *INT(6) = impact_core(vfx, vfy, *ROW(2), R.Lxx, R.Lxy, R.Lyy, &P[0], &P[1]);
        impulse_velocity(PAR(3), &R, s1, co1, s2, co2, P[0], P[1], d);
        for (int j = 0; j < LEG_NQ; j++)
            ROW(4)[j] = v[j] + d[j];
    }
}

/* ------------------------------------------------------------------------- the hopping controller (policies.hopper) */

static void k_hopper_torque(call *c)
{
    EACH hopper_torque_one(PAR(2), (const double *)c->a[3], ROW(0), *ROW(1), ROW(4), ROW(5), INT(6),
                           (unsigned char *)c->a[7] + i * c->step[7], ROW(8), ROW(9), ROW(10));
}

/* ------------------------------------------------------------------------- the model-predictive plan (policies.ilqr) */

/* The argument indices of hop_rollout (its row of module.c's table). */
enum {
    RO_Q, RO_QD, RO_MODE, RO_BIAS, RO_APEX, RO_PHASE, RO_WAS_FLIGHT, RO_SINCE_TOUCHDOWN, RO_COMMAND, RO_X_REF, RO_P, RO_GAINS, RO_CORRECTIONS, RO_K,
    RO_KK, RO_NOMINAL, RO_DT, RO_SUBSTEPS, RO_MAX_ANGLE, RO_MU, RO_LAW_STEP, RO_CLIP_SMOOTHING, RO_X, RO_MODES, RO_U, RO_V,
    RO_FLIGHT_TIME, RO_A, RO_B, RO_DU, RO_D
};

static void k_hop_rollout(call *c)
{
    const int H = (int)(c->cols[RO_CORRECTIONS] / PLAN_NU);
    const plan_settings S = {c->x[RO_DT], c->x[RO_MAX_ANGLE], c->x[RO_MU], c->x[RO_LAW_STEP], c->x[RO_CLIP_SMOOTHING],
                             (int)c->x[RO_SUBSTEPS]};
    EACH {
        const plan_pilot h = {*ROW(RO_BIAS), *ROW(RO_APEX), *ROW(RO_SINCE_TOUCHDOWN), *INT(RO_PHASE), *((unsigned char *)c->a[RO_WAS_FLIGHT] + i)};
        hop_plan_one(PAR(RO_P), (const double *)c->a[RO_GAINS], &S, H, ROW(RO_Q), ROW(RO_QD), (int)*INT(RO_MODE), h, *ROW(RO_COMMAND),
                     *ROW(RO_X_REF), ROW(RO_CORRECTIONS), OPTIONAL_ROW(RO_K), OPTIONAL_ROW(RO_KK), OPTIONAL_ROW(RO_NOMINAL), ROW(RO_X),
                     INT_ROW(RO_MODES), ROW(RO_U), ROW(RO_V), ROW(RO_FLIGHT_TIME), OPTIONAL_ROW(RO_A), OPTIONAL_ROW(RO_B),
                     OPTIONAL_ROW(RO_DU), OPTIONAL_ROW(RO_D));
    }
}

/* The argument indices of ilqr_backward. */
enum { BW_LX, BW_LXX, BW_A, BW_B, BW_D, BW_DU, BW_X, BW_U, BW_V, BW_EFFORT, BW_POWER, BW_SMOOTH, BW_REG, BW_TORQUE_LIMIT, BW_K, BW_KK };

static void k_ilqr_backward(call *c)
{
    const int H = (int)(c->cols[BW_V] / PLAN_NU);
    const double *lim = (const double *)c->a[BW_TORQUE_LIMIT];
    const plan_weights W = {c->x[BW_EFFORT], c->x[BW_POWER], c->x[BW_SMOOTH], c->x[BW_REG], {lim[0], lim[1]}};
    EACH ilqr_backward_one(&W, H, ROW(BW_LX), ROW(BW_LXX), ROW(BW_A), ROW(BW_B), ROW(BW_D), ROW(BW_DU), ROW(BW_X), ROW(BW_U), ROW(BW_V),
                           ROW(BW_K), ROW(BW_KK));
}

static void k_contact_mode(call *c) { EACH *INT(5) = contact_mode_one(PAR(4), ROW(0), ROW(1), ROW(2)[0], ROW(2)[1], *ROW(3)); }

static void k_response(call *c)
{
    EACH {
        double s1, co1, s2, co2;
        const double *v = ROW(1), *t = ROW(2);
        leg_trig(ROW(0), &s1, &co1, &s2, &co2);
        const double w1 = v[2] + v[3], w2 = w1 + v[4];
        const leg_response R = foot_response(PAR(3), s1, co1, s2, co2);
        const leg_free u = free_terms(PAR(3), &R, s1, co1, s2, co2, w1, w2, t[0], t[1], 0.0);
        const double Lam[4] = {R.Lxx, R.Lxy, R.Lxy, R.Lyy}, a0[2] = {u.a0x, u.a0y};
        memcpy(ROW(4), Lam, sizeof Lam);
        memcpy(ROW(5), a0, sizeof a0);
    }
}

/* ------------------------------------------------------------------------- time stepping */

static void k_turn(call *c) { EACH turn(sin(*ROW(0)), cos(*ROW(0)), *ROW(1), &ROW(2)[0], &ROW(2)[1]); }
static void k_project(call *c) { EACH project_one(PAR(2), ROW(0), ROW(1), ROW(3)); }

static void k_rk4_step(call *c)
{
    EACH {
        double s1, co1, s2, co2;
        const leg_drive u = {ROW(2)[0], ROW(2)[1], *ROW(4), 0.0};
        leg_trig(ROW(0), &s1, &co1, &s2, &co2);
        rk4_control_step(PAR(3), &u, ROW(0), ROW(1), ROW(5), c->x[6], (int)c->x[7], c->x[8], (int)c->k[9], s1, co1, s2, co2, ROW(10));
    }
}

static void k_rk4_jacobians(call *c)
{
    EACH {
        double s1, co1, s2, co2;
        const leg_drive u = {ROW(2)[0], ROW(2)[1], *ROW(4), 0.0};
        leg_trig(ROW(0), &s1, &co1, &s2, &co2);
        rk4_control_jacobians(PAR(3), &u, ROW(0), ROW(1), ROW(5), c->x[6], (int)c->x[7], c->x[8], (int)c->k[9], (int)c->k[10], s1, co1,
                              s2, co2, ROW(11), ROW(12), ROW(13), OPTIONAL_ROW(14));
    }
}

/* A hybrid step's log before the step: no event (the step writes those it locates). */
static void clear_log(leg_log *log)
{
    for (int j = 0; j < LEG_LOG_SIZE; j++) {
        log->event_kind[j] = -1;
        log->event_time[j] = NAN;
    }
}

/* hybrid_step's work, and hybrid_jacobians' (the same arguments first, then the derivatives' outputs). */
static void hybrid_rows(call *c, int jacobians)
{
    EACH {
        double s1, co1, s2, co2;
        leg_record *rec = (leg_record *)c->a[11] + i;
        const leg_drive u = {ROW(2)[0], ROW(2)[1], *ROW(4), *ROW(5)};
        leg_trig(ROW(0), &s1, &co1, &s2, &co2);
        clear_log(&rec->log);
        if (!jacobians) {
            *INT(6) = hybrid_control_step(PAR(3), &u, ROW(0), ROW(1), (int)*INT(6), ROW(7), c->x[8], (int)c->x[9], c->x[10], s1, co1,
                                          s2, co2, &rec->tally, &rec->log);
            continue;
        }
        int mode = (int)*INT(6);
        *INT(15) = hybrid_control_jacobians(PAR(3), &u, ROW(0), ROW(1), &mode, ROW(7), c->x[8], (int)c->x[9], c->x[10], s1, co1, s2,
                                            co2, (int)c->k[12], &rec->tally, &rec->log, ROW(13), ROW(14), OPTIONAL_ROW(16));
        *INT(6) = mode;
    }
}

static void k_hybrid_step(call *c) { hybrid_rows(c, 0); }
static void k_hybrid_jacobians(call *c) { hybrid_rows(c, 1); }

/* ------------------------------------------------------------------------- the environments (env.c, tasks.c) */

/* The env arrays of a call from argument `first` on: state, robots, settings, out and obs. */
static env_batch batch_at(const call *c, int first)
{
    const env_batch b = {(env_state *)c->a[first], c->n, (const env_robot *)c->a[first + 1], c->rows[first + 1],
                         (const env_settings *)c->a[first + 2], (env_out *)c->a[first + 3], (float *)c->a[first + 4],
                         c->cols[first + 4]};
    return b;
}

static void k_start(call *c)
{
    const env_batch b = batch_at(c, 1);
    physics_start(&b, (const double *)c->a[6], c->x[7]);
    task_start((int)c->k[0], &b);
}

static void k_assess(call *c)
{
    const env_batch b = batch_at(c, 1);
    task_assess((int)c->k[0], &b, 0, b.n);
}

/* Rows stepped and assessed together: a block's state, out and robot rows stay in cache between the physics and
 * the task's kernels. */
#define STEP_BLOCK 32

static void k_step(call *c)
{
    const env_batch b = batch_at(c, 3);
    for (Py_ssize_t i = c->k[1]; i < c->k[2]; i += STEP_BLOCK) {
        const Py_ssize_t end = c->k[2] - i > STEP_BLOCK ? i + STEP_BLOCK : c->k[2];
        physics_range(&b, i, end);
        task_assess((int)c->k[0], &b, i, end);
    }
}

/* ------------------------------------------------------------------------- the draws (draws.c) */

static void k_robot_params(call *c)
{
    c->result = robot_params((const double *)c->a[0], (const double *)c->a[1], c->rows[1], (const env_robot *)c->a[2],
                             (const double *)c->a[3], (env_robot *)c->a[4]);
}

/* generator rows[k]'s bit generator (set and in range: the binder's check) */
#define BITGEN(g, k) (((bitgen_t *const *)(g))[((const int64_t *)c->a[1])[k]])

static void k_draw_uniform(call *c)
{
    EACH {
        bitgen_t *bg = BITGEN(c->o[0], i);
        for (Py_ssize_t j = 0; j < c->cols[2]; j++)
            ROW(2)[j] = bg->next_double(bg->state);
    }
}

static void k_draw_robots(call *c)
{
    double u[ROBOT_DRAWN_MAX];
    const env_robot *base = (const env_robot *)c->a[3];
    EACH {
        bitgen_t *bg = BITGEN(c->o[0], i);
        env_robot *row = (env_robot *)c->a[6] + ((const int64_t *)c->a[1])[i];
        *INT(7) = c->k[5];
        for (Py_ssize_t t = 0; t < c->k[5]; t++) {
            for (Py_ssize_t j = 0; j < c->rows[2]; j++)
                u[j] = bg->next_double(bg->state);
            if (robot_params(u, (const double *)c->a[2], c->rows[2], base, (const double *)c->a[4], row)) {
                *INT(7) = t;
                break;
            }
        }
        if (*INT(7) == c->k[5])
            *row = *base;
    }
}

/* ------------------------------------------------------------------------- info (leg_env.info) */

/* The value kinds of an info key: a double, an int32 (as int64), a byte flag, two doubles, an int32 contact mode. */
enum { INFO_DOUBLE, INFO_INT, INFO_FLAG, INFO_VECTOR, INFO_MODE, N_INFO_KINDS };
static const size_t INFO_BYTES[N_INFO_KINDS] = {8, 4, 1, 16, 4};

#define INFO_BLOCK_ROWS 128 /* rows of out and state read per block: 128 x 680 bytes stay in L1/L2 */

/* Every row's info keys: spec row k (source: 0 out, 1 state; byte offset; kind; row of its kind's block) copies a
 * field of every robot into its row of a block: doubles (R, N), ints (R, N) int64, flags (R, N) bool, vectors
 * (R, N, 2); a mode goes to the ints. A block of robots at a time, in it a key at a time. */
static void k_info_columns(call *c)
{
    const int64_t *spec = (const int64_t *)c->a[0];
    const char *rows[2] = {(const char *)c->a[1], (const char *)c->a[2]};
    const size_t stride[2] = {sizeof(env_out), sizeof(env_state)};
    const Py_ssize_t n = c->n, m = c->rows[0];
    double *doubles = (double *)c->a[3], *vectors = (double *)c->a[6];
    int64_t *ints = (int64_t *)c->a[4];
    char *flags = (char *)c->a[5];
    int named = 1;
    for (Py_ssize_t i0 = 0; i0 < n; i0 += INFO_BLOCK_ROWS) {
        const Py_ssize_t i1 = i0 + INFO_BLOCK_ROWS < n ? i0 + INFO_BLOCK_ROWS : n;
        for (Py_ssize_t k = 0; k < m; k++) {
            const int64_t *e = spec + 4 * k;
            const char *at = rows[e[0]] + e[1];
            const size_t step = stride[e[0]];
            const Py_ssize_t first = e[3] * n;
            switch (e[2]) { /* one strided read, one contiguous write, a copy of constant size */
            case INFO_DOUBLE: {
                double *dst = doubles + first;
                for (Py_ssize_t i = i0; i < i1; i++)
                    memcpy(dst + i, at + i * step, 8);
                break;
            }
            case INFO_FLAG: {
                char *dst = flags + first;
                for (Py_ssize_t i = i0; i < i1; i++)
                    dst[i] = at[i * step] != 0;
                break;
            }
            case INFO_VECTOR: {
                double *dst = vectors + 2 * first;
                for (Py_ssize_t i = i0; i < i1; i++)
                    memcpy(dst + 2 * i, at + i * step, 16);
                break;
            }
            default: { /* an int32, or a contact mode (the call answers whether every mode has a name) */
                int64_t *dst = ints + first;
                const int mode = e[2] == INFO_MODE;
                for (Py_ssize_t i = i0; i < i1; i++) {
                    int32_t v;
                    memcpy(&v, at + i * step, 4);
                    dst[i] = v;
                    named &= !mode || (v >= 0 && v < LEG_N_MODES);
                }
            }
            }
        }
    }
    c->result = named;
}
