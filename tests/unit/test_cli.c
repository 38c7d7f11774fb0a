/* Command-line number parsing shared by master and worker: whole numbers within the
 * option's range, else an error naming the option. */
#include <criterion/criterion.h>
#include <string.h>
#include "base/cli.h"

Test(cli, u64_whole_number_in_range)
{
    uint64_t v = 0;
    char err[128];
    cr_assert_eq(cli_parse_u64("--x", "42", 1, 100, &v, err, sizeof err), 0);
    cr_assert_eq(v, 42u);
    const char *bad[] = {"", "0", "101", "4x", "-1", " 5", "0x10"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        v = 7;
        cr_assert_eq(cli_parse_u64("--x", bad[i], 1, 100, &v, err, sizeof err), -1, "\"%s\" taken", bad[i]);
        cr_assert_eq(v, 7u, "refused: nothing written");
        cr_assert(strstr(err, "--x") != NULL, "%s", err);
    }
}

/* Master and worker take the same --map-memory: MiB, 1 .. 2^24. */
Test(cli, map_memory_range)
{
    uint64_t v = 0;
    char err[128];
    cr_assert_eq(cli_parse_map_memory_mb("1", &v, err, sizeof err), 0);
    cr_assert_eq(v, 1u);
    cr_assert_eq(cli_parse_map_memory_mb("16777216", &v, err, sizeof err), 0);
    cr_assert_eq(v, 1u << 24);
    cr_assert_eq(cli_parse_map_memory_mb("0", &v, err, sizeof err), -1);
    cr_assert(strstr(err, "--map-memory") != NULL, "%s", err);
    cr_assert_eq(cli_parse_map_memory_mb("16777217", &v, err, sizeof err), -1);
    cr_assert_eq(cli_parse_map_memory_mb("8M", &v, err, sizeof err), -1);
}
