/* Smoke simulation settings: a JSON file (jansson) checked key by key, with errors naming
 * file:line:column of the offending key or value, as the scene parser's do. Format in
 * docs/smoke.md. Callers: smoke/main.c, smoke/fluid.c, tests/unit/test_smoke.c. */
#ifndef BRUME_SMOKE_SETTINGS_H
#define BRUME_SMOKE_SETTINGS_H
#include <stddef.h>
#include <stdint.h>

#define SMOKE_MIN_RES 8
#define SMOKE_MAX_RES 512
#define SMOKE_MAX_VOXELS (1u << 27)

struct smoke_settings {
    uint32_t res[3];        /* voxels along x, y (up), z; each in [8, 512] */
    float size;             /* world length of the x side; voxels are cubes */
    uint32_t frames;        /* frames written */
    uint32_t steps_per_frame;
    float dt;               /* seconds per step */
    float viscosity;        /* kinematic, world units^2 / s */
    float alpha, beta;      /* buoyancy: f_y = -alpha density + beta temperature */
    float epsilon;          /* vorticity confinement */
    float source_center[3]; /* world units, domain [0, size*res/res[0]] per axis */
    float source_radius;
    float source_rate;      /* density per second at the centre */
    float source_temperature;
    float source_velocity[3];
    float source_jitter;    /* relative noise on the rate, in [0, 1] */
    uint32_t sponge_width;  /* voxels from each face */
    float sponge_strength;  /* damping rate (1/s) at the face */
    uint64_t seed;
    uint32_t threads;       /* FFTW threads and slabs of the grid loops; 1 by default */
    char output[256];       /* pattern with one run of '#', relative to the settings' folder;
                               ending in .nvdb (NanoVDB) or .grid (dense BRGRID01) */
    float nvdb_threshold;   /* .nvdb frames store the densities above it only */
};

/* Built-in defaults (a 32^3 plume); the file overrides them key by key. */
void smoke_settings_default(struct smoke_settings *s);
/* Parses text (len bytes) named `name` in messages over *s (defaults first). 0 or -1 with
 * "name:line:col: message" in err. */
int smoke_settings_parse(const char *name, const char *text, size_t len, struct smoke_settings *s, char *err,
                         size_t errlen);
/* The same checks for settings built in code (tests): 0 or -1 with a message. */
int smoke_settings_check(const struct smoke_settings *s, char *err, size_t errlen);
/* 1 if the output pattern names NanoVDB files (.nvdb), 0 dense grids (.grid), -1 neither. */
int smoke_output_nvdb(const char *pattern);
/* Output path of frame `frame` from the pattern: the run of '#' becomes the zero-padded
 * number (wider if needed). 0 or -1. */
int smoke_frame_name(const char *pattern, uint32_t frame, char *out, size_t size);

#endif
