#!/bin/sh
# Launching workers over ssh (scripts/ssh-workers.sh). The command construction is checked
# on a hosts file (threads, ports, per-host keys, quoting, bad lines); then, when
# /usr/sbin/sshd exists, a private sshd on a spare loopback port with a throw-away host key
# and client key accepts the launcher's two workers, which render (with CurveZMQ) the
# same pixels as a local worker. Without sshd that part is skipped, saying why.
# Ends with "integration: N passed, N failed". Usage: BUILD=build sh tests/integration/ssh.sh
. "$(dirname "$0")/lib.sh"
lib_init ssh
S=scripts/ssh-workers.sh
BAD_LOGS="log launch sshd.log"
BAD_TAIL=15
cleanup() {
  [ -f "$T/sshd.pid" ] && kill "$(cat "$T/sshd.pid")" 2>/dev/null
  lib_cleanup
}
# long enough (a few seconds) for both workers to join before the frame is done
SCENE=scenes/cornell/cornell.json
ARGS="--spp 8 --tile 32"
WABS=$(cd "$(dirname "$BUILD/worker")" && pwd)/worker

# --- command construction ---
cat >"$T/hosts" <<EOF
# workers for the test
alice@node1 8
node2:2222 4 ssh_key=/keys/n2 curve_secret=/etc/brume/w.key

bob@node3
EOF
sh $S --hosts "$T/hosts" --connect "tcp://m:5555" --worker /opt/brume/worker --server-key "/etc/brume/it's.pub" \
  --curve-secret /etc/brume/default.key --ssh-opt "-o ConnectTimeout=5" --timeout-ms 60000 --dry-run >"$T/cmds" 2>"$T/log"
r=$?
l1=$(sed -n 1p "$T/cmds"); l2=$(sed -n 2p "$T/cmds"); l3=$(sed -n 3p "$T/cmds")
# what the remote shell receives: the last word of each command, unquoted once
remote() { eval "set -- $1"; eval "echo \"\${$#}\""; }
if [ $r = 0 ] && [ "$(wc -l <"$T/cmds")" = 3 ] &&
  [ "$(remote "$l1")" = "exec '/opt/brume/worker' --connect 'tcp://m:5555' --threads 8 --timeout-ms 60000 --curve-secret '/etc/brume/default.key' --server-key '/etc/brume/it'\\''s.pub'" ] &&
  echo "$l2" | grep -q -- "-p '2222' -i '/keys/n2'" && [ "$(eval "set -- $l2"; eval "echo \"\${$(($# - 1))}\"")" = node2 ] &&
  remote "$l2" | grep -q -- "--threads 4 --timeout-ms 60000 --curve-secret '/etc/brume/w.key'" &&
  echo "$l3" | grep -q "'bob@node3'" && ! remote "$l3" | grep -q -- "--threads"; then
  ok "ssh-workers.sh: one ssh command per host line, with threads, port, per-host ssh and CurveZMQ keys, quoted"
else sed 's/^/    /' "$T/cmds"; bad "ssh-workers.sh: one ssh command per host line, with threads, port, per-host ssh and CurveZMQ keys, quoted"; fi

printf 'node1 0\n' >"$T/bad1"; printf 'node1 4 colour=blue\n' >"$T/bad2"; printf 'node1 curve_secret=/w.key\n' >"$T/bad3"
r=0
for b in bad1 bad2 bad3; do
  sh $S --hosts "$T/$b" --connect tcp://m:1 >"$T/out" 2>&1 && r=1
  grep -q "$T/$b:1: " "$T/out" || r=1
done
sh $S --connect tcp://m:1 >"$T/out" 2>&1 && r=1
if [ $r = 0 ]; then ok "ssh-workers.sh: bad host lines and missing options are refused with file:line, nothing started"
else cat "$T/out" >"$T/log"; bad "ssh-workers.sh: bad host lines and missing options are refused with file:line, nothing started"; fi

# --- live: a private sshd on loopback ---
SSHD=/usr/sbin/sshd
why=""
[ -x $SSHD ] || why="$SSHD not installed (apt-get install openssh-server)"
command -v ssh-keygen >/dev/null 2>&1 || why="${why:-ssh-keygen not installed}"
if [ -z "$why" ]; then
  SP=$(free_port)
  P=$(free_port)
  ssh-keygen -q -t ed25519 -N '' -f "$T/host_key" && ssh-keygen -q -t ed25519 -N '' -f "$T/client_key" &&
    cp "$T/client_key.pub" "$T/authorized_keys"
  chmod 700 "$T"
  cat >"$T/sshd_config" <<EOF
Port $SP
ListenAddress 127.0.0.1
HostKey $T/host_key
AuthorizedKeysFile $T/authorized_keys
PasswordAuthentication no
KbdInteractiveAuthentication no
UsePAM no
StrictModes no
PermitRootLogin prohibit-password
PidFile $T/sshd.pid
EOF
  [ "$(id -u)" = 0 ] && mkdir -p /run/sshd
  $SSHD -f "$T/sshd_config" -E "$T/sshd.log" 2>>"$T/sshd.log" || why="sshd does not start: $(tail -1 "$T/sshd.log")"
  i=0
  while [ -z "$why" ] && ! ssh -o BatchMode=yes -o StrictHostKeyChecking=no -o UserKnownHostsFile=/dev/null -o LogLevel=ERROR \
      -i "$T/client_key" -p $SP 127.0.0.1 true 2>"$T/sshtry"; do
    i=$((i + 1)); [ $i -ge 30 ] && why="cannot log in to the test sshd: $(tail -1 "$T/sshtry")"; sleep 0.2
  done
fi
if [ -n "$why" ]; then
  echo "skip: ssh launch against a live sshd ($why)"
else
  timeout 60 $M $SCENE -o "$T/ref.exr" --workers 1 $ARGS >"$T/log" 2>&1 || bad "reference render"
  # throw-away keys for the run: the workers get theirs over ssh (--keys)
  BRUME_BIN=$(dirname "$WABS") sh $S --make-keys "$T/keys" >/dev/null || bad "ssh-workers.sh --make-keys"
  printf '%s@127.0.0.1:%s 1\n127.0.0.1:%s 1 ssh_key=%s\n' "$(id -un)" $SP $SP "$T/client_key" >"$T/hosts"
  # The workers start first and connect before the master binds (ZeroMQ retries): a render
  # of a few seconds would otherwise finish before a slow ssh login brings the second one.
  timeout 90 sh $S --hosts "$T/hosts" --connect "tcp://127.0.0.1:$P" --worker "$WABS" --ssh-key "$T/client_key" \
    --keys "$T/keys" --timeout-ms 20000 --log-dir "$T/wlogs" \
    --ssh-opt "-o StrictHostKeyChecking=no" --ssh-opt "-o UserKnownHostsFile=/dev/null" --ssh-opt "-o LogLevel=ERROR" >"$T/launch" 2>&1 &
  spid=$!
  i=0
  while [ "$(pgrep -f -c -- "$WABS.*127.0.0.1:$P" 2>/dev/null)" -lt 2 ] && [ $i -lt 150 ]; do
    i=$((i + 1)); sleep 0.2
  done
  timeout 60 $M $SCENE -o "$T/ssh.exr" $ARGS --workers 0 --bind "tcp://127.0.0.1:$P" \
    --curve-secret "$T/keys/master.key" --allow "$T/keys/allow" >"$T/log" 2>&1 &
  mpid=$!
  echo "$mpid $spid" >"$T/pids"
  wait $spid
  sr=$?
  wait $mpid && r=0 || r=1
  echo "ssh: 2 workers over ssh to 127.0.0.1:$SP; workers joined $(counter workers_joined "$T/ssh.exr"); tiles per worker: $(grep -c 'summary: worker' "$T/log") workers listed"
  if [ $r = 0 ] && [ $sr = 0 ] && [ "$(counter workers_joined "$T/ssh.exr")" = 2 ] && [ "$(counter auth_rejects "$T/ssh.exr")" = 0 ] &&
    grep -q "2 worker(s) done, 0 failed" "$T/launch" && $X cmp "$T/ref.exr" "$T/ssh.exr" >/dev/null; then
    ok "ssh-workers.sh against a live sshd: 2 workers over ssh with throw-away CurveZMQ keys sent over ssh, identical pixels"
  else cat "$T"/wlogs/* >>"$T/launch" 2>/dev/null; bad "ssh-workers.sh against a live sshd: 2 workers over ssh with throw-away CurveZMQ keys sent over ssh, identical pixels"; fi
fi

finish
