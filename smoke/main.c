/* smokesim: runs a stable-fluids smoke simulation from a JSON settings file and writes one
 * density grid per frame, resumably (docs/smoke.md).
 * Usage: smokesim SETTINGS.json [--out DIR] [--threads N] [--restart]
 *                 [--bench STEPS [--res N] [--warmup STEPS]] */
#include "base/cli.h"
#include "base/log.h"
#include "fluid.h"
#include "settings.h"
#include "store.h"
#include <libgen.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static void usage(void)
{
    fprintf(stderr, "usage: smokesim SETTINGS.json [--out DIR] [--threads N] [--restart] "
                    "[--bench STEPS [--res N] [--warmup STEPS]]\n");
    exit(2);
}

static char *read_file(const char *path, size_t *len)
{
    FILE *fp = fopen(path, "rb");
    if (!fp)
        return NULL;
    size_t cap = 4096, n = 0;
    char *buf = mem_alloc(cap);
    size_t got;
    while ((got = fread(buf + n, 1, cap - n, fp)) > 0) {
        n += got;
        if (n == cap) {
            if (cap >= (1u << 24))
                break;  /* settings are small; the parser reports the cut */
            cap *= 2;
            buf = mem_realloc(buf, cap);
        }
    }
    fclose(fp);
    *len = n;
    return buf;
}

static void phase_report(const struct fluid *f, uint64_t steps)
{
    double total = 0.0;
    for (int p = 0; p < PH_COUNT_; p++)
        total += f->cpu[p];
    fprintf(stderr, "smokesim: CPU per step %.2f ms:", 1e3 * total / (double)(steps ? steps : 1));
    for (int p = 0; p < PH_COUNT_; p++)
        fprintf(stderr, " %s %.1f%%", fluid_phase_names[p], total > 0 ? 100.0 * f->cpu[p] / total : 0.0);
    fprintf(stderr, "\n");
}

int main(int argc, char **argv)
{
    log_set_prefix("smokesim");
    const char *settings_path = NULL, *out_dir = NULL;
    uint64_t threads = 0, bench = 0, res = 0, warmup = 0;
    int restart = 0;
    char err[1024];
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (strcmp(a, "--out") == 0 && i + 1 < argc) {
            out_dir = argv[++i];
        } else if (strcmp(a, "--threads") == 0 && i + 1 < argc) {
            if (cli_parse_u64(a, argv[++i], 1, 256, &threads, err, sizeof err) != 0) {
                fprintf(stderr, "smokesim: %s\n", err);
                return 2;
            }
        } else if (strcmp(a, "--bench") == 0 && i + 1 < argc) {
            if (cli_parse_u64(a, argv[++i], 1, 100000, &bench, err, sizeof err) != 0) {
                fprintf(stderr, "smokesim: %s\n", err);
                return 2;
            }
        } else if (strcmp(a, "--warmup") == 0 && i + 1 < argc) {
            if (cli_parse_u64(a, argv[++i], 0, 100000, &warmup, err, sizeof err) != 0) {
                fprintf(stderr, "smokesim: %s\n", err);
                return 2;
            }
        } else if (strcmp(a, "--res") == 0 && i + 1 < argc) {
            if (cli_parse_u64(a, argv[++i], SMOKE_MIN_RES, SMOKE_MAX_RES, &res, err, sizeof err) != 0) {
                fprintf(stderr, "smokesim: %s\n", err);
                return 2;
            }
        } else if (strcmp(a, "--restart") == 0) {
            restart = 1;
        } else if (a[0] == '-' || settings_path) {
            usage();
        } else {
            settings_path = a;
        }
    }
    if (!settings_path)
        usage();
    size_t len = 0;
    char *text = read_file(settings_path, &len);
    if (!text) {
        fprintf(stderr, "smokesim: %s: cannot read\n", settings_path);
        return 1;
    }
    struct smoke_settings s;
    if (smoke_settings_parse(settings_path, text, len, &s, err, sizeof err) != 0) {
        fprintf(stderr, "smokesim: %s\n", err);
        free(text);
        return 1;
    }
    free(text);
    if (threads)
        s.threads = (uint32_t)threads;
    if (res) {
        /* Bench: same physical setup at another resolution (sponge scaled with it). */
        s.sponge_width = (uint32_t)((uint64_t)s.sponge_width * res / s.res[0]);
        for (int a = 1; a < 3; a++)
            s.res[a] = (uint32_t)((uint64_t)s.res[a] * res / s.res[0]);
        s.res[0] = (uint32_t)res;
        if (smoke_settings_check(&s, err, sizeof err) != 0) {
            fprintf(stderr, "smokesim: --res %llu: %s\n", (unsigned long long)res, err);
            return 1;
        }
    }
    struct fluid f;
    fluid_init(&f, &s);
    if (bench) {
        /* Untimed steps first: the plume grows, and the temperature's support with it. */
        for (uint64_t i = 0; i < warmup; i++)
            fluid_step(&f);
        memset(f.cpu, 0, sizeof f.cpu);
        memset(f.wall, 0, sizeof f.wall);
        double t0 = now_s();
        for (uint64_t i = 0; i < bench; i++)
            fluid_step(&f);
        double wall = now_s() - t0;
        double cpu = 0.0;
        for (int p = 0; p < PH_COUNT_; p++)
            cpu += f.cpu[p];
        struct rusage ru;
        getrusage(RUSAGE_SELF, &ru);
        /* The last state as a frame of each format (the .nvdb encoded in memory). */
        uint8_t *nv = NULL;
        size_t nv_bytes = 0;
        uint64_t active = 0;
        if (store_encode_nvdb(&f, &nv, &nv_bytes, &active, err, sizeof err) != 0) {
            fprintf(stderr, "smokesim: %s\n", err);
            fluid_free(&f);
            return 1;
        }
        free(nv);
        printf("res %ux%ux%u threads %u warmup %llu steps %llu wall_ms_per_step %.2f cpu_ms_per_step %.2f "
               "fft_ms %.2f advect_ms %.2f fft_share %.3f advect_share %.3f maxrss_kib %ld bytes_per_voxel %zu "
               "grid_bytes %zu nvdb_bytes %zu nvdb_voxels %llu fft_wall_ms %.2f advect_wall_ms %.2f\n",
               f.nx, f.ny, f.nz, s.threads, (unsigned long long)warmup, (unsigned long long)bench,
               1e3 * wall / (double)bench, 1e3 * cpu / (double)bench, 1e3 * f.cpu[PH_FFT] / (double)bench,
               1e3 * f.cpu[PH_ADVECT] / (double)bench, cpu > 0 ? f.cpu[PH_FFT] / cpu : 0.0,
               cpu > 0 ? f.cpu[PH_ADVECT] / cpu : 0.0, ru.ru_maxrss, fluid_bytes_per_voxel(), store_grid_bytes(&f),
               nv_bytes, (unsigned long long)active, 1e3 * f.wall[PH_FFT] / (double)bench,
               1e3 * f.wall[PH_ADVECT] / (double)bench);
        phase_report(&f, bench);
        fluid_free(&f);
        return 0;
    }
    char dirbuf[1024];
    if (!out_dir) {
        snprintf(dirbuf, sizeof dirbuf, "%s", settings_path);
        out_dir = dirname(dirbuf);
    }
    char ckpt[1400], pat[1400], path[1400];
    snprintf(pat, sizeof pat, "%s/%s", out_dir, s.output);
    const char *hash = strchr(s.output, '#');
    snprintf(ckpt, sizeof ckpt, "%s/%.*scheckpoint", out_dir, (int)(hash - s.output), s.output);
    uint32_t done = 0;
    if (!restart) {
        int rc = store_read_checkpoint(ckpt, &f, &done, err, sizeof err);
        if (rc < 0) {
            fprintf(stderr, "smokesim: %s\n", err);
            fluid_free(&f);
            return 1;
        }
        if (rc == 1)
            fprintf(stderr, "smokesim: resuming from %s after frame %u (step %llu)\n", ckpt, done,
                    (unsigned long long)f.step);
    }
    if (done >= s.frames)
        fprintf(stderr, "smokesim: all %u frames are done (%s)\n", s.frames, ckpt);
    double t0 = now_s();
    uint64_t steps_run = 0, total_steps = (uint64_t)(s.frames - (done < s.frames ? done : s.frames)) *
                                          s.steps_per_frame;
    size_t bytes = 0;
    for (uint32_t frame = done + 1; frame <= s.frames; frame++) {
        size_t frame_bytes = 0;
        for (uint32_t k = 0; k < s.steps_per_frame; k++) {
            fluid_step(&f);
            steps_run++;
        }
        if (smoke_frame_name(pat, frame, path, sizeof path) != 0 ||
            store_write_frame(path, &f, &frame_bytes, err, sizeof err) != 0 ||
            store_write_checkpoint(ckpt, &f, frame, err, sizeof err) != 0) {
            fprintf(stderr, "smokesim: frame %u: %s\n", frame, err[0] ? err : "bad output name");
            fluid_free(&f);
            return 1;
        }
        bytes += frame_bytes;
        double el = now_s() - t0, per = el / (double)steps_run;
        double eta = per * (double)(total_steps - steps_run);
        fprintf(stderr, "smokesim: frame %u/%u step %llu/%llu %.1f ms/step ETA %dm%02ds %s\n", frame, s.frames,
                (unsigned long long)f.step, (unsigned long long)s.frames * s.steps_per_frame, 1e3 * per,
                (int)(eta / 60), (int)eta % 60, path);
    }
    double el = now_s() - t0;
    fprintf(stderr, "smokesim: done: %llu steps in %.1f s (%.1f ms/step), %zu bytes of grids written (dense: %zu), %ux%ux%u, "
                    "checkpoint %s\n",
            (unsigned long long)steps_run, el, steps_run ? 1e3 * el / (double)steps_run : 0.0, bytes,
            store_grid_bytes(&f) * (s.frames - done), f.nx, f.ny,
            f.nz, ckpt);
    if (steps_run)
        phase_report(&f, steps_run);
    fluid_free(&f);
    return 0;
}
