/* NanoVDB files to dense density grids (see nvdb.h). The file layout (segment header,
 * per-grid metadata and name, grid buffers) is parsed here with explicit bounds; the
 * grid's tree is read with PNanoVDB's accessors over a buffer whose every read is checked
 * (an out-of-range read returns 0 and marks the buffer, and the load then fails). The root
 * level's tile search is ours (sorted keys, binary search), so a file with many root tiles
 * cannot make each lookup linear; below the root PNanoVDB walks upper, lower and leaf nodes. */
#include "scene/nvdb.h"
#include "base/bytes.h"
#include "base/log.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* PNanoVDB in C with our own buffer: byte-addressed little-endian reads, checked. */
#define PNANOVDB_C
#define PNANOVDB_BUF_CUSTOM
typedef struct pnanovdb_buf_t {
    const uint8_t *data;
    uint64_t size;
    int *oob; /* set to 1 by any read outside [0, size) */
} pnanovdb_buf_t;

static inline uint32_t pnanovdb_buf_read_uint32(pnanovdb_buf_t buf, uint64_t byte_offset)
{
    if (buf.size < 4 || byte_offset > buf.size - 4) {
        *buf.oob = 1;
        return 0;
    }
    const uint8_t *p = buf.data + byte_offset;
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static inline uint64_t pnanovdb_buf_read_uint64(pnanovdb_buf_t buf, uint64_t byte_offset)
{
    if (buf.size < 8 || byte_offset > buf.size - 8) {
        *buf.oob = 1;
        return 0;
    }
    return (uint64_t)pnanovdb_buf_read_uint32(buf, byte_offset) |
           (uint64_t)pnanovdb_buf_read_uint32(buf, byte_offset + 4) << 32;
}

typedef uint32_t pnanovdb_grid_type_t;
/* Only ever indexed with the constant PNANOVDB_GRID_TYPE_FLOAT, never with a file's value. */
#define PNANOVDB_GRID_TYPE_GET(grid_typeIn, nameIn) pnanovdb_grid_type_constants[grid_typeIn].nameIn

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wstrict-prototypes"
#pragma GCC diagnostic ignored "-Wunused-parameter"
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wcast-qual"
#pragma GCC diagnostic ignored "-Wsign-compare"
#include <nanovdb/PNanoVDB.h>
#pragma GCC diagnostic pop

#define FT PNANOVDB_GRID_TYPE_FLOAT
#define FILE_HEADER_SIZE 16u
#define META_SIZE 176u
#define NAME_MAX_BYTES 4096u


uint64_t nvdb_max_voxels = GRID_MAX_VOXELS;

int nvdb_is_nvdb(const uint8_t *data, size_t size)
{
    return size >= 8 && memcmp(data, "NanoVDB", 7) == 0;
}

static const char *type_name(uint32_t t)
{
    static const char *const names[] = {"unknown", "float", "double", "int16", "int32", "int64", "vec3f",
                                        "vec3d", "mask", "half", "uint32", "boolean", "rgba8", "fp4",
                                        "fp8", "fp16", "fpN", "vec4f", "vec4d", "index"};
    return t < sizeof names / sizeof names[0] ? names[t] : "unknown";
}

static const char *class_name(uint32_t c)
{
    static const char *const names[] = {"unknown", "level set", "fog volume", "staggered", "point index",
                                        "point data", "topology", "voxel volume", "index grid"};
    return c < sizeof names / sizeof names[0] ? names[c] : "unknown";
}

/* A grid name from the file, safe to print: printable ASCII, at most 48 bytes shown. */
static const char *shown(const char *name, char *buf, size_t n)
{
    size_t k = 0;
    for (; name[k] && k + 4 < n && k < 48; k++)
        buf[k] = (name[k] >= 0x20 && name[k] < 0x7f && name[k] != '"') ? name[k] : '?';
    buf[k] = '\0';
    if (name[k])
        str_fmt(buf + k, n - k, "...");
    return buf;
}

struct grid_rec {
    const char *name;       /* NUL-terminated, inside the file */
    uint64_t offset, size;  /* of the grid buffer in the file */
    uint32_t type, cls;
};

/* Walks the segments; fills recs (at most max) and returns how many there are, or -1. */
static int64_t list_grids(const uint8_t *d, size_t size, struct grid_rec **recs, char *err, size_t errlen)
{
    size_t pos = 0, cap = 0;
    int64_t n = 0;
    *recs = NULL;
    while (pos < size) {
        if (size - pos < FILE_HEADER_SIZE) {
            str_fmt(err, errlen, "truncated: %zu bytes after the last grid, a segment header needs %u", size - pos,
                    FILE_HEADER_SIZE);
            goto fail;
        }
        const uint8_t *h = d + pos;
        uint64_t magic = bytes_get_u64(h);
        if (magic != PNANOVDB_MAGIC_NUMBER) {
            if (memcmp(h, "NanoVDB", 7) == 0)
                str_fmt(err, errlen, "NanoVDB magic \"%.8s\" at byte %zu: this reader reads files of NanoVDB 32.x "
                        "(magic \"NanoVDB0\")", (const char *)h, pos);
            else
                str_fmt(err, errlen, "not a NanoVDB file: no \"NanoVDB0\" segment header at byte %zu", pos);
            goto fail;
        }
        uint32_t version = bytes_get_u32(h + 8);
        uint16_t count = bytes_get_u16(h + 12), codec = bytes_get_u16(h + 14);
        if (pnanovdb_version_get_major(version) != PNANOVDB_MAJOR_VERSION_NUMBER) {
            str_fmt(err, errlen, "NanoVDB version %u.%u.%u: this reader reads major version %u", pnanovdb_version_get_major(version),
                    pnanovdb_version_get_minor(version), pnanovdb_version_get_patch(version), PNANOVDB_MAJOR_VERSION_NUMBER);
            goto fail;
        }
        if (codec != 0) {
            str_fmt(err, errlen, "grids compressed with %s are not supported: write the file uncompressed (codec NONE)",
                    codec == 1 ? "ZIP" : codec == 2 ? "BLOSC" : "an unknown codec");
            goto fail;
        }
        if (count == 0) {
            str_fmt(err, errlen, "segment at byte %zu holds no grids", pos);
            goto fail;
        }
        pos += FILE_HEADER_SIZE;
        size_t first = (size_t)n;
        for (uint32_t g = 0; g < count; g++) {
            if (size - pos < META_SIZE) {
                str_fmt(err, errlen, "truncated in the metadata of grid %lld", (long long)n);
                goto fail;
            }
            const uint8_t *m = d + pos;
            uint64_t grid_size = bytes_get_u64(m), file_size = bytes_get_u64(m + 8);
            uint32_t name_size = bytes_get_u32(m + 136);
            uint16_t mcodec = bytes_get_u16(m + 168);
            if (name_size < 1 || name_size > NAME_MAX_BYTES || size - pos - META_SIZE < name_size) {
                str_fmt(err, errlen, "grid %lld: name of %u bytes %s", (long long)n, name_size,
                        name_size < 1 || name_size > NAME_MAX_BYTES ? "out of range (1..4096)" : "runs past the end of the file");
                goto fail;
            }
            if (m[META_SIZE + name_size - 1] != 0) {
                str_fmt(err, errlen, "grid %lld: name is not NUL-terminated", (long long)n);
                goto fail;
            }
            if (mcodec != 0 || file_size != grid_size) {
                str_fmt(err, errlen, "grid %lld: stored compressed or with a size (%llu) unlike its grid's (%llu): only "
                        "uncompressed grids are supported", (long long)n, (unsigned long long)file_size,
                        (unsigned long long)grid_size);
                goto fail;
            }
            mem_grow((void **)recs, &cap, (size_t)n + 1, sizeof **recs);
            (*recs)[n].name = (const char *)m + META_SIZE;
            (*recs)[n].size = grid_size;
            (*recs)[n].type = bytes_get_u32(m + 32);
            (*recs)[n].cls = bytes_get_u32(m + 36);
            n++;
            pos += META_SIZE + name_size;
        }
        for (size_t g = first; g < (size_t)n; g++) {
            if ((*recs)[g].size > size - pos) {
                str_fmt(err, errlen, "truncated: grid %zu needs %llu bytes, the file has %zu left", g,
                        (unsigned long long)(*recs)[g].size, size - pos);
                goto fail;
            }
            (*recs)[g].offset = pos;
            pos += (*recs)[g].size;
        }
    }
    if (n == 0) {
        str_fmt(err, errlen, "empty file");
        goto fail;
    }
    return n;
fail:
    free(*recs);
    *recs = NULL;
    return -1;
}

static const struct grid_rec *choose(const struct grid_rec *r, int64_t n, const char *want, char *err, size_t errlen)
{
    char nb[64];
    for (int64_t i = 0; i < n; i++) {
        if (want ? strcmp(r[i].name, want) != 0 : r[i].type != PNANOVDB_GRID_TYPE_FLOAT)
            continue;
        if (r[i].type != PNANOVDB_GRID_TYPE_FLOAT) {
            str_fmt(err, errlen, "grid \"%s\" holds %s values: only float grids can be densities",
                    shown(r[i].name, nb, sizeof nb), type_name(r[i].type));
            return NULL;
        }
        return &r[i];
    }
    if (want)
        str_fmt(err, errlen, "no grid named \"%s\"", shown(want, nb, sizeof nb));
    else
        str_fmt(err, errlen, "no float grid");
    size_t k = strlen(err);
    for (int64_t i = 0; i < n && i < 8 && k + 1 < errlen; i++) {
        str_fmt(err + k, errlen - k, "%s\"%s\" (%s)", i ? ", " : " (grids in the file: ", shown(r[i].name, nb, sizeof nb),
                type_name(r[i].type));
        k = strlen(err);
    }
    if (k + 1 < errlen)
        str_fmt(err + k, errlen - k, "%s)", n > 8 ? ", ..." : "");
    return NULL;
}

/* Root tiles by key, for a binary search (ties keep file order, as PNanoVDB's linear search). */
struct tile_key { uint64_t key; uint32_t idx; };

static int tile_key_cmp(const void *a, const void *b)
{
    const struct tile_key *x = a, *y = b;
    if (x->key != y->key)
        return x->key < y->key ? -1 : 1;
    return x->idx < y->idx ? -1 : x->idx > y->idx;
}

/* Where the value of voxels in one 8^3 block lives: a leaf (per-voxel addresses) or one address. */
struct block {
    int leaf;
    pnanovdb_leaf_handle_t leaf_h;
    pnanovdb_address_t addr;
};

static struct block lookup_block(pnanovdb_buf_t buf, pnanovdb_root_handle_t root, const struct tile_key *keys,
                                 uint32_t ntiles, pnanovdb_coord_t ijk)
{
    struct block b = {0};
    uint64_t key = pnanovdb_coord_to_key(&ijk);
    uint32_t lo = 0, hi = ntiles;
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (keys[mid].key < key)
            lo = mid + 1;
        else
            hi = mid;
    }
    if (lo == ntiles || keys[lo].key != key) {
        b.addr = pnanovdb_address_offset(root.address, PNANOVDB_GRID_TYPE_GET(FT, root_off_background));
        return b;
    }
    pnanovdb_root_tile_handle_t tile = pnanovdb_root_get_tile(FT, root, keys[lo].idx);
    if (pnanovdb_int64_is_zero(pnanovdb_root_tile_get_child(buf, tile))) {
        b.addr = pnanovdb_root_tile_get_value_address(FT, buf, tile);
        return b;
    }
    pnanovdb_upper_handle_t upper = pnanovdb_root_get_child(FT, buf, root, tile);
    uint32_t n2 = pnanovdb_upper_coord_to_offset(&ijk);
    if (!pnanovdb_upper_get_child_mask(buf, upper, n2)) {
        b.addr = pnanovdb_upper_get_table_address(FT, buf, upper, n2);
        return b;
    }
    pnanovdb_lower_handle_t lower = pnanovdb_upper_get_child(FT, buf, upper, n2);
    uint32_t n1 = pnanovdb_lower_coord_to_offset(&ijk);
    if (!pnanovdb_lower_get_child_mask(buf, lower, n1)) {
        b.addr = pnanovdb_lower_get_table_address(FT, buf, lower, n1);
        return b;
    }
    b.leaf = 1;
    b.leaf_h = pnanovdb_lower_get_child(FT, buf, lower, n1);
    return b;
}

static int read_grid(const uint8_t *gd, uint64_t gsize, const struct grid_rec *rec, struct density_grid *out,
                     struct xform *to_world, uint64_t *negatives, char *err, size_t errlen)
{
    char nb[64];
    const char *name = shown(rec->name, nb, sizeof nb);
    int oob = 0;
    pnanovdb_buf_t buf = {gd, gsize, &oob};
    pnanovdb_grid_handle_t grid = {{0}};
    const uint64_t min_size = PNANOVDB_GRID_SIZE + PNANOVDB_TREE_SIZE + 64;
    if (gsize < min_size) {
        str_fmt(err, errlen, "grid \"%s\": %llu bytes, fewer than a grid's headers (%llu)", name,
                (unsigned long long)gsize, (unsigned long long)min_size);
        return -1;
    }
    uint32_t version = pnanovdb_grid_get_version(buf, grid);
    uint32_t gtype = pnanovdb_grid_get_grid_type(buf, grid), gclass = pnanovdb_grid_get_grid_class(buf, grid);
    uint32_t gindex = pnanovdb_grid_get_grid_index(buf, grid), gcount = pnanovdb_grid_get_grid_count(buf, grid);
    if (pnanovdb_grid_get_magic(buf, grid) != PNANOVDB_MAGIC_NUMBER) {
        str_fmt(err, errlen, "grid \"%s\": no NanoVDB magic at the start of its buffer", name);
        return -1;
    }
    if (pnanovdb_version_get_major(version) != PNANOVDB_MAJOR_VERSION_NUMBER) {
        str_fmt(err, errlen, "grid \"%s\": NanoVDB version %u.x, this reader reads %u.x", name,
                pnanovdb_version_get_major(version), PNANOVDB_MAJOR_VERSION_NUMBER);
        return -1;
    }
    if (gtype != rec->type || gtype != PNANOVDB_GRID_TYPE_FLOAT) {
        str_fmt(err, errlen, "grid \"%s\": its buffer holds %s values (metadata: %s): only float grids can be densities",
                name, type_name(gtype), type_name(rec->type));
        return -1;
    }
    if (gclass != PNANOVDB_GRID_CLASS_UNKNOWN && gclass != PNANOVDB_GRID_CLASS_FOG_VOLUME) {
        str_fmt(err, errlen, "grid \"%s\" is a %s grid: densities need a fog volume (or class unknown)", name,
                class_name(gclass));
        return -1;
    }
    if (pnanovdb_grid_get_grid_size(buf, grid) != gsize || gcount == 0 || gindex >= gcount) {
        str_fmt(err, errlen, "grid \"%s\": header inconsistent with the file (size %llu for %llu bytes, index %u of %u)",
                name, (unsigned long long)pnanovdb_grid_get_grid_size(buf, grid), (unsigned long long)gsize, gindex, gcount);
        return -1;
    }
    if (!(pnanovdb_grid_get_flags(buf, grid) & PNANOVDB_GRID_FLAGS_HAS_BBOX)) {
        str_fmt(err, errlen, "grid \"%s\" was written without its bounding box (statistics off): write it with "
                "statistics", name);
        return -1;
    }
    /* Index-to-world map: world = A ijk + b (row-major A), in double. */
    pnanovdb_map_handle_t map = pnanovdb_grid_get_map(buf, grid);
    double A[3][3], b[3];
    int finite = 1;
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) {
            A[i][j] = pnanovdb_map_get_matd(buf, map, (uint32_t)(3 * i + j));
            finite = finite && fabs(A[i][j]) <= 1e30;
        }
        b[i] = pnanovdb_map_get_vecd(buf, map, (uint32_t)i);
        finite = finite && fabs(b[i]) <= 1e30;
    }
    double det = A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) - A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0]) +
                 A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]);
    if (!finite || !isfinite(det) || det == 0.0) {
        str_fmt(err, errlen, "grid \"%s\": index-to-world map is singular or not finite", name);
        return -1;
    }
    /* Tree and root: the root and its tile table lie inside the buffer. */
    pnanovdb_tree_handle_t tree = pnanovdb_grid_get_tree(buf, grid);
    uint64_t root_off = pnanovdb_tree_get_node_offset_root(buf, tree);
    const uint64_t root_size = PNANOVDB_GRID_TYPE_GET(FT, root_size), tile_size = PNANOVDB_GRID_TYPE_GET(FT, root_tile_size);
    uint64_t root_at = PNANOVDB_GRID_SIZE + root_off;
    if (root_off > gsize || root_at > gsize || gsize - root_at < root_size) {
        str_fmt(err, errlen, "grid \"%s\": root node offset %llu outside the grid's %llu bytes", name,
                (unsigned long long)root_off, (unsigned long long)gsize);
        return -1;
    }
    pnanovdb_root_handle_t root = pnanovdb_tree_get_root(buf, tree);
    uint32_t ntiles = pnanovdb_root_get_tile_count(buf, root);
    if ((uint64_t)ntiles > (gsize - root_at - root_size) / tile_size) {
        str_fmt(err, errlen, "grid \"%s\": %u root tiles do not fit in the grid's %llu bytes", name, ntiles,
                (unsigned long long)gsize);
        return -1;
    }
    float background = pnanovdb_read_float(buf, pnanovdb_address_offset(root.address, PNANOVDB_GRID_TYPE_GET(FT, root_off_background)));
    if (!isfinite(background) || background > 0.0f) {
        str_fmt(err, errlen, "grid \"%s\": background value %g: a density grid's background must be 0", name,
                (double)background);
        return -1;
    }
    pnanovdb_coord_t bmin = pnanovdb_root_get_bbox_min(buf, root), bmax = pnanovdb_root_get_bbox_max(buf, root);
    int32_t lo[3] = {bmin.x, bmin.y, bmin.z}, hi[3] = {bmax.x, bmax.y, bmax.z};
    uint64_t n[3], total = 1;
    for (int k = 0; k < 3; k++) {
        if (lo[k] > hi[k]) {
            str_fmt(err, errlen, "grid \"%s\" has no active voxels", name);
            return -1;
        }
        if (lo[k] <= INT32_MIN + 1 || hi[k] >= INT32_MAX - 1) {
            str_fmt(err, errlen, "grid \"%s\": index bounding box reaches the limits of int32", name);
            return -1;
        }
        n[k] = (uint64_t)((int64_t)hi[k] - lo[k] + 3); /* active box plus one voxel each side */
        total *= n[k]; /* <= (2^27 + 1) * 2^33: no overflow */
        if (total > nvdb_max_voxels || total > GRID_MAX_VOXELS)
            total = (uint64_t)GRID_MAX_VOXELS + 1;
    }
    if (total > GRID_MAX_VOXELS) {
        uint64_t most = nvdb_max_voxels < GRID_MAX_VOXELS ? nvdb_max_voxels : GRID_MAX_VOXELS;
        str_fmt(err, errlen, "grid \"%s\": active box [%d %d %d]..[%d %d %d] needs %llux%llux%llu dense voxels "
                "(with a border of 1), more than %llu", name, lo[0], lo[1], lo[2], hi[0], hi[1], hi[2],
                (unsigned long long)n[0], (unsigned long long)n[1], (unsigned long long)n[2], (unsigned long long)most);
        return -1;
    }
    if (oob) {
        str_fmt(err, errlen, "grid \"%s\": truncated headers", name);
        return -1;
    }

    struct tile_key *keys = mem_alloc(sizeof *keys * (ntiles ? ntiles : 1));
    for (uint32_t t = 0; t < ntiles; t++) {
        keys[t].key = pnanovdb_root_tile_get_key(buf, pnanovdb_root_get_tile(FT, root, t));
        keys[t].idx = t;
    }
    qsort(keys, ntiles, sizeof *keys, tile_key_cmp);

    float *v = mem_alloc(sizeof(float) * total);
    uint64_t neg = 0;
    int bad = 0;
    pnanovdb_coord_t bad_at = {0, 0, 0};
    size_t at = 0;
    for (uint64_t z = 0; z < n[2] && !bad; z++)
        for (uint64_t y = 0; y < n[1] && !bad; y++) {
            struct block blk = {0};
            int32_t block_x = 0;
            int have = 0;
            for (uint64_t x = 0; x < n[0]; x++) {
                pnanovdb_coord_t ijk = {lo[0] - 1 + (int32_t)x, lo[1] - 1 + (int32_t)y, lo[2] - 1 + (int32_t)z};
                if (!have || (ijk.x & ~7) != block_x) {
                    blk = lookup_block(buf, root, keys, ntiles, ijk);
                    block_x = ijk.x & ~7;
                    have = 1;
                }
                pnanovdb_address_t a = blk.leaf ? pnanovdb_leaf_get_value_address(FT, buf, blk.leaf_h, &ijk) : blk.addr;
                float d = pnanovdb_read_float(buf, a);
                if (!isfinite(d)) {
                    bad = 1;
                    bad_at = ijk;
                    break;
                }
                neg += d < 0.0f;
                v[at++] = d > 0.0f ? d : 0.0f;
            }
        }
    free(keys);
    if (bad || oob) {
        free(v);
        if (oob)
            str_fmt(err, errlen, "grid \"%s\": corrupt tree: a node lies outside the grid's %llu bytes", name,
                    (unsigned long long)gsize);
        else
            str_fmt(err, errlen, "grid \"%s\": voxel [%d %d %d]: density must be finite", name, bad_at.x, bad_at.y, bad_at.z);
        return -1;
    }
    memset(out, 0, sizeof *out);
    out->nx = (uint32_t)n[0], out->ny = (uint32_t)n[1], out->nz = (uint32_t)n[2];
    out->data = v;
    out->scale = 1.0f;
    out->grid_to_world = out->world_to_grid = xform_identity();
    /* Unit cube -> index: x = (lo - 1 - 0.5) + u n (voxel centres at integers); then the map. */
    for (int i = 0; i < 3; i++) {
        double off = b[i];
        for (int j = 0; j < 3; j++) {
            to_world->m[i][j] = (float)(A[i][j] * (double)n[j]);
            off += A[i][j] * ((double)lo[j] - 1.5);
        }
        to_world->m[i][3] = (float)off;
    }
    *negatives = neg;
    return 0;
}

int nvdb_parse(const uint8_t *data, size_t size, const char *grid_name, struct density_grid *out,
               struct xform *to_world, uint64_t *negatives, char *err, size_t errlen)
{
    memset(out, 0, sizeof *out);
    *negatives = 0;
    struct grid_rec *recs;
    int64_t n = list_grids(data, size, &recs, err, errlen);
    if (n < 0)
        return -1;
    const struct grid_rec *r = choose(recs, n, grid_name, err, errlen);
    int rc = r ? read_grid(data + r->offset, r->size, r, out, to_world, negatives, err, errlen) : -1;
    free(recs);
    return rc;
}
