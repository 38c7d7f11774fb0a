/* Small 3-vector maths, header-only and inline. Plain struct of three floats; every
 * function is pure. Used everywhere from scene loading to the integrator's inner loop. */
#ifndef BRUME_VEC_H
#define BRUME_VEC_H
#include <math.h>
#include <stdint.h>
#include <string.h>

typedef struct vec3 { float x, y, z; } vec3;

static inline vec3 v3(float x, float y, float z) { vec3 r = {x, y, z}; return r; }
static inline vec3 v3_add(vec3 a, vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline vec3 v3_sub(vec3 a, vec3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline vec3 v3_mul(vec3 a, vec3 b) { return v3(a.x * b.x, a.y * b.y, a.z * b.z); }
static inline vec3 v3_scale(vec3 a, float s) { return v3(a.x * s, a.y * s, a.z * s); }
static inline vec3 v3_neg(vec3 a) { return v3(-a.x, -a.y, -a.z); }
static inline float v3_dot(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline vec3 v3_cross(vec3 a, vec3 b)
{
    return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline float v3_length(vec3 a) { return sqrtf(v3_dot(a, a)); }
/* The largest |component| of a when a can be rescaled by it (finite, not zero, no NaN);
 * else 0. For the two functions below. */
static inline float v3_rescale_by_(vec3 a)
{
    float m = fabsf(a.x) > fabsf(a.y) ? fabsf(a.x) : fabsf(a.y);
    m = fabsf(a.z) > m ? fabsf(a.z) : m;
    return m > 0.0f && m <= 0x1.fffffep127f && a.x == a.x && a.y == a.y && a.z == a.z ? m : 0.0f;
}
/* Rescaled by the largest component first when the squared length leaves float's normal
 * range: the normal of a triangle with edges of 1e10 (its cross product squared overflows)
 * or of 1e-10 (underflows) is still a unit vector. Bit for bit the plain formula inside
 * that range; zero and NaN vectors come back unchanged. */
static inline vec3 v3_normalize_rescaled_(vec3 a)
{
    float m = v3_rescale_by_(a);
    if (m > 0.0f) {
        vec3 b = v3(a.x / m, a.y / m, a.z / m);
        return v3_scale(b, 1.0f / sqrtf(v3_dot(b, b)));
    }
    float l = v3_length(a);
    return l > 0.0f ? v3_scale(a, 1.0f / l) : a;
}
/* |a|, also where the squared length overflows or underflows (a triangle's area from
 * its cross product at 1e10 or 1e-10); bit for bit v3_length inside float's range. */
static inline float v3_length_rescaled(vec3 a)
{
    float d = v3_dot(a, a);
    if (d >= 0x1p-126f && d <= 0x1.fffffep127f)
        return sqrtf(d);
    float m = v3_rescale_by_(a);
    if (!(m > 0.0f))
        return sqrtf(d);
    vec3 b = v3(a.x / m, a.y / m, a.z / m);
    return m * sqrtf(v3_dot(b, b));
}
static inline vec3 v3_normalize(vec3 a)
{
    float d = v3_dot(a, a);
    if (d >= 0x1p-126f && d <= 0x1.fffffep127f)
        return v3_scale(a, 1.0f / sqrtf(d));
    return v3_normalize_rescaled_(a);
}
/* fmaxf and fminf bit for bit as glibc computes them (the other operand when one is NaN,
 * the first when they compare equal, so +0 or -0 as given), inlined: without -ffast-math
 * GCC calls libm for them, a call per use in hot code. */
static inline float f_max(float a, float b) { return ((a >= b || b != b) && a == a) ? a : b; }
static inline float f_min(float a, float b) { return ((a <= b || b != b) && a == a) ? a : b; }
/* fmax and fmin (double) the same way. */
static inline double d_max(double a, double b) { return ((a >= b || b != b) && a == a) ? a : b; }
static inline double d_min(double a, double b) { return ((a <= b || b != b) && a == a) ? a : b; }
/* Plain comparisons, not fmaxf: inlined, and callers never pass NaN here. */
static inline float v3_max_component(vec3 a)
{
    float m = a.x > a.y ? a.x : a.y;
    return m > a.z ? m : a.z;
}
static inline float v3_max_abs(vec3 a) { return f_max(fabsf(a.x), f_max(fabsf(a.y), fabsf(a.z))); }
/* v3_max_abs(a) >= t without the maximum (f_max skips a NaN component; so does >=). */
static inline int v3_max_abs_ge(vec3 a, float t) { return fabsf(a.x) >= t || fabsf(a.y) >= t || fabsf(a.z) >= t; }
/* isfinite of each component: an exponent below all ones. */
static inline int v3_is_finite(vec3 a)
{
    uint32_t x, y, z;
    memcpy(&x, &a.x, sizeof x);
    memcpy(&y, &a.y, sizeof y);
    memcpy(&z, &a.z, sizeof z);
    const uint32_t e = 0x7f800000u;
    return (x & e) != e && (y & e) != e && (z & e) != e;
}
/* Every component == 0 (either sign; NaN is not black): the bits of all three, sign left
 * out, are zero. One test rather than three float compares, each with its NaN case. */
static inline int v3_is_black(vec3 a)
{
    uint32_t x, y, z;
    memcpy(&x, &a.x, sizeof x);
    memcpy(&y, &a.y, sizeof y);
    memcpy(&z, &a.z, sizeof z);
    return ((x | y | z) << 1) == 0;
}

/* Orthonormal basis around unit n (Duff et al. 2017, branchless). */
static inline void v3_basis(vec3 n, vec3 *t, vec3 *b)
{
    float sign = copysignf(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float bb = n.x * n.y * a;
    *t = v3(1.0f + sign * n.x * n.x * a, sign * bb, -sign * n.x);
    *b = v3(bb, sign + n.y * n.y * a, -n.y);
}

/* sin and cos of 2 pi u for u in [0, 1], by quadrant reduction and short polynomials
 * (absolute error below 2e-7). Our own arithmetic rather than libm's sincosf: it is
 * faster in the sampling routines, and its bits do not depend on the C library version
 * of the machine a worker runs on, so every node renders the same pixels. */
static inline void sincos_2pi(float u, float *s, float *c)
{
    float t = 4.0f * u;
    int k = (int)(t + 0.5f);
    float x = (t - (float)k) * 1.57079632679489662f, x2 = x * x;
    float sx = x * (1.0f + x2 * (-1.0f / 6.0f + x2 * (1.0f / 120.0f + x2 * (-1.0f / 5040.0f + x2 * (1.0f / 362880.0f)))));
    float cx = 1.0f + x2 * (-0.5f + x2 * (1.0f / 24.0f + x2 * (-1.0f / 720.0f + x2 * (1.0f / 40320.0f))));
    switch (k & 3) {
    case 0: *s = sx; *c = cx; break;
    case 1: *s = cx; *c = -sx; break;
    case 2: *s = -sx; *c = -cx; break;
    default: *s = -cx; *c = sx; break;
    }
}

/* A direction uniform in the cone of directions within acos(cos_max) of unit axis (pdf
 * 1 / (2 pi (1 - cos_max))), from u1, u2 in [0, 1). */
static inline vec3 v3_cone_sample(vec3 axis, float cos_max, float u1, float u2)
{
    float z = 1.0f - u1 * (1.0f - cos_max), r = sqrtf(f_max(0.0f, 1.0f - z * z)), sp, cp;
    sincos_2pi(u2, &sp, &cp);
    vec3 t, b;
    v3_basis(axis, &t, &b);
    return v3_normalize(v3_add(v3_scale(axis, z), v3_add(v3_scale(t, r * cp), v3_scale(b, r * sp))));
}

/* Row-major 3x4 affine transform: p' = M[:, :3] p + M[:, 3]. */
struct xform { float m[3][4]; };

static inline struct xform xform_identity(void)
{
    struct xform t = {{{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}}};
    return t;
}
static inline vec3 xform_point(const struct xform *t, vec3 p)
{
    return v3(t->m[0][0] * p.x + t->m[0][1] * p.y + t->m[0][2] * p.z + t->m[0][3],
              t->m[1][0] * p.x + t->m[1][1] * p.y + t->m[1][2] * p.z + t->m[1][3],
              t->m[2][0] * p.x + t->m[2][1] * p.y + t->m[2][2] * p.z + t->m[2][3]);
}
static inline vec3 xform_vector(const struct xform *t, vec3 v)
{
    return v3(t->m[0][0] * v.x + t->m[0][1] * v.y + t->m[0][2] * v.z,
              t->m[1][0] * v.x + t->m[1][1] * v.y + t->m[1][2] * v.z,
              t->m[2][0] * v.x + t->m[2][1] * v.y + t->m[2][2] * v.z);
}
/* a then b: result applies a first, then b. */
static inline struct xform xform_then(const struct xform *a, const struct xform *b)
{
    struct xform r;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 4; j++) {
            float s = b->m[i][0] * a->m[0][j] + b->m[i][1] * a->m[1][j] + b->m[i][2] * a->m[2][j];
            r.m[i][j] = s + (j == 3 ? b->m[i][3] : 0.0f);
        }
    return r;
}

/* The same in double: scene loading composes and applies transforms in double, subtracts
 * the render frame's origin (scene.h) and rounds to float once, so a scene far from the
 * world origin keeps the precision it has near its camera. */
struct dxform { double m[3][4]; };

static inline struct dxform dxform_identity(void)
{
    struct dxform t = {{{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}}};
    return t;
}
/* a then b */
static inline struct dxform dxform_then(const struct dxform *a, const struct dxform *b)
{
    struct dxform r;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 4; j++)
            r.m[i][j] = b->m[i][0] * a->m[0][j] + b->m[i][1] * a->m[1][j] + b->m[i][2] * a->m[2][j] +
                        (j == 3 ? b->m[i][3] : 0.0);
    return r;
}
static inline void dxform_point(const struct dxform *t, const double p[3], double out[3])
{
    for (int i = 0; i < 3; i++)
        out[i] = t->m[i][0] * p[0] + t->m[i][1] * p[1] + t->m[i][2] * p[2] + t->m[i][3];
}
static inline struct dxform dxform_from_float(const struct xform *t)
{
    struct dxform r;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 4; j++)
            r.m[i][j] = t->m[i][j];
    return r;
}
static inline struct xform dxform_to_float(const struct dxform *t)
{
    struct xform r;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 4; j++)
            r.m[i][j] = (float)t->m[i][j];
    return r;
}
/* t followed by a move of the whole space by -origin (origin NULL: t). */
static inline struct dxform dxform_minus_origin(const struct dxform *t, const double *origin)
{
    struct dxform r = *t;
    for (int i = 0; origin && i < 3; i++)
        r.m[i][3] -= origin[i];
    return r;
}

/* p moved by delta units in the last place, away from zero. */
static inline float float_bits_offset(float p, int delta)
{
    uint32_t i; /* unsigned: the bits wrap (at -0.0 a negative step would overflow an int) */
    memcpy(&i, &p, sizeof i);
    i += (uint32_t)((p < 0.0f) ? -delta : delta);
    float r;
    memcpy(&r, &i, sizeof r);
    return r;
}

/* Moves a surface point p off the surface to the side of the unit normal n, robustly at
 * any magnitude (Waechter and Binder, Ray Tracing Gems ch. 6): a few ulps far from the
 * origin, a fixed step near it. The fixed step is 2^-16 while p lies half a unit or more
 * from the origin, and shrinks with |p| below that: a scene a millionth of a unit across
 * would otherwise step 2^-16, far past its own geometry, and lose its direct light. The
 * rounding of the hit itself is the caller's p_err (surface.h). Hot: inlined into every
 * spawn. */
__attribute__((always_inline)) static inline vec3 offset_ray_origin(vec3 p, vec3 n)
{
    const float origin = 1.0f / 32.0f, int_scale = 256.0f;
    int ox = (int)(int_scale * n.x), oy = (int)(int_scale * n.y), oz = (int)(int_scale * n.z);
    vec3 pi = v3(float_bits_offset(p.x, ox), float_bits_offset(p.y, oy), float_bits_offset(p.z, oz));
    if (fabsf(p.x) >= origin && fabsf(p.y) >= origin && fabsf(p.z) >= origin)
        return pi; /* the usual case: no fixed step, so no float_scale */
    float float_scale = f_min(1.0f / 65536.0f, f_max(f_max(fabsf(p.x), fabsf(p.y)), fabsf(p.z)) * 0x1p-15f);
    return v3(fabsf(p.x) < origin ? p.x + float_scale * n.x : pi.x,
              fabsf(p.y) < origin ? p.y + float_scale * n.y : pi.y,
              fabsf(p.z) < origin ? p.z + float_scale * n.z : pi.z);
}

/* One axis of v3_clip_box: narrows [*t0, *t1] to where o + t d lies in [l, h]. */
static inline int f_clip_slab(float o, float d, float l, float h, float *t0, float *t1)
{
    if (!(l <= h))
        return 0;
    if (d == 0.0f)
        return !(o < l || o > h);
    float ta = (l - o) / d, tb = (h - o) / d;
    *t0 = f_max(*t0, f_min(ta, tb));
    *t1 = f_min(*t1, f_max(ta, tb));
    return 1;
}

/* Narrows [*t0, *t1] to the part of o + t d inside the box [lo, hi] (slab test; d need
 * not be unit, a zero component keeps or drops the whole line); returns 1 if any of it is
 * left (*t0 <= *t1), 0 when none is or the box is empty. */
static inline int v3_clip_box(vec3 o, vec3 d, vec3 lo, vec3 hi, float *t0, float *t1)
{
    if (!f_clip_slab(o.x, d.x, lo.x, hi.x, t0, t1) || !f_clip_slab(o.y, d.y, lo.y, hi.y, t0, t1) ||
        !f_clip_slab(o.z, d.z, lo.z, hi.z, t0, t1))
        return 0;
    return *t0 <= *t1;
}

#endif
