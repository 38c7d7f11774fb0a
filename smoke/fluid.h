/* Stable fluids on a periodic 3D grid (Stam 1999 and 2001, Fedkiw, Stam and Jensen 2001):
 * semi-Lagrangian advection (trilinear, midpoint backtrace), exact diffusion and pressure
 * projection in Fourier space (FFTW single precision, real-to-complex, plans made once),
 * buoyancy from density and temperature, vorticity confinement, a spherical source and a
 * sponge layer at the borders (docs/smoke.md). The state is x fastest, then y (up), then z.
 * Callers: smoke/main.c, tests/unit/test_smoke.c. */
#ifndef BRUME_SMOKE_FLUID_H
#define BRUME_SMOKE_FLUID_H
#include <stddef.h>
#include <stdint.h>
#include "settings.h"

enum fluid_phase { PH_SOURCE, PH_FORCES, PH_ADVECT, PH_FFT, PH_SPECTRAL, PH_SPONGE, PH_COUNT_ };
extern const char *const fluid_phase_names[PH_COUNT_];

struct fluid {
    struct smoke_settings s;
    uint32_t nx, ny, nz;
    size_t n;                  /* voxels */
    float h;                   /* voxel size (world units) */
    float *u, *v, *w, *d, *t;  /* velocity (world units / s), density, temperature */
    float *spare;              /* the next temperature, swapped in after advection */
    float *tmp[4];             /* scratch: four arrays of n floats in one block of at least
                                  5 (nx + 2)(ny + 2)(nz + 2) floats, where advection packs
                                  u v w d and copies the scalar, each with a one-voxel halo */
    void *spec[3];             /* fftwf_complex, nz*ny*(nx/2+1) each */
    void *plan_fwd, *plan_bwd;
    uint64_t step;             /* steps done */
    double cpu[PH_COUNT_];     /* CPU seconds per phase (all threads) */
    double wall[PH_COUNT_];
};

/* Allocates the state (zero) and makes the FFTW plans with s->threads threads. */
void fluid_init(struct fluid *f, const struct smoke_settings *s);
void fluid_free(struct fluid *f);
/* One time step of s.dt: advect velocity, density and temperature through the current
 * (projected) velocity, add the source and the forces, sponge, diffuse and project. */
void fluid_step(struct fluid *f);

/* Pieces, for the tests. */
void fluid_project(struct fluid *f, float dt, float nu);  /* diffuse by nu over dt, then project */
/* Advects src into dst (neither in f->tmp) through the current velocity. */
void fluid_advect_scalar(const struct fluid *f, const float *src, float *dst, float dt);
/* Spectral divergence norm and velocity norm (root of the sum of squares over modes). */
void fluid_divergence(struct fluid *f, double *div_norm, double *vel_norm);
/* Tests: non-zero makes advection take its SSE2 path on a CPU with AVX too (the same bits). */
extern int fluid_no_avx;
/* Bytes the state and scratch take per voxel. */
size_t fluid_bytes_per_voxel(void);

#endif
