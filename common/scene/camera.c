/* Thin-lens camera (see camera.h). Looking down -z with +y up gives +x to the right, the
 * usual right-handed convention (matching Embree's tutorials and the Cornell box data).
 * Keyframed orientation is slerped as quaternions (in double), so 180-degree turns and
 * keys at equal times stay finite; positions and focus distances are interpolated linearly. */
#include "scene/camera.h"
#include "base/cdf.h"
#include <math.h>

static void still_basis(vec3 pos, vec3 look, vec3 up_hint, struct camera_pose *p)
{
    p->origin = pos;
    p->forward = v3_normalize(v3_sub(look, pos));
    p->right = v3_normalize(v3_cross(p->forward, up_hint));
    p->up = v3_cross(p->right, p->forward);
}

/* Shepperd's method on the rotation with columns (right, up, -forward). */
static void basis_to_quat(const struct camera_pose *p, float q[4])
{
    double m00 = p->right.x, m01 = p->up.x, m02 = -p->forward.x;
    double m10 = p->right.y, m11 = p->up.y, m12 = -p->forward.y;
    double m20 = p->right.z, m21 = p->up.z, m22 = -p->forward.z;
    double tr = m00 + m11 + m22, x, y, z, w, s;
    if (tr > 0.0) {
        s = sqrt(tr + 1.0) * 2.0;
        w = 0.25 * s, x = (m21 - m12) / s, y = (m02 - m20) / s, z = (m10 - m01) / s;
    } else if (m00 > m11 && m00 > m22) {
        s = sqrt(1.0 + m00 - m11 - m22) * 2.0;
        w = (m21 - m12) / s, x = 0.25 * s, y = (m01 + m10) / s, z = (m02 + m20) / s;
    } else if (m11 > m22) {
        s = sqrt(1.0 + m11 - m00 - m22) * 2.0;
        w = (m02 - m20) / s, x = (m01 + m10) / s, y = 0.25 * s, z = (m12 + m21) / s;
    } else {
        s = sqrt(1.0 + m22 - m00 - m11) * 2.0;
        w = (m10 - m01) / s, x = (m02 + m20) / s, y = (m12 + m21) / s, z = 0.25 * s;
    }
    double n = sqrt(x * x + y * y + z * z + w * w);
    q[0] = (float)(x / n), q[1] = (float)(y / n), q[2] = (float)(z / n), q[3] = (float)(w / n);
}

static void quat_to_basis(const double q[4], struct camera_pose *p)
{
    double x = q[0], y = q[1], z = q[2], w = q[3];
    p->right = v3((float)(1 - 2 * (y * y + z * z)), (float)(2 * (x * y + w * z)), (float)(2 * (x * z - w * y)));
    p->up = v3((float)(2 * (x * y - w * z)), (float)(1 - 2 * (x * x + z * z)), (float)(2 * (y * z + w * x)));
    p->forward = v3((float)-(2 * (x * z + w * y)), (float)-(2 * (y * z - w * x)), (float)-(1 - 2 * (x * x + y * y)));
}

static void quat_slerp(const float a[4], const float b[4], double t, double out[4])
{
    double d = 0.0, bb[4];
    for (int i = 0; i < 4; i++)
        d += (double)a[i] * b[i];
    double sign = d < 0.0 ? -1.0 : 1.0; /* shorter arc; q and -q are one rotation */
    d *= sign;
    for (int i = 0; i < 4; i++)
        bb[i] = sign * b[i];
    double wa, wb;
    if (d > 0.9995) {
        wa = 1.0 - t, wb = t;   /* nearly equal: nlerp, no division by a tiny sine */
    } else {
        double th = acos(d < 1.0 ? d : 1.0), s = sin(th);
        wa = sin((1.0 - t) * th) / s, wb = sin(t * th) / s;
    }
    double n = 0.0;
    for (int i = 0; i < 4; i++) {
        out[i] = wa * a[i] + wb * bb[i];
        n += out[i] * out[i];
    }
    n = sqrt(n);
    for (int i = 0; i < 4; i++)
        out[i] /= n;
}

static float pose_focus(const struct camera *cam, const struct camera_pose *p, float dist_to_look)
{
    float f = cam->focus_distance > 0.0f ? cam->focus_distance : dist_to_look;
    if (cam->has_focus_point)
        f = v3_dot(v3_sub(cam->focus_point, p->origin), p->forward);
    /* A focus point behind the camera or on it: the nearest finite plane still works. */
    return f > 1e-6f && isfinite(f) ? f : 1e-6f;
}

double camera_filter_eval(uint32_t filter, float width, double x)
{
    double w = filter == FILTER_GAUSSIAN ? 3.0 * width : filter == FILTER_BLACKMAN_HARRIS ? 2.0 * width : 1.0;
    if (!(fabs(x) <= 0.5 * w))
        return 0.0;
    switch (filter) {
    case FILTER_GAUSSIAN: {
        double v = x * 6.0 / w;
        return exp(-2.0 * v * v);
    }
    case FILTER_BLACKMAN_HARRIS: {
        double v = 2.0 * M_PI * (x / w + 0.5);
        return 0.35875 - 0.48829 * cos(v) + 0.14128 * cos(2.0 * v) - 0.01168 * cos(3.0 * v);
    }
    default:
        return 1.0;
    }
}

/* The filter's CDF table (midpoint rule per cell, in double) and its spread. */
static void filter_init(struct camera *cam, const struct camera_desc *d)
{
    cam->filter = d->filter < FILTER_COUNT_ ? d->filter : FILTER_BOX;
    cam->filter_footprint = 1.0f;
    if (cam->filter == FILTER_BOX || !(d->filter_width > 0.0f))
        return;
    double w = cam->filter == FILTER_GAUSSIAN ? 3.0 * d->filter_width : 2.0 * d->filter_width;
    double r = 0.5 * w, dx = w / CAMERA_FILTER_TABLE, sum = 0.0, m2 = 0.0;
    double cdf[CAMERA_FILTER_TABLE + 1];
    cdf[0] = 0.0;
    for (int i = 0; i < CAMERA_FILTER_TABLE; i++) {
        double x = -r + (i + 0.5) * dx, f = camera_filter_eval(cam->filter, d->filter_width, x);
        sum += f;
        m2 += f * x * x;
        cdf[i + 1] = sum;
    }
    for (int i = 0; i <= CAMERA_FILTER_TABLE; i++)
        cam->filter_cdf[i] = (float)(cdf[i] / sum);
    cam->filter_cdf[CAMERA_FILTER_TABLE] = 1.0f;
    cam->filter_radius = (float)r;
    double sd = sqrt(m2 / sum), box_sd = sqrt(1.0 / 12.0);
    cam->filter_footprint = sd > box_sd ? (float)(sd / box_sd) : 1.0f;
}

float camera_filter_offset(const struct camera *cam, float u)
{
    if (cam->filter == FILTER_BOX)
        return u - 0.5f;
    /* The cell k with cdf[k] <= u < cdf[k + 1], then linear within it. */
    const float *c = cam->filter_cdf;
    uint32_t lo = cdf_cell(c, CAMERA_FILTER_TABLE, u);
    float span = c[lo + 1] - c[lo], t = span > 0.0f ? (u - c[lo]) / span : 0.5f;
    t = t < 0.0f ? 0.0f : t > 1.0f ? 1.0f : t;
    return cam->filter_radius * (2.0f * ((float)lo + t) / CAMERA_FILTER_TABLE - 1.0f);
}

void camera_init(struct camera *cam, const struct camera_desc *d, uint32_t width, uint32_t height)
{
    *cam = (struct camera){0};
    still_basis(d->position, d->look_at, d->up, &cam->still);
    cam->tan_half_fov_y = tanf(d->fov_y_deg * (float)M_PI / 360.0f);
    cam->width = (float)width;
    cam->height = (float)height;
    cam->aspect = (float)width / (float)height;
    cam->lens_radius = d->aperture_radius > 0.0f ? d->aperture_radius : 0.0f;
    cam->uses_lens = cam->lens_radius > 0.0f;
    cam->blades = d->blades >= 3 && d->blades <= CAMERA_MAX_BLADES ? d->blades : 0;
    for (uint32_t k = 0; cam->blades && k <= cam->blades; k++) {
        double a = d->blade_rotation_deg * M_PI / 180.0 + 2.0 * M_PI * (double)(k % cam->blades) / cam->blades;
        cam->blade_x[k] = (float)cos(a);
        cam->blade_y[k] = (float)sin(a);
    }
    filter_init(cam, d);
    cam->has_focus_point = d->has_focus_point;
    cam->focus_point = d->focus_point;
    cam->focus_distance = d->focus_distance;
    cam->shutter_open = d->shutter_open;
    cam->shutter_close = d->shutter_close > d->shutter_open ? d->shutter_close : d->shutter_open;
    cam->shutter_ramp = d->shutter_ramp > 0.0f ? (d->shutter_ramp < 0.5f ? d->shutter_ramp : 0.5f) : 0.0f;

    uint32_t n = d->num_keyframes <= CAMERA_MAX_KEYFRAMES ? d->num_keyframes : CAMERA_MAX_KEYFRAMES;
    int differ = 0;
    for (uint32_t i = 1; i < n; i++) {
        const struct camera_keyframe *a = &d->keyframes[0], *b = &d->keyframes[i];
        if (a->position.x != b->position.x || a->position.y != b->position.y || a->position.z != b->position.z ||
            a->look_at.x != b->look_at.x || a->look_at.y != b->look_at.y || a->look_at.z != b->look_at.z ||
            a->up.x != b->up.x || a->up.y != b->up.y || a->up.z != b->up.z)
            differ = 1;
    }
    if (n > 0 && !differ) /* keys that never change are a still camera */
        still_basis(d->keyframes[0].position, d->keyframes[0].look_at, d->keyframes[0].up, &cam->still);
    vec3 look0 = n > 0 ? d->keyframes[0].look_at : d->look_at; /* any distance, also past 1e19 */
    cam->still.focus = pose_focus(cam, &cam->still, v3_length_rescaled(v3_sub(look0, cam->still.origin)));
    if (differ) {
        cam->moving = 1;
        cam->num_keys = n;
        for (uint32_t i = 0; i < n; i++) {
            const struct camera_keyframe *k = &d->keyframes[i];
            struct camera_pose p;
            still_basis(k->position, k->look_at, k->up, &p);
            cam->key_time[i] = k->time;
            cam->key_pos[i] = k->position;
            basis_to_quat(&p, cam->key_rot[i]);
            cam->key_dist[i] = v3_length_rescaled(v3_sub(k->look_at, k->position));
        }
    }
    cam->uses_time = cam->shutter_close > cam->shutter_open && cam->moving;
    cam->origin = cam->still.origin;
    cam->forward = cam->still.forward;
    cam->right = cam->still.right;
    cam->up = cam->still.up;
}

void camera_set_scene_motion(struct camera *cam, int objects_move)
{
    cam->uses_time = cam->shutter_close > cam->shutter_open && (cam->moving || objects_move);
}

void camera_pose_at(const struct camera *cam, double t, struct camera_pose *p)
{
    if (!cam->moving) {
        *p = cam->still;
        return;
    }
    uint32_t n = cam->num_keys, i = 0;
    while (i + 1 < n && t >= cam->key_time[i + 1])
        i++;
    uint32_t j = i + 1 < n ? i + 1 : i;
    double dt = (double)cam->key_time[j] - cam->key_time[i];
    double w = dt > 0.0 ? (t - cam->key_time[i]) / dt : 0.0;
    w = w < 0.0 ? 0.0 : (w > 1.0 ? 1.0 : w); /* hold the end keys outside their range */
    double q[4];
    quat_slerp(cam->key_rot[i], cam->key_rot[j], w, q);
    quat_to_basis(q, p);
    vec3 a = cam->key_pos[i], b = cam->key_pos[j];
    p->origin = v3((float)(a.x + (b.x - a.x) * w), (float)(a.y + (b.y - a.y) * w), (float)(a.z + (b.z - a.z) * w));
    float dist = (float)(cam->key_dist[i] + (cam->key_dist[j] - cam->key_dist[i]) * w);
    p->focus = pose_focus(cam, p, dist);
}

void camera_lens_point(const struct camera *cam, float lu, float lv, float *x, float *y)
{
    float px, py;
    if (cam->blades) {
        /* A triangle (centre, vertex k, vertex k+1) chosen uniformly (they have equal
         * areas), then a uniform point in it: no rejection, strata stay in one piece. */
        float t = lu * (float)cam->blades;
        uint32_t k = (uint32_t)t;
        k = k < cam->blades ? k : cam->blades - 1;
        float f = t - (float)k;
        f = f < 1.0f ? f : 0x1.fffffep-1f;
        float s = sqrtf(f);
        px = s * (cam->blade_x[k] * (1.0f - lv) + cam->blade_x[k + 1] * lv);
        py = s * (cam->blade_y[k] * (1.0f - lv) + cam->blade_y[k + 1] * lv);
    } else {
        /* Shirley and Chiu's concentric map keeps the sampler's strata compact. */
        float a = 2.0f * lu - 1.0f, b = 2.0f * lv - 1.0f, r, phi;
        if (a == 0.0f && b == 0.0f) {
            r = 0.0f, phi = 0.0f;
        } else if (fabsf(a) > fabsf(b)) {
            r = a, phi = (float)(M_PI / 4) * (b / a);
        } else {
            r = b, phi = (float)(M_PI / 2) - (float)(M_PI / 4) * (a / b);
        }
        px = r * cosf(phi);
        py = r * sinf(phi);
    }
    *x = px * cam->lens_radius;
    *y = py * cam->lens_radius;
}

void camera_ray_lens(const struct camera *cam, const struct camera_pose *p, float fx, float fy, float lu, float lv,
                     vec3 *origin, vec3 *dir)
{
    vec3 d = camera_film_dir(cam, p, fx, fy);
    if (!cam->uses_lens) {
        *origin = p->origin;
        *dir = v3_normalize(d);
        return;
    }
    float ax, ay;
    camera_lens_point(cam, lu, lv, &ax, &ay);
    vec3 off = v3_add(v3_scale(p->right, ax), v3_scale(p->up, ay));
    /* The pinhole ray meets the focal plane at d * focus (d has unit forward component);
     * aim there from the lens point. Scale first so huge apertures or focus distances do
     * not overflow the squared length in normalize. */
    float s = fmaxf(p->focus, fmaxf(fabsf(ax), fabsf(ay)));
    float inv = 1.0f / s;
    *dir = v3_normalize(v3_sub(v3_scale(d, p->focus * inv), v3_scale(off, inv)));
    *origin = v3_add(p->origin, off);
}

/* Trapezoid shutter: transmission ramps linearly over the first and last `r` of the
 * interval. Inverting its CDF warps a uniform u into a time with that density. */
float camera_shutter_warp(const struct camera *cam, float u)
{
    double r = cam->shutter_ramp;
    if (r <= 0.0)
        return u;
    double h = 1.0 / (1.0 - r), a = 0.5 * h * r, t;
    if (u < a)
        t = sqrt(2.0 * r * u / h);
    else if (u > 1.0 - a)
        t = 1.0 - sqrt(2.0 * r * (1.0 - u) / h);
    else
        t = r + (u - a) / h;
    t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
    return (float)t;
}

/* The camera ray of pixel jitter (ju, jv) in [0, 1)^2 at shutter time time01, the lens
 * sample from the sampler. */
static void generate_at(const struct camera *cam, const struct sampler *smp, uint32_t frame, uint32_t px, uint32_t py,
                        float ju, float jv, float time01, struct camera_sample *out)
{
    float fx, fy;
    if (cam->filter == FILTER_BOX) { /* the pixel itself, bit for bit as without a filter */
        fx = (float)px + ju;
        fy = (float)py + jv;
    } else {
        fx = (float)px + 0.5f + camera_filter_offset(cam, ju);
        fy = (float)py + 0.5f + camera_filter_offset(cam, jv);
    }
    out->jx = ju, out->jy = jv;
    out->time01 = time01;
    if (!cam->uses_lens && !cam->moving) {
        camera_ray(cam, fx, fy, &out->o, &out->d); /* the pinhole, bit for bit */
        return;
    }
    struct camera_pose pose;
    camera_pose_at(cam, camera_shutter_time(cam, frame, out->time01), &pose);
    float lu = 0.0f, lv = 0.0f;
    if (cam->uses_lens)
        sampler_get_2d(smp, DIM_LENS_U, &lu, &lv);
    camera_ray_lens(cam, &pose, fx, fy, lu, lv, &out->o, &out->d);
}

void camera_generate_general_(const struct camera *cam, const struct sampler *smp, uint32_t frame, uint32_t px,
                              uint32_t py, struct camera_sample *out)
{
    float ju, jv;
    sampler_get_2d(smp, DIM_PIXEL_X, &ju, &jv);
    generate_at(cam, smp, frame, px, py, ju, jv,
                cam->uses_time ? camera_shutter_warp(cam, sampler_get(smp, DIM_TIME)) : 0.0f, out);
}

/* u + s modulo 1, for u and s in [0, 1): in [0, 1) (a sum that rounds to 1 wraps to 0). */
static float wrap01(float u, float s)
{
    float v = u + s;
    return v >= 1.0f ? v - 1.0f : v;
}

void camera_generate_shifted(const struct camera *cam, const struct sampler *smp, uint32_t frame, uint32_t px,
                             uint32_t py, const struct camera_sample *base, float su, float sv, struct camera_sample *out)
{
    generate_at(cam, smp, frame, px, py, wrap01(base->jx, su), wrap01(base->jy, sv), base->time01, out);
}
