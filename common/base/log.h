/* Project log and always-on checks. Every module logs through here; library error hooks
 * (Embree, OpenEXRCore, libzmq failures) are routed here too. Thread-safe: one line per call.
 * CHECK() is always on, DCHECK() only in debug builds; both are expressions.
 * Out-of-memory aborts in mem_alloc() and friends: callers never test for NULL. */
#ifndef BRUME_LOG_H
#define BRUME_LOG_H
#include <stddef.h>
#include <stdarg.h>

enum log_level { LOG_ERROR = 0, LOG_WARN = 1, LOG_INFO = 2, LOG_DEBUG = 3 };

void log_set_level(enum log_level level);
void log_set_prefix(const char *prefix); /* e.g. "master" or "worker 3"; copied */
void log_msg(enum log_level level, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
#define log_error(...) log_msg(LOG_ERROR, __VA_ARGS__)
#define log_warn(...) log_msg(LOG_WARN, __VA_ARGS__)
#define log_info(...) log_msg(LOG_INFO, __VA_ARGS__)
#define log_debug(...) log_msg(LOG_DEBUG, __VA_ARGS__)

_Noreturn void log_fatal_check(const char *expr, const char *file, int line);
#define CHECK(e) ((e) ? (void)0 : log_fatal_check(#e, __FILE__, __LINE__))
#ifdef NDEBUG
#define DCHECK(e) ((void)0)
#else
#define DCHECK(e) CHECK(e)
#endif

/* Allocation wrappers: abort with a message on out-of-memory. */
void *mem_alloc(size_t size);
void *mem_calloc(size_t count, size_t size);
void *mem_realloc(void *p, size_t size);
char *mem_strdup(const char *s);
/* Grows *array (of *capacity elements of elem_size) to hold at least need elements. */
void mem_grow(void **array, size_t *capacity, size_t need, size_t elem_size);
/* Called once by main(): buffers of up to 32 MiB come from the heap, and up to 256 MiB
 * freed at its top stay there. A photon pass's blob and scratch (megabytes, freed within
 * the pass) are then reused by the next pass instead of going back to the kernel, which
 * would hand them out again as fresh pages, each faulted in and cleared. */
void mem_keep_freed(void);

/* Formats into buf (always NUL-terminated, truncating); returns buf. For error strings. */
char *str_fmt(char *buf, size_t size, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

#endif
