/* CurveZMQ admission for the master (see zap.h): allow-listed CURVE keys in, everyone
 * else answered 400 and counted. A ZAP request is network input: its parts are checked
 * for count and size before use. Called by master/master.c. */
#include "zap.h"
#include "base/log.h"
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zmq.h>

struct zap {
    void *rep, *monitor;
    void *monitor2;             /* the broadcast socket's (zap_watch), or NULL */
    uint8_t (*allowed)[32];     /* allowed CURVE public keys, binary */
    size_t num_allowed;
    uint64_t refused;           /* only the first few are logged */
};

void zap_allow_key(struct zap *z, const struct net_key *k)
{
    z->allowed = mem_realloc(z->allowed, sizeof *z->allowed * (z->num_allowed + 1));
    zmq_z85_decode(z->allowed[z->num_allowed++], k->z85);
}

size_t zap_num_allowed(const struct zap *z) { return z->num_allowed; }
void *zap_socket(const struct zap *z) { return z->rep; }
void *zap_monitor_socket(const struct zap *z) { return z->monitor; }
void *zap_monitor2_socket(const struct zap *z) { return z->monitor2; }

int zap_watch(struct zap *z, void *zctx, void *sock)
{
    if (z->monitor2 || zmq_socket_monitor(sock, "inproc://brume-monitor-2",
                                          ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL | ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL |
                                              ZMQ_EVENT_HANDSHAKE_FAILED_AUTH) != 0)
        return -1;
    int linger = 0;
    z->monitor2 = zmq_socket(zctx, ZMQ_PAIR);
    zmq_setsockopt(z->monitor2, ZMQ_LINGER, &linger, sizeof linger);
    return zmq_connect(z->monitor2, "inproc://brume-monitor-2");
}

int zap_write_local_keys(const char *key_path, const char *pub_path, const struct net_key *master_public,
                         struct net_key *local_public, char *err, size_t errlen)
{
    struct net_key sec, pub;
    if (net_key_pair_write(key_path, err, errlen) != 0 || net_key_pair_load(key_path, &pub, &sec, err, errlen) != 0)
        return -1;
    FILE *f = fopen(pub_path, "w");
    if (!f || fprintf(f, "%s\n", master_public->z85) < 0 || fclose(f) != 0) {
        str_fmt(err, errlen, "%s: %s", pub_path, strerror(errno));
        return -1;
    }
    *local_public = pub;
    return 0;
}

int zap_allow_file(struct zap *z, const char *allow_path, char *err, size_t errlen)
{
    struct net_key *keys = NULL;
    size_t count = 0;
    if (net_key_list_load(allow_path, &keys, &count, err, errlen) != 0)
        return -1;
    for (size_t i = 0; i < count; i++)
        zap_allow_key(z, &keys[i]);
    free(keys);
    return 0;
}

struct zap *zap_new(void *zctx, void *sock, const struct net_key *secret, char *err, size_t errlen)
{
    if (!zmq_has("curve")) {
        str_fmt(err, errlen, "CurveZMQ: this libzmq has no CURVE support");
        return NULL;
    }
    struct zap *z = mem_calloc(1, sizeof *z);
    /* The handler must be bound before the first peer connects. */
    z->rep = zmq_socket(zctx, ZMQ_REP);
    int linger = 0;
    zmq_setsockopt(z->rep, ZMQ_LINGER, &linger, sizeof linger);
    if (zmq_bind(z->rep, "inproc://zeromq.zap.01") != 0 || net_curve_server(sock, secret) != 0) {
        str_fmt(err, errlen, "cannot enable CurveZMQ: %s", zmq_strerror(errno));
        zap_free(&z);
        return NULL;
    }
    /* Handshakes that fail before ZAP (a client without CURVE, a wrong server key) are
     * counted through the socket monitor. */
    if (zmq_socket_monitor(sock, "inproc://brume-monitor",
                           ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL | ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL |
                               ZMQ_EVENT_HANDSHAKE_FAILED_AUTH) == 0) {
        z->monitor = zmq_socket(zctx, ZMQ_PAIR);
        zmq_setsockopt(z->monitor, ZMQ_LINGER, &linger, sizeof linger);
        zmq_connect(z->monitor, "inproc://brume-monitor");
    }
    return z;
}

void zap_free(struct zap **zp)
{
    struct zap *z = *zp;
    if (!z)
        return;
    if (z->monitor)
        zmq_close(z->monitor);
    if (z->monitor2)
        zmq_close(z->monitor2);
    if (z->rep)
        zmq_close(z->rep);
    free(z->allowed);
    free(z);
    *zp = NULL;
}

int zap_handle(struct zap *z)
{
    zmq_msg_t part[8];
    int n = 0, more = 1;
    while (more && n < 8) {
        zmq_msg_init(&part[n]);
        if (zmq_msg_recv(&part[n], z->rep, ZMQ_DONTWAIT) < 0) {
            zmq_msg_close(&part[n]);
            break;
        }
        more = zmq_msg_more(&part[n]);
        n++;
    }
    while (more) { /* a request with too many parts: drain it */
        zmq_msg_t x;
        zmq_msg_init(&x);
        if (zmq_msg_recv(&x, z->rep, ZMQ_DONTWAIT) < 0)
            more = 0;
        else
            more = zmq_msg_more(&x);
        zmq_msg_close(&x);
    }
    if (n < 2) {
        for (int i = 0; i < n; i++)
            zmq_msg_close(&part[i]);
        return 0; /* no request id to answer */
    }
    int ok = n == 7 && zmq_msg_size(&part[5]) == 5 && !memcmp(zmq_msg_data(&part[5]), "CURVE", 5) &&
             zmq_msg_size(&part[6]) == 32;
    if (ok) {
        ok = 0;
        for (size_t i = 0; i < z->num_allowed && !ok; i++)
            ok = !memcmp(z->allowed[i], zmq_msg_data(&part[6]), 32);
    }
    if (!ok && ++z->refused <= 5)
        log_warn("a worker with a key not in the allow-list was refused");
    const char *status = ok ? "200" : "400", *text = ok ? "OK" : "key not allowed";
    /* The User-Id is the key in Z85: libzmq attaches it to every message of the
     * connection, so the master knows who sent what without trusting the peer. */
    char user_id[NET_Z85_KEY_LEN + 1] = "";
    if (ok)
        zmq_z85_encode(user_id, zmq_msg_data(&part[6]), 32);
    zmq_send(z->rep, "1.0", 3, ZMQ_SNDMORE);
    zmq_send(z->rep, zmq_msg_data(&part[1]), zmq_msg_size(&part[1]), ZMQ_SNDMORE);
    zmq_send(z->rep, status, 3, ZMQ_SNDMORE);
    zmq_send(z->rep, text, strlen(text), ZMQ_SNDMORE);
    zmq_send(z->rep, user_id, strlen(user_id), ZMQ_SNDMORE);
    zmq_send(z->rep, "", 0, 0);
    for (int i = 0; i < n; i++)
        zmq_msg_close(&part[i]);
    return !ok;
}

static unsigned monitor_drain(void *monitor);

unsigned zap_monitor_drain(struct zap *z)
{
    return (z->monitor ? monitor_drain(z->monitor) : 0) + (z->monitor2 ? monitor_drain(z->monitor2) : 0);
}

static unsigned monitor_drain(void *monitor)
{
    unsigned failures = 0;
    for (;;) {
        zmq_msg_t ev, addr;
        zmq_msg_init(&ev);
        if (zmq_msg_recv(&ev, monitor, ZMQ_DONTWAIT) < 0) {
            zmq_msg_close(&ev);
            return failures;
        }
        int more = zmq_msg_more(&ev);
        if (zmq_msg_size(&ev) >= 2) {
            uint16_t event;
            memcpy(&event, zmq_msg_data(&ev), 2);
            if (event != ZMQ_EVENT_HANDSHAKE_FAILED_AUTH) /* those were counted by ZAP */
                failures++;
        }
        zmq_msg_close(&ev);
        if (more) {
            zmq_msg_init(&addr);
            zmq_msg_recv(&addr, monitor, ZMQ_DONTWAIT);
            zmq_msg_close(&addr);
        }
    }
}
