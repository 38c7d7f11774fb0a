/* master: renders a scene with local and/or remote workers. Parses the command line and
 * runs master_run(). */
#include "cli.h"
#include "launch.h"
#include "log.h"
#include "master.h"
#include "sampler.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void usage(FILE *f)
{
    fprintf(f,
            "usage: master SCENE.json -o OUT.exr [options]\n"
            "  -o, --output OUT.exr   output image (tiled OpenEXR; written atomically)\n"
            "  --workers N            local worker processes to start (default 1; 0 = remote only)\n"
            "  --threads T            render threads per local worker (default: cores / N)\n"
            "  --spp S                samples per pixel (overrides the scene)\n"
            "  --seed K               random seed (overrides the scene)\n"
            "  --tile W               tile size in pixels, 8..1024 (overrides the scene)\n"
            "  --max-depth D          maximum path vertices (overrides the scene)\n"
            "  --sampler NAME         independent, stratified or sobol (overrides the scene)\n"
            "  --bind ENDPOINT        also accept workers at ENDPOINT, e.g. tcp://127.0.0.1:5555\n"
            "  --preview OUT.png      also write a tone-mapped sRGB PNG preview\n"
            "  --worker-exe PATH      worker binary for local workers (default: next to master)\n"
            "  --worker-timeout-ms MS evict a worker silent for MS milliseconds (default 10000)\n"
            "  --verbose              debug logging\n");
}

int main(int argc, char **argv)
{
    struct master_opts o;
    memset(&o, 0, sizeof o);
    o.workers = 1;
    o.worker_timeout_ms = 10000;
    int have_threads = 0;
    char worker_exe[4096];
    log_set_prefix("master");
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        char err[256];
        uint64_t v;
        int has_arg = i + 1 < argc;
#define NUM_OPT(name, lo, hi, dst, flag)                                                                           \
    if (has_arg && !strcmp(a, name)) {                                                                             \
        if (cli_parse_u64(a, argv[++i], lo, hi, &v, err, sizeof err) != 0) {                                       \
            log_error("%s", err);                                                                                  \
            return 2;                                                                                              \
        }                                                                                                          \
        dst = v;                                                                                                   \
        flag = 1;                                                                                                  \
        continue;                                                                                                  \
    }
        int dummy;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage(stdout);
            return 0;
        }
        if (!strcmp(a, "--verbose")) {
            log_set_level(LOG_DEBUG);
            continue;
        }
        NUM_OPT("--workers", 0, 256, o.workers, dummy)
        NUM_OPT("--threads", 1, 1024, o.threads, have_threads)
        NUM_OPT("--spp", 1, 1048576, o.spp, o.have_spp)
        NUM_OPT("--seed", 0, UINT64_MAX, o.seed, o.have_seed)
        NUM_OPT("--tile", 8, 1024, o.tile, o.have_tile)
        NUM_OPT("--max-depth", 1, 1024, o.depth, o.have_depth)
        NUM_OPT("--worker-timeout-ms", 100, 86400000, o.worker_timeout_ms, dummy)
#undef NUM_OPT
        if (has_arg && (!strcmp(a, "-o") || !strcmp(a, "--output"))) {
            o.output_path = argv[++i];
        } else if (has_arg && !strcmp(a, "--bind")) {
            o.bind = argv[++i];
        } else if (has_arg && !strcmp(a, "--sampler")) {
            enum sampler_type st;
            if (sampler_type_from_name(argv[++i], &st) != 0) {
                log_error("--sampler: unknown sampler \"%s\" (independent, stratified or sobol)", argv[i]);
                return 2;
            }
            o.sampler = (uint32_t)st;
            o.have_sampler = 1;
        } else if (has_arg && !strcmp(a, "--preview")) {
            o.preview_path = argv[++i];
        } else if (has_arg && !strcmp(a, "--worker-exe")) {
            o.worker_exe = argv[++i];
        } else if (a[0] != '-' && !o.scene_path) {
            o.scene_path = a;
        } else {
            log_error("unknown or incomplete option \"%s\" (see --help)", a);
            return 2;
        }
        (void)dummy;
    }
    if (!o.scene_path || !o.output_path) {
        log_error("a scene and -o OUT.exr are required (see --help)");
        return 2;
    }
    if (o.workers == 0 && !o.bind) {
        log_error("--workers 0 needs --bind ENDPOINT, or nobody could render");
        return 2;
    }
    if (!have_threads) {
        uint32_t cores = cli_num_cores();
        o.threads = o.workers > 0 && cores / o.workers > 0 ? cores / o.workers : 1;
    }
    if (!o.worker_exe && o.workers > 0) {
        if (launch_default_worker_exe(worker_exe, sizeof worker_exe) != 0) {
            log_error("cannot find the worker binary next to master (use --worker-exe)");
            return 2;
        }
        o.worker_exe = worker_exe;
    }
    return master_run(&o);
}
