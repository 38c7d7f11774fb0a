/* Project log and allocation wrappers (see log.h). Lines go to stderr, whole lines at once,
 * so the output of several threads and processes interleaves by line, never inside one. */
#include "base/log.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <pthread.h>
#include <malloc.h>

static enum log_level g_level = LOG_INFO;
static char g_prefix[64] = "brume";
static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;

void log_set_level(enum log_level level) { g_level = level; }

void log_set_prefix(const char *prefix)
{
    snprintf(g_prefix, sizeof g_prefix, "%s", prefix);
}

void log_msg(enum log_level level, const char *fmt, ...)
{
    static const char *const names[] = {"error", "warning", "info", "debug"};
    if (level > g_level)
        return;
    char line[2048];
    int n = snprintf(line, sizeof line, "%s: %s: ", g_prefix, names[level]);
    va_list ap;
    va_start(ap, fmt);
    if (n >= 0 && (size_t)n < sizeof line)
        vsnprintf(line + n, sizeof line - (size_t)n, fmt, ap);
    va_end(ap);
    pthread_mutex_lock(&g_lock);
    fprintf(stderr, "%s\n", line);
    fflush(stderr);
    pthread_mutex_unlock(&g_lock);
}

void log_fatal_check(const char *expr, const char *file, int line)
{
    fprintf(stderr, "%s: fatal: CHECK(%s) failed at %s:%d\n", g_prefix, expr, file, line);
    abort();
}

static void *oom(size_t size)
{
    fprintf(stderr, "%s: fatal: out of memory allocating %zu bytes\n", g_prefix, size);
    abort();
}

void mem_keep_freed(void)
{
    /* glibc's own limits (M_MMAP_THRESHOLD at most 32 MiB on 64-bit); a refusal only
     * costs page faults. */
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, 256 << 20);
}

void *mem_alloc(size_t size)
{
    void *p = malloc(size ? size : 1);
    return p ? p : oom(size);
}

void *mem_calloc(size_t count, size_t size)
{
    void *p = calloc(count ? count : 1, size ? size : 1);
    return p ? p : oom(count * size);
}

void *mem_realloc(void *p, size_t size)
{
    void *q = realloc(p, size ? size : 1);
    return q ? q : oom(size);
}

char *mem_strdup(const char *s)
{
    size_t n = strlen(s) + 1;
    return memcpy(mem_alloc(n), s, n);
}

void mem_grow(void **array, size_t *capacity, size_t need, size_t elem_size)
{
    if (need <= *capacity)
        return;
    size_t cap = *capacity ? *capacity : 8;
    while (cap < need)
        cap *= 2;
    *array = mem_realloc(*array, cap * elem_size);
    *capacity = cap;
}

char *str_fmt(char *buf, size_t size, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, size, fmt, ap);
    va_end(ap);
    return buf;
}
