/*
 * dq_fk_ros.messages._cdr: fixed-layout CDR messages filled from float64 rows, in C.
 *
 * The compiled form of dq_fk_ros.messages.cdr_templates.CdrPacker, the reference: a message's bytes
 * (header, frame ids, padding) are laid out once as a template; a call copies the
 * template into a new bytes object and writes the stamp (int32 sec, uint32 nanosec) at
 * every stamp offset and a row of float64 values at every slot offset, little-endian as
 * the template's CDR header says. test_frame_bytes.py holds the two equal byte for byte.
 *
 * Template(data, stamps, slots, width):
 *   one(sec, nanosec, values, rows) -> bytes: slot i gets values[rows[i]] (a /tf message)
 *   each(sec, nanosec, values, rows) -> list of bytes: one message per row, its single
 *       slot values[row] (a PoseStamped per frame)
 * values: a C-contiguous float64 (n, width) array; rows: a sequence of ints in [0, n).
 *
 * Both types are immutable: their state is set once, in __new__ (a second __init__ is
 * refused). Every argument is converted to C values, every sequence copied into a tuple
 * of our own, before anything is checked; no size is computed that could overflow
 * (docs/security.md, test_compiled_fuzz.py, make sanitize).
 *
 * Only the CPython C API and the buffer protocol: no numpy headers.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <math.h>
#include <string.h>

#include "c_arguments.h"

/* the largest message a template or a reader takes (a JointState of 4096 joints is 300 kB) */
#define MAX_MESSAGE (64 << 20)

typedef struct {
    PyObject_HEAD
    char *data;
    Py_ssize_t size, n_stamps, n_slots, width;
    Py_ssize_t *stamps, *slots;
    int initialised;
} TemplateObject;

static int set_once(PyObject *self, int *initialised)
{
    if (*initialised) {
        PyErr_Format(PyExc_TypeError, "a %s is set once, when it is made; make a new one",
                     Py_TYPE(self)->tp_name);
        return -1;
    }
    *initialised = 1;  /* the __init__ that follows __new__ in the type's call */
    return 0;
}

static void template_dealloc(TemplateObject *self)
{
    PyMem_Free(self->data);
    PyMem_Free(self->stamps);
    PyMem_Free(self->slots);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* Offsets with room for `bytes` bytes in a message of `size`, never in the 4-byte header. */
static Py_ssize_t *offsets(PyObject *obj, Py_ssize_t size, Py_ssize_t bytes, Py_ssize_t *n,
                           const char *what)
{
    return ints_within(obj, 4, size - bytes, n, size, what);
}

/* a copy of a bytes-like object's bytes (1..MAX_MESSAGE of them) */
static char *bytes_copy(PyObject *obj, Py_ssize_t *len, const char *what)
{
    Py_buffer b;
    if (PyObject_GetBuffer(obj, &b, PyBUF_SIMPLE) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be bytes", what);
        return NULL;
    }
    char *out = NULL;
    if (b.len > MAX_MESSAGE) {
        PyErr_Format(PyExc_ValueError, "%s: at most %d bytes", what, MAX_MESSAGE);
    } else if ((out = PyMem_Malloc(b.len ? b.len : 1)) == NULL) {
        PyErr_NoMemory();
    } else {
        memcpy(out, b.buf, b.len);
        *len = b.len;
    }
    PyBuffer_Release(&b);
    return out;
}

static PyObject *template_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    PyObject *data, *stamps, *slots;
    Py_ssize_t width;
    static char *names[] = {"data", "stamps", "slots", "width", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOn", names, &data, &stamps, &slots,
                                     &width))
        return NULL;
    TemplateObject *self = (TemplateObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    Py_ssize_t size = 0;
    self->data = bytes_copy(data, &size, "data");  /* copied, then checked */
    if (self->data == NULL)
        goto fail;
    if (size < 4 || self->data[1] != 1 || width < 1 || width > 64) {
        PyErr_SetString(PyExc_ValueError,
                        "a little-endian CDR template and a width of 1 to 64 values");
        goto fail;
    }
    self->size = size;
    self->width = width;
    self->stamps = offsets(stamps, size, 8, &self->n_stamps, "stamp");
    if (self->stamps == NULL)
        goto fail;
    self->slots = offsets(slots, size, 8 * width, &self->n_slots, "slot");
    if (self->slots == NULL)
        goto fail;
    return (PyObject *)self;
fail:
    Py_DECREF(self);
    return NULL;
}

static int template_init(TemplateObject *self, PyObject *args, PyObject *kwargs)
{
    return set_once((PyObject *)self, &self->initialised);
}

/* sec, nanosec: as builtin_interfaces/Time takes them (int32, uint32) */
static int stamp_args(PyObject *sec_obj, PyObject *nsec_obj, int32_t *sec, uint32_t *nsec)
{
    long long s = PyLong_AsLongLong(sec_obj);
    if (s == -1 && PyErr_Occurred())
        return -1;
    long long n = PyLong_AsLongLong(nsec_obj);
    if (n == -1 && PyErr_Occurred())
        return -1;
    if (s < INT32_MIN || s > INT32_MAX || n < 0 || n > UINT32_MAX) {
        PyErr_SetString(PyExc_ValueError, "a stamp of int32 sec and uint32 nanosec");
        return -1;
    }
    *sec = (int32_t)s;
    *nsec = (uint32_t)n;
    return 0;
}

/* values (n, width) float64 C-contiguous */
static int take_values(TemplateObject *self, PyObject *obj, Py_buffer *v, Py_ssize_t *n)
{
    if (PyObject_GetBuffer(obj, v, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyErr_Clear();
        PyErr_SetString(PyExc_ValueError, "values must be a C-contiguous float64 array");
        return -1;
    }
    if (v->itemsize != 8 || v->format == NULL || strcmp(v->format, "d") != 0
        || (v->len / 8) % self->width) {
        PyBuffer_Release(v);
        PyErr_Format(PyExc_ValueError, "values must be float64 rows of %zd", self->width);
        return -1;
    }
    *n = v->len / 8 / self->width;
    return 0;
}

static PyObject *message(TemplateObject *self, int32_t sec, uint32_t nsec, char **out)
{
    PyObject *msg = PyBytes_FromStringAndSize(self->data, self->size);
    if (msg == NULL)
        return NULL;
    *out = PyBytes_AS_STRING(msg);  /* a new object nobody else holds yet */
    for (Py_ssize_t k = 0; k < self->n_stamps; k++) {
        memcpy(*out + self->stamps[k], &sec, 4);
        memcpy(*out + self->stamps[k] + 4, &nsec, 4);
    }
    return msg;
}

/*
 * The call's arguments as C values: the stamp, the rows (a tuple of our own, each an int
 * in [0, n) by then) and the values' buffer, in that order, so that no Python code runs
 * once the buffer is checked.
 */
static int parse_call(TemplateObject *self, PyObject *const *args, Py_ssize_t nargs,
                      const char *usage, int32_t *sec, uint32_t *nsec, Py_buffer *v,
                      Py_ssize_t *n, Py_ssize_t **rows, Py_ssize_t *n_rows)
{
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, usage);
        return -1;
    }
    if (stamp_args(args[0], args[1], sec, nsec) < 0)
        return -1;
    *rows = ints_within(args[3], 0, PY_SSIZE_T_MAX, n_rows, PY_SSIZE_T_MAX / 8, "row");
    if (*rows == NULL)
        return -1;
    if (take_values(self, args[2], v, n) < 0) {
        PyMem_Free(*rows);
        return -1;
    }
    for (Py_ssize_t i = 0; i < *n_rows; i++)
        if ((*rows)[i] >= *n) {
            PyErr_Format(PyExc_IndexError, "row %zd of %zd values", (*rows)[i], *n);
            PyBuffer_Release(v);
            PyMem_Free(*rows);
            return -1;
        }
    return 0;
}

static PyObject *template_one(TemplateObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    int32_t sec;
    uint32_t nsec;
    Py_buffer v;
    Py_ssize_t n, *rows, n_rows;
    PyObject *msg = NULL;
    char *out;
    if (parse_call(self, args, nargs, "one(sec, nanosec, values, rows)", &sec, &nsec, &v, &n,
                   &rows, &n_rows) < 0)
        return NULL;
    if (n_rows != self->n_slots) {
        PyErr_Format(PyExc_ValueError, "%zd rows for %zd slots", n_rows, self->n_slots);
        goto done;
    }
    msg = message(self, sec, nsec, &out);
    if (msg == NULL)
        goto done;
    for (Py_ssize_t i = 0; i < self->n_slots; i++)
        memcpy(out + self->slots[i], (const double *)v.buf + rows[i] * self->width,
               8 * self->width);
done:
    PyBuffer_Release(&v);
    PyMem_Free(rows);
    return msg;
}

static PyObject *template_each(TemplateObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    int32_t sec;
    uint32_t nsec;
    Py_buffer v;
    Py_ssize_t n, *rows, n_rows;
    PyObject *list = NULL;
    char *out;
    if (parse_call(self, args, nargs, "each(sec, nanosec, values, rows)", &sec, &nsec, &v,
                   &n, &rows, &n_rows) < 0)
        return NULL;
    if (self->n_slots != 1) {
        PyErr_SetString(PyExc_ValueError, "each() takes a template of one slot");
        goto done;
    }
    list = PyList_New(n_rows);
    if (list == NULL)
        goto done;
    for (Py_ssize_t i = 0; i < n_rows; i++) {
        PyObject *msg = message(self, sec, nsec, &out);
        if (msg == NULL) {
            Py_CLEAR(list);
            goto done;
        }
        memcpy(out + self->slots[0], (const double *)v.buf + rows[i] * self->width,
               8 * self->width);
        PyList_SET_ITEM(list, i, msg);
    }
done:
    PyBuffer_Release(&v);
    PyMem_Free(rows);
    return list;
}

static PyMethodDef template_methods[] = {
    {"one", (PyCFunction)(void (*)(void))template_one, METH_FASTCALL,
     "one(sec, nanosec, values, rows) -> bytes: slot i gets the row values[rows[i]]"},
    {"each", (PyCFunction)(void (*)(void))template_each, METH_FASTCALL,
     "each(sec, nanosec, values, rows) -> [bytes]: one message per row (one slot)"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject TemplateType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "dq_fk_ros.messages._cdr.Template",
    .tp_doc = "Template(data, stamps, slots, width): a fixed-layout CDR message (immutable)",
    .tp_basicsize = sizeof(TemplateObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = template_new,
    .tp_init = (initproc)template_init,
    .tp_dealloc = (destructor)template_dealloc,
    .tp_methods = template_methods,
};

/*
 * JointStateReader(size, fixed, mask, counts_at, counts, positions_at, velocities_at,
 *                  order, lower, upper, jump_back_ns): the short path of
 * JointStateMerger._merge_complete (the reference) for one serialized JointState layout,
 * from the bytes. read(raw, last_stamp_ns, q, qdot, q_out, qdot_out) -> stamp_ns or None.
 *
 * It takes a message only when the reference would publish it with nothing to say: the
 * same size, the same frame id and names (bytes 12.. compared where mask is 0xff: CDR
 * padding may hold anything), the same three array lengths, every position finite and
 * within [lower, upper], every velocity finite (or none at all), no jump back in time. Then
 * it writes position k to q[order[k]] and velocity k (NaN without) to qdot[order[k]] (the
 * merger's lists of exact floats), copies all of q and qdot to q_out and qdot_out (float64),
 * and returns the stamp in ns. Anything else: None, nothing written (the reference decides).
 */
#define MAX_NAMES 4096

typedef struct {
    PyObject_HEAD
    Py_ssize_t size, fixed_len, n, n_vel, pos_at, vel_at, counts_at[3];
    uint32_t counts[3];
    long long jump_back_ns;
    unsigned char *fixed, *mask;
    Py_ssize_t *order;
    double *lower, *upper;
    int initialised;
} ReaderObject;

static void reader_dealloc(ReaderObject *self)
{
    PyMem_Free(self->fixed);
    PyMem_Free(self->mask);
    PyMem_Free(self->order);
    PyMem_Free(self->lower);
    PyMem_Free(self->upper);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* n floats of a sequence (copied into a tuple first), as a new C array */
static double *floats_of(PyObject *obj, Py_ssize_t n, const char *what)
{
    PyObject *seq = PySequence_Tuple(obj);
    if (seq == NULL) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s: a sequence of floats", what);
        return NULL;
    }
    double *out = NULL;
    if (PyTuple_GET_SIZE(seq) != n) {
        PyErr_Format(PyExc_ValueError, "%s must have one value per name", what);
        goto done;
    }
    out = PyMem_Malloc((n ? n : 1) * sizeof(double));
    if (out == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        out[i] = PyFloat_AsDouble(PyTuple_GET_ITEM(seq, i));
        if (out[i] == -1.0 && PyErr_Occurred()) {
            PyMem_Free(out);
            out = NULL;
            goto done;
        }
    }
done:
    Py_DECREF(seq);
    return out;
}

/* the reader's state: every sequence converted to C first, then checked together */
static int reader_build(ReaderObject *self, Py_ssize_t size, PyObject *fixed, PyObject *mask,
                        PyObject *counts_at, PyObject *counts, PyObject *order,
                        PyObject *lower, PyObject *upper)
{
    Py_ssize_t mask_len = 0, n3 = 0, nc = 0, n_order = 0;
    Py_ssize_t *at = NULL, *cs = NULL;
    int ok = -1;
    if (size < 12 || size > MAX_MESSAGE) {
        PyErr_Format(PyExc_ValueError, "size must be 12 to %d bytes", MAX_MESSAGE);
        return -1;
    }
    self->size = size;
    if ((self->fixed = (unsigned char *)bytes_copy(fixed, &self->fixed_len, "fixed")) == NULL
        || (self->mask = (unsigned char *)bytes_copy(mask, &mask_len, "mask")) == NULL)
        return -1;
    if (self->fixed_len != mask_len || self->fixed_len > size - 12) {
        PyErr_SetString(PyExc_ValueError, "fixed and mask: the same length, inside the message");
        return -1;
    }
    if ((at = offsets(counts_at, size, 4, &n3, "count")) == NULL
        || (cs = ints_within(counts, 0, MAX_NAMES, &nc, 3, "array length")) == NULL)
        goto done;
    if (n3 != 3 || nc != 3) {
        PyErr_SetString(PyExc_ValueError, "three array lengths and their offsets");
        goto done;
    }
    for (int k = 0; k < 3; k++) {
        self->counts_at[k] = at[k];
        self->counts[k] = (uint32_t)cs[k];
    }
    self->n = cs[0];
    self->n_vel = cs[1];
    if (self->n_vel != 0 && self->n_vel != self->n) {
        PyErr_SetString(PyExc_ValueError, "velocities: none, or one per position");
        goto done;
    }
    /* (n <= 4096: 8 n cannot overflow; the offsets are compared without adding to them) */
    if (self->pos_at < 4 || self->pos_at > size || 8 * self->n > size - self->pos_at
        || self->vel_at < 4 || self->vel_at > size || 8 * self->n_vel > size - self->vel_at) {
        PyErr_SetString(PyExc_ValueError, "the arrays lie outside the message");
        goto done;
    }
    self->order = ints_within(order, 0, MAX_NAMES * 16, &n_order, MAX_NAMES, "order index");
    if (self->order == NULL)
        goto done;
    if (n_order != self->n) {
        PyErr_SetString(PyExc_ValueError, "order: one index per name");
        goto done;
    }
    if ((self->lower = floats_of(lower, self->n, "lower")) == NULL
        || (self->upper = floats_of(upper, self->n, "upper")) == NULL)
        goto done;
    if (self->jump_back_ns < 0) {
        PyErr_SetString(PyExc_ValueError, "jump_back_ns must be >= 0");
        goto done;
    }
    ok = 0;
done:
    PyMem_Free(at);
    PyMem_Free(cs);
    return ok;
}

static PyObject *reader_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    Py_ssize_t size, pos_at, vel_at;
    PyObject *fixed, *mask, *counts_at, *counts, *order, *lower, *upper;
    long long jump;
    static char *names[] = {"size", "fixed", "mask", "counts_at", "counts", "positions_at",
                            "velocities_at", "order", "lower", "upper", "jump_back_ns",
                            NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "nOOOOnnOOOL", names, &size, &fixed,
                                     &mask, &counts_at, &counts, &pos_at, &vel_at, &order,
                                     &lower, &upper, &jump))
        return NULL;
    ReaderObject *self = (ReaderObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    self->pos_at = pos_at;
    self->vel_at = vel_at;
    self->jump_back_ns = jump;
    if (reader_build(self, size, fixed, mask, counts_at, counts, order, lower, upper) < 0) {
        Py_DECREF(self);  /* a reader half built is no reader */
        return NULL;
    }
    return (PyObject *)self;
}

static int reader_init(ReaderObject *self, PyObject *args, PyObject *kwargs)
{
    return set_once((PyObject *)self, &self->initialised);
}

static int out_vector(PyObject *obj, Py_buffer *v, Py_ssize_t n)
{
    if (PyObject_GetBuffer(obj, v, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE) < 0) {
        v->obj = NULL;
        return -1;
    }
    if (v->itemsize != 8 || v->format == NULL || strcmp(v->format, "d") != 0
        || v->len != 8 * n) {
        PyBuffer_Release(v);
        v->obj = NULL;
        PyErr_Format(PyExc_ValueError, "q_out and qdot_out: writable float64, %zd values", n);
        return -1;
    }
    return 0;
}

static PyObject *reader_read(ReaderObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 6 || !PyList_CheckExact(args[2]) || !PyList_CheckExact(args[3])) {
        PyErr_SetString(PyExc_TypeError, "read(raw, last_stamp_ns, q, qdot, q_out, qdot_out)"
                                         " with q and qdot lists of floats");
        return NULL;
    }
    /* first every argument as C values (the stamp's __index__ may run Python code), then
       the checks, then the work, with no Python code between them */
    int have_last = args[1] != Py_None;
    long long last = 0;
    if (have_last) {
        last = PyLong_AsLongLong(args[1]);
        if (last == -1 && PyErr_Occurred())
            return NULL;
    }
    PyObject *q = args[2], *qdot = args[3];
    if (q == qdot) {  /* each slot would be replaced twice, its first new float let go of */
        PyErr_SetString(PyExc_ValueError, "q and qdot: two different lists");
        return NULL;
    }
    Py_ssize_t dof = PyList_GET_SIZE(q);
    Py_buffer raw = {0}, q_out = {0}, qdot_out = {0};
    PyObject *result = NULL;
    if (PyObject_GetBuffer(args[0], &raw, PyBUF_SIMPLE) < 0) {
        raw.obj = NULL;
        goto done;
    }
    if (out_vector(args[4], &q_out, dof) < 0 || out_vector(args[5], &qdot_out, dof) < 0)
        goto done;
    if (dof > 0 && (char *)q_out.buf < (char *)qdot_out.buf + qdot_out.len
        && (char *)qdot_out.buf < (char *)q_out.buf + q_out.len) {
        PyErr_SetString(PyExc_ValueError, "q_out and qdot_out: buffers that do not overlap");
        goto done;
    }
    if (PyList_GET_SIZE(qdot) != dof) {
        PyErr_SetString(PyExc_ValueError, "q and qdot: the same length");
        goto done;
    }
    for (Py_ssize_t k = 0; k < self->n; k++)
        if (self->order[k] >= dof) {
            PyErr_SetString(PyExc_ValueError, "order indexes past q");
            goto done;
        }
    for (Py_ssize_t i = 0; i < dof; i++)
        if (!PyFloat_Check(PyList_GET_ITEM(q, i)) || !PyFloat_Check(PyList_GET_ITEM(qdot, i))) {
            PyErr_SetString(PyExc_TypeError, "q and qdot: lists of floats");
            goto done;
        }
    const unsigned char *b = raw.buf;
    result = Py_None;
    if (raw.len != self->size || b[0] != 0 || b[1] != 1)
        goto done;
    for (Py_ssize_t i = 0; i < self->fixed_len; i++)
        if ((b[12 + i] ^ self->fixed[i]) & self->mask[i])
            goto done;
    for (int k = 0; k < 3; k++) {
        uint32_t c;
        memcpy(&c, b + self->counts_at[k], 4);
        if (c != self->counts[k])
            goto done;
    }
    const unsigned char *pos = b + self->pos_at, *vel = b + self->vel_at;
    for (Py_ssize_t k = 0; k < self->n; k++) {
        double v;
        memcpy(&v, pos + 8 * k, 8);
        if (!(v >= self->lower[k] && v <= self->upper[k]) || !isfinite(v))
            goto done;
    }
    for (Py_ssize_t k = 0; k < self->n_vel; k++) {
        double v;
        memcpy(&v, vel + 8 * k, 8);
        if (!isfinite(v))
            goto done;
    }
    int32_t sec;
    uint32_t nsec;
    memcpy(&sec, b + 4, 4);
    memcpy(&nsec, b + 8, 4);
    long long stamp = (long long)sec * 1000000000LL + nsec;  /* |.| < 2^62: no overflow */
    if (stamp != 0 && have_last) {
        long long limit;
        if (__builtin_sub_overflow(last, self->jump_back_ns, &limit))
            limit = LLONG_MIN;
        if (stamp < limit)
            goto done;
    }
    /* The new floats go in first, the old ones are let go of last: letting go of an item
       (a float subclass's __del__) may run Python code, which must find nothing half done. */
    PyObject *held_stack[2 * 128], **held = held_stack;
    if (self->n > 128 && (held = PyMem_Malloc(2 * self->n * sizeof(PyObject *))) == NULL) {
        PyErr_NoMemory();
        result = NULL;
        goto done;
    }
    Py_ssize_t n_held = 0;
    result = PyLong_FromLongLong(stamp);
    for (Py_ssize_t k = 0; k < self->n && result; k++) {
        double v, r = NAN;
        memcpy(&v, pos + 8 * k, 8);
        if (self->n_vel)
            memcpy(&r, vel + 8 * k, 8);
        PyObject *fv = PyFloat_FromDouble(v), *fr = PyFloat_FromDouble(r);
        if (fv == NULL || fr == NULL) {
            Py_XDECREF(fv);
            Py_XDECREF(fr);
            Py_CLEAR(result);
            break;
        }
        Py_ssize_t at = self->order[k];
        held[n_held++] = PyList_GET_ITEM(q, at);
        held[n_held++] = PyList_GET_ITEM(qdot, at);
        PyList_SET_ITEM(q, at, fv);  /* steals fv; the old item is held */
        PyList_SET_ITEM(qdot, at, fr);
    }
    if (result) {
        double *qo = q_out.buf, *qdo = qdot_out.buf;
        for (Py_ssize_t i = 0; i < dof; i++) {
            qo[i] = PyFloat_AS_DOUBLE(PyList_GET_ITEM(q, i));
            qdo[i] = PyFloat_AS_DOUBLE(PyList_GET_ITEM(qdot, i));
        }
    }
    PyBuffer_Release(&raw);
    PyBuffer_Release(&q_out);
    PyBuffer_Release(&qdot_out);
    for (Py_ssize_t i = 0; i < n_held; i++)
        Py_DECREF(held[i]);
    if (held != held_stack)
        PyMem_Free(held);
    return result;
done:
    if (raw.obj) PyBuffer_Release(&raw);
    if (q_out.obj) PyBuffer_Release(&q_out);
    if (qdot_out.obj) PyBuffer_Release(&qdot_out);
    Py_XINCREF(result);
    return result;
}

static PyMethodDef reader_methods[] = {
    {"read", (PyCFunction)(void (*)(void))reader_read, METH_FASTCALL,
     "read(raw, last_stamp_ns, q, qdot, q_out, qdot_out) -> stamp_ns, or None: not taken"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject ReaderType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "dq_fk_ros.messages._cdr.JointStateReader",
    .tp_doc = "JointStateReader(...): the merger's short path for one JointState layout "
              "(immutable)",
    .tp_basicsize = sizeof(ReaderObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = reader_new,
    .tp_init = (initproc)reader_init,
    .tp_dealloc = (destructor)reader_dealloc,
    .tp_methods = reader_methods,
};

/*
 * Runs(offsets, lengths, expected): where a TFMessage layout's count and frame ids are, and
 * their bytes. match(raw) -> bool: raw holds expected's bytes at every offset (the compiled
 * form of cdr._is_layout, the reference: test_cdr.py's test_tf_latest_tells_layouts_apart).
 */
#define MAX_RUNS (1 << 20)

typedef struct {
    PyObject_HEAD
    Py_ssize_t n, *offsets, *lengths, end;
    char *expected;
    int initialised;
} RunsObject;

static void runs_dealloc(RunsObject *self)
{
    PyMem_Free(self->offsets);
    PyMem_Free(self->lengths);
    PyMem_Free(self->expected);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *runs_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    PyObject *offsets, *lengths, *expected;
    static char *names[] = {"offsets", "lengths", "expected", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOO", names, &offsets, &lengths,
                                     &expected))
        return NULL;
    RunsObject *self = (RunsObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    Py_ssize_t n_lengths = 0, size = 0, total = 0;
    if ((self->offsets = ints_within(offsets, 0, MAX_MESSAGE, &self->n, MAX_RUNS,
                                     "run offset")) == NULL
        || (self->lengths = ints_within(lengths, 0, MAX_MESSAGE, &n_lengths, MAX_RUNS,
                                        "run length")) == NULL
        || (self->expected = bytes_copy(expected, &size, "expected")) == NULL)
        goto fail;
    if (n_lengths != self->n) {
        PyErr_SetString(PyExc_ValueError, "offsets and lengths: one each per run");
        goto fail;
    }
    for (Py_ssize_t i = 0; i < self->n; i++) {
        /* each term <= 64 MiB, at most 2**20 of them: no overflow */
        total += self->lengths[i];
        if (self->offsets[i] + self->lengths[i] > self->end)
            self->end = self->offsets[i] + self->lengths[i];
    }
    if (total != size) {
        PyErr_SetString(PyExc_ValueError, "expected: the runs' bytes, back to back");
        goto fail;
    }
    return (PyObject *)self;
fail:
    Py_DECREF(self);
    return NULL;
}

static int runs_init(RunsObject *self, PyObject *args, PyObject *kwargs)
{
    return set_once((PyObject *)self, &self->initialised);
}

static PyObject *runs_match(RunsObject *self, PyObject *raw_obj)
{
    Py_buffer raw;
    if (PyObject_GetBuffer(raw_obj, &raw, PyBUF_SIMPLE) < 0)
        return NULL;
    int same = raw.len >= self->end;
    const char *b = raw.buf, *e = self->expected;
    for (Py_ssize_t i = 0; same && i < self->n; e += self->lengths[i], i++)
        same = memcmp(b + self->offsets[i], e, (size_t)self->lengths[i]) == 0;
    PyBuffer_Release(&raw);
    return PyBool_FromLong(same);
}

static PyObject *runs_match_many(RunsObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer data = {0}, starts = {0}, lengths = {0};
    PyObject *out = NULL;
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "match_many(data, starts, lengths, size)");
        return NULL;
    }
    Py_ssize_t size = PyLong_AsSsize_t(args[3]);  /* converted before anything is held */
    if (size == -1 && PyErr_Occurred())
        return NULL;
    if (PyObject_GetBuffer(args[0], &data, PyBUF_SIMPLE) < 0)
        return NULL;
    if (int64_buffer(args[1], &starts, 0, "starts") < 0
        || int64_buffer(args[2], &lengths, 0, "lengths") < 0)
        goto done;
    Py_ssize_t n = starts.len / 8;
    if (lengths.len / 8 != n) {
        PyErr_SetString(PyExc_ValueError, "starts and lengths: one each per message");
        goto done;
    }
    out = PyBytes_FromStringAndSize(NULL, n);
    if (out == NULL)
        goto done;
    char *same = PyBytes_AS_STRING(out);
    const char *b = data.buf;
    const int64_t *at = starts.buf, *len = lengths.buf;
    for (Py_ssize_t i = 0; i < n; i++) {
        int64_t s = at[i], l = len[i];
        if (s < 0 || l < 0 || s > data.len || l > data.len - s) {
            PyErr_Format(PyExc_ValueError, "message %zd lies outside the buffer", i);
            Py_CLEAR(out);
            goto done;
        }
        int ok = l == size && l >= self->end;
        const char *m = b + s, *e = self->expected;
        for (Py_ssize_t r = 0; ok && r < self->n; e += self->lengths[r], r++)
            ok = memcmp(m + self->offsets[r], e, (size_t)self->lengths[r]) == 0;
        same[i] = (char)ok;
    }
done:
    PyBuffer_Release(&data);
    PyBuffer_Release(&starts);  /* (obj NULL: nothing held, nothing done) */
    PyBuffer_Release(&lengths);
    return out;
}

static PyMethodDef runs_methods[] = {
    {"match", (PyCFunction)runs_match, METH_O,
     "match(raw) -> bool: raw holds the expected bytes at every run"},
    {"match_many", (PyCFunction)(void (*)(void))runs_match_many, METH_FASTCALL,
     "match_many(data, starts, lengths, size) -> bytes of 0/1: message i, the bytes at "
     "data[starts[i]:][:lengths[i]] (int64 arrays), is size bytes and holds the expected "
     "bytes at every run"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject RunsType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "dq_fk_ros.messages._cdr.Runs",
    .tp_doc = "Runs(offsets, lengths, expected): byte runs a message must hold (immutable)",
    .tp_basicsize = sizeof(RunsObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = runs_new,
    .tp_init = (initproc)runs_init,
    .tp_dealloc = (destructor)runs_dealloc,
    .tp_methods = runs_methods,
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cdr",
    "Fixed-layout CDR messages filled in C (the reference: dq_fk_ros.messages.cdr_templates.CdrPacker).",
    -1, NULL,
};

PyMODINIT_FUNC PyInit__cdr(void)
{
    const uint16_t one = 1;
    if (*(const unsigned char *)&one != 1) {  /* the templates are little-endian CDR */
        PyErr_SetString(PyExc_ImportError, "a big-endian machine: the Python packer runs");
        return NULL;
    }
    if (PyType_Ready(&TemplateType) < 0 || PyType_Ready(&ReaderType) < 0
        || PyType_Ready(&RunsType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    if (PyModule_AddType(m, &TemplateType) < 0 || PyModule_AddType(m, &ReaderType) < 0
        || PyModule_AddType(m, &RunsType) < 0) {
        Py_DECREF(m);  /* (the types are named by their tp_name's last part) */
        return NULL;
    }
    return m;
}
