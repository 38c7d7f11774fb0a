/* libFuzzer target for the photon map decoder (common/render/photon_map.c), which reads the volume
 * blob a worker fetches from the master. The input picks the first map's photon count
 * (byte 0) and table size (byte 1, a power of two) and supplies its photons and bucket
 * table, so the header fits and the decoder's deeper checks (bucket order, positions) are
 * reached; whatever input is left follows as a second map (the surface map) behind a
 * "BVPM0002" magic. The raw input is also decoded as it is, and as a volume blob (the
 * progressive passes' maps behind a "BVOL0002" header), and the built map is wrapped in
 * a volume blob of up to three passes whose header fields and map sizes the input also
 * sets; the input also serves as photon beams (a beams section behind an empty map). A
 * decoded map then answers every lookup at a few points. Built and run by
 * tests/fuzz/run.sh. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include "base/log.h"
#include "render/photon_map.h"
#include "render/photon_beams.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static void put_u32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}

static void exercise(const uint8_t *blob, size_t n)
{
    struct photon_map *m = NULL;
    char err[256];
    if (photon_map_decode(blob, n, &m, err, sizeof err) != 0)
        return;
    static const float pts[4][3] = {{0, 0, 0}, {0.3f, -0.2f, 0.9f}, {1e6f, 0, 0}, {-0.5f, 0.5f, 0.25f}};
    struct medium md;
    memset(&md, 0, sizeof md);
    md.sigma_a = v3(0.1f, 0.1f, 0.1f);
    md.sigma_s = v3(1, 1, 1);
    md.sigma_t = v3_add(md.sigma_a, md.sigma_s);
    for (int i = 0; i < 4; i++) {
        vec3 x = v3(pts[i][0], pts[i][1], pts[i][2]);
        (void)photon_map_gather_knn(m, x, v3(0, 1, 0), -0.2f, 8, 4.0f * m->radius, PHOTON_DEPTH_ANY, 0.7f, 2.0f);
        (void)photon_map_beam(m, x, v3(0, 0, 1), 2.0f, &md, NULL, PHOTON_DEPTH_ANY);
        (void)photon_map_surface(m, x, v3(0, 1, 0), PHOTON_DEPTH_ANY);
        if (m->beams) {
            (void)photon_beams_estimate(m->beams, x, v3(0, 0, 1), 2.0f, &md, NULL, PHOTON_DEPTH_ANY);
            (void)photon_beams_estimate(m->beams, x, v3_normalize(v3(1, -1, 0.5f)), 1e3f, &md, NULL, 3);
        }
    }
    photon_map_free(&m);
}

/* The input as photon beams behind an empty volume map: the beams' section with its header
 * (count from the input's length, sometimes one off) and the input's bytes as beams. */
static void exercise_beams(const uint8_t *data, size_t size)
{
    if (size < 1)
        return;
    uint32_t n = (uint32_t)((size - 1) / sizeof(struct photon_beam));
    size_t map = 48 + 8, sec = PB_HEADER + sizeof(struct photon_beam) * (size_t)n, total = map + sec;
    uint8_t *b = mem_calloc(total, 1);
    memcpy(b, "BVPM0002", 8);
    put_u32(b + 12, 1); /* table size */
    b[16] = 100;
    float r = 0.25f, c = 0.5f, rb = data[0] & 1 ? 0.05f : 3.0f;
    memcpy(b + 24, &r, 4);
    memcpy(b + 28, &c, 4);
    uint8_t *s = b + map;
    memcpy(s, PB_MAGIC, 8);
    put_u32(s + 8, n + (data[0] & 0x80 ? 1 : 0));
    s[16] = 100;
    memcpy(s + 24, &rb, 4);
    memcpy(s + PB_HEADER, data + 1, sec - PB_HEADER);
    exercise(b, total);
    free(b);
}

/* A volume blob: every map of the chain answers the lookups. */
static void exercise_blob(const uint8_t *blob, size_t n)
{
    struct photon_map *maps = NULL;
    struct scene_media st;
    uint32_t count = 0;
    char err[256];
    memset(&st, 0, sizeof st);
    if (volume_blob_decode(blob, n, &st, &maps, &count, err, sizeof err) != 0)
        return;
    static const float pts[2][3] = {{0, 0, 0}, {0.3f, -0.2f, 0.9f}};
    for (const struct photon_map *m = maps; m; m = m->next_pass)
        for (int i = 0; i < 2; i++) {
            vec3 x = v3(pts[i][0], pts[i][1], pts[i][2]);
            (void)photon_map_gather_knn(m, x, v3(0, 1, 0), 0.3f, 4, 4.0f * m->radius, PHOTON_DEPTH_ANY, 1.0f, 0.0f);
            (void)photon_map_surface(m, x, v3(0, 1, 0), PHOTON_DEPTH_ANY);
        }
    photon_map_free(&maps);
}

static void put_u64(uint8_t *p, uint64_t v)
{
    for (int i = 0; i < 8; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    exercise(data, size);
    exercise_blob(data, size);
    exercise_beams(data, size);
    if (size < 2)
        return 0;
    uint32_t n = data[0], table = 1u << (data[1] % 8);
    size_t body = sizeof(struct photon) * n + 4 * ((size_t)table + 1);
    size_t avail = size - 2, take = avail < body ? avail : body;
    size_t rest = avail - take, total = 48 + body + (rest ? 8 + rest : 0);
    uint8_t *b = mem_calloc(total, 1);
    memcpy(b, "BVPM0002", 8);
    put_u32(b + 8, n);
    put_u32(b + 12, table);
    b[16] = 100; /* photons emitted */
    float r = 0.25f, c = 0.5f;
    memcpy(b + 24, &r, 4);
    memcpy(b + 28, &c, 4);
    memcpy(b + 48, data + 2, take);
    if (rest) {
        memcpy(b + 48 + body, "BVPM0002", 8);
        memcpy(b + 48 + body + 8, data + 2 + take, rest);
    }
    exercise(b, total);
    /* The map as 1..3 passes of a volume blob: the count and the first size from the input
     * (mostly right, sometimes off), so the blob's own checks and the maps' both run. */
    uint32_t passes = 1 + data[0] % 3;
    size_t vsize = 48 + passes * (8 + total);
    uint8_t *vb = mem_calloc(vsize, 1);
    memcpy(vb, "BVOL0002", 8);
    put_u32(vb + 8, data[1] % 5);                      /* method (4: out of range) */
    memcpy(vb + 16, &r, 4);                            /* radius */
    put_u32(vb + 20, passes + (data[1] >> 7));         /* sometimes one map more than there are */
    float alpha = 2.0f / 3.0f;
    memcpy(vb + 32, &alpha, 4);
    for (uint32_t p = 0; p < passes; p++) {
        size_t at = 48 + p * (8 + total);
        put_u64(vb + at, total + (p == 0 && (data[1] & 0x40) ? 1 : 0));
        memcpy(vb + at + 8, b, total);
    }
    exercise_blob(vb, vsize);
    free(vb);
    free(b);
    return 0;
}
