/* Stable fluids solver (see fluid.h and docs/smoke.md). */
#include "fluid.h"
#include "base/log.h"
#include "base/rng.h"
#include <fftw3.h>
#include <math.h>
#include <pthread.h>
#include <string.h>
#include <time.h>

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
    /* five fields, four scratch, three half spectra (nx/2+1 complex per nx reals ~ 1 float) */
    return 9 * sizeof(float) + 3 * sizeof(float) * 1;
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
    float **fields[] = {&f->u, &f->v, &f->w, &f->d, &f->t, &f->tmp[0], &f->tmp[1], &f->tmp[2], &f->tmp[3]};
    for (size_t i = 0; i < sizeof fields / sizeof *fields; i++) {
        *fields[i] = fftwf_malloc(f->n * sizeof(float));
        CHECK(*fields[i] != NULL);
        memset(*fields[i], 0, f->n * sizeof(float));
    }
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
    float *fields[] = {f->u, f->v, f->w, f->d, f->t, f->tmp[0], f->tmp[1], f->tmp[2], f->tmp[3]};
    for (size_t i = 0; i < sizeof fields / sizeof *fields; i++)
        fftwf_free(fields[i]);
    for (int c = 0; c < 3; c++)
        fftwf_free(f->spec[c]);
    memset(f, 0, sizeof *f);
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

static inline uint32_t wrap(int64_t i, uint32_t n)
{
    int64_t m = i % (int64_t)n;
    return (uint32_t)(m < 0 ? m + n : m);
}

/* Trilinear weights at voxel coordinates (x, y, z), voxel centres at integers, on the
 * periodic grid: the four x rows' starts, the two x indices and the fractions. */
struct lerp {
    size_t r[4];  /* rows (y0 z0) (y1 z0) (y0 z1) (y1 z1) */
    uint32_t x0, x1;
    float tx, ty, tz;
};

static inline uint32_t wrap_index(float c, uint32_t n)
{
    int64_t i = (int64_t)c;
    if (i >= 0 && i < (int64_t)n)
        return (uint32_t)i;
    return wrap(i, n);
}

static inline void lerp_at(const struct fluid *f, float x, float y, float z, struct lerp *l)
{
    /* Far outside (huge velocities): clamp before the integer conversion; periodicity
     * makes any finite position valid. */
    const float lim = 1e6f;
    x = fminf(fmaxf(x, -lim), lim);
    y = fminf(fmaxf(y, -lim), lim);
    z = fminf(fmaxf(z, -lim), lim);
    float fx = floorf(x), fy = floorf(y), fz = floorf(z);
    l->tx = x - fx;
    l->ty = y - fy;
    l->tz = z - fz;
    l->x0 = wrap_index(fx, f->nx);
    l->x1 = l->x0 + 1 == f->nx ? 0 : l->x0 + 1;
    uint32_t y0 = wrap_index(fy, f->ny), y1 = y0 + 1 == f->ny ? 0 : y0 + 1;
    uint32_t z0 = wrap_index(fz, f->nz), z1 = z0 + 1 == f->nz ? 0 : z0 + 1;
    size_t sx = f->nx, sxy = (size_t)f->nx * f->ny;
    l->r[0] = y0 * sx + z0 * sxy;
    l->r[1] = y1 * sx + z0 * sxy;
    l->r[2] = y0 * sx + z1 * sxy;
    l->r[3] = y1 * sx + z1 * sxy;
}

/* Written as a + t (b - a), so a constant field comes back exactly. */
static inline float lerp_get(const struct lerp *l, const float *q)
{
    float a[4];
    for (int i = 0; i < 4; i++)
        a[i] = q[l->r[i] + l->x0] + l->tx * (q[l->r[i] + l->x1] - q[l->r[i] + l->x0]);
    float b0 = a[0] + l->ty * (a[1] - a[0]), b1 = a[2] + l->ty * (a[3] - a[2]);
    return b0 + l->tz * (b1 - b0);
}

/* Departure point of voxel (i, j, k) over dt: midpoint (RK2) backtrace through the
 * current velocity, in voxel units; its weights in *l. */
static void backtrace(const struct fluid *f, uint32_t i, uint32_t j, uint32_t k, size_t idx, float dt,
                      struct lerp *l)
{
    float s = dt / f->h;
    lerp_at(f, (float)i - 0.5f * s * f->u[idx], (float)j - 0.5f * s * f->v[idx], (float)k - 0.5f * s * f->w[idx], l);
    float ux = lerp_get(l, f->u), vy = lerp_get(l, f->v), wz = lerp_get(l, f->w);
    lerp_at(f, (float)i - s * ux, (float)j - s * vy, (float)k - s * wz, l);
}

/* Advects count fields src[c] into dst[c] through the current velocity. */
struct advect_arg {
    const float *const *src;
    float *const *dst;
    int count;
    float dt;
};
static void advect_slab(const struct fluid *f, void *p, uint32_t k0, uint32_t k1)
{
    const struct advect_arg *a = p;
    size_t idx = (size_t)k0 * f->nx * f->ny;
    for (uint32_t k = k0; k < k1; k++)
        for (uint32_t j = 0; j < f->ny; j++)
            for (uint32_t i = 0; i < f->nx; i++, idx++) {
                struct lerp l;
                backtrace(f, i, j, k, idx, a->dt, &l);
                for (int c = 0; c < a->count; c++)
                    a->dst[c][idx] = lerp_get(&l, a->src[c]);
            }
}
static void advect_fields(const struct fluid *f, const float *const *src, float *const *dst, int count, float dt)
{
    struct advect_arg a = {src, dst, count, dt};
    par_slabs(f, advect_slab, &a);
}

void fluid_advect_scalar(const struct fluid *f, const float *src, float *dst, float dt)
{
    advect_fields(f, &src, &dst, 1, dt);
}

static void advect_velocity(struct fluid *f, float dt)
{
    const float *src[3] = {f->u, f->v, f->w};
    float *dst[3] = {f->tmp[0], f->tmp[1], f->tmp[2]};
    advect_fields(f, src, dst, 3, dt);
    memcpy(f->u, f->tmp[0], f->n * sizeof(float));
    memcpy(f->v, f->tmp[1], f->n * sizeof(float));
    memcpy(f->w, f->tmp[2], f->n * sizeof(float));
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
    float *in[3] = {f->u, f->v, f->w};
    for (int c = 0; c < 3; c++) {
        /* r2c keeps its input with out-of-place plans only when told; copy to scratch. */
        memcpy(f->tmp[0], in[c], f->n * sizeof(float));
        fftwf_execute_dft_r2c(f->plan_fwd, f->tmp[0], f->spec[c]);
    }
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
                float decay = inv_n * expf(-nu * k2 * dt);
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

static void add_source(struct fluid *f, float dt)
{
    const struct smoke_settings *s = &f->s;
    float r = s->source_radius, r2 = r * r;
    size_t idx = 0;
    for (uint32_t k = 0; k < f->nz; k++)
        for (uint32_t j = 0; j < f->ny; j++)
            for (uint32_t i = 0; i < f->nx; i++, idx++) {
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

static inline size_t at(const struct fluid *f, uint32_t i, uint32_t j, uint32_t k)
{
    return i + (size_t)f->nx * (j + (size_t)f->ny * k);
}

/* Buoyancy (Fedkiw et al. 2001: f = (-alpha d + beta T) up, ambient temperature 0) and
 * vorticity confinement f = epsilon h (N x omega), N = grad|omega| / |grad|omega||, with
 * periodic central differences. First pass: buoyancy and omega (into tmp[0..3]); second:
 * the confinement force. */
static void vorticity_slab(const struct fluid *f, void *arg, uint32_t k0, uint32_t k1)
{
    (void)arg;
    float inv2h = 0.5f / f->h;
    float *ox = f->tmp[0], *oy = f->tmp[1], *oz = f->tmp[2], *mag = f->tmp[3];
    for (uint32_t k = k0; k < k1; k++) {
        uint32_t km = k ? k - 1 : f->nz - 1, kp = k + 1 == f->nz ? 0 : k + 1;
        for (uint32_t j = 0; j < f->ny; j++) {
            uint32_t jm = j ? j - 1 : f->ny - 1, jp = j + 1 == f->ny ? 0 : j + 1;
            for (uint32_t i = 0; i < f->nx; i++) {
                uint32_t im = i ? i - 1 : f->nx - 1, ip = i + 1 == f->nx ? 0 : i + 1;
                size_t c = at(f, i, j, k);
                float dwdy = (f->w[at(f, i, jp, k)] - f->w[at(f, i, jm, k)]) * inv2h;
                float dvdz = (f->v[at(f, i, j, kp)] - f->v[at(f, i, j, km)]) * inv2h;
                float dudz = (f->u[at(f, i, j, kp)] - f->u[at(f, i, j, km)]) * inv2h;
                float dwdx = (f->w[at(f, ip, j, k)] - f->w[at(f, im, j, k)]) * inv2h;
                float dvdx = (f->v[at(f, ip, j, k)] - f->v[at(f, im, j, k)]) * inv2h;
                float dudy = (f->u[at(f, i, jp, k)] - f->u[at(f, i, jm, k)]) * inv2h;
                ox[c] = dwdy - dvdz;
                oy[c] = dudz - dwdx;
                oz[c] = dvdx - dudy;
                mag[c] = sqrtf(ox[c] * ox[c] + oy[c] * oy[c] + oz[c] * oz[c]);
            }
        }
    }
}

static void force_slab(const struct fluid *f, void *arg, uint32_t k0, uint32_t k1)
{
    const struct smoke_settings *s = &f->s;
    float dt = *(const float *)arg;
    float inv2h = 0.5f / f->h;
    const float *ox = f->tmp[0], *oy = f->tmp[1], *oz = f->tmp[2], *mag = f->tmp[3];
    float scale = s->epsilon * f->h * dt;
    for (uint32_t k = k0; k < k1; k++) {
        uint32_t km = k ? k - 1 : f->nz - 1, kp = k + 1 == f->nz ? 0 : k + 1;
        for (uint32_t j = 0; j < f->ny; j++) {
            uint32_t jm = j ? j - 1 : f->ny - 1, jp = j + 1 == f->ny ? 0 : j + 1;
            for (uint32_t i = 0; i < f->nx; i++) {
                size_t c = at(f, i, j, k);
                f->v[c] += dt * (-s->alpha * f->d[c] + s->beta * f->t[c]);
                if (s->epsilon <= 0.0f)
                    continue;
                uint32_t im = i ? i - 1 : f->nx - 1, ip = i + 1 == f->nx ? 0 : i + 1;
                float gx = (mag[at(f, ip, j, k)] - mag[at(f, im, j, k)]) * inv2h;
                float gy = (mag[at(f, i, jp, k)] - mag[at(f, i, jm, k)]) * inv2h;
                float gz = (mag[at(f, i, j, kp)] - mag[at(f, i, j, km)]) * inv2h;
                float gl = sqrtf(gx * gx + gy * gy + gz * gz);
                if (!(gl > 1e-20f))
                    continue;
                gx /= gl;
                gy /= gl;
                gz /= gl;
                f->u[c] += scale * (gy * oz[c] - gz * oy[c]);
                f->v[c] += scale * (gz * ox[c] - gx * oz[c]);
                f->w[c] += scale * (gx * oy[c] - gy * ox[c]);
            }
        }
    }
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

static void sponge(struct fluid *f, float *const *fields, int count, float dt)
{
    if (f->s.sponge_width == 0 || f->s.sponge_strength <= 0.0f)
        return;
    for (uint32_t k = 0; k < f->nz; k++) {
        float rz = sponge_rate(&f->s, k, f->nz);
        for (uint32_t j = 0; j < f->ny; j++) {
            float ry = fmaxf(rz, sponge_rate(&f->s, j, f->ny));
            size_t row = at(f, 0, j, k);
            for (uint32_t i = 0; i < f->nx; i++) {
                float rate = fmaxf(ry, sponge_rate(&f->s, i, f->nx));
                if (rate <= 0.0f)
                    continue;
                float damp = expf(-rate * dt);
                for (int c = 0; c < count; c++)
                    fields[c][row + i] *= damp;
            }
        }
    }
}

void fluid_step(struct fluid *f)
{
    float dt = f->s.dt;
    struct clocks c = clocks_now();
    add_source(f, dt);
    lap(f, &c, PH_SOURCE);
    add_forces(f, dt);
    lap(f, &c, PH_FORCES);
    advect_velocity(f, dt);
    lap(f, &c, PH_ADVECT);
    float *vel[3] = {f->u, f->v, f->w};
    sponge(f, vel, 3, dt);
    lap(f, &c, PH_SPONGE);
    fluid_project(f, dt, f->s.viscosity);
    c = clocks_now();
    const float *src[2] = {f->d, f->t};
    float *dst[2] = {f->tmp[0], f->tmp[1]};
    advect_fields(f, src, dst, 2, dt);
    memcpy(f->d, f->tmp[0], f->n * sizeof(float));
    memcpy(f->t, f->tmp[1], f->n * sizeof(float));
    lap(f, &c, PH_ADVECT);
    float *sc[2] = {f->d, f->t};
    sponge(f, sc, 2, dt);
    lap(f, &c, PH_SPONGE);
    f->step++;
}
