/* Tabulated piecewise-constant distributions (light picking, pixel filters, environment
 * maps): the cell of a cumulative table that a uniform number falls in. Callers:
 * scene/light.c, scene/camera.c, scene/envmap.c. */
#ifndef BRUME_CDF_H
#define BRUME_CDF_H
#include <stdint.h>

/* The cell i of n with cdf[i] <= u < cdf[i + 1], by bisection over cdf[0..n] (cdf[0] <= u,
 * cdf non-decreasing); an empty cell (cdf[i] == cdf[i + 1]) can be returned only when u
 * equals its value. */
static inline uint32_t cdf_cell(const float *cdf, uint32_t n, float u)
{
    uint32_t lo = 0, hi = n;
    while (hi - lo > 1) {
        uint32_t mid = (lo + hi) / 2;
        if (cdf[mid] <= u)
            lo = mid;
        else
            hi = mid;
    }
    return lo;
}

#endif
