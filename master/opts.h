/* The master's settings for one run, as master/main.c parses them from the command line:
 * plain values, no behaviour. Read by master.c and, for the media overrides, photons.c
 * (a header of its own so that the photon pass need not include the master loop). */
#ifndef BRUME_MASTER_OPTS_H
#define BRUME_MASTER_OPTS_H
#include <stdint.h>

struct master_opts {
    const char *scene_path;
    const char *output_path;
    const char *preview_path;   /* PNG next to the EXR, or NULL */
    const char *bind;           /* extra endpoint for remote workers, or NULL */
    const char *worker_exe;     /* worker binary for local workers */
    uint32_t workers;           /* local workers to start */
    uint32_t threads;           /* per local worker */
    uint32_t map_memory_mb;     /* --map-memory for local workers, MiB (0: the worker's default) */
    uint32_t worker_timeout_ms; /* evict a worker silent this long */
    uint32_t stall_ms;          /* evict a worker whose render threads make no progress this long */
    int no_journal;             /* do not keep OUT.journal (measurements only) */
    uint32_t bcast_mbps;        /* --bcast-mbps: pace of the blob broadcast, MB/s (0: none, point to point only) */
    uint32_t check_threads;     /* --check-threads: threads checking RESULT chunks off the loop (0: in the loop) */
    int have_check_threads;
    int verbose;                /* also print every counter (they always go to OUT.stats.json) */
    const uint32_t *only_tiles; /* --tiles: render just these (others stay black), or NULL */
    uint32_t num_only_tiles;
    const char *curve_secret;   /* CurveZMQ key pair of the master, or NULL */
    const char *allow_path;     /* allowed worker public keys, with curve_secret */
    int insecure;               /* --insecure: a tcp:// bind without CurveZMQ (warned every run) */
    int argc;                   /* the command line, to print the command that re-renders a tile */
    char **argv;
    int have_spp, have_seed, have_tile, have_depth;
    int have_sampler;
    uint32_t sampler;           /* enum sampler_type, with have_sampler */
    uint32_t embree_isa;        /* enum embree_isa (--embree-isa; 0, the default, is AVX2) */
    int have_aovs, have_filter;
    uint32_t aovs;              /* --aovs: bit set of enum aov */
    uint32_t filter;            /* --filter: enum pixel_filter */
    float filter_width;
    uint32_t spp, tile, depth;
    uint64_t seed;
    int have_frames;            /* --frames A:B[:STEP]: a range, one numbered output per frame */
    uint32_t frame_first, frame_last, frame_step;
    /* Media (photons.c): overrides of the scene's "volume" block, photon-pass threads. */
    uint32_t photon_threads;
    int have_media_method, have_photons, have_gather_radius, have_march_step, have_indirect;
    uint32_t media_method, indirect;
    uint64_t photons;
    float gather_radius, march_step;
    double photon_memory_gb;    /* --photon-memory GB: the photon maps' budget (0: half the machine's memory) */
    int have_passes;            /* --passes N (1..1024): passes (photon maps, batch means; adaptive: the most per tile) */
    uint32_t passes;
    /* Adaptive rendering (docs/adaptive.md): overrides of render.target_error,
     * render.pixel_error and render.time_limit, and a cap on rounds (reproduces a
     * time-limited run). */
    int have_target_error, have_pixel_error, have_time_limit, have_max_rounds;
    double target_error, pixel_error, time_limit;
    uint32_t max_rounds;
};

#endif
