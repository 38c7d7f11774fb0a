# The integration scripts' shared set-up, sourced by each: the binaries, a private temp
# folder, pass / fail counting and the helpers they all use.
#   lib_init NAME   T = a new /tmp/brume-NAME.XXXXXX; on exit `cleanup` runs: it kills
#                   this script's own processes (pids in $T/pids whose command lines name
#                   $T, so a pid reused by someone else's process is never hit) and
#                   removes $T (kept when KEEP_T is set). A script may redefine cleanup,
#                   calling lib_cleanup at its end (kill_ours kills without removing).
#   ok / bad MSG    count a check; bad prints the tails of $BAD_LOGS (files in $T).
#   run CMD...      CMD with a timeout (TMO, default 120 s), output in $T/log.
#   counter NAME OUT    a master counter, from OUT.stats.json (OUT as given to -o);
#                   empty when the file or the counter is missing.
#   free_port       a TCP port on 127.0.0.1 that nothing listens on now (the kernel's pick
#                   for a bind to port 0), so scripts running side by side do not collide.
#   finish          the closing line "integration: N passed, N failed"; fails if any did.
set -u
BUILD=${BUILD:-build}
M=$BUILD/master
W=$BUILD/worker
X=$BUILD/exrtool
pass=0
fail=0
BAD_LOGS=log
BAD_TAIL=25
ok() { pass=$((pass + 1)); echo "ok: $1"; }
bad() {
  fail=$((fail + 1))
  echo "FAIL: $1"
  for f in $BAD_LOGS; do [ -s "$T/$f" ] && { echo "  $f:"; sed 's/^/    /' "$T/$f" | tail -"$BAD_TAIL"; }; done
  return 0
}
free_port() { python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
run() { timeout "${TMO:-120}" "$@" >"$T/log" 2>&1; }
counter() {
  python3 -c 'import json, sys
try: print(json.load(open(sys.argv[1] + ".stats.json"))["counters"][sys.argv[2]])
except (OSError, ValueError, KeyError): pass' "$2" "$1"
}
ours() { tr '\0' ' ' 2>/dev/null <"/proc/$1/cmdline" | grep -q "$T"; }
# kill_when PID TRIES PAUSE CMD...: runs CMD every PAUSE s until it succeeds (at most TRIES
# times), then kills PID with SIGKILL and reaps it (a master killed mid-render).
kill_when() {
  kw_pid=$1 kw_tries=$2 kw_pause=$3
  shift 3
  kw_i=0
  while [ $kw_i -lt "$kw_tries" ] && ! "$@"; do sleep "$kw_pause"; kw_i=$((kw_i + 1)); done
  kill -9 "$kw_pid" 2>/dev/null
  wait "$kw_pid" 2>/dev/null
}
kill_ours() { for p in $(cat "$T/pids" 2>/dev/null); do ours "$p" && { kill -CONT "$p"; kill -9 "$p"; } 2>/dev/null; done; }
lib_cleanup() {
  kill_ours
  [ -n "${KEEP_T:-}" ] || rm -rf "$T"
}
cleanup() { lib_cleanup; }
lib_init() {
  T=$(mktemp -d "/tmp/brume-$1.XXXXXX")
  trap cleanup EXIT
  # Masters put their local socket folders in $TMPDIR: a killed one leaves it inside $T.
  TMPDIR=$T
  export TMPDIR
}
finish() {
  echo "integration: $pass passed, $fail failed"
  [ "$fail" = 0 ]
}
