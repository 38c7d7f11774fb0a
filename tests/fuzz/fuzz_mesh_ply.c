/* libFuzzer target for the PLY reader: the input is a PLY file (any format). Any crash,
 * leak, sanitizer report, error without the file's name or mesh that scene_validate
 * refuses (an index out of range, a non-finite position) is a bug. Built and run by tests/fuzz/run.sh (all targets) and tests/fuzz/ci.sh
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
    /* Indices, materials, finite positions: what every render checks. */
    scene.settings = (struct render_settings){.width = 1, .height = 1, .spp = 1, .max_depth = 1, .tile_size = 8};
    scene.camera.look_at = v3(0, 0, -1);
    scene.camera.up = v3(0, 1, 0);
    scene.camera.fov_y_deg = 45.0f;
    if (rc == 0 && scene_validate(&scene, err, sizeof err) != 0)
        abort();
    free(copy);
    mesh_obj_cache_fini(&cache);
    scene_fini(&scene);
    return 0;
}
