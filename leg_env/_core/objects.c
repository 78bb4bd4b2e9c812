/* The compiled module's two types: Generators (each sub-env's numpy bit generator, held for the draws) and Batch
 * (one env's arrays bound once, for the single environment's step of one call). Part of the unity build of module.c,
 * after the binder, which both use.
 */

/* ------------------------------------------------------------------------------------------ Generators */

#define MAX_ROWS ((Py_ssize_t)1 << 26) /* the most sub-envs of a batch (kernels.MAX_ROWS): one bound for every table */

static PyObject *name_capsule, *name_bit_generator; /* interned at import: looked up for every row set */

/* The bit generator of a numpy Generator or BitGenerator, with a new reference to the BitGenerator in *owner (its
 * capsule holds a pointer into it). A bare capsule is refused: it does not keep its BitGenerator alive. */
static bitgen_t *bitgen_of(PyObject *entry, Py_ssize_t row, PyObject **owner)
{
    PyObject *capsule = NULL;
    *owner = NULL;
    if (entry != Py_None && !PyCapsule_CheckExact(entry)) {
        capsule = PyObject_GetAttr(entry, name_capsule); /* a BitGenerator */
        if (capsule != NULL) {
            *owner = Py_NewRef(entry);
        } else {
            PyErr_Clear();
            *owner = PyObject_GetAttr(entry, name_bit_generator); /* a Generator */
            if (*owner == NULL || (capsule = PyObject_GetAttr(*owner, name_capsule)) == NULL)
                PyErr_Clear();
        }
    }
    bitgen_t *bg = capsule != NULL && PyCapsule_IsValid(capsule, "BitGenerator") ? (bitgen_t *)PyCapsule_GetPointer(capsule, "BitGenerator") : NULL;
    Py_XDECREF(capsule); /* the owner holds it */
    if (bg == NULL || bg->next_double == NULL) {
        PyErr_Clear();
        Py_CLEAR(*owner);
        PyErr_Format(PyExc_ValueError, "generator of row %zd is not a numpy Generator or BitGenerator", row);
    }
    return bg;
}

static void Generators_dealloc(GeneratorsObject *self)
{
    for (Py_ssize_t i = 0; self->owners != NULL && i < self->n; i++)
        Py_XDECREF(self->owners[i]);
    PyMem_Free(self->owners);
    PyMem_Free(self->bg);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *Generators_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    static char *names[] = {"n", NULL};
    Py_ssize_t n;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "n:Generators", names, &n))
        return NULL;
    if (n < 0 || n > MAX_ROWS)
        return PyErr_Format(PyExc_ValueError, "Generators: n must be in [0, %zd], got %zd", MAX_ROWS, n);
    GeneratorsObject *self = (GeneratorsObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
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
    PyObject *generator, *owner;
    Py_ssize_t i;
    if (!PyArg_ParseTuple(args, "nO:set", &i, &generator))
        return NULL;
    if (i < 0 || i >= self->n)
        return PyErr_Format(PyExc_ValueError, "Generators.set: row %zd is not in [0, %zd)", i, self->n);
    bitgen_t *bg = bitgen_of(generator, i, &owner);
    if (bg == NULL)
        return NULL;
    self->bg[i] = bg;
    Py_XSETREF(self->owners[i], owner);
    Py_RETURN_NONE;
}

static PyMethodDef Generators_methods[] = {
    {"set", (PyCFunction)Generators_set, METH_VARARGS, "set(i, generator): row i draws from this numpy Generator or BitGenerator."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject GeneratorsType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "leg_env._core.kernels.Generators",
    .tp_basicsize = sizeof(GeneratorsObject),
    .tp_dealloc = (destructor)Generators_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT, /* no cycles: a BitGenerator holds nothing of a user's */
    .tp_doc = "Generators(n): the bit generators of n rows, held for compiled draws (set(i, generator)).",
    .tp_methods = Generators_methods,
    .tp_new = Generators_new,
};

/* ------------------------------------------------------------------------------------------ Batch */

static int check_batch(call *c) { return c->n >= 1 ? env_ok(c, 1, 0) : error(PyExc_ValueError, "Batch: state must have at least one row"); }

static const entry BATCH = {"Batch", "An env's arrays, held for its control steps.", NULL, check_batch, HELD, {TASK, ENV_ARRAYS}};
static const entry BATCH_START = {"start", "", NULL, NULL, HELD, {{"noise", 'd', '1', 'i', 6, ANY, OPT_NONE}, REAL(scale, 0.0, DBL_MAX, 0)}};

typedef struct {
    PyObject_HEAD held h;
    call c;
    env_batch b;
    int task;
    PyObject *keys;     /* the bound info's keys, NULL before bind_info */
    int64_t *spec;      /* their rows (source, offset, kind, unused) */
    Py_ssize_t n_plain; /* the keys without the reward terms (the first n_plain) */
    Py_ssize_t n_vec;   /* doubles of the array-valued keys */
    PyObject *names;    /* the contact modes' names */
} BatchObject;

static void info_unbind(BatchObject *self)
{
    Py_CLEAR(self->keys);
    Py_CLEAR(self->names);
    PyMem_Free(self->spec);
    self->spec = NULL;
}

static void Batch_dealloc(BatchObject *self)
{
    info_unbind(self);
    release_all(&self->h);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *Batch_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    if ((kwds != NULL && PyDict_Size(kwds) > 0) || !PyTuple_Check(args))
        return PyErr_Format(PyExc_TypeError, "Batch takes no keyword arguments");
    BatchObject *self = (BatchObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    memset(self->c.a, 0, sizeof self->c.a);
    if (!bind(&BATCH, &PyTuple_GET_ITEM(args, 0), PyTuple_GET_SIZE(args), &self->c, &self->h)) {
        Py_DECREF(self);
        return NULL;
    }
    self->b = batch_at(&self->c, 1);
    self->task = (int)self->c.k[0];
    return (PyObject *)self;
}

/* step_one(a0, a1) -> reward: robot 0's action, its control step and the task's evaluation */
static PyObject *Batch_step_one(BatchObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    static const entry STEP = {"step_one", "", NULL, NULL, HELD, {REAL(a0, -DBL_MAX, DBL_MAX, 0), REAL(a1, -DBL_MAX, DBL_MAX, 0)}};
    BIND(STEP)
    if (!env_values(&self->b, self->task, 1)) /* the arrays may have been written since the last call */
        return NULL;
    self->b.state->action[0] = c.x[0];
    self->b.state->action[1] = c.x[1];
    physics_range(&self->b, 0, 1);
    task_assess(self->task, &self->b, 0, 1);
    return PyFloat_FromDouble(summed_terms(self->task, &self->b));
}

/* start(noise or None, scale): robot 0 started and evaluated by the task, without stepping */
static PyObject *Batch_start(BatchObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    BIND(BATCH_START)
    env_batch one = self->b;
    one.n = 1;
    if (env_values(&one, self->task, 0)) {
        physics_start(&one, (const double *)c.a[0], c.x[1]);
        task_start(self->task, &one);
    }
    release_all(&h);
    return PyErr_Occurred() ? NULL : Py_NewRef(Py_None);
}

/* bind_info(keys, spec, n_plain, names): the info keys info() reads, parsed once: spec's rows (source 0 the out
 * row, 1 the state row; byte offset; kind, as info_columns'); a mode key is given as names[mode], a vector as a
 * slice of info()'s vectors array; the first n_plain keys are those without the reward terms. */
static PyObject *Batch_bind_info(BatchObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    static const entry BIND_INFO = {"bind_info", "", NULL, NULL, HELD, {{"keys", 'g', 0, 'i', 0, ANY, 0},
                                    {"spec", 'q', '*', 'i', 4, 0.0, PY_SSIZE_T_MAX, 0}, INTEGER(n_plain, 0, PY_SSIZE_T_MAX), {"names", 'g', 0, 'i', 0, ANY, 0}}};
    BIND(BIND_INFO)
    int64_t *spec = NULL;
    if (!PyTuple_Check(args[0]) || !PyTuple_Check(args[3]) || PyTuple_GET_SIZE(args[0]) != c.rows[1] || c.k[2] > c.rows[1])
        error(PyExc_ValueError, "bind_info takes a tuple of keys, one spec row per key, n_plain at most their number and a tuple of names");
    else if (info_spec_ok((const int64_t *)c.a[1], c.rows[1], NULL) && (spec = PyMem_Malloc((c.rows[1] + 1) * 4 * sizeof(int64_t))) == NULL)
        PyErr_NoMemory();
    if (spec != NULL) {
        memcpy(spec, c.a[1], c.rows[1] * 4 * sizeof(int64_t));
        info_unbind(self);
        self->spec = spec;
        self->keys = Py_NewRef(args[0]);
        self->names = Py_NewRef(args[3]);
        self->n_plain = c.k[2];
        self->n_vec = 0;
        for (Py_ssize_t k = 0; k < c.rows[1]; k++)
            self->n_vec += spec[4 * k + 2] == INFO_VECTOR ? 2 : 0;
    }
    release_all(&h);
    return spec == NULL ? NULL : Py_NewRef(Py_None);
}

/* info(rewards, vectors) -> dict: robot 0's info by the bound spec (with the reward terms if rewards is true); the
 * array-valued keys are slices of `vectors`, a fresh float64 array of the spec's vector doubles. */
static PyObject *Batch_info(BatchObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    static const entry INFO = {"info", "", NULL, NULL, HELD, {FLAG(rewards), {"vectors", 'd', '*', 'o', 1, ANY, 0}}};
    BIND(INFO)
    if (self->keys == NULL || c.rows[1] < self->n_vec)
        return release_all(&h), PyErr_Format(PyExc_ValueError, "info: a bound spec (bind_info) and vectors of %zd doubles", self->n_vec);
    const char *rows[2] = {(const char *)self->b.out, (const char *)self->b.state};
    const Py_ssize_t n = c.k[0] ? PyTuple_GET_SIZE(self->keys) : self->n_plain;
    PyObject *info = PyDict_New();
    for (Py_ssize_t k = 0, used = 0; info != NULL && k < n; k++) {
        const int64_t *e = self->spec + 4 * k;
        const char *at = rows[e[0]] + e[1];
        PyObject *value = NULL;
        double x;
        int32_t i32;
        switch (e[2]) { /* a copy of constant size: each kind reads its own bytes */
        case INFO_DOUBLE:
            value = (memcpy(&x, at, 8), PyFloat_FromDouble(x));
            break;
        case INFO_INT:
            value = (memcpy(&i32, at, 4), PyLong_FromLong(i32));
            break;
        case INFO_FLAG:
            value = PyBool_FromLong(*at != 0);
            break;
        case INFO_MODE:
            memcpy(&i32, at, 4);
            value = i32 >= 0 && i32 < PyTuple_GET_SIZE(self->names) ? Py_NewRef(PyTuple_GET_ITEM(self->names, i32))
                                                                     : PyErr_Format(PyExc_ValueError, "info: contact mode %d has no name", (int)i32);
            break;
        default: /* a vector */
            memcpy((double *)c.a[1] + used, at, 16);
            value = PySequence_GetSlice(args[1], used, used + 2);
            used += 2;
        }
        if (value == NULL || PyDict_SetItem(info, PyTuple_GET_ITEM(self->keys, k), value) < 0)
            Py_CLEAR(info);
        Py_XDECREF(value);
    }
    release_all(&h);
    return info;
}

#define METHOD(name, doc) {#name, (PyCFunction)(void (*)(void))Batch_##name, METH_FASTCALL, doc}
static PyMethodDef Batch_methods[] = {
    METHOD(bind_info, "bind_info(keys, spec, n_plain, names): the info keys info() reads, parsed once."),
    METHOD(info, "info(rewards, vectors) -> dict: robot 0's info keys read from its out and state rows by the bound spec."),
    METHOD(step_one, "step_one(a0, a1) -> reward: robot 0's action, control step and evaluation."),
    METHOD(start, "start(noise or None, scale): start robot 0 (at the nominal posture plus noise if given) and evaluate it."),
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
