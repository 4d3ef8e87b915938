/*
 * Python ints converted to C and checked, for the package's C extensions (messages/_cdr.c,
 * storage/_mcap.c): one int in a range, and a sequence of them copied first into a tuple of
 * our own (an item's __index__ cannot change the others while they are read); an int64
 * array's buffer.
 */
#ifndef DQ_FK_C_ARGUMENTS_H
#define DQ_FK_C_ARGUMENTS_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <string.h>

/* One int of a sequence, in [low, high]; what names it in the error. */
static int int_within(PyObject *item, Py_ssize_t low, Py_ssize_t high, Py_ssize_t *at,
                      const char *what)
{
    *at = PyLong_AsSsize_t(item);
    int not_int = *at == -1 && PyErr_Occurred();  /* not an int, or too large */
    if (not_int)
        PyErr_Clear();
    if (not_int || *at < low || *at > high) {
        if (not_int)
            PyErr_Format(PyExc_ValueError, "%s must be an int in %zd..%zd", what, low, high);
        else
            PyErr_Format(PyExc_ValueError, "%s %zd is outside %zd..%zd", what, *at, low,
                         high);
        return -1;
    }
    return 0;
}

/*
 * A sequence of ints, each in [low, high], as a new C array (*n of them, at most max_n).
 * The sequence is copied into a tuple first: an item's __index__ cannot change the others.
 */
static Py_ssize_t *ints_within(PyObject *obj, Py_ssize_t low, Py_ssize_t high, Py_ssize_t *n,
                               Py_ssize_t max_n, const char *what)
{
    PyObject *seq = PySequence_Tuple(obj);
    if (seq == NULL) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s: a sequence of ints", what);
        return NULL;
    }
    *n = PyTuple_GET_SIZE(seq);
    if (*n > max_n) {
        PyErr_Format(PyExc_ValueError, "%s: at most %zd of them", what, max_n);
        Py_DECREF(seq);
        return NULL;
    }
    Py_ssize_t *out = PyMem_Malloc((*n ? *n : 1) * sizeof(Py_ssize_t));
    if (out == NULL) {
        Py_DECREF(seq);
        PyErr_NoMemory();
        return NULL;
    }
    for (Py_ssize_t i = 0; i < *n; i++)
        if (int_within(PyTuple_GET_ITEM(seq, i), low, high, out + i, what) < 0) {
            PyMem_Free(out);
            Py_DECREF(seq);
            return NULL;
        }
    Py_DECREF(seq);
    return out;
}

/* A buffer of int64 items (numpy 'q' or 'l' on LP64), writable or not. */
static int int64_buffer(PyObject *obj, Py_buffer *b, int writable, const char *what)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, b, flags) < 0) {
        b->obj = NULL;
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "%s: a C-contiguous%s int64 array", what,
                     writable ? " writable" : "");
        return -1;
    }
    if (b->itemsize != 8 || b->format == NULL
        || (strcmp(b->format, "q") != 0 && strcmp(b->format, "l") != 0
            && strcmp(b->format, "<q") != 0 && strcmp(b->format, "=q") != 0)) {
        PyBuffer_Release(b);
        b->obj = NULL;
        PyErr_Format(PyExc_ValueError, "%s: a C-contiguous%s int64 array", what,
                     writable ? " writable" : "");
        return -1;
    }
    return 0;
}

#endif /* DQ_FK_C_ARGUMENTS_H */
