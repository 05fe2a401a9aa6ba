/* The compiled part of roarmctl's state checker (roarmctl/motion/collision.py, which builds its tables).
 *
 * For each arm state of a batch, in one C loop: joint limits, the forward kinematics of the
 * library's FK tables (Kinematics._steps, packed by collision.py; tests compare every link frame
 * with Kinematics.frames4), the smallest singular value of the translational Jacobian (the
 * singularity margin), every collision shape's world pose, and conservative pre-filters that
 * clear (shape, item) and (shape, shape) pairs that are certainly apart: bounding sphere vs the
 * item's world box, world boxes, then the separating-axis test of the two oriented bounding boxes
 * (each shape lies inside its box, so a separating axis of the boxes separates the shapes).
 * The pairs that no filter clears are returned as candidates; FCL (python-fcl) decides those.
 *
 * No numpy headers: arrays come in through the buffer protocol, C-contiguous float64 / int64 /
 * uint8 as collision.py makes them. Lengths are checked against the packed header.
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

/* Per-step float record: offset, A (16), B (16), C (16), post (16) */
#define STEPF 65
#define STEPI 5
#define CHAINF 19  /* origin (16), axis (3) */
#define CHAINI 2   /* parent link, kind (0 revolute, 1 prismatic) */
#define SHAPEF 19  /* rot (9), pos (3), half (3), half_self (3), radius (1) */
#define ITEMF 24   /* aabb centre (3), aabb half (3), rot (9), centre (3), local half (3), pad (3) */
#define POSEF 12   /* per state and shape: world rot (9), centre (3) */

typedef struct {
    int64_t dof, arm_n, n_links, n_steps, tcp, n_chain, S, M, n_active, n_pairs, grip, has_margin, n_const, n_groups, n_lp;
    const int64_t *arm, *const_idx, *steps, *chain, *shape_link, *active, *amask, *pairs, *g_link, *g_start, *g_order,
        *g_mask, *lp_links, *lp_start, *lp_order;
    const double *lower, *upper, *qt, *margin, *const_fr, *stepf, *chainf, *shapef, *itemf, *active_r2, *pair_r2, *active_r, *pair_r, *g_c, *g_r, *lp_f;
} Model;

#define HEADER 15

static int parse_model(Model *m, const Py_buffer *fb, const Py_buffer *ib) {
    const int64_t *I = (const int64_t *)ib->buf;
    const double *F = (const double *)fb->buf;
    Py_ssize_t ni = ib->len / 8, nf = fb->len / 8;
    if (ni < HEADER) goto bad;
    m->dof = I[0]; m->arm_n = I[1]; m->n_links = I[2]; m->n_steps = I[3]; m->tcp = I[4]; m->n_chain = I[5];
    m->S = I[6]; m->M = I[7]; m->n_active = I[8]; m->n_pairs = I[9]; m->grip = I[10]; m->has_margin = I[11];
    m->n_const = I[12]; m->n_groups = I[13]; m->n_lp = I[14];
    if (m->dof > MAXDOF || m->n_links > MAXLINKS || m->S > MAXSHAPES || m->arm_n > m->dof || m->n_chain > MAXDOF)
        goto bad;
    Py_ssize_t need_i = HEADER + m->arm_n + m->n_const + STEPI * m->n_steps + CHAINI * m->n_chain + m->S
                        + m->n_active + m->n_active * m->M + 2 * m->n_pairs
                        + m->n_groups + (m->n_groups + 1) + m->n_active + m->n_groups * m->M
                        + 2 * m->n_lp + (m->n_lp + 1) + m->n_pairs;
    Py_ssize_t need_f = 2 * m->arm_n + m->dof + 1 + 16 * m->n_const + STEPF * m->n_steps + CHAINF * m->n_chain
                        + SHAPEF * m->S + ITEMF * m->M + 2 * m->n_active + 2 * m->n_pairs + 4 * m->n_groups + 8 * m->n_lp;
    if (ni != need_i || nf != need_f) goto bad;
    const int64_t *p = I + HEADER;
    m->arm = p; p += m->arm_n;
    m->const_idx = p; p += m->n_const;
    m->steps = p; p += STEPI * m->n_steps;
    m->chain = p; p += CHAINI * m->n_chain;
    m->shape_link = p; p += m->S;
    m->active = p; p += m->n_active;
    m->amask = p; p += m->n_active * m->M;
    m->pairs = p; p += 2 * m->n_pairs;
    m->g_link = p; p += m->n_groups;      /* groups: the active shapes of one link, in one bounding sphere */
    m->g_start = p; p += m->n_groups + 1;
    m->g_order = p; p += m->n_active;     /* active indices, group by group */
    m->g_mask = p; p += m->n_groups * m->M;
    m->lp_links = p; p += 2 * m->n_lp;    /* link pairs: the self pairs between the shapes of two links */
    m->lp_start = p; p += m->n_lp + 1;
    m->lp_order = p;                      /* pair indices, link pair by link pair */
    const double *q = F;
    m->lower = q; q += m->arm_n;
    m->upper = q; q += m->arm_n;
    m->qt = q; q += m->dof;
    m->margin = q; q += 1;
    m->const_fr = q; q += 16 * m->n_const;
    m->stepf = q; q += STEPF * m->n_steps;
    m->chainf = q; q += CHAINF * m->n_chain;
    m->shapef = q; q += SHAPEF * m->S;
    m->itemf = q; q += ITEMF * m->M;
    m->active_r2 = q; q += m->n_active;
    m->pair_r2 = q; q += m->n_pairs;
    m->active_r = q; q += m->n_active;  /* sqrt of the above, for the grown ("near") tests */
    m->pair_r = q; q += m->n_pairs;
    m->g_c = q; q += 3 * m->n_groups;     /* group sphere centre in the link frame, radius */
    m->g_r = q; q += m->n_groups;
    m->lp_f = q;                          /* per link pair: sphere centre (link frame) and radius of each link */
    return 0;
bad:
    PyErr_SetString(PyExc_ValueError, "_checkkernel: packed tables do not match their header");
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

/* Link frames (n_links x 16, row-major 4x4) for the full configuration qf. */
static void fk(const Model *m, const double *qf, double *Fr) {
    for (int64_t c = 0; c < m->n_const; c++)
        memcpy(Fr + 16 * m->const_idx[c], m->const_fr + 16 * c, 16 * sizeof(double));
    double mm[16], t[16];
    for (int64_t s = 0; s < m->n_steps; s++) {
        const int64_t *si = m->steps + STEPI * s;
        const double *sf = m->stepf + STEPF * s;
        int64_t kind = si[0], parent = si[1], child = si[2], qi = si[3], has_post = si[4];
        const double *A = sf + 1, *B = sf + 17, *C = sf + 33, *P = sf + 49;
        const double *mp = mm;
        if (kind == 0) {           /* fixed */
            mp = C;
        } else if (kind == 1) {    /* revolute about local z: cos A + sin B + C */
            double ang = qf[qi] + sf[0], c = cos(ang), sn = sin(ang);
            for (int k = 0; k < 12; k++) mm[k] = c * A[k] + sn * B[k] + C[k];  /* mat4mul reads no bottom row */
        } else if (kind == 2) {    /* revolute about A[0..2]: origin @ Rodrigues */
            double ang = qf[qi] + sf[0], c = cos(ang), sn = sin(ang), v = 1.0 - c;
            double x = A[0], y = A[1], z = A[2], r[16] = {0};
            r[0] = c + x * x * v;     r[1] = x * y * v - z * sn; r[2] = x * z * v + y * sn;
            r[4] = y * x * v + z * sn; r[5] = c + y * y * v;     r[6] = y * z * v - x * sn;
            r[8] = z * x * v - y * sn; r[9] = z * y * v + x * sn; r[10] = c + z * z * v;
            r[15] = 1.0;
            mat4mul(C, r, mm);
        } else {                   /* prismatic: origin, moved by d along origin_rot @ axis (in A) */
            double d = qf[qi] + sf[0];
            memcpy(mm, C, sizeof mm);
            mm[3] += d * A[0]; mm[7] += d * A[1]; mm[11] += d * A[2];
        }
        if (has_post) {
            mat4mul(Fr + 16 * parent, mp, t);
            mat4mul(t, P, Fr + 16 * child);
        } else {
            mat4mul(Fr + 16 * parent, mp, Fr + 16 * child);
        }
    }
}

/* Gram matrix of the 3 x n translational Jacobian J: J J^T (3 x 3) when n >= 3, else J^T J (n x n);
 * returns its size. Its smallest eigenvalue is the square of J's smallest singular value. */
static int gram(const Model *m, const double *Fr, double A[3][3]) {
    int64_t n = m->n_chain;
    double J[3 * MAXDOF];
    const double *T = Fr + 16 * m->tcp;
    double pt[3] = {T[3], T[7], T[11]};
    for (int64_t j = 0; j < n; j++) {
        const int64_t *ci = m->chain + CHAINI * j;
        const double *cf = m->chainf + CHAINF * j;
        const double *Pa = Fr + 16 * ci[0], *O = cf, *ax = cf + 16;
        double oa[3], z[3];
        for (int r = 0; r < 3; r++) {
            /* o = p_parent + R_parent @ origin_t;  z = R_parent @ (origin_R @ axis) */
            oa[r] = Pa[4 * r + 3] + Pa[4 * r] * O[3] + Pa[4 * r + 1] * O[7] + Pa[4 * r + 2] * O[11];
        }
        double la[3];
        for (int r = 0; r < 3; r++) la[r] = O[4 * r] * ax[0] + O[4 * r + 1] * ax[1] + O[4 * r + 2] * ax[2];
        for (int r = 0; r < 3; r++) z[r] = Pa[4 * r] * la[0] + Pa[4 * r + 1] * la[1] + Pa[4 * r + 2] * la[2];
        double *col = J + 3 * j;
        if (ci[1] == 0) {
            double d[3] = {pt[0] - oa[0], pt[1] - oa[1], pt[2] - oa[2]};
            col[0] = z[1] * d[2] - z[2] * d[1];
            col[1] = z[2] * d[0] - z[0] * d[2];
            col[2] = z[0] * d[1] - z[1] * d[0];
        } else {
            col[0] = z[0]; col[1] = z[1]; col[2] = z[2];
        }
    }
    if (n >= 3) {
        for (int r = 0; r < 3; r++)
            for (int c = r; c < 3; c++) {
                double s = 0;
                for (int64_t k = 0; k < n; k++) s += J[3 * k + r] * J[3 * k + c];
                A[r][c] = A[c][r] = s;
            }
        return 3;
    }
    for (int r = 0; r < n; r++)
        for (int c = r; c < n; c++)
            A[r][c] = A[c][r] = J[3 * r] * J[3 * c] + J[3 * r + 1] * J[3 * c + 1] + J[3 * r + 2] * J[3 * c + 2];
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

/* sigma_min >= margin, decided by the closed-form smallest eigenvalue of the 3 x 3 Gram matrix (Smith
 * 1961: a few operations, error below about 3e-8 of the trace even for close eigenvalues) wherever it is
 * clearly on one side (1e-6 of the trace), else by sigma_min itself: the same decisions as sigma_min. */
static int margin_ok(const Model *m, const double *Fr) {
    double G[3][3];
    int dim = gram(m, Fr, G);
    double margin = m->margin[0];
    if (dim == 3) {
        double p1 = G[0][1] * G[0][1] + G[0][2] * G[0][2] + G[1][2] * G[1][2];
        double tr = G[0][0] + G[1][1] + G[2][2], qm = tr / 3.0;
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
        double band = 1e-6 * tr;
        if (lo > margin * margin + band) return 1;
        if (lo < margin * margin - band) return 0;
    }
    return sigma_min(G, dim) >= margin;
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
    memcpy(qf, m->qt, m->dof * sizeof(double));
    for (int64_t j = 0; j < m->arm_n; j++) qf[m->arm[j]] = q[i * m->arm_n + j];
    if (n_grip && m->grip >= 0) qf[m->grip] = grip[i];
}

/* One state: arm values qi (arm_n), gripper value *gp (or the template's when gp is NULL), output row i.
 * Returns 1 (valid so far: FCL decides the candidates it added), 0 (limits or margin) or -1 (a candidate
 * buffer is full). With stop, an invalid state returns at once (no near flag, no poses). */
static int check_state(const Model *mp, const double *qi, const double *gp, Py_ssize_t i, uint8_t *valid, uint8_t *near,
                       int64_t *sc, Py_ssize_t *ns, Py_ssize_t cap_s, int64_t *pc, Py_ssize_t *np_, Py_ssize_t cap_p,
                       double *pose, double sweep, int stop) {
    const Model m = *mp;
    double qf[MAXDOF], Fr[16 * MAXLINKS];
    near[i] = 0;
    int ok = 1;
    for (int64_t j = 0; j < m.arm_n; j++)
        if (!(qi[j] >= m.lower[j] - 1e-9 && qi[j] <= m.upper[j] + 1e-9)) ok = 0;
    memcpy(qf, m.qt, m.dof * sizeof(double));
    for (int64_t j = 0; j < m.arm_n; j++) qf[m.arm[j]] = qi[j];
    if (gp && m.grip >= 0) qf[m.grip] = *gp;
    fk(&m, qf, Fr);
    if (ok && m.has_margin && !margin_ok(&m, Fr)) ok = 0;
    valid[i] = (uint8_t)ok;
    if (!ok && stop) return 0;
    double *ps = pose + i * m.S * POSEF;
    uint8_t rot_done[MAXSHAPES];  /* rotations only for the shapes that pass a sphere test */
    for (int64_t a = 0; a < m.S; a++) {
        const double *L = Fr + 16 * m.shape_link[a], *sf = m.shapef + SHAPEF * a;
        double *o = ps + POSEF * a;
        for (int r = 0; r < 3; r++)
            o[9 + r] = L[4 * r + 3] + (L[4 * r] * sf[9] + L[4 * r + 1] * sf[10] + L[4 * r + 2] * sf[11]);
        rot_done[a] = 0;
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
        const double *L = Fr + 16 * m.g_link[g], *gc = m.g_c + 3 * g;
        double cg[3], gr = m.g_r[g] + (sweep > 0 ? sweep : 0.0);
        for (int r = 0; r < 3; r++) cg[r] = L[4 * r + 3] + L[4 * r] * gc[0] + L[4 * r + 1] * gc[1] + L[4 * r + 2] * gc[2];
        for (int64_t k = 0; k < m.M; k++) {
            if (!m.g_mask[g * m.M + k]) continue;
            const double *it = m.itemf + ITEMF * k;
            double dg = 0;
            for (int r = 0; r < 3; r++) {
                double e = fabs(cg[r] - it[r]) - it[3 + r];
                if (e > 0) dg += e * e;
            }
            if (!(dg < gr * gr)) continue;
            for (int64_t gi = m.g_start[g]; gi < m.g_start[g + 1]; gi++) {
                int64_t ai = m.g_order[gi], a = m.active[ai];
                if (!m.amask[ai * m.M + k]) continue;
                const double *o = ps + POSEF * a, *sf = m.shapef + SHAPEF * a;
                double r2 = m.active_r2[ai];
                double d2 = 0;
                for (int r = 0; r < 3; r++) {
                    double e = fabs(o[9 + r] - it[r]) - it[3 + r];
                    if (e > 0) d2 += e * e;
                }
                if (sweep > 0 && d2 < (m.active_r[ai] + sweep) * (m.active_r[ai] + sweep)) near[i] = 1;
                if (!ok || !(d2 < r2)) continue;
                NEED_ROT(a)
                int in = 1;  /* world boxes */
                for (int r = 0; r < 3 && in; r++) {
                    double hw = fabs(o[3 * r]) * sf[12] + fabs(o[3 * r + 1]) * sf[13] + fabs(o[3 * r + 2]) * sf[14];
                    if (!(fabs(o[9 + r] - it[r]) < hw + it[3 + r])) in = 0;
                }
                if (!in || obb_apart(o, o + 9, sf + 12, it + 6, it + 15, it + 18)) continue;
                if (*ns >= cap_s) return -1;
                sc[3 * *ns] = i; sc[3 * *ns + 1] = a; sc[3 * *ns + 2] = k; (*ns)++;
            }
        }
    }
    for (int64_t lp = 0; lp < m.n_lp; lp++) {
        /* each link's sphere holds the spheres of its shapes: where the two links' spheres (grown by sweep)
         * are apart, so are all their shape pairs */
        const double *LA = Fr + 16 * m.lp_links[2 * lp], *LB = Fr + 16 * m.lp_links[2 * lp + 1], *f = m.lp_f + 8 * lp;
        double dl = 0, lim = f[3] + f[7] + (sweep > 0 ? 2 * sweep : 0.0);
        for (int r = 0; r < 3; r++) {
            double e = (LA[4 * r + 3] + LA[4 * r] * f[0] + LA[4 * r + 1] * f[1] + LA[4 * r + 2] * f[2])
                       - (LB[4 * r + 3] + LB[4 * r] * f[4] + LB[4 * r + 1] * f[5] + LB[4 * r + 2] * f[6]);
            dl += e * e;
        }
        if (!(dl < lim * lim)) continue;
      for (int64_t pk = m.lp_start[lp]; pk < m.lp_start[lp + 1]; pk++) {
        int64_t p = m.lp_order[pk];
        int64_t a = m.pairs[2 * p], bb = m.pairs[2 * p + 1];
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
 * int64 candidates (state, shape, item) / (state, pair); pose (N, S, 12) float64: every shape's centre,
 * the rotation only of the shapes that some pair's sphere test kept (all shapes of the candidates). */
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
        PyErr_SetString(PyExc_ValueError, "_checkkernel.check: output buffers too small");
        goto done;
    }
    Py_ssize_t ns = 0, np_ = 0, limit = N;
    for (Py_ssize_t i = 0; i < N; i++) {
        int ok = check_state(&m, q + i * m.arm_n, n_grip ? grip + i : NULL, i, valid, near, sc, &ns, cap_s, pc, &np_,
                             cap_p, pose, sweep, stop);
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
    PyErr_SetString(PyExc_ValueError, "_checkkernel.check: candidate buffer too small");
done:
    for (int k = 0; k < got; k++) PyBuffer_Release(&b[k]);
    return result;
}

/* check_line(F, I, q0, d, steps, start, stride, idx, refine, valid, near, scene, self, pose, sweep, stop)
 *   -> (n_scene, n_self, limit, count)
 * Like check() for the states of the segment q0 -> q0 + d without building them in Python: state i of the
 * segment is q0 + d * t_i with t_i = i * (1 / steps) and t_steps = 1 (np.linspace's numbers). Without idx
 * (empty) the states are i = start, start + stride, ... <= steps; with idx, the states between i and i + 1
 * for each i of idx: s_i + (s_{i+1} - s_i) * (k / refine), k = 1 .. refine - 1 (the refinement). */
static void line_state(const double *q0, const double *d, int64_t n, int64_t steps, int64_t i, double *out) {
    double t = i == steps ? 1.0 : (double)i * (1.0 / (double)steps);
    for (int64_t j = 0; j < n; j++) out[j] = q0[j] + d[j] * t;
}

static PyObject *check_line(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 16) {
        PyErr_SetString(PyExc_TypeError, "check_line() takes 16 arguments");
        return NULL;
    }
    static const int bufarg[10] = {0, 1, 2, 3, 7, 9, 10, 11, 12, 13};
    Py_buffer b[10];
    int got = 0;
    PyObject *result = NULL;
    for (; got < 10; got++)
        if ((got < 5 ? get_in(args[bufarg[got]], &b[got]) : get_out(args[bufarg[got]], &b[got])) < 0) goto done;
    int64_t steps = PyLong_AsLongLong(args[4]), start = PyLong_AsLongLong(args[5]), stride = PyLong_AsLongLong(args[6]);
    int64_t refine = PyLong_AsLongLong(args[8]);
    double sweep = PyFloat_AsDouble(args[14]);
    int stop = PyObject_IsTrue(args[15]);
    if (PyErr_Occurred()) goto done;
    Model m;
    if (parse_model(&m, &b[0], &b[1]) < 0) goto done;
    const double *q0 = b[2].buf, *d = b[3].buf;
    const int64_t *idx = b[4].buf;
    Py_ssize_t n_idx = b[4].len / 8;
    uint8_t *valid = b[5].buf, *near = b[6].buf;
    int64_t *sc = b[7].buf, *pc = b[8].buf;
    double *pose = b[9].buf;
    Py_ssize_t cap_s = b[7].len / 24, cap_p = b[8].len / 16;
    if (steps < 1 || stride < 1 || start < 0 || refine < 1 || b[2].len != 8 * m.arm_n || b[3].len != 8 * m.arm_n) {
        PyErr_SetString(PyExc_ValueError, "_checkkernel.check_line: bad arguments");
        goto done;
    }
    Py_ssize_t N = n_idx ? n_idx * (refine - 1) : (start > steps ? 0 : (steps - start) / stride + 1);
    if (b[5].len < N || b[6].len < N || b[9].len < (Py_ssize_t)(N * m.S * POSEF * 8)) {
        PyErr_SetString(PyExc_ValueError, "_checkkernel.check_line: output buffers too small");
        goto done;
    }
    double qa[MAXDOF], qb[MAXDOF], qs[MAXDOF];
    Py_ssize_t ns = 0, np_ = 0, limit = N, row = 0;
    for (Py_ssize_t u = 0; u < (n_idx ? n_idx : N); u++) {
        int64_t kmax = n_idx ? refine - 1 : 1;
        if (n_idx) {
            line_state(q0, d, m.arm_n, steps, idx[u], qa);
            line_state(q0, d, m.arm_n, steps, idx[u] + 1, qb);
        }
        for (int64_t k = 1; k <= kmax; k++, row++) {
            if (n_idx) {
                double t = (double)k / (double)refine;
                for (int64_t j = 0; j < m.arm_n; j++) qs[j] = qa[j] + (qb[j] - qa[j]) * t;
            } else {
                line_state(q0, d, m.arm_n, steps, start + u * stride, qs);
            }
            int ok = check_state(&m, qs, NULL, row, valid, near, sc, &ns, cap_s, pc, &np_, cap_p, pose, sweep, stop);
            if (ok < 0) goto overflow;
            if (!ok && stop) {
                limit = row;
                goto finished;
            }
        }
    }
finished:
    for (Py_ssize_t i = limit + 1; i < N; i++) {
        valid[i] = 1;
        near[i] = 0;
    }
    result = Py_BuildValue("nnnn", ns, np_, limit, N);
    goto done;
overflow:
    PyErr_SetString(PyExc_ValueError, "_checkkernel.check_line: candidate buffer too small");
done:
    for (int k = 0; k < got; k++) PyBuffer_Release(&b[k]);
    return result;
}

/* frames(F, I, q, grip, out): link frames (N, n_links, 16) and sigma(F, I, q, grip, out): (N,) margin
 * measure, for the tests and CollisionChecker.explain. */
static PyObject *frames_or_sigma(PyObject *const *args, Py_ssize_t nargs, int want_sigma) {
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "takes 5 arguments");
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
    if ((n_grip && n_grip != N) || b[4].len < (Py_ssize_t)(N * 8 * (want_sigma ? 1 : 16 * m.n_links))) {
        PyErr_SetString(PyExc_ValueError, "_checkkernel: output buffer too small");
        goto done;
    }
    double qf[MAXDOF], Fr[16 * MAXLINKS];
    double *out = b[4].buf;
    for (Py_ssize_t i = 0; i < N; i++) {
        full_q(&m, b[2].buf, b[3].buf, n_grip, i, qf);
        fk(&m, qf, Fr);
        if (want_sigma) {
            double G[3][3];
            int dim = gram(&m, Fr, G);
            out[i] = sigma_min(G, dim);
        }
        else
            memcpy(out + i * 16 * m.n_links, Fr, 16 * m.n_links * sizeof(double));
    }
    Py_INCREF(Py_None);
    result = Py_None;
done:
    for (int k = 0; k < got; k++) PyBuffer_Release(&b[k]);
    return result;
}

static PyObject *frames(PyObject *self, PyObject *const *args, Py_ssize_t nargs) { return frames_or_sigma(args, nargs, 0); }
static PyObject *sigma(PyObject *self, PyObject *const *args, Py_ssize_t nargs) { return frames_or_sigma(args, nargs, 1); }

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

static PyMethodDef methods[] = {
    {"check", (PyCFunction)(void (*)(void))check, METH_FASTCALL, "Batch state check (see collision.py)."},
    {"check_line", (PyCFunction)(void (*)(void))check_line, METH_FASTCALL, "Check states of a straight segment."},
    {"frames", (PyCFunction)(void (*)(void))frames, METH_FASTCALL, "Link frames of a batch."},
    {"sigma", (PyCFunction)(void (*)(void))sigma, METH_FASTCALL, "Margin measure of a batch."},
    {"apart", (PyCFunction)(void (*)(void))apart, METH_FASTCALL, "Separating-axis test of two boxes."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef moddef = {PyModuleDef_HEAD_INIT, "_checkkernel", "roarmctl's compiled state-check kernel.", -1, methods};

PyMODINIT_FUNC PyInit__checkkernel(void) { return PyModule_Create(&moddef); }
