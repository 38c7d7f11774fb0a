/* Decoding texture images from bytes: PNG and JPEG through stb_image (Debian's libstb),
 * Radiance HDR by hand (hdr.c), OpenEXR through OpenEXRCore (imgio.c). The header is read first and
 * its size checked (each side at most MIP_MAX_DIM) before anything is allocated. 8-bit
 * images keep their bytes (sRGB-encoded unless `srgb` is 0: then linear, e.g. for data
 * maps); 16-bit PNGs and HDR/EXR become float. Gray stays one channel, gray+alpha drops
 * alpha, RGBA drops alpha. Callers: scene_json.c, mesh_obj.c (through image_load_asset). */
#ifndef BRUME_IMAGE_LOAD_H
#define BRUME_IMAGE_LOAD_H
#include <stddef.h>
#include <stdint.h>
#include "base/asset.h"
#include "image/mip.h"

/* Decodes size bytes named `name` (in messages) into *out (zeroed on failure). Returns 0,
 * or -1 with one line "name: reason" in err. */
int image_load_memory(const char *name, const uint8_t *data, size_t size, int srgb, struct tex_image *out,
                      char *err, size_t errlen);

/* Reads rel_path through src (so the master records it and workers fetch it as a blob)
 * and decodes it; display is the name used in messages. */
int image_load_asset(const struct asset_source *src, const char *rel_path, const char *display, int srgb,
                     struct tex_image *out, char *err, size_t errlen);

#endif
