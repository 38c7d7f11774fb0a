#define CAMERA_FILTER_TABLE 256

/* Thin-lens camera with a shutter and keyframed motion: turns a continuous film position
 * (pixels, origin top-left, y down), a lens sample and a time sample into a world-space
 * ray. Built once per job from the scene's camera_desc; read-only afterwards. Aperture 0
 * is exactly the pinhole camera and consumes no lens dimensions; a closed shutter or a
 * still scene consumes no time dimension. Callers: integrator.c, tests. */
#ifndef BRUME_CAMERA_H
#define BRUME_CAMERA_H
#include "scene/sampler.h"
#include "scene/scene.h"
#include "base/vec.h"

/* Camera frame at one time. focus: distance of the focal plane along forward. */
struct camera_pose {
    vec3 origin;
    vec3 forward, right, up;   /* orthonormal; right-handed with forward into the scene */
    float focus;
};

struct camera {
    struct camera_pose still;  /* the pose when there are no keyframes */
    vec3 origin;               /* == still.origin (kept for older callers) */
    vec3 forward, right, up;
    float tan_half_fov_y;
    float aspect;              /* width / height */
    float width, height;
    float lens_radius;         /* 0 = pinhole */
    uint32_t blades;           /* 0 = circular aperture */
    float blade_x[CAMERA_MAX_BLADES + 1], blade_y[CAMERA_MAX_BLADES + 1]; /* unit polygon, closed */
    int has_focus_point;
    vec3 focus_point;
    float focus_distance;      /* as given (0 = distance to look_at) */
    float shutter_open, shutter_close, shutter_ramp;
    int uses_lens;             /* lens dimensions are consumed */
    int moving;                /* keyframes that differ: pose depends on time */
    int uses_time;             /* the time dimension is consumed */
    uint32_t num_keys;
    float key_time[CAMERA_MAX_KEYFRAMES];
    vec3 key_pos[CAMERA_MAX_KEYFRAMES];
    float key_rot[CAMERA_MAX_KEYFRAMES][4];   /* unit quaternion (x, y, z, w) of (right, up, -forward) */
    float key_dist[CAMERA_MAX_KEYFRAMES];     /* |look_at - position| */
    /* Pixel filter (filter importance sampling): 0 = box; else the 1D CDF of the
     * separable filter over [-filter_radius, filter_radius] at CAMERA_FILTER_TABLE + 1
     * evenly spaced offsets, inverted piecewise-linearly (a piecewise-constant pdf). */
    uint32_t filter;           /* enum pixel_filter */
    float filter_radius;       /* pixels */
    float filter_footprint;    /* the filter's standard deviation over the box's (>= 1): texture footprints scale by it */
    float filter_cdf[CAMERA_FILTER_TABLE + 1];
};

/* What a camera ray carries: origin, unit direction, and its time as a fraction of the
 * shutter interval (after the shutter curve; give it to motion-blurred geometry; in
 * frames: camera_shutter_time). */
struct camera_sample {
    vec3 o, d;
    float time01;
    float jx, jy;   /* the sample's position in its pixel, [0, 1)^2 (pixel jitter) */
};

void camera_init(struct camera *cam, const struct camera_desc *desc, uint32_t width, uint32_t height);
/* Objects move: the time dimension is then consumed whenever the shutter is open. Call
 * after camera_init when the scene has moving geometry. */
void camera_set_scene_motion(struct camera *cam, int objects_move);

/* The direction of pose p through film point (fx, fy) in pixels, not normalised. */
static inline vec3 camera_film_dir(const struct camera *cam, const struct camera_pose *p, float fx, float fy)
{
    float sx = (2.0f * fx / cam->width - 1.0f) * cam->aspect * cam->tan_half_fov_y;
    float sy = (1.0f - 2.0f * fy / cam->height) * cam->tan_half_fov_y;
    return v3_add(p->forward, v3_add(v3_scale(p->right, sx), v3_scale(p->up, sy)));
}
/* Pinhole ray of the still pose through film point (fx, fy) in pixels; direction normalised. */
static inline void camera_ray(const struct camera *cam, float fx, float fy, vec3 *origin, vec3 *dir)
{
    *origin = cam->still.origin;
    *dir = v3_normalize(camera_film_dir(cam, &cam->still, fx, fy));
}
/* Thin-lens ray at a pose; (lu, lv) in [0,1)^2 is the lens sample (ignored at aperture 0). */
void camera_ray_lens(const struct camera *cam, const struct camera_pose *pose, float fx, float fy, float lu, float lv,
                     vec3 *origin, vec3 *dir);
/* Point on the aperture (in lens-plane units, scene units) for a sample in [0,1)^2. */
void camera_lens_point(const struct camera *cam, float lu, float lv, float *x, float *y);
/* Pose at absolute time t (frames). */
void camera_pose_at(const struct camera *cam, double t, struct camera_pose *pose);
/* Shutter curve: maps a uniform u to time01 in [0, 1]. */
float camera_shutter_warp(const struct camera *cam, float u);
/* The absolute time (frames) of time01 of frame `frame`'s shutter, for camera_pose_at:
 * computed only where a pose can depend on it. */
static inline double camera_shutter_time(const struct camera *cam, uint32_t frame, float time01)
{
    return (double)frame + cam->shutter_open + (double)time01 * (cam->shutter_close - cam->shutter_open);
}

/* The 1D filter's value at offset x (pixels) from the pixel centre, unnormalised, as
 * Cycles defines it: gaussian exp(-2 (6 x / W)^2) over |x| <= W / 2 with W = 3 width;
 * blackman-harris the 4-term window over W = 2 width; box 1 over |x| <= 1/2. */
double camera_filter_eval(uint32_t filter, float width, double x);
/* A uniform u in [0, 1) to a pixel offset from the pixel centre, distributed as the
 * filter (the box: u - 1/2). */
float camera_filter_offset(const struct camera *cam, float u);

/* The camera ray for sample smp of pixel (px, py) in frame `frame`: pixel jitter (through
 * the pixel filter), lens and time from the sampler's fixed dimensions. Inline for a still
 * pinhole with the box filter and no time (one per camera sample); the rest in camera.c. */
void camera_generate_general_(const struct camera *cam, const struct sampler *smp, uint32_t frame, uint32_t px,
                              uint32_t py, struct camera_sample *out);
/* Sample base's camera ray (made by camera_generate from smp) with its pixel jitter moved by
 * (su, sv) in [0, 1)^2 modulo 1, its lens sample and time (base->time01) unchanged: uniform
 * over the pixel as the jitter is, so any function of the ray has the same expectation;
 * shifts on a lattice give stratified rays around one sample. */
void camera_generate_shifted(const struct camera *cam, const struct sampler *smp, uint32_t frame, uint32_t px,
                             uint32_t py, const struct camera_sample *base, float su, float sv, struct camera_sample *out);
static inline void camera_generate(const struct camera *cam, const struct sampler *smp, uint32_t frame, uint32_t px,
                                   uint32_t py, struct camera_sample *out)
{
    if (cam->filter != FILTER_BOX || cam->uses_time || cam->uses_lens || cam->moving) {
        camera_generate_general_(cam, smp, frame, px, py, out);
        return;
    }
    float ju, jv;
    sampler_get_2d(smp, DIM_PIXEL_X, &ju, &jv);
    out->jx = ju, out->jy = jv;
    out->time01 = 0.0f;
    camera_ray(cam, (float)px + ju, (float)py + jv, &out->o, &out->d);
}

#endif
