/* ZeroMQ helpers (see net.h). Messages are at most PROTO_MAX_MESSAGE bytes: libzmq
 * enforces that on receive (ZMQ_MAXMSGSIZE) before any of our code sees the bytes. */
#include "net.h"
#include "log.h"
#include <errno.h>
#include <string.h>
#include <stdlib.h>
#include <time.h>
#include <zmq.h>

void net_socket_setup(void *sock)
{
    int64_t max = PROTO_MAX_MESSAGE;
    int linger = 0;
    zmq_setsockopt(sock, ZMQ_MAXMSGSIZE, &max, sizeof max);
    zmq_setsockopt(sock, ZMQ_LINGER, &linger, sizeof linger);
}

int net_send(void *sock, const uint8_t *id, size_t id_len, const struct proto_msg *msg, struct proto_buf *scratch)
{
    if (proto_encode(msg, scratch) != 0) {
        log_error("cannot encode %s message (field out of limits)", proto_type_name(msg->type));
        return -1;
    }
    if (id_len > 0 && zmq_send(sock, id, id_len, ZMQ_SNDMORE | ZMQ_DONTWAIT) < 0) {
        log_debug("send identity: %s", zmq_strerror(errno));
        return -1;
    }
    if (zmq_send(sock, scratch->data, scratch->size, id_len > 0 ? ZMQ_DONTWAIT : 0) < 0) {
        log_debug("send %s: %s", proto_type_name(msg->type), zmq_strerror(errno));
        return -1;
    }
    return 0;
}

static void drain(void *sock)
{
    int more = 1;
    size_t sz = sizeof more;
    while (zmq_getsockopt(sock, ZMQ_RCVMORE, &more, &sz) == 0 && more) {
        zmq_msg_t m;
        zmq_msg_init(&m);
        zmq_msg_recv(&m, sock, ZMQ_DONTWAIT);
        zmq_msg_close(&m);
    }
}

int net_recv(void *sock, int with_identity, struct net_frame *f)
{
    memset(f, 0, sizeof *f);
    zmq_msg_t m;
    zmq_msg_init(&m);
    if (zmq_msg_recv(&m, sock, ZMQ_DONTWAIT) < 0) {
        zmq_msg_close(&m);
        return 0;
    }
    if (with_identity) {
        size_t n = zmq_msg_size(&m);
        int more = zmq_msg_more(&m);
        if (n == 0 || n > NET_MAX_IDENTITY || !more) {
            zmq_msg_close(&m);
            drain(sock);
            return -1;
        }
        memcpy(f->id, zmq_msg_data(&m), n);
        f->id_len = n;
        zmq_msg_close(&m);
        zmq_msg_init(&m);
        if (zmq_msg_recv(&m, sock, ZMQ_DONTWAIT) < 0) {
            zmq_msg_close(&m);
            return -1;
        }
    }
    if (zmq_msg_more(&m)) {
        zmq_msg_close(&m);
        drain(sock);
        return -1;
    }
    f->size = zmq_msg_size(&m);
    f->data = mem_alloc(f->size ? f->size : 1);
    memcpy(f->data, zmq_msg_data(&m), f->size);
    zmq_msg_close(&m);
    return 1;
}

void net_frame_free(struct net_frame *f)
{
    free(f->data);
    f->data = NULL;
    f->size = 0;
}

uint64_t net_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000u + (uint64_t)ts.tv_nsec / 1000000u;
}
