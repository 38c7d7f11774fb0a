/* libFuzzer target for texture image decoding (common/image/image_load.c): inputs that start
 * with a format's magic are decoded as they are (the seeds are the scenes' images); any
 * other input gets a magic chosen by its first byte prepended (so every decoder sees it),
 * must decode to a checked image or fail with a message; a decoded image then builds its
 * MIP pyramid and answers one lookup of every filter. Built and run by tests/fuzz/run.sh. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include "image/image_load.h"
#include "base/log.h"
#include "image/mip.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const char *const magic[] = {"\x89PNG\r\n\x1a\n", "\xff\xd8\xff", "#?RADIANCE\n", "\x76\x2f\x31\x01"};
    if (size == 0)
        return 0;
    int raw = 0;
    for (int k = 0; k < 4; k++)
        if (size >= strlen(magic[k]) && memcmp(data, magic[k], strlen(magic[k])) == 0)
            raw = 1;
    const char *mg = raw ? "" : magic[data[0] % 4];
    size_t mn = strlen(mg), skip = raw ? 0 : 1;
    uint8_t *buf = mem_alloc(mn + size);
    memcpy(buf, mg, mn);
    memcpy(buf + mn, data + skip, size - skip);
    struct tex_image img;
    char err[512];
    if (image_load_memory("f.img", buf, mn + size - skip, (int)(size & 1), &img, err, sizeof err) == 0) {
        if (tex_image_bytes(img.width, img.height, img.channels, img.format) == 0)
            abort();
        if ((uint64_t)img.width * img.height <= (1u << 20)) {
            struct mip m;
            mip_init(&m, &img, TEXWRAP_REPEAT);
            for (int f = 0; f < TEXFILTER_COUNT_; f++)
                (void)mip_lookup(&m, (enum texture_filter)f, 8.0f, 0.3f, 0.7f, 0.01f, 0.002f, -0.001f, 0.05f);
            mip_fini(&m);
        }
        tex_image_fini(&img);
    } else if (strncmp(err, "f.img", 5) != 0) {
        abort(); /* every message names the file */
    }
    free(buf);
    return 0;
}
