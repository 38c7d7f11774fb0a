/* Textures, MIP pyramids, EWA and ray differentials:
 * - pyramid sizes and means for non-power-of-two images, the level for a footprint, EWA
 *   weights for known footprints (sum to one, Gaussian in the ellipse's metric), the
 *   anisotropy clamp, the checker's closed-form box filter against numerical integration;
 * - camera differentials against finite differences, a flat mirror against the unfolded
 *   camera, a glass slab against analytic refraction, sphere and triangle texture
 *   derivatives, degenerate UVs and grazing angles;
 * - decoding PNG, JPEG, HDR and EXR bytes, and garbage, truncated and oversized files;
 * - renders: a checkerboard to the horizon at 1 spp, EWA far below unfiltered against a
 *   converged box-filtered reference; a 16k texture, a wide-open thin lens and
 *   degenerate UVs render without NaN. */
#include <criterion/criterion.h>
#include <math.h>
#include <stb/stb_image_write.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "image/image_load.h"
#include "image/imgio.h"
#include "render/integrator.h"
#include "base/log.h"
#include "scene/material.h"
#include "image/mip.h"
#include "render/raydiff.h"
#include "scene/texture.h"
#include "helpers.h"

/* ---- helpers ---- */

static void f32_image(struct tex_image *im, uint32_t w, uint32_t h, uint32_t nc)
{
    cr_assert_eq(tex_image_alloc(im, w, h, nc, TEXEL_F32), 0);
}

static float *texels(struct tex_image *im)
{
    return (float *)im->data;
}

static double level_mean(const struct mip *m, uint32_t level)
{
    const struct tex_image *im = &m->levels[level];
    double s = 0;
    for (uint32_t y = 0; y < im->height; y++)
        for (uint32_t x = 0; x < im->width; x++)
            s += mip_texel(m, level, x, y).x;
    return s / ((double)im->width * im->height);
}

/* ---- MIP ---- */

Test(mip, non_power_of_two_levels_keep_the_mean)
{
    struct tex_image im;
    f32_image(&im, 37, 5, 1);
    for (uint32_t i = 0; i < 37 * 5; i++)
        texels(&im)[i] = (float)((i * 7919u) % 101u) / 100.0f;
    struct mip m;
    mip_init(&m, &im, TEXWRAP_REPEAT);
    static const uint32_t w[] = {37, 18, 9, 4, 2, 1}, h[] = {5, 2, 1, 1, 1, 1};
    cr_assert_eq(m.num_levels, 6);
    double mean0 = level_mean(&m, 0);
    for (uint32_t l = 0; l < m.num_levels; l++) {
        cr_expect_eq(m.levels[l].width, w[l], "level %u", l);
        cr_expect_eq(m.levels[l].height, h[l], "level %u", l);
        cr_expect(fabs(level_mean(&m, l) - mean0) < 1e-5, "level %u mean %g vs %g", l, level_mean(&m, l), mean0);
    }
    mip_fini(&m);
    tex_image_fini(&im);
}

Test(mip, srgb_bytes_average_in_linear_space)
{
    /* Black and white texels average to linear 0.5, i.e. sRGB byte 188, not 128. */
    struct tex_image im;
    cr_assert_eq(tex_image_alloc(&im, 2, 1, 1, TEXEL_U8_SRGB), 0);
    ((uint8_t *)im.data)[0] = 0;
    ((uint8_t *)im.data)[1] = 255;
    struct mip m;
    mip_init(&m, &im, TEXWRAP_CLAMP);
    cr_assert_eq(m.num_levels, 2);
    cr_expect_eq(((uint8_t *)m.levels[1].data)[0], 188);
    cr_expect(fabsf(mip_texel(&m, 1, 0, 0).x - 0.5f) < 0.003f);
    cr_expect(fabsf(mip_srgb_to_linear(128.0f / 255.0f) - 0.2158605f) < 1e-5f);
    mip_fini(&m);
    tex_image_fini(&im);
}

Test(mip, level_for_known_footprint)
{
    struct tex_image im;
    f32_image(&im, 256, 64, 1);
    struct mip m;
    mip_init(&m, &im, TEXWRAP_REPEAT);
    cr_assert_eq(m.num_levels, 9);
    cr_expect_float_eq(mip_level_for_width(&m, 1.0f / 256.0f), 0.0f, 1e-6);
    cr_expect_float_eq(mip_level_for_width(&m, 4.0f / 256.0f), 2.0f, 1e-5);
    cr_expect_float_eq(mip_level_for_width(&m, 0.5f / 256.0f), 0.0f, 1e-6);
    cr_expect_float_eq(mip_level_for_width(&m, 10.0f), 8.0f, 1e-6);
    cr_expect_float_eq(mip_level_for_width(&m, NAN), 0.0f, 1e-6);
    /* EWA: a 64:1 footprint with max anisotropy 8 widens the minor axis to major / 8;
     * the major axis given second is swapped to the front. */
    float ds0 = 0.0f, dt0 = 0.5f / 256.0f, ds1 = 32.0f / 256.0f, dt1 = 0.0f;
    float lvl = mip_ewa_select(&m, 8.0f, &ds0, &dt0, &ds1, &dt1);
    cr_expect_float_eq(ds0, 32.0f / 256.0f, 1e-7);
    cr_expect_float_eq(dt0, 0.0f, 1e-9);
    cr_expect_float_eq(ds1, 0.0f, 1e-9);
    cr_expect_float_eq(dt1, 4.0f / 256.0f, 1e-6);
    cr_expect_float_eq(lvl, 2.0f, 1e-5);
    mip_fini(&m);
    tex_image_fini(&im);
}

Test(mip, ewa_weights_sum_to_one_and_follow_the_ellipse)
{
    struct tex_image im;
    f32_image(&im, 64, 64, 1);
    struct mip m;
    mip_init(&m, &im, TEXWRAP_REPEAT);
    enum { CAP = 4096 };
    int64_t xs[CAP], ys[CAP];
    float ws[CAP];
    struct mip_ewa_record rec = {xs, ys, ws, CAP, 0};
    /* Axis-aligned ellipse: 6 texels along s, 2 along t, centred between texels. */
    float s = 20.0f / 64.0f, t = 30.0f / 64.0f;
    mip_ewa_level(&m, 0, s, t, 6.0f / 64.0f, 0.0f, 0.0f, 2.0f / 64.0f, &rec);
    cr_assert(rec.count > 10 && rec.count <= CAP, "count %zu", rec.count);
    double sum = 0, cx = 0, cy = 0;
    float wmax = 0;
    for (size_t i = 0; i < rec.count; i++) {
        cr_expect(ws[i] > 0.0f);
        sum += ws[i];
        cx += ws[i] * (double)xs[i];
        cy += ws[i] * (double)ys[i];
        wmax = fmaxf(wmax, ws[i]);
    }
    cr_expect(fabs(sum - 1.0) < 1e-5, "sum %g", sum);
    /* Symmetric about the centre (texel centres at integer + 0.5 -> 19.5, 29.5). */
    cr_expect(fabs(cx - 19.5) < 1e-3 && fabs(cy - 29.5) < 1e-3, "centroid %g %g", cx, cy);
    /* Longer along s than t: the farthest texel with weight lies further in s. */
    double ext_s = 0, ext_t = 0;
    for (size_t i = 0; i < rec.count; i++) {
        ext_s = fmax(ext_s, fabs((double)xs[i] - 19.5));
        ext_t = fmax(ext_t, fabs((double)ys[i] - 29.5));
    }
    cr_expect(ext_s > 2.0 * ext_t, "extent %g x %g", ext_s, ext_t);
    /* A rotated footprint: weights sum to one too, and a constant texture stays constant. */
    for (uint32_t i = 0; i < 64 * 64; i++)
        texels(&im)[i] = 0.375f;
    vec3 c = mip_ewa_level(&m, 0, 0.1f, 0.9f, 3.0f / 64, 3.0f / 64, -0.5f / 64, 0.5f / 64, &rec);
    sum = 0;
    for (size_t i = 0; i < rec.count; i++)
        sum += ws[i];
    cr_expect(fabs(sum - 1.0) < 1e-5);
    cr_expect_float_eq(c.x, 0.375f, 1e-6);
    mip_fini(&m);
    tex_image_fini(&im);
}

Test(mip, filters_agree_on_smooth_images_and_wrap)
{
    struct tex_image im;
    f32_image(&im, 128, 96, 3);
    for (uint32_t y = 0; y < 96; y++)
        for (uint32_t x = 0; x < 128; x++)
            for (int c = 0; c < 3; c++)
                texels(&im)[(y * 128 + x) * 3 + c] = 0.5f + 0.4f * sinf(6.2831853f * (x + 0.5f) / 128.0f);
    struct mip m;
    mip_init(&m, &im, TEXWRAP_REPEAT);
    for (int f = 0; f < TEXFILTER_COUNT_; f++) {
        vec3 a = mip_lookup(&m, (enum texture_filter)f, 8, 0.3f, 0.4f, 0.5f / 128, 0, 0, 0.5f / 96);
        vec3 b = mip_lookup(&m, (enum texture_filter)f, 8, 2.3f, -3.6f, 0.5f / 128, 0, 0, 0.5f / 96);
        float want = 0.5f + 0.4f * sinf(6.2831853f * 0.3f);
        cr_expect(fabsf(a.x - want) < 0.03f, "filter %d: %g vs %g", f, a.x, want);
        cr_expect(fabsf(a.x - b.x) < 1e-4f, "repeat, filter %d", f);
    }
    /* A footprint covering the whole texture gives its mean. */
    vec3 all = mip_lookup(&m, TEXFILTER_EWA, 8, 0.5f, 0.5f, 2.0f, 0, 0, 2.0f);
    cr_expect(fabsf(all.x - 0.5f) < 0.01f, "%g", all.x);
    vec3 nanl = mip_lookup(&m, TEXFILTER_EWA, 8, NAN, 0.5f, 0, 0, 0, 0);
    cr_expect(v3_is_finite(nanl));
    vec3 inf_d = mip_lookup(&m, TEXFILTER_EWA, 8, 0.5f, 0.5f, INFINITY, NAN, 1e30f, -1e30f);
    cr_expect(v3_is_finite(inf_d));
    mip_fini(&m);
    tex_image_fini(&im);
}

/* ---- checker ---- */

Test(texture, checker_box_filter_matches_numerical_integration)
{
    vec3 c0 = v3(1, 1, 1), c1 = v3(0, 0, 0);
    uint64_t st = 12345;
    for (int k = 0; k < 200; k++) {
        st = st * 6364136223846793005ull + 1442695040888963407ull;
        float s = (float)((st >> 33) % 100000) / 1000.0f - 50.0f;
        st = st * 6364136223846793005ull + 1442695040888963407ull;
        float t = (float)((st >> 33) % 100000) / 1000.0f - 50.0f;
        float ds = 0.01f + (float)(k % 13) * 0.27f, dt = 0.02f + (float)(k % 7) * 0.41f;
        vec3 v = texture_checker_box(s, t, ds, dt, c0, c1);
        /* Midpoint rule on a fine grid. */
        int n = 400;
        double acc = 0;
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                double x = s - ds + (2.0 * ds) * (i + 0.5) / n, y = t - dt + (2.0 * dt) * (j + 0.5) / n;
                acc += (((int64_t)floor(x) + (int64_t)floor(y)) & 1) ? 0.0 : 1.0;
            }
        acc /= (double)n * n;
        cr_expect(fabs(v.x - acc) < 0.01, "s %g t %g ds %g dt %g: %g vs %g", s, t, ds, dt, v.x, acc);
    }
    cr_expect_float_eq(texture_checker_box(0.5f, 0.5f, 0, 0, c0, c1).x, 1.0f, 0);
    cr_expect_float_eq(texture_checker_box(1.5f, 0.5f, 0, 0, c0, c1).x, 0.0f, 0);
}

/* ---- ray differentials ---- */

static vec3 vlerp_diff(vec3 a, vec3 b, float inv_eps)
{
    return v3_scale(v3_sub(b, a), inv_eps);
}

static void expect_vec_near(vec3 a, vec3 b, float tol, const char *what)
{
    float e = v3_length(v3_sub(a, b)), scale = fmaxf(v3_length(b), 1e-3f);
    cr_expect(e <= tol * scale, "%s: (%g %g %g) vs (%g %g %g)", what, a.x, a.y, a.z, b.x, b.y, b.z);
}

Test(raydiff, camera_matches_finite_differences_pinhole_and_lens)
{
    struct camera_desc d;
    memset(&d, 0, sizeof d);
    d.position = v3(1, 2, 3);
    d.look_at = v3(0, 0.5f, -2);
    d.up = v3(0, 1, 0);
    d.fov_y_deg = 50;
    for (int lens = 0; lens < 2; lens++) {
        d.aperture_radius = lens ? 0.4f : 0.0f;
        struct camera cam;
        camera_init(&cam, &d, 200, 100);
        float fx = 37.3f, fy = 81.6f, lu = 0.8f, lv = 0.15f, eps = 0.01f;
        vec3 o, dir, ox, dx, oy, dy;
        camera_ray_lens(&cam, &cam.still, fx, fy, lu, lv, &o, &dir);
        camera_ray_lens(&cam, &cam.still, fx + eps, fy, lu, lv, &ox, &dx);
        camera_ray_lens(&cam, &cam.still, fx, fy + eps, lu, lv, &oy, &dy);
        struct raydiff rd;
        raydiff_camera(&cam, &cam.still, dir, 1.0f, &rd);
        expect_vec_near(rd.dddx, vlerp_diff(dir, dx, 1 / eps), 2e-2f, "dd/dx");
        expect_vec_near(rd.dddy, vlerp_diff(dir, dy, 1 / eps), 2e-2f, "dd/dy");
        cr_expect(v3_length(rd.dodx) == 0.0f && v3_length(v3_sub(ox, o)) == 0.0f, "same lens point");
    }
    cr_expect_float_eq(raydiff_spp_scale(1), 1.0f, 0);
    cr_expect_float_eq(raydiff_spp_scale(16), 0.25f, 1e-7);
    cr_expect_float_eq(raydiff_spp_scale(4096), 0.125f, 0);
}

/* The hit of the plane dot(n, p) = c along (o, d) and the transfer of rd there. */
static float plane_hit(vec3 o, vec3 d, vec3 n, float c, const struct raydiff *rd, vec3 *p, vec3 *dpdx, vec3 *dpdy)
{
    float t = (c - v3_dot(n, o)) / v3_dot(n, d);
    *p = v3_add(o, v3_scale(d, t));
    raydiff_transfer(rd, d, t, n, dpdx, dpdy);
    return t;
}

static vec3 mirror_z(vec3 v, float z0, int point)
{
    return v3(v.x, v.y, point ? 2 * z0 - v.z : -v.z);
}

Test(raydiff, flat_mirror_equals_unfolded_camera)
{
    vec3 o = v3(0.3f, 1.0f, -4.0f), d = v3_normalize(v3(0.2f, -0.1f, 1.0f));
    struct raydiff rd = {v3(0, 0, 0), v3(0, 0, 0), v3(0.01f, 0.002f, -0.001f), v3(-0.001f, 0.012f, 0.0005f), 0.0f, 0.0f};
    /* Mirror: the plane z = 2 facing the camera (normal -z). */
    vec3 nm = v3(0, 0, -1), p, dpx, dpy;
    plane_hit(o, d, nm, -2.0f, &rd, &p, &dpx, &dpy);
    vec3 r = v3_sub(d, v3_scale(nm, 2 * v3_dot(d, nm)));
    struct raydiff fold = rd;
    raydiff_reflect(&fold, d, r, nm, v3(0, 0, 0), v3(0, 0, 0), dpx, dpy);
    /* Target: a tilted plane in front of the mirror. */
    vec3 nt = v3_normalize(v3(0.3f, 0.2f, 1.0f));
    float ct = v3_dot(nt, v3(0, 0, -1));
    vec3 p2, d2x, d2y;
    plane_hit(p, r, nt, ct, &fold, &p2, &d2x, &d2y);
    /* Unfolded: the straight camera ray against the target mirrored through z = 2. */
    vec3 ntm = mirror_z(nt, 2, 0);
    float ctm = v3_dot(ntm, mirror_z(v3_scale(nt, ct / v3_dot(nt, nt)), 2, 1));
    vec3 q, qx, qy;
    plane_hit(o, d, ntm, ctm, &rd, &q, &qx, &qy);
    expect_vec_near(mirror_z(q, 2, 1), p2, 1e-4f, "point");
    expect_vec_near(mirror_z(qx, 2, 0), d2x, 1e-3f, "dp/dx");
    expect_vec_near(mirror_z(qy, 2, 0), d2y, 1e-3f, "dp/dy");
    cr_expect(v3_length(d2x) > 0.01f);
}

/* Traces (o, d) through the slab a <= z <= a + h of index n with exact Snell refraction
 * (material_refract) to the plane z = zt; returns the point there. */
static vec3 slab_trace(vec3 o, vec3 d, float a, float h, float n, float zt)
{
    vec3 p1 = v3_add(o, v3_scale(d, (a - o.z) / d.z));
    vec3 n1 = v3(0, 0, -1), t1, t2;
    cr_assert(material_refract(v3_neg(d), n1, -v3_dot(d, n1), n, &t1));
    vec3 p2 = v3_add(p1, v3_scale(t1, (a + h - p1.z) / t1.z));
    cr_assert(material_refract(v3_neg(t1), n1, -v3_dot(t1, n1), 1.0f / n, &t2));
    return v3_add(p2, v3_scale(t2, (zt - p2.z) / t2.z));
}

/* A 1-spp (or one-per-cell) lookup is centred on its cell: through a pinhole onto a plane
 * parallel to the film, where texture coordinates are affine in the film position, the
 * centred coordinates of a jittered ray equal those of the ray through the cell's centre,
 * also after a flat mirror; a diffuse bounce drops the offset. */
Test(raydiff, lookups_are_centred_on_the_sample_cell)
{
    struct camera_desc cd;
    memset(&cd, 0, sizeof cd);
    cd.position = v3(0.2f, 0.1f, 0);
    cd.look_at = v3(0.2f, 0.1f, 1);
    cd.up = v3(0, 1, 0);
    cd.fov_y_deg = 40;
    struct camera cam;
    camera_init(&cam, &cd, 64, 48);
    const float a = 3.7f; /* u = a x, v = a y on the plane z = zp (seen directly or folded) */
    static const uint32_t cells[][2] = {{1, 1}, {2, 2}, {4, 4}, {2, 4}, {16, 16}};
    for (int mirror = 0; mirror < 2; mirror++)
        for (size_t ci = 0; ci < sizeof cells / sizeof *cells; ci++) {
            uint32_t nx = cells[ci][0], ny = cells[ci][1];
            float sx = raydiff_cell_scale(nx), sy = raydiff_cell_scale(ny), jx = 0.93f, jy = 0.08f;
            float cxp = (floorf(jx * nx) + 0.5f) / nx, cyp = (floorf(jy * ny) + 0.5f) / ny;
            struct tex_coord tcs[2];
            for (int centre = 0; centre < 2; centre++) {
                float fx = 21.0f + (centre ? cxp : jx), fy = 30.0f + (centre ? cyp : jy);
                vec3 o, d, p, dpx, dpy;
                camera_ray(&cam, fx, fy, &o, &d);
                struct raydiff rd;
                raydiff_camera(&cam, &cam.still, d, 1.0f, &rd);
                rd.dddx = v3_scale(rd.dddx, sx);
                rd.dddy = v3_scale(rd.dddy, sy);
                raydiff_set_center(&rd, centre ? 0.5f : jx, centre ? 0.5f : jy, centre ? 0 : nx, ny, sx, sy);
                float t, zp = mirror ? -1.0f : 5.0f;
                if (mirror) { /* the mirror z = 2 folds the ray back onto the plane z = -1 */
                    plane_hit(o, d, v3(0, 0, -1), -2.0f, &rd, &p, &dpx, &dpy);
                    vec3 r = v3(d.x, d.y, -d.z);
                    raydiff_reflect(&rd, d, r, v3(0, 0, -1), v3(0, 0, 0), v3(0, 0, 0), dpx, dpy);
                    t = plane_hit(p, r, v3(0, 0, 1), -1.0f, &rd, &p, &dpx, &dpy);
                    o = v3_sub(p, v3_scale(r, t)), d = r;
                } else {
                    t = plane_hit(o, d, v3(0, 0, -1), -5.0f, &rd, &p, &dpx, &dpy);
                }
                /* The hit on a big triangle of that plane whose uv is a x its (x, y). */
                const vec3 tri[3] = {v3(-50, -50, zp), v3(50, -50, zp), v3(-50, 50, zp)};
                const float uv[3][2] = {{-50 * a, -50 * a}, {50 * a, -50 * a}, {-50 * a, 50 * a}};
                struct raydiff_hit hit;
                raydiff_triangle(tri, uv, NULL, (p.x + 50) / 100, (p.y + 50) / 100, v3(0, 0, 1), &rd, d, t, &hit);
                struct tex_coord tc = hit.tc;
                cr_expect(tc.cx == rd.cx && tc.cy == rd.cy, "the hit carries the ray's offset");
                tex_coord_centre(&tc, &tc.u, &tc.v);
                tcs[centre] = tc;
                cr_expect(centre || fabsf(rd.cx) > 0.01f, "a jittered sample has an offset");
            }
            cr_expect(fabsf(tcs[0].u - tcs[1].u) < 2e-5f && fabsf(tcs[0].v - tcs[1].v) < 2e-5f,
                      "mirror %d cells %ux%u: centred (%g %g) vs cell centre (%g %g)", mirror, nx, ny, tcs[0].u, tcs[0].v,
                      tcs[1].u, tcs[1].v);
        }
    struct raydiff rd = {v3(0, 0, 0), v3(0, 0, 0), v3(0.01f, 0, 0), v3(0, 0.01f, 0), 0.3f, -0.2f};
    raydiff_diffuse(&rd, v3(0, 0, 1), v3(0.01f, 0, 0), v3(0, 0.01f, 0));
    cr_expect(rd.cx == 0.0f && rd.cy == 0.0f, "a diffuse bounce drops the offset");
    raydiff_set_center(&rd, NAN, 0.5f, 1, 1, 1.0f, 1.0f);
    cr_expect(rd.cx == 0.0f && rd.cy == 0.0f, "no offset from a bad jitter");
}

/* The centring offset moves the footprint filters' lookups only: a point lookup (nearest,
 * bilinear) stays at the sample, so that jittered samples still integrate the texture. */
Test(texture, centring_moves_footprint_filters_only)
{
    struct texture t;
    texture_init(&t, TEXTURE_IMAGE, "ramp");
    f32_image(&t.image, 64, 4, 1);
    for (uint32_t y = 0; y < 4; y++)
        for (uint32_t x = 0; x < 64; x++)
            texels(&t.image)[y * 64 + x] = (float)x / 64.0f;
    struct mip m;
    mip_init(&m, &t.image, TEXWRAP_CLAMP);
    /* A footprint of 1/4 texel (level 0) moved 4 texels along u: cx * dudx = 4 / 64. */
    struct tex_coord tc = {0.3f, 0.5f, 0.25f / 64.0f, 0.0f, 0.0f, 0.25f / 4.0f, 16.0f, 0.0f};
    float expect[TEXFILTER_COUNT_];
    expect[TEXFILTER_NEAREST] = 19.0f / 64.0f;            /* texel floor(0.3 * 64) = 19 */
    expect[TEXFILTER_BILINEAR] = (0.3f * 64.0f - 0.5f) / 64.0f;
    expect[TEXFILTER_TRILINEAR] = ((0.3f + 4.0f / 64.0f) * 64.0f - 0.5f) / 64.0f;
    expect[TEXFILTER_EWA] = expect[TEXFILTER_TRILINEAR];
    for (int f = 0; f < TEXFILTER_COUNT_; f++) {
        t.filter = (enum texture_filter)f;
        vec3 c = texture_eval(&t, &m, &tc);
        cr_expect(fabsf(c.x - expect[f]) < 2e-3f, "%s: %g, expected %g", texture_filter_name(t.filter), c.x, expect[f]);
    }
    mip_fini(&m);
    texture_fini(&t);
}

/* Coordinates far beyond any texture (OBJ uvs of 1e30), infinite or NaN: every filter and
 * wrap mode gives a finite, repeatable colour, clamp gives the edge texel beyond either
 * edge, and the checker its square's parity, without converting out of int64's range. */
Test(texture, huge_and_non_finite_coordinates_give_finite_repeatable_colours)
{
    struct texture t;
    texture_init(&t, TEXTURE_IMAGE, "row");
    f32_image(&t.image, 4, 1, 1);
    for (uint32_t x = 0; x < 4; x++)
        texels(&t.image)[x] = (float)(x + 1);
    const float us[] = {1e30f, -1e30f, 1e15f, -1e15f, 0x1p63f, -0x1p63f, NAN, INFINITY, -INFINITY};
    const enum texture_wrap wraps[] = {TEXWRAP_CLAMP, TEXWRAP_REPEAT};
    for (int wi = 0; wi < 2; wi++) {
        struct mip m;
        mip_init(&m, &t.image, wraps[wi]);
        for (int f = 0; f < TEXFILTER_COUNT_; f++)
            for (size_t i = 0; i < sizeof us / sizeof us[0]; i++)
                for (int d = 0; d < 2; d++) {
                    t.filter = (enum texture_filter)f;
                    float du = d ? 0.1f : 1e-4f;
                    struct tex_coord tc = {us[i], 0.5f, du, 0.0f, 0.0f, du, 0.0f, 0.0f};
                    vec3 a = texture_eval(&t, &m, &tc), b = texture_eval(&t, &m, &tc);
                    cr_expect(isfinite(a.x) && a.x == b.x, "wrap %d %s u %g: %g then %g", wi,
                              texture_filter_name(t.filter), us[i], a.x, b.x);
                    if (wraps[wi] == TEXWRAP_CLAMP && isfinite(us[i]) && fabsf(us[i]) >= 1e15f) {
                        float want = us[i] > 0 ? 4.0f : 1.0f;
                        cr_expect(fabsf(a.x - want) < 1e-5f, "clamp %s u %g: %g, expected the edge %g",
                                  texture_filter_name(t.filter), us[i], a.x, want);
                    }
                }
        mip_fini(&m);
    }
    texture_fini(&t);
    /* Floats from 2^24 up are even integers: the square is odd when the other axis is. */
    const vec3 c0 = v3(0, 0, 0), c1 = v3(1, 1, 1);
    for (size_t i = 0; i < 6; i++) {
        cr_expect(texture_checker_box(us[i], 0.5f, 0.0f, 0.0f, c0, c1).x == 0.0f, "u %g", us[i]);
        cr_expect(texture_checker_box(us[i], 1.5f, 0.0f, 0.0f, c0, c1).x == 1.0f, "u %g", us[i]);
        cr_expect(texture_checker_box(0.5f, us[i], 0.1f, 0.0f, c0, c1).x == 0.0f, "v %g", us[i]);
    }
    for (size_t i = 6; i < 9; i++)
        cr_expect(isfinite(texture_checker_box(us[i], 0.5f, 0.1f, 0.1f, c0, c1).x), "u %g", us[i]);
}

/* EWA's weights for a footprint of w texels have the variance of a box w wide (w^2 / 12),
 * as mip_ewa_box_scale promises: a 1-pixel footprint filters like the pixel. */
Test(mip, ewa_weights_have_the_variance_of_a_box_over_the_footprint)
{
    struct tex_image im;
    f32_image(&im, 512, 512, 1);
    struct mip m;
    mip_init(&m, &im, TEXWRAP_REPEAT);
    enum { CAP = 16384 };
    static int64_t xs[CAP], ys[CAP];
    static float ws[CAP];
    struct mip_ewa_record rec = {xs, ys, ws, CAP, 0};
    const float w = 60.0f, k = mip_ewa_box_scale();
    cr_expect(k > 0.7f && k < 0.85f, "scale %g", k);
    float s = 200.5f / 512.0f, t = 300.5f / 512.0f;
    mip_ewa_level(&m, 0, s, t, k * w / 512.0f, 0.0f, 0.0f, k * w / 512.0f, &rec);
    cr_assert(rec.count > 100 && rec.count <= CAP, "count %zu", rec.count);
    double vx = 0, vy = 0;
    for (size_t i = 0; i < rec.count; i++) {
        vx += ws[i] * ((double)xs[i] + 0.5 - 200.5) * ((double)xs[i] + 0.5 - 200.5);
        vy += ws[i] * ((double)ys[i] + 0.5 - 300.5) * ((double)ys[i] + 0.5 - 300.5);
    }
    double box = (double)w * w / 12.0;
    cr_expect(fabs(vx / box - 1.0) < 0.03 && fabs(vy / box - 1.0) < 0.03, "variance %g %g vs box %g", vx, vy, box);
    mip_fini(&m);
    tex_image_fini(&im);
}

Test(raydiff, glass_slab_matches_analytic_refraction)
{
    const float a = 2.0f, h = 0.5f, n = 1.5f, zt = 6.0f;
    /* Normal incidence: a point source's image moves h (1 - 1/n) closer; the footprint
     * at zt is k (zt - h (1 - 1/n)) (paraxial, exact to first order on the axis). */
    for (int oblique = 0; oblique < 2; oblique++) {
        vec3 o = v3(0, 0, 0);
        vec3 d = oblique ? v3_normalize(v3(0.5f, 0.2f, 1.0f)) : v3(0, 0, 1);
        vec3 ex = v3_normalize(v3_cross(d, v3(0, 1, 0))), ey = v3_cross(ex, d);
        const float k = 0.01f;
        struct raydiff rd = {v3(0, 0, 0), v3(0, 0, 0), v3_scale(ex, k), v3_scale(ey, k), 0.0f, 0.0f};
        vec3 nz = v3(0, 0, -1), p1, d1x, d1y, p2, d2x, d2y, p3, d3x, d3y;
        plane_hit(o, d, nz, -a, &rd, &p1, &d1x, &d1y);
        vec3 t1, t2;
        cr_assert(material_refract(v3_neg(d), nz, -v3_dot(d, nz), n, &t1));
        raydiff_refract(&rd, d, t1, nz, v3(0, 0, 0), v3(0, 0, 0), d1x, d1y, 1.0f / n);
        plane_hit(p1, t1, nz, -(a + h), &rd, &p2, &d2x, &d2y);
        cr_assert(material_refract(v3_neg(t1), nz, -v3_dot(t1, nz), 1.0f / n, &t2));
        raydiff_refract(&rd, t1, t2, nz, v3(0, 0, 0), v3(0, 0, 0), d2x, d2y, n);
        plane_hit(p2, t2, nz, -zt, &rd, &p3, &d3x, &d3y);
        /* A parallel slab leaves every direction unchanged: so are their derivatives. */
        expect_vec_near(t2, d, 1e-5f, "exit direction");
        expect_vec_near(rd.dddx, v3_scale(ex, k), 1e-3f, "exit dd/dx");
        /* Against exact refraction of neighbouring rays (central differences). */
        float e = 1e-2f;
        vec3 dpx = v3_normalize(v3_add(d, v3_scale(rd.dddx, 0)));
        (void)dpx;
        vec3 fxp = slab_trace(o, v3_normalize(v3_add(d, v3_scale(ex, k * e))), a, h, n, zt);
        vec3 fxm = slab_trace(o, v3_normalize(v3_sub(d, v3_scale(ex, k * e))), a, h, n, zt);
        vec3 fyp = slab_trace(o, v3_normalize(v3_add(d, v3_scale(ey, k * e))), a, h, n, zt);
        vec3 fym = slab_trace(o, v3_normalize(v3_sub(d, v3_scale(ey, k * e))), a, h, n, zt);
        expect_vec_near(d3x, v3_scale(v3_sub(fxp, fxm), 0.5f / e), 2e-2f, "slab dp/dx");
        expect_vec_near(d3y, v3_scale(v3_sub(fyp, fym), 0.5f / e), 2e-2f, "slab dp/dy");
        if (!oblique)
            cr_expect(fabsf(v3_dot(d3x, ex) - k * (zt - h * (1 - 1 / n))) < 1e-5f, "paraxial %g vs %g",
                      v3_dot(d3x, ex), k * (zt - h * (1 - 1 / n)));
    }
}

Test(raydiff, sphere_and_triangle_texture_derivatives)
{
    vec3 c = v3(0.5f, -1.0f, 2.0f);
    float r = 1.5f;
    vec3 o = v3(0.2f, 0.3f, -3.0f);
    vec3 target = v3_add(c, v3_scale(v3_normalize(v3(0.3f, 0.4f, -1.0f)), r));
    vec3 d = v3_normalize(v3_sub(target, o));
    struct raydiff rd = {v3(0, 0, 0), v3(0, 0, 0), v3(1e-3f, 0, 0), v3(0, 1e-3f, 2e-4f), 0.0f, 0.0f};
    struct raydiff_hit hh;
    float t = v3_length(v3_sub(target, o));
    raydiff_sphere(c, r, target, &rd, d, t, &hh);
    /* Central differences: move along dp/dx on the sphere (projected), compare (u, v). */
    float e = 1e-3f * r / v3_length(hh.dpdx);
    vec3 pp = v3_add(c, v3_scale(v3_normalize(v3_sub(v3_add(target, v3_scale(hh.dpdx, e)), c)), r));
    vec3 pm = v3_add(c, v3_scale(v3_normalize(v3_sub(v3_sub(target, v3_scale(hh.dpdx, e)), c)), r));
    float up, vp, um, vm;
    raydiff_sphere_uv(c, pp, &up, &vp);
    raydiff_sphere_uv(c, pm, &um, &vm);
    float fdu = (up - um) / (2 * e), fdv = (vp - vm) / (2 * e);
    cr_expect(fabsf(fdu - hh.tc.dudx) < 0.02f * fabsf(hh.tc.dudx) + 1e-7f, "du/dx %g vs %g", fdu, hh.tc.dudx);
    cr_expect(fabsf(fdv - hh.tc.dvdx) < 0.02f * fabsf(hh.tc.dvdx) + 1e-7f, "dv/dx %g vs %g", fdv, hh.tc.dvdx);
    cr_expect(fabsf(hh.tc.dudx) > 1e-5f && fabsf(hh.tc.dvdx) > 1e-5f);
    /* Triangle with a uv map scaled by 3 along u: du/dx = 3 dp.x / edge. */
    vec3 p[3] = {v3(0, 0, 5), v3(2, 0, 5), v3(0, 2, 5)};
    const float uv[3][2] = {{0, 0}, {3, 0}, {0, 1}};
    struct raydiff cam = {v3(0, 0, 0), v3(0, 0, 0), v3(0.01f, 0, 0), v3(0, 0.01f, 0), 0.0f, 0.0f};
    raydiff_triangle(p, uv, NULL, 0.25f, 0.25f, v3(0, 0, -1), &cam, v3(0, 0, 1), 5.0f, &hh);
    cr_expect_float_eq(hh.dpdx.x, 0.05f, 1e-6);
    cr_expect_float_eq(hh.tc.dudx, 0.05f * 3 / 2, 1e-6);
    cr_expect_float_eq(hh.tc.dvdy, 0.05f * 1 / 2, 1e-6);
    cr_expect_float_eq(hh.tc.u, 0.75f, 1e-6);
    /* Degenerate uvs (all equal, or on a line): finite, zero where undefined. */
    const float same[3][2] = {{0.5f, 0.5f}, {0.5f, 0.5f}, {0.5f, 0.5f}};
    raydiff_triangle(p, same, NULL, 0.25f, 0.25f, v3(0, 0, -1), &cam, v3(0, 0, 1), 5.0f, &hh);
    cr_expect(hh.tc.dudx == 0 && hh.tc.dvdx == 0 && hh.tc.dudy == 0 && hh.tc.dvdy == 0);
    /* A zero-area triangle: finite. */
    vec3 flat[3] = {v3(0, 0, 5), v3(1, 0, 5), v3(2, 0, 5)};
    raydiff_triangle(flat, uv, NULL, 0.25f, 0.25f, v3(0, 0, 0), &cam, v3(0, 0, 1), 5.0f, &hh);
    cr_expect(v3_is_finite(hh.dpdx) && isfinite(hh.tc.dudx) && isfinite(hh.tc.dvdy));
    /* Shading normals: the derivative of the interpolated normal. */
    vec3 nrm[3] = {v3(0, 0, -1), v3_normalize(v3(0.5f, 0, -1)), v3(0, 0, -1)};
    raydiff_triangle(p, uv, nrm, 0.25f, 0.25f, v3(0, 0, -1), &cam, v3(0, 0, 1), 5.0f, &hh);
    cr_expect(hh.dndx.x > 0.0f && fabsf(hh.dndy.x) < 1e-6f);
}

Test(raydiff, grazing_angles_stay_finite_and_bounded)
{
    struct raydiff rd = {v3(0, 0, 0), v3(0, 0, 0), v3(1e-3f, 0, 0), v3(0, 1e-3f, 0), 0.0f, 0.0f};
    vec3 dpx, dpy;
    for (int k = 0; k < 5; k++) {
        float cz = k == 4 ? 0.0f : powf(10.0f, -2.0f * (float)k - 2.0f);
        vec3 d = v3_normalize(v3(0, sqrtf(1 - cz * cz), -cz));
        raydiff_transfer(&rd, d, 100.0f, v3(0, 0, 1), &dpx, &dpy);
        cr_expect(v3_is_finite(dpx) && v3_is_finite(dpy));
        cr_expect(v3_max_abs(dpy) <= RAYDIFF_MAX_SPACE);
    }
    struct raydiff big = {v3(1e30f, 0, 0), v3(0, 0, 0), v3(INFINITY, 0, 0), v3(NAN, 0, 0), 0.0f, 0.0f};
    raydiff_transfer(&big, v3(0, 0, 1), 1.0f, v3(0, 0, -1), &dpx, &dpy);
    cr_expect(v3_is_finite(dpx) && v3_is_finite(dpy));
    /* Refraction at the critical angle: finite. */
    vec3 n = v3(0, 0, -1), din = v3_normalize(v3(0.6667f, 0, 0.745f)), t;
    if (material_refract(v3_neg(din), n, -v3_dot(din, n), 1.0f / 1.5f, &t)) {
        raydiff_refract(&rd, din, t, n, v3(0.1f, 0, 0), v3(0, 0.1f, 0), dpx, dpy, 1.5f);
        cr_expect(v3_is_finite(rd.dddx) && v3_is_finite(rd.dddy));
    }
    /* Diffuse: the spread never shrinks. */
    struct raydiff wide = {v3(0, 0, 0), v3(0, 0, 0), v3(0.5f, 0, 0), v3(0, 0.5f, 0), 0.0f, 0.0f};
    raydiff_diffuse(&wide, v3(0, 0, 1), v3(1, 0, 0), v3(0, 1, 0));
    cr_expect(v3_length(wide.dddx) >= 0.5f - 1e-6f && v3_length(wide.dddy) >= 0.5f - 1e-6f);
    raydiff_diffuse(&rd, v3(0, 0, 1), v3(1, 0, 0), v3(0, 1, 0));
    cr_expect(v3_length(rd.dddx) >= RAYDIFF_DIFFUSE_SPREAD - 1e-6f);
}

/* ---- image decoding ---- */

struct membuf {
    uint8_t *p;
    size_t n, cap;
};

static void mem_write(void *ctx, void *data, int size)
{
    struct membuf *b = ctx;
    mem_grow((void **)&b->p, &b->cap, b->n + (size_t)size, 1);
    memcpy(b->p + b->n, data, (size_t)size);
    b->n += (size_t)size;
}

static struct membuf encode(const char *fmt, int w, int h, int nc, const void *px)
{
    struct membuf b = {NULL, 0, 0};
    int ok = 0;
    if (!strcmp(fmt, "png"))
        ok = stbi_write_png_to_func(mem_write, &b, w, h, nc, px, w * nc);
    else if (!strcmp(fmt, "jpg"))
        ok = stbi_write_jpg_to_func(mem_write, &b, w, h, nc, px, 100);
    else if (!strcmp(fmt, "hdr"))
        ok = stbi_write_hdr_to_func(mem_write, &b, w, h, nc, px);
    cr_assert(ok && b.n > 0, "encoding %s", fmt);
    return b;
}

/* An EXR in memory: written through imgio to a temporary file, read back. */
static struct membuf encode_exr(uint32_t w, uint32_t h, const float *rgb)
{
    struct image_desc d;
    memset(&d, 0, sizeof d);
    d.width = w, d.height = h, d.tile_size = 16, d.num_channels = 3, d.compression = IMGIO_ZIP;
    strcpy(d.channel_names[0], "R");
    strcpy(d.channel_names[1], "G");
    strcpy(d.channel_names[2], "B");
    struct image_attrs a;
    memset(&a, 0, sizeof a);
    char err[512], path[] = "/tmp/brume-test-tex-XXXXXX";
    int fd = mkstemp(path);
    cr_assert(fd >= 0);
    close(fd);
    struct imgio_encoder *e = imgio_encoder_new(&d, err, sizeof err);
    struct imgio_writer *wr = imgio_writer_open(path, &d, &a, err, sizeof err);
    cr_assert(e && wr, "%s", err);
    float *tile = mem_alloc(16 * 16 * 3 * sizeof *tile);
    for (uint32_t ty = 0; ty < imgio_tiles_y(&d); ty++)
        for (uint32_t tx = 0; tx < imgio_tiles_x(&d); tx++) {
            uint32_t x0, y0, tw, th;
            imgio_tile_rect(&d, tx, ty, &x0, &y0, &tw, &th);
            for (uint32_t y = 0; y < th; y++)
                memcpy(&tile[y * tw * 3], &rgb[((y0 + y) * w + x0) * 3], tw * 3 * sizeof(float));
            uint8_t *chunk;
            size_t n;
            cr_assert_eq(imgio_encode_tile(e, tx, ty, tile, &chunk, &n, err, sizeof err), 0, "%s", err);
            cr_assert_eq(imgio_writer_put_tile(wr, tx, ty, chunk, n, err, sizeof err), 0, "%s", err);
            free(chunk);
        }
    free(tile);
    imgio_encoder_free(&e);
    cr_assert_eq(imgio_writer_close(&wr, err, sizeof err), 0, "%s", err);
    FILE *f = fopen(path, "rb");
    cr_assert(f);
    struct membuf b = {NULL, 0, 0};
    uint8_t buf[4096];
    size_t r;
    while ((r = fread(buf, 1, sizeof buf, f)) > 0)
        mem_write(&b, buf, (int)r);
    fclose(f);
    unlink(path);
    return b;
}

Test(image_load, png_jpeg_hdr_exr_decode)
{
    log_set_level(LOG_ERROR);
    uint8_t rgb[6 * 4 * 3], gray[6 * 4];
    float frgb[6 * 4 * 3];
    for (int i = 0; i < 6 * 4; i++) {
        rgb[3 * i] = (uint8_t)(i * 10), rgb[3 * i + 1] = 128, rgb[3 * i + 2] = 255;
        gray[i] = (uint8_t)(i * 5);
        frgb[3 * i] = 0.25f * (float)i, frgb[3 * i + 1] = 3.5f, frgb[3 * i + 2] = 0.125f;
    }
    struct tex_image im;
    char err[512];
    struct membuf b = encode("png", 6, 4, 3, rgb);
    cr_assert_eq(image_load_memory("a.png", b.p, b.n, 1, &im, err, sizeof err), 0, "%s", err);
    cr_expect(im.width == 6 && im.height == 4 && im.channels == 3 && im.format == TEXEL_U8_SRGB);
    cr_expect_eq(((uint8_t *)im.data)[3 * 7], 70); /* bytes kept, row-major from the top */
    tex_image_fini(&im);
    free(b.p);
    b = encode("png", 6, 4, 1, gray);
    cr_assert_eq(image_load_memory("g.png", b.p, b.n, 0, &im, err, sizeof err), 0, "%s", err);
    cr_expect(im.channels == 1 && im.format == TEXEL_U8_LINEAR && ((uint8_t *)im.data)[5] == 25);
    tex_image_fini(&im);
    free(b.p);
    b = encode("jpg", 6, 4, 3, rgb);
    cr_assert_eq(image_load_memory("a.jpg", b.p, b.n, 1, &im, err, sizeof err), 0, "%s", err);
    cr_expect(im.width == 6 && im.height == 4 && im.channels == 3);
    cr_expect(abs(((uint8_t *)im.data)[1] - 128) < 8, "jpeg green %d", ((uint8_t *)im.data)[1]);
    tex_image_fini(&im);
    free(b.p);
    b = encode("hdr", 6, 4, 3, frgb);
    cr_assert_eq(image_load_memory("a.hdr", b.p, b.n, 1, &im, err, sizeof err), 0, "%s", err);
    cr_expect(im.format == TEXEL_F32 && im.channels == 3);
    cr_expect(fabsf(((float *)im.data)[3 * 5] - 1.25f) < 0.02f && fabsf(((float *)im.data)[1] - 3.5f) < 0.05f);
    tex_image_fini(&im);
    free(b.p);
    b = encode_exr(6, 4, frgb);
    cr_assert_eq(image_load_memory("a.exr", b.p, b.n, 1, &im, err, sizeof err), 0, "%s", err);
    cr_expect(im.format == TEXEL_F32 && im.width == 6 && im.height == 4);
    cr_expect_float_eq(((float *)im.data)[3 * 5], 1.25f, 1e-6);
    tex_image_fini(&im);
    free(b.p);
}

Test(image_load, garbage_truncated_and_oversized_files_fail_cleanly)
{
    log_set_level(LOG_ERROR);
    struct tex_image im;
    char err[512];
    cr_expect_eq(image_load_memory("x.gif", (const uint8_t *)"GIF89a....", 10, 1, &im, err, sizeof err), -1);
    cr_expect(strstr(err, "x.gif: not a PNG, JPEG") != NULL, "%s", err);
    cr_expect_eq(image_load_memory("e.png", (const uint8_t *)"", 0, 1, &im, err, sizeof err), -1);
    uint8_t px[16 * 16 * 3];
    for (size_t i = 0; i < sizeof px; i++)
        px[i] = (uint8_t)(i * 37);
    float fpx[16 * 16 * 3];
    for (size_t i = 0; i < 16 * 16 * 3; i++)
        fpx[i] = (float)i / 100.0f;
    struct membuf files[4] = {encode("png", 16, 16, 3, px), encode("jpg", 16, 16, 3, px),
                              encode("hdr", 16, 16, 3, fpx), encode_exr(16, 16, fpx)};
    static const char *const names[4] = {"t.png", "t.jpg", "t.hdr", "t.exr"};
    uint64_t st = 99;
    for (int f = 0; f < 4; f++) {
        /* Every truncation, then random byte corruptions: decode or fail, never crash. */
        for (size_t n = 0; n < files[f].n; n += 1 + n / 16) {
            if (image_load_memory(names[f], files[f].p, n, 1, &im, err, sizeof err) == 0) {
                cr_expect(im.width == 16 && im.height == 16);
                tex_image_fini(&im);
            } else {
                cr_expect(strncmp(err, names[f], 5) == 0, "%s", err);
            }
        }
        uint8_t *copy = mem_alloc(files[f].n);
        for (int k = 0; k < 300; k++) {
            memcpy(copy, files[f].p, files[f].n);
            for (int j = 0; j < 4; j++) {
                st = st * 6364136223846793005ull + 1442695040888963407ull;
                size_t at = (size_t)(st >> 33) % files[f].n;
                copy[at] ^= (uint8_t)(1u << ((st >> 20) & 7));
            }
            if (image_load_memory(names[f], copy, files[f].n, 1, &im, err, sizeof err) == 0) {
                cr_expect(tex_image_bytes(im.width, im.height, im.channels, im.format) > 0);
                tex_image_fini(&im);
            }
        }
        free(copy);
    }
    /* A PNG header claiming 20000 x 20000: refused before decoding. */
    uint8_t *big = mem_alloc(files[0].n);
    memcpy(big, files[0].p, files[0].n);
    big[16] = 0, big[17] = 0, big[18] = 0x4e, big[19] = 0x20; /* IHDR width */
    big[20] = 0, big[21] = 0, big[22] = 0x4e, big[23] = 0x20; /* IHDR height */
    cr_expect_eq(image_load_memory("big.png", big, files[0].n, 1, &im, err, sizeof err), -1);
    cr_expect(strstr(err, "big.png") != NULL, "%s", err);
    free(big);
    /* An EXR header claiming 2^20 x 1024 (12 GiB of float RGB): refused by its size from the
     * header, before its pixels are allocated, not from what a decode then finds. */
    big = mem_alloc(files[3].n);
    memcpy(big, files[3].p, files[3].n);
    static const char dw_attr[] = "dataWindow\0box2i\0";
    uint8_t *at = memmem(big, files[3].n, dw_attr, sizeof dw_attr - 1);
    cr_assert(at != NULL);
    int32_t box[4] = {0, 0, (1 << 20) - 1, 1023}; /* xmin ymin xmax ymax, little-endian */
    memcpy(at + sizeof dw_attr - 1 + 4, box, sizeof box);
    cr_expect_eq(image_load_memory("big.exr", big, files[3].n, 1, &im, err, sizeof err), -1);
    cr_expect(strstr(err, "big.exr: image size 1048576x1024 not supported") != NULL, "%s", err);
    free(big);
    for (int f = 0; f < 4; f++)
        free(files[f].p);
}

/* ---- renders ---- */

static void render_settings(struct scene *s, uint32_t w, uint32_t h, uint32_t spp)
{
    s->settings.width = w;
    s->settings.height = h;
    s->settings.spp = spp;
    s->settings.max_depth = 1;
    s->settings.seed = 7;
    s->settings.tile_size = 16;
    s->settings.sampler = SAMPLER_STRATIFIED;
}

/* A floor y = 0 from -R to R with uv 0..1, seen from a low camera looking at the horizon;
 * its material's albedo is texture tex (0-based). A point light far above. */
static void horizon_scene(struct scene *s, float R, uint32_t tex)
{
    struct material m;
    memset(&m, 0, sizeof m);
    m.type = MATERIAL_DIFFUSE;
    m.albedo = v3(1, 1, 1);
    m.albedo_tex = tex + 1;
    scene_add_material(s, &m);
    struct mesh me;
    memset(&me, 0, sizeof me);
    me.num_vertices = 4;
    me.num_triangles = 2;
    me.positions = mem_alloc(12 * sizeof(float));
    me.uvs = mem_alloc(8 * sizeof(float));
    const float pos[12] = {-R, 0, -R, -R, 0, R, R, 0, R, R, 0, -R}, uv[8] = {0, 0, 0, 1, 1, 1, 1, 0};
    memcpy(me.positions, pos, sizeof pos);
    memcpy(me.uvs, uv, sizeof uv);
    me.indices = mem_alloc(6 * sizeof(uint32_t));
    const uint32_t idx[6] = {0, 1, 2, 0, 2, 3};
    memcpy(me.indices, idx, sizeof idx);
    me.material_ids = mem_calloc(2, sizeof(uint32_t));
    scene_add_mesh(s, &me);
    struct light l = {.type = LIGHT_POINT, .position = v3(0, 1e4f, 0), .intensity = v3(1e8f, 1e8f, 1e8f)};
    scene_add_light(s, &l);
    s->camera.position = v3(0, 1, -R * 0.99f);
    s->camera.look_at = v3(0, 0.3f, 0);
    s->camera.up = v3(0, 1, 0);
    s->camera.fov_y_deg = 40;
}

static double rmse(const float *a, const float *b, uint32_t w, uint32_t y0, uint32_t y1)
{
    double e = 0;
    for (uint32_t y = y0; y < y1; y++)
        for (uint32_t x = 0; x < w; x++)
            for (int c = 0; c < 3; c++) {
                double d = a[(y * w + x) * TILE_NUM_CHANNELS + c] - b[(y * w + x) * TILE_NUM_CHANNELS + c];
                e += d * d;
            }
    return sqrt(e / ((double)w * (y1 - y0) * 3));
}

/* The image-texture checker: 8 x 8 squares of 32 texels, colours matching a procedural
 * checker of 8 squares per unit (the image's v flip included: see the nearest check). */
static void checker_image(struct texture *t, vec3 c0, vec3 c1)
{
    texture_init(t, TEXTURE_IMAGE, "img");
    cr_assert_eq(tex_image_alloc(&t->image, 256, 256, 3, TEXEL_F32), 0);
    float *p = t->image.data;
    for (uint32_t y = 0; y < 256; y++)
        for (uint32_t x = 0; x < 256; x++) {
            /* Row y holds t = (y + 0.5) / 256, i.e. v = 1 - t: square parity of (x, 255 - y). */
            int odd = ((x / 32) + ((255 - y) / 32)) & 1;
            vec3 c = odd ? c1 : c0;
            p[(y * 256 + x) * 3] = c.x, p[(y * 256 + x) * 3 + 1] = c.y, p[(y * 256 + x) * 3 + 2] = c.z;
        }
}

Test(texture_render, checkerboard_to_the_horizon_ewa_beats_unfiltered, .timeout = 120)
{
    log_set_level(LOG_ERROR);
    const float R = 400.0f, reps = 100.0f;
    const vec3 c0 = v3(0.9f, 0.9f, 0.9f), c1 = v3(0.05f, 0.05f, 0.05f);
    const uint32_t W = 96, H = 48;
    /* Reference: the procedural checker point-sampled at 1024 spp (the pixel's box
     * integral to within noise). */
    struct scene ref;
    memset(&ref, 0, sizeof ref);
    struct texture proc;
    texture_init(&proc, TEXTURE_CHECKER, "proc");
    proc.filter = TEXFILTER_NEAREST;
    proc.scale[0] = proc.scale[1] = 8.0f * reps;
    proc.color0 = c0, proc.color1 = c1;
    scene_add_texture(&ref, &proc);
    horizon_scene(&ref, R, 0);
    render_settings(&ref, W, H, 1024);
    struct tile_stats st;
    float *want = test_render(&ref, 1, &st);
    cr_expect_eq(st.nan_samples, 0);
    /* The same squares from an image, 1 spp, per filter. */
    double err[TEXFILTER_COUNT_], far[TEXFILTER_COUNT_];
    float *img[TEXFILTER_COUNT_];
    for (int f = 0; f < TEXFILTER_COUNT_; f++) {
        struct scene s;
        memset(&s, 0, sizeof s);
        struct texture t;
        checker_image(&t, c0, c1);
        t.filter = (enum texture_filter)f;
        t.max_aniso = 16;
        t.scale[0] = t.scale[1] = reps;
        scene_add_texture(&s, &t);
        horizon_scene(&s, R, 0);
        render_settings(&s, W, H, 1);
        img[f] = test_render(&s, 1, &st);
        cr_expect_eq(st.nan_samples, 0);
        err[f] = rmse(img[f], want, W, 0, H);
        /* Rows showing the far floor: just below the horizon (which is row H / 2 - 1). */
        far[f] = rmse(img[f], want, W, H / 2, H / 2 + H / 6);
        scene_fini(&s);
    }
    /* The image and procedural checkers are the same function: nearest at 1 spp equals
     * the procedural point lookup at 1 spp. */
    struct scene one;
    memset(&one, 0, sizeof one);
    scene_add_texture(&one, &proc);
    horizon_scene(&one, R, 0);
    render_settings(&one, W, H, 1);
    float *proc1 = test_render(&one, 1, &st);
    cr_expect(rmse(proc1, img[TEXFILTER_NEAREST], W, 0, H) < 0.02, "image vs procedural %g",
              rmse(proc1, img[TEXFILTER_NEAREST], W, 0, H));
    cr_log_info("checker horizon RMSE at 1 spp: nearest %.4f bilinear %.4f trilinear %.4f ewa %.4f (far rows: "
                "%.4f %.4f %.4f %.4f)",
                err[0], err[1], err[2], err[3], far[0], far[1], far[2], far[3]);
    cr_expect(err[TEXFILTER_EWA] < 0.5 * err[TEXFILTER_NEAREST], "ewa %g vs nearest %g", err[TEXFILTER_EWA],
              err[TEXFILTER_NEAREST]);
    cr_expect(far[TEXFILTER_EWA] < 0.25 * far[TEXFILTER_NEAREST], "far rows: ewa %g vs nearest %g",
              far[TEXFILTER_EWA], far[TEXFILTER_NEAREST]);
    cr_expect(err[TEXFILTER_EWA] < err[TEXFILTER_TRILINEAR] * 1.05, "ewa %g vs trilinear %g", err[TEXFILTER_EWA],
              err[TEXFILTER_TRILINEAR]);
    for (int f = 0; f < TEXFILTER_COUNT_; f++)
        free(img[f]);
    free(proc1);
    free(want);
    one.num_textures = 0; /* proc is shared with ref */
    scene_fini(&one);
    scene_fini(&ref);
}

static int all_finite(const float *px, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (!isfinite(px[i]))
            return 0;
    return 1;
}

Test(texture_render, huge_texture_thin_lens_degenerate_uvs_no_nan, .timeout = 120)
{
    log_set_level(LOG_ERROR);
    /* 16384 x 16384 gray bytes (256 MiB + 85 MiB of levels), a wide-open thin lens
     * focused far away, at grazing angles to the horizon. */
    struct scene s;
    memset(&s, 0, sizeof s);
    struct texture t;
    texture_init(&t, TEXTURE_IMAGE, "huge");
    cr_assert_eq(tex_image_alloc(&t.image, 16384, 16384, 1, TEXEL_U8_SRGB), 0);
    uint8_t *p = t.image.data;
    for (size_t y = 0; y < 16384; y++)
        for (size_t x = 0; x < 16384; x++)
            p[y * 16384 + x] = (uint8_t)((((x >> 3) ^ (y >> 3)) & 1) * 255);
    t.max_aniso = 64;
    t.scale[0] = 3, t.scale[1] = 3;
    scene_add_texture(&s, &t);
    horizon_scene(&s, 1000.0f, 0);
    render_settings(&s, 32, 24, 2);
    s.camera.aperture_radius = 5.0f;
    s.camera.focus_distance = 0.05f;
    struct tile_stats st;
    float *px = test_render(&s, 1, &st);
    cr_expect_eq(st.nan_samples, 0);
    cr_expect(all_finite(px, (size_t)32 * 24 * TILE_NUM_CHANNELS));
    free(px);
    /* Every filter at extreme footprints on the huge pyramid. */
    struct mip m;
    mip_init(&m, &s.textures[0].image, TEXWRAP_CLAMP);
    cr_expect_eq(m.num_levels, 15);
    for (int f = 0; f < TEXFILTER_COUNT_; f++) {
        vec3 a = mip_lookup(&m, (enum texture_filter)f, 64, 0.5f, 0.5f, 1e-9f, 0, 0, 1e6f);
        vec3 b = mip_lookup(&m, (enum texture_filter)f, 64, 1.5f, -0.5f, 1.0f, 1.0f, 1.0f, 1.0f);
        vec3 c = mip_lookup(&m, (enum texture_filter)f, 64, 0.25f, 0.75f, 1e-3f, 1e-3f, -1e-3f, 1e-3f + 1e-9f);
        cr_expect(v3_is_finite(a) && v3_is_finite(b) && v3_is_finite(c), "filter %d", f);
        cr_expect(a.x >= 0 && a.x <= 1 && b.x >= 0 && b.x <= 1 && c.x >= 0 && c.x <= 1);
    }
    mip_fini(&m);
    /* Degenerate uvs: every vertex at one uv, then all on one line. */
    for (int k = 0; k < 2; k++) {
        float *uv = s.meshes[0].uvs;
        for (int i = 0; i < 4; i++) {
            uv[2 * i] = k ? 0.1f * (float)i : 0.5f;
            uv[2 * i + 1] = k ? 0.2f * (float)i : 0.5f;
        }
        s.camera.aperture_radius = 0.0f;
        px = test_render(&s, 1, &st);
        cr_expect_eq(st.nan_samples, 0);
        cr_expect(all_finite(px, (size_t)32 * 24 * TILE_NUM_CHANNELS));
        free(px);
    }
    scene_fini(&s);
}

/* ---- scene files: the "textures" section, albedo_texture and MTL map_Kd ---- */

#include "scene/scene_json.h"

#define SCENE_HEAD                                                                      \
    "{\"version\": 1,\n"                                                                \
    "\"camera\": {\"position\": [0, 0, -5], \"look_at\": [0, 0, 0], \"fov_y\": 40},\n" \
    "\"render\": {\"width\": 16, \"height\": 16},\n"

/* The scene tests' folder: a 4 x 2 PNG under two names and OBJ/MTL files that use it. */
static const struct mem_file *scene_files(void)
{
    static uint8_t png[4 * 2 * 3];
    static struct membuf enc;
    static struct mem_file files[] = {
        {"tex/a.png", NULL, 0},
        {"m/b.png", NULL, 0},
        {"quad.obj", "mtllib m/q.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl p\nf 1/1 2/2 3/3\n", 0},
        {"m/q.mtl", "newmtl p\nmap_Kd -s 2 3 -o 0.5 0 -clamp on b.png\nnewmtl q\nmap_Kd -bm 1 b.png\n"
                    "newmtl r\nKd 0.5 0.25 1\nmap_Kd b.png\nmap_Bump -bm 0.2 b.png\nnorm -s 2 2 b.png\n", 0},
        {"nofile.obj", "mtllib m/n.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl p\nf 1 2 3\n", 0},
        {"m/n.mtl", "newmtl p\nmap_Kd -s 2 2\n", 0},
        {"gone.obj", "mtllib m/g.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl p\nf 1 2 3\n", 0},
        {"m/g.mtl", "newmtl p\nmap_Kd   gone.png\n", 0},
        {NULL, NULL, 0}};
    if (!enc.p) {
        for (size_t i = 0; i < sizeof png; i++)
            png[i] = (uint8_t)(i * 20);
        enc = encode("png", 4, 2, 3, png);
        files[0].data = files[1].data = enc.p;
        files[0].size = files[1].size = enc.n;
    }
    return files;
}

Test(texture_scene, textures_section_and_albedo_texture)
{
    log_set_level(LOG_ERROR);
    struct scene s;
    char err[512];
    const char *text = SCENE_HEAD
        "\"textures\": {\"c\": {\"type\": \"checker\", \"scale\": [4, 8], \"color0\": [1, 0, 0], \"filter\": \"trilinear\"},\n"
        "  \"img\": {\"type\": \"image\", \"file\": \"tex/a.png\", \"max_anisotropy\": 4, \"offset\": [0.5, 0.25],"
        " \"wrap\": \"clamp\", \"srgb\": false}},\n"
        "\"materials\": {\"m\": {\"type\": \"diffuse\", \"albedo_texture\": \"img\"},\n"
        "  \"n\": {\"type\": \"diffuse\", \"albedo_texture\": \"c\", \"albedo\": [0.5, 0.5, 0.5]},\n"
        "  \"g\": {\"type\": \"dielectric\", \"bump_texture\": \"img\", \"bump_scale\": -0.05},\n"
        "  \"k\": {\"type\": \"mirror\", \"normal_texture\": \"img\"}},\n"
        "\"objects\": [{\"type\": \"obj\", \"file\": \"quad.obj\"}]\n}";
    cr_assert_eq(test_scene_load(text, scene_files(), &s, err), 0, "%s", err);
    cr_assert_eq(s.num_textures, 6); /* c, img, map_Kd of p and r (q's is skipped), r's bump and norm */
    cr_expect_eq(s.textures[0].type, TEXTURE_CHECKER);
    cr_expect_eq(s.textures[0].filter, TEXFILTER_TRILINEAR);
    cr_expect_float_eq(s.textures[0].scale[1], 8.0f, 0);
    cr_expect_float_eq(s.textures[0].color0.x, 1.0f, 0);
    cr_expect_eq(s.textures[1].filter, TEXFILTER_EWA);
    cr_expect_float_eq(s.textures[1].max_aniso, 4.0f, 0);
    cr_expect_eq(s.textures[1].wrap, TEXWRAP_CLAMP);
    cr_expect_eq(s.textures[1].image.format, TEXEL_U8_LINEAR);
    cr_expect(s.textures[1].image.width == 4 && s.textures[1].image.height == 2);
    cr_expect_eq(s.materials[0].albedo_tex, 2);
    cr_expect_float_eq(s.materials[0].albedo.y, 1.0f, 0);
    cr_expect_eq(s.materials[1].albedo_tex, 1);
    cr_expect_float_eq(s.materials[1].albedo.y, 0.5f, 0);
    cr_expect_eq(s.materials[2].bump_tex, 2);
    cr_expect_float_eq(s.materials[2].bump_scale, -0.05f, 0);
    cr_expect_eq(s.materials[3].normal_tex, 2);
    /* MTL: map_Kd with -s, -o and -clamp, relative to the MTL's folder; no Kd -> white. */
    const struct material *p = NULL, *q = NULL, *r = NULL;
    for (uint32_t i = 0; i < s.num_materials; i++) {
        if (!strcmp(s.materials[i].name, "m/q.mtl:p"))
            p = &s.materials[i];
        if (!strcmp(s.materials[i].name, "m/q.mtl:q"))
            q = &s.materials[i];
        if (!strcmp(s.materials[i].name, "m/q.mtl:r"))
            r = &s.materials[i];
    }
    cr_assert(p && q && r);
    cr_assert(p->albedo_tex > 0);
    const struct texture *t = &s.textures[p->albedo_tex - 1];
    cr_expect(t->scale[0] == 2 && t->scale[1] == 3 && t->offset[0] == 0.5f && t->wrap == TEXWRAP_CLAMP);
    cr_expect_float_eq(p->albedo.x, 1.0f, 0);
    cr_expect_eq(q->albedo_tex, 0); /* an unsupported option: the map is skipped with a warning */
    cr_expect(r->albedo_tex > 0 && r->albedo.y == 0.25f); /* Kd multiplies the map */
    cr_assert(r->bump_tex > 0);
    cr_expect_float_eq(r->bump_scale, 0.2f, 0);
    cr_expect_eq(s.textures[r->bump_tex - 1].image.format, TEXEL_U8_LINEAR); /* heights are data */
    cr_expect_eq(s.materials[0].bump_tex, 0);
    cr_assert(r->normal_tex > 0);
    cr_expect_eq(s.textures[r->normal_tex - 1].image.format, TEXEL_U8_LINEAR);
    cr_expect_float_eq(s.textures[r->normal_tex - 1].scale[0], 2.0f, 0);
    cr_expect(s.meshes[0].uvs != NULL);
    scene_fini(&s);
}

static void expect_scene_error(const char *text, const char *want)
{
    test_scene_expect_error(text, scene_files(), want);
}

Test(texture_scene, errors_name_line_and_column)
{
    log_set_level(LOG_ERROR);
    expect_scene_error(SCENE_HEAD "\"textures\": {\"c\": {\"type\": \"checker\", \"filter\": \"box\"}}}",
                       "scenes/t.json:4:49: unknown filter \"box\"");
    expect_scene_error(SCENE_HEAD "\"textures\": {\"c\": {\"type\": \"checker\", \"file\": \"a.png\"}}}",
                       "scenes/t.json:4:39: key \"file\" applies to image textures only");
    expect_scene_error(SCENE_HEAD "\"textures\": {\"c\": {\"type\": \"image\"}}}", "missing key \"file\"");
    expect_scene_error(SCENE_HEAD "\"textures\": {\"c\": {\"type\": \"image\", \"file\": \"x.png\"}}}",
                       "scenes/t.json:4:45: cannot load image: x.png: No such file");
    expect_scene_error(SCENE_HEAD "\"textures\": {\"c\": {\"type\": \"image\", \"file\": \"../x.png\"}}}",
                       "scenes/t.json:4:45: file: \"..\" component");
    expect_scene_error(SCENE_HEAD "\"textures\": {\"c\": {\"type\": \"image\", \"file\": \"quad.obj\"}}}",
                       "quad.obj: not a PNG, JPEG, Radiance HDR or OpenEXR image");
    expect_scene_error(SCENE_HEAD "\"textures\": {\"c\": {\"type\": \"checker\", \"max_anisotropy\": 0}}}",
                       "scenes/t.json:4:57: max_anisotropy must be in [1, 64]");
    expect_scene_error(SCENE_HEAD "\"textures\": {\"c\": {\"type\": \"checker\", \"scale\": [1, 0]}}}",
                       "scenes/t.json:4:52: scale components must be");
    expect_scene_error(SCENE_HEAD "\"textures\": {\"c\": {\"type\": \"wood\"}}}",
                       "scenes/t.json:4:28: unknown texture type \"wood\"");
    expect_scene_error(SCENE_HEAD "\"materials\": {\"m\": {\"type\": \"diffuse\", \"albedo_texture\": \"nope\"}}}",
                       "scenes/t.json:4:58: unknown texture \"nope\"");
    expect_scene_error(SCENE_HEAD "\"textures\": {\"c\": {\"type\": \"checker\"}},\n"
                                  "\"materials\": {\"m\": {\"type\": \"mirror\", \"albedo_texture\": \"c\"}}}",
                       "scenes/t.json:5:39: key \"albedo_texture\" does not apply to a mirror material");
    expect_scene_error(SCENE_HEAD "\"materials\": {\"m\": {\"type\": \"mirror\", \"bump_scale\": 2}}}",
                       "scenes/t.json:4:39: bump_scale needs \"bump_texture\"");
    expect_scene_error(SCENE_HEAD "\"materials\": {\"m\": {\"type\": \"mirror\", \"bump_texture\": \"x\"}}}",
                       "scenes/t.json:4:55: unknown texture \"x\"");
    expect_scene_error(SCENE_HEAD "\"objects\": [{\"type\": \"obj\", \"file\": \"nofile.obj\"}]}",
                       "scenes/m/n.mtl:2:14: map_Kd needs a file name");
    expect_scene_error(SCENE_HEAD "\"objects\": [{\"type\": \"obj\", \"file\": \"gone.obj\"}]}",
                       "scenes/m/g.mtl:2:10: map_Kd: m/gone.png: No such file");
}

/* ---- bump mapping ---- */

#include "render/texshade.h"

Test(bump, height_ramp_tilts_the_normal_as_computed_by_hand)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    struct texture t;
    texture_init(&t, TEXTURE_IMAGE, "h");
    t.filter = TEXFILTER_BILINEAR;
    t.wrap = TEXWRAP_CLAMP;
    cr_assert_eq(tex_image_alloc(&t.image, 64, 4, 1, TEXEL_F32), 0);
    for (uint32_t y = 0; y < 4; y++)
        for (uint32_t x = 0; x < 64; x++)
            ((float *)t.image.data)[y * 64 + x] = ((float)x + 0.5f) / 64.0f; /* h(u) = u, bilinear: exact inside */
    scene_add_texture(&s, &t);
    struct mip m;
    mip_init(&m, &s.textures[0].image, TEXWRAP_CLAMP);
    struct material mat;
    memset(&mat, 0, sizeof mat);
    mat.type = MATERIAL_DIFFUSE;
    mat.bump_tex = 1;
    mat.bump_scale = 0.5f;
    vec3 p[3] = {v3(0, 0, 0), v3(2, 0, 0), v3(0, 2, 0)};
    const float uv[3][2] = {{0, 0}, {1, 0}, {0, 1}};
    struct raydiff cam = {v3(0, 0, 0), v3(0, 0, 0), v3(0.001f, 0, 0), v3(0, 0.001f, 0), 0.0f, 0.0f};
    struct raydiff_hit dh;
    raydiff_triangle(p, uv, NULL, 0.3f, 0.3f, v3(0, 0, 1), &cam, v3(0, 0, -1), 5.0f, &dh);
    cr_assert(dh.has_dpduv);
    expect_vec_near(dh.dpdu, v3(2, 0, 0), 1e-5f, "dp/du");
    expect_vec_near(dh.dpdv, v3(0, 2, 0), 1e-5f, "dp/dv");
    vec3 n = texshade_bump(&s, &m, &mat, &dh, v3(0, 0, 1), v3(0, 0, 1));
    /* dh/du = 0.5: dp/du' = (2, 0, 0.5), dp/dv' = (0, 2, 0): n = normalize(-1, 0, 4). */
    expect_vec_near(n, v3_normalize(v3(-1, 0, 4)), 2e-3f, "bumped normal");
    /* Seen from below (ns = -z): the same displaced surface, so its other side's normal. */
    vec3 nb = texshade_bump(&s, &m, &mat, &dh, v3(0, 0, -1), v3(0, 0, -1));
    expect_vec_near(nb, v3_normalize(v3(1, 0, -4)), 2e-3f, "from below");
    /* Degenerate uvs: no change. */
    const float same[3][2] = {{0.5f, 0.5f}, {0.5f, 0.5f}, {0.5f, 0.5f}};
    raydiff_triangle(p, same, NULL, 0.3f, 0.3f, v3(0, 0, 1), &cam, v3(0, 0, -1), 5.0f, &dh);
    cr_expect(!dh.has_dpduv);
    n = texshade_bump(&s, &m, &mat, &dh, v3(0, 0, 1), v3(0, 0, 1));
    cr_expect(n.x == 0 && n.y == 0 && n.z == 1);
    /* A huge scale would tip the normal under the surface: kept finite and on the ng side. */
    mat.bump_scale = 1e6f;
    raydiff_triangle(p, uv, NULL, 0.3f, 0.3f, v3(0, 0, 1), &cam, v3(0, 0, -1), 5.0f, &dh);
    n = texshade_bump(&s, &m, &mat, &dh, v3(0, 0, 1), v3(0, 0, 1));
    cr_expect(v3_is_finite(n) && n.z > 0.0f);
    mip_fini(&m);
    scene_fini(&s);
}

/* ---- end to end: filtering through a mirror ---- */

/* The horizon checker again, but seen in a mirror: the floor lies at z < 0, a mirror
 * stands at z = 0 facing the camera, which looks at the mirror. If differentials were lost
 * at the mirror, EWA would alias like the unfiltered lookup. */
Test(texture_render, ewa_through_a_mirror_filters_like_direct_view, .timeout = 120)
{
    log_set_level(LOG_ERROR);
    const float R = 400.0f, reps = 100.0f;
    const vec3 c0 = v3(0.9f, 0.9f, 0.9f), c1 = v3(0.05f, 0.05f, 0.05f);
    const uint32_t W = 96, H = 48;
    float *img[3]; /* nearest at 1 spp, EWA at 1 spp, the nearest 1024-spp reference */
    for (int pass = 0; pass < 3; pass++) {
        enum texture_filter f = pass == 1 ? TEXFILTER_EWA : TEXFILTER_NEAREST;
        struct scene s;
        memset(&s, 0, sizeof s);
        struct texture t;
        checker_image(&t, c0, c1);
        t.filter = f;
        t.max_aniso = 16;
        t.scale[0] = t.scale[1] = reps;
        scene_add_texture(&s, &t);
        horizon_scene(&s, R, 0);
        /* Floor only at z < 0 (uvs as before over the full square), a mirror at z = 0. */
        float *pos = s.meshes[0].positions;
        pos[5] = 0.0f, pos[8] = 0.0f; /* the two far corners (z = R) move to z = 0 */
        s.meshes[0].uvs[3] = 0.5f, s.meshes[0].uvs[5] = 0.5f;
        struct material mir;
        memset(&mir, 0, sizeof mir);
        mir.type = MATERIAL_MIRROR;
        mir.reflectance = v3(1, 1, 1);
        uint32_t mid = scene_add_material(&s, &mir);
        struct mesh me;
        memset(&me, 0, sizeof me);
        me.num_vertices = 4;
        me.num_triangles = 2;
        me.positions = mem_alloc(12 * sizeof(float));
        const float mp[12] = {-R, -1, 0, R, -1, 0, R, R, 0, -R, R, 0};
        memcpy(me.positions, mp, sizeof mp);
        me.indices = mem_alloc(6 * sizeof(uint32_t));
        const uint32_t idx[6] = {0, 1, 2, 0, 2, 3};
        memcpy(me.indices, idx, sizeof idx);
        me.material_ids = mem_alloc(2 * sizeof(uint32_t));
        me.material_ids[0] = me.material_ids[1] = mid;
        scene_add_mesh(&s, &me);
        s.camera.position = v3(0, 1, -1);
        s.camera.look_at = v3(0, 0.3f, 10);
        s.lights[0].position = v3(0, 1e4f, -1.0f); /* above the floor, in front of the mirror */
        render_settings(&s, W, H, pass == 2 ? 1024 : 1);
        s.settings.max_depth = 2;
        struct tile_stats st;
        img[pass] = test_render(&s, 1, &st);
        cr_expect_eq(st.nan_samples, 0);
        scene_fini(&s);
    }
    float *near1 = img[0], *ewa1 = img[1], *ref = img[2];
    double e_near = rmse(near1, ref, W, 0, H), e_ewa = rmse(ewa1, ref, W, 0, H);
    double mean = 0;
    for (uint32_t i = 0; i < W * H; i++)
        mean += ref[i * TILE_NUM_CHANNELS];
    mean /= W * H;
    cr_log_info("through a mirror, RMSE at 1 spp: nearest %.4f ewa %.4f (image mean %.3f)", e_near, e_ewa, mean);
    cr_expect(mean > 0.05, "the mirror shows the lit floor (mean %g)", mean);
    cr_expect(e_ewa < 0.5 * e_near, "ewa %g vs nearest %g", e_ewa, e_near);
    free(near1);
    free(ewa1);
    free(ref);
}

/* The horizon checker seen through a glass slab standing in front of the camera: the
 * differentials refract twice on the way (the slab's Fresnel reflections are noise that
 * both filters share). */
Test(texture_render, ewa_through_glass_filters_like_direct_view, .timeout = 120)
{
    log_set_level(LOG_ERROR);
    const float R = 400.0f, reps = 100.0f;
    const vec3 c0 = v3(0.9f, 0.9f, 0.9f), c1 = v3(0.05f, 0.05f, 0.05f);
    const uint32_t W = 96, H = 48;
    float *img[3]; /* nearest at 1 spp, EWA at 1 spp, the nearest 1024-spp reference */
    for (int pass = 0; pass < 3; pass++) {
        struct scene s;
        memset(&s, 0, sizeof s);
        struct texture t;
        checker_image(&t, c0, c1);
        t.filter = pass == 1 ? TEXFILTER_EWA : TEXFILTER_NEAREST;
        t.max_aniso = 16;
        t.scale[0] = t.scale[1] = reps;
        scene_add_texture(&s, &t);
        horizon_scene(&s, R, 0);
        struct material glass;
        memset(&glass, 0, sizeof glass);
        glass.type = MATERIAL_DIELECTRIC;
        glass.ior = 1.5f;
        glass.transmittance = v3(1, 1, 1);
        uint32_t gid = scene_add_material(&s, &glass);
        /* A closed box 0.3 thick, tilted about y, across the whole view, 1 unit ahead. */
        struct mesh me;
        memset(&me, 0, sizeof me);
        me.num_vertices = 8;
        me.num_triangles = 12;
        me.positions = mem_alloc(24 * sizeof(float));
        const float zc = -R * 0.99f + 1.0f, hx = 50.0f, ylo = 0.01f, yhi = 40.0f, th = 0.15f, k = 0.3f;
        for (int i = 0; i < 8; i++) {
            float x = (i & 1) ? hx : -hx, y = (i & 2) ? yhi : ylo, z = zc + ((i & 4) ? th : -th) + k * x * 0.02f;
            me.positions[3 * i] = x, me.positions[3 * i + 1] = y, me.positions[3 * i + 2] = z;
        }
        /* Outward faces of the box (vertex bits: x=1, y=2, z=4). */
        static const uint32_t q[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
        me.indices = mem_alloc(36 * sizeof(uint32_t));
        for (int f = 0; f < 6; f++) {
            const uint32_t tri[6] = {q[f][0], q[f][1], q[f][2], q[f][0], q[f][2], q[f][3]};
            memcpy(&me.indices[6 * f], tri, sizeof tri);
        }
        me.material_ids = mem_alloc(12 * sizeof(uint32_t));
        for (int i = 0; i < 12; i++)
            me.material_ids[i] = gid;
        scene_add_mesh(&s, &me);
        render_settings(&s, W, H, pass == 2 ? 1024 : 1);
        s.settings.max_depth = 4;
        struct tile_stats st;
        img[pass] = test_render(&s, 1, &st);
        cr_expect_eq(st.nan_samples, 0);
        scene_fini(&s);
    }
    double e_near = rmse(img[0], img[2], W, 0, H), e_ewa = rmse(img[1], img[2], W, 0, H), mean = 0;
    for (uint32_t i = 0; i < W * H; i++)
        mean += img[2][i * TILE_NUM_CHANNELS];
    mean /= W * H;
    cr_log_info("through glass, RMSE at 1 spp: nearest %.4f ewa %.4f (image mean %.3f)", e_near, e_ewa, mean);
    cr_expect(mean > 0.05, "the glass shows the lit floor (mean %g)", mean);
    cr_expect(e_ewa < 0.7 * e_near, "ewa %g vs nearest %g", e_ewa, e_near); /* 0.58; 0.87 without refraction */
    for (int i = 0; i < 3; i++)
        free(img[i]);
}

Test(bump, tangent_space_normal_map)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    struct texture t;
    texture_init(&t, TEXTURE_IMAGE, "n");
    t.filter = TEXFILTER_BILINEAR;
    cr_assert_eq(tex_image_alloc(&t.image, 4, 4, 3, TEXEL_F32), 0);
    for (int i = 0; i < 16; i++) { /* n = (0.5, 0, 0.866) in tangent space */
        float *px = &((float *)t.image.data)[3 * i];
        px[0] = 0.75f, px[1] = 0.5f, px[2] = 0.5f + 0.5f * 0.8660254f;
    }
    scene_add_texture(&s, &t);
    struct mip m;
    mip_init(&m, &s.textures[0].image, TEXWRAP_REPEAT);
    struct material mat;
    memset(&mat, 0, sizeof mat);
    mat.type = MATERIAL_MIRROR;
    mat.normal_tex = 1;
    /* u along +y on this triangle: the tangent T is +y, B = N x T = -x. */
    vec3 p[3] = {v3(0, 0, 0), v3(0, 2, 0), v3(-2, 0, 0)};
    const float uv[3][2] = {{0, 0}, {1, 0}, {0, 1}};
    struct raydiff cam = {v3(0, 0, 0), v3(0, 0, 0), v3(0.001f, 0, 0), v3(0, 0.001f, 0), 0.0f, 0.0f};
    struct raydiff_hit dh;
    raydiff_triangle(p, uv, NULL, 0.3f, 0.3f, v3(0, 0, 1), &cam, v3(0, 0, -1), 5.0f, &dh);
    vec3 n = texshade_bump(&s, &m, &mat, &dh, v3(0, 0, 1), v3(0, 0, 1));
    expect_vec_near(n, v3(0, 0.5f, 0.8660254f), 1e-4f, "normal-mapped");
    /* The flat value (0.5, 0.5, 1) leaves the normal alone. */
    float *px = s.textures[0].image.data;
    for (int i = 0; i < 16; i++)
        px[3 * i] = 0.5f, px[3 * i + 1] = 0.5f, px[3 * i + 2] = 1.0f;
    mip_fini(&m);
    mip_init(&m, &s.textures[0].image, TEXWRAP_REPEAT);
    n = texshade_bump(&s, &m, &mat, &dh, v3(0, 0, 1), v3(0, 0, 1));
    expect_vec_near(n, v3(0, 0, 1), 1e-5f, "flat map");
    /* A map pointing into the surface: the shading normal is kept. */
    for (int i = 0; i < 16; i++)
        px[3 * i] = 0.5f, px[3 * i + 1] = 0.5f, px[3 * i + 2] = 0.0f;
    mip_fini(&m);
    mip_init(&m, &s.textures[0].image, TEXWRAP_REPEAT);
    n = texshade_bump(&s, &m, &mat, &dh, v3(0, 0, 1), v3(0, 0, 1));
    cr_expect(n.x == 0 && n.y == 0 && n.z == 1);
    mip_fini(&m);
    scene_fini(&s);
}
