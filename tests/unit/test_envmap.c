/* The environment light (envmap.c, light.c, the integrators): a chi-square test of the
 * piecewise-constant 2D distribution's sampling, its directions' pdfs against envmap_pdf,
 * the furnace (a diffuse sphere of albedo a under a uniform white sky renders a), and
 * importance sampling against uniform sphere sampling on a sky with a small bright sun
 * (the same mean within noise). Also the scene file's "environment" light, and its photons:
 * their power against the closed form, aimed at media or not, and a scattering sphere
 * under a uniform sky by the photon map against VPT. */
#include <criterion/criterion.h>
#include <math.h>
#include <string.h>
#include "base/log.h"
#include "base/rng.h"
#include "scene/envmap.h"
#include "scene/light.h"
#include "render/photon_map.h"
#include "render/photon_trace.h"
#include "render/render_job.h"
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

/* The sky's photons (envmap_emit): the expected power of all of them is pi R^2 times the
 * integral of L over the sphere (R: the scene's disc), and that of the lines crossing a
 * ball of radius r inside the scene's bounding sphere pi r^2 times the same integral, for
 * a uniform sky and one with a sun, with no aiming and with 1/2 and 3/4 of the lines aimed
 * at a media sphere: both balls (the media sphere and one away from it) get their power, within
 * 4 standard errors, and aiming makes the media sphere's estimate less noisy. */
Test(envmap, photon_emission_power)
{
    enum { W = 16, H = 8, N = 300000 };
    const vec3 c = v3(1, 2, 3), cm = v3(3, 1, 4);
    const float R = 5.0f, rm = 1.0f;
    const vec3 ball_c[2] = {cm, v3(-2, 2, 3.5f)};
    const float ball_r[2] = {rm, 1.2f};
    for (int k = 0; k < 2; k++) {
        float *rgb = k ? sky(W, H, 40.0f, 2) : mem_alloc(sizeof(float) * 3 * W * H);
        for (int i = 0; !k && i < W * H; i++)
            rgb[3 * i] = 0.5f, rgb[3 * i + 1] = 1.0f, rgb[3 * i + 2] = 2.0f;
        struct environment *e = envmap_new(rgb, W, H, 2.0f, 30.0f);
        /* The integral of L (green) over the sphere: each texel's radiance times its solid angle. */
        double integral = 0.0;
        for (uint32_t y = 0; y < H; y++)
            for (uint32_t x = 0; x < W; x++)
                integral += 2.0 * rgb[3 * (y * W + x) + 1] * (2.0 * M_PI / W) * (cos(M_PI * y / H) - cos(M_PI * (y + 1) / H));
        if (!k)
            cr_assert(fabs(integral - 4.0 * M_PI * 2.0) < 1e-9 * integral);
        double se_media[3];
        for (int a = 0; a < 3; a++) {
            float share = a == 0 ? 0.0f : a == 1 ? 0.5f : 0.75f;
            double tot = 0.0, sum[2] = {0, 0}, sq[2] = {0, 0};
            uint64_t key = rng_key(7, (uint32_t)k, (uint64_t)a, 0);
            for (uint32_t i = 0; i < N; i++) {
                float u[5];
                for (uint32_t j = 0; j < 5; j++)
                    u[j] = rng_uniform(key, 5 * i + j);
                vec3 o, d;
                double f = envmap_emit(e, c, R, cm, rm, share, u, &o, &d).y;
                cr_assert(f >= 0.0 && isfinite(f));
                if (f == 0.0)
                    continue;
                cr_assert(fabsf(v3_length(d) - 1.0f) < 1e-5f);
                cr_assert(v3_length(v3_sub(o, c)) >= R * 0.9999f && v3_length(v3_sub(o, cm)) >= rm, "origin inside");
                tot += f;
                for (int b = 0; b < 2; b++) {
                    vec3 q = v3_sub(ball_c[b], o);
                    vec3 perp = v3_sub(q, v3_scale(d, v3_dot(q, d)));
                    if (v3_dot(perp, perp) <= ball_r[b] * ball_r[b])
                        sum[b] += f, sq[b] += f * f;
                }
            }
            double want = M_PI * R * R * integral;
            cr_assert(fabs(tot / N - want) < 0.02 * want, "sky %d share %g: total %g, want %g", k, (double)share, tot / N, want);
            for (int b = 0; b < 2; b++) {
                double mean = sum[b] / N, se = sqrt(fmax(sq[b] / N - mean * mean, 0.0) / N);
                double wb = M_PI * ball_r[b] * ball_r[b] * integral;
                cr_log_info("sky %d share %g ball %d: %g +- %g, want %g", k, (double)share, b, mean, se, wb);
                cr_assert(fabs(mean - wb) < 4.0 * se + 1e-6 * wb, "sky %d share %g ball %d: %g +- %g, want %g", k,
                          (double)share, b, mean, se, wb);
                if (b == 0)
                    se_media[a] = se;
            }
        }
        cr_assert(se_media[1] < 0.5 * se_media[0] && se_media[2] < se_media[1], "aiming: errors %g %g against %g",
                  se_media[1], se_media[2], se_media[0]);
        envmap_free(&e);
    }
}

/* A sphere of scattering medium (albedo 0.9, optical radius 3) over a black floor under a
 * uniform white sky (a 1 x 1 map): the photon map's image (beam) against VPT's, within 10 %
 * as for point lights (test_medium.c), and clearly brighter than single scattering alone.
 * The floor makes the scene's sphere large and the media's small in it, so half of the
 * sky's photons are aimed at the media. (Over a grey floor, where light bounced off the
 * floor is a third of the image, the beam estimate's RMSE over 24 seeds is 8 %: see
 * ENV_AIM_SHARE in photon_trace.c.) The map's bytes are the same for 1 and 2 threads. */
#define ENV_MEDIUM_SCENE(method)                                                                             \
    "{\"version\": 1, \"camera\": {\"position\": [0, 0, -4], \"look_at\": [0, 0, 0], \"fov_y\": 18},\n"        \
    "\"render\": {\"width\": 12, \"height\": 12, \"spp\": 1, \"max_depth\": 64, \"tile_size\": 8},\n"           \
    "\"materials\": {\"black\": {\"type\": \"diffuse\", \"albedo\": [0, 0, 0]}},\n"                             \
    "\"media\": {\"m\": {\"sigma_a\": [0.3, 0.3, 0.3], \"sigma_s\": [2.7, 2.7, 2.7], \"g\": 0.2}},\n"          \
    "\"volume\": {\"method\": \"" method "\", \"photons\": 100000, \"radius\": 0.06, \"step\": 0.03},\n"      \
    "\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"medium\": \"m\"},\n"        \
    "  {\"type\": \"obj\", \"file\": \"floor.obj\", \"material\": \"black\"}],\n"                              \
    "\"lights\": [{\"type\": \"environment\", \"file\": \"sky.hdr\"}]}"

static double env_render_mean(struct scene *s, struct photon_map *map, uint32_t spp, double *se)
{
    s->settings.spp = spp;
    struct tile_stats st;
    float *px = test_render_map(s, map, 2, &st);
    double mean = test_channel_mean(px, s->settings.width, s->settings.height, CH_G, se);
    cr_assert(isfinite(mean) && st.nan_samples == 0);
    free(px);
    return mean;
}

Test(envmap, photons_in_medium_match_vpt, .timeout = 120)
{
    static const unsigned char hdr[] = "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 1\n\x80\x80\x80\x81";
    static const char floor_obj[] = "v -10 -1.2 -10\nv 10 -1.2 -10\nv 10 -1.2 10\nv -10 -1.2 10\nf 1 4 3 2\n";
    struct mem_file files[] = {{"sky.hdr", hdr, sizeof hdr - 1}, {"floor.obj", floor_obj, 0}, {NULL, NULL, 0}};
    struct scene s;
    char err[512];
    cr_assert_eq(test_scene_load(ENV_MEDIUM_SCENE("vpt"), files, &s, err), 0, "%s", err);
    cr_assert_float_eq(envmap_eval(s.env, v3(0, 1, 0)).y, 1.0f, 1e-6f);
    double se_ref, ref = env_render_mean(&s, NULL, 128, &se_ref);
    s.media->method = MEDIA_MARCH_BEAM;
    struct render_job job;
    cr_assert_eq(render_job_init(&job, &s, 0, 1, err, sizeof err), 0, "%s", err);
    uint8_t *blob = NULL;
    size_t n = 0;
    struct photon_pass_stats st;
    cr_assert_eq(photon_trace_map(&job, 1, 2, &blob, &n, &st, err, sizeof err), 0, "%s", err);
    /* The same bytes from one thread (photon i draws only from its own random numbers). */
    uint8_t *blob1 = NULL;
    size_t n1 = 0;
    struct photon_pass_stats st1;
    cr_assert_eq(photon_trace_map(&job, 1, 1, &blob1, &n1, &st1, err, sizeof err), 0, "%s", err);
    cr_assert(n1 == n && memcmp(blob1, blob, n) == 0, "1 and 2 threads give different maps");
    free(blob1);
    render_job_fini(&job);
    struct photon_map *map = NULL;
    cr_assert_eq(photon_map_decode(blob, n, &map, err, sizeof err), 0, "%s", err);
    free(blob);
    double se_b, beam = env_render_mean(&s, map, 4, &se_b);
    photon_map_free(&map);
    double se_s, single = env_render_mean(&s, NULL, 4, &se_s);
    cr_log_info("uniform sky, scattering sphere: beam %g, vpt %g +- %g, single scattering %g; %llu photons stored",
                beam, ref, se_ref, single, (unsigned long long)st.stored);
    cr_assert(fabs(beam / ref - 1.0) < 0.10, "beam %g vs vpt %g (+- %g)", beam, ref, se_ref);
    cr_assert(single < 0.8 * ref, "single %g vs vpt %g", single, ref);
    scene_fini(&s);
}
