/* libFuzzer target for the scene file reader: arbitrary bytes as scene.json, with an
 * in-memory asset source serving one small valid OBJ (and its MTL) under a few names.
 * Any crash, leak, sanitizer report or error without "file:line:col" is a bug.
 * Built and run by tests/fuzz/run.sh. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include "base/log.h"
#include "scene/scene_json.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static int fuzz_read(void *ctx, const char *rel_path, char **out, size_t *size, char *err, size_t errlen)
{
    (void)ctx;
    static const char obj[] = "mtllib m.mtl\nusemtl red\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\n"
                              "f 1//1 2//1 3//1 4//1\nusemtl light\nf -1 -2 -3\n";
    static const char mtl[] = "newmtl red\nKd 0.8 0.1 0.1\nnewmtl light\nKe 10 10 10\n";
    const char *src;
    if (strcmp(rel_path, "m.mtl") == 0 || strcmp(rel_path, "sub/m.mtl") == 0)
        src = mtl;
    else if (strcmp(rel_path, "a.obj") == 0 || strcmp(rel_path, "sub/a.obj") == 0 ||
             strcmp(rel_path, "cornell.obj") == 0 || strcmp(rel_path, "tiny.obj") == 0 ||
             strcmp(rel_path, "lamp.obj") == 0)
        src = obj;
    else {
        str_fmt(err, errlen, "%s: No such file or directory", rel_path);
        return -1;
    }
    *size = strlen(src);
    *out = mem_alloc(*size + 1);
    memcpy(*out, src, *size + 1);
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static int quiet;
    if (!quiet) {
        log_set_level(LOG_ERROR);
        quiet = 1;
    }
    struct asset_source src = {fuzz_read, NULL};
    struct scene scene;
    memset(&scene, 0, sizeof scene);
    char err[1024];
    char *copy = mem_alloc(size ? size : 1);
    memcpy(copy, data, size);
    int rc = scene_json_parse("s/f.json", copy, size, &src, &scene, err, sizeof err);
    if (rc != 0) {
        if (strncmp(err, "s/", 2) != 0)
            abort();  /* every message names the file */
        if (scene.materials || scene.meshes || scene.num_meshes)
            abort();  /* failure leaves the scene freed */
    } else if (scene_validate(&scene, err, sizeof err) != 0) {
        abort();
    }
    free(copy);
    scene_fini(&scene);
    return 0;
}
