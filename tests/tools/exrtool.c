/* exrtool: small checks on rendered EXRs for tests and benchmarks.
 *   exrtool cmp A.exr B.exr      exit 0 if R,G,B,A are bit-identical, else 1 (prints differences)
 *   exrtool rmse A.exr REF.exr   prints the RMSE of R,G,B against REF
 *   exrtool mean A.exr           prints the mean of R,G,B,A
 * Reads files through imgio_read (OpenEXRCore). */
#include "image/imgio.h"
#include "base/log.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const channels[] = {"R", "G", "B", "A"};

static float *load(const char *path, uint32_t *w, uint32_t *h)
{
    char err[512];
    float *px = NULL;
    if (imgio_read(path, channels, 4, &px, w, h, err, sizeof err) != 0) {
        fprintf(stderr, "exrtool: %s\n", err);
        exit(2);
    }
    return px;
}

int main(int argc, char **argv)
{
    if (argc == 3 && !strcmp(argv[1], "mean")) {
        uint32_t w, h;
        float *a = load(argv[2], &w, &h);
        double s[4] = {0, 0, 0, 0};
        for (size_t i = 0; i < (size_t)w * h; i++)
            for (int c = 0; c < 4; c++)
                s[c] += a[i * 4 + c];
        printf("%.9g %.9g %.9g %.9g\n", s[0] / (w * h), s[1] / (w * h), s[2] / (w * h), s[3] / (w * h));
        free(a);
        return 0;
    }
    if (argc == 8 && !strcmp(argv[1], "cmprect")) {
        /* cmprect A B X0 Y0 W H: R,G,B,A bit-identical inside the rectangle (a --tiles render). */
        uint32_t wa, ha, wb, hb;
        float *a = load(argv[2], &wa, &ha), *b = load(argv[3], &wb, &hb);
        uint32_t x0 = (uint32_t)atoi(argv[4]), y0 = (uint32_t)atoi(argv[5]), rw = (uint32_t)atoi(argv[6]),
                 rh = (uint32_t)atoi(argv[7]);
        if (wa != wb || ha != hb || x0 + rw > wa || y0 + rh > ha) {
            fprintf(stderr, "exrtool: sizes differ or rectangle outside the image\n");
            return 1;
        }
        size_t diff = 0;
        for (uint32_t y = y0; y < y0 + rh; y++)
            diff += memcmp(&a[((size_t)y * wa + x0) * 4], &b[((size_t)y * wa + x0) * 4], sizeof(float) * 4 * rw) != 0;
        free(a);
        free(b);
        printf("%zu rows differ\n", diff);
        return diff ? 1 : 0;
    }
    if (argc != 4 || (strcmp(argv[1], "cmp") && strcmp(argv[1], "rmse"))) {
        fprintf(stderr, "usage: exrtool cmp A.exr B.exr | exrtool rmse A.exr REF.exr | exrtool mean A.exr\n");
        return 2;
    }
    uint32_t wa, ha, wb, hb;
    float *a = load(argv[2], &wa, &ha), *b = load(argv[3], &wb, &hb);
    if (wa != wb || ha != hb) {
        fprintf(stderr, "exrtool: sizes differ: %ux%u vs %ux%u\n", wa, ha, wb, hb);
        return 1;
    }
    size_t n = (size_t)wa * ha;
    if (!strcmp(argv[1], "cmp")) {
        size_t diff = 0;
        double maxd = 0;
        for (size_t i = 0; i < n * 4; i++)
            if (memcmp(&a[i], &b[i], sizeof(float)) != 0) {
                diff++;
                double d = fabs((double)a[i] - b[i]);
                maxd = d > maxd ? d : maxd;
            }
        if (diff)
            printf("exrtool: %zu of %zu values differ (max abs difference %g)\n", diff, n * 4, maxd);
        free(a);
        free(b);
        return diff ? 1 : 0;
    }
    double se = 0;
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++) {
            double d = (double)a[i * 4 + c] - b[i * 4 + c];
            se += d * d;
        }
    printf("%.9g\n", sqrt(se / (3.0 * n)));
    free(a);
    free(b);
    return 0;
}
