/* base/vec.h: f_max and f_min are fmaxf and fminf bit for bit, d_max and d_min fmax and
 * fmin (NaN, signed zeros, infinities, denormals), so replacing the libm calls in hot code
 * moves no pixel; the tests on bits (v3_is_black, v3_is_finite, v3_max_abs_ge) answer as
 * the float compares they replace, and offset_ray_origin as its plain formula. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdint.h>
#include <string.h>
#include "base/vec.h"

static uint32_t bits(float x)
{
    uint32_t u;
    memcpy(&u, &x, sizeof u);
    return u;
}

static uint64_t bits_d(double x)
{
    uint64_t u;
    memcpy(&u, &x, sizeof u);
    return u;
}

/* The values as floats for f_max and f_min, as doubles for d_max and d_min (1e-40 is a
 * float denormal, 1e-310 a double one). */
Test(vec, f_max_f_min_d_max_d_min_are_libm)
{
    const double v[] = {0.0, -0.0, 1.0, -1.0, NAN, -NAN, INFINITY, -INFINITY, 1e-40, -1e-40, 3.5, 0x1p-126, 1e-310};
    const int n = (int)(sizeof v / sizeof v[0]);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            volatile float a = (float)v[i], b = (float)v[j]; /* volatile: libm's functions, not folded constants */
            cr_expect_eq(bits(f_max(a, b)), bits(fmaxf(a, b)), "f_max(%g, %g)", (double)a, (double)b);
            cr_expect_eq(bits(f_min(a, b)), bits(fminf(a, b)), "f_min(%g, %g)", (double)a, (double)b);
            volatile double x = v[i], y = v[j];
            cr_expect_eq(bits_d(d_max(x, y)), bits_d(fmax(x, y)), "d_max(%g, %g)", x, y);
            cr_expect_eq(bits_d(d_min(x, y)), bits_d(fmin(x, y)), "d_min(%g, %g)", x, y);
        }
}

static const float special[] = {0.0f, -0.0f, 1.0f, -1.0f, 0.5f, -0.5f, NAN, -NAN, INFINITY, -INFINITY,
                                1e-40f, -1e-40f, 0x1p-126f, 3.4e38f};
#define NSPECIAL (int)(sizeof special / sizeof special[0])

Test(vec, bit_tests_are_the_float_compares)
{
    const float t[] = {0.5f, 0.0f, -1.0f, NAN, INFINITY};
    for (int i = 0; i < NSPECIAL; i++)
        for (int j = 0; j < NSPECIAL; j++)
            for (int k = 0; k < NSPECIAL; k++) {
                volatile float x = special[i], y = special[j], z = special[k];
                vec3 a = v3(x, y, z);
                cr_expect_eq(v3_is_black(a), x == 0.0f && y == 0.0f && z == 0.0f, "black (%g, %g, %g)",
                             (double)x, (double)y, (double)z);
                cr_expect_eq(v3_is_finite(a), isfinite(x) && isfinite(y) && isfinite(z), "finite (%g, %g, %g)",
                             (double)x, (double)y, (double)z);
                for (int m = 0; m < (int)(sizeof t / sizeof t[0]); m++)
                    cr_expect_eq(v3_max_abs_ge(a, t[m]), v3_max_abs(a) >= t[m], "max_abs_ge (%g, %g, %g) %g",
                                 (double)x, (double)y, (double)z, (double)t[m]);
            }
}

/* offset_ray_origin as written before its fixed step went behind the axis-plane test. */
static vec3 offset_plain(vec3 p, vec3 n)
{
    const float origin = 1.0f / 32.0f, int_scale = 256.0f;
    float float_scale = f_min(1.0f / 65536.0f, f_max(f_max(fabsf(p.x), fabsf(p.y)), fabsf(p.z)) * 0x1p-15f);
    int ox = (int)(int_scale * n.x), oy = (int)(int_scale * n.y), oz = (int)(int_scale * n.z);
    vec3 pi = v3(float_bits_offset(p.x, ox), float_bits_offset(p.y, oy), float_bits_offset(p.z, oz));
    return v3(fabsf(p.x) < origin ? p.x + float_scale * n.x : pi.x,
              fabsf(p.y) < origin ? p.y + float_scale * n.y : pi.y,
              fabsf(p.z) < origin ? p.z + float_scale * n.z : pi.z);
}

Test(vec, offset_ray_origin_is_the_plain_formula)
{
    /* Components far from, near and on the axis planes (and NaN), every sign. */
    const float c[] = {0.0f, -0.0f, 1e-7f, -3e-3f, 0.03125f, -0.03124f, 0.4f, -1.0f, 556.0f, -1e5f, NAN};
    const int nc = (int)(sizeof c / sizeof c[0]);
    const vec3 ns[] = {v3(0, 1, 0), v3(0, 0, -1), v3_normalize(v3(0.3f, -0.5f, 0.8f)), v3_normalize(v3(-1, -1, 1))};
    for (int i = 0; i < nc; i++)
        for (int j = 0; j < nc; j++)
            for (int k = 0; k < nc; k++)
                for (int m = 0; m < 4; m++) {
                    vec3 p = v3(c[i], c[j], c[k]), a = offset_ray_origin(p, ns[m]), b = offset_plain(p, ns[m]);
                    cr_expect(memcmp(&a, &b, sizeof a) == 0, "p (%g, %g, %g) n %d", (double)p.x, (double)p.y,
                              (double)p.z, m);
                }
}

/* v3_normalize and v3_length_rescaled where the squared length overflows (components of
 * 1e20: a triangle normal from the cross product of 1e10-long edges) or underflows (1e-20):
 * a unit vector and the true length; inside float's range bit for bit the plain formulas;
 * zero and NaN vectors unchanged. */
Test(vec, normalize_and_length_beyond_the_squared_range)
{
    const float ks[] = {1e20f, 1e-20f, 1e38f, 1e-40f, 1e-45f};
    for (int i = 0; i < 5; i++) {
        vec3 a = v3(ks[i], -2.0f * ks[i], 2.0f * ks[i]);
        if (ks[i] == 1e-45f)
            a = v3(ks[i], 0.0f, 0.0f); /* the smallest denormal */
        vec3 n = v3_normalize(a);
        float want = ks[i] == 1e-45f ? 1.0f : 1.0f / 3.0f;
        cr_expect(fabsf(n.x - want) < 1e-6f && fabsf(v3_length(n) - 1.0f) < 1e-6f, "k %g: (%g %g %g)", (double)ks[i],
                  (double)n.x, (double)n.y, (double)n.z);
        float l = v3_length_rescaled(a), lw = ks[i] == 1e-45f ? ks[i] : 3.0f * ks[i];
        cr_expect(l == lw || fabsf(l - lw) <= 1e-6f * lw, "k %g: length %g, want %g", (double)ks[i], (double)l, (double)lw);
    }
    uint64_t key = 12345;
    for (int i = 0; i < 100000; i++) {
        key = key * 6364136223846793005ull + 1442695040888963407ull;
        float e = (float)((int)(key >> 40) % 60 - 30);
        vec3 a = v3(ldexpf((float)(key >> 11 & 0xffff) - 32768.0f, (int)e), (float)(key >> 27 & 0xff) - 128.0f,
                    (float)(key >> 35 & 0xff) * 0.25f);
        float d = v3_dot(a, a);
        if (!(d >= 0x1p-126f && d <= 0x1.fffffep127f))
            continue;
        vec3 n = v3_normalize(a), p = v3_scale(a, 1.0f / sqrtf(d));
        cr_assert(memcmp(&n, &p, sizeof n) == 0 && v3_length_rescaled(a) == sqrtf(d));
    }
    vec3 z = v3_normalize(v3(0, 0, 0)), q = v3_normalize(v3(NAN, 1, 0));
    cr_expect(z.x == 0.0f && z.y == 0.0f && z.z == 0.0f && isnan(q.x) && q.y == 1.0f);
}
