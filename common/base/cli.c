/* Command-line helpers (see cli.h). */
#include "base/cli.h"
#include "base/log.h"
#include <ctype.h>
#include <errno.h>
#include <stdlib.h>
#include <unistd.h>

int cli_parse_u64(const char *opt, const char *text, uint64_t min, uint64_t max, uint64_t *out, char *err,
                  size_t errlen)
{
    if (!text || !*text || !isdigit((unsigned char)text[0])) {
        str_fmt(err, errlen, "%s: expected a number, got \"%s\"", opt, text ? text : "");
        return -1;
    }
    errno = 0;
    char *end;
    unsigned long long v = strtoull(text, &end, 10);
    if (errno || *end || v < min || v > max) {
        str_fmt(err, errlen, "%s: \"%s\" is not a number in %llu..%llu", opt, text, (unsigned long long)min,
                (unsigned long long)max);
        return -1;
    }
    *out = v;
    return 0;
}

int cli_parse_map_memory_mb(const char *text, uint64_t *mb, char *err, size_t errlen)
{
    return cli_parse_u64("--map-memory", text, 1, 1ull << 24, mb, err, errlen);
}

uint32_t cli_num_cores(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n > 0 ? (uint32_t)n : 1;
}
