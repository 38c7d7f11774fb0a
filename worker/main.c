/* worker: renders tiles for a master. Parses the command line and runs worker_run(). */
#include "base/cli.h"
#include "base/log.h"
#include "worker.h"
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <unistd.h>

static void usage(FILE *f)
{
    fprintf(f,
            "usage: worker --connect ENDPOINT [--threads T] [--timeout-ms MS] [--map-memory MB] [--verbose]\n"
            "              [--curve-secret KEYFILE --server-key MASTER.pub]\n"
            "  --connect ENDPOINT  the master's endpoint, e.g. tcp://10.0.0.1:5555 or ipc:///tmp/x.sock\n"
            "  --threads T         render threads (default: all cores)\n"
            "  --timeout-ms MS     give up after MS milliseconds without a word from the master (default 30000)\n"
            "  --map-memory MB     decoded photon maps (one per pass) held at most, in MiB (default %u); past it\n"
            "                      the least recently used map no queued unit needs is dropped and fetched again\n"
            "                      if a later unit needs it; one map is always held\n"
            "  --curve-secret F    our CurveZMQ key pair (from master --keygen); needs --server-key\n"
            "  --server-key F      the master's public key file (KEYFILE.pub of the master's pair)\n"
            "  --exit-with-parent  exit when the process that started us dies (local workers)\n"
            "  --fault KIND[:N]    tests only: hang-after:N, crash-tile:N, garbage, slow:MS,\n"
            "                      nonfinite-tile:N, slow-load:MS\n"
            "  --verbose           debug logging\n",
            WORKER_MAP_MEMORY_MB);
}

static int parse_fault(const char *s, struct worker_opts *o)
{
    static const struct { const char *name; enum worker_fault f; int needs_n; } kinds[] = {
        {"hang-after", FAULT_HANG_AFTER, 1}, {"crash-tile", FAULT_CRASH_TILE, 1},
        {"garbage", FAULT_GARBAGE, 0}, {"slow-load", FAULT_SLOW_LOAD, 1}, {"slow", FAULT_SLOW, 1},
        {"nonfinite-tile", FAULT_NONFINITE_TILE, 1}};
    for (size_t i = 0; i < sizeof kinds / sizeof kinds[0]; i++) {
        size_t n = strlen(kinds[i].name);
        if (strncmp(s, kinds[i].name, n) != 0)
            continue;
        o->fault = kinds[i].f;
        if (!kinds[i].needs_n)
            return s[n] == '\0' ? 0 : -1;
        uint64_t v;
        char err[128];
        if (s[n] != ':' || cli_parse_u64("--fault", s + n + 1, 0, UINT32_MAX, &v, err, sizeof err) != 0)
            return -1;
        o->fault_arg = (uint32_t)v;
        return 0;
    }
    return -1;
}

int main(int argc, char **argv)
{
    struct worker_opts o = {NULL, cli_num_cores(), 30000, NULL, NULL, FAULT_NONE, 0, (uint64_t)WORKER_MAP_MEMORY_MB << 20};
    char prefix[64];
    snprintf(prefix, sizeof prefix, "worker %d", (int)getpid());
    log_set_prefix(prefix);
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        char err[256];
        uint64_t v;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage(stdout);
            return 0;
        } else if (!strcmp(a, "--verbose")) {
            log_set_level(LOG_DEBUG);
        } else if (!strcmp(a, "--exit-with-parent")) {
            /* A master killed with SIGKILL cannot stop its local workers: the kernel does. */
            pid_t parent = getppid();
            if (prctl(PR_SET_PDEATHSIG, SIGTERM) != 0 || getppid() != parent)
                return 1;
        } else if (i + 1 < argc && !strcmp(a, "--connect")) {
            o.endpoint = argv[++i];
        } else if (i + 1 < argc && !strcmp(a, "--curve-secret")) {
            o.curve_secret = argv[++i];
        } else if (i + 1 < argc && !strcmp(a, "--server-key")) {
            o.server_key = argv[++i];
        } else if (i + 1 < argc && !strcmp(a, "--fault")) {
            if (parse_fault(argv[++i], &o) != 0) {
                log_error("--fault: \"%s\" is not hang-after:N, crash-tile:N, garbage, slow:MS, nonfinite-tile:N or slow-load:MS", argv[i]);
                return 2;
            }
        } else if (i + 1 < argc && !strcmp(a, "--threads")) {
            if (cli_parse_u64(a, argv[++i], 1, 1024, &v, err, sizeof err) != 0) {
                log_error("%s", err);
                return 2;
            }
            o.threads = (uint32_t)v;
        } else if (i + 1 < argc && !strcmp(a, "--map-memory")) {
            if (cli_parse_map_memory_mb(argv[++i], &v, err, sizeof err) != 0) {
                log_error("%s", err);
                return 2;
            }
            o.map_memory_bytes = v << 20;
        } else if (i + 1 < argc && !strcmp(a, "--timeout-ms")) {
            if (cli_parse_u64(a, argv[++i], 100, 86400000, &v, err, sizeof err) != 0) {
                log_error("%s", err);
                return 2;
            }
            o.master_timeout_ms = (uint32_t)v;
        } else {
            log_error("unknown or incomplete option \"%s\" (see --help)", a);
            return 2;
        }
    }
    if (!o.endpoint) {
        log_error("--connect ENDPOINT is required (see --help)");
        return 2;
    }
    if (!o.curve_secret != !o.server_key) {
        log_error("--curve-secret and --server-key go together");
        return 2;
    }
    mem_keep_freed();
    return worker_run(&o);
}
