/* AOVs (render/aov.c, their channels in render/tile.c, their fold in master/fold.c):
 * - values on analytic scenes: a plane at a known distance with a known normal and
 *   albedo; the albedo seen through a mirror is the mirror's reflectance times the albedo
 *   of the diffuse surface behind it (the first non-specular hit);
 * - a whole-tile render of several passes and the master's fold of the passes rendered
 *   one by one give the same bits, AOVs included, and the beauty is the same with and
 *   without AOVs;
 * - the master's check of workers' AOV values.
 * Note: the beauty of a whole-tile render of passes and of the master's fold can differ
 * in the last bits under -O3 (GCC's SLP vectorisation of integrator.c; seen before the
 * AOVs too), so only the AOVs are compared bit for bit here. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "helpers.h"
#include "master/fold.h"
#include "render/aov.h"
#include "scene/scene_json.h"

/* A material of the given type whose albedo and reflectance are c. */
static uint32_t add_mat(struct scene *s, const char *name, enum material_type type, vec3 c)
{
    struct material m = {.type = type, .albedo = c, .reflectance = c};
    snprintf(m.name, sizeof m.name, "%s", name);
    return scene_add_material(s, &m);
}

#define ADD_QUAD(s, a, b, c, d, mat)                                                                                \
    do {                                                                                                           \
        struct mesh q_ = test_quad(a, b, c, d, mat, 0);                                                            \
        scene_add_mesh(s, &q_);                                                                                    \
    } while (0)

/* Camera at the origin looking down -z, w x h pixels, fov 20 degrees. */
static void setup(struct scene *s, uint32_t w, uint32_t h, uint32_t spp, uint32_t aovs)
{
    s->camera = (struct camera_desc){.position = v3(0, 0, 0), .look_at = v3(0, 0, -1), .up = v3(0, 1, 0),
                                     .fov_y_deg = 20.0f};
    s->settings = (struct render_settings){
        .width = w, .height = h, .spp = spp, .max_depth = 4, .seed = 9, .tile_size = 16, .aovs = aovs};
    struct light l = {.type = LIGHT_POINT, .position = v3(0, 2, 0), .intensity = v3(3, 3, 3)};
    scene_add_light(s, &l);
}

static const float *pixel(const float *px, const struct tile_layout *l, uint32_t w, uint32_t x, uint32_t y)
{
    return &px[((size_t)y * w + x) * l->num_channels];
}

Test(aov, layout_names_and_parsing)
{
    struct tile_layout l;
    tile_layout_init(&l, AOV_ALL);
    cr_assert_eq(l.num_channels, TILE_NUM_CHANNELS + 12);
    cr_assert_eq(l.off[AOV_Z], TILE_NUM_CHANNELS);
    cr_assert_eq(l.off[AOV_ID_MATERIAL], TILE_NUM_CHANNELS + 11);
    tile_layout_init(&l, 1u << AOV_ALBEDO);
    cr_assert_eq(l.num_channels, TILE_NUM_CHANNELS + 3);
    cr_assert_eq(l.off[AOV_Z], -1);
    cr_assert_str_eq(tile_aov_channel_name(AOV_N, 2), "N.Z");
    struct render_settings rs = {.width = 8, .height = 8, .tile_size = 8, .aovs = (1u << AOV_P) | (1u << AOV_ID_OBJECT)};
    struct image_desc d;
    tile_image_desc(&d, &rs);
    cr_assert_eq(d.num_channels, TILE_NUM_CHANNELS + 4);
    cr_assert_str_eq(d.channel_names[TILE_NUM_CHANNELS], "P.X");
    cr_assert_str_eq(d.channel_names[TILE_NUM_CHANNELS + 3], "id.object");
    tile_layout_from_desc(&l, &d);
    cr_assert_eq(l.aovs, rs.aovs);
    uint32_t m;
    cr_assert_eq(scene_aovs_from_list("Z,albedo,id.material", &m), 0);
    cr_assert_eq(m, (1u << AOV_Z) | (1u << AOV_ALBEDO) | (1u << AOV_ID_MATERIAL));
    cr_assert_eq(scene_aovs_from_list("all", &m), 0);
    cr_assert_eq(m, AOV_ALL);
    cr_assert_eq(scene_aovs_from_list("Z,,N", &m), -1);
    cr_assert_eq(scene_aovs_from_list("depth", &m), -1);
}

Test(aov, plane_at_known_distance)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    setup(&s, 9, 9, 8, AOV_ALL);
    add_mat(&s, "unused", MATERIAL_DIFFUSE, v3(0.5f, 0.5f, 0.5f));
    uint32_t pm = add_mat(&s, "plane", MATERIAL_DIFFUSE, v3(0.2f, 0.4f, 0.6f));
    ADD_QUAD(&s, v3(-50, -50, -7), v3(50, -50, -7), v3(50, 50, -7), v3(-50, 50, -7), pm);
    struct tile_stats st;
    float *px = test_render(&s, 1, &st);
    struct tile_layout l;
    tile_layout_init(&l, AOV_ALL);
    for (uint32_t y = 0; y < 9; y++)
        for (uint32_t x = 0; x < 9; x++) {
            const float *p = pixel(px, &l, 9, x, y);
            /* Z: the distance to the plane along the pixel's nearest sample: 7 / cos of its
             * angle, which is at most the pixel's far corner's. */
            double tx = ((x + 1.0) / 4.5 - 1.0) * tan(10.0 * M_PI / 180.0), ty = ((y + 1.0) / 4.5 - 1.0) * tan(10.0 * M_PI / 180.0);
            double far = 7.0 * sqrt(1.0 + (fabs(tx) + 0.04) * (fabs(tx) + 0.04) + (fabs(ty) + 0.04) * (fabs(ty) + 0.04));
            cr_assert(p[l.off[AOV_Z]] >= 7.0f && p[l.off[AOV_Z]] <= far, "Z %g at (%u, %u)", p[l.off[AOV_Z]], x, y);
            cr_assert_eq(p[l.off[AOV_N] + 0], 0.0f);
            cr_assert_eq(p[l.off[AOV_N] + 1], 0.0f);
            cr_assert_eq(p[l.off[AOV_N] + 2], 1.0f);
            cr_assert_float_eq(p[l.off[AOV_ALBEDO] + 0], 0.2f, 1e-7f);
            cr_assert_float_eq(p[l.off[AOV_ALBEDO] + 1], 0.4f, 1e-7f);
            cr_assert_float_eq(p[l.off[AOV_ALBEDO] + 2], 0.6f, 1e-7f);
            cr_assert_float_eq(p[l.off[AOV_P] + 2], -7.0f, 1e-5f);
            cr_assert_eq(p[l.off[AOV_ID_OBJECT]], 0.0f);
            cr_assert_eq(p[l.off[AOV_ID_MATERIAL]], (float)pm);
            cr_assert(aov_pixel_valid(&l, p, 1, 2));
        }
    /* P's mean over the image is on the axis (the pixels are symmetric about it). */
    double px_sum = 0.0;
    for (uint32_t i = 0; i < 81; i++)
        px_sum += px[i * l.num_channels + l.off[AOV_P]];
    cr_assert(fabs(px_sum / 81.0) < 0.02, "mean P.X %g", px_sum / 81.0);
    free(px);
    scene_fini(&s);
}

Test(aov, albedo_through_a_mirror)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    setup(&s, 5, 5, 4, AOV_ALL);
    uint32_t mm = add_mat(&s, "mirror", MATERIAL_MIRROR, v3(0.8f, 0.8f, 0.8f));
    uint32_t wm = add_mat(&s, "wall", MATERIAL_DIFFUSE, v3(0.5f, 0.25f, 1.0f));
    ADD_QUAD(&s, v3(-50, -50, -5), v3(50, -50, -5), v3(50, 50, -5), v3(-50, 50, -5), mm);
    ADD_QUAD(&s, v3(-50, -50, 1), v3(-50, 50, 1), v3(50, 50, 1), v3(50, -50, 1), wm); /* behind the camera */
    struct tile_stats st;
    float *px = test_render(&s, 1, &st);
    struct tile_layout l;
    tile_layout_init(&l, AOV_ALL);
    const float *p = pixel(px, &l, 5, 2, 2);
    cr_assert_float_eq(p[l.off[AOV_ALBEDO] + 0], 0.4f, 1e-6f);
    cr_assert_float_eq(p[l.off[AOV_ALBEDO] + 1], 0.2f, 1e-6f);
    cr_assert_float_eq(p[l.off[AOV_ALBEDO] + 2], 0.8f, 1e-6f);
    cr_assert(p[l.off[AOV_Z]] >= 5.0f && p[l.off[AOV_Z]] < 5.01f, "Z is the mirror's: %g", p[l.off[AOV_Z]]);
    cr_assert_eq(p[l.off[AOV_ID_MATERIAL]], (float)mm, "the first hit's material");
    cr_assert_eq(p[l.off[AOV_ID_OBJECT]], 0.0f);
    free(px);
    scene_fini(&s);
}

/* The scene of the fold test: a floor, a sphere, a mirror, sky in the upper rows. */
static void fold_scene(struct scene *s, uint32_t aovs)
{
    memset(s, 0, sizeof *s);
    setup(s, 12, 10, 6, aovs);
    s->camera.position = v3(0, 1, 4);
    s->camera.look_at = v3(0, 0.5f, 0);
    s->camera.fov_y_deg = 40.0f;
    uint32_t fm = add_mat(s, "floor", MATERIAL_DIFFUSE, v3(0.6f, 0.5f, 0.4f));
    uint32_t mm = add_mat(s, "mirror", MATERIAL_MIRROR, v3(0.9f, 0.9f, 0.9f));
    ADD_QUAD(s, v3(-5, 0, -5), v3(-5, 0, 5), v3(5, 0, 5), v3(5, 0, -5), fm);
    struct sphere sp = {"ball", v3(-0.5f, 0.5f, 0), 0.5f, mm, NULL, 0};
    scene_add_sphere(s, &sp);
    struct sphere sp2 = {"ball2", v3(0.7f, 0.3f, 0.5f), 0.3f, fm, NULL, 0};
    scene_add_sphere(s, &sp2);
}

Test(aov, passes_whole_tile_equals_master_fold)
{
    struct scene s;
    fold_scene(&s, AOV_ALL);
    const uint32_t passes = 3, w = 12, h = 10;
    struct render_job job;
    char err[256];
    cr_assert_eq(render_job_init(&job, &s, 0, 1, err, sizeof err), 0, "%s", err);
    render_job_set_passes(&job, passes);
    struct tile_layout l;
    tile_layout_init(&l, AOV_ALL);
    float *whole = calloc((size_t)w * h * l.num_channels, sizeof(float));
    struct tile_stats st;
    integrator_render_tile(&job, 0, 0, w, h, whole, &st);

    /* The master's way: each pass of the one 16-pixel tile on its own, folded out of order. */
    struct image_desc d;
    tile_image_desc(&d, &s.settings);
    cr_assert_eq(d.num_channels, l.num_channels);
    struct fold *f = fold_new(&d, passes, s.settings.spp / passes, integrator_streams(0));
    float *unit = calloc((size_t)w * h * l.num_channels, sizeof(float));
    float *out = calloc((size_t)w * h * (l.num_channels + 1), sizeof(float));
    const uint32_t order[3] = {2, 0, 1};
    int fin = 0;
    for (int i = 0; i < 3; i++) {
        integrator_render_tile_pass(&job, order[i], 0, 0, w, h, unit, &st);
        fin = fold_add(f, 0, order[i], unit, out, &st);
    }
    cr_assert(fin);
    struct image_desc od;
    fold_output_desc(&d, &od);
    cr_assert_str_eq(od.channel_names[FOLD_CH_SAMPLES], "samples");
    cr_assert_str_eq(od.channel_names[FOLD_CH_SAMPLES + 1], "Z");
    int sky = 0, mirror = 0;
    for (size_t i = 0; i < (size_t)w * h; i++) {
        const float *a = &whole[i * l.num_channels], *b = &out[i * (l.num_channels + 1)];
        cr_assert_eq(memcmp(a + TILE_NUM_CHANNELS, b + TILE_NUM_CHANNELS + 1, sizeof(float) * 12), 0,
                     "AOVs of pixel %zu", i);
        sky += isinf(a[l.off[AOV_Z]]);
        mirror += a[l.off[AOV_ID_MATERIAL]] == 1.0f;
    }
    cr_assert(sky > 0 && mirror > 0, "the scene shows sky (%d) and the mirror (%d)", sky, mirror);
    fold_free(&f);
    render_job_fini(&job);

    /* Beauty alone: the same beauty bits (the AOVs change no random number). */
    struct scene s0;
    fold_scene(&s0, 0);
    cr_assert_eq(render_job_init(&job, &s0, 0, 1, err, sizeof err), 0, "%s", err);
    render_job_set_passes(&job, passes);
    float *beauty = calloc((size_t)w * h * TILE_NUM_CHANNELS, sizeof(float));
    integrator_render_tile(&job, 0, 0, w, h, beauty, &st);
    for (size_t i = 0; i < (size_t)w * h; i++)
        cr_assert_eq(memcmp(&beauty[i * TILE_NUM_CHANNELS], &whole[i * l.num_channels], sizeof(float) * TILE_NUM_CHANNELS), 0);
    render_job_fini(&job);
    free(beauty);
    free(whole);
    free(unit);
    free(out);
    scene_fini(&s);
    scene_fini(&s0);
}

Test(aov, worker_values_checked)
{
    struct tile_layout l;
    tile_layout_init(&l, AOV_ALL);
    float px[TILE_MAX_CHANNELS];
    memset(px, 0, sizeof px);
    px[l.off[AOV_Z]] = INFINITY;
    px[l.off[AOV_ID_OBJECT]] = -1.0f;
    px[l.off[AOV_ID_MATERIAL]] = 2.0f;
    cr_assert(aov_pixel_valid(&l, px, 3, 3), "+inf Z, id -1 and an id in range pass");
    float bad[][2] = {{(float)AOV_Z, -1.0f}, {(float)AOV_Z, -INFINITY}, {(float)AOV_Z, NAN},
                      {(float)AOV_ID_OBJECT, 3.0f}, {(float)AOV_ID_OBJECT, 0.5f}, {(float)AOV_ID_MATERIAL, -2.0f},
                      {(float)AOV_N, NAN}, {(float)AOV_P, INFINITY}, {(float)AOV_ALBEDO, -INFINITY}};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        float q[TILE_MAX_CHANNELS];
        memcpy(q, px, sizeof q);
        q[l.off[(int)bad[i][0]]] = bad[i][1];
        cr_assert(!aov_pixel_valid(&l, q, 3, 3), "case %zu accepted", i);
    }
}
