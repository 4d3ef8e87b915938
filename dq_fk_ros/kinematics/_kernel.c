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
 * Only the CPython C API and the buffer protocol: no numpy headers.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#define OP_FIELDS 7

typedef struct {
    Py_buffer program, base, tool, q, out;
    int have_tool;
} Args;

static void release(Args *a)
{
    if (a->program.obj) PyBuffer_Release(&a->program);
    if (a->base.obj) PyBuffer_Release(&a->base);
    if (a->tool.obj) PyBuffer_Release(&a->tool);
    if (a->q.obj) PyBuffer_Release(&a->q);
    if (a->out.obj) PyBuffer_Release(&a->out);
}

/* A C-contiguous float64 buffer (writable if asked); else a Python error. */
static int take(PyObject *obj, Py_buffer *view, int writable, const char *what)
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

static Py_ssize_t count(Py_buffer *v) { return v->len / 8; }

/* Check the program against the number of joint values: every index in range. */
static int check_program(const double *p, Py_ssize_t n_ops, Py_ssize_t dof)
{
    for (Py_ssize_t i = 0; i < n_ops; i++) {
        const double *op = p + i * OP_FIELDS;
        if (op[0] == 0.0) {
            double ti = op[3], di = op[5];
            if (ti >= (double)dof || di >= (double)dof || ti != floor(ti) || di != floor(di)) {
                PyErr_SetString(PyExc_ValueError, "program indexes a joint value q lacks");
                return -1;
            }
        } else if (op[0] != 1.0) {
            PyErr_SetString(PyExc_ValueError, "program step kind must be 0 (z) or 1 (x)");
            return -1;
        }
    }
    return 0;
}

static Py_ssize_t marks(const double *p, Py_ssize_t n_ops)
{
    Py_ssize_t m = 0;
    for (Py_ssize_t i = 0; i < n_ops; i++)
        m += p[i * OP_FIELDS + 6] != 0.0;
    return m;
}

/* a * b, [Zivkovic2023] eq. (12), in dq_multiply_coeffs' order of terms */
static void multiply(const double *a, const double *b, double *o)
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

static void canonical(double *h)
{
    if (h[0] < 0.0)
        for (int k = 0; k < 8; k++) h[k] = -h[k];
}

/*
 * Run the program from base at q; write frame 0, every marked frame, then base*tool, into
 * out (8 doubles each); only the last one if end_only. As run_program, step by step.
 */
static void run(const double *prog, Py_ssize_t n_ops, const double *base, const double *tool,
                const double *q, double *out, int end_only, int canon)
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
        double p1 = op[1], p2 = op[2], p3 = op[3], p4 = op[4], p5 = op[5];
        if (op[0] == 0.0) {  /* h (c + s k) (1 + eps hd k) */
            double half = p3 < 0 ? 0.5 * p1 : 0.5 * (p1 + p2 * q[(Py_ssize_t)p3]);
            double c = cos(half), s = sin(half);
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
        if (op[6] != 0.0 && !end_only) {
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
        double p1 = op[1], p2 = op[2], p3 = op[3], p4 = op[4], p5 = op[5];
        if (op[0] == 0.0) {
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
        if (op[6] != 0.0 && !end_only) {
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

/* Parse (program, base, tool or None, q, out, canonical[, dof]); check sizes; 0 or -1. */
static int parse(PyObject *const *args, Py_ssize_t nargs, Py_ssize_t expected, Args *a,
                 const char *name)
{
    memset(a, 0, sizeof *a);
    if (nargs != expected) {
        PyErr_Format(PyExc_TypeError, "%s(program, base, tool, q, out, canonical%s)", name,
                     expected == 7 ? ", dof" : "");
        return -1;
    }
    if (take(args[0], &a->program, 0, "program") < 0 || take(args[1], &a->base, 0, "base") < 0
        || take(args[3], &a->q, 0, "q") < 0 || take(args[4], &a->out, 1, "out") < 0)
        return -1;
    a->have_tool = args[2] != Py_None;
    if (a->have_tool && take(args[2], &a->tool, 0, "tool") < 0)
        return -1;
    if (count(&a->program) % OP_FIELDS || count(&a->base) != 8
        || (a->have_tool && count(&a->tool) != 8)) {
        PyErr_SetString(PyExc_ValueError, "program must be (n, 7), base and tool 8 values");
        return -1;
    }
    return 0;
}

static PyObject *kernel_frames(PyObject *self, PyObject *const *args, Py_ssize_t nargs,
                               int end_only)
{
    Args a;
    if (parse(args, nargs, 7, &a, end_only ? "end" : "frames") < 0) {
        release(&a);
        return NULL;
    }
    int canon = PyObject_IsTrue(args[5]);
    Py_ssize_t dof = PyLong_AsSsize_t(args[6]);
    const double *prog = a.program.buf;
    Py_ssize_t n_ops = count(&a.program) / OP_FIELDS;
    Py_ssize_t per = end_only ? 8 : 8 * (1 + marks(prog, n_ops) + a.have_tool);
    if (canon < 0 || (dof < 0 && PyErr_Occurred())) {
        release(&a);
        return NULL;
    }
    if (a.q.ndim != 1 || count(&a.q) != dof) {
        PyErr_Format(PyExc_ValueError, "q must be %zd joint values", dof);
        release(&a);
        return NULL;
    }
    if (check_program(prog, n_ops, dof) < 0) {
        release(&a);
        return NULL;
    }
    if (count(&a.out) != per) {
        PyErr_Format(PyExc_ValueError, "out must hold %zd values, not %zd", per,
                     count(&a.out));
        release(&a);
        return NULL;
    }
    run(prog, n_ops, a.base.buf, a.have_tool ? a.tool.buf : NULL, a.q.buf, a.out.buf,
        end_only, canon);
    release(&a);
    Py_RETURN_NONE;
}

static PyObject *kernel_batch(PyObject *self, PyObject *const *args, Py_ssize_t nargs,
                              int end_only)
{
    Args a;
    if (parse(args, nargs, 6, &a, end_only ? "end_batch" : "frames_batch") < 0) {
        release(&a);
        return NULL;
    }
    int canon = PyObject_IsTrue(args[5]);
    const double *prog = a.program.buf;
    Py_ssize_t n_ops = count(&a.program) / OP_FIELDS;
    Py_ssize_t per = end_only ? 8 : 8 * (1 + marks(prog, n_ops) + a.have_tool);
    if (canon < 0) {
        release(&a);
        return NULL;
    }
    if (a.q.ndim != 2) {
        PyErr_SetString(PyExc_ValueError, "q must be (N, dof)");
        release(&a);
        return NULL;
    }
    Py_ssize_t n = a.q.shape[0], dof = a.q.shape[1];
    if (check_program(prog, n_ops, dof) < 0) {
        release(&a);
        return NULL;
    }
    if (count(&a.out) != n * per) {
        PyErr_Format(PyExc_ValueError, "out must hold %zd values, not %zd", n * per,
                     count(&a.out));
        release(&a);
        return NULL;
    }
    const double *q = a.q.buf, *tool = a.have_tool ? a.tool.buf : NULL;
    double *out = a.out.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i += BLOCK) {
        Py_ssize_t m = n - i < BLOCK ? n - i : BLOCK;
        run_block(prog, n_ops, a.base.buf, tool, q + i * dof, dof, m, out + i * per, per,
                  end_only, canon);
    }
    Py_END_ALLOW_THREADS
    release(&a);
    Py_RETURN_NONE;
}

/*
 * jacobian(program, base, tool, rows, modified, q, out (6, dof), dof): the geometric
 * Jacobian of the end effector in the fixed frame, as KinematicChain.jacobian_geometric
 * (the reference): every frame from run(), then per row its joint axis (z of frame i-1,
 * standard; of frame i, modified) and, for a revolute variable, z x (p_end - p). rows is
 * (n, 3): the theta variable's index, the d variable's index (-1: none) and the scale.
 */
#define MAX_STACK_FRAMES 128

static void translation(const double *h, double *t)
{
    /* 2 d r*, the vector part ([Zivkovic2023] eq. (17)) */
    double w = h[0], x = -h[1], y = -h[2], z = -h[3];
    double dw = h[4], dx = h[5], dy = h[6], dz = h[7];
    t[0] = 2.0 * (dw * x + dx * w + dy * z - dz * y);
    t[1] = 2.0 * (dw * y - dx * z + dy * w + dz * x);
    t[2] = 2.0 * (dw * z + dx * y - dy * x + dz * w);
}

static PyObject *jacobian(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    Args a;
    Py_buffer rows = {0};
    double stack[8 * MAX_STACK_FRAMES], *frames = stack;
    if (nargs != 8) {
        PyErr_SetString(PyExc_TypeError,
                        "jacobian(program, base, tool, rows, modified, q, out, dof)");
        return NULL;
    }
    PyObject *forward[7] = {args[0], args[1], args[2], args[5], args[6], Py_True, args[7]};
    if (parse(forward, 7, 7, &a, "jacobian") < 0) {
        release(&a);
        return NULL;
    }
    PyObject *result = NULL;
    int modified = PyObject_IsTrue(args[4]);
    Py_ssize_t dof = PyLong_AsSsize_t(args[7]);
    const double *prog = a.program.buf;
    Py_ssize_t n_ops = count(&a.program) / OP_FIELDS;
    Py_ssize_t n_frames = 1 + marks(prog, n_ops) + a.have_tool;
    if (modified < 0 || (dof < 0 && PyErr_Occurred()))
        goto done;
    if (take(args[3], &rows, 0, "rows") < 0)
        goto done;
    Py_ssize_t n = count(&rows) / 3;
    if (count(&rows) % 3 || n != marks(prog, n_ops)) {
        PyErr_SetString(PyExc_ValueError, "rows must be (n, 3), one per row of the program");
        goto done;
    }
    if (a.q.ndim != 1 || count(&a.q) != dof || count(&a.out) != 6 * dof) {
        PyErr_Format(PyExc_ValueError, "q must be %zd joint values and out (6, %zd)", dof, dof);
        goto done;
    }
    if (check_program(prog, n_ops, dof) < 0)
        goto done;
    const double *r = rows.buf;
    for (Py_ssize_t i = 0; i < n; i++) {
        for (int k = 0; k < 2; k++) {
            double index = r[3 * i + k];
            if (index >= (double)dof || index != floor(index)) {
                PyErr_SetString(PyExc_ValueError, "rows index a joint value q lacks");
                goto done;
            }
        }
    }
    if (n_frames > MAX_STACK_FRAMES) {
        frames = PyMem_Malloc(8 * n_frames * sizeof(double));
        if (frames == NULL) {
            PyErr_NoMemory();
            goto done;
        }
    }
    run(prog, n_ops, a.base.buf, a.have_tool ? a.tool.buf : NULL, a.q.buf, frames, 0, 0);
    double *jac = a.out.buf, p_end[3];
    memset(jac, 0, 6 * dof * sizeof(double));
    translation(frames + 8 * (n_frames - 1), p_end);
    for (Py_ssize_t i = 0; i < n; i++) {
        const double *h = frames + 8 * (modified ? i + 1 : i);
        double w = h[0], x = h[1], y = h[2], zq = h[3];
        double z[3] = {2.0 * (x * zq + w * y), 2.0 * (y * zq - w * x),
                       1.0 - 2.0 * (x * x + y * y)};
        double scale = r[3 * i + 2], p[3];
        Py_ssize_t ti = (Py_ssize_t)r[3 * i], di = (Py_ssize_t)r[3 * i + 1];
        if (ti >= 0) {
            translation(h, p);
            double e0 = p_end[0] - p[0], e1 = p_end[1] - p[1], e2 = p_end[2] - p[2];
            jac[0 * dof + ti] += scale * (z[1] * e2 - z[2] * e1);
            jac[1 * dof + ti] += scale * (z[2] * e0 - z[0] * e2);
            jac[2 * dof + ti] += scale * (z[0] * e1 - z[1] * e0);
            for (int k = 0; k < 3; k++)
                jac[(3 + k) * dof + ti] += scale * z[k];
        }
        if (di >= 0)
            for (int k = 0; k < 3; k++)
                jac[k * dof + di] += scale * z[k];
    }
    result = Py_None;
    Py_INCREF(result);
done:
    if (frames != stack)
        PyMem_Free(frames);
    if (rows.obj)
        PyBuffer_Release(&rows);
    release(&a);
    return result;
}

static PyObject *frames(PyObject *s, PyObject *const *a, Py_ssize_t n)
{ return kernel_frames(s, a, n, 0); }
static PyObject *end(PyObject *s, PyObject *const *a, Py_ssize_t n)
{ return kernel_frames(s, a, n, 1); }
static PyObject *frames_batch(PyObject *s, PyObject *const *a, Py_ssize_t n)
{ return kernel_batch(s, a, n, 0); }
static PyObject *end_batch(PyObject *s, PyObject *const *a, Py_ssize_t n)
{ return kernel_batch(s, a, n, 1); }

/*
 * Chain(program, base, tool, dof): a chain checked once and copied into C memory, whose
 * frames(q, out) and end(q, out) take two buffers per call (the single-call fast path;
 * the module functions above take all five each time).
 */
typedef struct {
    PyObject_HEAD
    double *prog;
    Py_ssize_t n_ops, dof, per;
    double base[8], tool[8];
    int have_tool;
} ChainObject;

static void chain_dealloc(ChainObject *self)
{
    PyMem_Free(self->prog);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static int chain_init(ChainObject *self, PyObject *args, PyObject *kwargs)
{
    PyObject *program, *base, *tool;
    Py_ssize_t dof;
    static char *names[] = {"program", "base", "tool", "dof", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOn", names, &program, &base, &tool,
                                     &dof))
        return -1;
    Args a;
    memset(&a, 0, sizeof a);
    int ok = -1;
    if (take(program, &a.program, 0, "program") < 0 || take(base, &a.base, 0, "base") < 0)
        goto done;
    a.have_tool = tool != Py_None;
    if (a.have_tool && take(tool, &a.tool, 0, "tool") < 0)
        goto done;
    if (count(&a.program) % OP_FIELDS || count(&a.base) != 8
        || (a.have_tool && count(&a.tool) != 8) || dof < 0) {
        PyErr_SetString(PyExc_ValueError, "program must be (n, 7), base and tool 8 values");
        goto done;
    }
    Py_ssize_t n_ops = count(&a.program) / OP_FIELDS;
    if (check_program(a.program.buf, n_ops, dof) < 0)
        goto done;
    double *prog = PyMem_Malloc((n_ops ? n_ops : 1) * OP_FIELDS * sizeof(double));
    if (prog == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    memcpy(prog, a.program.buf, n_ops * OP_FIELDS * sizeof(double));
    PyMem_Free(self->prog);
    self->prog = prog;
    self->n_ops = n_ops;
    self->dof = dof;
    self->per = 8 * (1 + marks(prog, n_ops) + a.have_tool);
    memcpy(self->base, a.base.buf, sizeof self->base);
    self->have_tool = a.have_tool;
    if (a.have_tool)
        memcpy(self->tool, a.tool.buf, sizeof self->tool);
    ok = 0;
done:
    release(&a);
    return ok;
}

static PyObject *chain_call(ChainObject *self, PyObject *const *args, Py_ssize_t nargs,
                            int end_only)
{
    Py_buffer q = {0}, out = {0};
    if (self->prog == NULL) {
        PyErr_SetString(PyExc_ValueError, "the chain was not initialised");
        return NULL;
    }
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, end_only ? "end(q, out)" : "frames(q, out)");
        return NULL;
    }
    if (take(args[0], &q, 0, "q") < 0)
        return NULL;
    if (take(args[1], &out, 1, "out") < 0) {
        PyBuffer_Release(&q);
        return NULL;
    }
    Py_ssize_t per = end_only ? 8 : self->per;
    if (q.ndim != 1 || count(&q) != self->dof || count(&out) != per) {
        PyErr_Format(PyExc_ValueError, "q must be %zd joint values and out %zd values",
                     self->dof, per);
        PyBuffer_Release(&q);
        PyBuffer_Release(&out);
        return NULL;
    }
    run(self->prog, self->n_ops, self->base, self->have_tool ? self->tool : NULL, q.buf,
        out.buf, end_only, 1);
    PyBuffer_Release(&q);
    PyBuffer_Release(&out);
    Py_RETURN_NONE;
}

static PyObject *chain_frames(ChainObject *s, PyObject *const *a, Py_ssize_t n)
{ return chain_call(s, a, n, 0); }
static PyObject *chain_end(ChainObject *s, PyObject *const *a, Py_ssize_t n)
{ return chain_call(s, a, n, 1); }

static PyMethodDef chain_methods[] = {
    {"frames", (PyCFunction)(void (*)(void))chain_frames, METH_FASTCALL,
     "frames(q, out): every frame (w >= 0) into out, (n_frames, 8)"},
    {"end", (PyCFunction)(void (*)(void))chain_end, METH_FASTCALL,
     "end(q, out): the last frame (tool if any, w >= 0) into out, (8,)"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject ChainType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "dq_fk_ros.kinematics._kernel.Chain",
    .tp_doc = "Chain(program, base, tool, dof): a chain's program, checked and copied once",
    .tp_basicsize = sizeof(ChainObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)chain_init,
    .tp_dealloc = (destructor)chain_dealloc,
    .tp_methods = chain_methods,
};

/*
 * Model(chains, links, dof): a robot's tree of DH chains and the links fixed to them, as
 * RobotModel.frame_poses_general computes them (the reference; test_kernel.py holds them
 * equal). chains: a sequence of (Chain, parent frame index or -1, q indices of its variables
 * (float64), pose rows (m, 10) float64: cos al/2, sin al/2, a, theta, d, scale, theta
 * index, d index, sin al, cos al; standard 1/0). links: (L, 17) float64: attach index,
 * TF-parent index (-1: the fixed frame), offset (8), motion kind (-1 none, 0 revolute,
 * 1 prismatic), axis (3), q index, multiplier, offset value.
 * poses(q, absolute, relative): every frame's pose (n_frames, 7) and every TF transform
 * (n_rows + n_links, 7), (x, y, z, qx, qy, qz, qw) with qw >= 0; absolute may be None.
 * poses_batch(q (N, dof), absolute (N, n_frames, 7), relative): the same, configuration by
 * configuration (the bag tool's chunks).
 * frames(q, out): every frame's coefficients (n_frames, 8), w >= 0.
 */
#define LINK_FIELDS 17

typedef struct {
    ChainObject *chain;
    Py_ssize_t parent, n_frames, n_rows, first_frame, first_row;
    Py_ssize_t *q_map;
    double *rows;
    int standard;
} ModelChain;

typedef struct {
    PyObject_HEAD
    ModelChain *chains;
    Py_ssize_t n_chains, n_links, dof, n_frames, n_relative, max_chain_dof;
    double *links, *coeffs, *q_chain;
} ModelObject;

static const double IDENTITY[8] = {1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};

static void model_clear(ModelObject *self)
{
    for (Py_ssize_t c = 0; c < self->n_chains; c++) {
        Py_XDECREF(self->chains[c].chain);
        PyMem_Free(self->chains[c].q_map);
        PyMem_Free(self->chains[c].rows);
    }
    PyMem_Free(self->chains);
    PyMem_Free(self->links);
    PyMem_Free(self->coeffs);
    PyMem_Free(self->q_chain);
    self->chains = NULL;
    self->links = self->coeffs = self->q_chain = NULL;
    self->n_chains = 0;
}

static void model_dealloc(ModelObject *self)
{
    model_clear(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* An index stored as a double: integral, in [low, high). */
static int index_ok(double v, Py_ssize_t low, Py_ssize_t high)
{
    return v == floor(v) && v >= (double)low && v < (double)high;
}

static int model_take_chain(ModelObject *self, PyObject *item, Py_ssize_t c)
{
    ModelChain *mc = &self->chains[c];
    PyObject *chain, *q_map, *rows;
    Py_ssize_t parent;
    int standard;
    Py_buffer qv = {0}, rv = {0};
    int ok = -1;
    if (!PyArg_ParseTuple(item, "O!nOOp", &ChainType, &chain, &parent, &q_map, &rows,
                          &standard))
        return -1;
    ChainObject *ch = (ChainObject *)chain;
    if (ch->prog == NULL) {
        PyErr_SetString(PyExc_ValueError, "the chain was not initialised");
        return -1;
    }
    if (take(q_map, &qv, 0, "q indices") < 0)
        return -1;
    if (take(rows, &rv, 0, "pose rows") < 0)
        goto done;
    Py_ssize_t n_rows = count(&rv) / 10;
    Py_ssize_t n_frames = ch->per / 8;
    if (count(&qv) != ch->dof || count(&rv) % 10 || n_rows + 1 + ch->have_tool != n_frames) {
        PyErr_SetString(PyExc_ValueError, "a chain's q indices or pose rows do not fit it");
        goto done;
    }
    if (!(parent == -1 || (parent >= 0 && parent < self->n_frames))) {
        PyErr_SetString(PyExc_ValueError, "a chain hangs from a frame not computed before it");
        goto done;
    }
    const double *qm = qv.buf, *r = rv.buf;
    for (Py_ssize_t k = 0; k < ch->dof; k++)
        if (!index_ok(qm[k], 0, self->dof)) {
            PyErr_SetString(PyExc_ValueError, "a chain's q index is outside q");
            goto done;
        }
    for (Py_ssize_t i = 0; i < n_rows; i++)
        if (!index_ok(r[i * 10 + 6], -1, ch->dof) || !index_ok(r[i * 10 + 7], -1, ch->dof)) {
            PyErr_SetString(PyExc_ValueError, "a pose row indexes a variable the chain lacks");
            goto done;
        }
    mc->q_map = PyMem_Malloc((ch->dof ? ch->dof : 1) * sizeof(Py_ssize_t));
    mc->rows = PyMem_Malloc((n_rows ? n_rows : 1) * 10 * sizeof(double));
    if (mc->q_map == NULL || mc->rows == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t k = 0; k < ch->dof; k++)
        mc->q_map[k] = (Py_ssize_t)qm[k];
    memcpy(mc->rows, r, n_rows * 10 * sizeof(double));
    Py_INCREF(chain);
    mc->chain = ch;
    mc->parent = parent;
    mc->n_frames = n_frames;
    mc->n_rows = n_rows;
    mc->first_frame = self->n_frames;
    mc->first_row = self->n_relative;
    mc->standard = standard;
    self->n_frames += n_frames;
    self->n_relative += n_rows;
    if (ch->dof > self->max_chain_dof)
        self->max_chain_dof = ch->dof;
    ok = 0;
done:
    if (qv.obj) PyBuffer_Release(&qv);
    if (rv.obj) PyBuffer_Release(&rv);
    return ok;
}

static int model_build(ModelObject *self, PyObject *chains, PyObject *links, Py_ssize_t dof)
{
    self->n_frames = self->n_relative = self->n_links = self->max_chain_dof = 0;
    if (dof < 0) {
        PyErr_SetString(PyExc_ValueError, "dof must be >= 0");
        return -1;
    }
    self->dof = dof;
    PyObject *seq = PySequence_Fast(chains, "chains must be a sequence");
    if (seq == NULL)
        return -1;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(seq);
    if (n < 1) {
        Py_DECREF(seq);
        PyErr_SetString(PyExc_ValueError, "a model has at least one chain");
        return -1;
    }
    self->chains = PyMem_Calloc(n, sizeof(ModelChain));
    if (self->chains == NULL) {
        Py_DECREF(seq);
        PyErr_NoMemory();
        return -1;
    }
    for (Py_ssize_t c = 0; c < n; c++) {
        self->n_chains = c + 1;
        if (model_take_chain(self, PySequence_Fast_GET_ITEM(seq, c), c) < 0) {
            Py_DECREF(seq);
            return -1;
        }
    }
    Py_DECREF(seq);
    Py_buffer lv;
    if (take(links, &lv, 0, "links") < 0)
        return -1;
    if (count(&lv) % LINK_FIELDS) {
        PyBuffer_Release(&lv);
        PyErr_SetString(PyExc_ValueError, "links must be (n, 17)");
        return -1;
    }
    Py_ssize_t n_links = count(&lv) / LINK_FIELDS;
    const double *l = lv.buf;
    for (Py_ssize_t j = 0; j < n_links; j++) {
        const double *f = l + j * LINK_FIELDS;
        Py_ssize_t here = self->n_frames + j;  /* a link hangs from a frame before it */
        double kind = f[10];
        if (!index_ok(f[0], -1, here) || !index_ok(f[1], -1, here)
            || !(kind == -1.0 || kind == 0.0 || kind == 1.0)
            || (kind != -1.0 && !index_ok(f[14], 0, dof))) {
            PyBuffer_Release(&lv);
            PyErr_SetString(PyExc_ValueError, "a link indexes a frame or joint it cannot use");
            return -1;
        }
    }
    self->links = PyMem_Malloc((n_links ? n_links : 1) * LINK_FIELDS * sizeof(double));
    if (self->links == NULL) {
        PyBuffer_Release(&lv);
        PyErr_NoMemory();
        return -1;
    }
    memcpy(self->links, l, n_links * LINK_FIELDS * sizeof(double));
    PyBuffer_Release(&lv);
    self->n_links = n_links;
    self->n_frames += n_links;
    self->n_relative += n_links;
    self->coeffs = PyMem_Malloc(self->n_frames * 8 * sizeof(double));
    self->q_chain = PyMem_Malloc((self->max_chain_dof ? self->max_chain_dof : 1)
                                 * sizeof(double));
    if (self->coeffs == NULL || self->q_chain == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    return 0;
}

static int model_init(ModelObject *self, PyObject *args, PyObject *kwargs)
{
    PyObject *chains, *links;
    Py_ssize_t dof;
    static char *names[] = {"chains", "links", "dof", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOn", names, &chains, &links, &dof))
        return -1;
    model_clear(self);
    if (model_build(self, chains, links, dof) < 0) {
        model_clear(self);  /* a model half built is no model */
        return -1;
    }
    return 0;
}

/* pose_xyzw_from_coeffs: (x, y, z, qx, qy, qz, qw), qw >= 0, [Zivkovic2023] eq. (17) */
static void pose_of(const double *h, double *p)
{
    double w = h[0], x = h[1], y = h[2], z = h[3], dw = h[4], dx = h[5], dy = h[6], dz = h[7];
    if (w < 0.0) {
        w = -w; x = -x; y = -y; z = -z; dw = -dw; dx = -dx; dy = -dy; dz = -dz;
    }
    p[0] = 2.0 * (dx * w - dw * x - dy * z + dz * y);
    p[1] = 2.0 * (dy * w - dw * y + dx * z - dz * x);
    p[2] = 2.0 * (dz * w - dw * z - dx * y + dy * x);
    p[3] = x; p[4] = y; p[5] = z; p[6] = w;
}

/* KinematicChain.row_poses for one row: the transform frame i-1 -> frame i */
static void row_pose(const double *r, const double *q, int standard, double *p)
{
    double ca = r[0], sa = r[1], a = r[2], theta = r[3], d = r[4], scale = r[5];
    double ti = r[6], di = r[7], s_alpha = r[8], c_alpha = r[9];
    if (ti >= 0) theta = theta + scale * q[(Py_ssize_t)ti];
    if (di >= 0) d = d + scale * q[(Py_ssize_t)di];
    double half = 0.5 * theta;
    double ct = cos(half), st = sin(half);
    double qx, qy, qz, qw;
    if (standard) {
        qx = sa * ct; qy = sa * st; qz = ca * st; qw = ca * ct;
        p[0] = a * (1.0 - 2.0 * st * st); p[1] = 2.0 * a * st * ct; p[2] = d;
    } else {
        qx = sa * ct; qy = -sa * st; qz = ca * st; qw = ca * ct;
        p[0] = a; p[1] = -d * s_alpha; p[2] = d * c_alpha;
    }
    if (qw < 0.0) {
        qx = -qx; qy = -qy; qz = -qz; qw = -qw;
    }
    p[3] = qx; p[4] = qy; p[5] = qz; p[6] = qw;
}

/* Every frame's coefficients into self->coeffs (not made w >= 0); the TF transforms into
 * relative (7 per transform) unless NULL. As RobotModel.frame_poses_general. */
static void model_run(ModelObject *self, const double *q, double *relative)
{
    double *coeffs = self->coeffs, *qc = self->q_chain;
    for (Py_ssize_t c = 0; c < self->n_chains; c++) {
        ModelChain *mc = &self->chains[c];
        ChainObject *ch = mc->chain;
        for (Py_ssize_t k = 0; k < ch->dof; k++)
            qc[k] = q[mc->q_map[k]];
        double base[8];
        if (mc->parent >= 0)
            multiply(coeffs + 8 * mc->parent, ch->base, base);
        else
            memcpy(base, ch->base, sizeof base);
        run(ch->prog, ch->n_ops, base, ch->have_tool ? ch->tool : NULL, qc,
            coeffs + 8 * mc->first_frame, 0, 0);
        if (relative)
            for (Py_ssize_t i = 0; i < mc->n_rows; i++)
                row_pose(mc->rows + 10 * i, qc, mc->standard,
                         relative + 7 * (mc->first_row + i));
    }
    Py_ssize_t first = self->n_frames - self->n_links;
    Py_ssize_t first_rel = self->n_relative - self->n_links;
    for (Py_ssize_t j = 0; j < self->n_links; j++) {
        const double *f = self->links + j * LINK_FIELDS;
        Py_ssize_t attach = (Py_ssize_t)f[0], tf_parent = (Py_ssize_t)f[1];
        double offset[8];
        memcpy(offset, f + 2, sizeof offset);
        if (f[10] >= 0.0) {  /* RobotModel's _motion: a rotation about or a move along axis */
            double value = f[15] * q[(Py_ssize_t)f[14]] + f[16];
            double zero = 0.0 * value, m[8], moved[8];
            if (f[10] == 1.0) {
                double half = 0.5 * value;
                m[0] = 1.0 + zero; m[1] = zero; m[2] = zero; m[3] = zero; m[4] = zero;
                m[5] = half * f[11]; m[6] = half * f[12]; m[7] = half * f[13];
            } else {
                double cc = cos(0.5 * value), ss = sin(0.5 * value);
                m[0] = cc; m[1] = ss * f[11]; m[2] = ss * f[12]; m[3] = ss * f[13];
                m[4] = zero; m[5] = zero; m[6] = zero; m[7] = zero;
            }
            multiply(offset, m, moved);
            memcpy(offset, moved, sizeof offset);
        }
        double *pose = coeffs + 8 * (first + j);
        multiply(attach >= 0 ? coeffs + 8 * attach : IDENTITY, offset, pose);
        if (relative) {
            double *p = relative + 7 * (first_rel + j);
            if (tf_parent == attach) {
                pose_of(offset, p);
            } else {
                const double *above = tf_parent >= 0 ? coeffs + 8 * tf_parent : IDENTITY;
                double inv[8] = {above[0], -above[1], -above[2], -above[3],
                                 above[4], -above[5], -above[6], -above[7]}, rel[8];
                multiply(inv, pose, rel);
                pose_of(rel, p);
            }
        }
    }
}

static int model_q(ModelObject *self, PyObject *obj, Py_buffer *q)
{
    if (self->chains == NULL) {
        PyErr_SetString(PyExc_ValueError, "the model was not initialised");
        return -1;
    }
    if (take(obj, q, 0, "q") < 0)
        return -1;
    if (q->ndim != 1 || count(q) != self->dof) {
        PyErr_Format(PyExc_ValueError, "q must be %zd joint values", self->dof);
        PyBuffer_Release(q);
        return -1;
    }
    return 0;
}

static int model_out(PyObject *obj, Py_buffer *v, Py_ssize_t n, const char *what)
{
    if (take(obj, v, 1, what) < 0)
        return -1;
    if (count(v) != n) {
        PyErr_Format(PyExc_ValueError, "%s must have %zd values", what, n);
        PyBuffer_Release(v);
        return -1;
    }
    return 0;
}

static PyObject *model_poses(ModelObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer q = {0}, absolute = {0}, relative = {0};
    PyObject *result = NULL;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "poses(q, absolute, relative)");
        return NULL;
    }
    if (model_q(self, args[0], &q) < 0)
        return NULL;
    if (args[1] != Py_None && model_out(args[1], &absolute, 7 * self->n_frames, "absolute") < 0)
        goto done;
    if (model_out(args[2], &relative, 7 * self->n_relative, "relative") < 0)
        goto done;
    model_run(self, q.buf, relative.buf);
    if (absolute.obj)
        for (Py_ssize_t k = 0; k < self->n_frames; k++)
            pose_of(self->coeffs + 8 * k, (double *)absolute.buf + 7 * k);
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&q);
    if (absolute.obj) PyBuffer_Release(&absolute);
    if (relative.obj) PyBuffer_Release(&relative);
    return result;
}

static PyObject *model_frames(ModelObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer q = {0}, out = {0};
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "frames(q, out)");
        return NULL;
    }
    if (model_q(self, args[0], &q) < 0)
        return NULL;
    if (model_out(args[1], &out, 8 * self->n_frames, "out") < 0) {
        PyBuffer_Release(&q);
        return NULL;
    }
    model_run(self, q.buf, NULL);
    memcpy(out.buf, self->coeffs, self->n_frames * 8 * sizeof(double));
    for (Py_ssize_t k = 0; k < self->n_frames; k++)
        canonical((double *)out.buf + 8 * k);
    PyBuffer_Release(&q);
    PyBuffer_Release(&out);
    Py_RETURN_NONE;
}

static PyObject *model_poses_batch(ModelObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer q = {0}, absolute = {0}, relative = {0};
    PyObject *result = NULL;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "poses_batch(q, absolute, relative)");
        return NULL;
    }
    if (self->chains == NULL) {
        PyErr_SetString(PyExc_ValueError, "the model was not initialised");
        return NULL;
    }
    if (take(args[0], &q, 0, "q") < 0)
        return NULL;
    Py_ssize_t n = self->dof ? count(&q) / self->dof : (q.ndim == 2 ? q.shape[0] : -1);
    if (q.ndim != 2 || q.shape[1] != self->dof || n < 0) {
        PyErr_Format(PyExc_ValueError, "q must be (N, %zd) joint values", self->dof);
        goto done;
    }
    if (args[1] != Py_None
        && model_out(args[1], &absolute, 7 * self->n_frames * n, "absolute") < 0)
        goto done;
    if (model_out(args[2], &relative, 7 * self->n_relative * n, "relative") < 0)
        goto done;
    for (Py_ssize_t i = 0; i < n; i++) {
        model_run(self, (const double *)q.buf + i * self->dof,
                  (double *)relative.buf + i * 7 * self->n_relative);
        if (absolute.obj) {
            double *a = (double *)absolute.buf + i * 7 * self->n_frames;
            for (Py_ssize_t k = 0; k < self->n_frames; k++)
                pose_of(self->coeffs + 8 * k, a + 7 * k);
        }
    }
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&q);
    if (absolute.obj) PyBuffer_Release(&absolute);
    if (relative.obj) PyBuffer_Release(&relative);
    return result;
}

static PyMethodDef model_methods[] = {
    {"poses_batch", (PyCFunction)(void (*)(void))model_poses_batch, METH_FASTCALL,
     "poses_batch(q (N, dof), absolute, relative): poses() for N configurations"},
    {"poses", (PyCFunction)(void (*)(void))model_poses, METH_FASTCALL,
     "poses(q, absolute, relative): (x, y, z, qx, qy, qz, qw) of every frame and transform"},
    {"frames", (PyCFunction)(void (*)(void))model_frames, METH_FASTCALL,
     "frames(q, out): every frame's coefficients (w >= 0) into out, (n_frames, 8)"},
    {NULL, NULL, 0, NULL},
};

static PyObject *model_n_frames(ModelObject *self, void *closure)
{ return PyLong_FromSsize_t(self->n_frames); }
static PyObject *model_n_relative(ModelObject *self, void *closure)
{ return PyLong_FromSsize_t(self->n_relative); }

static PyGetSetDef model_getset[] = {
    {"n_frames", (getter)model_n_frames, NULL, "frames computed", NULL},
    {"n_relative", (getter)model_n_relative, NULL, "TF transforms computed", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject ModelType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "dq_fk_ros.kinematics._kernel.Model",
    .tp_doc = "Model(chains, links, dof): a tree of chains and its links, checked once",
    .tp_basicsize = sizeof(ModelObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)model_init,
    .tp_dealloc = (destructor)model_dealloc,
    .tp_methods = model_methods,
    .tp_getset = model_getset,
};

static PyMethodDef methods[] = {
    {"frames", (PyCFunction)(void (*)(void))frames, METH_FASTCALL,
     "frames(program, base, tool, q, out, canonical, dof): every frame of the chain into out"},
    {"end", (PyCFunction)(void (*)(void))end, METH_FASTCALL,
     "end(program, base, tool, q, out, canonical, dof): the last frame (tool if any) into out"},
    {"frames_batch", (PyCFunction)(void (*)(void))frames_batch, METH_FASTCALL,
     "frames_batch(program, base, tool, q (N, dof), out, canonical): N x every frame"},
    {"jacobian", (PyCFunction)(void (*)(void))jacobian, METH_FASTCALL,
     "jacobian(program, base, tool, rows, modified, q, out (6, dof), dof): geometric"},
    {"end_batch", (PyCFunction)(void (*)(void))end_batch, METH_FASTCALL,
     "end_batch(program, base, tool, q (N, dof), out, canonical): N x the last frame"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_kernel",
    "The DH chain's poses in C (the reference: dq_fk_ros.kinematics.dh_code.run_program).",
    -1, methods,
};

PyMODINIT_FUNC PyInit__kernel(void)
{
    if (PyType_Ready(&ChainType) < 0 || PyType_Ready(&ModelType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    if (PyModule_AddType(m, &ChainType) < 0 || PyModule_AddType(m, &ModelType) < 0) {
        Py_DECREF(m);  /* (the types are named by their tp_name's last part) */
        return NULL;
    }
    return m;
}
