/* Photon beams (see photon_beams.h): the wire section, its bounded decoding, the chunks'
 * Embree BVH and the beam x beam estimate. */
#include "render/photon_beams.h"
#include "render/photon_codec.h"
#include "render/accel.h"
#include "base/bytes.h"
#include "base/log.h"
#include "scene/grid.h"
#include <embree3/rtcore.h>
#include <float.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

_Static_assert(sizeof(struct photon_beam) == 32, "beams are 32 bytes on the wire");

#define PB_MAX_BEAMS (1u << 26)
#define PB_MAX_TOTAL_CHUNKS (1u << 28)

struct pb_decoded {
    float a[3], u[3], len, power[3];
    uint32_t depth;
};

/* A chunk holds what its exact test reads (one cache line's worth), so a query touches the
 * beams themselves only for its hits; chunks are stored in Morton order of their centres. */
struct pb_chunk {
    float a[3], u[3];   /* the beam's start and direction */
    float v0, v1;       /* its part of the beam */
    uint32_t beam, depth;
    float power[3];
};

struct photon_beams {
    uint32_t n, num_chunks;
    uint64_t emitted;
    float radius;
    struct pb_decoded *beams;
    struct pb_chunk *chunks;
    RTCScene scene;     /* NULL when there are no chunks */
    enum embree_isa isa; /* the kernels its BVH is built and traversed with (the job's) */
    /* The chunks and BVH are built by the first query (on a render thread, so a worker's
     * decoding stays quick and its heartbeats flow) or by photon_beams_set_radius. */
    pthread_mutex_t lock;
    _Atomic int built;
};

/* ---- writing ---- */

void photon_beam_store(struct photon_beam_list *l, vec3 a, vec3 b, vec3 power, uint32_t depth)
{
    if (!v3_is_finite(power) || v3_is_black(power) || !v3_is_finite(a) || !v3_is_finite(b))
        return;
    if (a.x == b.x && a.y == b.y && a.z == b.z)
        return;
    mem_grow((void **)&l->a, &l->cap, (size_t)l->n + 1, sizeof *l->a);
    struct photon_beam *pb = &l->a[l->n++];
    pb->a[0] = a.x, pb->a[1] = a.y, pb->a[2] = a.z;
    pb->b[0] = b.x, pb->b[1] = b.y, pb->b[2] = b.z;
    photon_rgbe_encode(power, pb->rgbe);
    pb->depth = depth;
}

int photon_beams_serialise(struct photon_beam_list *blocks, uint32_t num_blocks, float radius, uint64_t emitted,
                           uint8_t **out, size_t *bytes_out, uint32_t *count, char *err, size_t errlen)
{
    uint64_t total = 0;
    for (uint32_t b = 0; b < num_blocks; b++)
        total += blocks[b].n;
    if (total > PB_MAX_BEAMS) {
        for (uint32_t b = 0; b < num_blocks; b++)
            free(blocks[b].a);
        str_fmt(err, errlen, "photon pass: too many photon beams stored (%llu, at most %u)",
                (unsigned long long)total, PB_MAX_BEAMS);
        return -1;
    }
    size_t bytes = PB_HEADER + sizeof(struct photon_beam) * (size_t)total;
    uint8_t *o = mem_calloc(bytes, 1);
    memcpy(o, PB_MAGIC, 8);
    bytes_put_u32(o + 8, (uint32_t)total);
    bytes_put_u64(o + 16, emitted);
    bytes_put_f32(o + 24, radius);
    size_t at = PB_HEADER;
    for (uint32_t b = 0; b < num_blocks; b++) {
        if (blocks[b].n)
            memcpy(o + at, blocks[b].a, sizeof(struct photon_beam) * blocks[b].n);
        at += sizeof(struct photon_beam) * blocks[b].n;
        free(blocks[b].a);
        blocks[b].a = NULL;
    }
    *out = o;
    *bytes_out = bytes;
    *count = (uint32_t)total;
    return 0;
}

/* ---- the BVH ---- */

/* One Embree device per instruction set, made on first use: the beams' BVH is traversed
 * with the job's kernels, as every other ray query (scene.h, enum embree_isa). */
static RTCDevice pb_devices[EMBREE_ISA_COUNT_];
static pthread_mutex_t pb_devices_lock = PTHREAD_MUTEX_INITIALIZER;

static RTCDevice pb_device_get(enum embree_isa isa)
{
    char config[64], err[256];
    CHECK((unsigned)isa < EMBREE_ISA_COUNT_);
    pthread_mutex_lock(&pb_devices_lock);
    if (!pb_devices[isa] && embree_device_config(isa, 0, config, sizeof config, err, sizeof err) == 0)
        pb_devices[isa] = rtcNewDevice(config);
    RTCDevice d = pb_devices[isa];
    pthread_mutex_unlock(&pb_devices_lock);
    return d;
}

static void chunk_bounds(const struct photon_beams *pb, uint32_t i, float lo[3], float hi[3])
{
    const struct pb_chunk *c = &pb->chunks[i];
    for (int k = 0; k < 3; k++) {
        float p0 = c->a[k] + c->u[k] * c->v0, p1 = c->a[k] + c->u[k] * c->v1;
        float l = fminf(p0, p1), h = fmaxf(p0, p1);
        float pad = pb->radius * 1.0001f + 1e-6f * (fabsf(l) + fabsf(h)) + 1e-30f;
        lo[k] = fmaxf(l - pad, -FLT_MAX), hi[k] = fminf(h + pad, FLT_MAX); /* finite for Embree */
    }
}

static void bounds_cb(const struct RTCBoundsFunctionArguments *args)
{
    float lo[3], hi[3];
    chunk_bounds(args->geometryUserPtr, args->primID, lo, hi);
    args->bounds_o->lower_x = lo[0], args->bounds_o->upper_x = hi[0];
    args->bounds_o->lower_y = lo[1], args->bounds_o->upper_y = hi[1];
    args->bounds_o->lower_z = lo[2], args->bounds_o->upper_z = hi[2];
}

struct pb_hit {
    uint32_t chunk;
    float w;    /* camera parameter of the closest approach */
    float k;    /* phase / (2 r sin theta) */
};

struct pb_query {
    struct RTCIntersectContext ctx; /* first: Embree hands the callbacks this pointer */
    const struct photon_beams *pb;
    double o[3], d[3];
    float t1;
    float g;
    uint32_t depth_max;
    struct pb_hit *hits;
    uint32_t n, cap;
};

/* The exact test of chunk i against the query's segment: 1 with *h when the beam's closest
 * approach to the camera ray lies in the chunk, on the segment and within r. */
static int chunk_test(const struct pb_query *q, uint32_t i, struct pb_hit *h)
{
    const struct photon_beams *pb = q->pb;
    const struct pb_chunk *c = &pb->chunks[i];
    if (c->depth > q->depth_max)
        return 0;
    const double *d = q->d;
    double u[3] = {c->u[0], c->u[1], c->u[2]};
    double W[3] = {q->o[0] - c->a[0], q->o[1] - c->a[1], q->o[2] - c->a[2]};
    double cr[3] = {d[1] * u[2] - d[2] * u[1], d[2] * u[0] - d[0] * u[2], d[0] * u[1] - d[1] * u[0]};
    double s2 = cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2];
    if (!(s2 >= (double)PB_MIN_SIN * PB_MIN_SIN))
        return 0;
    double cc = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
    double dd = d[0] * W[0] + d[1] * W[1] + d[2] * W[2], ee = u[0] * W[0] + u[1] * W[1] + u[2] * W[2];
    double w = (cc * ee - dd) / s2, v = (ee - cc * dd) / s2;
    if (!(w >= 0.0 && w < (double)q->t1) || !(v >= (double)c->v0 && v < (double)c->v1))
        return 0;
    double r = (double)pb->radius, dist2 = 0.0;
    for (int k = 0; k < 3; k++) {
        double x = W[k] + w * d[k] - v * u[k];
        dist2 += x * x;
    }
    if (!(dist2 <= r * r))
        return 0;
    /* light travelling along u scatters toward the camera, along -d */
    double ph = phase_hg_cut((float)-cc, q->g);
    double rk = fmax(r, 1e-9);
    h->chunk = i;
    h->w = (float)w;
    h->k = (float)fmin(ph / (2.0 * rk * sqrt(s2)), 1e30);
    return h->k > 0.0f;
}

static void intersect_cb(const struct RTCIntersectFunctionNArguments *args)
{
    if (!args->valid[0])
        return;
    struct pb_query *q = (struct pb_query *)args->context;
    struct pb_hit h;
    if (!chunk_test(q, args->primID, &h))
        return;
    if (q->n == q->cap) {
        q->cap = q->cap ? 2 * q->cap : 256;
        q->hits = mem_realloc(q->hits, sizeof *q->hits * q->cap);
    }
    q->hits[q->n++] = h;
}

/* 10 bits of x in every third bit. */
static uint32_t spread3(uint32_t x)
{
    x &= 1023u;
    x = (x | x << 16) & 0x030000ffu;
    x = (x | x << 8) & 0x0300f00fu;
    x = (x | x << 4) & 0x030c30c3u;
    x = (x | x << 2) & 0x09249249u;
    return x;
}

struct morton_key {
    uint32_t code, index;
};

static int cmp_morton(const void *a, const void *b)
{
    const struct morton_key *x = a, *y = b;
    if (x->code != y->code)
        return x->code < y->code ? -1 : 1;
    return x->index < y->index ? -1 : x->index > y->index;
}

/* Reorders chunks by the Morton code of their centres (ties by their order before), so
 * that chunks near in space are near in memory. Deterministic. */
static void morton_order(struct pb_chunk *c, uint32_t n)
{
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    float *ctr = mem_alloc(sizeof *ctr * 3 * (size_t)n);
    for (uint32_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) {
            float x = c[i].a[k] + c[i].u[k] * 0.5f * (c[i].v0 + c[i].v1);
            ctr[3 * (size_t)i + k] = x;
            lo[k] = fminf(lo[k], x), hi[k] = fmaxf(hi[k], x);
        }
    struct morton_key *key = mem_alloc(sizeof *key * n);
    for (uint32_t i = 0; i < n; i++) {
        uint32_t code = 0;
        for (int k = 0; k < 3; k++) {
            float ext = hi[k] - lo[k], f = ext > 0.0f ? (ctr[3 * (size_t)i + k] - lo[k]) / ext : 0.0f;
            uint32_t q = f > 0.0f ? (uint32_t)fminf(f * 1023.0f, 1023.0f) : 0u;
            code |= spread3(q) << k;
        }
        key[i] = (struct morton_key){code, i};
    }
    qsort(key, n, sizeof *key, cmp_morton);
    struct pb_chunk *tmp = mem_alloc(sizeof *tmp * n);
    for (uint32_t i = 0; i < n; i++)
        tmp[i] = c[key[i].index];
    memcpy(c, tmp, sizeof *tmp * n);
    free(tmp);
    free(key);
    free(ctr);
}

static void build_now(struct photon_beams *pb)
{
    if (pb->scene) {
        rtcReleaseScene(pb->scene);
        pb->scene = NULL;
    }
    free(pb->chunks);
    pb->chunks = NULL;
    pb->num_chunks = 0;
    if (pb->n == 0)
        return;
    /* Chunks of at most PB_CHUNK_RADII radii (so their boxes stay near the beam), at most
     * PB_MAX_CHUNKS per beam and PB_MAX_TOTAL_CHUNKS in all (then one per beam). */
    double cl = (double)PB_CHUNK_RADII * (double)pb->radius;
    uint64_t total = 0;
    for (uint32_t i = 0; i < pb->n; i++) {
        double k = ceil((double)pb->beams[i].len / cl);
        total += k >= PB_MAX_CHUNKS || !(k >= 1.0) ? (k >= 1.0 ? PB_MAX_CHUNKS : 1u) : (uint32_t)k;
    }
    int one = total > PB_MAX_TOTAL_CHUNKS;
    if (one)
        total = pb->n;
    pb->chunks = mem_alloc(sizeof *pb->chunks * total);
    uint32_t m = 0;
    for (uint32_t i = 0; i < pb->n; i++) {
        float len = pb->beams[i].len;
        double k = one ? 1.0 : ceil((double)len / cl);
        uint32_t nc = k >= PB_MAX_CHUNKS ? PB_MAX_CHUNKS : (k >= 1.0 ? (uint32_t)k : 1u);
        for (uint32_t j = 0; j < nc; j++) {
            float v0 = j == 0 ? 0.0f : (float)((double)len * j / nc);
            float v1 = j + 1 == nc ? len : (float)((double)len * (j + 1) / nc);
            const struct pb_decoded *b = &pb->beams[i];
            pb->chunks[m++] = (struct pb_chunk){{b->a[0], b->a[1], b->a[2]}, {b->u[0], b->u[1], b->u[2]}, v0, v1, i,
                                                b->depth, {b->power[0], b->power[1], b->power[2]}};
        }
    }
    pb->num_chunks = m;
    morton_order(pb->chunks, m);
    RTCDevice device = pb_device_get(pb->isa);
    CHECK(device != NULL); /* Embree could not start (the job's accel_init checked the CPU) */
    pb->scene = rtcNewScene(device);
    rtcSetSceneBuildQuality(pb->scene, RTC_BUILD_QUALITY_MEDIUM);
    rtcSetSceneFlags(pb->scene, RTC_SCENE_FLAG_ROBUST);
    accel_attach_user_geometry(device, pb->scene, m, pb, bounds_cb, intersect_cb);
    rtcCommitScene(pb->scene);
}

static void ensure_built(struct photon_beams *pb)
{
    if (atomic_load_explicit(&pb->built, memory_order_acquire))
        return;
    pthread_mutex_lock(&pb->lock);
    if (!atomic_load_explicit(&pb->built, memory_order_relaxed)) {
        build_now(pb);
        atomic_store_explicit(&pb->built, 1, memory_order_release);
    }
    pthread_mutex_unlock(&pb->lock);
}

static struct photon_beams *beams_new(uint32_t n, float radius)
{
    struct photon_beams *pb = mem_calloc(1, sizeof *pb);
    pb->n = n;
    pb->radius = radius;
    pb->beams = mem_alloc(sizeof *pb->beams * (n ? n : 1));
    pthread_mutex_init(&pb->lock, NULL);
    atomic_init(&pb->built, 0);
    return pb;
}

/* ---- reading ---- */

int photon_beams_is_section(const uint8_t *data, size_t size)
{
    return size >= 8 && memcmp(data, PB_MAGIC, 8) == 0;
}

static void decode_beam(const struct photon_beam *w, struct pb_decoded *o)
{
    double e[3] = {(double)w->b[0] - w->a[0], (double)w->b[1] - w->a[1], (double)w->b[2] - w->a[2]};
    double len = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
    for (int k = 0; k < 3; k++) {
        o->a[k] = w->a[k];
        o->u[k] = (float)(e[k] / len);
    }
    o->len = (float)len;
    vec3 p = photon_rgbe_decode(w->rgbe);
    o->power[0] = p.x, o->power[1] = p.y, o->power[2] = p.z;
    o->depth = w->depth;
}

int photon_beams_decode(const uint8_t *data, size_t size, struct photon_beams **out, char *err, size_t errlen)
{
    *out = NULL;
    if (!photon_beams_is_section(data, size) || size < PB_HEADER) {
        str_fmt(err, errlen, "photon beams: not a beams section (bad header)");
        return -1;
    }
    uint32_t n = bytes_get_u32(data + 8), zero = bytes_get_u32(data + 12);
    uint64_t emitted = bytes_get_u64(data + 16);
    float radius = bytes_get_f32(data + 24);
    int pad = bytes_get_u32(data + 28) == 0;
    if (zero != 0 || !pad || n > PB_MAX_BEAMS || !(radius > 0.0f) || !isfinite(radius) ||
        size != PB_HEADER + sizeof(struct photon_beam) * (uint64_t)n) {
        str_fmt(err, errlen, "photon beams: inconsistent header (count, radius or size)");
        return -1;
    }
    struct photon_beam *wire = mem_alloc(sizeof *wire * (n ? n : 1));
    if (n)
        memcpy(wire, data + PB_HEADER, sizeof *wire * (size_t)n);
    for (uint32_t i = 0; i < n; i++) {
        const struct photon_beam *w = &wire[i];
        int ok = w->depth >= 1 && w->depth <= PHOTON_DEPTH_MAX;
        double len2 = 0.0;
        for (int k = 0; k < 3 && ok; k++) {
            ok = isfinite(w->a[k]) && isfinite(w->b[k]);
            double e = (double)w->b[k] - w->a[k];
            len2 += e * e;
        }
        if (!ok || !(len2 > 0.0) || !isfinite(len2) || !isfinite((float)sqrt(len2))) {
            free(wire);
            str_fmt(err, errlen, "photon beams: beam %u has a bad end point, length or depth", i);
            return -1;
        }
    }
    struct photon_beams *pb = beams_new(n, radius);
    pb->emitted = emitted;
    for (uint32_t i = 0; i < n; i++)
        decode_beam(&wire[i], &pb->beams[i]);
    free(wire);
    *out = pb;
    return 0;
}

struct photon_beams *photon_beams_from(const struct photon_beam *beams, uint32_t n, float radius)
{
    struct photon_beams *pb = beams_new(n, radius);
    for (uint32_t i = 0; i < n; i++)
        decode_beam(&beams[i], &pb->beams[i]);
    return pb;
}

void photon_beams_set_radius(struct photon_beams *pb, float radius)
{
    pb->radius = radius;
    build_now(pb);
    atomic_store_explicit(&pb->built, 1, memory_order_release);
}

void photon_beams_set_isa(struct photon_beams *pb, enum embree_isa isa)
{
    if (!pb || pb->isa == isa)
        return;
    pthread_mutex_lock(&pb->lock);
    CHECK(!atomic_load_explicit(&pb->built, memory_order_relaxed)); /* before the first query */
    pb->isa = isa;
    pthread_mutex_unlock(&pb->lock);
}

void photon_beams_free(struct photon_beams **pp)
{
    struct photon_beams *pb = *pp;
    *pp = NULL;
    if (!pb)
        return;
    if (pb->scene)
        rtcReleaseScene(pb->scene);
    free(pb->chunks);
    free(pb->beams);
    pthread_mutex_destroy(&pb->lock);
    free(pb);
}

uint32_t photon_beams_count(const struct photon_beams *pb) { return pb ? pb->n : 0; }
size_t photon_beams_bytes(const struct photon_beams *pb) { return pb ? sizeof *pb + (size_t)pb->n * sizeof *pb->beams : 0; }
float photon_beams_radius(const struct photon_beams *pb) { return pb ? pb->radius : 0.0f; }

/* ---- the estimate ---- */

/* Sorts hits by chunk: insertion sort for a few, else an LSD radix sort (8 bits a pass,
 * stable) through a scratch array. */

static void sort_hits(struct pb_hit *h, uint32_t n)
{
    if (n <= 32) {
        for (uint32_t i = 1; i < n; i++)
            for (uint32_t j = i; j > 0 && h[j].chunk < h[j - 1].chunk; j--) {
                struct pb_hit t = h[j];
                h[j] = h[j - 1], h[j - 1] = t;
            }
        return;
    }
    struct pb_hit *tmp = mem_alloc(sizeof *tmp * n);
    uint32_t top = 0;
    for (uint32_t i = 0; i < n; i++)
        top |= h[i].chunk;
    struct pb_hit *a = h, *b = tmp;
    for (int shift = 0; shift < 32 && (top >> shift) != 0; shift += 8) {
        uint32_t count[257] = {0};
        for (uint32_t i = 0; i < n; i++)
            count[(a[i].chunk >> shift & 255) + 1]++;
        for (int k = 0; k < 256; k++)
            count[k + 1] += count[k];
        for (uint32_t i = 0; i < n; i++)
            b[count[a[i].chunk >> shift & 255]++] = a[i];
        struct pb_hit *t = a;
        a = b, b = t;
    }
    if (a != h)
        memcpy(h, a, sizeof *h * n);
    free(tmp);
}

/* Sums the hits in chunk order (each chunk once). */
static vec3 sum_hits(const struct photon_beams *pb, struct pb_hit *h, uint32_t n, vec3 o, vec3 d,
                     const struct medium *md, const struct photon_tau *tau)
{
    sort_hits(h, n);
    double acc[3] = {0, 0, 0};
    for (uint32_t i = 0; i < n; i++) {
        if (i > 0 && h[i].chunk == h[i - 1].chunk)
            continue;
        const struct pb_chunk *b = &pb->chunks[h[i].chunk];
        float w = h[i].w;
        vec3 ss = md->sigma_s;
        if (md->grid) {
            float rho = grid_density(md->grid, v3_add(o, v3_scale(d, w)));
            if (!(rho > 0.0f))
                continue;
            ss = v3_scale(ss, rho);
        }
        vec3 tr = tau ? photon_tau_transmittance(tau, md, w) : medium_transmittance(md, w);
        double k = h[i].k;
        acc[0] += k * b->power[0] * ss.x * tr.x;
        acc[1] += k * b->power[1] * ss.y * tr.y;
        acc[2] += k * b->power[2] * ss.z * tr.z;
    }
    return v3((float)fmin(acc[0], 1e30), (float)fmin(acc[1], 1e30), (float)fmin(acc[2], 1e30));
}

static void query_init(struct pb_query *q, const struct photon_beams *pb, vec3 o, vec3 d, float t1,
                       const struct medium *md, uint32_t depth_max)
{
    memset(q, 0, sizeof *q);
    rtcInitIntersectContext(&q->ctx);
    q->pb = pb;
    q->o[0] = o.x, q->o[1] = o.y, q->o[2] = o.z;
    q->d[0] = d.x, q->d[1] = d.y, q->d[2] = d.z;
    q->t1 = t1;
    q->g = md->g;
    q->depth_max = depth_max;
}

vec3 photon_beams_estimate(struct photon_beams *pb, vec3 o, vec3 d, float t1, const struct medium *md,
                           const struct photon_tau *tau, uint32_t depth_max)
{
    if (!pb || pb->n == 0 || !(t1 > 0.0f) || !isfinite(t1) || !v3_is_finite(o) || !v3_is_finite(d) ||
        v3_is_black(md->sigma_s))
        return v3(0, 0, 0);
    ensure_built(pb);
    struct pb_query q;
    query_init(&q, pb, o, d, t1, md, depth_max);
    struct RTCRayHit rh;
    memset(&rh, 0, sizeof rh);
    accel_ray_set(&rh.ray, o, 0.0f, d, 0.0f);
    rh.ray.tfar = t1;
    rh.ray.mask = 0xffffffffu;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    if (accel_ray_ok_(o, d))
        rtcIntersect1(pb->scene, &q.ctx, &rh);
    vec3 r = sum_hits(pb, q.hits, q.n, o, d, md, tau);
    free(q.hits); /* per query: a query tests hundreds of chunks, the allocation is noise */
    return r;
}

vec3 photon_beams_estimate_brute(struct photon_beams *pb, vec3 o, vec3 d, float t1, const struct medium *md,
                                 const struct photon_tau *tau, uint32_t depth_max)
{
    if (!pb || !(t1 > 0.0f) || !isfinite(t1) || v3_is_black(md->sigma_s))
        return v3(0, 0, 0);
    ensure_built(pb);
    struct pb_query q;
    query_init(&q, pb, o, d, t1, md, depth_max);
    struct pb_hit *hits = mem_alloc(sizeof *hits * (pb->num_chunks ? pb->num_chunks : 1));
    uint32_t n = 0;
    for (uint32_t i = 0; i < pb->num_chunks; i++)
        n += chunk_test(&q, i, &hits[n]);
    vec3 r = sum_hits(pb, hits, n, o, d, md, tau);
    free(hits);
    return r;
}
