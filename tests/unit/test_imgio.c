/* Unit tests for image I/O (common/image/imgio.c): tile grid math, bit-exact encode/decode of
 * tile chunks for every compression (interior and clipped edge tiles, channels given out
 * of alphabetical order), rejection of malformed chunks, a whole tiled file assembled from
 * shuffled tiles and read back (and through OpenEXR's C++ library, for our ZIP chunks are
 * libdeflate's), reading a scanline HALF file, and PNG previews.
 * Run by `make unit` with every other tests/unit/test_*.c; temp files go under mkdtemp. */
#include <criterion/criterion.h>
#include <fcntl.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include "image/imgio.h"

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpedantic"
#pragma GCC diagnostic ignored "-Wstrict-prototypes"
#include <OpenEXR/openexr.h>
#include <png.h>
#pragma GCC diagnostic pop

/* Renderer order on purpose differs from OpenEXR's sorted order (A B G R albedo.r depth). */
static const char *const k_names[] = {"R", "G", "B", "A", "depth", "albedo.r"};
#define K_NC 6u

static struct image_desc make_desc(enum imgio_compression comp, uint32_t w, uint32_t h, uint32_t ts)
{
    struct image_desc d;
    memset(&d, 0, sizeof d);
    d.width = w;
    d.height = h;
    d.tile_size = ts;
    d.num_channels = K_NC;
    for (uint32_t c = 0; c < K_NC; c++)
        snprintf(d.channel_names[c], sizeof d.channel_names[c], "%s", k_names[c]);
    d.compression = comp;
    return d;
}

static uint32_t lcg(uint32_t *s)
{
    *s = *s * 1664525u + 1013904223u;
    return *s >> 8;
}

/* Value of image pixel (x, y) channel c: smooth (compresses) or noise (does not), with a
 * few awkward floats sprinkled in so bit-exactness is really tested. */
static float pixel_value(uint32_t x, uint32_t y, uint32_t c, int noise)
{
    if (noise) {
        uint32_t s = (x * 73856093u) ^ (y * 19349663u) ^ (c * 83492791u);
        for (int i = 0; i < 3; i++)
            lcg(&s);
        union { uint32_t u; float f; } v = {(s & 0x7f7fffffu) | ((s & 1u) << 31)};
        return v.f;
    }
    if ((x * 7 + y * 3 + c) % 97 == 0)
        return -0.0f;
    if ((x + y * 5 + c) % 89 == 0)
        return 1e-40f; /* denormal */
    return (float)c * 10.0f + (float)x * 0.25f + (float)y * 0.125f;
}

static float *make_tile(const struct image_desc *d, uint32_t tx, uint32_t ty, int noise)
{
    uint32_t x0, y0, w, h;
    imgio_tile_rect(d, tx, ty, &x0, &y0, &w, &h);
    float *p = malloc((size_t)w * h * d->num_channels * sizeof(float));
    cr_assert_not_null(p);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++)
            for (uint32_t c = 0; c < d->num_channels; c++)
                p[((size_t)y * w + x) * d->num_channels + c] = pixel_value(x0 + x, y0 + y, c, noise);
    return p;
}

static size_t tile_floats(const struct image_desc *d, uint32_t tx, uint32_t ty)
{
    uint32_t x0, y0, w, h;
    imgio_tile_rect(d, tx, ty, &x0, &y0, &w, &h);
    return (size_t)w * h * d->num_channels;
}

static void make_tmpdir(char *dir, size_t n)
{
    snprintf(dir, n, "/tmp/brume_imgio_XXXXXX");
    cr_assert_not_null(mkdtemp(dir));
}

/* ------------------------------------------------------------------------------------- */

Test(imgio, tile_grid)
{
    struct image_desc d = make_desc(IMGIO_ZIP, 70, 45, 16);
    cr_assert_eq(imgio_tiles_x(&d), 5);
    cr_assert_eq(imgio_tiles_y(&d), 3);
    uint32_t x0, y0, w, h;
    imgio_tile_rect(&d, 0, 0, &x0, &y0, &w, &h);
    cr_assert(x0 == 0 && y0 == 0 && w == 16 && h == 16);
    imgio_tile_rect(&d, 2, 1, &x0, &y0, &w, &h);
    cr_assert(x0 == 32 && y0 == 16 && w == 16 && h == 16);
    imgio_tile_rect(&d, 4, 2, &x0, &y0, &w, &h);
    cr_assert(x0 == 64 && y0 == 32 && w == 6 && h == 13, "edge %u %u %u %u", x0, y0, w, h);

    struct image_desc e = make_desc(IMGIO_ZIP, 64, 32, 16); /* exact multiple */
    cr_assert_eq(imgio_tiles_x(&e), 4);
    cr_assert_eq(imgio_tiles_y(&e), 2);
    imgio_tile_rect(&e, 3, 1, &x0, &y0, &w, &h);
    cr_assert(x0 == 48 && y0 == 16 && w == 16 && h == 16);

    struct image_desc f = make_desc(IMGIO_ZIP, 10, 7, 64); /* tile bigger than the image */
    cr_assert_eq(imgio_tiles_x(&f), 1);
    cr_assert_eq(imgio_tiles_y(&f), 1);
    imgio_tile_rect(&f, 0, 0, &x0, &y0, &w, &h);
    cr_assert(x0 == 0 && y0 == 0 && w == 10 && h == 7);
}

static void roundtrip_one(enum imgio_compression comp, uint32_t tx, uint32_t ty, int noise)
{
    char err[256] = "";
    struct image_desc d = make_desc(comp, 70, 45, 16);
    struct imgio_encoder *e = imgio_encoder_new(&d, err, sizeof err);
    cr_assert_not_null(e, "%s", err);
    float *in = make_tile(&d, tx, ty, noise);
    size_t n = tile_floats(&d, tx, ty);
    uint8_t *chunk = NULL;
    size_t size = 0;
    cr_assert_eq(imgio_encode_tile(e, tx, ty, in, &chunk, &size, err, sizeof err), 0, "%s", err);
    cr_assert_gt(size, 0);
    cr_assert_leq(size, n * sizeof(float));
    if (comp == IMGIO_NONE)
        cr_assert_eq(size, n * sizeof(float));
    else if (!noise && n >= 256 * K_NC) /* PIZ's tables outweigh the gain on tiny tiles */
        cr_assert_lt(size, n * sizeof(float), "smooth data should compress (comp %d)", comp);

    /* Same input, same bytes: the encoder is reusable and deterministic. */
    uint8_t *again = NULL;
    size_t again_size = 0;
    cr_assert_eq(imgio_encode_tile(e, tx, ty, in, &again, &again_size, err, sizeof err), 0, "%s", err);
    cr_assert_eq(again_size, size);
    cr_assert_eq(memcmp(again, chunk, size), 0);

    float *out = malloc(n * sizeof(float));
    memset(out, 0xAB, n * sizeof(float));
    cr_assert_eq(imgio_decode_tile(&d, tx, ty, chunk, size, out, err, sizeof err), 0, "%s", err);
    cr_assert_eq(memcmp(in, out, n * sizeof(float)), 0, "comp %d tile (%u,%u) noise %d differs", comp, tx, ty,
                 noise);
    free(out);
    free(again);
    free(chunk);
    free(in);
    imgio_encoder_free(&e);
    cr_assert_null(e);
}

Test(imgio, roundtrip_all_compressions)
{
    const enum imgio_compression comps[] = {IMGIO_NONE, IMGIO_ZIP, IMGIO_PIZ};
    for (int i = 0; i < 3; i++)
        for (int noise = 0; noise < 2; noise++) {
            roundtrip_one(comps[i], 1, 1, noise); /* interior */
            roundtrip_one(comps[i], 4, 2, noise); /* clipped 6x13 corner */
            roundtrip_one(comps[i], 4, 0, noise); /* clipped 6x16 */
            roundtrip_one(comps[i], 0, 2, noise); /* clipped 16x13 */
        }
}

Test(imgio, encoder_rejects_bad_input)
{
    char err[256] = "";
    struct image_desc d = make_desc(IMGIO_ZIP, 70, 45, 16);
    d.tile_size = 0;
    cr_assert_null(imgio_encoder_new(&d, err, sizeof err));
    d = make_desc(IMGIO_ZIP, 70, 45, 16);
    snprintf(d.channel_names[4], sizeof d.channel_names[4], "R");
    cr_assert_null(imgio_encoder_new(&d, err, sizeof err));
    cr_assert(strstr(err, "duplicate") != NULL, "%s", err);
    d = make_desc(IMGIO_ZIP, 70, 45, 16);
    struct imgio_encoder *e = imgio_encoder_new(&d, err, sizeof err);
    cr_assert_not_null(e, "%s", err);
    float *in = make_tile(&d, 0, 0, 0);
    uint8_t *chunk = (uint8_t *)1;
    size_t size = 1;
    cr_assert_eq(imgio_encode_tile(e, 5, 0, in, &chunk, &size, err, sizeof err), -1);
    cr_assert_null(chunk);
    cr_assert_eq(size, 0);
    cr_assert_eq(imgio_encode_tile(e, 0, 3, in, &chunk, &size, err, sizeof err), -1);
    free(in);
    imgio_encoder_free(&e);
    imgio_encoder_free(&e); /* idempotent */
}

static uint8_t *encode_or_die(const struct image_desc *d, uint32_t tx, uint32_t ty, int noise, size_t *size)
{
    char err[256] = "";
    struct imgio_encoder *e = imgio_encoder_new(d, err, sizeof err);
    cr_assert_not_null(e, "%s", err);
    float *in = make_tile(d, tx, ty, noise);
    uint8_t *chunk = NULL;
    cr_assert_eq(imgio_encode_tile(e, tx, ty, in, &chunk, size, err, sizeof err), 0, "%s", err);
    free(in);
    imgio_encoder_free(&e);
    return chunk;
}

Test(imgio, decode_rejects_malformed)
{
    const enum imgio_compression comps[] = {IMGIO_NONE, IMGIO_ZIP, IMGIO_PIZ};
    for (int i = 0; i < 3; i++) {
        char err[256] = "";
        struct image_desc d = make_desc(comps[i], 70, 45, 16);
        size_t size = 0;
        uint8_t *chunk = encode_or_die(&d, 1, 1, 0, &size);
        float *out = malloc(tile_floats(&d, 1, 1) * sizeof(float));

        /* Truncated, empty, NULL. */
        cr_assert_eq(imgio_decode_tile(&d, 1, 1, chunk, size - 1, out, err, sizeof err), -1, "comp %d", i);
        cr_assert(err[0] != '\0');
        cr_assert_eq(imgio_decode_tile(&d, 1, 1, chunk, size / 2, out, err, sizeof err), -1);
        cr_assert_eq(imgio_decode_tile(&d, 1, 1, chunk, 0, out, err, sizeof err), -1);
        cr_assert_eq(imgio_decode_tile(&d, 1, 1, NULL, size, out, err, sizeof err), -1);

        /* Oversized: trailing bytes after a valid chunk, or larger than any tile can be. */
        uint8_t *big = calloc(1, size + 4096 * 64);
        memcpy(big, chunk, size);
        /* OpenEXRCore's PIZ decoder stops once the tile is complete, so a few trailing bytes
         * after a PIZ chunk go unnoticed (the pixels are still fully checked); ZIP chunks
         * (inflated by imgio with libdeflate) must be consumed to the last byte, and
         * uncompressed chunks have an exact size. */
        int rc_trail = imgio_decode_tile(&d, 1, 1, big, size + 1, out, err, sizeof err);
        cr_assert(comps[i] == IMGIO_PIZ ? (rc_trail == 0 || rc_trail == -1) : rc_trail == -1, "comp %d", i);
        cr_assert_eq(imgio_decode_tile(&d, 1, 1, big, size + 4096 * 64, out, err, sizeof err), -1);
        free(big);

        /* Wrong tile coordinates: out of the grid, or a tile of another size. */
        cr_assert_eq(imgio_decode_tile(&d, 5, 1, chunk, size, out, err, sizeof err), -1);
        cr_assert_eq(imgio_decode_tile(&d, 1, 3, chunk, size, out, err, sizeof err), -1);
        cr_assert_eq(imgio_decode_tile(&d, UINT32_MAX, UINT32_MAX, chunk, size, out, err, sizeof err), -1);
        cr_assert_eq(imgio_decode_tile(&d, 4, 2, chunk, size, out, err, sizeof err), -1, "comp %d", i);

        /* Flipped bytes: either rejected or decoded into the buffer, never a crash
         * (ASan/UBSan builds check the "never"). */
        uint8_t *bad = malloc(size);
        for (size_t pos = 0; pos < size; pos += 1 + size / 97) {
            memcpy(bad, chunk, size);
            bad[pos] ^= 0xFF;
            int rc = imgio_decode_tile(&d, 1, 1, bad, size, out, err, sizeof err);
            cr_assert(rc == 0 || rc == -1);
        }
        free(bad);

        /* Garbage of a plausible compressed size. */
        if (comps[i] != IMGIO_NONE) {
            uint8_t *junk = malloc(size);
            uint32_t s = 12345u + (uint32_t)i;
            for (size_t k = 0; k < size; k++)
                junk[k] = (uint8_t)lcg(&s);
            cr_assert_eq(imgio_decode_tile(&d, 1, 1, junk, size, out, err, sizeof err), -1);
            free(junk);
        }

        /* The buffer still decodes after all that. */
        cr_assert_eq(imgio_decode_tile(&d, 1, 1, chunk, size, out, err, sizeof err), 0, "%s", err);
        free(out);
        free(chunk);
    }
}

/* Random mutations (flips, truncations, splices of random bytes) of valid chunks must never
 * crash, leak or touch memory outside the output buffer. */
Test(imgio, decode_fuzz_smoke)
{
    const enum imgio_compression comps[] = {IMGIO_NONE, IMGIO_ZIP, IMGIO_PIZ};
    uint32_t s = 99u;
    for (int i = 0; i < 3; i++) {
        char err[256];
        struct image_desc d = make_desc(comps[i], 70, 45, 16);
        for (int noise = 0; noise < 2; noise++) {
            size_t size = 0;
            uint8_t *chunk = encode_or_die(&d, 4, 2, noise, &size);
            size_t n = tile_floats(&d, 4, 2);
            float *out = malloc(n * sizeof(float));
            uint8_t *m = malloc(size);
            for (int iter = 0; iter < 150; iter++) {
                memcpy(m, chunk, size);
                size_t len = size;
                int kind = (int)(lcg(&s) % 3);
                int count = 1 + (int)(lcg(&s) % 8);
                for (int k = 0; k < count; k++) {
                    size_t pos = lcg(&s) % size;
                    if (kind == 0)
                        m[pos] ^= (uint8_t)(1u << (lcg(&s) % 8));
                    else
                        m[pos] = (uint8_t)lcg(&s);
                }
                if (kind == 2)
                    len = 1 + lcg(&s) % size;
                int rc = imgio_decode_tile(&d, 4, 2, m, len, out, err, sizeof err);
                cr_assert(rc == 0 || rc == -1);
            }
            free(m);
            free(out);
            free(chunk);
        }
    }
}

/* ------------------------------------------------------------------------------------- */

static int have_exrheader(void)
{
    return system("command -v exrheader >/dev/null 2>&1") == 0;
}

static char *run_capture(const char *cmd)
{
    FILE *p = popen(cmd, "r");
    cr_assert_not_null(p);
    size_t cap = 1 << 16, len = 0;
    char *buf = malloc(cap);
    size_t r;
    while (len < cap - 1 && (r = fread(buf + len, 1, cap - 1 - len, p)) > 0)
        len += r;
    buf[len] = '\0';
    pclose(p);
    return buf;
}

static void full_file_roundtrip(enum imgio_compression comp)
{
    char dir[64], path[128], err[512] = "";
    make_tmpdir(dir, sizeof dir);
    snprintf(path, sizeof path, "%s/frame.exr.tmp", dir);
    struct image_desc d = make_desc(comp, 70, 45, 16);
    uint32_t ntx = imgio_tiles_x(&d), nty = imgio_tiles_y(&d), nt = ntx * nty;

    /* Encode every tile (as workers would), then shuffle the arrival order. */
    uint8_t **chunks = calloc(nt, sizeof *chunks);
    size_t *sizes = calloc(nt, sizeof *sizes);
    uint32_t *order = calloc(nt, sizeof *order);
    struct imgio_encoder *e = imgio_encoder_new(&d, err, sizeof err);
    cr_assert_not_null(e, "%s", err);
    for (uint32_t t = 0; t < nt; t++) {
        float *in = make_tile(&d, t % ntx, t / ntx, 0);
        cr_assert_eq(imgio_encode_tile(e, t % ntx, t / ntx, in, &chunks[t], &sizes[t], err, sizeof err), 0,
                     "%s", err);
        free(in);
        order[t] = t;
    }
    imgio_encoder_free(&e);
    uint32_t s = 7u + (uint32_t)comp;
    for (uint32_t t = nt - 1; t > 0; t--) {
        uint32_t j = lcg(&s) % (t + 1), tmp = order[t];
        order[t] = order[j];
        order[j] = tmp;
    }

    struct image_attrs a;
    memset(&a, 0, sizeof a);
    a.spp = 1234;
    a.seed = 18446744073709551557ull;
    a.render_seconds = 12.5;
    snprintf(a.scene_hash, sizeof a.scene_hash, "%s", "0123456789abcdef0123456789abcdef0123456789abcdef0123456789abcdef");
    snprintf(a.software, sizeof a.software, "%s", "brume test");
    struct imgio_writer *w = imgio_writer_open(path, &d, &a, err, sizeof err);
    cr_assert_not_null(w, "%s", err);
    cr_assert_eq(imgio_writer_put_tile(w, ntx, 0, chunks[0], sizes[0], err, sizeof err), -1);
    cr_assert(strstr(err, path) != NULL, "%s", err);
    for (uint32_t k = 0; k < nt; k++) {
        uint32_t t = order[k];
        cr_assert_eq(imgio_writer_put_tile(w, t % ntx, t / ntx, chunks[t], sizes[t], err, sizeof err), 0, "%s",
                     err);
        if (k == 3) { /* a re-issued straggler arrives twice: skipped, and no tile is lost */
            cr_assert_eq(imgio_writer_put_tile(w, t % ntx, t / ntx, chunks[t], sizes[t], err, sizeof err), 0,
                         "%s", err);
        }
    }
    cr_assert_eq(imgio_writer_close(&w, err, sizeof err), 0, "%s", err);
    cr_assert_null(w);

    /* Read back in renderer order: bit-exact against the source image. */
    float *px = NULL;
    uint32_t rw = 0, rh = 0;
    cr_assert_eq(imgio_read(path, k_names, K_NC, &px, &rw, &rh, err, sizeof err), 0, "%s", err);
    cr_assert(rw == 70 && rh == 45);
    for (uint32_t y = 0; y < rh; y++)
        for (uint32_t x = 0; x < rw; x++)
            for (uint32_t c = 0; c < K_NC; c++) {
                float want = pixel_value(x, y, c, 0), got = px[((size_t)y * rw + x) * K_NC + c];
                cr_assert(memcmp(&want, &got, sizeof want) == 0, "pixel (%u,%u) ch %u: %g != %g", x, y, c,
                          (double)got, (double)want);
            }
    free(px);

    /* A subset of channels in another order. */
    const char *const sub[] = {"depth", "R"};
    cr_assert_eq(imgio_read(path, sub, 2, &px, &rw, &rh, err, sizeof err), 0, "%s", err);
    cr_assert_eq(px[(10 * 70 + 20) * 2 + 0], pixel_value(20, 10, 4, 0));
    cr_assert_eq(px[(10 * 70 + 20) * 2 + 1], pixel_value(20, 10, 0, 0));
    free(px);

    /* A missing channel is an error naming it. */
    const char *const missing[] = {"R", "nosuch"};
    px = (float *)1;
    cr_assert_eq(imgio_read(path, missing, 2, &px, &rw, &rh, err, sizeof err), -1);
    cr_assert(strstr(err, "nosuch") != NULL, "%s", err);
    cr_assert_null(px);

    if (have_exrheader()) {
        char cmd[256];
        snprintf(cmd, sizeof cmd, "exrheader '%s' 2>&1", path);
        char *outp = run_capture(cmd);
        cr_assert(strstr(outp, "tiledesc") != NULL, "%s", outp);
        cr_assert(strstr(outp, "tiledimage") != NULL, "%s", outp);
        cr_assert(strstr(outp, "brume_spp (type int): 1234") != NULL, "%s", outp);
        cr_assert(strstr(outp, "18446744073709551557") != NULL, "%s", outp);
        cr_assert(strstr(outp, "brume_render_seconds") != NULL, "%s", outp);
        cr_assert(strstr(outp, "0123456789abcdef0123456789abcdef") != NULL, "%s", outp);
        cr_assert(strstr(outp, "brume test") != NULL, "%s", outp);
        cr_assert(strstr(outp, "random y") != NULL, "%s", outp);
        free(outp);
    }
    if (system("command -v exrcheck >/dev/null 2>&1") == 0) {
        char cmd[256];
        snprintf(cmd, sizeof cmd, "exrcheck '%s' >/dev/null 2>&1", path);
        cr_assert_eq(system(cmd), 0, "exrcheck rejects %s", path);
    }
    /* ZIP chunks are deflated and inflated by libdeflate, not by OpenEXR's zlib: OpenEXR's
     * own C++ library (exrmaketiled, from openexr) rewrites our file uncompressed (its
     * decoder against our encoder) and as ZIP (then our decoder against its encoder), and
     * both read back bit-exact. */
    for (int z = 0; comp == IMGIO_ZIP && z < 2 && system("command -v exrmaketiled >/dev/null 2>&1") == 0; z++) {
        char cmd[512], path2[160];
        snprintf(path2, sizeof path2, "%s/remade.exr", dir);
        snprintf(cmd, sizeof cmd, "exrmaketiled -t 16 16 -z %s '%s' '%s' >/dev/null 2>&1", z ? "zip" : "none", path,
                 path2);
        cr_assert_eq(system(cmd), 0, "exrmaketiled cannot read %s", path);
        cr_assert_eq(imgio_read(path2, k_names, K_NC, &px, &rw, &rh, err, sizeof err), 0, "%s", err);
        cr_assert(rw == 70 && rh == 45);
        for (uint32_t i = 0; i < 70u * 45u * K_NC; i++) {
            float want = pixel_value(i / K_NC % 70, i / K_NC / 70, i % K_NC, 0);
            cr_assert(memcmp(&want, &px[i], sizeof want) == 0, "remade (%s) value %u: %g != %g", z ? "zip" : "none",
                      i, (double)px[i], (double)want);
        }
        free(px);
        unlink(path2);
    }

    for (uint32_t t = 0; t < nt; t++)
        free(chunks[t]);
    free(chunks);
    free(sizes);
    free(order);
    unlink(path);
    cr_assert_eq(rmdir(dir), 0);
}

Test(imgio, full_file_zip) { full_file_roundtrip(IMGIO_ZIP); }
Test(imgio, full_file_piz) { full_file_roundtrip(IMGIO_PIZ); }
Test(imgio, full_file_none) { full_file_roundtrip(IMGIO_NONE); }

Test(imgio, writer_errors_name_the_path)
{
    char err[512] = "";
    struct image_desc d = make_desc(IMGIO_ZIP, 70, 45, 16);
    struct image_attrs a;
    memset(&a, 0, sizeof a);
    const char *bad = "/nonexistent_brume_dir/x/frame.exr";
    cr_assert_null(imgio_writer_open(bad, &d, &a, err, sizeof err));
    cr_assert(strstr(err, bad) != NULL, "%s", err);

}

Test(imgio, writer_close_fails_on_missing_tile)
{
    char dir[64], path[128], err[512] = "";
    make_tmpdir(dir, sizeof dir);
    snprintf(path, sizeof path, "%s/partial.exr", dir);
    struct image_desc d = make_desc(IMGIO_ZIP, 40, 20, 16);
    struct image_attrs a;
    memset(&a, 0, sizeof a);
    struct imgio_writer *w = imgio_writer_open(path, &d, &a, err, sizeof err);
    cr_assert_not_null(w, "%s", err);
    size_t size = 0;
    uint8_t *chunk = encode_or_die(&d, 0, 0, 0, &size);
    cr_assert_eq(imgio_writer_put_tile(w, 0, 0, chunk, size, err, sizeof err), 0, "%s", err);
    cr_assert_eq(imgio_writer_put_tile(w, 1, 0, chunk, 0, err, sizeof err), -1);
    cr_assert_eq(imgio_writer_close(&w, err, sizeof err), -1);
    cr_assert_null(w);
    cr_assert(strstr(err, "missing") != NULL && strstr(err, path) != NULL, "%s", err);
    cr_assert_neq(access(path, F_OK), 0, "partial file left behind");
    free(chunk);
    cr_assert_eq(rmdir(dir), 0);
}

Test(imgio, read_errors)
{
    char dir[64], path[128], err[512] = "";
    make_tmpdir(dir, sizeof dir);
    float *px = NULL;
    uint32_t w, h;
    snprintf(path, sizeof path, "%s/missing.exr", dir);
    cr_assert_eq(imgio_read(path, k_names, 1, &px, &w, &h, err, sizeof err), -1);
    cr_assert(strstr(err, path) != NULL, "%s", err);

    snprintf(path, sizeof path, "%s/junk.exr", dir);
    FILE *f = fopen(path, "wb");
    cr_assert_not_null(f);
    fputs("v/1\001 this is not an EXR file at all, just text", f);
    fclose(f);
    cr_assert_eq(imgio_read(path, k_names, 1, &px, &w, &h, err, sizeof err), -1);
    cr_assert(strstr(err, path) != NULL, "%s", err);
    cr_assert_null(px);
    unlink(path);
    rmdir(dir);
}

/* A scanline file with HALF channels, ZIP (16 lines per chunk) and a data window that does
 * not start at the origin, written with OpenEXRCore directly: imgio_read must handle it. */
Test(imgio, read_scanline_half)
{
    char dir[64], path[128], err[512] = "";
    make_tmpdir(dir, sizeof dir);
    snprintf(path, sizeof path, "%s/half.exr", dir);
    const int W = 23, H = 37;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    exr_context_t ctx = NULL;
    cr_assert_eq(exr_start_write(&ctx, path, EXR_WRITE_FILE_DIRECTLY, &init), EXR_ERR_SUCCESS);
    int part = 0;
    cr_assert_eq(exr_add_part(ctx, NULL, EXR_STORAGE_SCANLINE, &part), EXR_ERR_SUCCESS);
    exr_attr_box2i_t dw;
    exr_attr_v2f_t swc;
    memset(&swc, 0, sizeof swc);
    dw.min.x = 3;
    dw.min.y = 5;
    dw.max.x = 3 + W - 1;
    dw.max.y = 5 + H - 1;
    cr_assert_eq(exr_initialize_required_attr(ctx, part, &dw, &dw, 1.f, &swc, 1.f, EXR_LINEORDER_INCREASING_Y,
                                              EXR_COMPRESSION_ZIP),
                 EXR_ERR_SUCCESS);
    const char *names[] = {"B", "G", "R"};
    for (int c = 0; c < 3; c++)
        cr_assert_geq(exr_add_channel(ctx, part, names[c], EXR_PIXEL_HALF, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1), 0);
    cr_assert_eq(exr_write_header(ctx), EXR_ERR_SUCCESS);
    /* Values exactly representable as half, so the comparison can be exact. */
    float *src = malloc(sizeof(float) * (size_t)W * H * 3);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < 3; c++)
                src[((size_t)y * W + x) * 3 + c] = (float)(x - 10) * 0.25f + (float)y * 8.0f + (float)c * 0.5f;
    int32_t lines = 0;
    cr_assert_eq(exr_get_scanlines_per_chunk(ctx, part, &lines), EXR_ERR_SUCCESS);
    for (int y = 0; y < H; y += lines) {
        exr_chunk_info_t ci;
        exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
        cr_assert_eq(exr_write_scanline_chunk_info(ctx, part, 5 + y, &ci), EXR_ERR_SUCCESS);
        cr_assert_eq(exr_encoding_initialize(ctx, part, &ci, &enc), EXR_ERR_SUCCESS);
        for (int i = 0; i < enc.channel_count; i++) {
            int c = strcmp(enc.channels[i].channel_name, "R") == 0 ? 0
                    : strcmp(enc.channels[i].channel_name, "G") == 0 ? 1 : 2;
            enc.channels[i].user_bytes_per_element = 4;
            enc.channels[i].user_data_type = EXR_PIXEL_FLOAT;
            enc.channels[i].user_pixel_stride = 12;
            enc.channels[i].user_line_stride = 12 * W;
            enc.channels[i].encode_from_ptr = (const uint8_t *)(src + (size_t)y * W * 3 + c);
        }
        cr_assert_eq(exr_encoding_choose_default_routines(ctx, part, &enc), EXR_ERR_SUCCESS);
        cr_assert_eq(exr_encoding_run(ctx, part, &enc), EXR_ERR_SUCCESS);
        exr_encoding_destroy(ctx, &enc);
    }
    cr_assert_eq(exr_finish(&ctx), EXR_ERR_SUCCESS);

    const char *const want[] = {"R", "G", "B"};
    float *px = NULL;
    uint32_t w = 0, h = 0;
    cr_assert_eq(imgio_read(path, want, 3, &px, &w, &h, err, sizeof err), 0, "%s", err);
    cr_assert(w == (uint32_t)W && h == (uint32_t)H);
    cr_assert_eq(memcmp(px, src, sizeof(float) * (size_t)W * H * 3), 0);
    free(px);
    free(src);
    unlink(path);
    rmdir(dir);
}

/* ------------------------------------------------------------------------------------- */

Test(imgio, png_preview)
{
    char dir[64], path[128], tmp[160], err[512] = "";
    make_tmpdir(dir, sizeof dir);
    snprintf(path, sizeof path, "%s/preview.png", dir);
    const uint32_t W = 5, H = 2, stride = 4;
    const float vals[5] = {0.0f, 0.5f, 1.0f, 2.0f, -1.0f};
    const uint8_t expect[5] = {0, 188, 255, 255, 0}; /* sRGB(0.5) = 0.7354 */
    float px[5 * 2 * 4];
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++)
            for (uint32_t c = 0; c < stride; c++)
                px[(y * W + x) * stride + c] = c == 3 ? 123.0f : vals[x] * 0.5f; /* exposure 2 undoes 0.5 */
    px[(1 * W + 0) * stride + 1] = NAN;
    cr_assert_eq(imgio_write_png(path, px, W, H, stride, 2.0f, err, sizeof err), 0, "%s", err);
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    cr_assert_neq(access(tmp, F_OK), 0, "temporary file left behind");

    FILE *f = fopen(path, "rb");
    cr_assert_not_null(f);
    uint8_t sig[8];
    cr_assert_eq(fread(sig, 1, 8, f), 8);
    fclose(f);
    static const uint8_t png_sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    cr_assert_eq(memcmp(sig, png_sig, 8), 0);

    png_image img;
    memset(&img, 0, sizeof img);
    img.version = PNG_IMAGE_VERSION;
    cr_assert(png_image_begin_read_from_file(&img, path));
    img.format = PNG_FORMAT_RGB;
    uint8_t rgb[5 * 2 * 3];
    cr_assert_eq(PNG_IMAGE_SIZE(img), sizeof rgb);
    cr_assert(png_image_finish_read(&img, NULL, rgb, 0, NULL));
    for (uint32_t x = 0; x < W; x++)
        for (uint32_t c = 0; c < 3; c++)
            cr_assert_eq(rgb[x * 3 + c], expect[x], "x %u c %u: %u", x, c, rgb[x * 3 + c]);
    cr_assert_eq(rgb[(1 * W + 0) * 3 + 1], 0, "NaN must map to black");

    char badpath[160];
    snprintf(badpath, sizeof badpath, "%s/no/such/dir.png", dir);
    cr_assert_eq(imgio_write_png(badpath, px, W, H, stride, 1.0f, err, sizeof err), -1);
    cr_assert(strstr(err, badpath) != NULL, "%s", err);
    cr_assert_eq(imgio_write_png(path, px, W, H, 2, 1.0f, err, sizeof err), -1); /* stride < 3 */

    unlink(path);
    cr_assert_eq(rmdir(dir), 0);
}

/* Tile (0,0) of d encoded from px (returned, its size in *size) and decoded into out. */
static uint8_t *round_trip_tile00(const struct image_desc *d, const float *px, float *out, size_t *size)
{
    char err[256];
    struct imgio_encoder *e = imgio_encoder_new(d, err, sizeof err);
    cr_assert_not_null(e, "%s", err);
    uint8_t *chunk;
    cr_assert_eq(imgio_encode_tile(e, 0, 0, px, &chunk, size, err, sizeof err), 0, "%s", err);
    imgio_encoder_free(&e);
    cr_assert_eq(imgio_decode_tile(d, 0, 0, chunk, *size, out, err, sizeof err), 0, "%s", err);
    return chunk;
}

/* HALF channels (image_desc.half_mask): the chunk rounds to the nearest half (ties to
 * even, overflow to infinity, subnormals), decodes back exactly, and a file of such
 * chunks reads the same through OpenEXRCore's own unpacking (imgio_read) as through the
 * tile decoder's. */
Test(imgio, half_channels_round_to_nearest_even)
{
    struct image_desc d = make_desc(IMGIO_ZIP, 8, 4, 8);
    d.half_mask = 1u << 5 | 1u << 1; /* albedo.r and G */
    static const float in[][2] = {
        {0.1f, 0.0999755859375f},  {1.0f / 3.0f, 0.333251953125f}, {65504.0f, 65504.0f},
        {65519.99f, 65504.0f},     {65520.0f, INFINITY},           {-1e9f, -INFINITY},
        {0x1p-24f, 0x1p-24f},      {0x1p-25f, 0.0f},               {0x1.8p-25f, 0x1p-24f},
        {0x1.8p-24f, 0x1p-23f},    {0x1.002p+0f, 1.0f},            {0x1.006p+0f, 0x1.008p+0f},
        {-2.0f, -2.0f},            {0x1p-14f, 0x1p-14f},           {0x1.ffcp-15f, 0x1p-14f},
        {-0.0f, -0.0f},            {0x1.0p-20f, 0x1.0p-20f},       {3.14159265f, 3.140625f},
    };
    const size_t n = sizeof in / sizeof in[0];
    float px[8 * 4 * K_NC], out[8 * 4 * K_NC];
    for (size_t i = 0; i < 8 * 4; i++)
        for (uint32_t c = 0; c < K_NC; c++)
            px[i * K_NC + c] = (c == 5 || c == 1) ? in[i % n][0] : pixel_value((uint32_t)i % 8, (uint32_t)i / 8, c, 1);
    char err[256];
    size_t size;
    uint8_t *chunk = round_trip_tile00(&d, px, out, &size);
    for (size_t i = 0; i < 8 * 4; i++)
        for (uint32_t c = 0; c < K_NC; c++) {
            float want = (c == 5 || c == 1) ? in[i % n][1] : px[i * K_NC + c], got = out[i * K_NC + c];
            cr_assert(memcmp(&want, &got, 4) == 0, "pixel %zu ch %u: %a from %a, want %a", i, c, (double)got,
                      (double)px[i * K_NC + c], (double)want);
        }
    /* Written as a file and read back by the library's unpacking: the same floats. */
    char path[] = "/tmp/brume_half_XXXXXX";
    int fd = mkstemp(path);
    cr_assert(fd >= 0);
    close(fd);
    struct image_attrs a;
    memset(&a, 0, sizeof a);
    struct imgio_writer *w = imgio_writer_open(path, &d, &a, err, sizeof err);
    cr_assert_not_null(w, "%s", err);
    cr_assert_eq(imgio_writer_put_tile(w, 0, 0, chunk, size, err, sizeof err), 0, "%s", err);
    cr_assert_eq(imgio_writer_close(&w, err, sizeof err), 0, "%s", err);
    float *rd = NULL;
    uint32_t rw, rh;
    cr_assert_eq(imgio_read(path, k_names, K_NC, &rd, &rw, &rh, err, sizeof err), 0, "%s", err);
    cr_assert(rw == 8 && rh == 4);
    cr_assert(memcmp(rd, out, sizeof out) == 0, "library unpacking differs from the tile decoder's");
    free(rd);
    unlink(path);
    free(chunk);
    /* A half_mask naming a channel past num_channels is refused. */
    d.half_mask = 1u << K_NC;
    cr_assert_null(imgio_encoder_new(&d, err, sizeof err));
}

/* The nearest half to f, ties to even, from its value (in double, independent of bit
 * tricks): f scaled to 11 significant bits (10 below 2^-14, where halves are subnormal),
 * rounded with nearbyint; 65520 and beyond round to infinity. */
static float half_reference(float f)
{
    if (isnan(f) || fabsf(f) >= 65520.0f)
        return isnan(f) ? f : copysignf(INFINITY, f);
    if (f == 0.0f)
        return f;
    int e = ilogbf(f);
    if (e < -14)
        e = -14;
    double r = nearbyint(ldexp((double)f, 10 - e));
    return (float)copysign(ldexp(r, e - 10), (double)f);
}

/* Every HALF bit pattern decodes to its exact value and encodes back to itself (NaNs stay
 * NaNs of their sign), and floats across the whole half range (normal, subnormal, ties,
 * overflow) round as half_reference says, in a chunk that mixes HALF and FLOAT channels. */
Test(imgio, half_conversion_exhaustive)
{
    const uint32_t W = 255, H = 258; /* 65536 pixels and more, rows not a multiple of 4 */
    struct image_desc d = make_desc(IMGIO_ZIP, W, H, 258);
    d.half_mask = 1u << 2 | 1u << 4;
    float *px = malloc(sizeof(float) * W * H * K_NC), *out = malloc(sizeof(float) * W * H * K_NC);
    cr_assert(px && out);
    uint32_t s = 7;
    for (uint32_t i = 0; i < W * H; i++) {
        /* Channel 2: the value of half bits i (sign, 5 exponent and 10 mantissa bits). */
        uint32_t e = i >> 10 & 0x1fu, m = i & 0x3ffu; /* i & 0xffff: every pattern at least once */
        float v = e == 0x1fu ? (m ? NAN : INFINITY)
                  : e        ? ldexpf(1.0f + m / 1024.0f, (int)e - 15)
                             : ldexpf((float)m, -24);
        px[i * K_NC + 2] = (i & 0x8000u) && !(i & 0x10000u) ? -v : v;
        /* Channel 4: floats spread over 0 .. 2^17, both signs, ties included. */
        uint32_t bits = 0x33000000u + (uint32_t)(((uint64_t)i * 0x14800000u) >> 16);
        if (i % 7 == 3)
            bits = (bits & ~0x1fffu) | 0x1000u; /* a tie between two normal halves */
        bits |= (lcg(&s) & 1u) << 31;
        memcpy(&px[i * K_NC + 4], &bits, 4);
        for (uint32_t c = 0; c < K_NC; c++)
            if (c != 2 && c != 4)
                px[i * K_NC + c] = pixel_value(i % W, i / W, c, 3);
    }
    size_t size;
    uint8_t *chunk = round_trip_tile00(&d, px, out, &size);
    for (uint32_t i = 0; i < W * H; i++)
        for (uint32_t c = 0; c < K_NC; c++) {
            float in = px[i * K_NC + c], got = out[i * K_NC + c];
            float want = c == 2 ? in : c == 4 ? half_reference(in) : in;
            if (isnan(want))
                cr_assert(isnan(got) && signbit(got) == signbit(want), "pixel %u ch %u: NaN became %a", i, c,
                          (double)got);
            else
                cr_assert(memcmp(&want, &got, 4) == 0, "pixel %u ch %u: %a from %a, want %a", i, c, (double)got,
                          (double)in, (double)want);
        }
    free(chunk);
    free(px);
    free(out);
}
