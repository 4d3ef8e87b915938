/*
 * dq_fk_ros.storage._mcap: an MCAP chunk's records read and written in C, without a Python
 * object per record (https://mcap.dev/spec: a record is opcode u8, length u64, body; a
 * message body is channel u16, sequence u32, log time u64, publish time u64, data).
 *
 * scan(records, wanted, start, stop, times, offsets, lengths, channels) -> n
 *     The message records of a chunk's uncompressed records whose channel is wanted
 *     (wanted[channel] != 0, 65536 bytes) and whose log time t has start <= t < stop (int64
 *     compare, as rosbags): their log time, data offset, data length and channel into the
 *     caller's int64 arrays, in record order. Records that are not messages are stepped
 *     over. A record that runs past the end, or a message record shorter than its header,
 *     raises ValueError naming its byte: the chunk is damaged.
 *     The reference: dq_fk_ros.storage.mcap_chunks.scan_records (test_mcap_chunks.py).
 * gather(src, offsets, lengths, dst) -> total
 *     Copy src[offsets[i]:offsets[i] + lengths[i]] for every i, back to back, into dst;
 *     every span is checked to lie in src and the whole to fit dst before a byte is copied.
 * Rows(ids, templates, stamps, slots, widths)
 *     K channels, each a fixed-layout CDR message (a template: its bytes, the offsets of its
 *     stamps, the offsets of its float64 slots of `width` values). fill(out, stamps_ns,
 *     log_times, values) writes N rows of K message records, row i the K messages stamped
 *     stamps_ns[i] and logged at log_times[i], channel k's slots holding the row i of
 *     values[k] ((N, slots * width) float64, rows at any stride, a row's values adjacent),
 *     into out (exactly N * row_bytes bytes, every byte written).
 *     The reference: CdrTemplate.fill and the numpy records of McapChunkStorage.write_rows
 *     (test_mcap_chunks.py holds them equal byte for byte).
 * reserve(fd, offset, length) -> bool
 *     Reserve the file's blocks [offset, offset + length) beyond its end without changing
 *     its size (Linux fallocate, FALLOC_FL_KEEP_SIZE): the writes that follow skip the file
 *     system's block reservation page by page. False where the file system or platform
 *     cannot (nothing is written or emulated). The writer truncates to its size at the end,
 *     which gives back what was not used.
 *
 * Every argument is converted to C values first (sequences copied into tuples of our own),
 * then every buffer taken and checked, then the work runs with no Python code in between;
 * no size is computed that could overflow (docs/security.md, test_compiled_fuzz.py, make
 * sanitize). Only the CPython C API and the buffer protocol: no numpy headers.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <fcntl.h>
#include <limits.h>
#include <stdint.h>
#include <string.h>

#include "../messages/c_arguments.h"

#define OP_MESSAGE 0x05
#define RECORD_HEAD 9        /* opcode u8, length u64 */
#define MESSAGE_HEAD 22      /* channel u16, sequence u32, log time u64, publish time u64 */
#define MAX_TEMPLATE (64 << 20)
#define MAX_CHANNELS 4096
#define MAX_WIDTH 64

static uint64_t load_u64(const unsigned char *p)
{
    uint64_t v;
    memcpy(&v, p, 8);
    return v;  /* little-endian: the module refuses to load elsewhere */
}

static int bytes_buffer(PyObject *obj, Py_buffer *b, int writable, const char *what)
{
    if (PyObject_GetBuffer(obj, b, writable ? PyBUF_WRITABLE : PyBUF_SIMPLE) < 0) {
        b->obj = NULL;
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s: a%s bytes-like object", what,
                     writable ? " writable" : "");
        return -1;
    }
    return 0;
}

static void release(Py_buffer *b)
{
    if (b->obj != NULL)
        PyBuffer_Release(b);
    b->obj = NULL;
}

static PyObject *scan(PyObject *module, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 8) {
        PyErr_SetString(PyExc_TypeError,
                        "scan(records, wanted, start, stop, times, offsets, lengths, channels)");
        return NULL;
    }
    long long start = PyLong_AsLongLong(args[2]);
    if (start == -1 && PyErr_Occurred())
        return NULL;
    long long stop = PyLong_AsLongLong(args[3]);
    if (stop == -1 && PyErr_Occurred())
        return NULL;
    Py_buffer rec = {0}, want = {0}, out[4] = {{0}};
    const char *names[4] = {"times", "offsets", "lengths", "channels"};
    PyObject *result = NULL;
    if (bytes_buffer(args[0], &rec, 0, "records") < 0
        || bytes_buffer(args[1], &want, 0, "wanted") < 0)
        goto done;
    for (int k = 0; k < 4; k++)
        if (int64_buffer(args[4 + k], &out[k], 1, names[k]) < 0)
            goto done;
    if (want.len != 65536) {
        PyErr_SetString(PyExc_ValueError, "wanted: 65536 bytes, one per channel id");
        goto done;
    }
    Py_ssize_t room = out[0].len / 8;
    for (int k = 1; k < 4; k++)
        if (out[k].len / 8 < room)
            room = out[k].len / 8;
    const unsigned char *b = rec.buf, *w = want.buf;
    int64_t *times = out[0].buf, *offs = out[1].buf, *lens = out[2].buf, *chans = out[3].buf;
    Py_ssize_t size = rec.len, pos = 0, n = 0;
    while (pos < size) {
        if (size - pos < RECORD_HEAD) {
            PyErr_Format(PyExc_ValueError, "the record at byte %zd is cut off by the chunk's "
                         "end", pos);
            goto done;
        }
        uint64_t length = load_u64(b + pos + 1);
        if (length > (uint64_t)(size - pos - RECORD_HEAD)) {
            PyErr_Format(PyExc_ValueError, "the record at byte %zd runs past the chunk's end",
                         pos);
            goto done;
        }
        if (b[pos] == OP_MESSAGE) {
            if (length < MESSAGE_HEAD) {
                PyErr_Format(PyExc_ValueError, "the message record at byte %zd is shorter "
                             "than its header", pos);
                goto done;
            }
            const unsigned char *body = b + pos + RECORD_HEAD;
            uint16_t channel;
            memcpy(&channel, body, 2);
            int64_t log_time = (int64_t)load_u64(body + 6);
            if (w[channel] && log_time >= start && log_time < stop) {
                if (n == room) {
                    PyErr_SetString(PyExc_ValueError, "more messages than the arrays hold");
                    goto done;
                }
                times[n] = log_time;
                offs[n] = pos + RECORD_HEAD + MESSAGE_HEAD;
                lens[n] = (int64_t)length - MESSAGE_HEAD;
                chans[n] = channel;
                n++;
            }
        }
        pos += RECORD_HEAD + (Py_ssize_t)length;
    }
    result = PyLong_FromSsize_t(n);
done:
    release(&rec);
    release(&want);
    for (int k = 0; k < 4; k++)
        release(&out[k]);
    return result;
}

static PyObject *gather(PyObject *module, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "gather(src, offsets, lengths, dst)");
        return NULL;
    }
    Py_buffer src = {0}, offs = {0}, lens = {0}, dst = {0};
    PyObject *result = NULL;
    if (bytes_buffer(args[0], &src, 0, "src") < 0
        || int64_buffer(args[1], &offs, 0, "offsets") < 0
        || int64_buffer(args[2], &lens, 0, "lengths") < 0
        || bytes_buffer(args[3], &dst, 1, "dst") < 0)
        goto done;
    if (offs.len != lens.len) {
        PyErr_SetString(PyExc_ValueError, "offsets and lengths: one each per span");
        goto done;
    }
    Py_ssize_t n = offs.len / 8, total = 0;
    /* the spans copied before they are checked: dst may overlap offsets or lengths, and
       what the copy writes must not change a span checked before it */
    int64_t *o = PyMem_Malloc(n ? 16 * (size_t)n : 1), *l = o + n;
    if (o == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    memcpy(o, offs.buf, 8 * (size_t)n);
    memcpy(l, lens.buf, 8 * (size_t)n);
    for (Py_ssize_t i = 0; i < n; i++) {
        if (o[i] < 0 || l[i] < 0 || o[i] > src.len || l[i] > src.len - o[i]) {
            PyErr_Format(PyExc_IndexError, "span %zd lies outside src", i);
            PyMem_Free(o);
            goto done;
        }
        if (l[i] > dst.len - total) {
            PyErr_SetString(PyExc_ValueError, "the spans do not fit dst");
            PyMem_Free(o);
            goto done;
        }
        total += l[i];
    }
    char *to = dst.buf;
    const char *from = src.buf;
    /* memmove: src and dst may be views of one object's bytes */
    for (Py_ssize_t i = 0, at = 0; i < n; at += l[i], i++)
        memmove(to + at, from + o[i], (size_t)l[i]);
    PyMem_Free(o);
    result = PyLong_FromSsize_t(total);
done:
    release(&src);
    release(&offs);
    release(&lens);
    release(&dst);
    return result;
}

/* ---------------------------------------------------------------------------------------
 * Rows: K fixed-layout messages a row, written as MCAP message records.
 */
typedef struct {
    char *data;                 /* the template's bytes */
    Py_ssize_t size, n_stamps, n_slots, width;
    Py_ssize_t *stamps, *slots;
    uint16_t id;
    Py_ssize_t at;              /* the record's offset in a row */
} Channel;

typedef struct {
    PyObject_HEAD
    Channel *channels;
    Py_ssize_t k, row_bytes;
    int initialised;
} RowsObject;

static void rows_clear(RowsObject *self)
{
    if (self->channels != NULL)
        for (Py_ssize_t i = 0; i < self->k; i++) {
            PyMem_Free(self->channels[i].data);
            PyMem_Free(self->channels[i].stamps);
            PyMem_Free(self->channels[i].slots);
        }
    PyMem_Free(self->channels);
    self->channels = NULL;
}

static void rows_dealloc(RowsObject *self)
{
    rows_clear(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* tuple(obj) of exactly k items, or NULL */
static PyObject *tuple_of(PyObject *obj, Py_ssize_t k, const char *what)
{
    PyObject *t = PySequence_Tuple(obj);
    if (t == NULL) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s: a sequence, one per channel", what);
        return NULL;
    }
    if (PyTuple_GET_SIZE(t) != k) {
        Py_DECREF(t);
        PyErr_Format(PyExc_ValueError, "%s: one per channel (%zd)", what, k);
        return NULL;
    }
    return t;
}

static int channel_build(Channel *c, PyObject *template, PyObject *stamps, PyObject *slots)
{
    Py_buffer b;
    if (bytes_buffer(template, &b, 0, "template") < 0)
        return -1;
    if (b.len < 4 || b.len > MAX_TEMPLATE) {
        PyBuffer_Release(&b);
        PyErr_Format(PyExc_ValueError, "a template has 4 to %d bytes", MAX_TEMPLATE);
        return -1;
    }
    c->data = PyMem_Malloc(b.len);
    if (c->data == NULL) {
        PyBuffer_Release(&b);
        PyErr_NoMemory();
        return -1;
    }
    memcpy(c->data, b.buf, b.len);
    c->size = b.len;
    PyBuffer_Release(&b);
    if (((unsigned char *)c->data)[1] != 1) {
        PyErr_SetString(PyExc_ValueError, "a template is little-endian CDR");
        return -1;
    }
    c->stamps = ints_within(stamps, 4, c->size - 8, &c->n_stamps, c->size, "stamp offset");
    if (c->stamps == NULL)
        return -1;
    /* 8 * width <= 512: size - 8 * width cannot overflow */
    c->slots = ints_within(slots, 4, c->size - 8 * c->width, &c->n_slots, c->size,
                           "slot offset");
    return c->slots == NULL ? -1 : 0;
}

static PyObject *rows_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    PyObject *ids, *templates, *stamps, *slots, *widths;
    static char *names[] = {"ids", "templates", "stamps", "slots", "widths", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOOO", names, &ids, &templates, &stamps,
                                     &slots, &widths))
        return NULL;
    RowsObject *self = (RowsObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    Py_ssize_t k, kw, *id = NULL, *width = NULL;
    PyObject *t_templates = NULL, *t_stamps = NULL, *t_slots = NULL;
    if ((id = ints_within(ids, 0, 65535, &k, MAX_CHANNELS, "channel id")) == NULL
        || (width = ints_within(widths, 1, MAX_WIDTH, &kw, MAX_CHANNELS, "width")) == NULL)
        goto fail;
    if (k < 1 || kw != k) {
        PyErr_SetString(PyExc_ValueError, "ids and widths: one per channel, at least one");
        goto fail;
    }
    if ((t_templates = tuple_of(templates, k, "templates")) == NULL
        || (t_stamps = tuple_of(stamps, k, "stamps")) == NULL
        || (t_slots = tuple_of(slots, k, "slots")) == NULL)
        goto fail;
    self->channels = PyMem_Calloc(k, sizeof(Channel));
    if (self->channels == NULL) {
        PyErr_NoMemory();
        goto fail;
    }
    self->k = k;
    Py_ssize_t row = 0;
    for (Py_ssize_t i = 0; i < k; i++) {
        Channel *c = self->channels + i;
        c->id = (uint16_t)id[i];
        c->width = width[i];
        if (channel_build(c, PyTuple_GET_ITEM(t_templates, i), PyTuple_GET_ITEM(t_stamps, i),
                          PyTuple_GET_ITEM(t_slots, i)) < 0)
            goto fail;
        c->at = row;
        /* k <= 4096 records of <= 64 MiB + 31 each: below 2**39, no overflow */
        row += RECORD_HEAD + MESSAGE_HEAD + c->size;
    }
    self->row_bytes = row;
    PyMem_Free(id);
    PyMem_Free(width);
    Py_DECREF(t_templates);
    Py_DECREF(t_stamps);
    Py_DECREF(t_slots);
    return (PyObject *)self;
fail:
    PyMem_Free(id);
    PyMem_Free(width);
    Py_XDECREF(t_templates);
    Py_XDECREF(t_stamps);
    Py_XDECREF(t_slots);
    Py_DECREF(self);  /* a Rows half built is no Rows */
    return NULL;
}

static int rows_init(RowsObject *self, PyObject *args, PyObject *kwargs)
{
    if (self->initialised) {
        PyErr_SetString(PyExc_TypeError, "a Rows is set once, when it is made; make a new one");
        return -1;
    }
    self->initialised = 1;
    return 0;
}

/* (n, slots * width) float64 values: rows at any stride, each row's values contiguous */
static int values_buffer(PyObject *obj, Py_buffer *b, Py_ssize_t n, const Channel *c)
{
    if (PyObject_GetBuffer(obj, b, PyBUF_STRIDES | PyBUF_FORMAT) < 0) {
        b->obj = NULL;
        PyErr_Clear();
        PyErr_SetString(PyExc_ValueError, "values: float64 arrays of rows");
        return -1;
    }
    /* slots <= template size <= 64 MiB, width <= 64: per row below 2**33 values */
    Py_ssize_t per_row = c->n_slots * c->width;
    if (b->itemsize != 8 || b->format == NULL || b->ndim != 2 || b->shape == NULL
        || b->strides == NULL
        || (strcmp(b->format, "d") != 0 && strcmp(b->format, "<d") != 0)
        || b->shape[0] != n || b->shape[1] != per_row
        || (per_row > 1 && b->strides[1] != 8)) {
        PyBuffer_Release(b);
        b->obj = NULL;
        PyErr_Format(PyExc_ValueError, "values of channel %d: (%zd, %zd) float64, each row's "
                     "values contiguous", (int)c->id, n, per_row);
        return -1;
    }
    return 0;
}

static void write_record(char *to, const Channel *c, int64_t log_time, uint32_t sec,
                         uint32_t nsec, const double *values)
{
    uint64_t length = MESSAGE_HEAD + (uint64_t)c->size;
    uint32_t sequence = 0;
    to[0] = OP_MESSAGE;
    memcpy(to + 1, &length, 8);
    memcpy(to + 9, &c->id, 2);
    memcpy(to + 11, &sequence, 4);
    memcpy(to + 15, &log_time, 8);
    memcpy(to + 23, &log_time, 8);
    char *msg = to + RECORD_HEAD + MESSAGE_HEAD;
    memcpy(msg, c->data, c->size);
    for (Py_ssize_t s = 0; s < c->n_stamps; s++) {
        memcpy(msg + c->stamps[s], &sec, 4);
        memcpy(msg + c->stamps[s] + 4, &nsec, 4);
    }
    for (Py_ssize_t s = 0; s < c->n_slots; s++)
        memcpy(msg + c->slots[s], values + s * c->width, 8 * c->width);
}

static PyObject *rows_fill(RowsObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "fill(out, stamps_ns, log_times, values)");
        return NULL;
    }
    Py_ssize_t k = self->k;
    PyObject *t_values = tuple_of(args[3], k, "values");
    if (t_values == NULL)
        return NULL;
    Py_buffer out = {0}, stamps = {0}, times = {0};
    Py_buffer *values = PyMem_Calloc(k, sizeof(Py_buffer));
    PyObject *result = NULL;
    if (values == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    if (bytes_buffer(args[0], &out, 1, "out") < 0
        || int64_buffer(args[1], &stamps, 0, "stamps_ns") < 0
        || int64_buffer(args[2], &times, 0, "log_times") < 0)
        goto done;
    Py_ssize_t n = stamps.len / 8;
    if (times.len != stamps.len) {
        PyErr_SetString(PyExc_ValueError, "stamps_ns and log_times: one each per row");
        goto done;
    }
    for (Py_ssize_t i = 0; i < k; i++)
        if (values_buffer(PyTuple_GET_ITEM(t_values, i), values + i, n, self->channels + i) < 0)
            goto done;
    if (n > PY_SSIZE_T_MAX / self->row_bytes || out.len != n * self->row_bytes) {
        PyErr_Format(PyExc_ValueError, "out: %zd rows of %zd bytes", n, self->row_bytes);
        goto done;
    }
    const int64_t *st = stamps.buf, *lt = times.buf;
    char *to = out.buf;
    for (Py_ssize_t r = 0; r < n; r++, to += self->row_bytes) {
        int64_t sec = st[r] / 1000000000, rem = st[r] % 1000000000;
        if (rem < 0) {  /* floor division, as numpy's // and % */
            rem += 1000000000;
            sec -= 1;
        }
        /* builtin_interfaces/Time: int32 sec (its low 32 bits, as a numpy int32 view takes
           it) and uint32 nanosec */
        uint32_t sec32 = (uint32_t)(uint64_t)sec, nsec = (uint32_t)rem;
        for (Py_ssize_t i = 0; i < k; i++) {
            const Channel *c = self->channels + i;
            /* row r of an (n, per_row) buffer: its exporter holds n rows at this stride
               (a channel without slots reads nothing, whatever its empty array's strides) */
            const char *row = c->n_slots == 0 ? NULL
                : (const char *)values[i].buf + r * values[i].strides[0];
            write_record(to + c->at, c, lt[r], sec32, nsec, (const double *)row);
        }
    }
    Py_INCREF(Py_None);
    result = Py_None;
done:
    release(&out);
    release(&stamps);
    release(&times);
    if (values != NULL)
        for (Py_ssize_t i = 0; i < k; i++)
            release(values + i);
    PyMem_Free(values);
    Py_DECREF(t_values);
    return result;
}

static PyObject *rows_get_row_bytes(RowsObject *self, void *closure)
{
    return PyLong_FromSsize_t(self->row_bytes);
}

static PyObject *rows_get_offsets(RowsObject *self, void *closure)
{
    PyObject *t = PyTuple_New(self->k);
    if (t == NULL)
        return NULL;
    for (Py_ssize_t i = 0; i < self->k; i++) {
        PyObject *v = PyLong_FromSsize_t(self->channels[i].at);
        if (v == NULL) {
            Py_DECREF(t);
            return NULL;
        }
        PyTuple_SET_ITEM(t, i, v);
    }
    return t;
}

static PyMethodDef rows_methods[] = {
    {"fill", (PyCFunction)(void (*)(void))rows_fill, METH_FASTCALL,
     "fill(out, stamps_ns, log_times, values): N rows of message records into out"},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef rows_getset[] = {
    {"row_bytes", (getter)rows_get_row_bytes, NULL, "bytes of one row of K records", NULL},
    {"offsets", (getter)rows_get_offsets, NULL, "each channel's record offset in a row",
     NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject RowsType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "dq_fk_ros.storage._mcap.Rows",
    .tp_doc = "Rows(ids, templates, stamps, slots, widths): K fixed-layout messages a row, "
              "written as MCAP message records (immutable)",
    .tp_basicsize = sizeof(RowsObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = rows_new,
    .tp_init = (initproc)rows_init,
    .tp_dealloc = (destructor)rows_dealloc,
    .tp_methods = rows_methods,
    .tp_getset = rows_getset,
};

static PyObject *reserve(PyObject *module, PyObject *const *args, Py_ssize_t nargs)
{
    Py_ssize_t fd, offset, length;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "reserve(fd, offset, length)");
        return NULL;
    }
    if (int_within(args[0], 0, INT_MAX, &fd, "fd") < 0
        || int_within(args[1], 0, PY_SSIZE_T_MAX, &offset, "offset") < 0
        || int_within(args[2], 1, PY_SSIZE_T_MAX - offset, &length, "length") < 0)
        return NULL;
#if defined(__linux__) && defined(FALLOC_FL_KEEP_SIZE)
    int r;
    Py_BEGIN_ALLOW_THREADS
    r = fallocate((int)fd, FALLOC_FL_KEEP_SIZE, (off_t)offset, (off_t)length);
    Py_END_ALLOW_THREADS
    return PyBool_FromLong(r == 0);
#else
    Py_RETURN_FALSE;
#endif
}

static PyMethodDef module_methods[] = {
    {"reserve", (PyCFunction)(void (*)(void))reserve, METH_FASTCALL,
     "reserve(fd, offset, length) -> bool: blocks reserved past the end, its size kept"},
    {"scan", (PyCFunction)(void (*)(void))scan, METH_FASTCALL,
     "scan(records, wanted, start, stop, times, offsets, lengths, channels) -> n"},
    {"gather", (PyCFunction)(void (*)(void))gather, METH_FASTCALL,
     "gather(src, offsets, lengths, dst) -> total: the spans back to back into dst"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_mcap",
    "MCAP chunk records read and written in C (the reference: dq_fk_ros.storage.mcap_chunks).",
    -1, module_methods,
};

PyMODINIT_FUNC PyInit__mcap(void)
{
    const uint16_t one = 1;
    if (*(const unsigned char *)&one != 1) {  /* MCAP and the templates are little-endian */
        PyErr_SetString(PyExc_ImportError, "a big-endian machine: the Python paths run");
        return NULL;
    }
    if (PyType_Ready(&RowsType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    if (PyModule_AddType(m, &RowsType) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
