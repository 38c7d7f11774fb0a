/* Motion evaluation (see motion.h). Interpolation runs in double and rounds once, so the
 * keys Embree receives, the keys the integrator reconstructs hits with and the keys the
 * stillness test compares are the same floats everywhere. */
#include "scene/motion.h"
#include <math.h>
#include <string.h>

void motion_quat_from_axis_angle(vec3 axis, double degrees, float q[4])
{
    double x = axis.x, y = axis.y, z = axis.z, l = sqrt(x * x + y * y + z * z);
    double h = 0.5 * degrees * (M_PI / 180.0), s = sin(h) / (l > 0.0 ? l : 1.0);
    q[0] = (float)cos(h);
    q[1] = (float)(x * s);
    q[2] = (float)(y * s);
    q[3] = (float)(z * s);
}

int motion_keys_check(const struct motion_key *keys, uint32_t n)
{
    if (n > 0 && !keys)
        return -1;
    for (uint32_t i = 0; i < n; i++) {
        const struct motion_key *k = &keys[i];
        double q2 = 0.0;
        for (int j = 0; j < 4; j++)
            q2 += (double)k->quat[j] * k->quat[j];
        if (!isfinite(k->time) || (i > 0 && !(k->time > keys[i - 1].time)) || !v3_is_finite(k->scale) ||
            !v3_is_finite(k->translate) || !(k->scale.x > 0.0f && k->scale.y > 0.0f && k->scale.z > 0.0f) ||
            !(fabs(q2 - 1.0) < 1e-3))
            return -1;
    }
    return 0;
}

/* Index i of the segment [keys i, i + 1] holding t, and the weight of key i + 1. */
static uint32_t segment(const float *times, size_t stride, uint32_t n, double t, double *w)
{
#define TIME(k) (*(const float *)((const char *)times + (size_t)(k) * stride))
    *w = 0.0;
    if (n < 2 || t <= TIME(0))
        return 0;
    if (t >= TIME(n - 1)) {
        *w = 1.0;
        return n - 2;
    }
    uint32_t i = 0;
    while (i + 2 < n && t >= TIME(i + 1))
        i++;
    double dt = (double)TIME(i + 1) - TIME(i);
    *w = dt > 0.0 ? (t - TIME(i)) / dt : 1.0;
    return i;
#undef TIME
}

static void slerp(const float a[4], const float b_in[4], double w, float out[4])
{
    double b[4] = {b_in[0], b_in[1], b_in[2], b_in[3]};
    double d = (double)a[0] * b[0] + (double)a[1] * b[1] + (double)a[2] * b[2] + (double)a[3] * b[3];
    if (d < 0.0) {
        d = -d;
        for (int k = 0; k < 4; k++)
            b[k] = -b[k];
    }
    double wa, wb;
    if (d > 0.9995) { /* nearly equal: lerp and renormalise, as Embree does */
        wa = 1.0 - w;
        wb = w;
    } else {
        double th = acos(d), s = sin(th);
        wa = sin((1.0 - w) * th) / s;
        wb = sin(w * th) / s;
    }
    double r[4], l = 0.0;
    for (int k = 0; k < 4; k++) {
        r[k] = wa * a[k] + wb * b[k];
        l += r[k] * r[k];
    }
    l = sqrt(l);
    for (int k = 0; k < 4; k++)
        out[k] = (float)(r[k] / l);
}

static float lerpf(float a, float b, double w) { return (float)((double)a + ((double)b - a) * w); }
static vec3 lerp3(vec3 a, vec3 b, double w) { return v3(lerpf(a.x, b.x, w), lerpf(a.y, b.y, w), lerpf(a.z, b.z, w)); }

void motion_key_at(const struct motion_key *keys, uint32_t n, double t, struct motion_key *out)
{
    double w;
    uint32_t i = segment(&keys[0].time, sizeof *keys, n, t, &w);
    if (n < 2 || w == 0.0) {
        *out = keys[i];
    } else if (w == 1.0) {
        *out = keys[i + 1];
    } else {
        const struct motion_key *a = &keys[i], *b = &keys[i + 1];
        out->scale = lerp3(a->scale, b->scale, w);
        out->translate = lerp3(a->translate, b->translate, w);
        slerp(a->quat, b->quat, w, out->quat);
    }
    out->time = (float)t;
}

static int key_equal(const struct motion_key *a, const struct motion_key *b)
{
    return memcmp(&a->scale, &b->scale, sizeof a->scale) == 0 && memcmp(a->quat, b->quat, sizeof a->quat) == 0 &&
           memcmp(&a->translate, &b->translate, sizeof a->translate) == 0;
}

/* Keys first..last are the ones interpolation reads for times in [t0, t1]. */
static void affecting(const float *times, size_t stride, uint32_t n, double t0, double t1, uint32_t *first,
                      uint32_t *last)
{
    double w;
    uint32_t f = segment(times, stride, n, t0, &w);
    *first = w == 1.0 ? f + 1 : f; /* at or after the segment's end: only its end key */
    uint32_t l = segment(times, stride, n, t1, &w);
    *last = w == 0.0 ? l : l + 1;  /* at or before the segment's start: only its start key */
    if (*last < *first)
        *last = *first;
}

int motion_keys_still(const struct motion_key *keys, uint32_t n, double t0, double t1)
{
    if (n < 2)
        return 1;
    if (!(t1 > t0)) {
        return 1;
    }
    uint32_t f, l;
    affecting(&keys[0].time, sizeof *keys, n, t0, t1, &f, &l);
    for (uint32_t i = f + 1; i <= l; i++)
        if (!key_equal(&keys[f], &keys[i]))
            return 0;
    return 1;
}

int motion_frames_still(const float *frame_positions, const float *frame_times, uint32_t num_frames,
                        uint32_t num_vertices, double t0, double t1)
{
    if (num_frames < 2 || !(t1 > t0))
        return 1;
    uint32_t f, l;
    affecting(frame_times, sizeof(float), num_frames, t0, t1, &f, &l);
    size_t nf = 3 * (size_t)num_vertices;
    for (uint32_t i = f + 1; i <= l; i++)
        if (memcmp(&frame_positions[f * nf], &frame_positions[i * nf], nf * sizeof(float)) != 0)
            return 0;
    return 1;
}

void motion_frames_at(const float *positions, const float *frame_positions, const float *frame_times,
                      uint32_t num_frames, uint32_t num_vertices, double t, float *out)
{
    size_t nf = 3 * (size_t)num_vertices;
    if (num_frames < 2) {
        memcpy(out, positions, nf * sizeof(float));
        return;
    }
    double w;
    uint32_t i = segment(frame_times, sizeof(float), num_frames, t, &w);
    const float *a = &frame_positions[i * nf], *b = &frame_positions[(i + 1) * nf];
    if (w == 0.0 || w == 1.0) {
        memcpy(out, w == 0.0 ? a : b, nf * sizeof(float));
        return;
    }
    for (size_t k = 0; k < nf; k++)
        out[k] = lerpf(a[k], b[k], w);
}

uint32_t motion_step_count(const float *times, size_t stride, uint32_t n, double t0, double t1)
{
    double len = t1 - t0;
    int inner = 0;
    for (uint32_t k = 0; k < n; k++) {
        double t = *(const float *)((const char *)times + k * stride);
        inner |= t > t0 && t < t1;
    }
    if (!inner || !(len > 0.0))
        return 2;
    for (uint32_t segs = 2; segs <= MOTION_MAX_SEGMENTS; segs++) {
        int aligned = 1;
        for (uint32_t k = 0; k < n && aligned; k++) {
            double t = *(const float *)((const char *)times + k * stride);
            if (t > t0 && t < t1) {
                double x = (t - t0) / len * segs;
                aligned = fabs(x - floor(x + 0.5)) <= 1e-4 * segs;
            }
        }
        if (aligned)
            return segs + 1;
    }
    return MOTION_MAX_SEGMENTS + 1;
}

double motion_xform_det(const struct xform *t)
{
    const float(*a)[4] = t->m;
    return (double)a[0][0] * ((double)a[1][1] * a[2][2] - (double)a[1][2] * a[2][1]) +
           (double)a[0][1] * ((double)a[1][2] * a[2][0] - (double)a[1][0] * a[2][2]) +
           (double)a[0][2] * ((double)a[1][0] * a[2][1] - (double)a[1][1] * a[2][0]);
}

struct xform motion_xform_inverse(const struct xform *t)
{
    double a[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            a[i][j] = t->m[i][j];
    double c[3][3] = {{a[1][1] * a[2][2] - a[1][2] * a[2][1], a[0][2] * a[2][1] - a[0][1] * a[2][2],
                       a[0][1] * a[1][2] - a[0][2] * a[1][1]},
                      {a[1][2] * a[2][0] - a[1][0] * a[2][2], a[0][0] * a[2][2] - a[0][2] * a[2][0],
                       a[0][2] * a[1][0] - a[0][0] * a[1][2]},
                      {a[1][0] * a[2][1] - a[1][1] * a[2][0], a[0][1] * a[2][0] - a[0][0] * a[2][1],
                       a[0][0] * a[1][1] - a[0][1] * a[1][0]}};
    double det = motion_xform_det(t);
    double inv = det != 0.0 ? 1.0 / det : 0.0;
    struct xform r;
    for (int i = 0; i < 3; i++) {
        double tr = 0.0;
        for (int j = 0; j < 3; j++) {
            r.m[i][j] = (float)(c[i][j] * inv);
            tr += c[i][j] * inv * t->m[j][3];
        }
        r.m[i][3] = (float)-tr;
    }
    return r;
}

vec3 motion_xform_normal(const struct xform *t, vec3 n)
{
    /* Columns of the cofactor matrix are cross products of the transform's columns. */
    vec3 c0 = v3(t->m[0][0], t->m[1][0], t->m[2][0]), c1 = v3(t->m[0][1], t->m[1][1], t->m[2][1]),
         c2 = v3(t->m[0][2], t->m[1][2], t->m[2][2]);
    return v3_add(v3_add(v3_scale(v3_cross(c1, c2), n.x), v3_scale(v3_cross(c2, c0), n.y)),
                  v3_scale(v3_cross(c0, c1), n.z));
}
