/* Flat scene container: growth helpers, validation and freeing (see scene.h). */
#include "scene/scene.h"
#include "base/log.h"
#include "scene/medium.h"
#include "scene/motion.h"
#include "scene/texture.h"
#include "scene/envmap.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

void scene_fini(struct scene *scene)
{
    for (uint32_t i = 0; i < scene->num_meshes; i++) {
        struct mesh *m = &scene->meshes[i];
        free(m->positions);
        free(m->normals);
        free(m->uvs);
        free(m->indices);
        free(m->material_ids);
        free(m->keys);
        free(m->frame_positions);
        free(m->frame_times);
    }
    for (uint32_t i = 0; i < scene->num_spheres; i++)
        free(scene->spheres[i].keys);
    free(scene->meshes);
    free(scene->materials);
    free(scene->spheres);
    free(scene->lights);
    media_scene_free(&scene->media);
    for (uint32_t i = 0; i < scene->num_textures; i++)
        texture_fini(&scene->textures[i]);
    free(scene->textures);
    envmap_free(&scene->env);
    for (uint32_t i = 0; i < scene->frame_files; i++)
        free(scene->frame_patterns[i]);
    free(scene->frame_patterns);
    memset(scene, 0, sizeof *scene);
}

/* Arrays grow to powers of two; the count doubles as the capacity check. */
static void *grow(void *array, uint32_t count, size_t elem)
{
    if (count == 0 || (count & (count - 1)) == 0)
        return mem_realloc(array, (size_t)(count ? count * 2 : 4) * elem);
    return array;
}

uint32_t scene_add_material(struct scene *s, const struct material *m)
{
    s->materials = grow(s->materials, s->num_materials, sizeof *m);
    s->materials[s->num_materials] = *m;
    return s->num_materials++;
}

uint32_t scene_add_mesh(struct scene *s, const struct mesh *m)
{
    s->meshes = grow(s->meshes, s->num_meshes, sizeof *m);
    s->meshes[s->num_meshes] = *m;
    return s->num_meshes++;
}

uint32_t scene_add_sphere(struct scene *s, const struct sphere *sp)
{
    s->spheres = grow(s->spheres, s->num_spheres, sizeof *sp);
    s->spheres[s->num_spheres] = *sp;
    return s->num_spheres++;
}

uint32_t scene_add_texture(struct scene *s, const struct texture *t)
{
    s->textures = grow(s->textures, s->num_textures, sizeof *t);
    s->textures[s->num_textures] = *t;
    return s->num_textures++;
}

uint32_t scene_add_light(struct scene *s, const struct light *l)
{
    s->lights = grow(s->lights, s->num_lights, sizeof *l);
    s->lights[s->num_lights] = *l;
    return s->num_lights++;
}

static int finite3(vec3 v) { return v3_is_finite(v); }

static int nonneg3(vec3 v, float hi)
{
    return v3_is_finite(v) && v.x >= 0 && v.y >= 0 && v.z >= 0 && v.x <= hi && v.y <= hi && v.z <= hi;
}

static int media_validate(const struct scene *s, char *err, size_t errlen)
{
    const struct scene_media *m = s->media;
    if (!m)
        return 0;
    for (uint32_t i = 0; i < m->num_media; i++) {
        const struct medium *md = &m->media[i];
        if (!nonneg3(md->sigma_a, 1e30f) || !nonneg3(md->sigma_s, 1e30f) || !nonneg3(md->emission, 1e30f) ||
            !(md->g > -1.0f && md->g < 1.0f)) {
            str_fmt(err, errlen, "medium \"%s\": coefficients must be in [0, 1e30] and g in (-1, 1)", md->name);
            return -1;
        }
    }
    if (m->fog != MEDIUM_NONE && m->fog >= m->num_media) {
        str_fmt(err, errlen, "fog medium index out of range");
        return -1;
    }
    for (uint32_t i = 0; i < m->num_mesh_medium; i++)
        if (m->mesh_medium[i] != MEDIUM_NONE && (m->mesh_medium[i] >= m->num_media || i >= s->num_meshes)) {
            str_fmt(err, errlen, "mesh medium out of range");
            return -1;
        }
    for (uint32_t i = 0; i < m->num_sphere_medium; i++)
        if (m->sphere_medium[i] != MEDIUM_NONE && (m->sphere_medium[i] >= m->num_media || i >= s->num_spheres)) {
            str_fmt(err, errlen, "sphere medium out of range");
            return -1;
        }
    if (m->interface_material != UINT32_MAX && m->interface_material >= s->num_materials) {
        str_fmt(err, errlen, "interface material out of range");
        return -1;
    }
    if ((unsigned)m->method >= MEDIA_METHOD_COUNT_ || !(m->step >= 0.0f) || !isfinite(m->step) ||
        !(m->radius >= 0.0f) || !isfinite(m->radius) || !(m->skip_bound >= 0.0f && m->skip_bound <= 1.0f) ||
        m->photons > (1ull << 32) || m->max_photon_depth > 1024) {
        str_fmt(err, errlen, "volume settings out of range");
        return -1;
    }
    return 0;
}

int scene_validate(const struct scene *s, char *err, size_t errlen)
{
    const struct render_settings *r = &s->settings;
    if (r->width < 1 || r->height < 1 || r->width > SCENE_MAX_DIM || r->height > SCENE_MAX_DIM) {
        str_fmt(err, errlen, "resolution %ux%u out of range 1..%d", r->width, r->height, SCENE_MAX_DIM);
        return -1;
    }
    if (r->spp < 1 || r->spp > SCENE_MAX_SPP) {
        str_fmt(err, errlen, "spp %u out of range 1..%d", r->spp, SCENE_MAX_SPP);
        return -1;
    }
    if (r->max_depth < 1 || r->max_depth > SCENE_MAX_DEPTH) {
        str_fmt(err, errlen, "max_depth %u out of range 1..%d", r->max_depth, SCENE_MAX_DEPTH);
        return -1;
    }
    if (r->tile_size < 8 || r->tile_size > 1024) {
        str_fmt(err, errlen, "tile size %u out of range 8..1024", r->tile_size);
        return -1;
    }
    const struct camera_desc *c = &s->camera;
    if (!finite3(c->position) || !finite3(c->look_at) || !finite3(c->up) ||
        !(c->fov_y_deg > 0.0f && c->fov_y_deg < 180.0f)) {
        str_fmt(err, errlen, "camera: non-finite vectors or fov_y outside (0, 180)");
        return -1;
    }
    vec3 fwd = v3_sub(c->look_at, c->position);
    if (v3_length_rescaled(fwd) == 0.0f || v3_length(v3_cross(v3_normalize(fwd), v3_normalize(c->up))) == 0.0f) {
        str_fmt(err, errlen, "camera: look_at equals position or up is parallel to the view direction");
        return -1;
    }
    for (uint32_t i = 0; i < s->num_textures; i++) {
        const struct texture *t = &s->textures[i];
        if (!(t->max_aniso >= 1.0f && t->max_aniso <= TEXTURE_MAX_ANISO) || !isfinite(t->scale[0]) ||
            !isfinite(t->scale[1]) || !isfinite(t->offset[0]) || !isfinite(t->offset[1]) ||
            (unsigned)t->filter >= TEXFILTER_COUNT_ || !finite3(t->color0) || !finite3(t->color1) ||
            (t->type == TEXTURE_IMAGE &&
             tex_image_bytes(t->image.width, t->image.height, t->image.channels, t->image.format) == 0)) {
            str_fmt(err, errlen, "texture \"%s\": invalid parameters or image", t->name);
            return -1;
        }
    }
    for (uint32_t i = 0; i < s->num_materials; i++) {
        const struct material *m = &s->materials[i];
        if (!finite3(m->albedo) || !finite3(m->emission) || m->albedo.x < 0 || m->albedo.y < 0 ||
            m->albedo.z < 0 || m->albedo.x > 1 || m->albedo.y > 1 || m->albedo.z > 1 ||
            m->emission.x < 0 || m->emission.y < 0 || m->emission.z < 0) {
            str_fmt(err, errlen, "material \"%s\": albedo must be in [0,1] and emission >= 0", m->name);
            return -1;
        }
        if (m->albedo_tex > s->num_textures || m->bump_tex > s->num_textures || m->normal_tex > s->num_textures ||
            !isfinite(m->bump_scale)) {
            str_fmt(err, errlen, "material \"%s\": texture index out of range", m->name);
            return -1;
        }
        if (m->roughness_tex > s->num_textures || !(m->alpha_x >= 0.0f && m->alpha_x <= 1.0f) ||
            !(m->alpha_y >= 0.0f && m->alpha_y <= 1.0f) || !finite3(m->eta) || !finite3(m->k)) {
            str_fmt(err, errlen, "material \"%s\": roughness must be in [0, 1], eta and k finite", m->name);
            return -1;
        }
        if ((m->type == MATERIAL_DIELECTRIC || m->type == MATERIAL_PLASTIC) && !(m->ior > 0.0f && isfinite(m->ior))) {
            str_fmt(err, errlen, "material \"%s\": ior must be > 0 and finite", m->name);
            return -1;
        }
    }
    for (uint32_t i = 0; i < s->num_meshes; i++) {
        const struct mesh *m = &s->meshes[i];
        for (size_t k = 0; k < 3 * (size_t)m->num_vertices; k++)
            if (!isfinite(m->positions[k])) {
                str_fmt(err, errlen, "mesh \"%s\": non-finite vertex position", m->name);
                return -1;
            }
        for (size_t k = 0; k < 3 * (size_t)m->num_triangles; k++)
            if (m->indices[k] >= m->num_vertices) {
                str_fmt(err, errlen, "mesh \"%s\": vertex index out of range", m->name);
                return -1;
            }
        for (size_t k = 0; k < m->num_triangles; k++)
            if (m->material_ids[k] >= s->num_materials) {
                str_fmt(err, errlen, "mesh \"%s\": material index out of range", m->name);
                return -1;
            }
        if (motion_keys_check(m->keys, m->num_keys) != 0) {
            str_fmt(err, errlen, "mesh \"%s\": keyframes need increasing finite times, scales > 0 and unit quaternions", m->name);
            return -1;
        }
        if (m->num_frames == 1 || (m->num_frames > 1 && (!m->frame_positions || !m->frame_times))) {
            str_fmt(err, errlen, "mesh \"%s\": deformation needs at least two frames", m->name);
            return -1;
        }
        for (uint32_t k = 0; k < m->num_frames; k++)
            if (!isfinite(m->frame_times[k]) || (k > 0 && !(m->frame_times[k] > m->frame_times[k - 1]))) {
                str_fmt(err, errlen, "mesh \"%s\": frame times must be finite and increasing", m->name);
                return -1;
            }
        for (size_t k = 0; k < 3 * (size_t)m->num_vertices * m->num_frames; k++)
            if (!isfinite(m->frame_positions[k])) {
                str_fmt(err, errlen, "mesh \"%s\": non-finite vertex position in a deformation frame", m->name);
                return -1;
            }
    }
    for (uint32_t i = 0; i < s->num_spheres; i++) {
        const struct sphere *sp = &s->spheres[i];
        if (!finite3(sp->center) || !(sp->radius > 0.0f) || !isfinite(sp->radius) ||
            sp->material_id >= s->num_materials) {
            str_fmt(err, errlen, "sphere \"%s\": needs a finite center, radius > 0 and a material", sp->name);
            return -1;
        }
        if (motion_keys_check(sp->keys, sp->num_keys) != 0) {
            str_fmt(err, errlen, "sphere \"%s\": keyframes need increasing finite times, scales > 0 and unit quaternions", sp->name);
            return -1;
        }
    }
    for (uint32_t i = 0; i < s->num_lights; i++) {
        const struct light *l = &s->lights[i];
        if (!finite3(l->position) || !finite3(l->intensity) || l->intensity.x < 0 ||
            l->intensity.y < 0 || l->intensity.z < 0) {
            str_fmt(err, errlen, "light %u: needs a finite position and intensity >= 0", i);
            return -1;
        }
        if (l->type == LIGHT_SPOT && (!finite3(l->direction) || fabsf(v3_length(l->direction) - 1.0f) > 1e-3f ||
                                      !(l->cos_outer >= -1.0f && l->cos_outer < l->cos_inner && l->cos_inner <= 1.0f))) {
            str_fmt(err, errlen, "light %u: a spot needs a unit direction and cos_outer < cos_inner", i);
            return -1;
        }
    }
    return media_validate(s, err, errlen);
}
