/* The photon map (see photon_map.h): the photons' encodings, the hash grid, the blob
 * written by the master and decoded (every size and index checked) by workers, and the
 * radiance estimates. No tracing here: photon_trace.c fills the lists this serialises. */
#include "render/photon_map.h"
#include "render/photon_beams.h"
#include "scene/grid.h"
#include "base/bytes.h"
#include "base/log.h"
#include <emmintrin.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

_Static_assert(sizeof(struct photon) == 20, "photons are 20 bytes on the wire");

#define PM_MAGIC "BVPM0002"
#define PM_HEADER 48
/* Kernels use at least this radius and estimates saturate at 1e30, so a gather radius
 * near 0 cannot turn one photon into an infinite estimate. */
#define PM_MIN_KERNEL_RADIUS 1e-9

/* ---- encodings ---- */

uint16_t photon_dir_encode(vec3 d)
{
    float s = fabsf(d.x) + fabsf(d.y) + fabsf(d.z);
    float x = d.x / s, y = d.y / s;
    if (d.z < 0.0f) {
        float ox = (1.0f - fabsf(y)) * (x >= 0.0f ? 1.0f : -1.0f);
        float oy = (1.0f - fabsf(x)) * (y >= 0.0f ? 1.0f : -1.0f);
        x = ox, y = oy;
    }
    int qx = (int)lrintf((x * 0.5f + 0.5f) * 255.0f), qy = (int)lrintf((y * 0.5f + 0.5f) * 255.0f);
    qx = qx < 0 ? 0 : (qx > 255 ? 255 : qx);
    qy = qy < 0 ? 0 : (qy > 255 ? 255 : qy);
    return (uint16_t)(qx | qy << 8);
}

vec3 photon_dir_decode(uint16_t e)
{
    float x = (float)(e & 255) / 255.0f * 2.0f - 1.0f, y = (float)(e >> 8) / 255.0f * 2.0f - 1.0f;
    float z = 1.0f - fabsf(x) - fabsf(y);
    if (z < 0.0f) {
        float ox = (1.0f - fabsf(y)) * (x >= 0.0f ? 1.0f : -1.0f);
        float oy = (1.0f - fabsf(x)) * (y >= 0.0f ? 1.0f : -1.0f);
        x = ox, y = oy;
    }
    return v3_normalize(v3(x, y, z));
}

/* ---- hash grid ---- */

static uint32_t bucket_of(int32_t ix, int32_t iy, int32_t iz, uint32_t mask)
{
    uint32_t h = ((uint32_t)ix * 73856093u) ^ ((uint32_t)iy * 19349663u) ^ ((uint32_t)iz * 83492791u);
    return h & mask;
}

static int32_t cell_coord(float x, float inv_cell)
{
    float f = floorf(x * inv_cell);
    f = f < -1e9f ? -1e9f : (f > 1e9f ? 1e9f : f);
    if (!(f == f))
        f = 0.0f; /* NaN (an infinite inverse times 0): any cell; callers check distances */
    return (int32_t)f;
}

static int host_little_endian(void)
{
    uint16_t x = 1;
    uint8_t b;
    memcpy(&b, &x, 1);
    return b == 1;
}

int photon_map_serialise(struct photon_list *blocks, uint32_t num_blocks, float radius, uint64_t emitted,
                         uint8_t **out_map, size_t *bytes_out, uint32_t *n_out, char *err, size_t errlen)
{
    uint64_t total = 0;
    for (uint32_t b = 0; b < num_blocks; b++)
        total += blocks[b].n;
    int big_endian = !host_little_endian();
    if (total > UINT32_MAX / 2 || big_endian) {
        for (uint32_t b = 0; b < num_blocks; b++)
            free(blocks[b].a);
        str_fmt(err, errlen, big_endian ? "photon pass: big-endian hosts are not supported"
                                        : "photon pass: too many photons stored");
        return -1;
    }
    uint32_t n = (uint32_t)total;
    uint32_t table = 1;
    while (table < n / 2)
        table <<= 1;
    float cell = 2.0f * radius, inv = 1.0f / cell;
    /* A counting sort by bucket straight from the blocks into the map's bytes: no joined
     * or sorted copy of the photons on the way. */
    uint32_t *start = mem_calloc((size_t)table + 1, sizeof *start), *bk = mem_alloc(sizeof *bk * (n ? n : 1));
    for (uint32_t b = 0, i = 0; b < num_blocks; b++)
        for (uint32_t j = 0; j < blocks[b].n; j++, i++) {
            const float *p = blocks[b].a[j].p;
            bk[i] = bucket_of(cell_coord(p[0], inv), cell_coord(p[1], inv), cell_coord(p[2], inv), table - 1);
            start[bk[i] + 1]++;
        }
    for (uint32_t i = 0; i < table; i++)
        start[i + 1] += start[i];
    size_t bytes = PM_HEADER + sizeof(struct photon) * (size_t)n + 4 * ((size_t)table + 1);
    uint8_t *out = mem_alloc(bytes);
    memset(out, 0, PM_HEADER);
    memcpy(out, PM_MAGIC, 8);
    bytes_put_u32(out + 8, n);
    bytes_put_u32(out + 12, table);
    bytes_put_u64(out + 16, emitted);
    bytes_put_f32(out + 24, radius);
    bytes_put_f32(out + 28, cell);
    uint32_t *fill = mem_alloc(sizeof *fill * table);
    memcpy(fill, start, sizeof *fill * table);
    uint8_t *photons = out + PM_HEADER;
    for (uint32_t b = 0, i = 0; b < num_blocks; b++) {
        for (uint32_t j = 0; j < blocks[b].n; j++, i++)
            memcpy(photons + sizeof(struct photon) * (size_t)fill[bk[i]]++, &blocks[b].a[j], sizeof(struct photon));
        free(blocks[b].a);
    }
    free(fill);
    free(bk);
    uint8_t *sp = out + PM_HEADER + sizeof(struct photon) * (size_t)n;
    for (uint32_t i = 0; i <= table; i++)
        bytes_put_u32(sp + 4 * (size_t)i, start[i]);
    free(start);
    *out_map = out;
    *bytes_out = bytes;
    *n_out = n;
    return 0;
}

size_t photon_map_serialised_bytes(const uint8_t *map)
{
    return PM_HEADER + sizeof(struct photon) * (size_t)bytes_get_u32(map + 8) + 4 * ((size_t)bytes_get_u32(map + 12) + 1);
}

int photon_map_set_radius(uint8_t *map, size_t bytes, float radius, char *err, size_t errlen)
{
    CHECK(bytes >= PM_HEADER && memcmp(map, PM_MAGIC, 8) == 0 && photon_map_serialised_bytes(map) == bytes);
    if (bytes_get_f32(map + 24) == radius)
        return 0;
    uint32_t n = bytes_get_u32(map + 8);
    struct photon_list block = {mem_alloc(sizeof *block.a * (n ? n : 1)), n, n};
    memcpy(block.a, map + PM_HEADER, sizeof *block.a * (size_t)n);
    uint8_t *again = NULL;
    size_t again_bytes = 0;
    uint32_t count = 0;
    if (photon_map_serialise(&block, 1, radius, bytes_get_u64(map + 16), &again, &again_bytes, &count, err, errlen) != 0)
        return -1;
    CHECK(again_bytes == bytes); /* the bucket table's size depends on the photon count alone */
    memcpy(map, again, bytes);
    free(again);
    return 0;
}

struct photon_beam_grid;
static struct photon_beam_grid *beam_grid_build(const struct photon_map *m, int row_axis);
static void beam_grid_free(struct photon_beam_grid *g);

/* One map at the start of data: its size (from its header) goes to *used. */
static int decode_one(const uint8_t *data, size_t size, size_t *used, struct photon_map **out, char *err,
                      size_t errlen)
{
    *out = NULL;
    if (size < PM_HEADER || memcmp(data, PM_MAGIC, 8) != 0) {
        str_fmt(err, errlen, "photon map: not a photon map (bad header)");
        return -1;
    }
    if (!host_little_endian()) {
        str_fmt(err, errlen, "photon map: big-endian hosts are not supported");
        return -1;
    }
    uint32_t n = bytes_get_u32(data + 8), table = bytes_get_u32(data + 12);
    uint64_t emitted = bytes_get_u64(data + 16);
    float radius = bytes_get_f32(data + 24), cell = bytes_get_f32(data + 28);
    if (table == 0 || (table & (table - 1)) != 0 || table > (1u << 30) || n > UINT32_MAX / 2 ||
        !(radius > 0.0f) || !isfinite(radius) || cell != 2.0f * radius || !isfinite(1.0f / cell) ||
        size < PM_HEADER + sizeof(struct photon) * (uint64_t)n + 4 * ((uint64_t)table + 1)) {
        str_fmt(err, errlen, "photon map: inconsistent sizes in the header");
        return -1;
    }
    *used = PM_HEADER + sizeof(struct photon) * (size_t)n + 4 * ((size_t)table + 1);
    struct photon_map *m = mem_calloc(1, sizeof *m);
    m->num_photons = n;
    m->table_size = table;
    m->num_emitted = emitted;
    m->radius = radius;
    m->cell_size = cell;
    m->photons = mem_alloc(sizeof *m->photons * (n ? n : 1));
    if (n)
        memcpy(m->photons, data + PM_HEADER, sizeof *m->photons * (size_t)n);
    m->bucket_start = mem_alloc(sizeof *m->bucket_start * ((size_t)table + 1));
    const uint8_t *sp = data + PM_HEADER + sizeof(struct photon) * (size_t)n;
    memcpy(m->bucket_start, sp, 4 * ((size_t)table + 1)); /* little-endian, as the host (checked above) */
    int ok = m->bucket_start[0] == 0 && m->bucket_start[table] == n;
    for (uint32_t i = 0; ok && i < table; i++)
        ok = m->bucket_start[i] <= m->bucket_start[i + 1];
    for (uint32_t i = 0; ok && i < n; i++)
        ok = isfinite(m->photons[i].p[0]) && isfinite(m->photons[i].p[1]) && isfinite(m->photons[i].p[2]) &&
             PHOTON_EVENTS(m->photons[i].depth) >= 1 && PHOTON_EVENTS(m->photons[i].depth) <= PHOTON_DEPTH_MAX;
    if (!ok) {
        str_fmt(err, errlen, "photon map: bucket table, photon positions or depths are invalid");
        photon_map_free(&m);
        return -1;
    }
    /* Decoded direction and power per photon (reader side only, never serialised): the
     * lookups read them for the photons they accept. */
    m->decoded = mem_alloc(sizeof *m->decoded * (n ? n : 1));
    for (uint32_t i = 0; i < n; i++) {
        vec3 dd = photon_dir_decode(m->photons[i].dir), pw = photon_rgbe_decode(m->photons[i].rgbe);
        m->decoded[i] = (struct photon_decoded){{dd.x, dd.y, dd.z}, {pw.x, pw.y, pw.z},
                                                photon_density_floor(m->photons[i].depth)};
    }
    *out = m;
    return 0;
}

int photon_map_row_axis(vec3 d)
{
    float a[3] = {fabsf(d.x), fabsf(d.y), fabsf(d.z)};
    int k = a[1] > a[0] ? 1 : 0;
    return a[2] > a[k] ? 2 : k;
}

int photon_map_decode(const uint8_t *data, size_t size, struct photon_map **out, char *err, size_t errlen)
{
    return photon_map_decode_rows(data, size, 0, out, err, errlen);
}

int photon_map_decode_rows(const uint8_t *data, size_t size, int row_axis, struct photon_map **out, char *err,
                           size_t errlen)
{
    size_t used = 0, used2 = 0;
    if (decode_one(data, size, &used, out, err, errlen) != 0)
        return -1;
    /* What may follow: a surface map (the same photon count; its radius may differ:
     * progressive passes shrink it by the 2D rule, the volume map's by the 3D or 1D one),
     * then the photon beams' section (photon_beams.h), each at most once, in this order. */
    if (used < size && !photon_beams_is_section(data + used, size - used)) {
        struct photon_map *s = NULL;
        if (decode_one(data + used, size - used, &used2, &s, err, errlen) != 0 || s->num_emitted != (*out)->num_emitted) {
            if (s)
                str_fmt(err, errlen, "photon map: the surface map does not fit the blob or the volume map");
            photon_map_free(&s);
            photon_map_free(out);
            return -1;
        }
        (*out)->surface = s;
        used += used2;
    }
    if (used < size) {
        if (!photon_beams_is_section(data + used, size - used)) {
            str_fmt(err, errlen, "photon map: %zu unknown bytes after the maps", size - used);
            photon_map_free(out);
            return -1;
        }
        if (photon_beams_decode(data + used, size - used, &(*out)->beams, err, errlen) != 0) {
            photon_map_free(out);
            return -1;
        }
    }
    (*out)->beam = beam_grid_build(*out, row_axis >= 0 && row_axis < 3 ? row_axis : 0);
    return 0;
}

void photon_map_free(struct photon_map **pm)
{
    struct photon_map *m = *pm;
    *pm = NULL;
    while (m) { /* the passes' chain, iteratively (up to VOLUME_BLOB_MAX_MAPS long) */
        struct photon_map *next = m->next_pass;
        photon_map_free(&m->surface);
        photon_beams_free(&m->beams);
        free(m->decoded);
        free(m->photons);
        free(m->bucket_start);
        beam_grid_free(m->beam);
        free(m);
        m = next;
    }
}

double photon_pass_radius(double r0, double alpha, uint32_t pass, int dim)
{
    double rd = 1.0;
    for (uint32_t p = 1; p <= pass; p++)
        rd *= ((double)p + alpha) / ((double)p + 1.0);
    return r0 * pow(rd, 1.0 / (double)dim);
}

/* ---- lookups ---- */

/* ---- the forward cone ---- */

/* Henyey-Greenstein without the forward cone, in float for the lookups' inner loops. */
static inline float phase_hg_fast(float cos_theta, float g)
{
    if (cos_theta > MEDIUM_FORWARD_COS)
        return 0.0f;
    float d = 1.0f + g * g - 2.0f * g * cos_theta;
    d = d > 1e-30f ? d : 1e-30f;
    return (1.0f - g * g) / (4.0f * (float)M_PI * d * sqrtf(d));
}

/* phase x power of a decoded photon for light leaving along d_out. */
static inline vec3 decoded_contrib(const struct photon_decoded *pd, vec3 d_out, float g)
{
    float p = phase_hg_fast(pd->dir[0] * d_out.x + pd->dir[1] * d_out.y + pd->dir[2] * d_out.z, g);
    return v3(p * pd->power[0], p * pd->power[1], p * pd->power[2]);
}

/* phase x power of photon i for light leaving along d_out. */
static inline vec3 photon_contrib(const struct photon_map *m, uint32_t i, vec3 d_out, float g)
{
    if (m->decoded)
        return decoded_contrib(&m->decoded[i], d_out, g);
    const struct photon *ph = &m->photons[i];
    return v3_scale(photon_rgbe_decode(ph->rgbe), phase_hg_cut(v3_dot(photon_dir_decode(ph->dir), d_out), g));
}

/* Visits each bucket of the cells [lo, hi] once (hash collisions would repeat them). */
#define MAX_VISIT 64

static uint32_t collect_buckets(const struct photon_map *m, vec3 lo, vec3 hi, uint32_t *out)
{
    float inv = 1.0f / m->cell_size;
    int32_t x0 = cell_coord(lo.x, inv), y0 = cell_coord(lo.y, inv), z0 = cell_coord(lo.z, inv);
    int32_t x1 = cell_coord(hi.x, inv), y1 = cell_coord(hi.y, inv), z1 = cell_coord(hi.z, inv);
    uint32_t nb = 0;
    for (int32_t z = z0; z <= z1 && z - z0 < 4; z++)
        for (int32_t y = y0; y <= y1 && y - y0 < 4; y++)
            for (int32_t x = x0; x <= x1 && x - x0 < 4; x++) {
                uint32_t b = bucket_of(x, y, z, m->table_size - 1);
                int seen = 0;
                for (uint32_t i = 0; i < nb && !seen; i++)
                    seen = out[i] == b;
                if (!seen && nb < MAX_VISIT)
                    out[nb++] = b;
            }
    return nb;
}

/* The buckets of the cells the sphere of radius r around x touches. */
static uint32_t sphere_buckets(const struct photon_map *m, vec3 x, float r, uint32_t *buckets)
{
    return collect_buckets(m, v3(x.x - r, x.y - r, x.z - r), v3(x.x + r, x.y + r, x.z + r), buckets);
}

/* acc times k, saturated at 1e30 (a near-zero kernel radius cannot give infinity). */
static vec3 scaled(const double acc[3], double k)
{
    return v3((float)fmin(acc[0] * k, 1e30), (float)fmin(acc[1] * k, 1e30), (float)fmin(acc[2] * k, 1e30));
}

vec3 photon_map_surface(const struct photon_map *vm, vec3 x, vec3 n, uint32_t depth_max)
{
    const struct photon_map *m = vm ? vm->surface : NULL;
    if (!m || m->num_photons == 0)
        return v3(0, 0, 0);
    float r = m->radius, r2 = r * r, slab = 0.25f * r;
    uint32_t buckets[MAX_VISIT];
    uint32_t nb = sphere_buckets(m, x, r, buckets);
    double acc[3] = {0, 0, 0};
    for (uint32_t bi = 0; bi < nb; bi++)
        for (uint32_t i = m->bucket_start[buckets[bi]]; i < m->bucket_start[buckets[bi] + 1]; i++) {
            const struct photon *ph = &m->photons[i];
            vec3 dp = v3_sub(v3(ph->p[0], ph->p[1], ph->p[2]), x);
            if (PHOTON_EVENTS(ph->depth) > depth_max || v3_dot(dp, dp) > r2 || fabsf(v3_dot(dp, n)) > slab)
                continue;
            const struct photon_decoded *pd = m->decoded ? &m->decoded[i] : NULL;
            vec3 dir = pd ? v3(pd->dir[0], pd->dir[1], pd->dir[2]) : photon_dir_decode(ph->dir);
            if (v3_dot(dir, n) >= 0.0f)
                continue; /* arrived on the other side */
            vec3 pw = pd ? v3(pd->power[0], pd->power[1], pd->power[2]) : photon_rgbe_decode(ph->rgbe);
            acc[0] += pw.x, acc[1] += pw.y, acc[2] += pw.z;
        }
    double rk = fmax((double)r, PM_MIN_KERNEL_RADIUS);
    return scaled(acc, 1.0 / (M_PI * rk * rk));
}

/* Max-heap on squared distance (the root is the farthest of the k kept). */
struct knn_item { float d2; uint32_t i; };

static void heap_sift_down(struct knn_item *h, uint32_t n, uint32_t i)
{
    for (;;) {
        uint32_t l = 2 * i + 1, r = l + 1, m = i;
        if (l < n && (h[l].d2 > h[m].d2 || (h[l].d2 == h[m].d2 && h[l].i > h[m].i)))
            m = l;
        if (r < n && (h[r].d2 > h[m].d2 || (h[r].d2 == h[m].d2 && h[r].i > h[m].i)))
            m = r;
        if (m == i)
            return;
        struct knn_item t = h[i];
        h[i] = h[m], h[m] = t;
        i = m;
    }
}

static void heap_sift_up(struct knn_item *h, uint32_t i)
{
    while (i > 0) {
        uint32_t p = (i - 1) / 2;
        if (!(h[i].d2 > h[p].d2 || (h[i].d2 == h[p].d2 && h[i].i > h[p].i)))
            return;
        struct knn_item t = h[i];
        h[i] = h[p], h[p] = t;
        i = p;
    }
}

/* Offers the photons of bucket b to the heap of the k nearest within r2max. */
static void knn_bucket(const struct photon_map *m, uint32_t b, vec3 x, uint32_t k, float r2max, struct knn_item *h,
                       uint32_t *n)
{
    for (uint32_t i = m->bucket_start[b]; i < m->bucket_start[b + 1]; i++) {
        const struct photon *ph = &m->photons[i];
        vec3 dp = v3_sub(v3(ph->p[0], ph->p[1], ph->p[2]), x);
        float d2 = v3_dot(dp, dp);
        if (!(d2 <= r2max))
            continue;
        if (*n < k) {
            h[*n] = (struct knn_item){d2, i};
            heap_sift_up(h, (*n)++);
        } else if (d2 < h[0].d2 || (d2 == h[0].d2 && i < h[0].i)) {
            h[0] = (struct knn_item){d2, i};
            heap_sift_down(h, *n, 0);
        }
    }
}

#define KNN_MAX_RING 8          /* cells searched around x's cell: rmax is capped at 8 cells */
#define KNN_SEEN 8192           /* buckets remembered per query (hash collisions repeat them) */

uint32_t photon_map_knn(const struct photon_map *m, vec3 x, uint32_t k, float rmax, uint32_t *idx, float *r2_out)
{
    *r2_out = 0.0f;
    if (!m || m->num_photons == 0 || k == 0)
        return 0;
    if (k > PM_KNN_MAX)
        k = PM_KNN_MAX;
    float cs = m->cell_size, inv = 1.0f / cs;
    rmax = fminf(rmax, (float)KNN_MAX_RING * cs);
    if (!(rmax > 0.0f) || !isfinite(x.x + x.y + x.z))
        return 0;
    float r2max = rmax * rmax;
    int32_t cx = cell_coord(x.x, inv), cy = cell_coord(x.y, inv), cz = cell_coord(x.z, inv);
    int32_t rings = (int32_t)ceilf(rmax * inv);
    if (rings > KNN_MAX_RING)
        rings = KNN_MAX_RING;
    struct knn_item h[PM_KNN_MAX];
    uint32_t n = 0, mask = m->table_size - 1, seen[KNN_SEEN], side = 2 * (uint32_t)rings + 1, set = 64;
    while (set < 2 * side * side * side && set < KNN_SEEN)
        set *= 2;
    memset(seen, 0xff, sizeof *seen * set);
    /* Rings of cells at Chebyshev distance s from x's cell hold only photons at least
     * (s - 1) cells away: stop once the k-th nearest is closer than that. */
    for (int32_t sr = 0; sr <= rings; sr++) {
        float gap = (float)(sr - 1) * cs;
        if (sr >= 1 && (gap > rmax || (n == k && h[0].d2 <= gap * gap)))
            break;
        for (int32_t dz = -sr; dz <= sr; dz++)
            for (int32_t dy = -sr; dy <= sr; dy++)
                for (int32_t dx = -sr; dx <= sr; dx++) {
                    if (abs(dx) != sr && abs(dy) != sr && abs(dz) != sr)
                        continue; /* inner cells: an earlier ring */
                    uint32_t b = bucket_of(cx + dx, cy + dy, cz + dz, mask);
                    uint32_t hs = (b * 2654435761u) & (set - 1);
                    while (seen[hs] != UINT32_MAX && seen[hs] != b)
                        hs = (hs + 1) & (set - 1);
                    if (seen[hs] == b)
                        continue;
                    seen[hs] = b;
                    knn_bucket(m, b, x, k, r2max, h, &n);
                }
    }
    for (uint32_t j = 0; j < n; j++)
        idx[j] = h[j].i;
    /* Fewer than k within rmax: the estimate's sphere is the maximum radius. */
    *r2_out = n == k ? h[0].d2 : r2max;
    return n;
}

vec3 photon_map_gather_knn(const struct photon_map *m, vec3 x, vec3 d_out, float g, uint32_t k, float rmax,
                           uint32_t depth_max, float rho, float grid_max)
{
    uint32_t idx[PM_KNN_MAX];
    float r2;
    uint32_t n = photon_map_knn(m, x, k, rmax, idx, &r2);
    if (n == 0)
        return v3(0, 0, 0);
    double acc[3] = {0, 0, 0};
    /* The k nearest of all photons, then only the short enough ones counted: the same
     * estimate as a ball of radius r_k holding just those, so still consistent. */
    for (uint32_t j = 0; j < n; j++) {
        uint16_t word = m->photons[idx[j]].depth;
        if (PHOTON_EVENTS(word) > depth_max)
            continue;
        vec3 c = photon_contrib(m, idx[j], d_out, g);
        if (grid_max > 0.0f)
            c = v3_scale(c, photon_density_weight(rho, m->decoded ? m->decoded[idx[j]].density_floor : photon_density_floor(word),
                                                  grid_max));
        acc[0] += c.x, acc[1] += c.y, acc[2] += c.z;
    }
    double rk = fmax(sqrt((double)r2), PM_MIN_KERNEL_RADIUS);
    return scaled(acc, 1.0 / (4.0 / 3.0 * M_PI * rk * rk * rk));
}

/* ---- the beam query: rows of photons along x ---- */

/* The beam estimate needs the photons within r of a segment, a thin tube, which the hash
 * grid's cells of 2r (and the buckets colliding cells share) cover only loosely. So the
 * reader sorts a copy of the volume map's positions into rows (photon_map_decode): cells
 * of k r across y and z, unbounded along x, a row's photons by x (then by index). A query
 * visits the rows the tube crosses, each only over the x interval the tube can reach there
 * (the segment clipped to the row's slabs grown by r), and reads just those photons, in an
 * order fixed by the map and the ray. Each row visited costs a lookup, each photon read a
 * distance test: k grows where photons are sparse (fewer rows, a few more photons), from 1
 * to BEAM_MAX_K as the photons' mean crowding c (a photon's count of photons in its bucket
 * of the blob's grid of 2r cells) falls. Per unit of ray length a walk visits about 1 / (k
 * r) rows and reads photons from a box of about 2r by k r across it, so the cost is least
 * at k ~ c^(-1/2): k = 2 (BEAM_CROWD / c)^(1/2), the constant measured on the three media
 * scenes (dense smoke: k = 1, fog_spot: 3.1, cornell_fog: 5.5).
 * Layout, for the cache: a row is found in a flat table of row starts indexed by its
 * (y, z) cell where the grid has at most BEAM_FLAT_PER_PHOTON cells per photon plus
 * BEAM_FLAT_CELLS, else (sparse or huge grids) in a hash table of the rows that hold
 * photons. The records are separate arrays in row order: x alone for the search within a
 * row (for rows of at most BEAM_LINEAR photons a count, four at a time, of those below the
 * interval; else a binary search), then
 * y, z and depth, read for the photons within the row's x interval, and a copy of the
 * decoded direction and power, read only for the photons accepted (in row order, so a
 * row's accepted photons share cache lines). The rows cost 38 bytes a photon
 * plus the row table (the flat one at most 16 bytes a photon plus 256 KiB). */
#define BEAM_CROWD 20.0
#define BEAM_MAX_K 8.0
#define BEAM_MAX_CELLS 32768.0f     /* cells per axis at most (tiny radii): walks stay bounded */
#define BEAM_FLAT_PER_PHOTON 4u
#define BEAM_FLAT_CELLS 65536u
#define BEAM_LINEAR 16u
#define BEAM_X_PAD 3u /* floats past the last photon's x: the four-at-a-time scan's loads */
/* Rounding slack, relative to the coordinates' largest magnitude s (ray origin, photons'
 * box): a photon the acceptance test takes (float arithmetic) is within r + about 20
 * epsilons x |p - o| of the ray; the walk pads r by 2 BEAM_SLACK s, over 130 epsilons x s. */
#define BEAM_SLACK 4e-6f

struct beam_row { uint32_t y, z, start, end; }; /* a hash slot; y == UINT32_MAX: empty */

struct photon_beam_grid {
    float lo[3], hi[3], scale;  /* the photons' box (in the grid's axes), its largest |coordinate| */
    uint8_t axis[3];            /* the world axis of the grid's x (along the rows), y and z */
    uint8_t world[3];           /* the grid's axis of world x, y and z */
    float cell, inv;
    uint32_t cmax[3];           /* the largest cell coordinate per axis: a far ray walks no further */
    uint32_t ny;                /* flat table: rows per z slab (cmax[1] + 1); 0: the hash table */
    uint32_t *row_start;        /* flat: row (y, z) is [row_start[z ny + y], row_start[z ny + y + 1]) */
    uint32_t mask;              /* hash: mask + 1 slots, at most half full */
    struct beam_row *rows;
    uint32_t num_rows, longest; /* rows holding photons, the most photons in one */
    /* num_photons records, by row, then x, then photon index */
    float *x, *y, *z;
    const float *wx, *wy, *wz; /* the same arrays in world x, y and z (x, y, z in world[] order) */
    uint16_t *depth;
    struct photon_decoded *dec; /* direction and power, a copy of the map's decoded photons */
};

static uint32_t beam_cell(const struct photon_beam_grid *g, float v, int axis)
{
    float f = floorf((v - g->lo[axis]) * g->inv); /* monotone in v: queries bound cells safely */
    if (!(f > 0.0f))
        return 0; /* also NaN */
    return f < (float)g->cmax[axis] ? (uint32_t)f : g->cmax[axis];
}

static uint32_t beam_row_slot(uint32_t y, uint32_t z, uint32_t mask)
{
    uint32_t h = y * 0x9e3779b1u ^ z * 0x85ebca77u;
    return (h ^ h >> 15) & mask;
}

/* Row (y, z)'s records [*start, *end); 0 when it holds none. */
static inline int beam_row_range(const struct photon_beam_grid *g, uint32_t y, uint32_t z, uint32_t *start,
                                 uint32_t *end)
{
    if (g->ny) {
        const uint32_t *rs = g->row_start + (size_t)z * g->ny + y;
        *start = rs[0], *end = rs[1];
        return rs[0] < rs[1];
    }
    for (uint32_t h = beam_row_slot(y, z, g->mask);; h = (h + 1) & g->mask) {
        const struct beam_row *r = &g->rows[h];
        if (r->y == y && r->z == z) {
            *start = r->start, *end = r->end;
            return 1;
        }
        if (r->y == UINT32_MAX)
            return 0;
    }
}

/* Sorts the keys and their photon indices (given in index order) by key, stably: LSD radix
 * sort, 16 bits a pass, so equal keys keep index order. */
static void beam_sort(uint64_t *key, uint32_t *idx, uint32_t n)
{
    uint64_t *k2 = mem_alloc(sizeof *k2 * n);
    uint32_t *i2 = mem_alloc(sizeof *i2 * n), *count = mem_alloc(sizeof *count * 65536);
    for (int shift = 0; shift < 64; shift += 16) {
        memset(count, 0, sizeof *count * 65536);
        for (uint32_t i = 0; i < n; i++)
            count[key[i] >> shift & 0xffff]++;
        for (uint32_t b = 0, sum = 0; b < 65536; b++) {
            uint32_t c = count[b];
            count[b] = sum;
            sum += c;
        }
        for (uint32_t i = 0; i < n; i++) {
            uint32_t j = count[key[i] >> shift & 0xffff]++;
            k2[j] = key[i];
            i2[j] = idx[i];
        }
        uint64_t *tk = key;
        key = k2, k2 = tk;
        uint32_t *ti = idx;
        idx = i2, i2 = ti;
    }
    free(k2); /* four passes: the sorted data is back in the caller's arrays */
    free(i2);
    free(count);
}

/* x as an unsigned key in the order of the floats (-0 just before +0, which compare equal). */
static uint32_t beam_x_key(float x)
{
    uint32_t u;
    memcpy(&u, &x, 4);
    return u >> 31 ? ~u : u | 0x80000000u;
}

/* The entries of a grid's row table beside n records (one each), from its cells (cmax)
 * and rows (num_rows): what beam_rows_index allocates and beam_grid_bytes counts. Flat
 * (row_starts = cells + 1, slots = 0) while the (y, z) cells are few beside the photons,
 * else a hash table (slots: a power of two, at most half full). */
struct beam_grid_sizes {
    size_t row_starts, slots;
};
static struct beam_grid_sizes beam_grid_sizes(const struct photon_beam_grid *g, uint32_t n)
{
    struct beam_grid_sizes z = {0, 0};
    uint64_t cells = (uint64_t)(g->cmax[1] + 1) * (g->cmax[2] + 1);
    if (cells <= (uint64_t)BEAM_FLAT_PER_PHOTON * n + BEAM_FLAT_CELLS) {
        z.row_starts = (size_t)cells + 1;
        return z;
    }
    z.slots = 2;
    while (z.slots < 2 * (size_t)g->num_rows)
        z.slots <<= 1;
    return z;
}

/* The row tables of the sorted keys (rows by z cell, then y cell, in the top 32 bits). */
static void beam_rows_index(struct photon_beam_grid *g, const uint64_t *key, uint32_t n)
{
    struct beam_grid_sizes sz = beam_grid_sizes(g, n);
    if (sz.row_starts) {
        g->ny = g->cmax[1] + 1;
        g->row_start = mem_calloc(sz.row_starts, sizeof *g->row_start);
        for (uint32_t j = 0; j < n; j++) /* count each row's records after its start ... */
            g->row_start[(size_t)(key[j] >> 48) * g->ny + (key[j] >> 32 & 0xffff) + 1]++;
        for (size_t c = 1; c < sz.row_starts; c++) /* ... and sum: rows are in key order */
            g->row_start[c] += g->row_start[c - 1];
        return;
    }
    uint32_t slots = (uint32_t)sz.slots;
    g->mask = slots - 1;
    g->rows = mem_alloc(sizeof *g->rows * slots);
    for (uint32_t s = 0; s < slots; s++)
        g->rows[s].y = UINT32_MAX;
    for (uint32_t j = 0, row_start = 0; j < n; j++) {
        if (j + 1 < n && key[j + 1] >> 32 == key[j] >> 32)
            continue;
        uint32_t y = (uint32_t)(key[j] >> 32 & 0xffff), z = (uint32_t)(key[j] >> 48);
        uint32_t h = beam_row_slot(y, z, g->mask);
        while (g->rows[h].y != UINT32_MAX)
            h = (h + 1) & g->mask;
        g->rows[h] = (struct beam_row){y, z, row_start, j + 1};
        row_start = j + 1;
    }
}

static struct photon_beam_grid *beam_grid_build(const struct photon_map *m, int row_axis)
{
    uint32_t n = m->num_photons;
    if (n == 0 || !m->decoded)
        return NULL;
    struct photon_beam_grid *g = mem_calloc(1, sizeof *g);
    for (int k = 0; k < 3; k++) {
        g->axis[k] = (uint8_t)((row_axis + k) % 3);
        g->world[g->axis[k]] = (uint8_t)k;
    }
    float lo[3], hi[3];
    for (int k = 0; k < 3; k++)
        lo[k] = hi[k] = m->photons[0].p[g->axis[k]];
    for (uint32_t i = 1; i < n; i++)
        for (int k = 0; k < 3; k++) {
            lo[k] = fminf(lo[k], m->photons[i].p[g->axis[k]]);
            hi[k] = fmaxf(hi[k], m->photons[i].p[g->axis[k]]);
        }
    float ext = 0.0f, scale = 0.0f;
    for (int k = 0; k < 3; k++) {
        g->lo[k] = lo[k];
        g->hi[k] = hi[k];
        ext = fmaxf(ext, hi[k] - lo[k]);
        scale = fmaxf(scale, fmaxf(fabsf(lo[k]), fabsf(hi[k])));
    }
    g->scale = scale;
    double crowd = 0.0;
    for (uint32_t b = 0; b < m->table_size; b++) {
        double c = (double)(m->bucket_start[b + 1] - m->bucket_start[b]);
        crowd += c * c / (double)n;
    }
    float kr = (float)fmin(fmax(2.0 * sqrt(BEAM_CROWD / fmax(crowd, 1.0)), 1.0), BEAM_MAX_K);
    /* Cells no smaller than the slack, so a tiny radius far from the origin does not make
     * a query walk thousands of rows across the slack alone. */
    g->cell = fmaxf(fmaxf(kr * m->radius, ext / BEAM_MAX_CELLS), fmaxf(BEAM_SLACK * scale, 1e-30f));
    g->inv = 1.0f / g->cell;
    for (int k = 0; k < 3; k++) {
        g->cmax[k] = (uint32_t)BEAM_MAX_CELLS + 1u; /* rounding's margin */
        g->cmax[k] = beam_cell(g, hi[k], k);
    }
    uint64_t *key = mem_alloc(sizeof *key * n);
    uint32_t *idx = mem_alloc(sizeof *idx * n);
    for (uint32_t i = 0; i < n; i++) {
        const float *p = m->photons[i].p;
        key[i] = (uint64_t)beam_cell(g, p[g->axis[2]], 2) << 48 | (uint64_t)beam_cell(g, p[g->axis[1]], 1) << 32 |
                 beam_x_key(p[g->axis[0]]);
        idx[i] = i;
    }
    beam_sort(key, idx, n); /* by row (z, y cells), then x, then index */
    g->x = mem_alloc(sizeof *g->x * ((size_t)n + BEAM_X_PAD)); /* the scan's loads pass a row's end */
    for (uint32_t k = 0; k < BEAM_X_PAD; k++)
        g->x[(size_t)n + k] = INFINITY;
    g->y = mem_alloc(sizeof *g->y * n);
    g->z = mem_alloc(sizeof *g->z * n);
    const float *const a[3] = {g->x, g->y, g->z};
    g->wx = a[g->world[0]], g->wy = a[g->world[1]], g->wz = a[g->world[2]];
    g->depth = mem_alloc(sizeof *g->depth * n);
    g->dec = mem_alloc(sizeof *g->dec * n);
    for (uint32_t j = 0, row_start = 0; j < n; j++) {
        const struct photon *ph = &m->photons[idx[j]];
        g->x[j] = ph->p[g->axis[0]], g->y[j] = ph->p[g->axis[1]], g->z[j] = ph->p[g->axis[2]];
        g->depth[j] = (uint16_t)PHOTON_EVENTS(ph->depth);
        g->dec[j] = m->decoded[idx[j]];
        if (j + 1 < n && key[j + 1] >> 32 == key[j] >> 32)
            continue;
        g->num_rows++;
        g->longest = j + 1 - row_start > g->longest ? j + 1 - row_start : g->longest;
        row_start = j + 1;
    }
    beam_rows_index(g, key, n);
    free(key);
    free(idx);
    return g;
}

static void beam_grid_free(struct photon_beam_grid *g)
{
    if (!g)
        return;
    free(g->row_start);
    free(g->rows);
    free(g->x);
    free(g->y);
    free(g->z);
    free(g->depth);
    free(g->dec);
    free(g);
}

/* The beam grid's records (n, as beam_grid_build allocates them) and tables (by
 * beam_grid_sizes, as beam_rows_index allocates them). */
static size_t beam_grid_bytes(const struct photon_beam_grid *g, uint32_t n)
{
    if (!g)
        return 0;
    struct beam_grid_sizes z = beam_grid_sizes(g, n);
    return sizeof *g + (size_t)n * (3 * sizeof *g->x + sizeof *g->depth + sizeof *g->dec) +
           BEAM_X_PAD * sizeof *g->x + z.row_starts * sizeof *g->row_start + z.slots * sizeof *g->rows;
}

size_t photon_map_bytes(const struct photon_map *m)
{
    size_t b = 0;
    for (; m; m = m->next_pass) {
        b += sizeof *m + (size_t)m->num_photons * sizeof *m->photons + ((size_t)m->table_size + 1) * sizeof *m->bucket_start;
        if (m->decoded)
            b += (size_t)m->num_photons * sizeof *m->decoded;
        b += beam_grid_bytes(m->beam, m->num_photons) + photon_beams_bytes(m->beams) + photon_map_bytes(m->surface);
    }
    return b;
}

int photon_map_beam_layout(const struct photon_map *m, float *cell, uint32_t *rows, uint32_t *longest)
{
    const struct photon_beam_grid *g = m ? m->beam : NULL;
    if (!g)
        return -1;
    *cell = g->cell;
    *rows = g->num_rows;
    *longest = g->longest;
    return g->ny != 0;
}

/* Plain comparisons: the operands are never NaN here, and libm's fminf is a call. */
static inline float beam_min(float a, float b) { return a < b ? a : b; }
static inline float beam_max(float a, float b) { return a > b ? a : b; }

struct beam_ray {
    vec3 o, d, d_out;   /* the ray, and -d */
    vec3 go, gd;        /* o and d in the rows' axes (photon_beam_grid.axis), for the walk */
    float t1, r2;
    float grid_max; /* md's grid's maximum density; 0 in a homogeneous medium */
    uint32_t depth_max;
    const struct medium *md;
    const struct photon_tau *tau;
};

/* A photon at closest-point parameter t that counts (beam_add's test passed): its phase x
 * power x transmittance to t into acc. pd: its decoded direction and power (the rows'
 * copy), or NULL to read photon i's from the map. */
static inline void beam_take(const struct photon_map *m, uint32_t i, const struct photon_decoded *pd, float t,
                             const struct beam_ray *br, double acc[3])
{
    float rho = 0.0f; /* with a table, the density the march took at t */
    vec3 tr = br->tau ? medium_tr_tau(br->md, photon_tau_depth_density(br->tau, t, &rho)) : medium_transmittance(br->md, t);
    float g = br->md->g;
    vec3 c = v3_mul(pd ? decoded_contrib(pd, br->d_out, g) : photon_contrib(m, i, br->d_out, g), tr);
    if (br->grid_max > 0.0f) {
        if (!br->tau)
            rho = grid_density(br->md->grid, v3_add(br->o, v3_scale(br->d, t)));
        float fl = pd ? pd->density_floor : photon_density_floor(m->photons[i].depth);
        c = v3_scale(c, photon_density_weight(rho, fl, br->grid_max));
    }
    acc[0] += c.x, acc[1] += c.y, acc[2] += c.z;
}

/* Photon i at (px, py, pz) counts when its closest-point parameter t lies in [0, t1), it
 * is within r of the ray and its depth is at most depth_max: then beam_take. */
static inline void beam_add(const struct photon_map *m, uint32_t i, const struct photon_decoded *pd, float px,
                            float py, float pz, uint32_t depth, const struct beam_ray *br, double acc[3])
{
    vec3 dp = v3_sub(v3(px, py, pz), br->o);
    float t = v3_dot(dp, br->d);
    if (!(t >= 0.0f && t < br->t1))
        return;
    vec3 perp = v3_sub(dp, v3_scale(br->d, t));
    if (v3_dot(perp, perp) > br->r2 || depth > br->depth_max)
        return;
    beam_take(m, i, pd, t, br, acc);
}

/* The photons [l, end) of a row up to the first past xhi along it, in order, into acc. Four at a
 * time, the geometric test of beam_add (t in [0, t1), squared distance to the ray not over
 * r^2) in SSE lanes with beam_add's operations in its order, so each lane's t is the
 * scalar one bit for bit; the photons it passes and whose depth passes go to beam_take with
 * that t in row order, so acc sums exactly what the plain loop sums. */
static void beam_row(const struct photon_map *m, const struct photon_beam_grid *g, const struct beam_ray *br,
                     uint32_t l, uint32_t end, float xhi, double acc[3])
{
    /* the photons' world x, y and z, and their coordinate along the rows */
    const float *xs = g->wx, *ys = g->wy, *zs = g->wz, *rx = g->x;
    const __m128 ox = _mm_set1_ps(br->o.x), oy = _mm_set1_ps(br->o.y), oz = _mm_set1_ps(br->o.z);
    const __m128 dx = _mm_set1_ps(br->d.x), dy = _mm_set1_ps(br->d.y), dz = _mm_set1_ps(br->d.z);
    const __m128 t1 = _mm_set1_ps(br->t1), r2 = _mm_set1_ps(br->r2), hi = _mm_set1_ps(xhi), zero = _mm_setzero_ps();
    uint32_t j = l;
    for (; j + 4 <= end; j += 4) {
        __m128 in = _mm_cmple_ps(_mm_loadu_ps(rx + j), hi);
        __m128 qx = _mm_sub_ps(_mm_loadu_ps(xs + j), ox), qy = _mm_sub_ps(_mm_loadu_ps(ys + j), oy);
        __m128 qz = _mm_sub_ps(_mm_loadu_ps(zs + j), oz);
        __m128 t = _mm_add_ps(_mm_add_ps(_mm_mul_ps(qx, dx), _mm_mul_ps(qy, dy)), _mm_mul_ps(qz, dz));
        __m128 ex = _mm_sub_ps(qx, _mm_mul_ps(dx, t)), ey = _mm_sub_ps(qy, _mm_mul_ps(dy, t));
        __m128 ez = _mm_sub_ps(qz, _mm_mul_ps(dz, t));
        __m128 e2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(ex, ex), _mm_mul_ps(ey, ey)), _mm_mul_ps(ez, ez));
        __m128 ok = _mm_and_ps(_mm_and_ps(_mm_cmpge_ps(t, zero), _mm_cmplt_ps(t, t1)), _mm_cmpngt_ps(e2, r2));
        int pass = _mm_movemask_ps(_mm_and_ps(ok, in));
        if (pass) {
            float tl[4];
            _mm_storeu_ps(tl, t);
            for (int k = pass; k; k &= k - 1) {
                int lane = __builtin_ctz((unsigned)k);
                uint32_t i = j + (uint32_t)lane;
                if (g->depth[i] <= br->depth_max)
                    beam_take(m, 0, &g->dec[i], tl[lane], br, acc);
            }
        }
        if (_mm_movemask_ps(in) != 0xf)
            return;
    }
    for (; j < end && rx[j] <= xhi; j++)
        beam_add(m, 0, &g->dec[j], xs[j], ys[j], zs[j], g->depth[j], br, acc);
}

/* The rows (y, z cells) the tube around the segment crosses, z slab by z slab; in each
 * the photons whose x the tube reaches there. e is r plus the rounding slack: a photon
 * within r of the ray at parameter t lies within e of o + t d on every axis. */
static void beam_walk(const struct photon_map *m, const struct photon_beam_grid *g, const struct beam_ray *br,
                      double acc[3])
{
    vec3 o = br->go, d = br->gd;
    float scale = beam_max(g->scale, beam_max(beam_max(fabsf(o.x), fabsf(o.y)), fabsf(o.z)));
    float e = m->radius * (1.0f + BEAM_SLACK) + 2.0f * BEAM_SLACK * scale, c = g->cell;
    float ta = 0.0f, tb = br->t1;
    vec3 blo = v3(g->lo[0] - e, g->lo[1] - e, g->lo[2] - e), bhi = v3(g->hi[0] + e, g->hi[1] + e, g->hi[2] + e);
    if (!v3_clip_box(o, d, blo, bhi, &ta, &tb))
        return;
    if (!(tb < INFINITY))
        tb = ta; /* d = 0: the ray is the point o */
    float za = o.z + d.z * ta, zb = o.z + d.z * tb, ya = o.y + d.y * ta, yb = o.y + d.y * tb;
    uint32_t z0 = beam_cell(g, beam_min(za, zb) - e, 2), z1 = beam_cell(g, beam_max(za, zb) + e, 2);
    uint32_t y0 = beam_cell(g, beam_min(ya, yb) - e, 1), y1 = beam_cell(g, beam_max(ya, yb) + e, 1);
    const float *xs = g->x; /* along the rows */
    /* The rows the walk would visit (a slab's y cells at most): when that is more than half
     * the photons (a slack grown huge by an origin far away), reading them all is cheaper. */
    double slab_y = fabs((double)d.y) * ((double)c + 2.0 * e) / fabs((double)d.z) + 2.0 * e;
    double walk = (double)(z1 - z0 + 1) * fmin((double)(y1 - y0 + 1), slab_y / c + 2.0);
    if (!(walk <= 0.5 * (double)m->num_photons)) {
        for (uint32_t j = 0; j < m->num_photons; j++)
            beam_add(m, 0, &g->dec[j], g->wx[j], g->wy[j], g->wz[j], g->depth[j], br, acc);
        return;
    }
    for (uint32_t cz = z0; cz <= z1; cz++) {
        float sa = ta, sb = tb, zl = g->lo[2] + (float)cz * c;
        if (!f_clip_slab(o.z, d.z, zl - e, zl + c + e, &sa, &sb) || !(sa <= sb))
            continue;
        float sya = o.y + d.y * sa, syb = o.y + d.y * sb;
        uint32_t sy0 = beam_cell(g, beam_min(sya, syb) - e, 1), sy1 = beam_cell(g, beam_max(sya, syb) + e, 1);
        for (uint32_t cy = sy0; cy <= sy1; cy++) {
            float ra = sa, rb = sb, yl = g->lo[1] + (float)cy * c;
            if (!f_clip_slab(o.y, d.y, yl - e, yl + c + e, &ra, &rb) || !(ra <= rb))
                continue;
            uint32_t l, end;
            if (!beam_row_range(g, cy, cz, &l, &end))
                continue;
            float xa = o.x + d.x * ra, xb = o.x + d.x * rb, xlo = beam_min(xa, xb) - e, xhi = beam_max(xa, xb) + e;
            if (end - l <= BEAM_LINEAR) {
                /* The first photon of the row at x >= xlo: the row is sorted by x, so it
                 * comes after the photons below xlo, counted four at a time (the loads
                 * may pass the row's end: those lanes are masked, and g->x is padded). */
                const __m128 lo4 = _mm_set1_ps(xlo);
                uint32_t n = end - l, below = 0;
                for (uint32_t j = 0; j < n; j += 4) {
                    int mk = _mm_movemask_ps(_mm_cmplt_ps(_mm_loadu_ps(xs + l + j), lo4));
                    if (n - j < 4)
                        mk &= (1 << (n - j)) - 1;
                    below += (uint32_t)__builtin_popcount((unsigned)mk);
                    if (mk != 0xf)
                        break;
                }
                l += below;
            } else {
                for (uint32_t h = end; l < h;) {
                    uint32_t mid = l + (h - l) / 2;
                    if (xs[mid] < xlo)
                        l = mid + 1;
                    else
                        h = mid;
                }
            }
            beam_row(m, g, br, l, end, xhi, acc);
        }
    }
}

vec3 photon_map_beam(const struct photon_map *m, vec3 o, vec3 d, float t1, const struct medium *md,
                     const struct photon_tau *tau, uint32_t depth_max)
{
    if (!m || m->num_photons == 0 || !(t1 > 0.0f) || !v3_is_finite(o) || !v3_is_finite(d))
        return v3(0, 0, 0);
    float r = m->radius;
    struct beam_ray br = {o, d, v3_neg(d), o, d, t1, r * r, md->grid ? md->grid->max_density : 0.0f, depth_max, md, tau};
    double acc[3] = {0, 0, 0};
    if (m->beam) {
        const uint8_t *ax = m->beam->axis;
        const float wo[3] = {o.x, o.y, o.z}, wd[3] = {d.x, d.y, d.z};
        br.go = v3(wo[ax[0]], wo[ax[1]], wo[ax[2]]);
        br.gd = v3(wd[ax[0]], wd[ax[1]], wd[ax[2]]);
        beam_walk(m, m->beam, &br, acc);
    } else { /* a map built by hand (tests): every photon */
        for (uint32_t i = 0; i < m->num_photons; i++) {
            const struct photon *ph = &m->photons[i];
            beam_add(m, i, NULL, ph->p[0], ph->p[1], ph->p[2], PHOTON_EVENTS(ph->depth), &br, acc);
        }
    }
    double rk = fmax((double)r, PM_MIN_KERNEL_RADIUS);
    return scaled(acc, 1.0 / (M_PI * rk * rk));
}

/* ---- the volume blob ---- */

#define VB_MAGIC "BVOL0002"
#define VB_HEADER 48

int volume_blob_make_passes(const struct scene_media *sm, const uint8_t *const *maps, const size_t *map_sizes,
                            uint32_t num_maps, uint8_t **out, size_t *out_size)
{
    size_t n = VB_HEADER;
    for (uint32_t i = 0; i < num_maps; i++)
        n += 8 + map_sizes[i];
    uint8_t *b = mem_calloc(n, 1);
    memcpy(b, VB_MAGIC, 8);
    bytes_put_u32(b + 8, (uint32_t)sm->method);
    bytes_put_f32(b + 12, sm->step);
    bytes_put_f32(b + 16, sm->radius);
    bytes_put_u32(b + 20, num_maps);
    bytes_put_u64(b + 24, sm->photons);
    bytes_put_f32(b + 32, sm->alpha > 0.0f ? sm->alpha : MEDIA_DEFAULT_ALPHA);
    bytes_put_u32(b + 36, (uint32_t)sm->indirect);
    size_t at = VB_HEADER;
    for (uint32_t i = 0; i < num_maps; i++) {
        bytes_put_u64(b + at, (uint64_t)map_sizes[i]);
        memcpy(b + at + 8, maps[i], map_sizes[i]);
        at += 8 + map_sizes[i];
    }
    *out = b;
    *out_size = n;
    return 0;
}

int volume_blob_make(const struct scene_media *sm, const uint8_t *map, size_t map_size, uint8_t **out,
                     size_t *out_size)
{
    return volume_blob_make_passes(sm, &map, &map_size, map ? 1u : 0u, out, out_size);
}

int volume_blob_decode(const uint8_t *data, size_t size, struct scene_media *settings, struct photon_map **maps,
                       uint32_t *num_maps, char *err, size_t errlen)
{
    *maps = NULL;
    *num_maps = 0;
    if (size < VB_HEADER || memcmp(data, VB_MAGIC, 8) != 0) {
        str_fmt(err, errlen, "volume blob: bad header");
        return -1;
    }
    uint32_t method = bytes_get_u32(data + 8), n = bytes_get_u32(data + 20);
    float step = bytes_get_f32(data + 12), radius = bytes_get_f32(data + 16), alpha = bytes_get_f32(data + 32);
    uint32_t indirect = bytes_get_u32(data + 36);
    int zero = bytes_get_u64(data + 40) == 0;
    if (method >= MEDIA_METHOD_COUNT_ || indirect >= MEDIA_INDIRECT_COUNT_ || !(step >= 0.0f) || !isfinite(step) ||
        !(radius >= 0.0f) || !isfinite(radius) || !(alpha > 0.0f && alpha <= 1.0f) || n > VOLUME_BLOB_MAX_MAPS ||
        !zero) {
        str_fmt(err, errlen, "volume blob: settings out of range");
        return -1;
    }
    struct photon_map *head = NULL, **tail = &head;
    size_t at = VB_HEADER;
    for (uint32_t i = 0; i < n; i++) {
        uint64_t len = size - at >= 8 ? bytes_get_u64(data + at) : UINT64_MAX;
        if (len == UINT64_MAX || len > size - at - 8) {
            str_fmt(err, errlen, "volume blob: map %u of %u does not fit the blob", i, n);
            photon_map_free(&head);
            return -1;
        }
        if (photon_map_decode(data + at + 8, (size_t)len, tail, err, errlen) != 0) {
            photon_map_free(&head);
            return -1;
        }
        tail = &(*tail)->next_pass;
        at += 8 + (size_t)len;
    }
    if (at != size) {
        str_fmt(err, errlen, "volume blob: %zu bytes after the last map", size - at);
        photon_map_free(&head);
        return -1;
    }
    if (settings) {
        settings->method = (enum media_method)method;
        settings->step = step;
        settings->radius = radius;
        settings->photons = bytes_get_u64(data + 24);
        settings->alpha = alpha;
        settings->indirect = (enum media_indirect)indirect;
    }
    *maps = head;
    *num_maps = n;
    return 0;
}

int volume_blob_apply(struct scene *s, const uint8_t *data, size_t size, struct photon_map **map, char *err,
                      size_t errlen)
{
    struct scene_media *sm = s->media;
    *map = NULL;
    if (!sm) {
        str_fmt(err, errlen, "volume blob: a scene without media");
        return -1;
    }
    struct scene_media st = *sm;
    uint32_t n;
    if (volume_blob_decode(data, size, &st, map, &n, err, errlen) != 0)
        return -1;
    sm->method = st.method;
    sm->step = st.step;
    sm->radius = st.radius;
    sm->photons = st.photons;
    sm->alpha = st.alpha;
    sm->indirect = st.indirect;
    return 0;
}
