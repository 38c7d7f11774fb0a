/* ZeroMQ plumbing shared by master and worker: socket options every socket gets
 * (ZMQ_MAXMSGSIZE, LINGER 0), and sending / receiving one protocol message with an
 * optional ROUTER identity frame. Receiving never trusts a frame: the caller decodes it
 * with proto_decode() and drops what fails. */
#ifndef BRUME_NET_H
#define BRUME_NET_H
#include <stddef.h>
#include <stdint.h>
#include "proto.h"

#define NET_MAX_IDENTITY 256

void net_socket_setup(void *sock);
/* Encodes and sends msg (preceded by identity when id_len > 0). 0 or -1 (logged). */
int net_send(void *sock, const uint8_t *id, size_t id_len, const struct proto_msg *msg, struct proto_buf *scratch);

/* One received message: identity (ROUTER only) and the payload frame. */
struct net_frame {
    uint8_t id[NET_MAX_IDENTITY];
    size_t id_len;
    uint8_t *data;      /* mem_alloc'd copy of the payload, freed by net_frame_free */
    size_t size;
};
/* Receives one message without blocking (call after zmq_poll said POLLIN). with_identity:
 * expect an identity frame first (ROUTER). Returns 1 on a well-formed envelope, 0 when
 * nothing was there, -1 on a malformed envelope (wrong frame count: drained and dropped). */
int net_recv(void *sock, int with_identity, struct net_frame *f);
void net_frame_free(struct net_frame *f);

/* Monotonic milliseconds. */
uint64_t net_now_ms(void);

#endif
