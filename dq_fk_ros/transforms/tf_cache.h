/*
 * BufferCore's caches read from C for dq_fk_ros/transforms/_tf.c: each item of the caches
 * list held (a strong reference, its arrays' buffers) while it is read, every attribute
 * checked (TypeError, ValueError otherwise); an edge's sample at a time as MovingEdge.get and
 * StaticEdge.get give it. Include after tf_math.h.
 */
#ifndef DQ_FK_TF_CACHE_H
#define DQ_FK_TF_CACHE_H

/* the cache attributes' names, interned once (a lookup by C string makes a str each time) */
static PyObject *NAME_STATIC, *NAME_PARENT, *NAME_VALUES, *NAME_STAMPS, *NAME_PARENTS,
    *NAME_START, *NAME_COUNT;

typedef struct {
    int kind;                 /* 0 root (no cache), 1 static, 2 dynamic */
    PyObject *item;           /* held */
    Py_ssize_t parent;        /* static */
    double v[7];
    Py_buffer sb, pb, vb;     /* dynamic: stamps, parents, values */
    const int64_t *s;
    const int64_t *p;
    const double *val;
    Py_ssize_t start, n;      /* live samples [start, n): n is the cache's count */
    Py_ssize_t room;          /* samples the arrays hold */
    /* the slerp of the last interval read (lookup_many: stamps in one interval share it) */
    Py_ssize_t last_k;
    double theta, d;
    int zero;
} Cache;

static void release(Cache *c)
{
    if (c->kind == 2) {
        PyBuffer_Release(&c->sb);
        PyBuffer_Release(&c->pb);
        PyBuffer_Release(&c->vb);
    }
    Py_XDECREF(c->item);
    c->item = NULL;
    c->kind = 0;
}

static int buffer_of(PyObject *owner, PyObject *name, Py_buffer *b, char kind, int writable)
{
    PyObject *obj = PyObject_GetAttr(owner, name);
    if (obj == NULL)
        return -1;
    int r = PyObject_GetBuffer(obj, b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT |
                                           (writable ? PyBUF_WRITABLE : 0));
    Py_DECREF(obj);
    if (r < 0)
        return -1;
    const char *f = b->format ? b->format : "";
    int ok = b->itemsize == 8 && b->ndim == 1 &&
             (kind == 'q' ? (strcmp(f, "q") == 0 || strcmp(f, "l") == 0)
                          : strcmp(f, "d") == 0);
    if (!ok) {
        PyBuffer_Release(b);
        PyErr_Format(PyExc_TypeError, "cache %U: an array of %s", name,
                     kind == 'q' ? "int64" : "float64");
        return -1;
    }
    return 0;
}

static int int_attr(PyObject *item, PyObject *name, Py_ssize_t low, Py_ssize_t high,
                    Py_ssize_t *out)
{
    PyObject *value = PyObject_GetAttr(item, name);
    if (value == NULL)
        return -1;
    *out = PyLong_CheckExact(value) ? PyLong_AsSsize_t(value) : -1;
    Py_DECREF(value);
    if (*out < low || *out > high) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "cache.%U: an int within the arrays", name);
        return -1;
    }
    return 0;
}

/* Read item `frame` of the list: 0 done (c->kind set), -1 an exception. */
static int load_for(PyObject *caches, Py_ssize_t frame, Cache *c, int writable)
{
    memset(c, 0, sizeof(*c));
    c->last_k = -1;
    if (frame < 0 || frame >= PyList_GET_SIZE(caches)) {
        PyErr_SetString(PyExc_ValueError, "a frame id outside the caches");
        return -1;
    }
    PyObject *item = PyList_GET_ITEM(caches, frame);
    if (item == Py_None)
        return 0;
    Py_INCREF(item);            /* before any Python code runs: the list may change */
    c->item = item;
    PyObject *flag = PyObject_GetAttr(item, NAME_STATIC);
    if (flag == NULL)
        goto fail;
    int is_static = flag == Py_True ? 1 : flag == Py_False ? 0 : -1;
    Py_DECREF(flag);
    if (is_static < 0) {
        PyErr_SetString(PyExc_TypeError, "cache.static: True or False");
        goto fail;
    }
    if (is_static) {
        PyObject *parent = PyObject_GetAttr(item, NAME_PARENT);
        if (parent == NULL)
            goto fail;
        c->parent = PyLong_CheckExact(parent) ? PyLong_AsSsize_t(parent) : -1;
        Py_DECREF(parent);
        if (c->parent < 0) {
            PyErr_Clear();
            PyErr_SetString(PyExc_ValueError, "cache.parent: an int >= 0");
            goto fail;
        }
        PyObject *values = PyObject_GetAttr(item, NAME_VALUES);
        if (values == NULL)
            goto fail;
        int good = PyTuple_CheckExact(values) && PyTuple_GET_SIZE(values) == 7;
        for (int k = 0; good && k < 7; k++) {
            PyObject *x = PyTuple_GET_ITEM(values, k);
            good = PyFloat_CheckExact(x);
            if (good)
                c->v[k] = PyFloat_AS_DOUBLE(x);
        }
        Py_DECREF(values);
        if (!good) {
            PyErr_SetString(PyExc_TypeError, "cache.values: a tuple of 7 floats");
            goto fail;
        }
        c->kind = 1;
        return 0;
    }
    if (buffer_of(item, NAME_STAMPS, &c->sb, 'q', writable) < 0)
        goto fail;
    if (buffer_of(item, NAME_PARENTS, &c->pb, 'q', writable) < 0) {
        PyBuffer_Release(&c->sb);
        goto fail;
    }
    if (buffer_of(item, NAME_VALUES, &c->vb, 'd', writable) < 0) {
        PyBuffer_Release(&c->sb);
        PyBuffer_Release(&c->pb);
        goto fail;
    }
    c->kind = 2;   /* from here release() frees the buffers */
    c->room = c->sb.len / 8;
    if (c->pb.len / 8 < c->room)
        c->room = c->pb.len / 8;
    if (c->vb.len / 56 < c->room)
        c->room = c->vb.len / 56;
    if (int_attr(item, NAME_COUNT, 0, c->room, &c->n) < 0 ||
        int_attr(item, NAME_START, 0, c->n, &c->start) < 0)
        goto fail;
    c->s = c->sb.buf;
    c->p = c->pb.buf;
    c->val = c->vb.buf;
    return 0;
fail:
    release(c);
    return -1;
}

static int load(PyObject *caches, Py_ssize_t frame, Cache *c)
{
    return load_for(caches, frame, c, 0);
}

/* (newest stamp, its parent) as BufferCore's latest(); (0, 0) when empty. */
static void latest(const Cache *c, int64_t *stamp, Py_ssize_t *parent)
{
    if (c->kind == 1) {
        *stamp = 0;
        *parent = c->parent;
    } else if (c->n > c->start) {
        *stamp = c->s[c->n - 1];
        *parent = (Py_ssize_t)c->p[c->n - 1];
    } else {
        *stamp = 0;
        *parent = 0;
    }
}

/* The edge at t, as MovingEdge.get / StaticEdge.get: 1 (parent, v) or 0 no sample answers. */
static int get(Cache *c, int64_t t, Py_ssize_t *parent, double *v)
{
    if (c->kind == 1) {
        *parent = c->parent;
        memcpy(v, c->v, sizeof c->v);
        return 1;
    }
    Py_ssize_t n = c->n, start = c->start, last = n - 1, k, k2 = -1;
    if (n - start <= 0)
        return 0;
    const int64_t *s = c->s;
    if (t == 0)
        k = last;
    else if (n - start == 1) {
        if (s[last] != t)
            return 0;
        k = last;
    } else if (t == s[last])
        k = last;
    else if (t == s[start])
        k = start;
    else if (t > s[last] || t < s[start])
        return 0;
    else {
        k = after(s, start, n, t) - 1;
        k2 = k + 1;
    }
    const double *a = c->val + 7 * k;
    if (k2 < 0 || c->p[k] != c->p[k2]) {
        *parent = (Py_ssize_t)c->p[k];
        memcpy(v, a, 7 * sizeof(double));
        return 1;
    }
    const double *b = c->val + 7 * k2;
    double ratio = (double)(t - s[k]) / (double)(s[k2] - s[k]);
    double r = 1.0 - ratio;
    v[0] = r * a[0] + ratio * b[0];
    v[1] = r * a[1] + ratio * b[1];
    v[2] = r * a[2] + ratio * b[2];
    if (c->last_k != k) {
        c->zero = slerp_angle(a + 3, b + 3, &c->theta, &c->d);
        c->last_k = k;
    }
    slerp_with(a + 3, b + 3, ratio, c->theta, c->d, c->zero, v + 3);
    *parent = (Py_ssize_t)c->p[k];
    return 1;
}

#endif /* DQ_FK_TF_CACHE_H */
