/* NanoVDB density grids (common/scene/nvdb.c) against files written by NanoVDB's own C++ writer
 * (tests/tools/make_nvdb.cpp, run by `make unit` into $BRUME_TESTDATA):
 * - the dense copy holds the analytic values exactly, placed by the grid's map (a shear)
 *   and the scene's transform on top; lookups at voxel centres give those values;
 * - a dense BRGRID file of the same data and placement gives bit-identical densities,
 *   transmittance and rendered pixels;
 * - the first float grid, or one by name; sparse trees across nodes and root tiles;
 * - compressed, non-float, level-set, NaN, too large, non-zero background, truncated and
 *   corrupted files are refused with a message, never a crash; negatives become 0. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "render/integrator.h"
#include "base/log.h"
#include "render/media_integrator.h"
#include "scene/grid.h"
#include "scene/nvdb.h"
#include "base/rng.h"
#include "scene/scene_json.h"
#include "helpers.h"

#include "../tools/nvdb_values.h" /* the analytic densities of make_nvdb.cpp */

/* The ball's map, world = A ijk + t (make_nvdb.cpp). */
static const double BALL_A[3][3] = {{0.125, 0.0, 0.0625}, {0.0, 0.25, 0.0}, {0.0, 0.0, 0.125}};
static const double BALL_T[3] = {-1.0, 0.5, -0.75};
static const int BALL_LO[3] = {-6, -4, -5}, BALL_HI[3] = {9, 7, 5};

/* The in-memory folder: add_file() fills the first free slot, so g_files stays ended by an
 * empty one; the names and bytes are owned here. */
static char g_names[16][64];
static uint8_t *g_data[16];
static struct mem_file g_files[16];

static uint8_t *read_testdata(const char *name, size_t *size)
{
    const char *dir = getenv("BRUME_TESTDATA");
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", dir ? dir : "../../build/testdata", name);
    return test_read_file(path, size, "`make unit` writes it with build/make_nvdb");
}

/* Adds a file to the in-memory asset source under name (bytes are copied). */
static void add_file(const char *name, const uint8_t *data, size_t size)
{
    for (int i = 0; i < 15; i++)
        if (!g_files[i].path) {
            snprintf(g_names[i], sizeof g_names[i], "%s", name);
            g_data[i] = malloc(size + 1);
            memcpy(g_data[i], data, size);
            g_files[i] = (struct mem_file){g_names[i], g_data[i], size};
            return;
        }
    cr_assert_fail("too many files");
}

/* Adds the test data file `file` to the in-memory asset source as `as`. */
static void add_testdata(const char *file, const char *as)
{
    size_t n;
    uint8_t *d = read_testdata(file, &n);
    add_file(as, d, n);
    free(d);
}

static void clear_files(void)
{
    for (int i = 0; i < 16; i++) {
        free(g_data[i]);
        g_data[i] = NULL;
        g_files[i] = (struct mem_file){NULL, NULL, 0};
    }
}

static int load(const char *text, struct scene *s, char *err)
{
    return test_scene_load(text, g_files, s, err);
}

static void load_ok(const char *text, struct scene *s)
{
    char err[512] = "";
    cr_assert_eq(load(text, s, err), 0, "parse failed: %s", err);
}

#define HEAD                                                                                             \
    "{\"version\": 1,\n\"camera\": {\"position\": [-0.625, 1.75, -7], \"look_at\": [-0.625, 1.75, -1.5], " \
    "\"fov_y\": 30},\n\"render\": {\"width\": 12, \"height\": 12, \"spp\": 2, \"max_depth\": 8, \"tile_size\": 8}"

/* A scene whose fog is a grid medium with the given density object. */
static void scene_with(char *text, size_t n, const char *density)
{
    snprintf(text, n,
             HEAD ",\n\"media\": {\"m\": {\"sigma_a\": [0.5, 0.2, 1], \"sigma_s\": [2, 2, 2], \"g\": 0.3, \"density\": %s}},\n"
                  "\"volume\": {\"method\": \"vpt\", \"fog\": \"m\"},\n"
                  "\"lights\": [{\"type\": \"point\", \"position\": [2, 4, -4], \"intensity\": [30, 30, 30]}]}",
             density);
}

static int parse_file(const char *name, const char *grid, struct density_grid *g, struct xform *x, uint64_t *neg,
                      char *err, size_t errlen)
{
    size_t n;
    uint8_t *d = read_testdata(name, &n);
    int rc = nvdb_parse(d, n, grid, g, x, neg, err, errlen);
    free(d);
    return rc;
}

static float dense_at(const struct density_grid *g, const int lo[3], int i, int j, int k)
{
    int x = i - (lo[0] - 1), y = j - (lo[1] - 1), z = k - (lo[2] - 1);
    return g->data[((size_t)z * g->ny + (size_t)y) * g->nx + (size_t)x];
}

/* The exact unit-cube-to-world transform of the ball (all numbers are dyadic). */
static struct xform ball_to_world(void)
{
    struct xform x;
    int n[3] = {BALL_HI[0] - BALL_LO[0] + 3, BALL_HI[1] - BALL_LO[1] + 3, BALL_HI[2] - BALL_LO[2] + 3};
    for (int i = 0; i < 3; i++) {
        double off = BALL_T[i];
        for (int j = 0; j < 3; j++) {
            x.m[i][j] = (float)(BALL_A[i][j] * n[j]);
            off += BALL_A[i][j] * (BALL_LO[j] - 1.5);
        }
        x.m[i][3] = (float)off;
    }
    return x;
}

Test(nvdb, analytic_values_exact)
{
    struct density_grid g;
    struct xform x;
    uint64_t neg = 99;
    char err[512] = "";
    cr_assert_eq(parse_file("ball.nvdb", NULL, &g, &x, &neg, err, sizeof err), 0, "%s", err);
    cr_assert_eq(neg, 0);
    cr_assert(g.nx == 18 && g.ny == 14 && g.nz == 13, "%ux%ux%u", g.nx, g.ny, g.nz);
    for (int k = BALL_LO[2] - 1; k <= BALL_HI[2] + 1; k++)
        for (int j = BALL_LO[1] - 1; j <= BALL_HI[1] + 1; j++)
            for (int i = BALL_LO[0] - 1; i <= BALL_HI[0] + 1; i++)
                cr_assert_eq(dense_at(&g, BALL_LO, i, j, k), ball_value(i, j, k), "voxel %d %d %d", i, j, k);
    struct xform want = ball_to_world();
    cr_assert_eq(memcmp(&x, &want, sizeof x), 0, "placement differs from the grid's map");
    free(g.data);

    /* Through the scene: the map, then the transform; lookups at voxel centres. */
    add_testdata("ball.nvdb", "ball.nvdb");
    char text[2048];
    scene_with(text, sizeof text, "{\"file\": \"ball.nvdb\", \"scale\": 2, \"transform\": {\"scale\": 2, \"translate\": [1, 0, 0]}}");
    struct scene s;
    load_ok(text, &s);
    const struct density_grid *sg = s.media->media[0].grid;
    cr_assert_not_null(sg);
    cr_assert_eq(sg->max_density, 2.0f * 12.0f / 8.0f);
    cr_assert_eq(sg->voxel_world, 2.0f * 0.125f, "%g", (double)sg->voxel_world);
    for (int k = BALL_LO[2] - 1; k <= BALL_HI[2] + 1; k++)
        for (int j = BALL_LO[1] - 1; j <= BALL_HI[1] + 1; j++)
            for (int i = BALL_LO[0] - 1; i <= BALL_HI[0] + 1; i++) {
                double w[3];
                for (int r = 0; r < 3; r++)
                    w[r] = BALL_A[r][0] * i + BALL_A[r][1] * j + BALL_A[r][2] * k + BALL_T[r];
                vec3 p = v3((float)(2 * w[0] + 1), (float)(2 * w[1]), (float)(2 * w[2]));
                float got = grid_density(sg, p), want_v = 2.0f * ball_value(i, j, k);
                cr_assert(fabsf(got - want_v) <= 1e-5f * (1.0f + want_v), "voxel %d %d %d: %g vs %g", i, j, k,
                          (double)got, (double)want_v);
            }
    /* Beyond the border voxels the density is 0. */
    cr_assert_eq(grid_density(sg, v3(1e3f, 0, 0)), 0.0f);
    scene_fini(&s);
    clear_files();
}

Test(nvdb, first_float_grid_and_by_name)
{
    struct density_grid g;
    struct xform x;
    uint64_t neg;
    char err[512] = "";
    cr_assert_eq(parse_file("multi.nvdb", NULL, &g, &x, &neg, err, sizeof err), 0, "%s", err);
    cr_assert(g.nx == 18 && g.ny == 14 && g.nz == 13); /* "density", after the vec3f grid */
    cr_assert_eq(dense_at(&g, BALL_LO, 3, 2, 1), ball_value(3, 2, 1));
    free(g.data);
    const int tlo[3] = {-2, 0, -1};
    cr_assert_eq(parse_file("multi.nvdb", "temperature", &g, &x, &neg, err, sizeof err), 0, "%s", err);
    cr_assert(g.nx == 8 && g.ny == 5 && g.nz == 5, "%ux%ux%u", g.nx, g.ny, g.nz);
    for (int k = -2; k <= 2; k++)
        for (int j = -1; j <= 3; j++)
            for (int i = -3; i <= 4; i++)
                cr_assert_eq(dense_at(&g, tlo, i, j, k), temperature_value(i, j, k));
    cr_assert_eq(x.m[0][0], 8.0f);
    cr_assert_eq(x.m[0][3], -3.5f);
    free(g.data);
    cr_assert_neq(parse_file("multi.nvdb", "velocity", &g, &x, &neg, err, sizeof err), 0);
    cr_assert(strstr(err, "grid \"velocity\" holds vec3f values: only float grids") != NULL, "%s", err);
    cr_assert_neq(parse_file("multi.nvdb", "smoke", &g, &x, &neg, err, sizeof err), 0);
    cr_assert(strstr(err, "no grid named \"smoke\" (grids in the file: \"velocity\" (vec3f), \"density\" (float), "
                          "\"temperature\" (float))") != NULL, "%s", err);

    /* Two segments (files written one after the other): grids of the second are found too. */
    size_t n1, n2;
    uint8_t *a = read_testdata("negative.nvdb", &n1), *b = read_testdata("multi.nvdb", &n2);
    a = realloc(a, n1 + n2);
    memcpy(a + n1, b, n2);
    cr_assert_eq(nvdb_parse(a, n1 + n2, "temperature", &g, &x, &neg, err, sizeof err), 0, "%s", err);
    cr_assert_eq(dense_at(&g, tlo, 3, 2, 1), temperature_value(3, 2, 1));
    free(g.data);
    cr_assert_eq(nvdb_parse(a, n1 + n2, NULL, &g, &x, &neg, err, sizeof err), 0, "%s", err);
    cr_assert(g.nx == 5 && neg == 1); /* the first float grid: negative.nvdb's */
    free(g.data);
    free(a);
    free(b);

    /* In a scene: "grid" picks by name; a bad name is reported at the file key. */
    add_testdata("multi.nvdb", "multi.nvdb");
    char text[2048];
    scene_with(text, sizeof text, "{\"file\": \"multi.nvdb\", \"grid\": \"temperature\"}");
    struct scene s;
    load_ok(text, &s);
    cr_assert_eq(s.media->media[0].grid->nx, 8u);
    scene_fini(&s);
    scene_with(text, sizeof text, "{\"file\": \"multi.nvdb\", \"grid\": \"velocity\"}");
    cr_assert_neq(load(text, &s, err), 0);
    cr_assert(strstr(err, "scenes/t.json:4:") != NULL && strstr(err, "grid \"multi.nvdb\": grid \"velocity\" holds vec3f") != NULL,
              "%s", err);
    clear_files();
}

Test(nvdb, sparse_tree_across_nodes_and_root_tiles)
{
    struct density_grid g;
    struct xform x;
    uint64_t neg;
    char err[512] = "";
    cr_assert_eq(parse_file("sparse.nvdb", NULL, &g, &x, &neg, err, sizeof err), 0, "%s", err);
    const int lo[3] = {-3, 0, -130}, hi[3] = {131, 4, 2};
    cr_assert(g.nx == (uint32_t)(hi[0] - lo[0] + 3) && g.ny == (uint32_t)(hi[1] - lo[1] + 3) &&
              g.nz == (uint32_t)(hi[2] - lo[2] + 3), "%ux%ux%u", g.nx, g.ny, g.nz);
    uint64_t nonzero = 0;
    for (int k = lo[2] - 1; k <= hi[2] + 1; k++)
        for (int j = lo[1] - 1; j <= hi[1] + 1; j++)
            for (int i = lo[0] - 1; i <= hi[0] + 1; i++) {
                float v = dense_at(&g, lo, i, j, k);
                cr_assert_eq(v, sparse_value(i, j, k), "voxel %d %d %d: %g", i, j, k, (double)v);
                nonzero += v > 0.0f;
            }
    cr_assert_eq(nonzero, 6 * 4 * 3 + 7 * 4 * 5);
    free(g.data);
}

/* The BRGRID bytes of the ball over its dense box. */
static uint8_t *ball_brgrid(size_t *size)
{
    uint32_t n[3] = {18, 14, 13};
    *size = 20 + 4 * (size_t)n[0] * n[1] * n[2];
    uint8_t *b = malloc(*size);
    memcpy(b, GRID_MAGIC, 8);
    memcpy(b + 8, n, 12);
    size_t at = 20;
    for (int k = BALL_LO[2] - 1; k <= BALL_HI[2] + 1; k++)
        for (int j = BALL_LO[1] - 1; j <= BALL_HI[1] + 1; j++)
            for (int i = BALL_LO[0] - 1; i <= BALL_HI[0] + 1; i++, at += 4) {
                float v = ball_value(i, j, k);
                memcpy(b + at, &v, 4);
            }
    return b;
}

static float *render(const struct scene *s)
{
    struct tile_stats st;
    float *px = test_render(s, 1, &st);
    cr_assert_eq(st.nan_samples, 0);
    return px;
}

Test(nvdb, same_as_dense_grid, .timeout = 60)
{
    add_testdata("ball.nvdb", "ball.nvdb");
    /* The dense file under an .nvdb name, the NanoVDB one under a .grid name: content decides. */
    size_t n;
    uint8_t *d = ball_brgrid(&n);
    add_file("ball_dense.nvdb", d, n);
    free(d);
    struct xform t = ball_to_world(), s2 = {{{2, 0, 0, 1}, {0, 2, 0, 0}, {0, 0, 2, 0}}};
    struct xform full = xform_then(&t, &s2);
    char dens[1024], text[2048];
    int k = snprintf(dens, sizeof dens, "{\"file\": \"ball_dense.nvdb\", \"scale\": 1.5, \"transform\": {\"matrix\": [");
    for (int i = 0; i < 12; i++)
        k += snprintf(dens + k, sizeof dens - (size_t)k, "%s%.9g", i ? ", " : "", (double)full.m[i / 4][i % 4]);
    snprintf(dens + k, sizeof dens - (size_t)k, "]}}");
    struct scene a, b;
    scene_with(text, sizeof text, dens);
    load_ok(text, &b);
    scene_with(text, sizeof text, "{\"file\": \"ball.nvdb\", \"scale\": 1.5, \"transform\": {\"scale\": 2, \"translate\": [1, 0, 0]}}");
    load_ok(text, &a);
    const struct density_grid *ga = a.media->media[0].grid, *gb = b.media->media[0].grid;
    cr_assert_eq(memcmp(&ga->grid_to_world, &gb->grid_to_world, sizeof ga->grid_to_world), 0);
    cr_assert_eq(ga->max_density, gb->max_density);
    vec3 lo, hi;
    grid_world_box(ga, &lo, &hi);
    vec3 ext = v3_sub(hi, lo);
    for (uint32_t i = 0; i < 20000; i++) {
        uint64_t key = rng_key(3, 0, i, 0);
        vec3 p = v3(lo.x - 0.1f * ext.x + 1.2f * ext.x * rng_uniform(key, 0), lo.y - 0.1f * ext.y + 1.2f * ext.y * rng_uniform(key, 1),
                    lo.z - 0.1f * ext.z + 1.2f * ext.z * rng_uniform(key, 2));
        float da = grid_density(ga, p), db = grid_density(gb, p);
        cr_assert_eq(memcmp(&da, &db, 4), 0, "point %u: %a vs %a", i, (double)da, (double)db);
        if (i < 200) {
            vec3 dir = v3_normalize(v3(rng_uniform(key, 3) - 0.5f, rng_uniform(key, 4) - 0.5f, rng_uniform(key, 5) - 0.5f));
            vec3 ta = medium_tr_segment(&a.media->media[0], p, dir, 3.0f, key, (int)(i & 1));
            vec3 tb = medium_tr_segment(&b.media->media[0], p, dir, 3.0f, key, (int)(i & 1));
            cr_assert_eq(memcmp(&ta, &tb, sizeof ta), 0);
        }
    }
    size_t npx = (size_t)a.settings.width * a.settings.height * TILE_NUM_CHANNELS;
    float *pa = render(&a), *pb = render(&b);
    double sum = 0.0;
    for (size_t i = 0; i < npx; i += TILE_NUM_CHANNELS)
        sum += pa[i + CH_R];
    cr_assert(sum > 0.0, "the test image is black");
    cr_assert_eq(memcmp(pa, pb, sizeof(float) * npx), 0, "renders differ");
    free(pa);
    free(pb);
    scene_fini(&a);
    scene_fini(&b);
    /* "grid" with a dense file is an error at the key. */
    scene_with(text, sizeof text, "{\"file\": \"ball_dense.nvdb\", \"grid\": \"density\"}");
    char err[512];
    cr_assert_neq(load(text, &a, err), 0);
    cr_assert(strstr(err, "\"ball_dense.nvdb\" is not a NanoVDB file (only those hold named grids)") != NULL, "%s", err);
    clear_files();
}

Test(nvdb, negatives_clamped)
{
    struct density_grid g;
    struct xform x;
    uint64_t neg;
    char err[512] = "";
    cr_assert_eq(parse_file("negative.nvdb", NULL, &g, &x, &neg, err, sizeof err), 0, "%s", err);
    cr_assert_eq(neg, 1);
    const int lo[3] = {0, 0, 0};
    cr_assert_eq(dense_at(&g, lo, 1, 1, 1), 0.0f);
    cr_assert_eq(dense_at(&g, lo, 2, 0, 0), 0.75f);
    for (size_t i = 0; i < (size_t)g.nx * g.ny * g.nz; i++)
        cr_assert(g.data[i] >= 0.0f && !signbit(g.data[i]));
    free(g.data);
}

Test(nvdb, refusals)
{
    static const struct { const char *file, *want; } cases[] = {
        {"ball_zip.nvdb", "grids compressed with ZIP are not supported: write the file uncompressed (codec NONE)"},
        {"ball_blosc.nvdb", "grids compressed with BLOSC are not supported"},
        {"nan.nvdb", "grid \"density\": voxel [1 2 0]: density must be finite"},
        {"huge.nvdb", "needs 603x603x603 dense voxels (with a border of 1), more than 134217728"},
        {"levelset.nvdb", "grid \"surface\" is a level set grid: densities need a fog volume"},
        {"background.nvdb", "background value 0.5: a density grid's background must be 0"},
        {"double.nvdb", "no float grid (grids in the file: \"density\" (double))"},
        {"nobbox.nvdb", "grid \"density\" was written without its bounding box (statistics off)"},
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        struct density_grid g;
        struct xform x;
        uint64_t neg;
        char err[512] = "";
        cr_assert_neq(parse_file(cases[c].file, NULL, &g, &x, &neg, err, sizeof err), 0, "%s loaded", cases[c].file);
        cr_assert(strstr(err, cases[c].want) != NULL, "%s: %s", cases[c].file, err);
        cr_assert_null(g.data);
    }
    /* In a scene the message carries file:line:col. */
    add_testdata("ball_zip.nvdb", "z.nvdb");
    char text[2048], err[512];
    scene_with(text, sizeof text, "{\"file\": \"z.nvdb\"}");
    struct scene s;
    cr_assert_neq(load(text, &s, err), 0);
    cr_assert(strstr(err, "scenes/t.json:4:") != NULL && strstr(err, "grid \"z.nvdb\": grids compressed with ZIP") != NULL,
              "%s", err);
    clear_files();
}

static void put32(uint8_t *p, uint32_t v) { memcpy(p, &v, 4); }
static void put64(uint8_t *p, uint64_t v) { memcpy(p, &v, 8); }

/* Loads (or refuses) bytes; a load must give a sane grid, a refusal a message. */
static int try_bytes(const uint8_t *d, size_t n, char *err, size_t errlen)
{
    struct density_grid g;
    struct xform x;
    uint64_t neg;
    err[0] = '\0';
    int rc = nvdb_parse(d, n, NULL, &g, &x, &neg, err, errlen);
    if (rc == 0) {
        cr_assert((uint64_t)g.nx * g.ny * g.nz <= GRID_MAX_VOXELS);
        for (size_t i = 0; i < (size_t)g.nx * g.ny * g.nz; i++)
            cr_assert(isfinite(g.data[i]) && g.data[i] >= 0.0f);
        free(g.data);
    } else {
        cr_assert(err[0] != '\0', "refused without a message");
        cr_assert_null(g.data);
    }
    return rc;
}

Test(nvdb, truncated_and_corrupted, .timeout = 120)
{
    size_t n;
    uint8_t *orig = read_testdata("multi.nvdb", &n);
    uint8_t *d = malloc(n);
    char err[512];
    /* Every cut fails: headers, metadata, names, the grids' buffers. */
    for (size_t cut = 0; cut < n; cut += cut < 2048 ? 1 : 4099) {
        memcpy(d, orig, cut);
        cr_assert_neq(try_bytes(d, cut, err, sizeof err), 0, "cut at %zu loaded", cut);
    }
    /* Header fields. Metadata of grid 0 starts at 16, its name ("velocity\0") at 192. */
    struct { size_t at; int width; uint64_t value; const char *want; } f[] = {
        {0, 8, 0x314244566f6e614eull, "reads files of NanoVDB 32.x"},
        {0, 8, 0x1122334455667788ull, "not a NanoVDB file"},
        {8, 4, 31u << 21, "NanoVDB version 31.0.0"},
        {12, 2, 0, "holds no grids"},
        {14, 2, 1, "compressed with ZIP"},
        {14, 2, 7, "compressed with an unknown codec"},
        {16 + 136, 4, 100000, "name of 100000 bytes out of range"},
        {16 + 136, 4, 0, "name of 0 bytes"},
        {16 + 8, 8, 12345, "stored compressed or with a size"},
        {16 + 0, 8, 1ull << 40, "stored compressed or with a size"},
    };
    for (size_t c = 0; c < sizeof f / sizeof f[0]; c++) {
        memcpy(d, orig, n);
        if (f[c].width == 8)
            put64(d + f[c].at, f[c].value);
        else if (f[c].width == 4)
            put32(d + f[c].at, (uint32_t)f[c].value);
        else {
            uint16_t v = (uint16_t)f[c].value;
            memcpy(d + f[c].at, &v, 2);
        }
        cr_assert_neq(try_bytes(d, n, err, sizeof err), 0, "case %zu loaded", c);
        cr_assert(strstr(err, f[c].want) != NULL, "case %zu: %s", c, err);
    }
    /* Bytes after the last grid: a bad or short second segment header (nothing leaks). */
    d = realloc(d, n + 40);
    memcpy(d, orig, n);
    memset(d + n, 'x', 40);
    cr_assert_neq(try_bytes(d, n + 40, err, sizeof err), 0);
    cr_assert(strstr(err, "not a NanoVDB file: no \"NanoVDB0\" segment header at byte") != NULL, "%s", err);
    cr_assert_neq(try_bytes(d, n + 5, err, sizeof err), 0);
    cr_assert(strstr(err, "truncated: 5 bytes after the last grid") != NULL, "%s", err);
    memcpy(d + n, orig, 16);
    put32(d + n + 8, 33u << 21);
    cr_assert_neq(try_bytes(d, n + 16, err, sizeof err), 0);
    cr_assert(strstr(err, "NanoVDB version 33.0.0") != NULL, "%s", err);
    free(orig);
    /* The single-grid file: fields of the grid buffer (after 16 + 176 + 8 bytes "density\0"). */
    orig = read_testdata("ball.nvdb", &n);
    d = realloc(d, n);
    const size_t G = 16 + 176 + 8, T = G + 672; /* grid, tree */
    struct { size_t at; int width; uint64_t value; const char *want; } gf[] = {
        {G + 0, 8, 0, "no NanoVDB magic"},
        {G + 16, 4, 20u << 21, "version 20.x"},
        {G + 636, 4, 6, "holds vec3f values (metadata: float)"},
        {G + 632, 4, 1, "is a level set grid"},
        {G + 32, 8, 999, "header inconsistent"},
        {G + 28, 4, 0, "header inconsistent"},
        {G + 296 + 88, 8, 0, "singular or not finite"},          /* matd[0]: a zero row */
        {G + 296 + 88 + 8 * 4, 8, 0x7ff0000000000000ull, "singular or not finite"}, /* inf */
        {T + 24, 8, 1ull << 62, "root node offset"},
        {T + 24, 8, (uint64_t)-8, "root node offset"},
    };
    for (size_t c = 0; c < sizeof gf / sizeof gf[0]; c++) {
        memcpy(d, orig, n);
        if (gf[c].width == 8)
            put64(d + gf[c].at, gf[c].value);
        else
            put32(d + gf[c].at, (uint32_t)gf[c].value);
        if (gf[c].at == G + 296 + 88) { /* the whole first row */
            put64(d + gf[c].at + 8, 0);
            put64(d + gf[c].at + 16, 0);
        }
        cr_assert_neq(try_bytes(d, n, err, sizeof err), 0, "grid case %zu loaded", c);
        cr_assert(strstr(err, gf[c].want) != NULL, "grid case %zu: %s", c, err);
    }
    /* Root fields: tile count, bounding box, background. */
    memcpy(d, orig, n);
    uint64_t root_off;
    memcpy(&root_off, orig + T + 24, 8);
    const size_t R = T + root_off;
    put32(d + R + 24, 0x7fffffffu);
    cr_assert_neq(try_bytes(d, n, err, sizeof err), 0);
    cr_assert(strstr(err, "root tiles do not fit") != NULL, "%s", err);
    memcpy(d, orig, n);
    put32(d + R + 0, 100); /* min x > max x */
    cr_assert_neq(try_bytes(d, n, err, sizeof err), 0);
    cr_assert(strstr(err, "has no active voxels") != NULL, "%s", err);
    memcpy(d, orig, n);
    put32(d + R + 12, 0x7fffffffu);
    cr_assert_neq(try_bytes(d, n, err, sizeof err), 0);
    cr_assert(strstr(err, "limits of int32") != NULL, "%s", err);
    memcpy(d, orig, n);
    put32(d + R + 12, 100000); /* too large */
    put32(d + R + 16, 100000);
    cr_assert_neq(try_bytes(d, n, err, sizeof err), 0);
    cr_assert(strstr(err, "dense voxels (with a border of 1), more than") != NULL, "%s", err);
    /* A child offset far outside the buffer: every lookup below that tile reads out of range. */
    memcpy(d, orig, n);
    for (uint32_t t = 0; t < 8; t++)
        put64(d + R + 64 + 32 * t + 8, 1ull << 60);
    cr_assert_neq(try_bytes(d, n, err, sizeof err), 0);
    cr_assert(strstr(err, "corrupt tree: a node lies outside the grid's") != NULL, "%s", err);
    /* Random byte changes anywhere: a sane grid or a message, never a crash (grids kept
     * small so that a changed bounding box cannot make a trial slow). */
    nvdb_max_voxels = 1u << 16;
    int loaded = 0, refused = 0;
    for (uint32_t trial = 0; trial < 3000; trial++) {
        memcpy(d, orig, n);
        uint64_t key = rng_key(11, 0, trial, 0);
        int changes = 1 + (int)(rng_bits(key, 0) % 4);
        for (int c = 0; c < changes; c++) {
            uint64_t r = rng_bits(key, (uint32_t)(1 + c));
            /* Most changes in the headers and node tables, where they matter. */
            size_t at = (r & 1) ? (size_t)((r >> 8) % (G + 672 + 64 + 4096)) : (size_t)((r >> 8) % n);
            d[at % n] = (uint8_t)(r >> 48);
        }
        if (try_bytes(d, n, err, sizeof err) == 0)
            loaded++;
        else
            refused++;
    }
    cr_assert(loaded > 0 && refused > 0, "loaded %d refused %d", loaded, refused);
    free(orig);
    free(d);
}
