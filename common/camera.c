/* Pinhole camera (see camera.h). Looking down -z with +y up gives +x to the right, the
 * usual right-handed convention (matching Embree's tutorials and the Cornell box data). */
#include "camera.h"
#include <math.h>

void camera_init(struct camera *cam, const struct camera_desc *d, uint32_t width, uint32_t height)
{
    cam->origin = d->position;
    cam->forward = v3_normalize(v3_sub(d->look_at, d->position));
    cam->right = v3_normalize(v3_cross(cam->forward, d->up));
    cam->up = v3_cross(cam->right, cam->forward);
    cam->tan_half_fov_y = tanf(d->fov_y_deg * (float)M_PI / 360.0f);
    cam->width = (float)width;
    cam->height = (float)height;
    cam->aspect = (float)width / (float)height;
}

void camera_ray(const struct camera *cam, float fx, float fy, vec3 *origin, vec3 *dir)
{
    float sx = (2.0f * fx / cam->width - 1.0f) * cam->aspect * cam->tan_half_fov_y;
    float sy = (1.0f - 2.0f * fy / cam->height) * cam->tan_half_fov_y;
    vec3 d = v3_add(cam->forward, v3_add(v3_scale(cam->right, sx), v3_scale(cam->up, sy)));
    *origin = cam->origin;
    *dir = v3_normalize(d);
}
