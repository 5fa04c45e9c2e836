#!/usr/bin/env bash
# Alternating A/B pairs of two prism commands on one scene:
#   examples/measure/ab_pairs.sh "A" "B" PAIRS SCENE [prism render args...]
# A and B are commands (a binary, or e.g. "taskset -c 1 path/to/prism":
# pinning one thread to one core steadies a noisy VM). Each pair runs
# `A render SCENE ...` then `B render SCENE ...`; prints the medians and
# minima of the render times (`prism render`'s "in S s"), the ratio of the
# medians and of the minima (B/A), and every pair's own ratio, sorted.
set -euo pipefail
if [ $# -lt 4 ]; then
  echo "usage: $0 \"COMMAND_A\" \"COMMAND_B\" PAIRS SCENE [prism render args...]" >&2
  exit 2
fi
A=$1; B=$2; N=$3; S=$4; shift 4
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
ta=(); tb=()
seconds() {
  # shellcheck disable=SC2086 # the command is split on purpose
  $1 render "$S" -o "$tmp/$2.exr" "${@:3}" 2>&1 | grep -oE 'in [0-9.]+ s' | awk '{print $2}'
}
for _ in $(seq "$N"); do
  ta+=("$(seconds "$A" a "$@")")
  tb+=("$(seconds "$B" b "$@")")
done
python3 - "${ta[*]}" "${tb[*]}" <<'PY'
import statistics as s, sys
a = [float(x) for x in sys.argv[1].split()]
b = [float(x) for x in sys.argv[2].split()]
r = sorted(y / x for x, y in zip(a, b))
print("A median %.3f min %.3f | B median %.3f min %.3f | B/A medians %.3f, minima %.3f,"
      " pairs' median %.3f [%s]" % (s.median(a), min(a), s.median(b), min(b),
      s.median(b) / s.median(a), min(b) / min(a), s.median(r), " ".join("%.2f" % x for x in r)))
PY
