/* Keeping strangers out: CurveZMQ on the master's ROUTER socket and its blob broadcast
 * with a ZAP handler (RFC 27) that admits only allow-listed worker public keys, and socket
 * monitors that count handshakes failing before ZAP. Invariant: the handler is bound
 * before the sockets bind or connect, so no peer is ever admitted unchecked. Called by
 * master/master.c, which polls zap_socket and the monitor sockets and calls
 * zap_handle/zap_monitor_drain. */
#ifndef BRUME_ZAP_H
#define BRUME_ZAP_H
#include <stddef.h>
#include "wire/net.h"

struct zap;

/* Turns CurveZMQ on for sock (server side, the master's secret key); nobody is admitted
 * until keys are allowed (zap_allow_key, zap_allow_file). NULL with the reason on failure.
 * An admitted peer's messages carry its public key as User-Id (net_frame.user_id). */
struct zap *zap_new(void *zctx, void *sock, const struct net_key *secret, char *err, size_t errlen);
/* Admits the keys listed in allow_path. 0, or -1 with the reason (file and line). */
int zap_allow_file(struct zap *z, const char *allow_path, char *err, size_t errlen);
void zap_free(struct zap **zp);
size_t zap_num_allowed(const struct zap *z);
void zap_allow_key(struct zap *z, const struct net_key *k);
/* A fresh key pair for the master's own local workers at key_path (+ ".pub") and the
 * master's public key at pub_path, both in the private socket folder; *local_public is
 * the workers' public key, to be allowed. 0, or -1 with the reason. */
int zap_write_local_keys(const char *key_path, const char *pub_path, const struct net_key *master_public,
                         struct net_key *local_public, char *err, size_t errlen);
void *zap_socket(const struct zap *z);
void *zap_monitor_socket(const struct zap *z); /* NULL when the monitor could not start */
/* Counts the failed handshakes of a second CURVE socket (the blob broadcast) too: its
 * monitor is zap_monitor2_socket (NULL before or when it could not start). 0 or -1. */
int zap_watch(struct zap *z, void *zctx, void *sock);
void *zap_monitor2_socket(const struct zap *z);
/* Answers one ZAP request; 1 when it refused a key (the first few are logged), else 0. */
int zap_handle(struct zap *z);
/* Reads the monitors' events; the handshakes that failed before ZAP (those refused by ZAP
 * are counted by zap_handle). */
unsigned zap_monitor_drain(struct zap *z);

#endif
