/* Textures in the path tracer (see texshade.h). Hit geometry is rebuilt in world space
 * from the scene data as surface_from_hit does (rigid instances through Embree's
 * transform at the ray's time, deforming meshes from the blended time steps). */
#include "render/texshade.h"
#include "scene/microfacet.h"
#include "base/log.h"
#include "scene/motion.h"
#include "scene/texture.h"
#include <math.h>
#include <stdlib.h>

void texshade_camera(const struct render_job *job, const struct camera_sample *cs, const struct sampler *smp,
                     struct raydiff *rd)
{
    struct camera_pose pose;
    camera_pose_at(&job->camera, camera_shutter_time(&job->camera, job->frame, cs->time01), &pose);
    uint32_t nx, ny;
    if (!sampler_pixel_cells(smp, &nx, &ny)) {
        /* No grid: an isotropic footprint of the pixel's area over spp, at the sample. */
        raydiff_camera(&job->camera, &pose, cs->d,
                       raydiff_spp_scale(job->scene->settings.spp) * job->camera.filter_footprint, rd);
        return;
    }
    /* The footprint is the sample's cell of the grid, centred on it; a pixel filter wider
     * than the box spreads the samples, and the cells, by its spread over the box's. */
    float sx = raydiff_cell_scale(nx), sy = raydiff_cell_scale(ny);
    raydiff_camera(&job->camera, &pose, cs->d, job->camera.filter_footprint, rd);
    rd->dddx = v3_scale(rd->dddx, sx);
    rd->dddy = v3_scale(rd->dddy, sy);
    raydiff_set_center(rd, cs->jx, cs->jy, nx, ny, sx, sy);
}

static vec3 vertex_at(const struct accel_motion *mo, const float *pos, uint32_t nv, uint32_t k, float time01)
{
    if (!mo || mo->num_steps <= 1 || !mo->steps) {
        const float *a = mo && mo->num_steps == 1 && mo->steps ? &mo->steps[3 * (size_t)k] : &pos[3 * (size_t)k];
        return v3(a[0], a[1], a[2]);
    }
    float ft = time01 * (float)(mo->num_steps - 1), fi = floorf(ft);
    fi = fi < 0.0f ? 0.0f : (fi > (float)(mo->num_steps - 2) ? (float)(mo->num_steps - 2) : fi);
    float f = ft - fi;
    const float *a = &mo->steps[3 * (size_t)k] + (size_t)fi * 3 * nv, *b = a + 3 * (size_t)nv;
    return v3((1.0f - f) * a[0] + f * b[0], (1.0f - f) * a[1] + f * b[1], (1.0f - f) * a[2] + f * b[2]);
}

void texshade_hit(const struct render_job *job, vec3 org, vec3 dir, const struct accel_hit *h, float time01,
                  const struct raydiff *rd, struct raydiff_hit *out)
{
    const struct scene *sc = job->scene;
    struct xform x;
    int moving = accel_object_xform(&job->accel, h->geom, h->prim, time01, &x);
    if (h->geom == job->accel.sphere_geom && sc->num_spheres > 0) {
        const struct sphere *sp = &sc->spheres[h->prim];
        vec3 p = v3_add(org, v3_scale(dir, h->t));
        vec3 c = moving ? xform_point(&x, sp->center) : sp->center;
        /* Rigid spheres may scale: the radius seen is the distance to the centre. */
        float r = moving ? v3_length(v3_sub(p, c)) : sp->radius;
        raydiff_sphere(c, r, p, rd, dir, h->t, out);
        if (moving) { /* texture coordinates stay on the object: from the object-space point */
            struct xform xi = motion_xform_inverse(&x);
            raydiff_sphere_uv(sp->center, xform_point(&xi, p), &out->tc.u, &out->tc.v);
        }
        return;
    }
    const struct mesh *m = &sc->meshes[h->geom];
    const uint32_t *idx = &m->indices[3 * h->prim];
    const struct accel_motion *mo = job->accel.mesh_motion ? &job->accel.mesh_motion[h->geom] : NULL;
    if (mo && mo->num_steps == 0)
        mo = NULL;
    vec3 p[3], nrm[3];
    float uv[3][2];
    for (int k = 0; k < 3; k++) {
        p[k] = vertex_at(mo, m->positions, m->num_vertices, idx[k], time01);
        if (moving)
            p[k] = xform_point(&x, p[k]);
        if (m->uvs) {
            uv[k][0] = m->uvs[2 * idx[k]];
            uv[k][1] = m->uvs[2 * idx[k] + 1];
        }
        if (m->normals) {
            const float *n = &m->normals[3 * idx[k]];
            nrm[k] = v3(n[0], n[1], n[2]);
            if (moving)
                nrm[k] = v3_normalize(motion_xform_normal(&x, nrm[k]));
        }
    }
    /* Deforming meshes are shaded flat (surface_from_hit): no normal derivatives there. */
    int smooth = m->normals && !mo;
    vec3 ng = v3_cross(v3_sub(p[1], p[0]), v3_sub(p[2], p[0]));
    raydiff_triangle(p, m->uvs ? (const float(*)[2])uv : NULL, smooth ? nrm : NULL, h->u, h->v, ng, rd, dir, h->t,
                     out);
}

const struct material *texshade_material(const struct render_job *job, const struct material *mat,
                                         const struct raydiff_hit *dh, struct material *buf)
{
    int albedo = mat->albedo_tex && (mat->type == MATERIAL_DIFFUSE || mat->type == MATERIAL_PLASTIC);
    if (!albedo && !mat->roughness_tex)
        return mat;
    *buf = *mat;
    if (albedo) {
        uint32_t ti = mat->albedo_tex - 1;
        vec3 c = texture_eval(&job->scene->textures[ti], job->mips ? &job->mips[ti] : NULL, &dh->tc);
        /* An albedo stays in [0, 1] whatever an HDR image holds. */
        c = v3(fminf(fmaxf(c.x, 0.0f), 1.0f), fminf(fmaxf(c.y, 0.0f), 1.0f), fminf(fmaxf(c.z, 0.0f), 1.0f));
        buf->albedo = v3_mul(mat->albedo, c);
    }
    if (mat->roughness_tex) { /* the texture's first channel is the roughness, alpha = r^2 */
        uint32_t ti = mat->roughness_tex - 1;
        vec3 c = texture_eval(&job->scene->textures[ti], job->mips ? &job->mips[ti] : NULL, &dh->tc);
        float r = fminf(fmaxf(c.x, 0.0f), 1.0f);
        buf->alpha_x = buf->alpha_y = microfacet_alpha(r);
    }
    return buf;
}

static float height_at(const struct texture *t, const struct mip *m, struct tex_coord tc)
{
    vec3 c = texture_eval(t, m, &tc);
    return (c.x + c.y + c.z) * (1.0f / 3.0f);
}

/* A tangent-space normal map: RGB in [0, 1] is 2 n - 1 in the frame (dp/du made
 * orthogonal, its completion, the normal), z along the normal. */
static vec3 normal_map(const struct scene *scene, const struct mip *mips, const struct material *mat,
                       const struct raydiff_hit *dh, vec3 N)
{
    uint32_t ti = mat->normal_tex - 1;
    vec3 c = texture_eval(&scene->textures[ti], mips ? &mips[ti] : NULL, &dh->tc);
    vec3 mt = v3(2.0f * c.x - 1.0f, 2.0f * c.y - 1.0f, 2.0f * c.z - 1.0f);
    vec3 T = v3_normalize(v3_sub(dh->dpdu, v3_scale(N, v3_dot(N, dh->dpdu))));
    vec3 B = v3_cross(N, T);
    return v3_normalize(v3_add(v3_add(v3_scale(T, mt.x), v3_scale(B, mt.y)), v3_scale(N, mt.z)));
}

vec3 texshade_bump(const struct scene *scene, const struct mip *mips, const struct material *mat,
                   const struct raydiff_hit *dh, vec3 ng, vec3 ns)
{
    if ((!mat->bump_tex && !mat->normal_tex) || !dh->has_dpduv)
        return ns;
    /* Perturb on the side dp/du x dp/dv points to, then face ns's side again. */
    vec3 c = v3_cross(dh->dpdu, dh->dpdv);
    vec3 N = v3_dot(c, ns) >= 0.0f ? ns : v3_neg(ns), nb;
    if (mat->normal_tex) {
        nb = normal_map(scene, mips, mat, dh, N);
    } else {
        uint32_t ti = mat->bump_tex - 1;
        const struct texture *t = &scene->textures[ti];
        const struct mip *m = mips ? &mips[ti] : NULL;
        /* Differences over half the footprint (a small fixed step when there is none). */
        float du = 0.5f * (fabsf(dh->tc.dudx) + fabsf(dh->tc.dudy)), dv = 0.5f * (fabsf(dh->tc.dvdx) + fabsf(dh->tc.dvdy));
        du = du > 0.0f ? du : 0.0005f;
        dv = dv > 0.0f ? dv : 0.0005f;
        struct tex_coord tc = dh->tc, tu = dh->tc, tv = dh->tc;
        tu.u += du;
        tv.v += dv;
        float h0 = height_at(t, m, tc);
        float dhdu = mat->bump_scale * (height_at(t, m, tu) - h0) / du;
        float dhdv = mat->bump_scale * (height_at(t, m, tv) - h0) / dv;
        vec3 pu = v3_add(dh->dpdu, v3_scale(N, dhdu)), pv = v3_add(dh->dpdv, v3_scale(N, dhdv));
        nb = v3_normalize(v3_cross(pu, pv));
    }
    if (v3_dot(nb, ns) < 0.0f)
        nb = v3_neg(nb);
    if (!v3_is_finite(nb) || !(v3_dot(nb, nb) > 0.5f) || !(v3_dot(nb, ng) > 0.0f))
        return ns;
    return nb;
}

void texshade_scatter(struct raydiff *rd, const struct material *mat, const struct bsdf_sample *bs, int front,
                      vec3 dir, vec3 ns, const struct raydiff_hit *dh)
{
    /* dh's normal derivatives belong to dh->n; the shading normal used may be flipped. */
    float sign = v3_dot(ns, dh->n) >= 0.0f ? 1.0f : -1.0f;
    vec3 dndx = v3_scale(dh->dndx, sign), dndy = v3_scale(dh->dndy, sign);
    if (!bs->is_delta) {
        raydiff_diffuse(rd, bs->wi, dh->dpdx, dh->dpdy);
    } else if (bs->transmitted) {
        float eta = front ? mat->ior : 1.0f / mat->ior; /* transmitted over incident */
        raydiff_refract(rd, dir, bs->wi, ns, dndx, dndy, dh->dpdx, dh->dpdy, 1.0f / eta);
    } else {
        raydiff_reflect(rd, dir, bs->wi, ns, dndx, dndy, dh->dpdx, dh->dpdy);
    }
}

const struct material *texshade_surface(const struct render_job *job, vec3 org, vec3 dir, const struct accel_hit *h,
                                        float time01, const struct raydiff *rd, struct surface *s,
                                        const struct material *mat, struct material *buf, struct raydiff_hit *dh)
{
    if (!job->textured)
        return mat;
    static const struct raydiff point; /* all zero: a point lookup */
    struct raydiff_hit local;
    if (!dh)
        dh = &local;
    texshade_hit(job, org, dir, h, time01, rd ? rd : &point, dh);
    mat = texshade_material(job, mat, dh, buf);
    s->ns = texshade_bump(job->scene, job->mips, mat, dh, s->ng, s->ns);
    return mat;
}

void texshade_cross(struct raydiff *rd, vec3 dir, float t, vec3 n)
{
    vec3 dpdx, dpdy;
    raydiff_transfer(rd, dir, t, n, &dpdx, &dpdy);
    rd->dodx = dpdx;
    rd->dody = dpdy;
}

void texshade_scatter_volume(struct raydiff *rd, vec3 dir, float t, vec3 d_out)
{
    vec3 dpdx, dpdy;
    raydiff_transfer(rd, dir, t, dir, &dpdx, &dpdy);
    raydiff_diffuse(rd, d_out, dpdx, dpdy);
}
