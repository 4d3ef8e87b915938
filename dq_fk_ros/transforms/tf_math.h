/*
 * tf2's arithmetic for dq_fk_ros/transforms/_tf.c: poses (x y z qx qy qz qw) composed and
 * inverted, tf2's slerp, a sorted stamp array searched; the same operations, in the same
 * order, as dq_fk_ros/transforms/pose_math.py's compose, inverse and slerp.
 */
#ifndef DQ_FK_TF_MATH_H
#define DQ_FK_TF_MATH_H

#include <math.h>
#include <stdint.h>
#include <string.h>

static void rotate(const double *q, const double *v, double *out)
{
    double qx = q[0], qy = q[1], qz = q[2], qw = q[3];
    double vx = v[0], vy = v[1], vz = v[2];
    double tx = 2.0 * (qy * vz - qz * vy);
    double ty = 2.0 * (qz * vx - qx * vz);
    double tz = 2.0 * (qx * vy - qy * vx);
    out[0] = vx + qw * tx + qy * tz - qz * ty;
    out[1] = vy + qw * ty + qz * tx - qx * tz;
    out[2] = vz + qw * tz + qx * ty - qy * tx;
}

static void multiply(const double *a, const double *b, double *out)
{
    double ax = a[0], ay = a[1], az = a[2], aw = a[3];
    double bx = b[0], by = b[1], bz = b[2], bw = b[3];
    out[0] = aw * bx + ax * bw + ay * bz - az * by;
    out[1] = aw * by - ax * bz + ay * bw + az * bx;
    out[2] = aw * bz + ax * by - ay * bx + az * bw;
    out[3] = aw * bw - ax * bx - ay * by - az * bz;
}

/* out = a * b (poses x y z qx qy qz qw); out may be b. */
static void compose(const double *a, const double *b, double *out)
{
    double p[3], q[4];
    rotate(a + 3, b, p);
    multiply(a + 3, b + 3, q);
    out[0] = p[0] + a[0];
    out[1] = p[1] + a[1];
    out[2] = p[2] + a[2];
    memcpy(out + 3, q, sizeof q);
}

static void inverse(const double *a, double *out)
{
    double q[4] = {-a[3], -a[4], -a[5], a[6]}, p[3];
    rotate(q, a, p);
    out[0] = -p[0];
    out[1] = -p[1];
    out[2] = -p[2];
    memcpy(out + 3, q, sizeof q);
}

/* What slerp computes of two quaternions alone: the angle, 1 / sin of it; 1 if zero. */
static int slerp_angle(const double *q0, const double *q1, double *theta, double *d)
{
    double x0 = q0[0], y0 = q0[1], z0 = q0[2], w0 = q0[3];
    double x1 = q1[0], y1 = q1[1], z1 = q1[2], w1 = q1[3];
    double dot = x0 * x1 + y0 * y1 + z0 * z1 + w0 * w1;
    double norms = sqrt((x0 * x0 + y0 * y0 + z0 * z0 + w0 * w0) *
                        (x1 * x1 + y1 * y1 + z1 * z1 + w1 * w1));
    double c = fabs(dot) / norms;
    *theta = acos(c > 1.0 ? 1.0 : c < -1.0 ? -1.0 : c);
    if (*theta == 0.0 || c != c)   /* (c NaN only for a zero quaternion: never stored) */
        return 1;
    *d = 1.0 / sin(*theta);
    return 0;
}

static void slerp_with(const double *q0, const double *q1, double ratio, double theta,
                       double d, int zero, double *out)
{
    if (zero) {
        memcpy(out, q0, 4 * sizeof(double));
        return;
    }
    double x0 = q0[0], y0 = q0[1], z0 = q0[2], w0 = q0[3];
    double x1 = q1[0], y1 = q1[1], z1 = q1[2], w1 = q1[3];
    double dot = x0 * x1 + y0 * y1 + z0 * z1 + w0 * w1;
    double s0 = sin((1.0 - ratio) * theta);
    double s1 = sin(ratio * theta);
    if (dot < 0)
        s1 = -s1;
    out[0] = (x0 * s0 + x1 * s1) * d;
    out[1] = (y0 * s0 + y1 * s1) * d;
    out[2] = (z0 * s0 + z1 * s1) * d;
    out[3] = (w0 * s0 + w1 * s1) * d;
}

/* First index in [lo, n) whose stamp is > t (bisect_right). */
static Py_ssize_t after(const int64_t *s, Py_ssize_t lo, Py_ssize_t n, int64_t t)
{
    Py_ssize_t hi = n;
    while (lo < hi) {
        Py_ssize_t mid = lo + (hi - lo) / 2;
        if (t < s[mid])
            hi = mid;
        else
            lo = mid + 1;
    }
    return lo;
}

#endif /* DQ_FK_TF_MATH_H */
