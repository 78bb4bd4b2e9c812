/* leg_env._core.kernels: the compiled core of leg-env, a CPython extension module.
 *
 * One translation unit (a unity build: the physics files are included below), so that the compiler
 * inlines the small math functions across files without link-time optimisation on any platform.
 *
 * Every function takes numpy arrays (any object with the buffer protocol) and loops over robots in C
 * with the GIL released. The Python wrappers (leg_env.dynamics, contact, integrate, hybrid) broadcast
 * and validate values; this file checks every buffer once more (type, C order, writability, size),
 * so that no call, however wrong, reads or writes past an array: a mistake is a Python exception that
 * names the argument.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

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
#include "hybrid.c"
#include "env.c"
#include "tasks.c"
#include "draws.c"

/* leg_params is LegParams.array as it is: eleven doubles, no padding */
typedef char leg_params_is_eleven_doubles[sizeof(leg_params) == 11 * sizeof(double) ? 1 : -1];

/* ------------------------------------------------------------------------------------------------
 * Buffers
 * ------------------------------------------------------------------------------------------------ */

#define MAX_BUFFERS 16

typedef struct {
    Py_buffer views[MAX_BUFFERS];
    int n;
} held;

static void release_all(held *h)
{
    for (int i = 0; i < h->n; i++)
        PyBuffer_Release(&h->views[i]);
    h->n = 0;
}

enum kind { F64, I64, F32, BOOL, U32, RECORD };

static const char *const KIND_NAME[] = {"float64", "int64", "float32", "bool", "uint32", "leg_record"};
static const char KIND_CODE[] = {'d', 'q', 'f', '?', 'I', 0};
static const Py_ssize_t KIND_SIZE[] = {8, 8, 4, 1, 4, (Py_ssize_t)sizeof(leg_record)};

static int format_is(const Py_buffer *v, char code)
{
    const char *f = v->format;
    if (f == NULL)
        return 0;
    if (*f == '@' || *f == '=')
        f++;
#if PY_LITTLE_ENDIAN
    else if (*f == '<')
        f++;
#else
    else if (*f == '>' || *f == '!')
        f++;
#endif
    if (code == 'q') /* a 64-bit signed integer: 'q', or 'l' where long has 64 bits */
        return (f[0] == 'q' || (f[0] == 'l' && sizeof(long) == 8)) && f[1] == '\0';
    return f[0] == code && f[1] == '\0';
}

/* The buffer of `obj`: C-contiguous, of the kind, writable if asked. NULL with a ValueError naming `name`. */
static Py_buffer *view_of(PyObject *obj, const char *name, enum kind kind, int writable, held *h)
{
    if (h->n >= MAX_BUFFERS) {
        PyErr_SetString(PyExc_RuntimeError, "leg_env._core.kernels: too many buffers in one call");
        return NULL;
    }
    const int flags = PyBUF_C_CONTIGUOUS | (writable ? PyBUF_WRITABLE : 0) | (kind == RECORD ? 0 : PyBUF_FORMAT);
    Py_buffer *v = &h->views[h->n];
    if (PyObject_GetBuffer(obj, v, flags) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "%s must be a C-contiguous%s %s array, got %.80R", name, writable ? ", writable" : "",
                     KIND_NAME[kind], (PyObject *)Py_TYPE(obj));
        return NULL;
    }
    h->n++;
    if (v->itemsize != KIND_SIZE[kind] || (kind != RECORD && !format_is(v, KIND_CODE[kind]))) {
        PyErr_Format(PyExc_ValueError, "%s must be a %s array (got format %s, item size %zd)", name, KIND_NAME[kind],
                     v->format ? v->format : "?", v->itemsize);
        return NULL;
    }
    return v;
}

/* The data of `obj`, a C-contiguous buffer of `count` items of the kind (count < 0: any multiple of
 * -count, returned in *rows as count / -count). NULL with a Python exception naming `name` otherwise. */
static void *buffer_of(PyObject *obj, const char *name, enum kind kind, Py_ssize_t count, int writable, held *h,
                       Py_ssize_t *rows)
{
    Py_buffer *v = view_of(obj, name, kind, writable, h);
    if (v == NULL)
        return NULL;
    const Py_ssize_t items = v->len / v->itemsize;
    if (count < 0) {
        if (items % (-count) != 0) {
            PyErr_Format(PyExc_ValueError, "%s must have shape (N, %zd), got %zd values", name, -count, items);
            return NULL;
        }
        *rows = items / (-count);
    } else if (items != count) {
        PyErr_Format(PyExc_ValueError, "%s must have %zd values, got %zd", name, count, items);
        return NULL;
    }
    return v->buf;
}

/* The data of `obj`, a 2-d C-contiguous buffer of the kind: its rows and columns in *rows, *cols. */
static void *matrix_of(PyObject *obj, const char *name, enum kind kind, int writable, held *h, Py_ssize_t *rows,
                       Py_ssize_t *cols)
{
    Py_buffer *v = view_of(obj, name, kind, writable, h);
    if (v == NULL)
        return NULL;
    if (v->ndim != 2 || v->shape == NULL) {
        PyErr_Format(PyExc_ValueError, "%s must be a 2-d array, got %d dimensions", name, v->ndim);
        return NULL;
    }
    *rows = v->shape[0];
    *cols = v->shape[1];
    return v->buf;
}

#define F64_IN(obj, name, count) ((const double *)buffer_of((obj), (name), F64, (count), 0, &h, NULL))
#define F64_OUT(obj, name, count) ((double *)buffer_of((obj), (name), F64, (count), 1, &h, NULL))
#define I64_OUT(obj, name, count) ((int64_t *)buffer_of((obj), (name), I64, (count), 1, &h, NULL))

/* The robots' parameters: one row shared by every robot, or a row each (a randomised batch). Every
 * value must be a physical one: a non-positive or non-finite mass, inertia or length is refused, so
 * that no division in the kernels is by zero by construction of the parameters. */
static const leg_params *params_of(PyObject *obj, Py_ssize_t n, Py_ssize_t *stride, held *h)
{
    Py_ssize_t rows = 0;
    const leg_params *P = (const leg_params *)buffer_of(obj, "p", F64, -11, 0, h, &rows);
    if (P == NULL)
        return NULL;
    if (rows != 1 && rows != n) {
        PyErr_Format(PyExc_ValueError, "p must have 1 row or one per robot (%zd), got %zd", n, rows);
        return NULL;
    }
    for (Py_ssize_t i = 0; i < rows; i++) {
        const double *f = (const double *)&P[i];
        for (int j = 0; j < 10; j++)
            if (!(f[j] > 0.0 && f[j] < INFINITY)) {
                PyErr_Format(PyExc_ValueError, "p: masses, inertias and lengths must be positive and finite (row %zd)", i);
                return NULL;
            }
        if (!(f[10] >= 0.0 && f[10] < INFINITY)) {
            PyErr_Format(PyExc_ValueError, "p: g must be finite and >= 0 (row %zd)", i);
            return NULL;
        }
    }
    *stride = rows == 1 ? 0 : 1;
    return P;
}

static int n_args(Py_ssize_t nargs, Py_ssize_t want, const char *fn)
{
    if (nargs != want) {
        PyErr_Format(PyExc_TypeError, "%s takes %zd arguments, got %zd", fn, want, nargs);
        return 0;
    }
    return 1;
}

static int as_double(PyObject *obj, const char *name, double *out)
{
    *out = PyFloat_AsDouble(obj);
    if (*out == -1.0 && PyErr_Occurred()) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be a real number, got %.80R", name, obj);
        return 0;
    }
    return 1;
}

/* The truth of `obj` (a flag argument); 0 with a TypeError naming `name` if it has none (an array of
 * several values, or an object whose __bool__ raises). */
static int as_bool(PyObject *obj, const char *name, int *out)
{
    *out = PyObject_IsTrue(obj);
    if (*out < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be true or false, got %.80R", name, obj);
        return 0;
    }
    return 1;
}

/* The step rule's settings, checked: dt > 0 finite, 1 <= substeps <= LEG_MAX_SUBSTEPS, max_angle > 0. */
static int step_rule(PyObject *const *args, double *dt, int *substeps, double *max_angle)
{
    double s;
    if (!as_double(args[0], "dt", dt) || !as_double(args[1], "substeps", &s) || !as_double(args[2], "max_angle", max_angle))
        return 0;
    if (!(*dt > 0.0 && *dt < INFINITY)) {
        PyErr_SetString(PyExc_ValueError, "dt must be positive and finite");
        return 0;
    }
    if (!(s >= 1.0 && s <= LEG_MAX_SUBSTEPS && s == floor(s))) {
        PyErr_Format(PyExc_ValueError, "substeps must be a whole number in [1, %d]", LEG_MAX_SUBSTEPS);
        return 0;
    }
    if (!(*max_angle > 0.0)) {
        PyErr_SetString(PyExc_ValueError, "max_angle must be positive (inf for fixed steps)");
        return 0;
    }
    *substeps = (int)s;
    return 1;
}

#define BEGIN                                                                                                          \
    held h;                                                                                                            \
    h.n = 0;                                                                                                           \
    Py_ssize_t n = 0, ps = 0;                                                                                          \
    (void)ps;                                                                                                          \
    (void)n;

#define FAIL                                                                                                           \
    fail:                                                                                                              \
    release_all(&h);                                                                                                   \
    return NULL;

#define ROBOTS(obj) /* q (N, 5) of the first argument sets the number of robots */                                    \
    const double *q = (const double *)buffer_of((obj), "q", F64, -LEG_NQ, 0, &h, &n);                                  \
    if (q == NULL)                                                                                                     \
        goto fail;

#define CHECK(x)                                                                                                       \
    if ((x) == NULL)                                                                                                   \
        goto fail;

#define DONE                                                                                                           \
    release_all(&h);                                                                                                   \
    Py_RETURN_NONE;

/* ------------------------------------------------------------------------------------------------
 * The dynamics (leg_env.dynamics)
 * ------------------------------------------------------------------------------------------------ */

static PyObject *py_mass_matrix(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 3, "mass_matrix"))
        return NULL;
    ROBOTS(args[0])
    const leg_params *P = params_of(args[1], n, &ps, &h);
    CHECK(P)
    double *M = F64_OUT(args[2], "M", n * LEG_NQ * LEG_NQ);
    CHECK(M)
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++)
        mass_matrix_one(P + i * ps, q + i * LEG_NQ, M + i * LEG_NQ * LEG_NQ);
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

static PyObject *py_bias(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 5, "bias"))
        return NULL;
    ROBOTS(args[0])
    const double *qd = F64_IN(args[1], "qd", n * LEG_NQ);
    CHECK(qd)
    const leg_params *P = params_of(args[2], n, &ps, &h);
    CHECK(P)
    double *out = F64_OUT(args[3], "h", n * LEG_NQ);
    CHECK(out)
    int gravity_only;
    if (!as_bool(args[4], "gravity_only", &gravity_only))
        goto fail;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++)
        bias_one(P + i * ps, q + i * LEG_NQ, qd + i * LEG_NQ, gravity_only, out + i * LEG_NQ);
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

/* foot(q, p, out), jacobian(q, p, Jc): functions of the configuration only */
#define CONFIGURATION_FUNCTION(pyname, name, fn, width, outname)                                                       \
    static PyObject *pyname(PyObject *self, PyObject *const *args, Py_ssize_t nargs)                                   \
    {                                                                                                                  \
        BEGIN                                                                                                          \
        if (!n_args(nargs, 3, name))                                                                                   \
            return NULL;                                                                                               \
        ROBOTS(args[0])                                                                                                \
        const leg_params *P = params_of(args[1], n, &ps, &h);                                                          \
        CHECK(P)                                                                                                       \
        double *out = F64_OUT(args[2], outname, n * (width));                                                          \
        CHECK(out)                                                                                                     \
        Py_BEGIN_ALLOW_THREADS for (Py_ssize_t i = 0; i < n; i++) fn(P + i * ps, q + i * LEG_NQ, out + i * (width));   \
        Py_END_ALLOW_THREADS DONE FAIL                                                                                 \
    }

CONFIGURATION_FUNCTION(py_foot, "foot", foot_one, 2, "out")
CONFIGURATION_FUNCTION(py_jacobian, "jacobian", jacobian_one, 2 * LEG_NQ, "Jc")

static PyObject *py_jdot_qd(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 4, "jdot_qd"))
        return NULL;
    ROBOTS(args[0])
    const double *qd = F64_IN(args[1], "qd", n * LEG_NQ);
    CHECK(qd)
    const leg_params *P = params_of(args[2], n, &ps, &h);
    CHECK(P)
    double *out = F64_OUT(args[3], "out", n * 2);
    CHECK(out)
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++)
        jdot_qd_one(P + i * ps, q + i * LEG_NQ, qd + i * LEG_NQ, out + i * 2);
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

/* com(q, qd, p, position, velocity): the whole-body centre of mass and its velocity */
static PyObject *py_com(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 5, "com"))
        return NULL;
    ROBOTS(args[0])
    const double *qd = F64_IN(args[1], "qd", n * LEG_NQ);
    CHECK(qd)
    const leg_params *P = params_of(args[2], n, &ps, &h);
    CHECK(P)
    double *pos = F64_OUT(args[3], "position", n * 2);
    CHECK(pos)
    double *vel = F64_OUT(args[4], "velocity", n * 2);
    CHECK(vel)
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++)
        com_one(P + i * ps, q + i * LEG_NQ, qd + i * LEG_NQ, pos + i * 2, vel + i * 2);
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

static PyObject *py_energy(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 4, "energy"))
        return NULL;
    ROBOTS(args[0])
    const double *qd = F64_IN(args[1], "qd", n * LEG_NQ);
    CHECK(qd)
    const leg_params *P = params_of(args[2], n, &ps, &h);
    CHECK(P)
    double *out = F64_OUT(args[3], "out", n);
    CHECK(out)
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double s1, co1, s2, co2;
        const double *qi = q + i * LEG_NQ, *v = qd + i * LEG_NQ;
        leg_trig(qi, &s1, &co1, &s2, &co2);
        const double w1 = v[2] + v[3];
        out[i] = energy_core(P + i * ps, s1, co1, s2, co2, qi[1], v[0], v[1], v[2], w1, w1 + v[4]);
    }
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

/* stance(q, qd, tau, p, load, qdd, lam), flight(q, qd, tau, p, load, qdd); load: the horizontal force on
 * the torso's COM of each robot [N] */
static PyObject *mode_dynamics(PyObject *const *args, Py_ssize_t nargs, int mode, const char *fn)
{
    BEGIN
    const int with_lam = mode != LEG_FLIGHT;
    if (!n_args(nargs, with_lam ? 7 : 6, fn))
        return NULL;
    ROBOTS(args[0])
    const double *qd = F64_IN(args[1], "qd", n * LEG_NQ);
    CHECK(qd)
    const double *tau = F64_IN(args[2], "tau", n * LEG_NU);
    CHECK(tau)
    const leg_params *P = params_of(args[3], n, &ps, &h);
    CHECK(P)
    const double *load = F64_IN(args[4], "load", n);
    CHECK(load)
    double *qdd = F64_OUT(args[5], "qdd", n * LEG_NQ);
    CHECK(qdd)
    double *lam = NULL;
    if (with_lam) {
        lam = F64_OUT(args[6], "lam", n * 2);
        CHECK(lam)
    }
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double s1, co1, s2, co2;
        const double *v = qd + i * LEG_NQ;
        leg_trig(q + i * LEG_NQ, &s1, &co1, &s2, &co2);
        const double w1 = v[2] + v[3], w2 = w1 + v[4];
        const double *t = tau + i * LEG_NU;
        const leg_accel A = mode == LEG_STICK ? stance_core(P + i * ps, s1, co1, s2, co2, w1, w2, t[0], t[1], load[i])
                                              : flight_core(P + i * ps, s1, co1, s2, co2, w1, w2, t[0], t[1], load[i]);
        double *o = qdd + i * LEG_NQ;
        o[0] = A.xdd;
        o[1] = A.ydd;
        o[2] = A.thbdd;
        o[3] = A.q1dd;
        o[4] = A.q2dd;
        if (lam) {
            lam[2 * i] = A.lam_x;
            lam[2 * i + 1] = A.lam_y;
        }
    }
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

static PyObject *py_stance(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    return mode_dynamics(args, nargs, LEG_STICK, "stance");
}

static PyObject *py_flight(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    return mode_dynamics(args, nargs, LEG_FLIGHT, "flight");
}

static PyObject *py_equilibrium(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 4, "equilibrium"))
        return NULL;
    n = 1;
    (void)n;
    const leg_params *P = params_of(args[0], 1, &ps, &h);
    CHECK(P)
    double knee;
    if (!as_double(args[1], "knee", &knee))
        goto fail;
    double *q = F64_OUT(args[2], "q", LEG_NQ);
    CHECK(q)
    double *tau = F64_OUT(args[3], "tau", LEG_NU);
    CHECK(tau)
    equilibrium_one(P, knee, q, tau, NULL);
    DONE
    FAIL
}

/* ------------------------------------------------------------------------------------------------
 * The contact (leg_env.contact)
 * ------------------------------------------------------------------------------------------------ */

/* slip(q, qd, tau, mu, sigma, p, load, qdd, lam) */
static PyObject *py_slip(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 9, "slip"))
        return NULL;
    ROBOTS(args[0])
    const double *qd = F64_IN(args[1], "qd", n * LEG_NQ);
    CHECK(qd)
    const double *tau = F64_IN(args[2], "tau", n * LEG_NU);
    CHECK(tau)
    const double *mu = F64_IN(args[3], "mu", n);
    CHECK(mu)
    const double *sigma = F64_IN(args[4], "sigma", n);
    CHECK(sigma)
    const leg_params *P = params_of(args[5], n, &ps, &h);
    CHECK(P)
    const double *load = F64_IN(args[6], "load", n);
    CHECK(load)
    double *qdd = F64_OUT(args[7], "qdd", n * LEG_NQ);
    CHECK(qdd)
    double *lam = F64_OUT(args[8], "lam", n * 2);
    CHECK(lam)
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double s1, co1, s2, co2;
        const double *v = qd + i * LEG_NQ;
        leg_trig(q + i * LEG_NQ, &s1, &co1, &s2, &co2);
        const double w1 = v[2] + v[3], w2 = w1 + v[4];
        const leg_accel A =
            slip_core(P + i * ps, s1, co1, s2, co2, w1, w2, tau[2 * i], tau[2 * i + 1], load[i], mu[i], sigma[i]);
        double *o = qdd + i * LEG_NQ;
        o[0] = A.xdd;
        o[1] = A.ydd;
        o[2] = A.thbdd;
        o[3] = A.q1dd;
        o[4] = A.q2dd;
        lam[2 * i] = A.lam_x;
        lam[2 * i + 1] = A.lam_y;
    }
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

/* impact(q, qd, mu, p, qd_plus, impulse, status) */
static PyObject *py_impact(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 7, "impact"))
        return NULL;
    ROBOTS(args[0])
    const double *qd = F64_IN(args[1], "qd", n * LEG_NQ);
    CHECK(qd)
    const double *mu = F64_IN(args[2], "mu", n);
    CHECK(mu)
    const leg_params *P = params_of(args[3], n, &ps, &h);
    CHECK(P)
    double *qd_plus = F64_OUT(args[4], "qd_plus", n * LEG_NQ);
    CHECK(qd_plus)
    double *impulse = F64_OUT(args[5], "impulse", n * 2);
    CHECK(impulse)
    int64_t *status = I64_OUT(args[6], "status", n);
    CHECK(status)
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        const leg_params *Pi = P + i * ps;
        double s1, co1, s2, co2, vfx, vfy, Px, Py, d[LEG_NQ];
        const double *v = qd + i * LEG_NQ;
        leg_trig(q + i * LEG_NQ, &s1, &co1, &s2, &co2);
        const double w1 = v[2] + v[3], w2 = w1 + v[4];
        const leg_response R = foot_response(Pi, s1, co1, s2, co2);
        foot_velocity(Pi, s1, co1, s2, co2, v[0], v[1], w1, w2, &vfx, &vfy);
        status[i] = impact_core(vfx, vfy, mu[i], R.Lxx, R.Lxy, R.Lyy, &Px, &Py);
        impulse_velocity(Pi, &R, s1, co1, s2, co2, Px, Py, d);
        for (int j = 0; j < LEG_NQ; j++)
            qd_plus[i * LEG_NQ + j] = v[j] + d[j];
        impulse[2 * i] = Px;
        impulse[2 * i + 1] = Py;
    }
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

/* contact_mode(q, qd, tau, mu, p, out) */
static PyObject *py_contact_mode(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 6, "contact_mode"))
        return NULL;
    ROBOTS(args[0])
    const double *qd = F64_IN(args[1], "qd", n * LEG_NQ);
    CHECK(qd)
    const double *tau = F64_IN(args[2], "tau", n * LEG_NU);
    CHECK(tau)
    const double *mu = F64_IN(args[3], "mu", n);
    CHECK(mu)
    const leg_params *P = params_of(args[4], n, &ps, &h);
    CHECK(P)
    int64_t *out = I64_OUT(args[5], "out", n);
    CHECK(out)
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++)
        out[i] = contact_mode_one(P + i * ps, q + i * LEG_NQ, qd + i * LEG_NQ, tau[2 * i], tau[2 * i + 1], mu[i]);
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

/* response(q, qd, tau, p, Lam, a0): the contact inertia and the free foot acceleration */
static PyObject *py_response(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 6, "response"))
        return NULL;
    ROBOTS(args[0])
    const double *qd = F64_IN(args[1], "qd", n * LEG_NQ);
    CHECK(qd)
    const double *tau = F64_IN(args[2], "tau", n * LEG_NU);
    CHECK(tau)
    const leg_params *P = params_of(args[3], n, &ps, &h);
    CHECK(P)
    double *Lam = F64_OUT(args[4], "Lam", n * 4);
    CHECK(Lam)
    double *a0 = F64_OUT(args[5], "a0", n * 2);
    CHECK(a0)
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double s1, co1, s2, co2;
        const double *v = qd + i * LEG_NQ;
        leg_trig(q + i * LEG_NQ, &s1, &co1, &s2, &co2);
        const double w1 = v[2] + v[3], w2 = w1 + v[4];
        const leg_response R = foot_response(P + i * ps, s1, co1, s2, co2);
        const leg_free u = free_terms(P + i * ps, &R, s1, co1, s2, co2, w1, w2, tau[2 * i], tau[2 * i + 1], 0.0);
        Lam[4 * i] = R.Lxx;
        Lam[4 * i + 1] = R.Lxy;
        Lam[4 * i + 2] = R.Lxy;
        Lam[4 * i + 3] = R.Lyy;
        a0[2 * i] = u.a0x;
        a0[2 * i + 1] = u.a0y;
    }
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

/* ------------------------------------------------------------------------------------------------
 * Time stepping (leg_env.integrate, leg_env.hybrid)
 * ------------------------------------------------------------------------------------------------ */

/* turn(theta, d, out): (sin(theta + d), cos(theta + d)) by turn() from sin theta, cos theta; (N, 2) */
static PyObject *py_turn(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 3, "turn"))
        return NULL;
    const double *theta = (const double *)buffer_of(args[0], "theta", F64, -1, 0, &h, &n);
    CHECK(theta)
    const double *d = F64_IN(args[1], "d", n);
    CHECK(d)
    double *out = F64_OUT(args[2], "out", 2 * n);
    CHECK(out)
    for (Py_ssize_t i = 0; i < n; i++)
        turn(sin(theta[i]), cos(theta[i]), d[i], &out[2 * i], &out[2 * i + 1]);
    DONE
    FAIL
}

/* project(q, qd, p, anchor): q and qd in place */
static PyObject *py_project(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 4, "project"))
        return NULL;
    double *q = (double *)buffer_of(args[0], "q", F64, -LEG_NQ, 1, &h, &n);
    CHECK(q)
    double *qd = F64_OUT(args[1], "qd", n * LEG_NQ);
    CHECK(qd)
    const leg_params *P = params_of(args[2], n, &ps, &h);
    CHECK(P)
    const double *anchor = F64_IN(args[3], "anchor", n * 2);
    CHECK(anchor)
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++)
        project_one(P + i * ps, q + i * LEG_NQ, qd + i * LEG_NQ, anchor + 2 * i);
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

/* rk4_step(q, qd, tau, p, load, anchor, dt, substeps, max_angle, stance, lam_mean): one control step
 * of the pinned (stance) or free (flight) model in place */
static PyObject *py_rk4_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 11, "rk4_step"))
        return NULL;
    double *q = (double *)buffer_of(args[0], "q", F64, -LEG_NQ, 1, &h, &n);
    CHECK(q)
    double *qd = F64_OUT(args[1], "qd", n * LEG_NQ);
    CHECK(qd)
    const double *tau = F64_IN(args[2], "tau", n * LEG_NU);
    CHECK(tau)
    const leg_params *P = params_of(args[3], n, &ps, &h);
    CHECK(P)
    const double *load = F64_IN(args[4], "load", n);
    CHECK(load)
    const double *anchor = F64_IN(args[5], "anchor", n * 2);
    CHECK(anchor)
    double dt, max_angle;
    int substeps;
    if (!step_rule(args + 6, &dt, &substeps, &max_angle))
        goto fail;
    int stance;
    if (!as_bool(args[9], "stance", &stance))
        goto fail;
    double *lam = F64_OUT(args[10], "lam_mean", n * 2);
    CHECK(lam)
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double *qi = q + i * LEG_NQ, s1, co1, s2, co2;
        const leg_drive u = {tau[2 * i], tau[2 * i + 1], load[i], 0.0};
        leg_trig(qi, &s1, &co1, &s2, &co2);
        rk4_control_step(P + i * ps, &u, qi, qd + i * LEG_NQ, anchor + 2 * i, dt, substeps, max_angle, stance, s1,
                         co1, s2, co2, lam + 2 * i);
    }
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

/* hybrid_step(q, qd, tau, p, load, mu, mode, anchor, dt, substeps, max_angle, record): one control step
 * on the unilateral ground in place (q, qd, mode, anchor) with what it did in `record` */
static PyObject *py_hybrid_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 12, "hybrid_step"))
        return NULL;
    double *q = (double *)buffer_of(args[0], "q", F64, -LEG_NQ, 1, &h, &n);
    CHECK(q)
    double *qd = F64_OUT(args[1], "qd", n * LEG_NQ);
    CHECK(qd)
    const double *tau = F64_IN(args[2], "tau", n * LEG_NU);
    CHECK(tau)
    const leg_params *P = params_of(args[3], n, &ps, &h);
    CHECK(P)
    const double *load = F64_IN(args[4], "load", n);
    CHECK(load)
    const double *mu = F64_IN(args[5], "mu", n);
    CHECK(mu)
    int64_t *mode = I64_OUT(args[6], "mode", n);
    CHECK(mode)
    double *anchor = F64_OUT(args[7], "anchor", n * 2);
    CHECK(anchor)
    double dt, max_angle;
    int substeps;
    if (!step_rule(args + 8, &dt, &substeps, &max_angle))
        goto fail;
    leg_record *rec = (leg_record *)buffer_of(args[11], "record", RECORD, n, 1, &h, NULL);
    CHECK(rec)
    for (Py_ssize_t i = 0; i < n; i++) {
        if (mode[i] < LEG_STICK || mode[i] > LEG_FLIGHT) {
            PyErr_Format(PyExc_ValueError, "mode must be one of 0-3 (STICK, SLIP_FORWARD, SLIP_BACKWARD, FLIGHT), got %lld at row %zd",
                         (long long)mode[i], i);
            goto fail;
        }
        if (!(mu[i] >= 0.0 && mu[i] < INFINITY)) {
            PyErr_Format(PyExc_ValueError, "mu must be finite and >= 0, got %g at row %zd", mu[i], i);
            goto fail;
        }
    }
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double *qi = q + i * LEG_NQ, s1, co1, s2, co2;
        const leg_drive u = {tau[2 * i], tau[2 * i + 1], load[i], mu[i]};
        leg_trig(qi, &s1, &co1, &s2, &co2);
        for (int j = 0; j < LEG_LOG_SIZE; j++) { /* the log after the last event: none */
            rec[i].log.kind[j] = -1;
            rec[i].log.time[j] = NAN;
        }
        mode[i] = hybrid_control_step(P + i * ps, &u, qi, qd + i * LEG_NQ, (int)mode[i], anchor + 2 * i, dt, substeps,
                                      max_angle, s1, co1, s2, co2, &rec[i].tally, &rec[i].log);
    }
    Py_END_ALLOW_THREADS
    DONE
    FAIL
}

#include "module_env.c"

/* ------------------------------------------------------------------------------------------------
 * Layouts: every struct's fields, from which leg_env.layout builds the numpy dtypes
 * ------------------------------------------------------------------------------------------------ */

typedef struct {
    const char *name;
    size_t offset;
    const char *type; /* a numpy type ("f8", "i4", "?" for a byte flag) or a struct's name */
    size_t count;     /* 1 for a scalar, else the array's length */
} field;

#define F(type, member, code, count) {#member, offsetof(type, member), code, count}
#define TASK(type, member, name, code, count) {name, offsetof(type, member), code, count}
#define NAMED(type, member, name, code, count) {name, offsetof(type, member), code, count} /* a nested member */
/* the fields of a leg_tally member `tally` of `type`, under their own names (leg_record and env_out hold one) */
#define TALLY_FIELDS(type)                                                                                              \
    NAMED(type, tally.impulse, "impulse", "f8", 2), NAMED(type, tally.kick, "kick", "f8", 2),                           \
    NAMED(type, tally.stick_time, "stick_time", "f8", 1), NAMED(type, tally.slip_time, "slip_time", "f8", 1),           \
    NAMED(type, tally.flight_time, "flight_time", "f8", 1), NAMED(type, tally.slip_distance, "slip_distance", "f8", 1), \
    NAMED(type, tally.work, "work", "f8", 1), NAMED(type, tally.work_load, "work_load", "f8", 1),                       \
    NAMED(type, tally.slip_dissipation, "slip_dissipation", "f8", 1),                                                 \
    NAMED(type, tally.impact_dissipation, "impact_dissipation", "f8", 1), NAMED(type, tally.events, "events", "i4", 1), \
    NAMED(type, tally.painleve, "painleve", "i4", 1), NAMED(type, tally.settles, "settles", "i4", 1),                   \
    NAMED(type, tally.rk4_steps, "rk4_steps", "i4", 1)

static const field PARAMS_FIELDS[] = {
    F(leg_params, m_b, "f8", 1), F(leg_params, m1, "f8", 1), F(leg_params, m2, "f8", 1), F(leg_params, I_b, "f8", 1),
    F(leg_params, I1, "f8", 1),  F(leg_params, I2, "f8", 1), F(leg_params, l1, "f8", 1), F(leg_params, l2, "f8", 1),
    F(leg_params, c1, "f8", 1),  F(leg_params, c2, "f8", 1), F(leg_params, g, "f8", 1),  {NULL, 0, NULL, 0}};

static const field RECORD_FIELDS[] = {
    TALLY_FIELDS(leg_record),
    NAMED(leg_record, log.kind, "event_kind", "i4", LEG_LOG_SIZE), NAMED(leg_record, log.time, "event_time", "f8", LEG_LOG_SIZE),
    {NULL, 0, NULL, 0}};

static const field STATE_FIELDS[] = {
    F(env_state, q, "f8", LEG_NQ), F(env_state, qd, "f8", LEG_NQ), F(env_state, anchor, "f8", 2), F(env_state, action, "f8", 2),
    F(env_state, trig, "f8", 4), F(env_state, load, "f8", 1), F(env_state, prev_q, "f8", LEG_NQ),
    F(env_state, prev_qd, "f8", LEG_NQ), F(env_state, prev_anchor_x, "f8", 1), F(env_state, prev_trig, "f8", 4),
    F(env_state, mode, "i4", 1), F(env_state, prev_mode, "i4", 1), {NULL, 0, NULL, 0}};
static const field STATE_PUSH_FIELDS[] = {
    TASK(env_state, task.push.steps, "steps", "i4", 1), TASK(env_state, task.push.start, "push_start", "i4", PUSH_MAX),
    TASK(env_state, task.push.x_com0, "x_com0", "f8", 1), TASK(env_state, task.push.force, "push_force", "f8", PUSH_MAX),
    {NULL, 0, NULL, 0}};
static const field STATE_HOP_FIELDS[] = {
    TASK(env_state, task.hop.command, "command", "f8", 1), TASK(env_state, task.hop.x_com0, "x_com0", "f8", 1),
    TASK(env_state, task.hop.flight_run, "flight_run", "f8", 1), TASK(env_state, task.hop.ground_time, "ground_time", "f8", 1),
    TASK(env_state, task.hop.banked, "banked", "f8", 1), TASK(env_state, task.hop.pending, "pending", "f8", 1),
    TASK(env_state, task.hop.arc_kernel, "arc_kernel", "f8", 1), TASK(env_state, task.hop.held, "held", "f8", 1),
    TASK(env_state, task.hop.arc_apex, "arc_apex", "f8", 1), TASK(env_state, task.hop.apex, "apex", "f8", 1),
    TASK(env_state, task.hop.next_commands, "next_commands", "f8", HOP_COMMANDS),
    TASK(env_state, task.hop.command_age, "command_age", "i4", 1),
    TASK(env_state, task.hop.next_command, "next_command", "i4", 1),
    {NULL, 0, NULL, 0}};

static const field ROBOT_FIELDS[] = {
    F(env_robot, p, "leg_params", 1), F(env_robot, mu, "f8", 1), F(env_robot, torque_limit, "f8", LEG_NU),
    F(env_robot, q_nom, "f8", LEG_NQ), F(env_robot, tau_nom, "f8", LEG_NU), F(env_robot, com_nom, "f8", 2), {NULL, 0, NULL, 0}};

static const field SETTINGS_FIELDS[] = {
    F(env_settings, dt, "f8", 1), F(env_settings, max_angle, "f8", 1), F(env_settings, max_rate, "f8", 1),
    F(env_settings, alive_bonus, "f8", 1), F(env_settings, w_position, "f8", 1), F(env_settings, w_angle, "f8", 1),
    F(env_settings, w_velocity, "f8", 1), F(env_settings, w_unilateral, "f8", 1), F(env_settings, w_friction, "f8", 1),
    F(env_settings, w_ctrl, "f8", 1), F(env_settings, min_base_height, "f8", 1), F(env_settings, max_torso_angle, "f8", 1),
    F(env_settings, hip_range, "f8", 2), F(env_settings, knee_range, "f8", 2), F(env_settings, contact_loss_threshold, "f8", 1),
    F(env_settings, substeps, "i4", 1), F(env_settings, unilateral, "?", 1), F(env_settings, terminate_on_contact_loss, "?", 1),
    {NULL, 0, NULL, 0}};
static const field SETTINGS_PUSH_FIELDS[] = {
    TASK(env_settings, task.push.w_com, "w_com", "f8", 1), TASK(env_settings, task.push.push_steps, "push_steps", "i4", 1),
    TASK(env_settings, task.push.observe_com, "observe_com", "?", 1),
    {NULL, 0, NULL, 0}};
static const field SETTINGS_HOP_FIELDS[] = {
    TASK(env_settings, task.hop.w_height, "w_height", "f8", 1), TASK(env_settings, task.hop.height_scale, "height_scale", "f8", 1),
    TASK(env_settings, task.hop.w_drift, "w_drift", "f8", 1), TASK(env_settings, task.hop.w_tilt, "w_tilt", "f8", 1),
    TASK(env_settings, task.hop.w_impact, "w_impact", "f8", 1), TASK(env_settings, task.hop.w_slip, "w_slip", "f8", 1),
    TASK(env_settings, task.hop.height_scale_fine, "height_scale_fine", "f8", 1),
    TASK(env_settings, task.hop.w_drift_near, "w_drift_near", "f8", 1),
    TASK(env_settings, task.hop.drift_near_cap, "drift_near_cap", "f8", 1),
    TASK(env_settings, task.hop.w_limit, "w_limit", "f8", 1), TASK(env_settings, task.hop.limit_margin, "limit_margin", "f8", 1),
    TASK(env_settings, task.hop.min_flight, "min_flight", "f8", 1),
    TASK(env_settings, task.hop.max_ground_time, "max_ground_time", "f8", 1),
    TASK(env_settings, task.hop.flight_height, "flight_height", "?", 1),
    TASK(env_settings, task.hop.observe_progress, "observe_progress", "?", 1),
    TASK(env_settings, task.hop.pay_on_landing, "pay_on_landing", "?", 1),
    TASK(env_settings, task.hop.pay_hops_only, "pay_hops_only", "?", 1),
    TASK(env_settings, task.hop.pay_on_next_hop, "pay_on_next_hop", "?", 1),
    TASK(env_settings, task.hop.hold_height, "hold_height", "?", 1),
    TASK(env_settings, task.hop.observe_apex, "observe_apex", "?", 1),
    TASK(env_settings, task.hop.command_steps, "command_steps", "i4", 1),
    {NULL, 0, NULL, 0}};

static const field OUT_FIELDS[] = {
    F(env_out, lam, "f8", 2), F(env_out, base_drift, "f8", 1), F(env_out, foot_error, "f8", 1), F(env_out, normal_force, "f8", 1),
    TALLY_FIELDS(env_out),
    F(env_out, energy, "f8", 1), F(env_out, foot_height, "f8", 1), F(env_out, com, "f8", 2), F(env_out, com_velocity, "f8", 2),
    F(env_out, terms, "f8", MAX_TERMS),
    F(env_out, mode, "i4", 1), F(env_out, ending, "i4", 1), F(env_out, terminated, "?", 1), F(env_out, unilateral_violation, "?", 1),
    F(env_out, friction_violation, "?", 1), F(env_out, numerical_failure, "?", 1), {NULL, 0, NULL, 0}};
static const field OUT_PUSH_FIELDS[] = {
    TASK(env_out, task.push.push_force, "push_force", "f8", 1), TASK(env_out, task.push.work_push, "work_push", "f8", 1),
    {NULL, 0, NULL, 0}};

static PyObject *layout_of(const field *fields, size_t itemsize)
{
    PyObject *list = PyList_New(0);
    if (list == NULL)
        return NULL;
    for (const field *f = fields; f->name; f++) {
        PyObject *item = Py_BuildValue("(snsn)", f->name, (Py_ssize_t)f->offset, f->type, (Py_ssize_t)f->count);
        if (item == NULL || PyList_Append(list, item) < 0) {
            Py_XDECREF(item);
            Py_DECREF(list);
            return NULL;
        }
        Py_DECREF(item);
    }
    return Py_BuildValue("(nN)", (Py_ssize_t)itemsize, list);
}

/* layouts(): {struct: (itemsize, [(field, offset, numpy type or struct, count)])}; "env_state.push" and
 * the like are a task's fields of the struct's union (offsets from the struct's start) */
static PyObject *py_layouts(PyObject *self, PyObject *unused)
{
    static const struct {
        const char *name;
        const field *fields;
        size_t size;
    } structs[] = {
        {"leg_params", PARAMS_FIELDS, sizeof(leg_params)},
        {"leg_record", RECORD_FIELDS, sizeof(leg_record)},
        {"env_state", STATE_FIELDS, sizeof(env_state)},
        {"env_state.push", STATE_PUSH_FIELDS, sizeof(env_state)},
        {"env_state.hop", STATE_HOP_FIELDS, sizeof(env_state)},
        {"env_robot", ROBOT_FIELDS, sizeof(env_robot)},
        {"env_settings", SETTINGS_FIELDS, sizeof(env_settings)},
        {"env_settings.push", SETTINGS_PUSH_FIELDS, sizeof(env_settings)},
        {"env_settings.hop", SETTINGS_HOP_FIELDS, sizeof(env_settings)},
        {"env_out", OUT_FIELDS, sizeof(env_out)},
        {"env_out.push", OUT_PUSH_FIELDS, sizeof(env_out)},
    };
    PyObject *dict = PyDict_New();
    if (dict == NULL)
        return NULL;
    for (size_t k = 0; k < sizeof(structs) / sizeof(structs[0]); k++) {
        PyObject *layout = layout_of(structs[k].fields, structs[k].size);
        if (layout == NULL || PyDict_SetItemString(dict, structs[k].name, layout) < 0) {
            Py_XDECREF(layout);
            Py_DECREF(dict);
            return NULL;
        }
        Py_DECREF(layout);
    }
    return dict;
}

/* observation(): {name: column} of the observation's entries (obs_index of env.h) and the widths */
static PyObject *py_observation(PyObject *self, PyObject *unused)
{
    return Py_BuildValue(
        "{sisisisisisisisisisisisisisisisisisisisisisisisisisisisisi}", "base_x", OBS_BASE_X, "base_y", OBS_BASE_Y, "th_b", OBS_TH_B, "q1",
        OBS_Q1, "q2", OBS_Q2, "vx_b", OBS_VX_B, "vy_b", OBS_VY_B, "w_b", OBS_W_B, "w_q1", OBS_W_Q1, "w_q2", OBS_W_Q2, "lam_x",
        OBS_LAM_X, "lam_y", OBS_LAM_Y, "foot_height", OBS_FOOT_HEIGHT, "foot_vx", OBS_FOOT_VX, "foot_vy", OBS_FOOT_VY, "contact",
        OBS_CONTACT, "slip", OBS_SLIP, "impulse_y", OBS_IMPULSE_Y, "command", OBS_COMMAND, "pinned_dim", OBS_PINNED_DIM,
        "unilateral_dim", OBS_UNILATERAL_DIM, "hop_dim", OBS_HOP_DIM, "com_drift", OBS_COM_DRIFT, "ground_time", OBS_GROUND_TIME, "hop_progress_dim", OBS_PROGRESS_DIM,
        "last_apex", OBS_LAST_APEX, "hop_apex_dim", OBS_MAX_DIM, "push_com_drift", OBS_PUSH_COM_DRIFT, "push_com_dim", OBS_PUSH_DIM);
}

/* ------------------------------------------------------------------------------------------------ */

#define FAST(name, fn, doc) {name, (PyCFunction)(void (*)(void))fn, METH_FASTCALL, doc}

static PyMethodDef methods[] = {
    FAST("mass_matrix", py_mass_matrix, "mass_matrix(q, p, M): M(q), (N, 5, 5)."),
    FAST("bias", py_bias, "bias(q, qd, p, h, gravity_only): h(q, qd), (N, 5)."),
    FAST("foot", py_foot, "foot(q, p, out): the foot position, (N, 2)."),
    FAST("jacobian", py_jacobian, "jacobian(q, p, Jc): the contact Jacobian, (N, 2, 5)."),
    FAST("jdot_qd", py_jdot_qd, "jdot_qd(q, qd, p, out): Jcdot qd, (N, 2)."),
    FAST("com", py_com, "com(q, qd, p, position, velocity): the whole-body COM and its velocity, (N, 2) each."),
    FAST("energy", py_energy, "energy(q, qd, p, out): kinetic plus potential energy (y = 0 at zero potential), (N,)."),
    FAST("stance", py_stance, "stance(q, qd, tau, p, load, qdd, lam): the pinned-foot KKT solve."),
    FAST("flight", py_flight, "flight(q, qd, tau, p, load, qdd): the unconstrained dynamics."),
    FAST("equilibrium", py_equilibrium, "equilibrium(p, knee, q, tau): the static stance equilibrium."),
    FAST("slip", py_slip, "slip(q, qd, tau, mu, sigma, p, load, qdd, lam): the sliding dynamics."),
    FAST("impact", py_impact, "impact(q, qd, mu, p, qd_plus, impulse, status): the plastic impact map."),
    FAST("contact_mode", py_contact_mode, "contact_mode(q, qd, tau, mu, p, out): the consistent mode."),
    FAST("response", py_response, "response(q, qd, tau, p, Lam, a0): contact inertia and free foot acceleration."),
    FAST("turn", py_turn, "turn(theta, d, out): sin and cos of theta + d by angle addition, as the integrator turns."),
    FAST("project", py_project, "project(q, qd, p, anchor): the foot onto its anchor, in place."),
    FAST("rk4_step", py_rk4_step,
         "rk4_step(q, qd, tau, p, load, anchor, dt, substeps, max_angle, stance, lam_mean): one RK4 control step."),
    FAST("hybrid_step", py_hybrid_step,
         "hybrid_step(q, qd, tau, p, load, mu, mode, anchor, dt, substeps, max_angle, record): one hybrid control step."),
    FAST("physics_range", py_physics_range, "physics_range(lo, hi, state, robots, settings, out): one control step of rows lo .. hi - 1."),
    FAST("assess", py_assess, "assess(task, state, robots, settings, out, obs): the task after a control step."),
    FAST("step", py_step, "step(task, lo, hi, state, robots, settings, out, obs): physics_range then assess of rows lo .. hi - 1, block by block."),
    FAST("start", py_start,
         "start(task, state, robots, settings, out, obs, noise, scale): robots put on their contact (at the nominal posture "
         "plus noise, or as the state has them if noise is None) and evaluated."),
    FAST("perturbed_starts", py_perturbed_starts, "perturbed_starts(noise, scale, q_nom, p, q, qd, anchor)."),
    FAST("robot_params", py_robot_params, "robot_params(u, spec, base, limits, row) -> accepted."),
    FAST("info_columns", py_info_columns,
         "info_columns(spec, out, state, doubles, ints, flags, vectors, names, codes): every row's info keys, a block row per "
         "key."),
    FAST("draw_uniform", py_draw_uniform, "draw_uniform(generators, rows, out): uniforms from each row's generator."),
    FAST("draw_robots", py_draw_robots, "draw_robots(generators, rows, spec, base, limits, max_draws, robots, rejected)."),
    {"layouts", (PyCFunction)py_layouts, METH_NOARGS, "layouts(): {struct: (itemsize, [(field, offset, size)])}."},
    {"observation", (PyCFunction)py_observation, METH_NOARGS, "observation(): the observation's columns by name."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "kernels",
    "The compiled core of leg-env: the planar leg's dynamics, contact and time stepping in C.", -1, methods,
};

PyMODINIT_FUNC PyInit_kernels(void)
{
    if (PyType_Ready(&BatchType) < 0 || PyType_Ready(&GeneratorsType) < 0)
        return NULL;
    name_capsule = PyUnicode_InternFromString("capsule");
    name_bit_generator = PyUnicode_InternFromString("bit_generator");
    if (name_capsule == NULL || name_bit_generator == NULL)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    Py_INCREF(&BatchType);
    if (PyModule_AddObject(m, "Batch", (PyObject *)&BatchType) < 0) {
        Py_DECREF(&BatchType);
        Py_DECREF(m);
        return NULL;
    }
    Py_INCREF(&GeneratorsType);
    if (PyModule_AddObject(m, "Generators", (PyObject *)&GeneratorsType) < 0) {
        Py_DECREF(&GeneratorsType);
        Py_DECREF(m);
        return NULL;
    }
    if (PyModule_AddIntConstant(m, "MAX_SUBSTEPS", LEG_MAX_SUBSTEPS) < 0 || PyModule_AddIntConstant(m, "LOG_SIZE", LEG_LOG_SIZE) < 0
        || PyModule_AddIntConstant(m, "MAX_EVENTS", LEG_MAX_EVENTS) < 0 || PyModule_AddIntConstant(m, "MAX_TERMS", MAX_TERMS) < 0
        || PyModule_AddIntConstant(m, "PUSH_MAX", PUSH_MAX) < 0
        || PyModule_AddObject(m, "GROUND_TOL", PyFloat_FromDouble(LEG_GROUND_TOL)) < 0
        || PyModule_AddObject(m, "SETTLE_SPEED", PyFloat_FromDouble(LEG_SETTLE_SPEED)) < 0
        || PyModule_AddObject(m, "ROOT_TIME", PyFloat_FromDouble(LEG_ROOT_TIME)) < 0
        || PyModule_AddObject(m, "REST_SPEED", PyFloat_FromDouble(LEG_REST_SPEED)) < 0
        || PyModule_AddIntConstant(m, "STICK", LEG_STICK) < 0 || PyModule_AddIntConstant(m, "SLIP_FORWARD", LEG_SLIP_FORWARD) < 0
        || PyModule_AddIntConstant(m, "SLIP_BACKWARD", LEG_SLIP_BACKWARD) < 0 || PyModule_AddIntConstant(m, "FLIGHT", LEG_FLIGHT) < 0
        || PyModule_AddIntConstant(m, "LIFTOFF", LEG_LIFTOFF) < 0 || PyModule_AddIntConstant(m, "SLIP_ONSET", LEG_SLIP_ONSET) < 0
        || PyModule_AddIntConstant(m, "SLIDING_STOP", LEG_SLIDING_STOP) < 0 || PyModule_AddIntConstant(m, "TOUCHDOWN", LEG_TOUCHDOWN) < 0
        || PyModule_AddObject(m, "TURN_MAX", PyFloat_FromDouble(LEG_TURN_MAX)) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    PyObject *endings = PyTuple_New(N_ENDINGS);
    for (int k = 0; endings != NULL && k < N_ENDINGS; k++) {
        PyObject *name = PyUnicode_FromString(ENDING_NAMES[k]);
        if (name == NULL) {
            Py_CLEAR(endings);
            break;
        }
        PyTuple_SET_ITEM(endings, k, name);
    }
    if (endings == NULL || PyModule_AddObject(m, "ENDINGS", endings) < 0) {
        Py_XDECREF(endings);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
