/* Radiance RGBE decoding (see hdr.h). A texel (R, G, B, E) is C * 2^(E - 136) per
 * channel, 0 when E is 0 (stb_image_write's convention, so files round-trip exactly). */
#include "image/hdr.h"
#include "base/log.h"
#include "image/mip.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct hdr_reader {
    const uint8_t *d;
    size_t n, i;
};

/* The next header line (without '\n') into buf; 0 at the end of the data. */
static int next_line(struct hdr_reader *r, char *buf, size_t cap)
{
    if (r->i >= r->n)
        return 0;
    size_t o = 0;
    while (r->i < r->n && r->d[r->i] != '\n') {
        if (o + 1 < cap)
            buf[o++] = (char)r->d[r->i];
        r->i++;
    }
    if (r->i < r->n)
        r->i++;
    buf[o] = '\0';
    return 1;
}

static void rgbe_to_float(const uint8_t *p, float *out)
{
    if (p[3] == 0) {
        out[0] = out[1] = out[2] = 0.0f;
        return;
    }
    float f = ldexpf(1.0f, (int)p[3] - 136);
    out[0] = (float)p[0] * f;
    out[1] = (float)p[1] * f;
    out[2] = (float)p[2] * f;
}

/* One scanline of w pixels into line (4 bytes each). Returns 0 or -1 (message in why). */
static int read_scanline(struct hdr_reader *r, uint32_t w, uint8_t *line, const char **why)
{
    if (r->n - r->i < 4) {
        *why = "truncated pixel data";
        return -1;
    }
    const uint8_t *q = r->d + r->i;
    if (w >= 8 && w <= 0x7fff && q[0] == 2 && q[1] == 2 && !(q[2] & 0x80)) {
        if (((uint32_t)q[2] << 8 | q[3]) != w) {
            *why = "run-length scanline of the wrong width";
            return -1;
        }
        r->i += 4;
        for (int c = 0; c < 4; c++) {
            uint32_t x = 0;
            while (x < w) {
                if (r->i >= r->n) {
                    *why = "truncated run-length data";
                    return -1;
                }
                uint32_t count = r->d[r->i++];
                if (count > 128) {
                    count -= 128;
                    if (count > w - x || r->i >= r->n) {
                        *why = count > w - x ? "run past the end of a scanline" : "truncated run-length data";
                        return -1;
                    }
                    uint8_t v = r->d[r->i++];
                    for (uint32_t k = 0; k < count; k++)
                        line[4 * (x + k) + c] = v;
                } else {
                    if (count == 0 || count > w - x || count > r->n - r->i) {
                        *why = count == 0 ? "empty run" : (count > w - x ? "run past the end of a scanline"
                                                                         : "truncated run-length data");
                        return -1;
                    }
                    for (uint32_t k = 0; k < count; k++)
                        line[4 * (x + k) + c] = r->d[r->i++];
                }
                x += count;
            }
        }
        return 0;
    }
    /* Flat pixels, with old-style runs: (1, 1, 1, n) repeats the previous pixel n << shift times. */
    uint32_t x = 0, shift = 0;
    while (x < w) {
        if (r->n - r->i < 4) {
            *why = "truncated pixel data";
            return -1;
        }
        const uint8_t *p = r->d + r->i;
        r->i += 4;
        if (p[0] == 1 && p[1] == 1 && p[2] == 1) {
            if (x == 0 || shift > 24) {
                *why = "old-style run without a pixel to repeat";
                return -1;
            }
            uint64_t count = (uint64_t)p[3] << shift;
            if (count > w - x) {
                *why = "run past the end of a scanline";
                return -1;
            }
            for (uint32_t k = 0; k < count; k++)
                memcpy(&line[4 * (x + k)], &line[4 * (x - 1)], 4);
            x += (uint32_t)count;
            shift += 8;
            continue;
        }
        memcpy(&line[4 * x], p, 4);
        x++;
        shift = 0;
    }
    return 0;
}

int hdr_decode(const char *name, const uint8_t *data, size_t size, float **rgb, uint32_t *width,
               uint32_t *height, char *err, size_t errlen)
{
    *rgb = NULL;
    *width = *height = 0;
    struct hdr_reader r = {data, size, 0};
    char line[256];
    if (!next_line(&r, line, sizeof line) || (strncmp(line, "#?RADIANCE", 10) != 0 && strncmp(line, "#?RGBE", 6) != 0)) {
        str_fmt(err, errlen, "%s: not a Radiance HDR file", name);
        return -1;
    }
    for (;;) {
        if (!next_line(&r, line, sizeof line)) {
            str_fmt(err, errlen, "%s: header without an end", name);
            return -1;
        }
        if (line[0] == '\0')
            break;
        if (strncmp(line, "FORMAT=", 7) == 0 && strcmp(line + 7, "32-bit_rle_rgbe") != 0) {
            str_fmt(err, errlen, "%s: unsupported format \"%.40s\" (only 32-bit_rle_rgbe)", name, line + 7);
            return -1;
        }
    }
    if (!next_line(&r, line, sizeof line)) {
        str_fmt(err, errlen, "%s: no resolution line", name);
        return -1;
    }
    char ys = 0, xs = 0, extra = 0;
    long h = 0, w = 0;
    if (sscanf(line, "%cY %ld %cX %ld %c", &ys, &h, &xs, &w, &extra) != 4 || (ys != '-' && ys != '+') || xs != '+' ||
        h < 1 || w < 1 || h > MIP_MAX_DIM || w > MIP_MAX_DIM) {
        str_fmt(err, errlen, "%s: unsupported resolution line \"%.40s\" (need -Y H +X W, each 1..%d)", name, line,
                MIP_MAX_DIM);
        return -1;
    }
    size_t n = (size_t)w * (size_t)h;
    /* Every scanline takes at least 4 bytes: refuse a size the data cannot hold before
     * allocating for it. */
    if ((size_t)h * 4 > size - r.i) {
        str_fmt(err, errlen, "%s: %ld scanlines cannot fit in %zu bytes", name, h, size - r.i);
        return -1;
    }
    float *out = mem_alloc(n * 3 * sizeof *out);
    uint8_t *sl = mem_alloc((size_t)w * 4);
    for (long y = 0; y < h; y++) {
        const char *why = NULL;
        if (read_scanline(&r, (uint32_t)w, sl, &why) != 0) {
            str_fmt(err, errlen, "%s: scanline %ld: %s", name, y, why);
            free(sl);
            free(out);
            return -1;
        }
        long row = ys == '-' ? y : h - 1 - y;
        for (long x = 0; x < w; x++)
            rgbe_to_float(&sl[4 * x], &out[((size_t)row * (size_t)w + (size_t)x) * 3]);
    }
    free(sl);
    *rgb = out;
    *width = (uint32_t)w;
    *height = (uint32_t)h;
    return 0;
}
