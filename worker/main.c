/* worker: renders tiles for a master. Parses the command line and runs worker_run(). */
#include "cli.h"
#include "log.h"
#include "worker.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static void usage(FILE *f)
{
    fprintf(f,
            "usage: worker --connect ENDPOINT [--threads T] [--timeout-ms MS] [--verbose]\n"
            "  --connect ENDPOINT  the master's endpoint, e.g. tcp://10.0.0.1:5555 or ipc:///tmp/x.sock\n"
            "  --threads T         render threads (default: all cores)\n"
            "  --timeout-ms MS     give up after MS milliseconds without a word from the master (default 30000)\n"
            "  --verbose           debug logging\n");
}

int main(int argc, char **argv)
{
    struct worker_opts o = {NULL, cli_num_cores(), 30000};
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
        } else if (i + 1 < argc && !strcmp(a, "--connect")) {
            o.endpoint = argv[++i];
        } else if (i + 1 < argc && !strcmp(a, "--threads")) {
            if (cli_parse_u64(a, argv[++i], 1, 1024, &v, err, sizeof err) != 0) {
                log_error("%s", err);
                return 2;
            }
            o.threads = (uint32_t)v;
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
    return worker_run(&o);
}
