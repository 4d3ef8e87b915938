/*
 * dq_fk_ros.messages._cdr: fixed-layout CDR messages filled from float64 rows, in C.
 *
 * The compiled form of dq_fk_ros.messages.cdr.CdrPacker, the reference: a message's bytes
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
 * Only the CPython C API and the buffer protocol: no numpy headers.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <math.h>
#include <string.h>

typedef struct {
    PyObject_HEAD
    char *data;
    Py_ssize_t size, n_stamps, n_slots, width;
    Py_ssize_t *stamps, *slots;
} TemplateObject;

static void template_dealloc(TemplateObject *self)
{
    PyMem_Free(self->data);
    PyMem_Free(self->stamps);
    PyMem_Free(self->slots);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* A sequence of ints, each in [low, high]; what names them in the error. */
static Py_ssize_t *ints_within(PyObject *obj, Py_ssize_t low, Py_ssize_t high, Py_ssize_t *n,
                               const char *what)
{
    PyObject *seq = PySequence_Fast(obj, "offsets and indices must be sequences of ints");
    if (seq == NULL)
        return NULL;
    *n = PySequence_Fast_GET_SIZE(seq);
    Py_ssize_t *out = PyMem_Malloc((*n ? *n : 1) * sizeof(Py_ssize_t));
    if (out == NULL) {
        Py_DECREF(seq);
        PyErr_NoMemory();
        return NULL;
    }
    for (Py_ssize_t i = 0; i < *n; i++) {
        Py_ssize_t at = PyLong_AsSsize_t(PySequence_Fast_GET_ITEM(seq, i));
        int not_int = at == -1 && PyErr_Occurred();  /* not an int, or too large */
        if (not_int)
            PyErr_Clear();
        if (not_int || at < low || at > high) {
            PyErr_Format(PyExc_ValueError, "%s %zd is outside %zd..%zd", what, at, low, high);
            PyMem_Free(out);
            Py_DECREF(seq);
            return NULL;
        }
        out[i] = at;
    }
    Py_DECREF(seq);
    return out;
}

/* Offsets with room for `bytes` bytes in a message of `size`, never in the 4-byte header. */
static Py_ssize_t *offsets(PyObject *obj, Py_ssize_t size, Py_ssize_t bytes, Py_ssize_t *n,
                           const char *what)
{
    return ints_within(obj, 4, size - bytes, n, what);
}

static int template_init(TemplateObject *self, PyObject *args, PyObject *kwargs)
{
    Py_buffer data;
    PyObject *stamps, *slots;
    Py_ssize_t width;
    static char *names[] = {"data", "stamps", "slots", "width", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "y*OOn", names, &data, &stamps, &slots,
                                     &width))
        return -1;
    PyMem_Free(self->data);
    PyMem_Free(self->stamps);
    PyMem_Free(self->slots);
    self->data = NULL;
    self->stamps = self->slots = NULL;
    int ok = -1;
    if (data.len < 4 || ((const char *)data.buf)[1] != 1 || width < 1 || width > 64) {
        PyErr_SetString(PyExc_ValueError,
                        "a little-endian CDR template and a width of 1 to 64 values");
        goto done;
    }
    self->size = data.len;
    self->width = width;
    self->stamps = offsets(stamps, data.len, 8, &self->n_stamps, "stamp");
    if (self->stamps == NULL)
        goto done;
    self->slots = offsets(slots, data.len, 8 * width, &self->n_slots, "slot");
    if (self->slots == NULL)
        goto done;
    self->data = PyMem_Malloc(data.len);
    if (self->data == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    memcpy(self->data, data.buf, data.len);
    ok = 0;
done:
    PyBuffer_Release(&data);
    return ok;
}

/* sec, nanosec: as builtin_interfaces/Time takes them (int32, uint32) */
static int stamp_args(PyObject *sec_obj, PyObject *nsec_obj, int32_t *sec, uint32_t *nsec)
{
    long long s = PyLong_AsLongLong(sec_obj);
    if (s == -1 && PyErr_Occurred())
        return -1;
    unsigned long long n = PyLong_AsUnsignedLongLong(nsec_obj);
    if (n == (unsigned long long)-1 && PyErr_Occurred())
        return -1;
    if (s < INT32_MIN || s > INT32_MAX || n > UINT32_MAX) {
        PyErr_SetString(PyExc_ValueError, "a stamp of int32 sec and uint32 nanosec");
        return -1;
    }
    *sec = (int32_t)s;
    *nsec = (uint32_t)n;
    return 0;
}

/* values (n, width) float64 C-contiguous; every row index in [0, n) */
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

static int row_at(PyObject *rows, Py_ssize_t i, Py_ssize_t n, Py_ssize_t *row)
{
    *row = PyLong_AsSsize_t(PySequence_Fast_GET_ITEM(rows, i));
    if (*row == -1 && PyErr_Occurred())
        return -1;
    if (*row < 0 || *row >= n) {
        PyErr_Format(PyExc_IndexError, "row %zd of %zd values", *row, n);
        return -1;
    }
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

static int parse_call(TemplateObject *self, PyObject *const *args, Py_ssize_t nargs,
                      const char *usage, int32_t *sec, uint32_t *nsec, Py_buffer *v,
                      Py_ssize_t *n, PyObject **rows)
{
    if (self->data == NULL) {
        PyErr_SetString(PyExc_ValueError, "the template was not initialised");
        return -1;
    }
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, usage);
        return -1;
    }
    if (stamp_args(args[0], args[1], sec, nsec) < 0)
        return -1;
    *rows = PySequence_Fast(args[3], "rows must be a sequence of ints");
    if (*rows == NULL)
        return -1;
    if (take_values(self, args[2], v, n) < 0) {
        Py_DECREF(*rows);
        return -1;
    }
    return 0;
}

static PyObject *template_one(TemplateObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    int32_t sec;
    uint32_t nsec;
    Py_buffer v;
    Py_ssize_t n, row;
    PyObject *rows, *msg = NULL;
    char *out;
    if (parse_call(self, args, nargs, "one(sec, nanosec, values, rows)", &sec, &nsec, &v, &n,
                   &rows) < 0)
        return NULL;
    if (PySequence_Fast_GET_SIZE(rows) != self->n_slots) {
        PyErr_Format(PyExc_ValueError, "%zd rows for %zd slots",
                     PySequence_Fast_GET_SIZE(rows), self->n_slots);
        goto done;
    }
    msg = message(self, sec, nsec, &out);
    if (msg == NULL)
        goto done;
    for (Py_ssize_t i = 0; i < self->n_slots; i++) {
        if (row_at(rows, i, n, &row) < 0) {
            Py_CLEAR(msg);
            goto done;
        }
        memcpy(out + self->slots[i], (const double *)v.buf + row * self->width,
               8 * self->width);
    }
done:
    PyBuffer_Release(&v);
    Py_DECREF(rows);
    return msg;
}

static PyObject *template_each(TemplateObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    int32_t sec;
    uint32_t nsec;
    Py_buffer v;
    Py_ssize_t n, row;
    PyObject *rows, *list = NULL;
    char *out;
    if (parse_call(self, args, nargs, "each(sec, nanosec, values, rows)", &sec, &nsec, &v,
                   &n, &rows) < 0)
        return NULL;
    if (self->n_slots != 1) {
        PyErr_SetString(PyExc_ValueError, "each() takes a template of one slot");
        goto done;
    }
    Py_ssize_t count = PySequence_Fast_GET_SIZE(rows);
    list = PyList_New(count);
    if (list == NULL)
        goto done;
    for (Py_ssize_t i = 0; i < count; i++) {
        PyObject *msg;
        if (row_at(rows, i, n, &row) < 0 || (msg = message(self, sec, nsec, &out)) == NULL) {
            Py_CLEAR(list);
            goto done;
        }
        memcpy(out + self->slots[0], (const double *)v.buf + row * self->width,
               8 * self->width);
        PyList_SET_ITEM(list, i, msg);
    }
done:
    PyBuffer_Release(&v);
    Py_DECREF(rows);
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
    .tp_doc = "Template(data, stamps, slots, width): a fixed-layout CDR message",
    .tp_basicsize = sizeof(TemplateObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = PyType_GenericNew,
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
 * merger's lists of floats), copies all of q and qdot to q_out and qdot_out (float64), and
 * returns the stamp in ns. Anything else: None, nothing written (the reference decides).
 */
typedef struct {
    PyObject_HEAD
    Py_ssize_t size, fixed_len, n, n_vel, pos_at, vel_at, counts_at[3];
    uint32_t counts[3];
    long long jump_back_ns;
    unsigned char *fixed, *mask;
    Py_ssize_t *order;
    double *lower, *upper;
} ReaderObject;

static void reader_free(ReaderObject *self)
{
    PyMem_Free(self->fixed);
    PyMem_Free(self->mask);
    PyMem_Free(self->order);
    PyMem_Free(self->lower);
    PyMem_Free(self->upper);
    self->fixed = self->mask = NULL;
    self->order = NULL;
    self->lower = self->upper = NULL;
}

static void reader_dealloc(ReaderObject *self)
{
    reader_free(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static double *floats_of(PyObject *obj, Py_ssize_t n, const char *what)
{
    PyObject *seq = PySequence_Fast(obj, "bounds must be sequences of floats");
    if (seq == NULL)
        return NULL;
    double *out = NULL;
    if (PySequence_Fast_GET_SIZE(seq) != n) {
        PyErr_Format(PyExc_ValueError, "%s must have one value per name", what);
        goto done;
    }
    out = PyMem_Malloc((n ? n : 1) * sizeof(double));
    if (out == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        out[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(seq, i));
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

static int reader_build(ReaderObject *self, Py_ssize_t size, Py_buffer *fixed, Py_buffer *mask,
                        PyObject *counts_at, PyObject *counts, PyObject *order,
                        PyObject *lower, PyObject *upper)
{
    if (fixed->len != mask->len || 12 + fixed->len > size) {
        PyErr_SetString(PyExc_ValueError, "fixed and mask: the same length, inside the message");
        return -1;
    }
    self->size = size;
    self->fixed_len = fixed->len;
    self->fixed = PyMem_Malloc(fixed->len ? fixed->len : 1);
    self->mask = PyMem_Malloc(fixed->len ? fixed->len : 1);
    if (self->fixed == NULL || self->mask == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    memcpy(self->fixed, fixed->buf, fixed->len);
    memcpy(self->mask, mask->buf, mask->len);
    Py_ssize_t n3;
    Py_ssize_t *at = offsets(counts_at, size, 4, &n3, "count");
    if (at == NULL)
        return -1;
    if (n3 != 3) {
        PyMem_Free(at);
        PyErr_SetString(PyExc_ValueError, "three array lengths");
        return -1;
    }
    memcpy(self->counts_at, at, sizeof self->counts_at);
    PyMem_Free(at);
    PyObject *cs = PySequence_Fast(counts, "counts must be a sequence");
    if (cs == NULL)
        return -1;
    int bad = PySequence_Fast_GET_SIZE(cs) != 3;
    for (int k = 0; k < 3 && !bad; k++) {
        unsigned long c = PyLong_AsUnsignedLong(PySequence_Fast_GET_ITEM(cs, k));
        bad = (c == (unsigned long)-1 && PyErr_Occurred()) || c > 4096;
        self->counts[k] = (uint32_t)c;
    }
    Py_DECREF(cs);
    if (bad) {
        PyErr_Clear();
        PyErr_SetString(PyExc_ValueError, "three array lengths of at most 4096");
        return -1;
    }
    self->n = self->counts[0];
    self->n_vel = self->counts[1];
    if (self->n_vel != 0 && self->n_vel != self->n) {
        PyErr_SetString(PyExc_ValueError, "velocities: none, or one per position");
        return -1;
    }
    if (self->pos_at < 4 || self->pos_at + 8 * self->n > size
        || self->vel_at < 4 || self->vel_at + 8 * self->n_vel > size) {
        PyErr_SetString(PyExc_ValueError, "the arrays lie outside the message");
        return -1;
    }
    Py_ssize_t n_order;
    self->order = ints_within(order, 0, PY_SSIZE_T_MAX, &n_order, "order index");
    if (self->order == NULL)
        return -1;
    if (n_order != self->n) {
        PyErr_SetString(PyExc_ValueError, "order: one index per name");
        return -1;
    }
    self->lower = floats_of(lower, self->n, "lower");
    if (self->lower == NULL)
        return -1;
    self->upper = floats_of(upper, self->n, "upper");
    if (self->upper == NULL)
        return -1;
    return 0;
}

static int reader_init(ReaderObject *self, PyObject *args, PyObject *kwargs)
{
    Py_ssize_t size;
    Py_buffer fixed, mask;
    PyObject *counts_at, *counts, *order, *lower, *upper;
    long long jump;
    static char *names[] = {"size", "fixed", "mask", "counts_at", "counts", "positions_at",
                            "velocities_at", "order", "lower", "upper", "jump_back_ns",
                            NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "ny*y*OOnnOOOL", names, &size, &fixed,
                                     &mask, &counts_at, &counts, &self->pos_at,
                                     &self->vel_at, &order, &lower, &upper, &jump))
        return -1;
    reader_free(self);
    self->jump_back_ns = jump;
    int ok = reader_build(self, size, &fixed, &mask, counts_at, counts, order, lower, upper);
    if (ok < 0)
        reader_free(self);  /* a reader half built reads nothing */
    PyBuffer_Release(&fixed);
    PyBuffer_Release(&mask);
    return ok;
}

static int out_vector(PyObject *obj, Py_buffer *v, Py_ssize_t n)
{
    if (PyObject_GetBuffer(obj, v, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE) < 0)
        return -1;
    if (v->itemsize != 8 || v->format == NULL || strcmp(v->format, "d") != 0
        || v->len != 8 * n) {
        PyBuffer_Release(v);
        PyErr_Format(PyExc_ValueError, "q_out and qdot_out: writable float64, %zd values", n);
        return -1;
    }
    return 0;
}

static PyObject *reader_read(ReaderObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (self->fixed == NULL || self->lower == NULL || self->upper == NULL) {
        PyErr_SetString(PyExc_ValueError, "the reader was not initialised");
        return NULL;
    }
    if (nargs != 6 || !PyList_CheckExact(args[2]) || !PyList_CheckExact(args[3])) {
        PyErr_SetString(PyExc_TypeError, "read(raw, last_stamp_ns, q, qdot, q_out, qdot_out)"
                                         " with q and qdot lists of floats");
        return NULL;
    }
    PyObject *q = args[2], *qdot = args[3];
    Py_ssize_t dof = PyList_GET_SIZE(q);
    if (PyList_GET_SIZE(qdot) != dof) {
        PyErr_SetString(PyExc_ValueError, "q and qdot: the same length");
        return NULL;
    }
    for (Py_ssize_t k = 0; k < self->n; k++)
        if (self->order[k] >= dof) {
            PyErr_SetString(PyExc_ValueError, "order indexes past q");
            return NULL;
        }
    for (Py_ssize_t i = 0; i < dof; i++)
        if (!PyFloat_Check(PyList_GET_ITEM(q, i)) || !PyFloat_Check(PyList_GET_ITEM(qdot, i))) {
            PyErr_SetString(PyExc_TypeError, "q and qdot: lists of floats");
            return NULL;
        }
    Py_buffer raw;
    if (PyObject_GetBuffer(args[0], &raw, PyBUF_SIMPLE) < 0)
        return NULL;
    const unsigned char *b = raw.buf;
    PyObject *result = Py_None;
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
    long long stamp = (long long)sec * 1000000000LL + nsec;
    if (stamp != 0 && args[1] != Py_None) {
        long long last = PyLong_AsLongLong(args[1]);
        if (last == -1 && PyErr_Occurred()) {
            result = NULL;
            goto done;
        }
        if (stamp < last - self->jump_back_ns)
            goto done;
    }
    Py_buffer q_out, qdot_out;
    if (out_vector(args[4], &q_out, dof) < 0) {
        result = NULL;
        goto done;
    }
    if (out_vector(args[5], &qdot_out, dof) < 0) {
        PyBuffer_Release(&q_out);
        result = NULL;
        goto done;
    }
    PyObject *stamp_obj = PyLong_FromLongLong(stamp);
    for (Py_ssize_t k = 0; k < self->n && stamp_obj; k++) {
        double v, r = NAN;
        memcpy(&v, pos + 8 * k, 8);
        if (self->n_vel)
            memcpy(&r, vel + 8 * k, 8);
        PyObject *fv = PyFloat_FromDouble(v), *fr = PyFloat_FromDouble(r);
        if (fv == NULL || fr == NULL) {
            Py_XDECREF(fv);
            Py_XDECREF(fr);
            Py_CLEAR(stamp_obj);
            break;
        }
        PyList_SetItem(q, self->order[k], fv);     /* steals; frees the old float */
        PyList_SetItem(qdot, self->order[k], fr);
    }
    if (stamp_obj) {
        double *qo = q_out.buf, *qdo = qdot_out.buf;
        for (Py_ssize_t i = 0; i < dof; i++) {
            qo[i] = PyFloat_AS_DOUBLE(PyList_GET_ITEM(q, i));
            qdo[i] = PyFloat_AS_DOUBLE(PyList_GET_ITEM(qdot, i));
        }
    }
    PyBuffer_Release(&q_out);
    PyBuffer_Release(&qdot_out);
    PyBuffer_Release(&raw);
    return stamp_obj;
done:
    PyBuffer_Release(&raw);
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
    .tp_doc = "JointStateReader(...): the merger's short path for one JointState layout",
    .tp_basicsize = sizeof(ReaderObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)reader_init,
    .tp_dealloc = (destructor)reader_dealloc,
    .tp_methods = reader_methods,
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cdr",
    "Fixed-layout CDR messages filled in C (the reference: dq_fk_ros.messages.cdr.CdrPacker).",
    -1, NULL,
};

PyMODINIT_FUNC PyInit__cdr(void)
{
    const uint16_t one = 1;
    if (*(const unsigned char *)&one != 1) {  /* the templates are little-endian CDR */
        PyErr_SetString(PyExc_ImportError, "a big-endian machine: the Python packer runs");
        return NULL;
    }
    if (PyType_Ready(&TemplateType) < 0 || PyType_Ready(&ReaderType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    if (PyModule_AddType(m, &TemplateType) < 0 || PyModule_AddType(m, &ReaderType) < 0) {
        Py_DECREF(m);  /* (the types are named by their tp_name's last part) */
        return NULL;
    }
    return m;
}
