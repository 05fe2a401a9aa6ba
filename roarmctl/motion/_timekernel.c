/* The compiled inner loops of roarmctl's timing path (roarmctl/motion/timing.py, which calls them).
 *
 * - locate: for times x, the interval of TOPP-RA's profile each lies in and the time into it
 *   (``_Profile.eval``'s searchsorted, clip and subtraction);
 * - jerk_ok: the sampled joint jerk of the moving-average-filtered profile against the limits
 *   (``_jerk_ok``), stopping at the first sample over a limit;
 * - plateau_cap: the bisection of ``_plateau_cap`` for the path speed cap of a cruise.
 *
 * Each computes what the numpy code in timing.py computes, operation for operation and in the same
 * order (it is built with -fno-fast-math -ffp-contract=off: no reassociation, no fused multiply-add),
 * so its answers are the numpy code's, bit for bit; tests/test_timekernel.py compares them. Two
 * things stay in numpy because C cannot reproduce them exactly: tau**3 (numpy's power may be a SIMD
 * routine, not libm's pow) is computed by the caller between locate and jerk_ok, and the sums of
 * plateau_cap follow numpy's pairwise summation (reproduced here: ``pairwise_sum``).
 *
 * The spline is toppra's SplineInterpolator (scipy's CubicSpline): its first and second derivatives
 * are scipy PPoly objects, evaluated here as scipy's evaluate does (interval with x[i] <= s < x[i+1],
 * the last one closed; the polynomial summed from the constant term up with powers of s - x[i]).
 *
 * No numpy headers: arrays come in through the buffer protocol, C-contiguous float64 / int64 as
 * timing.py makes them; lengths are checked.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>

static int get_in(PyObject *o, Py_buffer *b) { return PyObject_GetBuffer(o, b, PyBUF_C_CONTIGUOUS); }
static int get_out(PyObject *o, Py_buffer *b) { return PyObject_GetBuffer(o, b, PyBUF_C_CONTIGUOUS | PyBUF_WRITABLE); }

/* Number of knots[0..n) that are <= x (numpy's searchsorted side="right"), starting the walk at ``j``
 * (any start gives the same count on a non-decreasing array; a nearby one is fast). */
static Py_ssize_t count_le(const double *knots, Py_ssize_t n, double x, Py_ssize_t j) {
    if (j < 0) j = 0;
    if (j > n) j = n;
    while (j < n && knots[j] <= x) j++;
    while (j > 0 && !(knots[j - 1] <= x)) j--;
    return j;
}

/* locate(knots, T, x, idx, tau): idx[k] = clip(searchsorted(knots, x[k], "right") - 1, 0, len(knots) - 2),
 * tau[k] = clip(x[k], 0, T) - knots[idx[k]]. */
static PyObject *locate(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "locate() takes 5 arguments");
        return NULL;
    }
    double T = PyFloat_AsDouble(args[1]);
    if (T == -1.0 && PyErr_Occurred()) return NULL;
    Py_buffer b[4];
    PyObject *const in[4] = {args[0], args[2], args[3], args[4]};
    int got = 0;
    PyObject *result = NULL;
    for (; got < 4; got++)
        if ((got < 2 ? get_in(in[got], &b[got]) : get_out(in[got], &b[got])) < 0) goto done;
    Py_ssize_t nk = b[0].len / 8, n = b[1].len / 8;
    if (nk < 2 || b[2].len != 8 * n || b[3].len != 8 * n) {
        PyErr_SetString(PyExc_ValueError, "locate(): knots (K>=2,), x (N,), idx (N,) int64, tau (N,) float64 expected");
        goto done;
    }
    const double *knots = b[0].buf, *x = b[1].buf;
    int64_t *idx = b[2].buf;
    double *tau = b[3].buf;
    Py_ssize_t j = 0, last = nk - 2;
    for (Py_ssize_t k = 0; k < n; k++) {
        j = count_le(knots, nk, x[k], j);
        Py_ssize_t i = j - 1;
        if (i < 0) i = 0;
        if (i > last) i = last;
        double xc = x[k];
        if (xc < 0.0) xc = 0.0;
        if (xc > T) xc = T;
        idx[k] = i;
        tau[k] = xc - knots[i];
    }
    result = Py_None;
    Py_INCREF(result);
done:
    for (int k = 0; k < got; k++) PyBuffer_Release(&b[k]);
    return result;
}

typedef struct {
    const double *t, *s, *sd, *sdd, *S;
    double T, s_end;
} Prof;

/* _Profile.eval at one time x (interval i, tau, tau**3 from locate and numpy): integral of s, s, sdot, sddot. */
static void prof_eval(const Prof *p, double x, Py_ssize_t i, double tau, double cube, double *S, double *s, double *v,
                      double *a) {
    double acc = p->sdd[i], vel = p->sd[i], s0 = p->s[i];
    double tau2 = tau * tau;
    double pos = s0 + vel * tau + acc * tau2 / 2;
    double integ = p->S[i] + s0 * tau + vel * tau2 / 2 + acc * cube / 6;
    int before = x < 0, after = x > p->T;
    *S = before ? 0.0 : (after ? integ + p->s_end * (x - p->T) : integ);
    *v = (before || after) ? 0.0 : vel + acc * tau;
    *a = (before || after) ? 0.0 : acc;
    *s = before ? 0.0 : pos;
}

/* scipy's interval of a PPoly with breakpoints bx[0..m]: x[i] <= s < x[i+1], s == x[m] in the last one,
 * extrapolating below and above; ``hint`` is where the walk starts. */
static Py_ssize_t ppoly_interval(const double *bx, Py_ssize_t m, double s, Py_ssize_t hint) {
    if (s < bx[0]) return 0;
    if (s >= bx[m]) return m - 1;
    Py_ssize_t i = hint < 0 ? 0 : (hint > m - 1 ? m - 1 : hint);
    while (i < m - 1 && s >= bx[i + 1]) i++;
    while (i > 0 && s < bx[i]) i--;
    return i;
}

/* jerk_ok(t, s, sd, sdd, S, T, s_end, x, idx, tau, cube, w, dt, bx, c1, c2, lim) -> bool
 * Profile arrays t, s, sd, S (N+1,), sdd (N,); x (2F,): the fine grid t_k, then t_k - w; idx, tau, cube (2F,)
 * from locate and numpy; bx (m+1,) spline breakpoints; c1 (3, m, n), c2 (2, m, n) the coefficients of the
 * spline's first and second derivatives; lim (n,). As timing._jerk_ok: the filtered s, sdot, sddot at t_k,
 * qdd = q'(s) sddot + q''(s) sdot^2, and |qdd_{k+1} - qdd_k| / dt <= lim for every k and joint. */
static PyObject *jerk_ok(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 17) {
        PyErr_SetString(PyExc_TypeError, "jerk_ok() takes 17 arguments");
        return NULL;
    }
    double T = PyFloat_AsDouble(args[5]), s_end = PyFloat_AsDouble(args[6]), w = PyFloat_AsDouble(args[11]),
           dt = PyFloat_AsDouble(args[12]);
    if (PyErr_Occurred()) return NULL;
    enum { NB = 13 };
    PyObject *const in[NB] = {args[0], args[1], args[2], args[3], args[4], args[7], args[8], args[9], args[10],
                              args[13], args[14], args[15], args[16]};
    Py_buffer b[NB];
    int got = 0;
    PyObject *result = NULL;
    double *prev = NULL;
    for (; got < NB; got++)
        if (get_in(in[got], &b[got]) < 0) goto done;
    Py_ssize_t np1 = b[0].len / 8, nx = b[5].len / 8, m = b[9].len / 8 - 1, n = b[12].len / 8;
    if (np1 < 2 || b[1].len != 8 * np1 || b[2].len != 8 * np1 || b[3].len != 8 * (np1 - 1) || b[4].len != 8 * np1 ||
        nx % 2 || b[6].len != 8 * nx || b[7].len != 8 * nx || b[8].len != 8 * nx || m < 1 || n < 1 ||
        b[10].len != 8 * 3 * m * n || b[11].len != 8 * 2 * m * n) {
        PyErr_SetString(PyExc_ValueError, "jerk_ok(): array lengths do not match");
        goto done;
    }
    Prof p = {b[0].buf, b[1].buf, b[2].buf, b[3].buf, b[4].buf, T, s_end};
    const double *x = b[5].buf, *tau = b[7].buf, *cube = b[8].buf, *bx = b[9].buf, *c1 = b[10].buf,
                 *c2 = b[11].buf, *lim = b[12].buf;
    const int64_t *idx = b[6].buf;
    Py_ssize_t F = nx / 2, mn = m * n;
    for (Py_ssize_t k = 0; k < nx; k++)
        if (idx[k] < 0 || idx[k] > np1 - 2) {
            PyErr_SetString(PyExc_ValueError, "jerk_ok(): interval index out of range");
            goto done;
        }
    prev = PyMem_Malloc(sizeof(double) * n);
    if (prev == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    int ok = 1;
    Py_ssize_t hint = 0;
    for (Py_ssize_t k = 0; k < F && ok; k++) {
        double S1, s1, v1, a1, S0, s0, v0, a0;
        prof_eval(&p, x[k], idx[k], tau[k], cube[k], &S1, &s1, &v1, &a1);
        prof_eval(&p, x[F + k], idx[F + k], tau[F + k], cube[F + k], &S0, &s0, &v0, &a0);
        double s = (S1 - S0) / w;
        if (s < 0.0) s = 0.0;
        if (s > s_end) s = s_end;
        double sd = (s1 - s0) / w, sdd = (v1 - v0) / w, sd2 = sd * sd;
        Py_ssize_t i = hint = ppoly_interval(bx, m, s, hint);
        double u = s - bx[i], u2 = u * u;
        for (Py_ssize_t j = 0; j < n; j++) {
            Py_ssize_t o = i * n + j;
            double p1 = c1[2 * mn + o] + c1[mn + o] * u + c1[o] * u2;
            double p2 = c2[mn + o] + c2[o] * u;
            double q = p1 * sdd + p2 * sd2;
            if (k > 0 && !(fabs(q - prev[j]) / dt <= lim[j])) {
                ok = 0;
                break;
            }
            prev[j] = q;
        }
    }
    result = PyBool_FromLong(ok);
done:
    PyMem_Free(prev);
    for (int k = 0; k < got; k++) PyBuffer_Release(&b[k]);
    return result;
}

/* numpy's sum of a contiguous float64 array (pairwise, blocks of 128 in 8 accumulators: numpy's
 * DOUBLE_pairwise_sum), so that plateau_cap's sums are np.sum's. */
static double pairwise_sum(const double *a, Py_ssize_t n) {
    if (n < 8) {
        double res = 0.;
        for (Py_ssize_t i = 0; i < n; i++) res += a[i];
        return res;
    }
    if (n <= 128) {
        double r[8], res;
        Py_ssize_t i;
        for (int j = 0; j < 8; j++) r[j] = a[j];
        for (i = 8; i < n - (n % 8); i += 8)
            for (int j = 0; j < 8; j++) r[j] += a[i + j];
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; i++) res += a[i];
        return res;
    }
    Py_ssize_t n2 = n / 2;
    n2 -= n2 % 8;
    return pairwise_sum(a, n2) + pairwise_sum(a + n2, n - n2);
}

/* plateau_cap(x_lo, x_hi, span, ds, hold, top, work) -> lo: timing._plateau_cap's 30-step bisection of the
 * speed cap c in [0, top] with cruise(c) = sum(frac * ds) / c >= hold; arrays (G-1,), work (G-1,) scratch. */
static PyObject *plateau_cap(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 7) {
        PyErr_SetString(PyExc_TypeError, "plateau_cap() takes 7 arguments");
        return NULL;
    }
    double hold = PyFloat_AsDouble(args[4]), top = PyFloat_AsDouble(args[5]);
    if (PyErr_Occurred()) return NULL;
    Py_buffer b[5];
    PyObject *const in[5] = {args[0], args[1], args[2], args[3], args[6]};
    int got = 0;
    PyObject *result = NULL;
    for (; got < 5; got++)
        if ((got < 4 ? get_in(in[got], &b[got]) : get_out(in[got], &b[got])) < 0) goto done;
    Py_ssize_t n = b[0].len / 8;
    for (int k = 1; k < 5; k++)
        if (b[k].len != 8 * n) {
            PyErr_SetString(PyExc_ValueError, "plateau_cap(): arrays of one length expected");
            goto done;
        }
    const double *x_lo = b[0].buf, *x_hi = b[1].buf, *span = b[2].buf, *ds = b[3].buf;
    double *work = b[4].buf;
    double lo = 0.0, hi = top;
    for (int it = 0; it < 30; it++) {
        double mid = 0.5 * (lo + hi), c2 = mid * mid;
        for (Py_ssize_t i = 0; i < n; i++) {
            double frac = x_lo[i] >= c2 ? 1.0 : (x_hi[i] <= c2 ? 0.0 : (x_hi[i] - c2) / span[i]);
            work[i] = frac * ds[i];
        }
        double cruise = pairwise_sum(work, n) / mid;
        if (cruise >= hold)
            lo = mid;
        else
            hi = mid;
    }
    result = PyFloat_FromDouble(lo);
done:
    for (int k = 0; k < got; k++) PyBuffer_Release(&b[k]);
    return result;
}

static PyMethodDef methods[] = {
    {"locate", (PyCFunction)(void (*)(void))locate, METH_FASTCALL, "Profile interval and time into it (see timing.py)."},
    {"jerk_ok", (PyCFunction)(void (*)(void))jerk_ok, METH_FASTCALL, "Filtered profile's sampled jerk within limits."},
    {"plateau_cap", (PyCFunction)(void (*)(void))plateau_cap, METH_FASTCALL, "Bisection of a cruise's speed cap."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef moddef = {PyModuleDef_HEAD_INIT, "_timekernel", "roarmctl's compiled timing loops.", -1, methods};

PyMODINIT_FUNC PyInit__timekernel(void) { return PyModule_Create(&moddef); }
