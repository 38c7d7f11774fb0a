// Writes the NanoVDB test files of tests/unit/test_nvdb.c and tests/integration/media.sh with
// NanoVDB's own C++ writer (nanovdb/util/GridBuilder.h, nanovdb/util/IO.h from Debian's
// libnanovdb-dev), so the C reader (common/scene/nvdb.c) is tested against the reference
// implementation, never against itself. Every density is a closed-form function of the
// integer index (ball_value etc., in nvdb_values.h, shared with test_nvdb.c), exact in float.
// Usage: make_nvdb OUTDIR   (built by the Makefile with g++; ZIP and BLOSC for the refusals)
//        make_nvdb --from-grid IN.grid OUT.nvdb   (a dense BRGRID01 grid as a NanoVDB fog
//        volume whose map puts voxel centres where the dense grid has them in its unit cube,
//        by smoke/nvdb_out.cpp's nvdb_encode_fog)
#include <nanovdb/util/GridBuilder.h>
#include <nanovdb/util/IO.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

using nanovdb::Coord;
using nanovdb::CoordBBox;
using nanovdb::GridClass;
using nanovdb::GridHandle;
using nanovdb::HostBuffer;
using nanovdb::Map;

#include "nvdb_values.h"
#include "smoke/nvdb_out.h"  // the dense-to-NanoVDB writer smokesim uses too

// The ball's index-to-world map: a shear, so that a transposed matrix shows.
// world = A ijk + t with A = [[1/8, 0, 1/16], [0, 1/4, 0], [0, 0, 1/8]], t = (-1, 0.5, -0.75).
static Map ball_map()
{
    // Map::set takes OpenVDB's row-vector matrices: m[j][i] is index axis j's part of world axis i.
    const double m[3][3] = {{0.125, 0.0, 0.0}, {0.0, 0.25, 0.0}, {0.0625, 0.0, 0.125}};
    const double inv[3][3] = {{8.0, 0.0, 0.0}, {0.0, 4.0, 0.0}, {-4.0, 0.0, 8.0}};
    const double t[3] = {-1.0, 0.5, -0.75};
    Map map;
    map.set(m, inv, t, 1.0);
    return map;
}

template<typename F>
static GridHandle<HostBuffer> float_grid(F f, const CoordBBox &box, const Map &map, const std::string &name,
                                         GridClass cls = GridClass::FogVolume, float background = 0.0f)
{
    nanovdb::GridBuilder<float> b(background, cls);
    b(f, box);
    return b.getHandle(map, name);
}

static bool write(const std::string &path, const std::vector<GridHandle<HostBuffer>> &h,
                  nanovdb::io::Codec codec = nanovdb::io::Codec::NONE)
{
    try {
        nanovdb::io::writeGrids(path, h, codec);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "make_nvdb: %s: %s\n", path.c_str(), e.what());
        return false;
    }
    return true;
}

static std::vector<GridHandle<HostBuffer>> one(GridHandle<HostBuffer> &&h)
{
    std::vector<GridHandle<HostBuffer>> v;
    v.push_back(std::move(h));
    return v;
}

// BRGRID01 (common/scene/medium.h): magic, nx ny nz (uint32 LE), nx*ny*nz float32 LE, x fastest.
static int from_grid(const char *in, const char *out)
{
    std::FILE *f = std::fopen(in, "rb");
    if (!f) {
        std::fprintf(stderr, "make_nvdb: cannot open %s\n", in);
        return 1;
    }
    char magic[8];
    uint32_t n[3];
    if (std::fread(magic, 1, 8, f) != 8 || std::memcmp(magic, "BRGRID01", 8) != 0 || std::fread(n, 4, 3, f) != 3 ||
        (uint64_t)n[0] * n[1] * n[2] > (1u << 27) || !n[0] || !n[1] || !n[2]) {
        std::fprintf(stderr, "make_nvdb: %s is not a BRGRID01 grid\n", in);
        std::fclose(f);
        return 1;
    }
    std::vector<float> v((size_t)n[0] * n[1] * n[2]);
    bool ok = std::fread(v.data(), 4, v.size(), f) == v.size();
    std::fclose(f);
    if (!ok) {
        std::fprintf(stderr, "make_nvdb: %s is truncated\n", in);
        return 1;
    }
    // Index i's centre at (i + 0.5) / n in the unit cube, as in the dense grid.
    const double size[3] = {1.0 / n[0], 1.0 / n[1], 1.0 / n[2]};
    const double origin[3] = {0.5 / n[0], 0.5 / n[1], 0.5 / n[2]};
    uint8_t *buf = nullptr;
    size_t len = 0;
    char err[256];
    if (nvdb_encode_fog(v.data(), n, 0.0f, size, origin, "density", &buf, &len, nullptr, err, sizeof err) != 0) {
        std::fprintf(stderr, "make_nvdb: %s: %s\n", in, err);
        return 1;
    }
    std::FILE *o = std::fopen(out, "wb");
    ok = o && std::fwrite(buf, 1, len, o) == len;
    ok = (o && std::fclose(o) == 0) && ok;
    std::free(buf);
    if (!ok)
        std::fprintf(stderr, "make_nvdb: cannot write %s\n", out);
    return ok ? 0 : 1;
}

int main(int argc, char **argv)
{
    if (argc == 4 && std::strcmp(argv[1], "--from-grid") == 0)
        return from_grid(argv[2], argv[3]);
    if (argc != 2) {
        std::fprintf(stderr, "usage: make_nvdb OUTDIR | make_nvdb --from-grid IN.grid OUT.nvdb\n");
        return 2;
    }
    const std::string d = std::string(argv[1]) + "/";
    const CoordBBox ball_box(Coord(-8, -6, -7), Coord(11, 9, 7));
    auto ball = [](const Coord &c) { return ball_value(c[0], c[1], c[2]); };
    Map unit;
    unit.set(1.0, nanovdb::Vec3d(0.0), 1.0);
    bool ok = true;

    ok &= write(d + "ball.nvdb", one(float_grid(ball, ball_box, ball_map(), "density")));
    ok &= write(d + "ball_zip.nvdb", one(float_grid(ball, ball_box, ball_map(), "density")), nanovdb::io::Codec::ZIP);
    ok &= write(d + "ball_blosc.nvdb", one(float_grid(ball, ball_box, ball_map(), "density")), nanovdb::io::Codec::BLOSC);

    // A vector grid first, then two float grids: "first float grid" and selection by name.
    {
        std::vector<GridHandle<HostBuffer>> h;
        nanovdb::GridBuilder<nanovdb::Vec3f> vb(nanovdb::Vec3f(0.0f));
        vb([](const Coord &c) { return nanovdb::Vec3f((float)c[0], 1.0f, 0.0f); }, CoordBBox(Coord(0), Coord(3)));
        h.push_back(vb.getHandle(ball_map(), "velocity"));
        h.push_back(float_grid(ball, ball_box, ball_map(), "density"));
        h.push_back(float_grid([](const Coord &c) { return temperature_value(c[0], c[1], c[2]); },
                               CoordBBox(Coord(-4), Coord(4)), unit, "temperature"));
        ok &= write(d + "multi.nvdb", h);
    }
    {
        Map half;
        half.set(0.5, nanovdb::Vec3d(0.0), 1.0);
        ok &= write(d + "sparse.nvdb", one(float_grid([](const Coord &c) { return sparse_value(c[0], c[1], c[2]); },
                                                       CoordBBox(Coord(-140), Coord(140)), half, "density")));
    }
    // Refusals and the clamp.
    {
        auto neg = [](const Coord &c) { return c == Coord(1, 1, 1) ? -0.5f : (c[0] + c[1] + c[2] == 2 ? 0.75f : 0.0f); };
        ok &= write(d + "negative.nvdb", one(float_grid(neg, CoordBBox(Coord(0), Coord(3)), unit, "density")));
        auto nan = [](const Coord &c) { return c == Coord(1, 2, 0) ? std::numeric_limits<float>::quiet_NaN() : 1.0f; };
        ok &= write(d + "nan.nvdb", one(float_grid(nan, CoordBBox(Coord(0), Coord(3)), unit, "density")));
        nanovdb::GridBuilder<float> fb(0.0f, GridClass::FogVolume);
        auto acc = fb.getAccessor();
        acc.setValue(Coord(0), 1.0f);
        acc.setValue(Coord(600), 1.0f);
        ok &= write(d + "huge.nvdb", one(fb.getHandle(unit, "density")));
        auto sphere = [](const Coord &c) { return std::sqrt((float)(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])) - 3.0f; };
        ok &= write(d + "levelset.nvdb",
                    one(float_grid(sphere, CoordBBox(Coord(-2), Coord(2)), unit, "surface", GridClass::LevelSet, 3.0f)));
        ok &= write(d + "background.nvdb",
                    one(float_grid([](const Coord &) { return 1.0f; }, CoordBBox(Coord(0), Coord(2)), unit, "density",
                                   GridClass::FogVolume, 0.5f)));
        nanovdb::GridBuilder<float> nb(0.0f, GridClass::FogVolume);
        nb([](const Coord &) { return 1.0f; }, CoordBBox(Coord(0), Coord(2)));
        nb.setStats(nanovdb::StatsMode::Disable);
        ok &= write(d + "nobbox.nvdb", one(nb.getHandle(unit, "density")));
        nanovdb::GridBuilder<double> db(0.0, GridClass::FogVolume);
        db([](const Coord &) { return 1.0; }, CoordBBox(Coord(0), Coord(2)));
        ok &= write(d + "double.nvdb", one(db.getHandle(unit, "density")));
    }
    return ok ? 0 : 1;
}
