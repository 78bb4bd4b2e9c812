/* leg_env._core.kernels, the environments' half: the control step, the starts, the tasks and the draws
 * on the structured arrays of leg_env.layout (one env_state, env_robot, env_out per row; one
 * env_settings), and Batch, the single environment's arrays bound once.
 *
 * Included by module.c (the unity build), after the buffer helpers.
 */

/* The rows of a structured array of a C struct of `itemsize` bytes: 1-d, C-contiguous. NULL with a
 * ValueError naming `name` otherwise. (The dtype's fields are leg_env.layout's, checked against this
 * file's layouts at import; here only the size can be checked.) */
static void *rows_of(PyObject *obj, const char *name, Py_ssize_t itemsize, int writable, held *h, Py_ssize_t *rows)
{
    if (h->n >= MAX_BUFFERS) {
        PyErr_SetString(PyExc_RuntimeError, "leg_env._core.kernels: too many buffers in one call");
        return NULL;
    }
    Py_buffer *v = &h->views[h->n];
    if (PyObject_GetBuffer(obj, v, PyBUF_C_CONTIGUOUS | (writable ? PyBUF_WRITABLE : 0)) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "%s must be a C-contiguous%s structured array of leg_env.layout, got %.80R", name,
                     writable ? ", writable" : "", (PyObject *)Py_TYPE(obj));
        return NULL;
    }
    h->n++;
    if (v->ndim != 1 || v->itemsize != itemsize) {
        PyErr_Format(PyExc_ValueError, "%s must be a 1-d array of its leg_env.layout dtype (items of %zd bytes), got %d-d items of %zd bytes",
                     name, itemsize, v->ndim, v->itemsize);
        return NULL;
    }
    *rows = v->len / itemsize;
    return v->buf;
}

/* The values a step relies on, checked: every robot's parameters and friction and the settings (a step
 * that terminates, no division by zero by construction) and, if `modes`, every state's contact mode and
 * the one an undone step restores. batch_of checks them at every call; Batch at each of its calls too,
 * since its arrays can be written between calls. */
static int batch_values(const env_batch *b, int modes)
{
    const env_settings *c = b->settings;
    if (!(c->dt > 0.0 && c->dt < INFINITY && c->substeps >= 1 && c->substeps <= LEG_MAX_SUBSTEPS && c->max_angle > 0.0
          && c->max_rate > 0.0)) {
        PyErr_SetString(PyExc_ValueError, "settings: dt, substeps, max_angle or max_rate out of range");
        return 0;
    }
    for (Py_ssize_t i = 0; i < b->robot_rows; i++) {
        const env_robot *r = b->robots + i;
        const double *pf = (const double *)&r->p;
        int ok = r->mu >= 0.0 && r->mu < INFINITY && r->p.g >= 0.0 && r->p.g < INFINITY;
        for (int j = 0; j < 10; j++)
            ok = ok && pf[j] > 0.0 && pf[j] < INFINITY;
        if (!ok) {
            PyErr_Format(PyExc_ValueError, "robots row %zd: mu, masses, inertias, lengths or g out of range", i);
            return 0;
        }
    }
    for (Py_ssize_t i = 0; modes && i < b->n; i++) {
        const env_state *s = b->state + i;
        if (s->mode < LEG_STICK || s->mode > LEG_FLIGHT || s->prev_mode < LEG_STICK || s->prev_mode > LEG_FLIGHT) {
            PyErr_Format(PyExc_ValueError, "state row %zd: the contact modes must be 0, 1, 2 or 3, got %d (prev_mode %d)", i,
                         (int)s->mode, (int)s->prev_mode);
            return 0;
        }
    }
    return 1;
}

/* obs's width is the one the task and the ground of the settings need (checked at every call of a Batch
 * too: its settings can be written after it bound obs, and the task's kernel writes that many columns). */
static int obs_fits(int task, const env_batch *b)
{
    if (b->obs == NULL)
        return 1;
    if (task == TASK_HOP && b->settings->task.hop.observe_apex && !b->settings->task.hop.observe_progress) {
        PyErr_SetString(PyExc_ValueError, "obs cannot fit this task and its settings: observe_apex needs observe_progress (the apex is the entry after the ground time)");
        return 0;
    }
    const Py_ssize_t need = task_obs_dim(task, b->settings);
    if (b->obs_cols != need) {
        PyErr_Format(PyExc_ValueError, "obs must have shape (%zd, %zd) for this task and its settings (unilateral, observe_progress, observe_apex, observe_com), got (%zd, %zd)",
                     b->n, need, b->n, b->obs_cols);
        return 0;
    }
    return 1;
}

/* The arrays of a call, checked: (state, robots, settings, out) and obs (NULL for the physics alone). */
static int batch_of(int task, PyObject *state, PyObject *robots, PyObject *settings, PyObject *out, PyObject *obs, held *h,
                    env_batch *b, int modes)
{
    Py_ssize_t rows, cols;
    if (task < TASK_STANCE || task >= N_TASKS) {
        PyErr_Format(PyExc_ValueError, "task must be 0 (stance), 1 (push) or 2 (hop), got %d", task);
        return 0;
    }
    b->state = (env_state *)rows_of(state, "state", sizeof(env_state), 1, h, &b->n);
    if (b->state == NULL)
        return 0;
    b->robots = (const env_robot *)rows_of(robots, "robots", sizeof(env_robot), 0, h, &b->robot_rows);
    if (b->robots == NULL)
        return 0;
    if (b->robot_rows < 1 || (b->robot_rows != 1 && b->robot_rows != b->n)) {
        PyErr_Format(PyExc_ValueError, "robots must have 1 row or one per robot (%zd), got %zd", b->n, b->robot_rows);
        return 0;
    }
    b->settings = (const env_settings *)rows_of(settings, "settings", sizeof(env_settings), 0, h, &rows);
    if (b->settings == NULL)
        return 0;
    if (rows != 1) {
        PyErr_Format(PyExc_ValueError, "settings must have 1 row, got %zd", rows);
        return 0;
    }
    b->out = (env_out *)rows_of(out, "out", sizeof(env_out), 1, h, &rows);
    if (b->out == NULL)
        return 0;
    if (rows != b->n) {
        PyErr_Format(PyExc_ValueError, "out must have one row per robot (%zd), got %zd", b->n, rows);
        return 0;
    }
    b->obs = NULL;
    b->obs_cols = 0;
    if (obs != NULL) {
        b->obs = (float *)matrix_of(obs, "obs", F32, 1, h, &rows, &cols);
        if (b->obs == NULL)
            return 0;
        if (rows != b->n) {
            PyErr_Format(PyExc_ValueError, "obs must have one row per robot (%zd), got %zd", b->n, rows);
            return 0;
        }
        b->obs_cols = cols;
    }
    return obs_fits(task, b) && batch_values(b, modes);
}

/* An integer argument: a TypeError naming `name` if `obj` is not an integer, a ValueError if it is out of range. */
static int int_arg(PyObject *obj, const char *name, Py_ssize_t *out)
{
    PyObject *index = PyNumber_Index(obj);
    if (index == NULL) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be an integer, got %.80R", name, obj);
        return 0;
    }
    *out = PyLong_AsSsize_t(index);
    Py_DECREF(index);
    if (*out == -1 && PyErr_Occurred()) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "%s is out of range, got %.80R", name, obj);
        return 0;
    }
    return 1;
}

/* physics_range(lo, hi, state, robots, settings, out): one control step of rows lo .. hi - 1 (GIL released) */
static PyObject *py_physics_range(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    env_batch b;
    Py_ssize_t lo, hi;
    if (!n_args(nargs, 6, "physics_range") || !int_arg(args[0], "lo", &lo) || !int_arg(args[1], "hi", &hi))
        return NULL;
    if (!batch_of(TASK_STANCE, args[2], args[3], args[4], args[5], NULL, &h, &b, 1))
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

/* The start noise argument: None (the states are given), or (N, 6) uniforms (not read at scale 0). */
static int noise_of(PyObject *noise_obj, PyObject *scale_obj, Py_ssize_t n, held *h, const double **noise, double *scale)
{
    static const double zeros[6] = {0.0};
    *noise = NULL;
    *scale = 0.0;
    if (noise_obj == Py_None)
        return 1;
    if (!as_double(scale_obj, "scale", scale))
        return 0;
    if (!(*scale >= 0.0 && *scale < INFINITY)) {
        PyErr_SetString(PyExc_ValueError, "scale must be finite and >= 0");
        return 0;
    }
    *noise = zeros;
    if (*scale > 0.0) {
        *noise = (const double *)buffer_of(noise_obj, "noise", F64, 6 * n, 0, h, NULL);
        if (*noise == NULL)
            return 0;
    }
    return 1;
}

/* start(task, state, robots, settings, out, obs, noise, scale): the rows put on their contact (at their
 * nominal posture plus noise, or where the state has them if noise is None), then the task's evaluation */
static PyObject *py_start(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    env_batch b;
    Py_ssize_t task;
    const double *noise;
    double scale;
    if (!n_args(nargs, 8, "start") || !int_arg(args[0], "task", &task))
        return NULL;
    if (!batch_of((int)(task < 0 || task >= N_TASKS ? -1 : task), args[1], args[2], args[3], args[4], args[5], &h, &b, 0)
        || !noise_of(args[6], args[7], b.n, &h, &noise, &scale))
        goto fail;
    physics_start(&b, noise, scale);
    task_start((int)task, &b);
    release_all(&h);
    Py_RETURN_NONE;
fail:
    release_all(&h);
    return NULL;
}

/* assess(task, state, robots, settings, out, obs): the task after a control step of every row */
static PyObject *py_assess(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    env_batch b;
    Py_ssize_t task;
    if (!n_args(nargs, 6, "assess") || !int_arg(args[0], "task", &task))
        return NULL;
    if (!batch_of((int)(task < 0 || task >= N_TASKS ? -1 : task), args[1], args[2], args[3], args[4], args[5], &h, &b, 1))
        goto fail;
    task_assess((int)task, &b, 0, b.n);
    release_all(&h);
    Py_RETURN_NONE;
fail:
    release_all(&h);
    return NULL;
}

/* Rows stepped and assessed together by `step`: a block's state, out and robot rows stay in cache between
 * the physics and the task's kernels. */
#define STEP_BLOCK 32

/* step(task, lo, hi, state, robots, settings, out, obs): one control step of rows lo .. hi - 1 and the task
 * after it, block by block (GIL released): bitwise physics_range then assess of the same rows, with the
 * arrays checked once */
static PyObject *py_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    env_batch b;
    Py_ssize_t task, lo, hi;
    if (!n_args(nargs, 8, "step") || !int_arg(args[0], "task", &task) || !int_arg(args[1], "lo", &lo) || !int_arg(args[2], "hi", &hi))
        return NULL;
    if (!batch_of((int)(task < 0 || task >= N_TASKS ? -1 : task), args[3], args[4], args[5], args[6], args[7], &h, &b, 1))
        goto fail;
    if (!(0 <= lo && lo <= hi && hi <= b.n)) {
        PyErr_Format(PyExc_ValueError, "rows lo .. hi must satisfy 0 <= lo <= hi <= %zd, got %zd .. %zd", b.n, lo, hi);
        goto fail;
    }
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = lo; i < hi; i += STEP_BLOCK) {
        const Py_ssize_t end = hi - i > STEP_BLOCK ? i + STEP_BLOCK : hi;
        physics_range(&b, i, end);
        task_assess((int)task, &b, i, end);
    }
    Py_END_ALLOW_THREADS
    release_all(&h);
    Py_RETURN_NONE;
fail:
    release_all(&h);
    return NULL;
}

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

#define ROBOT_DOUBLES ((Py_ssize_t)(sizeof(env_robot) / sizeof(double)))
typedef char env_robot_is_doubles[sizeof(env_robot) % sizeof(double) == 0 ? 1 : -1];
#define N_LIMITS 7

/* The robot spec of a randomisation, checked: (F, 4) rows (the field's index among env_robot's doubles,
 * kind, low, high), every index a drawn field's (a parameter, mu or a torque limit: not what follows). */
static const double *spec_of(PyObject *obj, Py_ssize_t *n_spec, held *h)
{
    const double *spec = (const double *)buffer_of(obj, "spec", F64, -4, 0, h, n_spec);
    if (spec == NULL)
        return NULL;
    const double first_derived = (double)(offsetof(env_robot, q_nom) / sizeof(double));
    for (Py_ssize_t f = 0; f < *n_spec; f++) {
        const double col = spec[4 * f], kind = spec[4 * f + 1];
        if (!(col >= 0.0 && col < first_derived && col == floor(col)) || !(kind == 0.0 || kind == 1.0 || kind == 2.0)) {
            PyErr_Format(PyExc_ValueError, "spec row %zd: the field must be a drawn one's index in [0, %g) and kind 0, 1 or 2", f,
                         first_derived);
            return NULL;
        }
    }
    return spec;
}

/* robot_params(u, spec, base, limits, row) -> bool: base and row are 1-row arrays of env_robot */
static PyObject *py_robot_params(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BEGIN
    if (!n_args(nargs, 5, "robot_params"))
        return NULL;
    Py_ssize_t n_spec = 0, rows = 0;
    const double *spec = spec_of(args[1], &n_spec, &h);
    CHECK(spec)
    const double *u = F64_IN(args[0], "u", n_spec);
    CHECK(u)
    const env_robot *base = (const env_robot *)rows_of(args[2], "base", sizeof(env_robot), 0, &h, &rows);
    CHECK(base)
    if (rows != 1) {
        PyErr_Format(PyExc_ValueError, "base must have 1 row, got %zd", rows);
        goto fail;
    }
    const double *limits = F64_IN(args[3], "limits", N_LIMITS);
    CHECK(limits)
    env_robot *row = (env_robot *)rows_of(args[4], "row", sizeof(env_robot), 1, &h, &rows);
    CHECK(row)
    if (rows != 1) {
        PyErr_Format(PyExc_ValueError, "row must have 1 row, got %zd", rows);
        goto fail;
    }
    (void)n;
    const int accepted = robot_params(u, spec, n_spec, base, limits, row);
    release_all(&h);
    return PyBool_FromLong(accepted);
    FAIL
}

/* The bit generator of one entry of `generators`: a numpy Generator or BitGenerator. A new reference to the
 * BitGenerator is left in *owner, held for as long as it is drawn from. A bare capsule is refused: it does not
 * keep its BitGenerator alive (numpy's capsule holds a pointer into it). NULL with a ValueError. */
static PyObject *name_capsule, *name_bit_generator; /* interned at import: looked up for every drawn row */

static bitgen_t *bitgen_of(PyObject *entry, long long index, PyObject **owner)
{
    PyObject *capsule = NULL, *bit_generator = NULL;
    *owner = NULL;
    if (entry != Py_None && !PyCapsule_CheckExact(entry)) { /* a bare capsule does not keep its generator alive */
        capsule = PyObject_GetAttr(entry, name_capsule); /* a BitGenerator */
        if (capsule != NULL) {
            Py_INCREF(entry);
            bit_generator = entry;
        } else {
            PyErr_Clear();
            bit_generator = PyObject_GetAttr(entry, name_bit_generator); /* a Generator */
            if (bit_generator == NULL)
                PyErr_Clear();
            else if ((capsule = PyObject_GetAttr(bit_generator, name_capsule)) == NULL)
                PyErr_Clear();
        }
        *owner = bit_generator;
    }
    bitgen_t *bg = capsule != NULL && PyCapsule_IsValid(capsule, "BitGenerator") ? (bitgen_t *)PyCapsule_GetPointer(capsule, "BitGenerator") : NULL;
    Py_XDECREF(capsule); /* the owner holds it (a BitGenerator keeps its capsule) */
    if (bg == NULL || bg->next_double == NULL) {
        PyErr_Clear();
        Py_CLEAR(*owner);
        PyErr_Format(PyExc_ValueError, "generators[%lld] is not a numpy Generator or BitGenerator", index);
        return NULL;
    }
    return bg;
}

/* Generators(n): the bit generators of n rows, each held with a pointer to its C interface, so that a draw
 * reads the pointers of the rows it draws from instead of looking each one up through Python attributes. A row
 * is set by set(i, generator) (a numpy Generator or BitGenerator), which holds a reference to its BitGenerator
 * for as long as the row keeps it: the pointer stays valid. draw_uniform and draw_robots take one in place of
 * a list. */
typedef struct {
    PyObject_HEAD Py_ssize_t n;
    PyObject **owners; /* the BitGenerators (NULL: not set) */
    bitgen_t **bg;     /* their C interfaces */
} GeneratorsObject;

#define GENERATORS_MAX ((Py_ssize_t)1 << 26)

static int Generators_traverse(GeneratorsObject *self, visitproc visit, void *arg)
{
    for (Py_ssize_t i = 0; i < self->n; i++)
        Py_VISIT(self->owners[i]);
    return 0;
}

static int Generators_clear(GeneratorsObject *self)
{
    for (Py_ssize_t i = 0; i < self->n; i++) {
        self->bg[i] = NULL;
        Py_CLEAR(self->owners[i]);
    }
    return 0;
}

static void Generators_dealloc(GeneratorsObject *self)
{
    PyObject_GC_UnTrack(self);
    if (self->owners != NULL)
        Generators_clear(self);
    PyMem_Free(self->owners);
    PyMem_Free(self->bg);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *Generators_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    static char *names[] = {"n", NULL};
    PyObject *n_obj;
    Py_ssize_t n;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O:Generators", names, &n_obj) || !int_arg(n_obj, "n", &n))
        return NULL;
    if (n < 0 || n > GENERATORS_MAX) {
        PyErr_Format(PyExc_ValueError, "Generators: n must be in [0, %zd], got %zd", GENERATORS_MAX, n);
        return NULL;
    }
    GeneratorsObject *self = (GeneratorsObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    self->n = 0;
    self->owners = PyMem_Calloc(n ? n : 1, sizeof(PyObject *));
    self->bg = PyMem_Calloc(n ? n : 1, sizeof(bitgen_t *));
    if (self->owners == NULL || self->bg == NULL) {
        Py_DECREF(self);
        return PyErr_NoMemory();
    }
    self->n = n;
    return (PyObject *)self;
}

static PyObject *Generators_set(GeneratorsObject *self, PyObject *args)
{
    PyObject *row, *generator, *owner = NULL;
    Py_ssize_t i;
    if (!PyArg_ParseTuple(args, "OO:set", &row, &generator) || !int_arg(row, "row", &i))
        return NULL;
    if (i < 0 || i >= self->n) {
        PyErr_Format(PyExc_ValueError, "Generators.set: row %zd is not in [0, %zd)", i, self->n);
        return NULL;
    }
    bitgen_t *bg = bitgen_of(generator, (long long)i, &owner);
    if (bg == NULL)
        return NULL;
    self->bg[i] = bg;
    Py_XSETREF(self->owners[i], owner); /* the new reference bitgen_of left */
    Py_RETURN_NONE;
}

static Py_ssize_t Generators_len(GeneratorsObject *self) { return self->n; }

static PyMethodDef Generators_methods[] = {
    {"set", (PyCFunction)Generators_set, METH_VARARGS, "set(i, generator): row i draws from this numpy Generator or BitGenerator."},
    {NULL, NULL, 0, NULL},
};

static PySequenceMethods Generators_sequence = {.sq_length = (lenfunc)Generators_len};

static PyTypeObject GeneratorsType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "leg_env._core.kernels.Generators",
    .tp_basicsize = sizeof(GeneratorsObject),
    .tp_dealloc = (destructor)Generators_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_doc = "Generators(n): the bit generators of n rows, held for compiled draws (set(i, generator)).",
    .tp_traverse = (traverseproc)Generators_traverse,
    .tp_clear = (inquiry)Generators_clear,
    .tp_methods = Generators_methods,
    .tp_as_sequence = &Generators_sequence,
    .tp_new = Generators_new,
};

/* The bit generators of `generators` (a list of numpy Generators or BitGenerators, or a Generators) at
 * `rows`, with a reference to each listed one's owner in owners[k] (release_owners() frees them; a Generators
 * holds its own, and owners stay NULL). */
static int bitgens_of(PyObject *generators, const int64_t *rows, Py_ssize_t n_rows, bitgen_t **out, PyObject **owners)
{
    for (Py_ssize_t k = 0; k < n_rows; k++)
        owners[k] = NULL;
    if (Py_IS_TYPE(generators, &GeneratorsType)) { /* held: the pointers are valid while it is (the caller holds it) */
        const GeneratorsObject *G = (const GeneratorsObject *)generators;
        for (Py_ssize_t k = 0; k < n_rows; k++) {
            if (rows[k] < 0 || rows[k] >= G->n) {
                PyErr_Format(PyExc_ValueError, "rows[%zd] = %lld is not an index of generators", k, (long long)rows[k]);
                return 0;
            }
            if ((out[k] = G->bg[rows[k]]) == NULL) {
                PyErr_Format(PyExc_ValueError, "generators[%lld] is not set", (long long)rows[k]);
                return 0;
            }
        }
        return 1;
    }
    if (!PyList_Check(generators)) {
        PyErr_Format(PyExc_TypeError, "generators must be a list of numpy Generators or BitGenerators (or a Generators), got %.80R",
                     (PyObject *)Py_TYPE(generators));
        return 0;
    }
    for (Py_ssize_t k = 0; k < n_rows; k++) {
        /* the list's length is read at each entry: an attribute look-up may run code that changes it */
        if (rows[k] < 0 || rows[k] >= PyList_GET_SIZE(generators)) {
            PyErr_Format(PyExc_ValueError, "rows[%zd] = %lld is not an index of generators", k, (long long)rows[k]);
            return 0;
        }
        PyObject *entry = PyList_GET_ITEM(generators, rows[k]);
        Py_INCREF(entry);
        out[k] = bitgen_of(entry, (long long)rows[k], &owners[k]);
        Py_DECREF(entry);
        if (out[k] == NULL)
            return 0;
    }
    return 1;
}

static void release_owners(PyObject **owners, Py_ssize_t n)
{
    if (owners == NULL)
        return;
    for (Py_ssize_t k = 0; k < n; k++)
        Py_XDECREF(owners[k]);
}

/* draw_uniform(generators, rows, out): out[k] = generators[rows[k]]'s next out.shape[1] doubles */
static PyObject *py_draw_uniform(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    Py_ssize_t n_rows = 0, rows2, cols, n_owners = 0;
    bitgen_t **bg = NULL;
    PyObject **owners = NULL;
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
    owners = PyMem_Malloc((n_rows ? n_rows : 1) * sizeof(PyObject *));
    if (bg == NULL || owners == NULL) {
        PyErr_NoMemory();
        goto fail;
    }
    n_owners = n_rows;
    if (!bitgens_of(args[0], rows, n_rows, bg, owners))
        goto fail;
    for (Py_ssize_t k = 0; k < n_rows; k++)
        for (Py_ssize_t j = 0; j < cols; j++)
            out[k * cols + j] = bg[k]->next_double(bg[k]->state);
    release_owners(owners, n_owners);
    PyMem_Free(owners);
    PyMem_Free(bg);
    release_all(&h);
    Py_RETURN_NONE;
fail:
    release_owners(owners, n_owners);
    PyMem_Free(owners);
    PyMem_Free(bg);
    release_all(&h);
    return NULL;
}

#define DRAWS_MAX 1000000 /* most tries of draw_robots per robot: a bound on the work of one call */

/* draw_robots(generators, rows, spec, base, limits, max_draws, robots, rejected): robot_params for each
 * sub-env rows[k], drawing spec's uniforms per try from its own generator, up to max_draws tries;
 * robots[rows[k]] becomes the first accepted robot (the nominal base if every try is refused) and
 * rejected[k] the number of refused tries. */
static PyObject *py_draw_robots(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    Py_ssize_t n_rows = 0, n_spec = 0, robot_rows = 0, base_rows = 0, max_draws, n_owners = 0;
    bitgen_t **bg = NULL;
    PyObject **owners = NULL;
    double *u = NULL;
    if (!n_args(nargs, 8, "draw_robots") || !int_arg(args[5], "max_draws", &max_draws))
        return NULL;
    if (max_draws < 1 || max_draws > DRAWS_MAX) {
        PyErr_Format(PyExc_ValueError, "max_draws must be in [1, %d], got %zd", DRAWS_MAX, max_draws);
        return NULL;
    }
    const int64_t *rows = (const int64_t *)buffer_of(args[1], "rows", I64, -1, 0, &h, &n_rows);
    if (rows == NULL)
        goto fail;
    /* the generators first: looking them up may run Python code, which could write the arrays checked below */
    bg = PyMem_Malloc((n_rows ? n_rows : 1) * sizeof(bitgen_t *));
    owners = PyMem_Malloc((n_rows ? n_rows : 1) * sizeof(PyObject *));
    if (bg == NULL || owners == NULL) {
        PyErr_NoMemory();
        goto fail;
    }
    n_owners = n_rows;
    if (!bitgens_of(args[0], rows, n_rows, bg, owners))
        goto fail;
    const double *spec = spec_of(args[2], &n_spec, &h);
    const env_robot *base = spec ? (const env_robot *)rows_of(args[3], "base", sizeof(env_robot), 0, &h, &base_rows) : NULL;
    const double *limits = base ? F64_IN(args[4], "limits", N_LIMITS) : NULL;
    env_robot *robots = limits ? (env_robot *)rows_of(args[6], "robots", sizeof(env_robot), 1, &h, &robot_rows) : NULL;
    int64_t *rejected = robots ? I64_OUT(args[7], "rejected", n_rows) : NULL;
    if (rejected == NULL)
        goto fail;
    if (base_rows != 1) {
        PyErr_Format(PyExc_ValueError, "base must have 1 row, got %zd", base_rows);
        goto fail;
    }
    for (Py_ssize_t k = 0; k < n_rows; k++)
        if (rows[k] < 0 || rows[k] >= robot_rows) {
            PyErr_Format(PyExc_ValueError, "rows[%zd] = %lld is not a row of robots", k, (long long)rows[k]);
            goto fail;
        }
    u = PyMem_Malloc((n_spec ? n_spec : 1) * sizeof(double));
    if (u == NULL) {
        PyErr_NoMemory();
        goto fail;
    }
    for (Py_ssize_t k = 0; k < n_rows; k++) {
        env_robot *row = robots + rows[k];
        rejected[k] = max_draws;
        for (Py_ssize_t t = 0; t < max_draws; t++) {
            for (Py_ssize_t j = 0; j < n_spec; j++)
                u[j] = bg[k]->next_double(bg[k]->state);
            if (robot_params(u, spec, n_spec, base, limits, row)) {
                rejected[k] = t;
                break;
            }
        }
        if (rejected[k] == max_draws)
            *row = *base;
    }
    release_owners(owners, n_owners);
    PyMem_Free(owners);
    PyMem_Free(bg);
    PyMem_Free(u);
    release_all(&h);
    Py_RETURN_NONE;
fail:
    release_owners(owners, n_owners);
    PyMem_Free(owners);
    PyMem_Free(bg);
    PyMem_Free(u);
    release_all(&h);
    return NULL;
}

/* info_columns(spec, out, state, doubles, ints, flags, vectors, names, codes): every row's info keys in one
 * pass, each key's values into a row of a fresh block: spec is a tuple of (source, offset, kind, row): source
 * 0 out, 1 state; kind 'd' a double into doubles[row], 'i' an int32 into ints[row] (int64), '?' a byte into
 * flags[row] (bool), 'v' two doubles into vectors[row] (an (N, 2) block), 'm' the contact mode (an int32 in
 * 0 .. 3) as its name into names[row]: the mode's row of codes, the (4, W) UCS-4 code points of the names
 * (names is the uint32 view of an (R, N) array of W-character strings). leg_env.info makes the blocks and
 * the keys' views of them. */
#define INFO_BLOCK_ROWS 128 /* rows of out and state read per block: 128 x 680 bytes stay in L1/L2 */

static PyObject *py_info_columns(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    Py_ssize_t n = 0, n_state = 0, r_d = 0, r_i = 0, r_b = 0, r_v = 0, r_m = 0, n_codes = 0;
    if (!n_args(nargs, 9, "info_columns"))
        return NULL;
    if (!PyTuple_Check(args[0])) {
        PyErr_SetString(PyExc_TypeError, "info_columns: spec must be a tuple");
        return NULL;
    }
    const char *out = (const char *)rows_of(args[1], "out", sizeof(env_out), 0, &h, &n);
    const char *state = out ? (const char *)rows_of(args[2], "state", sizeof(env_state), 0, &h, &n_state) : NULL;
    double *doubles = state ? (double *)buffer_of(args[3], "doubles", F64, -(n > 0 ? n : 1), 1, &h, &r_d) : NULL;
    int64_t *ints = doubles ? (int64_t *)buffer_of(args[4], "ints", I64, -(n > 0 ? n : 1), 1, &h, &r_i) : NULL;
    unsigned char *flags = ints ? (unsigned char *)matrix_of(args[5], "flags", BOOL, 1, &h, &r_b, &n_state) : NULL;
    double *vectors = flags ? (double *)buffer_of(args[6], "vectors", F64, -(2 * (n > 0 ? n : 1)), 1, &h, &r_v) : NULL;
    const uint32_t *codes = vectors ? (const uint32_t *)buffer_of(args[8], "codes", U32, -LEG_N_MODES, 0, &h, &n_codes) : NULL;
    const Py_ssize_t width = n_codes; /* characters of a mode's name */
    uint32_t *names = codes && width > 0 ? (uint32_t *)buffer_of(args[7], "names", U32, -(width * (n > 0 ? n : 1)), 1, &h, &r_m) : NULL;
    if (codes != NULL && width == 0)
        PyErr_SetString(PyExc_ValueError, "info_columns: codes must have shape (4, W) with W > 0");
    if (names == NULL)
        goto fail;
    Py_ssize_t n_rows_state = 0;
    rows_of(args[2], "state", sizeof(env_state), 0, &h, &n_rows_state);
    if (n_rows_state != n || (r_b > 0 && n_state != n)) {
        PyErr_SetString(PyExc_ValueError, "info_columns: out, state and the blocks must have the same rows");
        goto fail;
    }
    const Py_ssize_t m = PyTuple_GET_SIZE(args[0]);
    long *spec = PyMem_Malloc((m ? m : 1) * 4 * sizeof(long));
    if (spec == NULL) {
        PyErr_NoMemory();
        goto fail;
    }
    for (Py_ssize_t k = 0; k < m; k++) {
        PyObject *item = PyTuple_GET_ITEM(args[0], k);
        if (!PyTuple_Check(item) || PyTuple_GET_SIZE(item) != 4 || !PyUnicode_Check(PyTuple_GET_ITEM(item, 2))) {
            PyMem_Free(spec);
            PyErr_SetString(PyExc_TypeError, "info_columns: every spec entry must be (source, offset, kind, row)");
            goto fail;
        }
        const long source = PyLong_AsLong(PyTuple_GET_ITEM(item, 0)), offset = PyLong_AsLong(PyTuple_GET_ITEM(item, 1));
        const long row = PyLong_AsLong(PyTuple_GET_ITEM(item, 3));
        const char *kind = PyUnicode_AsUTF8(PyTuple_GET_ITEM(item, 2));
        if (PyErr_Occurred() || kind == NULL) {
            PyMem_Free(spec);
            goto fail;
        }
        const size_t size = source == 0 ? sizeof(env_out) : sizeof(env_state);
        const size_t bytes = kind[0] == 'd' ? 8 : (kind[0] == 'v' ? 16 : (kind[0] == '?' ? 1 : 4));
        const Py_ssize_t rows = kind[0] == 'd' ? r_d : (kind[0] == 'v' ? r_v : (kind[0] == '?' ? r_b : (kind[0] == 'm' ? r_m : r_i)));
        if ((source != 0 && source != 1) || offset < 0 || (size_t)offset + bytes > size || row < 0 || row >= rows
            || !(kind[0] == 'd' || kind[0] == 'i' || kind[0] == 'm' || kind[0] == '?' || kind[0] == 'v')) {
            PyMem_Free(spec);
            PyErr_Format(PyExc_ValueError, "info_columns: spec entry %zd is outside its row or block", k);
            goto fail;
        }
        spec[4 * k] = source;
        spec[4 * k + 1] = offset;
        spec[4 * k + 2] = kind[0];
        spec[4 * k + 3] = row;
    }
    /* a block of rows at a time (their out and state rows stay in cache), in it a key at a time: one strided
     * read, one contiguous write */
    int bad_mode = 0;
    for (Py_ssize_t i0 = 0; i0 < n; i0 += INFO_BLOCK_ROWS) {
        const Py_ssize_t i1 = i0 + INFO_BLOCK_ROWS < n ? i0 + INFO_BLOCK_ROWS : n;
        for (Py_ssize_t k = 0; k < m; k++) {
            const size_t stride = spec[4 * k] == 0 ? sizeof(env_out) : sizeof(env_state);
            const char *at = (spec[4 * k] == 0 ? out : state) + spec[4 * k + 1];
            const long row = spec[4 * k + 3];
            switch ((char)spec[4 * k + 2]) {
            case 'd': {
                double *dst = doubles + row * n;
                for (Py_ssize_t i = i0; i < i1; i++)
                    memcpy(dst + i, at + i * stride, 8);
                break;
            }
            case 'm': {
                uint32_t *dst = names + row * n * width;
                for (Py_ssize_t i = i0; i < i1; i++) {
                    int32_t mode;
                    memcpy(&mode, at + i * stride, 4);
                    if (mode < 0 || mode >= LEG_N_MODES) {
                        bad_mode = 1;
                        mode = 0;
                    }
                    for (Py_ssize_t j = 0; j < width; j++)
                        dst[i * width + j] = codes[mode * width + j];
                }
                break;
            }
            case 'i': {
                int64_t *dst = ints + row * n;
                for (Py_ssize_t i = i0; i < i1; i++) {
                    int32_t i32;
                    memcpy(&i32, at + i * stride, 4);
                    dst[i] = i32;
                }
                break;
            }
            case '?': {
                unsigned char *dst = flags + row * n;
                for (Py_ssize_t i = i0; i < i1; i++)
                    dst[i] = at[i * stride] != 0;
                break;
            }
            default: {
                double *dst = vectors + row * n * 2;
                for (Py_ssize_t i = i0; i < i1; i++)
                    memcpy(dst + 2 * i, at + i * stride, 16);
            }
            }
        }
    }
    PyMem_Free(spec);
    if (bad_mode) {
        PyErr_SetString(PyExc_ValueError, "info_columns: a contact mode outside 0 .. 3 in out");
        goto fail;
    }
    release_all(&h);
    Py_RETURN_NONE;
fail:
    release_all(&h);
    return NULL;
}

/* ------------------------------------------------------------------------------------------------
 * Batch: one env's arrays handed to C once (the single environment's step is one call)
 * ------------------------------------------------------------------------------------------------ */

/* One key of a bound info spec (Batch.bind_info): read from the out (0) or state (1) row at `offset` as `kind`. */
typedef struct {
    PyObject *key;
    int source;
    Py_ssize_t offset;
    char kind;
} info_item;

typedef struct {
    PyObject_HEAD held h;
    env_batch b;
    int task;
    info_item *items;    /* the bound info spec, NULL before bind_info */
    Py_ssize_t n_items;  /* its keys with the reward terms */
    Py_ssize_t n_plain;  /* without them (the first n_plain) */
    Py_ssize_t n_vec;    /* doubles of its array-valued keys */
    PyObject *names;     /* the contact modes' names */
} BatchObject;

static void info_unbind(BatchObject *self)
{
    for (Py_ssize_t k = 0; self->items != NULL && k < self->n_items; k++)
        Py_XDECREF(self->items[k].key);
    PyMem_Free(self->items);
    self->items = NULL;
    self->n_items = self->n_plain = self->n_vec = 0;
    Py_CLEAR(self->names);
}

static void Batch_dealloc(BatchObject *self)
{
    info_unbind(self);
    release_all(&self->h);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *Batch_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    PyObject *task_obj, *state, *robots, *settings, *out, *obs;
    Py_ssize_t task;
    if (kwds != NULL && PyDict_Size(kwds) > 0) {
        PyErr_SetString(PyExc_TypeError, "Batch takes no keyword arguments");
        return NULL;
    }
    if (!PyTuple_Check(args) || PyTuple_GET_SIZE(args) != 6) {
        PyErr_Format(PyExc_TypeError, "Batch takes 6 arguments (task, state, robots, settings, out, obs), got %zd",
                     PyTuple_Check(args) ? PyTuple_GET_SIZE(args) : (Py_ssize_t)-1);
        return NULL;
    }
    if (!PyArg_UnpackTuple(args, "Batch", 6, 6, &task_obj, &state, &robots, &settings, &out, &obs) || !int_arg(task_obj, "task", &task))
        return NULL;
    BatchObject *self = (BatchObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    self->h.n = 0;
    self->items = NULL;
    self->n_items = self->n_plain = self->n_vec = 0;
    self->names = NULL;
    self->task = (int)(task < 0 || task >= N_TASKS ? -1 : task);
    if (!batch_of(self->task, state, robots, settings, out, obs, &self->h, &self->b, 0)) {
        Py_DECREF(self);
        return NULL;
    }
    if (self->b.n < 1) { /* step_one steps robot 0 */
        PyErr_SetString(PyExc_ValueError, "Batch: state must have at least one row (robot 0 is the one stepped)");
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
    double a0, a1;
    if (!as_double(args[0], "a0", &a0) || !as_double(args[1], "a1", &a1))
        return NULL;
    if (!(isfinite(a0) && isfinite(a1))) {
        PyErr_Format(PyExc_ValueError, "step_one: the action (a0, a1) must be finite, got (%g, %g)", a0, a1);
        return NULL;
    }
    const env_batch *b = &self->b;
    if (!batch_values(b, 1) || !obs_fits(self->task, b)) /* the arrays may have been written since the last call */
        return NULL;
    env_state *s = state_row(b, 0);
    s->action[0] = a0;
    s->action[1] = a1;
    physics_range(b, 0, 1);
    task_assess(self->task, b, 0, 1);
    return PyFloat_FromDouble(summed_terms(self->task, b));
}

/* start(noise or None, scale): every robot started (at its nominal posture plus noise, or where the state
 * has it if noise is None) and evaluated by the task, without stepping */
static PyObject *Batch_start(BatchObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    const double *noise;
    double scale;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "start takes 2 arguments (noise or None, scale)");
        return NULL;
    }
    if (!batch_values(&self->b, 0) || !obs_fits(self->task, &self->b) || !noise_of(args[0], args[1], self->b.n, &h, &noise, &scale)) {
        release_all(&h);
        return NULL;
    }
    physics_start(&self->b, noise, scale);
    task_start(self->task, &self->b);
    release_all(&h);
    Py_RETURN_NONE;
}

/* bind_info(spec, n_plain, names): the info keys robot 0's info() reads, parsed once: spec is a tuple of
 * (key, source, offset, kind): source 0 the out row, 1 the state row; offset in bytes; kind 'd' a double, 'i' an
 * int32, '?' a byte flag, 'm' an int32 contact mode given as names[mode], 'v' two doubles (a slice of info()'s
 * vectors array); the first n_plain entries are the keys without the reward terms. */
static PyObject *Batch_bind_info(BatchObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    Py_ssize_t n_plain;
    if (nargs != 3 || !PyTuple_Check(args[0]) || !PyTuple_Check(args[2])) {
        PyErr_SetString(PyExc_TypeError, "bind_info takes (spec tuple, n_plain, mode names tuple)");
        return NULL;
    }
    if (!int_arg(args[1], "n_plain", &n_plain))
        return NULL;
    PyObject *spec = args[0];
    const Py_ssize_t n = PyTuple_GET_SIZE(spec);
    if (n_plain < 0 || n_plain > n) {
        PyErr_Format(PyExc_ValueError, "bind_info: n_plain must be in [0, %zd], got %zd", n, n_plain);
        return NULL;
    }
    info_item *items = PyMem_Calloc(n ? n : 1, sizeof(info_item));
    if (items == NULL)
        return PyErr_NoMemory();
    Py_ssize_t n_vec = 0;
    for (Py_ssize_t k = 0; k < n; k++) {
        PyObject *item = PyTuple_GET_ITEM(spec, k);
        if (!PyTuple_Check(item) || PyTuple_GET_SIZE(item) != 4 || !PyUnicode_Check(PyTuple_GET_ITEM(item, 0))
            || !PyUnicode_Check(PyTuple_GET_ITEM(item, 3))) {
            PyErr_SetString(PyExc_TypeError, "bind_info: every spec entry must be (key, source, offset, kind)");
            goto fail;
        }
        const long source = PyLong_AsLong(PyTuple_GET_ITEM(item, 1));
        const long offset = PyLong_AsLong(PyTuple_GET_ITEM(item, 2));
        const char *kind = PyUnicode_AsUTF8(PyTuple_GET_ITEM(item, 3));
        if (PyErr_Occurred() || kind == NULL)
            goto fail;
        if (strlen(kind) != 1 || strchr("di?mv", kind[0]) == NULL) {
            PyErr_Format(PyExc_ValueError, "bind_info: unknown kind %s", kind);
            goto fail;
        }
        const size_t size = source == 0 ? sizeof(env_out) : sizeof(env_state);
        const size_t width = kind[0] == 'd' ? 8 : (kind[0] == 'v' ? 16 : (kind[0] == '?' ? 1 : 4));
        if ((source != 0 && source != 1) || offset < 0 || (size_t)offset + width > size) {
            PyErr_Format(PyExc_ValueError, "bind_info: spec entry %zd reads outside its row", k);
            goto fail;
        }
        items[k].key = PyTuple_GET_ITEM(item, 0);
        Py_INCREF(items[k].key);
        items[k].source = (int)source;
        items[k].offset = offset;
        items[k].kind = kind[0];
        n_vec += kind[0] == 'v' ? 2 : 0;
    }
    info_unbind(self);
    self->items = items;
    self->n_items = n;
    self->n_plain = n_plain;
    self->n_vec = n_vec;
    self->names = args[2];
    Py_INCREF(self->names);
    Py_RETURN_NONE;
fail:
    for (Py_ssize_t k = 0; k < n; k++)
        Py_XDECREF(items[k].key);
    PyMem_Free(items);
    return NULL;
}

/* info(rewards, vectors) -> dict: robot 0's info by the bound spec (with the reward terms if rewards is true);
 * the array-valued keys are slices of `vectors`, a fresh float64 array of the spec's n_vec doubles. */
static PyObject *Batch_info(BatchObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    held h;
    h.n = 0;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "info takes (rewards, vectors)");
        return NULL;
    }
    if (self->items == NULL) {
        PyErr_SetString(PyExc_ValueError, "info: no spec bound (call bind_info first)");
        return NULL;
    }
    const int rewards = PyObject_IsTrue(args[0]);
    if (rewards < 0)
        return NULL;
    PyObject *vec_obj = args[1];
    Py_ssize_t n_vec = 0;
    double *vec = (double *)buffer_of(vec_obj, "vectors", F64, -1, 1, &h, &n_vec);
    if (vec == NULL)
        return NULL;
    if (n_vec < self->n_vec) {
        PyErr_Format(PyExc_ValueError, "info: vectors must hold %zd doubles, got %zd", self->n_vec, n_vec);
        goto fail_h;
    }
    const char *out = (const char *)self->b.out, *state = (const char *)self->b.state;
    const Py_ssize_t n = rewards ? self->n_items : self->n_plain;
    PyObject *info = PyDict_New();
    if (info == NULL)
        goto fail_h;
    Py_ssize_t used = 0;
    for (Py_ssize_t k = 0; k < n; k++) {
        const info_item *it = self->items + k;
        const char *at = (it->source == 0 ? out : state) + it->offset;
        PyObject *value = NULL;
        double x;
        int32_t i32;
        switch (it->kind) {
        case 'd':
            memcpy(&x, at, 8);
            value = PyFloat_FromDouble(x);
            break;
        case 'i':
            memcpy(&i32, at, 4);
            value = PyLong_FromLong(i32);
            break;
        case '?':
            value = PyBool_FromLong(*at != 0);
            break;
        case 'm':
            memcpy(&i32, at, 4);
            if (i32 < 0 || i32 >= PyTuple_GET_SIZE(self->names)) {
                PyErr_Format(PyExc_ValueError, "info: contact mode %d has no name", (int)i32);
                goto fail;
            }
            value = PyTuple_GET_ITEM(self->names, i32);
            Py_INCREF(value);
            break;
        default: /* 'v' */
            memcpy(vec + used, at, 16);
            value = PySequence_GetSlice(vec_obj, used, used + 2);
            used += 2;
            break;
        }
        if (value == NULL || PyDict_SetItem(info, it->key, value) < 0) {
            Py_XDECREF(value);
            goto fail;
        }
        Py_DECREF(value);
    }
    release_all(&h);
    return info;
fail:
    Py_DECREF(info);
fail_h:
    release_all(&h);
    return NULL;
}

static PyMethodDef Batch_methods[] = {
    {"bind_info", (PyCFunction)(void (*)(void))Batch_bind_info, METH_FASTCALL,
     "bind_info(spec, n_plain, names): the info keys info() reads, parsed once."},
    {"info", (PyCFunction)(void (*)(void))Batch_info, METH_FASTCALL,
     "info(rewards, vectors) -> dict: robot 0's info keys read from its out and state rows by the bound spec (leg_env.info)."},
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
    .tp_doc = "Batch(task, state, robots, settings, out, obs): an env's arrays, held for its control steps.",
    .tp_methods = Batch_methods,
    .tp_new = Batch_new,
};
