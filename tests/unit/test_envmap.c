/* The environment light (envmap.c, light.c, the integrators): a chi-square test of the
 * piecewise-constant 2D distribution's sampling, its directions' pdfs against envmap_pdf,
 * the furnace (a diffuse sphere of albedo a under a uniform white sky renders a), and
 * importance sampling against uniform sphere sampling on a sky with a small bright sun
 * (the same mean within noise). Also the scene file's "environment" light. */
#include <criterion/criterion.h>
#include <math.h>
#include <string.h>
#include "base/log.h"
#include "base/rng.h"
#include "scene/envmap.h"
#include "scene/light.h"
#include "helpers.h"

/* A w x h sky: a vertical gradient and a sun of radiance `sun` over about `sun_px` texels. */
static float *sky(uint32_t w, uint32_t h, float sun, uint32_t sun_px)
{
    float *rgb = mem_alloc(sizeof(float) * 3 * w * h);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            float t = (float)y / h, *c = &rgb[3 * (y * w + x)];
            c[0] = 0.3f + 0.5f * t;
            c[1] = 0.5f + 0.3f * t;
            c[2] = y < h / 2 ? 1.0f : 0.2f;
            if (x >= w / 3 && x < w / 3 + sun_px && y >= h / 4 && y < h / 4 + sun_px)
                c[0] = c[1] = c[2] = sun;
        }
    return rgb;
}

Test(envmap, distribution_chi_square)
{
    enum { W = 24, H = 12, N = 200000 };
    struct environment *e = envmap_new(sky(W, H, 40.0f, 2), W, H, 1.0f, 30.0f);
    static int count[W * H];
    double expect[W * H], total = 0.0;
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++) {
            const float *c = &e->rgb[3 * (y * W + x)];
            total += expect[y * W + x] = (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]) * sin(M_PI * (y + 0.5) / H);
        }
    uint64_t key = rng_key(4, 0, 0, 0);
    for (int i = 0; i < N; i++) {
        float u, v, pdf;
        envmap_sample_uv(e, rng_uniform(key, 2 * (uint32_t)i), rng_uniform(key, 2 * (uint32_t)i + 1), &u, &v, &pdf);
        cr_assert(u >= 0.0f && u < 1.0f && v >= 0.0f && v < 1.0f);
        uint32_t x = (uint32_t)(u * W), y = (uint32_t)(v * H);
        cr_assert(fabsf(pdf - envmap_pdf_uv(e, u, v)) <= 1e-5f * pdf);
        cr_assert(fabs(pdf - expect[y * W + x] / total * W * H) <= 1e-4 * pdf, "pdf %g", (double)pdf);
        count[y * W + x]++;
    }
    double chi2 = 0.0;
    for (int b = 0; b < W * H; b++) {
        double ex = N * expect[b] / total;
        chi2 += (count[b] - ex) * (count[b] - ex) / ex;
    }
    int dof = W * H - 1;
    cr_assert(chi2 < dof + 6.0 * sqrt(2.0 * dof), "chi2 %g over %d bins", chi2, dof);
    /* Directions: their pdf is envmap_pdf's, and they integrate to 1 over the sphere. */
    double integral = 0.0;
    for (int i = 0; i < 4000; i++) {
        float pdf;
        vec3 d = envmap_sample(e, rng_uniform(key, 9000000 + 2 * (uint32_t)i), rng_uniform(key, 9000001 + 2 * (uint32_t)i), &pdf);
        cr_assert(fabsf(v3_length(d) - 1.0f) < 1e-5f);
        cr_assert(fabsf(envmap_pdf(e, d) - pdf) <= 1e-2f * pdf, "%g against %g", (double)envmap_pdf(e, d), (double)pdf);
    }
    enum { M = 400 };
    for (int i = 0; i < M; i++)
        for (int j = 0; j < M; j++) {
            double th = M_PI * (i + 0.5) / M, ph = 2 * M_PI * (j + 0.5) / M;
            vec3 d = v3((float)(sin(th) * cos(ph)), (float)cos(th), (float)(sin(th) * sin(ph)));
            integral += envmap_pdf(e, d) * sin(th) * (M_PI / M) * (2 * M_PI / M);
        }
    cr_assert(fabs(integral - 1.0) < 1e-2, "pdf integrates to %g", integral);
    envmap_free(&e);
}

/* A diffuse sphere of albedo a seen by the whole frame, under a sky env. */
static void sphere_scene(struct scene *s, float albedo, float *rgb, uint32_t w, uint32_t h, uint32_t spp)
{
    memset(s, 0, sizeof *s);
    struct material m;
    memset(&m, 0, sizeof m);
    m.type = MATERIAL_DIFFUSE;
    m.albedo = v3(albedo, albedo, albedo);
    uint32_t mi = scene_add_material(s, &m);
    struct sphere sp = {"ball", v3(0, 0, -4), 1.0f, mi, NULL, 0};
    scene_add_sphere(s, &sp);
    s->camera = (struct camera_desc){.position = v3(0, 0, 0), .look_at = v3(0, 0, -1), .up = v3(0, 1, 0), .fov_y_deg = 16.0f};
    s->settings = (struct render_settings){.width = 16, .height = 16, .spp = spp, .max_depth = 8, .seed = 3, .tile_size = 16};
    s->env = envmap_new(rgb, w, h, 1.0f, 0.0f);
}

Test(envmap, furnace_convex_object)
{
    const float albedos[] = {0.3f, 0.8f};
    for (int k = 0; k < 2; k++) {
        struct scene s;
        float *rgb = mem_alloc(sizeof(float) * 3 * 8 * 4);
        for (int i = 0; i < 8 * 4 * 3; i++)
            rgb[i] = 1.0f;
        sphere_scene(&s, albedos[k], rgb, 8, 4, 32);
        struct tile_stats st;
        float *px = test_render(&s, 2, &st);
        double se, mean = test_channel_mean(px, 16, 16, CH_G, &se);
        /* Light sampling and BSDF sampling both see exactly 1 from every direction. */
        cr_assert(fabs(mean - albedos[k]) < 4.0 * se + 1e-3, "albedo %g: %g (se %g)", (double)albedos[k], mean, se);
        free(px);
        scene_fini(&s);
    }
}

/* A sphere on a plane under a sky with a sun of 1/1000 of the texels: importance and
 * uniform sampling agree within their noise. */
Test(envmap, importance_matches_uniform)
{
    double mean[2], se[2];
    for (int u = 0; u < 2; u++) {
        struct scene s;
        sphere_scene(&s, 0.7f, sky(64, 32, 2000.0f, 1), 64, 32, u ? 512 : 64);
        s.camera.fov_y_deg = 40.0f;
        struct material m;
        memset(&m, 0, sizeof m);
        m.type = MATERIAL_DIFFUSE;
        m.albedo = v3(0.5f, 0.5f, 0.5f);
        uint32_t pm = scene_add_material(&s, &m);
        struct mesh q = test_quad(v3(-6, -1, 2), v3(6, -1, 2), v3(6, -1, -10), v3(-6, -1, -10), pm, 1);
        scene_add_mesh(&s, &q);
        s.env->uniform = u;
        struct tile_stats st;
        float *px = test_render(&s, 2, &st);
        mean[u] = test_channel_mean(px, 16, 16, CH_G, &se[u]);
        free(px);
        scene_fini(&s);
    }
    double d = fabs(mean[0] - mean[1]), sd = sqrt(se[0] * se[0] + se[1] * se[1]);
    cr_assert(d < 4.0 * sd, "importance %g (se %g) against uniform %g (se %g)", mean[0], se[0], mean[1], se[1]);
    cr_assert(se[0] < se[1], "importance sampling noisier (%g) than uniform (%g) at 1/8 the samples", se[0], se[1]);
}

Test(envmap, scene_file)
{
    /* A 2 x 1 Radiance file: left texel 2, right texel 0.5 (flat RGBE: mantissa, exponent). */
    static const unsigned char hdr[] = "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 2\n\x80\x80\x80\x82\x80\x80\x80\x80";
    struct mem_file files[] = {{"sky.hdr", hdr, sizeof hdr - 1}, {NULL, NULL, 0}};
    struct scene s;
    char err[512];
    const char *text = "{\"version\": 1, \"camera\": {\"position\": [0,0,0], \"look_at\": [0,0,-1], \"fov_y\": 40},"
                       " \"render\": {\"width\": 8, \"height\": 8, \"spp\": 1},"
                       " \"lights\": [{\"type\": \"environment\", \"file\": \"sky.hdr\", \"strength\": 3, \"rotation\": 90}]}";
    cr_assert_eq(test_scene_load(text, files, &s, err), 0, "%s", err);
    cr_assert(s.env && s.env->width == 2 && s.env->height == 1);
    cr_assert_float_eq(s.env->rgb[0], 2.0f, 1e-6f);
    cr_assert_float_eq(s.env->rgb[3], 0.5f, 1e-6f);
    cr_assert_float_eq(s.env->strength, 3.0f, 1e-6f);
    /* rotation 90: u = (atan2(z, x) - 90 deg) / 360; +z (phi 90) is u = 0, the left texel. */
    cr_assert_float_eq(envmap_eval(s.env, v3(0, 0, 1)).x, 6.0f, 1e-5f);
    cr_assert_float_eq(envmap_eval(s.env, v3(0, 0, -1)).x, 1.5f, 1e-5f);
    scene_fini(&s);
    test_scene_expect_error("{\"version\": 1, \"camera\": {\"position\": [0,0,0], \"look_at\": [0,0,-1], \"fov_y\": 40},"
                            " \"render\": {\"width\": 8, \"height\": 8, \"spp\": 1}, \"lights\": [{\"type\": \"environment\", \"file\": \"sky.hdr\", \"strength\": -1}]}",
                            files, "strength must be in [0, 1e12]");
    test_scene_expect_error("{\"version\": 1, \"camera\": {\"position\": [0,0,0], \"look_at\": [0,0,-1], \"fov_y\": 40},"
                            " \"render\": {\"width\": 8, \"height\": 8, \"spp\": 1}, \"lights\": [{\"type\": \"environment\"}]}",
                            files, "file");
}
