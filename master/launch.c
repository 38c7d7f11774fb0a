/* Local worker processes (see launch.h). Workers inherit stderr so their log lines reach
 * the user; stdin and stdout are detached. */
#include "launch.h"
#include "base/log.h"
#include <errno.h>
#include <fcntl.h>
#include <libgen.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

extern char **environ;

pid_t launch_worker(const char *exe, const char *endpoint, uint32_t threads, uint32_t map_memory_mb,
                    const char *key_path, const char *server_pub_path)
{
    /* posix_spawn wants mutable strings: give it copies. */
    char exe_s[4096], connect_s[] = "--connect", endpoint_s[1024], threads_opt[] = "--threads", threads_s[16];
    char parent_s[] = "--exit-with-parent", secret_opt[] = "--curve-secret", server_opt[] = "--server-key";
    char map_opt[] = "--map-memory", map_s[16];
    char key_s[1024] = "", pub_s[1024] = "";
    snprintf(exe_s, sizeof exe_s, "%s", exe);
    snprintf(endpoint_s, sizeof endpoint_s, "%s", endpoint);
    snprintf(threads_s, sizeof threads_s, "%u", threads);
    snprintf(map_s, sizeof map_s, "%u", map_memory_mb);
    char *argv_full[13] = {exe_s, connect_s, endpoint_s, threads_opt, threads_s, parent_s, NULL};
    int n = 6;
    if (key_path) {
        snprintf(key_s, sizeof key_s, "%s", key_path);
        snprintf(pub_s, sizeof pub_s, "%s", server_pub_path);
        argv_full[n++] = secret_opt;
        argv_full[n++] = key_s;
        argv_full[n++] = server_opt;
        argv_full[n++] = pub_s;
    }
    if (map_memory_mb > 0) {
        argv_full[n++] = map_opt;
        argv_full[n++] = map_s;
    }
    CHECK(n < (int)(sizeof argv_full / sizeof *argv_full));
    argv_full[n] = NULL;
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    pid_t pid;
    int rc = posix_spawn(&pid, exe, &fa, NULL, argv_full, environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) {
        log_error("cannot start worker %s: %s", exe, strerror(rc));
        return -1;
    }
    return pid;
}

pid_t launch_reap(int *status)
{
    pid_t p = waitpid(-1, status, WNOHANG);
    return p > 0 ? p : 0;
}

void launch_stop_all(const pid_t *pids, uint32_t count, uint32_t timeout_ms)
{
    struct timespec nap = {0, 20 * 1000000L};
    uint32_t waited = 0;
    for (;;) {
        uint32_t alive = 0;
        for (uint32_t i = 0; i < count; i++)
            if (pids[i] > 0 && kill(pids[i], 0) == 0) {
                int st;
                if (waitpid(pids[i], &st, WNOHANG) == 0)
                    alive++;
            }
        if (alive == 0 || waited >= timeout_ms)
            break;
        nanosleep(&nap, NULL);
        waited += 20;
    }
    for (uint32_t i = 0; i < count; i++)
        if (pids[i] > 0 && kill(pids[i], 0) == 0) {
            kill(pids[i], SIGKILL);
            waitpid(pids[i], NULL, 0);
        }
}

int launch_default_worker_exe(char *out, size_t outlen)
{
    char self[4096];
    ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    if (n <= 0)
        return -1;
    self[n] = '\0';
    snprintf(out, outlen, "%s/worker", dirname(self));
    return access(out, X_OK) == 0 ? 0 : -1;
}
