/* codecbench: the cost of each OpenEXRCore codec on render tiles (docs/benchmarks.md).
 *   codecbench IMAGE.exr [REPS] [TILE]
 * Cuts the image's beauty channels (R, G, B, A, variance.R/G/B, as a worker sends them)
 * into TILE x TILE tiles (32), encodes each as a worker does and decodes it as the
 * master's check does, REPS times (3), with every codec imgio offers; checks the round
 * trip is lossless and prints CPU ns per pixel for each side and bytes per pixel. */
#include "image/imgio.h"
#include "render/tile.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double cpu_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

int main(int argc, char **argv)
{
    if (argc < 2 || argc > 4) {
        fprintf(stderr, "usage: codecbench IMAGE.exr [REPS] [TILE]\n");
        return 2;
    }
    const int reps = argc > 2 ? atoi(argv[2]) : 3;
    const uint32_t ts = argc > 3 ? (uint32_t)atoi(argv[3]) : 32;
    const uint32_t nc = TILE_NUM_CHANNELS;
    float *px;
    uint32_t w, h;
    char err[256];
    if (reps < 1 || ts < 1 || ts > 256 ||
        imgio_read(argv[1], tile_channel_names, nc, &px, &w, &h, err, sizeof err) != 0) {
        fprintf(stderr, "codecbench: %s\n", reps < 1 || ts < 1 || ts > 256 ? "bad REPS or TILE" : err);
        return 1;
    }
    if (w < ts || h < ts) {
        fprintf(stderr, "codecbench: %s is smaller than one %u px tile\n", argv[1], ts);
        return 1;
    }
    static const struct { enum imgio_compression c; const char *name; } codecs[] = {
        {IMGIO_NONE, "NONE"}, {IMGIO_RLE, "RLE"}, {IMGIO_ZIPS, "ZIPS"}, {IMGIO_ZIP, "ZIP"}, {IMGIO_PIZ, "PIZ"}};
    float *tile = malloc(sizeof(float) * ts * ts * nc), *back = malloc(sizeof(float) * ts * ts * nc);
    printf("%ux%u px in %ux%u tiles of %u px, %u channels (%u bytes/px raw), %d reps\n", w, h, w / ts, h / ts, ts, nc,
           4 * nc, reps);
    printf("%-6s %16s %16s %12s\n", "codec", "encode ns/px", "decode ns/px", "bytes/px");
    for (size_t c = 0; c < sizeof codecs / sizeof codecs[0]; c++) {
        struct render_settings rs;
        memset(&rs, 0, sizeof rs);
        rs.width = w;
        rs.height = h;
        rs.tile_size = ts;
        struct image_desc d;
        tile_image_desc(&d, &rs); /* a worker's frame description, without AOVs */
        d.compression = codecs[c].c;
        struct imgio_encoder *e = imgio_encoder_new(&d, err, sizeof err);
        if (!e) {
            fprintf(stderr, "codecbench: %s\n", err);
            return 1;
        }
        double t_enc = 0.0, t_dec = 0.0, bytes = 0.0, pixels = 0.0;
        for (int r = 0; r < reps; r++)
            for (uint32_t ty = 0; ty < h / ts; ty++)
                for (uint32_t tx = 0; tx < w / ts; tx++) {
                    for (uint32_t y = 0; y < ts; y++)
                        memcpy(&tile[(size_t)y * ts * nc], &px[((size_t)(ty * ts + y) * w + tx * ts) * nc],
                               sizeof(float) * ts * nc);
                    uint8_t *chunk;
                    size_t n;
                    double t0 = cpu_s();
                    if (imgio_encode_tile(e, tx, ty, tile, &chunk, &n, err, sizeof err) != 0) {
                        fprintf(stderr, "codecbench: %s: %s\n", codecs[c].name, err);
                        return 1;
                    }
                    double t1 = cpu_s();
                    if (imgio_decode_tile(&d, tx, ty, chunk, n, back, err, sizeof err) != 0) {
                        fprintf(stderr, "codecbench: %s: %s\n", codecs[c].name, err);
                        return 1;
                    }
                    t_enc += t1 - t0;
                    t_dec += cpu_s() - t1;
                    bytes += (double)n;
                    pixels += (double)ts * ts;
                    free(chunk);
                    if (memcmp(tile, back, sizeof(float) * ts * ts * nc) != 0) {
                        fprintf(stderr, "codecbench: %s: tile (%u, %u) does not round-trip\n", codecs[c].name, tx, ty);
                        return 1;
                    }
                }
        printf("%-6s %16.1f %16.1f %12.2f\n", codecs[c].name, 1e9 * t_enc / pixels, 1e9 * t_dec / pixels,
               bytes / pixels);
        imgio_encoder_free(&e);
    }
    free(tile);
    free(back);
    free(px);
    return 0;
}
