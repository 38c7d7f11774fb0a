/* The analytic densities of the NanoVDB test files, shared by their writer
 * (tests/tools/make_nvdb.cpp, C++) and their reader's tests (tests/unit/test_nvdb.c, C):
 * values at integer index coordinates, exact in float. */
#ifndef BRUME_NVDB_VALUES_H
#define BRUME_NVDB_VALUES_H

/* The test grid: box [-6,9]x[-4,7]x[-5,5] of index space, zeros (inactive) inside too. */
static inline float ball_value(int i, int j, int k)
{
    if (i < -6 || i > 9 || j < -4 || j > 7 || k < -5 || k > 5)
        return 0.0f;
    return (float)((i * i + 3 * j + 5 * k + 200) % 13) / 8.0f;
}

static inline float temperature_value(int i, int j, int k)
{
    if (i < -2 || i > 3 || j < 0 || j > 2 || k < -1 || k > 1)
        return 0.0f;
    return (float)(1 + (i + 2) + 6 * j) * 0.5f;
}

/* Two blocks far apart: across a lower node (128) and two root tiles (k < 0 and k >= 0). */
static inline float sparse_value(int i, int j, int k)
{
    if (i >= -3 && i <= 2 && j >= 0 && j <= 3 && k >= 0 && k <= 2)
        return (float)(1 + ((i + 3) * 7 + j * 3 + k) % 11) * 0.25f;
    if (i >= 125 && i <= 131 && j >= 1 && j <= 4 && k >= -130 && k <= -126)
        return (float)(2 + (i + j + k + 1000) % 5) * 0.5f;
    return 0.0f;
}

#endif
