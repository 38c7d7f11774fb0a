# Shared by the bench scripts (scripts/bench*.sh), sourced after `set -eu`:
#   . scripts/lib.sh; bench_init NAME [DEBIAN_PACKAGE...]
# Sets BUILD (env, default build), CORES, OUT (bench-out/, where tables and plots go) and T
# (a temporary folder, removed on exit). Helpers that run a render keep its output in
# $T/log and, when it fails, show it and end the script.
BUILD=${BUILD:-build}
CORES=$(nproc)
OUT=bench-out

# bench_init NAME [PACKAGE...]: installs what is missing, makes $OUT and $T.
bench_init() {
  T=$(mktemp -d "/tmp/brume-$1.XXXXXX")
  trap 'rm -rf "$T"' EXIT
  shift
  [ $# -eq 0 ] || sh scripts/install-deps.sh "$@"
  mkdir -p "$OUT"
}

# free_port: a TCP port on 127.0.0.1 that nothing listens on now (the kernel's pick for a
# bind to port 0, as tests/integration/lib.sh's), so runs side by side do not collide.
free_port() { python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }

# logged CMD...: runs CMD with its output in $T/log; on failure shows the log and exits.
logged() {
  "$@" >"$T/log" 2>&1 || { cat "$T/log" >&2; echo "bench: command failed: $*" >&2; exit 1; }
}

# cpu_secs CMD...: CPU seconds (user + system, children included) of one logged run. On a
# shared, noisy machine CPU time is steadier than wall time for renders that keep every
# thread busy.
cpu_secs() {
  logged /usr/bin/time -f "cpu %U %S" -o "$T/cpu" "$@"
  awk '/^cpu/ {print $2 + $3}' "$T/cpu"
}

# wall_secs CMD...: wall seconds of one logged run, process start included.
wall_secs() {
  s=$(date +%s.%N)
  logged "$@"
  e=$(date +%s.%N)
  echo "$e - $s" | bc -l
}

# render_secs [LOG]: the render's own wall time from the master's summary line.
render_secs() { awk '/summary: wall/ {print $3}' "${1:-$T/log}"; }

# median: of the numbers on stdin, one a line (mean of the middle two for an even count).
median() { sort -g | awk '{a[NR] = $1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }

# ref_key FILE...: 16 hex digits of the files and the worker binary, so that a cached
# reference image is redone when the scene or the renderer changes.
ref_key() { cat "$@" "$BUILD/worker" | sha256sum | cut -c1-16; }

# plot PNG: runs the gnuplot script on stdin, when gnuplot is installed, and names the plot.
plot() {
  if command -v gnuplot >/dev/null 2>&1; then
    if gnuplot 2>/dev/null; then echo "plot: $1"; fi
  else
    cat >/dev/null
  fi
}

# files_key FILE...: 16 hex digits of the files' contents alone (not the binaries), for a
# cache of results that depend on a scene and settings but not on this build.
files_key() { cat "$@" | sha256sum | cut -c1-16; }

# loglog_slope: least-squares slope of log(y) against log(x) over the "x y" lines on stdin
# (lines with a non-positive x or y are skipped); "nan" for fewer than two points.
loglog_slope() {
  awk '$1 > 0 && $2 > 0 { x = log($1); y = log($2); n++; sx += x; sy += y; sxx += x * x; sxy += x * y }
       END { d = n * sxx - sx * sx; if (n < 2 || d == 0) print "nan"; else printf "%.4f\n", (n * sxy - sx * sy) / d }'
}

# loglog_interp X: y at X on the piecewise-linear log-log curve through the "x y" points on
# stdin (any order); outside their range the nearest end segment is extended and a "*" is
# appended (an extrapolation). "nan" for fewer than two points.
loglog_interp() {
  sort -g | awk -v q="$1" '$1 > 0 && $2 > 0 { n++; x[n] = log($1); y[n] = log($2) }
    END { if (n < 2) { print "nan"; exit }
          lq = log(q); i = 1; while (i < n - 1 && lq > x[i + 1]) i++
          f = (x[i + 1] == x[i]) ? 0 : (lq - x[i]) / (x[i + 1] - x[i])
          printf "%.6g%s\n", exp(y[i] + f * (y[i + 1] - y[i])), (lq < x[1] || lq > x[n]) ? "*" : "" }'
}

# work IMG: the rays plus camera samples the render of IMG traced (its stats), a cost that the
# machine's load does not move (it leaves out what a unit costs beyond its rays: encoding,
# folding).
work() { python3 -c 'import json, sys; d = json.load(open(sys.argv[1])); print(d["rays"] + d["samples"])' "$1.stats.json"; }

# scene_at NAME WxH DIR: a copy of scenes/NAME in DIR with the render resolution WxH
# (the scene's own when WxH is empty); prints the JSON's path.
scene_at() {
  mkdir -p "$3"
  cp -r "scenes/$1/." "$3/"
  if [ -n "$2" ]; then
    python3 -c 'import json, sys
p, w, h = sys.argv[1], int(sys.argv[2].split("x")[0]), int(sys.argv[2].split("x")[1])
d = json.load(open(p)); d["render"]["width"] = w; d["render"]["height"] = h
json.dump(d, open(p, "w"), indent=1)' "$3/$1.json" "$2"
  fi
  echo "$3/$1.json"
}
