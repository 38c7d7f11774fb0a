/* proto_seeds DIR: writes one valid encoded message of every type into DIR (seed_<TYPE>),
 * the seed corpus for the protocol fuzz target, so the fuzzer starts from frames that
 * get past the header and explores the fields. Used by tests/fuzz/ci.sh. */
#include <stdio.h>
#include <string.h>
#include "wire/proto.h"

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: proto_seeds DIR\n");
        return 2;
    }
    static const uint8_t bytes[48] = {1, 2, 3, 4, 5, 6, 7, 8};
    static const uint8_t chunk_hashes[2 * BLOB_HASH_SIZE] = {3, 1, 4, 1, 5, 9, 2, 6};
    static struct proto_asset assets[2];
    snprintf(assets[0].path, sizeof assets[0].path, "scene.json");
    assets[0].size = 100;
    snprintf(assets[1].path, sizeof assets[1].path, "m/a.obj");
    assets[1].size = 7;
    struct proto_buf b = {0};
    int rc = 0;
    for (int t = MSG_HELLO; t < MSG_TYPE_MAX_; t++) {
        struct proto_msg m;
        memset(&m, 0, sizeof m);
        m.type = (enum proto_type)t;
        switch (m.type) {
        case MSG_HELLO: m.u.hello.threads = 4; m.u.hello.pid = 77; snprintf(m.u.hello.host, sizeof m.u.hello.host, "node1"); break;
        case MSG_JOB:
            m.u.job.job_id = 5; m.u.job.width = 64; m.u.job.height = 48; m.u.job.spp = 4; m.u.job.tile_size = 16;
            m.u.job.max_depth = 4; snprintf(m.u.job.scene_path, sizeof m.u.job.scene_path, "scene.json");
            m.u.job.num_assets = 2; m.u.job.assets = assets; break;
        case MSG_BLOB_REQ: m.u.blob_req.length = 16; break;
        case MSG_BLOB_DATA: m.u.blob_data.total_size = sizeof bytes; m.u.blob_data.bytes = bytes; m.u.blob_data.length = sizeof bytes; break;
        case MSG_READY: m.u.ready.job_id = 5; m.u.ready.credits = 2; break;
        case MSG_TILE: m.u.tile.job_id = 5; m.u.tile.tile = 3; m.u.tile.attempt = 1; m.u.tile.pass = 1; m.u.tile.mask = 0x8421; break;
        case MSG_RESULT: m.u.result.job_id = 5; m.u.result.tile = 3; m.u.result.attempt = 1; m.u.result.chunk = bytes; m.u.result.chunk_size = sizeof bytes; break;
        case MSG_ERROR: m.u.error.job_id = 5; snprintf(m.u.error.text, sizeof m.u.error.text, "x"); break;
        case MSG_HEARTBEAT: m.u.heartbeat.job_id = 5; m.u.heartbeat.samples_done = 9; break;
        case MSG_ACK: m.u.ack.job_id = 5; m.u.ack.count = 3; m.u.ack.tiles[1] = 1; m.u.ack.tiles[2] = 2; break;
        case MSG_KEPT: m.u.kept.job_id = 5; m.u.kept.tile = 3; m.u.kept.chunk = bytes; m.u.kept.chunk_size = sizeof bytes; break;
        case MSG_MAP: m.u.map.job_id = 5; m.u.map.pass = 2; m.u.map.published = 3; m.u.map.size = 1000; break;
        case MSG_CHUNKS_REQ: m.u.chunks_req.hash.bytes[0] = 9; break;
        case MSG_CHUNKS: /* a blob of one chunk and a bit: two hashes (48 bytes of `bytes` and 16 more) */
            m.u.chunks.size = BLOB_CHUNK_SIZE + 1; m.u.chunks.flags = PROTO_CHUNKS_BCAST; m.u.chunks.bcast_port = 5556;
            m.u.chunks.count = 2; m.u.chunks.hashes = chunk_hashes; break;
        case MSG_BYE: case MSG_TYPE_MAX_: break;
        }
        char path[4096];
        snprintf(path, sizeof path, "%s/seed_%s", argv[1], proto_type_name(m.type));
        FILE *f = fopen(path, "wb");
        if (proto_encode(&m, &b) != 0 || !f || fwrite(b.data, 1, b.size, f) != b.size) {
            fprintf(stderr, "proto_seeds: cannot write %s\n", path);
            rc = 1;
        }
        if (f)
            fclose(f);
    }
    proto_buf_fini(&b);
    return rc;
}
