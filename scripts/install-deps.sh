#!/bin/sh
# Installs the Debian packages named on the command line that are not installed yet.
# Called by the Makefile once per build folder; uses sudo when not root.
missing=""
for p in "$@"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
[ -z "$missing" ] && exit 0
echo "installing Debian packages:$missing" >&2
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
log=$(mktemp /tmp/brume-apt.XXXXXX)
if ! { $SUDO apt-get update -qq && $SUDO apt-get install -y -qq $missing; } >"$log" 2>&1; then
  tail -20 "$log" >&2
  echo "install-deps: apt-get install failed for:$missing (full log: $log)" >&2
  exit 1
fi
rm -f "$log"
