/*
 * The kernel's Chain: one DH chain's factor program, checked and copied once; every frame or
 * the end effector for one configuration or a batch (blocks of configurations, without the
 * GIL), and the geometric Jacobian. Reference: dh_code.run_program (test_kernel.py).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "kernel_core.h"
#include "kernel_types.h"

/*
 * Batches: blocks of BLOCK configurations, each step applied to the whole block (the
 * loops over the block vectorise), with a branch-free sine and cosine: fdlibm's kernels
 * (k_sin.c, k_cos.c) after a Cody-Waite reduction by pi/2, within an ulp or two of libm's
 * (test_kernel.py: batches equal the numpy reference to 1e-12). Arguments beyond
 * REDUCE_LIMIT, NaN or infinite take libm's sin and cos for the whole block.
 */
#define BLOCK 64
#define REDUCE_LIMIT 1.0e5

static inline void sincos_poly(double x, double *s_out, double *c_out)
{
    const double invpio2 = 6.36619772367581382433e-01;
    const double pio2_1 = 1.57079632673412561417e+00, pio2_2 = 6.07710050630396597660e-11,
                 pio2_3 = 2.02226624871116645580e-21;
    const double S1 = -1.66666666666666324348e-01, S2 = 8.33333333332248946124e-03,
                 S3 = -1.98412698298579493134e-04, S4 = 2.75573137070700676789e-06,
                 S5 = -2.50507602534068634195e-08, S6 = 1.58969099521155010221e-10;
    const double C1 = 4.16666666666666019037e-02, C2 = -1.38888888888741095749e-03,
                 C3 = 2.48015872894767294178e-05, C4 = -2.75573143513906633035e-07,
                 C5 = 2.08757232129817482790e-09, C6 = -1.13596475577881948265e-11;
    const double shifter = 6755399441055744.0;  /* 1.5 * 2^52: rounds to an integer */
    double fk = (x * invpio2 + shifter) - shifter;
    double r = ((x - fk * pio2_1) - fk * pio2_2) - fk * pio2_3;
    double z = r * r;
    double v = z * r;
    double ps = S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)));
    double sr = r + v * (S1 + z * ps);
    double pc = z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6)))));
    double hz = 0.5 * z, w = 1.0 - hz;
    double cr = w + (((1.0 - w) - hz) + z * pc);
    /* the quadrant: fk - 4 round(fk / 4), in -2..2 (-2 is 2, -1 is 3); compares and
       selects on doubles only, so the loop over a block has no branch */
    double n = fk - 4.0 * ((fk * 0.25 + shifter) - shifter);
    int odd = fabs(n) == 1.0;
    double sign_s = ((n > 1.5) | (n < -0.5)) ? -1.0 : 1.0;
    double sign_c = ((n > 0.5) | (n < -1.5)) ? -1.0 : 1.0;
    double a = odd ? cr : sr, b = odd ? sr : cr;
    *s_out = sign_s * a;
    *c_out = sign_c * b;
}

static void sincos_block(const double *restrict x, double *restrict s, double *restrict c,
                         Py_ssize_t m)
{
    double outside = 0.0;
    for (Py_ssize_t j = 0; j < m; j++)
        outside = (fabs(x[j]) <= REDUCE_LIMIT) ? outside : 1.0;  /* NaN too */
    if (outside != 0.0) {
        for (Py_ssize_t j = 0; j < m; j++) {
            s[j] = sin(x[j]);
            c[j] = cos(x[j]);
        }
        return;
    }
    for (Py_ssize_t j = 0; j < m; j++)
        sincos_poly(x[j], s + j, c + j);
}

static void store(double *restrict out, Py_ssize_t per, Py_ssize_t m,
                  const double *restrict h[8], int canon)
{
    for (Py_ssize_t j = 0; j < m; j++) {
        double sign = (canon && h[0][j] < 0.0) ? -1.0 : 1.0;
        double *o = out + j * per;
        for (int k = 0; k < 8; k++)
            o[k] = sign * h[k][j];
    }
}

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
__attribute__((target_clones("avx512f", "avx2", "default")))
#endif
static void run_block(const double *prog, Py_ssize_t n_ops, const double *base,
                      const double *tool, const double *q, Py_ssize_t dof, Py_ssize_t m,
                      double *out, Py_ssize_t per, int end_only, int canon)
{
    double aw[BLOCK], ax[BLOCK], ay[BLOCK], az[BLOCK];
    double bw[BLOCK], bx[BLOCK], by[BLOCK], bz[BLOCK];
    double half[BLOCK], s[BLOCK], c[BLOCK];
    const double *h[8] = {aw, ax, ay, az, bw, bx, by, bz};
    for (Py_ssize_t j = 0; j < m; j++) {
        aw[j] = base[0]; ax[j] = base[1]; ay[j] = base[2]; az[j] = base[3];
        bw[j] = base[4]; bx[j] = base[5]; by[j] = base[6]; bz[j] = base[7];
    }
    double *f = out;
    if (!end_only) {
        store(f, per, m, h, canon);
        f += 8;
    }
    for (Py_ssize_t i = 0; i < n_ops; i++) {
        const double *op = prog + i * OP_FIELDS;
        double p1 = op[OP_P1], p2 = op[OP_P2], p3 = op[OP_P3], p4 = op[OP_P4], p5 = op[OP_P5];
        if (op[OP_KIND] == 0.0) {
            if (p3 < 0) {
                double sc = sin(0.5 * p1), cc = cos(0.5 * p1);
                for (Py_ssize_t j = 0; j < m; j++) { s[j] = sc; c[j] = cc; }
            } else {
                Py_ssize_t t = (Py_ssize_t)p3;
                for (Py_ssize_t j = 0; j < m; j++)
                    half[j] = 0.5 * (p1 + p2 * q[j * dof + t]);
                sincos_block(half, s, c, m);
            }
            if (p5 >= 0 || p4 != 0.0) {  /* turn and slide along z in one pass */
                Py_ssize_t t = p5 < 0 ? 0 : (Py_ssize_t)p5;
                double moving = p5 < 0 ? 0.0 : p2;
                for (Py_ssize_t j = 0; j < m; j++) {
                    double cj = c[j], sj = s[j];
                    double nw = aw[j] * cj - az[j] * sj, nx = ax[j] * cj + ay[j] * sj,
                           ny = ay[j] * cj - ax[j] * sj, nz = az[j] * cj + aw[j] * sj;
                    double mw = bw[j] * cj - bz[j] * sj, mx = bx[j] * cj + by[j] * sj,
                           my = by[j] * cj - bx[j] * sj, mz = bz[j] * cj + bw[j] * sj;
                    double hd = p5 < 0 ? 0.5 * p4 : 0.5 * (p4 + moving * q[j * dof + t]);
                    aw[j] = nw; ax[j] = nx; ay[j] = ny; az[j] = nz;
                    bw[j] = mw - hd * nz; bx[j] = mx + hd * ny;
                    by[j] = my - hd * nx; bz[j] = mz + hd * nw;
                }
            } else {
                for (Py_ssize_t j = 0; j < m; j++) {
                    double cj = c[j], sj = s[j];
                    double nw = aw[j] * cj - az[j] * sj, nx = ax[j] * cj + ay[j] * sj,
                           ny = ay[j] * cj - ax[j] * sj, nz = az[j] * cj + aw[j] * sj;
                    double mw = bw[j] * cj - bz[j] * sj, mx = bx[j] * cj + by[j] * sj,
                           my = by[j] * cj - bx[j] * sj, mz = bz[j] * cj + bw[j] * sj;
                    aw[j] = nw; ax[j] = nx; ay[j] = ny; az[j] = nz;
                    bw[j] = mw; bx[j] = mx; by[j] = my; bz[j] = mz;
                }
            }
        } else if (p1 != 0.0 && p4 != 0.0) {  /* slide along x, then turn: one pass */
            for (Py_ssize_t j = 0; j < m; j++) {
                double w = bw[j] - p1 * ax[j], x = bx[j] + p1 * aw[j],
                       y = by[j] + p1 * az[j], z = bz[j] - p1 * ay[j];
                double nw = aw[j] * p2 - ax[j] * p3, nx = ax[j] * p2 + aw[j] * p3,
                       ny = ay[j] * p2 + az[j] * p3, nz = az[j] * p2 - ay[j] * p3;
                double mw = w * p2 - x * p3, mx = x * p2 + w * p3,
                       my = y * p2 + z * p3, mz = z * p2 - y * p3;
                aw[j] = nw; ax[j] = nx; ay[j] = ny; az[j] = nz;
                bw[j] = mw; bx[j] = mx; by[j] = my; bz[j] = mz;
            }
        } else {
            if (p1 != 0.0) {
                for (Py_ssize_t j = 0; j < m; j++) {
                    double w = bw[j] - p1 * ax[j], x = bx[j] + p1 * aw[j],
                           y = by[j] + p1 * az[j], z = bz[j] - p1 * ay[j];
                    bw[j] = w; bx[j] = x; by[j] = y; bz[j] = z;
                }
            }
            if (p4 != 0.0) {
                for (Py_ssize_t j = 0; j < m; j++) {
                    double nw = aw[j] * p2 - ax[j] * p3, nx = ax[j] * p2 + aw[j] * p3,
                           ny = ay[j] * p2 + az[j] * p3, nz = az[j] * p2 - ay[j] * p3;
                    double mw = bw[j] * p2 - bx[j] * p3, mx = bx[j] * p2 + bw[j] * p3,
                           my = by[j] * p2 + bz[j] * p3, mz = bz[j] * p2 - by[j] * p3;
                    aw[j] = nw; ax[j] = nx; ay[j] = ny; az[j] = nz;
                    bw[j] = mw; bx[j] = mx; by[j] = my; bz[j] = mz;
                }
            }
        }
        if (op[OP_MARK] != 0.0 && !end_only) {
            store(f, per, m, h, canon);
            f += 8;
        }
    }
    if (tool) {  /* h * tool across the block: multiply()'s terms, in its order */
        const double *b = tool;
        for (Py_ssize_t j = 0; j < m; j++) {
            double a0 = aw[j], a1 = ax[j], a2 = ay[j], a3 = az[j];
            double a4 = bw[j], a5 = bx[j], a6 = by[j], a7 = bz[j];
            aw[j] = a0 * b[0] - a1 * b[1] - a2 * b[2] - a3 * b[3];
            ax[j] = a0 * b[1] + a1 * b[0] + a2 * b[3] - a3 * b[2];
            ay[j] = a0 * b[2] - a1 * b[3] + a2 * b[0] + a3 * b[1];
            az[j] = a0 * b[3] + a1 * b[2] - a2 * b[1] + a3 * b[0];
            bw[j] = a0 * b[4] - a1 * b[5] - a2 * b[6] - a3 * b[7]
                  + a4 * b[0] - a5 * b[1] - a6 * b[2] - a7 * b[3];
            bx[j] = a0 * b[5] + a1 * b[4] + a2 * b[7] - a3 * b[6]
                  + a4 * b[1] + a5 * b[0] + a6 * b[3] - a7 * b[2];
            by[j] = a0 * b[6] - a1 * b[7] + a2 * b[4] + a3 * b[5]
                  + a4 * b[2] - a5 * b[3] + a6 * b[0] + a7 * b[1];
            bz[j] = a0 * b[7] + a1 * b[6] - a2 * b[5] + a3 * b[4]
                  + a4 * b[3] + a5 * b[2] - a6 * b[1] + a7 * b[0];
        }
    }
    if (tool || end_only)
        store(f, per, m, h, canon);
}

/* 2 d r*, the vector part of a pose's translation ([Zivkovic2023] eq. (17)) */
static void translation(const double *h, double *t)
{
    double w = h[0], x = -h[1], y = -h[2], z = -h[3];
    double dw = h[4], dx = h[5], dy = h[6], dz = h[7];
    t[0] = 2.0 * (dw * x + dx * w + dy * z - dz * y);
    t[1] = 2.0 * (dw * y - dx * z + dy * w + dz * x);
    t[2] = 2.0 * (dw * z + dx * y - dy * x + dz * w);
}


static void chain_dealloc(ChainObject *self)
{
    PyMem_Free(self->prog);
    PyMem_Free(self->rows);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* the Chain's state from its arguments, all of them C values already */
static int chain_build(ChainObject *self, Py_buffer *program, Py_buffer *base,
                       Py_buffer *tool, Py_ssize_t dof, Py_buffer *rows)
{
    if (count(program) % OP_FIELDS || count(base) != 8 || (tool->obj && count(tool) != 8)) {
        PyErr_SetString(PyExc_ValueError, "program must be (n, 7), base and tool 8 values");
        return -1;
    }
    if (dof < 0 || dof > MAX_DOF) {
        PyErr_Format(PyExc_ValueError, "dof must be 0 to %d", MAX_DOF);
        return -1;
    }
    Py_ssize_t n_ops = count(program) / OP_FIELDS;
    /* copied first: what is checked is what runs */
    self->prog = PyMem_Malloc((n_ops ? n_ops : 1) * OP_FIELDS * sizeof(double));
    if (self->prog == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    memcpy(self->prog, program->buf, n_ops * OP_FIELDS * sizeof(double));
    if (check_program(self->prog, n_ops, dof) < 0)
        return -1;
    self->n_ops = n_ops;
    self->dof = dof;
    Py_ssize_t n_marks = marks(self->prog, n_ops);
    self->per = 8 * (1 + n_marks + (tool->obj != NULL));
    memcpy(self->base, base->buf, sizeof self->base);
    self->have_tool = tool->obj != NULL;
    if (self->have_tool)
        memcpy(self->tool, tool->buf, sizeof self->tool);
    self->n_rows = -1;
    if (rows->obj == NULL)
        return 0;
    Py_ssize_t n = count(rows) / 3;
    if (count(rows) % 3 || n != n_marks) {
        PyErr_SetString(PyExc_ValueError, "rows must be (n, 3), one per row of the program");
        return -1;
    }
    self->rows = PyMem_Malloc((n ? n : 1) * 3 * sizeof(double));
    if (self->rows == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    memcpy(self->rows, rows->buf, n * 3 * sizeof(double));
    for (Py_ssize_t i = 0; i < n; i++)
        for (int k = 0; k < 2; k++) {
            double index = self->rows[3 * i + k];
            if (index >= (double)dof || index != floor(index)) {
                PyErr_SetString(PyExc_ValueError, "rows index a joint value q lacks");
                return -1;
            }
        }
    self->n_rows = n;
    return 0;
}

static PyObject *chain_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    PyObject *program, *base, *tool, *rows = Py_None;
    Py_ssize_t dof;
    int modified = 0;
    static char *names[] = {"program", "base", "tool", "dof", "rows", "modified", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOn|Op", names, &program, &base, &tool,
                                     &dof, &rows, &modified))
        return NULL;  /* (every Python callback an argument has runs above) */
    ChainObject *self = (ChainObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    Py_buffer pv = {0}, bv = {0}, tv = {0}, rv = {0};
    int ok = take(program, &pv, 0, "program") == 0 && take(base, &bv, 0, "base") == 0
        && (tool == Py_None || take(tool, &tv, 0, "tool") == 0)
        && (rows == Py_None || take(rows, &rv, 0, "rows") == 0)
        && chain_build(self, &pv, &bv, &tv, dof, &rv) == 0;
    self->modified = modified;
    let_go(&pv);
    let_go(&bv);
    let_go(&tv);
    let_go(&rv);
    if (!ok) {
        Py_DECREF(self);
        return NULL;
    }
    return (PyObject *)self;
}

static int chain_init(ChainObject *self, PyObject *args, PyObject *kwargs)
{
    return set_once((PyObject *)self, &self->initialised);
}

/* q, a C-contiguous float64 vector of dof values, and out, writable, of `need` values */
static int chain_buffers(PyObject *const *args, Py_ssize_t nargs, const char *usage,
                         Py_buffer *q, Py_buffer *out)
{
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, usage);
        return -1;
    }
    if (take(args[0], q, 0, "q") < 0)
        return -1;
    if (take(args[1], out, 1, "out") < 0) {
        PyBuffer_Release(q);
        return -1;
    }
    return 0;
}

static PyObject *chain_call(ChainObject *self, PyObject *const *args, Py_ssize_t nargs,
                            int end_only)
{
    Py_buffer q, out;
    if (chain_buffers(args, nargs, end_only ? "end(q, out)" : "frames(q, out)", &q, &out) < 0)
        return NULL;
    Py_ssize_t per = end_only ? 8 : self->per;
    if (q.ndim != 1 || count(&q) != self->dof || count(&out) != per) {
        PyErr_Format(PyExc_ValueError, "q must be %zd joint values and out %zd values",
                     self->dof, per);
        PyBuffer_Release(&q);
        PyBuffer_Release(&out);
        return NULL;
    }
    run(self->prog, self->n_ops, self->base, self->have_tool ? self->tool : NULL, q.buf,
        out.buf, end_only, 1, NULL);
    PyBuffer_Release(&q);
    PyBuffer_Release(&out);
    Py_RETURN_NONE;
}

static PyObject *chain_batch(ChainObject *self, PyObject *const *args, Py_ssize_t nargs,
                             int end_only)
{
    Py_buffer q, out;
    if (chain_buffers(args, nargs, end_only ? "end_batch(q, out)" : "frames_batch(q, out)",
                      &q, &out) < 0)
        return NULL;
    Py_ssize_t per = end_only ? 8 : self->per, need;
    if (q.ndim != 2 || q.shape[1] != self->dof) {
        PyErr_Format(PyExc_ValueError, "q must be (N, %zd)", self->dof);
        goto fail;
    }
    Py_ssize_t n = q.shape[0];
    if (mul_size(n, per, &need) < 0 || count(&out) != need) {
        PyErr_Format(PyExc_ValueError, "out must hold (N, %zd) values for %zd "
                     "configurations, not %zd", per, n, count(&out));
        goto fail;
    }
    const double *qb = q.buf, *tool = self->have_tool ? self->tool : NULL;
    double *ob = out.buf;
    Py_ssize_t dof = self->dof;
    /* without the GIL: the program is this Chain's (immutable), q and out held to the end */
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i += BLOCK) {
        Py_ssize_t m = n - i < BLOCK ? n - i : BLOCK;
        run_block(self->prog, self->n_ops, self->base, tool, qb + i * dof, dof, m,
                  ob + i * per, per, end_only, 1);
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&q);
    PyBuffer_Release(&out);
    Py_RETURN_NONE;
fail:
    PyBuffer_Release(&q);
    PyBuffer_Release(&out);
    return NULL;
}

#define MAX_STACK_FRAMES 128

static PyObject *chain_jacobian(ChainObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer q, out;
    double stack[8 * MAX_STACK_FRAMES], *frames = stack;
    Py_ssize_t dof = self->dof, n_frames = self->per / 8;
    if (self->n_rows < 0) {
        PyErr_SetString(PyExc_ValueError, "this Chain was made without rows: no jacobian");
        return NULL;
    }
    if (chain_buffers(args, nargs, "jacobian(q, out (6, dof))", &q, &out) < 0)
        return NULL;
    PyObject *result = NULL;
    if (q.ndim != 1 || count(&q) != dof || count(&out) != 6 * dof) {
        PyErr_Format(PyExc_ValueError, "q must be %zd joint values and out (6, %zd)", dof, dof);
        goto done;
    }
    if (n_frames > MAX_STACK_FRAMES) {
        frames = PyMem_Malloc(8 * n_frames * sizeof(double));
        if (frames == NULL) {
            PyErr_NoMemory();
            goto done;
        }
    }
    /* every frame first (q is read there only), then out is written */
    run(self->prog, self->n_ops, self->base, self->have_tool ? self->tool : NULL, q.buf,
        frames, 0, 0, NULL);
    double *jac = out.buf, p_end[3];
    const double *r = self->rows;
    memset(jac, 0, 6 * dof * sizeof(double));
    translation(frames + 8 * (n_frames - 1), p_end);
    for (Py_ssize_t i = 0; i < self->n_rows; i++) {
        const double *h = frames + 8 * (self->modified ? i + 1 : i);
        double w = h[0], x = h[1], y = h[2], zq = h[3];
        double z[3] = {2.0 * (x * zq + w * y), 2.0 * (y * zq - w * x),
                       1.0 - 2.0 * (x * x + y * y)};
        double scale = r[3 * i + 2], p[3];
        if (r[3 * i] >= 0) {
            Py_ssize_t ti = (Py_ssize_t)r[3 * i];
            translation(h, p);
            double e0 = p_end[0] - p[0], e1 = p_end[1] - p[1], e2 = p_end[2] - p[2];
            jac[0 * dof + ti] += scale * (z[1] * e2 - z[2] * e1);
            jac[1 * dof + ti] += scale * (z[2] * e0 - z[0] * e2);
            jac[2 * dof + ti] += scale * (z[0] * e1 - z[1] * e0);
            for (int k = 0; k < 3; k++)
                jac[(3 + k) * dof + ti] += scale * z[k];
        }
        if (r[3 * i + 1] >= 0) {
            Py_ssize_t di = (Py_ssize_t)r[3 * i + 1];
            for (int k = 0; k < 3; k++)
                jac[k * dof + di] += scale * z[k];
        }
    }
    result = Py_None;
    Py_INCREF(result);
done:
    if (frames != stack)
        PyMem_Free(frames);
    PyBuffer_Release(&q);
    PyBuffer_Release(&out);
    return result;
}

static PyObject *chain_frames(ChainObject *s, PyObject *const *a, Py_ssize_t n)
{ return chain_call(s, a, n, 0); }
static PyObject *chain_end(ChainObject *s, PyObject *const *a, Py_ssize_t n)
{ return chain_call(s, a, n, 1); }
static PyObject *chain_frames_batch(ChainObject *s, PyObject *const *a, Py_ssize_t n)
{ return chain_batch(s, a, n, 0); }
static PyObject *chain_end_batch(ChainObject *s, PyObject *const *a, Py_ssize_t n)
{ return chain_batch(s, a, n, 1); }

static PyMethodDef chain_methods[] = {
    {"frames", (PyCFunction)(void (*)(void))chain_frames, METH_FASTCALL,
     "frames(q, out): every frame (w >= 0) into out, (n_frames, 8)"},
    {"end", (PyCFunction)(void (*)(void))chain_end, METH_FASTCALL,
     "end(q, out): the last frame (tool if any, w >= 0) into out, (8,)"},
    {"frames_batch", (PyCFunction)(void (*)(void))chain_frames_batch, METH_FASTCALL,
     "frames_batch(q (N, dof), out (N, n_frames, 8)): frames() for N configurations"},
    {"end_batch", (PyCFunction)(void (*)(void))chain_end_batch, METH_FASTCALL,
     "end_batch(q (N, dof), out (N, 8)): end() for N configurations"},
    {"jacobian", (PyCFunction)(void (*)(void))chain_jacobian, METH_FASTCALL,
     "jacobian(q, out (6, dof)): the geometric Jacobian of the end effector"},
    {NULL, NULL, 0, NULL},
};

static PyObject *chain_n_frames(ChainObject *self, void *closure)
{ return PyLong_FromSsize_t(self->per / 8); }
static PyObject *chain_dof(ChainObject *self, void *closure)
{ return PyLong_FromSsize_t(self->dof); }

static PyGetSetDef chain_getset[] = {
    {"n_frames", (getter)chain_n_frames, NULL, "frames computed", NULL},
    {"dof", (getter)chain_dof, NULL, "joint values taken", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

PyTypeObject ChainType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "dq_fk_ros.kinematics._kernel.Chain",
    .tp_doc = "Chain(program, base, tool, dof, rows=None, modified=False): a chain's "
              "program, checked and copied once (immutable)",
    .tp_basicsize = sizeof(ChainObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = chain_new,
    .tp_init = (initproc)chain_init,
    .tp_dealloc = (destructor)chain_dealloc,
    .tp_methods = chain_methods,
    .tp_getset = chain_getset,
};
