/* junkpeer: a misbehaving client for integration tests. Connects a DEALER to a master and
 * sends what a broken or hostile peer might: random bytes, a truncated frame, a frame of
 * another protocol version, a multi-frame envelope, an oversized frame, and (after a valid
 * HELLO) results for tiles it was never given. The master must log and drop all of it.
 *   junkpeer ENDPOINT */
#include "wire/proto.h"
#include "wire/net.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <zmq.h>

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: junkpeer ENDPOINT\n");
        return 2;
    }
    void *ctx = zmq_ctx_new(), *s = zmq_socket(ctx, ZMQ_DEALER);
    int linger = 2000;
    zmq_setsockopt(s, ZMQ_LINGER, &linger, sizeof linger);
    if (zmq_connect(s, argv[1]) != 0) {
        fprintf(stderr, "junkpeer: cannot connect to %s\n", argv[1]);
        return 1;
    }
    uint8_t junk[512];
    srand(1);
    for (size_t i = 0; i < sizeof junk; i++)
        junk[i] = (uint8_t)rand();
    zmq_send(s, junk, sizeof junk, 0);                  /* random bytes */
    zmq_send(s, "", 0, 0);                              /* empty frame */
    zmq_send(s, junk, 10, ZMQ_SNDMORE);                 /* multi-frame envelope */
    zmq_send(s, junk, 10, 0);

    struct proto_buf b = {0};
    struct proto_msg m = {.type = MSG_HELLO};
    m.u.hello.threads = 1;
    m.u.hello.pid = 1;
    snprintf(m.u.hello.host, sizeof m.u.hello.host, "junk\x01peer");
    proto_encode(&m, &b);
    zmq_send(s, b.data, b.size - 3, 0);                 /* truncated HELLO */
    b.data[4] = 99;                                     /* another protocol version */
    zmq_send(s, b.data, b.size, 0);
    b.data[4] = PROTO_VERSION & 0xff;
    zmq_send(s, b.data, b.size, 0);                     /* a valid HELLO: now a known peer */
    usleep(200000);

    static uint8_t chunk[4096];
    for (uint32_t tile = 0; tile < 64; tile++) {        /* results for tiles never assigned */
        struct proto_msg r = {.type = MSG_RESULT};
        r.u.result.job_id = tile;                       /* wrong job ids */
        r.u.result.tile = tile;
        r.u.result.attempt = 1;
        r.u.result.chunk = chunk;
        r.u.result.chunk_size = sizeof chunk;
        proto_encode(&r, &b);
        zmq_send(s, b.data, b.size, 0);
    }
    struct proto_msg q = {.type = MSG_BLOB_REQ};        /* a blob that does not exist */
    q.u.blob_req.length = 100;
    proto_encode(&q, &b);
    zmq_send(s, b.data, b.size, 0);
    struct proto_msg bye = {.type = MSG_BYE};
    proto_encode(&bye, &b);
    zmq_send(s, b.data, b.size, 0);
    proto_buf_fini(&b);
    zmq_close(s);
    zmq_ctx_term(ctx);
    return 0;
}
