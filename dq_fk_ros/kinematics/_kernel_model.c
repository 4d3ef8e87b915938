/*
 * The kernel's Model: a robot's tree of DH chains and the links fixed to them, every frame's
 * pose and every TF transform for one configuration or a batch. Reference:
 * dq_fk_ros.kinematics.tree_kinematics.TreeKinematics.frame_poses_general (test_kernel.py
 * holds them equal).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "kernel_core.h"
#include "kernel_types.h"

/*
 * Model(chains, links, dof): chains: a sequence of (Chain, parent frame index or -1, q
 * indices of its variables (float64), pose rows (m, ROW_FIELDS) float64, standard 1/0);
 * links: (L, LINK_FIELDS) float64. Both laid out in kernel_layout.h.
 * poses(q, absolute, relative): every frame's pose (n_frames, 7) and every TF transform
 * (n_rows + n_links, 7), (x, y, z, qx, qy, qz, qw) with qw >= 0; absolute may be None.
 * poses_batch(q (N, dof), absolute (N, n_frames, 7), relative): the same, configuration by
 * configuration (the bag tool's chunks).
 * frames(q, out): every frame's coefficients (n_frames, 8), w >= 0.
 */

typedef struct {
    ChainObject *chain;
    Py_ssize_t parent, n_frames, n_rows, first_frame, first_row;
    Py_ssize_t n_z;  /* the chain program's z steps: their trig serves rows 0..n_z-1 */
    Py_ssize_t *q_map;
    double *rows;
    int standard;
} ModelChain;

typedef struct {
    PyObject_HEAD
    ModelChain *chains;
    Py_ssize_t n_chains, n_links, dof, n_frames, n_relative, max_chain_dof, max_chain_z;
    double *links, *coeffs, *q_chain, *trig;
    int initialised;
} ModelObject;

static const double IDENTITY[8] = {1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};

static void model_dealloc(ModelObject *self)
{
    for (Py_ssize_t c = 0; c < self->n_chains; c++) {
        Py_XDECREF(self->chains[c].chain);
        PyMem_Free(self->chains[c].q_map);
        PyMem_Free(self->chains[c].rows);
    }
    PyMem_Free(self->chains);
    PyMem_Free(self->links);
    PyMem_Free(self->coeffs);
    PyMem_Free(self->q_chain);
    PyMem_Free(self->trig);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* An index stored as a double: integral, in [low, high). */
static int index_ok(double v, Py_ssize_t low, Py_ssize_t high)
{
    return v == floor(v) && v >= (double)low && v < (double)high;
}

/* One (Chain, parent, q indices, pose rows, standard) of the tuple the model holds. */
static int model_take_chain(ModelObject *self, PyObject *item, Py_ssize_t c)
{
    ModelChain *mc = &self->chains[c];
    PyObject *chain, *q_map, *rows;
    Py_ssize_t parent;
    int standard;
    Py_buffer qv = {0}, rv = {0};
    int ok = -1;
    if (!PyTuple_Check(item)) {
        PyErr_SetString(PyExc_TypeError,
                        "a chain is a tuple (Chain, parent, q indices, pose rows, standard)");
        return -1;
    }
    /* (the item is a tuple the model's own tuple holds: its parts stay alive while the
       parent's __index__ or standard's __bool__ runs; nothing below depends on them) */
    if (!PyArg_ParseTuple(item, "O!nOOp", &ChainType, &chain, &parent, &q_map, &rows,
                          &standard))
        return -1;
    ChainObject *ch = (ChainObject *)chain;
    if (take(q_map, &qv, 0, "q indices") < 0 || take(rows, &rv, 0, "pose rows") < 0)
        goto done;
    Py_ssize_t n_rows = count(&rv) / 10;
    Py_ssize_t n_frames = ch->per / 8;
    if (count(&qv) != ch->dof || count(&rv) % ROW_FIELDS || n_rows + 1 + ch->have_tool != n_frames) {
        PyErr_SetString(PyExc_ValueError, "a chain's q indices or pose rows do not fit it");
        goto done;
    }
    if (!(parent == -1 || (parent >= 0 && parent < self->n_frames))) {
        PyErr_SetString(PyExc_ValueError, "a chain hangs from a frame not computed before it");
        goto done;
    }
    mc->q_map = PyMem_Malloc((ch->dof ? ch->dof : 1) * sizeof(Py_ssize_t));
    mc->rows = PyMem_Malloc((n_rows ? n_rows : 1) * ROW_FIELDS * sizeof(double));
    if (mc->q_map == NULL || mc->rows == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    memcpy(mc->rows, rv.buf, n_rows * ROW_FIELDS * sizeof(double));  /* copied, then checked */
    const double *qm = qv.buf, *r = mc->rows;
    for (Py_ssize_t k = 0; k < ch->dof; k++) {
        double v = qm[k];
        if (!index_ok(v, 0, self->dof)) {
            PyErr_SetString(PyExc_ValueError, "a chain's q index is outside q");
            goto done;
        }
        mc->q_map[k] = (Py_ssize_t)v;
    }
    for (Py_ssize_t i = 0; i < n_rows; i++)
        if (!index_ok(r[i * ROW_FIELDS + ROW_THETA_INDEX], -1, ch->dof)
            || !index_ok(r[i * ROW_FIELDS + ROW_D_INDEX], -1, ch->dof)) {
            PyErr_SetString(PyExc_ValueError, "a pose row indexes a variable the chain lacks");
            goto done;
        }
    if (add_size(self->n_frames, n_frames, &self->n_frames) < 0
        || add_size(self->n_relative, n_rows, &self->n_relative) < 0) {
        PyErr_SetString(PyExc_ValueError, "a model too large to compute");
        goto done;
    }
    Py_INCREF(chain);
    mc->chain = ch;
    mc->parent = parent;
    mc->n_frames = n_frames;
    mc->n_rows = n_rows;
    mc->first_frame = self->n_frames - n_frames;
    mc->first_row = self->n_relative - n_rows;
    mc->standard = standard;
    mc->n_z = 0;
    for (Py_ssize_t i = 0; i < ch->n_ops; i++)
        mc->n_z += ch->prog[i * OP_FIELDS + OP_KIND] == 0.0;
    if (ch->dof > self->max_chain_dof)
        self->max_chain_dof = ch->dof;
    if (mc->n_z > self->max_chain_z)
        self->max_chain_z = mc->n_z;
    ok = 0;
done:
    let_go(&qv);
    let_go(&rv);
    return ok;
}

static int model_build(ModelObject *self, PyObject *chains, PyObject *links, Py_ssize_t dof)
{
    if (dof < 0 || dof > MAX_DOF) {
        PyErr_Format(PyExc_ValueError, "dof must be 0 to %d", MAX_DOF);
        return -1;
    }
    self->dof = dof;
    /* a tuple of our own: a callback while a chain is read cannot change the others */
    PyObject *seq = PySequence_Tuple(chains);
    if (seq == NULL)
        return -1;
    Py_ssize_t n = PyTuple_GET_SIZE(seq);
    if (n < 1) {
        Py_DECREF(seq);
        PyErr_SetString(PyExc_ValueError, "a model has at least one chain");
        return -1;
    }
    self->chains = PyMem_Calloc(n, sizeof(ModelChain));
    if (self->chains == NULL) {
        Py_DECREF(seq);
        PyErr_NoMemory();
        return -1;
    }
    for (Py_ssize_t c = 0; c < n; c++) {
        self->n_chains = c + 1;
        if (model_take_chain(self, PyTuple_GET_ITEM(seq, c), c) < 0) {
            Py_DECREF(seq);
            return -1;
        }
    }
    Py_DECREF(seq);
    Py_buffer lv;
    if (take(links, &lv, 0, "links") < 0)
        return -1;
    if (count(&lv) % LINK_FIELDS) {
        PyBuffer_Release(&lv);
        PyErr_SetString(PyExc_ValueError, "links must be (n, LINK_FIELDS) float64 (_kernel.LAYOUTS['link'])");
        return -1;
    }
    Py_ssize_t n_links = count(&lv) / LINK_FIELDS;
    self->links = PyMem_Malloc((n_links ? n_links : 1) * LINK_FIELDS * sizeof(double));
    if (self->links == NULL) {
        PyBuffer_Release(&lv);
        PyErr_NoMemory();
        return -1;
    }
    memcpy(self->links, lv.buf, n_links * LINK_FIELDS * sizeof(double));
    PyBuffer_Release(&lv);
    Py_ssize_t n_frames, n_relative, coeff_bytes;
    if (add_size(self->n_frames, n_links, &n_frames) < 0
        || add_size(self->n_relative, n_links, &n_relative) < 0
        || mul_size(n_frames, 8 * sizeof(double), &coeff_bytes) < 0
        || mul_size(n_frames, 7 * 8, &coeff_bytes) < 0) {
        PyErr_SetString(PyExc_ValueError, "a model too large to compute");
        return -1;
    }
    for (Py_ssize_t j = 0; j < n_links; j++) {
        const double *f = self->links + j * LINK_FIELDS;
        Py_ssize_t here = self->n_frames + j;  /* a link hangs from a frame before it */
        double kind = f[LINK_MOTION];
        if (!index_ok(f[LINK_ATTACH], -1, here) || !index_ok(f[LINK_TF_PARENT], -1, here)
            || !(kind == -1.0 || kind == 0.0 || kind == 1.0)
            || (kind != -1.0 && !index_ok(f[LINK_Q_INDEX], 0, dof))) {
            PyErr_SetString(PyExc_ValueError, "a link indexes a frame or joint it cannot use");
            return -1;
        }
    }
    self->n_links = n_links;
    self->n_frames = n_frames;
    self->n_relative = n_relative;
    self->coeffs = PyMem_Malloc((n_frames ? n_frames : 1) * 8 * sizeof(double));
    self->q_chain = PyMem_Malloc((self->max_chain_dof ? self->max_chain_dof : 1)
                                 * sizeof(double));
    /* 3 doubles a z step (n_ops <= a chain's checked size: no overflow) */
    self->trig = PyMem_Malloc((self->max_chain_z ? self->max_chain_z : 1) * 3 * sizeof(double));
    if (self->coeffs == NULL || self->q_chain == NULL || self->trig == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    return 0;
}

static PyObject *model_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    PyObject *chains, *links;
    Py_ssize_t dof;
    static char *names[] = {"chains", "links", "dof", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOn", names, &chains, &links, &dof))
        return NULL;
    ModelObject *self = (ModelObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    if (model_build(self, chains, links, dof) < 0) {
        Py_DECREF(self);  /* a model half built is no model */
        return NULL;
    }
    return (PyObject *)self;
}

static int model_init(ModelObject *self, PyObject *args, PyObject *kwargs)
{
    return set_once((PyObject *)self, &self->initialised);
}

/* pose_xyzw_from_coeffs: (x, y, z, qx, qy, qz, qw), qw >= 0, [Zivkovic2023] eq. (17) */
static void pose_of(const double *h, double *p)
{
    double w = h[0], x = h[1], y = h[2], z = h[3], dw = h[4], dx = h[5], dy = h[6], dz = h[7];
    if (w < 0.0) {
        w = -w; x = -x; y = -y; z = -z; dw = -dw; dx = -dx; dy = -dy; dz = -dz;
    }
    p[0] = 2.0 * (dx * w - dw * x - dy * z + dz * y);
    p[1] = 2.0 * (dy * w - dw * y + dx * z - dz * x);
    p[2] = 2.0 * (dz * w - dw * z - dx * y + dy * x);
    p[3] = x; p[4] = y; p[5] = z; p[6] = w;
}

/*
 * KinematicChain.row_poses for one row: the transform frame i-1 -> frame i. trig (or NULL):
 * the (half angle, cos, sin) the chain program computed for this row's z step; taken when
 * its half angle is this row's, bit for bit (then cos and sin are too), else computed.
 */
static void row_pose(const double *r, const double *q, int standard, double *p,
                     const double *trig)
{
    double ca = r[ROW_COS_HALF_ALPHA], sa = r[ROW_SIN_HALF_ALPHA], a = r[ROW_A];
    double theta = r[ROW_THETA], d = r[ROW_D], scale = r[ROW_SCALE];
    double ti = r[ROW_THETA_INDEX], di = r[ROW_D_INDEX];
    double s_alpha = r[ROW_SIN_ALPHA], c_alpha = r[ROW_COS_ALPHA];
    if (ti >= 0) theta = theta + scale * q[(Py_ssize_t)ti];
    if (di >= 0) d = d + scale * q[(Py_ssize_t)di];
    double half = 0.5 * theta;
    double ct, st;
    if (trig && trig[0] == half) {
        ct = trig[1]; st = trig[2];
    } else {
        ct = cos(half); st = sin(half);
    }
    double qx, qy, qz, qw;
    if (standard) {
        qx = sa * ct; qy = sa * st; qz = ca * st; qw = ca * ct;
        p[0] = a * (1.0 - 2.0 * st * st); p[1] = 2.0 * a * st * ct; p[2] = d;
    } else {
        qx = sa * ct; qy = -sa * st; qz = ca * st; qw = ca * ct;
        p[0] = a; p[1] = -d * s_alpha; p[2] = d * c_alpha;
    }
    if (qw < 0.0) {
        qx = -qx; qy = -qy; qz = -qz; qw = -qw;
    }
    p[3] = qx; p[4] = qy; p[5] = qz; p[6] = qw;
}

/* Every frame's coefficients into self->coeffs (not made w >= 0); the TF transforms into
 * relative (7 per transform) unless NULL. As TreeKinematics.frame_poses_general. */
static void model_run(ModelObject *self, const double *q, double *relative)
{
    double *coeffs = self->coeffs, *qc = self->q_chain;
    for (Py_ssize_t c = 0; c < self->n_chains; c++) {
        ModelChain *mc = &self->chains[c];
        ChainObject *ch = mc->chain;
        for (Py_ssize_t k = 0; k < ch->dof; k++)
            qc[k] = q[mc->q_map[k]];
        double base[8];
        if (mc->parent >= 0)
            multiply(coeffs + 8 * mc->parent, ch->base, base);
        else
            memcpy(base, ch->base, sizeof base);
        run(ch->prog, ch->n_ops, base, ch->have_tool ? ch->tool : NULL, qc,
            coeffs + 8 * mc->first_frame, 0, 0, relative ? self->trig : NULL);
        if (relative)
            for (Py_ssize_t i = 0; i < mc->n_rows; i++)
                row_pose(mc->rows + ROW_FIELDS * i, qc, mc->standard,
                         relative + 7 * (mc->first_row + i),
                         i < mc->n_z ? self->trig + 3 * i : NULL);
    }
    Py_ssize_t first = self->n_frames - self->n_links;
    Py_ssize_t first_rel = self->n_relative - self->n_links;
    for (Py_ssize_t j = 0; j < self->n_links; j++) {
        const double *f = self->links + j * LINK_FIELDS;
        Py_ssize_t attach = (Py_ssize_t)f[LINK_ATTACH];
        Py_ssize_t tf_parent = (Py_ssize_t)f[LINK_TF_PARENT];
        double offset[8];
        memcpy(offset, f + LINK_OFFSET, sizeof offset);
        if (f[LINK_MOTION] >= 0.0) {  /* RobotModel's _motion: a rotation about or a move along axis */
            double value = f[LINK_MULTIPLIER] * q[(Py_ssize_t)f[LINK_Q_INDEX]] + f[LINK_VALUE];
            double zero = 0.0 * value, m[8], moved[8];
            if (f[LINK_MOTION] == 1.0) {
                double half = 0.5 * value;
                m[0] = 1.0 + zero; m[1] = zero; m[2] = zero; m[3] = zero; m[4] = zero;
                m[5] = half * f[LINK_AXIS]; m[6] = half * f[LINK_AXIS_Y]; m[7] = half * f[LINK_AXIS_Z];
            } else {
                double cc = cos(0.5 * value), ss = sin(0.5 * value);
                m[0] = cc; m[1] = ss * f[LINK_AXIS]; m[2] = ss * f[LINK_AXIS_Y];
                m[3] = ss * f[LINK_AXIS_Z];
                m[4] = zero; m[5] = zero; m[6] = zero; m[7] = zero;
            }
            multiply(offset, m, moved);
            memcpy(offset, moved, sizeof offset);
        }
        double *pose = coeffs + 8 * (first + j);
        multiply(attach >= 0 ? coeffs + 8 * attach : IDENTITY, offset, pose);
        if (relative) {
            double *p = relative + 7 * (first_rel + j);
            if (tf_parent == attach) {
                pose_of(offset, p);
            } else {
                const double *above = tf_parent >= 0 ? coeffs + 8 * tf_parent : IDENTITY;
                double inv[8] = {above[0], -above[1], -above[2], -above[3],
                                 above[4], -above[5], -above[6], -above[7]}, rel[8];
                multiply(inv, pose, rel);
                pose_of(rel, p);
            }
        }
    }
}


static int model_q(ModelObject *self, PyObject *obj, Py_buffer *q)
{
    if (take(obj, q, 0, "q") < 0)
        return -1;
    if (q->ndim != 1 || count(q) != self->dof) {
        PyErr_Format(PyExc_ValueError, "q must be %zd joint values", self->dof);
        PyBuffer_Release(q);
        return -1;
    }
    return 0;
}

/* a writable float64 buffer of n values times `times` (an overflow is no fit) */
static int model_out(PyObject *obj, Py_buffer *v, Py_ssize_t n, Py_ssize_t times,
                     const char *what)
{
    Py_ssize_t need;
    if (take(obj, v, 1, what) < 0)
        return -1;
    if (mul_size(n, times, &need) < 0 || count(v) != need) {
        PyErr_Format(PyExc_ValueError, "%s must have %zd x %zd values", what, times, n);
        PyBuffer_Release(v);
        v->obj = NULL;
        return -1;
    }
    return 0;
}

static PyObject *model_poses(ModelObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer q = {0}, absolute = {0}, relative = {0};
    PyObject *result = NULL;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "poses(q, absolute, relative)");
        return NULL;
    }
    if (model_q(self, args[0], &q) < 0)
        return NULL;
    if (args[1] != Py_None
        && model_out(args[1], &absolute, 7 * self->n_frames, 1, "absolute") < 0)
        goto done;
    if (model_out(args[2], &relative, 7 * self->n_relative, 1, "relative") < 0)
        goto done;
    model_run(self, q.buf, relative.buf);
    if (absolute.obj)
        for (Py_ssize_t k = 0; k < self->n_frames; k++)
            pose_of(self->coeffs + 8 * k, (double *)absolute.buf + 7 * k);
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&q);
    let_go(&absolute);
    let_go(&relative);
    return result;
}

static PyObject *model_frames(ModelObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer q = {0}, out = {0};
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "frames(q, out)");
        return NULL;
    }
    if (model_q(self, args[0], &q) < 0)
        return NULL;
    if (model_out(args[1], &out, 8 * self->n_frames, 1, "out") < 0) {
        PyBuffer_Release(&q);
        return NULL;
    }
    model_run(self, q.buf, NULL);
    memcpy(out.buf, self->coeffs, self->n_frames * 8 * sizeof(double));
    for (Py_ssize_t k = 0; k < self->n_frames; k++)
        canonical((double *)out.buf + 8 * k);
    PyBuffer_Release(&q);
    PyBuffer_Release(&out);
    Py_RETURN_NONE;
}

static PyObject *model_poses_batch(ModelObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer q = {0}, absolute = {0}, relative = {0};
    PyObject *result = NULL;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "poses_batch(q, absolute, relative)");
        return NULL;
    }
    if (take(args[0], &q, 0, "q") < 0)
        return NULL;
    if (q.ndim != 2 || q.shape[1] != self->dof) {
        PyErr_Format(PyExc_ValueError, "q must be (N, %zd) joint values", self->dof);
        goto done;
    }
    Py_ssize_t n = q.shape[0];
    if (args[1] != Py_None
        && model_out(args[1], &absolute, 7 * self->n_frames, n, "absolute") < 0)
        goto done;
    if (model_out(args[2], &relative, 7 * self->n_relative, n, "relative") < 0)
        goto done;
    if (self->n_relative == 0 && (absolute.obj == NULL || self->n_frames == 0))
        n = 0;  /* nothing to write: N bounded by what is written (an empty (2^57, 0) q) */
    for (Py_ssize_t i = 0; i < n; i++) {
        model_run(self, (const double *)q.buf + i * self->dof,
                  (double *)relative.buf + i * 7 * self->n_relative);
        if (absolute.obj) {
            double *a = (double *)absolute.buf + i * 7 * self->n_frames;
            for (Py_ssize_t k = 0; k < self->n_frames; k++)
                pose_of(self->coeffs + 8 * k, a + 7 * k);
        }
    }
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&q);
    let_go(&absolute);
    let_go(&relative);
    return result;
}

static PyMethodDef model_methods[] = {
    {"poses_batch", (PyCFunction)(void (*)(void))model_poses_batch, METH_FASTCALL,
     "poses_batch(q (N, dof), absolute, relative): poses() for N configurations"},
    {"poses", (PyCFunction)(void (*)(void))model_poses, METH_FASTCALL,
     "poses(q, absolute, relative): (x, y, z, qx, qy, qz, qw) of every frame and transform"},
    {"frames", (PyCFunction)(void (*)(void))model_frames, METH_FASTCALL,
     "frames(q, out): every frame's coefficients (w >= 0) into out, (n_frames, 8)"},
    {NULL, NULL, 0, NULL},
};

static PyObject *model_n_frames(ModelObject *self, void *closure)
{ return PyLong_FromSsize_t(self->n_frames); }
static PyObject *model_n_relative(ModelObject *self, void *closure)
{ return PyLong_FromSsize_t(self->n_relative); }

static PyGetSetDef model_getset[] = {
    {"n_frames", (getter)model_n_frames, NULL, "frames computed", NULL},
    {"n_relative", (getter)model_n_relative, NULL, "TF transforms computed", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

PyTypeObject ModelType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "dq_fk_ros.kinematics._kernel.Model",
    .tp_doc = "Model(chains, links, dof): a tree of chains and its links, checked once "
              "(immutable)",
    .tp_basicsize = sizeof(ModelObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = model_new,
    .tp_init = (initproc)model_init,
    .tp_dealloc = (destructor)model_dealloc,
    .tp_methods = model_methods,
    .tp_getset = model_getset,
};
