// NanoVDB output (see nvdb_out.h): GridBuilder fills the tree from the dense values (it
// skips background values itself), getHandle applies the map, io::writeGrid serialises
// into memory (the caller writes the file atomically).
#include "nvdb_out.h"

#include <nanovdb/util/GridBuilder.h>
#include <nanovdb/util/IO.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>

extern "C" int nvdb_encode_fog(const float *values, const uint32_t n[3], float threshold,
                               const double voxel_size[3], const double origin[3], const char *name,
                               uint8_t **out, size_t *len, uint64_t *active, char *err, size_t errlen)
{
    *out = nullptr;
    *len = 0;
    if (!n[0] || !n[1] || !n[2] || n[0] > (1u << 20) || n[1] > (1u << 20) || n[2] > (1u << 20)) {
        std::snprintf(err, errlen, "nvdb: grid size %ux%ux%u out of range", n[0], n[1], n[2]);
        return -1;
    }
    for (int a = 0; a < 3; a++)
        if (!(voxel_size[a] > 0.0) || !std::isfinite(voxel_size[a]) || !std::isfinite(origin[a])) {
            std::snprintf(err, errlen, "nvdb: voxel size and origin must be finite, the size > 0");
            return -1;
        }
    try {
        const size_t sx = n[0], sxy = (size_t)n[0] * n[1];
        nanovdb::GridBuilder<float> b(0.0f, nanovdb::GridClass::FogVolume);
        b([&](const nanovdb::Coord &c) {
              float v = values[(size_t)c[2] * sxy + (size_t)c[1] * sx + (size_t)c[0]];
              return v > threshold && std::isfinite(v) ? v : 0.0f;
          },
          nanovdb::CoordBBox(nanovdb::Coord(0), nanovdb::Coord((int)n[0] - 1, (int)n[1] - 1, (int)n[2] - 1)));
        // Map::set takes OpenVDB's row-vector matrix (m[j][i]: index axis j's part of world axis i).
        const double m[3][3] = {{voxel_size[0], 0.0, 0.0}, {0.0, voxel_size[1], 0.0}, {0.0, 0.0, voxel_size[2]}};
        const double inv[3][3] = {
            {1.0 / voxel_size[0], 0.0, 0.0}, {0.0, 1.0 / voxel_size[1], 0.0}, {0.0, 0.0, 1.0 / voxel_size[2]}};
        nanovdb::Map map;
        map.set(m, inv, origin, 1.0);
        auto handle = b.getHandle(map, name);
        if (active)
            *active = handle.grid<float>() ? handle.grid<float>()->activeVoxelCount() : 0;
        // writeGrid seeks over the header it writes last; a string stream cannot seek past
        // its end, so it starts as zeros of the file's size (header plus the uncompressed grid).
        nanovdb::io::Segment seg(nanovdb::io::Codec::NONE);
        seg.add(handle);
        std::stringstream os(std::string(seg.memUsage() + handle.size(), '\0'),
                             std::ios::in | std::ios::out | std::ios::binary);
        nanovdb::io::writeGrid(os, handle, nanovdb::io::Codec::NONE);
        if (!os || (uint64_t)os.tellp() != seg.memUsage() + handle.size())
            throw std::runtime_error("the written size is not the expected one");
        const std::string s = os.str();
        *out = static_cast<uint8_t *>(std::malloc(s.size() ? s.size() : 1));
        if (!*out) {
            std::snprintf(err, errlen, "nvdb: out of memory (%zu bytes)", s.size());
            return -1;
        }
        std::memcpy(*out, s.data(), s.size());
        *len = s.size();
    } catch (const std::exception &e) {
        std::snprintf(err, errlen, "nvdb: %s", e.what());
        return -1;
    }
    return 0;
}
