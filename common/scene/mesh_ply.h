/* PLY (Stanford polygon file) reader: ascii, binary_little_endian and binary_big_endian
 * 1.0. The "vertex" element gives positions (x y z), normals (nx ny nz) and uvs (u v,
 * s t, texture_u texture_v or texture_s texture_t) of any numeric type; the "face"
 * element's list "vertex_indices" (or "vertex_index") gives polygons of any count type,
 * triangulated as OBJ faces are (mesh_obj_from_arrays). Other elements and properties
 * are read and skipped. Untrusted bytes: every count is checked against the bytes left
 * and PLY_MAX_ELEMENTS before anything is allocated, every index against the vertex
 * count; errors are one line naming the file, the element and property (and for ascii
 * the line). Hand-written because Debian packages no small C PLY reader (rply, miniply,
 * tinyply and happly are not packaged). Called by scene_json.c; fuzzed by
 * tests/fuzz/fuzz_mesh_ply.c. */
#ifndef BRUME_MESH_PLY_H
#define BRUME_MESH_PLY_H
#include <stddef.h>
#include "scene/mesh_obj.h"

#define PLY_MAX_ELEMENTS (1u << 28)   /* of one element, and face corners in all */
#define PLY_MAX_FACE_CORNERS 65535u   /* corners of one polygon */

/* Parses the PLY file in data (len bytes, need not be NUL-terminated) named rel_path and
 * appends its mesh (when it has faces) to scene, with opt's transform, material override
 * (else the default grey) and name. 0, or -1 with one line in err. */
int mesh_ply_parse(struct scene *scene, struct mesh_obj_cache *cache, const char *rel_path, const uint8_t *data,
                   size_t len, const struct mesh_obj_options *opt, char *err, size_t errlen);

#endif
