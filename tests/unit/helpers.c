/* Scaffolding shared by the unit tests; see helpers.h. Linked into build/unit_tests only. */
#include "helpers.h"
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "base/log.h"
#include "render/photon_map.h"
#include "scene/scene_json.h"

int mem_read(void *ctx, const char *rel_path, char **data, size_t *size, char *err, size_t errlen)
{
    for (const struct mem_file *f = ctx; f && f->path; f++)
        if (strcmp(f->path, rel_path) == 0) {
            *size = f->size ? f->size : strlen(f->data);
            *data = mem_alloc(*size + 1);
            memcpy(*data, f->data, *size);
            (*data)[*size] = '\0'; /* asset_source promises a terminator beyond *size */
            return 0;
        }
    snprintf(err, errlen, "%s: No such file or directory", rel_path);
    return -1;
}

int test_scene_load(const char *text, const struct mem_file *files, struct scene *s, char *err)
{
    struct asset_source src = {mem_read, (void *)(uintptr_t)files};
    static const double world[3] = {0, 0, 0};
    return scene_json_parse_origin("scenes/t.json", text, strlen(text), &src, world, s, err, 512);
}

const char *test_scene_expect_error(const char *text, const struct mem_file *files, const char *want)
{
    static char err[512];
    struct scene s;
    err[0] = '\0';
    cr_assert_eq(test_scene_load(text, files, &s, err), -1, "accepted: %s", text);
    cr_expect(strstr(err, want) != NULL, "error \"%s\" lacks \"%s\"", err, want);
    /* scene_json_parse leaves a failed scene freed */
    cr_expect_null(s.materials);
    cr_expect_eq(s.num_meshes, 0);
    return err;
}

struct mesh test_quad(vec3 a, vec3 b, vec3 c, vec3 d, uint32_t mat, int flip)
{
    struct mesh m;
    memset(&m, 0, sizeof m);
    m.num_vertices = 4;
    m.num_triangles = 2;
    m.positions = mem_alloc(sizeof(float) * 12);
    vec3 v[4] = {a, b, c, d};
    for (int i = 0; i < 4; i++) {
        m.positions[3 * i] = v[i].x;
        m.positions[3 * i + 1] = v[i].y;
        m.positions[3 * i + 2] = v[i].z;
    }
    static const uint32_t idx[6] = {0, 1, 2, 0, 2, 3}, idx_flip[6] = {0, 2, 1, 0, 3, 2};
    m.indices = mem_alloc(sizeof idx);
    memcpy(m.indices, flip ? idx_flip : idx, sizeof idx);
    m.material_ids = mem_alloc(sizeof(uint32_t) * 2);
    m.material_ids[0] = m.material_ids[1] = mat;
    return m;
}

float *test_render_map(const struct scene *s, struct photon_map *map, uint32_t threads, struct tile_stats *st)
{
    struct render_job job;
    char err[256];
    cr_assert_eq(render_job_init(&job, s, 0, threads, err, sizeof err), 0, "%s", err);
    int lent = map != NULL;
    render_job_set_photon_map(&job, &map);
    uint32_t w = s->settings.width, h = s->settings.height;
    struct tile_layout lay;
    tile_layout_init(&lay, s->settings.aovs);
    float *px = mem_alloc(sizeof(float) * w * h * lay.num_channels);
    integrator_render_tile(&job, 0, 0, w, h, px, st);
    /* lent: the slots go back to the caller as the chain it gave */
    for (uint32_t p = 0; lent && p < job.num_passes; p++) {
        job.pass_maps[p]->next_pass = p + 1 < job.num_passes ? job.pass_maps[p + 1] : NULL;
        job.pass_maps[p] = NULL;
    }
    render_job_fini(&job);
    return px;
}

float *test_render(const struct scene *s, uint32_t threads, struct tile_stats *st)
{
    return test_render_map(s, NULL, threads, st);
}

double test_channel_mean(const float *px, uint32_t w, uint32_t h, enum tile_channel ch, double *se)
{
    double sum = 0, var = 0;
    for (uint32_t i = 0; i < w * h; i++) {
        sum += px[i * TILE_NUM_CHANNELS + ch];
        var += px[i * TILE_NUM_CHANNELS + ch + CH_VAR_R];
    }
    *se = sqrt(var) / (w * h);
    return sum / (w * h);
}

uint8_t *test_read_file(const char *path, size_t *size, const char *hint)
{
    FILE *f = fopen(path, "rb");
    cr_assert_not_null(f, "%s missing: %s", path, hint);
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    uint8_t *d = malloc((size_t)n + 1);
    cr_assert_eq(fread(d, 1, (size_t)n, f), (size_t)n);
    fclose(f);
    *size = (size_t)n;
    return d;
}

void test_ramp_camera(struct scene *s, uint32_t w, uint32_t spp)
{
    float aspect = (float)w / 4.0f, half_w = 2.0f;
    s->camera = (struct camera_desc){.position = v3(0, 0, 10), .look_at = v3(0, 0, 0), .up = v3(0, 1, 0)};
    s->camera.fov_y_deg = 2.0f * atanf(half_w / (10.0f * aspect)) * 180.0f / (float)M_PI;
    s->camera.shutter_open = 0.0f;
    s->camera.shutter_close = 1.0f;
    s->settings.width = w;
    s->settings.height = 4;
    s->settings.spp = spp;
    s->settings.max_depth = 1;
    s->settings.seed = 3;
    s->settings.tile_size = 16;
}

void test_direction_chi_square(const char *what, vec3 c, double th_max, int nt, int np, int q,
                               float (*pdf)(void *ctx, vec3 w), vec3 (*sample)(void *ctx, uint32_t k), void *ctx,
                               int n, double tol, int max_light, int min_cells)
{
    enum { MAXC = 32 };
    cr_assert(nt >= 1 && nt <= MAXC && np >= 1 && np <= MAXC);
    vec3 t = v3_normalize(v3_cross(c, fabsf(c.y) < 0.9f ? v3(0, 1, 0) : v3(1, 0, 0))), b = v3_cross(c, t);
    static double mass[MAXC][MAXC];
    static int count[MAXC][MAXC];
    double total = 0.0;
    for (int i = 0; i < nt; i++)
        for (int j = 0; j < np; j++) {
            double m = 0.0;
            for (int a = 0; a < q; a++)
                for (int e = 0; e < q; e++) {
                    double th = th_max * (i + (a + 0.5) / q) / nt, ph = 2.0 * M_PI * (j + (e + 0.5) / q) / np;
                    vec3 w = v3_add(v3_scale(c, (float)cos(th)),
                                    v3_add(v3_scale(t, (float)(sin(th) * cos(ph))), v3_scale(b, (float)(sin(th) * sin(ph)))));
                    m += pdf(ctx, v3_normalize(w)) * sin(th) * (th_max / nt / q) * (2.0 * M_PI / np / q);
                }
            mass[i][j] = m;
            count[i][j] = 0;
            total += m;
        }
    cr_assert(fabs(total - 1.0) < tol, "%s: the density integrates to %g", what, total);
    for (int k = 0; k < n; k++) {
        vec3 w = sample(ctx, (uint32_t)k);
        cr_assert(fabsf(v3_length(w) - 1.0f) < 1e-5f, "%s: sample %d not a unit direction", what, k);
        cr_assert(pdf(ctx, w) > 0.0f, "%s: sample %d where the density is 0", what, k);
        double th = acos(fmax(-1.0, fmin(1.0, v3_dot(w, c)))), ph = atan2(v3_dot(w, b), v3_dot(w, t));
        ph = ph < 0.0 ? ph + 2.0 * M_PI : ph;
        int i = (int)(th / th_max * nt), j = (int)(ph / (2.0 * M_PI) * np);
        cr_assert(th <= th_max, "%s: sample %d outside the cells' cone", what, k);
        count[i < nt ? i : nt - 1][j < np ? j : np - 1]++;
    }
    double chi2 = 0.0;
    int cells = 0, light = 0;
    for (int i = 0; i < nt; i++)
        for (int j = 0; j < np; j++) {
            double e = mass[i][j] * n;
            if (e < 5.0) {
                light += count[i][j];
                continue;
            }
            chi2 += (count[i][j] - e) * (count[i][j] - e) / e;
            cells++;
        }
    cr_log_info("%s: chi2 %g over %d cells, %d samples in cells of mass < 5 / n", what, chi2, cells, light);
    cr_assert(light <= max_light, "%s: %d samples where the density says almost none", what, light);
    cr_assert(cells >= min_cells, "%s: %d cells", what, cells);
    cr_assert(chi2 < (cells - 1) + 6 * sqrt(2.0 * (cells - 1)), "%s: chi2 %g over %d cells", what, chi2, cells);
}
