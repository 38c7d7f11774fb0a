/* BSDFs: the Fresnel equations against closed forms (normal incidence, grazing, energy
 * R + T = 1 from the independent transmission coefficients, total internal reflection),
 * mirror and dielectric sampling (Snell's law, 1/eta^2 radiance scaling), and white
 * furnaces: a glass or mirror object inside a closed, uniformly emitting box renders the
 * box's radiance, also for grazing rays through a glass slab. */
#include <criterion/criterion.h>
#include <math.h>
#include <string.h>
#include "render/integrator.h"
#include "base/log.h"
#include "scene/material.h"
#include "helpers.h"

Test(material, fresnel_normal_incidence)
{
    const float etas[] = {1.33f, 1.5f, 2.4f, 1.0f / 1.5f};
    for (int i = 0; i < 4; i++) {
        float n = etas[i], expect = ((n - 1) / (n + 1)) * ((n - 1) / (n + 1));
        cr_assert_float_eq(material_fresnel_dielectric(1.0f, n), expect, 1e-6f, "eta %g", (double)n);
    }
    cr_assert_float_eq(material_fresnel_dielectric(1.0f, 1.5f), 0.04f, 1e-6f);
    cr_assert_eq(material_fresnel_dielectric(0.7f, 1.0f), 0.0f);
}

Test(material, fresnel_grazing_goes_to_one)
{
    cr_assert_float_eq(material_fresnel_dielectric(0.0f, 1.5f), 1.0f, 1e-6f);
    cr_assert(material_fresnel_dielectric(1e-4f, 1.5f) > 0.999f);
    cr_assert(material_fresnel_dielectric(1e-30f, 1.5f) <= 1.0f);
    /* Increasing toward grazing beyond Brewster's angle. */
    float prev = material_fresnel_dielectric(cosf(1.0f), 1.5f);
    for (float th = 1.05f; th < 1.5707f; th += 0.05f) {
        float f = material_fresnel_dielectric(cosf(th), 1.5f);
        cr_assert(f >= prev, "theta %g", (double)th);
        prev = f;
    }
}

Test(material, reflectance_plus_transmittance_is_one)
{
    /* T from the transmission amplitude coefficients (an independent formula). */
    const double etas[] = {1.2, 1.5, 2.4, 1.0 / 1.5};
    for (int e = 0; e < 4; e++)
        for (int k = 0; k <= 100; k++) {
            double eta = etas[e], ci = k / 100.0, s2t = (1 - ci * ci) / (eta * eta);
            float f = material_fresnel_dielectric((float)ci, (float)eta);
            if (s2t >= 1.0) {
                cr_assert_eq(f, 1.0f);
                continue;
            }
            if (ci == 0.0)
                continue;
            double ct = sqrt(1 - s2t), ts = 2 * ci / (ci + eta * ct), tp = 2 * ci / (eta * ci + ct);
            double t = 0.5 * (eta * ct / ci) * (ts * ts + tp * tp);
            cr_assert(fabs(f + t - 1.0) < 2e-6, "eta %g cos %g: R %g T %g", eta, ci, (double)f, t);
        }
}

Test(material, total_internal_reflection)
{
    float eta = 1.0f / 1.5f, cos_crit = sqrtf(1.0f - eta * eta); /* sin_c = 1/1.5 */
    vec3 n = v3(0, 0, 1);
    for (float ci = 0.0f; ci < cos_crit - 1e-4f; ci += 0.01f) {
        cr_assert_eq(material_fresnel_dielectric(ci, eta), 1.0f);
        vec3 wo = v3(sqrtf(1 - ci * ci), 0, ci), wt;
        cr_assert_eq(material_refract(wo, n, ci, eta, &wt), 0);
    }
    cr_assert(material_fresnel_dielectric(cos_crit + 1e-3f, eta) < 1.0f);
    /* Sampling inside the glass beyond the critical angle always reflects, weight 1. */
    struct material m;
    memset(&m, 0, sizeof m);
    m.type = MATERIAL_DIELECTRIC;
    m.ior = 1.5f;
    m.transmittance = v3(1, 1, 1);
    vec3 wo = v3_normalize(v3(1, 0, 0.2f));
    for (int i = 0; i < 64; i++) {
        struct bsdf_sample bs;
        material_sample(&m, n, wo, 0, (i + 0.5f) / 64.0f, 0.5f, &bs);
        cr_assert(bs.pdf > 0.0f && bs.is_delta && !bs.transmitted);
        cr_assert_float_eq(bs.weight.x, 1.0f, 0.0f);
        cr_assert_float_eq(bs.wi.z, wo.z, 1e-6f);
        cr_assert_float_eq(bs.wi.x, -wo.x, 1e-6f);
    }
}

Test(material, refraction_follows_snell_and_scales_radiance)
{
    struct material m;
    memset(&m, 0, sizeof m);
    m.type = MATERIAL_DIELECTRIC;
    m.ior = 1.5f;
    m.transmittance = v3(1, 0.5f, 0.25f);
    vec3 n = v3(0, 0, 1);
    for (int front = 0; front <= 1; front++)
        for (float th = 0.0f; th < 1.55f; th += 0.1f) {
            vec3 wo = v3(sinf(th), 0, cosf(th));
            float eta = front ? 1.5f : 1.0f / 1.5f, f = material_fresnel_dielectric(wo.z, eta);
            if (f >= 1.0f)
                continue;
            struct bsdf_sample bs;
            material_sample(&m, n, wo, front, 0.999999f, 0.5f, &bs); /* u1 > F: refract */
            cr_assert(bs.transmitted && bs.is_delta);
            cr_assert(v3_is_finite(bs.wi) && fabsf(v3_length(bs.wi) - 1.0f) < 1e-5f);
            cr_assert(bs.wi.z < 0.0f);
            float sin_t = sqrtf(bs.wi.x * bs.wi.x + bs.wi.y * bs.wi.y);
            cr_assert_float_eq(sin_t * eta, sinf(th), 2e-5f, "theta %g front %d", (double)th, front);
            cr_assert(bs.wi.x <= 0.0f); /* continues to the other side of the normal */
            cr_assert_float_eq(bs.weight.x, 1.0f / (eta * eta), 1e-6f);
            cr_assert_float_eq(bs.weight.y, 0.5f / (eta * eta), 1e-6f);
            cr_assert_float_eq(bs.pdf, 1.0f - f, 1e-6f);
        }
}

Test(material, mirror_reflects_with_its_reflectance)
{
    struct material m;
    memset(&m, 0, sizeof m);
    m.type = MATERIAL_MIRROR;
    m.reflectance = v3(0.9f, 0.5f, 0.1f);
    vec3 n = v3(0, 1, 0), wo = v3_normalize(v3(1, 2, 3));
    struct bsdf_sample bs;
    material_sample(&m, n, wo, 1, 0.3f, 0.7f, &bs);
    cr_assert(bs.is_delta && !bs.transmitted && bs.pdf > 0.0f);
    cr_assert_float_eq(bs.wi.x, -wo.x, 1e-6f);
    cr_assert_float_eq(bs.wi.y, wo.y, 1e-6f);
    cr_assert_float_eq(bs.wi.z, -wo.z, 1e-6f);
    cr_assert_eq(bs.weight.y, 0.5f);
    float pdf;
    vec3 f = material_eval(&m, n, wo, bs.wi, 1, &pdf);
    cr_assert(v3_is_black(f) && pdf == 0.0f);
    /* Grazing and below-surface outgoing directions give no sample and no NaN. */
    material_sample(&m, n, v3(1, 0, 0), 1, 0.3f, 0.7f, &bs);
    cr_assert_eq(bs.pdf, 0.0f);
    m.type = MATERIAL_DIELECTRIC;
    m.ior = 1.5f;
    m.transmittance = v3(1, 1, 1);
    for (int front = 0; front <= 1; front++) {
        material_sample(&m, n, v3_normalize(v3(1, 1e-7f, 0)), front, 0.99f, 0.5f, &bs);
        cr_assert(v3_is_finite(bs.wi) && v3_is_finite(bs.weight) && isfinite(bs.pdf));
    }
}

/* ---- White furnaces ---- */

static uint32_t add_mat(struct scene *s, enum material_type type, vec3 emission)
{
    struct material m;
    memset(&m, 0, sizeof m);
    m.type = type;
    m.emission = emission;
    m.reflectance = v3(1, 1, 1);
    m.transmittance = v3(1, 1, 1);
    m.ior = 1.5f;
    return scene_add_material(s, &m);
}

/* Quad a b c d whose right-handed normal points toward `toward` (or away when away != 0). */
static void add_quad(struct scene *s, vec3 a, vec3 b, vec3 c, vec3 d, uint32_t mat, vec3 inside, int outward)
{
    vec3 nrm = v3_cross(v3_sub(b, a), v3_sub(c, a));
    int flip = (v3_dot(nrm, v3_sub(inside, a)) > 0.0f) == (outward != 0);
    struct mesh m = test_quad(a, b, c, d, mat, flip);
    scene_add_mesh(s, &m);
}

/* Axis-aligned box [lo, hi] as six quads, normals outward (or inward). */
static void add_box(struct scene *s, vec3 lo, vec3 hi, uint32_t mat, int outward)
{
    vec3 c = v3_scale(v3_add(lo, hi), 0.5f);
    float x0 = lo.x, y0 = lo.y, z0 = lo.z, x1 = hi.x, y1 = hi.y, z1 = hi.z;
    add_quad(s, v3(x0, y0, z0), v3(x1, y0, z0), v3(x1, y0, z1), v3(x0, y0, z1), mat, c, outward);
    add_quad(s, v3(x0, y1, z0), v3(x1, y1, z0), v3(x1, y1, z1), v3(x0, y1, z1), mat, c, outward);
    add_quad(s, v3(x0, y0, z0), v3(x0, y1, z0), v3(x0, y1, z1), v3(x0, y0, z1), mat, c, outward);
    add_quad(s, v3(x1, y0, z0), v3(x1, y1, z0), v3(x1, y1, z1), v3(x1, y0, z1), mat, c, outward);
    add_quad(s, v3(x0, y0, z0), v3(x1, y0, z0), v3(x1, y1, z0), v3(x0, y1, z0), mat, c, outward);
    add_quad(s, v3(x0, y0, z1), v3(x1, y0, z1), v3(x1, y1, z1), v3(x0, y1, z1), mat, c, outward);
}

static void furnace_setup(struct scene *s, uint32_t spp)
{
    memset(s, 0, sizeof *s);
    uint32_t env = add_mat(s, MATERIAL_DIFFUSE, v3(1, 1, 1)); /* albedo 0: paths end on it */
    add_box(s, v3(-6, -6, -6), v3(6, 6, 6), env, 0);
    s->settings.width = 24;
    s->settings.height = 24;
    s->settings.spp = spp;
    s->settings.max_depth = 64;
    s->settings.seed = 11;
    s->settings.tile_size = 16;
}

static void furnace_check(const struct scene *s)
{
    struct tile_stats st;
    float *px = test_render(s, 2, &st);
    double se, mean = test_channel_mean(px, s->settings.width, s->settings.height, CH_G, &se);
    cr_assert_eq(st.nan_samples, 0);
    cr_assert(fabs(mean - 1.0) < 4.0 * se + 2e-3, "furnace mean %.5f (stderr %.2g)", mean, se);
    free(px);
}

Test(material, white_furnace_glass_sphere)
{
    struct scene s;
    furnace_setup(&s, 64);
    uint32_t glass = add_mat(&s, MATERIAL_DIELECTRIC, v3(0, 0, 0));
    struct sphere sp = {"glass", v3(0, 0, -3), 1.5f, glass, NULL, 0};
    scene_add_sphere(&s, &sp);
    s.camera = (struct camera_desc){.position = v3(0, 0, 0), .look_at = v3(0, 0, -1), .up = v3(0, 1, 0),
                                    .fov_y_deg = 70.0f};
    furnace_check(&s);
    scene_fini(&s);
}

Test(material, white_furnace_mirror_and_glass_box)
{
    struct scene s;
    furnace_setup(&s, 32);
    uint32_t glass = add_mat(&s, MATERIAL_DIELECTRIC, v3(0, 0, 0)), mirror = add_mat(&s, MATERIAL_MIRROR, v3(0, 0, 0));
    add_box(&s, v3(-1, -1, -4), v3(1, 1, -2), glass, 1);
    struct sphere sp = {"mirror", v3(2, 1, -3), 1.0f, mirror, NULL, 0};
    scene_add_sphere(&s, &sp);
    s.camera = (struct camera_desc){.position = v3(0.2f, 0.3f, 0), .look_at = v3(0, 0, -3), .up = v3(0, 1, 0),
                                    .fov_y_deg = 80.0f};
    furnace_check(&s);
    scene_fini(&s);
}

Test(material, white_furnace_grazing_glass_slab)
{
    /* A thin glass slab seen almost edge-on: grazing entry, long internal reflection chains. */
    struct scene s;
    furnace_setup(&s, 32);
    uint32_t glass = add_mat(&s, MATERIAL_DIELECTRIC, v3(0, 0, 0));
    add_box(&s, v3(-5, -0.1f, -5), v3(5, 0.1f, 5), glass, 1);
    s.camera = (struct camera_desc){.position = v3(0, 0.1001f, 4.9f), .look_at = v3(0, 0.1f, -5), .up = v3(0, 1, 0),
                                    .fov_y_deg = 2.0f};
    furnace_check(&s);
    scene_fini(&s);
}

/* Rough lobes in the furnace: a frosted glass sphere, a rough mirror and a plastic ball
 * (albedo 1) inside the emitting box. Single-scattering GGX loses energy (about 1% per
 * bounce at roughness 0.3, test_microfacet.c), so the image lies just below 1, never above. */
Test(material, white_furnace_rough_lobes)
{
    struct scene s;
    furnace_setup(&s, 32);
    uint32_t glass = add_mat(&s, MATERIAL_DIELECTRIC, v3(0, 0, 0)), mirror = add_mat(&s, MATERIAL_MIRROR, v3(0, 0, 0));
    uint32_t plastic = add_mat(&s, MATERIAL_PLASTIC, v3(0, 0, 0));
    s.materials[glass].alpha_x = s.materials[glass].alpha_y = 0.09f;
    s.materials[mirror].alpha_x = 0.09f;
    s.materials[mirror].alpha_y = 0.01f;
    s.materials[plastic].alpha_x = s.materials[plastic].alpha_y = 0.04f;
    s.materials[plastic].albedo = v3(1, 1, 1);
    struct sphere a = {"frosted", v3(-1, 0, -3), 1.0f, glass, NULL, 0}, b = {"rough mirror", v3(1.2f, 0.8f, -3.5f), 0.8f, mirror, NULL, 0},
                  c = {"plastic", v3(1, -1, -3), 0.6f, plastic, NULL, 0};
    scene_add_sphere(&s, &a);
    scene_add_sphere(&s, &b);
    scene_add_sphere(&s, &c);
    s.camera = (struct camera_desc){.position = v3(0, 0, 0), .look_at = v3(0, 0, -3), .up = v3(0, 1, 0), .fov_y_deg = 60.0f};
    struct tile_stats st;
    float *px = test_render(&s, 2, &st);
    double se, mean = test_channel_mean(px, s.settings.width, s.settings.height, CH_G, &se);
    cr_assert_eq(st.nan_samples, 0);
    cr_assert(mean <= 1.0 + 4.0 * se + 1e-3 && mean > 0.95, "furnace mean %.5f (stderr %.2g)", mean, se);
    free(px);
    scene_fini(&s);
}
