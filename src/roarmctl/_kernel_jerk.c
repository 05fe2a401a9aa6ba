/* The jerk check of the timing's filter search (src/roarmctl/motion/jerk_filter.py, _jerk_ok), one sample after the
 * other, stopping at the first pair of samples that is certainly over a limit; compiled into roarmctl._kernel
 * (registered in _kernel.c's method table).
 *
 * The profile (jerk_filter.Profile: TOPP-RA's result in time, constant path acceleration between grid points) is
 * filtered by the moving average of width w at t = 0, dt, 2 dt, ...: s_w = (S(t) - S(t - w)) / w clipped to
 * [0, s_end], sdot_w = (s(t) - s(t - w)) / w, sddot_w = (sdot(t) - sdot(t - w)) / w, S the integral of s; the joint
 * accelerations are qdd = q'(s_w) sddot_w + q''(s_w) sdot_w^2 with toppra's spline's derivatives (its scipy PPoly
 * coefficients), and a pair of samples is within the limits when |qdd(t + dt) - qdd(t)| / dt <= jmax (1 + 1e-9),
 * joint by joint: the same quantities as the numpy check, in another order of operations. So its answer is taken
 * only where it is certain: a ratio of jerk to limit more than ``tol`` above 1 fails the check, a pass needs every
 * ratio more than ``tol`` below 1; anything else (or a NaN) is left to the numpy check (status -1). Rounding differs
 * between the two by about 1e-12 of a limit, far inside any ``tol`` the caller gives (1e-6).
 *
 * Most widths the search asks fail near the start, where the filter first meets a step of the path acceleration:
 * sampled from the start, such a check stops after a tenth of the grid or so, where numpy computed all of it.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#define JERK_MAXDOF 64

/* A profile and the interval of its grid the last evaluation fell in (times asked in order: found by stepping). */
typedef struct {
    const double *t;      /* (G,) grid times, t[0] = 0 */
    const double *st;     /* (5, G - 1) per interval: start time, s, sdot, integral of s, sddot */
    Py_ssize_t n;         /* intervals, G - 1 */
    double T, s_end;
    Py_ssize_t i;
} JerkProfile;

/* Integral of s, s and sdot of the profile at time x: at rest before 0 and after T (as Profile.eval). */
static void profile_at(JerkProfile *p, double x, double *S, double *s, double *sd) {
    if (x < 0.0) {
        *S = *s = *sd = 0.0;
        return;
    }
    double xc = x < p->T ? x : p->T;
    Py_ssize_t i = p->i, n = p->n;
    while (i + 1 < n && p->t[i + 1] <= xc) i++;
    while (i > 0 && p->t[i] > xc) i--;
    p->i = i;
    double t0 = p->st[i], s0 = p->st[n + i], v = p->st[2 * n + i], S0 = p->st[3 * n + i], a = p->st[4 * n + i];
    double tau = xc - t0, tau2 = tau * tau;
    *s = s0 + v * tau + a * tau2 / 2;
    *S = S0 + s0 * tau + v * tau2 / 2 + a * tau2 * tau / 6;
    *sd = v + a * tau;
    if (x > p->T) {
        *S += p->s_end * (x - p->T);
        *sd = 0.0;
    }
}

/* jerk_check(t, starts, T, s_end, x, coef, w, dt, count, jmax, tol) -> (status, pair):
 * t (G,), starts (5, G - 1): the profile (Profile.t, Profile._starts); x (K,) and coef (5, K - 1, n): the spline's
 * breakpoints and the coefficients of its first (3) and second (2) derivatives; ``count`` samples every ``dt`` s from
 * 0 at filter width ``w`` s; jmax (n,) rad/s^3. status 1: every pair certainly within; 0: the pair (pair, pair + 1)
 * is certainly over (the first such pair); -1: not certain either way. */
PyObject *jerk_check(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 11) {
        PyErr_SetString(PyExc_TypeError, "jerk_check() takes 11 arguments");
        return NULL;
    }
    static const int bufs[5] = {0, 1, 4, 5, 9};
    Py_buffer b[5];
    int got = 0;
    PyObject *result = NULL;
    for (; got < 5; got++)
        if (PyObject_GetBuffer(args[bufs[got]], &b[got], PyBUF_C_CONTIGUOUS) < 0) goto done;
    double T = PyFloat_AsDouble(args[2]), s_end = PyFloat_AsDouble(args[3]), w = PyFloat_AsDouble(args[6]);
    double dt = PyFloat_AsDouble(args[7]), tol = PyFloat_AsDouble(args[10]);
    Py_ssize_t count = PyLong_AsSsize_t(args[8]);
    if (PyErr_Occurred()) goto done;
    Py_ssize_t G = b[0].len / 8, K = b[2].len / 8, n = b[4].len / 8;
    if (G < 2 || K < 2 || n < 1 || n > JERK_MAXDOF || b[0].len != 8 * G || b[1].len != 8 * 5 * (G - 1)
        || b[2].len != 8 * K || b[3].len != 8 * 5 * (K - 1) * n || b[4].len != 8 * n || !(w > 0.0) || !(dt > 0.0)
        || count < 0) {
        PyErr_SetString(PyExc_ValueError, "jerk_check(): inconsistent array lengths or a width or step not > 0");
        goto done;
    }
    JerkProfile now = {b[0].buf, b[1].buf, G - 1, T, s_end, 0}, back = now;
    const double *x = b[2].buf, *c = b[3].buf, *jmax = b[4].buf;
    Py_ssize_t m = K - 1, iz = 0;
    double prev[JERK_MAXDOF], lim[JERK_MAXDOF];
    for (Py_ssize_t j = 0; j < n; j++) lim[j] = jmax[j] * (1 + 1e-9);
    int status = 1;
    Py_ssize_t pair = -1;
    for (Py_ssize_t k = 0; k < count && pair < 0; k++) {
        double tk = k * dt, S1, s1, v1, S0, s0, v0;
        profile_at(&now, tk, &S1, &s1, &v1);
        profile_at(&back, tk - w, &S0, &s0, &v0);
        double s = (S1 - S0) / w;
        s = s < 0.0 ? 0.0 : (s > s_end ? s_end : s);
        double sd = (s1 - s0) / w, sdd = (v1 - v0) / w;
        while (iz + 1 < m && x[iz + 1] <= s) iz++;
        while (iz > 0 && x[iz] > s) iz--;
        double z = s - x[iz];
        for (Py_ssize_t j = 0; j < n; j++) {
            const double *cj = c + iz * n + j;  /* coefficient r of interval iz, joint j: cj[r * m * n] */
            double q1 = cj[2 * m * n] + cj[m * n] * z + cj[0] * (z * z);
            double q2 = cj[4 * m * n] + cj[3 * m * n] * z;
            double qdd = q1 * sdd + q2 * (sd * sd);
            if (k > 0) {
                double r = fabs(qdd - prev[j]) / dt / lim[j];
                if (!(r <= 1.0 - tol)) {
                    if (r > 1.0 + tol) {
                        status = 0;
                        pair = k - 1;
                    } else {
                        status = status == 1 ? -1 : status;
                    }
                }
            }
            prev[j] = qdd;
        }
    }
    result = Py_BuildValue("(in)", status, pair);
done:
    for (int j = 0; j < got; j++) PyBuffer_Release(&b[j]);
    return result;
}
