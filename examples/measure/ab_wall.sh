#!/usr/bin/env bash
# Alternating wall-clock A/B of two prism binaries on one scene:
#   examples/measure/ab_wall.sh A B RUNS SCENE [prism render args...]
# Runs `A render SCENE`, `B render SCENE`, ... RUNS times each, alternating,
# and prints the median render seconds of each and their ratio B/A.
set -euo pipefail
if [ $# -lt 4 ]; then
  echo "usage: $0 BINARY_A BINARY_B RUNS SCENE [prism render args...]" >&2
  exit 2
fi
A=$1; B=$2; R=$3; S=$4; shift 4
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
ta=(); tb=()
for _ in $(seq "$R"); do
  for which in A B; do
    bin=$A; [ $which = B ] && bin=$B
    t=$("$bin" render "$S" -o "$tmp/$which.exr" "$@" 2>&1 | grep -oE 'in [0-9.]+ s' | awk '{print $2}')
    if [ $which = A ]; then ta+=("$t"); else tb+=("$t"); fi
  done
done
python3 -c "
import statistics as s
a=[float(x) for x in '${ta[*]}'.split()]; b=[float(x) for x in '${tb[*]}'.split()]
print('%s %s: A %.3f B %.3f B/A %.3f' % ('$S', '$*', s.median(a), s.median(b), s.median(b)/s.median(a)))"
