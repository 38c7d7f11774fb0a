/* texbench: the cost of one texture lookup per filter, for benchmarks.
 *   texbench [N]   N lookups per filter (default 2000000) on a 1024 x 1024 RGB8 sRGB
 *                  texture, at footprints a plane seen from 1 to 89 degrees would give
 *                  (a minor axis of 0.25 to 4 texels, anisotropy 1 to 30), max anisotropy 16.
 * Prints "filter ns_per_lookup checksum" lines. The footprints are a fixed pseudo-random
 * sequence, the same for every filter. */
#include "base/log.h"
#include "image/mip.h"
#include "scene/texture.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

int main(int argc, char **argv)
{
    long n = argc > 1 ? atol(argv[1]) : 2000000;
    if (n <= 0)
        n = 2000000;
    struct tex_image im;
    CHECK(tex_image_alloc(&im, 1024, 1024, 3, TEXEL_U8_SRGB) == 0);
    uint8_t *p = im.data;
    for (size_t i = 0; i < (size_t)1024 * 1024 * 3; i++)
        p[i] = (uint8_t)((i * 2654435761u) >> 24);
    struct mip m;
    mip_init(&m, &im, TEXWRAP_REPEAT);
    enum { K = 4096 };
    float *fp = mem_alloc(sizeof(float) * 6 * K);
    uint64_t st = 1;
    for (int i = 0; i < K; i++) {
        float r[4];
        for (int j = 0; j < 4; j++) {
            st = st * 6364136223846793005ull + 1442695040888963407ull;
            r[j] = (float)(st >> 40) / (float)(1 << 24);
        }
        float minor = powf(2.0f, -2.0f + 4.0f * r[2]) / 1024.0f, aniso = 1.0f + 29.0f * r[3] * r[3];
        float ang = 6.2831853f * r[3];
        fp[6 * i] = r[0], fp[6 * i + 1] = r[1];
        fp[6 * i + 2] = minor * aniso * cosf(ang), fp[6 * i + 3] = minor * aniso * sinf(ang);
        fp[6 * i + 4] = -minor * sinf(ang), fp[6 * i + 5] = minor * cosf(ang);
    }
    for (int f = 0; f < TEXFILTER_COUNT_; f++) {
        double sum = 0, t0 = now();
        for (long i = 0; i < n; i++) {
            const float *q = &fp[6 * (i % K)];
            vec3 c = mip_lookup(&m, (enum texture_filter)f, 16.0f, q[0], q[1], q[2], q[3], q[4], q[5]);
            sum += c.x + c.y + c.z;
        }
        double t = now() - t0;
        printf("%s %.2f %.6f\n", texture_filter_name((enum texture_filter)f), t * 1e9 / (double)n, sum / (double)n);
    }
    mip_fini(&m);
    tex_image_fini(&im);
    free(fp);
    return 0;
}
