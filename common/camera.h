/* Pinhole camera: turns a continuous film position (pixels, origin top-left, y down)
 * into a world-space ray. Built once per job from the scene's camera_desc; read-only
 * afterwards. The thin lens will take (u, v) lens samples here. */
#ifndef BRUME_CAMERA_H
#define BRUME_CAMERA_H
#include "scene.h"
#include "vec.h"

struct camera {
    vec3 origin;
    vec3 forward, right, up;   /* orthonormal; right-handed with forward into the scene */
    float tan_half_fov_y;
    float aspect;              /* width / height */
    float width, height;
};

void camera_init(struct camera *cam, const struct camera_desc *desc, uint32_t width, uint32_t height);
/* Ray through film point (fx, fy) in pixels; direction normalised. */
void camera_ray(const struct camera *cam, float fx, float fy, vec3 *origin, vec3 *dir);

#endif
