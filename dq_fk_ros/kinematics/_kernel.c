/*
 * dq_fk_ros.kinematics._kernel: the DH chain's every-frame poses in C.
 *
 * The compiled form of dq_fk_ros.kinematics.dh_code.run_program, the reference: the same
 * factors (the sparse z and x steps of [Zivkovic2023] eqs. (13)-(15)) applied in the same
 * order, on doubles, into buffers the caller owns (no allocation per call). A program is
 * an (n_ops, 7) float64 array of the ZStep/XStep fields (kind, p1..p5, mark); base and
 * tool are 8 coefficients (w, x, y, z, w', x', y', z'). test_kernel.py holds this equal to
 * the numpy path on random tables, joint values and batches: single calls to the bit (libm's
 * sin and cos, as Python's math), batches to an ulp or two (blocks of configurations with a
 * vectorisable sine and cosine, see run_block).
 *
 * Two types, both immutable: Chain (one chain's program, _kernel_chain.c) and Model (a tree
 * of chains and its links, _kernel_model.c); the records Python packs for them are laid out
 * in kernel_layout.h, whose field names this module exports as LAYOUTS; kernel_core.h holds
 * what both use. What no Python value may do to them (docs/security.md, test_compiled_fuzz.py,
 * make sanitize): every argument is converted to C values, and every sequence copied, before
 * anything is checked; every size product is checked for overflow before it sizes a buffer
 * or a loop; a type's state is set once, in __new__ (a second __init__ is refused); what the
 * batch loop reads without the GIL is the Chain's own copy and buffers it holds for the call.
 *
 * Only the CPython C API and the buffer protocol: no numpy headers.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "kernel_layout.h"
#include "kernel_types.h"

/* the names of a layout's fields, in order: a tuple of str */
static PyObject *layout_names(const char *const *names, int n)
{
    PyObject *t = PyTuple_New(n);
    for (int i = 0; t != NULL && i < n; i++) {
        PyObject *s = PyUnicode_FromString(names[i]);
        if (s == NULL) {
            Py_CLEAR(t);
            break;
        }
        PyTuple_SET_ITEM(t, i, s);
    }
    return t;
}

#define LAYOUT_NAME(name, text) text,
static const char *const OP_NAMES[] = {OP_LAYOUT(LAYOUT_NAME)};
static const char *const ROW_NAMES[] = {ROW_LAYOUT(LAYOUT_NAME)};
static const char *const LINK_NAMES[] = {LINK_LAYOUT(LAYOUT_NAME)};

static PyObject *layouts(void)
{
    PyObject *d = PyDict_New(), *t;
    if (d == NULL)
        return NULL;
    if ((t = layout_names(OP_NAMES, OP_FIELDS)) == NULL || PyDict_SetItemString(d, "op", t) < 0)
        goto fail;
    Py_DECREF(t);
    if ((t = layout_names(ROW_NAMES, ROW_FIELDS)) == NULL
        || PyDict_SetItemString(d, "row", t) < 0)
        goto fail;
    Py_DECREF(t);
    if ((t = layout_names(LINK_NAMES, LINK_FIELDS)) == NULL
        || PyDict_SetItemString(d, "link", t) < 0)
        goto fail;
    Py_DECREF(t);
    return d;
fail:
    Py_XDECREF(t);
    Py_DECREF(d);
    return NULL;
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_kernel",
    "The DH chain's poses in C (the reference: dq_fk_ros.kinematics.dh_code.run_program).",
    -1, NULL,
};

PyMODINIT_FUNC PyInit__kernel(void)
{
    if (PyType_Ready(&ChainType) < 0 || PyType_Ready(&ModelType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    PyObject *named = layouts();
    if (named == NULL || PyModule_AddType(m, &ChainType) < 0
        || PyModule_AddType(m, &ModelType) < 0
        || PyModule_AddObjectRef(m, "LAYOUTS", named) < 0) {
        Py_XDECREF(named);
        Py_DECREF(m);  /* (the types are named by their tp_name's last part) */
        return NULL;
    }
    Py_DECREF(named);
    return m;
}
