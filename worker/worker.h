/* The worker loop: connect to a master, fetch the job's blobs (cached by hash), build the
 * scene once per job, render tiles on a pool of threads and send each back as an EXR tile
 * chunk. Called by worker/main.c. */
#ifndef BRUME_WORKER_H
#define BRUME_WORKER_H
#include <stdint.h>

/* Faults a worker can inject on purpose, for the fault-tolerance tests only. */
enum worker_fault {
    FAULT_NONE,
    FAULT_HANG_AFTER,   /* render threads hang (main thread still answers) after N tiles */
    FAULT_CRASH_TILE,   /* abort() when asked to render tile N */
    FAULT_GARBAGE,      /* every result carries a NaN pixel (the master must reject it) */
    FAULT_SLOW,         /* sleep N ms before each tile (a straggler) */
    FAULT_NONFINITE_TILE, /* tile (unit) N carries an infinite pixel, as a scene past float's range would */
    FAULT_SLOW_LOAD     /* loading a job's scene takes N ms longer (a big scene on a loaded machine) */
};

/* The default of --map-memory, MiB: decoded photon maps one worker process holds. */
#define WORKER_MAP_MEMORY_MB 2048u

struct worker_opts {
    const char *endpoint;
    uint32_t threads;
    uint32_t master_timeout_ms;   /* give up after this long without a word from the master */
    const char *curve_secret;     /* our key pair file (CurveZMQ), or NULL */
    const char *server_key;       /* the master's public key file, with curve_secret */
    enum worker_fault fault;
    uint32_t fault_arg;
    uint64_t map_memory_bytes;    /* budget of decoded photon maps (one map is always held) */
};

/* Runs until the master says BYE (returns 0) or a fatal error (returns 1, logged). */
int worker_run(const struct worker_opts *opts);

#endif
