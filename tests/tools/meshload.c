/* meshload: CPU time to load a mesh file, for the PLY-against-OBJ benchmark
 * (scripts/bench_io.sh).
 *   meshload FILE [REPS]   reads FILE (.obj or .ply) from disk and parses it REPS times
 *                          (default 3); prints "triangles vertices best_cpu_s mean_cpu_s"
 * CPU time of this process (CLOCK_PROCESS_CPUTIME_ID), reading the file included. */
#include "base/asset.h"
#include "base/log.h"
#include "scene/mesh_obj.h"
#include "scene/mesh_ply.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double cpu_now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static int read_file(void *ctx, const char *rel, char **data, size_t *size, char *err, size_t errlen)
{
    (void)ctx;
    FILE *f = fopen(rel, "rb");
    if (!f) {
        str_fmt(err, errlen, "%s: cannot open", rel);
        return -1;
    }
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    *data = mem_alloc((size_t)n + 1);
    *size = fread(*data, 1, (size_t)n, f);
    (*data)[*size] = '\0';
    fclose(f);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: meshload FILE [REPS]\n");
        return 2;
    }
    int reps = argc > 2 ? atoi(argv[2]) : 3;
    size_t len = strlen(argv[1]);
    int ply = len > 4 && !strcmp(argv[1] + len - 4, ".ply");
    double best = 1e30, sum = 0.0;
    uint32_t tris = 0, verts = 0;
    for (int r = 0; r < (reps > 0 ? reps : 1); r++) {
        struct scene s = {0};
        struct mesh_obj_cache cache = {0};
        struct asset_source src = {read_file, NULL};
        char err[1024];
        double t0 = cpu_now();
        char *data;
        size_t size;
        if (read_file(NULL, argv[1], &data, &size, err, sizeof err) != 0) {
            fprintf(stderr, "meshload: %s\n", err);
            return 1;
        }
        int rc = ply ? mesh_ply_parse(&s, &cache, argv[1], (const uint8_t *)data, size, NULL, err, sizeof err)
                     : mesh_obj_parse(&s, &cache, &src, argv[1], data, size, NULL, err, sizeof err);
        free(data);
        double t = cpu_now() - t0;
        if (rc != 0 || s.num_meshes != 1) {
            fprintf(stderr, "meshload: %s\n", rc ? err : "no mesh");
            return 1;
        }
        tris = s.meshes[0].num_triangles;
        verts = s.meshes[0].num_vertices;
        best = t < best ? t : best;
        sum += t;
        mesh_obj_cache_fini(&cache);
        scene_fini(&s);
    }
    printf("%u %u %.4f %.4f\n", tris, verts, best, sum / (reps > 0 ? reps : 1));
    return 0;
}
