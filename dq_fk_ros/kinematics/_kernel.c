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
 * Two types, both immutable: Chain (one chain's program) and Model (a tree of chains and
 * its links). What no Python value may do to them (docs/security.md, test_compiled_fuzz.py,
 * make sanitize): every argument is converted to C values, and every sequence copied, before
 * anything is checked; every size product is checked for overflow before it sizes a buffer
 * or a loop; a type's state is set once, in __new__ (a second __init__ is refused); what the
 * batch loop reads without the GIL is the Chain's own copy and buffers it holds for the call.
 *
 * Only the CPython C API and the buffer protocol: no numpy headers.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#define OP_FIELDS 7
/* joint values a chain or a model takes at most (sizes stay far from overflow) */
#define MAX_DOF (1 << 20)

/* a * b into *r, unless negative or past PY_SSIZE_T_MAX: 0, else -1 */
static int mul_size(Py_ssize_t a, Py_ssize_t b, Py_ssize_t *r)
{
    if (a < 0 || b < 0 || (b != 0 && a > PY_SSIZE_T_MAX / b))
        return -1;
    *r = a * b;
    return 0;
}

/* a + b into *r, likewise */
static int add_size(Py_ssize_t a, Py_ssize_t b, Py_ssize_t *r)
{
    if (a < 0 || b < 0 || a > PY_SSIZE_T_MAX - b)
        return -1;
    *r = a + b;
    return 0;
}

/* A C-contiguous float64 buffer (writable if asked); else a Python error, view->obj NULL. */
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

static void let_go(Py_buffer *view)
{
    if (view->obj)
        PyBuffer_Release(view);
}

static Py_ssize_t count(Py_buffer *v) { return v->len / 8; }

/* refuse a second __init__: the state of these types is set once, in __new__ */
static int set_once(PyObject *self, int *initialised)
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


/* 2 d r*, the vector part of a pose's translation ([Zivkovic2023] eq. (17)) */
static void translation(const double *h, double *t)
{
    double w = h[0], x = -h[1], y = -h[2], z = -h[3];
    double dw = h[4], dx = h[5], dy = h[6], dz = h[7];
    t[0] = 2.0 * (dw * x + dx * w + dy * z - dz * y);
    t[1] = 2.0 * (dw * y - dx * z + dy * w + dz * x);
    t[2] = 2.0 * (dw * z + dx * y - dy * x + dz * w);
}

/*
 * Chain(program, base, tool, dof, rows=None, modified=False): a chain checked and copied
 * into C memory once. frames(q, out) and end(q, out): one configuration; frames_batch(q,
 * out) and end_batch(q, out): N of them (q (N, dof)), without the GIL; jacobian(q, out):
 * the geometric Jacobian (6, dof) of the end effector in the fixed frame, as
 * KinematicChain._jacobian_geometric_reference: every frame from run(), then per row its
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
        out.buf, end_only, 1);
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
        frames, 0, 0);
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

static PyTypeObject ChainType = {
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
    int initialised;
} ModelObject;

static const double IDENTITY[8] = {1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};

static void model_dealloc(ModelObject *self)
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
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* An index stored as a double: integral, in [low, high). */
static int index_ok(double v, Py_ssize_t low, Py_ssize_t high)
{
    return v == floor(v) && v >= (double)low && v < (double)high;
}

/* One (Chain, parent, q indices, pose rows, standard) of the tuple the model holds. */
static int model_take_chain(ModelObject *self, PyObject *item, Py_ssize_t c)
{
    ModelChain *mc = &self->chains[c];
    PyObject *chain, *q_map, *rows;
    Py_ssize_t parent;
    int standard;
    Py_buffer qv = {0}, rv = {0};
    int ok = -1;
    if (!PyTuple_Check(item)) {
        PyErr_SetString(PyExc_TypeError,
                        "a chain is a tuple (Chain, parent, q indices, pose rows, standard)");
        return -1;
    }
    /* (the item is a tuple the model's own tuple holds: its parts stay alive while the
       parent's __index__ or standard's __bool__ runs; nothing below depends on them) */
    if (!PyArg_ParseTuple(item, "O!nOOp", &ChainType, &chain, &parent, &q_map, &rows,
                          &standard))
        return -1;
    ChainObject *ch = (ChainObject *)chain;
    if (take(q_map, &qv, 0, "q indices") < 0 || take(rows, &rv, 0, "pose rows") < 0)
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
    mc->q_map = PyMem_Malloc((ch->dof ? ch->dof : 1) * sizeof(Py_ssize_t));
    mc->rows = PyMem_Malloc((n_rows ? n_rows : 1) * 10 * sizeof(double));
    if (mc->q_map == NULL || mc->rows == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    memcpy(mc->rows, rv.buf, n_rows * 10 * sizeof(double));  /* copied, then checked */
    const double *qm = qv.buf, *r = mc->rows;
    for (Py_ssize_t k = 0; k < ch->dof; k++) {
        double v = qm[k];
        if (!index_ok(v, 0, self->dof)) {
            PyErr_SetString(PyExc_ValueError, "a chain's q index is outside q");
            goto done;
        }
        mc->q_map[k] = (Py_ssize_t)v;
    }
    for (Py_ssize_t i = 0; i < n_rows; i++)
        if (!index_ok(r[i * 10 + 6], -1, ch->dof) || !index_ok(r[i * 10 + 7], -1, ch->dof)) {
            PyErr_SetString(PyExc_ValueError, "a pose row indexes a variable the chain lacks");
            goto done;
        }
    if (add_size(self->n_frames, n_frames, &self->n_frames) < 0
        || add_size(self->n_relative, n_rows, &self->n_relative) < 0) {
        PyErr_SetString(PyExc_ValueError, "a model too large to compute");
        goto done;
    }
    Py_INCREF(chain);
    mc->chain = ch;
    mc->parent = parent;
    mc->n_frames = n_frames;
    mc->n_rows = n_rows;
    mc->first_frame = self->n_frames - n_frames;
    mc->first_row = self->n_relative - n_rows;
    mc->standard = standard;
    if (ch->dof > self->max_chain_dof)
        self->max_chain_dof = ch->dof;
    ok = 0;
done:
    let_go(&qv);
    let_go(&rv);
    return ok;
}

static int model_build(ModelObject *self, PyObject *chains, PyObject *links, Py_ssize_t dof)
{
    if (dof < 0 || dof > MAX_DOF) {
        PyErr_Format(PyExc_ValueError, "dof must be 0 to %d", MAX_DOF);
        return -1;
    }
    self->dof = dof;
    /* a tuple of our own: a callback while a chain is read cannot change the others */
    PyObject *seq = PySequence_Tuple(chains);
    if (seq == NULL)
        return -1;
    Py_ssize_t n = PyTuple_GET_SIZE(seq);
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
        if (model_take_chain(self, PyTuple_GET_ITEM(seq, c), c) < 0) {
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
    self->links = PyMem_Malloc((n_links ? n_links : 1) * LINK_FIELDS * sizeof(double));
    if (self->links == NULL) {
        PyBuffer_Release(&lv);
        PyErr_NoMemory();
        return -1;
    }
    memcpy(self->links, lv.buf, n_links * LINK_FIELDS * sizeof(double));
    PyBuffer_Release(&lv);
    Py_ssize_t n_frames, n_relative, coeff_bytes;
    if (add_size(self->n_frames, n_links, &n_frames) < 0
        || add_size(self->n_relative, n_links, &n_relative) < 0
        || mul_size(n_frames, 8 * sizeof(double), &coeff_bytes) < 0
        || mul_size(n_frames, 7 * 8, &coeff_bytes) < 0) {
        PyErr_SetString(PyExc_ValueError, "a model too large to compute");
        return -1;
    }
    for (Py_ssize_t j = 0; j < n_links; j++) {
        const double *f = self->links + j * LINK_FIELDS;
        Py_ssize_t here = self->n_frames + j;  /* a link hangs from a frame before it */
        double kind = f[10];
        if (!index_ok(f[0], -1, here) || !index_ok(f[1], -1, here)
            || !(kind == -1.0 || kind == 0.0 || kind == 1.0)
            || (kind != -1.0 && !index_ok(f[14], 0, dof))) {
            PyErr_SetString(PyExc_ValueError, "a link indexes a frame or joint it cannot use");
            return -1;
        }
    }
    self->n_links = n_links;
    self->n_frames = n_frames;
    self->n_relative = n_relative;
    self->coeffs = PyMem_Malloc((n_frames ? n_frames : 1) * 8 * sizeof(double));
    self->q_chain = PyMem_Malloc((self->max_chain_dof ? self->max_chain_dof : 1)
                                 * sizeof(double));
    if (self->coeffs == NULL || self->q_chain == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    return 0;
}

static PyObject *model_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    PyObject *chains, *links;
    Py_ssize_t dof;
    static char *names[] = {"chains", "links", "dof", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOn", names, &chains, &links, &dof))
        return NULL;
    ModelObject *self = (ModelObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    if (model_build(self, chains, links, dof) < 0) {
        Py_DECREF(self);  /* a model half built is no model */
        return NULL;
    }
    return (PyObject *)self;
}

static int model_init(ModelObject *self, PyObject *args, PyObject *kwargs)
{
    return set_once((PyObject *)self, &self->initialised);
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
    if (take(obj, q, 0, "q") < 0)
        return -1;
    if (q->ndim != 1 || count(q) != self->dof) {
        PyErr_Format(PyExc_ValueError, "q must be %zd joint values", self->dof);
        PyBuffer_Release(q);
        return -1;
    }
    return 0;
}

/* a writable float64 buffer of n values times `times` (an overflow is no fit) */
static int model_out(PyObject *obj, Py_buffer *v, Py_ssize_t n, Py_ssize_t times,
                     const char *what)
{
    Py_ssize_t need;
    if (take(obj, v, 1, what) < 0)
        return -1;
    if (mul_size(n, times, &need) < 0 || count(v) != need) {
        PyErr_Format(PyExc_ValueError, "%s must have %zd x %zd values", what, times, n);
        PyBuffer_Release(v);
        v->obj = NULL;
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
    if (args[1] != Py_None
        && model_out(args[1], &absolute, 7 * self->n_frames, 1, "absolute") < 0)
        goto done;
    if (model_out(args[2], &relative, 7 * self->n_relative, 1, "relative") < 0)
        goto done;
    model_run(self, q.buf, relative.buf);
    if (absolute.obj)
        for (Py_ssize_t k = 0; k < self->n_frames; k++)
            pose_of(self->coeffs + 8 * k, (double *)absolute.buf + 7 * k);
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&q);
    let_go(&absolute);
    let_go(&relative);
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
    if (model_out(args[1], &out, 8 * self->n_frames, 1, "out") < 0) {
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
    if (take(args[0], &q, 0, "q") < 0)
        return NULL;
    if (q.ndim != 2 || q.shape[1] != self->dof) {
        PyErr_Format(PyExc_ValueError, "q must be (N, %zd) joint values", self->dof);
        goto done;
    }
    Py_ssize_t n = q.shape[0];
    if (args[1] != Py_None
        && model_out(args[1], &absolute, 7 * self->n_frames, n, "absolute") < 0)
        goto done;
    if (model_out(args[2], &relative, 7 * self->n_relative, n, "relative") < 0)
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
    let_go(&absolute);
    let_go(&relative);
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
    .tp_doc = "Model(chains, links, dof): a tree of chains and its links, checked once "
              "(immutable)",
    .tp_basicsize = sizeof(ModelObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = model_new,
    .tp_init = (initproc)model_init,
    .tp_dealloc = (destructor)model_dealloc,
    .tp_methods = model_methods,
    .tp_getset = model_getset,
};

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
    if (PyModule_AddType(m, &ChainType) < 0 || PyModule_AddType(m, &ModelType) < 0) {
        Py_DECREF(m);  /* (the types are named by their tp_name's last part) */
        return NULL;
    }
    return m;
}
