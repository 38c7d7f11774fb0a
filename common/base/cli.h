/* Strict command-line number parsing shared by master and worker: the whole string must
 * be a number within [min, max], else a one-line error naming the option. */
#ifndef BRUME_CLI_H
#define BRUME_CLI_H
#include <stddef.h>
#include <stdint.h>

int cli_parse_u64(const char *opt, const char *text, uint64_t min, uint64_t max, uint64_t *out, char *err,
                  size_t errlen);
/* --map-memory MB (master and worker): a worker's budget of decoded photon maps, in MiB,
 * 1..2^24. */
int cli_parse_map_memory_mb(const char *text, uint64_t *mb, char *err, size_t errlen);
/* Number of online processors (at least 1). */
uint32_t cli_num_cores(void);

#endif
