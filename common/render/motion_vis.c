/* Analytic camera visibility over the shutter (see motion_vis.h, docs/motion.md). Geometry
 * runs in double, relative to the ray origin. Moving geometry is resampled into linear
 * segments (Embree's own time steps, subdivided so no segment rotates more than
 * MV_MAX_ANGLE_DEG); a user geometry over the swept box of each (triangle, segment) lets
 * Embree collect the candidates of a ray. The strata only decide where the shutter is cut
 * and how each part is weighted: every stratum is shaded by the ordinary trace at a time
 * inside it, so an approximate cut costs noise, never bias. */
#include "render/motion_vis.h"
#include "base/log.h"
#include "scene/motion.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MV_MAX_CANDS 512   /* candidates of one ray at most; beyond, the ray samples time */
#define MV_MAX_PIECES 256
#define MV_MAX_PRIMS (1u << 22)     /* swept boxes of one object at most (when rotation splits) */
#define MV_MAX_DOUBLES (1u << 24)   /* resampled positions of one object at most */
#define MV_BISECT 48       /* halvings that locate a depth crossing (to 2^-48 of its interval) */

/* Ternary min / max: fmin and fmax are library calls without -ffast-math. */
static inline double min2(double a, double b) { return a < b ? a : b; }
static inline double max2(double a, double b) { return a > b ? a : b; }

static double dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static void cross3(const double a[3], const double b[3], double out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* d . (a x b) */
static double triple(const double d[3], const double a[3], const double b[3])
{
    double c[3];
    cross3(a, b, c);
    return dot3(d, c);
}

int mv_quadratic_roots(double a, double b, double c, double r[2])
{
    /* Scale so the largest coefficient is 1: no overflow of b^2 at 1e6 units, no
     * underflow of 4ac for 1e-7 triangles. */
    double m = max2(fabs(a), max2(fabs(b), fabs(c)));
    if (!(m > 0.0) || !isfinite(m))
        return 0;
    a /= m, b /= m, c /= m;
    if (a == 0.0) {
        if (b == 0.0)
            return 0;
        r[0] = -c / b;
        return 1;
    }
    double disc = b * b - 4.0 * a * c;
    if (disc < 0.0)
        return 0; /* no real root: the sign never changes (a double root lost to rounding
                   * only touches zero, which changes no coverage either) */
    double q = -0.5 * (b + copysign(sqrt(disc), b));
    if (q == 0.0) { /* b == 0 and c == 0: a double root at 0 */
        r[0] = 0.0;
        return 1;
    }
    double x0 = q / a, x1 = c / q;
    if (x0 > x1) {
        double t = x0;
        x0 = x1, x1 = t;
    }
    r[0] = x0;
    if (x1 == x0)
        return 1;
    r[1] = x1;
    return 2;
}

/* Local parameter s in [0, 1] of the segment at time01 t. */
static double seg_s(const struct mv_cand *c, double t)
{
    return c->tb > c->ta ? (t - c->ta) / (c->tb - c->ta) : 0.5;
}

static void lerp_point(const struct mv_cand *c, int i, double s, double out[3])
{
    for (int k = 0; k < 3; k++)
        out[k] = c->p0[i][k] + s * (c->p1[i][k] - c->p0[i][k]);
}

static double depth_at_s(const struct mv_cand *c, const double d[3], double s)
{
    if (c->sphere) {
        double w[3], r = c->p0[1][0] + s * (c->p1[1][0] - c->p0[1][0]);
        lerp_point(c, 0, s, w);
        double b = dot3(w, d), p[3] = {w[0] - b * d[0], w[1] - b * d[1], w[2] - b * d[2]};
        double q = r * r - dot3(p, p), h = sqrt(q > 0.0 ? q : 0.0);
        if (b - h > 0.0)
            return b - h;
        return b + h > 0.0 ? b + h : INFINITY;
    }
    double v[3][3], e1[3], e2[3], n[3];
    for (int i = 0; i < 3; i++)
        lerp_point(c, i, s, v[i]);
    for (int k = 0; k < 3; k++)
        e1[k] = v[1][k] - v[0][k], e2[k] = v[2][k] - v[0][k];
    cross3(e1, e2, n);
    double den = dot3(d, n);
    if (den == 0.0)
        return INFINITY;
    double t = dot3(v[0], n) / den;
    return t > 0.0 && isfinite(t) ? t : INFINITY;
}

double mv_cand_depth(const struct mv_cand *c, const double d[3], double t)
{
    return depth_at_s(c, d, seg_s(c, t));
}

/* Coefficients (a, b, c) of the edge function d . (v_i(s) x v_j(s)) of triangle c. */
static void edge_quadratic(const struct mv_cand *c, const double d[3], int i, int j, double q[3])
{
    double bi[3], bj[3];
    for (int k = 0; k < 3; k++)
        bi[k] = c->p1[i][k] - c->p0[i][k], bj[k] = c->p1[j][k] - c->p0[j][k];
    q[0] = triple(d, bi, bj);
    q[1] = triple(d, c->p0[i], bj) + triple(d, bi, c->p0[j]);
    q[2] = triple(d, c->p0[i], c->p0[j]);
}

/* Coefficients of r(s)^2 - dist(s)^2 for a sphere: positive where the line passes inside.
 * The distance uses the parts of centre and motion across d (no |w|^2 - (w.d)^2). */
static void sphere_quadratic(const struct mv_cand *c, const double d[3], double q[3])
{
    double dc[3], p0[3], pd[3];
    for (int k = 0; k < 3; k++)
        dc[k] = c->p1[0][k] - c->p0[0][k];
    double b0 = dot3(c->p0[0], d), bd = dot3(dc, d);
    for (int k = 0; k < 3; k++)
        p0[k] = c->p0[0][k] - b0 * d[k], pd[k] = dc[k] - bd * d[k];
    double r0 = c->p0[1][0], dr = c->p1[1][0] - r0;
    q[0] = dr * dr - dot3(pd, pd);
    q[1] = 2.0 * (r0 * dr - dot3(p0, pd));
    q[2] = r0 * r0 - dot3(p0, p0);
}

static double eval_q(const double q[3], double s) { return (q[0] * s + q[1]) * s + q[2]; }

/* The sign of quadratic q over [0, 1]: 1 if > 0 throughout, -1 if < 0 throughout, else 0. */
static int fixed_sign(const double q[3])
{
    double lo = min2(q[2], q[0] + q[1] + q[2]), hi = max2(q[2], q[0] + q[1] + q[2]);
    if (q[0] != 0.0) {
        double v = -q[1] / (2.0 * q[0]);
        if (v > 0.0 && v < 1.0) {
            double e = eval_q(q, v);
            lo = min2(lo, e), hi = max2(hi, e);
        }
    }
    return lo > 0.0 ? 1 : (hi < 0.0 ? -1 : 0);
}

void mv_cand_coverage(struct mv_cand *c, const double d[3])
{
    double q[3][3] = {{0}}, split[8];
    int nq = c->sphere ? 1 : 3, ns = 0;
    c->niv = 0;
    if (c->sphere)
        sphere_quadratic(c, d, q[0]);
    else {
        for (int e = 0; e < 3; e++)
            edge_quadratic(c, d, e, (e + 1) % 3, q[e]);
        /* Most candidates from swept boxes never cover the ray: one edge keeps it outside
         * on one side while another stays on the other side all segment long. */
        int s0 = fixed_sign(q[0]), s1 = fixed_sign(q[1]), s2 = fixed_sign(q[2]);
        if (s0 * s1 < 0 || s1 * s2 < 0 || s0 * s2 < 0)
            return;
    }
    split[ns++] = 0.0;
    for (int e = 0; e < nq; e++) {
        double r[2];
        int n = mv_quadratic_roots(q[e][0], q[e][1], q[e][2], r);
        for (int k = 0; k < n; k++)
            if (r[k] > 0.0 && r[k] < 1.0)
                split[ns++] = r[k];
    }
    split[ns++] = 1.0;
    for (int i = 1; i < ns; i++) /* insertion sort of at most 8 */
        for (int j = i; j > 0 && split[j] < split[j - 1]; j--) {
            double t = split[j];
            split[j] = split[j - 1], split[j - 1] = t;
        }
    int zero = !(c->tb > c->ta);
    /* Every vertex in front of the origin at both ends: any hit is in front (a covered
     * triangle that is not edge-on has a finite depth). */
    int front = !c->sphere;
    for (int i = 0; i < 3 && front; i++)
        front = dot3(c->p0[i], d) > 0.0 && dot3(c->p1[i], d) > 0.0;
    for (int i = 0; i + 1 < ns; i++) {
        if (!(split[i + 1] > split[i]) && !zero)
            continue;
        double m = 0.5 * (split[i] + split[i + 1]);
        int covered;
        if (c->sphere) {
            covered = eval_q(q[0], m) > 0.0;
        } else {
            /* Both windings: the triangle may flip during the segment. All zero is a
             * degenerate (line) triangle seen edge-on: no area. */
            double e0 = eval_q(q[0], m), e1 = eval_q(q[1], m), e2 = eval_q(q[2], m);
            covered = (e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0 && (e0 > 0.0 || e1 > 0.0 || e2 > 0.0)) ||
                      (e0 <= 0.0 && e1 <= 0.0 && e2 <= 0.0 && (e0 < 0.0 || e1 < 0.0 || e2 < 0.0));
        }
        if (!covered || (!front && depth_at_s(c, d, m) == INFINITY))
            continue;
        double t0 = c->ta + split[i] * (c->tb - c->ta), t1 = c->ta + split[i + 1] * (c->tb - c->ta);
        if (i + 1 == ns - 1)
            t1 = c->tb; /* exact segment ends, so neighbouring segments join */
        if (i == 0)
            t0 = c->ta;
        if (c->niv > 0 && c->iv[c->niv - 1][1] == t0)
            c->iv[c->niv - 1][1] = t1;
        else if (c->niv < MV_MAX_IV) {
            c->iv[c->niv][0] = t0;
            c->iv[c->niv][1] = t1;
            c->niv++;
        }
        if (zero)
            break;
    }
}

/* The surface in front at time t among the active candidates (or MV_STILL); ties go to
 * the still surface, then to the earlier candidate. */
static uint32_t winner(const struct mv_cand *c, const uint32_t *act, uint32_t na, const double d[3], double still,
                       double t)
{
    uint32_t best = MV_STILL;
    double bd = still;
    for (uint32_t k = 0; k < na; k++) {
        double z = mv_cand_depth(&c[act[k]], d, t);
        if (z < bd || (z == bd && best != MV_STILL && act[k] < best))
            bd = z, best = act[k];
    }
    return best;
}

/* A coverage interval's start (on = 1) or end (on = 0) for the sweep over the shutter. */
struct mv_event {
    double t;
    uint32_t cand, on;
};

static int cmp_event(const void *a, const void *b)
{
    const struct mv_event *x = a, *y = b;
    if (x->t != y->t)
        return x->t < y->t ? -1 : 1;
    if (x->on != y->on)
        return x->on < y->on ? -1 : 1; /* ends first: an interval that starts where another ends */
    return x->cand < y->cand ? -1 : x->cand > y->cand;
}

/* Appends [t0, t1] of cand to the pieces, merging with the last one. 0 when full. */
static int emit(struct mv_piece *out, uint32_t *n, uint32_t max, double t0, double t1, uint32_t cand)
{
    if (*n > 0 && out[*n - 1].cand == cand) {
        out[*n - 1].t1 = t1;
        return 1;
    }
    if (*n >= max)
        return 0;
    out[*n].t0 = t0, out[*n].t1 = t1, out[*n].cand = cand;
    (*n)++;
    return 1;
}

uint32_t mv_resolve(const struct mv_cand *c, uint32_t nc, const double d[3], double still_depth,
                    struct mv_piece *out, uint32_t max)
{
    if (nc > MV_MAX_CANDS || max == 0)
        return 0;
    static _Thread_local struct mv_event ev[2 * MV_MAX_IV * MV_MAX_CANDS];
    uint32_t ne = 0, n = 0, na = 0;
    for (uint32_t i = 0; i < nc; i++)
        for (uint32_t k = 0; k < c[i].niv; k++)
            if (c[i].iv[k][1] > c[i].iv[k][0]) {
                ev[ne++] = (struct mv_event){c[i].iv[k][0], i, 1};
                ev[ne++] = (struct mv_event){c[i].iv[k][1], i, 0};
            }
    if (ne <= 32) { /* the usual few: insertion sort beats qsort's set-up */
        for (uint32_t i = 1; i < ne; i++)
            for (uint32_t j = i; j > 0 && cmp_event(&ev[j], &ev[j - 1]) < 0; j--) {
                struct mv_event t = ev[j];
                ev[j] = ev[j - 1], ev[j - 1] = t;
            }
    } else {
        qsort(ev, ne, sizeof *ev, cmp_event);
    }
    /* Sweep: between consecutive event times the active set (candidates covering the ray)
     * is fixed. */
    uint32_t act[MV_MAX_CANDS];
    double lo = 0.0;
    for (uint32_t e = 0; e <= ne; e++) {
        double hi = e < ne ? ev[e].t : 1.0;
        hi = hi > 1.0 ? 1.0 : hi;
        if (hi > lo) {
            /* The front surface at both ends; where they differ, the depth curves cross:
             * bisect for the crossing, and go on from it. */
            uint32_t wa = winner(c, act, na, d, still_depth, lo);
            for (uint32_t guard = 0;; guard++) {
                uint32_t wb = winner(c, act, na, d, still_depth, hi);
                if (wa == wb || guard >= na) {
                    if (!emit(out, &n, max, lo, hi, wa))
                        return 0;
                    break;
                }
                double l = lo, r = hi;
                for (int it = 0; it < MV_BISECT; it++) {
                    double m = 0.5 * (l + r);
                    if (winner(c, act, na, d, still_depth, m) == wa)
                        l = m;
                    else
                        r = m;
                }
                if (!emit(out, &n, max, lo, r, wa))
                    return 0;
                lo = r;
                wa = winner(c, act, na, d, still_depth, r);
            }
            lo = hi;
        }
        if (e == ne)
            break;
        if (ev[e].on) {
            act[na++] = ev[e].cand;
        } else {
            uint32_t k = 0;
            while (k < na && act[k] != ev[e].cand)
                k++;
            if (k < na) /* keep the order: ties go to the earlier candidate whatever the sweep */
                memmove(&act[k], &act[k + 1], sizeof *act * (na - k - 1)), na--;
        }
    }
    return n;
}

double mv_shutter_cdf(double r, double t)
{
    t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
    if (r <= 0.0)
        return t;
    double h = 1.0 / (1.0 - r); /* the density's plateau */
    if (t < r)
        return 0.5 * h * t * t / r;
    if (t > 1.0 - r)
        return 1.0 - 0.5 * h * (1.0 - t) * (1.0 - t) / r;
    return 0.5 * h * r + h * (t - r);
}

static uint32_t piece_key(const struct mv_piece *p, const struct mv_cand *c)
{
    return p->cand == MV_STILL ? MV_STILL : c[p->cand].obj;
}

void mv_strata_from_pieces(const struct camera *cam, const struct mv_piece *p, uint32_t np, const struct mv_cand *c,
                           float u, struct mv_strata *st)
{
    uint32_t key[MV_MAX_STRATA], nk = 0;
    double r = cam->shutter_ramp;
    double w[MV_MAX_STRATA] = {0};
    uint8_t of[MV_MAX_PIECES];
    for (uint32_t i = 0; i < np && i < MV_MAX_PIECES; i++) {
        uint32_t k = piece_key(&p[i], c), j = 0;
        while (j < nk && key[j] != k)
            j++;
        if (j == nk) {
            if (nk < MV_MAX_STRATA)
                key[nk++] = k;
            else
                j = MV_MAX_STRATA - 1; /* the rest join the last stratum: still unbiased */
        }
        of[i] = (uint8_t)j;
        w[j] += mv_shutter_cdf(r, p[i].t1) - mv_shutter_cdf(r, p[i].t0);
    }
    st->n = 0;
    for (uint32_t j = 0; j < nk; j++) {
        if (!(w[j] > 0.0))
            continue;
        /* u over the stratum's share of the shutter curve, walked through its pieces. */
        double x = (double)u * w[j], t = 0.0;
        for (uint32_t i = 0; i < np && i < MV_MAX_PIECES; i++) {
            if (of[i] != j)
                continue;
            double c0 = mv_shutter_cdf(r, p[i].t0), wi = mv_shutter_cdf(r, p[i].t1) - c0;
            t = p[i].t1;
            if (x < wi) {
                t = camera_shutter_warp(cam, (float)(c0 + x));
                t = t < p[i].t0 ? p[i].t0 : (t > p[i].t1 ? p[i].t1 : t);
                break;
            }
            x -= wi;
        }
        st->time01[st->n] = (float)t;
        st->weight[st->n] = w[j];
        st->n++;
    }
}

/* ---- candidates from Embree ---- */

/* A moving mesh or sphere resampled at segs + 1 uniform times over the shutter. */
struct mv_object {
    uint32_t obj;           /* stratum key */
    int sphere;
    uint32_t segs, num_vertices;
    const uint32_t *indices; /* triangles (meshes) */
    double *pos;            /* (segs + 1) * 3 * num_vertices; spheres: (segs + 1) * 4 (centre, radius) */
};

struct motion_vis {
    RTCScene scene;
    const struct accel *accel;
    uint32_t num_objects;
    struct mv_object *objects;
    uint8_t *top_moving;    /* per top-level geometry of the accel: it has motion data */
};

/* Collects candidates while Embree walks the swept boxes (never reports a hit). */
struct mv_query {
    struct RTCIntersectContext ctx; /* first: Embree hands it back to the callback */
    double o[3], d[3];
    double u[3], v[3];      /* completes d to an orthonormal, right-handed basis (u, v, d) */
    struct mv_cand *cand;
    uint32_t nc;
    int overflow;
};

static void apply_key(const struct motion_key *k, const double p[3], double out[3])
{
    double v[3] = {p[0] * k->scale.x, p[1] * k->scale.y, p[2] * k->scale.z};
    double w = k->quat[0], u[3] = {k->quat[1], k->quat[2], k->quat[3]}, t[3], uu[3];
    cross3(u, v, t);
    cross3(u, t, uu);
    out[0] = v[0] + 2.0 * (w * t[0] + uu[0]) + k->translate.x;
    out[1] = v[1] + 2.0 * (w * t[1] + uu[1]) + k->translate.y;
    out[2] = v[2] + 2.0 * (w * t[2] + uu[2]) + k->translate.z;
}

/* Linear segments over [t0, t1] for keys and frames: Embree's steps, each split so no part
 * turns more than MV_MAX_ANGLE_DEG (the chord's distance from the arc is then at most
 * R (1 - cos(MV_MAX_ANGLE_DEG / 2)) for a point at R from the axis). */
static uint32_t object_segments(const struct motion_key *keys, uint32_t nkeys, const float *ftimes, uint32_t nframes,
                                double t0, double t1, uint32_t num_vertices, uint32_t num_prims)
{
    uint32_t steps = 2;
    if (nkeys > 0 && !motion_keys_still(keys, nkeys, t0, t1))
        steps = motion_step_count(&keys[0].time, sizeof *keys, nkeys, t0, t1);
    if (nframes >= 2) {
        uint32_t fs = motion_step_count(ftimes, sizeof(float), nframes, t0, t1);
        steps = fs > steps ? fs : steps;
    }
    uint32_t base = steps - 1, sub = 1;
    if (nkeys > 0) {
        double worst = 0.0;
        for (uint32_t k = 0; k < base; k++) {
            struct motion_key a, b;
            motion_key_at(keys, nkeys, t0 + (t1 - t0) * k / base, &a);
            motion_key_at(keys, nkeys, t0 + (t1 - t0) * (k + 1) / base, &b);
            double dq = fabs((double)a.quat[0] * b.quat[0] + (double)a.quat[1] * b.quat[1] +
                             (double)a.quat[2] * b.quat[2] + (double)a.quat[3] * b.quat[3]);
            double ang = 2.0 * acos(dq < 1.0 ? dq : 1.0) * (180.0 / M_PI);
            worst = ang > worst ? ang : worst;
        }
        sub = (uint32_t)ceil(worst / MV_MAX_ANGLE_DEG);
        sub = sub < 1 ? 1 : (sub * base > 1024 ? 1024 / base : sub);
        /* Memory: at most MV_MAX_PRIMS swept boxes and MV_MAX_DOUBLES positions an object
         * (a coarser cut costs noise, not bias). */
        uint64_t by_prims = MV_MAX_PRIMS / ((uint64_t)base * num_prims + 1);
        uint64_t by_pos = MV_MAX_DOUBLES / ((uint64_t)base * 3 * num_vertices + 1);
        uint64_t cap = by_prims < by_pos ? by_prims : by_pos;
        sub = sub > cap ? (cap > 1 ? (uint32_t)cap : 1) : sub;
    }
    return base * sub;
}

static void object_fill(struct mv_object *ob, const float *positions, const struct motion_key *keys, uint32_t nkeys,
                        const float *fpos, const float *ftimes, uint32_t nframes, double t0, double t1, float radius)
{
    uint32_t nv = ob->num_vertices, stride = ob->sphere ? 4 : 3 * nv;
    float *tmp = mem_alloc(sizeof(float) * 3 * nv);
    ob->pos = mem_alloc(sizeof(double) * stride * (ob->segs + 1));
    for (uint32_t k = 0; k <= ob->segs; k++) {
        double t = t0 + (t1 - t0) * k / ob->segs;
        if (nframes >= 2)
            motion_frames_at(positions, fpos, ftimes, nframes, nv, t, tmp);
        else
            memcpy(tmp, positions, sizeof(float) * 3 * nv);
        struct motion_key key;
        if (nkeys > 0)
            motion_key_at(keys, nkeys, t, &key);
        double *dst = ob->pos + (size_t)k * stride;
        for (uint32_t v = 0; v < nv; v++) {
            double p[3] = {tmp[3 * v], tmp[3 * v + 1], tmp[3 * v + 2]};
            if (nkeys > 0)
                apply_key(&key, p, &dst[3 * v]);
            else
                memcpy(&dst[3 * v], p, sizeof p);
        }
        if (ob->sphere) { /* a non-uniform scale makes an ellipsoid: bound it by its largest axis */
            double s = nkeys > 0 ? fmax(key.scale.x, fmax(key.scale.y, key.scale.z)) : 1.0;
            dst[3] = radius * s;
        }
    }
    free(tmp);
}

static void cand_fill(const struct mv_object *ob, uint32_t prim, const double o[3], struct mv_cand *c)
{
    uint32_t tri = prim / ob->segs, seg = prim % ob->segs;
    c->obj = ob->obj, c->prim = tri, c->seg = seg, c->sphere = ob->sphere;
    c->niv = 0;
    c->ta = (double)seg / ob->segs;
    c->tb = (double)(seg + 1) / ob->segs;
    uint32_t stride = ob->sphere ? 4 : 3 * ob->num_vertices;
    const double *a = ob->pos + (size_t)seg * stride, *b = a + stride;
    if (ob->sphere) {
        for (int k = 0; k < 3; k++)
            c->p0[0][k] = a[k] - o[k], c->p1[0][k] = b[k] - o[k];
        c->p0[1][0] = a[3], c->p1[1][0] = b[3];
        c->p0[1][1] = c->p0[1][2] = c->p1[1][1] = c->p1[1][2] = 0.0;
        c->p0[2][0] = c->p0[2][1] = c->p0[2][2] = c->p1[2][0] = c->p1[2][1] = c->p1[2][2] = 0.0;
        return;
    }
    for (int i = 0; i < 3; i++) {
        uint32_t v = ob->indices[3 * tri + i];
        for (int k = 0; k < 3; k++)
            c->p0[i][k] = a[3 * v + k] - o[k], c->p1[i][k] = b[3 * v + k] - o[k];
    }
}

static void bounds_cb(const struct RTCBoundsFunctionArguments *args)
{
    const struct mv_object *ob = args->geometryUserPtr;
    struct mv_cand c;
    const double zero[3] = {0, 0, 0};
    cand_fill(ob, args->primID, zero, &c);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    int np = ob->sphere ? 1 : 3;
    for (int i = 0; i < np; i++)
        for (int k = 0; k < 3; k++) {
            double r0 = ob->sphere ? c.p0[1][0] : 0.0, r1 = ob->sphere ? c.p1[1][0] : 0.0;
            lo[k] = fmin(lo[k], fmin(c.p0[i][k] - r0, c.p1[i][k] - r1));
            hi[k] = fmax(hi[k], fmax(c.p0[i][k] + r0, c.p1[i][k] + r1));
        }
    float pad[3];
    for (int k = 0; k < 3; k++) /* outward past the float rounding */
        pad[k] = (float)(1e-6 * (fabs(lo[k]) + fabs(hi[k])) + 1e-30);
    args->bounds_o->lower_x = (float)lo[0] - pad[0], args->bounds_o->upper_x = (float)hi[0] + pad[0];
    args->bounds_o->lower_y = (float)lo[1] - pad[1], args->bounds_o->upper_y = (float)hi[1] + pad[1];
    args->bounds_o->lower_z = (float)lo[2] - pad[2], args->bounds_o->upper_z = (float)hi[2] + pad[2];
}

/* 1 when triangle prim of ob cannot cover the query's ray during its segment: two edges
 * keep it on opposite sides all along (fixed_sign). In the plane across d (basis u, v),
 * d . (a x b) is the 2D cross product of the projections: cheaper than the triple products
 * of mv_cand_coverage, which most candidates never reach. */
static int quick_reject(const struct mv_object *ob, uint32_t prim, const struct mv_query *q)
{
    uint32_t tri = prim / ob->segs, seg = prim % ob->segs, stride = 3 * ob->num_vertices;
    const double *base = ob->pos + (size_t)seg * stride;
    double a[3][2], b[3][2];
    for (int i = 0; i < 3; i++) {
        const double *pa = base + 3 * ob->indices[3 * tri + i], *pb = pa + stride;
        double x0[3] = {pa[0] - q->o[0], pa[1] - q->o[1], pa[2] - q->o[2]};
        double x1[3] = {pb[0] - q->o[0], pb[1] - q->o[1], pb[2] - q->o[2]};
        a[i][0] = dot3(q->u, x0), a[i][1] = dot3(q->v, x0);
        b[i][0] = dot3(q->u, x1) - a[i][0], b[i][1] = dot3(q->v, x1) - a[i][1];
    }
    int sg[3];
    for (int e = 0; e < 3; e++) {
        int i = e, j = (e + 1) % 3;
        double c[3] = {b[i][0] * b[j][1] - b[i][1] * b[j][0],
                       a[i][0] * b[j][1] - a[i][1] * b[j][0] + b[i][0] * a[j][1] - b[i][1] * a[j][0],
                       a[i][0] * a[j][1] - a[i][1] * a[j][0]};
        sg[e] = fixed_sign(c);
    }
    return sg[0] * sg[1] < 0 || sg[1] * sg[2] < 0 || sg[0] * sg[2] < 0;
}

static void intersect_cb(const struct RTCIntersectFunctionNArguments *args)
{
    if (!args->valid[0])
        return;
    struct mv_query *q = (struct mv_query *)args->context;
    const struct mv_object *ob = args->geometryUserPtr;
    if (!ob->sphere && quick_reject(ob, args->primID, q))
        return;
    if (q->nc >= MV_MAX_CANDS) {
        q->overflow = 1;
        return;
    }
    struct mv_cand *c = &q->cand[q->nc];
    cand_fill(args->geometryUserPtr, args->primID, q->o, c);
    mv_cand_coverage(c, q->d);
    if (c->niv > 0)
        q->nc++;
}

/* A candidate's place in the answer's order: object, triangle, segment. */
struct mv_key {
    uint32_t obj, prim, seg, idx;
};

static int cmp_key(const void *a, const void *b)
{
    const struct mv_key *x = a, *y = b;
    if (x->obj != y->obj)
        return x->obj < y->obj ? -1 : 1;
    if (x->prim != y->prim)
        return x->prim < y->prim ? -1 : 1;
    return x->seg < y->seg ? -1 : x->seg > y->seg;
}

static void add_object(struct motion_vis *mv, struct mv_object *ob, uint32_t prims)
{
    accel_attach_user_geometry(mv->accel->device, mv->scene, prims, ob, bounds_cb, intersect_cb);
}

struct motion_vis *motion_vis_new(const struct accel *a, const struct scene *s, const struct camera *cam,
                                  uint32_t frame)
{
    if (s->camera.motion_blur != MOTION_BLUR_ANALYTIC || !a->has_motion || !cam->uses_time)
        return NULL;
    if (cam->moving) {
        log_info("motion blur: the camera moves, so camera rays sample time (analytic visibility needs a still "
                 "camera)");
        return NULL;
    }
    double t0 = (double)frame + cam->shutter_open, t1 = (double)frame + cam->shutter_close;
    struct motion_vis *mv = mem_calloc(1, sizeof *mv);
    mv->accel = a;
    mv->objects = mem_calloc((size_t)s->num_meshes + s->num_spheres, sizeof *mv->objects);
    mv->top_moving = mem_calloc(a->num_top ? a->num_top : 1, 1);
    mv->scene = rtcNewScene(a->device);
    rtcSetSceneBuildQuality(mv->scene, RTC_BUILD_QUALITY_MEDIUM);
    rtcSetSceneFlags(mv->scene, RTC_SCENE_FLAG_ROBUST);
    for (uint32_t i = 0; i < s->num_meshes; i++) {
        const struct mesh *m = &s->meshes[i];
        if ((m->num_keys == 0 && m->num_frames < 2) || m->num_triangles == 0)
            continue;
        struct mv_object *ob = &mv->objects[mv->num_objects++];
        ob->obj = i;
        ob->num_vertices = m->num_vertices;
        ob->indices = m->indices;
        ob->segs = object_segments(m->keys, m->num_keys, m->frame_times, m->num_frames, t0, t1, m->num_vertices,
                                   m->num_triangles);
        object_fill(ob, m->positions, m->keys, m->num_keys, m->frame_positions, m->frame_times, m->num_frames, t0, t1,
                    0.0f);
        add_object(mv, ob, m->num_triangles * ob->segs);
    }
    for (uint32_t i = 0; i < s->num_spheres; i++) {
        const struct sphere *sp = &s->spheres[i];
        if (sp->num_keys == 0)
            continue;
        struct mv_object *ob = &mv->objects[mv->num_objects++];
        ob->obj = s->num_meshes + i;
        ob->sphere = 1;
        ob->num_vertices = 1;
        ob->segs = object_segments(sp->keys, sp->num_keys, NULL, 0, t0, t1, 1, 1);
        float c[3] = {sp->center.x, sp->center.y, sp->center.z};
        object_fill(ob, c, sp->keys, sp->num_keys, NULL, NULL, 0, t0, t1, sp->radius);
        add_object(mv, ob, ob->segs);
    }
    rtcCommitScene(mv->scene);
    for (uint32_t g = 0; g < a->num_top; g++) {
        uint32_t mi = a->top_mesh[g];
        mv->top_moving[g] = mi == a->sphere_geom ? a->top_sphere[g] != UINT32_MAX
                                                 : (s->meshes[mi].num_keys > 0 || s->meshes[mi].num_frames >= 2);
    }
    log_info("motion blur: analytic camera visibility over %u moving objects", mv->num_objects);
    return mv;
}

void motion_vis_free(struct motion_vis **mvp)
{
    struct motion_vis *mv = *mvp;
    if (!mv)
        return;
    rtcReleaseScene(mv->scene);
    for (uint32_t i = 0; i < mv->num_objects; i++)
        free(mv->objects[i].pos);
    free(mv->objects);
    free(mv->top_moving);
    free(mv);
    *mvp = NULL;
}

/* Nearest still surface along the ray (moving ones are skipped), INFINITY for none, NAN
 * when too many moving surfaces lie in front to step past. */
static double still_depth(const struct motion_vis *mv, vec3 o, vec3 d)
{
    float tnear = 0.0f;
    for (int it = 0; it < 64; it++) {
        struct RTCIntersectContext ctx;
        rtcInitIntersectContext(&ctx);
        struct RTCRayHit rh;
        memset(&rh, 0, sizeof rh);
        accel_ray_set(&rh.ray, o, tnear, d, 0.0f);
        rh.ray.tfar = INFINITY;
        rh.ray.mask = 0xffffffffu;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        if (!accel_ray_ok_(o, d))
            return INFINITY;
        rtcIntersect1(mv->accel->scene, &ctx, &rh);
        if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID)
            return INFINITY;
        unsigned top = rh.hit.instID[0] != RTC_INVALID_GEOMETRY_ID ? rh.hit.instID[0] : rh.hit.geomID;
        if (!mv->top_moving[top])
            return rh.ray.tfar;
        tnear = nextafterf(rh.ray.tfar, INFINITY);
    }
    return NAN;
}

uint32_t motion_vis_strata(const struct motion_vis *mv, const struct camera *cam, const struct camera_sample *cs,
                           float u, struct mv_strata *st)
{
    st->n = 1;
    st->time01[0] = cs->time01;
    st->weight[0] = 1.0;
    /* 260 kB: off the render threads' stacks */
    static _Thread_local struct mv_cand found[MV_MAX_CANDS], cand[MV_MAX_CANDS];
    struct mv_query q;
    rtcInitIntersectContext(&q.ctx);
    q.o[0] = cs->o.x, q.o[1] = cs->o.y, q.o[2] = cs->o.z;
    q.d[0] = cs->d.x, q.d[1] = cs->d.y, q.d[2] = cs->d.z;
    double dl = sqrt(dot3(q.d, q.d));
    for (int k = 0; k < 3; k++)
        q.d[k] /= dl;
    /* Duff et al., "Building an Orthonormal Basis, Revisited" (JCGT 2017). */
    double sgn = copysign(1.0, q.d[2]), ia = -1.0 / (sgn + q.d[2]), ib = q.d[0] * q.d[1] * ia;
    q.u[0] = 1.0 + sgn * q.d[0] * q.d[0] * ia, q.u[1] = sgn * ib, q.u[2] = -sgn * q.d[0];
    q.v[0] = ib, q.v[1] = sgn + q.d[1] * q.d[1] * ia, q.v[2] = -q.d[1];
    q.cand = found, q.nc = 0, q.overflow = 0;
    struct RTCRayHit rh;
    memset(&rh, 0, sizeof rh);
    accel_ray_set(&rh.ray, cs->o, 0.0f, cs->d, 0.0f);
    rh.ray.tfar = INFINITY;
    rh.ray.mask = 0xffffffffu;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    if (accel_ray_ok_(cs->o, cs->d))
        rtcIntersect1(mv->scene, &q.ctx, &rh);
    if (q.overflow || q.nc == 0)
        return 1; /* nothing moving on this ray (or too much): time stays sampled */
    /* Embree's visiting order is not part of the answer: sort, drop repeated visits. */
    struct mv_key key[MV_MAX_CANDS];
    for (uint32_t i = 0; i < q.nc; i++)
        key[i] = (struct mv_key){found[i].obj, found[i].prim, found[i].seg, i};
    if (q.nc <= 16) {
        for (uint32_t i = 1; i < q.nc; i++)
            for (uint32_t j = i; j > 0 && cmp_key(&key[j], &key[j - 1]) < 0; j--) {
                struct mv_key t = key[j];
                key[j] = key[j - 1], key[j - 1] = t;
            }
    } else {
        qsort(key, q.nc, sizeof *key, cmp_key);
    }
    uint32_t nc = 0;
    for (uint32_t i = 0; i < q.nc; i++)
        if (i == 0 || cmp_key(&key[i - 1], &key[i]) != 0)
            cand[nc++] = found[key[i].idx];
    double sd = still_depth(mv, cs->o, cs->d);
    if (isnan(sd))
        return 1;
    struct mv_piece pieces[MV_MAX_PIECES];
    uint32_t np = mv_resolve(cand, nc, q.d, sd * dl, pieces, MV_MAX_PIECES);
    if (np <= 1)
        return 1;
    mv_strata_from_pieces(cam, pieces, np, cand, u, st);
    if (st->n <= 1) {
        st->n = 1;
        st->time01[0] = cs->time01;
        st->weight[0] = 1.0;
    }
    return st->n;
}
