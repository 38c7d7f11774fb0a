/* The flat scene: what a job renders, after parsing and with every transform applied
 * (all positions in the render frame: world space minus scene.origin). Owned by the job;
 * read-only while tiles render.
 * Built by scene_json.c (from scene.json and its OBJ/MTL assets); consumed by accel.c,
 * light.c, camera.c and integrator.c on both master and worker. */
#ifndef BRUME_SCENE_H
#define BRUME_SCENE_H
#include <stddef.h>
#include <stdint.h>
#include "base/vec.h"
#include "scene/motion.h"
#include "scene/scene_limits.h"

struct scene_media;

/* Mirror, conductor and dielectric are delta BSDFs when smooth (alpha below
 * MICROFACET_SMOOTH_ALPHA, microfacet.h: no light sampling at their vertices, see
 * integrator.c) and GGX microfacet BSDFs when rough; plastic is a dielectric coat over
 * Lambert, never delta (material.c). */
enum material_type { MATERIAL_DIFFUSE, MATERIAL_MIRROR, MATERIAL_DIELECTRIC, MATERIAL_CONDUCTOR, MATERIAL_PLASTIC };

struct material {
    char name[SCENE_NAME_MAX];
    enum material_type type;
    vec3 albedo;   /* diffuse and plastic: diffuse reflectance, each channel in [0, 1] */
    vec3 emission; /* emitted radiance (W / sr / m^2), >= 0; non-zero makes the surface a light */
    vec3 reflectance;   /* mirror: reflectance per channel in [0, 1]; conductor with schlick:
                         * reflectance at normal incidence */
    vec3 transmittance; /* dielectric: tint of refracted light per channel in [0, 1] */
    float ior;          /* dielectric, plastic: index of refraction inside / outside (the side
                         * the geometric normal points to is outside) */
    float alpha_x, alpha_y; /* mirror, conductor, dielectric, plastic: GGX widths along the
                             * shading frame's axes (u_axis and its completion, material.h); 0 = smooth */
    vec3 eta, k;        /* conductor: complex index of refraction per channel */
    int schlick;        /* conductor: Schlick's Fresnel with F0 = reflectance, not eta and k */
    int sample_all;     /* GGX lobes: sample D cos (all normals), not the visible normals */
    uint32_t roughness_tex; /* microfacet types: 1 + texture index; its value r sets
                             * alpha_x = alpha_y = r^2; 0 = none */
    uint32_t albedo_tex; /* diffuse: 1 + index into scene.textures (albedo multiplies it); 0 = none */
    uint32_t bump_tex;   /* any type: 1 + index of a height texture perturbing the shading normal; 0 = none */
    float bump_scale;    /* height units per texture value (in scene units) */
    uint32_t normal_tex; /* any type: 1 + index of a tangent-space normal map (RGB = 2 n - 1); 0 = none */
    vec3 u_axis;         /* anisotropic lobes: the surface's u direction at the hit shaded (set on a
                          * per-hit copy, material_with_axis); zero in the scene: the arbitrary frame */
};

/* A triangle mesh in the render frame. normals and uvs are per vertex and may be NULL. */
struct mesh {
    char name[SCENE_NAME_MAX];
    uint32_t num_vertices, num_triangles;
    float *positions;       /* 3 * num_vertices */
    float *normals;         /* 3 * num_vertices, or NULL */
    float *uvs;             /* 2 * num_vertices, or NULL */
    uint32_t *indices;      /* 3 * num_triangles, each < num_vertices */
    uint32_t *material_ids; /* num_triangles, each < scene.num_materials */
    /* Motion, both optional. keys: rigid motion (num_keys >= 1, increasing times).
     * frame_positions: deformation, num_frames >= 2 vertex sets of the same topology
     * (3 * num_vertices floats each, frame 0 equal to positions) at increasing
     * frame_times; positions then holds frame 0. */
    struct motion_key *keys;
    uint32_t num_keys;
    uint32_t num_frames;
    float *frame_positions;
    float *frame_times;
};

struct sphere {
    char name[SCENE_NAME_MAX];
    vec3 center;
    float radius;
    uint32_t material_id;
    struct motion_key *keys;    /* rigid motion as for meshes, or NULL */
    uint32_t num_keys;
};

enum light_type { LIGHT_POINT, LIGHT_SPOT };

struct light {
    enum light_type type;
    vec3 position;
    vec3 intensity; /* radiant intensity (W / sr) per channel; a spot's on its axis */
    vec3 direction; /* spot: unit axis */
    float cos_outer, cos_inner; /* spot: no light beyond the outer cone, full inside the inner
                                 * one, a smoothstep in between (light.c) */
};

#define CAMERA_MAX_KEYFRAMES 64
#define CAMERA_MAX_BLADES 64

/* One camera pose at a time in frames (fractional allowed). */
struct camera_keyframe {
    float time;
    vec3 position, look_at, up;
};

/* camera.motion_blur: "sampled" draws one time per camera ray; "analytic" computes the
 * visible surfaces over the shutter per ray and shades each (render/motion_vis.h). */
enum motion_blur { MOTION_BLUR_SAMPLED, MOTION_BLUR_ANALYTIC };

/* Camera as described; camera.c turns it into a ray generator. aperture 0 = pinhole. */
struct camera_desc {
    vec3 position, look_at, up;
    float fov_y_deg;
    float aperture_radius;  /* lens radius in scene units; 0 = pinhole */
    float focus_distance;   /* along the view direction; 0 = distance to look_at */
    /* Shutter interval in frames, relative to the frame's time; open == close means no
     * motion blur (and no time dimension is consumed). */
    float shutter_open, shutter_close;
    float shutter_ramp;     /* trapezoid shutter: open/close ramp fraction in [0, 0.5]; 0 = box */
    uint32_t motion_blur;   /* enum motion_blur: how camera rays see moving geometry */
    uint32_t blades;        /* polygonal aperture with this many blades (>= 3); 0 = circle */
    float blade_rotation_deg;
    int has_focus_point;    /* focus on the plane through focus_point (overrides focus_distance) */
    vec3 focus_point;
    uint32_t num_keyframes; /* 0 = still camera at position / look_at / up; else sorted by time */
    struct camera_keyframe keyframes[CAMERA_MAX_KEYFRAMES];
    /* Pixel reconstruction filter (render.filter), applied by filter importance sampling:
     * the pixel sample is moved by the filter's inverse CDF (camera.c). width: the
     * filter's width in pixels (box: 1; gaussian, blackman-harris: as Cycles counts it). */
    uint32_t filter;        /* enum pixel_filter */
    float filter_width;
};

enum pixel_filter { FILTER_BOX, FILTER_GAUSSIAN, FILTER_BLACKMAN_HARRIS, FILTER_COUNT_ };
#define SCENE_FILTER_MIN_WIDTH 0.25f
#define SCENE_FILTER_MAX_WIDTH 16.0f
#define SCENE_FILTER_DEFAULT_WIDTH 1.5f /* Cycles' default */

/* How the sample dimensions of a pixel are generated (sampler.h). */
enum sampler_type { SAMPLER_INDEPENDENT, SAMPLER_STRATIFIED, SAMPLER_SOBOL, SAMPLER_COUNT_ };
/* Chosen by measurement (scripts/bench_sampling.sh on scenes/dof_motion): lowest RMSE at
 * equal time (0.67x independent's at 64 spp against stratified's 0.73x) and the steepest
 * convergence (slope -0.60 against -0.59). */
#define SCENE_DEFAULT_SAMPLER SAMPLER_SOBOL

#define SCENE_MAX_PASSES 1024u

/* Embree's kernels (instruction set) for every ray query of a job, the same on every worker
 * and in the master's photon pass: Embree's kernels for different instruction sets give
 * different hits in the last bits (their reciprocals differ), so a cluster mixing CPUs
 * would render different pixels per tile (docs/cluster.md). The zero value is the default,
 * AVX2 (x86-64-v3). Names: render/accel.h. */
enum embree_isa { EMBREE_ISA_AVX2, EMBREE_ISA_SSE42, EMBREE_ISA_AVX512, EMBREE_ISA_COUNT_ };

/* Arbitrary output variables (render.aovs), written next to the beauty (render/tile.h
 * gives their channels): the first hit's camera distance, world shading normal, albedo
 * of the first non-specular hit, world position, object and material ids. */
enum aov { AOV_Z, AOV_N, AOV_ALBEDO, AOV_P, AOV_ID_OBJECT, AOV_ID_MATERIAL, AOV_COUNT_ };
#define AOV_ALL ((1u << AOV_COUNT_) - 1u)

struct render_settings {
    uint32_t width, height;
    uint32_t spp;
    uint32_t max_depth;     /* path vertices after the camera; 1 = direct light only */
    uint64_t seed;
    uint32_t tile_size;     /* square tiles of tile_size pixels; edge tiles are clipped */
    enum sampler_type sampler;
    uint32_t passes;        /* render.passes (1..SCENE_MAX_PASSES): passes (docs/media.md, docs/adaptive.md); 0 = default */
    float target_error;     /* render.target_error: adaptive to this relRMSE (docs/adaptive.md); 0 = none */
    float pixel_error;      /* render.pixel_error: adaptive until every pixel's relative error is this (docs/adaptive.md); 0 = none */
    float time_limit;       /* render.time_limit: seconds, adaptive, stops at a round boundary; 0 = none */
    uint32_t aovs;          /* render.aovs: bit set of enum aov (render/tile.h); 0 = beauty only */
    enum embree_isa embree_isa; /* the job's Embree kernels (--embree-isa); not in the scene file */
};

struct texture; /* texture.h */
struct environment; /* envmap.h */

struct scene {
    /* World position of the render frame's (0, 0, 0): the camera's position (its first
     * key's if it moves), read in double. Every position below (vertices, centres, lights,
     * the camera, key translations, grids) is stored relative to it, rounded to float once,
     * so precision is relative to the camera wherever the scene lies. Directions and sizes
     * are unchanged. Only for reporting: rendering never needs it. */
    double origin[3];
    struct camera_desc camera;
    struct render_settings settings;
    struct material *materials;
    uint32_t num_materials;
    struct mesh *meshes;
    uint32_t num_meshes;
    struct sphere *spheres;
    uint32_t num_spheres;
    struct light *lights;
    uint32_t num_lights;
    struct scene_media *media;  /* participating media (medium.h); NULL when the scene has none */
    struct texture *textures;   /* texture.h; referenced by materials */
    uint32_t num_textures;
    struct environment *env;    /* envmap.h: the environment light, or NULL */
    uint32_t frame_files;       /* files named per frame (a run of '#'): parsed again each frame */
    char **frame_patterns;      /* their names as written ("smoke.####.nvdb"), frame_files of them */
};

/* Frees everything the scene owns and zeroes it. Safe on a zeroed scene. */
void scene_fini(struct scene *scene);

/* Appends a material / mesh / sphere / light and returns its index. The scene takes
 * ownership of a mesh's arrays. */
uint32_t scene_add_material(struct scene *scene, const struct material *m);
uint32_t scene_add_mesh(struct scene *scene, const struct mesh *m);
uint32_t scene_add_sphere(struct scene *scene, const struct sphere *s);
uint32_t scene_add_light(struct scene *scene, const struct light *l);
/* Takes ownership of the texture's image. */
uint32_t scene_add_texture(struct scene *scene, const struct texture *t);

/* Checks invariants (indices in range, finite numbers, sizes within limits); on failure
 * writes one line into err and returns -1. Run on every scene before rendering. */
int scene_validate(const struct scene *scene, char *err, size_t errlen);

#endif
