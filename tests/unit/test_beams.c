/* Photon beams (common/render/photon_beams.c): the beam x beam estimate against a closed
 * form (a collimated flux of parallel beams crossing a camera ray: in-scattered radiance
 * E sigma_s f(theta) integral of Tr), the BVH query against a loop over every beam, the
 * wire section's round trip and its refusals. The images against VPT are in
 * test_medium.c (beams_match_vpt_*). */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "base/bytes.h"
#include "base/log.h"
#include "base/rng.h"
#include "render/photon_beams.h"
#include "render/photon_map.h"
#include "scene/medium.h"

static struct medium grey(float ss, float st, float g)
{
    struct medium md;
    memset(&md, 0, sizeof md);
    md.sigma_s = v3(ss, ss, ss);
    md.sigma_a = v3(st - ss, st - ss, st - ss);
    md.sigma_t = v3(st, st, st);
    md.g = g;
    return md;
}

static struct photon_beam make_beam(vec3 a, vec3 b, vec3 power, uint32_t depth)
{
    struct photon_beam pb;
    memset(&pb, 0, sizeof pb);
    pb.a[0] = a.x, pb.a[1] = a.y, pb.a[2] = a.z;
    pb.b[0] = b.x, pb.b[1] = b.y, pb.b[2] = b.z;
    photon_rgbe_encode(power, pb.rgbe);
    pb.depth = depth;
    return pb;
}

/* Parallel beams along u on a square lattice of spacing h (flux density E = power / h^2)
 * cross the camera ray o + t d, t in [0, len), at angle theta. The lattice's rows across
 * the ray's plane sit at (k + 1/2) h, so exactly 2r / h of them lie within r. */
static void lattice_case(float theta, float r, float sigma_t, float len)
{
    const float h = r / 8.0f, ss = 0.5f, g = 0.3f;
    vec3 d = v3(0, 0, 1), o = v3(0.1f, -0.2f, 0.3f);
    vec3 u = v3(sinf(theta), 0, cosf(theta));
    vec3 e1 = v3(0, 1, 0), e2 = v3_normalize(v3_cross(u, e1)); /* both across u */
    uint8_t code[4];
    photon_rgbe_encode(v3(0.25f, 0.25f, 0.25f), code);
    const float power = photon_rgbe_decode(code).x;
    struct photon_beam *beams = NULL;
    size_t cap = 0;
    uint32_t n = 0;
    /* the ray's shadow across u spans |e2 . d| len; the margin keeps the ends covered */
    float span = fabsf(v3_dot(e2, d)) * len + 4.0f * r;
    int k2 = (int)ceilf(span / h);
    for (int i = -8; i < 8; i++)
        for (int j = -k2; j <= k2; j++) {
            vec3 p = v3_add(o, v3_add(v3_scale(e1, ((float)i + 0.5f) * h), v3_scale(e2, (float)j * h)));
            mem_grow((void **)&beams, &cap, (size_t)n + 1, sizeof *beams);
            beams[n++] = make_beam(v3_sub(p, v3_scale(u, 3.0f * len)), v3_add(p, v3_scale(u, 3.0f * len)),
                                   v3(0.25f, 0.25f, 0.25f), 1);
        }
    struct photon_beams *pb = photon_beams_from(beams, n, r);
    struct medium md = grey(ss, sigma_t, g);
    vec3 est = photon_beams_estimate(pb, o, d, len, &md, NULL, PHOTON_DEPTH_ANY);
    double E = power / ((double)h * h);
    double itr = sigma_t > 0.0f ? -expm1(-(double)sigma_t * len) / sigma_t : len;
    double want = E * ss * phase_hg_cut(v3_dot(u, v3_neg(d)), g) * itr;
    fprintf(stderr, "beams lattice: theta %.3f r %g sigma_t %g: %g against %g (%u beams)\n", (double)theta, (double)r,
            (double)sigma_t, (double)est.x, want, n);
    cr_assert(fabs(est.x / want - 1.0) < 0.02, "theta %g: estimate %g, closed form %g", (double)theta,
              (double)est.x, want);
    cr_assert(est.x == est.y && est.y == est.z);
    /* depth filter: all beams have depth 1 */
    vec3 none = photon_beams_estimate(pb, o, d, len, &md, NULL, 0);
    cr_assert(none.x == 0.0f);
    photon_beams_free(&pb);
    free(beams);
}

Test(beams, collimated_flux_closed_form)
{
    lattice_case(1.0471976f, 0.05f, 0.0f, 2.0f);  /* 60 degrees, no attenuation */
    lattice_case(1.0471976f, 0.05f, 0.8f, 2.0f);  /* the camera ray's transmittance */
    lattice_case(0.3f, 0.02f, 0.3f, 1.5f);        /* a shallow angle: 1 / sin theta */
    lattice_case(2.5f, 0.05f, 0.2f, 1.0f);        /* against the ray (back-scattering) */
}

/* One beam crossing the ray perpendicularly at distance 0.5 r, at t = 1: the estimate is
 * power sigma_s f(90 degrees) Tr(1) / (2 r); beyond r, past the segment's end, or with the
 * crossing outside the beam's length, nothing. */
Test(beams, single_beam)
{
    const float r = 0.1f;
    struct medium md = grey(0.7f, 1.1f, -0.4f);
    struct photon_beam b[4] = {
        make_beam(v3(-1, 0.5f * r, 1), v3(1, 0.5f * r, 1), v3(1, 2, 4), 3),     /* within r */
        make_beam(v3(-1, 1.5f * r, 1.2f), v3(1, 1.5f * r, 1.2f), v3(1, 1, 1), 3), /* beyond r */
        make_beam(v3(-1, 0, 5), v3(1, 0, 5), v3(1, 1, 1), 3),                    /* past the segment */
        make_beam(v3(0.2f, 0, 0.5f), v3(1, 0, 0.5f), v3(1, 1, 1), 3),            /* ends before the ray */
    };
    struct photon_beams *pb = photon_beams_from(b, 4, r);
    vec3 est = photon_beams_estimate(pb, v3(0, 0, 0), v3(0, 0, 1), 3.0f, &md, NULL, PHOTON_DEPTH_ANY);
    vec3 pw = photon_rgbe_decode(b[0].rgbe);
    double k = 0.7 * phase_hg_cut(0.0f, -0.4f) * exp(-1.1) / (2.0 * r);
    cr_assert(fabs(est.x / (pw.x * k) - 1.0) < 1e-5 && fabs(est.z / (pw.z * k) - 1.0) < 1e-5,
              "%g %g against %g %g", (double)est.x, (double)est.z, pw.x * k, pw.z * k);
    vec3 shallow = photon_beams_estimate(pb, v3(0, 0, 0), v3(0, 0, 1), 3.0f, &md, NULL, 2);
    cr_assert(shallow.x == 0.0f); /* depth 3 > 2 */
    photon_beams_free(&pb);
}

/* The BVH's answer equals the loop over every beam (the same sum, in the same order) for
 * random beams, rays and radii. */
Test(beams, bvh_matches_brute_force, .timeout = 60)
{
    const uint32_t n = 3000;
    struct photon_beam *b = mem_alloc(sizeof *b * n);
    uint64_t key = rng_mix64(12345);
    for (uint32_t i = 0; i < n; i++) {
        vec3 a = v3(rng_uniform(key, 8 * i) * 4 - 2, rng_uniform(key, 8 * i + 1) * 4 - 2, rng_uniform(key, 8 * i + 2) * 4 - 2);
        vec3 e = v3(rng_uniform(key, 8 * i + 3) - 0.5f, rng_uniform(key, 8 * i + 4) - 0.5f, rng_uniform(key, 8 * i + 5) - 0.5f);
        float l = 0.01f + 3.0f * rng_uniform(key, 8 * i + 6) * rng_uniform(key, 8 * i + 6);
        b[i] = make_beam(a, v3_add(a, v3_scale(v3_normalize(e), l)), v3(1, 0.5f, 0.25f), 1 + i % 5);
    }
    struct medium md = grey(0.5f, 0.6f, 0.5f);
    const float radii[] = {1e-4f, 0.03f, 0.2f, 2.0f};
    struct photon_beams *pb = photon_beams_from(b, n, radii[0]);
    uint32_t nonzero = 0;
    for (uint32_t ri = 0; ri < 4; ri++) {
        photon_beams_set_radius(pb, radii[ri]);
        for (uint32_t q = 0; q < 200; q++) {
            uint64_t k2 = rng_mix64(key ^ (q + 1000u * ri));
            vec3 o = v3(rng_uniform(k2, 0) * 6 - 3, rng_uniform(k2, 1) * 6 - 3, rng_uniform(k2, 2) * 6 - 3);
            vec3 d = v3_normalize(v3(rng_uniform(k2, 3) - 0.5f, rng_uniform(k2, 4) - 0.5f, rng_uniform(k2, 5) - 0.5f));
            if (q % 7 == 0)
                d = v3(0, 0, q % 2 ? 1.0f : -1.0f); /* along an axis */
            float t1 = 0.1f + 8.0f * rng_uniform(k2, 6);
            uint32_t dm = q % 3 == 0 ? 3 : PHOTON_DEPTH_ANY;
            vec3 x = photon_beams_estimate(pb, o, d, t1, &md, NULL, dm);
            vec3 y = photon_beams_estimate_brute(pb, o, d, t1, &md, NULL, dm);
            cr_assert(x.x == y.x && x.y == y.y && x.z == y.z, "radius %g query %u: %g against %g", (double)radii[ri],
                      q, (double)x.x, (double)y.x);
            nonzero += x.x > 0.0f;
        }
    }
    cr_assert(nonzero > 100, "only %u queries found beams", nonzero);
    photon_beams_free(&pb);
    free(b);
}

static uint8_t *section(const struct photon_beam *b, uint32_t n, float radius, size_t *size)
{
    struct photon_beam_list l = {NULL, 0, 0};
    for (uint32_t i = 0; i < n; i++) {
        vec3 a = v3(b[i].a[0], b[i].a[1], b[i].a[2]), e = v3(b[i].b[0], b[i].b[1], b[i].b[2]);
        photon_beam_store(&l, a, e, photon_rgbe_decode(b[i].rgbe), b[i].depth);
    }
    uint8_t *out = NULL;
    uint32_t count = 0;
    char err[128];
    cr_assert_eq(photon_beams_serialise(&l, 1, radius, 99, &out, size, &count, err, sizeof err), 0, "%s", err);
    cr_assert_eq(count, n);
    return out;
}

Test(beams, section_roundtrip_and_refusals)
{
    struct photon_beam b[3] = {make_beam(v3(0, 0, 0), v3(1, 0, 0), v3(1, 1, 1), 1),
                               make_beam(v3(0, 1, 0), v3(0, 1, 2), v3(2, 1, 1), 7),
                               make_beam(v3(-1, 0, 0), v3(-1, -3, 0), v3(0.5f, 1, 1), 2)};
    size_t size;
    uint8_t *s = section(b, 3, 0.25f, &size);
    cr_assert_eq(size, PB_HEADER + 3 * sizeof(struct photon_beam));
    char err[256];
    struct photon_beams *pb = NULL;
    cr_assert_eq(photon_beams_decode(s, size, &pb, err, sizeof err), 0, "%s", err);
    cr_assert_eq(photon_beams_count(pb), 3);
    cr_assert_eq(photon_beams_radius(pb), 0.25f);
    photon_beams_free(&pb);
    /* truncated anywhere, or one byte more */
    for (size_t k = 0; k < size; k++) {
        cr_assert_neq(photon_beams_decode(s, k, &pb, err, sizeof err), 0, "truncated to %zu", k);
        cr_assert_null(pb);
    }
    uint8_t *big = mem_calloc(size + 1, 1);
    memcpy(big, s, size);
    cr_assert_neq(photon_beams_decode(big, size + 1, &pb, err, sizeof err), 0);
    free(big);
    /* damaged fields: count, padding, radius, an end point, a zero length, a depth */
    struct { size_t at; uint32_t v; } bad[] = {
        {8, 4}, {8, 2}, {12, 1}, {28, 1}, {24, 0}, {24, 0x7fc00000u}, {24, 0xbf800000u},
        {PB_HEADER + 4, 0x7f800000u}, {PB_HEADER + 12, 0}, {PB_HEADER + 28, 0}, {PB_HEADER + 28, 5000},
    };
    for (size_t i = 0; i < sizeof bad / sizeof *bad; i++) {
        uint8_t *c = mem_alloc(size);
        memcpy(c, s, size);
        if (bad[i].at == PB_HEADER + 12) { /* end = start: zero length */
            memcpy(c + PB_HEADER + 12, c + PB_HEADER, 12);
        } else {
            bytes_put_u32(c + bad[i].at, bad[i].v);
        }
        cr_assert_neq(photon_beams_decode(c, size, &pb, err, sizeof err), 0, "damage %zu accepted", i);
        free(c);
    }
    /* behind a volume map (no photons) in a pass's map: decoded into map->beams */
    uint8_t *vm = NULL;
    size_t vbytes = 0;
    uint32_t vn = 0;
    struct photon_list none = {NULL, 0, 0};
    cr_assert_eq(photon_map_serialise(&none, 1, 0.25f, 99, &vm, &vbytes, &vn, err, sizeof err), 0);
    uint8_t *joined = mem_alloc(vbytes + size);
    memcpy(joined, vm, vbytes);
    memcpy(joined + vbytes, s, size);
    struct photon_map *m = NULL;
    cr_assert_eq(photon_map_decode(joined, vbytes + size, &m, err, sizeof err), 0, "%s", err);
    cr_assert_eq(photon_beams_count(m->beams), 3);
    photon_map_free(&m);
    /* anything else after the map is refused */
    joined[vbytes] = 'X';
    cr_assert_neq(photon_map_decode(joined, vbytes + size, &m, err, sizeof err), 0);
    free(joined);
    free(vm);
    free(s);
}

/* Extreme radii and coordinates stay finite (the BVH's boxes are clamped to finite floats). */
Test(beams, extreme_values_finite)
{
    struct medium md = grey(0.5f, 0.6f, 0.2f);
    struct photon_beam b[2] = {make_beam(v3(-1e38f, 0, 0), v3(1e38f, 0, 1), v3(1, 1, 1), 1),
                               make_beam(v3(0, 0, 0), v3(0, 1e-30f, 0), v3(1e30f, 1, 1), 1)};
    const float radii[] = {1e-30f, 1.0f, 3e38f};
    for (int i = 0; i < 3; i++) {
        struct photon_beams *pb = photon_beams_from(b, 2, radii[i]);
        vec3 e = photon_beams_estimate(pb, v3(0, -1, 0.5f), v3(0, 1, 0), 2.0f, &md, NULL, PHOTON_DEPTH_ANY);
        cr_assert(v3_is_finite(e) && e.x >= 0.0f, "radius %g: %g", (double)radii[i], (double)e.x);
        photon_beams_free(&pb);
    }
}
