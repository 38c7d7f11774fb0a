/* ZeroMQ plumbing shared by master and worker: socket options every socket gets
 * (ZMQ_MAXMSGSIZE, LINGER 0), and sending / receiving one protocol message with an
 * optional ROUTER identity frame. Receiving never trusts a frame: the caller decodes it
 * with proto_decode() and drops what fails. */
#ifndef BRUME_NET_H
#define BRUME_NET_H
#include <stddef.h>
#include <stdint.h>
#include "wire/proto.h"

#define NET_MAX_IDENTITY 256
#define NET_Z85_KEY_LEN 40

void net_socket_setup(void *sock);
/* Encodes and sends msg (preceded by identity when id_len > 0) without blocking: -1
 * (logged at debug level, errno set) when it cannot be queued (no peer, queue full). */
int net_send(void *sock, const uint8_t *id, size_t id_len, const struct proto_msg *msg, struct proto_buf *scratch);

/* A received payload frame as libzmq delivered it (not copied): whoever holds it frees
 * it with net_payload_free. */
struct net_payload;
/* One received message: identity (ROUTER only) and the payload frame. */
struct net_frame {
    uint8_t id[NET_MAX_IDENTITY];
    size_t id_len;
    const uint8_t *data; /* the payload's bytes, inside payload */
    size_t size;
    struct net_payload *payload; /* freed by net_frame_fini, unless net_frame_take took it */
    /* Who the peer is: with CurveZMQ, the Z85 public key its handshake proved (the ZAP
     * handler's User-Id); "" without CurveZMQ. Set by libzmq, never by the peer. */
    char user_id[NET_Z85_KEY_LEN + 1];
};
/* Receives one message without blocking (call after zmq_poll said POLLIN). with_identity:
 * expect an identity frame first (ROUTER). Returns 1 on a well-formed envelope, 0 when
 * nothing was there, -1 on a malformed envelope (wrong frame count: drained and dropped). */
int net_recv(void *sock, int with_identity, struct net_frame *f);
void net_frame_fini(struct net_frame *f);
/* Takes the payload over from f: data stays valid until net_payload_free. */
struct net_payload *net_frame_take(struct net_frame *f);
/* A payload holding a copy of size bytes at data (for what did not come from net_recv). */
struct net_payload *net_payload_copy(const void *data, size_t size);
/* The payload's bytes (the same as the frame's data), writable for its holder. */
uint8_t *net_payload_data(struct net_payload *p);
void net_payload_free(struct net_payload **p);

/* CurveZMQ keys are 40-character Z85 strings. A key pair file holds the public key on
 * its first line and the secret key on its second; a public key file (and each line of
 * an allow-list) holds one public key, optionally followed by a name. Lines starting with
 * '#' are comments. */
struct net_key { char z85[NET_Z85_KEY_LEN + 1]; };
int net_key_pair_load(const char *path, struct net_key *public_key, struct net_key *secret_key, char *err, size_t errlen);
int net_key_public_load(const char *path, struct net_key *public_key, char *err, size_t errlen);
/* Reads an allow-list; *keys is mem_alloc'd. Returns 0 or -1 (err says which line). */
int net_key_list_load(const char *path, struct net_key **keys, size_t *count, char *err, size_t errlen);
/* Writes PATH (key pair, mode 0600) and PATH.pub (public key). 0 or -1. */
int net_key_pair_write(const char *path, char *err, size_t errlen);
/* Client side of CurveZMQ: set before zmq_connect. 0 or -1. */
int net_curve_client(void *sock, const struct net_key *server_public, const struct net_key *our_public,
                     const struct net_key *our_secret);
/* Server side: CURVE with ZAP domain "brume" and a handshake deadline; set before
 * zmq_bind. 0 or -1. */
#define NET_HANDSHAKE_MS 5000 /* a connection that has not finished its handshake by then is closed */
int net_curve_server(void *sock, const struct net_key *our_secret);
/* True for tcp:// endpoints (reachable over a network, loopback included). */
int net_endpoint_is_tcp(const char *endpoint);
/* True for endpoints only this machine can reach (ipc, inproc, tcp on loopback). */
int net_endpoint_is_local(const char *endpoint);

/* The broadcast (PUB) endpoint beside a ROUTER endpoint: ipc://PATH -> ipc://PATH.bcast,
 * tcp://HOST:PORT -> tcp://HOST:bcast_port (bcast_port 0: tcp://HOST:*, for binding to a
 * free port). 0, or -1 for another transport or when out[outlen] is too small. */
int net_bcast_endpoint(const char *endpoint, uint16_t bcast_port, char *out, size_t outlen);
/* The port of a tcp://HOST:PORT endpoint (e.g. ZMQ_LAST_ENDPOINT), 0 when none. */
uint16_t net_endpoint_port(const char *endpoint);

/* Monotonic milliseconds. */
uint64_t net_now_ms(void);

#endif
