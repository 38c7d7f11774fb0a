/* master: renders a scene with local and/or remote workers. Parses the command line and
 * runs master_run(). */
#include "base/cli.h"
#include "launch.h"
#include "base/log.h"
#include "master.h"
#include "scene/medium.h"
#include "wire/net.h"
#include "render/accel.h"
#include "scene/sampler.h"
#include "scene/scene_json.h"
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
            "  --map-memory MB        local workers' budget of decoded photon maps, MiB (worker --map-memory)\n"
            "  --spp S                samples per pixel (overrides the scene)\n"
            "  --seed K               random seed (overrides the scene)\n"
            "  --tile W               tile size in pixels, 8..1024 (overrides the scene)\n"
            "  --max-depth D          maximum path vertices (overrides the scene)\n"
            "  --sampler NAME         independent, stratified or sobol (overrides the scene)\n"
            "  --aovs LIST            AOVs beside the beauty: Z,N,albedo,P,id.object,id.material or all\n"
            "                         (overrides render.aovs)\n"
            "  --filter F[:W]         pixel filter box, gaussian or blackman-harris, W pixels wide\n"
            "                         (overrides render.filter)\n"
            "  --embree-isa NAME      avx2 (default), sse4.2 or avx512: Embree's kernels on every node, the\n"
            "                         same for all so that pixels do not depend on CPUs (docs/cluster.md)\n");
    fprintf(f,
            "  --bind ENDPOINT        also accept workers at ENDPOINT, e.g. tcp://127.0.0.1:5555\n"
            "  --preview OUT.png      also write a tone-mapped sRGB PNG preview (per frame with --frames, named like -o)\n"
            "  --worker-exe PATH      worker binary for local workers (default: next to master)\n"
            "  --worker-timeout-ms MS evict a worker silent for MS milliseconds (default 10000)\n"
            "  --stall-ms MS          evict a worker whose render threads finish no work for MS ms (default 30000)\n"
            "  --frames A:B[:STEP]    render frames A..B (every STEP-th): OUT.exr becomes OUT.0001.exr, ...,\n"
            "                         or a run of # in the name is replaced by the frame number; frames whose\n"
            "                         output exists with the same scene and settings are skipped\n"
            "  --tiles N[,M..]        render only these tiles (the others are left black); no journal\n"
            "  --no-journal           do not keep OUT.exr.journal (a killed master then starts over)\n"
            "  --bcast-mbps R         stream blobs to every worker at once at R MB/s (default 0: each\n"
            "                         worker fetches every blob point to point; docs/cluster.md)\n"
            "  --check-threads N      threads that decode-check result chunks off the master's loop\n"
            "                         (default: cores - 1, 1..8; 0 = in the loop)\n"
            "  --curve-secret KEYFILE CurveZMQ: the master's key pair (from --keygen); needs --allow\n"
            "  --allow FILE           public keys of the workers allowed in, one per line\n"
            "                         (a tcp:// --bind without them: CurveZMQ with throw-away keys, so only\n"
            "                         the local workers can join)\n"
            "  --insecure             a tcp:// --bind without CurveZMQ: anyone who reaches it can join (warned)\n"
            "  --keygen KEYFILE       write a new key pair to KEYFILE and KEYFILE.pub, then exit\n"
            "  --media-method NAME    vpt, march, beam or beams: how media are rendered (overrides the scene)\n"
            "  --indirect NAME        gather or path: march and beam's indirect light at diffuse\n"
            "                         surfaces (overrides volume.indirect)\n"
            "  --photons N            photons the photon pass emits, per pass (overrides the scene)\n"
            "  --passes N             passes, 1..1024 (overrides render.passes; default one per\n"
            "                         sample with a photon map, 1 otherwise); each renders ceil(spp / N) samples with its own scramble (and\n"
            "                         photon map); the error estimate is then from batch means\n"
            "  --target-error E       adaptive: render until the estimated relRMSE is E (overrides\n"
            "                         render.target_error); --spp is the cap (default 4096), --passes the most\n"
            "                         passes a tile gets (default spp / 8)\n"
            "  --pixel-error P        adaptive: render until every pixel's estimated relative standard error\n"
            "                         (over max(pixel, 0.1 x image mean)) is P, or its block is at the cap\n"
            "                         (overrides render.pixel_error); with --target-error both must hold\n"
            "  --time-limit T         adaptive: stop at the first round boundary after T seconds (overrides\n"
            "                         render.time_limit); the EXR records the rounds reached\n"
            "  --max-rounds R         adaptive: at most R rounds (reproduces a time-limited run exactly)\n"
            "  --gather-radius R      photon gather radius in scene units (overrides the scene)\n"
            "  --march-step R         ray-marching step in scene units (overrides the scene)\n"
            "  --photon-threads T     threads of the photon pass (default: cores); the map is the same for any T\n"
            "  --photon-memory GB     budget of a frame's photon maps, checked by a pilot before tracing\n"
            "                         (default: half the machine's memory)\n"
            "  --verbose              debug logging, and every counter at the end (always in OUT.stats.json)\n");
}

/* "A:B" or "A:B:STEP"; every number whole, A <= B, STEP >= 1. */
static int parse_frames(const char *s, struct master_opts *o)
{
    uint64_t v[3] = {0, 0, 1};
    int n = 0;
    const char *p = s;
    while (n < 3) {
        char num[32], err[128];
        size_t len = strcspn(p, ":");
        if (len == 0 || len >= sizeof num)
            return -1;
        memcpy(num, p, len);
        num[len] = '\0';
        if (cli_parse_u64("--frames", num, n == 2 ? 1 : 0, n == 2 ? UINT32_MAX : UINT32_MAX - 1, &v[n], err, sizeof err) != 0)
            return -1;
        n++;
        p += len;
        if (*p == '\0')
            break;
        p++;
    }
    if (n < 2 || *p != '\0' || v[0] > v[1])
        return -1;
    o->have_frames = 1;
    o->frame_first = (uint32_t)v[0];
    o->frame_last = (uint32_t)v[1];
    o->frame_step = (uint32_t)v[2];
    return 0;
}

int main(int argc, char **argv)
{
    struct master_opts o;
    memset(&o, 0, sizeof o);
    o.workers = 1;
    o.worker_timeout_ms = 10000;
    o.stall_ms = 30000;
    o.bcast_mbps = 0; /* off: see docs/cluster.md for why, measured */
    o.argc = argc;
    o.argv = argv;
    int have_threads = 0;
    static uint32_t only_tiles[4096];
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
            o.verbose = 1;
            continue;
        }
        NUM_OPT("--workers", 0, 256, o.workers, dummy)
        NUM_OPT("--threads", 1, 1024, o.threads, have_threads)
        NUM_OPT("--spp", 1, 1048576, o.spp, o.have_spp)
        NUM_OPT("--seed", 0, UINT64_MAX, o.seed, o.have_seed)
        NUM_OPT("--tile", 8, 1024, o.tile, o.have_tile)
        NUM_OPT("--max-depth", 1, 1024, o.depth, o.have_depth)
        NUM_OPT("--worker-timeout-ms", 100, 86400000, o.worker_timeout_ms, dummy)
        NUM_OPT("--stall-ms", 100, 86400000, o.stall_ms, dummy)
        NUM_OPT("--bcast-mbps", 0, 1000000, o.bcast_mbps, dummy)
        NUM_OPT("--photon-threads", 1, 1024, o.photon_threads, dummy)
        NUM_OPT("--check-threads", 0, 64, o.check_threads, o.have_check_threads)
        NUM_OPT("--photons", 0, 1ull << 32, o.photons, o.have_photons)
        NUM_OPT("--passes", 1, 1024, o.passes, o.have_passes)
        NUM_OPT("--max-rounds", 1, 1024, o.max_rounds, o.have_max_rounds)
#undef NUM_OPT
        if (has_arg && !strcmp(a, "--map-memory")) {
            if (cli_parse_map_memory_mb(argv[++i], &v, err, sizeof err) != 0) {
                log_error("%s", err);
                return 2;
            }
            o.map_memory_mb = (uint32_t)v;
            continue;
        }
        if (has_arg && (!strcmp(a, "--target-error") || !strcmp(a, "--pixel-error") || !strcmp(a, "--time-limit"))) {
            int target = strcmp(a, "--time-limit") != 0;
            char *end;
            const char *t = argv[++i];
            double d = strtod(t, &end);
            if (!*t || *end || !(d > 0.0) || !(d < (target ? 1.0 : 1e9))) {
                log_error("%s: \"%s\" is not a number in %s", a, t, target ? "(0, 1)" : "(0, 1e9) seconds");
                return 2;
            }
            if (!strcmp(a, "--pixel-error")) {
                o.pixel_error = d;
                o.have_pixel_error = 1;
            } else if (target) {
                o.target_error = d;
                o.have_target_error = 1;
            } else {
                o.time_limit = d;
                o.have_time_limit = 1;
            }
            continue;
        }
        if (has_arg && !strcmp(a, "--photon-memory")) {
            char *end;
            const char *t = argv[++i];
            double d = strtod(t, &end);
            if (!*t || *end || !(d > 0.0) || !(d < 1e9)) {
                log_error("%s: \"%s\" is not a number of GB > 0", a, t);
                return 2;
            }
            o.photon_memory_gb = d;
            continue;
        }
        if (has_arg && (!strcmp(a, "--gather-radius") || !strcmp(a, "--march-step"))) {
            char *end;
            const char *t = argv[++i];
            float f = strtof(t, &end);
            if (!*t || *end || !(f > 0.0f) || !(f < 1e30f)) {
                log_error("%s: \"%s\" is not a number > 0", a, t);
                return 2;
            }
            if (!strcmp(a, "--gather-radius")) {
                o.gather_radius = f;
                o.have_gather_radius = 1;
            } else {
                o.march_step = f;
                o.have_march_step = 1;
            }
            continue;
        }
        if (has_arg && (!strcmp(a, "--media-method") || !strcmp(a, "--indirect"))) {
            const char *t = argv[++i];
            const int method = !strcmp(a, "--media-method");
            enum media_method mm = MEDIA_VPT;
            enum media_indirect mi = MEDIA_INDIRECT_GATHER;
            if (method ? media_method_from_name(t, &mm) != 0 : media_indirect_from_name(t, &mi) != 0) {
                log_error("%s: \"%s\" is not %s", a, t, method ? "vpt, march, beam or beams" : "gather or path");
                return 2;
            }
            if (method) {
                o.media_method = (uint32_t)mm;
                o.have_media_method = 1;
            } else {
                o.indirect = (uint32_t)mi;
                o.have_indirect = 1;
            }
            continue;
        }
        if (has_arg && (!strcmp(a, "-o") || !strcmp(a, "--output"))) {
            o.output_path = argv[++i];
        } else if (!strcmp(a, "--no-journal")) {
            o.no_journal = 1;
        } else if (!strcmp(a, "--insecure")) {
            o.insecure = 1;
        } else if (has_arg && !strcmp(a, "--curve-secret")) {
            o.curve_secret = argv[++i];
        } else if (has_arg && !strcmp(a, "--allow")) {
            o.allow_path = argv[++i];
        } else if (has_arg && !strcmp(a, "--keygen")) {
            if (net_key_pair_write(argv[++i], err, sizeof err) != 0) {
                log_error("%s", err);
                return 1;
            }
            printf("wrote %s (key pair, keep private) and %s.pub (public key)\n", argv[i], argv[i]);
            return 0;
        } else if (has_arg && !strcmp(a, "--tiles")) {
            const char *p = argv[++i];
            o.num_only_tiles = 0;
            while (*p) {
                char num[32];
                size_t n = strcspn(p, ",");
                if (n == 0 || n >= sizeof num || o.num_only_tiles >= 4096) {
                    log_error("--tiles: expected N[,M..], got \"%s\"", argv[i]);
                    return 2;
                }
                memcpy(num, p, n);
                num[n] = '\0';
                if (cli_parse_u64("--tiles", num, 0, UINT32_MAX - 1, &v, err, sizeof err) != 0) {
                    log_error("%s", err);
                    return 2;
                }
                only_tiles[o.num_only_tiles++] = (uint32_t)v;
                p += n + (p[n] == ',');
            }
            if (o.num_only_tiles == 0) {
                log_error("--tiles: expected N[,M..]");
                return 2;
            }
            o.only_tiles = only_tiles;
        } else if (has_arg && !strcmp(a, "--frames")) {
            if (parse_frames(argv[++i], &o) != 0) {
                log_error("--frames: expected A:B or A:B:STEP with A <= B and STEP >= 1, got \"%s\"", argv[i]);
                return 2;
            }
        } else if (has_arg && !strcmp(a, "--bind")) {
            o.bind = argv[++i];
        } else if (has_arg && !strcmp(a, "--embree-isa")) {
            enum embree_isa isa;
            if (embree_isa_from_name(argv[++i], &isa) != 0) {
                log_error("--embree-isa: unknown instruction set \"%s\" (avx2, sse4.2 or avx512)", argv[i]);
                return 2;
            }
            o.embree_isa = (uint32_t)isa;
        } else if (has_arg && !strcmp(a, "--sampler")) {
            enum sampler_type st;
            if (sampler_type_from_name(argv[++i], &st) != 0) {
                log_error("--sampler: unknown sampler \"%s\" (independent, stratified or sobol)", argv[i]);
                return 2;
            }
            o.sampler = (uint32_t)st;
            o.have_sampler = 1;
        } else if (has_arg && !strcmp(a, "--aovs")) {
            if (scene_aovs_from_list(argv[++i], &o.aovs) != 0) {
                log_error("--aovs: expected a list of Z, N, albedo, P, id.object, id.material, or all; got \"%s\"",
                          argv[i]);
                return 2;
            }
            o.have_aovs = 1;
        } else if (has_arg && !strcmp(a, "--filter")) {
            if (scene_filter_from_spec(argv[++i], &o.filter, &o.filter_width) != 0) {
                log_error("--filter: expected box, gaussian[:WIDTH] or blackman-harris[:WIDTH] (WIDTH in pixels, "
                          "%g..%g); got \"%s\"", (double)SCENE_FILTER_MIN_WIDTH, (double)SCENE_FILTER_MAX_WIDTH, argv[i]);
                return 2;
            }
            o.have_filter = 1;
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
    if (!o.output_path[0]) { /* else OUT.stats.json would be a hidden ".stats.json" */
        log_error("-o: the output name is empty");
        return 2;
    }
    if (!o.curve_secret != !o.allow_path) {
        log_error("--curve-secret and --allow go together");
        return 2;
    }
    if (o.insecure && o.curve_secret) {
        log_error("--insecure and --curve-secret contradict each other");
        return 2;
    }
    if (o.bind && net_endpoint_is_tcp(o.bind) && !o.curve_secret && !o.insecure && o.workers == 0) {
        log_error("--bind %s: workers must prove a key (CurveZMQ, on for every tcp:// endpoint): give --curve-secret "
                  "and --allow (see docs/cluster.md), or --insecure to let anyone who reaches it join", o.bind);
        return 2;
    }
    if (o.workers == 0 && !o.bind) {
        log_error("--workers 0 needs --bind ENDPOINT, or nobody could render");
        return 2;
    }
    if (!o.photon_threads)
        o.photon_threads = cli_num_cores();
    if (!o.have_check_threads) { /* the loop's core stays the loop's */
        uint32_t cores = cli_num_cores();
        o.check_threads = cores <= 2 ? 1 : cores - 1 < 8 ? cores - 1 : 8;
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
    mem_keep_freed();
    return master_run(&o);
}
