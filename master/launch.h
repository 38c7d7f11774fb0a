/* Starting and stopping local worker processes (the one-command local render). */
#ifndef BRUME_LAUNCH_H
#define BRUME_LAUNCH_H
#include <stdint.h>
#include <sys/types.h>

/* Starts `exe --connect endpoint --threads threads --exit-with-parent` (with
 * `--curve-secret key_path --server-key server_pub_path` when key_path is not NULL, and
 * `--map-memory map_memory_mb` when it is not 0); returns the pid or -1 (logged). */
pid_t launch_worker(const char *exe, const char *endpoint, uint32_t threads, uint32_t map_memory_mb,
                    const char *key_path, const char *server_pub_path);
/* Reaps exited children without blocking: returns a pid that exited (status in *status)
 * or 0 if none. */
pid_t launch_reap(int *status);
/* Waits up to timeout_ms for the given pids to exit, then SIGKILLs the rest. */
void launch_stop_all(const pid_t *pids, uint32_t count, uint32_t timeout_ms);
/* Path of the worker binary next to the running executable. */
int launch_default_worker_exe(char *out, size_t outlen);

#endif
