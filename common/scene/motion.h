/* Keyframed rigid motion and deformation frames, evaluated at a time in frames, and the
 * Embree time steps that represent them across one frame's shutter interval. Pure
 * functions of the scene's keys: master and workers derive the same steps. Callers:
 * scene_json.c (quaternions from axis and angle), accel.c (steps), integrator.c (hits). */
#ifndef BRUME_MOTION_H
#define BRUME_MOTION_H
#include <stdint.h>
#include "base/vec.h"

#define MOTION_MAX_SEGMENTS 64  /* Embree time segments per frame at most */

/* One key of rigid motion, in frames. The key's transform is T R S (scale, then rotation,
 * then translation) applied after the object's static "transform"; between keys scale and
 * translation interpolate linearly and the rotation by slerp along the shorter arc. */
struct motion_key {
    float time;
    vec3 scale;         /* > 0 per axis (no mirrors: the winding stays meaningful) */
    float quat[4];      /* unit quaternion (r, i, j, k) */
    vec3 translate;
};

/* 0 if the keys are usable: n == 0, or keys non-NULL with finite, strictly increasing
 * times, finite scales > 0, finite translations and unit quaternions (to 1e-3). */
int motion_keys_check(const struct motion_key *keys, uint32_t n);
/* Unit quaternion (r, i, j, k) of a right-handed rotation about a unit axis. */
void motion_quat_from_axis_angle(vec3 axis, double degrees, float q[4]);
/* The key at time t: linear scale and translation, slerp (shorter arc) rotation; clamped
 * to the first and last key outside their range. */
void motion_key_at(const struct motion_key *keys, uint32_t n, double t, struct motion_key *out);
/* 1 if no key that affects [t0, t1] differs from another (or t1 <= t0): still. */
int motion_keys_still(const struct motion_key *keys, uint32_t n, double t0, double t1);
/* Deformation frames: 1 if every frame affecting [t0, t1] has the same positions. */
int motion_frames_still(const float *frame_positions, const float *frame_times, uint32_t num_frames,
                        uint32_t num_vertices, double t0, double t1);
/* Vertex positions of m at time t (3 * num_vertices floats into out). */
void motion_frames_at(const float *positions, const float *frame_positions, const float *frame_times,
                      uint32_t num_frames, uint32_t num_vertices, double t, float *out);
/* Embree time steps (>= 2) for [t0, t1] (t1 > t0) given key times: 2 when no key lies
 * inside, else the fewest uniform steps that land on every inner key (to 1e-4 of the
 * interval), at most MOTION_MAX_SEGMENTS + 1 (then inner keys are approximated). */
uint32_t motion_step_count(const float *times, size_t stride_bytes, uint32_t n, double t0, double t1);

/* Inverse of an invertible affine transform; normals transform with motion_xform_normal
 * (the cofactor matrix: inverse transpose times det, so orientation is kept for det > 0). */
struct xform motion_xform_inverse(const struct xform *t);
/* Determinant of the linear part (the volume scale). */
double motion_xform_det(const struct xform *t);
vec3 motion_xform_normal(const struct xform *t, vec3 n);

#endif
