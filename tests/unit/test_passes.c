/* Progressive photon-map passes (docs/media.md#progressive-passes): the radius schedule,
 * batch means on synthetic data, the pass loop of the integrator, the volume blob with P
 * maps, the scene keys, and a media scene whose average over passes converges to the
 * path tracer's image with an error estimate that sees the photon maps' error. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include "base/log.h"
#include "base/rng.h"
#include "master/opts.h"
#include "master/photons.h"
#include "render/integrator.h"
#include "render/passes.h"
#include "render/photon_map.h"
#include "scene/medium.h"
#include "scene/scene_limits.h"
#include "helpers.h"

/* ---- radius schedule ---- */

Test(passes, radius_schedule)
{
    const double a = 2.0 / 3.0;
    cr_assert_eq(photon_pass_radius(0.1, a, 0, 3), 0.1);
    cr_assert_eq(photon_pass_radius(0.1, a, 0, 2), 0.1);
    /* r_1^3 = r_0^3 (1 + alpha) / 2, r_2^3 = r_1^3 (2 + alpha) / 3; the same with squares in 2D. */
    cr_assert_float_eq(photon_pass_radius(1.0, a, 1, 3), cbrt(5.0 / 6.0), 1e-12);
    cr_assert_float_eq(photon_pass_radius(1.0, a, 2, 3), cbrt(5.0 / 6.0 * 8.0 / 9.0), 1e-12);
    cr_assert_float_eq(photon_pass_radius(1.0, a, 1, 2), sqrt(5.0 / 6.0), 1e-12);
    cr_assert_float_eq(photon_pass_radius(1.0, a, 2, 2), sqrt(5.0 / 6.0 * 8.0 / 9.0), 1e-12);
    cr_assert_float_eq(photon_pass_radius(2.0, 0.5, 3, 3), 2.0 * cbrt(0.75 * (2.5 / 3.0) * (3.5 / 4.0)), 1e-12);
    /* alpha = 1: the radius stays. */
    for (uint32_t p = 0; p < 100; p++) {
        cr_assert_float_eq(photon_pass_radius(0.3, 1.0, p, 3), 0.3, 1e-12);
        cr_assert_float_eq(photon_pass_radius(0.3, 1.0, p, 2), 0.3, 1e-12);
    }
    /* Monotone, the 2D radius below the 3D one, and r_p -> 0 as p^((alpha - 1) / dim):
     * r_p^dim p^(1 - alpha) tends to 1 / Gamma(1 + alpha). */
    double prev3 = 1.0, prev2 = 1.0;
    for (uint32_t p = 1; p <= 1024; p++) {
        double r3 = photon_pass_radius(1.0, a, p, 3), r2 = photon_pass_radius(1.0, a, p, 2);
        cr_assert(r3 < prev3 && r2 < prev2 && r2 < r3 && r2 > 0.0, "pass %u", p);
        prev3 = r3;
        prev2 = r2;
    }
    double r = photon_pass_radius(1.0, a, 1000000, 3);
    cr_assert(r < 0.25, "r %g", r);
    cr_assert_float_eq(r * r * r * pow(1e6, 1.0 - a), 1.0 / tgamma(1.0 + a), 1e-4);
}

/* ---- the default plan of passes ---- */

Test(passes, kernel_dims)
{
    /* beam: photon points against the ray, a 2D disc across it; march: a 3D sphere. */
    cr_assert_eq(passes_volume_kernel_dim(MEDIA_MARCH_BEAM), 2);
    cr_assert_eq(passes_volume_kernel_dim(MEDIA_MARCH_STEPS), 3);
    cr_assert_eq(PASSES_SURFACE_KERNEL_DIM, 2);
    /* Knaus and Zwicker's alpha for a 2D kernel, 4 / (d + 4), is the default. */
    cr_assert_float_eq(MEDIA_DEFAULT_ALPHA, 4.0f / (2.0f + 4.0f), 1e-7);
}

Test(passes, plan)
{
    struct pass_plan pl;
    /* Default: a pass per sample, so the maps (and the radius shrinkage) grow with spp;
     * photons per pass at most 8 emitted per pixel (here the stored cap, 3 / 0.35 per pixel,
     * is above it: a dense cloud, where most photons are never stored). */
    for (uint32_t spp = 1; spp * PASS_PHOTONS_PER_PIXEL * 128 * 128 <= PASS_MAX_PHOTONS; spp *= 2) {
        cr_assert_eq(passes_plan(spp, 0, 300000, 0, 0.35, 128 * 128, &pl), 0);
        cr_assert_eq(pl.passes, spp);
        cr_assert_eq(pl.spp_per_pass, 1u);
        cr_assert_eq(pl.spp, spp);
        cr_assert_eq(pl.photons, PASS_PHOTONS_PER_PIXEL * 128 * 128);
    }
    /* Fewer photons than the caps, or photons given on the command line: kept. */
    cr_assert_eq(passes_plan(8, 0, 50000, 0, 1.1, 160 * 120, &pl), 0);
    cr_assert_eq(pl.photons, 50000u);
    cr_assert_eq(passes_plan(8, 0, 300000, 1, 2.5, 128 * 128, &pl), 0);
    cr_assert_eq(pl.photons, 300000u);
    cr_assert_eq(pl.passes, 8u);
    /* All maps together stay within PASS_MAX_PHOTONS: then passes take more samples, and
     * spp is not raised more than one sample per pass. */
    cr_assert_eq(passes_plan(1000, 0, 32768, 1, 1.0, 1, &pl), 0);
    cr_assert(pl.passes * pl.photons <= PASS_MAX_PHOTONS);
    cr_assert_eq(pl.passes, 500u);
    cr_assert_eq(pl.spp_per_pass, 2u);
    cr_assert_eq(pl.spp, 1000u);
    cr_assert_eq(passes_plan(7, 0, PASS_MAX_PHOTONS * 4, 1, 1.0, 1, &pl), 0);
    cr_assert_eq(pl.passes, 1u);
    cr_assert_eq(pl.spp, 7u);
    /* Past SCENE_MAX_PASSES samples, passes take several each. */
    cr_assert_eq(passes_plan(5000, 0, 100, 0, 1.0, 1000, &pl), 0);
    cr_assert_eq(pl.passes, 1000u);
    cr_assert_eq(pl.spp_per_pass, 5u);
    /* An explicit count wins: ceil(spp / P) per pass, spp raised to P k, photons as given. */
    cr_assert_eq(passes_plan(10, 4, 300000, 0, 2.5, 128 * 128, &pl), 0);
    cr_assert_eq(pl.passes, 4u);
    cr_assert_eq(pl.spp_per_pass, 3u);
    cr_assert_eq(pl.spp, 12u);
    cr_assert_eq(pl.photons, 300000u);
    /* Over the spp limit: refused, with the plan that was asked for. */
    cr_assert_eq(passes_plan(SCENE_MAX_SPP, 1000, 100, 0, 1.0, 1, &pl), -1);
    cr_assert_eq(pl.spp, 0u);
    cr_assert_eq(pl.passes, 1000u);
}

Test(passes, plan_caps_stored_photons)
{
    struct pass_plan pl;
    /* Thin fog in a closed box: every photon is stored 2.5 times in the volume map, so the
     * maps' bytes and the beam queries' work go with 2.5 x the photons emitted; the stored
     * cap (3 per pixel) binds before the emitted one (8 per pixel). */
    cr_assert_eq(passes_plan(16, 0, 200000, 0, 2.5, 128 * 128, &pl), 0);
    cr_assert_eq(pl.photons, (uint64_t)(3.0 * 128 * 128 / 2.5));
    cr_assert_eq(pl.passes, 16u);
    cr_assert_eq(pl.spp_per_pass, 1u);
    /* Exactly at the emitted cap the stored one does not bind, nor when the pilot stored
     * nothing (no stored cap), and --photons is kept whatever the pilot says. */
    cr_assert_eq(passes_plan(16, 0, 200000, 0, 3.0 / PASS_PHOTONS_PER_PIXEL, 128 * 128, &pl), 0);
    cr_assert_eq(pl.photons, PASS_PHOTONS_PER_PIXEL * 128 * 128);
    cr_assert_eq(passes_plan(16, 0, 200000, 0, 0.0, 128 * 128, &pl), 0);
    cr_assert_eq(pl.photons, PASS_PHOTONS_PER_PIXEL * 128 * 128);
    cr_assert_eq(passes_plan(16, 0, 200000, 1, 2.5, 128 * 128, &pl), 0);
    cr_assert_eq(pl.photons, 200000u);
    /* A map that stores photons by the hundred per photon emitted keeps at least one. */
    cr_assert_eq(passes_plan(4, 0, 200000, 0, 1e9, 1, &pl), 0);
    cr_assert_eq(pl.photons, 1u);
}

/* The frames of a range must plan the same passes, and each frame's pilot (its own grid)
 * gives its own ratio: past the photons' total (spp x photons above PASS_MAX_PHOTONS) the
 * passes still come from the emitted cap alone, whatever the ratio. */
Test(passes, plan_passes_do_not_depend_on_the_pilot)
{
    struct pass_plan a, b, c;
    const uint64_t px = 256 * 256;
    cr_assert_eq(passes_plan(1024, 0, 300000, 0, 0.0, px, &a), 0);
    cr_assert_eq(passes_plan(1024, 0, 300000, 0, 0.3, px, &b), 0);
    cr_assert_eq(passes_plan(1024, 0, 300000, 0, 5.0, px, &c), 0);
    cr_assert_gt(a.spp_per_pass, 1u, "the case must reach the photons' total");
    cr_assert_eq(b.passes, a.passes);
    cr_assert_eq(c.passes, a.passes);
    cr_assert_eq(c.spp_per_pass, a.spp_per_pass);
    cr_assert_eq(c.spp, a.spp);
    cr_assert_lt(c.photons, a.photons, "the stored cap still lowers the photons");
}

/* ---- batch means ---- */

/* Standard normal draws from a counter-based generator (Box-Muller). */
static double normal(uint64_t key, uint32_t i)
{
    double u1 = 1.0 - rng_uniform(key, 2 * i), u2 = rng_uniform(key, 2 * i + 1);
    return sqrt(-2.0 * log(u1)) * cos(2.0 * M_PI * u2);
}

/* P pass means drawn with a known sigma per pixel: the pixel is their average, and over
 * many pixels the estimated variance of the mean is sigma^2 / P within a few %. */
Test(passes, batch_means_synthetic)
{
    const uint32_t pixels = 40000, P[] = {2, 4, 8, 16};
    const double sigma[3] = {0.5, 2.0, 0.01}, mu[3] = {1.0, -3.0, 0.25};
    for (size_t t = 0; t < sizeof P / sizeof *P; t++) {
        double sum_var[3] = {0, 0, 0}, sum_sq_err[3] = {0, 0, 0};
        for (uint32_t px = 0; px < pixels; px++) {
            struct pass_batch b;
            memset(&b, 0, sizeof b);
            double avg[3] = {0, 0, 0};
            for (uint32_t p = 0; p < P[t]; p++) {
                double m[3];
                for (int k = 0; k < 3; k++) {
                    m[k] = mu[k] + sigma[k] * normal(rng_key(7, t, px, p), (uint32_t)k);
                    avg[k] += m[k] / P[t];
                }
                pass_batch_add(&b, p % SAMPLER_STREAMS, m);
            }
            for (int k = 0; k < 3; k++) {
                cr_assert_float_eq(b.mean[k], avg[k], 1e-9 * (1.0 + fabs(avg[k])));
                sum_var[k] += pass_batch_var_of_mean(&b, k);
                sum_sq_err[k] += (b.mean[k] - mu[k]) * (b.mean[k] - mu[k]);
            }
        }
        for (int k = 0; k < 3; k++) {
            double want = sigma[k] * sigma[k] / P[t], est = sum_var[k] / pixels, actual = sum_sq_err[k] / pixels;
            cr_assert(fabs(est / want - 1.0) < 0.04, "P %u ch %d: estimate %g, sigma^2/P %g", P[t], k, est, want);
            cr_assert(fabs(actual / want - 1.0) < 0.04, "P %u ch %d: error %g, sigma^2/P %g", P[t], k, actual, want);
        }
    }
    struct pass_batch one;
    memset(&one, 0, sizeof one);
    pass_batch_add(&one, 0, (double[3]){1, 2, 3});
    cr_assert_eq(pass_batch_var_of_mean(&one, 0), 0.0);
}

/* Passes of a stream are one sample set, not independent: here the blocks of a stream
 * cancel in pairs (+z, -z, as a QMC sequence's blocks balance each other) plus a small
 * independent noise e, so a pass mean varies by z (sigma 1) while a stream of B blocks
 * varies only by e / B. The estimate over the stream means sees the true variance of the
 * pixel's mean, sigma_e^2 / P; one over the passes would report about 1 + sigma_e^2 / P. */
Test(passes, batch_means_over_streams_not_passes)
{
    const uint32_t pixels = 40000, R = SAMPLER_STREAMS, blocks[] = {2, 4, 8};
    const double sigma_e = 0.1, mu = 0.5;
    for (size_t t = 0; t < sizeof blocks / sizeof *blocks; t++) {
        uint32_t P = R * blocks[t];
        double sum_var = 0, sum_sq_err = 0;
        for (uint32_t px = 0; px < pixels; px++) {
            struct pass_batch b;
            memset(&b, 0, sizeof b);
            double z[SAMPLER_STREAMS] = {0};
            for (uint32_t p = 0; p < P; p++) {
                uint32_t stream = p % R, block = p / R;
                /* z of block 2j is undone by block 2j + 1 of the same stream. */
                if (block % 2 == 0)
                    z[stream] = normal(rng_key(9, t, px, p), 0);
                double v = mu + (block % 2 == 0 ? z[stream] : -z[stream]) + sigma_e * normal(rng_key(9, t, px, p), 1);
                pass_batch_add(&b, stream, (double[3]){v, v, v});
            }
            sum_var += pass_batch_var_of_mean(&b, 1);
            sum_sq_err += (b.mean[1] - mu) * (b.mean[1] - mu);
        }
        double want = sigma_e * sigma_e / P, est = sum_var / pixels, actual = sum_sq_err / pixels;
        cr_assert(fabs(actual / want - 1.0) < 0.05, "P %u: error %g, sigma_e^2/P %g", P, actual, want);
        cr_assert(fabs(est / want - 1.0) < 0.05, "P %u: estimate %g, sigma_e^2/P %g", P, est, want);
    }
}

/* ---- the scene ---- */

#define BOX_OBJ                                                                                             \
    "v -10 -10 -10\nv 10 -10 -10\nv 10 -10 10\nv -10 -10 10\nv -10 10 -10\nv 10 10 -10\nv 10 10 10\nv -10 10 10\n" \
    "f 1 4 3 2\nf 5 6 7 8\nf 4 8 7 3\nf 1 2 6 5\nf 1 5 8 4\nf 2 3 7 6\n"
/* A white floor: the square y = -1.2, |x|, |z| <= 4, facing up. */
#define FLOOR_OBJ "v -4 -1.2 -4\nv 4 -1.2 -4\nv 4 -1.2 4\nv -4 -1.2 4\nf 1 4 3 2\n"
static const struct mem_file g_files[] = {{"box.obj", BOX_OBJ, 0}, {"floor.obj", FLOOR_OBJ, 0}, {NULL, NULL, 0}};

/* A scattering sphere (albedo 0.9, optical radius 3) over a white floor, lit by a point
 * light, seen from above: volume and surface photon maps both matter. */
#define PASS_SCENE(method, w, photons, radius)                                                              \
    "{\"version\": 1,\n\"camera\": {\"position\": [0, 3, -4], \"look_at\": [0, -0.4, 0], \"fov_y\": 40},\n" \
    "\"render\": {\"width\": " #w ", \"height\": " #w ", \"spp\": 1, \"max_depth\": 32, \"tile_size\": 8},\n" \
    "\"materials\": {\"black\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0]},\n"                            \
    "  \"white\": {\"type\": \"diffuse\", \"albedo\": [0.8, 0.8, 0.8]}},\n"                                    \
    "\"media\": {\"m\": {\"sigma_a\": [0.3, 0.3, 0.3], \"sigma_s\": [2.7, 2.7, 2.7], \"g\": 0.2}},\n"            \
    "\"volume\": {\"method\": \"" method "\", \"photons\": " #photons ", \"radius\": " #radius                  \
    ", \"step\": 0.03},\n"                                                                                        \
    "\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"medium\": \"m\"},\n"          \
    "  {\"type\": \"obj\", \"file\": \"floor.obj\", \"material\": \"white\"},\n"                               \
    "  {\"type\": \"obj\", \"file\": \"box.obj\", \"material\": \"black\"}],\n"                                \
    "\"lights\": [{\"type\": \"point\", \"position\": [2, 2, -2], \"intensity\": [20, 20, 20]}]}"

static void load_ok(const char *text, struct scene *s)
{
    char err[512];
    cr_assert_eq(test_scene_load(text, g_files, s, err), 0, "%s", err);
}

/* The master's media preparation with `passes` passes (and spp per pass): the settings
 * blob applied to s as a worker applies it, and the maps the master's tracer thread
 * traces, decoded as a worker decodes them, chained in pass order. */
static struct photon_map *prepare(struct scene *s, uint32_t passes, uint32_t spp_per_pass, uint32_t *got)
{
    struct master_opts o;
    memset(&o, 0, sizeof o);
    o.photon_threads = 2;
    o.have_passes = 1;
    o.passes = passes;
    s->settings.spp = spp_per_pass * passes;
    struct asset_dir dir;
    memset(&dir, 0, sizeof dir);
    cr_assert_eq(master_media_prepare(s, &o, 0, &dir, passes, got), 0);
    cr_assert_eq(dir.num_files, 1u);
    cr_assert_eq(s->settings.spp, spp_per_pass * passes);
    struct photon_map *maps = NULL, **tail = &maps;
    char err[256];
    cr_assert_eq(volume_blob_apply(s, (const uint8_t *)dir.files[0].data, dir.files[0].size, &maps, err, sizeof err),
                 0, "%s", err);
    cr_assert_null(maps, "the settings blob holds no map");
    asset_dir_fini(&dir);
    struct photon_tracer *t = photon_tracer_new(s, &o, 0, *got, *got, err, sizeof err);
    cr_assert_not_null(t, "%s", err);
    for (uint32_t want = 0; want < *got;) {
        uint32_t pass;
        uint8_t *data;
        size_t size;
        double secs;
        int rc = photon_tracer_poll(t, &pass, &data, &size, &secs, NULL, NULL, err, sizeof err);
        cr_assert_geq(rc, 0, "%s", err);
        if (rc == 0) {
            struct timespec nap = {0, 2000000};
            nanosleep(&nap, NULL);
            continue;
        }
        cr_assert_eq(pass, want++, "maps come in pass order");
        cr_assert_eq(photon_map_decode(data, size, tail, err, sizeof err), 0, "%s", err);
        tail = &(*tail)->next_pass;
        free(data);
    }
    photon_tracer_free(&t, 0);
    return maps;
}

/* The bytes a decoded map holds by its layout (photon_map.h), the beam grid's struct
 * aside: the map's struct, its photons, bucket starts and decoded photons; for a volume map
 * its beam grid's records (position, depth, decoded photon) and row table: cells + 1 row
 * starts when flat, else a power of two of hash slots at least twice the rows. The cells
 * come from the photons' box (y and z) in cells of the grid's size. */
static size_t layout_bytes(const struct photon_map *m)
{
    if (!m)
        return 0;
    cr_assert_null(m->beams);
    size_t n = m->num_photons, b = sizeof *m + n * sizeof(struct photon) + ((size_t)m->table_size + 1) * 4;
    if (m->decoded)
        b += n * sizeof(struct photon_decoded);
    float cell;
    uint32_t rows, longest;
    int flat = photon_map_beam_layout(m, &cell, &rows, &longest);
    if (flat < 0)
        return b;
    b += n * (3 * sizeof(float) + sizeof(uint16_t) + sizeof(struct photon_decoded));
    if (flat) {
        size_t cells = 1;
        for (int a = 1; a < 3; a++) {
            float lo = m->photons[0].p[a], hi = lo;
            for (size_t i = 1; i < n; i++) {
                lo = fminf(lo, m->photons[i].p[a]);
                hi = fmaxf(hi, m->photons[i].p[a]);
            }
            float f = floorf((hi - lo) * (1.0f / cell));
            cells *= f > 0.0f ? (size_t)f + 1 : 1;
        }
        return b + (cells + 1) * sizeof(uint32_t);
    }
    size_t slots = 2;
    while (slots < 2 * (size_t)rows)
        slots <<= 1;
    return b + slots * 4 * sizeof(uint32_t);
}

/* The blob holds P maps with the radii of the schedule; beam's volume maps and the surface
 * maps shrink by the 2D rule; a damaged blob is refused. spp is raised to a multiple of the passes. */
Test(passes, volume_blob_maps)
{
    struct scene s;
    load_ok(PASS_SCENE("beam", 8, 2000, 0.1), &s);
    uint32_t n = 0;
    struct photon_map *maps = prepare(&s, 5, 1, &n);
    cr_assert_eq(n, 5u);
    uint32_t p = 0;
    size_t grid_struct = 0;
    for (const struct photon_map *m = maps; m; m = m->next_pass, p++) {
        cr_assert_float_eq(m->radius, (float)photon_pass_radius(0.1, 2.0 / 3.0, p, 2), 1e-7); /* beam: 2D */
        cr_assert_not_null(m->surface);
        cr_assert_float_eq(m->surface->radius, (float)photon_pass_radius(0.1, 2.0 / 3.0, p, 2), 1e-7);
        cr_assert(m->num_photons > 100);
        /* A worker budgets decoded maps by photon_map_bytes: each map of the chain once,
         * its bytes as the layout gives them, save the beam grid's own struct (a few
         * dozen fields, the same in every pass); the surface map's (no beam grid) exactly,
         * and with it a chain's end (NULL) counts nothing. */
        size_t own = photon_map_bytes(m) - photon_map_bytes(m->next_pass);
        size_t rest = layout_bytes(m) + layout_bytes(m->surface);
        cr_assert_eq(photon_map_bytes(m->surface), layout_bytes(m->surface), "pass %u: the surface map", p);
        cr_assert(own > rest && own <= rest + 256, "pass %u: %zu bytes, the layout gives %zu and a struct", p, own,
                  rest);
        if (p == 0)
            grid_struct = own - rest;
        cr_assert_eq(own - rest, grid_struct, "pass %u: the beam grid's struct counted as %zu bytes, pass 0's %zu", p,
                     own - rest, grid_struct);
    }
    cr_assert_eq(p, 5u);
    /* Different maps: each pass traces from its own seed. */
    cr_assert(maps->num_photons != maps->next_pass->num_photons ||
              memcmp(maps->photons, maps->next_pass->photons, 20) != 0);
    photon_map_free(&maps);

    /* No count asked: the master plans one pass per sample. */
    struct master_opts od;
    memset(&od, 0, sizeof od);
    od.photon_threads = 1;
    s.settings.spp = 3;
    struct asset_dir dd;
    memset(&dd, 0, sizeof dd);
    cr_assert_eq(master_media_prepare(&s, &od, 0, &dd, 0, &n), 0);
    cr_assert_eq(n, 3u);
    cr_assert_eq(s.settings.spp, 3u);
    asset_dir_fini(&dd);

    /* Not a multiple: ceil(spp / P) per pass. */
    struct master_opts o;
    memset(&o, 0, sizeof o);
    o.photon_threads = 1;
    o.have_passes = 1;
    o.passes = 3;
    o.have_photons = 1;
    o.photons = 500;
    o.have_indirect = 1; /* --indirect path: travels in the blob */
    o.indirect = MEDIA_INDIRECT_PATH;
    s.settings.spp = 4;
    struct asset_dir dir;
    memset(&dir, 0, sizeof dir);
    cr_assert_eq(master_media_prepare(&s, &o, 0, &dir, o.have_passes ? o.passes : 0, &n), 0);
    cr_assert_eq(n, 3u);
    cr_assert_eq(s.settings.spp, 6u);
    /* Decoding: the settings blob as made (no maps: they are blobs of their own), then
     * truncated or altered. */
    const uint8_t *b = (const uint8_t *)dir.files[0].data;
    size_t size = dir.files[0].size;
    struct scene_media st;
    memset(&st, 0, sizeof st);
    uint32_t count;
    char err[256];
    cr_assert_eq(volume_blob_decode(b, size, &st, &maps, &count, err, sizeof err), 0, "%s", err);
    cr_assert_eq(count, 0u);
    cr_assert_null(maps);
    cr_assert_float_eq(st.alpha, 2.0f / 3.0f, 1e-7);
    cr_assert_eq(st.indirect, MEDIA_INDIRECT_PATH);
    photon_map_free(&maps);
    for (size_t cut = 0; cut < size; cut += 1 + cut / 7) {
        cr_assert_neq(volume_blob_decode(b, cut, &st, &maps, &count, err, sizeof err), 0, "cut %zu", cut);
        cr_assert_null(maps);
    }
    uint8_t *bad = mem_alloc(size + 1);
    memcpy(bad, b, size);
    bad[size] = 0;
    cr_assert_neq(volume_blob_decode(bad, size + 1, &st, &maps, &count, err, sizeof err), 0); /* trailing byte */
    bad[20] = 1; /* one map more than there are */
    cr_assert_neq(volume_blob_decode(bad, size, &st, &maps, &count, err, sizeof err), 0);
    bad[20] = 0;
    bad[36] = MEDIA_INDIRECT_COUNT_; /* no such indirect mode */
    cr_assert_neq(volume_blob_decode(bad, size, &st, &maps, &count, err, sizeof err), 0);
    bad[36] = MEDIA_INDIRECT_PATH;
    memset(bad + 32, 0, 4); /* alpha 0 */
    cr_assert_neq(volume_blob_decode(bad, size, &st, &maps, &count, err, sizeof err), 0);
    free(bad);
    asset_dir_fini(&dir);

    /* VPT and photons 0: no maps (one pass). */
    s.media->method = MEDIA_VPT;
    memset(&dir, 0, sizeof dir);
    s.settings.spp = 4;
    cr_assert_eq(master_media_prepare(&s, &o, 0, &dir, o.have_passes ? o.passes : 0, &n), 0);
    cr_assert_eq(n, 0u);
    cr_assert_eq(s.settings.spp, 4u);
    asset_dir_fini(&dir);
    scene_fini(&s);
}

/* The pass loop: with the same map in every pass, the average of the pass means estimates
 * what one pass of all the samples does (the passes are independent randomisations of the
 * samples, so not the same points: agreement within noise, image mean within 4 standard
 * errors); the batch-means variance then estimates the camera noise alone, like the
 * sample variance. */
Test(passes, pass_average_same_maps)
{
    struct scene s;
    load_ok(PASS_SCENE("beam", 8, 3000, 0.1), &s);
    uint32_t n;
    struct photon_map *one = prepare(&s, 1, 1, &n);
    cr_assert_eq(n, 1u);
    /* A chain of 4 decoded copies of the one map. */
    struct master_opts o;
    (void)o;
    struct photon_map *chain = NULL;
    for (int i = 0; i < 4; i++) {
        struct scene t;
        load_ok(PASS_SCENE("beam", 8, 3000, 0.1), &t);
        struct photon_map *m = prepare(&t, 1, 1, &n);
        m->next_pass = chain;
        chain = m;
        scene_fini(&t);
    }
    s.settings.spp = 32;
    struct tile_stats st1, st4;
    float *a = test_render_map(&s, one, 1, &st1);
    float *b = test_render_map(&s, chain, 1, &st4);
    cr_assert_eq(st1.samples, st4.samples);
    double var1 = 0, var4 = 0, sum1 = 0, sum4 = 0;
    for (uint32_t i = 0; i < 64; i++) {
        for (int k = 0; k < 3; k++) {
            sum1 += a[i * TILE_NUM_CHANNELS + CH_R + k];
            sum4 += b[i * TILE_NUM_CHANNELS + CH_R + k];
            var1 += a[i * TILE_NUM_CHANNELS + CH_VAR_R + k];
            var4 += b[i * TILE_NUM_CHANNELS + CH_VAR_R + k];
        }
        cr_assert_eq(a[i * TILE_NUM_CHANNELS + CH_A], b[i * TILE_NUM_CHANNELS + CH_A]);
    }
    cr_assert(fabs(sum1 - sum4) <= 4.0 * sqrt(var1 + var4), "image sums %g vs %g, sd %g", sum1, sum4,
              sqrt(var1 + var4));
    cr_assert(var4 > 0.4 * var1 && var4 < 2.5 * var1, "batch %g vs sample %g", var4, var1);
    free(a);
    free(b);
    photon_map_free(&one);
    photon_map_free(&chain);
    scene_fini(&s);
}

/* ---- convergence ---- */

struct image_error {
    double rel_rmse;      /* against the reference, its own variance taken out */
    double rel_rmse_est;  /* from the variance channels */
};

static struct image_error compare(const float *px, const float *ref, uint32_t n)
{
    double se = 0, ref_var = 0, var = 0, mean = 0;
    for (uint32_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) {
            double d = (double)px[i * TILE_NUM_CHANNELS + CH_R + k] - ref[i * TILE_NUM_CHANNELS + CH_R + k];
            se += d * d;
            ref_var += ref[i * TILE_NUM_CHANNELS + CH_VAR_R + k];
            var += px[i * TILE_NUM_CHANNELS + CH_VAR_R + k];
            mean += ref[i * TILE_NUM_CHANNELS + CH_R + k];
        }
    mean /= 3.0 * n;
    struct image_error e = {sqrt(fmax(0.0, se - ref_var) / (3.0 * n)) / mean, sqrt(var / (3.0 * n)) / mean};
    return e;
}

/* Passes with fixed photons per pass (few: the maps' error dominates the camera noise of
 * 32 spp per pass) converge toward the path tracer: the error against a long VPT render
 * falls as P grows (1, 4, 16), one pass's sample variance is blind to the map's error, and
 * the batch-means estimate is within a factor 1.5 of the error (1.75 below: bias). */
Test(passes, converges_to_vpt, .timeout = 300)
{
    struct scene s;
    load_ok(PASS_SCENE("vpt", 12, 8000, 0.12), &s);
    const uint32_t n = 12 * 12;
    s.settings.spp = 4096;
    struct tile_stats st;
    float *ref = test_render_map(&s, NULL, 1, &st);
    double err[3] = {0, 0, 0};
    const uint32_t P[3] = {1, 4, 16};
    for (int t = 0; t < 3; t++) {
        scene_fini(&s);
        load_ok(PASS_SCENE("beam", 12, 8000, 0.12), &s);
        uint32_t got;
        struct photon_map *maps = prepare(&s, P[t], 32, &got);
        cr_assert_eq(got, P[t]);
        float *px = test_render_map(&s, maps, 1, &st);
        cr_assert_eq(st.nan_samples, 0u);
        for (uint32_t i = 0; i < n * TILE_NUM_CHANNELS; i++)
            cr_assert(isfinite(px[i]));
        struct image_error e = compare(px, ref, n);
        err[t] = e.rel_rmse;
        fprintf(stderr, "passes %2u: relRMSE against vpt %.4f, estimated %.4f (ratio %.2f)\n", P[t], e.rel_rmse,
                e.rel_rmse_est, e.rel_rmse_est / e.rel_rmse);
        if (P[t] == 1) /* measured ratio 0.51 */
            cr_assert(e.rel_rmse_est < 0.6 * e.rel_rmse, "one pass: estimate %g, error %g", e.rel_rmse_est,
                      e.rel_rmse);
        else /* Below: the kernels' bias (blur at the sphere's edge, 2 % of the mean here), which
              * no spread between passes shows, is part of the error, and the larger part the
              * less noise the maps have (measured ratios 0.78 and 0.57 for P = 4 and 16 with
              * heavy photons split, 0.75 and 0.63 without). */
            cr_assert(e.rel_rmse_est > e.rel_rmse / 2.0 && e.rel_rmse_est < e.rel_rmse * 1.5,
                      "passes %u: estimate %g, error %g", P[t], e.rel_rmse_est, e.rel_rmse);
        free(px);
        photon_map_free(&maps);
    }
    /* The error falls from 1 to 4 to 16 passes (0.083, 0.055, 0.041 measured): with the
     * final gather the surface map's noise is small, and with heavy photons split the
     * volume maps' noise too, so what is left at 4 passes and more is mostly the kernels'
     * bias, which shrinks slowly with the radius (0.12 to 0.105 after 4 passes, 0.091
     * after 16: the bias as r^2 by 0.75). */
    cr_assert(err[1] < 1.01 * err[0] && err[2] < 0.85 * err[1] && err[2] < 0.6 * err[0], "errors %g %g %g", err[0],
              err[1], err[2]);
    free(ref);
    scene_fini(&s);
}

/* ---- scene keys ---- */

Test(passes, scene_keys)
{
    struct scene s;
    char err[512];
    cr_assert_eq(test_scene_load("{\"version\": 1, \"camera\": {\"position\": [0, 0, -4], \"look_at\": [0, 0, 0], "
                                 "\"fov_y\": 40}, \"render\": {\"width\": 4, \"height\": 4, \"passes\": 16}}",
                                 NULL, &s, err),
                 0, "%s", err);
    cr_assert_eq(s.settings.passes, 16u);
    scene_fini(&s);
    test_scene_expect_error("{\"version\": 1, \"camera\": {\"position\": [0, 0, -4], \"look_at\": [0, 0, 0], "
                            "\"fov_y\": 40}, \"render\": {\"width\": 4, \"height\": 4, \"passes\": 0}}",
                            NULL, "passes");
    test_scene_expect_error("{\"version\": 1, \"camera\": {\"position\": [0, 0, -4], \"look_at\": [0, 0, 0], "
                            "\"fov_y\": 40}, \"render\": {\"width\": 4, \"height\": 4, \"passes\": 1025}}",
                            NULL, "passes");
    load_ok(PASS_SCENE("beam", 4, 100, 0.1), &s);
    cr_assert_eq(s.media->alpha, 0.0f); /* unset: MEDIA_DEFAULT_ALPHA */
    scene_fini(&s);
    const char *e = test_scene_expect_error(
        "{\"version\": 1, \"camera\": {\"position\": [0, 0, -4], \"look_at\": [0, 0, 0], \"fov_y\": 40},"
        "\"render\": {\"width\": 4, \"height\": 4}, \"media\": {\"m\": {\"sigma_a\": [1, 1, 1]}},"
        "\"volume\": {\"fog\": \"m\", \"alpha\": 1.5}}",
        NULL, "alpha must be in (0, 1]");
    (void)e;
}
