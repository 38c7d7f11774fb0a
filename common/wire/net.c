/* ZeroMQ helpers (see net.h). Messages are at most PROTO_MAX_MESSAGE bytes: libzmq
 * enforces that on receive (ZMQ_MAXMSGSIZE) before any of our code sees the bytes. */
#include "wire/net.h"
#include "base/log.h"
#include <ctype.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>
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
    if (zmq_send(sock, scratch->data, scratch->size, ZMQ_DONTWAIT) < 0) {
        int e = errno;
        log_debug("send %s: %s", proto_type_name(msg->type), zmq_strerror(e));
        errno = e;
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

struct net_payload { zmq_msg_t msg; };
#define NET_RECV_COPY_BELOW 8192 /* libzmq's default ZMQ_IN_BATCH_SIZE */

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
    const char *uid = zmq_msg_gets(&m, "User-Id");
    if (uid && strlen(uid) == NET_Z85_KEY_LEN)
        memcpy(f->user_id, uid, NET_Z85_KEY_LEN + 1);
    /* The message itself becomes the payload (moved, not copied), in a heap zmq_msg_t so
     * that data stays where it is. Except a small one: libzmq receives into batches of
     * 8 KiB (ZMQ_IN_BATCH_SIZE) and hands a message that fits in one out as a slice of it,
     * so that holding the message would hold the whole batch (the master keeps chunks for
     * the frame: 16 px tiles over ipc took twice the memory); those are copied. */
    size_t n = zmq_msg_size(&m);
    if (n < NET_RECV_COPY_BELOW) {
        f->payload = net_payload_copy(zmq_msg_data(&m), n);
    } else {
        f->payload = mem_alloc(sizeof *f->payload);
        zmq_msg_init(&f->payload->msg);
        zmq_msg_move(&f->payload->msg, &m);
    }
    zmq_msg_close(&m);
    f->size = zmq_msg_size(&f->payload->msg);
    f->data = zmq_msg_data(&f->payload->msg);
    return 1;
}

struct net_payload *net_payload_copy(const void *data, size_t size)
{
    struct net_payload *p = mem_alloc(sizeof *p);
    CHECK(zmq_msg_init_size(&p->msg, size) == 0);
    if (size)
        memcpy(zmq_msg_data(&p->msg), data, size);
    return p;
}

void net_payload_free(struct net_payload **p)
{
    if (!*p)
        return;
    zmq_msg_close(&(*p)->msg);
    free(*p);
    *p = NULL;
}

uint8_t *net_payload_data(struct net_payload *p)
{
    return zmq_msg_data(&p->msg);
}

struct net_payload *net_frame_take(struct net_frame *f)
{
    struct net_payload *p = f->payload;
    f->payload = NULL;
    return p;
}

void net_frame_fini(struct net_frame *f)
{
    net_payload_free(&f->payload);
    f->data = NULL;
    f->size = 0;
}

uint64_t net_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000u + (uint64_t)ts.tv_nsec / 1000000u;
}

/* ---- CurveZMQ keys ---- */

static int key_is_z85(const char *s, size_t n)
{
    if (n != NET_Z85_KEY_LEN)
        return 0;
    uint8_t raw[32];
    char tmp[NET_Z85_KEY_LEN + 1];
    memcpy(tmp, s, n);
    tmp[n] = '\0';
    return zmq_z85_decode(raw, tmp) != NULL;
}

/* Calls fn(ctx, key, lineno) for each non-comment line's first word; stops on fn < 0. */
static int key_lines(const char *path, int (*fn)(void *, const char *, size_t, int), void *ctx, char *err,
                     size_t errlen)
{
    FILE *f = fopen(path, "r");
    if (!f) {
        str_fmt(err, errlen, "%s: %s", path, strerror(errno));
        return -1;
    }
    char line[512];
    int lineno = 0, rc = 0;
    while (fgets(line, sizeof line, f)) {
        lineno++;
        size_t len = strlen(line);
        if (len == sizeof line - 1 && line[len - 1] != '\n') { /* only the first word counts: skip the rest */
            int ch;
            while ((ch = fgetc(f)) != EOF && ch != '\n')
                ;
        }
        char *p = line;
        while (isspace((unsigned char)*p))
            p++;
        if (*p == '#' || *p == '\0')
            continue;
        size_t n = 0;
        while (p[n] && !isspace((unsigned char)p[n]))
            n++;
        if (!key_is_z85(p, n)) {
            str_fmt(err, errlen, "%s:%d: not a 40-character Z85 CurveZMQ key", path, lineno);
            rc = -1;
            break;
        }
        if (fn(ctx, p, n, lineno) < 0)
            break;
    }
    fclose(f);
    return rc;
}

struct key_acc { struct net_key *keys; size_t count, cap, max; };

static int key_acc_add(void *ctx, const char *s, size_t n, int lineno)
{
    (void)lineno;
    struct key_acc *a = ctx;
    if (a->max && a->count >= a->max)
        return -1;
    mem_grow((void **)&a->keys, &a->cap, a->count + 1, sizeof *a->keys);
    memcpy(a->keys[a->count].z85, s, n);
    a->keys[a->count].z85[n] = '\0';
    a->count++;
    return 0;
}

int net_key_pair_load(const char *path, struct net_key *public_key, struct net_key *secret_key, char *err, size_t errlen)
{
    struct key_acc a = {.max = 2};
    if (key_lines(path, key_acc_add, &a, err, errlen) != 0) {
        free(a.keys);
        return -1;
    }
    if (a.count != 2) {
        free(a.keys);
        str_fmt(err, errlen, "%s: a key pair file holds a public and a secret key (see brume-keygen)", path);
        return -1;
    }
    *public_key = a.keys[0];
    *secret_key = a.keys[1];
    free(a.keys);
    /* The public key must belong to the secret one, or peers would reject us cryptically. */
    char derived[NET_Z85_KEY_LEN + 1];
    if (zmq_curve_public(derived, secret_key->z85) != 0 || strcmp(derived, public_key->z85) != 0) {
        str_fmt(err, errlen, "%s: the public key does not match the secret key", path);
        return -1;
    }
    return 0;
}

int net_key_public_load(const char *path, struct net_key *public_key, char *err, size_t errlen)
{
    struct key_acc a = {.max = 1};
    int rc = key_lines(path, key_acc_add, &a, err, errlen);
    if (rc == 0 && a.count == 0) {
        str_fmt(err, errlen, "%s: no public key in the file", path);
        rc = -1;
    }
    if (rc == 0)
        *public_key = a.keys[0];
    free(a.keys);
    return rc;
}

int net_key_list_load(const char *path, struct net_key **keys, size_t *count, char *err, size_t errlen)
{
    struct key_acc a = {0};
    if (key_lines(path, key_acc_add, &a, err, errlen) != 0) {
        free(a.keys);
        return -1;
    }
    *keys = a.keys;
    *count = a.count;
    return 0;
}

int net_key_pair_write(const char *path, char *err, size_t errlen)
{
    char pub[NET_Z85_KEY_LEN + 1], sec[NET_Z85_KEY_LEN + 1];
    if (zmq_curve_keypair(pub, sec) != 0) {
        str_fmt(err, errlen, "cannot create a key pair: %s (libzmq without CURVE?)", zmq_strerror(errno));
        return -1;
    }
    char pub_path[4200];
    snprintf(pub_path, sizeof pub_path, "%s.pub", path);
    int fd = open(path, O_WRONLY | O_CREAT | O_EXCL, 0600);
    if (fd < 0) {
        str_fmt(err, errlen, "%s: %s", path, strerror(errno));
        return -1;
    }
    char text[256];
    int n = snprintf(text, sizeof text, "# brume CurveZMQ key pair: public, then secret. Keep this file private.\n%s\n%s\n",
                     pub, sec);
    if (write(fd, text, (size_t)n) != n || fsync(fd) != 0) {
        str_fmt(err, errlen, "%s: %s", path, strerror(errno));
        close(fd);
        unlink(path);
        return -1;
    }
    close(fd);
    FILE *f = fopen(pub_path, "w");
    if (!f || fprintf(f, "%s\n", pub) < 0 || fclose(f) != 0) {
        str_fmt(err, errlen, "%s: %s", pub_path, strerror(errno));
        return -1;
    }
    return 0;
}

int net_curve_client(void *sock, const struct net_key *server_public, const struct net_key *our_public,
                     const struct net_key *our_secret)
{
    if (zmq_setsockopt(sock, ZMQ_CURVE_SERVERKEY, server_public->z85, NET_Z85_KEY_LEN) != 0 ||
        zmq_setsockopt(sock, ZMQ_CURVE_PUBLICKEY, our_public->z85, NET_Z85_KEY_LEN) != 0 ||
        zmq_setsockopt(sock, ZMQ_CURVE_SECRETKEY, our_secret->z85, NET_Z85_KEY_LEN) != 0)
        return -1;
    return 0;
}

int net_curve_server(void *sock, const struct net_key *our_secret)
{
    int one = 1;
    if (zmq_setsockopt(sock, ZMQ_CURVE_SERVER, &one, sizeof one) != 0 ||
        zmq_setsockopt(sock, ZMQ_CURVE_SECRETKEY, our_secret->z85, NET_Z85_KEY_LEN) != 0 ||
        zmq_setsockopt(sock, ZMQ_ZAP_DOMAIN, "brume", 5) != 0 ||
        zmq_setsockopt(sock, ZMQ_HANDSHAKE_IVL, &(int){NET_HANDSHAKE_MS}, sizeof(int)) != 0)
        return -1;
    return 0;
}

int net_endpoint_is_tcp(const char *e)
{
    return !strncmp(e, "tcp://", 6);
}

int net_endpoint_is_local(const char *e)
{
    if (!strncmp(e, "ipc://", 6) || !strncmp(e, "inproc://", 9))
        return 1;
    if (strncmp(e, "tcp://", 6) != 0)
        return 0;
    e += 6;
    return !strncmp(e, "127.", 4) || !strncmp(e, "localhost:", 10) || !strncmp(e, "[::1]:", 6);
}

int net_bcast_endpoint(const char *endpoint, uint16_t bcast_port, char *out, size_t outlen)
{
    int n;
    if (!strncmp(endpoint, "ipc://", 6)) {
        n = snprintf(out, outlen, "%s.bcast", endpoint);
    } else if (!strncmp(endpoint, "tcp://", 6)) {
        const char *colon = strrchr(endpoint + 6, ':');
        if (!colon)
            return -1;
        int host_len = (int)(colon - endpoint);
        n = bcast_port ? snprintf(out, outlen, "%.*s:%u", host_len, endpoint, (unsigned)bcast_port)
                       : snprintf(out, outlen, "%.*s:*", host_len, endpoint);
    } else {
        return -1;
    }
    return n < 0 || (size_t)n >= outlen ? -1 : 0;
}

uint16_t net_endpoint_port(const char *endpoint)
{
    if (strncmp(endpoint, "tcp://", 6) != 0)
        return 0;
    const char *colon = strrchr(endpoint + 6, ':');
    if (!colon || !colon[1])
        return 0;
    char *end;
    unsigned long v = strtoul(colon + 1, &end, 10);
    return *end == '\0' && v > 0 && v <= 65535 ? (uint16_t)v : 0;
}
