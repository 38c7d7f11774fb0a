/* Texture image decoding (see image_load.h). stb_image is used from Debian's shared
 * libstb (no implementation compiled here). Its failure reason is a global string, which
 * is fine: scenes are parsed by one thread. */
#include "image/image_load.h"
#include "image/hdr.h"
#include "image/imgio.h"
#include "base/log.h"
#include <limits.h>
#include <math.h>
#include <stb/stb_image.h>
#include <stdlib.h>
#include <string.h>

static int has_prefix(const uint8_t *d, size_t n, const char *p, size_t pn)
{
    return n >= pn && memcmp(d, p, pn) == 0;
}

static int load_exr(const char *name, const uint8_t *data, size_t size, struct tex_image *out, char *err,
                    size_t errlen)
{
    static const char *const rgb[] = {"R", "G", "B"}, *const gray[] = {"Y"};
    float *px = NULL;
    uint32_t w = 0, h = 0, nc = 3;
    char e1[512];
    if (imgio_read_memory(name, data, size, rgb, 3, MIP_MAX_DIM, &px, &w, &h, e1, sizeof e1) != 0) {
        if (!strstr(e1, ": no channel \"")) { /* damaged or too large: a gray read fails the same way */
            str_fmt(err, errlen, "%s", e1);
            return -1;
        }
        char e2[512];
        nc = 1;
        if (imgio_read_memory(name, data, size, gray, 1, MIP_MAX_DIM, &px, &w, &h, e2, sizeof e2) != 0) {
            str_fmt(err, errlen, "%s (and no Y channel either)", e1);
            return -1;
        }
    }
    if (tex_image_bytes(w, h, nc, TEXEL_F32) == 0) {
        free(px);
        str_fmt(err, errlen, "%s: image size %ux%u not supported (each side 1..%d)", name, w, h, MIP_MAX_DIM);
        return -1;
    }
    size_t n = (size_t)w * h * nc;
    for (size_t i = 0; i < n; i++) /* negative and NaN to 0, +Inf to the half maximum */
        px[i] = !(px[i] >= 0.0f) ? 0.0f : (isfinite(px[i]) ? px[i] : 65504.0f);
    out->width = w;
    out->height = h;
    out->channels = nc;
    out->format = TEXEL_F32;
    out->data = px;
    return 0;
}

int image_load_memory(const char *name, const uint8_t *data, size_t size, int srgb, struct tex_image *out,
                      char *err, size_t errlen)
{
    memset(out, 0, sizeof *out);
    if (has_prefix(data, size, "\x76\x2f\x31\x01", 4))
        return load_exr(name, data, size, out, err, errlen);
    if (has_prefix(data, size, "#?RADIANCE", 10) || has_prefix(data, size, "#?RGBE", 6)) {
        float *px = NULL;
        uint32_t w = 0, h = 0;
        if (hdr_decode(name, data, size, &px, &w, &h, err, errlen) != 0)
            return -1;
        out->width = w, out->height = h, out->channels = 3, out->format = TEXEL_F32, out->data = px;
        return 0;
    }
    int known = has_prefix(data, size, "\x89PNG\r\n\x1a\n", 8) || has_prefix(data, size, "\xff\xd8\xff", 3);
    if (!known) {
        str_fmt(err, errlen, "%s: not a PNG, JPEG, Radiance HDR or OpenEXR image", name);
        return -1;
    }
    if (size > INT_MAX) {
        str_fmt(err, errlen, "%s: file too large", name);
        return -1;
    }
    int w = 0, h = 0, comp = 0;
    if (!stbi_info_from_memory(data, (int)size, &w, &h, &comp)) {
        str_fmt(err, errlen, "%s: cannot read the image header: %s", name, stbi_failure_reason());
        return -1;
    }
    uint32_t nc = comp >= 3 ? 3 : 1;
    if (w <= 0 || h <= 0 || comp < 1 || comp > 4 || tex_image_bytes((uint32_t)w, (uint32_t)h, nc, TEXEL_F32) == 0) {
        str_fmt(err, errlen, "%s: image size %dx%d not supported (each side 1..%d)", name, w, h, MIP_MAX_DIM);
        return -1;
    }
    int dw = 0, dh = 0, dc = 0;
    if (stbi_is_16_bit_from_memory(data, (int)size)) {
        float *px = NULL;
        {
            uint16_t *p16 = stbi_load_16_from_memory(data, (int)size, &dw, &dh, &dc, (int)nc);
            if (p16 && dw == w && dh == h) {
                px = malloc((size_t)w * h * nc * sizeof *px);
                CHECK(px != NULL);
                for (size_t i = 0; i < (size_t)w * h * nc; i++) {
                    float c = (float)p16[i] / 65535.0f;
                    px[i] = srgb ? mip_srgb_to_linear(c) : c;
                }
            }
            stbi_image_free(p16);
        }
        if (!px || dw != w || dh != h) {
            str_fmt(err, errlen, "%s: cannot decode: %s", name, px ? "size changed" : stbi_failure_reason());
            free(px);
            return -1;
        }
        size_t n = (size_t)w * h * nc;
        for (size_t i = 0; i < n; i++)
            px[i] = !(px[i] >= 0.0f) ? 0.0f : (isfinite(px[i]) ? px[i] : 65504.0f);
        /* stb allocates with malloc; the project frees with free(): the same allocator. */
        out->data = px;
        out->format = TEXEL_F32;
    } else {
        uint8_t *px = stbi_load_from_memory(data, (int)size, &dw, &dh, &dc, (int)nc);
        if (!px || dw != w || dh != h) {
            str_fmt(err, errlen, "%s: cannot decode: %s", name, px ? "size changed" : stbi_failure_reason());
            stbi_image_free(px);
            return -1;
        }
        out->data = px;
        out->format = srgb ? TEXEL_U8_SRGB : TEXEL_U8_LINEAR;
    }
    out->width = (uint32_t)w;
    out->height = (uint32_t)h;
    out->channels = nc;
    return 0;
}

int image_load_asset(const struct asset_source *src, const char *rel_path, const char *display, int srgb,
                     struct tex_image *out, char *err, size_t errlen)
{
    memset(out, 0, sizeof *out);
    char *data = NULL;
    size_t size = 0;
    if (src->read(src->ctx, rel_path, &data, &size, err, errlen) != 0)
        return -1;
    int rc = image_load_memory(display, (const uint8_t *)data, size, srgb, out, err, errlen);
    free(data);
    return rc;
}
