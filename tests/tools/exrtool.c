/* exrtool: small checks on rendered EXRs for tests and benchmarks.
 *   exrtool cmp A.exr B.exr      exit 0 if R,G,B,A are bit-identical, else 1 (prints differences)
 *   exrtool rmse A.exr REF.exr   prints the RMSE of R,G,B against REF
 *   exrtool mean A.exr           prints the mean of R,G,B,A
 *   exrtool relrmse A.exr REF.exr [--box N | --mask S.exr [--tol T]]
 *                                prints the relative RMSE: RMS over pixels and R,G,B of A - REF over
 *                                the mean of REF over pixels and R,G,B; with --box N both images are
 *                                first box-downsampled by N x N (a partial block at the right or
 *                                bottom edge is the mean of the pixels it holds): low-frequency error;
 *                                with --mask only over the pixels where REF and S differ by more than
 *                                T (0.1) times REF's mean in a channel (S: a still render, so the
 *                                pixels that see motion)
 *   exrtool errtop A.exr REF.exr [N]
 *                                prints the share of the squared error (summed over R,G,B) held by the
 *                                0.1 % and the 1 % of pixels with the largest squared error:
 *                                near 0.001 and 0.01 for even noise, near 1 for fireflies; with N,
 *                                then the N worst pixels, one a line: x y squared error, A's R, REF's R
 *   exrtool errest A.exr         prints the relative RMSE the image estimates for itself from its
 *                                variance.R/G/B channels (the variance of each pixel's mean):
 *                                sqrt(mean over pixels and R,G,B of the variance) / mean of R,G,B
 *   exrtool semean A.exr         prints the mean of R,G,B over the image and its standard error from
 *                                the variance channels (pixels independent; within a pixel the
 *                                channels' errors taken as fully correlated, an upper bound)
 *   exrtool average OUT.exr A.exr B.exr
 *                                writes (A + B) / 2 (R,G,B,A), variance (vA + vB) / 4
 *   exrtool chsum A.exr NAME     prints the sum over pixels of channel NAME (e.g. "samples")
 *   exrtool chstat A.exr NAME [X0 Y0 W H]
 *                                prints channel NAME's mean, min and max over the finite values of
 *                                the image (or the rectangle), then the count of +inf and of NaN
 *                                values (AOVs: Z is +inf where nothing is hit)
 *   exrtool synth OUT.exr W H V [--checker AMP] [--var VAR]
 *                                writes a test image: R,G,B = V (+AMP where x + y is even, -AMP
 *                                where odd, with --checker; +AMP at pixel (1, 2) with --spot), A = 1,
 *                                every variance channel = VAR
 *   exrtool oracle --spp N [--floor N0] [--target E]... [--alloc S.exr]... A1.exr ... AK.exr
 *                                what any allocation of samples could gain (docs/adaptive.md,
 *                                "Oracle"): A1..AK (K >= 4) are renders of one scene at N spp that
 *                                differ only in their seed. Per pixel v = N times the spread of its
 *                                value over the K renders (the mean over R,G,B of the variance of
 *                                one render), so v / n is the error variance at n spp. Uniform cost
 *                                per sample. For square units of 1, 2, 4, 8, 16 and 32 pixels (a
 *                                grid from the image's corner: the adaptive render's blocks are 4,
 *                                its tiles 32) prints the best equal-error time ratio of any
 *                                allocation to uniform spp, (sum sqrt(V_u P_u))^2 / (sum V * pixels)
 *                                (V_u: the unit's v summed, P_u its pixels, as its cost); with
 *                                --target E (RMS error over pixels and R,G,B over the image mean,
 *                                the relRMSE) and --floor N0 (every unit gets at least N0 spp, as an
 *                                adaptive render's first round gives), the cost of the best
 *                                allocation reaching E against uniform's, in-sample and with the
 *                                allocation chosen on half the renders and judged on the other
 *                                half (both ways, averaged: free of the optimism of choosing and
 *                                judging on the same noisy v); with --alloc S.exr (an adaptive
 *                                render of the scene) its allocation, the samples channel, judged
 *                                on v: its mean spp, its expected relRMSE, its cost over uniform's
 *                                at that error, and the best 8 px allocation's (with the floor)
 *   exrtool pixerr A.exr P [--ref REF.exr] [--cap SPP] [--alloc S.exr]
 *                                the per-pixel bound (--pixel-error P, docs/adaptive.md): each pixel's
 *                                relative error over max(its mean of R,G,B, 0.1 x the image's mean);
 *                                prints "estimate: over N of M (K at the cap), worst W" from the
 *                                variance channels (sqrt of their mean over R,G,B; at the cap: the
 *                                samples channel at SPP), then with REF (the scale from REF) the
 *                                shares of pixels whose estimated and whose true error (RMS over
 *                                R,G,B of A - REF) exceeds 2P, P and P / 2; with --alloc S.exr (an
 *                                adaptive render of the scene), S's mean samples over the pixels whose
 *                                estimate in A is above P and over the others
 * Reads files through imgio_read (OpenEXRCore); writes tiled EXRs through imgio's writer. */
#include "image/imgio.h"
#include "base/log.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const channels[] = {"R", "G", "B", "A"};
enum { NCH = 7 }; /* R, G, B, A and the variance of each colour's mean, as the renderer writes */
static const char *const all_channels[NCH] = {"R", "G", "B", "A", "variance.R", "variance.G", "variance.B"};

static float *load_channels(const char *path, const char *const *names, int n, uint32_t *w, uint32_t *h)
{
    char err[512];
    float *px = NULL;
    if (imgio_read(path, names, n, &px, w, h, err, sizeof err) != 0) {
        fprintf(stderr, "exrtool: %s\n", err);
        exit(2);
    }
    return px;
}

/* R, G, B, A interleaved. */
static float *load(const char *path, uint32_t *w, uint32_t *h) { return load_channels(path, channels, 4, w, h); }

/* R, G, B, A, variance.R, variance.G, variance.B interleaved (7 floats a pixel). */
static float *load_var(const char *path, uint32_t *w, uint32_t *h)
{
    return load_channels(path, all_channels, NCH, w, h);
}

/* Two images of the same size (exit status 1 when they differ): *a and *b. */
static void load_pair(const char *pa, const char *pb, const char *const *names, int n, float **a, float **b,
                      uint32_t *w, uint32_t *h)
{
    uint32_t wb, hb;
    *a = load_channels(pa, names, n, w, h);
    *b = load_channels(pb, names, n, &wb, &hb);
    if (*w != wb || *h != hb) {
        fprintf(stderr, "exrtool: sizes differ: %ux%u vs %ux%u\n", *w, *h, wb, hb);
        exit(1);
    }
}

/* Writes w x h pixels of NCH interleaved channels as a tiled, uncompressed EXR. */
static void write_exr(const char *path, const float *px, uint32_t w, uint32_t h)
{
    char err[512];
    struct image_desc d;
    memset(&d, 0, sizeof d);
    d.width = w;
    d.height = h;
    d.tile_size = 32;
    d.num_channels = NCH;
    for (int c = 0; c < NCH; c++)
        snprintf(d.channel_names[c], sizeof d.channel_names[c], "%s", all_channels[c]);
    d.compression = IMGIO_NONE;
    struct image_attrs a;
    memset(&a, 0, sizeof a);
    a.spp = 1;
    snprintf(a.scene_hash, sizeof a.scene_hash, "%s", "0");
    snprintf(a.software, sizeof a.software, "%s", "brume exrtool");
    struct imgio_encoder *e = imgio_encoder_new(&d, err, sizeof err);
    struct imgio_writer *wr = e ? imgio_writer_open(path, &d, &a, err, sizeof err) : NULL;
    if (!wr) {
        fprintf(stderr, "exrtool: %s\n", err);
        exit(2);
    }
    float *tile = malloc(sizeof(float) * NCH * d.tile_size * d.tile_size);
    for (uint32_t ty = 0; ty < imgio_tiles_y(&d); ty++)
        for (uint32_t tx = 0; tx < imgio_tiles_x(&d); tx++) {
            uint32_t x0, y0, tw, th;
            imgio_tile_rect(&d, tx, ty, &x0, &y0, &tw, &th);
            for (uint32_t y = 0; y < th; y++)
                memcpy(&tile[(size_t)y * tw * NCH], &px[((size_t)(y0 + y) * w + x0) * NCH], sizeof(float) * NCH * tw);
            uint8_t *chunk = NULL;
            size_t size = 0;
            if (imgio_encode_tile(e, tx, ty, tile, &chunk, &size, err, sizeof err) != 0 ||
                imgio_writer_put_tile(wr, tx, ty, chunk, size, err, sizeof err) != 0) {
                fprintf(stderr, "exrtool: %s\n", err);
                exit(2);
            }
            free(chunk);
        }
    free(tile);
    imgio_encoder_free(&e);
    if (imgio_writer_close(&wr, err, sizeof err) != 0) {
        fprintf(stderr, "exrtool: %s\n", err);
        exit(2);
    }
}

/* Box-downsamples R,G,B (4 floats a pixel) by n x n in place of *px; partial blocks at the
 * right and bottom edges average the pixels they hold. Updates *w, *h. */
static void box_down(float **px, uint32_t *w, uint32_t *h, uint32_t n)
{
    uint32_t bw = (*w + n - 1) / n, bh = (*h + n - 1) / n;
    float *o = calloc((size_t)bw * bh * 4, sizeof(float));
    for (uint32_t by = 0; by < bh; by++)
        for (uint32_t bx = 0; bx < bw; bx++) {
            double s[3] = {0, 0, 0};
            size_t cnt = 0;
            for (uint32_t y = by * n; y < by * n + n && y < *h; y++)
                for (uint32_t x = bx * n; x < bx * n + n && x < *w; x++, cnt++)
                    for (int c = 0; c < 3; c++)
                        s[c] += (*px)[((size_t)y * *w + x) * 4 + c];
            for (int c = 0; c < 3; c++)
                o[((size_t)by * bw + bx) * 4 + c] = (float)(s[c] / (double)cnt);
        }
    free(*px);
    *px = o;
    *w = bw;
    *h = bh;
}

static int relrmse(int argc, char **argv)
{
    uint32_t n = 1;
    const char *mask_path = NULL;
    double tol = 0.1;
    int ok = argc >= 4;
    for (int i = 4; ok && i < argc; i += 2) {
        if (i + 1 >= argc)
            ok = 0;
        else if (!strcmp(argv[i], "--box") && atoi(argv[i + 1]) >= 1)
            n = (uint32_t)atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--mask"))
            mask_path = argv[i + 1];
        else if (!strcmp(argv[i], "--tol") && atof(argv[i + 1]) > 0.0)
            tol = atof(argv[i + 1]);
        else
            ok = 0;
    }
    if (!ok || (mask_path && n > 1)) {
        fprintf(stderr, "usage: exrtool relrmse A.exr REF.exr [--box N | --mask S.exr [--tol T]]\n");
        return 2;
    }
    uint32_t wa, ha;
    float *a, *b, *m = NULL;
    load_pair(argv[2], argv[3], channels, 4, &a, &b, &wa, &ha);
    if (n > 1) {
        uint32_t wb = wa, hb = ha;
        box_down(&a, &wa, &ha, n);
        box_down(&b, &wb, &hb, n);
    }
    size_t np = (size_t)wa * ha, nm = 0;
    double ref_mean = 0;
    for (size_t i = 0; i < np; i++)
        for (int c = 0; c < 3; c++)
            ref_mean += b[i * 4 + c] / (3.0 * np);
    if (mask_path) {
        float *r2;
        uint32_t wm, hm;
        load_pair(argv[3], mask_path, channels, 4, &r2, &m, &wm, &hm);
        free(r2);
    }
    double se = 0, sr = 0;
    for (size_t i = 0; i < np; i++) {
        /* The mask: pixels where REF and S differ by more than tol times REF's image mean. */
        int in = !m;
        for (int c = 0; c < 3 && !in; c++)
            in = fabs((double)b[i * 4 + c] - m[i * 4 + c]) > tol * ref_mean;
        if (!in)
            continue;
        nm++;
        for (int c = 0; c < 3; c++) {
            double d = (double)a[i * 4 + c] - b[i * 4 + c];
            se += d * d;
            sr += b[i * 4 + c];
        }
    }
    free(a);
    free(b);
    free(m);
    if (!(sr > 0)) {
        fprintf(stderr, "exrtool: the reference's mean is not positive%s\n", mask_path ? " in the mask" : "");
        return 1;
    }
    if (mask_path)
        fprintf(stderr, "exrtool: mask holds %zu of %zu pixels\n", nm, np);
    printf("%.9g\n", sqrt(se / (3.0 * nm)) / (sr / (3.0 * nm)));
    return 0;
}

static int cmp_desc(const void *x, const void *y)
{
    double a = *(const double *)x, b = *(const double *)y;
    return (a < b) - (a > b);
}

/* errtop: how much of the squared error the worst pixels hold (fireflies). */
struct pixerr { double e; uint32_t i; };

static int cmp_pixerr(const void *x, const void *y)
{
    return cmp_desc(&((const struct pixerr *)x)->e, &((const struct pixerr *)y)->e);
}

static int errtop(const char *pa, const char *pref, int worst)
{
    uint32_t w, h;
    float *a, *b;
    load_pair(pa, pref, channels, 4, &a, &b, &w, &h);
    size_t np = (size_t)w * h;
    struct pixerr *e = malloc(np * sizeof *e);
    double tot = 0;
    for (size_t i = 0; i < np; i++) {
        e[i].e = 0;
        e[i].i = (uint32_t)i;
        for (int c = 0; c < 3; c++) {
            double d = (double)a[i * 4 + c] - b[i * 4 + c];
            e[i].e += d * d;
        }
        tot += e[i].e;
    }
    qsort(e, np, sizeof *e, cmp_pixerr);
    size_t k1 = (np + 999) / 1000, k2 = (np + 99) / 100;
    double s1 = 0, s2 = 0;
    for (size_t i = 0; i < k2 && i < np; i++) {
        if (i < k1)
            s1 += e[i].e;
        s2 += e[i].e;
    }
    printf("%.6g %.6g\n", tot > 0 ? s1 / tot : 0.0, tot > 0 ? s2 / tot : 0.0);
    for (size_t i = 0; i < (size_t)worst && i < np; i++)
        printf("%u %u %.6g %.6g %.6g\n", e[i].i % w, e[i].i / w, e[i].e, (double)a[e[i].i * 4], (double)b[e[i].i * 4]);
    free(a);
    free(b);
    free(e);
    return 0;
}

/* errest and semean: the noise the image states for itself. */
static int noise(const char *cmd, const char *path)
{
    uint32_t w, h;
    float *a = load_var(path, &w, &h);
    size_t np = (size_t)w * h;
    double sum = 0, var = 0, var_corr = 0;
    for (size_t i = 0; i < np; i++) {
        double sd = 0;
        for (int c = 0; c < 3; c++) {
            sum += a[i * NCH + c];
            double v = fmax(0.0, a[i * NCH + 4 + c]);
            var += v;
            sd += sqrt(v) / 3.0;
        }
        var_corr += sd * sd;
    }
    free(a);
    double mean = sum / (3.0 * np);
    if (!strcmp(cmd, "semean")) {
        printf("%.9g %.9g\n", mean, sqrt(var_corr) / (double)np);
        return 0;
    }
    if (!(mean > 0)) {
        fprintf(stderr, "exrtool: the image's mean is not positive\n");
        return 1;
    }
    printf("%.9g\n", sqrt(var / (3.0 * np)) / mean);
    return 0;
}

static int average(const char *out, const char *pa, const char *pb)
{
    uint32_t wa, ha;
    float *a, *b;
    load_pair(pa, pb, all_channels, NCH, &a, &b, &wa, &ha);
    for (size_t i = 0; i < (size_t)wa * ha * NCH; i++)
        a[i] = (i % NCH) < 4 ? 0.5f * (a[i] + b[i]) : 0.25f * (a[i] + b[i]);
    write_exr(out, a, wa, ha);
    free(a);
    free(b);
    return 0;
}

static int synth(int argc, char **argv)
{
    if (argc < 6 || argc % 2) {
        fprintf(stderr, "usage: exrtool synth OUT.exr W H V [--checker AMP] [--var VAR] [--spot AMP]\n");
        return 2;
    }
    uint32_t w = (uint32_t)atoi(argv[3]), h = (uint32_t)atoi(argv[4]);
    double v = atof(argv[5]), amp = 0, var = 0, spot = 0;
    for (int i = 6; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--checker"))
            amp = atof(argv[i + 1]);
        else if (!strcmp(argv[i], "--var"))
            var = atof(argv[i + 1]);
        else if (!strcmp(argv[i], "--spot"))
            spot = atof(argv[i + 1]);
        else {
            fprintf(stderr, "exrtool: unknown option %s\n", argv[i]);
            return 2;
        }
    }
    if (w < 1 || h < 1 || w > 1u << 14 || h > 1u << 14) {
        fprintf(stderr, "exrtool: bad size\n");
        return 2;
    }
    float *px = malloc(sizeof(float) * NCH * w * h);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            float *p = &px[((size_t)y * w + x) * NCH];
            for (int c = 0; c < 3; c++) {
                p[c] = (float)(v + ((x + y) % 2 ? -amp : amp) + (x == 1 && y == 2 ? spot : 0.0));
                p[4 + c] = (float)var;
            }
            p[3] = 1.0f;
        }
    write_exr(argv[2], px, w, h);
    free(px);
    return 0;
}

/* chstat A.exr NAME [X0 Y0 W H]: statistics of one channel. */
static int chstat(int argc, char **argv)
{
    const char *names[1] = {argv[3]};
    uint32_t w, h;
    float *px = load_channels(argv[2], names, 1, &w, &h);
    uint32_t x0 = 0, y0 = 0, rw = w, rh = h;
    if (argc == 8) {
        x0 = (uint32_t)atoi(argv[4]), y0 = (uint32_t)atoi(argv[5]), rw = (uint32_t)atoi(argv[6]),
        rh = (uint32_t)atoi(argv[7]);
        if (x0 + rw > w || y0 + rh > h || !rw || !rh) {
            fprintf(stderr, "exrtool: rectangle outside the image\n");
            free(px);
            return 2;
        }
    }
    double sum = 0.0, lo = INFINITY, hi = -INFINITY;
    uint64_t n = 0, infs = 0, nans = 0;
    for (uint32_t y = y0; y < y0 + rh; y++)
        for (uint32_t x = x0; x < x0 + rw; x++) {
            float v = px[(size_t)y * w + x];
            if (isnan(v)) {
                nans++;
            } else if (isinf(v)) {
                infs += v > 0.0f;
                nans += v < 0.0f; /* -inf: never written; counted as bad */
            } else {
                sum += v;
                lo = v < lo ? v : lo;
                hi = v > hi ? v : hi;
                n++;
            }
        }
    printf("%.9g %.9g %.9g %llu %llu\n", n ? sum / (double)n : 0.0, n ? lo : 0.0, n ? hi : 0.0,
           (unsigned long long)infs, (unsigned long long)nans);
    free(px);
    return 0;
}


/* oracle: the best equal-error time ratio of any allocation of samples. */
enum { ORACLE_SIZES = 6, ORACLE_MAX_TARGETS = 8 };
static const uint32_t oracle_sizes[ORACLE_SIZES] = {1, 2, 4, 8, 16, 32};

/* Per-pixel v summed into s x s units (a grid from the corner): V[u] and pixels P[u]. */
static size_t oracle_units(const double *v, uint32_t w, uint32_t h, uint32_t s, double *V, double *P)
{
    uint32_t ux = (w + s - 1) / s, uy = (h + s - 1) / s;
    memset(V, 0, sizeof(double) * ux * uy);
    memset(P, 0, sizeof(double) * ux * uy);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            size_t u = (size_t)(y / s) * ux + x / s;
            V[u] += v[(size_t)y * w + x];
            P[u] += 1.0;
        }
    return (size_t)ux * uy;
}

/* The error variance sum_u Vj[u] / n_u of the allocation n_u = max(floor, lam sqrt(Vi[u] / P[u])). */
static double oracle_err(const double *Vi, const double *Vj, const double *P, size_t nu, double fl, double lam)
{
    double e = 0;
    for (size_t u = 0; u < nu; u++) {
        if (!(Vj[u] > 0))
            continue;
        double n = fmax(fl, lam * sqrt(Vi[u] / P[u]));
        e += n > 0 ? Vj[u] / n : INFINITY;
    }
    return e;
}

/* Samples in all that the allocation shaped by Vi (floor fl per pixel) needs for the error
 * variance judged by Vj to reach budget; INFINITY when it cannot. */
static double oracle_cost(const double *Vi, const double *Vj, const double *P, size_t nu, double fl, double budget)
{
    double lam;
    if (oracle_err(Vi, Vj, P, nu, fl, 0.0) <= budget) {
        lam = 0.0; /* the floor alone meets it */
    } else {
        double lo = 1.0, hi = 1.0;
        int k = 0;
        while (oracle_err(Vi, Vj, P, nu, fl, hi) > budget && k++ < 400)
            hi *= 2.0;
        if (k > 400)
            return INFINITY;
        while (oracle_err(Vi, Vj, P, nu, fl, lo) <= budget && lo > 1e-300)
            lo *= 0.5;
        for (int i = 0; i < 200; i++) {
            double mid = sqrt(lo * hi);
            if (oracle_err(Vi, Vj, P, nu, fl, mid) > budget)
                lo = mid;
            else
                hi = mid;
        }
        lam = hi;
    }
    double c = 0;
    for (size_t u = 0; u < nu; u++)
        c += P[u] * fmax(fl, lam * sqrt(Vi[u] / P[u]));
    return c;
}

static int oracle(int argc, char **argv)
{
    double spp = 0, fl = 0, targets[ORACLE_MAX_TARGETS];
    const char *alloc[ORACLE_MAX_TARGETS];
    int nt = 0, na = 0, i = 2;
    for (; i + 1 < argc && !strncmp(argv[i], "--", 2); i += 2) {
        if (!strcmp(argv[i], "--alloc") && na < ORACLE_MAX_TARGETS)
            alloc[na++] = argv[i + 1];
        else if (!strcmp(argv[i], "--spp"))
            spp = atof(argv[i + 1]);
        else if (!strcmp(argv[i], "--floor"))
            fl = atof(argv[i + 1]);
        else if (!strcmp(argv[i], "--target") && nt < ORACLE_MAX_TARGETS && atof(argv[i + 1]) > 0)
            targets[nt++] = atof(argv[i + 1]);
        else
            break;
    }
    int k = argc - i;
    if (k < 4 || !(spp > 0) || !(fl >= 0) || (i < argc && !strncmp(argv[i], "--", 2))) {
        fprintf(stderr, "usage: exrtool oracle --spp N [--floor N0] [--target E]... [--alloc S.exr]... A1.exr ... AK.exr (K >= 4)\n");
        return 2;
    }
    uint32_t w = 0, h = 0;
    size_t np = 0;
    /* Per pixel and channel: sums of the value and its square, over all renders and each half. */
    double *sum = NULL, *sq = NULL, *hsum[2] = {NULL, NULL}, *hsq[2] = {NULL, NULL};
    int half_k[2] = {k / 2, k - k / 2};
    for (int r = 0; r < k; r++) {
        uint32_t wr, hr;
        float *a = load(argv[i + r], &wr, &hr);
        if (r == 0) {
            w = wr, h = hr, np = (size_t)w * h;
            sum = calloc(np * 3, sizeof *sum), sq = calloc(np * 3, sizeof *sq);
            for (int j = 0; j < 2; j++)
                hsum[j] = calloc(np * 3, sizeof(double)), hsq[j] = calloc(np * 3, sizeof(double));
        } else if (wr != w || hr != h) {
            fprintf(stderr, "exrtool: sizes differ: %ux%u vs %ux%u\n", w, h, wr, hr);
            return 1;
        }
        int j = r < half_k[0] ? 0 : 1;
        for (size_t p = 0; p < np; p++)
            for (int c = 0; c < 3; c++) {
                double x = a[p * 4 + c];
                sum[p * 3 + c] += x, sq[p * 3 + c] += x * x;
                hsum[j][p * 3 + c] += x, hsq[j][p * 3 + c] += x * x;
            }
        free(a);
    }
    /* v: N x the variance of one render's pixel (mean over R, G, B), from all renders and each half. */
    double *v = malloc(np * sizeof *v), *hv[2] = {malloc(np * sizeof(double)), malloc(np * sizeof(double))};
    double mean = 0, var_one = 0;
    for (size_t p = 0; p < np; p++) {
        v[p] = hv[0][p] = hv[1][p] = 0;
        for (int c = 0; c < 3; c++) {
            size_t q = p * 3 + c;
            double m = sum[q] / k;
            v[p] += fmax(0.0, (sq[q] - k * m * m) / (k - 1)) / 3.0;
            mean += m / (3.0 * np);
            for (int j = 0; j < 2; j++) {
                double mh = hsum[j][q] / half_k[j];
                hv[j][p] += fmax(0.0, (hsq[j][q] - half_k[j] * mh * mh) / (half_k[j] - 1)) / 3.0;
            }
        }
        var_one += v[p] / np;
        v[p] *= spp, hv[0][p] *= spp, hv[1][p] *= spp;
    }
    if (!(mean > 0)) {
        fprintf(stderr, "exrtool: the image's mean is not positive\n");
        return 1;
    }
    printf("oracle: %d renders %ux%u at %g spp, image mean %.6g, relRMSE of one render %.5g (their spread)\n", k, w, h,
           spp, mean, sqrt(var_one) / mean);
    size_t maxu = np;
    double *V = malloc(maxu * sizeof *V), *P = malloc(maxu * sizeof *P);
    double *VA = malloc(maxu * sizeof *VA), *VB = malloc(maxu * sizeof *VB);
    printf("bound (no floor):");
    for (int si = 0; si < ORACLE_SIZES; si++) {
        size_t nu = oracle_units(v, w, h, oracle_sizes[si], V, P);
        double ssq = 0, sv = 0;
        for (size_t u = 0; u < nu; u++)
            ssq += sqrt(V[u] * P[u]), sv += V[u];
        printf(" %upx %.3f", oracle_sizes[si], sv > 0 ? ssq * ssq / (sv * (double)np) : 1.0);
    }
    printf("\n");
    for (int t = 0; t < nt; t++) {
        double budget = targets[t] * targets[t] * mean * mean * (double)np;
        double sv = 0;
        for (size_t p = 0; p < np; p++)
            sv += v[p];
        printf("target %g (uniform %.1f spp, floor %g spp), in-sample / halves:", targets[t], sv / budget, fl);
        for (int si = 0; si < ORACLE_SIZES; si++) {
            size_t nu = oracle_units(v, w, h, oracle_sizes[si], V, P);
            double in = oracle_cost(V, V, P, nu, fl, budget) / (sv / budget * (double)np), halves = 0;
            oracle_units(hv[0], w, h, oracle_sizes[si], VA, P);
            oracle_units(hv[1], w, h, oracle_sizes[si], VB, P);
            double sa = 0, sb = 0;
            for (size_t u = 0; u < nu; u++)
                sa += VA[u], sb += VB[u];
            halves = 0.5 * (oracle_cost(VA, VB, P, nu, fl, budget) / (sb / budget * (double)np) +
                            oracle_cost(VB, VA, P, nu, fl, budget) / (sa / budget * (double)np));
            printf(" %upx %.3f/%.3f", oracle_sizes[si], in, halves);
        }
        printf("\n");
    }
    for (int t = 0; t < na; t++) {
        /* An adaptive render's allocation (its samples channel) judged on v: its expected
         * error (variance v / n a pixel), and what uniform spp and the best 8 px allocation
         * with the floor would cost to reach that error. */
        const char *names[1] = {"samples"};
        uint32_t wa, ha;
        float *n = load_channels(alloc[t], names, 1, &wa, &ha);
        if (wa != w || ha != h) {
            fprintf(stderr, "exrtool: sizes differ: %ux%u vs %ux%u\n", w, h, wa, ha);
            return 1;
        }
        double err = 0, cost = 0, sv = 0;
        int ok = 1;
        for (size_t p = 0; p < np; p++) {
            ok &= n[p] > 0 || !(v[p] > 0);
            err += n[p] > 0 ? v[p] / n[p] : 0.0;
            cost += n[p], sv += v[p];
        }
        free(n);
        if (!ok) {
            fprintf(stderr, "exrtool: %s: a pixel with variance got no samples\n", alloc[t]);
            return 1;
        }
        size_t nu = oracle_units(v, w, h, 8, V, P);
        double uniform = sv / err * (double)np;
        printf("allocation %s: mean %.1f spp, expected relRMSE %.5g; / uniform at that error %.3f, best 8px "
               "(floor %g) / uniform %.3f\n", alloc[t], cost / (double)np, sqrt(err / (double)np) / mean, cost / uniform,
               fl, oracle_cost(V, V, P, nu, fl, err) / uniform);
    }
    free(sum), free(sq), free(v), free(V), free(P), free(VA), free(VB);
    for (int j = 0; j < 2; j++)
        free(hsum[j]), free(hsq[j]), free(hv[j]);
    return 0;
}

/* Per pixel: the variance of the mean over R, G, B and the mean of R, G, B (px: all_channels). */
static void pixel_var_mean(const float *px, double *var, double *mean)
{
    *var = ((double)px[4] + px[5] + px[6]) / 3.0;
    *mean = ((double)px[0] + px[1] + px[2]) / 3.0;
}

/* The scale of a pixel's relative error: max(its mean, ADAPT_PIXEL_FLOOR (0.1) x the image's mean). */
static double pixel_scale(double mean, double image_mean)
{
    return mean > 0.1 * image_mean ? mean : 0.1 * image_mean;
}

static int pixerr(int argc, char **argv)
{
    const char *ref_path = NULL, *alloc_path = NULL;
    double cap = 0.0, P = argc >= 4 ? atof(argv[3]) : 0.0;
    int ok = argc >= 4 && P > 0.0;
    for (int i = 4; ok && i < argc; i += 2) {
        if (i + 1 >= argc)
            ok = 0;
        else if (!strcmp(argv[i], "--ref"))
            ref_path = argv[i + 1];
        else if (!strcmp(argv[i], "--alloc"))
            alloc_path = argv[i + 1];
        else if (!strcmp(argv[i], "--cap") && atof(argv[i + 1]) > 0.0)
            cap = atof(argv[i + 1]);
        else
            ok = 0;
    }
    if (!ok) {
        fprintf(stderr, "usage: exrtool pixerr A.exr P [--ref REF.exr] [--cap SPP] [--alloc S.exr]\n");
        return 2;
    }
    uint32_t w, h;
    float *a = load_var(argv[2], &w, &h), *r = NULL, *spp = NULL, *alloc = NULL;
    size_t np = (size_t)w * h;
    const char *names[1] = {"samples"};
    if (alloc_path) {
        uint32_t ws, hs;
        alloc = load_channels(alloc_path, names, 1, &ws, &hs);
        if (ws != w || hs != h) {
            fprintf(stderr, "exrtool: sizes differ: %ux%u vs %ux%u\n", w, h, ws, hs);
            return 1;
        }
    }
    if (ref_path) {
        uint32_t wr, hr;
        r = load_var(ref_path, &wr, &hr);
        if (wr != w || hr != h) {
            fprintf(stderr, "exrtool: sizes differ: %ux%u vs %ux%u\n", w, h, wr, hr);
            return 1;
        }
    }
    if (cap > 0.0) {
        uint32_t ws, hs;
        spp = load_channels(argv[2], names, 1, &ws, &hs);
    }
    double mean_a = 0.0, mean_r = 0.0;
    for (size_t i = 0; i < np; i++) {
        double v, m;
        pixel_var_mean(&a[i * NCH], &v, &m);
        mean_a += m / (double)np;
        if (r) {
            pixel_var_mean(&r[i * NCH], &v, &m);
            mean_r += m / (double)np;
        }
    }
    const double levels[3] = {2.0 * P, P, 0.5 * P};
    size_t over = 0, capped = 0, est_over[3] = {0}, true_over[3] = {0};
    double worst = 0.0, alloc_sum[2] = {0.0, 0.0};
    for (size_t i = 0; i < np; i++) {
        double v, m;
        pixel_var_mean(&a[i * NCH], &v, &m);
        double e = v > 0.0 ? sqrt(v) / pixel_scale(m, mean_a) : 0.0;
        worst = e > worst ? e : worst;
        if (e > P) {
            over++;
            capped += spp && spp[i] >= cap;
        }
        if (alloc)
            alloc_sum[e > P] += alloc[i];
        if (!r)
            continue;
        double rv, rm, se = 0.0;
        pixel_var_mean(&r[i * NCH], &rv, &rm);
        for (int c = 0; c < 3; c++)
            se += ((double)a[i * NCH + c] - r[i * NCH + c]) * ((double)a[i * NCH + c] - r[i * NCH + c]) / 3.0;
        double sc = pixel_scale(rm, mean_r), te = sqrt(se) / sc, ee = v > 0.0 ? sqrt(v) / sc : 0.0;
        for (int k = 0; k < 3; k++) {
            true_over[k] += te > levels[k];
            est_over[k] += ee > levels[k];
        }
    }
    printf("estimate: over %zu of %zu (%zu at the cap), worst %.6g\n", over, np, capped, worst);
    if (r)
        printf("true above 2P, P, P/2: %.4f %.4f %.4f; estimate: %.4f %.4f %.4f\n", (double)true_over[0] / np,
               (double)true_over[1] / np, (double)true_over[2] / np, (double)est_over[0] / np, (double)est_over[1] / np,
               (double)est_over[2] / np);
    if (alloc)
        printf("alloc: mean samples %.6g where the estimate is above P, %.6g elsewhere\n",
               over ? alloc_sum[1] / (double)over : 0.0, np > over ? alloc_sum[0] / (double)(np - over) : 0.0);
    free(alloc);
    free(a);
    free(r);
    free(spp);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc >= 2 && !strcmp(argv[1], "pixerr"))
        return pixerr(argc, argv);
    if (argc >= 2 && !strcmp(argv[1], "oracle"))
        return oracle(argc, argv);
    if (argc >= 2 && !strcmp(argv[1], "relrmse"))
        return relrmse(argc, argv);
    if ((argc == 4 || argc == 5) && !strcmp(argv[1], "errtop"))
        return errtop(argv[2], argv[3], argc == 5 ? atoi(argv[4]) : 0);
    if (argc == 3 && (!strcmp(argv[1], "errest") || !strcmp(argv[1], "semean")))
        return noise(argv[1], argv[2]);
    if (argc == 5 && !strcmp(argv[1], "average"))
        return average(argv[2], argv[3], argv[4]);
    if (argc >= 2 && !strcmp(argv[1], "synth"))
        return synth(argc, argv);
    if ((argc == 4 || argc == 8) && !strcmp(argv[1], "chstat"))
        return chstat(argc, argv);
    if (argc == 4 && !strcmp(argv[1], "chsum")) {
        const char *names[1] = {argv[3]};
        uint32_t w, h;
        float *px = load_channels(argv[2], names, 1, &w, &h);
        double sum = 0.0;
        for (size_t i = 0; i < (size_t)w * h; i++)
            sum += px[i];
        printf("%.17g\n", sum);
        free(px);
        return 0;
    }
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
        fprintf(stderr, "usage: exrtool cmp A.exr B.exr | rmse A.exr REF.exr | mean A.exr | cmprect A B X0 Y0 W H |\n"
                        "       relrmse A.exr REF.exr [--box N | --mask S.exr [--tol T]] | errtop A.exr REF.exr [N] | errest A.exr | semean A.exr |\n"
                        "       chstat A.exr NAME [X0 Y0 W H] |\n"
                        "       average OUT.exr A.exr B.exr | synth OUT.exr W H V [--checker AMP] [--var VAR] |\n"
                        "       oracle --spp N [--floor N0] [--target E]... [--alloc S.exr]... A1.exr ... AK.exr\n");
        return 2;
    }
    uint32_t wa, ha;
    float *a, *b;
    load_pair(argv[2], argv[3], channels, 4, &a, &b, &wa, &ha);
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
