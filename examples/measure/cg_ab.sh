#!/usr/bin/env bash
# Per-pixel instruction counts of two prism binaries on one scene, with
# callgrind (valgrind from PATH, or $VALGRIND):
#   examples/measure/cg_ab.sh BASE NEW SCENE [extra prism render args...]
# Prints (instructions of a 96x72 render - those of a 48x36 one, 1 spp, one
# thread) for each binary and their ratio NEW/BASE: the difference cancels
# the start-up and scene-loading work.
set -euo pipefail
if [ $# -lt 3 ]; then
  echo "usage: $0 BASE NEW SCENE [prism render args...]" >&2
  exit 2
fi
A=$1; B=$2; S=$3; shift 3
VG=${VALGRIND:-valgrind}
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
count() {
  local bin=$1 w=$2 h=$3; shift 3
  "$VG" --tool=callgrind --callgrind-out-file="$tmp/cg.out" "$bin" render "$S" -o "$tmp/out.exr" \
    --width "$w" --height "$h" --spp 1 --threads 1 "$@" >/dev/null 2>&1
  grep -E '^(summary|totals):' "$tmp/cg.out" | head -1 | awk '{print $2}'
}
a=$(( $(count "$A" 96 72 "$@") - $(count "$A" 48 36 "$@") ))
b=$(( $(count "$B" 96 72 "$@") - $(count "$B" 48 36 "$@") ))
python3 -c "print('$S $*: base %d new %d ratio %.4f' % ($a, $b, $b/$a))"
