/* The worker loop: connect to a master, fetch the job's blobs (cached by hash), build the
 * scene once per job, render tiles on a pool of threads and send each back as an EXR tile
 * chunk. Called by worker/main.c. */
#ifndef BRUME_WORKER_H
#define BRUME_WORKER_H
#include <stdint.h>

struct worker_opts {
    const char *endpoint;
    uint32_t threads;
    uint32_t master_timeout_ms;   /* give up after this long without a word from the master */
};

/* Runs until the master says BYE (returns 0) or a fatal error (returns 1, logged). */
int worker_run(const struct worker_opts *opts);

#endif
