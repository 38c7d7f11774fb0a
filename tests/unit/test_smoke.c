/* The smoke simulator (smoke/):
 * - after projection the spectral divergence is at most 1e-6 of the velocity gradient's
 *   norm (both summed over the modes), and a gradient plus a curl, built in closed form,
 *   comes back as the curl alone (so a missing or wrong projection fails);
 * - diffusion is exact: single Fourier modes along x, y, z and a diagonal decay as
 *   exp(-nu |k|^2 t) within 1e-6 relative;
 * - advection leaves a constant field exactly constant, and gives the bits of the plain
 *   scheme written voxel by voxel (fast paths, halo, box, far points);
 * - advection without source or sponge conserves total density within 1e-4 per step on a
 *   blob in a divergence-free field (the loss measured is printed; docs/smoke.md);
 * - the same settings give bit-identical fields with 1 and 2 FFTW threads, and a run
 *   resumed from a checkpoint is bit-identical to one that never stopped;
 * - a frame written as a grid reads back through the renderer's grid parser, equal; written
 *   as NanoVDB it reads back through the renderer's NanoVDB parser and samples, placed in
 *   the world, as the dense one does within the stated threshold;
 * - zero viscosity, huge buoyancy and a source on the border stay finite;
 * - settings: a 1-voxel domain, NaN, unknown keys and bad patterns are refused with
 *   file:line:col. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "base/rng.h"
#include "smoke/fluid.h"
#include "smoke/settings.h"
#include "smoke/store.h"
#include "scene/grid.h"
#include "scene/medium.h"
#include "scene/nvdb.h"
#include "helpers.h"

static void small_settings(struct smoke_settings *s, uint32_t nx, uint32_t ny, uint32_t nz)
{
    smoke_settings_default(s);
    s->res[0] = nx;
    s->res[1] = ny;
    s->res[2] = nz;
    s->size = 1.0f;
}

/* A smooth random velocity: a few random Fourier modes per component. */
static void random_velocity(struct fluid *f, uint64_t seed, float amp)
{
    float *c[3] = {f->u, f->v, f->w};
    for (int comp = 0; comp < 3; comp++)
        for (int m = 0; m < 4; m++) {
            uint64_t key = rng_key(seed, (uint32_t)comp, (uint64_t)m, 0);
            float kx = (float)(int)(rng_uniform(key, 0) * 4), ky = (float)(int)(rng_uniform(key, 1) * 4),
                  kz = (float)(int)(rng_uniform(key, 2) * 4), ph = 6.2831853f * rng_uniform(key, 3);
            size_t idx = 0;
            for (uint32_t k = 0; k < f->nz; k++)
                for (uint32_t j = 0; j < f->ny; j++)
                    for (uint32_t i = 0; i < f->nx; i++, idx++)
                        c[comp][idx] += amp * sinf(6.2831853f * (kx * (float)i / (float)f->nx +
                                                               ky * (float)j / (float)f->ny +
                                                               kz * (float)k / (float)f->nz) + ph);
        }
}

/* A fluid of nx ny nz voxels with default settings and random_velocity(seed, amp). */
static void fluid_with_velocity(struct fluid *f, uint32_t nx, uint32_t ny, uint32_t nz, uint64_t seed, float amp)
{
    struct smoke_settings s;
    small_settings(&s, nx, ny, nz);
    fluid_init(f, &s);
    random_velocity(f, seed, amp);
}

Test(smoke, projection_is_divergence_free)
{
    struct fluid f;
    fluid_with_velocity(&f, 16, 24, 12, 3, 1.0f);
    double div0, vel0, div, vel;
    fluid_divergence(&f, &div0, &vel0);
    cr_assert_gt(div0, 0.1 * vel0, "the test field must start divergent (%g of %g)", div0, vel0);
    fluid_project(&f, 0.01f, 0.0f);
    fluid_divergence(&f, &div, &vel);
    cr_assert_gt(vel, 0.1 * vel0);
    cr_assert_leq(div, 1e-6 * vel, "divergence %g against velocity %g (ratio %g)", div, vel, div / vel);
    fluid_free(&f);
}

/* u = grad phi + curl A on a 16x24x12 grid (voxel edge 1/16), each from a few Fourier
 * modes in closed form: the projection must return curl A alone. Without it (or with a
 * wrong sign, axes swapped, wavenumbers off by the axis length) grad phi remains. */
Test(smoke, projection_keeps_the_curl_removes_the_gradient)
{
    struct smoke_settings s;
    small_settings(&s, 16, 24, 12);
    struct fluid f;
    fluid_init(&f, &s);
    const double tau = 2.0 * M_PI;
    const double len[3] = {f.h * 16.0, f.h * 24.0, f.h * 12.0};
    /* (mode numbers, amplitude, phase) for phi, and for A = (0, 0, a) then (a, 0, 0) */
    const struct { int m[3]; double amp, ph; } phi[2] = {{{1, 2, 0}, 0.05, 0.3}, {{2, 1, 3}, 0.02, 1.1}},
                                                 az = {{1, 3, 2}, 0.04, 0.7}, ax = {{0, 2, 1}, 0.03, 2.0};
    float *want = calloc(3 * f.n, sizeof(float));
    float *out[3] = {f.u, f.v, f.w};
    double big = 0.0, wmax = 0.0;
    size_t idx = 0;
    for (uint32_t k = 0; k < f.nz; k++)
        for (uint32_t j = 0; j < f.ny; j++)
            for (uint32_t i = 0; i < f.nx; i++, idx++) {
                const double x[3] = {i * (double)f.h, j * (double)f.h, k * (double)f.h};
                double g[3] = {0, 0, 0}, c[3] = {0, 0, 0};
                for (int m = 0; m < 2; m++) {
                    double arg = phi[m].ph, kv[3];
                    for (int a = 0; a < 3; a++) {
                        kv[a] = tau * phi[m].m[a] / len[a];
                        arg += kv[a] * x[a];
                    }
                    for (int a = 0; a < 3; a++)
                        g[a] += phi[m].amp * kv[a] * cos(arg);
                }
                double argz = az.ph, argx = ax.ph, kz[3], kx[3];
                for (int a = 0; a < 3; a++) {
                    kz[a] = tau * az.m[a] / len[a];
                    kx[a] = tau * ax.m[a] / len[a];
                    argz += kz[a] * x[a];
                    argx += kx[a] * x[a];
                }
                /* curl (0, 0, a) = (da/dy, -da/dx, 0); curl (a, 0, 0) = (0, da/dz, -da/dy) */
                c[0] += az.amp * kz[1] * cos(argz);
                c[1] += -az.amp * kz[0] * cos(argz) + ax.amp * kx[2] * cos(argx);
                c[2] += -ax.amp * kx[1] * cos(argx);
                for (int a = 0; a < 3; a++) {
                    out[a][idx] = (float)(g[a] + c[a]);
                    want[3 * idx + a] = (float)c[a];
                    big = fmax(big, fabs(g[a]));
                    wmax = fmax(wmax, fabs(c[a]));
                }
            }
    cr_assert_gt(big, 0.5 * wmax, "the gradient part must be large (%g against %g)", big, wmax);
    fluid_project(&f, 0.01f, 0.0f);
    double worst = 0.0;
    for (size_t i = 0; i < f.n; i++)
        for (int a = 0; a < 3; a++)
            worst = fmax(worst, fabs(out[a][i] - want[3 * i + a]));
    fprintf(stderr, "smoke: projection of grad + curl: worst error %.3g of %.3g\n", worst, wmax);
    cr_assert_leq(worst, 1e-5 * wmax, "worst error %g against the curl's %g", worst, wmax);
    free(want);
    fluid_free(&f);
}

/* A single mode u = a sin(2 pi (m . x / L)), a perpendicular to its wavevector k
 * (divergence-free), through diffusion by nu over dt: a exp(-nu |k|^2 dt) sin(...) within
 * 1e-6 of the amplitude at every voxel and component. */
static void mode_decays(const int m[3])
{
    struct smoke_settings s;
    small_settings(&s, 32, 16, 16);
    s.size = 2.0f;
    struct fluid f;
    fluid_init(&f, &s);
    const double tau = 2.0 * M_PI;
    const double len[3] = {(double)f.h * f.nx, (double)f.h * f.ny, (double)f.h * f.nz};
    double kv[3], k2 = 0.0;
    for (int a = 0; a < 3; a++) {
        kv[a] = tau * m[a] / len[a];
        k2 += kv[a] * kv[a];
    }
    /* a = k x e, e the axis least aligned with k, normalised */
    int e = fabs(kv[0]) <= fabs(kv[1]) && fabs(kv[0]) <= fabs(kv[2]) ? 0 : (fabs(kv[1]) <= fabs(kv[2]) ? 1 : 2);
    double ev[3] = {0, 0, 0};
    ev[e] = 1.0;
    double amp[3] = {kv[1] * ev[2] - kv[2] * ev[1], kv[2] * ev[0] - kv[0] * ev[2], kv[0] * ev[1] - kv[1] * ev[0]};
    double an = sqrt(amp[0] * amp[0] + amp[1] * amp[1] + amp[2] * amp[2]);
    for (int a = 0; a < 3; a++)
        amp[a] /= an;
    float *c[3] = {f.u, f.v, f.w};
    size_t idx = 0;
    for (uint32_t k = 0; k < f.nz; k++)
        for (uint32_t j = 0; j < f.ny; j++)
            for (uint32_t i = 0; i < f.nx; i++, idx++) {
                double ph = tau * ((double)m[0] * i / f.nx + (double)m[1] * j / f.ny + (double)m[2] * k / f.nz);
                for (int a = 0; a < 3; a++)
                    c[a][idx] = (float)(amp[a] * sin(ph));
            }
    const float nu = 0.01f, dt = 0.5f;
    fluid_project(&f, dt, nu);
    double decay = exp(-(double)nu * k2 * dt), worst = 0.0;
    idx = 0;
    for (uint32_t k = 0; k < f.nz; k++)
        for (uint32_t j = 0; j < f.ny; j++)
            for (uint32_t i = 0; i < f.nx; i++, idx++) {
                double ph = tau * ((double)m[0] * i / f.nx + (double)m[1] * j / f.ny + (double)m[2] * k / f.nz);
                for (int a = 0; a < 3; a++)
                    worst = fmax(worst, fabs(c[a][idx] - amp[a] * decay * sin(ph)) / decay);
            }
    cr_assert_lt(decay, 0.9, "mode %d %d %d: the decay must be visible (%g)", m[0], m[1], m[2], decay);
    cr_assert_leq(worst, 1e-6, "mode %d %d %d: worst error %g of the amplitude", m[0], m[1], m[2], worst);
    fluid_free(&f);
}

Test(smoke, fourier_modes_decay_exactly)
{
    const int modes[4][3] = {{3, 0, 0}, {0, 2, 0}, {0, 0, 3}, {2, 1, 3}};
    for (int i = 0; i < 4; i++)
        mode_decays(modes[i]);
}

Test(smoke, constant_stays_constant)
{
    struct fluid f;
    fluid_with_velocity(&f, 16, 16, 16, 5, 3.0f);
    for (size_t i = 0; i < f.n; i++)
        f.d[i] = 0.37f;
    float *out = malloc(f.n * sizeof(float));
    fluid_advect_scalar(&f, f.d, out, 0.05f);
    for (size_t i = 0; i < f.n; i++)
        cr_assert_eq(out[i], 0.37f, "voxel %zu: %.9g", i, (double)out[i]);
    free(out);
    fluid_free(&f);
}

/* The scheme written plainly, voxel by voxel (docs/smoke.md, Method 1): lower corner
 * floor(p) of the point clamped to +-1e6 voxels, wrapped, fractions p - floor(p), lerps
 * a + t (b - a) along x, then y, then z; the midpoint backtrace; values below 1e-20 in
 * magnitude become 0. */
static float ref_split(float x, uint32_t n, uint32_t *i0, uint32_t *i1)
{
    x = x > -1e6f ? x : -1e6f;
    x = x < 1e6f ? x : 1e6f;
    float fl = floorf(x);
    int64_t m = (int64_t)fl % (int64_t)n;
    *i0 = (uint32_t)(m < 0 ? m + n : m);
    *i1 = (*i0 + 1) % n;
    return x - fl;
}
static float ref_lookup(const struct fluid *f, const float *q, float x, float y, float z)
{
    uint32_t i[2], j[2], k[2];
    float tx = ref_split(x, f->nx, &i[0], &i[1]), ty = ref_split(y, f->ny, &j[0], &j[1]);
    float tz = ref_split(z, f->nz, &k[0], &k[1]);
#define Q(a, b, c) q[i[a] + (size_t)f->nx * (j[b] + (size_t)f->ny * k[c])]
    float a0 = Q(0, 0, 0) + tx * (Q(1, 0, 0) - Q(0, 0, 0)), a1 = Q(0, 1, 0) + tx * (Q(1, 1, 0) - Q(0, 1, 0));
    float a2 = Q(0, 0, 1) + tx * (Q(1, 0, 1) - Q(0, 0, 1)), a3 = Q(0, 1, 1) + tx * (Q(1, 1, 1) - Q(0, 1, 1));
#undef Q
    float b0 = a0 + ty * (a1 - a0), b1 = a2 + ty * (a3 - a2);
    return b0 + tz * (b1 - b0);
}
static void ref_advect(const struct fluid *f, const float *const vel[3], const float *src, float *dst, float dt)
{
    const float s = dt / f->h, hs = 0.5f * s;
    size_t idx = 0;
    for (uint32_t k = 0; k < f->nz; k++)
        for (uint32_t j = 0; j < f->ny; j++)
            for (uint32_t i = 0; i < f->nx; i++, idx++) {
                float x = (float)i - hs * vel[0][idx], y = (float)j - hs * vel[1][idx], z = (float)k - hs * vel[2][idx];
                float um = ref_lookup(f, vel[0], x, y, z), vm = ref_lookup(f, vel[1], x, y, z);
                float wm = ref_lookup(f, vel[2], x, y, z);
                float v = ref_lookup(f, src, (float)i - s * um, (float)j - s * vm, (float)k - s * wm);
                dst[idx] = fabsf(v) < 1e-20f ? 0.0f : v;
            }
}

/* The solver's advection (rows of four voxels, packed lookups, padded copies, the scalar's
 * box, general cells for far points) gives the plain scheme's bits: density (packed with
 * the velocity) and temperature (looked up alone) after one step with nothing else acting,
 * on a grid whose rows are not a multiple of 4, through a fast random velocity (backtraces
 * across every face) with a few huge values (clamped, general cells), scalars non-zero in
 * boxes away from the faces or reaching them (the skipped lookups); 1 and 2 threads, the
 * AVX and the SSE2 lookups. */
Test(smoke, advection_matches_the_plain_scheme)
{
    struct smoke_settings s;
    small_settings(&s, 13, 10, 9);
    s.dt = 0.05f;
    s.viscosity = 0.0f;
    s.alpha = s.beta = s.epsilon = 0.0f;
    s.sponge_width = 0;
    s.source_rate = 0.0f;
    s.source_radius = 1e-6f;  /* holds no voxel centre: no source */
    for (int run = 0; run < 8; run++) {
        const uint32_t threads = 1 + (uint32_t)(run & 1);
        s.threads = threads;
        fluid_no_avx = run >= 4;  /* the SSE2 path, on a CPU with AVX too */
        struct fluid f;
        fluid_init(&f, &s);
        random_velocity(&f, 21, 3.0f);  /* up to several voxels a step */
        f.u[17] = 1e9f;
        f.v[300] = -3e7f;
        f.w[f.n - 5] = 2e6f;
        size_t idx = 0;
        for (uint32_t k = 0; k < f.nz; k++)
            for (uint32_t j = 0; j < f.ny; j++)
                for (uint32_t i = 0; i < f.nx; i++, idx++) {
                    float r = rng_uniform(rng_key(3, 0, idx, 0), 0);
                    f.d[idx] = (i >= 2 && i <= 9 && j >= 3 && k <= 4) ? r : 0.0f;
                    f.t[idx] = (i >= 5 && i <= 7 && j >= 2 && j <= 5 && k >= 3 && k <= 6) ? 1.0f - r : 0.0f;
                }
        if (run & 2)
            f.t[0] = 0.5f;  /* a corner voxel: the box reaches the faces, cells across them reach it */
        float *vel0[3], *d0 = malloc(f.n * sizeof(float)), *t0 = malloc(f.n * sizeof(float));
        float *want_d = malloc(f.n * sizeof(float)), *want_t = malloc(f.n * sizeof(float));
        float *in[3] = {f.u, f.v, f.w};
        for (int c = 0; c < 3; c++) {
            vel0[c] = malloc(f.n * sizeof(float));
            memcpy(vel0[c], in[c], f.n * sizeof(float));
        }
        memcpy(d0, f.d, f.n * sizeof(float));
        memcpy(t0, f.t, f.n * sizeof(float));
        ref_advect(&f, (const float *const *)vel0, d0, want_d, s.dt);
        ref_advect(&f, (const float *const *)vel0, t0, want_t, s.dt);
        fluid_step(&f);
        size_t nonzero = 0;
        for (size_t i = 0; i < f.n; i++) {
            nonzero += want_t[i] != 0.0f;
            cr_assert(memcmp(&f.d[i], &want_d[i], sizeof(float)) == 0, "run %d: density at %zu: %.9g, plain %.9g", run,
                      i, (double)f.d[i], (double)want_d[i]);
            cr_assert(memcmp(&f.t[i], &want_t[i], sizeof(float)) == 0, "run %d: temperature at %zu: %.9g, plain %.9g",
                      run, i, (double)f.t[i], (double)want_t[i]);
        }
        cr_assert_gt(nonzero, f.n / 20, "the temperature moved somewhere (%zu voxels)", nonzero);
        fluid_no_avx = 0;
        for (int c = 0; c < 3; c++)
            free(vel0[c]);
        free(d0);
        free(t0);
        free(want_d);
        free(want_t);
        fluid_free(&f);
    }
}

Test(smoke, density_conserved_without_sources)
{
    struct fluid f;
    fluid_with_velocity(&f, 32, 32, 32, 9, 0.5f);
    fluid_project(&f, 0.0f, 0.0f);
    size_t idx = 0;
    for (uint32_t k = 0; k < f.nz; k++)
        for (uint32_t j = 0; j < f.ny; j++)
            for (uint32_t i = 0; i < f.nx; i++, idx++) {
                float dx = (float)i - 16, dy = (float)j - 16, dz = (float)k - 16;
                f.d[idx] = expf(-(dx * dx + dy * dy + dz * dz) / 18.0f);
            }
    double m0 = 0.0;
    for (size_t i = 0; i < f.n; i++)
        m0 += f.d[i];
    const int steps = 10;
    double m = m0;
    float *out = malloc(f.n * sizeof(float));
    for (int st = 0; st < steps; st++) {
        fluid_advect_scalar(&f, f.d, out, 0.02f);
        memcpy(f.d, out, f.n * sizeof(float));
    }
    free(out);
    m = 0.0;
    for (size_t i = 0; i < f.n; i++)
        m += f.d[i];
    double per_step = fabs(m - m0) / m0 / steps;
    fprintf(stderr, "smoke: density change per step without sources %.3g (relative)\n", per_step);
    cr_assert_leq(per_step, 1e-4, "relative change per step %g", per_step);
    fluid_free(&f);
}

static void run_steps(struct smoke_settings *s, int steps, struct fluid *f)
{
    fluid_init(f, s);
    for (int i = 0; i < steps; i++)
        fluid_step(f);
}

static void assert_same_state(const struct fluid *a, const struct fluid *b)
{
    cr_assert_eq(a->step, b->step);
    cr_assert(memcmp(a->d, b->d, a->n * 4) == 0, "density differs");
    cr_assert(memcmp(a->t, b->t, a->n * 4) == 0, "temperature differs");
    cr_assert(memcmp(a->u, b->u, a->n * 4) == 0 && memcmp(a->v, b->v, a->n * 4) == 0 &&
              memcmp(a->w, b->w, a->n * 4) == 0, "velocity differs");
}

Test(smoke, threads_bit_identical)
{
    struct smoke_settings s;
    small_settings(&s, 32, 48, 32);
    s.source_center[1] = 0.3f;
    struct fluid a, b;
    s.threads = 1;
    run_steps(&s, 6, &a);
    s.threads = 2;
    run_steps(&s, 6, &b);
    double mass = 0.0;
    for (size_t i = 0; i < a.n; i++)
        mass += a.d[i];
    cr_assert_gt(mass, 0.0);
    assert_same_state(&a, &b);
    fluid_free(&a);
    fluid_free(&b);
}

Test(smoke, checkpoint_resume_bit_identical)
{
    struct smoke_settings s;
    small_settings(&s, 16, 24, 16);
    s.steps_per_frame = 2;
    char path[] = "/tmp/brume_smoke_ckpt_XXXXXX";
    int fd = mkstemp(path);
    cr_assert_geq(fd, 0);
    close(fd);
    char err[256];
    struct fluid a, b;
    run_steps(&s, 4, &a);
    cr_assert_eq(store_write_checkpoint(path, &a, 2, err, sizeof err), 0, "%s", err);
    for (int i = 0; i < 4; i++)
        fluid_step(&a);
    fluid_init(&b, &s);
    uint32_t frame = 0;
    cr_assert_eq(store_read_checkpoint(path, &b, &frame, err, sizeof err), 1, "%s", err);
    cr_assert_eq(frame, 2);
    for (int i = 0; i < 4; i++)
        fluid_step(&b);
    assert_same_state(&a, &b);
    /* other settings: refused */
    struct smoke_settings s2 = s;
    s2.seed = 99;
    struct fluid c;
    fluid_init(&c, &s2);
    cr_assert_eq(store_read_checkpoint(path, &c, &frame, err, sizeof err), -1);
    cr_assert(strstr(err, "other settings"), "%s", err);
    unlink(path);
    cr_assert_eq(store_read_checkpoint(path, &c, &frame, err, sizeof err), 0);
    fluid_free(&a);
    fluid_free(&b);
    fluid_free(&c);
}

static int all_finite(const struct fluid *f)
{
    const float *c[5] = {f->u, f->v, f->w, f->d, f->t};
    for (int k = 0; k < 5; k++)
        for (size_t i = 0; i < f->n; i++)
            if (!isfinite(c[k][i]))
                return 0;
    return 1;
}

/* 10 steps of s: every value finite. */
static void assert_finite_after(struct smoke_settings *s, const char *what)
{
    struct fluid f;
    run_steps(s, 10, &f);
    cr_assert(all_finite(&f), "%s", what);
    fluid_free(&f);
}

Test(smoke, hard_cases_stay_finite)
{
    struct smoke_settings s;
    small_settings(&s, 16, 16, 16);
    s.viscosity = 0.0f;
    s.epsilon = 50.0f;
    assert_finite_after(&s, "zero viscosity, strong confinement");
    small_settings(&s, 16, 16, 16);
    s.alpha = 1e6f;
    s.beta = 1e6f;
    s.source_rate = 1e4f;
    assert_finite_after(&s, "huge buoyancy");
    small_settings(&s, 16, 16, 16);
    s.source_center[0] = s.source_center[1] = s.source_center[2] = 0.0f;
    s.source_radius = 0.3f;
    s.source_velocity[0] = -5.0f;
    assert_finite_after(&s, "source on the border");
}

static int parse(const char *text, char *err, size_t errlen)
{
    struct smoke_settings s;
    return smoke_settings_parse("sim.json", text, strlen(text), &s, err, errlen);
}

Test(smoke, settings_refused_with_positions)
{
    char err[512];
    cr_assert_eq(parse("{\"resolution\": [64, 64, 64], \"frames\": 3}", err, sizeof err), 0, "%s", err);
    cr_assert_eq(parse("{\n  \"resolution\": [1, 1, 1]\n}", err, sizeof err), -1);
    cr_assert(strstr(err, "sim.json:2:17:") && strstr(err, "resolution"), "%s", err);
    cr_assert_eq(parse("{\"dt\": NaN}", err, sizeof err), -1);
    cr_assert(strstr(err, "sim.json:1:"), "%s", err);
    cr_assert_eq(parse("{\"dt\": 1e999}", err, sizeof err), -1);
    cr_assert(strstr(err, "sim.json:1:"), "%s", err);
    cr_assert_eq(parse("{\"source\": {\n \"radius\": 0.1,\n   \"colour\": 3}}", err, sizeof err), -1);
    cr_assert(strstr(err, "sim.json:3:4:") && strstr(err, "colour"), "%s", err);
    cr_assert_eq(parse("{\"source\": {\"radius\": -1}}", err, sizeof err), -1);
    cr_assert(strstr(err, "sim.json:1:23:"), "%s", err);
    cr_assert_eq(parse("{\"output\": \"a.##.b.##\"}", err, sizeof err), -1);
    cr_assert_eq(parse("{\"output\": \"../x.####\"}", err, sizeof err), -1);
    cr_assert_eq(parse("{\"output\": \"x.####.vdb\"}", err, sizeof err), -1);
    cr_assert(strstr(err, "sim.json:1:12:") && strstr(err, ".nvdb or .grid"), "%s", err);
    cr_assert_eq(parse("{\"output\": \"x.####.nvdb\", \"nvdb_threshold\": 0.01}", err, sizeof err), 0, "%s", err);
    cr_assert_eq(parse("{\"nvdb_threshold\": -1}", err, sizeof err), -1);
    cr_assert(strstr(err, "sim.json:1:20:"), "%s", err);
    cr_assert_eq(parse("{\"sponge\": {\"width\": 40}}", err, sizeof err), -1);
    cr_assert(strstr(err, "sponge"), "%s", err);
    cr_assert_eq(parse("[1]", err, sizeof err), -1);
    cr_assert_eq(parse("{\"source\": {\"center\": [0.5, 1.5, 0.5]}}", err, sizeof err), -1);
    cr_assert(strstr(err, "outside the domain"), "%s", err);
    struct smoke_settings s;
    smoke_settings_default(&s);
    s.beta = NAN;
    cr_assert_eq(smoke_settings_check(&s, err, sizeof err), -1);
    cr_assert(strstr(err, "NaN"), "%s", err);
    char name[64];
    cr_assert_eq(smoke_frame_name("smoke.####.grid", 7, name, sizeof name), 0);
    cr_assert_str_eq(name, "smoke.0007.grid");
    cr_assert_eq(smoke_frame_name("s.#.grid", 12, name, sizeof name), 0);
    cr_assert_str_eq(name, "s.12.grid");
}

Test(smoke, grid_file_reads_back)
{
    struct smoke_settings s;
    small_settings(&s, 16, 24, 8);
    struct fluid f;
    run_steps(&s, 3, &f);
    f.d[5] = -1.0f;  /* written as 0: the format holds densities >= 0 */
    char path[] = "/tmp/brume_smoke_grid_XXXXXX";
    int fd = mkstemp(path);
    cr_assert_geq(fd, 0);
    close(fd);
    char err[256];
    cr_assert_eq(store_write_grid(path, &f, err, sizeof err), 0, "%s", err);
    FILE *fp = fopen(path, "rb");
    cr_assert(fp);
    size_t len = store_grid_bytes(&f);
    uint8_t *buf = malloc(len + 1);
    cr_assert_eq(fread(buf, 1, len + 1, fp), len);
    fclose(fp);
    unlink(path);
    struct density_grid g;
    memset(&g, 0, sizeof g);
    cr_assert_eq(grid_parse(buf, len, &g, err, sizeof err), 0, "%s", err);
    cr_assert(g.nx == 16 && g.ny == 24 && g.nz == 8);
    f.d[5] = 0.0f;
    cr_assert(memcmp(g.data, f.d, f.n * 4) == 0);
    free(g.data);
    free(buf);
    fluid_free(&f);
}

/* A frame of a non-cubic run written both ways: the .nvdb (NanoVDB's writer) reads back
 * through the renderer's NanoVDB parser, holds exactly the voxels above the threshold
 * (its bytes are not fewer at this size: a NanoVDB tree has a fixed cost of about 300 KB,
 * docs/smoke.md), and, with the dense grid's unit cube stretched over the domain [0, size n / nx]
 * (the placement scenes give it), samples at random world points as the dense grid does
 * within the threshold (what it leaves out) plus 1e-5 of the largest density (the two
 * lattices' rounding). */
Test(smoke, nvdb_frame_samples_as_dense, .timeout = 60)
{
    struct smoke_settings s;
    small_settings(&s, 24, 32, 16);
    s.source_center[2] = 0.3f;
    s.nvdb_threshold = 1e-3f;
    struct fluid f;
    run_steps(&s, 12, &f);
    char dpath[] = "/tmp/brume_smoke_dense_XXXXXX", npath[] = "/tmp/brume_smoke_nvdb_XXXXXX";
    int fd = mkstemp(dpath);
    cr_assert_geq(fd, 0);
    close(fd);
    fd = mkstemp(npath);
    cr_assert_geq(fd, 0);
    close(fd);
    char err[256];
    size_t nbytes = 0;
    uint64_t active = 0;
    cr_assert_eq(store_write_grid(dpath, &f, err, sizeof err), 0, "%s", err);
    cr_assert_eq(store_write_nvdb(npath, &f, &nbytes, &active, err, sizeof err), 0, "%s", err);
    size_t dlen, nlen;
    uint8_t *dbuf = test_read_file(dpath, &dlen, "written above"), *nbuf = test_read_file(npath, &nlen, "written above");
    unlink(dpath);
    unlink(npath);
    cr_assert_eq(nlen, nbytes);
    struct density_grid *gd = calloc(1, sizeof *gd), *gn = calloc(1, sizeof *gn);
    cr_assert_eq(grid_parse(dbuf, dlen, gd, err, sizeof err), 0, "%s", err);
    struct xform xn;
    uint64_t neg = 0;
    cr_assert(nvdb_is_nvdb(nbuf, nlen));
    cr_assert_eq(nvdb_parse(nbuf, nlen, NULL, gn, &xn, &neg, err, sizeof err), 0, "%s", err);
    cr_assert_eq(neg, 0);
    double dmax = 0.0;
    uint64_t above = 0;
    for (size_t i = 0; i < f.n; i++) {
        dmax = fmax(dmax, f.d[i]);
        above += f.d[i] > s.nvdb_threshold;
    }
    fprintf(stderr, "smoke: nvdb frame 24x32x16: %llu of %zu voxels stored, %zu bytes (dense %zu)\n",
            (unsigned long long)active, f.n, nlen, dlen);
    cr_assert_gt(dmax, 0.1, "the plume must be there (%g)", dmax);
    cr_assert_eq(active, above, "stored %llu, above the threshold %llu", (unsigned long long)active,
                 (unsigned long long)above);
    cr_assert_lt(active, f.n / 2);
    const float len[3] = {f.h * (float)f.nx, f.h * (float)f.ny, f.h * (float)f.nz};
    struct xform xd = {{{len[0], 0, 0, 0}, {0, len[1], 0, 0}, {0, 0, len[2], 0}}};
    grid_finish(gd, &xd, 1.0f);
    grid_finish(gn, &xn, 1.0f);
    double worst = 0.0, tol = s.nvdb_threshold + 1e-5 * dmax;
    for (uint32_t q = 0; q < 20000; q++) {
        float p[3];
        for (int a = 0; a < 3; a++)  /* within the outer voxel centres, where the dense grid interpolates */
            p[a] = f.h * (0.5f + rng_uniform(rng_key(17, q, 0, 0), (uint32_t)a) * (float)(f.s.res[a] - 1));
        vec3 w = {p[0], p[1], p[2]};
        double a = grid_density(gd, w), b = grid_density(gn, w);
        worst = fmax(worst, fabs(a - b));
        cr_assert_leq(fabs(a - b), tol, "at %g %g %g: dense %g, nvdb %g", (double)p[0], (double)p[1],
                      (double)p[2], a, b);
    }
    fprintf(stderr, "smoke: nvdb against dense: worst difference %.3g (bound %.3g, max density %.3g)\n", worst,
            tol, dmax);
    grid_free(&gd);
    grid_free(&gn);
    free(dbuf);
    free(nbuf);
    fluid_free(&f);
}
