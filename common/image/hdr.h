/* Radiance RGBE (.hdr) decoding, by hand: stb_image's HDR reader loops forever on some
 * truncated run-length data (found by tests/unit/test_texture.c), so this bounded one is
 * used instead. Accepts "#?RADIANCE"/"#?RGBE" headers, FORMAT=32-bit_rle_rgbe (or none),
 * resolution "-Y H +X W" or "+Y H +X W", flat, old-style run and new-style RLE scanlines.
 * Every read is bounded by the buffer; sizes are checked (each side 1..MIP_MAX_DIM)
 * before allocating. Called by image_load.c; fuzzed by tests/fuzz/fuzz_image_load.c. */
#ifndef BRUME_HDR_H
#define BRUME_HDR_H
#include <stddef.h>
#include <stdint.h>

/* Decodes into *rgb (mem_alloc'd, width * height * 3 linear floats, rows top first).
 * Returns 0, or -1 with "name: reason" in err. */
int hdr_decode(const char *name, const uint8_t *data, size_t size, float **rgb, uint32_t *width,
               uint32_t *height, char *err, size_t errlen);

#endif
