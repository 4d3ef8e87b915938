/*
 * dq_fk_ros.transforms._tf: tf2's lookup walk in C over BufferCore's own arrays.
 *
 * The fast path of dq_fk_ros/transforms/buffer_core.py (the reference, BufferCore._walk
 * and latest_common_time; test_tf_buffer_core.py's test_the_compiled_walk_* holds them
 * equal): the same rules and the same floating-point operations in the same order.
 *
 *   lookup(caches, target, source, time_ns) -> (time used, x, y, z, qx, qy, qz, qw) or None
 *       None: tf2 would raise; the caller asks the reference for the exception.
 *   append_many(caches, plan, raw, cache_ns) -> [indices of the plan's rows not taken]
 *       plan: int64 rows (child id, parent id, stamp offset, values offset) of a serialized
 *       TFMessage; each transform newer than its child's newest sample, valid, onto a
 *       dynamic cache with room is appended as MovingEdge.insert appends it (pruning
 *       included); the rest (new frames, old or equal stamps, refusals, a full cache) are the caller's,
 *       for BufferCore.set_transform (the reference; test_tf_listener_reads_as_set_transform).
 *   lookup_many(caches, up, down, stamps, out, ok) -> None
 *       the path's edges (child, parent) from the source up and from the target up, at each
 *       stamp (int64, n); out (float64, n * 7) and ok (uint8, n) written: ok 0 where an
 *       edge has no sample for the stamp or names another parent.
 *
 * caches is BufferCore.caches: a list whose items are None (a root), a static cache
 * (attributes static True, parent int, values a tuple of 7 floats) or a dynamic one
 * (static False, stamps array('q'), parents array('q'), values array('d') of 7 per sample,
 * start int). Every item is held (a strong reference, its arrays' buffers) while it is
 * read, every attribute checked; anything else raises TypeError or ValueError. No Python
 * value crashes it (test_compiled_fuzz.py, under make sanitize).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#define MAX_GRAPH_DEPTH 1000

#include "tf_math.h"
#include "tf_cache.h"

/* Load, read and release one edge: -1 exception, 0 root, 1 found, 2 no answer. */
static int gather(PyObject *caches, Py_ssize_t frame, int64_t t, int want_latest,
                  Py_ssize_t *parent, double *v, int64_t *stamp)
{
    Cache c;
    if (load(caches, frame, &c) < 0)
        return -1;
    int r;
    if (c.kind == 0)
        r = 0;
    else if (want_latest) {
        latest(&c, stamp, parent);
        r = *parent == 0 ? 2 : 1;
    } else
        r = get(&c, t, parent, v) ? 1 : 2;
    release(&c);
    return r;
}

/* Fold an edge's newest stamp into the common time (0, a static edge, counts for nothing). */
static void earliest(int64_t stamp, int64_t *common, int *have)
{
    if (stamp != 0) {
        *common = *have && *common < stamp ? *common : stamp;
        *have = 1;
    }
}

/* BufferCore.latest_common_time: 1 found (*t), 0 tf2 raises, -1 exception. */
static int common_time(PyObject *caches, Py_ssize_t target, Py_ssize_t source, int64_t *t)
{
    Py_ssize_t chain_parent[MAX_GRAPH_DEPTH + 2];
    int64_t chain_stamp[MAX_GRAPH_DEPTH + 2];
    Py_ssize_t count = 0, frame = source, parent, depth = 0, meet = 0;
    int64_t stamp, common = 0;
    int have = 0;
    double v[7];
    while (frame != 0) {
        int r = gather(caches, frame, 0, 1, &parent, v, &stamp);
        if (r < 0)
            return -1;
        if (r != 1)
            break;
        earliest(stamp, &common, &have);
        chain_stamp[count] = stamp;
        chain_parent[count++] = parent;
        frame = parent;
        if (frame == target) {
            *t = have ? common : 0;
            return 1;
        }
        if (++depth > MAX_GRAPH_DEPTH)
            return 0;
    }
    frame = target;
    depth = 0;
    have = 0;
    common = 0;
    for (;;) {
        int r = gather(caches, frame, 0, 1, &parent, v, &stamp);
        if (r < 0)
            return -1;
        if (r != 1)
            break;
        earliest(stamp, &common, &have);
        int found = 0;
        for (Py_ssize_t k = 0; k < count && !found; k++)
            found = chain_parent[k] == parent;
        if (found) {
            meet = parent;
            break;
        }
        frame = parent;
        if (frame == source) {
            *t = have ? common : 0;
            return 1;
        }
        if (++depth > MAX_GRAPH_DEPTH)
            return 0;
    }
    if (meet == 0)
        return 0;
    for (Py_ssize_t k = 0; k < count; k++) {
        earliest(chain_stamp[k], &common, &have);
        if (chain_parent[k] == meet)
            break;
    }
    *t = have ? common : 0;
    return 1;
}

static const double IDENTITY[7] = {0, 0, 0, 0, 0, 0, 1};

/* BufferCore._walk: 1 pose in *out, 0 tf2 raises, -1 exception. */
static int walk(PyObject *caches, Py_ssize_t target, Py_ssize_t source, int64_t t,
                double *out)
{
    double source_pose[7], target_pose[7], v[7], inv[7];
    Py_ssize_t frame = source, top = source, parent, depth = 0;
    int64_t unused;
    memcpy(source_pose, IDENTITY, sizeof source_pose);
    memcpy(target_pose, IDENTITY, sizeof target_pose);
    if (source == target) {
        memcpy(out, IDENTITY, sizeof IDENTITY);
        return 1;
    }
    while (frame != 0) {
        int r = gather(caches, frame, t, 0, &parent, v, &unused);
        if (r < 0)
            return -1;
        if (r == 0 || r == 2) {   /* a root; or no sample: there may still be a path */
            top = frame;
            break;
        }
        if (frame == target) {
            memcpy(out, source_pose, sizeof source_pose);
            return 1;
        }
        compose(v, source_pose, source_pose);
        top = frame;
        frame = parent;
        if (++depth > MAX_GRAPH_DEPTH)
            return 0;
    }
    frame = target;
    depth = 0;
    while (frame != top) {
        int r = gather(caches, frame, t, 0, &parent, v, &unused);
        if (r < 0)
            return -1;
        if (r == 0)
            break;
        if (r == 2)
            return 0;
        if (frame == source) {
            inverse(target_pose, out);
            return 1;
        }
        compose(v, target_pose, target_pose);
        frame = parent;
        if (++depth > MAX_GRAPH_DEPTH)
            return 0;
    }
    if (frame != top)
        return 0;
    inverse(target_pose, inv);
    compose(inv, source_pose, out);
    return 1;
}

static int frame_id(PyObject *obj, Py_ssize_t *id, const char *what)
{
    *id = PyLong_CheckExact(obj) ? PyLong_AsSsize_t(obj) : -1;
    if (*id < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "%s: a frame id, an int >= 0", what);
        return -1;
    }
    return 0;
}

static PyObject *tf_lookup(PyObject *self, PyObject *args)
{
    PyObject *caches, *target_obj, *source_obj, *time_obj;
    Py_ssize_t target, source;
    if (!PyArg_ParseTuple(args, "O!OOO", &PyList_Type, &caches, &target_obj, &source_obj,
                          &time_obj))
        return NULL;
    if (frame_id(target_obj, &target, "target") < 0 || frame_id(source_obj, &source, "source") < 0)
        return NULL;
    if (!PyLong_CheckExact(time_obj)) {
        PyErr_SetString(PyExc_TypeError, "time_ns: an int");
        return NULL;
    }
    int overflow = 0;
    long long t = PyLong_AsLongLongAndOverflow(time_obj, &overflow);
    if (overflow || (t == -1 && PyErr_Occurred())) {
        PyErr_Clear();
        PyErr_SetString(PyExc_OverflowError, "time_ns: within int64");
        return NULL;
    }
    Py_INCREF(caches);   /* held while read */
    int64_t used = (int64_t)t;
    int r = 1;
    if (used == 0)
        r = common_time(caches, target, source, &used);
    double pose[7];
    if (r == 1)
        r = walk(caches, target, source, used, pose);
    Py_DECREF(caches);
    if (r < 0)
        return NULL;
    if (r == 0)
        Py_RETURN_NONE;
    return Py_BuildValue("(Lddddddd)", (long long)used, pose[0], pose[1], pose[2], pose[3],
                         pose[4], pose[5], pose[6]);
}

/* A sequence of (child, parent) pairs as a C array of 2 * n ids. */
static Py_ssize_t *edge_list(PyObject *obj, Py_ssize_t *n, const char *what)
{
    PyObject *seq = PySequence_Tuple(obj);
    if (seq == NULL)
        return NULL;
    *n = PyTuple_GET_SIZE(seq);
    if (*n > MAX_GRAPH_DEPTH + 1) {
        Py_DECREF(seq);
        PyErr_Format(PyExc_ValueError, "%s: at most %d edges", what, MAX_GRAPH_DEPTH + 1);
        return NULL;
    }
    Py_ssize_t *ids = PyMem_Malloc(2 * (*n + 1) * sizeof(Py_ssize_t));
    if (ids == NULL) {
        Py_DECREF(seq);
        PyErr_NoMemory();
        return NULL;
    }
    for (Py_ssize_t k = 0; k < *n; k++) {
        PyObject *pair = PyTuple_GET_ITEM(seq, k);
        if (!PyTuple_CheckExact(pair) || PyTuple_GET_SIZE(pair) != 2 ||
            frame_id(PyTuple_GET_ITEM(pair, 0), ids + 2 * k, what) < 0 ||
            frame_id(PyTuple_GET_ITEM(pair, 1), ids + 2 * k + 1, what) < 0) {
            if (!PyErr_Occurred())
                PyErr_Format(PyExc_TypeError, "%s: (child, parent) pairs of ints", what);
            PyMem_Free(ids);
            Py_DECREF(seq);
            return NULL;
        }
    }
    Py_DECREF(seq);
    return ids;
}

static int overlaps(const Py_buffer *a, const Py_buffer *b)
{
    const char *x = a->buf, *y = b->buf;
    return a->len > 0 && b->len > 0 && x < y + b->len && y < x + a->len;
}

static PyObject *tf_lookup_many(PyObject *self, PyObject *args)
{
    PyObject *caches, *up_obj, *down_obj, *stamps_obj, *out_obj, *ok_obj;
    if (!PyArg_ParseTuple(args, "O!OOOOO", &PyList_Type, &caches, &up_obj, &down_obj,
                          &stamps_obj, &out_obj, &ok_obj))
        return NULL;
    Py_ssize_t nu, nd;
    Py_ssize_t *up = edge_list(up_obj, &nu, "up");
    if (up == NULL)
        return NULL;
    Py_ssize_t *down = edge_list(down_obj, &nd, "down");
    if (down == NULL) {
        PyMem_Free(up);
        return NULL;
    }
    Py_buffer sb = {0}, ob = {0}, kb = {0};
    Cache *caches_read = NULL;
    Py_ssize_t loaded = 0;
    PyObject *result = NULL;
    if (PyObject_GetBuffer(stamps_obj, &sb, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        goto done;
    if (PyObject_GetBuffer(out_obj, &ob, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT |
                           PyBUF_WRITABLE) < 0)
        goto done;
    if (PyObject_GetBuffer(ok_obj, &kb, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT |
                           PyBUF_WRITABLE) < 0)
        goto done;
    const char *sf = sb.format ? sb.format : "", *of = ob.format ? ob.format : "",
               *kf = kb.format ? kb.format : "";
    if (sb.itemsize != 8 || (strcmp(sf, "q") && strcmp(sf, "l") && strcmp(sf, "<q")
                              && strcmp(sf, "=q"))) {
        PyErr_SetString(PyExc_ValueError, "stamps: a C-contiguous int64 array");
        goto done;
    }
    if (ob.itemsize != 8 || (strcmp(of, "d") && strcmp(of, "<d") && strcmp(of, "=d"))) {
        PyErr_SetString(PyExc_ValueError, "out: a C-contiguous writable float64 array");
        goto done;
    }
    if (kb.itemsize != 1 || (strcmp(kf, "B") && strcmp(kf, "?") && strcmp(kf, "b")
                              && strcmp(kf, "<B") && strcmp(kf, "=B"))) {
        PyErr_SetString(PyExc_ValueError, "ok: a C-contiguous writable uint8 array");
        goto done;
    }
    Py_ssize_t n = sb.len / 8;
    if (ob.len / 8 / 7 != n || ob.len / 8 % 7 != 0 || kb.len != n) {
        PyErr_SetString(PyExc_ValueError, "out must hold 7 floats and ok one byte per stamp");
        goto done;
    }
    if (overlaps(&sb, &ob) || overlaps(&sb, &kb) || overlaps(&ob, &kb)) {
        PyErr_SetString(PyExc_ValueError, "stamps, out and ok must not overlap");
        goto done;
    }
    caches_read = PyMem_Calloc((size_t)(nu + nd + 1), sizeof(Cache));
    if (caches_read == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t k = 0; k < nu + nd; k++) {
        Py_ssize_t child = k < nu ? up[2 * k] : down[2 * (k - nu)];
        if (load(caches, child, caches_read + k) < 0)
            goto done;
        loaded = k + 1;
    }
    const int64_t *stamps = sb.buf;
    double *out = ob.buf;
    unsigned char *ok = kb.buf;
    for (Py_ssize_t i = 0; i < n; i++) {
        double source_pose[7], target_pose[7], v[7], inv[7];
        memcpy(source_pose, IDENTITY, sizeof source_pose);
        memcpy(target_pose, IDENTITY, sizeof target_pose);
        int good = 1;
        for (Py_ssize_t k = 0; k < nu + nd && good; k++) {
            Py_ssize_t parent, want = k < nu ? up[2 * k + 1] : down[2 * (k - nu) + 1];
            Cache *c = caches_read + k;
            good = c->kind != 0 && get(c, stamps[i], &parent, v) && parent == want;
            if (good)
                compose(v, k < nu ? source_pose : target_pose,
                        k < nu ? source_pose : target_pose);
        }
        ok[i] = (unsigned char)good;
        if (good) {
            inverse(target_pose, inv);
            compose(inv, source_pose, out + 7 * i);
        } else {
            for (int j = 0; j < 7; j++)
                out[7 * i + j] = NAN;
        }
    }
    Py_INCREF(Py_None);
    result = Py_None;
done:
    for (Py_ssize_t k = 0; k < loaded; k++)
        release(caches_read + k);
    PyMem_Free(caches_read);
    if (sb.obj)
        PyBuffer_Release(&sb);
    if (ob.obj)
        PyBuffer_Release(&ob);
    if (kb.obj)
        PyBuffer_Release(&kb);
    PyMem_Free(up);
    PyMem_Free(down);
    return result;
}

/* First index in [lo, n) whose stamp is >= t (bisect_left). */
static Py_ssize_t first_at(const int64_t *s, Py_ssize_t lo, Py_ssize_t n, int64_t t)
{
    Py_ssize_t hi = n;
    while (lo < hi) {
        Py_ssize_t mid = lo + (hi - lo) / 2;
        if (s[mid] < t)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

#define QUATERNION_TOLERANCE 10e-3

/*
 * One transform onto its child's dynamic cache, as MovingEdge.insert does for a stamp newer
 * than every other: 1 taken, 0 not the common case (the caller's reference takes it),
 * -1 an exception.
 */
static int append_one(PyObject *caches, Py_ssize_t child, Py_ssize_t parent, int64_t stamp,
                      const double *raw_values, int64_t cache_ns)
{
    double v[7];
    memcpy(v, raw_values, sizeof v);
    for (int k = 0; k < 7; k++)
        if (!isfinite(v[k]))
            return 0;
    double norm2 = v[3] * v[3] + v[4] * v[4] + v[5] * v[5] + v[6] * v[6];
    if (!(fabs(norm2 - 1.0) < QUATERNION_TOLERANCE))
        return 0;
    Cache c;
    if (load_for(caches, child, &c, 1) < 0) {
        PyErr_Clear();
        return 0;
    }
    if (c.kind != 2 || c.n - c.start <= 0 || c.n >= c.room || stamp <= c.s[c.n - 1] ||
        cache_ns < 0 || c.s[c.n - 1] < INT64_MIN + cache_ns) {
        release(&c);
        return 0;
    }
    Py_ssize_t start = first_at(c.s, c.start, c.n, c.s[c.n - 1] - cache_ns);
    double norm = sqrt(norm2);
    v[3] /= norm;
    v[4] /= norm;
    v[5] /= norm;
    v[6] /= norm;
    Py_ssize_t at = c.n;
    ((int64_t *)c.sb.buf)[at] = stamp;
    ((int64_t *)c.pb.buf)[at] = (int64_t)parent;
    memcpy((double *)c.vb.buf + 7 * at, v, sizeof v);
    int r = 1;
    PyObject *x = PyLong_FromSsize_t(at + 1);
    if (x == NULL || PyObject_SetAttr(c.item, NAME_COUNT, x) < 0)
        r = -1;
    Py_XDECREF(x);
    if (r == 1 && start != c.start) {
        x = PyLong_FromSsize_t(start);
        if (x == NULL || PyObject_SetAttr(c.item, NAME_START, x) < 0)
            r = -1;
        Py_XDECREF(x);
    }
    release(&c);
    return r;
}

static PyObject *tf_append_many(PyObject *self, PyObject *args)
{
    PyObject *caches, *plan_obj, *raw_obj;
    long long cache_ns;
    if (!PyArg_ParseTuple(args, "O!OOL", &PyList_Type, &caches, &plan_obj, &raw_obj,
                          &cache_ns))
        return NULL;
    Py_buffer pb = {0}, rb = {0};
    PyObject *left = NULL;
    if (PyObject_GetBuffer(plan_obj, &pb, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return NULL;
    const char *f = pb.format ? pb.format : "";
    if (pb.itemsize != 8 || (strcmp(f, "q") && strcmp(f, "l") && strcmp(f, "<q")
                              && strcmp(f, "=q")) || pb.len % 32 != 0) {
        PyErr_SetString(PyExc_ValueError, "plan: a C-contiguous int64 array of rows of 4");
        goto done;
    }
    if (PyObject_GetBuffer(raw_obj, &rb, PyBUF_SIMPLE) < 0)
        goto done;
    /* the plan and the message are copied first: appending may run Python code */
    Py_ssize_t rows = pb.len / 32, size = rb.len;
    int64_t *plan = PyMem_Malloc(pb.len ? (size_t)pb.len : 1);
    char *raw = PyMem_Malloc(size ? (size_t)size : 1);
    if (plan == NULL || raw == NULL) {
        PyMem_Free(plan);
        PyMem_Free(raw);
        PyErr_NoMemory();
        goto done;
    }
    memcpy(plan, pb.buf, (size_t)pb.len);
    memcpy(raw, rb.buf, (size_t)size);
    PyBuffer_Release(&rb);
    PyBuffer_Release(&pb);
    left = PyList_New(0);
    for (Py_ssize_t i = 0; left != NULL && i < rows; i++) {
        int64_t child = plan[4 * i], parent = plan[4 * i + 1];
        int64_t stamp_at = plan[4 * i + 2], value_at = plan[4 * i + 3];
        int r = 0;
        if (child > 0 && parent > 0 && child < PY_SSIZE_T_MAX && parent < PY_SSIZE_T_MAX &&
            stamp_at >= 0 && stamp_at <= size - 8 && value_at >= 0 && value_at <= size - 56) {
            int32_t sec;
            uint32_t nanosec;
            double values[7];
            memcpy(&sec, raw + stamp_at, 4);
            memcpy(&nanosec, raw + stamp_at + 4, 4);
            memcpy(values, raw + value_at, sizeof values);
            r = append_one(caches, (Py_ssize_t)child, (Py_ssize_t)parent,
                           (int64_t)sec * 1000000000 + nanosec, values, (int64_t)cache_ns);
        }
        if (r < 0) {
            Py_CLEAR(left);
            break;
        }
        if (r == 0) {
            PyObject *index = PyLong_FromSsize_t(i);
            if (index == NULL || PyList_Append(left, index) < 0)
                Py_CLEAR(left);
            Py_XDECREF(index);
        }
    }
    PyMem_Free(plan);
    PyMem_Free(raw);
    return left;
done:
    if (rb.obj)
        PyBuffer_Release(&rb);
    if (pb.obj)
        PyBuffer_Release(&pb);
    return NULL;
}

/*
 * csv_rows(stamps, poses) -> bytes: "stamp,x,y,z,qx,qy,qz,qw\n" per row, each float with
 * 9 decimals (nanometres; a quaternion to 1e-9): q = floor(|x| * 1e9 + 0.5) written as
 * q / 10^9 "." q % 10^9, a "-" before it when x < 0 and q > 0; |x| >= 9e9 or not finite:
 * "%.17g". The reference is tf_export.fixed9 in Python (test_tf_bag.py's
 * test_csv_rows_are_the_python_ones).
 */
static int fixed9(double x, char *out)
{
    if (isnan(x)) {
        memcpy(out, "nan", 3);   /* (printf writes -nan for a NaN with its sign bit set) */
        return 3;
    }
    if (!isfinite(x) || fabs(x) >= 9e9)
        return snprintf(out, 32, "%.17g", x);
    double scaled = floor(fabs(x) * 1e9 + 0.5);
    uint64_t q = (uint64_t)scaled;
    char digits[24];
    int n = 0, at = 0;
    uint64_t whole = q / 1000000000u, frac = q % 1000000000u;
    if (x < 0 && q > 0)
        out[at++] = '-';
    do {
        digits[n++] = (char)('0' + whole % 10);
        whole /= 10;
    } while (whole);
    while (n)
        out[at++] = digits[--n];
    out[at++] = '.';
    for (int k = 8; k >= 0; k--) {
        out[at + k] = (char)('0' + frac % 10);
        frac /= 10;
    }
    return at + 9;
}

static PyObject *tf_csv_rows(PyObject *self, PyObject *args)
{
    PyObject *stamps_obj, *poses_obj;
    if (!PyArg_ParseTuple(args, "OO", &stamps_obj, &poses_obj))
        return NULL;
    Py_buffer sb = {0}, pb = {0};
    PyObject *result = NULL;
    char *text = NULL;
    if (PyObject_GetBuffer(stamps_obj, &sb, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return NULL;
    if (PyObject_GetBuffer(poses_obj, &pb, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        goto done;
    const char *sf = sb.format ? sb.format : "", *pf = pb.format ? pb.format : "";
    if (sb.itemsize != 8 || (strcmp(sf, "q") && strcmp(sf, "l") && strcmp(sf, "<q") &&
                             strcmp(sf, "=q"))) {
        PyErr_SetString(PyExc_ValueError, "stamps: a C-contiguous int64 array");
        goto done;
    }
    if (pb.itemsize != 8 || (strcmp(pf, "d") && strcmp(pf, "<d") && strcmp(pf, "=d"))) {
        PyErr_SetString(PyExc_ValueError, "poses: a C-contiguous float64 array");
        goto done;
    }
    Py_ssize_t n = sb.len / 8;
    if (pb.len / 8 / 7 != n || pb.len / 8 % 7 != 0) {
        PyErr_SetString(PyExc_ValueError, "poses must hold 7 floats per stamp");
        goto done;
    }
    /* a row: at most 20 digits and a sign, 7 floats of at most 31 characters, 8 separators */
    const Py_ssize_t row_max = 21 + 7 * 32 + 8;
    if (n > PY_SSIZE_T_MAX / row_max - 1) {
        PyErr_SetString(PyExc_OverflowError, "too many rows");
        goto done;
    }
    text = PyMem_Malloc((size_t)(n * row_max + 1));
    if (text == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    const int64_t *stamps = sb.buf;
    const double *poses = pb.buf;
    Py_ssize_t at = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        at += snprintf(text + at, 22, "%lld", (long long)stamps[i]);
        for (int k = 0; k < 7; k++) {
            text[at++] = ',';
            at += fixed9(poses[7 * i + k], text + at);
        }
        text[at++] = '\n';
    }
    result = PyBytes_FromStringAndSize(text, at);
done:
    PyMem_Free(text);
    if (pb.obj)
        PyBuffer_Release(&pb);
    PyBuffer_Release(&sb);
    return result;
}

static PyMethodDef methods[] = {
    {"lookup", tf_lookup, METH_VARARGS,
     "lookup(caches, target, source, time_ns) -> (time used, x, y, z, qx, qy, qz, qw) or None"},
    {"append_many", tf_append_many, METH_VARARGS,
     "append_many(caches, plan, raw, cache_ns) -> [rows not taken]: a TFMessage's transforms"},
    {"csv_rows", tf_csv_rows, METH_VARARGS,
     "csv_rows(stamps, poses) -> bytes: stamp,x,y,z,qx,qy,qz,qw lines, 9 decimals"},
    {"lookup_many", tf_lookup_many, METH_VARARGS,
     "lookup_many(caches, up, down, stamps, out, ok): the path's pose at each stamp"},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_tf",
                                    "tf2's lookup walk in C (dq_fk_ros.transforms)", -1,
                                    methods};

PyMODINIT_FUNC PyInit__tf(void)
{
    NAME_STATIC = PyUnicode_InternFromString("static");
    NAME_PARENT = PyUnicode_InternFromString("parent");
    NAME_VALUES = PyUnicode_InternFromString("values");
    NAME_STAMPS = PyUnicode_InternFromString("stamps");
    NAME_PARENTS = PyUnicode_InternFromString("parents");
    NAME_START = PyUnicode_InternFromString("start");
    NAME_COUNT = PyUnicode_InternFromString("count");
    if (!NAME_STATIC || !NAME_PARENT || !NAME_VALUES || !NAME_STAMPS || !NAME_PARENTS ||
        !NAME_START || !NAME_COUNT)
        return NULL;
    return PyModule_Create(&module);
}
