/*
 * The kernel's two types, as its translation units share them: a Chain's state (read by a
 * Model, which holds its chains) and the type objects the module adds.
 */
#ifndef DQ_FK_KERNEL_TYPES_H
#define DQ_FK_KERNEL_TYPES_H

#include <Python.h>

/*
 * Chain(program, base, tool, dof, rows=None, modified=False): a chain checked and copied
 * into C memory once. frames(q, out) and end(q, out): one configuration; frames_batch(q,
 * out) and end_batch(q, out): N of them (q (N, dof)), without the GIL; jacobian(q, out):
 * the geometric Jacobian (6, dof) of the end effector in the fixed frame, as
 * chain_jacobians.jacobian_geometric_reference: every frame from run(), then per row its
 * joint axis (z of frame i-1, standard; of frame i, modified) and, for a revolute variable,
 * z x (p_end - p). rows is (n, 3), one per DH row: the theta variable's index, the d
 * variable's index (-1: none) and the scale; None: no jacobian().
 */
typedef struct {
    PyObject_HEAD
    double *prog, *rows;
    Py_ssize_t n_ops, dof, per, n_rows;
    double base[8], tool[8];
    int have_tool, modified, initialised;
} ChainObject;

#define KERNEL_HIDDEN __attribute__((visibility("hidden")))
extern KERNEL_HIDDEN PyTypeObject ChainType;
extern KERNEL_HIDDEN PyTypeObject ModelType;

#endif
