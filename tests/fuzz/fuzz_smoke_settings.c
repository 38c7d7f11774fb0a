/* libFuzzer target for the smoke simulator's settings reader (smoke/settings.c): arbitrary
 * bytes as sim.json. Any crash, sanitizer report, error without "sim.json:line:col: " or
 * accepted settings that fail smoke_settings_check is a bug. Built and run by
 * tests/fuzz/run.sh (with smoke/settings.c). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "../../smoke/settings.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    struct smoke_settings s;
    char err[1024];
    if (smoke_settings_parse("sim.json", (const char *)data, size, &s, err, sizeof err) == 0) {
        if (smoke_settings_check(&s, err, sizeof err) != 0)
            abort();
        return 0;
    }
    unsigned line, col;
    if (sscanf(err, "sim.json:%u:%u: ", &line, &col) != 2 || line == 0 || col == 0)
        abort();
    return 0;
}
