/* base/vec.h: f_max and f_min are fmaxf and fminf bit for bit (NaN, signed zeros,
 * infinities, denormals), so replacing the libm calls in hot code moves no pixel. */
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

Test(vec, f_max_f_min_are_fmaxf_fminf)
{
    const float v[] = {0.0f, -0.0f, 1.0f, -1.0f, NAN, -NAN, INFINITY, -INFINITY, 1e-40f, -1e-40f, 3.5f, 0x1p-126f};
    const int n = (int)(sizeof v / sizeof v[0]);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            volatile float a = v[i], b = v[j]; /* volatile: libm's functions, not folded constants */
            cr_expect_eq(bits(f_max(a, b)), bits(fmaxf(a, b)), "f_max(%g, %g)", (double)a, (double)b);
            cr_expect_eq(bits(f_min(a, b)), bits(fminf(a, b)), "f_min(%g, %g)", (double)a, (double)b);
        }
}
