#!/bin/sh
# Starts brume workers on a list of hosts over ssh, one worker per line of the hosts file,
# and waits for them (each exits when the master says BYE, or gives up when the master
# stays silent for --timeout-ms). Exit status: 0 when every worker exited 0, else 1.
#
# usage: scripts/ssh-workers.sh --make-keys DIR
#          throw-away CurveZMQ keys for one run in DIR (0700): master.key (give the master
#          --curve-secret DIR/master.key --allow DIR/allow), worker.key, allow; then exit
#        scripts/ssh-workers.sh --hosts FILE --connect ENDPOINT [options]
#   --hosts FILE        one worker per line:  HOST [THREADS] [ssh_key=FILE] [curve_secret=FILE]
#                       HOST may be user@host or user@host:port; THREADS defaults to the
#                       host's cores; ssh_key is a local identity file for that host;
#                       curve_secret is the worker's CurveZMQ key pair ON THAT HOST.
#                       Blank lines and lines starting with '#' are ignored.
#   --connect ENDPOINT  the master's endpoint as the workers see it (tcp://master:5555)
#   --worker PATH       the worker binary on the hosts (default: this checkout's build/worker)
#   --server-key FILE   the master's public key on the hosts (with curve_secret)
#   --curve-secret FILE default curve_secret for hosts whose line has none
#   --keys DIR          keys made by --make-keys: each host without a curve_secret gets
#                       DIR's worker key pair and the master's public key over ssh (stdin),
#                       in a private folder removed when the worker exits
#   --ssh-key FILE      default identity file for hosts whose line has none
#   --ssh-opt OPT       an extra ssh option (repeatable), e.g. --ssh-opt "-o ConnectTimeout=5"
#   --timeout-ms MS     passed to the workers (give up after MS ms without the master)
#   --log-dir DIR       one log per worker: DIR/N-HOST.log (default: a new /tmp folder)
#   --dry-run           print the ssh commands, one per line, and exit
#
# Example:  scripts/ssh-workers.sh --make-keys /tmp/run1
#           master scene.json -o out.exr --workers 0 --bind tcp://0.0.0.0:5555 \
#               --curve-secret /tmp/run1/master.key --allow /tmp/run1/allow &
#           scripts/ssh-workers.sh --hosts hosts.txt --connect tcp://$(hostname):5555 --keys /tmp/run1
set -u
here=$(cd "$(dirname "$0")/.." && pwd)
hosts="" connect="" worker="$here/build/worker" server_key="" def_curve="" def_key="" timeout_ms=""
log_dir="" dry=0 ssh_opts="" keys=""

die() { echo "ssh-workers: $*" >&2; exit 2; }
# Quotes one word for a POSIX shell (the remote side runs the command through one).
q() { printf "'%s'" "$(printf %s "$1" | sed "s/'/'\\\\''/g")"; }

while [ $# -gt 0 ]; do
  case "$1" in
    --hosts) [ $# -ge 2 ] || die "--hosts needs a file"; hosts=$2; shift 2 ;;
    --connect) [ $# -ge 2 ] || die "--connect needs an endpoint"; connect=$2; shift 2 ;;
    --worker) [ $# -ge 2 ] || die "--worker needs a path"; worker=$2; shift 2 ;;
    --server-key) [ $# -ge 2 ] || die "--server-key needs a file"; server_key=$2; shift 2 ;;
    --curve-secret) [ $# -ge 2 ] || die "--curve-secret needs a file"; def_curve=$2; shift 2 ;;
    --ssh-key) [ $# -ge 2 ] || die "--ssh-key needs a file"; def_key=$2; shift 2 ;;
    --keys) [ $# -ge 2 ] || die "--keys needs a folder"; keys=$2; shift 2 ;;
    --make-keys)
      [ $# -ge 2 ] || die "--make-keys needs a folder"
      m="${BRUME_BIN:-$here/build}/master"
      [ -x "$m" ] || die "$m: no master binary (set BRUME_BIN)"
      (umask 077 && mkdir -p "$2") || die "$2: cannot create the folder"
      chmod 700 "$2" && "$m" --keygen "$2/master.key" >/dev/null && "$m" --keygen "$2/worker.key" >/dev/null &&
        cp "$2/worker.key.pub" "$2/allow" || die "$2: cannot make the keys"
      echo "ssh-workers: keys in $2: give the master --curve-secret $2/master.key --allow $2/allow, and this script --keys $2"
      exit 0 ;;
    --ssh-opt) [ $# -ge 2 ] || die "--ssh-opt needs an option"; ssh_opts="$ssh_opts $2"; shift 2 ;;
    --timeout-ms) [ $# -ge 2 ] || die "--timeout-ms needs a number"; timeout_ms=$2; shift 2 ;;
    --log-dir) [ $# -ge 2 ] || die "--log-dir needs a folder"; log_dir=$2; shift 2 ;;
    --dry-run) dry=1; shift ;;
    -h|--help) sed -n '2,33p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) die "unknown option \"$1\" (see --help)" ;;
  esac
done
[ -n "$hosts" ] || die "--hosts FILE is required"
[ -r "$hosts" ] || die "$hosts: cannot read the hosts file"
[ -n "$connect" ] || die "--connect ENDPOINT is required"
case "$timeout_ms" in ""|*[!0-9]*) [ -z "$timeout_ms" ] || die "--timeout-ms: \"$timeout_ms\" is not a number" ;; esac
if [ -n "$keys" ]; then
  [ -r "$keys/worker.key" ] && [ -r "$keys/master.key.pub" ] || die "--keys $keys: no worker.key and master.key.pub there (see --make-keys)"
fi

# Builds the ssh command line of one hosts-file line into $cmd (words already quoted for
# `eval`); 1 for a line to skip, 2 for an error (message printed).
build_cmd() {
  line=$1 lineno=$2
  set -- $line
  [ $# -ge 1 ] || return 1
  case "$1" in \#*) return 1 ;; esac
  host=$1; shift
  threads="" key=$def_key curve=$def_curve
  if [ $# -ge 1 ] && [ -n "$1" ] && [ -z "$(printf %s "$1" | tr -d 0-9)" ]; then threads=$1; shift; fi
  for kv in "$@"; do
    case "$kv" in
      ssh_key=*) key=${kv#ssh_key=} ;;
      curve_secret=*) curve=${kv#curve_secret=} ;;
      *) echo "ssh-workers: $hosts:$lineno: unknown field \"$kv\" (THREADS, ssh_key=FILE, curve_secret=FILE)" >&2; return 2 ;;
    esac
  done
  port=""
  case "$host" in *:*) port=${host##*:}; host=${host%:*} ;; esac
  [ -n "$threads" ] && [ "$threads" -eq 0 ] && { echo "ssh-workers: $hosts:$lineno: THREADS must be at least 1" >&2; return 2; }
  if [ -n "$curve" ] && [ -z "$server_key" ]; then
    echo "ssh-workers: $hosts:$lineno: curve_secret needs --server-key (the master's public key)" >&2; return 2
  fi
  remote="$(q "$worker") --connect $(q "$connect")"
  [ -n "$threads" ] && remote="$remote --threads $threads"
  [ -n "$timeout_ms" ] && remote="$remote --timeout-ms $timeout_ms"
  feed=0
  if [ -n "$curve" ]; then
    remote="exec $remote --curve-secret $(q "$curve") --server-key $(q "$server_key")"
  elif [ -n "$keys" ]; then
    # the key pair and the master's public key arrive on stdin (3 lines), into a 0700 folder
    feed=1
    w=$remote
    remote="umask 077; d=\$(mktemp -d) || exit 1; IFS= read -r a && IFS= read -r b && IFS= read -r c &&"
    remote="$remote { echo \"\$a\"; echo \"\$b\"; } >\"\$d/w.key\" && echo \"\$c\" >\"\$d/m.pub\" ||"
    remote="$remote { rm -rf \"\$d\"; exit 1; }; $w --curve-secret \"\$d/w.key\" --server-key \"\$d/m.pub\";"
    remote="$remote r=\$?; rm -rf \"\$d\"; exit \$r"
  else
    remote="exec $remote"
  fi
  cmd="ssh -o BatchMode=yes"
  [ -n "$port" ] && cmd="$cmd -p $(q "$port")"
  [ -n "$key" ] && cmd="$cmd -i $(q "$key")"
  cmd="$cmd$ssh_opts $(q "$host") $(q "$remote")"
  label=$host
  return 0
}

# First every line is checked, so that a typo starts nothing (and leaves no log folder).
lineno=0 errors=0 valid=0
while IFS= read -r line || [ -n "$line" ]; do
  lineno=$((lineno + 1))
  build_cmd "$line" "$lineno"
  case $? in 0) valid=$((valid + 1)) ;; 2) errors=$((errors + 1)) ;; esac
done <"$hosts"
[ $errors = 0 ] || die "$errors bad line(s) in $hosts; nothing started"
[ $valid -gt 0 ] || die "$hosts: no hosts"
if [ $dry = 0 ]; then
  [ -n "$log_dir" ] || log_dir=$(mktemp -d /tmp/brume-ssh.XXXXXX)
  mkdir -p "$log_dir" || die "$log_dir: cannot create the log folder"
  if [ -n "$keys" ]; then
    # what a host without a curve_secret reads on stdin: its key pair, the master's key
    feed_file="$log_dir/.keys"
    (umask 077 && grep -hv '^#' "$keys/worker.key" "$keys/master.key.pub" >"$feed_file") || die "$feed_file: cannot write"
  fi
fi
pids="" n=0 lineno=0
while IFS= read -r line || [ -n "$line" ]; do
  lineno=$((lineno + 1))
  build_cmd "$line" "$lineno"
  [ $? = 0 ] || continue
  n=$((n + 1))
  if [ $dry = 1 ]; then echo "$cmd"; continue; fi
  log="$log_dir/$n-$(printf %s "$label" | tr -c 'A-Za-z0-9._-' _).log"
  if [ $feed = 1 ]; then eval "$cmd" <"$feed_file" >"$log" 2>&1 & else eval "$cmd" </dev/null >"$log" 2>&1 & fi
  pids="$pids $!"
  echo "ssh-workers: worker $n on $label started (log: $log)"
done <"$hosts"
[ $n -gt 0 ] || die "$hosts: no hosts"
[ $dry = 1 ] && exit 0
trap 'kill $pids 2>/dev/null' INT TERM
failed=0
i=0
for p in $pids; do
  i=$((i + 1))
  if ! wait "$p"; then failed=$((failed + 1)); echo "ssh-workers: worker $i failed (see $log_dir)" >&2; fi
done
[ -n "$keys" ] && rm -f "$feed_file"
echo "ssh-workers: $n worker(s) done, $failed failed"
[ $failed = 0 ]
