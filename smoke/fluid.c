/* Stable fluids solver (see fluid.h and docs/smoke.md). */
#include "fluid.h"
#include "base/log.h"
#include "base/rng.h"
#include <fftw3.h>
#include <immintrin.h>  /* SSE2 (every x86-64): movemask, 4x4 transposes */
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

int fluid_no_avx = 0;

const char *const fluid_phase_names[PH_COUNT_] = {"source", "forces", "advect", "fft", "spectral", "sponge"};

static pthread_once_t fftw_once = PTHREAD_ONCE_INIT;
static pthread_mutex_t planner_lock = PTHREAD_MUTEX_INITIALIZER;
static void fftw_setup(void) { CHECK(fftwf_init_threads() != 0); }

struct clocks {
    struct timespec cpu, wall;
};
static struct clocks clocks_now(void)
{
    struct clocks c;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c.cpu);
    clock_gettime(CLOCK_MONOTONIC, &c.wall);
    return c;
}
static double ts_diff(struct timespec a, struct timespec b)
{
    return (double)(b.tv_sec - a.tv_sec) + 1e-9 * (double)(b.tv_nsec - a.tv_nsec);
}
/* Adds the time since *c to phase ph and restarts *c. */
static void lap(struct fluid *f, struct clocks *c, enum fluid_phase ph)
{
    struct clocks now = clocks_now();
    f->cpu[ph] += ts_diff(c->cpu, now.cpu);
    f->wall[ph] += ts_diff(c->wall, now.wall);
    *c = now;
}

static size_t spec_len(const struct fluid *f) { return (size_t)f->nz * f->ny * (f->nx / 2 + 1); }

size_t fluid_bytes_per_voxel(void)
{
    /* five fields, a spare, a scratch block of five (the padded copies: about one voxel more
     * per row, column and plane), three half spectra (nx/2+1 complex per nx reals ~ 1 float) */
    return 11 * sizeof(float) + 3 * sizeof(float) * 1;
}

void fluid_init(struct fluid *f, const struct smoke_settings *s)
{
    memset(f, 0, sizeof *f);
    f->s = *s;
    f->nx = s->res[0];
    f->ny = s->res[1];
    f->nz = s->res[2];
    f->n = (size_t)f->nx * f->ny * f->nz;
    f->h = s->size / (float)f->nx;
    float **fields[] = {&f->u, &f->v, &f->w, &f->d, &f->t, &f->spare, &f->tmp[0]};
    for (size_t i = 0; i < sizeof fields / sizeof *fields; i++) {
        /* the scratch block: tmp[0..3], or the padded copies advection reads (4 + 1 floats a
         * padded voxel) */
        size_t pad = (size_t)(f->nx + 2) * (f->ny + 2) * (f->nz + 2);
        size_t len = i == 6 ? (4 * f->n > 5 * pad ? 4 * f->n : 5 * pad) : f->n;
        *fields[i] = fftwf_malloc(len * sizeof(float));
        CHECK(*fields[i] != NULL);
        memset(*fields[i], 0, len * sizeof(float));
    }
    for (int c = 1; c < 4; c++)
        f->tmp[c] = f->tmp[0] + (size_t)c * f->n;
    for (int c = 0; c < 3; c++) {
        f->spec[c] = fftwf_malloc(spec_len(f) * sizeof(fftwf_complex));
        CHECK(f->spec[c] != NULL);
        memset(f->spec[c], 0, spec_len(f) * sizeof(fftwf_complex));
    }
    pthread_once(&fftw_once, fftw_setup);
    pthread_mutex_lock(&planner_lock);
    fftwf_plan_with_nthreads((int)(s->threads ? s->threads : 1));
    /* FFTW's row-major dims: z slowest, x fastest. ESTIMATE: no timing, same plan every run. */
    f->plan_fwd = fftwf_plan_dft_r2c_3d((int)f->nz, (int)f->ny, (int)f->nx, f->tmp[0], f->spec[0],
                                        FFTW_ESTIMATE);
    f->plan_bwd = fftwf_plan_dft_c2r_3d((int)f->nz, (int)f->ny, (int)f->nx, f->spec[0], f->tmp[0],
                                        FFTW_ESTIMATE);
    pthread_mutex_unlock(&planner_lock);
    CHECK(f->plan_fwd && f->plan_bwd);
}

void fluid_free(struct fluid *f)
{
    pthread_mutex_lock(&planner_lock);
    if (f->plan_fwd)
        fftwf_destroy_plan(f->plan_fwd);
    if (f->plan_bwd)
        fftwf_destroy_plan(f->plan_bwd);
    pthread_mutex_unlock(&planner_lock);
    float *fields[] = {f->u, f->v, f->w, f->d, f->t, f->spare, f->tmp[0]};
    for (size_t i = 0; i < sizeof fields / sizeof *fields; i++)
        fftwf_free(fields[i]);
    for (int c = 0; c < 3; c++)
        fftwf_free(f->spec[c]);
    memset(f, 0, sizeof *f);
}

static inline size_t at(const struct fluid *f, uint32_t i, uint32_t j, uint32_t k)
{
    return i + (size_t)f->nx * (j + (size_t)f->ny * k);
}

/* ---- threads ---- */

/* Runs fn over z slabs [k0, k1) on s.threads threads (the calling one included). Each
 * voxel is written by one slab from inputs no slab writes, so the result does not depend
 * on the thread count. */
typedef void (*slab_fn)(const struct fluid *f, void *arg, uint32_t k0, uint32_t k1);
struct slab_job {
    const struct fluid *f;
    void *arg;
    slab_fn fn;
    uint32_t k0, k1;
};
static void *slab_main(void *p)
{
    struct slab_job *j = p;
    j->fn(j->f, j->arg, j->k0, j->k1);
    return NULL;
}
#define MAX_SLAB_THREADS 64
static void par_slabs(const struct fluid *f, slab_fn fn, void *arg)
{
    uint32_t t = f->s.threads < 1 ? 1 : f->s.threads;
    t = t > MAX_SLAB_THREADS ? MAX_SLAB_THREADS : t;
    t = t > f->nz ? f->nz : t;
    if (t == 1) {
        fn(f, arg, 0, f->nz);
        return;
    }
    struct slab_job jobs[MAX_SLAB_THREADS] = {{0}};
    pthread_t tid[MAX_SLAB_THREADS];
    for (uint32_t i = 0; i < t; i++)
        jobs[i] = (struct slab_job){f, arg, fn, (uint32_t)((uint64_t)f->nz * i / t),
                                    (uint32_t)((uint64_t)f->nz * (i + 1) / t)};
    for (uint32_t i = 1; i < t; i++)
        CHECK(pthread_create(&tid[i], NULL, slab_main, &jobs[i]) == 0);
    slab_main(&jobs[0]);
    for (uint32_t i = 1; i < t; i++)
        pthread_join(tid[i], NULL);
}

/* ---- advection ---- */

/* Velocity and density of a voxel side by side, so one trilinear lookup of four floats
 * serves all four (GCC vector extension; lane-wise IEEE operations, so the same bits as
 * four scalar lookups). */
typedef float v4f __attribute__((vector_size(16)));
typedef int32_t v4i __attribute__((vector_size(16)));
typedef float v8f __attribute__((vector_size(32)));

static inline uint32_t wrap(int64_t i, uint32_t n)
{
    int64_t m = i % (int64_t)n;
    return (uint32_t)(m < 0 ? m + n : m);
}

/* Advection reads padded copies: the packed velocity and density and the advected scalar,
 * each with a halo of one voxel on every side holding the periodic neighbours, so that a
 * cell whose upper corner lies across a face (or whose lower one lies one voxel before it)
 * needs no wrapped index: every cell is a lower corner and the strides 1, nx + 2,
 * (nx + 2)(ny + 2). They live in the scratch block (tmp[0..3] are its first quarters of n
 * floats outside advection). */
static size_t padded_count(const struct fluid *f) { return (size_t)(f->nx + 2) * (f->ny + 2) * (f->nz + 2); }
static size_t padded_origin(const struct fluid *f) { return 1 + (size_t)(f->nx + 2) * (1 + (size_t)(f->ny + 2)); }
static v4f *packed(const struct fluid *f) { return (v4f *)(void *)f->tmp[0]; }
static float *packed_scalar(const struct fluid *f) { return f->tmp[0] + 4 * padded_count(f); }

/* The cell holding a point (voxel centres at integers) on the periodic grid: its lower
 * corner as an index of the padded copies relative to voxel (0, 0, 0), that corner's voxel
 * (wrapped into the grid) and the fractions. */
struct cell {
    ptrdiff_t c;
    float tx, ty, tz;
    uint32_t i, j, k;
    int wrapped;  /* on some axis the upper corner is the halo (voxel 0 across the face) */
};

/* Lower corner and fraction along one axis of n voxels: the floor, clamped (huge
 * velocities) and wrapped, periodicity making any finite position valid. */
static inline uint32_t axis_split(float x, uint32_t n, float *t)
{
    const float lim = 1e6f;
    x = x > -lim ? x : -lim;  /* NaN goes to -lim, as fmaxf would take it */
    x = x < lim ? x : lim;
    float fl = floorf(x);
    *t = x - fl;
    return wrap((int64_t)fl, n);
}

/* Index box [lo, hi] per axis holding every non-zero value of a scalar (lo > hi: none).
 * Lookups in cells wholly outside it give 0 exactly (a + t (b - a) of zeros), so they are
 * skipped: the plume's temperature fills a small part of the domain. */
struct box {
    uint32_t lo[3], hi[3];
};
static void box_empty(struct box *b)
{
    for (int a = 0; a < 3; a++) {
        b->lo[a] = UINT32_MAX;
        b->hi[a] = 0;
    }
}
static void box_add(struct box *b, const struct box *o)
{
    for (int a = 0; a < 3; a++) {
        b->lo[a] = o->lo[a] < b->lo[a] ? o->lo[a] : b->lo[a];
        b->hi[a] = o->hi[a] > b->hi[a] ? o->hi[a] : b->hi[a];
    }
}
/* Whether the cell's 8 corners all lie outside the box. */
static inline int cell_outside(const struct cell *l, const struct box *b)
{
    return !l->wrapped && (l->i > b->hi[0] || l->i + 1 < b->lo[0] || l->j > b->hi[1] || l->j + 1 < b->lo[1] ||
                           l->k > b->hi[2] || l->k + 1 < b->lo[2]);
}

/* One padded row (pj, pk) of the packed fields and of the scalar: source row ((pj - 1) mod
 * ny, (pk - 1) mod nz), its last voxel before it and its first after it. The interior rows
 * also extend the box of the scalar's non-zero values. */
struct pack_arg {
    const float *scalar;
    struct box *plane;  /* nz */
};
static void pack_row(const struct fluid *f, const struct pack_arg *a, uint32_t pj, uint32_t pk, struct box *b)
{
    const uint32_t nx = f->nx, j = pj == 0 ? f->ny - 1 : (pj - 1) % f->ny, k = pk == 0 ? f->nz - 1 : (pk - 1) % f->nz;
    const size_t src = at(f, 0, j, k), dst = (size_t)pj * (nx + 2) + (size_t)pk * (nx + 2) * (f->ny + 2);
    v4f *q = packed(f) + dst + 1;
    float *t = packed_scalar(f) + dst + 1;
    const float *u = f->u + src, *v = f->v + src, *w = f->w + src, *d = f->d + src, *s = a->scalar + src;
    const int interior = pj >= 1 && pj <= f->ny && pk >= 1 && pk <= f->nz;
    uint32_t first = UINT32_MAX, last = 0, i = 0;  /* the row's non-zero scalars */
    for (; i + 4 <= nx; i += 4) {                 /* four voxels: a transpose */
        __m128 a0 = _mm_loadu_ps(u + i), a1 = _mm_loadu_ps(v + i), a2 = _mm_loadu_ps(w + i), a3 = _mm_loadu_ps(d + i);
        _MM_TRANSPOSE4_PS(a0, a1, a2, a3);
        q[i] = (v4f)a0;
        q[i + 1] = (v4f)a1;
        q[i + 2] = (v4f)a2;
        q[i + 3] = (v4f)a3;
        const __m128 sc = _mm_loadu_ps(s + i);
        _mm_storeu_ps(t + i, sc);
        const int nz = _mm_movemask_ps(_mm_cmpneq_ps(sc, _mm_setzero_ps()));
        if (nz) {
            first = first < UINT32_MAX ? first : i + (uint32_t)__builtin_ctz((unsigned)nz);
            last = i + 31 - (uint32_t)__builtin_clz((unsigned)nz);
        }
    }
    for (; i < nx; i++) {
        q[i] = (v4f){u[i], v[i], w[i], d[i]};
        t[i] = s[i];
        if (s[i] != 0.0f) {
            first = first < UINT32_MAX ? first : i;
            last = i;
        }
    }
    q[-1] = q[nx - 1];
    q[nx] = q[0];
    t[-1] = t[nx - 1];
    t[nx] = t[0];
    if (interior && first != UINT32_MAX) {
        const struct box one = {{first, j, k}, {last, j, k}};
        box_add(b, &one);
    }
}
/* Planes k0..k1 - 1 (padded k + 1), and the halo planes next to them across the faces. */
static void pack_slab(const struct fluid *f, void *arg, uint32_t k0, uint32_t k1)
{
    const struct pack_arg *a = arg;
    for (uint32_t k = k0; k < k1; k++) {
        struct box b;
        box_empty(&b);
        for (uint32_t pj = 0; pj < f->ny + 2; pj++) {
            pack_row(f, a, pj, k + 1, &b);
            if (k == 0)
                pack_row(f, a, pj, f->nz + 1, &b);
            if (k == f->nz - 1)
                pack_row(f, a, pj, 0, &b);
        }
        a->plane[k] = b;
    }
}

/* Packs, and returns the scalar's box. */
static struct box pack(const struct fluid *f, const float *scalar)
{
    struct pack_arg a = {scalar, mem_alloc(f->nz * sizeof(struct box))};
    par_slabs(f, pack_slab, &a);
    struct box b;
    box_empty(&b);
    for (uint32_t k = 0; k < f->nz; k++)
        box_add(&b, &a.plane[k]);
    free(a.plane);
    return b;
}

/* Advected scalars (density, temperature) of magnitude below this become 0: far from the
 * plume they would otherwise shrink step by step into subnormal floats, which the CPU
 * handles many times slower, and keep the temperature's active box as large as the grid. */
#define SCALAR_FLUSH 1e-20f
static inline float flush(float x) { return fabsf(x) < SCALAR_FLUSH ? 0.0f : x; }
static inline v4f flush4(v4f x)
{
    const v4f lim = {SCALAR_FLUSH, SCALAR_FLUSH, SCALAR_FLUSH, SCALAR_FLUSH};
    const v4i abs_mask = {INT32_MAX, INT32_MAX, INT32_MAX, INT32_MAX};
    return (v4f)((v4i)x & ~((v4f)((v4i)x & abs_mask) < lim));  /* flush, lane-wise */
}

/* What every voxel of an advection pass shares: the padded inputs at voxel (0, 0, 0), the
 * scalar's box, the outputs, and the grid. */
struct advect_ctx {
    const v4f *q;      /* packed velocity and density */
    const float *src;  /* the scalar */
    float *dst;
    float *vu, *vv, *vw, *vd;  /* NULL: only the scalar */
    uint32_t nx, ny, nz;
    ptrdiff_t dy, dz;  /* padded strides */
    float s, hs;       /* dt / h and half of it: velocity to voxels per step */
    const struct box *b;
    v4f blo[3], bhi[3];  /* the box as bounds on a point (see advect_row) */
    v4f top[3];          /* n per axis: fast cells' points lie in [-1, n) */
    v4i sy, sz;          /* dy, dz */
};

static inline void cell_at(const struct advect_ctx *x, float px, float py, float pz, struct cell *l)
{
    l->i = axis_split(px, x->nx, &l->tx);
    l->j = axis_split(py, x->ny, &l->ty);
    l->k = axis_split(pz, x->nz, &l->tz);
    l->wrapped = (l->i + 1 == x->nx) | (l->j + 1 == x->ny) | (l->k + 1 == x->nz);
    l->c = (ptrdiff_t)l->i + (ptrdiff_t)l->j * x->dy + (ptrdiff_t)l->k * x->dz;
}

/* Trilinear lookups in the cell of lower corner c with fractions tx ty tz, written
 * a + t (b - a) so a constant field comes back exactly: along x, then y, then z. */
#define TRILERP(p0, p1, dy, tx, ty, tz)                                                         \
    do {                                                                                        \
        const __typeof__(*(p0)) a0_ = (p0)[0] + (tx) * ((p0)[1] - (p0)[0]);                     \
        const __typeof__(*(p0)) a1_ = (p0)[dy] + (tx) * ((p0)[(dy) + 1] - (p0)[dy]);            \
        const __typeof__(*(p0)) a2_ = (p1)[0] + (tx) * ((p1)[1] - (p1)[0]);                     \
        const __typeof__(*(p0)) a3_ = (p1)[dy] + (tx) * ((p1)[(dy) + 1] - (p1)[dy]);            \
        const __typeof__(*(p0)) b0_ = a0_ + (ty) * (a1_ - a0_), b1_ = a2_ + (ty) * (a3_ - a2_); \
        return b0_ + (tz) * (b1_ - b0_);                                                        \
    } while (0)
static inline float lookup(const struct advect_ctx *x, ptrdiff_t c, float tx, float ty, float tz)
{
    TRILERP(x->src + c, x->src + c + x->dz, x->dy, tx, ty, tz);
}
static inline v4f lookup4(const struct advect_ctx *x, ptrdiff_t c, float tx, float ty, float tz)
{
    TRILERP(x->q + c, x->q + c + x->dz, x->dy, tx, ty, tz);
}
/* lookup4 with the corners below and above in z side by side in 8 floats: 4 lerps of 8
 * floats instead of 7 of 4, the same operations lane by lane (so the same bits), one
 * instruction each with AVX (advect_row_avx only: without AVX, GCC's 8-float code is
 * many times slower than lookup4). */
__attribute__((target("avx"), always_inline)) static inline v4f lookup4_avx(const struct advect_ctx *x, ptrdiff_t c,
                                                                           float tx, float ty, float tz)
{
    const v4f *p0 = x->q + c, *p1 = p0 + x->dz;
    const ptrdiff_t dy = x->dy;
    const v8f a = __builtin_shufflevector(p0[0], p1[0], 0, 1, 2, 3, 4, 5, 6, 7);
    const v8f b = __builtin_shufflevector(p0[1], p1[1], 0, 1, 2, 3, 4, 5, 6, 7);
    const v8f e = __builtin_shufflevector(p0[dy], p1[dy], 0, 1, 2, 3, 4, 5, 6, 7);
    const v8f g = __builtin_shufflevector(p0[dy + 1], p1[dy + 1], 0, 1, 2, 3, 4, 5, 6, 7);
    const v8f lo = a + tx * (b - a), hi = e + tx * (g - e);  /* along x: (a0, a2), (a1, a3) */
    const v8f m = lo + ty * (hi - lo);                         /* along y: (b0, b1) */
    const v4f m0 = __builtin_shufflevector(m, m, 0, 1, 2, 3), m1 = __builtin_shufflevector(m, m, 4, 5, 6, 7);
    return m0 + tz * (m1 - m0);
}

/* One voxel (output index idx), any point: the general cells. */
static void advect1(const struct advect_ctx *x, size_t idx, uint32_t i, uint32_t j, uint32_t k)
{
    const v4f q0 = x->q[(ptrdiff_t)i + (ptrdiff_t)j * x->dy + (ptrdiff_t)k * x->dz];
    struct cell l;
    cell_at(x, (float)i - x->hs * q0[0], (float)j - x->hs * q0[1], (float)k - x->hs * q0[2], &l);
    const v4f um = lookup4(x, l.c, l.tx, l.ty, l.tz);
    cell_at(x, (float)i - x->s * um[0], (float)j - x->s * um[1], (float)k - x->s * um[2], &l);
    if (x->vu) {
        const v4f v = lookup4(x, l.c, l.tx, l.ty, l.tz);
        x->vu[idx] = v[0];
        x->vv[idx] = v[1];
        x->vw[idx] = v[2];
        x->vd[idx] = flush(v[3]);
    }
    x->dst[idx] = cell_outside(&l, x->b) ? 0.0f : flush(lookup(x, l.c, l.tx, l.ty, l.tz));
}

/* The cells of four points. Where every coordinate of a point lies in [-1, n) (nearly every
 * point; the halo holds the neighbours across the faces) the lower corner is the floor,
 * (the truncation, less 1 below 0), c = floor x + floor y dy + floor z dz, and the fractions
 * p - floor p, as cell_at makes them; the other points (thrown far by huge velocities) get
 * cell_at's general cells, into their lanes and cell[l]. Returns the mask of those. */
static inline v4i floor4(v4f p)
{
    const v4i i = __builtin_convertvector(p, v4i);
    return i + (v4i)(p < __builtin_convertvector(i, v4f));  /* true is -1 */
}
static inline int cells4(const struct advect_ctx *x, v4f px, v4f py, v4f pz, v4i *c, v4f *tx, v4f *ty, v4f *tz,
                         struct cell *cell)
{
    const v4f m1 = {-1, -1, -1, -1};
    v4i in = (px >= m1) & (px < x->top[0]) & (py >= m1) & (py < x->top[1]) & (pz >= m1) & (pz < x->top[2]);
    const int slow = _mm_movemask_ps((__m128)in) ^ 15;
    v4f qx = px, qy = py, qz = pz;
    if (slow) {
        qx = (v4f)((v4i)px & in);  /* 0 where slow, so the conversions stay in range */
        qy = (v4f)((v4i)py & in);
        qz = (v4f)((v4i)pz & in);
    }
    v4i xi, yi, zi;
    const v4f zero = {0, 0, 0, 0};
    if (_mm_movemask_ps((__m128)((qx < zero) | (qy < zero) | (qz < zero)))) {
        xi = floor4(qx);
        yi = floor4(qy);
        zi = floor4(qz);
    } else {  /* the truncation is the floor */
        xi = __builtin_convertvector(qx, v4i);
        yi = __builtin_convertvector(qy, v4i);
        zi = __builtin_convertvector(qz, v4i);
    }
    *tx = qx - __builtin_convertvector(xi, v4f);
    *ty = qy - __builtin_convertvector(yi, v4f);
    *tz = qz - __builtin_convertvector(zi, v4f);
    *c = xi + yi * x->sy + zi * x->sz;
    if (slow)
        for (int l = 0; l < 4; l++)
            if (slow >> l & 1) {
                cell_at(x, px[l], py[l], pz[l], &cell[l]);
                (*c)[l] = (int32_t)cell[l].c;
                (*tx)[l] = cell[l].tx;
                (*ty)[l] = cell[l].ty;
                (*tz)[l] = cell[l].tz;
            }
    return slow;
}

/* A row of voxels goes through the stages of advect1 one stage at a time, four voxels side
 * by side (transposes of the packed lookups' results), so that no voxel waits on the one
 * before: departure points and cells of the midpoints, midpoint lookups, points and cells of
 * the departure points, final lookups. Each voxel gets exactly advect1's operations. The
 * row's last nx % 4 voxels go through advect1. */
struct row {
    v4i c[SMOKE_MAX_RES / 4];
    v4f tx[SMOKE_MAX_RES / 4], ty[SMOKE_MAX_RES / 4], tz[SMOKE_MAX_RES / 4];
    int out[SMOKE_MAX_RES / 4];  /* lanes whose scalar lookup is 0 */
    v4f m[SMOKE_MAX_RES];        /* midpoint lookups */
};
typedef v4f (*lookup4_fn)(const struct advect_ctx *x, ptrdiff_t c, float tx, float ty, float tz);
#define ROW_GET4(x, r, g, l) get4((x), (r)->c[g][l], (r)->tx[g][l], (r)->ty[g][l], (r)->tz[g][l])
__attribute__((always_inline)) static inline void advect_row(const struct advect_ctx *x, struct row *r, size_t row,
                                                             uint32_t j, uint32_t k, lookup4_fn get4)
{
    const uint32_t groups = x->nx / 4;
    const float fj = (float)j, fk = (float)k;
    const v4f *qrow = x->q + (ptrdiff_t)j * x->dy + (ptrdiff_t)k * x->dz;
    struct cell cell[4];
    for (uint32_t g = 0; g < groups; g++) {
        __m128 a0 = (__m128)qrow[4 * g], a1 = (__m128)qrow[4 * g + 1], a2 = (__m128)qrow[4 * g + 2];
        __m128 a3 = (__m128)qrow[4 * g + 3];
        _MM_TRANSPOSE4_PS(a0, a1, a2, a3);  /* a0 a1 a2: u v w of the four voxels */
        const v4f fi = __builtin_convertvector(((v4i){0, 1, 2, 3} + (int32_t)(4 * g)), v4f);
        cells4(x, fi - x->hs * (v4f)a0, fj - x->hs * (v4f)a1, fk - x->hs * (v4f)a2, &r->c[g], &r->tx[g], &r->ty[g],
               &r->tz[g], cell);
    }
    for (uint32_t g = 0; g < groups; g++)
        for (int l = 0; l < 4; l++)
            r->m[4 * g + l] = ROW_GET4(x, r, g, l);
    for (uint32_t g = 0; g < groups; g++) {
        __m128 m0 = (__m128)r->m[4 * g], m1 = (__m128)r->m[4 * g + 1], m2 = (__m128)r->m[4 * g + 2];
        __m128 m3 = (__m128)r->m[4 * g + 3];
        _MM_TRANSPOSE4_PS(m0, m1, m2, m3);
        const v4f fi = __builtin_convertvector(((v4i){0, 1, 2, 3} + (int32_t)(4 * g)), v4f);
        const v4f px = fi - x->s * (v4f)m0, py = fj - x->s * (v4f)m1, pz = fk - x->s * (v4f)m2;
        const int slow = cells4(x, px, py, pz, &r->c[g], &r->tx[g], &r->ty[g], &r->tz[g], cell);
        /* the scalar: a fast cell's lower corner floor(p) lies outside [lo - 1, hi] when
         * p < lo - 1 or p >= hi + 1, and then the lookup is 0 (see advect_slab for an axis
         * where the box touches a face) */
        const v4i out = (px < x->blo[0]) | (px >= x->bhi[0]) | (py < x->blo[1]) | (py >= x->bhi[1]) |
                        (pz < x->blo[2]) | (pz >= x->bhi[2]);
        r->out[g] = _mm_movemask_ps((__m128)out) & ~slow;
        if (slow)
            for (int l = 0; l < 4; l++)
                if (slow >> l & 1)
                    r->out[g] |= cell_outside(&cell[l], x->b) << l;
    }
    for (uint32_t g = 0; g < groups; g++) {
        const size_t idx = row + 4 * g;
        if (x->vu) {
            __m128 r0 = (__m128)ROW_GET4(x, r, g, 0), r1 = (__m128)ROW_GET4(x, r, g, 1);
            __m128 r2 = (__m128)ROW_GET4(x, r, g, 2), r3 = (__m128)ROW_GET4(x, r, g, 3);
            _MM_TRANSPOSE4_PS(r0, r1, r2, r3);
            _mm_storeu_ps(x->vu + idx, r0);
            _mm_storeu_ps(x->vv + idx, r1);
            _mm_storeu_ps(x->vw + idx, r2);
            _mm_storeu_ps(x->vd + idx, (__m128)flush4((v4f)r3));
        }
        v4f t = {0, 0, 0, 0};
        if (r->out[g] != 15)
            for (int l = 0; l < 4; l++)
                if (!(r->out[g] >> l & 1))
                    t[l] = flush(lookup(x, r->c[g][l], r->tx[g][l], r->ty[g][l], r->tz[g][l]));
        _mm_storeu_ps(x->dst + idx, (__m128)t);
    }
    for (uint32_t i = 4 * groups; i < x->nx; i++)
        advect1(x, row + i, i, j, k);
}
/* advect_row with each lookup, the AVX one compiled for AVX (chosen where the CPU has it). */
__attribute__((target("avx"))) static void advect_row_avx(const struct advect_ctx *x, struct row *r, size_t row,
                                                          uint32_t j, uint32_t k)
{
    advect_row(x, r, row, j, k, lookup4_avx);
}
static void advect_row_sse(const struct advect_ctx *x, struct row *r, size_t row, uint32_t j, uint32_t k)
{
    advect_row(x, r, row, j, k, lookup4);
}

/* One pass for every advected field: the departure point of voxel (i, j, k) over dt by a
 * midpoint (RK2) backtrace through the packed velocity, in voxel units, then one cell
 * set-up for all fields: velocity and density into u v w d (vel set; the packed copy is
 * the input, so in place is safe), scalar `src` into `dst` (0 where its cell lies outside
 * the scalar's box). A row at a time (advect_row). */
struct advect_arg {
    float *const *vel;  /* u v w d, or NULL: only the scalar */
    float *dst;
    float dt;
    struct box src_box;
};
static void advect_slab(const struct fluid *f, void *p, uint32_t k0, uint32_t k1)
{
    const struct advect_arg *a = p;
    const size_t o = padded_origin(f);
    struct advect_ctx x = {
        .q = packed(f) + o, .src = packed_scalar(f) + o, .dst = a->dst, .nx = f->nx, .ny = f->ny, .nz = f->nz,
        .dy = (ptrdiff_t)f->nx + 2, .dz = ((ptrdiff_t)f->nx + 2) * ((ptrdiff_t)f->ny + 2), .s = a->dt / f->h,
        .b = &a->src_box,
    };
    x.hs = 0.5f * x.s;
    if (a->vel) {
        x.vu = a->vel[0];
        x.vv = a->vel[1];
        x.vw = a->vel[2];
        x.vd = a->vel[3];
    }
    const uint32_t n[3] = {f->nx, f->ny, f->nz};
    for (int ax = 0; ax < 3; ax++) {
        /* A fast cell with p in [-1, 0) or [n - 1, n) has the corners n - 1 and 0: outside
         * the box when lo >= 1 and hi <= n - 2, as the bounds say; where the box reaches a
         * face, no cell is outside along that axis (-inf, inf; an empty box has lo > hi). */
        const v4f zero = {0, 0, 0, 0};
        const struct box *b = &a->src_box;
        const int clear = b->lo[ax] > b->hi[ax] || (b->lo[ax] >= 1 && b->hi[ax] + 2 <= n[ax]);
        x.blo[ax] = zero + (clear ? (float)b->lo[ax] - 1.0f : -INFINITY);
        x.bhi[ax] = zero + (clear ? (float)b->hi[ax] + 1.0f : INFINITY);
        x.top[ax] = zero + (float)n[ax];
    }
    x.sy = (v4i){0, 0, 0, 0} + (int32_t)x.dy;
    x.sz = (v4i){0, 0, 0, 0} + (int32_t)x.dz;
    struct row *r = mem_alloc(sizeof *r);
    const int avx = !fluid_no_avx && __builtin_cpu_supports("avx");
    for (uint32_t k = k0; k < k1; k++)
        for (uint32_t j = 0; j < f->ny; j++) {
            if (avx)
                advect_row_avx(&x, r, at(f, 0, j, k), j, k);
            else
                advect_row_sse(&x, r, at(f, 0, j, k), j, k);
        }
    free(r);
}

void fluid_advect_scalar(const struct fluid *f, const float *src, float *dst, float dt)
{
    struct advect_arg a = {NULL, dst, dt, pack(f, src)};
    par_slabs(f, advect_slab, &a);
}

/* Velocity, density and temperature through the current velocity; temperature goes to the
 * spare array, which then becomes the temperature (a pointer swap). */
static void advect_all(struct fluid *f, float dt)
{
    float *vel[4] = {f->u, f->v, f->w, f->d};
    struct advect_arg a = {vel, f->spare, dt, pack(f, f->t)};
    par_slabs(f, advect_slab, &a);
    float *t = f->t;
    f->t = f->spare;
    f->spare = t;
}

/* ---- Fourier space ---- */

/* Signed wavenumber of index m along an axis of n samples and length len; 0 for the
 * Nyquist index (its mode is removed: its sign is ambiguous). */
static float wavenumber(uint32_t m, uint32_t n, float len, int *nyquist)
{
    *nyquist = (n % 2 == 0 && m == n / 2);
    int64_t s = m <= n / 2 ? (int64_t)m : (int64_t)m - (int64_t)n;
    return *nyquist ? 0.0f : (float)(2.0 * M_PI * (double)s / (double)len);
}

static void forward3(struct fluid *f)
{
    /* Out-of-place real-to-complex plans keep their input (FFTW_PRESERVE_INPUT is their
     * default), so the velocity is transformed where it lies. */
    float *in[3] = {f->u, f->v, f->w};
    for (int c = 0; c < 3; c++)
        fftwf_execute_dft_r2c(f->plan_fwd, in[c], f->spec[c]);
}

void fluid_project(struct fluid *f, float dt, float nu)
{
    struct clocks c = clocks_now();
    forward3(f);
    lap(f, &c, PH_FFT);
    float lx = f->h * (float)f->nx, ly = f->h * (float)f->ny, lz = f->h * (float)f->nz;
    uint32_t hx = f->nx / 2 + 1;
    float inv_n = 1.0f / (float)f->n;
    fftwf_complex *U = f->spec[0], *V = f->spec[1], *W = f->spec[2];
    size_t idx = 0;
    for (uint32_t k = 0; k < f->nz; k++) {
        int nqz;
        float kz = wavenumber(k, f->nz, lz, &nqz);
        for (uint32_t j = 0; j < f->ny; j++) {
            int nqy;
            float ky = wavenumber(j, f->ny, ly, &nqy);
            for (uint32_t i = 0; i < hx; i++, idx++) {
                int nqx;
                float kx = wavenumber(i, f->nx, lx, &nqx);
                float k2 = kx * kx + ky * ky + kz * kz;
                if (nqx || nqy || nqz) {
                    for (int r = 0; r < 2; r++)
                        U[idx][r] = V[idx][r] = W[idx][r] = 0.0f;
                    continue;
                }
                float decay = nu > 0.0f ? inv_n * expf(-nu * k2 * dt) : inv_n;
                for (int r = 0; r < 2; r++) {
                    float a = U[idx][r], b = V[idx][r], e = W[idx][r];
                    if (k2 > 0.0f) {
                        float p = (kx * a + ky * b + kz * e) / k2;
                        a -= kx * p;
                        b -= ky * p;
                        e -= kz * p;
                    }
                    U[idx][r] = a * decay;
                    V[idx][r] = b * decay;
                    W[idx][r] = e * decay;
                }
            }
        }
    }
    lap(f, &c, PH_SPECTRAL);
    float *out[3] = {f->u, f->v, f->w};
    for (int comp = 0; comp < 3; comp++)
        fftwf_execute_dft_c2r(f->plan_bwd, f->spec[comp], out[comp]);
    lap(f, &c, PH_FFT);
}

void fluid_divergence(struct fluid *f, double *div_norm, double *vel_norm)
{
    forward3(f);
    float lx = f->h * (float)f->nx, ly = f->h * (float)f->ny, lz = f->h * (float)f->nz;
    uint32_t hx = f->nx / 2 + 1;
    fftwf_complex *U = f->spec[0], *V = f->spec[1], *W = f->spec[2];
    double dsum = 0.0, vsum = 0.0;
    size_t idx = 0;
    for (uint32_t k = 0; k < f->nz; k++) {
        int nq;
        double kz = wavenumber(k, f->nz, lz, &nq);
        for (uint32_t j = 0; j < f->ny; j++) {
            double ky = wavenumber(j, f->ny, ly, &nq);
            for (uint32_t i = 0; i < hx; i++, idx++) {
                double kx = wavenumber(i, f->nx, lx, &nq);
                double k2 = kx * kx + ky * ky + kz * kz;
                for (int r = 0; r < 2; r++) {
                    double a = U[idx][r], b = V[idx][r], e = W[idx][r];
                    double dv = kx * a + ky * b + kz * e;
                    dsum += dv * dv;
                    vsum += k2 * (a * a + b * b + e * e);
                }
            }
        }
    }
    *div_norm = sqrt(dsum);
    *vel_norm = sqrt(vsum);
}

/* ---- source, forces, sponge ---- */

/* Index range [*lo, *hi] of the voxels along one axis whose centres (m + 0.5) h may lie
 * within r of c (one voxel of slack; the sphere test decides). */

static void source_span(float c, float r, float h, uint32_t n, uint32_t *lo, uint32_t *hi)
{
    float a = floorf((c - r) / h - 0.5f) - 1.0f, b = ceilf((c + r) / h - 0.5f) + 1.0f;
    *lo = a <= 0.0f ? 0 : (a >= (float)(n - 1) ? n - 1 : (uint32_t)a);
    *hi = b <= 0.0f ? 0 : (b >= (float)(n - 1) ? n - 1 : (uint32_t)b);
}

static void add_source(struct fluid *f, float dt)
{
    const struct smoke_settings *s = &f->s;
    float r = s->source_radius, r2 = r * r;
    uint32_t lo[3], hi[3];
    const uint32_t n[3] = {f->nx, f->ny, f->nz};
    for (int a = 0; a < 3; a++)
        source_span(s->source_center[a], r, f->h, n[a], &lo[a], &hi[a]);
    for (uint32_t k = lo[2]; k <= hi[2]; k++)
        for (uint32_t j = lo[1]; j <= hi[1]; j++)
            for (uint32_t i = lo[0]; i <= hi[0]; i++) {
                size_t idx = at(f, i, j, k);
                float dx = ((float)i + 0.5f) * f->h - s->source_center[0];
                float dy = ((float)j + 0.5f) * f->h - s->source_center[1];
                float dz = ((float)k + 0.5f) * f->h - s->source_center[2];
                float q = (dx * dx + dy * dy + dz * dz) / r2;
                if (q >= 1.0f)
                    continue;
                float wgt = 1.0f - q;  /* smooth falloff to 0 at the radius */
                float noise = rng_uniform(rng_key(s->seed, (uint32_t)f->step, idx, 0), 0);
                float rate = s->source_rate * (1.0f + s->source_jitter * (2.0f * noise - 1.0f));
                f->d[idx] += dt * rate * wgt;
                f->t[idx] += wgt * (s->source_temperature - f->t[idx]);
                f->u[idx] += wgt * (s->source_velocity[0] - f->u[idx]);
                f->v[idx] += wgt * (s->source_velocity[1] - f->v[idx]);
                f->w[idx] += wgt * (s->source_velocity[2] - f->w[idx]);
            }
}


/* A row of q with its periodic neighbours across the x faces, buf[-1] and buf[nx]. */
static const float *row_halo(const float *q, uint32_t nx, float *buf)
{
    memcpy(buf, q, nx * sizeof(float));
    buf[-1] = q[nx - 1];
    buf[nx] = q[0];
    return buf;
}

/* Buoyancy (Fedkiw et al. 2001: f = (-alpha d + beta T) up, ambient temperature 0) and
 * vorticity confinement f = epsilon h (N x omega), N = grad|omega| / |grad|omega||, with
 * periodic central differences. First pass: omega and |omega| (into tmp[0..3]); second:
 * buoyancy and the confinement force. Rows at a time, the neighbours across the x faces
 * from a halo copy, and in the second pass every voxel's confinement computed and kept
 * where |grad|omega|| > 1e-20: loops the compiler turns into SIMD code (lane-wise, so the
 * same bits as voxel by voxel). */
/* One row of omega and |omega| (the x neighbours: wxp[i] = w[i + 1], wxm[i] = w[i - 1]). */
static void vorticity_row(uint32_t nx, float inv2h, const float *restrict wjp, const float *restrict wjm,
                          const float *restrict vkp, const float *restrict vkm, const float *restrict ukp,
                          const float *restrict ukm, const float *restrict ujp, const float *restrict ujm,
                          const float *restrict wxp, const float *restrict wxm, const float *restrict vxp,
                          const float *restrict vxm, float *restrict ox, float *restrict oy, float *restrict oz,
                          float *restrict mag)
{
    for (uint32_t i = 0; i < nx; i++) {
        float dwdy = (wjp[i] - wjm[i]) * inv2h;
        float dvdz = (vkp[i] - vkm[i]) * inv2h;
        float dudz = (ukp[i] - ukm[i]) * inv2h;
        float dwdx = (wxp[i] - wxm[i]) * inv2h;
        float dvdx = (vxp[i] - vxm[i]) * inv2h;
        float dudy = (ujp[i] - ujm[i]) * inv2h;
        float a = dwdy - dvdz, b = dudz - dwdx, e = dvdx - dudy;
        ox[i] = a;
        oy[i] = b;
        oz[i] = e;
        mag[i] = sqrtf(a * a + b * b + e * e);
    }
}

static void vorticity_slab(const struct fluid *f, void *arg, uint32_t k0, uint32_t k1)
{
    (void)arg;
    const float inv2h = 0.5f / f->h;
    const uint32_t nx = f->nx;
    float *buf = mem_alloc(2 * ((size_t)nx + 2) * sizeof(float));
    for (uint32_t k = k0; k < k1; k++) {
        uint32_t km = k ? k - 1 : f->nz - 1, kp = k + 1 == f->nz ? 0 : k + 1;
        for (uint32_t j = 0; j < f->ny; j++) {
            uint32_t jm = j ? j - 1 : f->ny - 1, jp = j + 1 == f->ny ? 0 : j + 1;
            const size_t c = at(f, 0, j, k), cjm = at(f, 0, jm, k), cjp = at(f, 0, jp, k);
            const size_t ckm = at(f, 0, j, km), ckp = at(f, 0, j, kp);
            const float *wx = row_halo(f->w + c, nx, buf + 1), *vx = row_halo(f->v + c, nx, buf + nx + 3);
            vorticity_row(nx, inv2h, f->w + cjp, f->w + cjm, f->v + ckp, f->v + ckm, f->u + ckp, f->u + ckm,
                          f->u + cjp, f->u + cjm, wx + 1, wx - 1, vx + 1, vx - 1, f->tmp[0] + c, f->tmp[1] + c,
                          f->tmp[2] + c, f->tmp[3] + c);
        }
    }
    free(buf);
}

/* a where the mask m is all ones, b where it is 0 (bitwise, so loops of it vectorize). */
static inline float pick(uint32_t m, float a, float b)
{
    uint32_t ia, ib;
    memcpy(&ia, &a, sizeof ia);
    memcpy(&ib, &b, sizeof ib);
    ia = (ia & m) | (ib & ~m);
    memcpy(&a, &ia, sizeof a);
    return a;
}

/* One row of buoyancy and confinement (mxp[i] = |omega|[i + 1], mxm[i] = |omega|[i - 1]). */
static void force_row(uint32_t nx, float dt, float alpha, float beta, float inv2h, float scale, float *restrict u,
                      float *restrict v, float *restrict w, const float *restrict d, const float *restrict t,
                      const float *restrict ox, const float *restrict oy, const float *restrict oz,
                      const float *restrict mxp, const float *restrict mxm, const float *restrict mjp,
                      const float *restrict mjm, const float *restrict mkp, const float *restrict mkm)
{
    for (uint32_t i = 0; i < nx; i++) {
        float vi = v[i] + dt * (-alpha * d[i] + beta * t[i]);
        float gx = (mxp[i] - mxm[i]) * inv2h;
        float gy = (mjp[i] - mjm[i]) * inv2h;
        float gz = (mkp[i] - mkm[i]) * inv2h;
        float gl = sqrtf(gx * gx + gy * gy + gz * gz);
        const uint32_t ok = -(uint32_t)(gl > 1e-20f);  /* no direction where |omega| is flat */
        gx /= gl;
        gy /= gl;
        gz /= gl;
        float fu = scale * (gy * oz[i] - gz * oy[i]);
        float fv = scale * (gz * ox[i] - gx * oz[i]);
        float fw = scale * (gx * oy[i] - gy * ox[i]);
        u[i] = pick(ok, u[i] + fu, u[i]);
        v[i] = pick(ok, vi + fv, vi);
        w[i] = pick(ok, w[i] + fw, w[i]);
    }
}

static void force_slab(const struct fluid *f, void *arg, uint32_t k0, uint32_t k1)
{
    const struct smoke_settings *s = &f->s;
    const float dt = *(const float *)arg, inv2h = 0.5f / f->h, scale = s->epsilon * f->h * dt;
    const uint32_t nx = f->nx;
    const float *mag = f->tmp[3];
    float *buf = mem_alloc(((size_t)nx + 2) * sizeof(float));
    for (uint32_t k = k0; k < k1; k++) {
        uint32_t km = k ? k - 1 : f->nz - 1, kp = k + 1 == f->nz ? 0 : k + 1;
        for (uint32_t j = 0; j < f->ny; j++) {
            uint32_t jm = j ? j - 1 : f->ny - 1, jp = j + 1 == f->ny ? 0 : j + 1;
            const size_t c = at(f, 0, j, k);
            if (s->epsilon <= 0.0f) {
                float *restrict v = f->v + c;
                const float *restrict d = f->d + c, *restrict t = f->t + c;
                for (uint32_t i = 0; i < nx; i++)
                    v[i] += dt * (-s->alpha * d[i] + s->beta * t[i]);
                continue;
            }
            const float *mx = row_halo(mag + c, nx, buf + 1);
            force_row(nx, dt, s->alpha, s->beta, inv2h, scale, f->u + c, f->v + c, f->w + c, f->d + c, f->t + c,
                      f->tmp[0] + c, f->tmp[1] + c, f->tmp[2] + c, mx + 1, mx - 1, mag + at(f, 0, jp, k),
                      mag + at(f, 0, jm, k), mag + at(f, 0, j, kp), mag + at(f, 0, j, km));
        }
    }
    free(buf);
}

static void add_forces(struct fluid *f, float dt)
{
    if (f->s.epsilon > 0.0f)
        par_slabs(f, vorticity_slab, &dt);
    par_slabs(f, force_slab, &dt);
}

/* Damping rate at index m of n: strength ((W - e) / W)^2 where e is the distance to the
 * nearer face, within the sponge width W; 0 inside. */
static float sponge_rate(const struct smoke_settings *s, uint32_t m, uint32_t n)
{
    uint32_t e = m < n - 1 - m ? m : n - 1 - m;
    if (e >= s->sponge_width)
        return 0.0f;
    float r = (float)(s->sponge_width - e) / (float)s->sponge_width;
    return s->sponge_strength * r * r;
}

/* exp(-max(rates) dt) is the smallest of the per-axis factors exp(-rate dt) (exp falls):
 * the factors are tabled per axis. */
struct sponge_arg {
    float *const *fields;
    int count;
    const float *damp[3];
};
/* fields[c][i] *= min(damp0[i], dy) for i in [i0, i1): a loop GCC vectorizes (a factor 1
 * changes no bits). */
static void sponge_run(float *restrict q, const float *restrict damp0, float dy, uint32_t i0, uint32_t i1)
{
    for (uint32_t i = i0; i < i1; i++)
        q[i] *= damp0[i] < dy ? damp0[i] : dy;
}

static void sponge_slab(const struct fluid *f, void *p, uint32_t k0, uint32_t k1)
{
    const struct sponge_arg *a = p;
    /* [xa, xb): the voxels of a row that the x faces' sponge leaves alone */
    uint32_t xa = 0, xb = f->nx;
    while (xa < f->nx && a->damp[0][xa] != 1.0f)
        xa++;
    while (xb > xa && a->damp[0][xb - 1] != 1.0f)
        xb--;
    for (uint32_t k = k0; k < k1; k++) {
        float dz = a->damp[2][k];
        for (uint32_t j = 0; j < f->ny; j++) {
            float dy = a->damp[1][j] < dz ? a->damp[1][j] : dz;
            size_t row = at(f, 0, j, k);
            for (int c = 0; c < a->count; c++) {
                if (dy == 1.0f) {  /* nothing to damp between xa and xb */
                    sponge_run(a->fields[c] + row, a->damp[0], dy, 0, xa);
                    sponge_run(a->fields[c] + row, a->damp[0], dy, xb, f->nx);
                } else {
                    sponge_run(a->fields[c] + row, a->damp[0], dy, 0, f->nx);
                }
            }
        }
    }
}

static void sponge(struct fluid *f, float *const *fields, int count, float dt)
{
    if (f->s.sponge_width == 0 || f->s.sponge_strength <= 0.0f)
        return;
    float *tab = mem_alloc(((size_t)f->nx + f->ny + f->nz) * sizeof(float));
    const uint32_t n[3] = {f->nx, f->ny, f->nz};
    for (uint32_t ax = 0, o = 0; ax < 3; o += n[ax++])
        for (uint32_t m = 0; m < n[ax]; m++) {
            float rate = sponge_rate(&f->s, m, n[ax]);
            tab[o + m] = rate > 0.0f ? expf(-rate * dt) : 1.0f;
        }
    struct sponge_arg a = {fields, count, {tab, tab + f->nx, tab + f->nx + f->ny}};
    par_slabs(f, sponge_slab, &a);
    free(tab);
}

void fluid_step(struct fluid *f)
{
    float dt = f->s.dt;
    struct clocks c = clocks_now();
    advect_all(f, dt);
    lap(f, &c, PH_ADVECT);
    add_source(f, dt);
    lap(f, &c, PH_SOURCE);
    add_forces(f, dt);
    lap(f, &c, PH_FORCES);
    float *all[5] = {f->u, f->v, f->w, f->d, f->t};
    sponge(f, all, 5, dt);
    lap(f, &c, PH_SPONGE);
    fluid_project(f, dt, f->s.viscosity);
    f->step++;
}
