/* leg_env._core.kernels: the compiled core of leg-env, a CPython extension module.
 *
 * One translation unit (a unity build: the physics files are included below), so that the compiler inlines the
 * small math functions across files without link-time optimisation on any platform.
 *
 * The boundary is written once. Every entry point is a row of ENTRIES: its name, its documentation, its
 * arguments (name, dtype, shape rule, role, accepted values) and the function of calls.c that does its work. One
 * binder fetches every argument of a call by its row, checks it (type, C order, writability, size, the values a
 * kernel relies on to stay in bounds and to terminate, no output sharing memory with another argument) and names
 * the argument in every error, before anything is written; then it runs the work, with the GIL released where the
 * row says so. kernels.table() reports the rows (leg_env._core.signatures(), which the fuzz test reads). The Python wrappers
 * (leg_env.physics) keep what the table does not say: broadcasting and the values of the physics.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <float.h>
#include <stdarg.h>
#include <math.h>
#include <stddef.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#include "robot.h"

#include "dynamics.c"
#include "contact.c"
#include "integrate.c"
#include "tangent.c"
#include "hybrid.c"
#include "env.c"
#include "tasks.c"
#include "draws.c"
#include "hopper.c"
#include "plan.c"
#include "calls.c"

typedef char leg_params_is_eleven_doubles[sizeof(leg_params) == LEG_N_PARAMS * sizeof(double) ? 1 : -1];

/* ------------------------------------------------------------------------------------------ the table */

enum { OPT_NONE = 1, OPT_WHOLE = 2, OPT_OPEN = 4 }; /* None is accepted (as NULL); a whole number; lo excluded */

/* An argument. Arrays: 'd' float64, 'q' int64, 'f' float32, '?' bool, 'P' leg_params (float64 rows of 11), 'R'
 * leg_record, 'S' env_state, 'B' env_robot, 'C' env_settings, 'O' env_out (structured rows). rows: 'N' one per robot (the first sets N), 'M' one shared or one per
 * robot, '1' one, '*' any number, 'T' any number of blocks of N rows. role: 'i' read, 'o' written, 'u' both.
 * width: values per row (0: a 2-d array's columns). lo, hi: the accepted values of a number or of an integer
 * array's entries (lo > hi: any). Scalars: 'r' a real number, 'i' an integer, 'l' a flag (a truth value), 'g' an
 * object its entry's check reads (a Generators). */
typedef struct {
    const char *name;
    char kind, rows, role;
    Py_ssize_t width;
    double lo, hi;
    int opts;
} arg_spec;

typedef struct {
    const char *name, *doc;
    void (*run)(call *);
    int (*check)(call *);       /* what the arguments' rows cannot say, checked with the GIL before run */
    int release;                /* run without the GIL */
    int answers;                /* return run's yes or no (else None) */
    arg_spec args[MAX_ARGS];
} entry;

#define ANY 1.0, 0.0
#define IN(name, w) {#name, 'd', 'N', 'i', w, ANY, 0}
#define OUT(name, w) {#name, 'd', 'N', 'o', w, ANY, 0}
#define INOUT(name, w) {#name, 'd', 'N', 'u', w, ANY, 0}
#define PARAMS {"p", 'P', 'M', 'i', LEG_N_PARAMS, ANY, 0}
#define REAL(name, lo, hi, opts) {#name, 'r', 0, 'i', 0, lo, hi, opts}
#define INTEGER(name, lo, hi) {#name, 'i', 0, 'i', 0, lo, hi, 0}
#define FLAG(name) {#name, 'l', 0, 'i', 0, ANY, 0}
#define STEP_RULE REAL(dt, 0.0, DBL_MAX, OPT_OPEN), REAL(substeps, 1.0, LEG_MAX_SUBSTEPS, OPT_WHOLE), REAL(max_angle, 0.0, INFINITY, OPT_OPEN)
#define TASK INTEGER(task, 0, N_TASKS - 1)
#define ENV_ARRAYS                                                                                                     \
    {"state", 'S', 'N', 'u', 1, ANY, 0}, {"robots", 'B', 'M', 'i', 1, ANY, 0}, {"settings", 'C', '1', 'i', 1, ANY, 0},     \
        {"out", 'O', 'N', 'o', 1, ANY, 0}, {"obs", 'f', 'N', 'o', 0, ANY, 0}
#define ROBOT_ROW(name, role) {#name, 'B', '1', role, 1, ANY, 0}
#define SPEC {"spec", 'd', '*', 'i', 4, ANY, 0}
#define LIMITS {"limits", 'd', '1', 'i', ROBOT_LIMITS, ANY, 0}

static int check_start(call *c);
static int check_assess(call *c);
static int check_step(call *c);
static int check_robot_params(call *c);
static int check_draws(call *c);
static int check_info(call *c);
static int check_hop_rollout(call *c);
static int check_ilqr_backward(call *c);

#define RELEASED 1, 0
#define HELD 0, 0
#define ANSWERS 0, 1
static const entry ENTRIES[] = {
    {"mass_matrix", "M(q), (N, 5, 5).", k_mass_matrix, NULL, RELEASED, {IN(q, 5), PARAMS, OUT(M, 25)}},
    {"bias", "h(q, qd), (N, 5); gravity_only: dP/dq.", k_bias, NULL, RELEASED, {IN(q, 5), IN(qd, 5), PARAMS, OUT(h, 5), FLAG(gravity_only)}},
    {"foot", "The foot position, (N, 2).", k_foot, NULL, RELEASED, {IN(q, 5), PARAMS, OUT(out, 2)}},
    {"jacobian", "The contact Jacobian Jc, (N, 2, 5).", k_jacobian, NULL, RELEASED, {IN(q, 5), PARAMS, OUT(Jc, 10)}},
    {"jdot_qd", "Jcdot qd, (N, 2).", k_jdot_qd, NULL, RELEASED, {IN(q, 5), IN(qd, 5), PARAMS, OUT(out, 2)}},
    {"com", "The whole-body COM and its velocity, (N, 2) each.", k_com, NULL, RELEASED,
     {IN(q, 5), IN(qd, 5), PARAMS, OUT(position, 2), OUT(velocity, 2)}},
    {"stance", "The pinned foot's KKT solve: qdd and lam under a horizontal load on the torso's COM.", k_stance, NULL, RELEASED,
     {IN(q, 5), IN(qd, 5), IN(tau, 2), PARAMS, IN(load, 1), OUT(qdd, 5), OUT(lam, 2)}},
    {"flight", "The unconstrained dynamics: qdd.", k_flight, NULL, RELEASED, {IN(q, 5), IN(qd, 5), IN(tau, 2), PARAMS, IN(load, 1), OUT(qdd, 5)}},
    {"slip", "The sliding foot's dynamics in direction sigma.", k_slip, NULL, RELEASED,
     {IN(q, 5), IN(qd, 5), IN(tau, 2), IN(mu, 1), IN(sigma, 1), PARAMS, IN(load, 1), OUT(qdd, 5), OUT(lam, 2)}},
    {"impact", "The plastic impact map: qd after it, the impulse and how it ended (leg_impact).", k_impact, NULL, RELEASED,
     {IN(q, 5), IN(qd, 5), IN(mu, 1), PARAMS, OUT(qd_plus, 5), OUT(impulse, 2), {"status", 'q', 'N', 'o', 1, ANY, 0}}},
    {"contact_mode", "The consistent contact mode under the torques.", k_contact_mode, NULL, RELEASED,
     {IN(q, 5), IN(qd, 5), IN(tau, 2), IN(mu, 1), PARAMS, {"out", 'q', 'N', 'o', 1, ANY, 0}}},
    {"response", "The contact inertia Lam (N, 2, 2) and the free foot acceleration a0 (N, 2).", k_response, NULL, RELEASED,
     {IN(q, 5), IN(qd, 5), IN(tau, 2), PARAMS, OUT(Lam, 4), OUT(a0, 2)}},
    {"equilibrium", "The static stance equilibrium at the knee angle: q (5,) and tau (2,).", k_equilibrium, NULL, HELD,
     {{"p", 'P', '1', 'i', LEG_N_PARAMS, ANY, 0}, REAL(knee, 1.0, 0.0, 0), {"q", 'd', '1', 'o', 5, ANY, 0}, {"tau", 'd', '1', 'o', 2, ANY, 0}}},
    {"turn", "(sin, cos) of theta + d by the integrator's angle addition, (N, 2).", k_turn, NULL, RELEASED, {IN(theta, 1), IN(d, 1), OUT(out, 2)}},
    {"project", "The foot onto its anchor with Jc qd = 0, moving the base: q and qd in place.", k_project, NULL, RELEASED,
     {INOUT(q, 5), INOUT(qd, 5), PARAMS, IN(anchor, 2)}},
    {"rk4_step", "One RK4 control step of the pinned (stance) or free model in place, and the mean contact force.", k_rk4_step, NULL,
     RELEASED, {INOUT(q, 5), INOUT(qd, 5), IN(tau, 2), PARAMS, IN(load, 1), IN(anchor, 2), STEP_RULE, FLAG(stance), OUT(lam_mean, 2)}},
    {"hybrid_step", "One control step on the unilateral ground in place (q, qd, mode, anchor), what it did in record.", k_hybrid_step,
     NULL, RELEASED,
     {INOUT(q, 5), INOUT(qd, 5), IN(tau, 2), PARAMS, IN(load, 1), {"mu", 'd', 'N', 'i', 1, 0.0, DBL_MAX, 0},
      {"mode", 'q', 'N', 'u', 1, LEG_STICK, LEG_FLIGHT, 0}, INOUT(anchor, 2), STEP_RULE, {"record", 'R', 'N', 'o', 1, ANY, 0}}},
    {"hybrid_jacobians", "hybrid_step with its derivatives A (N, 10, 10), B (N, 10, 2) and, unless None, P (N, 10, 12), NaN where "
                         "they do not exist; follow: the anchor's x is the foot's of q and moves with it; undefined: why not (0: "
                         "they exist).", k_hybrid_jacobians,
     NULL, RELEASED,
     {INOUT(q, 5), INOUT(qd, 5), IN(tau, 2), PARAMS, IN(load, 1), {"mu", 'd', 'N', 'i', 1, 0.0, DBL_MAX, 0},
      {"mode", 'q', 'N', 'u', 1, LEG_STICK, LEG_FLIGHT, 0}, INOUT(anchor, 2), STEP_RULE, {"record", 'R', 'N', 'o', 1, ANY, 0},
      FLAG(follow), OUT(A, 100), OUT(B, 20), {"undefined", 'q', 'N', 'o', 1, ANY, 0}, {"P", 'd', 'N', 'o', 120, ANY, OPT_NONE}}},
    {"rk4_jacobians", "rk4_step with its derivatives A = d(q, qd) / d(q, qd) before (N, 10, 10), B = d(q, qd) / d tau (N, 10, 2) "
                      "and, unless None, P = d(q, qd) / d(params, mu) (N, 10, 12); follow: the anchor is the foot of q and moves "
                      "with it.", k_rk4_jacobians, NULL, RELEASED,
     {INOUT(q, 5), INOUT(qd, 5), IN(tau, 2), PARAMS, IN(load, 1), IN(anchor, 2), STEP_RULE, FLAG(stance), FLAG(follow),
      OUT(lam_mean, 2), OUT(A, 100), OUT(B, 20), {"P", 'd', 'N', 'o', 120, ANY, OPT_NONE}}},
    {"hopper_torque", "The hopping controller's torques tau (N, 2) and COM speed vx_com (N,) from its reading obs (N, 11) of the "
                      "observation and the dead-reckoned drift x0, advancing bias, apex, phase, was_flight and since_touchdown (policies.hopper).",
     k_hopper_torque, NULL, RELEASED,
     {IN(obs, HOPPER_INPUTS), IN(x0, 1), PARAMS, {"gains", 'd', '1', 'i', HOPPER_GAINS, ANY, 0}, INOUT(bias, 1), INOUT(apex, 1),
      {"phase", 'q', 'N', 'u', 1, HOP_CROUCH, HOP_RELEASE, 0}, {"was_flight", '?', 'N', 'u', 1, ANY, 0}, INOUT(since_touchdown, 1), OUT(tau, 2),
      OUT(vx_com, 1)}},
    {"hop_rollout", "Plans of H control steps from (q, qd, mode), the hopper's state (bias, apex, phase, was_flight, since_touchdown) and its command and "
                    "COM start x_ref: the hopper's law plus corrections (N, 2H) (plus, each unless None, k (N, 2H) and K (N, 2H, 10) (x - "
                    "nominal (N, H + 1, 10), None: 0)), clipped, on hybrid_step; the states X (N, H + 1, 10), modes, actions U, "
                    "applied corrections V, time in flight, and each unless None the closed loop's A, B, Du = D dpi/dx and the clip's "
                    "derivative D (any given: the step's Jacobians are formed).",
     k_hop_rollout, check_hop_rollout, RELEASED,
     {IN(q, 5), IN(qd, 5), {"mode", 'q', 'N', 'i', 1, LEG_STICK, LEG_FLIGHT, 0}, IN(bias, 1), IN(apex, 1),
      {"phase", 'q', 'N', 'i', 1, HOP_CROUCH, HOP_RELEASE, 0}, {"was_flight", '?', 'N', 'i', 1, ANY, 0}, IN(since_touchdown, 1), IN(command, 1), IN(x_ref, 1),
      PARAMS, {"gains", 'd', '1', 'i', HOPPER_GAINS, ANY, 0}, IN(corrections, 0), {"k", 'd', 'N', 'i', 0, ANY, OPT_NONE},
      {"K", 'd', 'N', 'i', 0, ANY, OPT_NONE}, {"nominal", 'd', 'N', 'i', 0, ANY, OPT_NONE}, STEP_RULE, REAL(mu, 0.0, DBL_MAX, 0),
      REAL(law_step, 0.0, DBL_MAX, OPT_OPEN), REAL(clip_smoothing, 0.0, DBL_MAX, 0), OUT(X, 0), {"modes", 'q', 'N', 'o', 0, ANY, 0},
      OUT(U, 0), OUT(V, 0), OUT(flight_time, 0), {"A", 'd', 'N', 'o', 0, ANY, OPT_NONE}, {"B", 'd', 'N', 'o', 0, ANY, OPT_NONE},
      {"Du", 'd', 'N', 'o', 0, ANY, OPT_NONE}, {"D", 'd', 'N', 'o', 0, ANY, OPT_NONE}}},
    {"ilqr_backward", "The Gauss-Newton iLQR backward pass on the corrections over H steps: gains k (N, 2H) and K (N, 2H, 10) from "
                      "the state cost's half gradient lx (N, H, 10) and Hessian lxx (N, H, 10, 10), the closed loop's A, B, D, Du, "
                      "the states X (N, H + 1, 10), actions U and corrections V (N, 2H) and the action cost's weights.",
     k_ilqr_backward, check_ilqr_backward, RELEASED,
     {IN(lx, 0), IN(lxx, 0), IN(A, 0), IN(B, 0), IN(D, 0), IN(Du, 0), IN(X, 0), IN(U, 0), IN(V, 0), REAL(effort_weight, 0.0, DBL_MAX, 0),
      REAL(power_weight, 0.0, DBL_MAX, 0), REAL(smooth_weight, 0.0, DBL_MAX, 0), REAL(regularisation, 0.0, DBL_MAX, 0),
      {"torque_limit", 'd', '1', 'i', 2, ANY, 0}, OUT(k, 0), OUT(K, 0)}},
    {"start", "Robots put on their contact (at the nominal posture plus noise, or where the state has them if noise is None) and "
              "evaluated by the task.", k_start, check_start, HELD,
     {TASK, ENV_ARRAYS, {"noise", 'd', 'N', 'i', 6, ANY, OPT_NONE}, REAL(scale, 0.0, DBL_MAX, 0)}},
    {"assess", "The task after a control step of every robot.", k_assess, check_assess, HELD, {TASK, ENV_ARRAYS}},
    {"step", "A control step of robots lo .. hi - 1 and the task after it, block by block.", k_step, check_step, RELEASED,
     {TASK, INTEGER(lo, 0, PY_SSIZE_T_MAX), INTEGER(hi, 0, PY_SSIZE_T_MAX), ENV_ARRAYS}},
    {"robot_params", "A drawn robot in row from the uniforms u: whether it is accepted.", k_robot_params, check_robot_params, ANSWERS,
     {{"u", 'd', '*', 'i', 1, ANY, 0}, SPEC, ROBOT_ROW(base, 'i'), LIMITS, ROBOT_ROW(row, 'o')}},
    {"draw_uniform", "out[k] = the next out.shape[1] uniforms of generator rows[k].", k_draw_uniform, check_draws, HELD,
     {{"generators", 'g', 0, 'u', 0, ANY, 0}, {"rows", 'q', 'N', 'i', 1, 0.0, PY_SSIZE_T_MAX, 0}, OUT(out, 0)}},
    {"draw_robots", "robots[rows[k]] drawn from generator rows[k], up to max_draws tries; rejected[k] the refused tries.",
     k_draw_robots, check_draws, HELD,
     {{"generators", 'g', 0, 'u', 0, ANY, 0}, {"rows", 'q', 'N', 'i', 1, 0.0, PY_SSIZE_T_MAX, 0}, SPEC, ROBOT_ROW(base, 'i'), LIMITS,
      INTEGER(max_draws, 1, DRAWS_MAX), {"robots", 'B', '*', 'u', 1, ANY, 0}, {"rejected", 'q', 'N', 'o', 1, ANY, 0}}},
    {"info_columns", "Every row's info keys, each into its row of a block by spec (source, offset, kind, row); whether every contact "
                     "mode has a name.", k_info_columns, check_info, ANSWERS,
     {{"spec", 'q', '*', 'i', 4, 0.0, PY_SSIZE_T_MAX, 0}, {"out", 'O', 'N', 'i', 1, ANY, 0}, {"state", 'S', 'N', 'i', 1, ANY, 0},
      {"doubles", 'd', 'T', 'o', 1, ANY, 0}, {"ints", 'q', 'T', 'o', 1, ANY, 0}, {"flags", '?', 'T', 'o', 1, ANY, 0},
      {"vectors", 'd', 'T', 'o', 2, ANY, 0}}},
};
#define N_ENTRIES ((Py_ssize_t)(sizeof ENTRIES / sizeof ENTRIES[0]))

/* ------------------------------------------------------------------------------------------ the binder */

typedef struct {
    Py_buffer views[MAX_ARGS];
    const char *names[MAX_ARGS]; /* each view's argument */
    int written[MAX_ARGS];       /* whether the call writes it */
    int n;
} held;

static void release_all(held *h)
{
    for (int i = 0; i < h->n; i++)
        PyBuffer_Release(&h->views[i]);
    h->n = 0;
}

/* an array kind's item: its size, struct format code (0: a struct, not checked) and name */
static int item_of(char kind, Py_ssize_t *size, char *code, const char **name)
{
    static const struct { char kind, code; Py_ssize_t size; const char *name; } ITEMS[] = {
        {'d', 'd', 8, "float64"}, {'P', 'd', 8, "float64"}, {'q', 'q', 8, "int64"}, {'f', 'f', 4, "float32"}, {'?', '?', 1, "bool"},
        {'R', 0, sizeof(leg_record), "leg_record"}, {'S', 0, sizeof(env_state), "env_state"}, {'B', 0, sizeof(env_robot), "env_robot"},
        {'C', 0, sizeof(env_settings), "env_settings"}, {'O', 0, sizeof(env_out), "env_out"}};
    for (size_t k = 0; k < sizeof ITEMS / sizeof ITEMS[0]; k++)
        if (ITEMS[k].kind == kind) {
            *size = ITEMS[k].size, *code = ITEMS[k].code, *name = ITEMS[k].name;
            return 1;
        }
    return 0;
}

static int format_is(const char *f, char code)
{
    if (f == NULL)
        return 0;
    if (*f == '@' || *f == '=' || (PY_LITTLE_ENDIAN && *f == '<') || (!PY_LITTLE_ENDIAN && (*f == '>' || *f == '!')))
        f++;
    if (code == 'q') /* a 64-bit signed integer: 'q', or 'l' where long has 64 bits */
        return (f[0] == 'q' || (f[0] == 'l' && sizeof(long) == 8)) && f[1] == '\0';
    return f[0] == code && f[1] == '\0';
}

static int in_range(double v, const arg_spec *a)
{
    return a->lo > a->hi || ((a->opts & OPT_OPEN ? v > a->lo : v >= a->lo) && v <= a->hi);
}

/* 0, with an exception of type `type` (PyErr_Format's arguments) */
static int error(PyObject *type, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    PyErr_FormatV(type, format, args);
    va_end(args);
    return 0;
}

static int bad_value(const arg_spec *a, const char *what)
{
    return error(PyExc_ValueError, "%s must be %s in %s%g, %g], got %s", a->name, a->opts & OPT_WHOLE ? "a whole number" : "a value",
                        a->opts & OPT_OPEN ? "(" : "[", a->lo, a->hi, what);
}

/* Argument j of the call: an array's buffer, or a number. 0 with an exception naming it. */
static int fetch_arg(const arg_spec *a, PyObject *obj, int j, call *c, held *h)
{
    if (a->kind == 'r') {
        const double v = PyFloat_CheckExact(obj) ? PyFloat_AS_DOUBLE(obj) : PyFloat_AsDouble(obj);
        if (v == -1.0 && PyErr_Occurred())
            return PyErr_Clear(), error(PyExc_TypeError, "%s must be a real number, got %.80R", a->name, obj);
        if (!in_range(v, a) || ((a->opts & OPT_WHOLE) && v != floor(v))) {
            char text[40];
            PyOS_snprintf(text, sizeof text, "%.17g", v);
            return bad_value(a, text);
        }
        c->x[j] = v;
        return 1;
    }
    if (a->kind == 'l') {
        if ((c->k[j] = PyObject_IsTrue(obj)) < 0)
            return PyErr_Clear(), error(PyExc_TypeError, "%s must be true or false, got %.80R", a->name, obj);
        return 1;
    }
    if (a->kind == 'i') {
        PyObject *index = PyNumber_Index(obj);
        if (index == NULL)
            return PyErr_Clear(), error(PyExc_TypeError, "%s must be an integer, got %.80R", a->name, obj);
        c->k[j] = PyLong_AsSsize_t(index);
        Py_DECREF(index);
        if ((c->k[j] == -1 && PyErr_Occurred()) || !in_range((double)c->k[j], a))
            return PyErr_Clear(), bad_value(a, "another");
        return 1;
    }
    if ((a->opts & OPT_NONE) && obj == Py_None) {
        c->a[j] = NULL;
        c->rows[j] = c->cols[j] = 0;
        return 1;
    }
    Py_ssize_t size = 0;
    char code = 0;
    const char *type = "?";
    item_of(a->kind, &size, &code, &type);
    Py_buffer *v = &h->views[h->n];
    if (PyObject_GetBuffer(obj, v, PyBUF_C_CONTIGUOUS | (a->role != 'i' ? PyBUF_WRITABLE : 0) | (code ? PyBUF_FORMAT : 0)) < 0)
        return PyErr_Clear(), error(PyExc_ValueError, "%s must be a C-contiguous%s %s array, got %.80R", a->name,
                                    a->role != 'i' ? ", writable" : "", type, (PyObject *)Py_TYPE(obj));
    h->names[h->n] = a->name;
    h->written[h->n++] = a->role != 'i';
    if (v->itemsize != size || (code && !format_is(v->format, code)) || (!code && v->ndim != 1) || (uintptr_t)v->buf % (size < 8 ? size : 8))
        return error(PyExc_ValueError, "%s must be an aligned %s%s array (got format %s, item size %zd, %d dimensions, address %p)", a->name,
                     code ? "" : "1-d ", type, v->format ? v->format : "?", v->itemsize, v->ndim, v->buf);
    const Py_ssize_t items = v->len / size;
    c->a[j] = v->buf;
    c->cols[j] = a->width;
    if (a->kind == 'f' || (a->width == 0 && a->rows != 'T')) { /* a matrix: its columns are its own */
        if (v->ndim != 2 || v->shape == NULL)
            return error(PyExc_ValueError, "%s must be a 2-d array, got %d dimensions", a->name, v->ndim);
        c->rows[j] = v->shape[0];
        c->cols[j] = v->shape[1];
    } else if (a->rows == 'T') { /* blocks of N rows: (R, N) or (R, N, width) */
        const Py_ssize_t block = c->n * a->width;
        c->rows[j] = v->ndim >= 2 ? v->shape[0] : (block > 0 ? items / block : 0);
        if (items != c->rows[j] * block)
            return error(PyExc_ValueError, "%s must have shape (R, %zd%s), got %zd values", a->name, c->n, a->width > 1 ? ", 2" : "", items);
        return 1;
    } else {
        if (items % a->width != 0)
            return error(PyExc_ValueError, "%s must have shape (N, %zd), got %zd values", a->name, a->width, items);
        c->rows[j] = items / a->width;
    }
    const Py_ssize_t r = c->rows[j];
    c->step[j] = 1;
    if (a->rows == 'N' && c->n < 0)
        c->n = r;
    else if (a->rows == 'N' && r != c->n)
        return error(PyExc_ValueError, "%s must have one row per robot (%zd rows of %zd values), got %zd rows", a->name, c->n,
                             c->cols[j], r);
    else if ((a->rows == '1' || a->rows == 'M') && r != 1 && !(a->rows == 'M' && r == c->n && r > 0))
        return error(PyExc_ValueError, "%s must have 1 row%s of %zd values, got %zd", a->name, a->rows == 'M' ? " or one per robot" : "",
                             c->cols[j], r);
    if (a->rows == '1' || (a->rows == 'M' && r == 1))
        c->step[j] = 0;
    for (Py_ssize_t k = 0; strchr("qdP", a->kind) && (a->lo <= a->hi || a->kind == 'P') && k < items; k++) {
        const double f = a->kind == 'q' ? (double)((const int64_t *)v->buf)[k] : ((const double *)v->buf)[k];
        if (a->kind == 'P' && !(k % LEG_N_PARAMS == LEG_N_PARAMS - 1 ? f >= 0.0 && f < INFINITY : f > 0.0 && f < INFINITY))
            return error(PyExc_ValueError, "p: masses, inertias and lengths must be positive and finite, g finite and >= 0 "
                         "(row %zd, field %zd)", k / LEG_N_PARAMS, k % LEG_N_PARAMS); /* every division of the dynamics by them */
        if (a->kind != 'P' && !in_range(f, a)) {
            char text[60];
            PyOS_snprintf(text, sizeof text, "%.17g at entry %zd", f, k);
            return bad_value(a, text);
        }
    }
    return 1;
}

/* No array the call writes shares memory with another of its arrays: a kernel reads its inputs while it writes. */
static int no_overlap(const held *h)
{
    for (int x = 0; x < h->n; x++)
        for (int y = x + 1; y < h->n; y++) {
            const Py_buffer *u = &h->views[x], *w = &h->views[y];
            if ((h->written[x] || h->written[y]) && u->len > 0 && w->len > 0 && (const char *)u->buf < (const char *)w->buf + w->len
                && (const char *)w->buf < (const char *)u->buf + u->len)
                return error(PyExc_ValueError, "%s and %s must not share memory (%s is written)", h->names[x], h->names[y],
                                     h->written[x] ? h->names[x] : h->names[y]);
        }
    return 1;
}

/* The arguments of a call by its entry's row, fetched and checked into c (buffers held in h); 0 with an exception. */
static int bind(const entry *e, PyObject *const *args, Py_ssize_t nargs, call *c, held *h)
{
    Py_ssize_t want = 0;
    while (want < MAX_ARGS && e->args[want].name != NULL)
        want++;
    if (nargs != want)
        return error(PyExc_TypeError, "%s takes %zd arguments, got %zd", e->name, want, nargs);
    c->n = -1;
    c->result = 0;
    for (Py_ssize_t j = 0; j < nargs; j++)
        if (!((c->o[j] = args[j]) && e->args[j].kind == 'g') && !fetch_arg(&e->args[j], args[j], (int)j, c, h))
            return 0;
    if (c->n < 0)
        c->n = 1;
    return no_overlap(h) && (e->check == NULL || e->check(c));
}

/* A call's (or a method's) arguments by its entry: `call c` and `held h` bound, or the function returns NULL. */
#define BIND(e)                                                                                                        \
    call c;                                                                                                            \
    held h;                                                                                                            \
    h.n = 0;                                                                                                           \
    memset(c.a, 0, sizeof c.a);                                                                                        \
    if (!bind(&(e), args, nargs, &c, &h))                                                                              \
        return release_all(&h), NULL;

/* Every entry point: self is its row's index. */
static PyObject *dispatch(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    const entry *e = &ENTRIES[PyLong_AsSsize_t(self)];
    BIND(*e)
    if (e->release) {
        Py_BEGIN_ALLOW_THREADS
        e->run(&c);
        Py_END_ALLOW_THREADS
    } else {
        e->run(&c);
    }
    release_all(&h);
    return e->answers ? PyBool_FromLong(c.result) : Py_NewRef(Py_None);
}

/* ------------------------------------------------------------------------------------------ the checks */

/* The values an environment's step relies on: its settings (a step that terminates) and, if `modes`, every robot's
 * contact mode (and the one an undone step restores); the observation's width for the task. The robots' rows are
 * checked where they are written (LegParams, leg_env.randomize), not at every step: a non-physical robot gives a
 * numerical failure, never a fault. */
static int env_values(const env_batch *b, int task, int modes)
{
    const env_settings *s = b->settings;
    if (!(s->dt > 0.0 && s->dt < INFINITY && s->substeps >= 1 && s->substeps <= LEG_MAX_SUBSTEPS && s->max_angle > 0.0 && s->max_rate > 0.0
          && s->motor_speed > 0.0))
        return error(PyExc_ValueError, "settings: dt, substeps, max_angle, max_rate or motor_speed out of range");
    for (Py_ssize_t i = 0; modes && i < b->n; i++)
        if (b->state[i].mode < LEG_STICK || b->state[i].mode > LEG_FLIGHT || b->state[i].prev_mode < LEG_STICK || b->state[i].prev_mode > LEG_FLIGHT)
            return error(PyExc_ValueError, "state row %zd: the contact modes must be 0, 1, 2 or 3, got %d (prev_mode %d)", i,
                                 (int)b->state[i].mode, (int)b->state[i].prev_mode);
    if (task != TASK_STANCE && !s->unilateral)
        return error(PyExc_ValueError, "settings: task %d needs the unilateral ground (settings[\"unilateral\"])", task);
    if (b->obs_cols != task_obs_dim(task, s))
        return error(PyExc_ValueError, "obs must have shape (%zd, %zd) for task %d, its ground and observe_action, got (%zd, %zd)", b->n,
                     task_obs_dim(task, s), task, b->n, b->obs_cols);
    return 1;
}

static int env_ok(const call *c, int first, int modes)
{
    const env_batch b = batch_at(c, first);
    return env_values(&b, (int)c->k[0], modes);
}

static int check_start(call *c) { return env_ok(c, 1, 0); }
static int check_assess(call *c) { return env_ok(c, 1, 1); }

static int check_step(call *c)
{
    if (!(c->k[1] <= c->k[2] && c->k[2] <= c->n))
        return error(PyExc_ValueError, "rows lo .. hi must satisfy 0 <= lo <= hi <= %zd, got %zd .. %zd", c->n, c->k[1], c->k[2]);
    return env_ok(c, 3, 1);
}

/* Argument j (if not None) has `per_step` values a step of a plan of H steps, and `extra` more. */
static int plan_cols(const call *c, int j, const char *name, Py_ssize_t H, Py_ssize_t per_step, Py_ssize_t extra)
{
    if (c->a[j] == NULL || c->cols[j] == per_step * H + extra)
        return 1;
    return error(PyExc_ValueError, "%s must have %zd columns (%zd a step of the plan's %zd, and %zd), got %zd", name, per_step * H + extra,
                 per_step, H, extra, c->cols[j]);
}

static int check_hop_rollout(call *c)
{
    const Py_ssize_t H = c->cols[RO_CORRECTIONS] / PLAN_NU;
    if (H < 1 || c->cols[RO_CORRECTIONS] % PLAN_NU != 0 || H > INT32_MAX / (PLAN_NX * PLAN_NX))
        return error(PyExc_ValueError, "corrections must have 2 H columns (H >= 1 steps of 2 actions), got %zd", c->cols[RO_CORRECTIONS]);
    return plan_cols(c, RO_K, "k", H, PLAN_NU, 0) && plan_cols(c, RO_KK, "K", H, PLAN_NU * PLAN_NX, 0)
           && plan_cols(c, RO_NOMINAL, "nominal", H, PLAN_NX, PLAN_NX) && plan_cols(c, RO_X, "X", H, PLAN_NX, PLAN_NX)
           && plan_cols(c, RO_MODES, "modes", H, 1, 1) && plan_cols(c, RO_U, "U", H, PLAN_NU, 0) && plan_cols(c, RO_V, "V", H, PLAN_NU, 0)
           && plan_cols(c, RO_FLIGHT_TIME, "flight_time", H, 1, 0) && plan_cols(c, RO_A, "A", H, PLAN_NX * PLAN_NX, 0)
           && plan_cols(c, RO_B, "B", H, PLAN_NX * PLAN_NU, 0) && plan_cols(c, RO_DU, "Du", H, PLAN_NU * PLAN_NX, 0)
           && plan_cols(c, RO_D, "D", H, PLAN_NU, 0);
}

static int check_ilqr_backward(call *c)
{
    const Py_ssize_t H = c->cols[BW_V] / PLAN_NU;
    if (H < 1 || c->cols[BW_V] % PLAN_NU != 0 || H > INT32_MAX / (PLAN_NX * PLAN_NX))
        return error(PyExc_ValueError, "V must have 2 H columns (H >= 1 steps of 2 actions), got %zd", c->cols[BW_V]);
    return plan_cols(c, BW_LX, "lx", H, PLAN_NX, 0) && plan_cols(c, BW_LXX, "lxx", H, PLAN_NX * PLAN_NX, 0)
           && plan_cols(c, BW_A, "A", H, PLAN_NX * PLAN_NX, 0) && plan_cols(c, BW_B, "B", H, PLAN_NX * PLAN_NU, 0)
           && plan_cols(c, BW_D, "D", H, PLAN_NU, 0) && plan_cols(c, BW_DU, "Du", H, PLAN_NU * PLAN_NX, 0)
           && plan_cols(c, BW_X, "X", H, PLAN_NX, PLAN_NX) && plan_cols(c, BW_U, "U", H, PLAN_NU, 0)
           && plan_cols(c, BW_K, "k", H, PLAN_NU, 0) && plan_cols(c, BW_KK, "K", H, PLAN_NU * PLAN_NX, 0);
}

/* A randomisation's spec: (F, 4) rows (the field's index among env_robot's doubles, kind, low, high), every index a
 * drawn field's (a parameter, mu or a torque limit). */
static int spec_ok(const double *spec, Py_ssize_t rows)
{
    if (rows > ROBOT_DRAWN_MAX)
        return error(PyExc_ValueError, "spec must have at most %d rows, got %zd", ROBOT_DRAWN_MAX, rows);
    for (Py_ssize_t f = 0; f < rows; f++) {
        const double col = spec[4 * f], kind = spec[4 * f + 1];
        if (!(col >= 0.0 && col < ROBOT_DRAWN_FIELDS && col == floor(col)) || !(kind == 0.0 || kind == 1.0 || kind == 2.0))
            return error(PyExc_ValueError, "spec row %zd: the field must be a drawn one's index in [0, %g) and kind 0, 1 or 2", f,
                                 ROBOT_DRAWN_FIELDS);
    }
    return 1;
}

static int check_robot_params(call *c)
{
    if (c->rows[0] != c->rows[1])
        return error(PyExc_ValueError, "u must have one value per spec row (%zd), got %zd", c->rows[1], c->rows[0]);
    return spec_ok((const double *)c->a[1], c->rows[1]);
}

static PyTypeObject GeneratorsType;
typedef struct {
    PyObject_HEAD Py_ssize_t n;
    PyObject **owners; /* the BitGenerators (NULL: not set) */
    bitgen_t **bg;     /* their C interfaces */
} GeneratorsObject;

/* draw_uniform and draw_robots: a Generators whose rows are set, in range; draw_robots' spec and robots' rows. */
static int check_draws(call *c)
{
    if (!Py_IS_TYPE((PyObject *)c->o[0], &GeneratorsType))
        return error(PyExc_TypeError, "generators must be a Generators, got %.80R", (PyObject *)Py_TYPE((PyObject *)c->o[0]));
    const GeneratorsObject *G = (const GeneratorsObject *)c->o[0];
    const int robots = c->a[6] != NULL; /* draw_robots */
    for (Py_ssize_t k = 0; k < c->n; k++) {
        const int64_t row = ((const int64_t *)c->a[1])[k];
        if (row >= G->n || G->bg[row] == NULL)
            return error(PyExc_ValueError, "rows[%zd] = %lld is not a set row of generators", k, (long long)row);
        if (robots && row >= c->rows[6])
            return error(PyExc_ValueError, "rows[%zd] = %lld is not a row of robots", k, (long long)row);
    }
    c->o[0] = G->bg; /* what the draws read: the held pointers */
    return !robots || spec_ok((const double *)c->a[2], c->rows[2]);
}

/* info's spec rows (source 0 out, 1 state; byte offset; kind; row of its block) read inside their struct and write
 * inside their block (the rows of each kind's block: `rows`, or none to check). */
static int info_spec_ok(const int64_t *spec, Py_ssize_t m, const Py_ssize_t *rows)
{
    static const char *const BLOCKS[N_INFO_KINDS] = {"doubles", "ints", "flags", "vectors", "ints"};
    for (Py_ssize_t k = 0; k < m; k++) {
        const int64_t *e = spec + 4 * k;
        if (!(e[0] == 0 || e[0] == 1) || !(e[2] >= 0 && e[2] < N_INFO_KINDS))
            return error(PyExc_ValueError, "spec row %zd: the source must be 0 (out) or 1 (state) and the kind 0 .. %d", k, N_INFO_KINDS - 1);
        if (e[1] < 0 || e[1] + (int64_t)INFO_BYTES[e[2]] > (e[0] == 0 ? (int64_t)sizeof(env_out) : (int64_t)sizeof(env_state)))
            return error(PyExc_ValueError, "spec row %zd reads outside its %s row", k, e[0] == 0 ? "out" : "state");
        if (rows != NULL && e[3] >= rows[e[2]])
            return error(PyExc_ValueError, "spec row %zd writes row %lld of %s, which has %zd", k, (long long)e[3], BLOCKS[e[2]], rows[e[2]]);
    }
    return 1;
}

static int check_info(call *c)
{
    const Py_ssize_t rows[N_INFO_KINDS] = {c->rows[3], c->rows[4], c->rows[5], c->rows[6], c->rows[4]};
    return info_spec_ok((const int64_t *)c->a[0], c->rows[0], rows);
}

#include "objects.c"

/* ------------------------------------------------------------------------------------------ reports */

static int put(PyObject *dict, const char *key, PyObject *value) /* steals value */
{
    const int ok = value != NULL && PyDict_SetItemString(dict, key, value) == 0;
    Py_XDECREF(value);
    return ok;
}

/* table(): {name: (doc, releases_gil, answers, ((name, kind, rows, role, width, itemsize, lo, hi, opts), ...))}, every row
 * of the table of entry points as the binder reads it (leg_env._core.signatures() names its parts) */
static PyObject *py_table(PyObject *self, PyObject *unused)
{
    PyObject *out = PyDict_New();
    for (Py_ssize_t k = 0; out != NULL && k < N_ENTRIES; k++) {
        const entry *e = &ENTRIES[k];
        PyObject *args = PyTuple_New(0);
        for (int j = 0; args != NULL && j < MAX_ARGS && e->args[j].name != NULL; j++) {
            const arg_spec *a = &e->args[j];
            Py_ssize_t size = 0;
            char code;
            const char *type;
            item_of(a->kind, &size, &code, &type);
            PyObject *row = Py_BuildValue("((sCCCnnddi))", a->name, a->kind, a->rows ? a->rows : ' ', a->role, a->width, size, a->lo, a->hi, a->opts);
            Py_XSETREF(args, row ? PySequence_Concat(args, row) : NULL);
            Py_XDECREF(row);
        }
        if (args == NULL || !put(out, e->name, Py_BuildValue("(siiN)", e->doc, e->release, e->answers, args)))
            Py_CLEAR(out);
    }
    return out;
}

static const struct {
    const char *name;
    const field_layout *fields;
    size_t size;
} STRUCTS[] = {
#define STRUCT(name, type, FIELDS, path) {name, (const field_layout[]){FIELDS(FIELD_LAYOUT, type, path){NULL, 0, NULL, 0, NULL}}, sizeof(type)}
    STRUCT("leg_params", leg_params, LEG_PARAMS_FIELDS, ),
    STRUCT("leg_record", leg_record, LEG_RECORD_FIELDS, ),
    STRUCT("env_state", env_state, ENV_STATE_FIELDS, ),
    STRUCT("env_state.push", env_state, PUSH_STATE_FIELDS, task.push.),
    STRUCT("env_state.hop", env_state, HOP_STATE_FIELDS, task.hop.),
    STRUCT("env_robot", env_robot, ENV_ROBOT_FIELDS, ),
    STRUCT("env_settings", env_settings, ENV_SETTINGS_FIELDS, ),
    STRUCT("env_settings.push", env_settings, PUSH_SETTINGS_FIELDS, task.push.),
    STRUCT("env_settings.hop", env_settings, HOP_SETTINGS_FIELDS, task.hop.),
    STRUCT("env_out", env_out, ENV_OUT_FIELDS, ),
    STRUCT("env_out.push", env_out, PUSH_OUT_FIELDS, task.push.),
};

/* layouts(): {struct: (itemsize, [(field, offset, numpy type or struct, count, doc)])}; "env_state.push" and the like
 * are a task's fields of the struct's union (offsets from the struct's start) */
static PyObject *py_layouts(PyObject *self, PyObject *unused)
{
    PyObject *dict = PyDict_New();
    for (size_t k = 0; dict != NULL && k < sizeof STRUCTS / sizeof STRUCTS[0]; k++) {
        PyObject *list = PyList_New(0);
        for (const field_layout *f = STRUCTS[k].fields; list != NULL && f->name; f++) {
            PyObject *item = Py_BuildValue("(snsns)", f->name, (Py_ssize_t)f->offset, f->type, (Py_ssize_t)f->count, f->doc);
            if (item == NULL || PyList_Append(list, item) < 0)
                Py_CLEAR(list);
            Py_XDECREF(item);
        }
        if (list == NULL || !put(dict, STRUCTS[k].name, Py_BuildValue("(nN)", (Py_ssize_t)STRUCTS[k].size, list)))
            Py_CLEAR(dict);
    }
    return dict;
}

/* observation(): {name: column} of the observation's entries (obs_index of env.h) and the widths */
static PyObject *py_observation(PyObject *self, PyObject *unused)
{
#define OBS(name, NAME) {#name, NAME}
    static const struct { const char *name; int column; } COLUMNS[] = {
        OBS(base_x, OBS_BASE_X), OBS(base_y, OBS_BASE_Y), OBS(th_b, OBS_TH_B), OBS(q1, OBS_Q1), OBS(q2, OBS_Q2), OBS(vx_b, OBS_VX_B),
        OBS(vy_b, OBS_VY_B), OBS(w_b, OBS_W_B), OBS(w_q1, OBS_W_Q1), OBS(w_q2, OBS_W_Q2), OBS(lam_x, OBS_LAM_X), OBS(lam_y, OBS_LAM_Y),
        OBS(foot_height, OBS_FOOT_HEIGHT), OBS(foot_vx, OBS_FOOT_VX), OBS(foot_vy, OBS_FOOT_VY), OBS(contact, OBS_CONTACT), OBS(slip, OBS_SLIP),
        OBS(impulse_y, OBS_IMPULSE_Y), OBS(command, OBS_COMMAND), OBS(com_drift, OBS_COM_DRIFT), OBS(ground_time, OBS_GROUND_TIME),
        OBS(last_apex, OBS_LAST_APEX), OBS(push_com_drift, OBS_PUSH_COM_DRIFT), OBS(pinned_dim, OBS_PINNED_DIM),
        OBS(unilateral_dim, OBS_UNILATERAL_DIM), OBS(hop_dim, OBS_HOP_DIM), OBS(push_dim, OBS_PUSH_DIM)};
    PyObject *dict = PyDict_New();
    for (size_t k = 0; dict != NULL && k < sizeof COLUMNS / sizeof COLUMNS[0]; k++)
        if (!put(dict, COLUMNS[k].name, PyLong_FromLong(COLUMNS[k].column)))
            Py_CLEAR(dict);
    return dict;
}

/* ------------------------------------------------------------------------------------------ the module */

static PyMethodDef REPORTS[] = {
    {"table", (PyCFunction)py_table, METH_NOARGS, "table(): every entry point's row of the table the binder reads."},
    {"layouts", (PyCFunction)py_layouts, METH_NOARGS, "layouts(): {struct: (itemsize, [(field, offset, type, count, doc)])}."},
    {"observation", (PyCFunction)py_observation, METH_NOARGS, "observation(): the observation's columns by name."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "kernels", "The compiled core of leg-env: the planar leg's dynamics, contact and time stepping in C.", -1, REPORTS,
};

static PyMethodDef ENTRY_METHODS[N_ENTRIES]; /* every entry point: dispatch, with its row's index as self */
static char ENTRY_DOCS[N_ENTRIES][512];

#define ENDING_NAME(NAME, name) #name,
static const char *const ENDING_NAMES[N_ENDINGS] = {ENV_ENDINGS(ENDING_NAME)};

PyMODINIT_FUNC PyInit_kernels(void)
{
    static const struct { const char *name; long value; } INTS[] = {
        {"MAX_SUBSTEPS", LEG_MAX_SUBSTEPS}, {"LOG_SIZE", LEG_LOG_SIZE}, {"MAX_EVENTS", LEG_MAX_EVENTS}, {"MAX_TERMS", MAX_TERMS},
        {"PUSH_MAX", PUSH_MAX}, {"MAX_ROWS", MAX_ROWS}, {"STICK", LEG_STICK}, {"SLIP_FORWARD", LEG_SLIP_FORWARD},
        {"SLIP_BACKWARD", LEG_SLIP_BACKWARD}, {"FLIGHT", LEG_FLIGHT}, {"LIFTOFF", LEG_LIFTOFF}, {"SLIP_ONSET", LEG_SLIP_ONSET},
        {"SLIDING_STOP", LEG_SLIDING_STOP}, {"TOUCHDOWN", LEG_TOUCHDOWN}, {"INFO_DOUBLE", INFO_DOUBLE}, {"INFO_INT", INFO_INT},
        {"INFO_FLAG", INFO_FLAG}, {"INFO_VECTOR", INFO_VECTOR}, {"INFO_MODE", INFO_MODE}};
    static const struct { const char *name; double value; } DOUBLES[] = {
        {"GROUND_TOL", LEG_GROUND_TOL}, {"SETTLE_SPEED", LEG_SETTLE_SPEED}, {"ROOT_TIME", LEG_ROOT_TIME}, {"REST_SPEED", LEG_REST_SPEED},
        {"TURN_MAX", LEG_TURN_MAX}};
    if (PyType_Ready(&BatchType) < 0 || PyType_Ready(&GeneratorsType) < 0)
        return NULL;
    name_capsule = PyUnicode_InternFromString("capsule");
    name_bit_generator = PyUnicode_InternFromString("bit_generator");
    PyObject *m = name_capsule && name_bit_generator ? PyModule_Create(&module) : NULL;
    if (m == NULL || PyModule_AddObjectRef(m, "Batch", (PyObject *)&BatchType) < 0 || PyModule_AddObjectRef(m, "Generators", (PyObject *)&GeneratorsType) < 0)
        goto fail;
    for (Py_ssize_t k = 0; k < N_ENTRIES; k++) {
        const entry *e = &ENTRIES[k];
        int used = PyOS_snprintf(ENTRY_DOCS[k], sizeof ENTRY_DOCS[k], "%s(", e->name); /* the signature inspect reads, then the doc */
        for (int j = 0; j < MAX_ARGS && e->args[j].name; j++)
            used += PyOS_snprintf(ENTRY_DOCS[k] + used, sizeof ENTRY_DOCS[k] - used, "%s%s", j ? ", " : "", e->args[j].name);
        PyOS_snprintf(ENTRY_DOCS[k] + used, sizeof ENTRY_DOCS[k] - used, ")\n--\n\n%s", e->doc);
        ENTRY_METHODS[k] = (PyMethodDef){e->name, (PyCFunction)(void (*)(void))dispatch, METH_FASTCALL, ENTRY_DOCS[k]};
        PyObject *index = PyLong_FromSsize_t(k), *fn = index ? PyCFunction_NewEx(&ENTRY_METHODS[k], index, PyModule_GetNameObject(m)) : NULL;
        Py_XDECREF(index);
        if (fn == NULL || PyModule_AddObject(m, e->name, fn) < 0) {
            Py_XDECREF(fn);
            goto fail;
        }
    }
    for (size_t k = 0; k < sizeof INTS / sizeof INTS[0]; k++)
        if (PyModule_AddIntConstant(m, INTS[k].name, INTS[k].value) < 0)
            goto fail;
    for (size_t k = 0; k < sizeof DOUBLES / sizeof DOUBLES[0]; k++)
        if (!put(PyModule_GetDict(m), DOUBLES[k].name, PyFloat_FromDouble(DOUBLES[k].value)))
            goto fail;
    PyObject *endings = PyTuple_New(N_ENDINGS);
    for (int k = 0; endings != NULL && k < N_ENDINGS; k++)
        PyTuple_SET_ITEM(endings, k, PyUnicode_FromString(ENDING_NAMES[k]));
    if (endings == NULL || PyModule_AddObject(m, "ENDINGS", endings) < 0) {
        Py_XDECREF(endings);
        goto fail;
    }
    return m;
fail:
    Py_XDECREF(m);
    return NULL;
}
