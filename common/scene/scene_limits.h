/* Limits every part of a scene shares (name length, image size, samples, path length):
 * a header of its own, so that the parts (media, textures, motion) need not include the
 * whole scene description, which includes them. Checked by scene_json.c and scene.c. */
#ifndef BRUME_SCENE_LIMITS_H
#define BRUME_SCENE_LIMITS_H

#define SCENE_MAX_DIM 16384      /* width or height */
#define SCENE_MAX_SPP 1048576
#define SCENE_MAX_DEPTH 1024
#define SCENE_NAME_MAX 128

#endif
