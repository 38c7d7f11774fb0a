/* The path tracer against scenes with known answers, built in code:
 * - a closed diffuse sphere with a point light at its centre (every bounce depth);
 * - a floor under a square area light (differential-area-to-rectangle form factor), which
 *   checks next-event estimation and the MIS weights on triangle emitters;
 * - a floor under a spherical light (irradiance pi L r^2 / d^2), the same for spheres;
 * and the determinism of pixels under any tile split. */
#include <criterion/criterion.h>
#include <math.h>
#include <string.h>
#include "render/integrator.h"
#include "base/log.h"
#include "helpers.h"

static uint32_t add_mat(struct scene *s, vec3 albedo, vec3 emission)
{
    struct material m;
    memset(&m, 0, sizeof m);
    m.type = MATERIAL_DIFFUSE;
    m.albedo = albedo;
    m.emission = emission;
    return scene_add_material(s, &m);
}

static void add_quad(struct scene *s, vec3 a, vec3 b, vec3 c, vec3 d, uint32_t mat)
{
    struct mesh m = test_quad(a, b, c, d, mat, 0);
    scene_add_mesh(s, &m);
}

static void settings(struct scene *s, uint32_t w, uint32_t h, uint32_t spp, uint32_t depth)
{
    s->settings.width = w;
    s->settings.height = h;
    s->settings.spp = spp;
    s->settings.max_depth = depth;
    s->settings.seed = 5;
    s->settings.tile_size = 16;
}

/* Mean of channel R over the image and its standard error (from the variance channel). */
static void render_mean(const struct scene *s, double *mean, double *stderr_, uint64_t *nans)
{
    struct tile_stats st;
    float *px = test_render(s, 2, &st);
    *mean = test_channel_mean(px, s->settings.width, s->settings.height, CH_R, stderr_);
    *nans = st.nan_samples;
    free(px);
}

static void furnace_sphere(uint32_t depth)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    const float rho = 0.7f, R = 2.0f, I = 10.0f;
    uint32_t mat = add_mat(&s, v3(rho, rho, rho), v3(0, 0, 0));
    struct sphere sp = {"shell", v3(1, 2, 3), R, mat, NULL, 0};
    scene_add_sphere(&s, &sp);
    struct light l = {.type = LIGHT_POINT, .position = v3(1, 2, 3), .intensity = v3(I, I, I)};
    scene_add_light(&s, &l);
    s.camera = (struct camera_desc){.position = v3(1, 2, 3), .look_at = v3(1, 2, 4), .up = v3(0, 1, 0), .fov_y_deg = 90.0f};
    settings(&s, 16, 16, 64, depth);
    double expect = 0.0;
    for (uint32_t k = 0; k < depth && k < 200; k++)
        expect += pow(rho, k);
    expect *= rho / M_PI * I / (R * R);
    double mean, se;
    uint64_t nans;
    render_mean(&s, &mean, &se, &nans);
    cr_assert_eq(nans, 0);
    cr_assert(fabs(mean - expect) < 4.0 * se + 1e-5 * expect, "depth %u: mean %.6f expected %.6f (stderr %.2g)",
              depth, mean, expect, se);
    scene_fini(&s);
}

Test(integrator, closed_sphere_point_light_depth_1) { furnace_sphere(1); }

/* Rays per sample inside the shell at max_depth 2: the camera ray, a shadow ray at each of
 * the 2 vertices, the bounce between them; the last vertex's bounce is traced only when a
 * ray could find light by hitting an emitter (here a material no surface uses is enough
 * to keep it) or missing into an environment. */
static uint64_t shell_rays_per_sample(int emitter, float **px)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    uint32_t mat = add_mat(&s, v3(0.7f, 0.7f, 0.7f), v3(0, 0, 0));
    if (emitter)
        add_mat(&s, v3(0.5f, 0.5f, 0.5f), v3(1, 1, 1));
    struct sphere sp = {"shell", v3(1, 2, 3), 2.0f, mat, NULL, 0};
    scene_add_sphere(&s, &sp);
    struct light l = {.type = LIGHT_POINT, .position = v3(1, 2, 3), .intensity = v3(10, 10, 10)};
    scene_add_light(&s, &l);
    s.camera = (struct camera_desc){.position = v3(1, 2, 3), .look_at = v3(1, 2, 4), .up = v3(0, 1, 0), .fov_y_deg = 90.0f};
    settings(&s, 8, 8, 4, 2);
    struct tile_stats st;
    *px = test_render(&s, 1, &st);
    scene_fini(&s);
    cr_assert_eq(st.rays % st.samples, 0, "%llu rays for %llu samples", (unsigned long long)st.rays,
                 (unsigned long long)st.samples);
    return st.rays / st.samples;
}

Test(integrator, last_bounce_traced_only_where_a_ray_can_find_light)
{
    float *px0, *px1;
    cr_assert_eq(shell_rays_per_sample(0, &px0), 4);
    cr_assert_eq(shell_rays_per_sample(1, &px1), 5);
    /* The material no surface uses changes nothing seen: the skipped ray moved no pixel. */
    cr_assert(memcmp(px0, px1, sizeof(float) * 8 * 8 * TILE_NUM_CHANNELS) == 0, "skipping the last ray moved a pixel");
    free(px0);
    free(px1);
}
Test(integrator, closed_sphere_point_light_depth_3) { furnace_sphere(3); }
Test(integrator, closed_sphere_point_light_depth_50) { furnace_sphere(50); }

/* Form factor from a differential area to a parallel a x b rectangle at height h, the
 * rectangle's corner straight above the point. */
static double ff_corner(double a, double b, double h)
{
    double x = a / h, y = b / h;
    return (x / sqrt(1 + x * x) * atan(y / sqrt(1 + x * x)) + y / sqrt(1 + y * y) * atan(x / sqrt(1 + y * y))) /
           (2 * M_PI);
}

Test(integrator, floor_under_square_area_light)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    const float rho = 0.5f, Le = 3.0f;
    uint32_t floor_m = add_mat(&s, v3(rho, rho, rho), v3(0, 0, 0));
    uint32_t light_m = add_mat(&s, v3(0, 0, 0), v3(Le, Le, Le));
    add_quad(&s, v3(-50, 0, -50), v3(-50, 0, 50), v3(50, 0, 50), v3(50, 0, -50), floor_m);
    add_quad(&s, v3(-1, 1, -1), v3(1, 1, -1), v3(1, 1, 1), v3(-1, 1, 1), light_m); /* faces down */
    s.camera = (struct camera_desc){.position = v3(0, 0.5f, 0), .look_at = v3(0, 0, 0), .up = v3(0, 0, 1), .fov_y_deg = 0.5f};
    settings(&s, 8, 8, 256, 1);
    double expect = rho * Le * 4.0 * ff_corner(1, 1, 1);
    double mean, se;
    uint64_t nans;
    render_mean(&s, &mean, &se, &nans);
    cr_assert_eq(nans, 0);
    cr_assert(fabs(mean - expect) < 4.0 * se + 1e-3 * expect, "mean %.6f expected %.6f (stderr %.2g)", mean, expect,
              se);
    scene_fini(&s);
}

Test(integrator, floor_under_sphere_light)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    const float rho = 0.8f, Le = 2.0f, r = 0.5f, d = 3.0f;
    uint32_t floor_m = add_mat(&s, v3(rho, rho, rho), v3(0, 0, 0));
    uint32_t light_m = add_mat(&s, v3(0, 0, 0), v3(Le, Le, Le));
    add_quad(&s, v3(-50, 0, -50), v3(-50, 0, 50), v3(50, 0, 50), v3(50, 0, -50), floor_m);
    struct sphere sp = {"bulb", v3(0, d, 0), r, light_m, NULL, 0};
    scene_add_sphere(&s, &sp);
    s.camera = (struct camera_desc){.position = v3(0, 0.5f, 0), .look_at = v3(0, 0, 0), .up = v3(0, 0, 1), .fov_y_deg = 0.5f};
    settings(&s, 8, 8, 256, 1);
    double expect = rho * Le * (r * r) / (d * d);
    double mean, se;
    uint64_t nans;
    render_mean(&s, &mean, &se, &nans);
    cr_assert_eq(nans, 0);
    cr_assert(fabs(mean - expect) < 4.0 * se + 1e-3 * expect, "mean %.6f expected %.6f (stderr %.2g)", mean, expect,
              se);
    scene_fini(&s);
}

Test(integrator, pixels_do_not_depend_on_tile_split)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    uint32_t floor_m = add_mat(&s, v3(0.6f, 0.5f, 0.4f), v3(0, 0, 0));
    uint32_t light_m = add_mat(&s, v3(0, 0, 0), v3(5, 5, 5));
    add_quad(&s, v3(-5, 0, -5), v3(-5, 0, 5), v3(5, 0, 5), v3(5, 0, -5), floor_m);
    add_quad(&s, v3(-1, 2, -1), v3(1, 2, -1), v3(1, 2, 1), v3(-1, 2, 1), light_m);
    struct sphere sp = {"ball", v3(0, 0.5f, 0), 0.5f, floor_m, NULL, 0};
    scene_add_sphere(&s, &sp);
    s.camera = (struct camera_desc){.position = v3(0, 1, 4), .look_at = v3(0, 0.5f, 0), .up = v3(0, 1, 0), .fov_y_deg = 50.0f};
    settings(&s, 20, 12, 4, 5);
    struct render_job job;
    char err[256];
    cr_assert_eq(render_job_init(&job, &s, 0, 1, err, sizeof err), 0);
    enum { N = 20 * 12 * TILE_NUM_CHANNELS };
    static float whole[N], part[N];
    struct tile_stats st;
    integrator_render_tile(&job, 0, 0, 20, 12, whole, &st);
    /* Render 7x5 pieces, in reverse order, and paste them. */
    float piece[7 * 5 * TILE_NUM_CHANNELS];
    for (int ty = 2; ty >= 0; ty--)
        for (int tx = 2; tx >= 0; tx--) {
            uint32_t x0 = tx * 7, y0 = ty * 5, w = x0 + 7 > 20 ? 20 - x0 : 7, h = y0 + 5 > 12 ? 12 - y0 : 5;
            integrator_render_tile(&job, x0, y0, w, h, piece, &st);
            for (uint32_t y = 0; y < h; y++)
                memcpy(&part[((y0 + y) * 20 + x0) * TILE_NUM_CHANNELS], &piece[y * w * TILE_NUM_CHANNELS],
                       sizeof(float) * w * TILE_NUM_CHANNELS);
        }
    cr_assert_eq(memcmp(whole, part, sizeof whole), 0);
    render_job_fini(&job);
    scene_fini(&s);
}

Test(integrator, huge_coordinates_no_acne)
{
    /* A floor far from the origin under a light: no self-shadowing at 1e5 units. */
    struct scene s;
    memset(&s, 0, sizeof s);
    const float rho = 0.5f, Le = 3.0f, X = 1.0e5f;
    uint32_t floor_m = add_mat(&s, v3(rho, rho, rho), v3(0, 0, 0));
    uint32_t light_m = add_mat(&s, v3(0, 0, 0), v3(Le, Le, Le));
    add_quad(&s, v3(X - 50, 0, X - 50), v3(X - 50, 0, X + 50), v3(X + 50, 0, X + 50), v3(X + 50, 0, X - 50), floor_m);
    add_quad(&s, v3(X - 1, 1, X - 1), v3(X + 1, 1, X - 1), v3(X + 1, 1, X + 1), v3(X - 1, 1, X + 1), light_m);
    s.camera = (struct camera_desc){.position = v3(X, 0.5f, X), .look_at = v3(X, 0, X), .up = v3(0, 0, 1), .fov_y_deg = 0.5f};
    settings(&s, 8, 8, 256, 1);
    double expect = rho * Le * 4.0 * ff_corner(1, 1, 1);
    double mean, se;
    uint64_t nans;
    render_mean(&s, &mean, &se, &nans);
    cr_assert(fabs(mean - expect) < 4.0 * se + 1e-2 * expect, "mean %.6f expected %.6f", mean, expect);
    scene_fini(&s);
}

Test(integrator, non_finite_samples_counted_and_dropped)
{
    /* A point light so bright that I / d^2 overflows float: every such sample is Inf. */
    struct scene s;
    memset(&s, 0, sizeof s);
    uint32_t floor_m = add_mat(&s, v3(0.5f, 0.5f, 0.5f), v3(0, 0, 0));
    add_quad(&s, v3(-5, 0, -5), v3(-5, 0, 5), v3(5, 0, 5), v3(5, 0, -5), floor_m);
    struct light l = {.type = LIGHT_POINT, .position = v3(0, 0.01f, 0), .intensity = v3(3e38f, 3e38f, 3e38f)};
    scene_add_light(&s, &l);
    s.camera = (struct camera_desc){.position = v3(0, 1, 0), .look_at = v3(0, 0, 0), .up = v3(0, 0, 1), .fov_y_deg = 1.0f};
    settings(&s, 4, 4, 8, 2);
    struct render_job job;
    char err[256];
    cr_assert_eq(render_job_init(&job, &s, 0, 1, err, sizeof err), 0);
    float px[4 * 4 * TILE_NUM_CHANNELS];
    struct tile_stats st;
    integrator_render_tile(&job, 0, 0, 4, 4, px, &st);
    cr_assert_gt(st.nan_samples, 0);
    cr_assert_eq(st.samples, 4 * 4 * 8);
    for (size_t i = 0; i < sizeof px / sizeof px[0]; i++)
        cr_assert(isfinite(px[i]), "channel value %zu is %g", i, px[i]);
    render_job_fini(&job);
    scene_fini(&s);
}

Test(integrator, huge_sphere_floor_no_acne)
{
    /* A floor made of a sphere of radius 1e4: the hit point rounds at the scale of the
     * centre and radius, so without a matching offset shadow rays hit the floor itself. */
    struct scene s;
    memset(&s, 0, sizeof s);
    const float rho = 0.5f, I = 2.0f, R = 1.0e4f;
    uint32_t floor_m = add_mat(&s, v3(rho, rho, rho), v3(0, 0, 0));
    struct sphere sp = {"floor", v3(0, -R, 0), R, floor_m, NULL, 0};
    scene_add_sphere(&s, &sp);
    struct light l = {.type = LIGHT_POINT, .position = v3(0, 1, 0), .intensity = v3(I, I, I)};
    scene_add_light(&s, &l);
    s.camera = (struct camera_desc){.position = v3(0, 0.5f, 0), .look_at = v3(0, 0, 0), .up = v3(0, 0, 1), .fov_y_deg = 0.5f};
    settings(&s, 8, 8, 16, 1);
    double expect = rho / M_PI * I; /* light 1 unit straight above */
    double mean, se;
    uint64_t nans;
    render_mean(&s, &mean, &se, &nans);
    cr_assert(fabs(mean - expect) < 1e-2 * expect, "mean %.6f expected %.6f", mean, expect);
    scene_fini(&s);
}
