/* libFuzzer target for the PLY reader: the input is a PLY file (any format). Any crash,
 * leak, sanitizer report, error without the file's name or mesh with an index out of
 * range is a bug. Built and run by tests/fuzz/run.sh (all targets) and tests/fuzz/ci.sh
 * (briefly, in `make test`). */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include "base/log.h"
#include "scene/mesh_ply.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static int quiet;
    if (!quiet) {
        log_set_level(LOG_ERROR);
        quiet = 1;
    }
    struct mesh_obj_cache cache = {0};
    struct scene scene = {0};
    struct mesh_obj_options opt = mesh_obj_default_options();
    if (size & 1) { /* odd sizes also take the transform path, mirroring included */
        struct dxform t = {{{-2, 0, 0, 1}, {0, 1, 0, 2}, {0, 0, 0.5, 3}}};
        opt.transform = t;
    }
    char err[512];
    /* A copy of exactly size bytes: the reader must not read past it. */
    uint8_t *copy = mem_alloc(size ? size : 1);
    memcpy(copy, data, size);
    int rc = mesh_ply_parse(&scene, &cache, "dir/f.ply", copy, size, &opt, err, sizeof err);
    if (rc != 0 && strncmp(err, "dir/f.ply", 9) != 0)
        abort(); /* every error names the file */
    for (uint32_t i = 0; rc == 0 && i < scene.num_meshes; i++) {
        const struct mesh *m = &scene.meshes[i];
        for (size_t k = 0; k < 3 * (size_t)m->num_triangles; k++)
            if (m->indices[k] >= m->num_vertices)
                abort();
        for (size_t k = 0; k < m->num_triangles; k++)
            if (m->material_ids[k] >= scene.num_materials)
                abort();
    }
    free(copy);
    mesh_obj_cache_fini(&cache);
    scene_fini(&scene);
    return 0;
}
