/* MIP pyramids and filtered lookups (see mip.h). Down-sampling resamples by exact box
 * coverage, so odd and non-power-of-two sizes keep their mean; it works row by row
 * (memory O(width)), so a 16k level-0 never needs a float copy. The EWA weights are a
 * truncated Gaussian from a table filled once (pthread_once), normalized by their sum. */
#include "image/mip.h"
#include "base/log.h"
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

static float srgb_lut[256], linear_lut[256];
static float ewa_lut[MIP_EWA_LUT_SIZE];
static float ewa_box_scale;
static pthread_once_t tables_once = PTHREAD_ONCE_INIT;

float mip_srgb_to_linear(float c)
{
    return c <= 0.04045f ? c * (1.0f / 12.92f) : powf((c + 0.055f) * (1.0f / 1.055f), 2.4f);
}

float mip_linear_to_srgb(float c)
{
    return c <= 0.0031308f ? 12.92f * c : 1.055f * powf(c, 1.0f / 2.4f) - 0.055f;
}

static void tables_init(void)
{
    for (int i = 0; i < 256; i++) {
        srgb_lut[i] = mip_srgb_to_linear((float)i / 255.0f);
        linear_lut[i] = (float)i / 255.0f;
    }
    /* Gaussian exp(-alpha r^2) shifted to reach 0 at r = 1 (pbrt-v3's alpha = 2). */
    const float alpha = 2.0f;
    for (int i = 0; i < MIP_EWA_LUT_SIZE; i++) {
        float r2 = (float)i / (float)(MIP_EWA_LUT_SIZE - 1);
        ewa_lut[i] = expf(-alpha * r2) - expf(-alpha);
    }
    /* The ellipse's scale that gives the weights the variance of a box over the footprint
     * (1/12 per axis), so a footprint of one pixel filters like the pixel itself: the
     * per-axis variance of w(r) over the unit disc is (1/2) int r^3 w / int r w. */
    double num = 0.0, den = 0.0;
    for (int i = 0; i < 4096; i++) {
        double r = (i + 0.5) / 4096.0, w = exp(-alpha * r * r) - exp(-alpha);
        num += r * r * r * w;
        den += r * w;
    }
    ewa_box_scale = (float)(sqrt(1.0 / 12.0) / sqrt(0.5 * num / den));
}

float mip_ewa_box_scale(void)
{
    pthread_once(&tables_once, tables_init);
    return ewa_box_scale;
}

size_t tex_image_bytes(uint32_t width, uint32_t height, uint32_t channels, enum texel_format format)
{
    if (width == 0 || height == 0 || width > MIP_MAX_DIM || height > MIP_MAX_DIM || (channels != 1 && channels != 3))
        return 0;
    size_t elem = format == TEXEL_F32 ? sizeof(float) : 1;
    /* At most 16384^2 * 3 * 4 bytes: fits in 64 bits; checked anyway for 32-bit size_t. */
    uint64_t n = (uint64_t)width * height * channels * elem;
    if (n > (uint64_t)SIZE_MAX / 2)
        return 0;
    return (size_t)n;
}

int tex_image_alloc(struct tex_image *img, uint32_t width, uint32_t height, uint32_t channels,
                    enum texel_format format)
{
    memset(img, 0, sizeof *img);
    size_t n = tex_image_bytes(width, height, channels, format);
    if (n == 0)
        return -1;
    img->width = width;
    img->height = height;
    img->channels = channels;
    img->format = format;
    img->data = mem_calloc(n, 1);
    return 0;
}

void tex_image_fini(struct tex_image *img)
{
    free(img->data);
    memset(img, 0, sizeof *img);
}

/* ---- Texel access ---- */

static inline vec3 texel_at(const struct tex_image *im, size_t x, size_t y)
{
    size_t i = (y * im->width + x) * im->channels;
    if (im->format == TEXEL_F32) {
        const float *p = (const float *)im->data + i;
        return im->channels == 3 ? v3(p[0], p[1], p[2]) : v3(p[0], p[0], p[0]);
    }
    const float *lut = im->format == TEXEL_U8_SRGB ? srgb_lut : linear_lut;
    const uint8_t *p = (const uint8_t *)im->data + i;
    if (im->channels == 3)
        return v3(lut[p[0]], lut[p[1]], lut[p[2]]);
    float g = lut[p[0]];
    return v3(g, g, g);
}

static inline int64_t wrap_coord(int64_t c, uint32_t n, enum texture_wrap w)
{
    if (w == TEXWRAP_CLAMP)
        return c < 0 ? 0 : (c >= (int64_t)n ? (int64_t)n - 1 : c);
    int64_t r = c % (int64_t)n;
    return r < 0 ? r + n : r;
}

vec3 mip_texel(const struct mip *m, uint32_t level, int64_t x, int64_t y)
{
    const struct tex_image *im = &m->levels[level];
    return texel_at(im, (size_t)wrap_coord(x, im->width, m->wrap), (size_t)wrap_coord(y, im->height, m->wrap));
}

/* ---- Building ---- */

/* Source texel range and weights of destination texel d when n source texels map to
 * nd destination texels: the interval [d n / nd, (d + 1) n / nd) by coverage. */
struct box_taps {
    uint32_t first, count;
    float w[4];
};

static void box_taps(uint32_t d, uint32_t n, uint32_t nd, struct box_taps *t)
{
    double a = (double)d * n / nd, b = (double)(d + 1) * n / nd, inv = (double)nd / n;
    uint32_t lo = (uint32_t)floor(a), hi = (uint32_t)ceil(b);
    if (hi > n)
        hi = n;
    t->first = lo;
    t->count = 0;
    for (uint32_t i = lo; i < hi && t->count < 4; i++) {
        double l = a > i ? a : i, r = b < i + 1.0 ? b : i + 1.0;
        t->w[t->count++] = (float)((r - l) * inv);
    }
}

static void level_down(const struct tex_image *src, struct tex_image *dst)
{
    uint32_t w = src->width > 1 ? src->width / 2 : 1, h = src->height > 1 ? src->height / 2 : 1;
    CHECK(tex_image_alloc(dst, w, h, src->channels, src->format) == 0);
    const uint32_t nc = src->channels;
    float *row = mem_alloc((size_t)src->width * nc * sizeof *row);
    struct box_taps *tx = mem_alloc((size_t)w * sizeof *tx);
    for (uint32_t x = 0; x < w; x++)
        box_taps(x, src->width, w, &tx[x]);
    for (uint32_t y = 0; y < h; y++) {
        struct box_taps ty;
        box_taps(y, src->height, h, &ty);
        /* Vertical pass into one float row, in linear space. */
        memset(row, 0, (size_t)src->width * nc * sizeof *row);
        for (uint32_t k = 0; k < ty.count; k++)
            for (uint32_t x = 0; x < src->width; x++) {
                vec3 c = texel_at(src, x, ty.first + k);
                float *r = &row[(size_t)x * nc];
                r[0] += ty.w[k] * c.x;
                if (nc == 3) {
                    r[1] += ty.w[k] * c.y;
                    r[2] += ty.w[k] * c.z;
                }
            }
        for (uint32_t x = 0; x < w; x++) {
            float acc[3] = {0, 0, 0};
            for (uint32_t k = 0; k < tx[x].count; k++)
                for (uint32_t c = 0; c < nc; c++)
                    acc[c] += tx[x].w[k] * row[(size_t)(tx[x].first + k) * nc + c];
            size_t o = ((size_t)y * w + x) * nc;
            for (uint32_t c = 0; c < nc; c++) {
                if (dst->format == TEXEL_F32) {
                    ((float *)dst->data)[o + c] = acc[c];
                } else {
                    float v = acc[c] < 0.0f ? 0.0f : (acc[c] > 1.0f ? 1.0f : acc[c]);
                    if (dst->format == TEXEL_U8_SRGB)
                        v = mip_linear_to_srgb(v);
                    ((uint8_t *)dst->data)[o + c] = (uint8_t)lrintf(v * 255.0f);
                }
            }
        }
    }
    free(tx);
    free(row);
}

void mip_init(struct mip *m, const struct tex_image *base, enum texture_wrap wrap)
{
    pthread_once(&tables_once, tables_init);
    memset(m, 0, sizeof *m);
    CHECK(tex_image_bytes(base->width, base->height, base->channels, base->format) != 0);
    m->channels = base->channels;
    m->format = base->format;
    m->wrap = wrap;
    m->levels[0] = *base;
    m->num_levels = 1;
    while (m->num_levels < MIP_MAX_LEVELS) {
        const struct tex_image *prev = &m->levels[m->num_levels - 1];
        if (prev->width == 1 && prev->height == 1)
            break;
        level_down(prev, &m->levels[m->num_levels]);
        m->owns[m->num_levels] = 1;
        m->num_levels++;
    }
}

void mip_fini(struct mip *m)
{
    for (uint32_t i = 0; i < m->num_levels; i++)
        if (m->owns[i])
            tex_image_fini(&m->levels[i]);
    memset(m, 0, sizeof *m);
}

/* ---- Lookups ---- */

/* An integral float (from floorf or ceilf) as a texel index: clamped to int64's range first
 * (NaN to its bottom), so that the conversion is defined for any coordinate; indices inside
 * the range are unchanged, and beyond it they only ever meet clamp wrapping (repeat wraps the
 * coordinate first), which maps both ends to the edge texels as before. */
static inline int64_t texel_index(float f)
{
    return (int64_t)fminf(fmaxf(f, -0x1p63f), 0x1.fffffep62f);
}

static vec3 nearest(const struct mip *m, uint32_t level, float s, float t)
{
    const struct tex_image *im = &m->levels[level];
    return mip_texel(m, level, texel_index(floorf(s * (float)im->width)), texel_index(floorf(t * (float)im->height)));
}

static vec3 bilinear(const struct mip *m, uint32_t level, float s, float t)
{
    const struct tex_image *im = &m->levels[level];
    float x = s * (float)im->width - 0.5f, y = t * (float)im->height - 0.5f;
    float fx = floorf(x), fy = floorf(y), ax = x - fx, ay = y - fy;
    int64_t ix = texel_index(fx), iy = texel_index(fy);
    vec3 a = mip_texel(m, level, ix, iy), b = mip_texel(m, level, ix + 1, iy);
    vec3 c = mip_texel(m, level, ix, iy + 1), d = mip_texel(m, level, ix + 1, iy + 1);
    vec3 top = v3_add(v3_scale(a, 1.0f - ax), v3_scale(b, ax));
    vec3 bot = v3_add(v3_scale(c, 1.0f - ax), v3_scale(d, ax));
    return v3_add(v3_scale(top, 1.0f - ay), v3_scale(bot, ay));
}

float mip_level_for_width(const struct mip *m, float width)
{
    uint32_t res = m->levels[0].width > m->levels[0].height ? m->levels[0].width : m->levels[0].height;
    float texels = width * (float)res;
    if (!(texels > 1.0f))
        return 0.0f; /* also NaN */
    float l = log2f(texels), top = (float)(m->num_levels - 1);
    return l < top ? l : top;
}

static vec3 lerp_levels(const struct mip *m, float level, float s, float t)
{
    uint32_t i = (uint32_t)level;
    if (i + 1 >= m->num_levels)
        return bilinear(m, m->num_levels - 1, s, t);
    float f = level - (float)i;
    return v3_add(v3_scale(bilinear(m, i, s, t), 1.0f - f), v3_scale(bilinear(m, i + 1, s, t), f));
}

vec3 mip_ewa_level(const struct mip *m, uint32_t level, float s, float t, float ds0, float dt0, float ds1,
                   float dt1, struct mip_ewa_record *rec)
{
    if (rec)
        rec->count = 0;
    if (level >= m->num_levels)
        return bilinear(m, m->num_levels - 1, s, t);
    const struct tex_image *im = &m->levels[level];
    float w = (float)im->width, h = (float)im->height;
    s = s * w - 0.5f;
    t = t * h - 0.5f;
    ds0 *= w, ds1 *= w, dt0 *= h, dt1 *= h;
    /* Implicit ellipse A s^2 + B s t + C t^2 = F through the two axes; the + 1 keeps it
     * at least one texel wide, so a level's texels are never skipped between samples. */
    float A = dt0 * dt0 + dt1 * dt1 + 1.0f;
    float B = -2.0f * (ds0 * dt0 + ds1 * dt1);
    float C = ds0 * ds0 + ds1 * ds1 + 1.0f;
    float inv_f = 1.0f / (A * C - B * B * 0.25f);
    A *= inv_f, B *= inv_f, C *= inv_f;
    float det = -B * B + 4.0f * A * C, inv_det = 1.0f / det;
    float us = sqrtf(det * C), vs = sqrtf(A * det);
    float fs0 = ceilf(s - 2.0f * inv_det * us), fs1 = floorf(s + 2.0f * inv_det * us);
    float ft0 = ceilf(t - 2.0f * inv_det * vs), ft1 = floorf(t + 2.0f * inv_det * vs);
    /* The level was chosen so the box is a few texels by max_aniso; bound it anyway so
     * that a pathological ellipse costs a bounded loop. */
    const float max_half = 4096.0f;
    if (!(fs1 - fs0 <= 2 * max_half && ft1 - ft0 <= 2 * max_half) || !isfinite(s) || !isfinite(t))
        return bilinear(m, level, (s + 0.5f) / w, (t + 0.5f) / h);
    int64_t t0 = texel_index(ft0), t1 = texel_index(ft1);
    (void)fs0, (void)fs1;
    vec3 sum = v3(0, 0, 0);
    float sum_w = 0.0f;
    const int64_t iw = (int64_t)im->width;
    for (int64_t it = t0; it <= t1; it++) {
        float tt = (float)it - t;
        /* Only the span of this row inside the ellipse: A ss^2 + (B tt) ss + (C tt^2 - 1) < 0. */
        float qb = B * tt, qc = C * tt * tt - 1.0f, disc = qb * qb - 4.0f * A * qc;
        if (!(disc > 0.0f))
            continue;
        float root = sqrtf(disc), inv2a = 0.5f / A;
        int64_t s0 = texel_index(ceilf(s + (-qb - root) * inv2a)), s1 = texel_index(floorf(s + (-qb + root) * inv2a));
        if (s1 < s0)
            continue;
        int64_t y = wrap_coord(it, im->height, m->wrap), x = wrap_coord(s0, im->width, m->wrap);
        for (int64_t is = s0; is <= s1; is++) {
            float ss = (float)is - s;
            float r2 = A * ss * ss + B * ss * tt + C * tt * tt;
            if (r2 < 1.0f && r2 >= 0.0f) {
                int li = (int)(r2 * (float)(MIP_EWA_LUT_SIZE - 1));
                float wgt = ewa_lut[li < MIP_EWA_LUT_SIZE ? li : MIP_EWA_LUT_SIZE - 1];
                if (wgt > 0.0f) {
                    sum = v3_add(sum, v3_scale(texel_at(im, (size_t)x, (size_t)y), wgt));
                    sum_w += wgt;
                    if (rec && rec->count < rec->cap) {
                        rec->x[rec->count] = is;
                        rec->y[rec->count] = it;
                        rec->w[rec->count] = wgt;
                    }
                    if (rec)
                        rec->count++;
                }
            }
            /* The next texel of the row after wrapping, without a division per texel. */
            if (m->wrap == TEXWRAP_REPEAT)
                x = x + 1 == iw ? 0 : x + 1;
            else
                x = is + 1 < 0 ? 0 : (is + 1 >= iw ? iw - 1 : is + 1);
        }
    }
    if (!(sum_w > 0.0f))
        return bilinear(m, level, (s + 0.5f) / w, (t + 0.5f) / h);
    if (rec)
        for (size_t i = 0; i < rec->count && i < rec->cap; i++)
            rec->w[i] /= sum_w;
    return v3_scale(sum, 1.0f / sum_w);
}

float mip_ewa_select(const struct mip *m, float max_aniso, float *ds0, float *dt0, float *ds1, float *dt1)
{
    float l0 = *ds0 * *ds0 + *dt0 * *dt0, l1 = *ds1 * *ds1 + *dt1 * *dt1;
    if (l0 < l1) { /* axis 0 is the major one */
        float a = *ds0, b = *dt0;
        *ds0 = *ds1, *dt0 = *dt1, *ds1 = a, *dt1 = b;
    }
    float longer = sqrtf(*ds0 * *ds0 + *dt0 * *dt0), shorter = sqrtf(*ds1 * *ds1 + *dt1 * *dt1);
    if (!(max_aniso >= 1.0f))
        max_aniso = 1.0f;
    if (shorter * max_aniso < longer && shorter > 0.0f) {
        /* Clamp the eccentricity by widening the minor axis: blurrier, bounded cost. */
        float scale = longer / (shorter * max_aniso);
        *ds1 *= scale, *dt1 *= scale;
        shorter *= scale;
    }
    if (!(shorter > 0.0f) || !isfinite(longer))
        return -1.0f;
    return mip_level_for_width(m, shorter);
}

static float finite_or_zero(float x)
{
    return isfinite(x) ? x : 0.0f;
}

vec3 mip_lookup(const struct mip *m, enum texture_filter filter, float max_aniso, float s, float t, float dsdx,
                float dtdx, float dsdy, float dtdy)
{
    if (!isfinite(s) || !isfinite(t))
        return v3(0, 0, 0);
    /* Repeat: keep the coordinates small so float texel positions stay exact enough. */
    if (m->wrap == TEXWRAP_REPEAT) {
        s -= floorf(s);
        t -= floorf(t);
    }
    dsdx = finite_or_zero(dsdx), dtdx = finite_or_zero(dtdx);
    dsdy = finite_or_zero(dsdy), dtdy = finite_or_zero(dtdy);
    switch (filter) {
    case TEXFILTER_NEAREST:
        return nearest(m, 0, s, t);
    case TEXFILTER_BILINEAR:
        return bilinear(m, 0, s, t);
    case TEXFILTER_TRILINEAR: {
        float wdt = 2.0f * fmaxf(fmaxf(fabsf(dsdx), fabsf(dtdx)), fmaxf(fabsf(dsdy), fabsf(dtdy)));
        return lerp_levels(m, mip_level_for_width(m, wdt), s, t);
    }
    case TEXFILTER_EWA:
    case TEXFILTER_COUNT_:
        break;
    }
    const float k = mip_ewa_box_scale();
    dsdx *= k, dtdx *= k, dsdy *= k, dtdy *= k;
    float level = mip_ewa_select(m, max_aniso, &dsdx, &dtdx, &dsdy, &dtdy);
    if (level < 0.0f)
        return bilinear(m, 0, s, t);
    uint32_t il = (uint32_t)level;
    float f = level - (float)il;
    vec3 a = mip_ewa_level(m, il, s, t, dsdx, dtdx, dsdy, dtdy, NULL);
    if (f == 0.0f || il + 1 >= m->num_levels)
        return a;
    vec3 b = mip_ewa_level(m, il + 1, s, t, dsdx, dtdx, dsdy, dtdy, NULL);
    return v3_add(v3_scale(a, 1.0f - f), v3_scale(b, f));
}
