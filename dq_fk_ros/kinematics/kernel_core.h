/*
 * What both of the kernel's types use: sizes checked for overflow, float64 buffers taken
 * from Python, state set once, the dual-quaternion product and a chain's program run for one
 * configuration (dh_code.run_program, the reference). Each translation unit gets its own copy
 * (KERNEL_SHARED).
 */
#ifndef DQ_FK_KERNEL_CORE_H
#define DQ_FK_KERNEL_CORE_H

#include <Python.h>
#include <math.h>
#include <string.h>

#include "kernel_layout.h"

/* static, as in one file: each translation unit gets its copy and the compiler decides what
 * to inline, as it did when the kernel was one file (an inline hint on run() made the Model
 * 9 % slower: it was inlined into model_run); unused: not every file calls every one */
#define KERNEL_SHARED static __attribute__((unused))

/* a * b into *r, unless negative or past PY_SSIZE_T_MAX: 0, else -1 */
KERNEL_SHARED int mul_size(Py_ssize_t a, Py_ssize_t b, Py_ssize_t *r)
{
    if (a < 0 || b < 0 || (b != 0 && a > PY_SSIZE_T_MAX / b))
        return -1;
    *r = a * b;
    return 0;
}

/* a + b into *r, likewise */
KERNEL_SHARED int add_size(Py_ssize_t a, Py_ssize_t b, Py_ssize_t *r)
{
    if (a < 0 || b < 0 || a > PY_SSIZE_T_MAX - b)
        return -1;
    *r = a + b;
    return 0;
}

/* A C-contiguous float64 buffer (writable if asked); else a Python error, view->obj NULL. */
KERNEL_SHARED int take(PyObject *obj, Py_buffer *view, int writable, const char *what)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "%s must be a C-contiguous%s float64 array", what,
                     writable ? " writable" : "");
        view->obj = NULL;
        return -1;
    }
    if (view->itemsize != 8 || view->format == NULL || strcmp(view->format, "d") != 0) {
        PyBuffer_Release(view);
        view->obj = NULL;
        PyErr_Format(PyExc_ValueError, "%s must be a float64 array", what);
        return -1;
    }
    return 0;
}

KERNEL_SHARED void let_go(Py_buffer *view)
{
    if (view->obj)
        PyBuffer_Release(view);
}

KERNEL_SHARED Py_ssize_t count(Py_buffer *v) { return v->len / 8; }

/* refuse a second __init__: the state of these types is set once, in __new__ */
KERNEL_SHARED int set_once(PyObject *self, int *initialised)
{
    if (*initialised) {
        PyErr_Format(PyExc_TypeError, "a %s is set once, when it is made; make a new one",
                     Py_TYPE(self)->tp_name);
        return -1;
    }
    *initialised = 1;  /* the __init__ that follows __new__ in the type's call */
    return 0;
}

/* Check the program against the number of joint values: every index in range. */
KERNEL_SHARED int check_program(const double *p, Py_ssize_t n_ops, Py_ssize_t dof)
{
    for (Py_ssize_t i = 0; i < n_ops; i++) {
        const double *op = p + i * OP_FIELDS;
        if (op[OP_KIND] == 0.0) {
            double ti = op[OP_P3], di = op[OP_P5];
            if (ti >= (double)dof || di >= (double)dof || ti != floor(ti) || di != floor(di)) {
                PyErr_SetString(PyExc_ValueError, "program indexes a joint value q lacks");
                return -1;
            }
        } else if (op[OP_KIND] != 1.0) {
            PyErr_SetString(PyExc_ValueError, "program step kind must be 0 (z) or 1 (x)");
            return -1;
        }
    }
    return 0;
}

KERNEL_SHARED Py_ssize_t marks(const double *p, Py_ssize_t n_ops)
{
    Py_ssize_t m = 0;
    for (Py_ssize_t i = 0; i < n_ops; i++)
        m += p[i * OP_FIELDS + OP_MARK] != 0.0;
    return m;
}

/* a * b, [Zivkovic2023] eq. (12), in dq_multiply_coeffs' order of terms */
KERNEL_SHARED void multiply(const double *a, const double *b, double *o)
{
    double r0 = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3];
    double r1 = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2];
    double r2 = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1];
    double r3 = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0];
    double d0 = a[0] * b[4] - a[1] * b[5] - a[2] * b[6] - a[3] * b[7]
              + a[4] * b[0] - a[5] * b[1] - a[6] * b[2] - a[7] * b[3];
    double d1 = a[0] * b[5] + a[1] * b[4] + a[2] * b[7] - a[3] * b[6]
              + a[4] * b[1] + a[5] * b[0] + a[6] * b[3] - a[7] * b[2];
    double d2 = a[0] * b[6] - a[1] * b[7] + a[2] * b[4] + a[3] * b[5]
              + a[4] * b[2] - a[5] * b[3] + a[6] * b[0] + a[7] * b[1];
    double d3 = a[0] * b[7] + a[1] * b[6] - a[2] * b[5] + a[3] * b[4]
              + a[4] * b[3] + a[5] * b[2] - a[6] * b[1] + a[7] * b[0];
    o[0] = r0; o[1] = r1; o[2] = r2; o[3] = r3; o[4] = d0; o[5] = d1; o[6] = d2; o[7] = d3;
}

KERNEL_SHARED void canonical(double *h)
{
    if (h[0] < 0.0)
        for (int k = 0; k < 8; k++) h[k] = -h[k];
}

/*
 * Run the program from base at q; write frame 0, every marked frame, then base*tool, into
 * out (8 doubles each); only the last one if end_only. As run_program, step by step.
 * trig (or NULL): each z step's (half angle, cos, sin), 3 doubles a z step, in order (a
 * Model's TF transforms take them instead of computing them again).
 */
KERNEL_SHARED void run(const double *prog, Py_ssize_t n_ops, const double *base, const double *tool,
                const double *q, double *out, int end_only, int canon, double *trig)
{
    double aw = base[0], ax = base[1], ay = base[2], az = base[3];
    double bw = base[4], bx = base[5], by = base[6], bz = base[7];
    double *f = out;
    if (!end_only) {
        memcpy(f, base, 8 * sizeof(double));
        if (canon) canonical(f);
        f += 8;
    }
    for (Py_ssize_t i = 0; i < n_ops; i++) {
        const double *op = prog + i * OP_FIELDS;
        double p1 = op[OP_P1], p2 = op[OP_P2], p3 = op[OP_P3], p4 = op[OP_P4], p5 = op[OP_P5];
        if (op[OP_KIND] == 0.0) {  /* h (c + s k) (1 + eps hd k) */
            double half = p3 < 0 ? 0.5 * p1 : 0.5 * (p1 + p2 * q[(Py_ssize_t)p3]);
            double c = cos(half), s = sin(half);
            if (trig) {
                trig[0] = half; trig[1] = c; trig[2] = s;
                trig += 3;
            }
            double nw = aw * c - az * s, nx = ax * c + ay * s, ny = ay * c - ax * s,
                   nz = az * c + aw * s;
            double mw = bw * c - bz * s, mx = bx * c + by * s, my = by * c - bx * s,
                   mz = bz * c + bw * s;
            aw = nw; ax = nx; ay = ny; az = nz; bw = mw; bx = mx; by = my; bz = mz;
            if (p5 >= 0 || p4 != 0.0) {
                double hd = p5 < 0 ? 0.5 * p4 : 0.5 * (p4 + p2 * q[(Py_ssize_t)p5]);
                double w = bw - hd * az, x = bx + hd * ay, y = by - hd * ax, z = bz + hd * aw;
                bw = w; bx = x; by = y; bz = z;
            }
        } else {  /* h (1 + eps ha i) (c + s i), constant */
            if (p1 != 0.0) {
                double w = bw - p1 * ax, x = bx + p1 * aw, y = by + p1 * az, z = bz - p1 * ay;
                bw = w; bx = x; by = y; bz = z;
            }
            if (p4 != 0.0) {
                double nw = aw * p2 - ax * p3, nx = ax * p2 + aw * p3, ny = ay * p2 + az * p3,
                       nz = az * p2 - ay * p3;
                double mw = bw * p2 - bx * p3, mx = bx * p2 + bw * p3, my = by * p2 + bz * p3,
                       mz = bz * p2 - by * p3;
                aw = nw; ax = nx; ay = ny; az = nz; bw = mw; bx = mx; by = my; bz = mz;
            }
        }
        if (op[OP_MARK] != 0.0 && !end_only) {
            f[0] = aw; f[1] = ax; f[2] = ay; f[3] = az;
            f[4] = bw; f[5] = bx; f[6] = by; f[7] = bz;
            if (canon) canonical(f);
            f += 8;
        }
    }
    double last[8] = {aw, ax, ay, az, bw, bx, by, bz};
    if (tool) {
        multiply(last, tool, f);
    } else if (end_only) {
        memcpy(f, last, sizeof last);
    } else {
        return;
    }
    if (canon) canonical(f);
}

#endif
