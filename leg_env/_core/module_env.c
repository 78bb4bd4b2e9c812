/* leg_env._core.kernels, the environments' half: the control step, the starts, the tasks and the draws
 * on the packed arrays of leg_env.step, and Batch, the single environment's arrays bound once.
 *
 * Included by module.c (the unity build), after the buffer helpers.
 */

/* The packed arrays of a call, checked: (state, consts, out, obs, flags), obs may be NULL (physics only).
 * Every row length is checked against what the task reads and writes, so that no kernel reads or writes
 * past an array whatever it is given. */
static int batch_of(int task, PyObject *state, PyObject *consts, PyObject *out, PyObject *obs, PyObject *flags, held *h,
                    env_batch *b)
{
    if (task < TASK_STANCE || task > TASK_HOP) {
        PyErr_Format(PyExc_ValueError, "task must be 0 (stance), 1 (push) or 2 (hop), got %d", task);
        return 0;
    }
    Py_ssize_t task_state, task_constants, task_info, rows, cols;
    task_columns(task, &task_state, &task_constants, &task_info);
    b->state = (double *)matrix_of(state, "state", F64, 1, h, &b->n, &b->state_cols);
    if (b->state == NULL)
        return 0;
    if (b->state_cols < ENV_DOUBLES(env_state) + task_state) {
        PyErr_Format(PyExc_ValueError, "state must have at least %zd columns for this task, got %zd",
                     ENV_DOUBLES(env_state) + task_state, b->state_cols);
        return 0;
    }
    b->consts = (const double *)matrix_of(consts, "consts", F64, 0, h, &b->consts_rows, &b->consts_cols);
    if (b->consts == NULL)
        return 0;
    if ((b->consts_rows != 1 && b->consts_rows != b->n) || b->consts_cols < ENV_DOUBLES(env_robot) + task_constants) {
        PyErr_Format(PyExc_ValueError, "consts must have 1 row or one per robot (%zd) and at least %zd columns, got (%zd, %zd)",
                     b->n, ENV_DOUBLES(env_robot) + task_constants, b->consts_rows, b->consts_cols);
        return 0;
    }
    b->out = (double *)matrix_of(out, "out", F64, 1, h, &rows, &b->out_cols);
    if (b->out == NULL)
        return 0;
    if (rows != b->n || b->out_cols < ENV_DOUBLES(env_out) + task_terms(task) + task_info) {
        PyErr_Format(PyExc_ValueError, "out must have shape (%zd, >= %zd), got (%zd, %zd)", b->n,
                     ENV_DOUBLES(env_out) + task_terms(task) + task_info, rows, b->out_cols);
        return 0;
    }
    unsigned char *f = (unsigned char *)matrix_of(flags, "flags", BOOL, 1, h, &rows, &cols);
    if (f == NULL)
        return 0;
    if (rows != b->n || cols != N_FLAGS) {
        PyErr_Format(PyExc_ValueError, "flags must have shape (%zd, %d), got (%zd, %zd)", b->n, N_FLAGS, rows, cols);
        return 0;
    }
    b->flags = f;
    b->obs = NULL;
    b->obs_cols = 0;
    /* the settings every robot shares, and each robot's parameters, must make a step that terminates */
    for (Py_ssize_t i = 0; i < b->consts_rows; i++) {
        const env_robot *r = (const env_robot *)(b->consts + i * b->consts_cols);
        const double *pf = (const double *)&r->p;
        int ok = r->c.dt > 0.0 && r->c.dt < INFINITY && r->c.substeps >= 1.0 && r->c.substeps <= LEG_MAX_SUBSTEPS
                 && r->c.max_angle > 0.0 && r->c.mu >= 0.0 && r->c.mu < INFINITY;
        for (int j = 0; j < 10; j++)
            ok = ok && pf[j] > 0.0 && pf[j] < INFINITY;
        ok = ok && r->p.g >= 0.0 && r->p.g < INFINITY;
        if (!ok) {
            PyErr_Format(PyExc_ValueError, "consts row %zd: parameters and settings out of range (dt, substeps, max_angle, mu, "
                         "masses, inertias, lengths, g)", i);
            return 0;
        }
    }
    for (Py_ssize_t i = 0; i < b->n; i++) {
        const double mode = state_row(b, i)->mode;
        if (!(mode == LEG_STICK || mode == LEG_SLIP_FORWARD || mode == LEG_SLIP_BACKWARD || mode == LEG_FLIGHT)) {
            PyErr_Format(PyExc_ValueError, "state row %zd: the contact mode must be 0, 1, 2 or 3, got %g", i, mode);
            return 0;
        }
    }
    if (obs != NULL) {
        const Py_ssize_t need = (robot_row(b, 0)->c.unilateral > 0.5 ? 18 : 12) + (task == TASK_HOP ? 1 : 0);
        b->obs = (float *)matrix_of(obs, "obs", F32, 1, h, &rows, &b->obs_cols);
        if (b->obs == NULL)
            return 0;
        if (rows != b->n || b->obs_cols != need) {
            PyErr_Format(PyExc_ValueError, "obs must have shape (%zd, %zd), got (%zd, %zd)", b->n, need, rows, b->obs_cols);
            return 0;
        }
    }
    return 1;
}

static int int_arg(PyObject *obj, const char *name, Py_ssize_t *out)
{
    *out = PyNumber_AsSsize_t(obj, PyExc_OverflowError);
    if (*out == -1 && PyErr_Occurred()) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be an integer, got %.80R", name, obj);
        return 0;
    }
    return 1;
}

/* physics_range(lo, hi, state, consts, out, flags): one control step of rows lo .. hi - 1 (GIL released) */
static PyObject *py_physics_range(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    env_batch b;
    Py_ssize_t lo, hi;
    if (!n_args(nargs, 6, "physics_range") || !int_arg(args[0], "lo", &lo) || !int_arg(args[1], "hi", &hi))
        return NULL;
    if (!batch_of(TASK_STANCE, args[2], args[3], args[4], NULL, args[5], &h, &b))
        goto fail;
    if (!(0 <= lo && lo <= hi && hi <= b.n)) {
        PyErr_Format(PyExc_ValueError, "rows lo .. hi must satisfy 0 <= lo <= hi <= %zd, got %zd .. %zd", b.n, lo, hi);
        goto fail;
    }
    Py_BEGIN_ALLOW_THREADS
    physics_range(&b, lo, hi);
    Py_END_ALLOW_THREADS
    release_all(&h);
    Py_RETURN_NONE;
fail:
    release_all(&h);
    return NULL;
}

/* physics_start(state, consts, out, flags) and physics_start_noisy(noise, scale, state, consts, out, flags) */
static PyObject *start_physics(PyObject *const *args, Py_ssize_t nargs, int noisy)
{
    held h;
    h.n = 0;
    env_batch b;
    const double *noise = NULL;
    double scale = 0.0;
    if (!n_args(nargs, noisy ? 6 : 4, noisy ? "physics_start_noisy" : "physics_start"))
        return NULL;
    PyObject *const *a = args + (noisy ? 2 : 0);
    if (!batch_of(TASK_STANCE, a[0], a[1], a[2], NULL, a[3], &h, &b))
        goto fail;
    if (noisy) {
        if (!as_double(args[1], "scale", &scale))
            goto fail;
        if (!(scale >= 0.0 && scale < INFINITY)) {
            PyErr_SetString(PyExc_ValueError, "scale must be finite and >= 0");
            goto fail;
        }
        if (scale > 0.0) {
            noise = F64_IN(args[0], "noise", b.n * 6);
            CHECK(noise)
        } else {
            static const double zeros[6] = {0.0};
            noise = zeros; /* not read at scale 0: every row reads its 6 entries from the start */
            for (Py_ssize_t i = 0; i < b.n; i++) {
                const env_robot *r = robot_row(&b, i);
                env_state *s = state_row(&b, i);
                perturbed_start(zeros, 0.0, r->q_nom, &r->p, s->q, s->qd, s->anchor);
                start_row(&b, i);
            }
            release_all(&h);
            Py_RETURN_NONE;
        }
    }
    physics_start(&b, noise, scale);
    release_all(&h);
    Py_RETURN_NONE;
fail:
    release_all(&h);
    return NULL;
}

static PyObject *py_physics_start(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    return start_physics(args, nargs, 0);
}

static PyObject *py_physics_start_noisy(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    return start_physics(args, nargs, 1);
}

/* assess(task, state, consts, out, obs, flags) and start(task, ...): the task's kernels over every row */
static PyObject *task_kernel(PyObject *const *args, Py_ssize_t nargs, int starting)
{
    held h;
    h.n = 0;
    env_batch b;
    Py_ssize_t task;
    if (!n_args(nargs, 6, starting ? "start" : "assess") || !int_arg(args[0], "task", &task))
        return NULL;
    if (!batch_of((int)(task < 0 || task > 2 ? -1 : task), args[1], args[2], args[3], args[4], args[5], &h, &b))
        goto fail;
    if (starting)
        task_start((int)task, &b);
    else
        task_assess((int)task, &b, 0, b.n);
    release_all(&h);
    Py_RETURN_NONE;
fail:
    release_all(&h);
    return NULL;
}

static PyObject *py_assess(PyObject *self, PyObject *const *args, Py_ssize_t nargs) { return task_kernel(args, nargs, 0); }

static PyObject *py_start(PyObject *self, PyObject *const *args, Py_ssize_t nargs) { return task_kernel(args, nargs, 1); }

/* perturbed_starts(noise, scale, q_nom, p, q, qd, anchor): perturbed_start of every row of noise */
static PyObject *py_perturbed_starts(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 7, "perturbed_starts"))
        return NULL;
    const double *noise = (const double *)buffer_of(args[0], "noise", F64, -6, 0, &h, &n);
    CHECK(noise)
    double scale;
    if (!as_double(args[1], "scale", &scale))
        goto fail;
    const double *q_nom = F64_IN(args[2], "q_nom", LEG_NQ);
    CHECK(q_nom)
    const leg_params *P = params_of(args[3], 1, &ps, &h);
    CHECK(P)
    double *q = F64_OUT(args[4], "q", n * LEG_NQ);
    CHECK(q)
    double *qd = F64_OUT(args[5], "qd", n * LEG_NQ);
    CHECK(qd)
    double *anchor = F64_OUT(args[6], "anchor", n * 2);
    CHECK(anchor)
    for (Py_ssize_t i = 0; i < n; i++)
        perturbed_start(noise + 6 * i, scale, q_nom, P, q + i * LEG_NQ, qd + i * LEG_NQ, anchor + 2 * i);
    DONE
    FAIL
}

/* The robot spec of a randomisation, checked: (F, 4) rows (column, kind, low, high) with every column
 * inside a consts row of `cols` doubles. */
static const double *spec_of(PyObject *obj, Py_ssize_t cols, Py_ssize_t *n_spec, held *h)
{
    const double *spec = (const double *)buffer_of(obj, "spec", F64, -4, 0, h, n_spec);
    if (spec == NULL)
        return NULL;
    for (Py_ssize_t f = 0; f < *n_spec; f++) {
        const double col = spec[4 * f], kind = spec[4 * f + 1];
        if (!(col >= 0.0 && col < (double)cols && col == floor(col)) || !(kind == 0.0 || kind == 1.0 || kind == 2.0)) {
            PyErr_Format(PyExc_ValueError, "spec row %zd: column must be a whole number in [0, %zd) and kind 0, 1 or 2", f, cols);
            return NULL;
        }
    }
    return spec;
}

/* robot_params(u, spec, base, limits, row) -> bool */
static PyObject *py_robot_params(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 5, "robot_params"))
        return NULL;
    Py_ssize_t cols = 0, n_spec = 0;
    const double *base = (const double *)buffer_of(args[2], "base", F64, -1, 0, &h, &cols);
    CHECK(base)
    if (cols < ENV_DOUBLES(env_robot)) {
        PyErr_Format(PyExc_ValueError, "base must have at least %zd values", ENV_DOUBLES(env_robot));
        goto fail;
    }
    const double *spec = spec_of(args[1], cols, &n_spec, &h);
    CHECK(spec)
    const double *u = F64_IN(args[0], "u", n_spec);
    CHECK(u)
    const double *limits = F64_IN(args[3], "limits", 6);
    CHECK(limits)
    double *row = F64_OUT(args[4], "row", cols);
    CHECK(row)
    const int accepted = robot_params(u, spec, n_spec, base, limits, row, cols);
    release_all(&h);
    return PyBool_FromLong(accepted);
    FAIL
}

/* The bit generators of `generators` (a list of numpy BitGenerator capsules, or None) at `rows`. */
static int bitgens_of(PyObject *generators, const int64_t *rows, Py_ssize_t n_rows, bitgen_t **out)
{
    if (!PyList_Check(generators)) {
        PyErr_SetString(PyExc_TypeError, "generators must be a list of numpy BitGenerator capsules");
        return 0;
    }
    for (Py_ssize_t k = 0; k < n_rows; k++) {
        if (rows[k] < 0 || rows[k] >= PyList_GET_SIZE(generators)) {
            PyErr_Format(PyExc_ValueError, "rows[%zd] = %lld is not a generator's index", k, (long long)rows[k]);
            return 0;
        }
        PyObject *capsule = PyList_GET_ITEM(generators, rows[k]);
        bitgen_t *bg = PyCapsule_IsValid(capsule, "BitGenerator") ? (bitgen_t *)PyCapsule_GetPointer(capsule, "BitGenerator") : NULL;
        if (bg == NULL || bg->next_double == NULL) {
            PyErr_Clear();
            PyErr_Format(PyExc_ValueError, "generator %lld is not a numpy BitGenerator capsule", (long long)rows[k]);
            return 0;
        }
        out[k] = bg;
    }
    return 1;
}

/* draw_uniform(generators, rows, out): out[k] = generators[rows[k]]'s next out.shape[1] doubles */
static PyObject *py_draw_uniform(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    Py_ssize_t n_rows = 0, rows2, cols;
    bitgen_t **bg = NULL;
    if (!n_args(nargs, 3, "draw_uniform"))
        return NULL;
    const int64_t *rows = (const int64_t *)buffer_of(args[1], "rows", I64, -1, 0, &h, &n_rows);
    double *out = rows ? (double *)matrix_of(args[2], "out", F64, 1, &h, &rows2, &cols) : NULL;
    if (out == NULL)
        goto fail;
    if (rows2 != n_rows) {
        PyErr_Format(PyExc_ValueError, "out must have one row per entry of rows (%zd), got %zd", n_rows, rows2);
        goto fail;
    }
    bg = PyMem_Malloc((n_rows ? n_rows : 1) * sizeof(bitgen_t *));
    if (bg == NULL) {
        PyErr_NoMemory();
        goto fail;
    }
    if (!bitgens_of(args[0], rows, n_rows, bg))
        goto fail;
    for (Py_ssize_t k = 0; k < n_rows; k++)
        for (Py_ssize_t j = 0; j < cols; j++)
            out[k * cols + j] = bg[k]->next_double(bg[k]->state);
    PyMem_Free(bg);
    release_all(&h);
    Py_RETURN_NONE;
fail:
    PyMem_Free(bg);
    release_all(&h);
    return NULL;
}

/* draw_robots(generators, rows, spec, base, limits, max_draws, consts, rejected): robot_params for each
 * sub-env rows[k], drawing spec's uniforms per try from its own generator, up to max_draws tries;
 * consts[rows[k]] becomes the first accepted robot (the nominal base if every try is refused) and
 * rejected[k] the number of refused tries. */
static PyObject *py_draw_robots(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    Py_ssize_t n_rows = 0, cols = 0, n_spec = 0, consts_rows, consts_cols, max_draws;
    bitgen_t **bg = NULL;
    double *u = NULL;
    if (!n_args(nargs, 8, "draw_robots") || !int_arg(args[5], "max_draws", &max_draws))
        return NULL;
    const int64_t *rows = (const int64_t *)buffer_of(args[1], "rows", I64, -1, 0, &h, &n_rows);
    const double *base = rows ? (const double *)buffer_of(args[3], "base", F64, -1, 0, &h, &cols) : NULL;
    double *consts = base ? (double *)matrix_of(args[6], "consts", F64, 1, &h, &consts_rows, &consts_cols) : NULL;
    if (consts == NULL)
        goto fail;
    if (cols < ENV_DOUBLES(env_robot) || consts_cols != cols || max_draws < 1) {
        PyErr_SetString(PyExc_ValueError, "base and the rows of consts must have the same length (a robot's constants), max_draws >= 1");
        goto fail;
    }
    const double *spec = spec_of(args[2], cols, &n_spec, &h);
    const double *limits = spec ? F64_IN(args[4], "limits", 6) : NULL;
    int64_t *rejected = limits ? I64_OUT(args[7], "rejected", n_rows) : NULL;
    if (rejected == NULL)
        goto fail;
    for (Py_ssize_t k = 0; k < n_rows; k++)
        if (rows[k] < 0 || rows[k] >= consts_rows) {
            PyErr_Format(PyExc_ValueError, "rows[%zd] = %lld is not a row of consts", k, (long long)rows[k]);
            goto fail;
        }
    bg = PyMem_Malloc((n_rows ? n_rows : 1) * sizeof(bitgen_t *));
    u = PyMem_Malloc((n_spec ? n_spec : 1) * sizeof(double));
    if (bg == NULL || u == NULL) {
        PyErr_NoMemory();
        goto fail;
    }
    if (!bitgens_of(args[0], rows, n_rows, bg))
        goto fail;
    for (Py_ssize_t k = 0; k < n_rows; k++) {
        double *row = consts + rows[k] * cols;
        rejected[k] = max_draws;
        for (Py_ssize_t t = 0; t < max_draws; t++) {
            for (Py_ssize_t j = 0; j < n_spec; j++)
                u[j] = bg[k]->next_double(bg[k]->state);
            if (robot_params(u, spec, n_spec, base, limits, row, cols)) {
                rejected[k] = t;
                break;
            }
        }
        if (rejected[k] == max_draws)
            memcpy(row, base, cols * sizeof(double));
    }
    PyMem_Free(bg);
    PyMem_Free(u);
    release_all(&h);
    Py_RETURN_NONE;
fail:
    PyMem_Free(bg);
    PyMem_Free(u);
    release_all(&h);
    return NULL;
}

/* ------------------------------------------------------------------------------------------------
 * Batch: one env's packed arrays handed to C once (the single environment's step is one call)
 * ------------------------------------------------------------------------------------------------ */

typedef struct {
    PyObject_HEAD held h;
    env_batch b;
    int task;
} BatchObject;

static void Batch_dealloc(BatchObject *self)
{
    release_all(&self->h);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *Batch_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    PyObject *state, *consts, *out, *obs, *flags;
    int task;
    if (kwds != NULL && PyDict_Size(kwds) > 0) {
        PyErr_SetString(PyExc_TypeError, "Batch takes no keyword arguments");
        return NULL;
    }
    if (!PyArg_ParseTuple(args, "iOOOOO:Batch", &task, &state, &consts, &out, &obs, &flags))
        return NULL;
    BatchObject *self = (BatchObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    self->h.n = 0;
    self->task = task;
    if (!batch_of(task, state, consts, out, obs, flags, &self->h, &self->b)) {
        Py_DECREF(self);
        return NULL;
    }
    return (PyObject *)self;
}

/* step_one(a0, a1) -> reward: robot 0's action, its control step and the task's evaluation */
static PyObject *Batch_step_one(BatchObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "step_one takes 2 arguments (a0, a1)");
        return NULL;
    }
    const double a0 = PyFloat_AsDouble(args[0]), a1 = PyFloat_AsDouble(args[1]);
    if ((a0 == -1.0 || a1 == -1.0) && PyErr_Occurred())
        return NULL;
    if (!(isfinite(a0) && isfinite(a1))) {
        PyErr_SetString(PyExc_ValueError, "step_one: the action must be finite");
        return NULL;
    }
    const env_batch *b = &self->b;
    env_state *s = state_row(b, 0);
    if (!(s->mode == LEG_STICK || s->mode == LEG_SLIP_FORWARD || s->mode == LEG_SLIP_BACKWARD || s->mode == LEG_FLIGHT)) {
        PyErr_SetString(PyExc_ValueError, "step_one: the state's contact mode must be 0, 1, 2 or 3");
        return NULL;
    }
    s->action[0] = a0;
    s->action[1] = a1;
    physics_range(b, 0, 1);
    task_assess(self->task, b, 0, 1);
    return PyFloat_FromDouble(summed_terms(self->task, b));
}

/* physics_start(noise or None, scale): robot 0 started (at its nominal posture plus noise, if given) and
 * evaluated by the task, without stepping */
static PyObject *Batch_start(BatchObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    double scale = 0.0;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "start takes 2 arguments (noise or None, scale)");
        return NULL;
    }
    const double *noise = NULL;
    if (args[0] != Py_None) {
        if (!as_double(args[1], "scale", &scale))
            return NULL;
        if (!(scale >= 0.0 && scale < INFINITY)) {
            PyErr_SetString(PyExc_ValueError, "scale must be finite and >= 0");
            return NULL;
        }
        static const double zeros[6] = {0.0};
        noise = zeros;
        if (scale > 0.0) {
            noise = (const double *)buffer_of(args[0], "noise", F64, 6 * self->b.n, 0, &h, NULL);
            if (noise == NULL)
                return NULL;
        }
    }
    for (Py_ssize_t i = 0; i < self->b.n; i++) {
        if (noise) {
            const env_robot *r = robot_row(&self->b, i);
            env_state *s = state_row(&self->b, i);
            perturbed_start(scale > 0.0 ? noise + 6 * i : noise, scale, r->q_nom, &r->p, s->q, s->qd, s->anchor);
        }
        start_row(&self->b, i);
    }
    task_start(self->task, &self->b);
    release_all(&h);
    Py_RETURN_NONE;
}

static PyMethodDef Batch_methods[] = {
    {"step_one", (PyCFunction)(void (*)(void))Batch_step_one, METH_FASTCALL,
     "step_one(a0, a1) -> reward: robot 0's action, control step and evaluation."},
    {"start", (PyCFunction)(void (*)(void))Batch_start, METH_FASTCALL,
     "start(noise or None, scale): start every robot (at the nominal posture plus noise if given) and evaluate it."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject BatchType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "leg_env._core.kernels.Batch",
    .tp_basicsize = sizeof(BatchObject),
    .tp_dealloc = (destructor)Batch_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Batch(task, state, consts, out, obs, flags): an env's packed arrays, held for its control steps.",
    .tp_methods = Batch_methods,
    .tp_new = Batch_new,
};
