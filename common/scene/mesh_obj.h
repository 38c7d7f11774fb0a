/* Wavefront OBJ + MTL reader: one OBJ file becomes one world-space triangle mesh in the
 * flat scene, its MTL materials become scene materials. Hand-written and bounded (no
 * count above MESH_OBJ_MAX_ELEMENTS), safe on arbitrary bytes; every error is one line
 * "file:line:col: message". Called by scene_json.c; fuzzed by tests/fuzz/fuzz_mesh_obj.c. */
#ifndef BRUME_MESH_OBJ_H
#define BRUME_MESH_OBJ_H
#include <stddef.h>
#include <stdint.h>
#include "base/asset.h"
#include "scene/scene.h"
#include "base/vec.h"

#define MESH_OBJ_MAX_ELEMENTS (1u << 28) /* vertices, normals, uvs, face corners, triangles */
#define MESH_OBJ_NO_OVERRIDE UINT32_MAX

/* MTL files already turned into scene materials during one scene load. Two OBJs naming
 * the same MTL file share its materials; two different MTL files never share a material,
 * even when their material names are equal (scene names are "<mtl path>:<name>").
 * Zero-initialise before first use; free with mesh_obj_cache_free. */
struct mesh_obj_cache {
    struct mesh_obj_mtl *mtls;
    size_t num_mtls, cap_mtls;
    uint32_t default_material;  /* the white diffuse for faces without usemtl */
    int has_default;
};
void mesh_obj_cache_fini(struct mesh_obj_cache *cache);

struct mesh_obj_options {
    struct dxform transform;     /* object to the render frame (world minus the scene's
                                  * origin, scene.h), applied to the vertices in double;
                                  * normals get the inverse transpose, and a mirroring
                                  * transform flips the winding so the geometric normal
                                  * keeps facing the same side */
    uint32_t material_override;  /* scene material for every face, or MESH_OBJ_NO_OVERRIDE;
                                  * with an override, mtllib files are not read and usemtl
                                  * names are not checked */
    const char *display_dir;     /* prefixed to file names in messages ("" or "scenes/x/") */
    const char *mesh_name;       /* name of the mesh; NULL = the OBJ path */
};
/* Identity transform, no override, no prefix. */
struct mesh_obj_options mesh_obj_default_options(void);

/* Parses OBJ text already in memory (len bytes, need not be NUL-terminated) and appends its
 * mesh (if it has faces) and materials to scene; rel_path (relative to the scene folder)
 * names it in messages and anchors mtllib paths: MTL files are read through src relative
 * to the OBJ's folder. Returns 0, or -1 with one line in err; on failure the scene may
 * hold materials added so far, but no partial mesh. */
int mesh_obj_parse(struct scene *scene, struct mesh_obj_cache *cache, const struct asset_source *src,
                   const char *rel_path, const char *text, size_t len, const struct mesh_obj_options *opt,
                   char *err, size_t errlen);

/* A mesh given as arrays (the PLY reader's): per-vertex positions (double, as read),
 * optional normals and uvs, and polygons of face_sizes[f] corners each, their vertex
 * indices (< num_vertices, checked by the caller) in face_corners. */
struct mesh_arrays {
    double *positions;      /* 3 * num_vertices */
    float *normals, *uvs;   /* 3 / 2 * num_vertices, or NULL */
    size_t num_vertices;
    uint32_t *face_sizes;   /* >= 3 each */
    uint32_t *face_corners; /* sum of face_sizes */
    size_t num_faces;
};
/* Appends the mesh of a (polygons triangulated as OBJ faces are: fans for convex ones,
 * ear clipping otherwise; opt's transform, material override or the default grey, mesh
 * name) to scene. The arrays stay the caller's. 0, or -1 with "file: face N: why". */
int mesh_obj_from_arrays(struct scene *scene, struct mesh_obj_cache *cache, const struct mesh_arrays *a,
                         const struct mesh_obj_options *opt, const char *file, char *err, size_t errlen);

#endif
