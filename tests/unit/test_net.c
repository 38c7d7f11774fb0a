/* Unit tests for receiving messages (common/wire/net.c): a payload taken from its frame
 * holds its bytes intact while later messages arrive, at sizes on both sides of the
 * 8 KiB below which net_recv copies; a malformed envelope is dropped and the next message
 * still arrives. Over tcp on loopback, where libzmq receives into shared batches. */
#include <criterion/criterion.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <zmq.h>
#include "wire/net.h"

static uint8_t pattern(size_t msg, size_t i)
{
    return (uint8_t)(msg * 131u + i * 7u + (i >> 8));
}

/* A ROUTER bound on a loopback port and a DEALER connected to it. */
static void pair(void **ctx, void **router, void **dealer)
{
    *ctx = zmq_ctx_new();
    *router = zmq_socket(*ctx, ZMQ_ROUTER);
    *dealer = zmq_socket(*ctx, ZMQ_DEALER);
    cr_assert(*ctx && *router && *dealer);
    net_socket_setup(*router);
    net_socket_setup(*dealer);
    cr_assert_eq(zmq_bind(*router, "tcp://127.0.0.1:*"), 0);
    char ep[256];
    size_t len = sizeof ep;
    cr_assert_eq(zmq_getsockopt(*router, ZMQ_LAST_ENDPOINT, ep, &len), 0);
    cr_assert_eq(zmq_connect(*dealer, ep), 0);
}

/* Waits for and receives one message (1, 0 or -1 as net_recv). */
static int recv_one(void *router, struct net_frame *f)
{
    zmq_pollitem_t it = {router, 0, ZMQ_POLLIN, 0};
    cr_assert(zmq_poll(&it, 1, 5000) == 1, "nothing arrived");
    return net_recv(router, 1, f);
}

Test(net, taken_payloads_stay_intact_while_more_arrive, .timeout = 30)
{
    void *ctx, *router, *dealer;
    pair(&ctx, &router, &dealer);
    static const size_t sizes[] = {1, 40, 3000, 8191, 8192, 20000, 2000, 100000, 5000, 9000};
    enum { N = sizeof sizes / sizeof sizes[0] };
    for (size_t k = 0; k < N; k++) {
        uint8_t *buf = malloc(sizes[k]);
        for (size_t i = 0; i < sizes[k]; i++)
            buf[i] = pattern(k, i);
        cr_assert_eq(zmq_send(dealer, buf, sizes[k], 0), (int)sizes[k]);
        free(buf);
    }
    struct net_payload *held[N];
    for (size_t k = 0; k < N; k++) {
        struct net_frame f;
        cr_assert_eq(recv_one(router, &f), 1);
        cr_assert_gt(f.id_len, 0);
        cr_assert_eq(f.size, sizes[k]);
        cr_assert_eq(f.data, net_payload_data(f.payload));
        held[k] = net_frame_take(&f);
        cr_assert_null(f.payload);
        net_frame_fini(&f); /* nothing left to free: the payload is ours */
    }
    for (size_t k = 0; k < N; k++) {
        const uint8_t *d = net_payload_data(held[k]);
        for (size_t i = 0; i < sizes[k]; i++)
            cr_assert_eq(d[i], pattern(k, i), "message %zu byte %zu", k, i);
        net_payload_free(&held[k]);
        cr_assert_null(held[k]);
    }
    zmq_close(dealer);
    zmq_close(router);
    zmq_ctx_term(ctx);
}

Test(net, malformed_envelope_dropped, .timeout = 30)
{
    void *ctx, *router, *dealer;
    pair(&ctx, &router, &dealer);
    cr_assert_eq(zmq_send(dealer, "ab", 2, ZMQ_SNDMORE), 2); /* two frames: not ours */
    cr_assert_eq(zmq_send(dealer, "cd", 2, 0), 2);
    cr_assert_eq(zmq_send(dealer, "ok", 2, 0), 2);
    struct net_frame f;
    cr_assert_eq(recv_one(router, &f), -1);
    cr_assert_null(f.payload);
    cr_assert_eq(recv_one(router, &f), 1);
    cr_assert_eq(f.size, 2);
    cr_assert_eq(memcmp(f.data, "ok", 2), 0);
    net_frame_fini(&f);
    cr_assert_null(f.payload);
    zmq_close(dealer);
    zmq_close(router);
    zmq_ctx_term(ctx);
}

/* An allow-list line is a key and an optional name: a name longer than the reader's line
 * buffer is skipped with its line, not read as a next line holding no key. */
Test(net, allow_list_long_name)
{
    char path[] = "/tmp/brume-test-allow-XXXXXX", err[256];
    int fd = mkstemp(path);
    cr_assert(fd >= 0);
    FILE *f = fdopen(fd, "w");
    cr_assert(f != NULL);
    char pub[41], sec[41];
    cr_assert_eq(zmq_curve_keypair(pub, sec), 0);
    fprintf(f, "# workers\n%s ", pub);
    for (int i = 0; i < 2000; i++)
        fputc('n', f);
    fprintf(f, "\n%s second\n", pub);
    fclose(f);
    struct net_key *keys = NULL;
    size_t n = 0;
    int rc = net_key_list_load(path, &keys, &n, err, sizeof err);
    unlink(path);
    cr_assert_eq(rc, 0, "%s", err);
    cr_expect_eq(n, 2);
    free(keys);
}
