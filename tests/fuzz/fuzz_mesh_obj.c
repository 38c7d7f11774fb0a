/* libFuzzer target for the OBJ/MTL reader: the input is an OBJ file whose mtllib may
 * name "a.mtl" (a fixed, valid MTL) or "b.mtl" (the input itself read as an MTL), so
 * both grammars see arbitrary bytes. Any crash, leak or sanitizer report is a bug.
 * Built and run by tests/fuzz/run.sh. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include "base/log.h"
#include "scene/mesh_obj.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

struct input { const uint8_t *data; size_t size; };

static int fuzz_read(void *ctx, const char *rel_path, char **out, size_t *size, char *err, size_t errlen)
{
    const struct input *in = ctx;
    static const char fixed[] = "newmtl a\nKd 0.5 0.5 0.5\nnewmtl light\nKe 1 1 1\nmap_Ks t.png\n";
    const void *src;
    size_t n;
    if (strcmp(rel_path, "a.mtl") == 0) {
        src = fixed;
        n = sizeof fixed - 1;
    } else if (strcmp(rel_path, "b.mtl") == 0) {
        src = in->data;
        n = in->size;
    } else {
        str_fmt(err, errlen, "%s: No such file or directory", rel_path);
        return -1;
    }
    *out = mem_alloc(n + 1);
    memcpy(*out, src, n);
    (*out)[n] = '\0';
    *size = n;
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static int quiet;
    if (!quiet) {
        log_set_level(LOG_ERROR);  /* warnings on every input would drown the fuzzer */
        quiet = 1;
    }
    struct input in = {data, size};
    struct asset_source src = {fuzz_read, &in};
    struct mesh_obj_cache cache = {0};
    struct scene scene = {0};
    struct mesh_obj_options opt = mesh_obj_default_options();
    /* Odd sizes also exercise the transform path, mirroring included. */
    if (size & 1) {
        struct dxform t = {{{-2, 0, 0, 1}, {0, 1, 0, 2}, {0, 0, 0.5, 3}}};
        opt.transform = t;
    }
    char err[512];
    /* The input is not NUL-terminated: the parser must respect size. */
    char *copy = mem_alloc(size ? size : 1);
    memcpy(copy, data, size);
    int rc = mesh_obj_parse(&scene, &cache, &src, "dir/f.obj", copy, size, &opt, err, sizeof err);
    if (rc != 0 && strncmp(err, "dir/", 4) != 0 && strncmp(err, "f.obj", 5) != 0)
        abort();  /* every error names a file */
    if (rc == 0) {
        char why[256];
        for (uint32_t i = 0; i < scene.num_meshes; i++) {
            const struct mesh *m = &scene.meshes[i];
            for (size_t k = 0; k < 3 * (size_t)m->num_triangles; k++)
                if (m->indices[k] >= m->num_vertices)
                    abort();
            for (size_t k = 0; k < m->num_triangles; k++)
                if (m->material_ids[k] >= scene.num_materials)
                    abort();
        }
        (void)why;
    }
    free(copy);
    mesh_obj_cache_fini(&cache);
    scene_fini(&scene);
    return 0;
}
