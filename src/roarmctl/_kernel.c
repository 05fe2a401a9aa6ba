/* roarmctl's compiled kernel: the library's one forward kinematics, its Jacobian and its inverse dynamics
 * (recursive Newton-Euler), and the state checker of src/roarmctl/motion/collision.py.
 *
 * Kinematics (src/roarmctl/robot/kinematics.py packs the tables, see Kinematics._pack; robot/dynamics.py adds
 * the link bodies):
 *   fk          every link frame of a batch of configurations (Kinematics.frames4, the library's FK);
 *   jacobian    TCP pose and geometric Jacobian (Kinematics.pose_jacobian), tcp_velocity J_v qd;
 *   rnea        joint torques of a batch of states (dynamics.inverse_dynamics).
 * Checker: for each arm state of a batch, in one C loop: joint limits, the FK above, the smallest singular
 * value of the translational Jacobian (the singularity margin), every collision shape's world pose, and
 * conservative pre-filters that clear (shape, item) and (shape, shape) pairs that are certainly apart:
 * bounding sphere vs the item's world box, world boxes, then the separating-axis test of the two oriented
 * bounding boxes (each shape lies inside its box, so a separating axis of the boxes separates the shapes).
 * The pairs that no filter clears are returned as candidates; FCL (python-fcl) decides those.
 *
 * No numpy headers: arrays come in through the buffer protocol, C-contiguous float64 / int64 / uint8 as
 * the Python side makes them. Lengths are checked against the packed headers. Built with
 * -O3 -fno-fast-math -ffp-contract=off (pyproject.toml): no FMA contraction, the same sums everywhere.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#define MAXDOF 64
#define MAXLINKS 256
#define MAXSHAPES 512
#define SEP_TOL 1e-9   /* m: boxes count as apart only when separated by more than this */
#define PAR_EPS 1e-12  /* added to |R| in the SAT, for edges that are (nearly) parallel */

/* ------------------------------------------------------------------------------------------ kinematics
 * Kinematic tables (Kinematics._pack). Ints: header KHEADER (dof, n_links, n_steps, n_const, n_chain, tcp,
 * n_joints), const link indices, steps (STEPI each), TCP chain (CHAINI each), joints (JOINTI each).
 * Floats: constant link frames (16 each), steps (STEPF each), chain (CHAINF each), joints (JOINTF each).
 * Steps are the joints that move a link (links reached from the root through fixed joints only are
 * constant); the chain is the moving joints between the root and the TCP (each adds to one Jacobian column:
 * its own, or, multiplier times, its leader's for a mimic joint; n_cols columns, the arm joints); the
 * joints are every joint of the tree in order (the dynamics). */
#define KHEADER 7
#define STEPI 5    /* kind (0 fixed, 1 revolute about local z, 2 revolute about another axis, 3 prismatic),
                      parent link, child link, q index, has post */
#define STEPF 66   /* offset, A (16), B (16), C (16), post (16), multiplier; see fk(). The joint value is
                      multiplier * q + offset (1 for every joint but a URDF mimic joint's) */
#define CHAINI 3   /* parent link, kind (0 revolute, 1 prismatic), the Jacobian column its motion adds to */
#define CHAINF 7   /* joint axis (3) and joint origin point (3), both in the parent link's frame; the multiplier
                    * of the column's joint (1, or a mimic joint's: it moves multiplier times as fast) */
#define JOINTI 6   /* kind (0 fixed, 1 revolute, 2 prismatic), parent link, child link, q index or -1,
                      axis at the child's origin (revolute or fixed without post), joint above the parent or -1 */
#define JOINTF 19  /* axis (3, joint frame), origin (16) */
#define BODYF 14   /* per link: has a body (0/1), mass, com (3, link frame), inertia about the com (9, link axes) */

typedef struct {
    int64_t dof, n_links, n_steps, n_const, n_chain, tcp, n_joints;
    int64_t n_cols;  /* Jacobian columns: the arm joints (a mimic joint of the chain adds to its leader's) */
    const int64_t *const_idx, *steps, *chain, *joints;
    const double *const_fr, *stepf, *chainf, *jointf;
} Kin;

/* Parses the kinematic block at I[0..ni), F[0..nf); -1 with a ValueError when the lengths do not match. */
static int parse_kin(Kin *k, const int64_t *I, Py_ssize_t ni, const double *F, Py_ssize_t nf) {
    if (ni < KHEADER) goto bad;
    k->dof = I[0]; k->n_links = I[1]; k->n_steps = I[2]; k->n_const = I[3]; k->n_chain = I[4]; k->tcp = I[5];
    k->n_joints = I[6];
    if (k->dof < 0 || k->n_links < 1 || k->n_steps < 0 || k->n_const < 1 || k->n_chain < 0 || k->n_chain > MAXDOF
        || k->n_joints < 0 || k->tcp < 0 || k->tcp >= k->n_links)
        goto bad;
    if (ni != KHEADER + k->n_const + STEPI * k->n_steps + CHAINI * k->n_chain + JOINTI * k->n_joints) goto bad;
    if (nf != 16 * k->n_const + STEPF * k->n_steps + CHAINF * k->n_chain + JOINTF * k->n_joints) goto bad;
    const int64_t *p = I + KHEADER;
    k->const_idx = p; p += k->n_const;
    k->steps = p; p += STEPI * k->n_steps;
    k->chain = p; p += CHAINI * k->n_chain;
    k->joints = p;
    const double *q = F;
    k->const_fr = q; q += 16 * k->n_const;
    k->stepf = q; q += STEPF * k->n_steps;
    k->chainf = q; q += CHAINF * k->n_chain;
    k->jointf = q;
    /* every index in range, so that no table can make the loops read or write outside their arrays */
    for (int64_t c = 0; c < k->n_const; c++)
        if (k->const_idx[c] < 0 || k->const_idx[c] >= k->n_links) goto bad;
    for (int64_t s = 0; s < k->n_steps; s++) {
        const int64_t *si = k->steps + STEPI * s;
        if (si[0] < 0 || si[0] > 3 || si[1] < 0 || si[1] >= k->n_links || si[2] < 0 || si[2] >= k->n_links
            || (si[0] != 0 && (si[3] < 0 || si[3] >= k->dof)))
            goto bad;
    }
    k->n_cols = 0;
    for (int64_t j = 0; j < k->n_chain; j++) {
        const int64_t *ci = k->chain + CHAINI * j;
        if (ci[0] < 0 || ci[0] >= k->n_links || ci[2] < 0 || ci[2] >= k->n_chain) goto bad;
        if (ci[2] + 1 > k->n_cols) k->n_cols = ci[2] + 1;
    }
    for (int64_t j = 0; j < k->n_joints; j++) {
        const int64_t *ji = k->joints + JOINTI * j;
        if (ji[0] < 0 || ji[0] > 2 || ji[1] < 0 || ji[1] >= k->n_links || ji[2] < 0 || ji[2] >= k->n_links
            || ji[3] < -1 || ji[3] >= k->dof || (ji[0] != 0 && ji[3] < 0) || ji[5] < -1 || ji[5] >= k->n_joints
            || (ji[1] != 0 && ji[5] < 0))
            goto bad;
    }
    return 0;
bad:
    PyErr_SetString(PyExc_ValueError, "_kernel: kinematic tables do not match their header (if roarmctl's source was updated, its compiled kernel is older: rebuild it with `make install` or `pip install .`)");
    return -1;
}

/* out = a @ b for homogeneous transforms (bottom rows 0 0 0 1): the terms with the bottom row's zeros
 * are left out, the others summed in the order of the full 4 x 4 product (same numbers). */
static inline void mat4mul(const double *a, const double *b, double *out) {
    for (int r = 0; r < 3; r++) {
        const double a0 = a[4 * r], a1 = a[4 * r + 1], a2 = a[4 * r + 2];
        out[4 * r] = a0 * b[0] + a1 * b[4] + a2 * b[8];
        out[4 * r + 1] = a0 * b[1] + a1 * b[5] + a2 * b[9];
        out[4 * r + 2] = a0 * b[2] + a1 * b[6] + a2 * b[10];
        out[4 * r + 3] = a0 * b[3] + a1 * b[7] + a2 * b[11] + a[4 * r + 3];
    }
    out[12] = out[13] = out[14] = 0.0;
    out[15] = 1.0;
}

/* The matrix of step s (parent link frame -> child before any post) at joint value qv: C itself for a fixed step,
 * else written to mm (16, of which fk reads the top 12). */
static inline const double *step_matrix(const Kin *m, int64_t s, double qv, double *mm) {
    int64_t kind = m->steps[STEPI * s];
    const double *sf = m->stepf + STEPF * s;
    const double *A = sf + 1, *B = sf + 17, *C = sf + 33;
    if (kind == 0) {           /* fixed */
        return C;
    } else if (kind == 1) {    /* revolute about local z: origin @ Rz(q) = cos A + sin B + C */
        double ang = sf[65] * qv + sf[0], c = cos(ang), sn = sin(ang);
        for (int k = 0; k < 12; k++) mm[k] = c * A[k] + sn * B[k] + C[k];  /* mat4mul reads no bottom row */
    } else if (kind == 2) {    /* revolute about the unit axis A[0..2]: origin @ Rodrigues */
        double ang = sf[65] * qv + sf[0], c = cos(ang), sn = sin(ang), v = 1.0 - c;
        double x = A[0], y = A[1], z = A[2], r[16] = {0};
        r[0] = c + x * x * v;     r[1] = x * y * v - z * sn; r[2] = x * z * v + y * sn;
        r[4] = y * x * v + z * sn; r[5] = c + y * y * v;     r[6] = y * z * v - x * sn;
        r[8] = z * x * v - y * sn; r[9] = z * y * v + x * sn; r[10] = c + z * z * v;
        r[15] = 1.0;
        mat4mul(C, r, mm);
    } else {                   /* prismatic: origin, moved by d along origin_rot @ axis (in A) */
        double d = sf[65] * qv + sf[0];
        memcpy(mm, C, 16 * sizeof(double));
        mm[3] += d * A[0]; mm[7] += d * A[1]; mm[11] += d * A[2];
    }
    return mm;
}

/* Step matrices that a batch holds fixed (the joint value is the same in every state of the call: a joint outside the
 * arm, e.g. the gripper at its set value), made once for the call by step_matrix itself: the same numbers. */
typedef struct {
    uint8_t on[MAXLINKS];
    double mm[MAXLINKS][16];
} FkHeld;

/* Link frames Fr (n_links x 16, row-major 4x4, root frame) for the full configuration qf (dof); the steps that held
 * marks take their matrix from it (held may be NULL). */
static void fk_held(const Kin *m, const double *qf, double *Fr, const FkHeld *held) {
    for (int64_t c = 0; c < m->n_const; c++)
        memcpy(Fr + 16 * m->const_idx[c], m->const_fr + 16 * c, 16 * sizeof(double));
    double mm[16], t[16];
    for (int64_t s = 0; s < m->n_steps; s++) {
        const int64_t *si = m->steps + STEPI * s;
        int64_t parent = si[1], child = si[2], qi = si[3], has_post = si[4];
        const double *P = m->stepf + STEPF * s + 49;
        const double *mp = held && held->on[s] ? held->mm[s] : step_matrix(m, s, si[0] == 0 ? 0.0 : qf[qi], mm);
        if (has_post) {
            mat4mul(Fr + 16 * parent, mp, t);
            mat4mul(t, P, Fr + 16 * child);
        } else {
            mat4mul(Fr + 16 * parent, mp, Fr + 16 * child);
        }
    }
}

static void fk(const Kin *m, const double *qf, double *Fr) { fk_held(m, qf, Fr, NULL); }

/* Geometric Jacobian at the TCP from the link frames Fr: the motion of the chain's joint j is (z x (p_tcp - o), z)
 * for a revolute joint and (z, 0) for a prismatic one, with z the joint axis and o its origin point in the root
 * frame; it is column ci[2] (6 values: linear, angular), or multiplier times it is added there (a mimic joint of the
 * chain moves with its leader). With linear_only, the angular rows are not written. */
static void jac_cols(const Kin *m, const double *Fr, double *J, int linear_only) {
    const double *T = Fr + 16 * m->tcp;
    uint8_t seen[MAXDOF] = {0};
    int nr = linear_only ? 3 : 6;
    for (int64_t j = 0; j < m->n_chain; j++) {
        const int64_t *ci = m->chain + CHAINI * j;
        const double *cf = m->chainf + CHAINF * j;
        const double *Pa = Fr + 16 * ci[0], *la = cf, *pt = cf + 3, mult = cf[6];
        double o[3], z[3], v[6];
        for (int r = 0; r < 3; r++) {
            o[r] = Pa[4 * r + 3] + Pa[4 * r] * pt[0] + Pa[4 * r + 1] * pt[1] + Pa[4 * r + 2] * pt[2];
            z[r] = Pa[4 * r] * la[0] + Pa[4 * r + 1] * la[1] + Pa[4 * r + 2] * la[2];
        }
        if (ci[1] == 0) {
            double d[3] = {T[3] - o[0], T[7] - o[1], T[11] - o[2]};
            v[0] = z[1] * d[2] - z[2] * d[1];
            v[1] = z[2] * d[0] - z[0] * d[2];
            v[2] = z[0] * d[1] - z[1] * d[0];
            v[3] = z[0]; v[4] = z[1]; v[5] = z[2];
        } else {
            v[0] = z[0]; v[1] = z[1]; v[2] = z[2];
            v[3] = v[4] = v[5] = 0.0;
        }
        double *col = J + 6 * ci[2];
        if (!seen[ci[2]] && mult == 1.0) {  /* the column's own joint: its values as they are */
            for (int r = 0; r < nr; r++) col[r] = v[r];
        } else {
            if (!seen[ci[2]])
                for (int r = 0; r < nr; r++) col[r] = 0.0;
            for (int r = 0; r < nr; r++) col[r] += mult * v[r];
        }
        seen[ci[2]] = 1;
    }
}

static inline void cross3(const double *a, const double *b, double *out) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* Work arrays of rnea_state, per link (3 each) and per joint (3 each). */
typedef struct {
    double *w, *dw, *a, *com, *force, *moment, *f_sub, *n_sub, *axes, *piv;
    uint8_t *spins, *heavy;
} RneaWork;

/* Acceleration of the point r fixed to link k (r in the root frame). */
static inline void point_acc(const RneaWork *W, const double *Fr, int64_t k, const double *r, int moving, double *out) {
    const double *ak = W->a + 3 * k;
    if (!moving || !W->spins[k]) {
        out[0] = ak[0]; out[1] = ak[1]; out[2] = ak[2];
        return;
    }
    const double *w = W->w + 3 * k, *dw = W->dw + 3 * k;
    double d[3] = {r[0] - Fr[16 * k + 3], r[1] - Fr[16 * k + 7], r[2] - Fr[16 * k + 11]}, t1[3], wd[3], t2[3];
    cross3(dw, d, t1);
    cross3(w, d, wd);
    cross3(w, wd, t2);
    for (int i = 0; i < 3; i++) out[i] = ak[i] + t1[i] + t2[i];
}

/* Recursive Newton-Euler for one state (root-frame coordinates): the forward pass carries each link's angular
 * velocity and acceleration and the linear acceleration of its frame origin (gravity as an upward acceleration
 * of the root), the backward pass sums each subtree's force and its moment about the joint's pivot, and the
 * torque is that moment (force, for a prismatic joint) projected on the joint axis. A mimic joint's share adds
 * to the joint it follows. At rest (qd = qdd = 0) the velocity terms are skipped (they are zero). */
static void rnea_state(const Kin *m, const double *Fr, const double *qd, const double *qdd, double gravity,
                       const double *bodies, RneaWork *W, double *tau) {
    int64_t L = m->n_links, nj = m->n_joints;
    int moving = 0;
    for (int64_t i = 0; i < m->dof; i++)
        if (qd[i] != 0.0 || qdd[i] != 0.0) moving = 1;
    memset(W->w, 0, 3 * L * sizeof(double));
    memset(W->dw, 0, 3 * L * sizeof(double));
    memset(W->a, 0, 3 * L * sizeof(double));
    memset(W->spins, 0, L);
    W->a[2] = gravity;
    for (int64_t j = 0; j < nj; j++) {
        const int64_t *ji = m->joints + JOINTI * j;
        const double *jf = m->jointf + JOINTF * j;
        int64_t kind = ji[0], p = ji[1], c = ji[2], qi = ji[3], at_origin = ji[4];
        const double *ax = jf, *O = jf + 3, *Fc = Fr + 16 * c, *Fp = Fr + 16 * p;
        double *z = W->axes + 3 * j, *pv = W->piv + 3 * j;
        if (at_origin) {  /* child = before @ rotation about the axis (or nothing): same origin, same axis */
            for (int r = 0; r < 3; r++) {
                z[r] = Fc[4 * r] * ax[0] + Fc[4 * r + 1] * ax[1] + Fc[4 * r + 2] * ax[2];
                pv[r] = Fc[4 * r + 3];
            }
        } else {
            double before[16];
            mat4mul(Fp, O, before);
            for (int r = 0; r < 3; r++) {
                z[r] = before[4 * r] * ax[0] + before[4 * r + 1] * ax[1] + before[4 * r + 2] * ax[2];
                pv[r] = before[4 * r + 3];
            }
        }
        double *wc = W->w + 3 * c, *dwc = W->dw + 3 * c, *ac = W->a + 3 * c;
        const double *wp = W->w + 3 * p, *dwp = W->dw + 3 * p;
        double org_c[3] = {Fc[3], Fc[7], Fc[11]};
        if (kind == 1 && !moving) {
            memcpy(ac, W->a + 3 * p, 3 * sizeof(double));
        } else if (kind == 1) {
            double wz[3] = {qd[qi] * z[0], qd[qi] * z[1], qd[qi] * z[2]}, t[3] = {0, 0, 0};
            if (W->spins[p]) cross3(wp, wz, t);
            for (int r = 0; r < 3; r++) {
                wc[r] = wp[r] + wz[r];
                dwc[r] = dwp[r] + qdd[qi] * z[r] + t[r];
            }
            W->spins[c] = 1;
            double a_piv[3];  /* the pivot lies on the axis: it moves with the parent and with the child alike */
            point_acc(W, Fr, p, pv, moving, a_piv);
            if (at_origin) {
                memcpy(ac, a_piv, 3 * sizeof(double));
            } else {
                double d[3] = {org_c[0] - pv[0], org_c[1] - pv[1], org_c[2] - pv[2]}, t1[3], wd[3], t2[3];
                cross3(dwc, d, t1);
                cross3(wc, d, wd);
                cross3(wc, wd, t2);
                for (int r = 0; r < 3; r++) ac[r] = a_piv[r] + t1[r] + t2[r];
            }
        } else if (kind == 2) {
            memcpy(wc, wp, 3 * sizeof(double));
            memcpy(dwc, dwp, 3 * sizeof(double));
            W->spins[c] = W->spins[p];
            double a0[3], v[3] = {qd[qi] * z[0], qd[qi] * z[1], qd[qi] * z[2]}, cor[3] = {0, 0, 0};
            point_acc(W, Fr, p, org_c, moving, a0);
            if (moving && W->spins[p]) cross3(wp, v, cor);
            for (int r = 0; r < 3; r++) ac[r] = a0[r] + 2.0 * cor[r] + qdd[qi] * z[r];
        } else {
            memcpy(wc, wp, 3 * sizeof(double));
            memcpy(dwc, dwp, 3 * sizeof(double));
            W->spins[c] = W->spins[p];
            point_acc(W, Fr, p, org_c, moving, ac);
        }
    }
    /* each link's own inertial force (at its com) and moment about the com */
    memset(W->force, 0, 3 * L * sizeof(double));
    memset(W->moment, 0, 3 * L * sizeof(double));
    memset(W->heavy, 0, L);
    for (int64_t k = 0; k < L; k++) {
        const double *F = Fr + 16 * k, *b = bodies + BODYF * k;
        double *com = W->com + 3 * k;
        com[0] = F[3]; com[1] = F[7]; com[2] = F[11];
        if (b[0] == 0.0) continue;
        W->heavy[k] = 1;
        const double *c = b + 2, *I = b + 5;
        for (int r = 0; r < 3; r++) com[r] = F[4 * r + 3] + (F[4 * r] * c[0] + F[4 * r + 1] * c[1] + F[4 * r + 2] * c[2]);
        double acc[3];
        point_acc(W, Fr, k, com, moving, acc);
        for (int r = 0; r < 3; r++) W->force[3 * k + r] = b[1] * acc[r];
        if (!moving || !W->spins[k]) continue;
        /* root-frame inertia R I R^T */
        double RI[9], Iw[9];
        for (int r = 0; r < 3; r++)
            for (int s = 0; s < 3; s++) RI[3 * r + s] = F[4 * r] * I[s] + F[4 * r + 1] * I[3 + s] + F[4 * r + 2] * I[6 + s];
        for (int r = 0; r < 3; r++)
            for (int s = 0; s < 3; s++) Iw[3 * r + s] = RI[3 * r] * F[4 * s] + RI[3 * r + 1] * F[4 * s + 1] + RI[3 * r + 2] * F[4 * s + 2];
        const double *w = W->w + 3 * k, *dw = W->dw + 3 * k;
        double iw[3], idw[3], wiw[3];
        for (int r = 0; r < 3; r++) {
            iw[r] = Iw[3 * r] * w[0] + Iw[3 * r + 1] * w[1] + Iw[3 * r + 2] * w[2];
            idw[r] = Iw[3 * r] * dw[0] + Iw[3 * r + 1] * dw[1] + Iw[3 * r + 2] * dw[2];
        }
        cross3(w, iw, wiw);
        for (int r = 0; r < 3; r++) W->moment[3 * k + r] = idw[r] + wiw[r];
    }
    /* backward pass: subtree force and its moment about each joint's pivot; a subtree without a body adds
     * nothing, and the root's own sums are never read */
    memcpy(W->f_sub, W->force, 3 * L * sizeof(double));
    memset(W->n_sub, 0, 3 * L * sizeof(double));
    memset(tau, 0, m->dof * sizeof(double));
    for (int64_t j = nj - 1; j >= 0; j--) {
        const int64_t *ji = m->joints + JOINTI * j;
        int64_t kind = ji[0], p = ji[1], c = ji[2], qi = ji[3], jp = ji[5];
        if (!W->heavy[c]) continue;
        W->heavy[p] = 1;
        const double *pv = W->piv + 3 * j, *z = W->axes + 3 * j, *com = W->com + 3 * c;
        double *nc = W->n_sub + 3 * c, *fc = W->f_sub + 3 * c;
        double d[3] = {com[0] - pv[0], com[1] - pv[1], com[2] - pv[2]}, own[3];
        cross3(d, W->force + 3 * c, own);
        for (int r = 0; r < 3; r++) nc[r] += W->moment[3 * c + r] + own[r];
        if (qi >= 0) {
            const double *v = kind == 1 ? nc : fc;
            tau[qi] += z[0] * v[0] + z[1] * v[1] + z[2] * v[2];
        }
        if (p == 0) continue;
        /* hand the subtree's wrench to the parent, as a moment about the parent's own pivot */
        const double *pp = W->piv + 3 * jp;
        double e[3] = {pv[0] - pp[0], pv[1] - pp[1], pv[2] - pp[2]}, mom[3];
        cross3(e, fc, mom);
        for (int r = 0; r < 3; r++) {
            W->f_sub[3 * p + r] += fc[r];
            W->n_sub[3 * p + r] += nc[r] + mom[r];
        }
    }
}

/* ------------------------------------------------------------------------------------------ checker */
/* The checker's tables (CollisionChecker._pack): ints = header (HEADER) + the kinematic ints + the rest,
 * floats = the kinematic floats + the rest (layout in parse_model). */
#define SHAPEF 19  /* rot (9), pos (3), half (3), half_self (3), radius (1) */
#define ITEMF 37   /* aabb centre (3), aabb half (3), rot (9), centre (3), local half (3), pad (3), has a second box
                      (1), the second box's rot (9) and half (3) (same centre; a cylinder's, see collision.py) */
#define POSEF 12   /* per state and shape: world rot (9), centre (3) */

typedef struct {
    Kin k;
    int64_t arm_n, S, M, n_active, n_pairs, grip, has_margin, n_groups, n_lp, n_sph;
    const int64_t *arm, *shape_link, *active, *amask, *pairs, *g_sph, *g_start, *g_order,
        *g_mask, *lp_sph, *lp_start, *lp_order, *sph_link;
    const double *lower, *upper, *qt, *margin, *shapef, *itemf, *active_r2, *pair_r2, *active_r, *pair_r, *g_r, *lp_r, *sph_c;
} Model;

#define HEADER 12  /* arm_n, S, M, n_active, n_pairs, grip, has_margin, n_groups, n_lp, kin ints, kin floats, n_sph */
#define MAXSPH (2 * MAXLINKS)

static int parse_model(Model *m, const Py_buffer *fb, const Py_buffer *ib) {
    const int64_t *I = (const int64_t *)ib->buf;
    const double *F = (const double *)fb->buf;
    Py_ssize_t ni = ib->len / 8, nf = fb->len / 8;
    if (ni < HEADER) goto bad;
    m->arm_n = I[0]; m->S = I[1]; m->M = I[2]; m->n_active = I[3]; m->n_pairs = I[4]; m->grip = I[5];
    m->has_margin = I[6]; m->n_groups = I[7]; m->n_lp = I[8];
    int64_t kni = I[9], knf = I[10];
    m->n_sph = I[11];
    if (kni < 0 || knf < 0 || HEADER + kni > ni || knf > nf) goto bad;
    if (parse_kin(&m->k, I + HEADER, kni, F, knf) < 0) return -1;
    if (m->k.dof > MAXDOF || m->k.n_links > MAXLINKS || m->S > MAXSHAPES || m->arm_n > m->k.dof || m->k.n_chain > MAXDOF
        || m->k.n_steps > MAXLINKS || m->n_sph < 0 || m->n_sph > MAXSPH)
        goto bad;
    Py_ssize_t need_i = HEADER + kni + m->arm_n + m->S
                        + m->n_active + m->n_active * m->M + 2 * m->n_pairs
                        + m->n_groups + (m->n_groups + 1) + m->n_active + m->n_groups * m->M
                        + 2 * m->n_lp + (m->n_lp + 1) + m->n_pairs + m->n_sph;
    Py_ssize_t need_f = knf + 2 * m->arm_n + m->k.dof + 1
                        + SHAPEF * m->S + ITEMF * m->M + 2 * m->n_active + 2 * m->n_pairs + m->n_groups + 2 * m->n_lp
                        + 3 * m->n_sph;
    if (ni != need_i || nf != need_f) goto bad;
    const int64_t *p = I + HEADER + kni;
    m->arm = p; p += m->arm_n;
    m->shape_link = p; p += m->S;
    m->active = p; p += m->n_active;
    m->amask = p; p += m->n_active * m->M;
    m->pairs = p; p += 2 * m->n_pairs;
    m->g_sph = p; p += m->n_groups;       /* groups: the active shapes of one link, in one bounding sphere (its centre) */
    m->g_start = p; p += m->n_groups + 1;
    m->g_order = p; p += m->n_active;     /* active indices, group by group */
    m->g_mask = p; p += m->n_groups * m->M;
    m->lp_sph = p; p += 2 * m->n_lp;      /* link pairs: the self pairs between the shapes of two links (their centres) */
    m->lp_start = p; p += m->n_lp + 1;
    m->lp_order = p; p += m->n_pairs;     /* pair indices, link pair by link pair */
    m->sph_link = p;                      /* sphere centres: the link of each */
    const double *q = F + knf;
    m->lower = q; q += m->arm_n;
    m->upper = q; q += m->arm_n;
    m->qt = q; q += m->k.dof;
    m->margin = q; q += 1;
    m->shapef = q; q += SHAPEF * m->S;
    m->itemf = q; q += ITEMF * m->M;
    m->active_r2 = q; q += m->n_active;
    m->pair_r2 = q; q += m->n_pairs;
    m->active_r = q; q += m->n_active;  /* sqrt of the above, for the grown ("near") tests */
    m->pair_r = q; q += m->n_pairs;
    m->g_r = q; q += m->n_groups;         /* group sphere radius */
    m->lp_r = q; q += 2 * m->n_lp;        /* per link pair: the sphere radius of each link */
    m->sph_c = q;                         /* sphere centres in their link's frame (3 each); one world centre per state
                                           * serves every group and link pair that shares it */
    for (int64_t j = 0; j < m->n_sph; j++)
        if (m->sph_link[j] < 0 || m->sph_link[j] >= m->k.n_links) goto bad;
    for (int64_t g = 0; g < m->n_groups; g++)
        if (m->g_sph[g] < 0 || m->g_sph[g] >= m->n_sph) goto bad;
    for (int64_t j = 0; j < 2 * m->n_lp; j++)
        if (m->lp_sph[j] < 0 || m->lp_sph[j] >= m->n_sph) goto bad;
    return 0;
bad:
    PyErr_SetString(PyExc_ValueError, "_kernel: packed checker tables do not match their header (if roarmctl's source was updated, its compiled kernel is older: rebuild it with `make install` or `pip install .`)");
    return -1;
}

/* Gram matrix of the 3 x n translational Jacobian J: J J^T (3 x 3) when n >= 3, else J^T J (n x n);
 * returns its size. Its smallest eigenvalue is the square of J's smallest singular value. */
static int gram(const Model *m, const double *Fr, double A[3][3]) {
    int64_t n = m->k.n_cols;
    double J[6 * MAXDOF];
    jac_cols(&m->k, Fr, J, 1);
    if (n >= 3) {
        for (int r = 0; r < 3; r++)
            for (int c = r; c < 3; c++) {
                double s = 0;
                for (int64_t k = 0; k < n; k++) s += J[6 * k + r] * J[6 * k + c];
                A[r][c] = A[c][r] = s;
            }
        return 3;
    }
    for (int r = 0; r < n; r++)
        for (int c = r; c < n; c++)
            A[r][c] = A[c][r] = J[6 * r] * J[6 * c] + J[6 * r + 1] * J[6 * c + 1] + J[6 * r + 2] * J[6 * c + 2];
    return (int)n;
}

/* Smallest singular value of the 3 x n translational Jacobian (m/rad), from its Gram matrix G (dim x dim). */
static double sigma_min(double G[3][3], int dim) {
    if (dim == 0) return 0.0;
    if (dim == 1) return sqrt(G[0][0]);
    if (dim == 2) {  /* smallest eigenvalue of the 2 x 2 J^T J */
        double a = G[0][0], b = G[0][1], c = G[1][1];
        double h = 0.5 * (a + c), d = sqrt(0.25 * (a - c) * (a - c) + b * b);
        double lo = h - d;
        /* the product of the eigenvalues is the determinant: the small one without cancellation */
        double hi = h + d;
        double det = a * c - b * b;
        if (hi > 0 && det >= 0) lo = det / hi;
        return sqrt(lo > 0 ? lo : 0.0);
    }
    double A[3][3];
    memcpy(A, G, sizeof A);
    /* smallest eigenvalue of the 3 x 3 symmetric J J^T: cyclic Jacobi rotations (accurate for the
     * small eigenvalue of a positive semi-definite matrix, also when eigenvalues are close) */
    static const int PQ[3][2] = {{0, 1}, {0, 2}, {1, 2}};
    for (int sweep = 0; sweep < 50; sweep++) {
        double off = A[0][1] * A[0][1] + A[0][2] * A[0][2] + A[1][2] * A[1][2];
        double dia = A[0][0] * A[0][0] + A[1][1] * A[1][1] + A[2][2] * A[2][2];
        if (off <= 1e-36 * dia || off == 0) break;
        for (int k = 0; k < 3; k++) {
            int p = PQ[k][0], qq = PQ[k][1], r = 3 - p - qq;
            double apq = A[p][qq];
            if (apq == 0) continue;
            double theta = (A[qq][qq] - A[p][p]) / (2 * apq), t;
            if (fabs(theta) > 1e150)
                t = 0.5 / theta;
            else
                t = (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1));
            double c = 1 / sqrt(t * t + 1), s = t * c;
            double arp = A[r][p], arq = A[r][qq];
            A[p][p] -= t * apq;
            A[qq][qq] += t * apq;
            A[p][qq] = A[qq][p] = 0;
            A[r][p] = A[p][r] = c * arp - s * arq;
            A[r][qq] = A[qq][r] = s * arp + c * arq;
        }
    }
    double lo = A[0][0];
    if (A[1][1] < lo) lo = A[1][1];
    if (A[2][2] < lo) lo = A[2][2];
    return sqrt(lo > 0 ? lo : 0.0);
}

/* 1 when the symmetric 3 x 3 matrix (a00 a01 a02; a11 a12; a22) is positive definite by its LDL^T factorisation
 * without pivoting (every pivot > 0), else 0. Backward stable like Cholesky: when it succeeds the matrix differs from a positive definite one by
 * about 2e-15 times its largest diagonal entry at most, and it succeeds whenever the smallest eigenvalue exceeds
 * about that much (Higham, Accuracy and Stability of Numerical Algorithms, 2nd ed., 10.1). */
static inline int pd3(double a00, double a01, double a02, double a11, double a12, double a22) {
    if (!(a00 > 0)) return 0;
    double l1 = a01 / a00, l2 = a02 / a00;
    double d1 = a11 - l1 * a01;
    if (!(d1 > 0)) return 0;
    double e = a12 - l2 * a01;
    return a22 - l2 * a02 - (e / d1) * e > 0;
}

/* sigma_min >= margin, decided by the closed-form smallest eigenvalue of the 3 x 3 Gram matrix (Smith
 * 1961: a few operations, error below about 3e-8 of the trace even for close eigenvalues) wherever it is
 * clearly on one side (1e-6 of the trace), else by sigma_min itself: the same decisions as sigma_min.
 * Most states are decided before that, by whether G - t I is positive definite (pd3) at t = margin^2 + 2 band and
 * at t = margin^2 - 2 band: positive definite at the first means the smallest eigenvalue exceeds margin^2 + band by
 * about a band, so the closed form (off by far less than a band) says "above" too; not positive definite at the second
 * means it is below margin^2 - band by about a band, and the closed form says "below". The decisions are the closed
 * form's, without its acos, cos, square root and nine divisions. */
static int margin_decide(double G[3][3], int dim, double margin) {
    if (dim == 3) {
        double tr = G[0][0] + G[1][1] + G[2][2], band = 1e-6 * tr, mm2 = margin * margin;
        if (tr > 1e-100 && tr < 1e100) {  /* no underflow or overflow in pd3's products */
            double t = mm2 + 2.0 * band;
            if (pd3(G[0][0] - t, G[0][1], G[0][2], G[1][1] - t, G[1][2], G[2][2] - t)) return 1;
            t = mm2 - 2.0 * band;
            if (!pd3(G[0][0] - t, G[0][1], G[0][2], G[1][1] - t, G[1][2], G[2][2] - t)) return 0;
        }
        double p1 = G[0][1] * G[0][1] + G[0][2] * G[0][2] + G[1][2] * G[1][2];
        double qm = tr / 3.0;
        double p2 = (G[0][0] - qm) * (G[0][0] - qm) + (G[1][1] - qm) * (G[1][1] - qm) + (G[2][2] - qm) * (G[2][2] - qm) + 2 * p1;
        double lo = qm;
        if (p2 > 0) {
            double p = sqrt(p2 / 6.0), B[3][3];
            for (int r = 0; r < 3; r++)
                for (int c = 0; c < 3; c++) B[r][c] = (G[r][c] - (r == c ? qm : 0.0)) / p;
            double det = B[0][0] * (B[1][1] * B[2][2] - B[1][2] * B[2][1]) - B[0][1] * (B[1][0] * B[2][2] - B[1][2] * B[2][0])
                         + B[0][2] * (B[1][0] * B[2][1] - B[1][1] * B[2][0]);
            double r = det / 2.0;
            r = r < -1 ? -1 : r > 1 ? 1 : r;
            lo = qm + 2 * p * cos(acos(r) / 3.0 + 2.0943951023931957);
        }
        if (lo > mm2 + band) return 1;
        if (lo < mm2 - band) return 0;
    }
    return sigma_min(G, dim) >= margin;
}

static int margin_ok(const Model *m, const double *Fr) {
    double G[3][3];
    int dim = gram(m, Fr, G);
    return margin_decide(G, dim, m->margin[0]);
}

/* Separating-axis test of two oriented boxes: 1 when some axis separates them by more than SEP_TOL.
 * Ra, Rb row-major world rotations (columns are the box axes), ca, cb centres, ha, hb half extents. */
static int obb_apart(const double *Ra, const double *ca, const double *ha, const double *Rb, const double *cb, const double *hb) {
    double R[3][3], AR[3][3], t[3], d[3] = {cb[0] - ca[0], cb[1] - ca[1], cb[2] - ca[2]};
    for (int i = 0; i < 3; i++) {
        t[i] = Ra[i] * d[0] + Ra[3 + i] * d[1] + Ra[6 + i] * d[2];  /* (Ra^T d)_i */
        for (int j = 0; j < 3; j++) {
            R[i][j] = Ra[i] * Rb[j] + Ra[3 + i] * Rb[3 + j] + Ra[6 + i] * Rb[6 + j];  /* (Ra^T Rb)_ij */
            AR[i][j] = fabs(R[i][j]) + PAR_EPS;
        }
    }
    for (int i = 0; i < 3; i++)
        if (fabs(t[i]) > ha[i] + hb[0] * AR[i][0] + hb[1] * AR[i][1] + hb[2] * AR[i][2] + SEP_TOL) return 1;
    for (int j = 0; j < 3; j++)
        if (fabs(t[0] * R[0][j] + t[1] * R[1][j] + t[2] * R[2][j]) > ha[0] * AR[0][j] + ha[1] * AR[1][j] + ha[2] * AR[2][j] + hb[j] + SEP_TOL)
            return 1;
    for (int i = 0; i < 3; i++) {
        int i1 = (i + 1) % 3, i2 = (i + 2) % 3;
        for (int j = 0; j < 3; j++) {
            int j1 = (j + 1) % 3, j2 = (j + 2) % 3;
            double ra = ha[i1] * AR[i2][j] + ha[i2] * AR[i1][j];
            double rb = hb[j1] * AR[i][j2] + hb[j2] * AR[i][j1];
            if (fabs(t[i2] * R[i1][j] - t[i1] * R[i2][j]) > ra + rb + SEP_TOL) return 1;
        }
    }
    return 0;
}

/* Full configuration of state i: the template, the arm values and the gripper value. */
static void full_q(const Model *m, const double *q, const double *grip, Py_ssize_t n_grip, Py_ssize_t i, double *qf) {
    memcpy(qf, m->qt, m->k.dof * sizeof(double));
    for (int64_t j = 0; j < m->arm_n; j++) qf[m->arm[j]] = q[i * m->arm_n + j];
    if (n_grip && m->grip >= 0) qf[m->grip] = grip[i];
}

/* The steps whose joint value no state of a call changes (not an arm joint, nor the gripper when the call gives the
 * gripper per state): their matrices at the template's values, for fk_held. */
static void held_init(const Model *m, int grip_per_state, FkHeld *h) {
    for (int64_t s = 0; s < m->k.n_steps; s++) {
        const int64_t *si = m->k.steps + STEPI * s;
        int held = si[0] != 0 && !(grip_per_state && si[3] == m->grip);
        for (int64_t j = 0; j < m->arm_n && held; j++)
            if (m->arm[j] == si[3]) held = 0;
        h->on[s] = (uint8_t)held;
        if (held) {
            const double *mp = step_matrix(&m->k, s, m->qt[si[3]], h->mm[s]);
            if (mp != h->mm[s]) memcpy(h->mm[s], mp, 16 * sizeof(double));
        }
    }
}

/* One state: arm values qi (arm_n), gripper value *gp (or the template's when gp is NULL), output row i.
 * Returns 1 (valid so far: FCL decides the candidates it added), 0 (limits or margin) or -1 (a candidate
 * buffer is full). With stop, an invalid state returns at once (no near flag, no poses). */
static int check_state(const Model *mp, const double *qi, const double *gp, Py_ssize_t i, uint8_t *valid, uint8_t *near,
                       int64_t *sc, Py_ssize_t *ns, Py_ssize_t cap_s, int64_t *pc, Py_ssize_t *np_, Py_ssize_t cap_p,
                       double *pose, double sweep, int stop, const FkHeld *held) {
    const Model m = *mp;
    double qf[MAXDOF], Fr[16 * MAXLINKS];
    near[i] = 0;
    int ok = 1;
    for (int64_t j = 0; j < m.arm_n; j++)
        if (!(qi[j] >= m.lower[j] - 1e-9 && qi[j] <= m.upper[j] + 1e-9)) ok = 0;
    memcpy(qf, m.qt, m.k.dof * sizeof(double));
    for (int64_t j = 0; j < m.arm_n; j++) qf[m.arm[j]] = qi[j];
    if (gp && m.grip >= 0) qf[m.grip] = *gp;
    fk_held(&m.k, qf, Fr, held);
    if (ok && m.has_margin && !margin_ok(&m, Fr)) ok = 0;
    valid[i] = (uint8_t)ok;
    if (!ok && stop) return 0;
    double *ps = pose + i * m.S * POSEF;
    /* a shape's centre only when a group or link-pair sphere test reaches it, its rotation only when one of its own
     * sphere tests passes */
    uint8_t cen_done[MAXSHAPES], rot_done[MAXSHAPES], sph_done[MAXSPH];
    double wsph[MAXSPH][3];  /* world sphere centres, each made once */
    memset(cen_done, 0, m.S);
    memset(rot_done, 0, m.S);
    memset(sph_done, 0, m.n_sph);
#define NEED_SPH(j)                                                                                          \
    if (!sph_done[j]) {                                                                                     \
    const double *L_ = Fr + 16 * m.sph_link[j], *c_ = m.sph_c + 3 * (j);                                  \
    for (int r = 0; r < 3; r++) wsph[j][r] = L_[4 * r + 3] + L_[4 * r] * c_[0] + L_[4 * r + 1] * c_[1] + L_[4 * r + 2] * c_[2]; \
    sph_done[j] = 1;                                                                                    \
    }
#define NEED_CEN(a)                                                                                          \
    if (!cen_done[a]) {                                                                                     \
    const double *L_ = Fr + 16 * m.shape_link[a], *sf_ = m.shapef + SHAPEF * (a);                        \
    double *o_ = ps + POSEF * (a);                                                                      \
    for (int r = 0; r < 3; r++)                                                                         \
        o_[9 + r] = L_[4 * r + 3] + (L_[4 * r] * sf_[9] + L_[4 * r + 1] * sf_[10] + L_[4 * r + 2] * sf_[11]); \
    cen_done[a] = 1;                                                                                    \
    }
#define NEED_ROT(a)                                                                                          \
    if (!rot_done[a]) {                                                                                     \
    const double *L_ = Fr + 16 * m.shape_link[a], *sf_ = m.shapef + SHAPEF * (a);                        \
    double *o_ = ps + POSEF * (a);                                                                      \
    for (int r = 0; r < 3; r++)                                                                         \
        for (int c = 0; c < 3; c++)                                                                     \
            o_[3 * r + c] = L_[4 * r] * sf_[c] + L_[4 * r + 1] * sf_[3 + c] + L_[4 * r + 2] * sf_[6 + c]; \
    rot_done[a] = 1;                                                                                    \
    }
    for (int64_t g = 0; g < m.n_groups; g++) {
        /* the group's sphere holds every sphere of its shapes: where it (grown by sweep) misses an item's
         * box, so do they, and the item is skipped for all of them */
        int64_t gs = m.g_sph[g];
        NEED_SPH(gs)
        const double *cg = wsph[gs];
        double gr = m.g_r[g] + (sweep > 0 ? sweep : 0.0);
        for (int64_t k = 0; k < m.M; k++) {
            if (!m.g_mask[g * m.M + k]) continue;
            const double *it = m.itemf + ITEMF * k;
            double e0 = fabs(cg[0] - it[0]) - it[3], e1 = fabs(cg[1] - it[1]) - it[4], e2 = fabs(cg[2] - it[2]) - it[5];
            if (e0 > gr || e1 > gr || e2 > gr) continue;  /* one term alone is >= gr^2 already */
            double dg = 0;
            if (e0 > 0) dg += e0 * e0;
            if (e1 > 0) dg += e1 * e1;
            if (e2 > 0) dg += e2 * e2;
            if (!(dg < gr * gr)) continue;
            for (int64_t gi = m.g_start[g]; gi < m.g_start[g + 1]; gi++) {
                int64_t ai = m.g_order[gi], a = m.active[ai];
                if (!m.amask[ai * m.M + k]) continue;
                NEED_CEN(a)
                const double *o = ps + POSEF * a, *sf = m.shapef + SHAPEF * a;
                double r2 = m.active_r2[ai];
                double d2 = 0;
                for (int r = 0; r < 3; r++) {
                    double e = fabs(o[9 + r] - it[r]) - it[3 + r];
                    if (e > 0) d2 += e * e;
                }
                if (sweep > 0 && !near[i] && d2 < (m.active_r[ai] + sweep) * (m.active_r[ai] + sweep)) {
                    /* the sphere grown by the sweep touches the item's box; the shape's box grown by the sweep
                     * holds every point the shape reaches within the sweep, so the state is near only when that
                     * box is not apart from the item's */
                    NEED_ROT(a)
                    const double hs[3] = {sf[12] + sweep, sf[13] + sweep, sf[14] + sweep};
                    if (!obb_apart(o, o + 9, hs, it + 6, it + 15, it + 18)
                        && !(it[24] != 0.0 && obb_apart(o, o + 9, hs, it + 25, it + 15, it + 34)))
                        near[i] = 1;
                }
                if (!ok || !(d2 < r2)) continue;
                NEED_ROT(a)
                int in = 1;  /* world boxes */
                for (int r = 0; r < 3 && in; r++) {
                    double hw = fabs(o[3 * r]) * sf[12] + fabs(o[3 * r + 1]) * sf[13] + fabs(o[3 * r + 2]) * sf[14];
                    if (!(fabs(o[9 + r] - it[r]) < hw + it[3 + r])) in = 0;
                }
                if (!in || obb_apart(o, o + 9, sf + 12, it + 6, it + 15, it + 18)) continue;
                /* an item with a second box that holds it (a cylinder's, turned 45 degrees about its axis): apart from
                 * either box is apart from the item */
                if (it[24] != 0.0 && obb_apart(o, o + 9, sf + 12, it + 25, it + 15, it + 34)) continue;
                if (*ns >= cap_s) return -1;
                sc[3 * *ns] = i; sc[3 * *ns + 1] = a; sc[3 * *ns + 2] = k; (*ns)++;
            }
        }
    }
    for (int64_t lp = 0; lp < m.n_lp; lp++) {
        /* each link's sphere holds the spheres of its shapes: where the two links' spheres (grown by sweep)
         * are apart, so are all their shape pairs */
        int64_t sa = m.lp_sph[2 * lp], sb = m.lp_sph[2 * lp + 1];
        NEED_SPH(sa)
        NEED_SPH(sb)
        double dl = 0, lim = m.lp_r[2 * lp] + m.lp_r[2 * lp + 1] + (sweep > 0 ? 2 * sweep : 0.0);
        for (int r = 0; r < 3; r++) {
            double e = wsph[sa][r] - wsph[sb][r];
            dl += e * e;
        }
        if (!(dl < lim * lim)) continue;
      for (int64_t pk = m.lp_start[lp]; pk < m.lp_start[lp + 1]; pk++) {
        int64_t p = m.lp_order[pk];
        int64_t a = m.pairs[2 * p], bb = m.pairs[2 * p + 1];
        NEED_CEN(a)
        NEED_CEN(bb)
        const double *oa = ps + POSEF * a, *ob = ps + POSEF * bb;
        const double *fa = m.shapef + SHAPEF * a, *fb = m.shapef + SHAPEF * bb;
        double d2 = 0, dd[3];
        for (int r = 0; r < 3; r++) {
            dd[r] = oa[9 + r] - ob[9 + r];
            d2 += dd[r] * dd[r];
        }
        double r2 = m.pair_r2[p];
        if (sweep > 0 && !near[i] && d2 < (m.pair_r[p] + 2 * sweep) * (m.pair_r[p] + 2 * sweep)) near[i] = 1;
        if (!ok || !(d2 < r2)) continue;
        NEED_ROT(a)
        NEED_ROT(bb)
        int in = 1;
        for (int r = 0; r < 3 && in; r++) {
            double ha = fabs(oa[3 * r]) * fa[15] + fabs(oa[3 * r + 1]) * fa[16] + fabs(oa[3 * r + 2]) * fa[17];
            double hb = fabs(ob[3 * r]) * fb[15] + fabs(ob[3 * r + 1]) * fb[16] + fabs(ob[3 * r + 2]) * fb[17];
            if (!(fabs(dd[r]) < ha + hb)) in = 0;
        }
        if (!in || obb_apart(oa, oa + 9, fa + 15, ob, ob + 9, fb + 15)) continue;
        if (*np_ >= cap_p) return -1;
        pc[2 * *np_] = i; pc[2 * *np_ + 1] = p; (*np_)++;
      }
    }
        return ok;
}

static int get_in(PyObject *o, Py_buffer *b) { return PyObject_GetBuffer(o, b, PyBUF_C_CONTIGUOUS); }
static int get_out(PyObject *o, Py_buffer *b) { return PyObject_GetBuffer(o, b, PyBUF_C_CONTIGUOUS | PyBUF_WRITABLE); }

/* check(F, I, q, grip, valid, near, scene, self, pose, sweep, stop_at_first) -> (n_scene, n_self, limit)
 * q (N, arm_n) float64; grip (N,) or empty; valid, near (N,) uint8; scene (cap, 3) and self (cap, 2)
 * int64 candidates (state, shape, item) / (state, pair); pose (N, S, 12) float64: the centre of the shapes that
 * some group or link-pair sphere test reached, the rotation of those that some pair's sphere test kept (all shapes of
 * the candidates have both; the other rows are left as they were). */
static PyObject *check(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 11) {
        PyErr_SetString(PyExc_TypeError, "check() takes 11 arguments");
        return NULL;
    }
    Py_buffer b[9];
    int got = 0;
    PyObject *result = NULL;
    for (; got < 9; got++)
        if ((got < 4 ? get_in(args[got], &b[got]) : get_out(args[got], &b[got])) < 0) goto done;
    double sweep = PyFloat_AsDouble(args[9]);
    int stop = PyObject_IsTrue(args[10]);
    if (PyErr_Occurred()) goto done;
    Model m;
    if (parse_model(&m, &b[0], &b[1]) < 0) goto done;
    const double *q = b[2].buf, *grip = b[3].buf;
    Py_ssize_t N = m.arm_n ? b[2].len / 8 / m.arm_n : 0, n_grip = b[3].len / 8;
    uint8_t *valid = b[4].buf, *near = b[5].buf;
    int64_t *sc = b[6].buf, *pc = b[7].buf;
    double *pose = b[8].buf;
    Py_ssize_t cap_s = b[6].len / 24, cap_p = b[7].len / 16;
    if ((n_grip && n_grip != N) || b[4].len < N || b[5].len < N || b[8].len < (Py_ssize_t)(N * m.S * POSEF * 8)) {
        PyErr_SetString(PyExc_ValueError, "_kernel.check: output buffers too small");
        goto done;
    }
    Py_ssize_t ns = 0, np_ = 0, limit = N;
    FkHeld held;
    held_init(&m, n_grip > 0, &held);
    for (Py_ssize_t i = 0; i < N; i++) {
        int ok = check_state(&m, q + i * m.arm_n, n_grip ? grip + i : NULL, i, valid, near, sc, &ns, cap_s, pc, &np_,
                             cap_p, pose, sweep, stop, &held);
        if (ok < 0) goto overflow;
        if (!ok && stop) {
            limit = i;
            break;
        }
    }
    for (Py_ssize_t i = limit + 1; i < N; i++) {
        valid[i] = 1;
        near[i] = 0;
    }
    result = Py_BuildValue("nnn", ns, np_, limit);
    goto done;
overflow:
    PyErr_SetString(PyExc_ValueError, "_kernel.check: candidate buffer too small");
done:
    for (int k = 0; k < got; k++) PyBuffer_Release(&b[k]);
    return result;
}

/* check_line(F, I, q0, d, steps, start, stride, idx, refine, valid, near, scene, self, pose, sweep, stop, skip)
 *   -> (n_scene, n_self, limit, count)
 * Like check() for the states of the segment q0 -> q0 + d without building them in Python: state i of the
 * segment is q0 + d * t_i with t_i = i * (1 / steps) and t_steps = 1 (np.linspace's numbers). Without idx
 * (empty) the states are i = start, start + stride, ... <= steps; with idx, the states between i and i + 1
 * for each i of idx: s_i + (s_{i+1} - s_i) * (k / refine), k = 1 .. refine - 1 (the refinement).
 * skip > 0 (without idx, start 0, stride 1): the states skip, 2 skip, ... <= steps were checked already by a call
 * with start = stride = skip (same sweep) whose rows are still in valid/near; they are not checked again: they
 * count as valid and keep their near flags, moved to their rows here. */
static void line_state(const double *q0, const double *d, int64_t n, int64_t steps, int64_t i, double *out) {
    double t = i == steps ? 1.0 : (double)i * (1.0 / (double)steps);
    for (int64_t j = 0; j < n; j++) out[j] = q0[j] + d[j] * t;
}

/* The rows of a pass: the states start, start + stride, ... <= steps, or refine - 1 per index of idx. */
static Py_ssize_t pass_rows(int64_t steps, int64_t start, int64_t stride, Py_ssize_t n_idx, int64_t refine) {
    return n_idx ? n_idx * (refine - 1) : (start > steps ? 0 : (steps - start) / stride + 1);
}

/* One pass of check_line over its N = pass_rows(...) rows (the buffers hold them); returns 0, or -1 with a Python
 * error (a candidate buffer is full, or no memory). */
static int line_pass(const Model *m, const FkHeld *held, const double *q0, const double *d, int64_t steps, int64_t start,
                     int64_t stride, const int64_t *idx, Py_ssize_t n_idx, int64_t refine, int64_t skip, double sweep,
                     int stop, uint8_t *valid, uint8_t *near, int64_t *sc, Py_ssize_t cap_s, int64_t *pc, Py_ssize_t cap_p,
                     double *pose, Py_ssize_t *ns, Py_ssize_t *np_, Py_ssize_t *limit, const char *name) {
    Py_ssize_t N = pass_rows(steps, start, stride, n_idx, refine), row = 0;
    double qa[MAXDOF], qb[MAXDOF], qs[MAXDOF];
    uint8_t *pre = NULL;  /* with skip: the earlier call's near flags (its rows 0 .. n_pre - 1) */
    *ns = *np_ = 0;
    *limit = N;
    Py_ssize_t n_pre = skip > 0 && steps >= skip ? (steps - skip) / skip + 1 : 0;
    if (n_pre) {
        if (!(pre = PyMem_Malloc(n_pre))) {
            PyErr_NoMemory();
            return -1;
        }
        memcpy(pre, near, n_pre);
    }
    for (Py_ssize_t u = 0; u < (n_idx ? n_idx : N); u++) {
        int64_t kmax = n_idx ? refine - 1 : 1;
        if (n_idx) {
            line_state(q0, d, m->arm_n, steps, idx[u], qa);
            line_state(q0, d, m->arm_n, steps, idx[u] + 1, qb);
        }
        for (int64_t k = 1; k <= kmax; k++, row++) {
            if (n_idx) {
                double t = (double)k / (double)refine;
                for (int64_t j = 0; j < m->arm_n; j++) qs[j] = qa[j] + (qb[j] - qa[j]) * t;
            } else {
                int64_t s_i = start + u * stride;
                if (n_pre && s_i >= skip && s_i % skip == 0) {
                    valid[row] = 1;
                    near[row] = pre[s_i / skip - 1];
                    continue;
                }
                line_state(q0, d, m->arm_n, steps, s_i, qs);
            }
            int ok = check_state(m, qs, NULL, row, valid, near, sc, ns, cap_s, pc, np_, cap_p, pose, sweep, stop, held);
            if (ok < 0) {
                PyMem_Free(pre);
                PyErr_Format(PyExc_ValueError, "_kernel.%s: candidate buffer too small", name);
                return -1;
            }
            if (!ok && stop) {
                *limit = row;
                goto finished;
            }
        }
    }
finished:
    for (Py_ssize_t i = *limit + 1; i < N; i++) {
        valid[i] = 1;
        near[i] = 0;
    }
    PyMem_Free(pre);
    return 0;
}

static PyObject *check_line(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 17) {
        PyErr_SetString(PyExc_TypeError, "check_line() takes 17 arguments");
        return NULL;
    }
    static const int bufarg[10] = {0, 1, 2, 3, 7, 9, 10, 11, 12, 13};
    Py_buffer b[10];
    int got = 0;
    PyObject *result = NULL;
    for (; got < 10; got++)
        if ((got < 5 ? get_in(args[bufarg[got]], &b[got]) : get_out(args[bufarg[got]], &b[got])) < 0) goto done;
    int64_t steps = PyLong_AsLongLong(args[4]), start = PyLong_AsLongLong(args[5]), stride = PyLong_AsLongLong(args[6]);
    int64_t refine = PyLong_AsLongLong(args[8]), skip = PyLong_AsLongLong(args[16]);
    double sweep = PyFloat_AsDouble(args[14]);
    int stop = PyObject_IsTrue(args[15]);
    if (PyErr_Occurred()) goto done;
    Model m;
    if (parse_model(&m, &b[0], &b[1]) < 0) goto done;
    Py_ssize_t n_idx = b[4].len / 8;
    if (steps < 1 || stride < 1 || start < 0 || refine < 1 || b[2].len != 8 * m.arm_n || b[3].len != 8 * m.arm_n
        || skip < 0 || (skip > 0 && (n_idx || start != 0 || stride != 1))) {
        PyErr_SetString(PyExc_ValueError, "_kernel.check_line: bad arguments");
        goto done;
    }
    Py_ssize_t N = pass_rows(steps, start, stride, n_idx, refine);
    if (b[5].len < N || b[6].len < N || b[9].len < (Py_ssize_t)(N * m.S * POSEF * 8)) {
        PyErr_SetString(PyExc_ValueError, "_kernel.check_line: output buffers too small");
        goto done;
    }
    Py_ssize_t ns, np_, limit;
    FkHeld held;
    held_init(&m, 0, &held);
    if (line_pass(&m, &held, b[2].buf, b[3].buf, steps, start, stride, b[4].buf, n_idx, refine, skip, sweep, stop,
                  b[5].buf, b[6].buf, b[7].buf, b[7].len / 24, b[8].buf, b[8].len / 16, b[9].buf, &ns, &np_, &limit,
                  "check_line") < 0)
        goto done;
    result = Py_BuildValue("nnnn", ns, np_, limit, N);
done:
    for (int k = 0; k < got; k++) PyBuffer_Release(&b[k]);
    return result;
}

/* segment(F, I, q0, q1, resolution, gain, refine, coarse, first, valid, near, scene, self, pose, idx)
 *   -> (status, pass, n_scene, n_self, limit, n, count, steps, sweep)
 * CollisionChecker.segment_valid's passes over the segment q0 -> q1 (arm_n each) in one call, with the same numbers:
 * steps = max(1, ceil(|q1 - q0| / resolution)), the sweep 0.5 |e| gain with e = (q0 + d (1 / steps)) - q0 (the first
 * step), the sums of squares in index order (numpy's dot for fewer than 16 values); pass 0 every coarse-th state
 * (segments of more than 4 coarse states), pass 1 the rest (check_line's skip), pass 2 the refinement of the steps
 * next to a near state (refine, sweep 0), each with stop at the first invalid state, from pass `first` on (a
 * later call for the same segment, once FCL cleared the candidates of pass first - 1). It stops after the first pass
 * that fails (status 0: limits or margin, at row limit < n) or leaves candidates for FCL (status 2: n_scene, n_self,
 * limit and n of that pass, whose rows are in the buffers); status 1: every pass clear; status 3: the buffers are
 * too small for pass `pass` (nothing of it ran); status 4: not for this call (arm of 16 or more joints, lengths
 * that do not match, or numbers that are not finite): nothing ran. count: the states checked (as check_count
 * counts them); idx (int64, >= steps values): work space for the refined steps. */
static PyObject *segment(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 15) {
        PyErr_SetString(PyExc_TypeError, "segment() takes 15 arguments");
        return NULL;
    }
    static const int bufarg[10] = {0, 1, 2, 3, 9, 10, 11, 12, 13, 14};
    Py_buffer b[10];
    int got = 0;
    PyObject *result = NULL;
    for (; got < 10; got++)
        if ((got < 4 ? get_in(args[bufarg[got]], &b[got]) : get_out(args[bufarg[got]], &b[got])) < 0) goto done;
    double resolution = PyFloat_AsDouble(args[4]), gain = PyFloat_AsDouble(args[5]);
    int64_t refine = PyLong_AsLongLong(args[6]), cs = PyLong_AsLongLong(args[7]), first = PyLong_AsLongLong(args[8]);
    if (PyErr_Occurred()) goto done;
    Model m;
    if (parse_model(&m, &b[0], &b[1]) < 0) goto done;
    const double *q0 = b[2].buf, *q1 = b[3].buf;
    uint8_t *valid = b[4].buf, *near = b[5].buf;
    int64_t *sc = b[6].buf, *pc = b[7].buf, *idx = b[9].buf;
    double *pose = b[8].buf;
    Py_ssize_t cap_s = b[6].len / 24, cap_p = b[7].len / 16, rows = b[4].len < b[5].len ? b[4].len : b[5].len;
    if (m.S && rows > b[8].len / (Py_ssize_t)(m.S * POSEF * 8)) rows = b[8].len / (Py_ssize_t)(m.S * POSEF * 8);
    int status = 4, pass = 0;
    Py_ssize_t ns = 0, np_ = 0, limit = 0, N = 0, count = 0;
    int64_t steps = 0;
    double sweep = 0.0;
    if (m.arm_n >= 16 || m.arm_n < 1 || b[2].len != 8 * m.arm_n || b[3].len != 8 * m.arm_n || !(resolution > 0) || cs < 1
        || first < 0 || first > 2)
        goto out;
    double d[MAXDOF], dd = 0.0, ee = 0.0;
    for (int64_t j = 0; j < m.arm_n; j++) {
        d[j] = q1[j] - q0[j];
        dd += d[j] * d[j];
    }
    double x = sqrt(dd) / resolution;
    if (!(x <= 1e15)) goto out;  /* not finite, or more steps than anyone checks */
    steps = (int64_t)ceil(x);
    if (steps < 1) steps = 1;
    double t1 = 1.0 / (double)steps;
    for (int64_t j = 0; j < m.arm_n; j++) {
        double e = (q0[j] + d[j] * t1) - q0[j];
        ee += e * e;
    }
    sweep = 0.5 * sqrt(ee) * gain;
    status = 3;
    if (rows < steps + 1 || b[9].len / 8 < steps) goto out;
    FkHeld held;
    held_init(&m, 0, &held);
    int coarse = steps + 1 > 4 * cs;
    for (pass = coarse && first == 0 ? 0 : first > 1 ? 2 : 1; pass < 2; pass++) {
        int64_t skip = pass == 1 && coarse ? cs : 0;
        N = pass == 0 ? pass_rows(steps, cs, cs, 0, 1) : steps + 1;
        if (line_pass(&m, &held, q0, d, steps, pass == 0 ? cs : 0, pass == 0 ? cs : 1, NULL, 0, 1, skip, sweep, 1, valid,
                      near, sc, cap_s, pc, cap_p, pose, &ns, &np_, &limit, "segment") < 0)
            goto done;
        count += N - (skip ? steps / skip : 0);
        if (limit < N) {
            status = 0;
            goto out;
        }
        if (ns || np_) {
            status = 2;
            goto out;
        }
    }
    status = 1;
    if (refine <= 1 || sweep <= 0) goto out;
    Py_ssize_t n_idx = 0;
    for (int64_t i = 0; i < steps; i++)
        if (near[i] || near[i + 1]) idx[n_idx++] = i;
    if (!n_idx) goto out;
    N = n_idx * (refine - 1);
    if (N > rows) {
        status = 3;
        goto out;
    }
    if (line_pass(&m, &held, q0, d, steps, 0, 1, idx, n_idx, refine, 0, 0.0, 1, valid, near, sc, cap_s, pc, cap_p, pose,
                  &ns, &np_, &limit, "segment") < 0)
        goto done;
    count += N;
    status = limit < N ? 0 : ns || np_ ? 2 : 1;
out:
    result = Py_BuildValue("iinnnnnLd", status, pass, ns, np_, limit, N, count, (long long)steps, sweep);
done:
    for (int k = 0; k < got; k++) PyBuffer_Release(&b[k]);
    return result;
}

/* sigma(F, I, q, grip, out): (N,) margin measure (CollisionChecker.margin_measure). */
static PyObject *sigma(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "sigma() takes 5 arguments");
        return NULL;
    }
    Py_buffer b[5];
    int got = 0;
    PyObject *result = NULL;
    for (; got < 5; got++)
        if ((got < 4 ? get_in(args[got], &b[got]) : get_out(args[got], &b[got])) < 0) goto done;
    Model m;
    if (parse_model(&m, &b[0], &b[1]) < 0) goto done;
    Py_ssize_t N = m.arm_n ? b[2].len / 8 / m.arm_n : 0, n_grip = b[3].len / 8;
    if ((n_grip && n_grip != N) || b[4].len < (Py_ssize_t)(N * 8)) {
        PyErr_SetString(PyExc_ValueError, "_kernel.sigma: output buffer too small");
        goto done;
    }
    double qf[MAXDOF], Fr[16 * MAXLINKS];
    double *out = b[4].buf;
    for (Py_ssize_t i = 0; i < N; i++) {
        full_q(&m, b[2].buf, b[3].buf, n_grip, i, qf);
        fk(&m.k, qf, Fr);
        double G[3][3];
        int dim = gram(&m, Fr, G);
        out[i] = sigma_min(G, dim);
    }
    Py_INCREF(Py_None);
    result = Py_None;
done:
    for (int k = 0; k < got; k++) PyBuffer_Release(&b[k]);
    return result;
}

/* ---------------------------------------------------------------- kinematics and dynamics entry points
 * Each takes the kinematic tables (KF float64, KI int64) first; q, qd, qdd are (N, dof) float64 full
 * configurations (rad, m), rates and accelerations; outputs are written in place. */
static int get_kin(PyObject *const *args, Py_buffer *b, int *got, Kin *k) {
    for (; *got < 2; (*got)++)
        if (get_in(args[*got], &b[*got]) < 0) return -1;
    return parse_kin(k, (const int64_t *)b[1].buf, b[1].len / 8, (const double *)b[0].buf, b[0].len / 8);
}

static int bad_len(const char *what) {
    PyErr_Format(PyExc_ValueError, "_kernel.%s: array lengths do not match the tables", what);
    return -1;
}

/* fk(KF, KI, q, out): every link frame, out (N, n_links, 4, 4). */
static PyObject *fk_py(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "fk() takes 4 arguments");
        return NULL;
    }
    Py_buffer b[4];
    int got = 0;
    PyObject *result = NULL;
    Kin k;
    if (get_kin(args, b, &got, &k) < 0) goto done;
    if (get_in(args[2], &b[2]) < 0) goto done;
    got++;
    if (get_out(args[3], &b[3]) < 0) goto done;
    got++;
    Py_ssize_t N = b[3].len / (Py_ssize_t)(8 * 16 * k.n_links);
    if (b[3].len != N * 8 * 16 * k.n_links || b[2].len != N * 8 * k.dof) {
        bad_len("fk");
        goto done;
    }
    const double *q = b[2].buf;
    double *out = b[3].buf;
    for (Py_ssize_t i = 0; i < N; i++) fk(&k, q + i * k.dof, out + i * 16 * k.n_links);
    Py_INCREF(Py_None);
    result = Py_None;
done:
    for (int j = 0; j < got; j++) PyBuffer_Release(&b[j]);
    return result;
}

/* jacobian(KF, KI, q, tcp, jac): TCP poses tcp (N, 4, 4) and geometric Jacobians jac (N, 6, n_cols), rows
 * (vx, vy, vz, wx, wy, wz). tcp_velocity(KF, KI, q, qd, out): out (N, 3) = J_v(q) @ qd, qd (N, n_cols). */
static PyObject *jacobian_or_velocity(PyObject *const *args, Py_ssize_t nargs, int velocity) {
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "takes 5 arguments");
        return NULL;
    }
    Py_buffer b[5];
    int got = 0;
    PyObject *result = NULL;
    double *Fr = NULL, *J = NULL;
    Kin k;
    if (get_kin(args, b, &got, &k) < 0) goto done;
    for (; got < 5; got++)
        if ((got == 2 || (velocity && got == 3) ? get_in(args[got], &b[got]) : get_out(args[got], &b[got])) < 0) goto done;
    int64_t nc = k.n_cols;
    Py_ssize_t N = k.dof ? b[2].len / (8 * k.dof) : 0;
    if (b[2].len != N * 8 * k.dof
        || (velocity ? (b[3].len != N * 8 * nc || b[4].len != N * 8 * 3)
                     : (b[3].len != N * 8 * 16 || b[4].len != N * 8 * 6 * nc))) {
        bad_len(velocity ? "tcp_velocity" : "jacobian");
        goto done;
    }
    Fr = PyMem_Malloc(16 * k.n_links * sizeof(double));
    J = PyMem_Malloc((6 * nc + 1) * sizeof(double));
    if (!Fr || !J) {
        PyErr_NoMemory();
        goto done;
    }
    const double *q = b[2].buf;
    for (Py_ssize_t i = 0; i < N; i++) {
        fk(&k, q + i * k.dof, Fr);
        jac_cols(&k, Fr, J, velocity);
        if (velocity) {
            const double *qd = (const double *)b[3].buf + i * nc;
            double *v = (double *)b[4].buf + 3 * i;
            for (int r = 0; r < 3; r++) {
                double s = 0.0;
                for (int64_t j = 0; j < nc; j++) s += J[6 * j + r] * qd[j];
                v[r] = s;
            }
        } else {
            memcpy((double *)b[3].buf + 16 * i, Fr + 16 * k.tcp, 16 * sizeof(double));
            double *jac = (double *)b[4].buf + 6 * nc * i;
            for (int r = 0; r < 6; r++)
                for (int64_t j = 0; j < nc; j++) jac[r * nc + j] = J[6 * j + r];
        }
    }
    Py_INCREF(Py_None);
    result = Py_None;
done:
    PyMem_Free(Fr);
    PyMem_Free(J);
    for (int j = 0; j < got; j++) PyBuffer_Release(&b[j]);
    return result;
}

static PyObject *jacobian(PyObject *self, PyObject *const *args, Py_ssize_t nargs) { return jacobian_or_velocity(args, nargs, 0); }
static PyObject *tcp_velocity(PyObject *self, PyObject *const *args, Py_ssize_t nargs) { return jacobian_or_velocity(args, nargs, 1); }

/* rnea(KF, KI, bodies, q, qd, qdd, gravity, tau): joint torques tau (N, dof) (N m, N for prismatic joints);
 * bodies (n_links, BODYF) float64; gravity (m/s^2) along -z of the root frame. */
static PyObject *rnea(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 8) {
        PyErr_SetString(PyExc_TypeError, "rnea() takes 8 arguments");
        return NULL;
    }
    static const int bufarg[6] = {2, 3, 4, 5, 7, -1};
    Py_buffer b[8];
    int got = 0;
    PyObject *result = NULL;
    double *work = NULL;
    Kin k;
    if (get_kin(args, b, &got, &k) < 0) goto done;
    for (; got < 7; got++)
        if ((got < 6 ? get_in(args[bufarg[got - 2]], &b[got]) : get_out(args[bufarg[got - 2]], &b[got])) < 0) goto done;
    double gravity = PyFloat_AsDouble(args[6]);
    if (gravity == -1.0 && PyErr_Occurred()) goto done;
    int64_t L = k.n_links, dof = k.dof;
    Py_ssize_t N = dof ? b[3].len / (8 * dof) : 0;
    if (b[2].len != 8 * BODYF * L || b[3].len != N * 8 * dof || b[4].len != N * 8 * dof || b[5].len != N * 8 * dof
        || b[6].len != N * 8 * dof) {
        bad_len("rnea");
        goto done;
    }
    Py_ssize_t nd = 16 * L + 8 * 3 * L + 2 * 3 * k.n_joints + (2 * L + 7) / 8 + 1;
    work = PyMem_Malloc(nd * sizeof(double));
    if (!work) {
        PyErr_NoMemory();
        goto done;
    }
    double *Fr = work, *p = work + 16 * L;
    RneaWork W;
    W.w = p; p += 3 * L;
    W.dw = p; p += 3 * L;
    W.a = p; p += 3 * L;
    W.com = p; p += 3 * L;
    W.force = p; p += 3 * L;
    W.moment = p; p += 3 * L;
    W.f_sub = p; p += 3 * L;
    W.n_sub = p; p += 3 * L;
    W.axes = p; p += 3 * k.n_joints;
    W.piv = p; p += 3 * k.n_joints;
    W.spins = (uint8_t *)p;
    W.heavy = W.spins + L;
    const double *q = b[3].buf, *qd = b[4].buf, *qdd = b[5].buf;
    double *tau = b[6].buf;
    for (Py_ssize_t i = 0; i < N; i++) {
        fk(&k, q + i * dof, Fr);
        rnea_state(&k, Fr, qd + i * dof, qdd + i * dof, gravity, b[2].buf, &W, tau + i * dof);
    }
    Py_INCREF(Py_None);
    result = Py_None;
done:
    PyMem_Free(work);
    for (int j = 0; j < got; j++) PyBuffer_Release(&b[j]);
    return result;
}

/* apart(Ra, ca, ha, Rb, cb, hb) -> bool: the separating-axis test alone, for the tests. */
static PyObject *apart(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "apart() takes 6 arguments");
        return NULL;
    }
    Py_buffer b[6];
    int got = 0;
    PyObject *result = NULL;
    static const Py_ssize_t need[6] = {72, 24, 24, 72, 24, 24};
    for (; got < 6; got++)
        if (get_in(args[got], &b[got]) < 0) goto done;
    for (int k = 0; k < 6; k++)
        if (b[k].len != need[k]) {
            PyErr_SetString(PyExc_ValueError, "apart(): (3,3), (3,), (3,) float64 arrays expected");
            goto done;
        }
    result = PyBool_FromLong(obb_apart(b[0].buf, b[1].buf, b[2].buf, b[3].buf, b[4].buf, b[5].buf));
done:
    for (int k = 0; k < got; k++) PyBuffer_Release(&b[k]);
    return result;
}

/* _kernel_jerk.c: the timing's jerk check (motion/jerk_filter.py), compiled into this module. */
PyObject *jerk_check(PyObject *self, PyObject *const *args, Py_ssize_t nargs);

static PyMethodDef methods[] = {
    {"check", (PyCFunction)(void (*)(void))check, METH_FASTCALL, "Batch state check (see collision.py)."},
    {"check_line", (PyCFunction)(void (*)(void))check_line, METH_FASTCALL, "Check states of a straight segment."},
    {"segment", (PyCFunction)(void (*)(void))segment, METH_FASTCALL, "segment_valid's passes over a segment, in one call."},
    {"fk", (PyCFunction)(void (*)(void))fk_py, METH_FASTCALL, "Link frames of a batch (Kinematics.frames4)."},
    {"jacobian", (PyCFunction)(void (*)(void))jacobian, METH_FASTCALL, "TCP poses and Jacobians of a batch."},
    {"tcp_velocity", (PyCFunction)(void (*)(void))tcp_velocity, METH_FASTCALL, "TCP linear velocities of a batch."},
    {"rnea", (PyCFunction)(void (*)(void))rnea, METH_FASTCALL, "Inverse dynamics of a batch (Newton-Euler)."},
    {"sigma", (PyCFunction)(void (*)(void))sigma, METH_FASTCALL, "Margin measure of a batch."},
    {"apart", (PyCFunction)(void (*)(void))apart, METH_FASTCALL, "Separating-axis test of two boxes."},
    {"jerk_check", (PyCFunction)(void (*)(void))jerk_check, METH_FASTCALL, "The timing's jerk check, sample by sample."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef moddef = {PyModuleDef_HEAD_INIT, "_kernel", "roarmctl's compiled kinematics, dynamics and state-check kernel.", -1, methods};

/* The table layouts and work-array sizes above, as module constants: the Python side packs the tables with these
 * (collision_tables.py, dynamics.py) so that both languages read them from this one source. */
PyMODINIT_FUNC PyInit__kernel(void) {
    PyObject *m = PyModule_Create(&moddef);
    if (m == NULL)
        return NULL;
    if (PyModule_AddIntConstant(m, "MAXDOF", MAXDOF) < 0 || PyModule_AddIntConstant(m, "MAXLINKS", MAXLINKS) < 0
        || PyModule_AddIntConstant(m, "MAXSHAPES", MAXSHAPES) < 0 || PyModule_AddIntConstant(m, "SHAPEF", SHAPEF) < 0
        || PyModule_AddIntConstant(m, "ITEMF", ITEMF) < 0 || PyModule_AddIntConstant(m, "POSEF", POSEF) < 0
        || PyModule_AddIntConstant(m, "BODYF", BODYF) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
