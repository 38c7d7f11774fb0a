/* maketex: writes the procedural texture images the shipped scenes and benchmarks use
 * (no downloads: every texel is computed here), one file per format the renderer reads.
 *   maketex DIR    writes DIR/checker.png, DIR/globe.png, DIR/bricks.jpg, DIR/sky.hdr,
 *                  DIR/tiles.exr
 * PNG, JPEG and HDR through stb_image_write (libstb), EXR through imgio (OpenEXRCore). */
#include "image/imgio.h"
#include "base/log.h"
#include "image/mip.h"
#include <math.h>
#include <stb/stb_image_write.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static unsigned char enc(float linear)
{
    float c = mip_linear_to_srgb(linear < 0.0f ? 0.0f : (linear > 1.0f ? 1.0f : linear));
    return (unsigned char)lrintf(c * 255.0f);
}

static int write_exr(const char *path, const float *rgb, uint32_t w, uint32_t h)
{
    struct image_desc d;
    memset(&d, 0, sizeof d);
    d.width = w, d.height = h, d.tile_size = 64, d.num_channels = 3, d.compression = IMGIO_ZIP;
    strcpy(d.channel_names[0], "R");
    strcpy(d.channel_names[1], "G");
    strcpy(d.channel_names[2], "B");
    struct image_attrs a;
    memset(&a, 0, sizeof a);
    strcpy(a.software, "brume maketex");
    char err[512];
    struct imgio_encoder *e = imgio_encoder_new(&d, err, sizeof err);
    struct imgio_writer *wr = e ? imgio_writer_open(path, &d, &a, err, sizeof err) : NULL;
    if (!wr) {
        fprintf(stderr, "maketex: %s\n", err);
        return -1;
    }
    float *tile = mem_alloc(64 * 64 * 3 * sizeof *tile);
    for (uint32_t ty = 0; ty < imgio_tiles_y(&d); ty++)
        for (uint32_t tx = 0; tx < imgio_tiles_x(&d); tx++) {
            uint32_t x0, y0, tw, th;
            imgio_tile_rect(&d, tx, ty, &x0, &y0, &tw, &th);
            for (uint32_t y = 0; y < th; y++)
                memcpy(&tile[(size_t)y * tw * 3], &rgb[((size_t)(y0 + y) * w + x0) * 3], tw * 3 * sizeof(float));
            uint8_t *chunk = NULL;
            size_t n = 0;
            if (imgio_encode_tile(e, tx, ty, tile, &chunk, &n, err, sizeof err) != 0 ||
                imgio_writer_put_tile(wr, tx, ty, chunk, n, err, sizeof err) != 0) {
                fprintf(stderr, "maketex: %s\n", err);
                return -1;
            }
            free(chunk);
        }
    free(tile);
    imgio_encoder_free(&e);
    if (imgio_writer_close(&wr, err, sizeof err) != 0) {
        fprintf(stderr, "maketex: %s\n", err);
        return -1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: maketex DIR\n");
        return 2;
    }
    char path[4096];
    int ok = 1;
    /* checker.png: 512x512, 8x8 squares, high contrast (the floor to the horizon). */
    {
        uint32_t n = 512;
        unsigned char *px = mem_alloc((size_t)n * n * 3);
        for (uint32_t y = 0; y < n; y++)
            for (uint32_t x = 0; x < n; x++) {
                int odd = ((x / 64) + (y / 64)) & 1;
                unsigned char *p = &px[((size_t)y * n + x) * 3];
                p[0] = enc(odd ? 0.05f : 0.85f);
                p[1] = enc(odd ? 0.05f : 0.80f);
                p[2] = enc(odd ? 0.08f : 0.70f);
            }
        snprintf(path, sizeof path, "%s/checker.png", argv[1]);
        ok &= stbi_write_png(path, (int)n, (int)n, 3, px, (int)n * 3) != 0;
        free(px);
    }
    /* globe.png: 512x256 latitude-longitude grid with coloured bands (spheres). */
    {
        uint32_t w = 512, h = 256;
        unsigned char *px = mem_alloc((size_t)w * h * 3);
        for (uint32_t y = 0; y < h; y++)
            for (uint32_t x = 0; x < w; x++) {
                float u = (x + 0.5f) / w, v = (y + 0.5f) / h;
                int line = (x % 32) < 2 || (y % 32) < 2;
                float r = 0.5f + 0.45f * sinf(6.2831853f * u), g = 0.3f + 0.6f * v, b = 0.8f - 0.6f * v;
                if (((x / 16) + (y / 16)) & 1)
                    r *= 0.6f, g *= 0.6f, b *= 0.6f;
                unsigned char *p = &px[((size_t)y * w + x) * 3];
                p[0] = enc(line ? 0.95f : r);
                p[1] = enc(line ? 0.95f : g);
                p[2] = enc(line ? 0.95f : b);
            }
        snprintf(path, sizeof path, "%s/globe.png", argv[1]);
        ok &= stbi_write_png(path, (int)w, (int)h, 3, px, (int)w * 3) != 0;
        free(px);
    }
    /* bricks.jpg: 256x256 bricks with mortar. */
    {
        uint32_t n = 256;
        unsigned char *px = mem_alloc((size_t)n * n * 3);
        for (uint32_t y = 0; y < n; y++)
            for (uint32_t x = 0; x < n; x++) {
                uint32_t row = y / 32, xs = x + (row & 1) * 32;
                int mortar = (y % 32) < 3 || (xs % 64) < 3;
                float shade = 0.75f + 0.25f * (float)((xs / 64 * 7 + row * 13) % 5) / 4.0f;
                unsigned char *p = &px[((size_t)y * n + x) * 3];
                p[0] = enc(mortar ? 0.7f : 0.55f * shade);
                p[1] = enc(mortar ? 0.7f : 0.18f * shade);
                p[2] = enc(mortar ? 0.65f : 0.10f * shade);
            }
        snprintf(path, sizeof path, "%s/bricks.jpg", argv[1]);
        ok &= stbi_write_jpg(path, (int)n, (int)n, 3, px, 92) != 0;
        free(px);
    }
    /* sky.hdr: 256x128 float stripes (Radiance RGBE). */
    {
        uint32_t w = 256, h = 128;
        float *px = mem_alloc((size_t)w * h * 3 * sizeof *px);
        for (uint32_t y = 0; y < h; y++)
            for (uint32_t x = 0; x < w; x++) {
                float *p = &px[((size_t)y * w + x) * 3];
                int stripe = ((x + y) / 16) & 1;
                p[0] = stripe ? 0.9f : 0.1f;
                p[1] = stripe ? 0.6f : 0.2f;
                p[2] = stripe ? 0.1f : 0.7f;
            }
        snprintf(path, sizeof path, "%s/sky.hdr", argv[1]);
        ok &= stbi_write_hdr(path, (int)w, (int)h, 3, px) != 0;
        free(px);
    }
    /* tiles.exr: 128x128 float tiles (OpenEXR). */
    {
        uint32_t n = 128;
        float *px = mem_alloc((size_t)n * n * 3 * sizeof *px);
        for (uint32_t y = 0; y < n; y++)
            for (uint32_t x = 0; x < n; x++) {
                float *p = &px[((size_t)y * n + x) * 3];
                int edge = (x % 32) < 2 || (y % 32) < 2;
                p[0] = edge ? 0.1f : 0.2f + 0.6f * (float)(x / 32) / 3.0f;
                p[1] = edge ? 0.1f : 0.7f;
                p[2] = edge ? 0.1f : 0.2f + 0.6f * (float)(y / 32) / 3.0f;
            }
        snprintf(path, sizeof path, "%s/tiles.exr", argv[1]);
        ok &= write_exr(path, px, n, n) == 0;
        free(px);
    }
    if (!ok) {
        fprintf(stderr, "maketex: could not write every image into %s\n", argv[1]);
        return 1;
    }
    return 0;
}
