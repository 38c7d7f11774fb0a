/* Rays traced together (render/accel.c): a packet of n closest-hit rays gives the hits
 * accel_intersect gives ray by ray, and a packet of n occlusion segments the answers of
 * accel_occluded, bit for bit, for every n from 1 to ACCEL_PACKET (single rays below the
 * packet thresholds, then 4-, 8- and 16-wide packets with masked lanes). The path tracer
 * relies on it for pixels that do not depend on packets (tests/integration/packets.sh). */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "helpers.h"
#include "base/log.h"
#include "base/rng.h"
#include "render/accel.h"

/* A floor (y = 0, 4 x 4) and a smaller blocker above it (y = 1, 2 x 2), both still triangles. */
static const struct mem_file files[] = {
    {"floor.obj", "v -2 0 -2\nv 2 0 -2\nv 2 0 2\nv -2 0 2\nf 1 2 3 4\n", 0},
    {"blocker.obj", "v -1 1 -1\nv 1 1 -1\nv 1 1 1\nv -1 1 1\nf 1 2 3 4\n", 0},
    {NULL, NULL, 0}};

static void load_isa(struct scene *s, struct accel *a, enum embree_isa isa)
{
    char err[512];
    const char *text =
        "{\"version\": 1, \"camera\": {\"position\": [0, 3, 5], \"look_at\": [0, 0, 0], \"fov_y\": 40},\n"
        "\"render\": {\"width\": 8, \"height\": 8, \"spp\": 1, \"max_depth\": 2, \"seed\": 1, \"tile_size\": 8},\n"
        "\"objects\": [{\"type\": \"obj\", \"file\": \"floor.obj\"}, {\"type\": \"obj\", \"file\": \"blocker.obj\"}],\n"
        "\"lights\": [{\"type\": \"point\", \"position\": [0, 3, 0], \"intensity\": [1, 1, 1]}]}";
    log_set_level(LOG_ERROR);
    cr_assert_eq(test_scene_load(text, files, s, err), 0, "%s", err);
    s->settings.embree_isa = isa;
    cr_assert_eq(accel_init(a, s, 0, 1, err, sizeof err), 0, "%s", err);
    cr_assert(a->packets_exact);
}

static void load(struct scene *s, struct accel *a)
{
    load_isa(s, a, EMBREE_ISA_AVX2);
}

static float unit(uint64_t key, uint32_t dim)
{
    return rng_uniform(key, dim);
}

/* Ray or segment k of trial t: from a point on a plane at y = 2.5 (jittered about the
 * trial's centre, as a pixel's rays are) toward a point on the floor or below it, so that
 * some go past the blocker, some hit it and some miss everything. */
static void ray(uint32_t t, uint32_t k, vec3 *o, vec3 *target)
{
    uint64_t key = rng_key(7, t, 0, k), tk = rng_key(7, t, 1, 0);
    vec3 c = v3(4.0f * unit(tk, 0) - 2.0f, 2.5f, 4.0f * unit(tk, 1) - 2.0f);
    *o = v3_add(c, v3(0.2f * unit(key, 0), 0.0f, 0.2f * unit(key, 1)));
    *target = v3(6.0f * unit(key, 2) - 3.0f, unit(key, 3) < 0.3f ? -1.0f : 0.5f * unit(key, 4), 6.0f * unit(key, 5) - 3.0f);
}

/* Every instruction set a job may name and this CPU runs: its packet kernels against its
 * single-ray ones. */
static void intersect_packet_check(enum embree_isa isa)
{
    struct scene s;
    struct accel a;
    load_isa(&s, &a, isa);
    uint32_t hits = 0, misses = 0;
    for (uint32_t t = 0; t < 40; t++)
        for (uint32_t n = 1; n <= ACCEL_PACKET; n++) {
            vec3 org[ACCEL_PACKET], dir[ACCEL_PACKET];
            float time01[ACCEL_PACKET];
            struct accel_hit ph[ACCEL_PACKET];
            int found[ACCEL_PACKET];
            for (uint32_t k = 0; k < n; k++) {
                vec3 target;
                ray(t, k, &org[k], &target);
                dir[k] = v3_normalize(v3_sub(target, org[k]));
                time01[k] = 0.0f;
            }
            accel_intersect_packet(&a, n, org, dir, time01, ph, found);
            for (uint32_t k = 0; k < n; k++) {
                struct accel_hit h;
                int f = accel_intersect(&a, org[k], dir[k], INFINITY, 0.0f, &h);
                cr_assert_eq(found[k], f, "trial %u, n %u, ray %u: found %d, single %d", t, n, k, found[k], f);
                /* Counted only where Embree's packet kernels ran (smaller n go one by one). */
                if (!f) {
                    misses += n >= 4;
                    continue;
                }
                hits += n >= 4;
                cr_assert(h.geom == ph[k].geom && h.prim == ph[k].prim && memcmp(&h.t, &ph[k].t, sizeof h.t) == 0 &&
                              memcmp(&h.u, &ph[k].u, sizeof h.u) == 0 && memcmp(&h.v, &ph[k].v, sizeof h.v) == 0,
                          "trial %u, n %u, ray %u: packet hit differs from the single ray's", t, n, k);
            }
        }
    cr_assert(hits > 100 && misses > 100, "hits %u, misses %u: both kinds must occur", hits, misses);
    accel_fini(&a);
    scene_fini(&s);
}

Test(accel, intersect_packet_equals_single_rays)
{
    uint32_t n = 0;
    for (unsigned i = 0; i < EMBREE_ISA_COUNT_; i++)
        if (embree_isa_supported((enum embree_isa)i)) {
            intersect_packet_check((enum embree_isa)i);
            n++;
        }
    cr_assert(n >= 1, "no instruction set of Embree's runs here");
}

static void occluded_packet_check(enum embree_isa isa)
{
    struct scene s;
    struct accel a;
    load_isa(&s, &a, isa);
    uint32_t blocked = 0, clear = 0;
    const float tmax = 1.0f - 0x1p-12f; /* as the path tracer's shadow rays: short of the target */
    for (uint32_t t = 0; t < 40; t++)
        for (uint32_t n = 1; n <= ACCEL_PACKET; n++) {
            vec3 org[ACCEL_PACKET], dir[ACCEL_PACKET];
            float time01[ACCEL_PACKET];
            int occ[ACCEL_PACKET];
            for (uint32_t k = 0; k < n; k++) {
                vec3 target;
                ray(t, k, &org[k], &target);
                dir[k] = v3_sub(target, org[k]); /* the segment: t in (0, tmax) */
                time01[k] = 0.0f;
            }
            accel_occluded_packet(&a, n, org, dir, tmax, time01, occ);
            for (uint32_t k = 0; k < n; k++) {
                int o = accel_occluded(&a, org[k], dir[k], tmax, 0.0f);
                cr_assert_eq(occ[k], o, "trial %u, n %u, segment %u: packet %d, single %d", t, n, k, occ[k], o);
                if (n >= 4) { /* where the packet kernels ran */
                    blocked += o != 0;
                    clear += o == 0;
                }
            }
        }
    cr_assert(blocked > 100 && clear > 100, "blocked %u, clear %u: both kinds must occur", blocked, clear);
    accel_fini(&a);
    scene_fini(&s);
}

Test(accel, occluded_packet_equals_single_rays)
{
    for (unsigned i = 0; i < EMBREE_ISA_COUNT_; i++)
        if (embree_isa_supported((enum embree_isa)i))
            occluded_packet_check((enum embree_isa)i);
}

/* The instruction sets' names round trip; each one this CPU runs starts an Embree device
 * with the config the job's builds use; the default (0) is AVX2. */
Test(accel, embree_isa_names_and_devices)
{
    char config[64], err[256];
    cr_assert_eq(EMBREE_ISA_AVX2, 0);
    for (unsigned i = 0; i < EMBREE_ISA_COUNT_; i++) {
        enum embree_isa isa;
        cr_assert_eq(embree_isa_from_name(embree_isa_name((enum embree_isa)i), &isa), 0);
        cr_assert_eq((unsigned)isa, i);
        int ok = embree_device_config((enum embree_isa)i, 1, config, sizeof config, err, sizeof err);
        cr_assert_eq(ok == 0, embree_isa_supported((enum embree_isa)i) != 0);
        if (ok != 0) {
            cr_assert(strstr(err, embree_isa_name((enum embree_isa)i)), "%s", err);
            continue;
        }
        cr_assert(strstr(config, embree_isa_name((enum embree_isa)i)), "%s", config);
        RTCDevice d = rtcNewDevice(config);
        cr_assert(d != NULL, "%s: error %d", config, (int)rtcGetDeviceError(NULL));
        rtcReleaseDevice(d);
    }
    enum embree_isa isa = EMBREE_ISA_SSE42;
    cr_assert_eq(embree_isa_from_name("avx9", &isa), -1);
    cr_assert_eq(embree_isa_from_name("", &isa), -1);
    cr_assert_eq(isa, EMBREE_ISA_SSE42);
}

/* A shadow segment toward a point past Embree's bound on a ray (a light 1e19 away) is
 * still traced (scaled by a power of two): blocked where the blocker or the floor stands
 * in the way, clear where nothing does; packets agree. */
Test(accel, occluded_toward_a_point_beyond_the_ray_bound)
{
    struct scene s;
    struct accel a;
    load(&s, &a);
    const float tmax = 1.0f - 0x1p-12f;
    const vec3 o = v3(0.0f, 0.5f, 0.0f); /* between the floor (y = 0) and the blocker (y = 1) */
    const vec3 target[4] = {v3(0.0f, 1e19f, 0.0f), v3(0.0f, -1e19f, 0.0f), v3(1e19f, 0.5f, 0.0f), v3(0.0f, 3e38f, 0.0f)};
    const int want[4] = {1, 1, 0, 1};
    vec3 org[4], dir[4];
    float time01[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    int occ[4];
    for (int k = 0; k < 4; k++) {
        org[k] = o;
        dir[k] = v3_sub(target[k], o);
        cr_assert(!accel_ray_ok_(org[k], dir[k]), "segment %d must pass the bound", k);
        cr_assert_eq(accel_occluded(&a, org[k], dir[k], tmax, 0.0f), want[k], "segment %d", k);
    }
    accel_occluded_packet(&a, 4, org, dir, tmax, time01, occ);
    for (int k = 0; k < 4; k++)
        cr_assert_eq(occ[k], want[k], "packet, segment %d", k);
    accel_fini(&a);
    scene_fini(&s);
}
