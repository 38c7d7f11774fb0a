/* Participating media against known answers and invariants:
 * - Beer-Lambert through a homogeneous slab (shadow rays and camera rays), exact to float
 *   precision, for sigma_t from 1e-6 to 1e6;
 * - single scattering from a point light in an isotropic medium against the airlight
 *   integral (quadrature in double), within 1 %, and from a small area light close to the
 *   ray (equiangular sampling toward a point on the light) within noise;
 * - a media white furnace (albedo 1, uniform surroundings) with the volumetric path tracer;
 * - Henyey-Greenstein: normalisation and a chi-square test of sampling, g up to +-0.999;
 * - the photon map (beam and per-step estimates) against the path tracer on a
 *   multiple-scattering scene, and its bytes for 1 and 2 threads;
 * - hard cases stay finite; scene keys and their errors. */
#include <criterion/criterion.h>
#include <malloc.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "wire/blob.h"
#include "render/integrator.h"
#include "base/log.h"
#include "render/media_integrator.h"
#include "scene/medium.h"
#include "render/photon_map.h"
#include "render/photon_beams.h"
#include "render/photon_trace.h"
#include "render/media_track.h"
#include "scene/grid.h"
#include "base/rng.h"
#include "scene/scene_json.h"
#include "helpers.h"

/* A 20-unit cube around the origin with faces wound inwards. */
#define BOX_OBJ                                                                                             \
    "v -10 -10 -10\nv 10 -10 -10\nv 10 -10 10\nv -10 -10 10\nv -10 10 -10\nv 10 10 -10\nv 10 10 10\nv -10 10 10\n" \
    "f 1 4 3 2\nf 5 6 7 8\nf 4 8 7 3\nf 1 2 6 5\nf 1 5 8 4\nf 2 3 7 6\n"

/* The same cube wound outwards: a medium's boundary (outside = where normals point). */
#define BOX_OUT_OBJ                                                                                         \
    "v -10 -10 -10\nv 10 -10 -10\nv 10 -10 10\nv -10 -10 10\nv -10 10 -10\nv 10 10 -10\nv 10 10 10\nv -10 10 10\n" \
    "f 1 2 3 4\nf 5 8 7 6\nf 4 3 7 8\nf 1 5 6 2\nf 1 4 8 5\nf 2 6 7 3\n"

/* An 8^3 grid with a smooth, lopsided density and an empty corner region (filled by
 * grid_bytes()). */
#define GN 8
static uint8_t g_grid[20 + 4 * GN * GN * GN];
/* A white floor: the square y = -1.2, |x|, |z| <= 4, facing up. */
#define FLOOR_OBJ "v -4 -1.2 -4\nv 4 -1.2 -4\nv 4 -1.2 4\nv -4 -1.2 4\nf 1 4 3 2\n"
/* A small lamp: the square y = 0.3, |x|, |z| <= 0.25, emitting downwards (-y). */
#define LAMP_OBJ "v -0.25 0.3 -0.25\nv 0.25 0.3 -0.25\nv 0.25 0.3 0.25\nv -0.25 0.3 0.25\nf 1 2 3 4\n"
static struct mem_file g_files[] = {{"box.obj", BOX_OBJ, 0}, {"box_out.obj", BOX_OUT_OBJ, 0}, {"floor.obj", FLOOR_OBJ, 0},
                                    {"lamp.obj", LAMP_OBJ, 0},
                                    {"g.grid", (const char *)g_grid, sizeof g_grid}, {NULL, NULL, 0}};

static float grid_value(int x, int y, int z)
{
    if (x < 2 && y < 2)
        return 0.0f; /* empty space next to dense voxels */
    return (float)(x + 1) * (float)(1 + (y * 3 + z) % 5) * 0.25f + (x == 5 && y == 5 && z == 5 ? 20.0f : 0.0f);
}

static void grid_bytes(void)
{
    memcpy(g_grid, GRID_MAGIC, 8);
    uint32_t n = GN;
    for (int k = 0; k < 3; k++)
        memcpy(g_grid + 8 + 4 * k, &n, 4);
    for (int z = 0; z < GN; z++)
        for (int y = 0; y < GN; y++)
            for (int x = 0; x < GN; x++) {
                float v = grid_value(x, y, z);
                memcpy(g_grid + 20 + 4 * ((z * GN + y) * GN + x), &v, 4);
            }
}

static int load(const char *text, struct scene *s, char *err)
{
    grid_bytes();
    return test_scene_load(text, g_files, s, err);
}

static void load_ok(const char *text, struct scene *s)
{
    char err[512] = "";
    int rc = load(text, s, err);
    cr_assert_eq(rc, 0, "parse failed: %s", err);
}

static void job_ok(struct render_job *job, const struct scene *s)
{
    char err[512] = "";
    cr_assert_eq(render_job_init(job, s, 0, 1, err, sizeof err), 0, "%s", err);
}

#define HEAD(cam, w, h, spp, depth)                                                                       \
    "{\"version\": 1,\n\"camera\": {" cam ", \"fov_y\": 40},\n\"render\": {\"width\": " #w ", \"height\": " #h \
    ", \"spp\": " #spp ", \"max_depth\": " #depth ", \"tile_size\": 8}"

/* ---- Beer-Lambert ---- */

/* exp(-sigma_t d) in double, apart from the code under test: a float result is within a
 * few float roundings of it (the product sigma_t d rounded, then expf), relative to the
 * optical depth; past float's range both are 0 or subnormal. */
static void tr_near(float got, float sigma_t, float d, const char *what)
{
    double x = (double)sigma_t * d, want = exp(-x);
    cr_assert(fabs(got - want) <= 3e-7 * (1.0 + x) * want + 1e-44, "%s: sigma_t %g, d %g: %.9g, exp(-%g) = %.9g",
              what, (double)sigma_t, (double)d, (double)got, x, want);
}

Test(medium, transmittance_closed_form)
{
    struct medium m;
    memset(&m, 0, sizeof m);
    float sig[] = {1e-6f, 1e-3f, 0.5f, 1.0f, 37.0f, 1e3f, 1e6f};
    for (size_t i = 0; i < sizeof sig / sizeof *sig; i++) {
        m.sigma_t = v3(sig[i], 2 * sig[i], 0.0f);
        vec3 t = medium_transmittance(&m, 0.75f);
        tr_near(t.x, sig[i], 0.75f, "red");
        tr_near(t.y, 2 * sig[i], 0.75f, "green");
        cr_assert_eq(t.z, 1.0f);
        vec3 inf = medium_transmittance(&m, INFINITY);
        cr_assert(inf.x == 0.0f && inf.z == 1.0f);
        /* grey (one exponential for the three channels): the same bits per channel; and a
         * medium grey in two channels only takes each its own */
        m.sigma_t = v3(sig[i], sig[i], sig[i]);
        t = medium_transmittance(&m, 0.75f);
        tr_near(t.x, sig[i], 0.75f, "grey");
        cr_assert(t.y == t.x && t.z == t.x);
        m.sigma_t = v3(sig[i], sig[i], 3 * sig[i]);
        t = medium_transmittance(&m, 0.75f);
        tr_near(t.x, sig[i], 0.75f, "grey in two, red");
        cr_assert(t.y == t.x);
        tr_near(t.z, 3 * sig[i], 0.75f, "grey in two, blue");
    }
}

/* A slab: a medium box 2 units thick (x in [-1, 1]) inside invisible boundaries; shadow
 * rays and camera rays through it see exactly exp(-sigma_t 2). */
Test(medium, beer_lambert_slab)
{
    float sig[] = {1e-6f, 0.01f, 0.7f, 3.0f, 40.0f, 1e6f};
    for (size_t i = 0; i < sizeof sig / sizeof *sig; i++) {
        char text[2048];
        snprintf(text, sizeof text,
                 HEAD("\"position\": [-5, 0, 0], \"look_at\": [0, 0, 0]", 1, 1, 1, 1)
                 ",\n\"materials\": {\"lamp\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0], \"emission\": [2, 2, 2]}},\n"
                 "\"media\": {\"m\": {\"sigma_a\": [%.9g, %.9g, %.9g]}},\n"
                 "\"volume\": {\"method\": \"march\"},\n"
                 "\"objects\": [{\"type\": \"obj\", \"file\": \"box_out.obj\", \"medium\": \"m\",\n"
                 "  \"transform\": {\"scale\": [0.1, 0.3, 0.3]}},\n"
                 "  {\"type\": \"sphere\", \"center\": [50, 0, 0], \"radius\": 20, \"material\": \"lamp\"}]}",
                 (double)sig[i], (double)(0.5f * sig[i]), 0.0);
        struct scene s;
        load_ok(text, &s);
        struct render_job job;
        job_ok(&job, &s);
        uint64_t rays = 0;
        float expect = expf(-sig[i] * 2.0f);
        vec3 tr = media_shadow_transmittance(job.media, v3(-5, 0.1f, 0), v3(5, 0.2f, 0), MEDIUM_NONE, 0.0f, 1, &rays);
        /* The slanted shadow ray crosses 2 |d| / |d.x| of the slab, d = (10, 0.1, 0). */
        float slant = 2.0f * sqrtf(100.0f + 0.01f) / 10.0f;
        float es = expf(-sig[i] * slant), es_y = expf(-0.5f * sig[i] * slant);
        cr_assert(fabsf(tr.x - es) <= 1e-5f * es + 1e-30f, "sigma %g: %.9g vs %.9g", (double)sig[i], (double)tr.x, (double)es);
        cr_assert(fabsf(tr.y - es_y) <= 1e-5f * es_y + 1e-30f);
        cr_assert_eq(tr.z, 1.0f);
        /* Camera ray straight at the lamp: radiance 2 exp(-sigma 2), no noise (march). */
        struct sampler smp = sampler_start(1, 0, 0, 0);
        int hit;
        vec3 L = media_sample_path(&job, &smp, 0, 0, v3(-5, 0, 0), v3(1, 0, 0), 0.0f, &rays, &hit);
        cr_assert(fabsf(L.x - 2 * expect) <= 2e-5f * expect + 1e-30f, "sigma %g: L %.9g %.9g %.9g vs %.9g", (double)sig[i], (double)L.x, (double)L.y, (double)L.z, (double)(2 * expect));
        cr_assert(fabsf(L.z - 2.0f) <= 1e-6f);
        render_job_fini(&job);
        scene_fini(&s);
    }
}

/* ---- single scattering: the airlight integral ---- */

/* A single-scattering integrand along o + t d (|d| = 1) in an isotropic medium of sigma_s
 * ss and sigma_t st, from a point light of intensity I at lp or from the lamp (LAMP_OBJ)
 * of radiance I (lamp set), integrated by composite Simpson in double. */
struct ss_case { double I, ss, st; vec3 o, d, lp; int lamp; };

static double ss_integrand(const struct ss_case *c, double t)
{
    double x = c->o.x + t * c->d.x, y = c->o.y + t * c->d.y, z = c->o.z + t * c->d.z;
    double in = 0.0;
    if (!c->lamp) {
        double dx = x - c->lp.x, dy = y - c->lp.y, dz = z - c->lp.z, r2 = dx * dx + dy * dy + dz * dz;
        in = exp(-c->st * sqrt(r2)) / r2;
    } else {
        /* midpoint rule on the lamp: L_e cos_l / r^2 dA */
        const int m = 24;
        double cell = 0.5 / m;
        for (int a = 0; a < m; a++)
            for (int b = 0; b < m; b++) {
                double dx = x - (-0.25 + (a + 0.5) * cell), dy = y - 0.3, dz = z - (-0.25 + (b + 0.5) * cell);
                double r2 = dx * dx + dy * dy + dz * dz, r = sqrt(r2);
                if (dy < 0)
                    in += exp(-c->st * r) * (-dy / r) / r2 * cell * cell;
            }
    }
    return c->ss / (4 * M_PI) * c->I * exp(-c->st * t) * in;
}

static double airlight(const struct ss_case *c, double tmax, int n)
{
    /* The integrand is smooth; its peak has the width of the ray's distance to the light. */
    double h = tmax / n, sum = 0.0;
    for (int i = 0; i <= n; i++)
        sum += ss_integrand(c, i * h) * (i == 0 || i == n ? 1 : (i % 2 ? 4 : 2));
    return sum * h / 3.0;
}

/* The mean of m camera samples' red radiance along (o, d), sampler seed `seed`, and its
 * standard error; rays counts the rays cast. */
static double red_mean(const struct render_job *job, uint32_t seed, int m, vec3 o, vec3 d, double *se, uint64_t *rays)
{
    double s1 = 0.0, s2 = 0.0;
    for (int i = 0; i < m; i++) {
        struct sampler smp = sampler_start(seed, 0, 0, (uint32_t)i);
        int hit;
        double v = media_sample_path(job, &smp, 0, 0, o, d, 0.0f, rays, &hit).x;
        cr_assert(isfinite(v));
        s1 += v;
        s2 += v * v;
    }
    double mean = s1 / m;
    *se = sqrt(fmax(0.0, s2 / m - mean * mean) / m);
    return mean;
}

/* An isotropic fog inside a black sphere of radius 50; the camera ray passes the point
 * light at distance 1. */
#define AIRLIGHT_SCENE                                                                                      \
    HEAD("\"position\": [-5, 1, 0], \"look_at\": [0, 1, 0]", 1, 1, 1, 1)                                      \
    ",\n\"materials\": {\"black\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0]}},\n"                         \
    "\"media\": {\"fog\": {\"sigma_a\": [0.05, 0.05, 0.05], \"sigma_s\": [0.05, 0.05, 0.05]}},\n"                \
    "\"volume\": {\"method\": \"march\", \"fog\": \"fog\", \"step\": 0.02},\n"                                \
    "\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 50, \"material\": \"black\"}],\n"   \
    "\"lights\": [{\"type\": \"point\", \"position\": [0, 0, 0], \"intensity\": [10, 10, 10]}]}"

Test(medium, single_scattering_airlight)
{
    struct scene s;
    load_ok(AIRLIGHT_SCENE, &s);
    struct render_job job;
    job_ok(&job, &s);
    cr_assert_eq(job.media->camera_medium, 0u);
    vec3 o = v3(-5, 1, 0), d = v3(1, 0, 0);
    double tmax = 5.0 + sqrt(50.0 * 50.0 - 1.0);
    struct ss_case c = {10, 0.05, 0.1, o, d, v3(0, 0, 0), 0};
    double ref = airlight(&c, tmax, 2000000);
    double sum = 0.0;
    const int n = 64;
    uint64_t rays = 0;
    for (int i = 0; i < n; i++) {
        struct sampler smp = sampler_start(9, 0, 0, (uint32_t)i);
        int hit;
        sum += media_sample_path(&job, &smp, 0, 0, o, d, 0.0f, &rays, &hit).x;
    }
    double est = sum / n;
    cr_assert(fabs(est / ref - 1.0) < 0.01, "march %g vs airlight %g", est, ref);
    /* The same with the volumetric path tracer at max_depth 1 (single scattering). */
    render_job_fini(&job);
    s.media->method = MEDIA_VPT;
    job_ok(&job, &s);
    double se, mean = red_mean(&job, 11, 200000, o, d, &se, &rays);
    cr_assert(fabs(mean - ref) < 4 * se + 0.005 * ref, "vpt %g +- %g vs airlight %g", mean, se, ref);
    render_job_fini(&job);
    scene_fini(&s);
}

Test(medium, single_scattering_area_light)
{
    /* The camera ray passes 0.3 under a small lamp in an isotropic fog inside a black
     * sphere: VPT at max_depth 1 (free flight + NEE, phase sampling, and one equiangular
     * sample toward a point on the lamp, MIS-weighted) against the quadrature. Without the
     * equiangular sample the points near the lamp (1/r^2) make the estimate heavy-tailed:
     * its standard error here is 1.2 % of the mean (measured), with it 0.2 %. */
    const char *text = HEAD("\"position\": [-5, 0, 0], \"look_at\": [0, 0, 0]", 1, 1, 1, 1)
        ",\n\"materials\": {\"black\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0]},\n"
        "  \"lamp\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0], \"emission\": [10, 10, 10]}},\n"
        "\"media\": {\"fog\": {\"sigma_a\": [0.05, 0.05, 0.05], \"sigma_s\": [0.05, 0.05, 0.05]}},\n"
        "\"volume\": {\"method\": \"vpt\", \"fog\": \"fog\"},\n"
        "\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 50, \"material\": \"black\"},\n"
        "  {\"type\": \"obj\", \"file\": \"lamp.obj\", \"material\": \"lamp\"}]}";
    struct scene s;
    load_ok(text, &s);
    struct render_job job;
    job_ok(&job, &s);
    vec3 o = v3(-5, 0, 0), d = v3(1, 0, 0);
    struct ss_case c = {10, 0.05, 0.1, o, d, v3(0, 0, 0), 1};
    double ref = airlight(&c, 55.0, 20000);
    const int m = 100000;
    uint64_t rays = 0;
    double se, mean = red_mean(&job, 13, m, o, d, &se, &rays);
    cr_log_info("area light single scattering: vpt %g +- %g, quadrature %g", mean, se, ref);
    cr_assert(fabs(mean - ref) < 4 * se + 0.005 * ref, "vpt %g +- %g vs quadrature %g", mean, se, ref);
    cr_assert(se < 0.005 * ref, "vpt's standard error %g is %g of the mean", se, se / ref);
    render_job_fini(&job);
    scene_fini(&s);
}

Test(medium, camera_points_area_light)
{
    /* The same ray and lamp with beam, single scattering only (no photons, max_depth 1):
     * the camera segment takes its single scattering at CAMERA_POINTS points stratified in
     * a truncated exponential, each NEE weighted (balance heuristic, the points' density
     * counted CAMERA_POINTS times, the lamp sampled by solid angle) against one
     * equiangular sample toward a point on the lamp drawn by area, instead of a march. Its
     * mean must be the quadrature's (a wrong MIS weight or density shows as a bias of
     * several per cent), with few shadow rays per sample. */
    const char *text = HEAD("\"position\": [-5, 0, 0], \"look_at\": [0, 0, 0]", 1, 1, 1, 1)
        ",\n\"materials\": {\"black\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0]},\n"
        "  \"lamp\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0], \"emission\": [10, 10, 10]}},\n"
        "\"media\": {\"fog\": {\"sigma_a\": [0.05, 0.05, 0.05], \"sigma_s\": [0.05, 0.05, 0.05]}},\n"
        "\"volume\": {\"method\": \"beam\", \"fog\": \"fog\", \"photons\": 0, \"step\": 0.05},\n"
        "\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 50, \"material\": \"black\"},\n"
        "  {\"type\": \"obj\", \"file\": \"lamp.obj\", \"material\": \"lamp\"}]}";
    struct scene s;
    load_ok(text, &s);
    struct render_job job;
    job_ok(&job, &s);
    /* The second ray grazes the lamp's plane 0.05 below it: the points next to the lamp
     * see it at grazing angles, where sampling it by area (a density d^2 / (A cos) in
     * solid angle) gave a heavy tail; sampled by solid angle the standard error there is
     * below the bound (area sampling, at this seed: 0.0063 of the mean). */
    static const float ys[] = {0.0f, 0.25f};
    static const double se_max[] = {0.005, 0.0055};
    for (int k = 0; k < 2; k++) {
        vec3 o = v3(-5, ys[k], 0), d = v3(1, 0, 0);
        struct ss_case c = {10, 0.05, 0.1, o, d, v3(0, 0, 0), 1};
        double ref = airlight(&c, 55.0, 20000);
        const int m = 40000;
        uint64_t rays = 0;
        double se, mean = red_mean(&job, 17, m, o, d, &se, &rays);
        cr_log_info("area light single scattering, ray at y %g: beam %g +- %g (%g of the mean), quadrature %g, "
                    "%g rays per sample", o.y, mean, se, se / ref, ref, (double)rays / m);
        cr_assert(fabs(mean - ref) < 4 * se + 0.005 * ref, "beam %g +- %g vs quadrature %g", mean, se, ref);
        cr_assert(se < se_max[k] * ref, "beam's standard error %g is %g of the mean", se, se / ref);
        /* a march at this step would cast about 1100 shadow rays per sample */
        cr_assert((double)rays / m < 16.0, "%g rays per sample", (double)rays / m);
    }
    render_job_fini(&job);
    scene_fini(&s);
}

/* ---- white furnace ---- */

static void furnace(const char *medium_json, const char *camera, int fog)
{
    char text[2048];
    snprintf(text, sizeof text,
             HEAD("%s", 1, 1, 1, 1024)
             ",\n\"materials\": {\"sky\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0], \"emission\": [1, 1, 1]}},\n"
             "\"media\": {\"m\": %s},\n"
             "\"volume\": {\"method\": \"vpt\"%s},\n"
             "\"objects\": [{\"type\": \"obj\", \"file\": \"box.obj\", \"material\": \"sky\"}%s]}",
             camera, medium_json, fog ? ", \"fog\": \"m\"" : "",
             fog ? "" : ", {\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 2, \"medium\": \"m\"}");
    struct scene s;
    load_ok(text, &s);
    struct render_job job;
    job_ok(&job, &s);
    double s1 = 0.0, s2 = 0.0;
    const int n = 4000;
    uint64_t rays = 0;
    for (int i = 0; i < n; i++) {
        struct sampler smp = sampler_start(5, 0, 0, (uint32_t)i);
        float u = rng_uniform(rng_key(77, 0, 0, (uint32_t)i), 0), v = rng_uniform(rng_key(77, 0, 0, (uint32_t)i), 1);
        vec3 d = v3_normalize(v3(1.0f, 0.3f * (u - 0.5f), 0.3f * (v - 0.5f)));
        int hit;
        vec3 L = media_sample_path(&job, &smp, 0, 0, v3(-5, 0, 0), d, 0.0f, &rays, &hit);
        cr_assert(v3_is_finite(L));
        s1 += L.y;
        s2 += (double)L.y * L.y;
    }
    double mean = s1 / n, se = sqrt(fmax(0.0, s2 / n - mean * mean) / n);
    cr_assert(fabs(mean - 1.0) < 4 * se + 1e-3, "%s: furnace radiance %g +- %g", medium_json, mean, se);
    render_job_fini(&job);
    scene_fini(&s);
}

Test(medium, white_furnace_vpt)
{
    const char *cam = "\"position\": [-5, 0, 0], \"look_at\": [0, 0, 0]";
    furnace("{\"sigma_s\": [1, 1, 1]}", cam, 0);
    furnace("{\"sigma_s\": [4, 4, 4], \"g\": 0.7}", cam, 0);
    furnace("{\"sigma_s\": [0.3, 2, 5], \"g\": -0.5}", cam, 0);
    furnace("{\"sigma_s\": [0.2, 0.2, 0.2]}", cam, 1); /* camera inside the fog */
}

/* ---- heterogeneous media ---- */

#define GRID_MEDIUM "{\"sigma_a\": [1, 0.5, 2], \"sigma_s\": [0.5, 0.5, 0.5], \"density\": {\"file\": \"g.grid\", " \
                    "\"scale\": 0.1, \"transform\": {\"scale\": 2, \"translate\": [-1, -1, -1]}}}"

/* Three rays through the test grid (along an axis, oblique, nearly along another axis). */
static void grid_test_rays(vec3 orig[3], vec3 dirs[3])
{
    orig[0] = v3(-2, 0.3f, 0.1f), dirs[0] = v3(1, 0, 0);
    orig[1] = v3(-2, -0.4f, 0.5f), dirs[1] = v3_normalize(v3(1, 0.3f, -0.2f));
    orig[2] = v3(0.3f, -2, -0.7f), dirs[2] = v3_normalize(v3(0.2f, 1, 0.4f));
}

/* Transmittance through the grid against numerical integration of its density: ratio
 * tracking (unbiased) within 4 standard errors, the jittered march within 1 %. */
Test(medium, grid_transmittance)
{
    struct scene s;
    load_ok(HEAD("\"position\": [-5, 0, 0], \"look_at\": [0, 0, 0]", 1, 1, 1, 1)
            ",\n\"media\": {\"m\": " GRID_MEDIUM "},\n\"volume\": {\"fog\": \"m\"}}", &s);
    const struct medium *md = &s.media->media[0];
    cr_assert_not_null(md->grid);
    cr_assert(fabsf(md->grid->max_density - 0.1f * 21.5f) < 1e-4f, "%g", (double)md->grid->max_density); /* voxel (5,5,5) */
    cr_assert(fabsf(md->grid->voxel_world - 0.25f) < 1e-6f);
    vec3 dirs[3], orig[3];
    grid_test_rays(orig, dirs);
    for (int r = 0; r < 3; r++) {
        double tau = 0.0;
        const int n = 200000;
        float len = 4.0f;
        for (int i = 0; i < n; i++) { /* midpoint rule */
            float t = (float)((i + 0.5) * len / n);
            tau += grid_density(md->grid, v3_add(orig[r], v3_scale(dirs[r], t))) * (double)len / n;
        }
        double ref[3] = {exp(-1.5 * tau), exp(-1.0 * tau), exp(-2.5 * tau)};
        cr_assert(ref[0] > 0.05 && ref[0] < 0.95, "ray %d: transmittance %g makes a weak test", r, ref[0]);
        double s1[3] = {0, 0, 0}, s2[3] = {0, 0, 0};
        const int m = 20000;
        for (int i = 0; i < m; i++) {
            vec3 t = medium_tr_segment(md, orig[r], dirs[r], len, rng_key(5, 0, (uint64_t)r, (uint32_t)i), 1);
            float c[3] = {t.x, t.y, t.z};
            for (int k = 0; k < 3; k++) {
                s1[k] += c[k];
                s2[k] += (double)c[k] * c[k];
            }
        }
        for (int k = 0; k < 3; k++) {
            double mean = s1[k] / m, se = sqrt(fmax(0.0, s2[k] / m - mean * mean) / m);
            cr_assert(fabs(mean - ref[k]) < 4 * se + 1e-4, "ray %d ch %d: ratio tracking %g +- %g vs %g", r, k, mean, se, ref[k]);
        }
        double mm = 0.0;
        for (int i = 0; i < 64; i++)
            mm += medium_tr_segment(md, orig[r], dirs[r], len, rng_key(6, 0, (uint64_t)r, (uint32_t)i), 0).x;
        cr_assert(fabs(mm / 64 / ref[0] - 1.0) < 0.01, "ray %d: march %g vs %g", r, mm / 64, ref[0]);
        /* The clipped span skips the empty region but keeps every non-zero density. */
        float c0, c1;
        cr_assert(medium_clip(md, orig[r], dirs[r], len, &c0, &c1));
        for (int i = 0; i < 1000; i++) {
            float t = len * (i + 0.5f) / 1000.0f;
            if (t < c0 || t >= c1)
                cr_assert_eq(grid_density(md->grid, v3_add(orig[r], v3_scale(dirs[r], t))), 0.0f);
        }
    }
    scene_fini(&s);
}

/* A density file with a run of '#' names one grid per frame; frames may differ in
 * resolution; a missing frame's grid is an error naming the scene's file:line:col, the
 * frame and the file; frame 0 is a render without --frames. */
Test(medium, grid_per_frame)
{
    grid_bytes();
    uint8_t small[20 + 4 * 8];
    memcpy(small, GRID_MAGIC, 8);
    for (int k = 0; k < 3; k++) {
        uint32_t n = 2;
        memcpy(small + 8 + 4 * k, &n, 4);
    }
    for (int i = 0; i < 8; i++) {
        float v = (float)i;
        memcpy(small + 20 + 4 * i, &v, 4);
    }
    const struct mem_file files[] = {{"g.0007.grid", g_grid, sizeof g_grid}, {"g.0012.grid", small, sizeof small},
                                     {NULL, NULL, 0}};
    const char *t = HEAD("\"position\": [-5, 0, 0], \"look_at\": [0, 0, 0]", 1, 1, 1, 1)
        ",\n\"media\": {\"m\": {\"density\": {\"file\": \"g.####.grid\"}}}}";
    struct asset_source src = {mem_read, (void *)(uintptr_t)files};
    static const double world[3] = {0, 0, 0};
    struct scene s;
    char err[512] = "";
    cr_assert_eq(scene_json_parse_frame("scenes/t.json", t, strlen(t), &src, world, 7, &s, err, sizeof err), 0, "%s", err);
    cr_expect_eq(s.frame_files, 1);
    cr_expect_str_eq(s.frame_patterns[0], "g.####.grid");
    cr_expect_eq(s.media->media[0].grid->nx, GN);
    scene_fini(&s);
    cr_assert_eq(scene_json_parse_frame("scenes/t.json", t, strlen(t), &src, world, 12, &s, err, sizeof err), 0, "%s", err);
    cr_expect_eq(s.media->media[0].grid->nx, 2);
    cr_expect_eq(s.media->media[0].grid->max_density, 7.0f);
    scene_fini(&s);
    cr_assert_neq(scene_json_parse_frame("scenes/t.json", t, strlen(t), &src, world, 8, &s, err, sizeof err), 0);
    cr_expect(strstr(err, "scenes/t.json:4:37: cannot read frame 8's grid \"g.0008.grid\"") != NULL, "%s", err);
    cr_assert_neq(test_scene_load(t, files, &s, err), 0);
    cr_expect(strstr(err, "cannot read frame 0's grid \"g.0000.grid\"") != NULL, "%s", err);
    /* a bad grid of one frame is refused as any grid is */
    small[20] = 0xff, small[21] = 0xff, small[22] = 0xff, small[23] = 0x7f; /* NaN */
    cr_assert_neq(scene_json_parse_frame("scenes/t.json", t, strlen(t), &src, world, 12, &s, err, sizeof err), 0);
    cr_expect(strstr(err, "scenes/t.json:4:37: ") != NULL, "%s", err);
}

Test(medium, grid_errors)
{
    struct scene s;
    char err[512];
    const char *t = HEAD("\"position\": [-5, 0, 0], \"look_at\": [0, 0, 0]", 1, 1, 1, 1)
        ",\n\"media\": {\"m\": {\"density\": {\"file\": \"box.obj\"}}}}";
    cr_assert_neq(load(t, &s, err), 0);
    cr_assert(strstr(err, "scenes/t.json:4:37: grid \"box.obj\": not a density grid") != NULL, "%s", err);
    struct density_grid g;
    uint8_t bad[24];
    memcpy(bad, GRID_MAGIC, 8);
    uint32_t dims[3] = {1, 1, 1};
    memcpy(bad + 8, dims, 12);
    float v = -1.0f;
    memcpy(bad + 20, &v, 4);
    cr_assert_neq(grid_parse(bad, sizeof bad, &g, err, sizeof err), 0);
    cr_assert_neq(grid_parse(bad, sizeof bad - 1, &g, err, sizeof err), 0);
    dims[0] = 1u << 20;
    dims[1] = 1u << 20;
    memcpy(bad + 8, dims, 12);
    cr_assert_neq(grid_parse(bad, sizeof bad, &g, err, sizeof err), 0);
    /* 2^22 x 2^22 x 2^20 voxels is 0 modulo 2^64: with no data after the header it must
     * still be refused, not read as an empty grid of those sides. */
    dims[0] = 1u << 22;
    dims[1] = 1u << 22;
    dims[2] = 1u << 20;
    memcpy(bad + 8, dims, 12);
    cr_assert_neq(grid_parse(bad, 20, &g, err, sizeof err), 0);
    cr_assert(strstr(err, "out of range") != NULL, "%s", err);
}

/* Emission in a grid (e times the density, absorbing): the unbiased one-sample estimate
 * (VPT) within 4 standard errors of a fine integration of Tr(t) e rho(t) along three rays,
 * and renders of a thin ray through the grid (march and VPT) within 1 % and 2 %. */
static double render_mean(struct scene *s, struct photon_map *map, uint32_t spp, double *se);
#define EMIT_MEDIUM "{\"sigma_a\": [1, 0.5, 2], \"emission\": [1, 2, 0.5], \"density\": {\"file\": \"g.grid\", " \
                    "\"scale\": 0.1, \"transform\": {\"scale\": 2, \"translate\": [-1, -1, -1]}}}"
static double emission_reference(const struct medium *md, vec3 o, vec3 d, float len, int ch)
{
    const int n = 200000;
    double tau = 0.0, L = 0.0, st = ch == 0 ? md->sigma_t.x : (ch == 1 ? md->sigma_t.y : md->sigma_t.z);
    double e = ch == 0 ? md->emission.x : (ch == 1 ? md->emission.y : md->emission.z);
    for (int i = 0; i < n; i++) {
        double rho = grid_density(md->grid, v3_add(o, v3_scale(d, (float)((i + 0.5) * len / n)))), dt = (double)len / n;
        L += exp(-st * (tau + 0.5 * rho * dt)) * e * rho * dt;
        tau += rho * dt;
    }
    return L;
}

Test(medium, grid_emission, .timeout = 60)
{
    struct scene s;
    load_ok(HEAD("\"position\": [-5, 0.05, 0.1], \"look_at\": [0, 0.05, 0.1]", 1, 1, 1, 1)
            ",\n\"media\": {\"m\": " EMIT_MEDIUM "},\n\"volume\": {\"fog\": \"m\", \"method\": \"march\", \"step\": 0.01}}", &s);
    const struct medium *md = &s.media->media[0];
    vec3 dirs[3], orig[3];
    grid_test_rays(orig, dirs);
    for (int r = 0; r < 3; r++) {
        double s1[3] = {0, 0, 0}, s2[3] = {0, 0, 0};
        const int m = 40000;
        for (int i = 0; i < m; i++) {
            vec3 e = medium_emission_segment(md, orig[r], dirs[r], 4.0f, rng_key(7, 0, (uint64_t)r, (uint32_t)i));
            float c[3] = {e.x, e.y, e.z};
            for (int k = 0; k < 3; k++) {
                s1[k] += c[k];
                s2[k] += (double)c[k] * c[k];
            }
        }
        for (int k = 0; k < 3; k++) {
            double ref = emission_reference(md, orig[r], dirs[r], 4.0f, k);
            double mean = s1[k] / m, se = sqrt(fmax(0.0, s2[k] / m - mean * mean) / m);
            cr_assert(ref > 0.01, "ray %d: emission %g makes a weak test", r, ref);
            cr_assert(fabs(mean - ref) < 4 * se + 1e-5, "ray %d ch %d: estimate %g +- %g vs %g", r, k, mean, se, ref);
        }
    }
    /* Camera rays: a 1x1 image with a tiny field of view looks along +x through the grid. */
    s.camera.fov_y_deg = 0.01f;
    double ref = emission_reference(md, v3(-5, 0.05f, 0.1f), v3(1, 0, 0), 10.0f, 0), se;
    double march = render_mean(&s, NULL, 64, &se);
    s.media->method = MEDIA_VPT;
    double se_v, vpt = render_mean(&s, NULL, 4096, &se_v);
    fprintf(stderr, "grid emission: reference %g, march %g, vpt %g +- %g\n", ref, march, vpt, se_v);
    cr_assert(fabs(march / ref - 1.0) < 0.01, "march %g vs %g", march, ref);
    cr_assert(fabs(vpt / ref - 1.0) < 0.02, "vpt %g vs %g", vpt, ref);
    scene_fini(&s);
}

Test(medium, white_furnace_grid)
{
    const char *cam = "\"position\": [-5, 0, 0], \"look_at\": [0, 0, 0]";
    /* Optical depth ~5 across: paths end by leaving, not by max_depth (which would bias). */
    furnace("{\"sigma_s\": [0.5, 0.5, 0.5], \"g\": 0.3, \"density\": {\"file\": \"g.grid\", \"transform\": {\"scale\": 3, \"translate\": [-1.5, -1.5, -1.5]}}}", cam, 0);
}

/* ---- Henyey-Greenstein ---- */

static double hg_cdf(double g, double mu)
{
    if (fabs(g) < 1e-3)
        return (mu + 1.0) / 2.0;
    return (1.0 - g * g) / (2.0 * g) * (1.0 / sqrt(1.0 + g * g - 2.0 * g * mu) - 1.0 / (1.0 + g));
}

Test(medium, hg_integrates_to_one)
{
    float gs[] = {0.0f, 0.3f, -0.6f, 0.9f, 0.999f, -0.999f};
    for (size_t k = 0; k < sizeof gs / sizeof *gs; k++) {
        double g = gs[k], sum = 0.0;
        const int n = 2000000;
        /* mu = s (1 - 2 w^4): points crowd toward the peak at mu = s, s = sign(g). */
        double sg = g < 0 ? -1.0 : 1.0;
        for (int i = 0; i < n; i++) {
            double w = (i + 0.5) / n, mu = sg * (1.0 - 2.0 * w * w * w * w), dmu = 8.0 * w * w * w / n;
            sum += 2.0 * M_PI * phase_hg((float)mu, (float)g) * dmu;
        }
        cr_assert(fabs(sum - 1.0) < 2e-3, "g %g: integral %g", g, sum);
        cr_assert(fabs(hg_cdf(g, 1.0) - 1.0) < 1e-9);
    }
}

Test(medium, hg_sampling_chi_square)
{
    float gs[] = {0.0f, 0.5f, -0.8f, 0.999f, -0.999f};
    for (size_t k = 0; k < sizeof gs / sizeof *gs; k++) {
        double g = gs[k];
        enum { BINS = 100, N = 200000 };
        /* Bins of equal probability from the analytic CDF, found by bisection. */
        double edge[BINS + 1];
        edge[0] = -1.0;
        edge[BINS] = 1.0;
        for (int b = 1; b < BINS; b++) {
            double lo = -1.0, hi = 1.0, target = (double)b / BINS;
            for (int it = 0; it < 100; it++) {
                double mid = 0.5 * (lo + hi);
                *(hg_cdf(g, mid) < target ? &lo : &hi) = mid;
            }
            edge[b] = 0.5 * (lo + hi);
        }
        /* Near mu = +-1 equal-probability bins get narrower than float spacing for |g| near
         * 1: merge bins narrower than 2e-5 (expected counts from the analytic CDF). */
        double kept[BINS + 1];
        int nk = 0;
        kept[nk++] = -1.0;
        for (int b = 1; b < BINS; b++)
            if (edge[b] - kept[nk - 1] >= 2e-5 && 1.0 - edge[b] >= 2e-5)
                kept[nk++] = edge[b];
        kept[nk++] = 1.0;
        int nb = nk - 1;
        int count[BINS] = {0};
        uint64_t key = rng_key(3, 0, k, 0);
        for (int i = 0; i < N; i++) {
            vec3 out;
            vec3 din = v3_normalize(v3(0.3f, -0.4f, 0.8f));
            float u1 = rng_uniform(key, 2 * (uint32_t)i), u2 = rng_uniform(key, 2 * (uint32_t)i + 1);
            float pdf = phase_hg_sample(din, (float)g, u1, u2, &out);
            cr_assert(fabsf(v3_length(out) - 1.0f) < 1e-5f && pdf > 0.0f && isfinite(pdf));
            double mu = phase_hg_sample_cos((float)g, u1);
            int b = 0;
            while (b < nb - 1 && mu >= kept[b + 1])
                b++;
            count[b]++;
        }
        double chi2 = 0.0;
        for (int b = 0; b < nb; b++) {
            double e = N * (hg_cdf(g, kept[b + 1]) - hg_cdf(g, kept[b]));
            chi2 += (count[b] - e) * (count[b] - e) / e;
        }
        /* df = nb - 1; mean + 6 sd is far beyond p = 1e-6. */
        cr_assert(nb >= 8, "g %g: only %d bins", g, nb);
        cr_assert(chi2 < (nb - 1) + 6 * sqrt(2.0 * (nb - 1)), "g %g: chi2 %g over %d bins", g, chi2, nb);
    }
}

/* ---- photon map ---- */

/* A sphere of albedo 0.9, optical radius 3 (strong multiple scattering), lit by a point
 * light, seen from outside. */
#define MS_SCENE(method)                                                                                     \
    HEAD("\"position\": [0, 0, -4], \"look_at\": [0, 0, 0]", 16, 16, 1, 64)                                    \
    ",\n\"materials\": {\"black\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0]}},\n"                        \
    "\"media\": {\"m\": {\"sigma_a\": [0.3, 0.3, 0.3], \"sigma_s\": [2.7, 2.7, 2.7], \"g\": 0.2}},\n"          \
    "\"volume\": {\"method\": \"" method "\", \"photons\": 200000, \"radius\": 0.06, \"step\": 0.03},\n"       \
    "\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"medium\": \"m\"},\n"        \
    "  {\"type\": \"obj\", \"file\": \"box.obj\", \"material\": \"black\"}],\n"                               \
    "\"lights\": [{\"type\": \"point\", \"position\": [2, 2, -2], \"intensity\": [20, 20, 20]}]}"

static uint8_t *build_map(const struct scene *s, uint32_t threads, size_t *size, uint64_t min_stored)
{
    struct render_job job;
    job_ok(&job, s);
    uint8_t *blob = NULL;
    struct photon_pass_stats st;
    char err[256];
    cr_assert_eq(photon_trace_map(&job, 1, threads, &blob, size, &st, err, sizeof err), 0, "%s", err);
    cr_assert(st.stored >= min_stored, "stored %llu", (unsigned long long)st.stored);
    cr_assert(st.bytes <= 26 * st.stored + 4096, "bytes/photon %g", (double)st.bytes / st.stored);
    render_job_fini(&job);
    return blob;
}

Test(medium, photon_map_same_bytes_any_threads)
{
    struct scene s;
    load_ok(MS_SCENE("beam"), &s);
    size_t n1, n2;
    uint8_t *a = build_map(&s, 1, &n1, 1000), *b = build_map(&s, 2, &n2, 1000);
    cr_assert_eq(n1, n2);
    struct blob_hash h1, h2;
    blob_hash_compute(a, n1, &h1);
    blob_hash_compute(b, n2, &h2);
    cr_assert(blob_hash_equal(&h1, &h2));
    cr_assert_eq(memcmp(a, b, n1), 0);
    /* Decoding checks sizes: a truncated or altered header is refused. */
    struct photon_map *pm;
    char err[256];
    cr_assert_eq(photon_map_decode(a, n1, &pm, err, sizeof err), 0, "%s", err);
    photon_map_free(&pm);
    cr_assert_neq(photon_map_decode(a, n1 - 1, &pm, err, sizeof err), 0);
    a[8] ^= 1;
    cr_assert_neq(photon_map_decode(a, n1, &pm, err, sizeof err), 0);
    free(a);
    free(b);
    scene_fini(&s);
}

/* ---- photon emission densities ---- */

/* A medium sphere of radius 1 at the origin and one light outside it, far enough that its
 * photons aim at the media's bounding sphere (media_bounds: the box [-1, 1]^3, radius
 * sqrt 3). */
#define EMIT_SCENE(light)                                                                                  \
    HEAD("\"position\": [0, 0, -4], \"look_at\": [0, 0, 0]", 8, 8, 1, 8)                                      \
    ",\n\"materials\": {\"black\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0]}},\n"                        \
    "\"media\": {\"m\": {\"sigma_a\": [0.3, 0.3, 0.3], \"sigma_s\": [2.7, 2.7, 2.7], \"g\": 0.2}},\n"          \
    "\"volume\": {\"method\": \"beam\", \"photons\": 1000, \"radius\": 0.06, \"step\": 0.03},\n"              \
    "\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"medium\": \"m\"}],\n"       \
    "\"lights\": [" light "]}"

/* Bands of cos(angle to the axis from the light to the media), each split in two halves
 * by a plane through the axis: the aim cone's edge (cos 0.968 here) falls inside a band. */
#define EMIT_BANDS 9
static const double emit_band[EMIT_BANDS + 1] = {-1.0, -0.5, 0.0, 0.5, 0.9, 0.95, 0.965, 0.975, 0.99, 1.0};

static int emit_bin(vec3 d, vec3 axis, vec3 t)
{
    double z = v3_dot(d, axis);
    int k = 0;
    while (k < EMIT_BANDS - 1 && z >= emit_band[k + 1])
        k++;
    return 2 * k + (v3_dot(d, t) >= 0.0f);
}

/* The photons' power in each bin against the light's power there (the intensity times the
 * spot falloff integrated over the bin, midpoint rule on an equal-area grid): every bin
 * within 5 standard errors, their chi-square within its mean + 6 sd, and the total (the
 * energy) within 4 standard errors. Fails if either part of the mixture's pdf (the light's
 * own emission, the cone toward the media) is misstated. */
static void check_emission(const char *scene_text)
{
    struct scene s;
    load_ok(scene_text, &s);
    struct render_job job;
    job_ok(&job, &s);
    const struct light *l = &s.lights[0];
    vec3 axis = v3_normalize(v3_neg(l->position)), t, b;
    v3_basis(axis, &t, &b);
    enum { N = 400000, NB = 2 * EMIT_BANDS };
    struct photon_emitted *pe = malloc(sizeof *pe * N);
    photon_trace_emit(&job, 7, 0, N, pe);
    double sum[NB] = {0}, sum2[NB] = {0}, expect[NB] = {0}, tot = 0.0, tot2 = 0.0;
    for (int i = 0; i < N; i++) {
        double w = pe[i].power.x;
        cr_assert(isfinite(w) && w >= 0.0, "photon %d power %g", i, w);
        if (w == 0.0)
            continue;
        int k = emit_bin(pe[i].d, axis, t);
        sum[k] += w, sum2[k] += w * w * N;
        tot += w, tot2 += w * w * N;
    }
    free(pe);
    /* The light's power per bin: I x falloff over an equal-area (z, phi) grid, in the
     * directions that can reach the interaction box (a point light outside the box's slab
     * on an axis sends nothing away from it). */
    vec3 lo, hi;
    int reach = photon_interaction_bounds(&job, &lo, &hi);
    const float lp[3] = {l->position.x, l->position.y, l->position.z}, blo[3] = {lo.x, lo.y, lo.z},
                bhi[3] = {hi.x, hi.y, hi.z};
    const int NZ = 4000, NP = 256;
    for (int iz = 0; iz < NZ; iz++)
        for (int ip = 0; ip < NP; ip++) {
            double z = -1.0 + 2.0 * (iz + 0.5) / NZ, phi = 2.0 * M_PI * (ip + 0.5) / NP, r = sqrt(1.0 - z * z);
            vec3 d = v3_add(v3_scale(axis, (float)z), v3_add(v3_scale(t, (float)(r * cos(phi))), v3_scale(b, (float)(r * sin(phi)))));
            const float dd[3] = {d.x, d.y, d.z};
            int away = 0;
            for (int a = 0; a < 3 && reach && l->type == LIGHT_POINT; a++)
                away |= (lp[a] < blo[a] && dd[a] < 0.0f) || (lp[a] > bhi[a] && dd[a] > 0.0f);
            if (!away)
                expect[emit_bin(d, axis, t)] += l->intensity.x * light_spot_falloff(l, d) * 4.0 * M_PI / ((double)NZ * NP);
        }
    double chi2 = 0.0, etot = 0.0;
    int bins = 0;
    for (int k = 0; k < NB; k++) {
        etot += expect[k];
        double mean = sum[k], var = (sum2[k] - mean * mean) / N;
        if (expect[k] == 0.0) {
            cr_assert_eq(sum[k], 0.0, "bin %d: power %g where the light sends none", k, sum[k]);
            continue;
        }
        double z = (mean - expect[k]) / sqrt(var > 0.0 ? var : 1e-300);
        cr_assert(fabs(z) < 5.0, "bin %d: power %g, light's %g (%.1f standard errors)", k, mean, expect[k], z);
        chi2 += z * z;
        bins++;
    }
    cr_assert(chi2 < bins + 6.0 * sqrt(2.0 * bins), "chi2 %g over %d bins", chi2, bins);
    double se = sqrt((tot2 - tot * tot) / N);
    cr_assert(fabs(tot - etot) < 4.0 * se, "power %g, light's %g (se %g)", tot, etot, se);
    render_job_fini(&job);
    scene_fini(&s);
}

Test(medium, emission_density_point_light, .timeout = 60)
{
    check_emission(EMIT_SCENE("{\"type\": \"point\", \"position\": [4, 4, -4], \"intensity\": [5, 5, 5]}"));
}

/* A spot whose cone covers part of the media's cone: aimed photons outside the spot's cone
 * carry nothing, the spot's own photons inside the media's cone share the aimed ones' pdf. */
Test(medium, emission_density_spot_light, .timeout = 60)
{
    check_emission(EMIT_SCENE("{\"type\": \"spot\", \"position\": [4, 4, -4], \"look_at\": [1.5, 0, 0], "
                              "\"intensity\": [5, 5, 5], \"angle\": 20, \"falloff\": 5}"));
}

/* The volume blob carries the master's settings and map; a worker refuses a damaged one. */
Test(medium, volume_blob_roundtrip)
{
    struct scene s;
    load_ok(MS_SCENE("beam"), &s);
    size_t n;
    uint8_t *map = build_map(&s, 2, &n, 1000);
    s.media->method = MEDIA_MARCH_STEPS;
    s.media->step = 0.125f;
    uint8_t *vb;
    size_t vbs;
    volume_blob_make(s.media, map, n, &vb, &vbs);
    struct scene w;
    load_ok(MS_SCENE("beam"), &w);
    char err[256];
    struct photon_map *wm = NULL, *bad = NULL;
    cr_assert_eq(volume_blob_apply(&w, vb, vbs, &wm, err, sizeof err), 0, "%s", err);
    cr_assert_eq(w.media->method, MEDIA_MARCH_STEPS);
    cr_assert_eq(w.media->step, 0.125f);
    cr_assert_not_null(wm);
    /* The volume map, then the surface map (the black box keeps none, but the map is there). */
    const struct photon_map *vm = wm, *sm = vm->surface;
    cr_assert_not_null(sm);
    cr_assert_eq(sm->num_photons, 0u);
    cr_assert_eq(vm->num_photons * sizeof(struct photon) + 48 + 4 * ((size_t)vm->table_size + 1) +
                     sm->num_photons * sizeof(struct photon) + 48 + 4 * ((size_t)sm->table_size + 1),
                 n);
    cr_assert_neq(volume_blob_apply(&w, vb, vbs - 4, &bad, err, sizeof err), 0);
    vb[8] = 7; /* method out of range */
    cr_assert_neq(volume_blob_apply(&w, vb, vbs, &bad, err, sizeof err), 0);
    cr_assert_null(bad);
    photon_map_free(&wm);
    free(vb);
    free(map);
    scene_fini(&w);
    scene_fini(&s);
}

/* map (or NULL): lent to the job for the render, still the caller's after. */
static double render_mean(struct scene *s, struct photon_map *map, uint32_t spp, double *se)
{
    s->settings.spp = spp;
    struct tile_stats st;
    float *px = test_render_map(s, map, 1, &st);
    uint32_t w = s->settings.width, h = s->settings.height;
    for (uint32_t i = 0; i < w * h; i++)
        cr_assert(isfinite(px[i * TILE_NUM_CHANNELS + CH_R]));
    cr_assert_eq(st.nan_samples, 0);
    double mean = test_channel_mean(px, w, h, CH_R, se);
    free(px);
    return mean;
}

/* The scene's photon map, decoded as a worker does (the caller frees). */
static struct photon_map *decode_map(struct scene *s, uint64_t min_stored)
{
    size_t n;
    uint8_t *blob = build_map(s, 2, &n, min_stored);
    char err[256];
    struct photon_map *m = NULL;
    cr_assert_eq(photon_map_decode(blob, n, &m, err, sizeof err), 0, "%s", err);
    free(blob);
    return m;
}

/* Stated bias: the photon-map image mean is within 10 % of the path tracer's. */
Test(medium, photon_map_matches_vpt, .timeout = 120)
{
    struct scene s;
    load_ok(MS_SCENE("vpt"), &s);
    double se_ref, ref = render_mean(&s, NULL, 256, &se_ref);
    cr_assert(ref > 0.0);
    s.media->method = MEDIA_MARCH_BEAM;
    struct photon_map *map = decode_map(&s, 1000);
    double se_b, beam = render_mean(&s, map, 4, &se_b);
    s.media->method = MEDIA_MARCH_STEPS;
    double se_m, march = render_mean(&s, map, 4, &se_m);
    fprintf(stderr, "photon map vs vpt: beam %g per-step %g vpt %g +- %g\n", beam, march, ref, se_ref);
    cr_assert(fabs(beam / ref - 1.0) < 0.10, "beam %g vs vpt %g (+- %g)", beam, ref, se_ref);
    cr_assert(fabs(march / ref - 1.0) < 0.10, "per-step %g vs vpt %g (+- %g)", march, ref, se_ref);
    /* Without the map (single scattering only) the image is clearly darker: the map matters. */
    photon_map_free(&map);
    double se_s, single = render_mean(&s, NULL, 4, &se_s);
    cr_assert(single < 0.8 * ref, "single %g vs vpt %g", single, ref);
    scene_fini(&s);
}

/* The scattering sphere over a white floor seen from above: the floor's indirect light
 * (mostly from the sphere) comes from the surface photon map in march / beam. */
#define FLOOR_SCENE(method, surface)                                                                        \
    HEAD("\"position\": [0, 3, -4], \"look_at\": [0, -0.6, 0]", 16, 16, 1, 64)                              \
    ",\n\"materials\": {\"black\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0]},\n"                     \
    "  \"white\": {\"type\": \"diffuse\", \"albedo\": [0.8, 0.8, 0.8]}},\n"                                  \
    "\"media\": {\"m\": {\"sigma_a\": [0.3, 0.3, 0.3], \"sigma_s\": [2.7, 2.7, 2.7], \"g\": 0.2}},\n"          \
    "\"volume\": {\"method\": \"" method "\", \"photons\": 200000, \"radius\": 0.06, \"step\": 0.03, "       \
    "\"surface_photons\": " surface "},\n"                                                                   \
    "\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"medium\": \"m\"},\n"        \
    "  {\"type\": \"obj\", \"file\": \"floor.obj\", \"material\": \"white\"},\n"                             \
    "  {\"type\": \"obj\", \"file\": \"box.obj\", \"material\": \"black\"}],\n"                               \
    "\"lights\": [{\"type\": \"point\", \"position\": [2, 2, -2], \"intensity\": [20, 20, 20]}]}"

/* Stated bias: with the surface map the image mean is within 10 % of the path tracer's
 * and within 5 % of beam with path-traced surface bounces; without its photons (the
 * floor's indirect light missing) it is clearly darker. The map is the same bytes for
 * 1 and 2 threads and holds photons on the white floor only. */
Test(medium, surface_photon_map_matches_vpt, .timeout = 120)
{
    struct scene s;
    load_ok(FLOOR_SCENE("vpt", "true"), &s);
    double se_ref, ref = render_mean(&s, NULL, 256, &se_ref);
    scene_fini(&s);
    load_ok(FLOOR_SCENE("beam", "false"), &s);
    struct photon_map *map = decode_map(&s, 1000);
    cr_assert_null(map->surface);
    double se_p, path = render_mean(&s, map, 16, &se_p);
    scene_fini(&s);
    load_ok(FLOOR_SCENE("beam", "true"), &s);
    size_t n1, n2;
    uint8_t *a = build_map(&s, 1, &n1, 1000), *b = build_map(&s, 2, &n2, 1000);
    cr_assert(n1 == n2 && memcmp(a, b, n1) == 0, "the map depends on the thread count");
    free(a);
    free(b);
    photon_map_free(&map);
    map = decode_map(&s, 1000);
    const struct photon_map *sm = map->surface;
    cr_assert(sm && sm->num_photons > 1000, "surface photons: %u", sm ? sm->num_photons : 0);
    for (uint32_t i = 0; i < sm->num_photons; i++)
        cr_assert(fabsf(sm->photons[i].p[1] + 1.2f) < 1e-3f, "a surface photon off the floor at y %g", sm->photons[i].p[1]);
    double se_s, surf = render_mean(&s, map, 4, &se_s);
    /* With the final gather the floor's map is read only at second diffuse vertices (here
     * the black walls); with max_depth 1 the path ends at the floor, and max_depth bounds
     * the light path too: no surface photon is short enough, the image is the same
     * without them. */
    uint32_t depth = s.settings.max_depth;
    s.settings.max_depth = 1;
    double se_1, first = render_mean(&s, map, 4, &se_1);
    map->surface->num_photons = 0;
    double se_n, none = render_mean(&s, map, 4, &se_n);
    s.settings.max_depth = depth;
    fprintf(stderr, "surface map: beam+surface %g, beam+paths %g, vpt %g +- %g; max_depth 1: %g, without its photons %g\n",
            surf, path, ref, se_ref, first, none);
    cr_assert(fabs(surf / ref - 1.0) < 0.10, "beam+surface %g vs vpt %g", surf, ref);
    cr_assert(fabs(surf / path - 1.0) < 0.05, "beam+surface %g vs beam+paths %g", surf, path);
    cr_assert(none == first, "without surface photons %g vs %g (max_depth 1)", none, first);
    photon_map_free(&map);
    scene_fini(&s);
}

/* ---- hard cases ---- */

Test(medium, hard_cases_finite, .timeout = 120)
{
    const char *coeffs[] = {"\"sigma_s\": [1e-6, 1e-6, 1e-6]", "\"sigma_s\": [1e6, 1e6, 1e6]",
                            "\"sigma_a\": [1e6, 0, 1e-6]", "\"sigma_a\": [1, 1, 1]",
                            "\"sigma_s\": [3, 3, 3], \"g\": 0.999", "\"sigma_s\": [3, 0, 3], \"g\": -0.999",
                            "\"sigma_s\": [1, 1, 1], \"emission\": [1, 2, 3]"};
    const char *methods[] = {"vpt", "march", "beam"};
    for (size_t c = 0; c < sizeof coeffs / sizeof *coeffs; c++)
        for (int mth = 0; mth < 3; mth++)
            for (int inside = 0; inside < 2; inside++) {
                char text[2048];
                /* The light (and, in the second case, the camera) inside the medium. */
                snprintf(text, sizeof text,
                         HEAD("\"position\": [%s, 0.1, 0], \"look_at\": [0, 0, 0]", 8, 8, 2, 8)
                         ",\n\"materials\": {\"w\": {\"type\": \"diffuse\", \"albedo\": [0.5, 0.5, 0.5]}},\n"
                         "\"media\": {\"m\": {%s}},\n"
                         "\"volume\": {\"method\": \"%s\", \"photons\": 2000, \"radius\": 1e-30, \"step\": 0.05},\n"
                         "\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 2, \"medium\": \"m\"},\n"
                         "  {\"type\": \"obj\", \"file\": \"box.obj\", \"material\": \"w\"}],\n"
                         "\"lights\": [{\"type\": \"spot\", \"position\": [0.5, 0, 0], \"direction\": [-1, 0, 0], "
                         "\"intensity\": [5, 5, 5], \"angle\": 60}]}",
                         inside ? "-1.5" : "-5", coeffs[c], methods[mth]);
                struct scene s;
                load_ok(text, &s);
                struct photon_map *map = mth > 0 ? decode_map(&s, 0) : NULL;
                double se, mean = render_mean(&s, map, 2, &se);
                cr_assert(isfinite(mean) && mean >= 0.0, "%s %s: mean %g", coeffs[c], methods[mth], mean);
                photon_map_free(&map);
                scene_fini(&s);
            }
}

Test(medium, gather_radius_near_zero)
{
    struct photon_map m;
    struct photon ph = {{0, 0, 0}, {0, 0, 0, 0}, 0, 0};
    photon_rgbe_encode(v3(1, 1, 1), ph.rgbe);
    ph.dir = photon_dir_encode(v3(0, 0, 1));
    uint32_t start[2] = {0, 1};
    m.num_photons = 1;
    m.table_size = 1;
    m.num_emitted = 1;
    m.radius = 1e-30f;
    m.cell_size = 2e-30f;
    m.photons = &ph;
    m.bucket_start = start;
    m.decoded = NULL;
    m.beam = NULL;
    vec3 gk = photon_map_gather_knn(&m, v3(0, 0, 0), v3(1, 0, 0), 0.5f, 50, 2e-30f, PHOTON_DEPTH_ANY, 1.0f, 0.0f); /* outside the forward cone */
    cr_assert(v3_is_finite(gk) && gk.x > 0.0f);
    struct medium md;
    memset(&md, 0, sizeof md);
    md.sigma_t = v3(1, 1, 1);
    vec3 b = photon_map_beam(&m, v3(0, 0, -1), v3(0, 0, 1), 2.0f, &md, NULL, PHOTON_DEPTH_ANY);
    cr_assert(v3_is_finite(b));
}

Test(medium, encodings)
{
    vec3 c = v3(3.5f, 0.25f, 1e-3f);
    uint8_t e[4];
    photon_rgbe_encode(c, e);
    vec3 d = photon_rgbe_decode(e);
    cr_assert(fabsf(d.x - c.x) < 0.02f * c.x && fabsf(d.y - c.y) < 0.02f * c.x);
    for (int i = 0; i < 100; i++) {
        uint64_t k = rng_key(1, 0, (uint64_t)i, 0);
        vec3 v = v3_normalize(v3(rng_uniform(k, 0) - 0.5f, rng_uniform(k, 1) - 0.5f, rng_uniform(k, 2) - 0.5f));
        vec3 w = photon_dir_decode(photon_dir_encode(v));
        cr_assert(v3_dot(v, w) > 0.999f, "dir error %g", (double)v3_dot(v, w));
    }
    /* The depth word: events kept whole; the density floor within a factor 2 below the
     * density (down to 2^-32 of the grid's maximum), 1/2 at the maximum and in
     * homogeneous media (code 0), and the weight capped at PHOTON_DENSITY_RATIO floors. */
    for (uint32_t ev = 1; ev <= PHOTON_DEPTH_MAX; ev = ev * 3 + 1) {
        for (float rel = 1.0f; rel > 1e-12f; rel *= 0.37f) {
            uint16_t w = photon_depth_word(ev, rel);
            cr_assert_eq(PHOTON_EVENTS(w), ev);
            float fl = photon_density_floor(w);
            if (rel >= 0x1p-32f)
                cr_assert(fl <= rel && fl >= 0.5f * rel, "rel %g floor %g", (double)rel, (double)fl);
            else
                cr_assert_eq(fl, 0x1p-32f);
        }
        cr_assert_eq(photon_depth_word(ev, 1.0f), ev);
        cr_assert_eq(PHOTON_EVENTS(photon_depth_word(PHOTON_DEPTH_MAX, 1e-30f)), PHOTON_DEPTH_MAX);
    }
    cr_assert_eq(photon_density_floor(photon_depth_word(7, 1.0f)), 0.5f);
    cr_assert_eq(photon_density_weight(0.5f, 0.25f, 2.0f), 0.5f);
    cr_assert_eq(photon_density_weight(9.0f, 0.25f, 2.0f), PHOTON_DENSITY_RATIO * 0.5f);
}

/* ---- scene keys ---- */

static void expect_error(const char *text, const char *want)
{
    grid_bytes();
    test_scene_expect_error(text, g_files, want);
}

#define H HEAD("\"position\": [0, 0, -5], \"look_at\": [0, 0, 0]", 8, 8, 1, 4)

Test(medium, scene_keys)
{
    struct scene s;
    load_ok(H ",\n\"media\": {\"fog\": {\"sigma_a\": [0.1, 0.2, 0.3], \"sigma_s\": [1, 1, 1], \"emission\": [0, 0, 1], \"g\": 0.4}},\n"
              "\"volume\": {\"method\": \"vpt\", \"fog\": \"fog\", \"photons\": 5, \"radius\": 0.5, \"step\": 0.1, "
              "\"skip_bound\": 0.2, \"max_photon_depth\": 7, \"knn\": 20, \"shadow_cache\": false, \"indirect\": \"path\"},\n"
              "\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"medium\": \"fog\"}],\n"
              "\"lights\": [{\"type\": \"spot\", \"position\": [0, 1, 0], \"look_at\": [0, 0, 0], \"intensity\": [1, 1, 1], \"angle\": 30, \"falloff\": 10}]}",
            &s);
    cr_assert_eq(s.media->num_media, 1u);
    cr_assert_eq(s.media->fog, 0u);
    cr_assert_eq(s.media->method, MEDIA_VPT);
    cr_assert_eq(s.media->photons, 5u);
    cr_assert_eq(s.media->max_photon_depth, 7u);
    cr_assert_eq(s.media->knn, 20u);
    cr_assert_eq(s.media->shadow_cache, 0);
    cr_assert_eq(s.media->indirect, MEDIA_INDIRECT_PATH);
    cr_assert_eq(media_direct_samples(s.media), 1u); /* vpt's default */
    s.media->method = MEDIA_MARCH_BEAM;
    cr_assert_eq(media_direct_samples(s.media), MEDIA_DEFAULT_DIRECT_SAMPLES); /* the photon methods' */
    s.media->direct_samples = 3;
    cr_assert_eq(media_direct_samples(s.media), 3u);
    cr_assert_eq(media_sphere_inside(s.media, 0), 0u);
    cr_assert_eq(s.spheres[0].material_id, s.media->interface_material);
    cr_assert_eq(s.lights[0].type, LIGHT_SPOT);
    cr_assert(fabsf(s.lights[0].cos_outer - cosf(30.0f * (float)M_PI / 180.0f)) < 1e-6f);
    cr_assert(fabsf(s.lights[0].cos_inner - cosf(20.0f * (float)M_PI / 180.0f)) < 1e-6f);
    cr_assert(fabsf(s.lights[0].direction.y + 1.0f) < 1e-6f);
    cr_assert(fabsf(light_spot_falloff(&s.lights[0], v3(0, -1, 0)) - 1.0f) < 1e-6f);
    cr_assert_eq(light_spot_falloff(&s.lights[0], v3(1, -1, 0)), 0.0f);
    scene_fini(&s);

    expect_error(H ",\n\"media\": {\"fog\": {\"sigma_q\": [1, 1, 1]}}}", "scenes/t.json:4:19: unknown key \"sigma_q\" in medium \"fog\"");
    expect_error(H ",\n\"media\": {\"fog\": {\"sigma_s\": 1}}}", "scenes/t.json:4:30: sigma_s must be an array of 3 numbers");
    expect_error(H ",\n\"media\": {\"fog\": {\"sigma_s\": [1, -1, 1]}}}", "scenes/t.json:4:34: sigma_s components must be in [0, 1e+30]");
    expect_error(H ",\n\"media\": {\"fog\": {\"g\": 1}}}", "scenes/t.json:4:24: g must be in (-1, 1)");
    expect_error(H ",\n\"media\": {\"fog\": {}},\n\"volume\": {\"method\": \"fast\"}}", "scenes/t.json:5:22: method must be");
    expect_error(H ",\n\"media\": {\"fog\": {}},\n\"volume\": {\"indirect\": \"photons\"}}",
                 "scenes/t.json:5:24: indirect must be \"gather\" or \"path\"");
    expect_error(H ",\n\"media\": {\"fog\": {}},\n\"volume\": {\"indirect\": 1}}", "scenes/t.json:5:24: indirect must be");
    expect_error(H ",\n\"media\": {\"fog\": {}},\n\"volume\": {\"fog\": \"smoke\"}}", "scenes/t.json:5:19: unknown medium \"smoke\"");
    expect_error(H ",\n\"media\": {\"fog\": {}},\n\"volume\": {\"photons\": 1.5}}", "scenes/t.json:5:23: photons must be an integer");
    expect_error(H ",\n\"media\": {\"fog\": {}},\n\"volume\": {\"knn\": 0}}", "scenes/t.json:5:19: knn 0 out of range 1..1024");
    expect_error(H ",\n\"media\": {\"fog\": {}},\n\"volume\": {\"direct_samples\": 0}}",
                 "scenes/t.json:5:30: direct_samples 0 out of range 1..64");
    expect_error(H ",\n\"media\": {\"fog\": {}},\n\"volume\": {\"direct_samples\": 65}}",
                 "scenes/t.json:5:30: direct_samples 65 out of range 1..64");
    expect_error(H ",\n\"media\": {\"fog\": {}},\n\"volume\": {\"photon_split\": 0}}",
                 "scenes/t.json:5:28: photon_split 0 out of range 1..64");
    expect_error(H ",\n\"media\": {\"fog\": {}},\n\"volume\": {\"photon_split\": 65}}",
                 "scenes/t.json:5:28: photon_split 65 out of range 1..64");
    expect_error(H ",\n\"media\": {\"fog\": {}},\n\"volume\": {\"shadow_cache\": 1}}", "scenes/t.json:5:28: shadow_cache must be true or false");
    expect_error(H ",\n\"volume\": {}}", "scenes/t.json:4:1: \"volume\" needs \"media\"");
    expect_error(H ",\n\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"medium\": \"x\"}]}",
                 "scenes/t.json:4:76: unknown medium \"x\"");
    expect_error(H ",\n\"lights\": [{\"type\": \"spot\", \"position\": [0, 0, 0], \"intensity\": [1, 1, 1], \"angle\": 200, \"direction\": [0, 1, 0]}]}",
                 "scenes/t.json:4:85: angle (half-angle of the cone, degrees) must be in (0, 180]");
    expect_error(H ",\n\"lights\": [{\"type\": \"spot\", \"position\": [0, 0, 0], \"intensity\": [1, 1, 1], \"angle\": 20}]}",
                 "scenes/t.json:4:12: lights[0]: give exactly one of \"direction\" and \"look_at\"");
}

/* ---- shadow transmittance cache and k-nearest query ---- */

/* Optical depth by a fine midpoint rule (the reference of the cache tests). */
static double tau_reference(const struct medium *md, vec3 a, vec3 b)
{
    vec3 ab = v3_sub(b, a);
    double len = v3_length(ab), tau = 0.0;
    const int n = 20000;
    for (int i = 0; i < n; i++)
        tau += grid_density(md->grid, v3_add(a, v3_scale(ab, (float)((i + 0.5) / n)))) * len / n;
    return tau;
}

/* Stated bound, on the test grid (a density spike 20x its neighbours in one voxel: the
 * cache's worst case, as its shadow's edge is one voxel wide and the lattice has one vertex
 * per voxel): the cached transmittance (sigma_t 2.5) toward a point light outside and one
 * inside the grid is within 0.3 (absolute) of a fine integration at every probed point and
 * within 0.02 on average (measured 0.275 and 0.017); the lattice's own values
 * (grid_optical_depth, half-voxel midpoint rule) within 0.01 (measured 0.007); the same
 * bytes for 1 and 3 filling threads. */
Test(medium, shadow_cache_vs_exact, .timeout = 60)
{
    struct scene s;
    load_ok(HEAD("\"position\": [-5, 0, 0], \"look_at\": [0, 0, 0]", 1, 1, 1, 1)
            ",\n\"media\": {\"m\": " GRID_MEDIUM "},\n\"volume\": {\"fog\": \"m\"}}", &s);
    const struct medium *md = &s.media->media[0];
    vec3 lights[2] = {v3(3.0f, 2.5f, -1.5f), v3(0.1f, 0.2f, 0.3f)}; /* outside, and inside the grid */
    double worst = 0.0, sum = 0.0, worst_exact = 0.0;
    int count = 0;
    for (int l = 0; l < 2; l++) {
        struct tr_cache c1, c3;
        cr_assert_eq(tr_cache_init(&c1, md, lights[l], 1), 1);
        cr_assert_eq(tr_cache_init(&c3, md, lights[l], 3), 1);
        size_t nv = (size_t)c1.n[0] * c1.n[1] * c1.n[2];
        cr_assert(nv > 8 && memcmp(&c1.n, &c3.n, sizeof c1.n) == 0);
        cr_assert(memcmp(c1.tau, c3.tau, nv * sizeof *c1.tau) == 0, "cache depends on the thread count");
        float tau;
        cr_assert_eq(tr_cache_tau(&c1, v3_add(c1.hi, v3(0.01f, 0, 0)), &tau), 0, "outside the lattice");
        for (int i = 0; i < 400; i++) {
            vec3 p = v3(c1.lo.x + (c1.hi.x - c1.lo.x) * rng_uniform(77, 3 * (uint32_t)i),
                        c1.lo.y + (c1.hi.y - c1.lo.y) * rng_uniform(77, 3 * (uint32_t)i + 1),
                        c1.lo.z + (c1.hi.z - c1.lo.z) * rng_uniform(77, 3 * (uint32_t)i + 2));
            cr_assert_eq(tr_cache_tau(&c1, p, &tau), 1);
            double ref = tau_reference(md, p, lights[l]);
            double ex = grid_optical_depth(md, p, lights[l]);
            worst_exact = fmax(worst_exact, fabs(exp(-2.5 * ex) - exp(-2.5 * ref)));
            /* sigma_t = 2.5 is the channel that darkens most */
            double e = fabs(exp(-2.5 * tau) - exp(-2.5 * ref));
            worst = fmax(worst, e);
            sum += e;
            count++;
        }
        /* From points outside the lattice (zero density there): the value where the segment
         * enters the box, within the same bound; 0 when it misses the box. */
        double worst_out = 0.0;
        for (int i = 0; i < 200; i++) {
            vec3 dir = v3_normalize(v3(rng_uniform(78, 3 * (uint32_t)i) - 0.5f, rng_uniform(78, 3 * (uint32_t)i + 1) - 0.5f,
                                       rng_uniform(78, 3 * (uint32_t)i + 2) - 0.5f));
            vec3 p = v3_add(v3_scale(v3_add(c1.lo, c1.hi), 0.5f), v3_scale(dir, 2.0f * v3_length(v3_sub(c1.hi, c1.lo))));
            cr_assert_eq(tr_cache_tau(&c1, p, &tau), 0);
            cr_assert_eq(tr_cache_tau_from(&c1, p, &tau), 1);
            worst_out = fmax(worst_out, fabs(exp(-2.5 * tau) - exp(-2.5 * tau_reference(md, p, lights[l]))));
        }
        cr_log_info("shadow cache from outside: worst |dTr| %.4f", worst_out);
        cr_assert(worst_out < 0.3, "cache from outside: worst %g", worst_out);
        vec3 far = v3_add(c1.hi, v3(10, 10, 10)), light = c1.light;
        c1.light = v3_add(far, v3(1, 0, 0)); /* a segment beside the box */
        cr_assert(tr_cache_tau_from(&c1, far, &tau) == 1 && tau == 0.0f, "a segment that misses the box");
        c1.light = light;
        cr_assert_eq(tr_cache_tau_from(&c1, v3(NAN, 0, 0), &tau), 0);
        tr_cache_fini(&c1);
        tr_cache_fini(&c3);
        cr_assert_null(c1.tau);
    }
    cr_log_info("shadow cache: worst |dTr| %.4f, mean %.5f; exact entries worst |dTr| %.5f", worst, sum / count,
                worst_exact);
    cr_assert(worst_exact < 0.01, "grid_optical_depth off by %g", worst_exact);
    cr_assert(worst < 0.3, "cache worst %g", worst);
    cr_assert(sum / count < 0.02, "cache mean %g", sum / count);
    /* Homogeneous media have no cache. */
    struct medium hom;
    memset(&hom, 0, sizeof hom);
    struct tr_cache ch;
    cr_assert_eq(tr_cache_init(&ch, &hom, v3(0, 0, 0), 2), 0);
    cr_assert_null(ch.tau);
    scene_fini(&s);
}

static int knn_cmp(const void *a, const void *b)
{
    const float *x = a, *y = b;
    return (x[0] > y[0]) - (x[0] < y[0]) ? (x[0] > y[0]) - (x[0] < y[0]) : (x[1] > y[1]) - (x[1] < y[1]);
}

/* The k-nearest query returns exactly the k nearest photons within rmax (ties by index),
 * checked against brute force over the whole map, and the radius of the estimate. */
Test(medium, knn_matches_brute_force, .timeout = 60)
{
    struct scene s;
    load_ok(HEAD("\"position\": [0, 0, -25], \"look_at\": [0, 0, 0]", 1, 1, 1, 4)
            ",\n\"materials\": {\"w\": {\"type\": \"diffuse\", \"albedo\": [0.5, 0.5, 0.5]}},"
            "\n\"media\": {\"m\": " GRID_MEDIUM "},\n\"volume\": {\"fog\": \"m\", \"photons\": 20000, \"radius\": 0.08},"
            "\n\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 3, \"material\": \"w\"}],"
            "\n\"lights\": [{\"type\": \"point\", \"position\": [0.2, 0.1, -0.3], \"intensity\": [5, 5, 5]}]}", &s);
    struct photon_map *map = decode_map(&s, 2000);
    const struct photon_map *m = map;
    float (*all)[2] = malloc(sizeof *all * m->num_photons);
    uint32_t idx[PM_KNN_MAX];
    uint32_t ks[4] = {1, 8, 50, 300};
    int full = 0, partial = 0;
    for (int q = 0; q < 200; q++) {
        vec3 x = v3(-1 + 2 * rng_uniform(91, 3 * (uint32_t)q), -1 + 2 * rng_uniform(91, 3 * (uint32_t)q + 1),
                    -1 + 2 * rng_uniform(91, 3 * (uint32_t)q + 2));
        if (q < 20) /* some queries on photons themselves */
            x = v3(m->photons[q * 37].p[0], m->photons[q * 37].p[1], m->photons[q * 37].p[2]);
        uint32_t k = ks[q % 4];
        float rmax = (q % 3 == 0 ? 6.0f : 2.0f) * m->radius, r2; /* several rings of cells, or few */
        uint32_t n = photon_map_knn(m, x, k, rmax, idx, &r2);
        uint32_t nb = 0;
        for (uint32_t i = 0; i < m->num_photons; i++) {
            vec3 dp = v3_sub(v3(m->photons[i].p[0], m->photons[i].p[1], m->photons[i].p[2]), x);
            float d2 = v3_dot(dp, dp);
            if (d2 <= rmax * rmax) {
                all[nb][0] = d2;
                all[nb][1] = (float)i;
                nb++;
            }
        }
        qsort(all, nb, sizeof *all, knn_cmp);
        uint32_t want = nb < k ? nb : k;
        cr_assert_eq(n, want, "query %d k %u: %u photons, brute force %u", q, k, n, want);
        float got[PM_KNN_MAX][2];
        for (uint32_t j = 0; j < n; j++) {
            vec3 dp = v3_sub(v3(m->photons[idx[j]].p[0], m->photons[idx[j]].p[1], m->photons[idx[j]].p[2]), x);
            got[j][0] = v3_dot(dp, dp);
            got[j][1] = (float)idx[j];
        }
        qsort(got, n, sizeof *got, knn_cmp);
        for (uint32_t j = 0; j < n; j++)
            cr_assert(got[j][0] == all[j][0], "query %d: %u-th nearest %g vs %g", q, j, (double)got[j][0], (double)all[j][0]);
        if (n == k) {
            full++;
            cr_assert(r2 == all[k - 1][0]);
        } else {
            partial++;
            cr_assert(r2 == rmax * rmax);
        }
        vec3 e = photon_map_gather_knn(m, x, v3(0, 0, 1), 0.3f, k, rmax, PHOTON_DEPTH_ANY, 1.0f, 0.0f);
        /* > 0 unless every photon found lies in the forward cone (photon_map.h) */
        cr_assert(v3_is_finite(e) && (n > 0 ? e.x >= 0.0f : e.x == 0.0f));
    }
    cr_assert(full > 20 && partial > 5, "queries too easy: %d full, %d partial", full, partial);
    free(all);
    photon_map_free(&map);
    scene_fini(&s);
}

/* The estimate's definition, over every photon: closest-point parameter in [0, t1),
 * within r of the ray, phase x power x transmittance / (pi r^2) (saturated as the map's). */
static vec3 beam_brute_force(const struct photon_map *m, vec3 o, vec3 d, float t1, const struct medium *md,
                             uint32_t depth_max)
{
    double acc[3] = {0, 0, 0};
    float r = m->radius;
    for (uint32_t i = 0; i < m->num_photons; i++) {
        const struct photon *ph = &m->photons[i];
        vec3 dp = v3_sub(v3(ph->p[0], ph->p[1], ph->p[2]), o);
        float t = v3_dot(dp, d);
        vec3 perp = v3_sub(dp, v3_scale(d, t));
        if (t < 0.0f || !(t < t1) || v3_dot(perp, perp) > r * r || ph->depth > depth_max)
            continue;
        float f = phase_hg_cut(v3_dot(photon_dir_decode(ph->dir), v3_neg(d)), md->g);
        vec3 c = v3_mul(v3_scale(photon_rgbe_decode(ph->rgbe), f), medium_transmittance(md, t));
        acc[0] += c.x, acc[1] += c.y, acc[2] += c.z;
    }
    double k = 1.0 / (M_PI * fmax(r, 1e-9) * fmax(r, 1e-9));
    return v3((float)fmin(acc[0] * k, 1e30), (float)fmin(acc[1] * k, 1e30), (float)fmin(acc[2] * k, 1e30));
}

/* The beam query (rows of photons built at decode) against the loop over every photon,
 * to 1e-5 relative: random rays and rays aimed at photons, segments starting and ending
 * inside the photons' box, rays along the axes, a far-off cluster, radii from 1e-30 to 50
 * times the box, photon depths filtered. */
Test(medium, beam_matches_brute_force, .timeout = 120)
{
    struct { vec3 c; float half, r; uint32_t n; } cfg[] = {
        {{0, 0, 0}, 1.0f, 0.05f, 20000},   {{0, 0, 0}, 1.0f, 0.2f, 5000},  {{0, 0, 0}, 1.0f, 1e-4f, 20000},
        {{0, 0, 0}, 1.0f, 1e-30f, 3000},   {{0, 0, 0}, 1.0f, 50.0f, 3000}, {{1000, -500, 200}, 1.0f, 0.02f, 20000},
        {{0.3f, 0, -2}, 40.0f, 0.5f, 20000},
    };
    struct medium md;
    memset(&md, 0, sizeof md);
    md.sigma_t = v3(0.3f, 0.7f, 1.5f);
    md.g = 0.4f;
    uint32_t rays = 0, nonzero = 0;
    for (uint32_t c = 0; c < sizeof cfg / sizeof cfg[0]; c++) {
        struct photon_list block = {NULL, cfg[c].n, cfg[c].n};
        block.a = malloc(sizeof *block.a * cfg[c].n);
        for (uint32_t i = 0; i < cfg[c].n; i++) {
            uint64_t k = rng_key(301, c, i, 0);
            struct photon *ph = &block.a[i];
            /* half the photons in a few tight clumps, so rows hold very different counts */
            float s = i % 2 ? cfg[c].half : 0.05f * cfg[c].half;
            float at[3] = {cfg[c].c.x + (i % 2 ? 0.0f : 0.3f * cfg[c].half * ((float)(i % 6) - 2.5f)), cfg[c].c.y,
                           cfg[c].c.z};
            for (int a = 0; a < 3; a++)
                ph->p[a] = at[a] + s * (2.0f * rng_uniform(k, (uint32_t)a) - 1.0f);
            photon_rgbe_encode(v3(rng_uniform(k, 3), rng_uniform(k, 4), 0.1f + rng_uniform(k, 5)), ph->rgbe);
            ph->dir = photon_dir_encode(v3_normalize(v3(rng_uniform(k, 6) - 0.5f, rng_uniform(k, 7) - 0.5f,
                                                        rng_uniform(k, 8) - 0.5f)));
            ph->depth = (uint16_t)(1 + i % 8);
        }
        uint8_t *blob = NULL;
        size_t bytes = 0;
        uint32_t count = 0;
        char err[256];
        cr_assert_eq(photon_map_serialise(&block, 1, cfg[c].r, cfg[c].n, &blob, &bytes, &count, err, sizeof err), 0);
        struct photon_map *m = NULL;
        /* the rows along x, y and z in turn (photon_map_decode_rows) */
        cr_assert_eq(photon_map_decode_rows(blob, bytes, (int)(c % 3), &m, err, sizeof err), 0, "%s", err);
        free(blob);
        cr_assert_not_null(m->beam);
        for (uint32_t q = 0; q < 400; q++) {
            uint64_t k = rng_key(302, c, q, 0);
            float h = cfg[c].half;
            vec3 o = v3_add(cfg[c].c, v3_scale(v3(rng_uniform(k, 0) - 0.5f, rng_uniform(k, 1) - 0.5f,
                                                  rng_uniform(k, 2) - 0.5f), (q % 3 ? 2.5f : 6.0f) * h));
            vec3 d = v3_normalize(v3(rng_uniform(k, 3) - 0.5f, rng_uniform(k, 4) - 0.5f, rng_uniform(k, 5) - 0.5f));
            if (q % 5 == 0) { /* along an axis, either way */
                float dd[3] = {0, 0, 0};
                dd[q / 5 % 3] = q / 15 % 2 ? -1.0f : 1.0f;
                d = v3(dd[0], dd[1], dd[2]);
            }
            float t1 = (0.05f + 3.0f * rng_uniform(k, 6)) * h;
            if (q % 7 == 0)
                t1 = 1e30f;
            if (q % 4 == 1) { /* through a photon: o before it, or the photon inside the segment */
                const float *p = m->photons[(q * 7919u) % m->num_photons].p;
                o = v3_sub(v3(p[0], p[1], p[2]), v3_scale(d, t1 * rng_uniform(k, 7)));
            }
            uint32_t depth_max = q % 3 == 0 ? PHOTON_DEPTH_ANY : 1 + q % 8;
            vec3 a = photon_map_beam(m, o, d, t1, &md, NULL, depth_max);
            vec3 b = beam_brute_force(m, o, d, t1, &md, depth_max);
            float tol = 1e-5f * fmaxf(v3_max_component(b), 1e-30f);
            cr_assert(fabsf(a.x - b.x) <= tol && fabsf(a.y - b.y) <= tol && fabsf(a.z - b.z) <= tol,
                      "config %u ray %u: beam (%g %g %g), brute force (%g %g %g)", c, q, (double)a.x, (double)a.y,
                      (double)a.z, (double)b.x, (double)b.y, (double)b.z);
            rays++;
            nonzero += v3_max_component(b) > 0.0f;
        }
        photon_map_free(&m);
    }
    cr_assert(nonzero > rays / 3, "only %u of %u rays found photons", nonzero, rays);
}

/* March with the shadow cache against the exact marched shadow rays on the grid scene (a
 * density spike 20x its neighbours, the cache's worst case): image means within 2 %. */
#define CACHE_SCENE(flag)                                                                                      \
    HEAD("\"position\": [0, 0, -2.5], \"look_at\": [0, 0, 0]", 16, 16, 1, 4)                                     \
    ",\n\"materials\": {\"black\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0]}},"                          \
    "\n\"media\": {\"m\": " GRID_MEDIUM "},\n\"volume\": {\"fog\": \"m\", \"method\": \"march\", \"photons\": 0," \
    " \"shadow_cache\": " flag "},"                                                                             \
    "\n\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 4, \"material\": \"black\"}],"   \
    "\n\"lights\": [{\"type\": \"point\", \"position\": [1.5, 1.2, -1.0], \"intensity\": [20, 20, 20]}]}"
Test(medium, march_shadow_cache_image_bias, .timeout = 120)
{
    const char *text[2] = {CACHE_SCENE("false"), CACHE_SCENE("true")};
    double mean[2], se[2];
    for (int c = 0; c < 2; c++) {
        struct scene s;
        load_ok(text[c], &s);
        cr_assert_eq(s.media->shadow_cache, c);
        mean[c] = render_mean(&s, NULL, 16, &se[c]);
        scene_fini(&s);
    }
    cr_log_info("march: exact shadows %g +- %g, cached %g +- %g", mean[0], se[0], mean[1], se[1]);
    cr_assert(mean[0] > 0.01 && fabs(mean[1] / mean[0] - 1.0) < 0.02, "cached %g vs exact %g", mean[1], mean[0]);
}

/* Without volume.step a march in a grid takes its in-scattering every GRID_STEP_VOXELS
 * voxels (0.5 here, voxels of 0.25), but at most GRID_STEP_CAP times a homogeneous
 * medium's step (1/200 of the scene's diagonal); a step the scene gives is kept. STEP_SCENE
 * is CACHE_SCENE in a black sphere of radius R: the cap binds at R = 4, not at R = 40. The
 * jittered steps are unbiased at any length: the image mean with the default step is that
 * of steps of half a voxel (the optical depth's, so NEE at every one) within 4 standard
 * errors, for fewer shadow rays. */
#define STEP_SCENE(r, step)                                                                                    \
    HEAD("\"position\": [0, 0, -2.5], \"look_at\": [0, 0, 0]", 16, 16, 1, 4)                                     \
    ",\n\"materials\": {\"black\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0]}},"                          \
    "\n\"media\": {\"m\": " GRID_MEDIUM "},\n\"volume\": {\"fog\": \"m\", \"method\": \"march\", \"photons\": 0" step "}," \
    "\n\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": " #r ", \"material\": \"black\"}],"  \
    "\n\"lights\": [{\"type\": \"point\", \"position\": [1.5, 1.2, -1.0], \"intensity\": [20, 20, 20]}]}"
Test(medium, march_step_default_in_grids, .timeout = 60)
{
    const char *text[3] = {STEP_SCENE(40, ""), STEP_SCENE(40, ", \"step\": 0.125"), STEP_SCENE(4, "")};
    double mean[2], se[2];
    uint64_t rays[2];
    for (int c = 0; c < 3; c++) {
        struct scene s;
        load_ok(text[c], &s);
        struct render_job job;
        job_ok(&job, &s);
        const struct medium *md = &s.media->media[0];
        const float voxels = GRID_STEP_VOXELS * md->grid->voxel_world;
        cr_assert_eq(job.media->sm->step > 0.0f, c == 1); /* the scene gives a step */
        if (c != 1)
            cr_assert_eq(job.media->step, job.media->scene_size / 200.0f);
        if (c == 0) {
            cr_assert(voxels < GRID_STEP_CAP * job.media->step, "the cap binds: a weak test");
            cr_assert_eq(media_step(job.media, md), voxels);
            struct medium fog = *md; /* the same medium without its grid: the job's step */
            fog.grid = NULL;
            cr_assert_eq(media_step(job.media, &fog), job.media->step);
        } else if (c == 1) {
            cr_assert_eq(media_step(job.media, md), 0.125f);
        } else {
            cr_assert(GRID_STEP_CAP * job.media->step < voxels, "the cap does not bind: a weak test");
            cr_assert_eq(media_step(job.media, md), GRID_STEP_CAP * job.media->step);
        }
        render_job_fini(&job);
        if (c < 2) {
            s.settings.spp = 16;
            struct tile_stats st;
            float *px = test_render_map(&s, NULL, 1, &st);
            mean[c] = test_channel_mean(px, s.settings.width, s.settings.height, CH_R, &se[c]);
            rays[c] = st.rays;
            free(px);
        }
        scene_fini(&s);
    }
    cr_log_info("march: default step %g +- %g (%llu rays), half a voxel %g +- %g (%llu rays)", mean[0], se[0],
                (unsigned long long)rays[0], mean[1], se[1], (unsigned long long)rays[1]);
    cr_assert(mean[1] > 0.01 && fabs(mean[0] - mean[1]) < 4.0 * sqrt(se[0] * se[0] + se[1] * se[1]),
              "default step %g +- %g vs half a voxel %g +- %g", mean[0], se[0], mean[1], se[1]);
    cr_assert(rays[0] < rays[1] / 2, "default step %llu rays, half a voxel %llu", (unsigned long long)rays[0],
              (unsigned long long)rays[1]);
}

/* ---- photon methods against VPT over seeds (docs/media.md: open fog, the forward cone,
 * final gather) ---- */

/* The scene's photon map traced with photon seed `seed`, decoded as a worker does. */
static struct photon_map *seeded_map(const struct scene *s, uint64_t seed)
{
    struct render_job job;
    job_ok(&job, s);
    uint8_t *blob = NULL;
    size_t n;
    struct photon_pass_stats st;
    char err[256];
    cr_assert_eq(photon_trace_map(&job, seed, 2, &blob, &n, &st, err, sizeof err), 0, "%s", err);
    render_job_fini(&job);
    struct photon_map *m = NULL;
    cr_assert_eq(photon_map_decode(blob, n, &m, err, sizeof err), 0, "%s", err);
    free(blob);
    return m;
}

/* Mean over `seeds` renders (render seed and photon seed 1..seeds) of the image mean of
 * `text` by `method`, and the standard error of that mean from the spread over seeds. */
static double seeds_mean(const char *text, enum media_method method, uint32_t spp, int seeds, double *se)
{
    double sum = 0.0, sum2 = 0.0;
    for (int k = 1; k <= seeds; k++) {
        struct scene s;
        load_ok(text, &s);
        s.media->method = method;
        s.settings.seed = (uint64_t)k;
        struct photon_map *map = method == MEDIA_VPT ? NULL : seeded_map(&s, (uint64_t)k);
        double e, m = render_mean(&s, map, spp, &e);
        photon_map_free(&map);
        scene_fini(&s);
        sum += m;
        sum2 += m * m;
    }
    double mean = sum / seeds, var = (sum2 / seeds - mean * mean) * seeds / (seeds - 1);
    *se = sqrt(fmax(var, 0.0) / seeds);
    return mean;
}

/* a within 4 combined standard errors of b, plus `bias` of b (a stated kernel bias). */
static void agree(const char *what, double a, double se_a, double b, double se_b, double bias)
{
    double tol = 4.0 * sqrt(se_a * se_a + se_b * se_b) + bias * fabs(b);
    cr_assert(fabs(a - b) <= tol, "%s: %g +- %g vs vpt %g +- %g (tolerance %g)", what, a, se_a, b, se_b, tol);
}

/* Beam and march (photon_spp samples) agree with VPT (64 samples) over 4 seeds, within
 * the stated 3 % kernel bias; vpt_text may differ from photon_text only in its method. */
static void photon_methods_match_vpt(const char *what, const char *vpt_text, const char *photon_text,
                                     uint32_t photon_spp)
{
    double se_v, vpt = seeds_mean(vpt_text, MEDIA_VPT, 64, 4, &se_v);
    double se_b, beam = seeds_mean(photon_text, MEDIA_MARCH_BEAM, photon_spp, 4, &se_b);
    double se_m, march = seeds_mean(photon_text, MEDIA_MARCH_STEPS, photon_spp, 4, &se_m);
    fprintf(stderr, "%s: vpt %g +- %g, beam %g +- %g, march %g +- %g\n", what, vpt, se_v, beam, se_b, march, se_m);
    cr_assert(vpt > 0.01);
    agree("beam", beam, se_b, vpt, se_v, 0.03);
    agree("march", march, se_m, vpt, se_v, 0.03);
}

/* Open fog: a fog that fills all space, a floor and a sphere, a point light, no walls.
 * Light scatters outside the box around geometry, lights and camera and comes back; march
 * and beam follow camera rays past it and keep photons as far (the bounds rule). */
#define OPEN_FOG_SCENE                                                                                      \
    HEAD("\"position\": [0, 1, -5], \"look_at\": [0, -0.3, 0]", 12, 9, 1, 64)                               \
    ",\n\"materials\": {\"white\": {\"type\": \"diffuse\", \"albedo\": [0.6, 0.6, 0.6]}},\n"                 \
    "\"media\": {\"fog\": {\"sigma_a\": [0.1, 0.1, 0.1], \"sigma_s\": [0.3, 0.3, 0.3], \"g\": 0.3}},\n"       \
    "\"volume\": {\"method\": \"beam\", \"fog\": \"fog\", \"photons\": 40000, \"radius\": 0.15, "            \
    "\"step\": 0.1},\n"                                                                                      \
    "\"objects\": [{\"type\": \"obj\", \"file\": \"floor.obj\", \"material\": \"white\"},\n"                 \
    "  {\"type\": \"sphere\", \"center\": [0, -0.2, 0], \"radius\": 1, \"material\": \"white\"}],\n"          \
    "\"lights\": [{\"type\": \"point\", \"position\": [1.5, 2, -1.5], \"intensity\": [20, 20, 20]}]}"

Test(medium, open_fog_matches_vpt, .timeout = 120)
{
    photon_methods_match_vpt("open fog", OPEN_FOG_SCENE, OPEN_FOG_SCENE, 8);
}

/* g = 0.999: a scattering sphere in a white room lit by a small sphere light, seen with
 * the room's walls behind it. Nearly all of its scattering lies in a spike narrower than
 * a photon's direction code; march and beam take that spike (the forward cone) as no
 * scattering. VPT is the reference (an area light, so its phase sampling finds the light
 * through the spike too). */
#define SPIKE_SCENE                                                                                         \
    HEAD("\"position\": [0, 0, -3.5], \"look_at\": [0, 0, 0]", 12, 12, 1, 64)                               \
    ",\n\"materials\": {\"white\": {\"type\": \"diffuse\", \"albedo\": [0.5, 0.5, 0.5]},\n"                 \
    "  \"lamp\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0], \"emission\": [20, 20, 20]}},\n"              \
    "\"media\": {\"m\": {\"sigma_a\": [0.3, 0.3, 0.3], \"sigma_s\": [2.7, 2.7, 2.7], \"g\": 0.999}},\n"       \
    "\"volume\": {\"method\": \"beam\", \"photons\": 100000, \"radius\": 0.06, \"step\": 0.03},\n"            \
    "\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"medium\": \"m\"},\n"        \
    "  {\"type\": \"sphere\", \"center\": [2, 2, -2], \"radius\": 0.5, \"material\": \"lamp\"},\n"           \
    "  {\"type\": \"obj\", \"file\": \"box.obj\", \"material\": \"white\", "                                  \
    "\"transform\": {\"scale\": [0.4, 0.4, 0.4]}}]}"

Test(medium, forward_spike_matches_vpt, .timeout = 120)
{
    photon_methods_match_vpt("g 0.999", SPIKE_SCENE, SPIKE_SCENE, 4);
    /* The cone's share: 0 at g = 0 (up to the cone's solid angle), most of it at 0.999. */
    cr_assert(phase_forward_mass(0.0f) < 1e-3 && phase_forward_mass(0.999f) > 0.97);
    cr_assert(fabs(phase_forward_mass(0.3f) - phase_forward_mass(0.30001f)) < 1e-4);
}

/* Final gather (the scattering sphere over the white floor): beam and march, their
 * diffuse vertices taking one bounce before the surface map is read, against VPT over
 * seeds; the stated 3 % is the volume kernel's blur at the sphere's boundary (the
 * photon_map_matches_vpt test). */
Test(medium, final_gather_matches_vpt, .timeout = 120)
{
    photon_methods_match_vpt("final gather", FLOOR_SCENE("vpt", "true"), FLOOR_SCENE("beam", "true"), 4);
}

/* A closed box filled with fog (Cornell-like: white walls, a sphere lamp near the ceiling,
 * the camera inside): every camera ray ends on a wall, so the image is the first wall's
 * direct light, the fog along the camera ray, and what the final gather's bounce (marched
 * through the fog by one point per segment, gather_segment) brings back. */
#define FOG_BOX_SCENE(depth) FOG_BOX_SCENE_AS(depth, "gather")
#define FOG_BOX_SCENE_AS(depth, indirect) FOG_BOX_SCENE_OF(depth, indirect, "0.6", "0.01")
/* wall: the walls' albedo; sa: the fog's sigma_a (sigma_s 0.06) */
#define FOG_BOX_SCENE_OF(depth, indirect, wall, sa)                                                         \
    HEAD("\"position\": [0, 0, -9], \"look_at\": [0, -1, 0]", 12, 12, 1, depth)                             \
    ",\n\"materials\": {\"white\": {\"type\": \"diffuse\", \"albedo\": [" wall ", " wall ", " wall "]},\n"     \
    "  \"lamp\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0], \"emission\": [20, 20, 20]}},\n"              \
    "\"media\": {\"fog\": {\"sigma_a\": [" sa ", " sa ", " sa "], \"sigma_s\": [0.06, 0.06, 0.06], \"g\": 0.2}},\n" \
    "\"volume\": {\"method\": \"beam\", \"fog\": \"fog\", \"photons\": 40000, \"radius\": 0.5, "              \
    "\"step\": 0.25, \"indirect\": \"" indirect "\"},\n"                                                         \
    "\"objects\": [{\"type\": \"obj\", \"file\": \"box.obj\", \"material\": \"white\"},\n"                    \
    "  {\"type\": \"sphere\", \"center\": [0, 7, 2], \"radius\": 1, \"material\": \"lamp\"}]}"

Test(medium, fog_box_gather_matches_vpt, .timeout = 180)
{
    photon_methods_match_vpt("fog box", FOG_BOX_SCENE(64), FOG_BOX_SCENE(64), 8);
}

/* Light that scatters many times: walls of albedo 0.9 and a fog of albedo 0.99, at
 * max_depth 64. Photon paths are bounded by the render's
 * max_depth (media_max_photon_depth), so the maps hold every photon a lookup may count;
 * bounded at 16 interactions instead, beam and march come out 35 % below VPT here (0.546
 * and 0.555 against 0.846). */
#define DEEP_FOG_BOX_SCENE FOG_BOX_SCENE_OF(64, "gather", "0.9", "0.0006")

Test(medium, deep_scattering_matches_vpt, .timeout = 240)
{
    photon_methods_match_vpt("deep fog box", DEEP_FOG_BOX_SCENE, DEEP_FOG_BOX_SCENE, 8);
}

/* max_depth counts the scattering and surface events of the whole path for every method:
 * march and beam count a march step's single scattering as one event and leave out the
 * photons whose light path would make the path too long (docs/media.md). Short paths are
 * where the counts differ most. */
Test(medium, max_depth_same_for_all_methods, .timeout = 240)
{
    photon_methods_match_vpt("fog box, max_depth 1", FOG_BOX_SCENE(1), FOG_BOX_SCENE(1), 8);
    photon_methods_match_vpt("fog box, max_depth 2", FOG_BOX_SCENE(2), FOG_BOX_SCENE(2), 8);
    photon_methods_match_vpt("fog box, max_depth 3", FOG_BOX_SCENE(3), FOG_BOX_SCENE(3), 8);
}

/* Path-traced indirect light (volume.indirect "path"): march and beam for the camera
 * segments up to the first diffuse vertex, VPT after its bounce. Every camera ray ends on
 * a wall of the fog box, so the whole image passes through the switch: light counted by
 * both parts or by neither would show as a bias against VPT. At max_depth 2 the switch
 * has one event left (a scattering in the fog or a wall): depth must carry over. The
 * photon pass keeps no surface map, which nothing would read. */
Test(medium, path_indirect_matches_vpt, .timeout = 240)
{
    struct scene s;
    load_ok(FOG_BOX_SCENE_AS(64, "path"), &s);
    cr_assert_eq(s.media->indirect, MEDIA_INDIRECT_PATH);
    cr_assert(!media_wants_surface_photons(s.media));
    struct photon_map *m = seeded_map(&s, 1);
    cr_assert(m->num_photons > 0);
    cr_assert(m->surface == NULL || m->surface->num_photons == 0, "a surface map for path-traced indirect light");
    photon_map_free(&m);
    scene_fini(&s);
    photon_methods_match_vpt("fog box, path", FOG_BOX_SCENE(64), FOG_BOX_SCENE_AS(64, "path"), 8);
    photon_methods_match_vpt("fog box, path, max_depth 2", FOG_BOX_SCENE(2), FOG_BOX_SCENE_AS(2, "path"), 8);
}


/* ---- photon beams (the beams method; estimator tests in test_beams.c) ---- */

/* A grey grid cloud (the test grid, 3 units wide) over a white floor, a point light. */
#define GRID_CLOUD_SCENE(method)                                                                            \
    HEAD("\"position\": [0, 1, -6], \"look_at\": [0, -0.2, 0]", 12, 9, 1, 64)                               \
    ",\n\"materials\": {\"white\": {\"type\": \"diffuse\", \"albedo\": [0.6, 0.6, 0.6]}},\n"                 \
    "\"media\": {\"c\": {\"sigma_a\": [0.1, 0.1, 0.1], \"sigma_s\": [0.9, 0.9, 0.9], \"g\": 0.3, "           \
    "\"density\": {\"file\": \"g.grid\", \"transform\": {\"scale\": 3, \"translate\": [-1.5, -1, -1.5]}}}},\n" \
    "\"volume\": {\"method\": \"" method "\", \"fog\": \"c\", \"photons\": 30000, \"radius\": 0.1, "          \
    "\"step\": 0.05},\n"                                                                                     \
    "\"objects\": [{\"type\": \"obj\", \"file\": \"floor.obj\", \"material\": \"white\"}],\n"                \
    "\"lights\": [{\"type\": \"point\", \"position\": [1.5, 3, -1.5], \"intensity\": [20, 20, 20]}]}"

/* Beams (8 spp, one map per seed) against VPT (64 spp) over 4 seeds, within 4 standard
 * errors plus the stated 3 % kernel bias; the map stores beams, not points, in a grey
 * medium; without the beams the image is darker (they carry the multiple scattering). */
static void beams_match_vpt(const char *what, const char *text)
{
    double se_v, vpt = seeds_mean(text, MEDIA_VPT, 64, 4, &se_v);
    double se_b, beams = seeds_mean(text, MEDIA_MARCH_BEAMS, 8, 4, &se_b);
    fprintf(stderr, "%s: vpt %g +- %g, beams %g +- %g\n", what, vpt, se_v, beams, se_b);
    cr_assert(vpt > 0.01);
    agree("beams", beams, se_b, vpt, se_v, 0.03);
    struct scene s;
    load_ok(text, &s);
    s.media->method = MEDIA_MARCH_BEAMS;
    struct photon_map *m = seeded_map(&s, 1);
    cr_assert(photon_beams_count(m->beams) > 1000, "%u beams", photon_beams_count(m->beams));
    cr_assert_eq(m->num_photons, 0);
    double se_w, with = render_mean(&s, m, 4, &se_w);
    photon_beams_free(&m->beams);
    double se_n, without = render_mean(&s, m, 4, &se_n);
    cr_assert(without < with - 4.0 * sqrt(se_w * se_w + se_n * se_n), "with %g, without %g", with, without);
    photon_map_free(&m);
    scene_fini(&s);
}

Test(medium, beams_match_vpt_homogeneous, .timeout = 240)
{
    beams_match_vpt("open fog, beams", OPEN_FOG_SCENE);
}

Test(medium, beams_match_vpt_grid, .timeout = 240)
{
    beams_match_vpt("grid cloud, beams", GRID_CLOUD_SCENE("beams"));
}

/* The beams map: the same bytes for 1 and 2 tracing threads. */
Test(medium, beams_map_same_bytes_any_threads)
{
    struct scene s;
    load_ok(GRID_CLOUD_SCENE("beams"), &s);
    uint8_t *blob[2];
    size_t n[2];
    for (uint32_t t = 0; t < 2; t++) {
        struct render_job job;
        job_ok(&job, &s);
        struct photon_pass_stats st;
        char err[256];
        cr_assert_eq(photon_trace_map(&job, 1, t + 1, &blob[t], &n[t], &st, err, sizeof err), 0, "%s", err);
        cr_assert(st.stored_beams > 1000);
        render_job_fini(&job);
    }
    cr_assert_eq(n[0], n[1]);
    cr_assert_eq(memcmp(blob[0], blob[1], n[0]), 0);
    free(blob[0]);
    free(blob[1]);
    scene_fini(&s);
}

/* A cloud over the floor of GRID_CLOUD_SCENE lit from the side by a light below the
 * floor's plane, the camera looking down at the floor in front of it: the floor's top gets
 * no direct light, only what the cloud scatters down to it, which the final gather's
 * bounce finds by sampling directions toward the media as well as by the cosine lobe
 * (gather_bounce): toward the grid's density (grid_aim) for the grid cloud, into the cone
 * around a medium sphere's bounding sphere for a homogeneous ball. Beam (64 spp, one map a
 * seed) agrees with VPT (1024 spp) over 8 seeds within 4 standard errors plus the stated 3 %
 * kernel bias. The grid's gather segments also take their beam in pieces (tau_table_piece). The
 * test fails with the aimed part's density halved in the mixture's pdf (the grid's floor
 * 14 % bright), with a picked piece counted once (18 % dark) or with its end moved (16 %
 * bright). */
#define FLOOR_LIT_BY_CLOUD(media, fog, objects)                                                             \
    HEAD("\"position\": [0, 1.5, -5], \"look_at\": [0, -1.2, -2.5]", 12, 9, 1, 64)                           \
    ",\n\"materials\": {\"white\": {\"type\": \"diffuse\", \"albedo\": [0.8, 0.8, 0.8]}},\n"                 \
    "\"media\": {\"c\": {\"sigma_a\": [0.05, 0.05, 0.05], \"sigma_s\": [1.5, 1.5, 1.5], \"g\": 0.3" media "}},\n" \
    "\"volume\": {\"method\": \"beam\"" fog ", \"photons\": 30000, \"radius\": 0.1, \"step\": 0.05},\n"       \
    "\"objects\": [{\"type\": \"obj\", \"file\": \"floor.obj\", \"material\": \"white\"}" objects "],\n"     \
    "\"lights\": [{\"type\": \"point\", \"position\": [8, -1.3, 0], \"intensity\": [300, 300, 300]}]}"
#define GRID_FLOOR_SCENE                                                                                    \
    FLOOR_LIT_BY_CLOUD(", \"density\": {\"file\": \"g.grid\", \"transform\": {\"scale\": 3, \"translate\": [-1.5, -1, -1.5]}}", \
                       ", \"fog\": \"c\"", "")
#define BALL_FLOOR_SCENE \
    FLOOR_LIT_BY_CLOUD("", "", ", {\"type\": \"sphere\", \"center\": [0, 0.4, 0], \"radius\": 1.2, \"medium\": \"c\"}")

static void floor_lit_by_cloud(const char *what, const char *text)
{
    double se_v, vpt = seeds_mean(text, MEDIA_VPT, 1024, 8, &se_v);
    double se_b, beam = seeds_mean(text, MEDIA_MARCH_BEAM, 64, 8, &se_b);
    fprintf(stderr, "floor lit by %s: beam %g +- %g, vpt %g +- %g\n", what, beam, se_b, vpt, se_v);
    cr_assert(vpt > 1e-3, "the floor is lit by the cloud: %g", vpt);
    agree(what, beam, se_b, vpt, se_v, 0.03);
}

Test(medium, gather_toward_media_matches_vpt, .timeout = 240)
{
    floor_lit_by_cloud("a grid cloud", GRID_FLOOR_SCENE);
    floor_lit_by_cloud("a homogeneous ball", BALL_FLOOR_SCENE);
}

/* The interaction box holds the geometry (the unit sphere) and every grid, with a little
 * padding, so a light at (4, 4, -4) is outside it on every axis and sends photons into one
 * octant only (check_emission above checks their power there); with a homogeneous fog
 * filling space there is no such box. */
Test(medium, interaction_bounds)
{
    struct scene s;
    struct render_job job;
    vec3 lo, hi;
    load_ok(EMIT_SCENE("{\"type\": \"point\", \"position\": [4, 4, -4], \"intensity\": [5, 5, 5]}"), &s);
    job_ok(&job, &s);
    cr_assert(photon_interaction_bounds(&job, &lo, &hi));
    cr_assert(lo.x <= -1.0f && lo.y <= -1.0f && lo.z <= -1.0f && hi.x >= 1.0f && hi.y >= 1.0f && hi.z >= 1.0f);
    cr_assert(lo.x > -1.1f && lo.y > -1.1f && lo.z > -1.1f && hi.x < 1.1f && hi.y < 1.1f && hi.z < 1.1f);
    render_job_fini(&job);
    scene_fini(&s);
    load_ok(GRID_CLOUD_SCENE("beam"), &s); /* the grid 3 wide from (-1.5, -1, -1.5), the floor 8 wide at y -1.2 */
    job_ok(&job, &s);
    cr_assert(photon_interaction_bounds(&job, &lo, &hi));
    cr_assert(lo.x <= -4.0f && lo.y <= -1.2f && hi.y >= 2.0f && hi.z >= 4.0f && hi.y < 2.1f, "%g %g", (double)lo.y,
              (double)hi.y);
    render_job_fini(&job);
    scene_fini(&s);
    load_ok(OPEN_FOG_SCENE, &s);
    job_ok(&job, &s);
    cr_assert_not(photon_interaction_bounds(&job, &lo, &hi));
    render_job_fini(&job);
    scene_fini(&s);
}

/* ---- the density ratio in grids ---- */

/* The grid cloud of GRID_CLOUD_SCENE at a gather radius of 0.3 (0.8 voxel), seen close. */
#define GRID_EDGE_SCENE(method)                                                                             \
    HEAD("\"position\": [0, 0.5, -4.5], \"look_at\": [0, 0, 0]", 24, 18, 1, 64)                            \
    ",\n\"materials\": {\"white\": {\"type\": \"diffuse\", \"albedo\": [0.6, 0.6, 0.6]}},\n"                 \
    "\"media\": {\"c\": {\"sigma_a\": [0.1, 0.1, 0.1], \"sigma_s\": [0.9, 0.9, 0.9], \"g\": 0.3, "           \
    "\"density\": {\"file\": \"g.grid\", \"transform\": {\"scale\": 3, \"translate\": [-1.5, -1, -1.5]}}}},\n" \
    "\"volume\": {\"method\": \"" method "\", \"fog\": \"c\", \"photons\": 60000, \"radius\": 0.3, "          \
    "\"step\": 0.05},\n"                                                                                     \
    "\"objects\": [],\n"                                                                                    \
    "\"lights\": [{\"type\": \"point\", \"position\": [1.5, 3, -1.5], \"intensity\": [20, 20, 20]}]}"

/* Per-pixel red of `text` by `method`, averaged over photon seeds 1..seeds and the same
 * render seeds, or render seed `render_seed` in all when it is not 0 (the spread is then
 * the maps'), (mean[i]), and the variance of that average from the spread over seeds
 * (var[i]). */
static void seeds_image(const char *text, enum media_method method, uint32_t spp, int seeds, uint64_t render_seed,
                        double *mean, double *var, uint32_t *npx)
{
    uint32_t n = 0;
    for (int k = 1; k <= seeds; k++) {
        struct scene s;
        load_ok(text, &s);
        s.media->method = method;
        s.settings.seed = render_seed ? render_seed : (uint64_t)k;
        s.settings.spp = spp;
        struct photon_map *map = method == MEDIA_VPT ? NULL : seeded_map(&s, (uint64_t)k);
        struct tile_stats st;
        float *px = test_render_map(&s, map, 1, &st);
        n = s.settings.width * s.settings.height;
        for (uint32_t i = 0; i < n; i++) {
            double v = px[i * TILE_NUM_CHANNELS + CH_R];
            cr_assert(isfinite(v));
            mean[i] = (k == 1 ? 0.0 : mean[i]) + v;
            var[i] = (k == 1 ? 0.0 : var[i]) + v * v;
        }
        free(px);
        photon_map_free(&map);
        scene_fini(&s);
    }
    for (uint32_t i = 0; i < n; i++) {
        mean[i] /= seeds;
        var[i] = fmax(var[i] / seeds - mean[i] * mean[i], 0.0) / (seeds - 1);
    }
    *npx = n;
}

/* relRMSE of b against v (per-pixel means over seeds) less the two renders' noise (their
 * variances over seeds), in quadrature: what is left is bias. */
static double excess_rel(const double *b, const double *bv, const double *v, const double *vv, uint32_t n,
                         const char *what)
{
    double sum = 0.0, d2 = 0.0, noise = 0.0;
    for (uint32_t i = 0; i < n; i++) {
        sum += v[i];
        d2 += (b[i] - v[i]) * (b[i] - v[i]);
        noise += vv[i] + bv[i];
    }
    double mean = sum / n, rel = sqrt(d2 / n) / mean, rel_noise = sqrt(noise / n) / mean;
    double excess = sqrt(fmax(rel * rel - rel_noise * rel_noise, 0.0));
    fprintf(stderr, "%s: relRMSE %.4f, the renders' noise %.4f, the rest %.4f (mean %g)\n", what, rel, rel_noise,
            excess, mean);
    cr_assert(mean > 0.005);
    return excess;
}

/* ---- splitting heavy photons (volume.photon_split, photon_trace.c) ---- */

/* The grid cloud over a floor, lit by a point light far enough away that it aims a quarter
 * of its photons at the cloud: the others, some 10 times heavier, reach the cloud after
 * the floor or past the cone's edge. */
#define SPLIT_SCENE(split)                                                                                  \
    HEAD("\"position\": [0, 1, -6], \"look_at\": [0, -0.2, 0]", 12, 9, 1, 64)                               \
    ",\n\"materials\": {\"white\": {\"type\": \"diffuse\", \"albedo\": [0.8, 0.8, 0.8]}},\n"                 \
    "\"media\": {\"c\": {\"sigma_a\": [0.05, 0.05, 0.05], \"sigma_s\": [1.5, 1.5, 1.5], \"g\": 0.3, "         \
    "\"density\": {\"file\": \"g.grid\", \"transform\": {\"scale\": 3, \"translate\": [-1.5, -1, -1.5]}}}},\n" \
    "\"volume\": {\"method\": \"beam\", \"fog\": \"c\", \"photons\": 20000, \"radius\": 0.1, "                \
    "\"step\": 0.05, \"photon_split\": " split "},\n"                                                       \
    "\"objects\": [{\"type\": \"obj\", \"file\": \"floor.obj\", \"material\": \"white\"}],\n"                \
    "\"lights\": [{\"type\": \"point\", \"position\": [5, 6, -4], \"intensity\": [150, 150, 150]}]}"

/* Splitting keeps the expectation (the same camera samples, 16 photon seeds: the split
 * render's relRMSE against the unsplit one, their noise taken out, under 5 %; measured 0)
 * and lowers the maps' variance, summed over the pixels (measured: 0.58 of it without
 * splitting). Fails with a walker's power not divided by n (0.60 beyond noise) or with
 * walkers sharing their random numbers (variance ratio 1.04). */
Test(medium, heavy_photons_split, .timeout = 120)
{
    enum { SEEDS = 16, NSP = 12 * 9 };
    double a[NSP], av[NSP], b[NSP], bv[NSP], p1 = 0.0, p8 = 0.0;
    uint32_t n, nb;
    seeds_image(SPLIT_SCENE("1"), MEDIA_MARCH_BEAM, 4, SEEDS, 1, a, av, &n);
    seeds_image(SPLIT_SCENE("8"), MEDIA_MARCH_BEAM, 4, SEEDS, 1, b, bv, &nb);
    cr_assert_eq(n, (uint32_t)NSP);
    cr_assert_eq(nb, (uint32_t)NSP);
    for (uint32_t i = 0; i < n; i++)
        p1 += av[i], p8 += bv[i];
    double e = excess_rel(b, bv, a, av, n, "heavy photons, split against unsplit");
    fprintf(stderr, "heavy photons: the maps' variance split / unsplit %.3f\n", p8 / p1);
    cr_assert(e < 0.05, "split against unsplit: %g beyond noise", e);
    cr_assert(p8 < 0.7 * p1, "the maps' variance: split %g, unsplit %g", p8, p1);
}

/* Photons in a grid carry their power over the density where they were stored, and the
 * photon estimates take the density at the camera ray: the kernel then blurs the light
 * arriving in the medium, which is smooth, and not sigma_s times it, which has the grid's
 * edges (its empty corner, steps of up to 5x between voxels, a spike). At a radius near a
 * voxel's size, one map and no passes, beam's and march's pixels (8 seeds) are within
 * 20 % relRMSE of VPT's once the renders' noise is taken out (beam 0.12, march within the
 * noise); blurring sigma_s L, as the estimates did before, is 0.62 off for beam and 0.27
 * for march. */
Test(medium, grid_photons_blur_radiance_not_density, .timeout = 240)
{
    enum { NPX = 24 * 18 };
    double vm[NPX], vv[NPX], bm[NPX], bv[NPX];
    uint32_t n, nb;
    seeds_image(GRID_EDGE_SCENE("beam"), MEDIA_VPT, 1024, 4, 0, vm, vv, &n);
    cr_assert_eq(n, (uint32_t)NPX);
    seeds_image(GRID_EDGE_SCENE("beam"), MEDIA_MARCH_BEAM, 16, 8, 0, bm, bv, &nb);
    cr_assert_eq(nb, (uint32_t)NPX);
    double eb = excess_rel(bm, bv, vm, vv, n, "grid edges, beam against vpt");
    seeds_image(GRID_EDGE_SCENE("beam"), MEDIA_MARCH_STEPS, 4, 8, 0, bm, bv, &nb);
    double em = excess_rel(bm, bv, vm, vv, n, "grid edges, march against vpt");
    cr_assert(eb < 0.2, "beam: %g", eb);
    cr_assert(em < 0.2, "march: %g", em);
}

/* An integer in [0, n) from the stream k, dimension dim. */
static uint32_t tie_index(uint64_t k, uint32_t dim, uint32_t n)
{
    return (uint32_t)(rng_bits(k, dim) % n);
}

/* One lookup of a marched table gives the optical depth (0 before the table, its last
 * value after it, linear in each step) and the density (each step's slope, 0 outside),
 * at the table's ends too. */
Test(medium, tau_table_depth_and_density)
{
    const float tau[4] = {0.0f, 0.5f, 0.75f, 1.75f};
    const struct photon_tau tt = {tau, 4, 1.0f, 0.5f}; /* entries at t = 1, 1.5, 2, 2.5 */
    const float t[] = {0.0f, 1.0f, 1.25f, 1.5f, 2.25f, 2.5f, 9.0f};
    const float depth[] = {0.0f, 0.0f, 0.25f, 0.5f, 1.25f, 1.75f, 1.75f};
    const float density[] = {0.0f, 1.0f, 1.0f, 0.5f, 2.0f, 0.0f, 0.0f};
    for (int k = 0; k < 7; k++) {
        float rho = -1.0f, d = photon_tau_depth_density(&tt, t[k], &rho);
        cr_assert_eq(d, depth[k], "t %g: depth %g, not %g", (double)t[k], (double)d, (double)depth[k]);
        cr_assert_eq(rho, density[k], "t %g: density %g, not %g", (double)t[k], (double)rho, (double)density[k]);
        cr_assert_eq(photon_tau_depth(&tt, t[k]), d);
    }
    const struct photon_tau one = {tau, 1, 1.0f, 0.5f}; /* a table of one entry: no step */
    float rho = -1.0f;
    cr_assert(photon_tau_depth_density(&one, 1.0f, &rho) == 0.0f && rho == 0.0f);
}

/* The rows' axis for a view: the axis it runs most along, the first of equals. */
Test(medium, beam_row_axis_of_a_view)
{
    cr_assert_eq(photon_map_row_axis(v3(0.0f, 0.2f, 1.0f)), 2);
    cr_assert_eq(photon_map_row_axis(v3(-3.0f, 1.0f, 0.0f)), 0);
    cr_assert_eq(photon_map_row_axis(v3(0.1f, -2.0f, 1.9f)), 1);
    cr_assert_eq(photon_map_row_axis(v3(1.0f, -1.0f, 0.0f)), 0);
    cr_assert_eq(photon_map_row_axis(v3(0.0f, 1.0f, -1.0f)), 1);
    cr_assert_eq(photon_map_row_axis(v3(0.0f, 0.0f, 0.0f)), 0);
}

/* The beam query's rows against the loop over every photon (the map without rows), bit for
 * bit: photons on a lattice of the rows' cell borders, in rows of 1, 2, 15, 16, 17 and 33
 * photons (the linear scan's limit is 16) with x tied in threes, in dense clumps (long
 * rows, cells of r) and on the photons' box's corners; the rows found in the flat (y, z)
 * table (box 4 wide) and in the hash table (box 32 wide). Isotropic phase, no extinction
 * and small integer powers make every sum exact in any order, so equal sums mean the same
 * photons were taken. Rays along the axes on the borders, through photons, grazing the
 * box's faces and at random. */
Test(medium, beam_rows_with_tied_x_match_brute_force, .timeout = 120)
{
    const float r = 0.0625f; /* the rows' cell: dense clumps make it r (k = 1) */
    const uint32_t lens[6] = {1, 2, 15, 16, 17, 33};
    struct medium md;
    memset(&md, 0, sizeof md);
    md.sigma_t = v3(0, 0, 0);
    md.g = 0.0f;
    uint32_t rays = 0, nonzero = 0;
    for (int hashed = 0; hashed < 2; hashed++) {
        float box = hashed ? 32.0f : 4.0f;
        struct photon_list block = {NULL, 0, 0};
        block.cap = 16384;
        block.a = calloc(block.cap, sizeof *block.a);
        uint32_t n = 0;
#define PUT(X, Y, Z)                                                                                           \
    do {                                                                                                       \
        cr_assert(n < block.cap);                                                                              \
        struct photon *ph_ = &block.a[n];                                                                      \
        ph_->p[0] = (X), ph_->p[1] = (Y), ph_->p[2] = (Z);                                                     \
        photon_rgbe_encode(v3(1.0f, (float)(1 + n % 7), (float)(1 + n / 7 % 5)), ph_->rgbe);                   \
        ph_->dir = photon_dir_encode(v3_normalize(v3((float)(n % 3) - 1.0f, (float)(n % 5) - 2.0f, -1.0f))); \
        ph_->depth = (uint16_t)(1 + n % 8);                                                                    \
        n++;                                                                                                   \
    } while (0)
        for (int k = 0; k < 8; k++) /* the box's corners */
            PUT(k & 1 ? box : 0.0f, k & 2 ? box : 0.0f, k & 4 ? box : 0.0f);
        for (uint32_t cz = 0; cz < 16; cz++)
            for (uint32_t cy = 0; cy < 16; cy++)
                for (uint32_t j = 0, len = lens[(cy + 3 * cz) % 6]; j < len; j++)
                    PUT((float)(j / 3) * 0.125f, (float)cy * r + (float)(j % 3) * 0.25f * r,
                        (float)cz * r + (float)(j % 2) * 0.5f * r);
        for (uint32_t c = 0; c < 16; c++) /* clumps of 256 within one cell of 2r each */
            for (uint32_t j = 0; j < 256; j++)
                PUT(0.25f * (float)c + (float)(j % 8) / 64.0f, 2.0f + (float)(j / 8 % 8) / 64.0f,
                    2.0f + 0.125f * (float)(c % 4) + (float)(j / 64) / 64.0f);
#undef PUT
        block.n = n;
        uint8_t *blob = NULL;
        size_t bytes = 0;
        uint32_t count = 0;
        char err[256];
        cr_assert_eq(photon_map_serialise(&block, 1, r, n, &blob, &bytes, &count, err, sizeof err), 0);
        /* rows along x (the rows of the lattice above), then along y and z */
        for (int axis = 0; axis < 3; axis++) {
            struct photon_map *m = NULL;
            cr_assert_eq(photon_map_decode_rows(blob, bytes, axis, &m, err, sizeof err), 0, "%s", err);
            float cell = 0.0f;
            uint32_t rows = 0, longest = 0;
            cr_assert_eq(photon_map_beam_layout(m, &cell, &rows, &longest), !hashed);
            cr_assert(cell == r && (axis > 0 || (rows > 256 && longest > 16)), "cell %g, %u rows, longest %u",
                      (double)cell, rows, longest);
            struct photon_beam_grid *grid = m->beam;
            for (uint32_t q = 0; q < 600; q++) {
                uint64_t k = rng_key(303, (uint32_t)hashed, q, 0);
                /* on a lattice point of the borders (or just off it), inside the rows or the clumps */
                float oy = (float)(tie_index(k, 1, 20)) * r, oz = (float)(tie_index(k, 2, 20)) * r;
                if (q % 9 == 4)
                    oy = nextafterf(oy, -1.0f), oz = nextafterf(oz, 10.0f);
                if (q % 4 == 3)
                    oy += 2.0f, oz += 2.0f;
                vec3 o = v3((float)tie_index(k, 0, 14) * 0.125f - 0.25f, oy, oz), d;
                switch (q % 6) {
                case 0: d = v3(q / 6 % 2 ? -1.0f : 1.0f, 0, 0); break;
                case 1: d = v3(0, q / 6 % 2 ? -1.0f : 1.0f, 0); break;
                case 2: d = v3(0, 0, q / 6 % 2 ? -1.0f : 1.0f); break;
                case 3: /* grazing a face of the box */
                    o = v3(-1.0f, q / 6 % 2 ? box : 0.0f, oz);
                    d = v3_normalize(v3(1.0f, 0.0f, rng_uniform(k, 3) - 0.5f));
                    break;
                default:
                    d = v3_normalize(v3(rng_uniform(k, 3) - 0.5f, rng_uniform(k, 4) - 0.5f, rng_uniform(k, 5) - 0.5f));
                }
                float t1 = (float)(1 + tie_index(k, 6, 48)) * 0.125f; /* often ending on a tied x */
                if (q % 7 == 0)
                    t1 = 1e30f;
                if (q % 5 == 1) { /* through a photon */
                    const float *p = m->photons[tie_index(k, 7, m->num_photons)].p;
                    o = v3_sub(v3(p[0], p[1], p[2]), v3_scale(d, t1 * (float)tie_index(k, 8, 3) * 0.5f));
                }
                uint32_t depth_max = q % 3 == 0 ? PHOTON_DEPTH_ANY : 1 + q % 8;
                vec3 a = photon_map_beam(m, o, d, t1, &md, NULL, depth_max);
                m->beam = NULL; /* every photon, in index order */
                vec3 b = photon_map_beam(m, o, d, t1, &md, NULL, depth_max);
                m->beam = grid;
                cr_assert(a.x == b.x && a.y == b.y && a.z == b.z,
                          "%s, rows along axis %d, ray %u: rows (%.9g %.9g %.9g), every photon (%.9g %.9g %.9g)",
                          hashed ? "hash" : "flat", axis, q, (double)a.x, (double)a.y, (double)a.z, (double)b.x,
                          (double)b.y, (double)b.z);
                rays++;
                nonzero += b.x > 0.0f;
            }
            photon_map_free(&m);
        }
        free(blob);
    }
    cr_assert(nonzero > rays / 3, "only %u of %u rays found photons", nonzero, rays);
}

/* ---- random numbers per sample ---- */

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* One pixel's media paths over many passes of 1 spp with the sobol sampler and the photon
 * maps' SAMPLER_STREAMS_MAPS streams: every sample of the pixel takes its own random
 * numbers, so the values (continuous: free flights in a fog) are nearly all
 * distinct. Keyed by the pass-local index, the pixel's paths would repeat the streams'
 * SAMPLER_STREAMS_MAPS sequences whatever the passes, and the error stop falling. */
Test(medium, media_paths_differ_per_pass)
{
    struct scene s;
    load_ok(AIRLIGHT_SCENE, &s);
    s.media->method = MEDIA_VPT; /* single scattering by free flight: a continuous value */
    struct render_job job;
    job_ok(&job, &s);
    enum { N = 256 };
    double v[N];
    uint64_t rays = 0;
    struct sampler_pixel sp;
    sampler_pixel_init(&sp, SAMPLER_SOBOL, 5, 0, 0, 1);
    sampler_pixel_set_streams(&sp, SAMPLER_STREAMS_MAPS);
    for (uint32_t p = 0; p < N; p++) {
        sampler_pixel_set_pass(&sp, p);
        struct sampler smp = sampler_start_pixel(&sp, p); /* 1 spp: sample p is pass p's */
        int hit;
        v[p] = media_sample_path(&job, &smp, 0, 0, v3(-5, 1, 0), v3(1, 0, 0), 0.0f, &rays, &hit).x;
        cr_assert(isfinite(v[p]));
    }
    qsort(v, N, sizeof v[0], cmp_double);
    int distinct = 1;
    for (int i = 1; i < N; i++)
        distinct += v[i] != v[i - 1];
    cr_log_info("media paths over %d passes of 1 spp: %d distinct values", N, distinct);
    cr_assert(distinct >= N - N / 16, "%d distinct values of %d samples", distinct, N);
    render_job_fini(&job);
    scene_fini(&s);
}

/* ---- glow sampling ---- */

/* media_glow_sample against media_glow_pdf: the density integrates to 1 over the sphere
 * (quadrature in theta around c, the 1 / sin(theta) singularity cancelled by the solid
 * angle's sin(theta)), and a chi-square test of samples binned in (theta, azimuth) cells of
 * a frame of the test's own against the cells' masses under the pdf (quadrature). */
static float glow_pdf_of(void *ctx, vec3 w) { return media_glow_pdf(*(const vec3 *)ctx, w); }
static vec3 glow_sample_of(void *ctx, uint32_t k)
{
    return media_glow_sample(*(const vec3 *)ctx, rng_uniform(77, 2 * k), rng_uniform(77, 2 * k + 1));
}

Test(medium, glow_sampling_chi_square)
{
    vec3 c = v3_normalize(v3(0.3f, -0.5f, 0.81f));
    /* the whole sphere: the pdf must vanish outside its cone */
    test_direction_chi_square("glow sampling", c, M_PI, 8, 6, 64, glow_pdf_of, glow_sample_of, &c, 200000, 2e-3, 0, 24);
}

/* A point light 0.3 above a white floor in fog, the camera ray hitting the floor 0.25 to
 * its side: the final gather's bounce from there passes the light at any distance, and
 * the single scattering its segment gathers is ~ 1 / that distance. */
#define GLOW_SCENE                                                                                          \
    HEAD("\"position\": [0, 0.5, -2.5], \"look_at\": [0.25, -1.2, 0]", 1, 1, 1, 8)                          \
    ",\n\"materials\": {\"white\": {\"type\": \"diffuse\", \"albedo\": [0.8, 0.8, 0.8]},\n"                  \
    "  \"black\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0]}},\n"                                        \
    "\"media\": {\"fog\": {\"sigma_a\": [0.05, 0.05, 0.05], \"sigma_s\": [0.3, 0.3, 0.3]}},\n"                \
    "\"volume\": {\"method\": \"beam\", \"fog\": \"fog\", \"photons\": 20000, \"radius\": 0.1, "             \
    "\"step\": 0.05},\n"                                                                                     \
    "\"objects\": [{\"type\": \"obj\", \"file\": \"floor.obj\", \"material\": \"white\"},\n"                 \
    "  {\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 20, \"material\": \"black\"}],\n"            \
    "\"lights\": [{\"type\": \"point\", \"position\": [0, -0.9, 0], \"intensity\": [5, 5, 5]}]}"

/* n samples of the camera ray's path: mean, standard error, largest value. */
static double glow_stats(const struct render_job *job, int n, double *se, double *max)
{
    vec3 o = v3(0, 0.5f, -2.5f), d = v3_normalize(v3_sub(v3(0.25f, -1.2f, 0), o));
    double s1 = 0.0, s2 = 0.0;
    uint64_t rays = 0;
    *max = 0.0;
    for (int i = 0; i < n; i++) {
        struct sampler smp = sampler_start(21, 0, 0, (uint32_t)i);
        int hit;
        double v = media_sample_path(job, &smp, 0, 0, o, d, 0.0f, &rays, &hit).x;
        cr_assert(isfinite(v));
        s1 += v;
        s2 += v * v;
        *max = fmax(*max, v);
    }
    double mean = s1 / n;
    *se = sqrt(fmax(0.0, s2 / n - mean * mean) / n);
    return mean;
}

/* The gather next to a light in fog, with glow sampling: no sample far above the mean
 * (cosine sampling alone gives a heavy tail, its largest sample here dozens of times the
 * mean), and the same mean as cosine sampling alone (the job's glowing lights cleared)
 * within the standard errors: unbiased. */
Test(medium, glow_sampling_bounded, .timeout = 120)
{
    struct scene s;
    load_ok(GLOW_SCENE, &s);
    struct photon_map *map = seeded_map(&s, 3);
    struct render_job job;
    job_ok(&job, &s);
    render_job_set_photon_map(&job, &map);
    cr_assert_eq(render_job_pass_media(&job, 0)->num_glow, 1u);
    const int n = 20000;
    double se, max, mean = glow_stats(&job, n, &se, &max);
    /* the old estimator: cosine sampling only */
    job.media->num_glow = 0;
    for (uint32_t p = 0; job.pass_media && p < job.num_passes; p++)
        job.pass_media[p].num_glow = 0;
    double se0, max0, mean0 = glow_stats(&job, 4 * n, &se0, &max0);
    cr_log_info("glow sampling: mean %g +- %g, max %g (%g x the mean); cosine only: %g +- %g, max %g (%g x)", mean,
                se, max, max / mean, mean0, se0, max0, max0 / mean0);
    cr_assert(mean > 0.0);
    cr_assert(max < 8.0 * mean, "largest sample %g is %g x the mean %g", max, max / mean, mean);
    agree("glow sampling against cosine sampling", mean, se, mean0, se0, 0.0);
    render_job_fini(&job);
    scene_fini(&s);
}

/* The hash grid's bucket of p for cells of `cell` in a table of `table` buckets: the map's
 * layout (cells of twice the gather radius, photon_map.h; their integer coordinates hashed
 * with the three primes of Teschner et al. 2003, as photon_map.c does), written apart from
 * the map's code. */
static uint32_t layout_bucket(const float *p, float cell, uint32_t table)
{
    float inv = 1.0f / cell;
    uint32_t c[3];
    for (int a = 0; a < 3; a++)
        c[a] = (uint32_t)(int32_t)floorf(p[a] * inv);
    return (c[0] * 73856093u ^ c[1] * 19349663u ^ c[2] * 83492791u) & (table - 1);
}

static const uint8_t *sorted_photons_base;
static int photon_index_cmp(const void *a, const void *b)
{
    return memcmp(sorted_photons_base + 20 * (size_t)*(const uint32_t *)a,
                  sorted_photons_base + 20 * (size_t)*(const uint32_t *)b, 20);
}

/* photon_map_set_radius (the master's surface map per pass) sorts a serialised map again in
 * place for a new radius. Checked against the layout, computed apart: the header holds the
 * new radius and cell (the count, table and photons emitted kept); the photons are the
 * map's, each once; every photon lies in the bucket of its cell at the new radius, so each
 * bucket holds as many as a count over all the photons gives; within a bucket the photons
 * keep the order they had in the map (a stable sort). The same radius changes nothing. */
Test(medium, photon_map_set_radius_sorts_by_the_new_cells)
{
    const uint32_t n = 3000;
    struct photon_list block = {malloc(sizeof(struct photon) * n), n, n};
    for (uint32_t i = 0; i < n; i++) {
        uint64_t k = rng_key(77, i, 0, 0);
        struct photon *ph = &block.a[i];
        for (int a = 0; a < 3; a++)
            ph->p[a] = 4.0f * rng_uniform(k, (uint32_t)a) - 2.0f;
        photon_rgbe_encode(v3(rng_uniform(k, 3), 0.5f, 0.25f), ph->rgbe);
        ph->dir = photon_dir_encode(v3_normalize(v3(rng_uniform(k, 4) - 0.5f, 0.3f, rng_uniform(k, 5) - 0.5f)));
        ph->depth = (uint16_t)(1 + i % 5);
    }
    char err[256];
    uint8_t *blob = NULL;
    size_t bytes = 0;
    uint32_t count = 0;
    cr_assert_eq(photon_map_serialise(&block, 1, 0.3f, 5000, &blob, &bytes, &count, err, sizeof err), 0, "%s", err);
    cr_assert_eq(photon_map_serialised_bytes(blob), bytes);
    uint8_t *copy = malloc(bytes);
    memcpy(copy, blob, bytes);
    cr_assert_eq(photon_map_set_radius(copy, bytes, 0.3f, err, sizeof err), 0, "%s", err);
    cr_assert(memcmp(copy, blob, bytes) == 0, "the same radius changes nothing");
    const float radius = 0.17f;
    cr_assert_eq(photon_map_set_radius(copy, bytes, radius, err, sizeof err), 0, "%s", err);

    /* the header: 8 magic bytes, count, table, photons emitted, radius, cell */
    cr_assert(memcmp(copy, blob, 24) == 0, "magic, count, table and photons emitted kept");
    float r2, cell;
    memcpy(&r2, copy + 24, 4);
    memcpy(&cell, copy + 28, 4);
    cr_assert(r2 == radius && cell == 2.0f * radius, "radius %g, cell %g", (double)r2, (double)cell);
    uint32_t table;
    memcpy(&table, copy + 12, 4);
    const uint8_t *old_ph = blob + 48, *ph = copy + 48;
    const uint8_t *sb = copy + 48 + 20 * (size_t)n;
    uint32_t *start = malloc(sizeof *start * ((size_t)table + 1)), *want = calloc(table, sizeof *want);
    memcpy(start, sb, 4 * ((size_t)table + 1));
    cr_assert(start[0] == 0 && start[table] == n);

    /* each photon of the map, by its index in the map before: once each, in order per bucket */
    uint32_t *by_bytes = malloc(sizeof *by_bytes * n);
    for (uint32_t i = 0; i < n; i++)
        by_bytes[i] = i;
    sorted_photons_base = old_ph;
    qsort(by_bytes, n, sizeof *by_bytes, photon_index_cmp);
    uint8_t *seen = calloc(n, 1);
    for (uint32_t i = 0; i < n; i++) {
        struct photon p;
        memcpy(&p, old_ph + 20 * (size_t)i, 20);
        want[layout_bucket(p.p, cell, table)]++;
    }
    uint32_t moved = 0;
    for (uint32_t b = 0; b < table; b++) {
        cr_assert_eq(start[b + 1] - start[b], want[b], "bucket %u: %u photons, a count over all gives %u", b,
                     start[b + 1] - start[b], want[b]);
        uint32_t prev = 0;
        for (uint32_t j = start[b]; j < start[b + 1]; j++) {
            struct photon p;
            memcpy(&p, ph + 20 * (size_t)j, 20);
            cr_assert_eq(layout_bucket(p.p, cell, table), b, "photon %u lies in bucket %u, not %u", j,
                         layout_bucket(p.p, cell, table), b);
            /* its index in the map before (positions are distinct: one match) */
            size_t lo = 0, hi = n;
            while (lo < hi) {
                size_t mid = (lo + hi) / 2;
                if (memcmp(old_ph + 20 * (size_t)by_bytes[mid], ph + 20 * (size_t)j, 20) < 0)
                    lo = mid + 1;
                else
                    hi = mid;
            }
            cr_assert(lo < n && memcmp(old_ph + 20 * (size_t)by_bytes[lo], ph + 20 * (size_t)j, 20) == 0,
                      "photon %u is not one of the map's", j);
            uint32_t was = by_bytes[lo];
            cr_assert(!seen[was], "photon %u of the map twice", was);
            seen[was] = 1;
            cr_assert(j == start[b] || was > prev, "bucket %u: photons out of their order in the map", b);
            prev = was;
            moved += was != j;
        }
    }
    cr_assert(moved > n / 2, "the photons moved to their new buckets (%u of %u)", moved, n);
    free(seen);
    free(by_bytes);
    free(start);
    free(want);
    free(copy);
    free(blob);
}

/* photon_map_bytes (a worker's budget of decoded maps) is what photon_map_decode
 * allocates: the heap's bytes in use (glibc's mallinfo2, every block from the heap) grow by
 * the estimate plus malloc's own header and rounding (8 to 23 bytes a block; a decoded
 * volume map is 11 blocks, 4 of the map and 7 of the beam grid) for photon sets whose beam
 * rows are a flat table (photons in a small box) or a hash table (a box spread wide), large
 * and small. Under a sanitizer (its own allocator) the heap's counters do not move: skipped. */
Test(medium, photon_map_bytes_is_what_decode_allocates)
{
    static void *volatile probe; /* volatile: the compiler keeps each malloc and free */
    mallopt(M_MMAP_MAX, 0);      /* every block from the heap, where mallinfo2 counts it */
    probe = malloc(1);           /* this thread's arena and cache made */
    free(probe);
    struct mallinfo2 a = mallinfo2();
    probe = malloc(100000);
    struct mallinfo2 b = mallinfo2();
    free(probe);
    if (b.uordblks < a.uordblks + 100000 || b.uordblks > a.uordblks + 100000 + 32)
        cr_skip_test("the heap's counters do not follow malloc here (%zu bytes for a block of 100000: a sanitizer's "
                     "allocator)", b.uordblks - a.uordblks);
    const struct { uint32_t n; float box, r; int hashed; } sets[] = {
        {4000, 1.0f, 0.05f, 0}, {3000, 32.0f, 0.01f, 1}, {40000, 2.0f, 0.02f, 0}, {1000, 100.0f, 0.002f, 1}};
    for (size_t c = 0; c < sizeof sets / sizeof sets[0]; c++) {
        uint32_t n = sets[c].n;
        struct photon_list block = {malloc(sizeof(struct photon) * n), n, n};
        for (uint32_t i = 0; i < n; i++) {
            uint64_t k = rng_key(91, (uint32_t)c, i, 0);
            struct photon *ph = &block.a[i];
            for (int d = 0; d < 3; d++)
                ph->p[d] = sets[c].box * rng_uniform(k, (uint32_t)d);
            photon_rgbe_encode(v3(1.0f, 0.5f, 0.25f), ph->rgbe);
            ph->dir = photon_dir_encode(v3(0.0f, 0.0f, 1.0f));
            ph->depth = 1;
        }
        uint8_t *blob = NULL;
        size_t bytes = 0;
        uint32_t count = 0;
        char err[256];
        cr_assert_eq(photon_map_serialise(&block, 1, sets[c].r, n, &blob, &bytes, &count, err, sizeof err), 0, "%s",
                     err);
        struct photon_map *m = NULL;
        struct mallinfo2 before = mallinfo2();
        cr_assert_eq(photon_map_decode(blob, bytes, &m, err, sizeof err), 0, "%s", err);
        struct mallinfo2 after = mallinfo2();
        float cell;
        uint32_t rows, longest;
        cr_assert_eq(photon_map_beam_layout(m, &cell, &rows, &longest), !sets[c].hashed, "set %zu", c);
        size_t est = photon_map_bytes(m), got = after.uordblks - before.uordblks;
        cr_assert(got >= est + 11 * 8 && got <= est + 11 * 23,
                  "set %zu (%u photons, %s rows): the estimate %zu bytes, decode allocated %zu", c, n,
                  sets[c].hashed ? "hashed" : "flat", est, got);
        photon_map_free(&m);
        free(blob);
    }
}
